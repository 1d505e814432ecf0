//! End-to-end tests of `softtouch collect` on the simulated rig: a run's database,
//! kill -9 and resume, and fault injection.

use crate::common;
use common::{fails_with, ok, runtime, softtouch, tempdir, text};

use softtouch_collector::collect::sampler::PoseSampler;
use softtouch_collector::store::{Store, decode_window};
use softtouch_schemas::defaults;
use sqlx::Row as _;
use std::path::Path;
use std::process::Stdio;

/// Every sample's commanded pose, by index.
async fn poses(store: &Store, run: i64) -> Vec<(i64, f64, f64, f64)> {
    sqlx::query(store.dialect().sql("SELECT sample_index, cmd_x_m, cmd_z_m, cmd_theta_rad FROM samples WHERE run_id = ? ORDER BY sample_index"))
        .bind(run)
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"))
        .iter()
        .map(|r| (r.get(0), r.get(1), r.get(2), r.get(3)))
        .collect()
}

#[test]
fn a_simulated_run_stores_every_sample_with_its_frame_and_window() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["collect", "--samples", "240", "--seed", "11"]);
    assert!(
        out.status.success(),
        "{}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    assert!(
        text(&out.stdout).contains("240 ok"),
        "{}",
        text(&out.stdout)
    );

    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        let counts = store.row_counts(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((counts.samples, counts.frames, counts.windows), (240, 240, 240));

        let rows = sqlx::query(store.dialect().sql(
            "SELECT s.sample_index, s.frame_t_ns, s.window_start_ns, s.window_end_ns, s.reading_count,
                    w.reading_count, w.data, f.format, f.width, f.height, s.status, s.rod,
                    s.cmd_x_m, s.cmd_z_m, s.cmd_theta_rad, s.fx_n
             FROM samples s JOIN frames f USING (run_id, sample_index) JOIN ft_windows w USING (run_id, sample_index)
             WHERE s.run_id = 1 ORDER BY s.sample_index"),
        )
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        let ranges = defaults::scene().poses;
        let sampler = PoseSampler::new(11, ranges.clone());
        let mut rods = std::collections::BTreeSet::new();
        for row in &rows {
            let index: i64 = row.get(0);
            let (frame_t, start, end): (i64, i64, i64) = (row.get(1), row.get(2), row.get(3));
            assert!(start <= frame_t && frame_t <= end, "sample {index}: window does not contain its frame");
            let n: i64 = row.get(4);
            assert_eq!(n, row.get::<i64, _>(5));
            let readings = decode_window(&row.get::<Vec<u8>, _>(6)).unwrap_or_else(|| panic!("bad window blob"));
            assert_eq!(readings.len() as i64, n);
            assert!(n >= 25, "sample {index}: {n} readings");
            assert!(readings.iter().all(|r| r.t.0 as i64 >= start && r.t.0 as i64 <= end));
            assert_eq!((row.get::<String, _>(7).as_str(), row.get::<i64, _>(8), row.get::<i64, _>(9)), ("png", 640, 480));
            assert_eq!(row.get::<String, _>(10), "ok");
            rods.insert(row.get::<String, _>(11));
            let (x, z, th): (f64, f64, f64) = (row.get(12), row.get(13), row.get(14));
            assert!(ranges.x_m.contains(x) && ranges.z_m.contains(z) && ranges.theta_rad.contains(th));
            let expect = sampler.pose(u64::try_from(index).unwrap_or(0));
            assert_eq!((x, z, th), (expect.x_m, expect.z_m, expect.theta_rad), "pose {index} is a function of (seed, index)");
            assert!(row.get::<f64, _>(15).is_finite());
        }
        assert_eq!(rods.len(), 5, "every rod of the default scene took its block");
        assert_eq!(store.integrity_check().await.unwrap_or_default(), "ok");
    });

    let status = softtouch(dir.path(), &["status", "1"]);
    assert!(
        text(&status.stdout).contains("240/240 samples, 240 ok"),
        "{}",
        text(&status.stdout)
    );
}

