//! A resumed simulated run is bit-identical to an uninterrupted one (issue 15).
//!
//! Each test collects a run interrupted after some samples (a stop request, a store
//! failure, kill -9 of the binary mid-sample), resumes it to the end, collects the same
//! seed uninterrupted, and compares every stored column of every sample, the frame
//! (bytes and metadata) and the raw force/torque window exactly: not to a tolerance.
//! On the default (on-land) scene, whose tare is per run without drift, and on
//! `scenes/water.toml` (noise, drift, buoyancy offset, image effects; tare per sample).
//! Virtual time throughout; the kill -9 tests race the wall clock only in where the
//! signal lands, and every landing must give the same bytes.

use crate::common;
use common::{ok, runtime, softtouch, tempdir, text};

use softtouch_collector::collect::{
    CollectPlan, Counters, NewRunRequest, Outcome, Progress, Resumed, build_run_devices, collect,
};
use softtouch_collector::store::{Store, SyncStore};
use sqlx::{Column as _, Row as _, TypeInfo as _, ValueRef as _};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use tokio::sync::watch;

/// One stored value, compared exactly (floats by their bits).
#[derive(Debug, Clone, PartialEq, Eq)]
enum Cell {
    Null,
    Int(i64),
    Real(u64),
    Text(String),
    Blob(Vec<u8>),
}

/// Every column but `run_id` of every row of `table` for `run`, by sample index, named.
async fn rows(store: &Store, table: &str, run: i64) -> Vec<Vec<(String, Cell)>> {
    let sql = format!("SELECT * FROM {table} WHERE run_id = ? ORDER BY sample_index");
    sqlx::query(store.dialect().sql_owned(sql))
        .bind(run)
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{table}: {e}"))
        .iter()
        .map(|row| {
            row.columns()
                .iter()
                .filter(|c| c.name() != "run_id")
                .map(|c| {
                    let i = c.ordinal();
                    let raw = row.try_get_raw(i).unwrap_or_else(|e| panic!("{e}"));
                    let cell = if raw.is_null() {
                        Cell::Null
                    } else {
                        match raw.type_info().name() {
                            "INTEGER" | "BIGINT" | "INT" | "SMALLINT" => Cell::Int(row.get(i)),
                            "REAL" | "DOUBLE" => Cell::Real(row.get::<f64, _>(i).to_bits()),
                            "TEXT" => Cell::Text(row.get(i)),
                            "BLOB" => Cell::Blob(row.get(i)),
                            other => panic!("{table}.{}: unexpected type {other}", c.name()),
                        }
                    };
                    (c.name().to_owned(), cell)
                })
                .collect()
        })
        .collect()
}

/// A run as stored: samples (every label column, timestamps), frames, windows.
#[derive(Debug, PartialEq, Eq)]
struct Snapshot {
    samples: Vec<Vec<(String, Cell)>>,
    frames: Vec<Vec<(String, Cell)>>,
    windows: Vec<Vec<(String, Cell)>>,
    status: String,
}

fn snapshot(db: &Path, run: i64) -> Snapshot {
    runtime().block_on(async {
        let store = common::open_store(db).await;
        let status: String = sqlx::query_scalar(
            store
                .dialect()
                .sql("SELECT status FROM runs WHERE run_id = ?"),
        )
        .bind(run)
        .fetch_one(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        let s = Snapshot {
            samples: rows(&store, "samples", run).await,
            frames: rows(&store, "frames", run).await,
            windows: rows(&store, "ft_windows", run).await,
            status,
        };
        store.close().await;
        s
    })
}

/// Asserts two runs stored the same bytes, naming the first difference.
fn assert_identical(resumed: &Snapshot, uninterrupted: &Snapshot, planned: usize) {
    assert_eq!(resumed.status, "completed");
    assert_eq!(uninterrupted.status, "completed");
    for (what, a, b) in [
        ("samples", &resumed.samples, &uninterrupted.samples),
        ("frames", &resumed.frames, &uninterrupted.frames),
        ("ft_windows", &resumed.windows, &uninterrupted.windows),
    ] {
        assert_eq!(a.len(), planned, "{what}: resumed run");
        assert_eq!(b.len(), planned, "{what}: uninterrupted run");
        for (ra, rb) in a.iter().zip(b) {
            for (ca, cb) in ra.iter().zip(rb) {
                assert_eq!(ca, cb, "{what}: first difference (sample row {ra:?})");
            }
            assert_eq!(ra.len(), rb.len());
        }
    }
    // Sanity: the runs hold real, accepted samples.
    let ok = resumed
        .samples
        .iter()
        .filter(|r| {
            r.iter()
                .any(|(n, c)| n == "status" && *c == Cell::Text("ok".into()))
        })
        .count();
    assert!(ok * 2 > planned, "{ok} of {planned} accepted");
}

fn water_scene() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/water.toml")
}

