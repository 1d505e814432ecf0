//! End-to-end tests of `softtouch grasp trials`: a tiny model trained in-test grasps
//! simulated objects on land and underwater; the same seed gives the same
//! perturbations and outcomes, a trial run alone equals itself in a bigger session, a
//! kill -9 during the trials then a resume loses and doubles nothing, an open-loop
//! width that misses is recorded as misses, and bad input exits 2 naming what is known.

use crate::common;
use common::{fails_with, ok, runtime, softtouch, tempdir, tiny_model};
use std::path::Path;
use std::process::{Command, Stdio};

/// Short trials: 30 Hz camera, quick confirmation, a short lift and hold.
const FAST: [&str; 13] = [
    // The tiny land model reads the water scene's closings too poorly for the check
    // (`check_calibration`): these tests are about the sessions' mechanics, so they
    // take its calibrations against the check, as a lab may before a water tare.
    "--accept-calibration",
    "--fps",
    "30",
    "--confirm-s",
    "0.1",
    "--close-timeout-s",
    "1.5",
    "--lift-mm",
    "20",
    "--hold-s",
    "0.3",
    "--out-dir",
    "g",
];

fn trials(dir: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["grasp", "trials"];
    args.extend_from_slice(extra);
    if extra.contains(&"--resume") {
        // A resumed session runs on its stored settings; only the output may move.
        args.extend_from_slice(&["--out-dir", "g"]);
    } else {
        args.extend_from_slice(&FAST);
    }
    softtouch(dir, &args)
}

/// (medium, object, mode, trial, dx, dy, dz, success, reason, final width) of a session.
type TrialRow = (
    String,
    String,
    String,
    i64,
    f64,
    f64,
    f64,
    i64,
    Option<String>,
    f64,
);

async fn session_rows(db: &Path, session: i64) -> Vec<TrialRow> {
    let options = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(db)
        .read_only(true);
    let mut conn = sqlx::ConnectOptions::connect(&options)
        .await
        .unwrap_or_else(|e| panic!("open {}: {e}", db.display()));
    sqlx::query_as(
        "SELECT medium, object, mode, trial, dx_m, dy_m, dz_m, success, reason, final_width_m \
         FROM grasp_trials WHERE session_id = ? ORDER BY sigma_index, scene_index, object, mode, trial",
    )
    .bind(session)
    .fetch_all(&mut conn)
    .await
    .unwrap_or_else(|e| panic!("session {session}'s trials: {e}"))
}

async fn execute(db: &Path, sql: &'static str) {
    let options = sqlx::sqlite::SqliteConnectOptions::new().filename(db);
    let mut conn = sqlx::ConnectOptions::connect(&options)
        .await
        .unwrap_or_else(|e| panic!("open {}: {e}", db.display()));
    sqlx::query(sql)
        .execute(&mut conn)
        .await
        .unwrap_or_else(|e| panic!("{sql}: {e}"));
}

/// `grasp trials` of 3 cylinder trials per cell at `seed` (the fast settings), as a
/// child process whose output goes to `output()` (null, or piped to be read).
fn spawn_cylinder_trials(dir: &Path, seed: &str, output: fn() -> Stdio) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_softtouch"))
        .args([
            "grasp",
            "trials",
            "--model",
            "air-svae",
            "--objects",
            "cylinder",
            "--trials",
            "3",
            "--seed",
            seed,
        ])
        .args(FAST)
        .current_dir(dir)
        .stdout(output())
        .stderr(output())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Waits until `stored` counts at least `n` trials, failing if the child ends first
/// (then there would be nothing left to interrupt).
fn wait_until_stored(
    rt: &tokio::runtime::Runtime,
    child: &mut std::process::Child,
    db: &Path,
    stored: &'static str,
    n: i64,
) {
    loop {
        let exited = child.try_wait().ok().flatten();
        assert!(
            exited.is_none(),
            "the session ended on its own ({exited:?}) before {n} trials were stored: nothing to interrupt"
        );
        if rt.block_on(count(db, stored)) >= n {
            return;
        }
        std::thread::yield_now();
    }
}

