//! End-to-end tests of `softtouch collect` on the simulated rig: a run's database,
//! kill -9 and resume, and fault injection.

mod common;
use common::{runtime, softtouch, tempdir, text};

use softtouch_collector::collect::sampler::PoseSampler;
use softtouch_collector::store::{Store, decode_window};
use softtouch_schemas::defaults;
use sqlx::Row as _;
use std::path::Path;
use std::process::{Command, Stdio};

async fn open(db: &Path) -> Store {
    Store::open(db).await.unwrap_or_else(|e| panic!("{e}"))
}

/// Every sample's commanded pose, by index.
async fn poses(store: &Store, run: i64) -> Vec<(i64, f64, f64, f64)> {
    sqlx::query("SELECT sample_index, cmd_x_m, cmd_z_m, cmd_theta_rad FROM samples WHERE run_id = ? ORDER BY sample_index")
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
        let store = open(&dir.path().join("softtouch.db")).await;
        let counts = store.row_counts(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((counts.samples, counts.frames, counts.windows), (240, 240, 240));

        let rows = sqlx::query(
            "SELECT s.sample_index, s.frame_t_ns, s.window_start_ns, s.window_end_ns, s.reading_count,
                    w.reading_count, w.data, f.format, f.width, f.height, s.status, s.rod,
                    s.cmd_x_m, s.cmd_z_m, s.cmd_theta_rad, s.fx_n
             FROM samples s JOIN frames f USING (run_id, sample_index) JOIN ft_windows w USING (run_id, sample_index)
             WHERE s.run_id = 1 ORDER BY s.sample_index",
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

/// Samples of run 1 so far, read without migrating (the child owns the database).
async fn stored_samples(db: &Path) -> i64 {
    let options = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(db)
        .read_only(true);
    let Ok(mut conn) = sqlx::ConnectOptions::connect(&options).await else {
        return 0;
    };
    sqlx::query_scalar("SELECT COUNT(*) FROM samples WHERE run_id = 1")
        .fetch_one(&mut conn)
        .await
        .unwrap_or(0)
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
        let mut child = Command::new(env!("CARGO_BIN_EXE_softtouch"))
            .args(&args)
            .current_dir(dir.path())
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
        let store = open(&db).await;
        assert_eq!(store.integrity_check().await.unwrap_or_default(), "ok");
        let c = store.row_counts(1).await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.samples, planned);
        assert_eq!(c.windows, planned);
        let resumed = poses(&store, 1).await;
        let indices: Vec<i64> = resumed.iter().map(|p| p.0).collect();
        assert_eq!(indices, (0..planned).collect::<Vec<_>>(), "no gap, no duplicate");
        assert_eq!(resumed, poses(&store, 2).await, "the resumed run took the same poses");
        let orphans: i64 = sqlx::query_scalar(
            "SELECT (SELECT COUNT(*) FROM frames f WHERE NOT EXISTS (SELECT 1 FROM samples s WHERE s.run_id = f.run_id AND s.sample_index = f.sample_index))
                  + (SELECT COUNT(*) FROM ft_windows w WHERE NOT EXISTS (SELECT 1 FROM samples s WHERE s.run_id = w.run_id AND s.sample_index = w.sample_index))",
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
        let store = open(&dir.path().join("softtouch.db")).await;
        let count = |kind: &'static str| {
            let pool = store.pool().clone();
            async move {
                sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM events WHERE kind = ?")
                    .bind(kind)
                    .fetch_one(&pool)
                    .await
                    .unwrap_or(0)
            }
        };
        assert!(count("arm_fault").await > 0, "reflexes were injected and logged");
        assert_eq!(count("arm_fault").await, count("arm_recovered").await, "each reflex recovered");
        assert!(count("missing_readings").await > 0, "lost packets showed as gaps");
        let drops: String = sqlx::query_scalar("SELECT message FROM events WHERE kind = 'stream_counts'")
            .fetch_one(store.pool())
            .await
            .unwrap_or_default();
        assert!(!drops.contains(" 0 frames dropped") && !drops.contains(" 0 lost on the link"), "{drops}");

        // Every extra attempt of a sample has a warning event naming that sample.
        let rows = sqlx::query(
            "SELECT s.sample_index, s.attempts,
                    (SELECT COUNT(*) FROM events e WHERE e.run_id = s.run_id AND e.sample_index = s.sample_index AND e.level = 'warn')
             FROM samples s WHERE s.run_id = 1",
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
        // The table row: settle window accepted force_rmse_N torque_rmse_Nmm ...
        let row = out
            .lines()
            .find(|l| l.trim_start().starts_with("0.3 "))
            .unwrap_or_else(|| panic!("no table row in:\n{out}"));
        let cols: Vec<&str> = row.split_whitespace().collect();
        let num = |i: usize| {
            cols.get(i)
                .and_then(|c| c.parse::<f64>().ok())
                .unwrap_or_else(|| panic!("column {i} of `{row}`"))
        };
        (num(3), num(4))
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