/// `collect --samples N --seed S [--scene FILE]` as arguments.
fn new_run_args(samples: u64, seed: u64, scene: Option<&Path>) -> Vec<String> {
    let mut args = vec![
        "collect".to_owned(),
        "--samples".to_owned(),
        samples.to_string(),
        "--seed".to_owned(),
        seed.to_string(),
    ];
    if let Some(s) = scene {
        args.extend(["--scene".to_owned(), s.display().to_string()]);
    }
    args
}

fn run_binary(dir: &Path, args: &[String]) -> std::process::Output {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    softtouch(dir, &args)
}

/// The uninterrupted run of the same seed, as run `run` of the same database.
fn uninterrupted(dir: &Path, samples: u64, seed: u64, scene: Option<&Path>, run: i64) -> Snapshot {
    let out = run_binary(dir, &new_run_args(samples, seed, scene));
    ok(&out);
    assert!(
        text(&out.stdout).contains(&format!("run {run}:")),
        "{}",
        text(&out.stdout)
    );
    snapshot(&dir.join("softtouch.db"), run)
}

// ---------------------------------------------------------------- a stop request

/// Asks the job to stop (as one Ctrl-C does) once sample `after` is done.
struct StopAfter {
    after: u64,
    stop: watch::Sender<u32>,
}

impl Progress for StopAfter {
    fn sample_done(&mut self, index: u64, _c: &Counters) {
        if index == self.after {
            let _ = self.stop.send(1);
        }
    }
    fn note(&mut self, _message: &str) {}
}

/// Collect `plan` in this process (the library, on virtual time) with the devices
/// `softtouch collect` builds, asking it to stop after sample `stop_after`.
fn collect_in_process(store: &SyncStore, plan: &CollectPlan, stop_after: u64) -> Outcome {
    softtouch_collector::testing::block_on(async {
        let (devices, clock) = build_run_devices(store, plan)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let (stop, stop_rx) = watch::channel(0u32);
        let mut progress = StopAfter {
            after: stop_after,
            stop,
        };
        collect(store, plan, devices, clock, stop_rx, &mut progress)
            .await
            .0
    })
}

fn stopped_and_resumed(scene: Option<&Path>, samples: u64, seed: u64, stops: &[u64]) {
    let dir = tempdir();
    let db = dir.path().join("softtouch.db");
    let store = SyncStore::open(common::target_of(&db)).unwrap_or_else(|e| panic!("{e}"));
    let request = NewRunRequest {
        scene: scene.map(Path::to_path_buf),
        samples,
        seed: Some(seed),
        ..NewRunRequest::default()
    };
    let plan = CollectPlan::new_run(&store, &request).unwrap_or_else(|e| panic!("{e}"));
    let run = plan.run_id;
    let mut outcome = collect_in_process(&store, &plan, stops[0]);
    assert_eq!(outcome, Outcome::Stopped);
    for &stop in &stops[1..] {
        let Resumed::Plan(plan) =
            CollectPlan::resume(&store, run).unwrap_or_else(|e| panic!("{e}"))
        else {
            panic!("run {run} is complete before its last stop");
        };
        assert_eq!(plan.start_index, stop_index(&store, run));
        outcome = collect_in_process(&store, &plan, stop);
        assert_eq!(outcome, Outcome::Stopped);
    }
    store.close();
    // The rest through the binary, as an operator would.
    ok(&run_binary(
        dir.path(),
        &["collect".into(), "--resume".into(), run.to_string()],
    ));
    let resumed = snapshot(&db, run);
    let straight = uninterrupted(dir.path(), samples, seed, scene, run + 1);
    assert_identical(&resumed, &straight, usize::try_from(samples).unwrap_or(0));
}