async fn count(db: &Path, sql: &'static str) -> i64 {
    let options = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(db)
        .read_only(true);
    let Ok(mut conn) = sqlx::ConnectOptions::connect(&options).await else {
        return 0;
    };
    sqlx::query_scalar(sql)
        .fetch_one(&mut conn)
        .await
        .unwrap_or(0)
}

#[test]
fn grasp_trials_are_stored_reproducible_resumable_and_checked() {
    let dir = tempdir();
    let d = dir.path();
    let db = d.join("softtouch.db");
    tiny_model(d);
    let rt = runtime();

    // Session 1: both built-in media, two objects, both modes, two trials each.
    let base = [
        "--model",
        "air-svae",
        "--objects",
        "cylinder,cake",
        "--trials",
        "2",
        "--seed",
        "3",
    ];
    let out = ok(&trials(d, &base));
    assert!(out.contains("grasp session 1"), "{out}");
    assert!(out.contains("Wilson 95%"), "{out}");
    // Once the binary has exited, the `.db` file alone holds the session: a backup
    // that copies it alone misses nothing (the log was left holding it before).
    let wal = softtouch_collector::store::sqlite_file::db_size(&db).wal_bytes;
    assert_eq!(wal, 0, "the write-ahead log still holds {wal} bytes");
    let backup = d.join("backup.db");
    std::fs::copy(&db, &backup).unwrap_or_else(|e| panic!("copy: {e}"));
    assert_eq!(rt.block_on(session_rows(&backup, 1)).len(), 16);
    // The wall time of the 16 trials, one row per medium and mode with 4 trials each.
    let timing = out
        .split("wall time of the trials run now")
        .nth(1)
        .unwrap_or_else(|| panic!("no timing table in: {out}"));
    let timing_rows: Vec<Vec<&str>> = timing
        .lines()
        .skip(2)
        .take(4)
        .map(|l| l.split_whitespace().collect())
        .collect();
    for (row, (medium, mode)) in timing_rows.iter().zip([
        ("land", "open"),
        ("land", "closed"),
        ("water", "open"),
        ("water", "closed"),
    ]) {
        assert_eq!(row.len(), 8, "{row:?} in: {out}");
        assert_eq!((row[0], row[1], row[2]), (medium, mode, "4"), "{out}");
        let cycles: usize = row[3].parse().expect("cycles");
        let ms: f64 = row[4].parse().expect("ms per cycle");
        assert!(cycles > 4 && ms > 0.0 && ms.is_finite(), "{row:?}");
        assert!(row[7].ends_with("/4"), "{row:?}");
    }
    for needle in [
        "land", "water", "cylinder", "cake", "44%", "100%", "30%", "90%",
    ] {
        assert!(out.contains(needle), "no `{needle}` in: {out}");
    }
    let csv = std::fs::read_to_string(d.join("g/grasp-trials.csv")).expect("csv");
    assert!(csv.starts_with(
        "sigma_index,medium,object,mode,trials,held,rate,wilson_lo,wilson_hi,paper_rate"
    ));
    // 2 media × (2 objects + all) × 2 modes.
    assert_eq!(csv.lines().count(), 1 + 12, "{csv}");
    let rows_csv = std::fs::read_to_string(d.join("g/grasp-trials-rows.csv")).expect("rows csv");
    assert_eq!(rows_csv.lines().count(), 1 + 16);
    let png = std::fs::read(d.join("g/grasp-trials.png")).expect("png");
    assert!(png.starts_with(b"\x89PNG"));
    let first = rt.block_on(session_rows(&db, 1));
    assert_eq!(first.len(), 16);
    assert!(
        first.iter().all(|r| (r.7 == 1) == r.8.is_none()),
        "{first:?}"
    );
    let traces = rt.block_on(count(
        &db,
        "SELECT COUNT(*) FROM grasp_traces c JOIN grasp_trials t USING (trial_id) WHERE t.session_id = 1 AND c.cycles > 0",
    ));
    assert_eq!(traces, 16, "every trial has its trace");
    // Every trial that ran has its end frame, and those with a lift its lift frame.
    let ends = rt.block_on(count(
        &db,
        "SELECT COUNT(*) FROM grasp_trial_frames f JOIN grasp_trials t USING (trial_id) WHERE t.session_id = 1 AND f.moment = 'end'",
    ));
    assert_eq!(ends, 16);
    // Open against closed on the same perturbations, per medium.
    let paired = out
        .split("open against closed on the same perturbations")
        .nth(1)
        .unwrap_or_else(|| panic!("no paired table in: {out}"));
    let paired_rows: Vec<Vec<&str>> = paired
        .lines()
        .skip(2)
        .take(2)
        .map(|l| l.split_whitespace().collect())
        .collect();
    for (row, medium) in paired_rows.iter().zip(["land", "water"]) {
        assert_eq!(row.len(), 8, "{row:?}");
        assert_eq!((row[1], row[2]), (medium, "4"), "{out}");
        let cells: u64 = row[3..7]
            .iter()
            .map(|v| v.parse::<u64>().expect("count"))
            .sum();
        assert_eq!(cells, 4, "{row:?}");
        let p: f64 = row[7].parse().expect("p");
        assert!((0.0..=1.0).contains(&p), "{row:?}");
    }
    // A trial's trace by its id, as CSV.
    let trace = ok(&softtouch(d, &["results", "trace", "1"]));
    assert!(
        trace.starts_with("t_s,estimate_n,true_n,measured_count,request_count\n"),
        "{trace}"
    );
    assert!(trace.lines().count() > 5, "{trace}");
    // A row's peak true force is either finger's, as the verdict's: never below the
    // loop's finger in its trace, and above it where the other finger pressed harder.
    let peaks: Vec<(i64, Option<f64>)> = rt.block_on(async {
        let options = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(&db)
            .read_only(true);
        let mut conn = sqlx::ConnectOptions::connect(&options)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        sqlx::query_as("SELECT trial_id, peak_true_n FROM grasp_trials WHERE session_id = 1")
            .fetch_all(&mut conn)
            .await
            .unwrap_or_else(|e| panic!("{e}"))
    });
    let mut other_finger_higher = 0;
    for (id, peak) in &peaks {
        let trace = ok(&softtouch(d, &["results", "trace", &id.to_string()]));
        let watched = trace
            .lines()
            .skip(1)
            .filter_map(|l| l.split(',').nth(2)?.parse::<f64>().ok())
            .filter(|f| f.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        let Some(peak) = peak else { continue };
        assert!(
            *peak >= watched - 1e-4,
            "trial {id}: {peak} below its trace's {watched}"
        );
        if *peak > watched + 1e-3 {
            other_finger_higher += 1;
        }
    }
    assert!(other_finger_higher > 0, "{peaks:?}");
    fails_with(
        &softtouch(d, &["results", "trace", "999"]),
        2,
        "no grasp trial 999",
    );

    // Session 2, the same seed: the same perturbations and outcomes.
    let out = ok(&trials(d, &base));
    assert!(out.contains("grasp session 2"), "{out}");
    assert_eq!(rt.block_on(session_rows(&db, 2)), first);

    // Session 3: the cake's closed-loop trials alone equal themselves in session 1.
    ok(&trials(
        d,
        &[
            "--model",
            "air-svae",
            "--objects",
            "cake",
            "--modes",
            "closed",
            "--trials",
            "2",
            "--seed",
            "3",
        ],
    ));
    let alone = rt.block_on(session_rows(&db, 3));
    let within: Vec<TrialRow> = first
        .iter()
        .filter(|r| r.1 == "cake" && r.2 == "closed")
        .cloned()
        .collect();
    assert_eq!(alone, within);

    // Session 4: an open-loop width wider than any object misses every one.
    let out = ok(&trials(
        d,
        &[
            "--model",
            "air-svae",
            "--objects",
            "cylinder,cake",
            "--modes",
            "open",
            "--trials",
            "2",
            "--open-width-mm",
            "49",
            "--seed",
            "3",
        ],
    ));
    let missed = rt.block_on(session_rows(&db, 4));
    assert_eq!(missed.len(), 8, "{out}");
    assert!(
        missed
            .iter()
            .all(|r| r.7 == 0 && r.8.as_deref() == Some("miss")),
        "{missed:?}"
    );

    // Session 5, killed with SIGKILL once a few trials are stored, then resumed.
    let planned = 12i64;
    let mut child = spawn_cylinder_trials(d, "9", Stdio::null);
    let stored = "SELECT COUNT(*) FROM grasp_trials WHERE session_id = 5";
    wait_until_stored(&rt, &mut child, &db, stored, 3);
    child.kill().expect("SIGKILL"); // the child was still running just above
    let status = child.wait().expect("reaped");
    assert!(!status.success(), "killed, not finished: {status:?}");
    let before = rt.block_on(count(&db, stored));
    assert!(
        (3..planned).contains(&before),
        "the kill landed after 3 stored trials and before the end ({before})"
    );
    let out = ok(&trials(d, &["--resume", "5"]));
    assert!(out.contains(&format!("{before} stored")), "{out}");
    assert_eq!(rt.block_on(count(&db, stored)), planned);
    let orphans = rt.block_on(count(
        &db,
        "SELECT (SELECT COUNT(*) FROM grasp_trials t WHERE NOT EXISTS (SELECT 1 FROM grasp_traces c WHERE c.trial_id = t.trial_id)) \
              + (SELECT COUNT(*) FROM grasp_traces c WHERE NOT EXISTS (SELECT 1 FROM grasp_trials t WHERE t.trial_id = c.trial_id))",
    ));
    assert_eq!(
        orphans, 0,
        "no trial without its trace, no trace without its trial"
    );
    // An uninterrupted session with the same seed took the same trials.
    ok(&trials(
        d,
        &[
            "--model",
            "air-svae",
            "--objects",
            "cylinder",
            "--trials",
            "3",
            "--seed",
            "9",
        ],
    ));
    assert_eq!(
        rt.block_on(session_rows(&db, 5)),
        rt.block_on(session_rows(&db, 6))
    );

    // Session 7, sent SIGTERM once 2 trials are stored: it finishes the trial in hand,
    // stores it, prints the table of what ran and exits 0.
    let mut child = spawn_cylinder_trials(d, "11", Stdio::piped);
    let stored7 = "SELECT COUNT(*) FROM grasp_trials WHERE session_id = 7";
    wait_until_stored(&rt, &mut child, &db, stored7, 2);
    let pid = child.id().to_string();
    let sent = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill")
        .success();
    assert!(sent, "kill -TERM failed");
    let done = child.wait_with_output().expect("reaped");
    let stdout = String::from_utf8_lossy(&done.stdout);
    assert!(
        done.status.success(),
        "exit {:?}: {}",
        done.status.code(),
        String::from_utf8_lossy(&done.stderr)
    );
    let after = rt.block_on(count(&db, stored7));
    assert!(
        stdout.contains(&format!("stopped after {after} of {planned} trials")),
        "{stdout}"
    );
    assert!((2..planned).contains(&after), "{after}");
    assert!(
        stdout.contains("σ = 5 mm, land"),
        "the table of what ran: {stdout}"
    );
    // What a person reads: the stop names a trial, not a sample.
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(
        stderr.contains("SIGTERM: stopping after this trial"),
        "{stderr}"
    );
    // `results` lists a session's trial ids as a range a person reads.
    let listed = ok(&softtouch(d, &["results", "list"]));
    assert!(!listed.contains("..="), "{listed}");
    assert!(
        listed.lines().any(|l| l.contains("–")
            && l.split_whitespace()
                .any(|w| w.contains('–') && w.split('–').all(|n| n.parse::<u64>().is_ok()))),
        "{listed}"
    );

    // Bad input: exit 2, saying what is known.
    fails_with(
        &trials(d, &["--model", "air-svae", "--objects", "vase"]),
        2,
        "no object `vase` (it has: cylinder, oval-tube, ball, bottle, cake)",
    );
    let wide = d.join("wide.toml");
    let land =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/grasp.toml"))
            .expect("scenes/grasp.toml");
    std::fs::write(
        &wide,
        format!(
            "{land}\n[[objects]]\nname = \"platter\"\nshape = \"oval\"\naspect = 1.5\nwidth_m = 0.04\nmass_kg = 0.1\nfriction = 0.5\nprofile = {{ kind = \"prism\", height_m = 0.02 }}\n"
        ),
    )
    .expect("write scene");
    fails_with(
        &trials(
            d,
            &[
                "--model",
                "air-svae",
                "--objects",
                "platter",
                "--scene",
                wide.to_str().unwrap_or_default(),
            ],
        ),
        2,
        "outside the Hand-E's 50 mm stroke",
    );
    fails_with(&trials(d, &["--resume", "99"]), 2, "no grasp session 99");
    // The session recorded the model's sha256; a model changed under its name since
    // is refused on resume.
    assert_eq!(
        rt.block_on(count(
            &db,
            "SELECT COUNT(*) FROM grasp_sessions WHERE length(model_sha256) = 64 AND model_sha256 NOT GLOB '*[^0-9a-f]*'"
        )),
        rt.block_on(count(&db, "SELECT COUNT(*) FROM grasp_sessions")),
        "every session records a sha256"
    );
    rt.block_on(execute(
        &db,
        "UPDATE grasp_sessions SET model_sha256 = 'feedfacefeedface' WHERE session_id = 5",
    ));
    fails_with(
        &trials(d, &["--resume", "5"]),
        2,
        "model `air-svae` has changed since the session started (sha256 feedfacefeed then,",
    );
    // A resumed session's settings are the stored ones: a flag beside it is refused.
    fails_with(
        &trials(d, &["--resume", "5", "--trials", "4"]),
        2,
        "cannot be used with",
    );
    fails_with(
        &trials(d, &["--model", "air-svae", "--modes", "half"]),
        2,
        "--modes: unknown mode `half`",
    );
    fails_with(&trials(d, &["--model", "nope"]), 2, "nope");
    fails_with(
        &trials(d, &["--model", "air-svae", "--sigma-mm=-1"]),
        2,
        "--sigma-mm",
    );
    // A target the loop could never hold is refused before a session is stored.
    let sessions = || {
        runtime().block_on(count(
            &d.join("softtouch.db"),
            "SELECT COUNT(*) FROM grasp_sessions",
        ))
    };
    let before = sessions();
    fails_with(
        &trials(d, &["--model", "air-svae", "--target-n", "20"]),
        2,
        "--target-n 20: expected a force in (0, 9.9) N",
    );
    assert_eq!(
        sessions(),
        before,
        "a session was stored for a refused target"
    );
    // On a rig: the rig file must say where to grasp, and each object needs its
    // calibration on that rig with that model, before any session is stored.
    let plain = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../schemas/defaults/rig.toml"
    ))
    .expect("the default rig");
    std::fs::write(d.join("plain.toml"), &plain).expect("writes");
    let grasp = |x: f64| {
        format!(
            "{plain}\n[grasp]\nmedium = \"air\"\nsafe_pose = {{ translation_m = [0.5, 0.0, 0.4], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }}\napproach_height_m = 0.05\nspeed_m_s = 0.2\n\n[[grasp.objects]]\nname = \"bottle\"\nbase_from_grasp = {{ translation_m = [{x}, 0.0, 0.2], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }}\nopen_width_mm = 30.0\nlift_mm = 50.0\n"
        )
    };
    std::fs::write(d.join("lab.toml"), grasp(0.5)).expect("writes");
    std::fs::write(d.join("far.toml"), grasp(0.95)).expect("writes");
    let on_rig = |extra: &[&str]| {
        let mut args = vec!["grasp", "trials"];
        args.extend_from_slice(extra);
        softtouch(d, &args)
    };
    fails_with(
        &on_rig(&["--model", "air-svae", "--rig", "plain.toml"]),
        2,
        "the rig file has no [grasp] section",
    );
    fails_with(
        &on_rig(&["--model", "air-svae", "--rig", "far.toml"]),
        2,
        "grasp.objects[0].base_from_grasp",
    );
    fails_with(
        &on_rig(&[
            "--model",
            "air-svae",
            "--rig",
            "lab.toml",
            "--objects",
            "vase",
        ]),
        2,
        "has no object `vase` (it has: bottle)",
    );
    fails_with(
        &on_rig(&["--model", "air-svae", "--rig", "lab.toml"]),
        2,
        "run `softtouch grasp calibrate --rig FILE --model air-svae --object bottle` first",
    );
    fails_with(
        &on_rig(&["--rig", "lab.toml", "--resume", "1"]),
        2,
        "session 1 ran on the simulator: resume it without --rig",
    );
    assert_eq!(
        rt.block_on(count(&db, "SELECT COUNT(*) FROM grasp_sessions")),
        7,
        "refused runs create no session"
    );
}

