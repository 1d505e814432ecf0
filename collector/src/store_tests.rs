//! The store's tests that need the collector's fixtures (synthetic samples, planned
//! runs): what a sample, its frame and its window look like after a round trip.

use crate::store::*;
use crate::testing::{RunPlan, SampleBuilder, temp_store, tempdir};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{ContactPose, FrameFormat, FtStatus, TimestampNs, Wrench};
use softtouch_schemas::{FrameMeta, FtReading, Sample, SampleStatus};

/// The builder's default sample, measured and with a negative skew.
pub(crate) fn sample(index: u64) -> Sample {
    SampleBuilder::new(index)
        .measured(ContactPose {
            x_m: 0.0101,
            z_m: 0.0001,
            theta_rad: 0.0001,
        })
        .skew_ns(-500)
        .build()
}

pub(crate) fn window() -> Vec<FtReading> {
    (0..2u32)
        .map(|i| FtReading {
            t: TimestampNs(990_000 + u64::from(i) * 1_000),
            rdt_sequence: i + 1,
            ft_sequence: 70_000 + i,
            status: FtStatus::OK,
            wrench_in_sensor: Wrench::from_array([1.0, -2.0, 3.0, 0.1, -0.2, f64::from(i)]),
        })
        .collect()
}

fn meta() -> FrameMeta {
    FrameMeta {
        t: TimestampNs(1_000_000),
        sequence: 120,
        width: 2,
        height: 1,
        format: FrameFormat::Rgb8,
    }
}

async fn new_run(store: &Store) -> RunId {
    RunPlan::new(u64::MAX, 10).create(store).await
}

#[tokio::test]
async fn a_new_database_is_migrated_in_wal_mode_with_foreign_keys_on() -> Result<(), StoreError> {
    let (_dir, store) = temp_store("test.db").await;
    if store.dialect() == softtouch_store::Dialect::Postgres {
        // PostgreSQL has no journal mode to choose, and its foreign keys are always
        // on: a sample of a run that is not there is refused.
        let orphan = store
            .append_sample(424_242, &sample(0), None, &window())
            .await;
        assert!(
            matches!(orphan, Err(StoreError::Query { .. })),
            "{orphan:?}"
        );
        assert_eq!(store.integrity_check().await?, "ok");
        return Ok(());
    }
    let mode: String = sqlx::query_scalar("PRAGMA journal_mode")
        .fetch_one(store.pool())
        .await
        .map_err(query_err("t"))?;
    let fk: i64 = sqlx::query_scalar("PRAGMA foreign_keys")
        .fetch_one(store.pool())
        .await
        .map_err(query_err("t"))?;
    assert_eq!(mode, "wal");
    assert_eq!(fk, 1);
    assert!(Store::schema_version() >= 20_261_121_000_000);
    assert_eq!(store.integrity_check().await?, "ok");
    Ok(())
}

#[tokio::test]
async fn a_sample_is_written_with_its_frame_and_window_and_a_second_write_changes_nothing()
-> Result<(), StoreError> {
    let (_dir, store) = temp_store("test.db").await;
    let run = new_run(&store).await;
    let frame = Some(FrameRecord {
        meta: meta(),
        data: &[1, 2, 3, 4, 5, 6],
    });
    assert_eq!(
        store
            .append_sample(run, &sample(0), frame, &window())
            .await?,
        Appended::Inserted
    );

    let mut changed = sample(0);
    changed.rod = "square-10".into();
    assert_eq!(
        store.append_sample(run, &changed, frame, &window()).await?,
        Appended::AlreadyPresent
    );

    assert_eq!(
        store.row_counts(run).await?,
        RowCounts {
            samples: 1,
            frames: 1,
            windows: 1
        }
    );
    let rod: String = sqlx::query_scalar("SELECT rod FROM samples")
        .fetch_one(store.pool())
        .await
        .map_err(query_err("t"))?;
    assert_eq!(rod, "circle-10", "the first write stands");
    let blob: Vec<u8> = sqlx::query_scalar("SELECT data FROM ft_windows")
        .fetch_one(store.pool())
        .await
        .map_err(query_err("t"))?;
    assert_eq!(decode_window(&blob), Some(window()));
    assert_eq!(store.next_index(run).await?, 1);
    Ok(())
}