/// `(index, cmd x z θ, fx fy fz tx ty tz, status)` of run 1's samples, by index.
fn labels(db: &Path) -> Vec<(i64, [f64; 3], [f64; 6], String)> {
    runtime().block_on(async {
        let store = common::open_store(db).await;
        let rows = sqlx::query(store.dialect().sql(
            "SELECT sample_index, cmd_x_m, cmd_z_m, cmd_theta_rad, fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm, status
             FROM samples WHERE run_id = 1 ORDER BY sample_index",
        ))
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        rows.iter()
            .map(|r| {
                (
                    r.get(0),
                    [r.get(1), r.get(2), r.get(3)],
                    [r.get(4), r.get(5), r.get(6), r.get(7), r.get(8), r.get(9)],
                    r.get(10),
                )
            })
            .collect()
    })
}

/// The planned order changes only the order and the travel: the same seed gives the
/// same poses, bit for bit, and the same labels up to the sensor's noise (each label
/// is a mean of 50 readings of σ 0.0125 N and 0.0625 N·mm), as index order gives.
#[test]
fn the_planned_order_gives_the_same_poses_and_labels_as_index_order() {
    let planned = tempdir();
    let out = softtouch(
        planned.path(),
        &["collect", "--samples", "150", "--seed", "4"],
    );
    let stdout = ok(&out);
    // Where the time went, as the run's events store it.
    assert!(
        stdout.contains("where a sample's time went (150 samples"),
        "{stdout}"
    );
    let index = tempdir();
    let rig = defaults::RIG_TOML.replace("visit_order = \"planned\"", "visit_order = \"index\"");
    assert_ne!(rig, defaults::RIG_TOML);
    std::fs::write(index.path().join("rig.toml"), rig).unwrap_or_else(|e| panic!("{e}"));
    ok(&softtouch(
        index.path(),
        &[
            "collect",
            "--rig",
            "rig.toml",
            "--samples",
            "150",
            "--seed",
            "4",
        ],
    ));
    let a = labels(&planned.path().join("softtouch.db"));
    let b = labels(&index.path().join("softtouch.db"));
    assert_eq!(a.len(), 150);
    assert_eq!(b.len(), 150);
    let mut differ = 0;
    for (p, q) in a.iter().zip(&b) {
        assert_eq!(p.0, q.0);
        assert_eq!(
            p.1.map(f64::to_bits),
            q.1.map(f64::to_bits),
            "sample {}: pose",
            p.0
        );
        assert_eq!((p.3.as_str(), q.3.as_str()), ("ok", "ok"), "sample {}", p.0);
        for axis in 0..6 {
            // 5σ of the difference of two means of 50 readings, plus 0.5 %.
            let sigma = if axis < 3 { 0.0125 } else { 0.0000625 };
            let tol = 5.0 * sigma * (2.0f64 / 50.0).sqrt() + 0.005 * q.2[axis].abs();
            assert!(
                (p.2[axis] - q.2[axis]).abs() <= tol,
                "sample {} axis {axis}: planned {} against index order {}",
                p.0,
                p.2[axis],
                q.2[axis]
            );
            if p.2[axis].to_bits() != q.2[axis].to_bits() {
                differ += 1;
            }
        }
    }
    // Not the same run twice: the noise was drawn at other times.
    assert!(differ > 0);
    // The planned run visited its blocks in another order than the indices.
    runtime().block_on(async {
        let store = common::open_store(&planned.path().join("softtouch.db")).await;
        let events = store
            .events(1, 1000)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let plans: Vec<_> = events.iter().filter(|e| e.kind == "visit_plan").collect();
        assert_eq!(plans.len(), 5, "one per rod's block");
        assert!(
            plans[0].message.contains("planned order (fingerprint "),
            "{:?}",
            plans[0]
        );
        assert_ne!(plans[0].sample_index, Some(0), "the plan starts elsewhere");
        assert!(events.iter().any(|e| e.kind == "phase_times"));
    });
}

/// Samples of run 1 so far, read without migrating (the child owns the database).
async fn stored_samples(db: &Path) -> i64 {
    common::samples_in(db, 1).await
}