/// The next index a stopped run takes (every index below it is stored).
fn stop_index(store: &SyncStore, run: i64) -> u64 {
    store.next_index(run).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn a_run_stopped_twice_and_resumed_equals_an_uninterrupted_one_on_land() {
    // Stops inside a rod block and at its end (blocks of 2 over 5 rods).
    stopped_and_resumed(None, 10, 21, &[2, 5]);
}

#[test]
fn a_run_stopped_twice_and_resumed_equals_an_uninterrupted_one_underwater() {
    stopped_and_resumed(Some(&water_scene()), 10, 22, &[0, 6]);
}

// ---------------------------------------------------------------- a store failure

fn failed_and_resumed(scene: Option<&Path>, samples: u64, seed: u64) {
    let dir = tempdir();
    let db = dir.path().join("softtouch.db");
    ok(&softtouch(dir.path(), &["db", "init"]));
    let sql = |sql: String| {
        runtime().block_on(async {
            let store = common::open_store(&db).await;
            sqlx::raw_sql(sqlx::AssertSqlSafe(sql))
                .execute(store.pool())
                .await
                .unwrap_or_else(|e| panic!("{e}"));
            store.close().await;
        });
    };
    // Sample inserts fail from index 3 on (as a full disk would); events still go through.
    sql(common::fail_inserts_from(3));
    let out = run_binary(dir.path(), &new_run_args(samples, seed, scene));
    common::fails_with(&out, 1, "disk is full");
    sql(common::stop_failing().to_owned());
    let partial = snapshot(&db, 1);
    // Samples 0..3 are stored until the planned order first reaches an index from 3 on
    // (blocks of 2: the order within [2, 3] is the plan's).
    assert!(
        (2..=3).contains(&partial.samples.len()),
        "{} samples stored before the failure",
        partial.samples.len()
    );
    ok(&run_binary(
        dir.path(),
        &["collect".into(), "--resume".into(), "1".into()],
    ));
    let resumed = snapshot(&db, 1);
    let straight = uninterrupted(dir.path(), samples, seed, scene, 2);
    assert_identical(&resumed, &straight, usize::try_from(samples).unwrap_or(0));
}

#[test]
fn a_run_failed_by_its_store_and_resumed_equals_an_uninterrupted_one_on_land() {
    failed_and_resumed(None, 8, 31);
}

#[test]
fn a_run_failed_by_its_store_and_resumed_equals_an_uninterrupted_one_underwater() {
    failed_and_resumed(Some(&water_scene()), 8, 32);
}

// ---------------------------------------------------------------- kill -9

/// Samples of run 1 so far, read without migrating (the child owns the database).
fn count_samples(db: &Path) -> i64 {
    runtime().block_on(async { common::samples_in(db, 1).await })
}

/// Runs `args` and kills it (SIGKILL) once run 1 holds `at_least` samples; returns
/// whether it was killed before it ended by itself.
fn kill_after(dir: &Path, args: &[String], at_least: i64) -> bool {
    let mut child = common::command(dir)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"));
    let db = dir.join("softtouch.db");
    loop {
        if child.try_wait().ok().flatten().is_some() {
            return false;
        }
        if count_samples(&db) >= at_least {
            break;
        }
        std::thread::yield_now();
    }
    let _ = child.kill(); // SIGKILL: mid-sample, mid-write, wherever it is
    let _ = child.wait();
    true
}

fn killed_and_resumed(scene: Option<&Path>, samples: u64, seed: u64, kills: &[i64]) {
    let dir = tempdir();
    let db = dir.path().join("softtouch.db");
    let mut args = new_run_args(samples, seed, scene);
    let mut killed = 0;
    for &at in kills {
        killed += u32::from(kill_after(dir.path(), &args, at));
        args = vec!["collect".into(), "--resume".into(), "1".into()];
    }
    assert!(killed > 0, "no kill landed before the run ended");
    ok(&run_binary(dir.path(), &args));
    let resumed = snapshot(&db, 1);
    let straight = uninterrupted(dir.path(), samples, seed, scene, 2);
    assert_identical(&resumed, &straight, usize::try_from(samples).unwrap_or(0));
}

#[test]
fn a_run_killed_mid_sample_and_resumed_equals_an_uninterrupted_one_on_land() {
    killed_and_resumed(None, 40, 41, &[3, 11, 25]);
}

#[test]
fn a_run_killed_mid_sample_and_resumed_equals_an_uninterrupted_one_underwater() {
    killed_and_resumed(Some(&water_scene()), 40, 42, &[4, 17]);
}