#[tokio::test]
async fn a_transaction_that_fails_midway_leaves_nothing_half_written() -> Result<(), StoreError> {
    // Given a store with one good sample
    let (_dir, store) = temp_store("test.db").await;
    let run = new_run(&store).await;
    store
        .append_sample(
            run,
            &sample(0),
            Some(FrameRecord {
                meta: meta(),
                data: &[1],
            }),
            &window(),
        )
        .await?;

    // When the second sample's row goes in but its frame is refused (empty pixels
    // violate the frames table's CHECK), after the sample INSERT succeeded
    let err = store
        .append_sample(
            run,
            &sample(1),
            Some(FrameRecord {
                meta: meta(),
                data: &[],
            }),
            &window(),
        )
        .await
        .err();

    // Then the error says where it failed, and nothing of sample 1 is stored
    let msg = err.map(|e| e.to_string()).unwrap_or_default();
    assert!(msg.contains("inserting a frame"), "{msg}");
    assert_eq!(
        store.row_counts(run).await?,
        RowCounts {
            samples: 1,
            frames: 1,
            windows: 1
        }
    );
    assert_eq!(store.next_index(run).await?, 1);

    // And the same index can then be written whole
    let appended = store
        .append_sample(
            run,
            &sample(1),
            Some(FrameRecord {
                meta: meta(),
                data: &[9],
            }),
            &window(),
        )
        .await?;
    assert_eq!(appended, Appended::Inserted);
    assert_eq!(
        store.row_counts(run).await?,
        RowCounts {
            samples: 2,
            frames: 2,
            windows: 2
        }
    );
    Ok(())
}

#[tokio::test]
async fn runs_list_counts_ok_rejected_retries_and_faults() -> Result<(), StoreError> {
    let (_dir, store) = temp_store("test.db").await;
    let run = new_run(&store).await;
    let frame = Some(FrameRecord {
        meta: meta(),
        data: &[1],
    });
    store
        .append_sample(run, &sample(0), frame, &window())
        .await?;
    let mut rejected = sample(1);
    rejected.status = SampleStatus::Rejected(RejectReason::SensorFault);
    rejected.attempts = 3;
    store
        .append_sample(run, &rejected, frame, &window())
        .await?;
    store
        .log_event(
            run,
            Some(1),
            Some(TimestampNs(5)),
            EventLevel::Warn,
            "sensor_fault",
            "status 0x00020000",
        )
        .await?;
    store
        .log_event(run, None, None, EventLevel::Info, "started", "run started")
        .await?;
    store.set_run_status(run, RunStatus::Completed).await?;

    let runs = store.runs().await?;
    assert_eq!(runs.len(), 1);
    let r = &runs[0];
    assert_eq!(
        (
            r.status.as_str(),
            r.ok,
            r.rejected,
            r.retried,
            r.events,
            r.faults
        ),
        ("completed", 1, 1, 2, 2, 1)
    );
    assert_eq!(r.seed, -1, "u64::MAX is stored as its bit pattern");
    let record = store.run_record(run).await?;
    assert_eq!(
        (
            record.seed_u64(),
            record.rod_schedule.as_slice(),
            record.rod_block
        ),
        (u64::MAX, &["circle-10".to_owned()][..], 10)
    );
    assert!(matches!(
        store.run_record(7).await,
        Err(StoreError::NoSuchRun(7))
    ));
    let events = store.events(run, 1).await?;
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].kind, "started");
    assert!(matches!(
        store.set_run_status(99, RunStatus::Failed).await,
        Err(StoreError::NoSuchRun(99))
    ));
    Ok(())
}

#[tokio::test]
async fn a_store_dropped_without_closing_reopens_intact() -> Result<(), StoreError> {
    let (_dir, store) = temp_store("test.db").await;
    let target = store.target().clone();
    let run = new_run(&store).await;
    for i in 0..20 {
        store
            .append_sample(
                run,
                &sample(i),
                Some(FrameRecord {
                    meta: meta(),
                    data: &[1, 2],
                }),
                &window(),
            )
            .await?;
    }
    drop(store); // without close(): the WAL is not checkpointed
    let store = Store::open(&target).await?;
    assert_eq!(store.integrity_check().await?, "ok");
    assert_eq!(
        store.row_counts(run).await?,
        RowCounts {
            samples: 20,
            frames: 20,
            windows: 20
        }
    );
    Ok(())
}