#[test]
fn several_models_run_the_same_trials_and_their_spread_is_printed() {
    let dir = tempdir();
    let d = dir.path();
    tiny_model(d);
    // The same training under another name (training is deterministic): the
    // mechanics of the comparison, not a second seed's luck with a tiny model.
    let mut args = vec!["train", "--dataset", "air", "--name", "air-b"];
    args.extend(common::TINY);
    if let Some(i) = args.iter().position(|a| *a == "--epochs") {
        args[i + 1] = "30";
    }
    ok(&softtouch(d, &args));
    let out = ok(&trials(
        d,
        &[
            "--models",
            "air-svae,air-b",
            "--objects",
            "cylinder",
            "--trials",
            "1",
        ],
    ));
    assert!(out.contains("===== model air-svae ====="), "{out}");
    assert!(out.contains("===== model air-b ====="), "{out}");
    for file in ["g/air-svae/grasp-trials.csv", "g/air-b/grasp-trials.csv"] {
        assert!(d.join(file).exists(), "{file}");
    }
    let spread = out
        .split("across models")
        .nth(1)
        .unwrap_or_else(|| panic!("no spread in: {out}"));
    for key in [
        "σ 5 mm land open",
        "σ 5 mm land closed",
        "σ 5 mm water open",
        "σ 5 mm water closed",
    ] {
        let line = spread
            .lines()
            .find(|l| l.starts_with(key))
            .unwrap_or_else(|| panic!("no `{key}` in: {spread}"));
        assert!(
            line.contains("air-svae ")
                && line.contains("air-b ")
                && line.replace(' ', "").contains("sd0%"),
            "{line}"
        );
    }
    // The same perturbations for both models: the sessions' offsets agree.
    let rt = runtime();
    let a = rt.block_on(session_rows(&d.join("softtouch.db"), 1));
    let b = rt.block_on(session_rows(&d.join("softtouch.db"), 2));
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(
            (&x.1, &x.2, x.3, x.4, x.5, x.6),
            (&y.1, &y.2, y.3, y.4, y.5, y.6)
        );
    }
    fails_with(
        &trials(d, &["--models", "air-svae,nope", "--trials", "1"]),
        2,
        "no model named `nope`",
    );
}