#[test]
fn a_run_killed_at_random_points_resumes_to_exactly_the_planned_samples() {
    let dir = tempdir();
    let db = dir.path().join("softtouch.db");
    let planned = 150i64;
    // Kill points: after these many stored samples (spread over the run), plus wherever
    // the process happens to be when the signal lands.
    let kill_after = [7i64, 31, 64, 65, 110];
    let rt = runtime();
    let mut first = true;
    for target in kill_after {
        let args: Vec<String> = if first {
            ["collect", "--samples", &planned.to_string(), "--seed", "5"]
                .iter()
                .map(|s| (*s).to_owned())
                .collect()
        } else {
            ["collect", "--resume", "1"]
                .iter()
                .map(|s| (*s).to_owned())
                .collect()
        };
        first = false;
        let mut child = common::command(dir.path())
            .args(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("{e}"));
        // Watch the database until the target is reached (or the child ends), then kill -9.
        loop {
            if child.try_wait().ok().flatten().is_some() {
                break;
            }
            let stored = rt.block_on(stored_samples(&db));
            if stored >= target {
                break;
            }
            std::thread::yield_now();
        }
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
    }
    // Finish the run.
    let out = softtouch(dir.path(), &["collect", "--resume", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    // An uninterrupted run with the same seed, for comparison.
    let out = softtouch(
        dir.path(),
        &["collect", "--samples", &planned.to_string(), "--seed", "5"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));

    rt.block_on(async {
        let store = common::open_store(&db).await;
        assert_eq!(store.integrity_check().await.unwrap_or_default(), "ok");
        let c = store.row_counts(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.samples, planned);
        assert_eq!(c.windows, planned);
        let resumed = poses(&store, 1).await;
        let indices: Vec<i64> = resumed.iter().map(|p| p.0).collect();
        assert_eq!(indices, (0..planned).collect::<Vec<_>>(), "no gap, no duplicate");
        assert_eq!(resumed, poses(&store, 2).await, "the resumed run took the same poses");
        let orphans: i64 = sqlx::query_scalar(store.dialect().sql(
            "SELECT (SELECT COUNT(*) FROM frames f WHERE NOT EXISTS (SELECT 1 FROM samples s WHERE s.run_id = f.run_id AND s.sample_index = f.sample_index))
                  + (SELECT COUNT(*) FROM ft_windows w WHERE NOT EXISTS (SELECT 1 FROM samples s WHERE s.run_id = w.run_id AND s.sample_index = w.sample_index))"),
        )
        .fetch_one(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(orphans, 0, "no half-written sample");
        let runs = store.runs().await.unwrap_or_default();
        assert_eq!(runs[0].status, "completed");
    });
}

#[test]
fn a_scene_with_packet_loss_frame_drops_and_reflexes_completes_and_logs_every_fault() {
    let dir = tempdir();
    let scene = format!(
        "{}\n[[effects]]\nkind = \"ft_packet_loss\"\nprobability = 0.003\n\n[[effects]]\nkind = \"frame_drops\"\nprobability = 0.3\n\n[[effects]]\nkind = \"arm_reflex\"\nprobability = 0.05\n",
        defaults::SCENE_TOML
    );
    std::fs::write(dir.path().join("faulty.toml"), scene).unwrap_or_else(|e| panic!("{e}"));
    let out = softtouch(
        dir.path(),
        &[
            "collect",
            "--scene",
            "faulty.toml",
            "--samples",
            "120",
            "--seed",
            "2",
        ],
    );
    assert!(
        out.status.success(),
        "{}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );

    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        let count = |kind: &'static str| {
            let pool = store.pool().clone();
            let d = store.dialect();
            async move {
                sqlx::query_scalar::<_, i64>(d.sql("SELECT COUNT(*) FROM events WHERE kind = ?"))
                    .bind(kind)
                    .fetch_one(&pool)
                    .await
                    .unwrap_or(0)
            }
        };
        assert!(count("arm_fault").await > 0, "reflexes were injected and logged");
        assert_eq!(count("arm_fault").await, count("arm_recovered").await, "each reflex recovered");
        assert!(count("missing_readings").await > 0, "lost packets showed as gaps");
        let drops: String = sqlx::query_scalar(store.dialect().sql("SELECT message FROM events WHERE kind = 'stream_counts'"))
            .fetch_one(store.pool())
            .await
            .unwrap_or_default();
        assert!(!drops.contains(" 0 frames dropped") && !drops.contains(" 0 lost on the link"), "{drops}");

        // Every extra attempt of a sample has a warning event naming that sample.
        let rows = sqlx::query(store.dialect().sql(
            "SELECT s.sample_index, s.attempts,
                    (SELECT COUNT(*) FROM events e WHERE e.run_id = s.run_id AND e.sample_index = s.sample_index AND e.level = 'warn')
             FROM samples s WHERE s.run_id = 1"),
        )
        .fetch_all(store.pool())
        .await
        .unwrap_or_default();
        assert_eq!(rows.len(), 120);
        let mut retried = 0;
        for r in &rows {
            let (index, attempts, warnings): (i64, i64, i64) = (r.get(0), r.get(1), r.get(2));
            assert!(warnings >= attempts - 1, "sample {index}: {attempts} attempts but {warnings} warnings");
            retried += i64::from(attempts > 1);
        }
        assert!(retried > 0);
    });
}

/// The label error against the simulator's truth in a scene with a sensor offset and
/// zero drift (no noise): a tare per sample removes both, no tare leaves them in.
#[test]
fn a_tare_per_sample_removes_offset_and_drift_from_the_labels() {
    let dir = tempdir();
    let rig = common::ok(&softtouch(dir.path(), &["config", "show", "rig"]));
    let mut scene = common::ok(&softtouch(dir.path(), &["config", "show", "scene"]));
    scene.push_str(
        "\n[[effects]]\nkind = \"buoyancy_offset\"\nforce_n = [0.0, 0.0, 0.3]\ntorque_nm = [0.0, 0.0, 0.002]\n\
         \n[[effects]]\nkind = \"ft_drift\"\nforce_n_per_h = 3.0\ntorque_nm_per_h = 0.03\n",
    );
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap_or_else(|e| panic!("{e}"));
    let rmse = |tare: &str| -> (f64, f64) {
        let with = rig.replacen(
            "[procedure]\n",
            &format!("[procedure]\ntare = \"{tare}\"\n"),
            1,
        );
        assert_ne!(with, rig, "the rig has a [procedure] table");
        std::fs::write(dir.path().join(format!("rig-{tare}.toml")), with)
            .unwrap_or_else(|e| panic!("{e}"));
        let rig_arg = format!("rig-{tare}.toml");
        let out_arg = format!("out-{tare}");
        let out = common::ok(&softtouch(
            dir.path(),
            &[
                "bench",
                "collection",
                "--samples",
                "20",
                "--settle",
                "0.3",
                "--window",
                "0.05",
                "--rig",
                &rig_arg,
                "--scene",
                "scene.toml",
                "--out",
                &out_arg,
            ],
        ));
        // The table row: settle settle_s mean_s window accepted force_rmse_N
        // torque_rmse_Nmm ... (the fixed 0.3 s).
        let row = out
            .lines()
            .find(|l| l.split_whitespace().take(2).eq(["fixed", "0.3"]))
            .unwrap_or_else(|| panic!("no table row in:\n{out}"));
        let cols: Vec<&str> = row.split_whitespace().collect();
        let num = |i: usize| {
            cols.get(i)
                .and_then(|c| c.parse::<f64>().ok())
                .unwrap_or_else(|| panic!("column {i} of `{row}`"))
        };
        (num(5), num(6))
    };
    let (none_n, none_nmm) = rmse("none");
    let (tared_n, tared_nmm) = rmse("per-sample");
    // Untared: 0.3 N on Fz alone is 0.17 N RMS over three axes; 2 N·mm on Tz 1.15 N·mm.
    assert!(
        none_n > 0.15 && none_nmm > 1.0,
        "no tare: {none_n} N, {none_nmm} N·mm"
    );
    // Tared: what is left is the settling error of the default procedure (≈ 2 mN).
    assert!(
        tared_n < 0.01 && tared_nmm < 0.2,
        "tare per sample: {tared_n} N, {tared_nmm} N·mm"
    );
}

/// A collection appends to the log beside its database: the start, every run event
/// (here the rod change and the completion) and the outcome; not to stderr.
#[test]
fn a_collection_writes_its_log_beside_the_database() {
    if common::skip_on_postgres("a_collection_writes_its_log_beside_the_database") {
        return;
    }
    let dir = tempdir();
    let out = softtouch(dir.path(), &["collect", "--samples", "3", "--seed", "2"]);
    common::ok(&out);
    let log = std::fs::read_to_string(dir.path().join("softtouch.db.log"))
        .unwrap_or_else(|e| panic!("no softtouch.db.log: {e}"));
    assert!(
        log.contains("softtouch collect --samples 3 --seed 2 started"),
        "{log}"
    );
    assert!(
        log.contains("kind=\"rod_change\"") || log.contains("kind=rod_change"),
        "{log}"
    );
    assert!(log.contains("completed"), "{log}");
    assert!(
        log.lines().last().is_some_and(|l| l.contains("finished")),
        "{log}"
    );
    assert!(
        !text(&out.stderr).contains("rod_change"),
        "events stay off stderr"
    );
    // A second run appends.
    common::ok(&softtouch(
        dir.path(),
        &["collect", "--samples", "1", "--seed", "3"],
    ));
    let again = std::fs::read_to_string(dir.path().join("softtouch.db.log")).unwrap_or_default();
    assert!(again.starts_with(&log) && again.len() > log.len());
    // Read-only verbs write none.
    let other = tempdir();
    common::ok(&softtouch(other.path(), &["config", "show", "rig"]));
    assert!(!other.path().join("softtouch.db.log").exists());
}

/// Every sample's rod, by index.
async fn sample_rods(store: &Store, run: i64) -> Vec<(i64, String)> {
    sqlx::query(
        store
            .dialect()
            .sql("SELECT sample_index, rod FROM samples WHERE run_id = ? ORDER BY sample_index"),
    )
    .bind(run)
    .fetch_all(store.pool())
    .await
    .unwrap_or_else(|e| panic!("{e}"))
    .iter()
    .map(|r| (r.get(0), r.get(1)))
    .collect()
}

/// Forget samples from `from` on and mark the run stopped: what a run stopped early
/// leaves for `--resume`.
async fn cut_run(store: &Store, run: i64, from: i64) {
    for sql in [
        "DELETE FROM samples WHERE run_id = ?1 AND sample_index >= ?2",
        "UPDATE runs SET status = 'stopped' WHERE run_id = ?1 AND ?2 = ?2",
    ] {
        sqlx::query(store.dialect().sql(sql))
            .bind(run)
            .bind(from)
            .execute(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
    }
}

#[test]
fn rod_names_with_spaces_quotes_and_unicode_survive_collection_status_and_resume() {
    let dir = tempdir();
    // A comma is refused: `--rods` takes names comma-separated.
    let with_comma =
        defaults::SCENE_TOML.replace("name = \"circle-10\"", "name = \"circle, 10 mm\"");
    std::fs::write(dir.path().join("comma.toml"), with_comma).unwrap_or_else(|e| panic!("{e}"));
    fails_with(
        &softtouch(
            dir.path(),
            &["collect", "--scene", "comma.toml", "--samples", "1"],
        ),
        2,
        "field `rods[0].name`: `circle, 10 mm` contains a comma: names are given comma-separated (--objects, --rods)",
    );
    let comma = "circle; 10 mm";
    let quoted = "sq \"q\" ü";
    let scene = defaults::SCENE_TOML
        .replace("name = \"circle-10\"", "name = \"circle; 10 mm\"")
        .replace("name = \"square-10\"", "name = \"sq \\\"q\\\" ü\"");
    assert_ne!(scene, defaults::SCENE_TOML);
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap_or_else(|e| panic!("{e}"));
    ok(&softtouch(
        dir.path(),
        &[
            "collect",
            "--scene",
            "scene.toml",
            "--samples",
            "10",
            "--seed",
            "4",
            "--block",
            "2",
        ],
    ));
    let schedule = [comma, quoted, "triangle-12", "hexagon-10", "oval-12"];
    let expected: Vec<(i64, String)> = (0..10)
        .map(|i: i64| (i, schedule[usize::try_from(i / 2).unwrap_or(0)].to_owned()))
        .collect();
    let db = dir.path().join("softtouch.db");
    let rt = runtime();
    rt.block_on(async {
        let store = common::open_store(&db).await;
        assert_eq!(sample_rods(&store, 1).await, expected);
        let record = store.run_record(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(record.rod_schedule, schedule);
        cut_run(&store, 1, 1).await;
        store.close().await;
    });
    // The resume takes samples 1..10 with the stored schedule, read back exactly.
    ok(&softtouch(dir.path(), &["collect", "--resume", "1"]));
    rt.block_on(async {
        let store = common::open_store(&db).await;
        assert_eq!(sample_rods(&store, 1).await, expected);
        store.close().await;
    });
    let status = ok(&softtouch(dir.path(), &["status", "1"]));
    assert!(
        status.contains(
            r#"rods ["circle; 10 mm","sq \"q\" ü","triangle-12","hexagon-10","oval-12"], 2 samples each"#
        ),
        "{status}"
    );
}

#[test]
fn a_comma_joined_rod_schedule_of_an_old_database_is_migrated_and_reads_back() {
    if common::skip_on_postgres(
        "a_comma_joined_rod_schedule_of_an_old_database_is_migrated_and_reads_back",
    ) {
        return;
    }
    let dir = tempdir();
    ok(&softtouch(
        dir.path(),
        &["collect", "--samples", "4", "--seed", "2", "--block", "2"],
    ));
    let db = dir.path().join("softtouch.db");
    let rt = runtime();
    rt.block_on(async {
        let store = common::open_store(&db).await;
        // Back to the old format: the schedule comma-joined, the migration not applied.
        for sql in [
            "UPDATE runs SET rod_schedule = 'circle-10,square-10,,oval-12' WHERE run_id = 1",
            "DELETE FROM _sqlx_migrations WHERE version = 20261124120000",
        ] {
            sqlx::query(store.dialect().sql(sql))
                .execute(store.pool())
                .await
                .unwrap_or_else(|e| panic!("{e}"));
        }
        cut_run(&store, 1, 2).await;
        store.close().await;
        // Opening migrates it.
        let store = common::open_store(&db).await;
        let record = store.run_record(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            record.rod_schedule,
            ["circle-10", "square-10", "", "oval-12"]
        );
        let stored: String = sqlx::query_scalar(
            store
                .dialect()
                .sql("SELECT rod_schedule FROM runs WHERE run_id = 1"),
        )
        .fetch_one(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(stored, r#"["circle-10","square-10","","oval-12"]"#);
        // Damaged text is refused with what was found, never split or guessed.
        sqlx::query(
            store
                .dialect()
                .sql("UPDATE runs SET rod_schedule = 'circle-10,square-10' WHERE run_id = 1"),
        )
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        let status = ok(&softtouch(dir.path(), &["status", "1"]));
        assert!(
            status.contains(
                "rods: damaged rod schedule in the database: run 1: expected a JSON array"
            ),
            "{status}"
        );
        let e = store.run_record(1).await.expect_err("not JSON");
        assert!(
            e.to_string()
                .contains("run 1: expected a JSON array of rod names, found `circle-10,square-10`"),
            "{e}"
        );
        sqlx::query(
            store.dialect().sql(
                r#"UPDATE runs SET rod_schedule = '["circle-10","square-10"]' WHERE run_id = 1"#,
            ),
        )
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    // The migrated run resumes on its schedule: samples 2 and 3 on square-10.
    ok(&softtouch(dir.path(), &["collect", "--resume", "1"]));
    rt.block_on(async {
        let store = common::open_store(&db).await;
        let rods = sample_rods(&store, 1).await;
        assert_eq!(
            rods.iter().map(|(_, r)| r.as_str()).collect::<Vec<_>>(),
            ["circle-10", "circle-10", "square-10", "square-10"]
        );
        store.close().await;
    });
}

#[test]
fn a_resume_with_a_mistyped_db_exits_2_and_creates_nothing() {
    if common::skip_on_postgres("a_resume_with_a_mistyped_db_exits_2_and_creates_nothing") {
        return;
    }
    let dir = tempdir();
    let out = softtouch(dir.path(), &["--db", "typo.db", "collect", "--resume", "1"]);
    fails_with(&out, 2, "--resume: no database at typo.db");
    assert!(!dir.path().join("typo.db").exists());
    // A new run still creates its database.
    ok(&softtouch(
        dir.path(),
        &["--db", "new.db", "collect", "--samples", "1"],
    ));
    assert!(dir.path().join("new.db").exists());
}

#[test]
fn a_resume_refuses_a_rig_that_changes_more_than_where_devices_are() {
    let dir = tempdir();
    ok(&softtouch(
        dir.path(),
        &["collect", "--samples", "2", "--seed", "1"],
    ));
    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        cut_run(&store, 1, 1).await;
        store.close().await;
    });
    let write = |name: &str, rig: String| {
        std::fs::write(dir.path().join(name), rig).unwrap_or_else(|e| panic!("{e}"));
    };
    write(
        "settle.toml",
        defaults::RIG_TOML.replace("settle_s = 0.3", "settle_s = 0.5"),
    );
    let out = softtouch(
        dir.path(),
        &["collect", "--resume", "1", "--rig", "settle.toml"],
    );
    fails_with(&out, 2, "settle.toml");
    fails_with(
        &out,
        2,
        "field `procedure.settle_s`: differs from run 1's stored rig (stored 0.3, here 0.5)",
    );
    write(
        "driver.toml",
        defaults::RIG_TOML.replace(
            "[force_sensor]\ndriver = \"sim\"",
            "[force_sensor]\ndriver = \"net-ft\"\naddress = \"127.0.0.1\"\n#",
        ),
    );
    let out = softtouch(
        dir.path(),
        &["collect", "--resume", "1", "--rig", "driver.toml"],
    );
    fails_with(
        &out,
        2,
        "field `force_sensor.driver`: differs from run 1's stored rig",
    );
    let out = softtouch(
        dir.path(),
        &["collect", "--resume", "1", "--rig", "missing.toml"],
    );
    fails_with(&out, 2, "missing.toml: cannot read");
    // The same rig again is no change: the run completes.
    write("same.toml", defaults::RIG_TOML.to_owned());
    let done = ok(&softtouch(
        dir.path(),
        &["collect", "--resume", "1", "--rig", "same.toml"],
    ));
    assert!(done.contains("complete"), "{done}");
}

#[test]
fn a_resume_on_a_rig_with_a_moved_device_uses_and_records_the_new_port() {
    let dir = tempdir();
    let port = |name: &str| dir.path().join(name).display().to_string();
    let rig = |gripper_port: &str| {
        defaults::RIG_TOML.replace(
            "[gripper]\ndriver = \"sim\"",
            &format!("[gripper]\ndriver = \"hand-e\"\nport = \"{gripper_port}\"\nslave_id = 9\n#"),
        )
    };
    let old_port = port("ttyOLD");
    let new_port = port("ttyNEW");
    assert_ne!(rig(&old_port), defaults::RIG_TOML);
    std::fs::write(dir.path().join("old.toml"), rig(&old_port)).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.path().join("new.toml"), rig(&new_port)).unwrap_or_else(|e| panic!("{e}"));
    // The gripper's port does not exist: the run fails before collecting, exit 1.
    let out = softtouch(
        dir.path(),
        &["collect", "--rig", "old.toml", "--samples", "2"],
    );
    fails_with(&out, 1, &old_port);
    // The resume reaches the gripper on the new port (which fails the same way here:
    // no Hand-E in a test), and the run records the new rig.
    let out = softtouch(
        dir.path(),
        &["collect", "--resume", "1", "--rig", "new.toml"],
    );
    fails_with(&out, 1, &new_port);
    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        let record = store.run_record(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert!(record.rig_toml.contains(&new_port), "{}", record.rig_toml);
        let events = store.events(1, 100).await.unwrap_or_else(|e| panic!("{e}"));
        assert!(
            events.iter().any(|e| e.kind == "resumed"
                && e.message
                    .contains(&format!("gripper.port: \"{old_port}\" -> \"{new_port}\""))),
            "{events:?}"
        );
        store.close().await;
    });
    // Without --rig the resume now uses the recorded (new) port.
    let out = softtouch(dir.path(), &["collect", "--resume", "1"]);
    fails_with(&out, 1, &new_port);
}

#[test]
fn a_resume_checks_the_stored_scene_against_the_rig_again() {
    let dir = tempdir();
    ok(&softtouch(
        dir.path(),
        &["collect", "--samples", "2", "--seed", "1"],
    ));
    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        cut_run(&store, 1, 1).await;
        // A scene whose poses the rig cannot reach (stored by an older build, say).
        let scene = defaults::SCENE_TOML.replace("x_m = [0.0, 0.05]", "x_m = [0.0, 0.09]");
        sqlx::query(
            store
                .dialect()
                .sql("UPDATE runs SET scene_toml = ? WHERE run_id = 1"),
        )
        .bind(scene)
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    let out = softtouch(dir.path(), &["collect", "--resume", "1"]);
    fails_with(&out, 2, "run 1 scene, on rig <run 1 rig>");
    fails_with(
        &out,
        2,
        "field `poses.x_m`: range [0, 0.09] lies outside the rig's workspace",
    );
}

#[test]
fn a_water_run_with_poses_from_a_land_run_repeats_its_poses_and_rods_pose_by_pose() {
    let dir = tempdir();
    let water = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/water.toml");
    let water = water.to_str().unwrap_or_default();
    ok(&softtouch(
        dir.path(),
        &["collect", "--samples", "12", "--seed", "5", "--block", "4"],
    ));
    let out = ok(&softtouch(
        dir.path(),
        &["collect", "--scene", water, "--poses-from", "1"],
    ));
    assert!(
        out.contains("run 2 pairs with run 1: 12 samples in both, every rod and pose the same"),
        "{out}"
    );
    // Its disk is said before it starts, from a frame of the water scene (no frame of
    // it stored yet): nearly three times a dry sample.
    let disk = out
        .lines()
        .find(|l| l.starts_with("disk: about "))
        .unwrap_or_else(|| panic!("no disk line in: {out}"));
    assert!(
        disk.contains("for 12 samples (")
            && disk.contains("its frame one of scene `underwater` rendered and encoded"),
        "{disk}"
    );
    let status = ok(&softtouch(dir.path(), &["status", "2"]));
    assert!(status.contains("poses and rods of run 1"), "{status}");
    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        let (land, wet) = (store.run_record(1).await, store.run_record(2).await);
        let (land, wet) = (
            land.unwrap_or_else(|e| panic!("{e}")),
            wet.unwrap_or_else(|e| panic!("{e}")),
        );
        assert_eq!(wet.poses_from, Some(1));
        assert_eq!(land.poses_from, None);
        assert_eq!(
            (
                wet.seed,
                wet.samples_planned,
                &wet.rod_schedule,
                wet.rod_block
            ),
            (
                land.seed,
                land.samples_planned,
                &land.rod_schedule,
                land.rod_block
            )
        );
        assert!(wet.scene_toml.contains("underwater"));
        // Pose by pose, rod by rod, and the media differ.
        let (a, b) = (poses(&store, 1).await, poses(&store, 2).await);
        assert_eq!(a.len(), 12);
        assert_eq!(a, b);
        assert_eq!(sample_rods(&store, 1).await, sample_rods(&store, 2).await);
        assert_eq!(store.check_paired_poses(2, 1).await.ok(), Some(12));
        // A pose changed behind the pairing's back is found, naming the sample.
        sqlx::query(store.dialect().sql(
            "UPDATE samples SET cmd_x_m = cmd_x_m + 1e-12 WHERE run_id = 2 AND sample_index = 7",
        ))
        .execute(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        let e = store
            .check_paired_poses(2, 1)
            .await
            .expect_err("pose 7 differs")
            .to_string();
        assert!(
            e.contains("run 2 does not pair with run 1: sample 7"),
            "{e}"
        );
        // A run with no common sample does not pair either.
        let e = store
            .check_paired_poses(2, 99)
            .await
            .expect_err("nothing in common");
        assert!(
            e.to_string().contains("no sample index is stored in both"),
            "{e}"
        );
    });

    // Scenes that cannot repeat run 1's poses are refused before a run is created.
    let narrow = dir.path().join("narrow.toml");
    let land = defaults::SCENE_TOML;
    assert!(land.contains("x_m = [0.0, 0.05]") && land.contains("size_m = 0.01\n"));
    std::fs::write(
        &narrow,
        land.replace("x_m = [0.0, 0.05]", "x_m = [0.0, 0.04]"),
    )
    .expect("write scene");
    fails_with(
        &softtouch(
            dir.path(),
            &[
                "collect",
                "--scene",
                narrow.to_str().unwrap_or_default(),
                "--poses-from",
                "1",
            ],
        ),
        2,
        "--poses-from 1: scene",
    );
    let fat = dir.path().join("fat.toml");
    std::fs::write(&fat, land.replace("size_m = 0.01\n", "size_m = 0.011\n")).expect("write scene");
    fails_with(
        &softtouch(
            dir.path(),
            &[
                "collect",
                "--scene",
                fat.to_str().unwrap_or_default(),
                "--poses-from",
                "1",
            ],
        ),
        2,
        "expected the same rod",
    );
    fails_with(
        &softtouch(dir.path(), &["collect", "--poses-from", "99"]),
        2,
        "no run 99",
    );
    fails_with(
        &softtouch(dir.path(), &["collect", "--poses-from", "1", "--seed", "3"]),
        2,
        "--seed",
    );
    runtime().block_on(async {
        let store = common::open_store(&dir.path().join("softtouch.db")).await;
        let runs: i64 = sqlx::query_scalar(store.dialect().sql("SELECT COUNT(*) FROM runs"))
            .fetch_one(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(runs, 2, "refused pairings create no run");
    });
}