#[tokio::test]
async fn a_sample_rejected_before_any_frame_is_stored_without_one() -> Result<(), StoreError> {
    let (_dir, store) = temp_store("test.db").await;
    let run = new_run(&store).await;
    let mut s = sample(0);
    s.status = SampleStatus::Rejected(RejectReason::FrameTimeout);
    store.append_sample(run, &s, None, &[]).await?;
    assert_eq!(
        store.row_counts(run).await?,
        RowCounts {
            samples: 1,
            frames: 0,
            windows: 1
        }
    );
    Ok(())
}

#[test]
fn a_window_blob_of_the_wrong_length_is_refused_not_misread() {
    let blob = encode_window(&window());
    assert_eq!(decode_window(&blob), Some(window()));
    assert_eq!(decode_window(&blob[..blob.len() - 1]), None);
    assert_eq!(decode_window(&[]), Some(vec![]));
}

#[test]
fn stored_statuses_parse_back_or_fail_clearly() {
    assert_eq!(parse_status("ok", None), Ok(SampleStatus::Ok));
    assert_eq!(
        parse_status("rejected", Some("saturated")),
        Ok(SampleStatus::Rejected(RejectReason::Saturated))
    );
    assert!(parse_status("ok", Some("saturated")).is_err());
    assert!(parse_status("rejected", Some("bogus")).is_err());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_processes_opening_a_new_database_at_once_both_succeed() -> Result<(), StoreError> {
    let dir = tempdir();
    if crate::testing::on_postgres() {
        // Both migrate one new database at once: sqlx's advisory lock lets one in.
        for _ in 0..3 {
            let target = crate::testing::fresh_target(dir.path(), "fresh.db").await;
            let (a, b) = tokio::join!(Store::open(&target), Store::open(&target));
            let (a, b) = (a?, b?);
            assert_eq!(a.integrity_check().await?, "ok");
            a.close().await;
            b.close().await;
        }
        return Ok(());
    }
    let path = dir.path().join("fresh.db");
    for _ in 0..5 {
        let _ = std::fs::remove_file(&path);
        let (a, b) = tokio::join!(Store::open(&path), Store::open(&path));
        let (a, b) = (a?, b?);
        assert_eq!(a.integrity_check().await?, "ok");
        a.close().await;
        b.close().await;
        for suffix in ["-wal", "-shm"] {
            let _ = std::fs::remove_file(format!("{}{suffix}", path.display()));
        }
    }
    Ok(())
}

/// A run's rest frames: stored once (a second store, as a resumed run makes, keeps
/// the first), read back by the datasets that hold the run, gone with the run.
#[tokio::test]
async fn rest_frames_are_kept_once_per_run_and_read_by_dataset() -> Result<(), StoreError> {
    let (_dir, store) = temp_store("rest.db").await;
    let run = RunPlan::new(3, 2).create(&store).await;
    for i in 0..2 {
        let frame = FrameRecord {
            meta: meta(),
            data: &[7; 6],
        };
        store
            .append_sample(run, &sample(i), Some(frame), &window())
            .await?;
    }
    let first = [FrameRecord {
        meta: meta(),
        data: &[1, 2, 3, 4, 5, 6],
    }; 2];
    assert_eq!(store.insert_rest_frames(run, &first).await?, 2);
    let again = [FrameRecord {
        meta: meta(),
        data: &[9, 9, 9, 9, 9, 9],
    }; 3];
    // The first two keep their place; a third index is new.
    assert_eq!(store.insert_rest_frames(run, &again).await?, 1);
    let dataset = crate::dataset::create(
        &store,
        &crate::dataset::NewDataset {
            name: "both".into(),
            runs: vec![run],
            filters: crate::dataset::Filters::default(),
            ratio: crate::dataset::SplitRatio { parts: [1, 0, 0] },
            seed: 0,
        },
    )
    .await
    .map_err(|e| StoreError::Invalid {
        what: "dataset",
        why: e.to_string(),
    })?;
    let rows = store.dataset_rest_frames(dataset.dataset_id).await?;
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0].data, vec![1, 2, 3, 4, 5, 6]);
    assert_eq!(rows[2].data, vec![9, 9, 9, 9, 9, 9]);
    assert_eq!(
        (rows[0].width, rows[0].height, rows[0].format.as_str()),
        (2, 1, "rgb8")
    );
    Ok(())
}