#[test]
fn a_scene_value_is_set_or_swept_over_the_same_trials() {
    let dir = tempdir();
    let d = dir.path();
    let db = d.join("softtouch.db");
    tiny_model(d);
    let rt = runtime();
    let base = [
        "--model",
        "air-svae",
        "--scene",
        "grasp-water",
        "--objects",
        "bottle",
        "--modes",
        "open",
        "--trials",
        "3",
        "--seed",
        "4",
    ];
    let with = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        trials(d, &args)
    };
    // Refused before anything is stored, each naming what is wrong.
    for (extra, says) in [
        (
            ["--set", "objects.vase.wet_friction=0.2"],
            "no scene has `objects.vase.wet_friction`",
        ),
        (["--set", "objects.bottle.wet_friction=-1"], "wet_friction"),
        (["--set", "effects.object_flow.period_s=0"], "period_s"),
        (
            ["--sweep", "objects.bottle.wet_friction=0.1"],
            "at least two values",
        ),
        (
            ["--sweep", "objects.bottle.wet_friction=0.1,abc"],
            "wet_friction",
        ),
        (["--sweep", "sigma_mm=1,x"], "not a number of mm"),
    ] {
        fails_with(&with(&extra), 2, says);
    }
    let sessions = "SELECT COUNT(*) FROM grasp_sessions";
    assert_eq!(rt.block_on(count(&db, sessions)), 0, "nothing stored");

    // The bottle's wet friction swept: the same perturbations at each value, and the
    // physics, not the draw, deciding (nothing lifts a bottle without friction).
    let out = ok(&with(&["--sweep", "objects.bottle.wet_friction=0.0,2.0"]));
    for needle in [
        "water (scene 0; objects.bottle.wet_friction = 0.0)",
        "water (scene 1; objects.bottle.wet_friction = 2.0)",
        "success against objects.bottle.wet_friction (σ = 5 mm, all objects):",
        "first value held in at least 90 % of trials",
    ] {
        assert!(out.contains(needle), "`{needle}` in:\n{out}");
    }
    let rows = rt.block_on(session_rows(&db, 1));
    assert_eq!(rows.len(), 6, "{rows:?}");
    let (at_zero, at_two) = rows.split_at(3);
    for (a, b) in at_zero.iter().zip(at_two) {
        assert_eq!(
            (a.3, a.4.to_bits(), a.5.to_bits()),
            (b.3, b.4.to_bits(), b.5.to_bits())
        );
    }
    assert!(at_zero.iter().all(|r| r.7 == 0), "{at_zero:?}");
    let csv = std::fs::read_to_string(d.join("g/grasp-trials-sweep.csv")).expect("sweep csv");
    assert!(csv.starts_with(
        "path,value,sigma_mm,medium,object,mode,trials,held,rate,wilson_lo,wilson_hi"
    ));
    // 2 values × (bottle, all) × 1 mode.
    assert_eq!(csv.lines().count(), 1 + 4, "{csv}");
    assert!(
        csv.contains("objects.bottle.wet_friction,0.0,5,water,all,open,3,0,0,"),
        "{csv}"
    );
    let png = std::fs::read(d.join("g/grasp-trials-sweep.png")).expect("png");
    assert!(png.starts_with(b"\x89PNG"));

    // --set of one value runs as the sweep's trials at that value, bit for bit, and
    // says the value beside its results.
    let said = ok(&with(&["--set", "objects.bottle.wet_friction=2.0"]));
    assert!(
        said.contains("scene values set: objects.bottle.wet_friction=2.0"),
        "{said}"
    );
    let set = rt.block_on(session_rows(&db, 2));
    assert_eq!(set, at_two.to_vec());
    // Each session stored the scenes it ran: the value is in them.
    let scenes: String = rt.block_on(async {
        let options = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(&db)
            .read_only(true);
        let mut conn = sqlx::ConnectOptions::connect(&options).await.expect("open");
        sqlx::query_scalar("SELECT scenes_json FROM grasp_sessions WHERE session_id = 2")
            .fetch_one(&mut conn)
            .await
            .expect("scenes")
    });
    assert!(scenes.contains("\"wet_friction\":2.0"), "{scenes}");

    // The report shows success against the value.
    let html = common::report_page(d);
    let page = html.html();
    assert!(
        page.contains("success against objects.bottle.wet_friction (objects pooled)"),
        "no sweep figure"
    );
    assert!(page.contains("water, objects.bottle.wet_friction = 2.0"));
    let sets = html
        .select(&scraper::Selector::parse("[data-k=\"grasp-2-sets\"]").expect("selector"))
        .map(|e| e.text().collect::<String>())
        .collect::<Vec<_>>();
    assert_eq!(
        sets,
        ["objects.bottle.wet_friction=2.0"],
        "the set beside session 2"
    );
}
