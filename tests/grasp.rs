//! End-to-end tests of `softtouch grasp follow|disturb|twist`: a tiny model trained on
//! a small simulated collection closes the loop on the simulated soft-finger Hand-E;
//! the verbs print their tables and write the CSV and the PNG; bad input exits 2.

use crate::common;
use common::{fails_with, ok, softtouch, tempdir, tiny_model};

#[test]
fn grasp_follow_prints_a_row_per_target_and_writes_csv_and_png() {
    let dir = tempdir();
    let d = dir.path();
    tiny_model(d);
    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "follow",
            "--model",
            "air-svae",
            "--targets",
            "0.4,1.6",
            "--fps",
            "30",
            "--hold-s",
            "1",
            "--out-dir",
            "g",
        ],
    ));
    assert!(
        out.contains("calibration #1 (made now)") && out.contains("Λ_max = "),
        "{out}"
    );
    assert!(out.contains("the simulator's true Λ_max"), "{out}");
    assert!(out.contains("target N"), "{out}");
    for row in ["    0.40 ", "    1.60 "] {
        assert!(
            out.lines().any(|l| l.starts_with(row)),
            "no row {row:?}: {out}"
        );
    }
    let csv = std::fs::read_to_string(d.join("g/grasp-follow.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert!(
        rows[0].starts_with("t_s,frame,target_n,estimate_n,true_n"),
        "{}",
        rows[0]
    );
    // One row per camera frame: 2 s at 30 Hz.
    assert!((58..=62).contains(&(rows.len() - 1)), "{}", rows.len());
    assert!(rows[1..].iter().all(|r| r.split(',').count() == 9));
    let png = std::fs::read(d.join("g/grasp-follow.png")).expect("png");
    assert!(png.starts_with(b"\x89PNG"));

    disturb_and_twist(d);
    stored_results_match_the_exports_and_the_report(d);
    a_kill_leaves_a_whole_result_or_none(d);

    fails_with(
        &softtouch(
            d,
            &["grasp", "follow", "--model", "air-svae", "--targets", "12"],
        ),
        2,
        "--targets 12: expected a force in (0, 9.9) N",
    );
    fails_with(
        &softtouch(d, &["grasp", "follow", "--model", "nope"]),
        2,
        "nope",
    );
    fails_with(
        &softtouch(
            d,
            &["grasp", "follow", "--model", "air-svae", "--object", "vase"],
        ),
        2,
        "--object vase",
    );
}

/// `grasp disturb` (two fingers) and `grasp twist` on the model trained above, short.
fn disturb_and_twist(d: &std::path::Path) {
    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "disturb",
            "--model",
            "air-svae",
            "--fps",
            "30",
            "--settle-s",
            "0.5",
            "--turn-s",
            "0.3",
            "--phase-s",
            "1",
            "--fingers",
            "2",
            "--out-dir",
            "g",
        ],
    ));
    assert!(
        out.contains("holding 0.4 N (air medium) on `oval-tube`"),
        "{out}"
    );
    assert!(out.contains("2 finger(s)"), "{out}");
    for (row, turn) in [("    1 ", "45.0"), ("    2 ", "60.0"), ("    3 ", "-90.0")] {
        assert!(
            out.lines().any(|l| l.starts_with(row) && l.contains(turn)),
            "no phase row {row:?}: {out}"
        );
    }
    let csv = std::fs::read_to_string(d.join("g/grasp-disturb.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].starts_with("t_s,target_n,estimate_n,true_n,object_yaw_deg"));
    // 3.5 s at 30 Hz, one row per frame; the tube ends at 45 + 60 − 90 = 15°.
    assert!((100..=110).contains(&(rows.len() - 1)), "{}", rows.len());
    let yaw = |r: &str| r.split(',').nth(4).and_then(|v| v.parse::<f64>().ok());
    let max_yaw = rows[1..].iter().filter_map(|r| yaw(r)).fold(0.0, f64::max);
    assert!((max_yaw - 105.0).abs() < 1.0, "{max_yaw}");
    assert!((yaw(rows[rows.len() - 1]).expect("yaw") - 15.0).abs() < 1e-6);
    // Both fingers' estimates are recorded.
    assert!(
        rows[1..]
            .iter()
            .all(|r| r.split(',').nth(6).is_some_and(|v| !v.is_empty()))
    );
    assert!(
        std::fs::read(d.join("g/grasp-disturb.png"))
            .expect("png")
            .starts_with(b"\x89PNG")
    );

    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "twist",
            "--model",
            "air-svae",
            "--fps",
            "30",
            "--settle-s",
            "0.5",
            "--turn-s",
            "0.5",
            "--hold-s",
            "0.5",
            "--out-dir",
            "g",
        ],
    ));
    // One τz RMS per run, counted from the first turn: the terminal's row is the
    // metrics table's (the report and the stored summary are checked against the same
    // table in stored_results_match_the_exports_and_the_report).
    assert!(
        out.contains("numbers count from the first turn (0.5 s after the grasp"),
        "{out}"
    );
    let metrics = std::fs::read_to_string(d.join("g/grasp-twist-metrics.csv")).expect("csv");
    let all_cycles = std::fs::read_to_string(d.join("g/grasp-twist.csv")).expect("csv");
    for (state, row) in [("off", "           off "), ("on", "            on ")] {
        let terminal: Vec<&str> = out
            .lines()
            .find(|l| l.starts_with(row))
            .unwrap_or_else(|| panic!("no row {row:?}: {out}"))
            .split_whitespace()
            .collect();
        let stored: Vec<&str> = metrics
            .lines()
            .find(|l| l.starts_with(&format!("{state},")))
            .expect("a metrics row")
            .split(',')
            .collect();
        let at = |i: usize| format!("{:.3}", stored[i].parse::<f64>().expect("number"));
        assert_eq!(terminal[1], stored[2], "cycles scored, {state}");
        assert_eq!(terminal[2], at(3), "τz RMS, {state}");
        assert_eq!(terminal[3], at(4), "true τz RMS, {state}");
        let every: usize = all_cycles
            .lines()
            .filter(|l| l.starts_with(&format!("{state},")))
            .count();
        let scored: usize = stored[2].parse().expect("count");
        assert!(
            scored > 0 && scored < every,
            "{scored} of {every} cycles scored"
        );
    }
    let csv = std::fs::read_to_string(d.join("g/grasp-twist.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].starts_with("wrist_loop,t_s,target_n,estimate_n,true_n,tz_estimate_nmm"));
    let off = rows.iter().filter(|r| r.starts_with("off,")).count();
    let on = rows.iter().filter(|r| r.starts_with("on,")).count();
    assert!(
        (70..=80).contains(&off) && (70..=80).contains(&on),
        "{off} {on}"
    );
    // The turn made a true torque about z (measured from the shear).
    let tz = |r: &str| r.split(',').nth(6).and_then(|v| v.parse::<f64>().ok());
    let peak = rows[1..]
        .iter()
        .filter(|r| r.starts_with("off,"))
        .filter_map(|r| tz(r))
        .fold(0.0_f64, |m, t| m.max(t.abs()));
    assert!(peak > 0.5, "true τz peak {peak} N·mm");
    assert!(
        std::fs::read(d.join("g/grasp-twist.png"))
            .expect("png")
            .starts_with(b"\x89PNG")
    );

    fails_with(
        &softtouch(
            d,
            &["grasp", "disturb", "--model", "air-svae", "--fingers", "3"],
        ),
        2,
        "--fingers 3",
    );
    fails_with(
        &softtouch(
            d,
            &[
                "grasp", "disturb", "--model", "air-svae", "--object", "vase",
            ],
        ),
        2,
        "--object vase",
    );
    fails_with(
        &softtouch(
            d,
            &["grasp", "twist", "--model", "air-svae", "--turn-deg", "200"],
        ),
        2,
        "--turn-deg 200",
    );
}

#[test]
fn grasp_calibrate_stores_a_calibration_the_loop_then_reuses_and_refuses_a_blind_model() {
    let dir = tempdir();
    let d = dir.path();
    tiny_model(d);
    let out = ok(&softtouch(
        d,
        &["grasp", "calibrate", "--model", "air-svae", "--fps", "30"],
    ));
    assert!(out.contains("calibration #1: `cylinder`"), "{out}");
    assert!(out.contains("first touch at count"), "{out}");
    assert!(out.contains("the simulator's true Λ_max"), "{out}");
    assert!(out.contains("Λ(P) N/mm by count: "), "{out}");
    // The same setup, model and object: follow takes it rather than making another.
    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "follow",
            "--model",
            "air-svae",
            "--targets",
            "0.4",
            "--fps",
            "30",
            "--hold-s",
            "0.5",
            "--out-dir",
            "g",
        ],
    ));
    assert!(out.contains("calibration #1 (stored)"), "{out}");
    // Another rate is another setup: a new calibration.
    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "follow",
            "--model",
            "air-svae",
            "--targets",
            "0.4",
            "--fps",
            "60",
            "--hold-s",
            "0.5",
            "--out-dir",
            "g",
        ],
    ));
    assert!(out.contains("calibration #2 (made now)"), "{out}");
    // A model whose estimate does not rise with the contact (2 epochs: flat) is not
    // calibrated into a gain: it is refused, naming why.
    let mut args = vec!["train", "--dataset", "air", "--name", "blind"];
    args.extend(common::TINY);
    ok(&softtouch(d, &args));
    fails_with(
        &softtouch(d, &["grasp", "calibrate", "--model", "blind"]),
        2,
        "no touch",
    );
    fails_with(
        &softtouch(
            d,
            &["grasp", "calibrate", "--model", "air-svae", "--target", "0"],
        ),
        2,
        "--target 0",
    );
    a_stop_signal_while_calibrating_ends_the_verb_cleanly(d);
}

/// SIGTERM is watched from the verb's first instruction: sent while `grasp follow` is
/// still calibrating (the calibration not yet stored), the calibration finishes and is
/// stored, the loop stops at its first cycle, the summary is printed, the exit is 0,
/// and the database keeps no write-ahead log. (Before, the default disposition killed
/// it: exit 143 and a 90 kB log left.)
fn a_stop_signal_while_calibrating_ends_the_verb_cleanly(d: &std::path::Path) {
    use std::process::Stdio;
    if common::on_postgres() {
        return; // the write-ahead log and the count below are SQLite's
    }
    let db = d.join("softtouch.db");
    let calibrations = || {
        common::runtime().block_on(async {
            let options = sqlx::sqlite::SqliteConnectOptions::new()
                .filename(&db)
                .read_only(true);
            let mut conn = sqlx::ConnectOptions::connect(&options)
                .await
                .expect("opens");
            sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM grasp_calibrations")
                .fetch_one(&mut conn)
                .await
                .expect("counts")
        })
    };
    let before = calibrations();
    let child = common::command(d)
        .args([
            "grasp",
            "follow",
            "--model",
            "air-svae",
            "--targets",
            "0.4",
            "--fps",
            "45",
            "--hold-s",
            "0.5",
            "--out-dir",
            "g",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawns");
    // Wait until the process catches SIGTERM (bit 15 of SigCgt in /proc), then send it.
    let status = format!("/proc/{}/status", child.id());
    let start = std::time::Instant::now();
    loop {
        let caught = std::fs::read_to_string(&status)
            .ok()
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix("SigCgt:"))
                    .and_then(|m| u64::from_str_radix(m.trim(), 16).ok())
            })
            .is_some_and(|mask| mask & (1 << 14) != 0);
        if caught {
            break;
        }
        assert!(start.elapsed().as_secs() < 60, "SIGTERM never caught");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    assert_eq!(
        calibrations(),
        before,
        "the calibration was already stored: too late"
    );
    let sent = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(sent.success());
    let out = child.wait_with_output().expect("waits");
    let stdout = common::text(&out.stdout);
    assert!(
        out.status.success(),
        "{:?}\n{stdout}\n{}",
        out.status,
        common::text(&out.stderr)
    );
    assert!(stdout.contains("(made now)"), "{stdout}");
    assert!(stdout.contains("stopped by SIGTERM"), "{stdout}");
    assert_eq!(calibrations(), before + 1);
    let wal = softtouch_collector::store::sqlite_file::db_size(&db).wal_bytes;
    assert_eq!(wal, 0, "the write-ahead log holds {wal} bytes");
}

/// `grasp follow`, `disturb` and `twist` stored their results as they ended: the tables
/// are the exports byte for byte, and the report's Figure 5 shows their numbers.
fn stored_results_match_the_exports_and_the_report(d: &std::path::Path) {
    let listed = ok(&softtouch(d, &["results"]));
    for verb in ["grasp follow", "grasp disturb", "grasp twist"] {
        assert!(listed.contains(verb), "`{verb}` in:\n{listed}");
    }
    for (id, table) in [
        ("1", "grasp-follow.csv"),
        ("1", "grasp-follow-metrics.csv"),
        ("2", "grasp-disturb.csv"),
        ("3", "grasp-twist.csv"),
        ("3", "grasp-twist-metrics.csv"),
    ] {
        let file = std::fs::read_to_string(d.join("g").join(table)).expect("export");
        let stored = ok(&softtouch(d, &["results", "show", id, "--table", table]));
        assert_eq!(stored, file, "{table}");
    }
    let shown = ok(&softtouch(d, &["results", "show", "1"]));
    for needle in [
        "result 1: grasp follow",
        "model:     air-svae (artifact sha256 ",
        "\"targets_n\":[0.4,1.6]",
        "\"fps\":30.0",
        "scene:     ",
    ] {
        assert!(shown.contains(needle), "`{needle}` in:\n{shown}");
    }

    let html = common::report_page(d);
    let cell = |key: &str| common::data_k(&html, key);
    // Following: the steady-state error per target, as stored.
    let metrics = std::fs::read_to_string(d.join("g/grasp-follow-metrics.csv")).expect("csv");
    for (i, line) in metrics.lines().skip(1).enumerate() {
        let ss: f64 = line
            .split(',')
            .nth(4)
            .and_then(|v| v.parse().ok())
            .expect("ss");
        assert_eq!(cell(&format!("follow-1-{i}-ss")), format!("{ss:.3}"));
        // The grip a lab cannot see: the hold's peak true force and its closing past
        // the touch, as exported, and the true force bounded by the squeeze.
        let grip: Vec<f64> = line
            .split(',')
            .skip(11)
            .map(|v| v.parse().expect("peak_true_n, past_touch_mm"))
            .collect();
        assert_eq!(grip.len(), 2, "{line}");
        assert_eq!(
            cell(&format!("follow-1-{i}-peak-true")),
            format!("{:.2}", grip[0])
        );
        assert_eq!(
            cell(&format!("follow-1-{i}-past-touch")),
            format!("{:.2}", grip[1])
        );
        assert!(grip[0] > 0.0 && grip[1] >= 0.0, "{line}");
    }
    let follow = ok(&softtouch(d, &["results", "show", "1"]));
    assert!(follow.contains(", peak true "), "{follow}");
    let disturb = ok(&softtouch(d, &["results", "show", "2"]));
    assert!(disturb.contains("; peak true "), "{disturb}");
    // Twist: the true τz RMS per wrist-loop state is the metrics table's, in the report
    // and in the stored summary alike.
    let twist = std::fs::read_to_string(d.join("g/grasp-twist-metrics.csv")).expect("csv");
    let summary = ok(&softtouch(d, &["results", "show", "3"]));
    for state in ["off", "on"] {
        let rms: f64 = twist
            .lines()
            .find(|l| l.starts_with(&format!("{state},")))
            .and_then(|l| l.split(',').nth(4))
            .and_then(|v| v.parse().ok())
            .expect("true τz RMS");
        assert_eq!(
            cell(&format!("twist-3-{state}-true-rms")),
            format!("{rms:.3}")
        );
        let said = format!(
            "wrist loop {state}: true τz RMS {rms:.3} N·mm from the first turn, peak true "
        );
        assert!(summary.contains(&said), "`{said}` in:\n{summary}");
        assert!(
            cell("twist-3-summary").contains(&said),
            "the report's twist summary"
        );
    }
    assert!(
        html.html().contains("τz RMS from the first turn on"),
        "the report says how τz RMS is counted"
    );
    // Each run in its own panel, on one scale: neither curve hides the other.
    for state in ["off", "on"] {
        let title = format!("Twist: τz, wrist loop {state}");
        assert_eq!(html.html().matches(&title).count(), 1, "{title}");
    }
    let section: String = html
        .select(&scraper::Selector::parse("#figure-5").expect("selector"))
        .map(|e| e.text().collect::<String>())
        .collect();
    assert!(section.contains("No grasp benchmark stored"), "{section}");
    assert!(
        section.contains("softtouch grasp disturb, result 2"),
        "{section}"
    );
}

/// kill -9 of `grasp follow` in the moment between writing its CSVs and storing its
/// result (the window a kill can split): every stored result has both its tables (the
/// result and its tables are one transaction), and none is stored twice.
fn a_kill_leaves_a_whole_result_or_none(d: &std::path::Path) {
    use std::process::{Command, Stdio};
    let follows = || -> Vec<String> {
        ok(&softtouch(d, &["results"]))
            .lines()
            .filter(|l| l.contains("grasp follow"))
            .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
            .collect()
    };
    let before = follows().len();
    let mut finished = 0;
    let marker = d.join("k/grasp-follow-metrics.csv");
    for _ in 0..6 {
        let _ = std::fs::remove_file(&marker);
        let mut child = Command::new(env!("CARGO_BIN_EXE_softtouch"))
            .args([
                "grasp",
                "follow",
                "--model",
                "air-svae",
                "--targets",
                "0.4",
                "--fps",
                "30",
                "--hold-s",
                "1",
                "--out-dir",
                "k",
            ])
            .current_dir(d)
            .env_remove("SOFTTOUCH_DB")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn");
        // Kill as soon as the tables are on disk: the result is being stored.
        loop {
            if child.try_wait().ok().flatten().is_some() {
                finished += 1;
                break;
            }
            if marker.exists() {
                let _ = child.kill(); // SIGKILL
                break;
            }
            std::thread::yield_now();
        }
        let _ = child.wait();
    }
    let after = follows();
    assert!(
        after.len() >= before + finished && after.len() <= before + 6,
        "{before} → {}, {finished} finished",
        after.len()
    );
    for id in &after {
        let shown = ok(&softtouch(d, &["results", "show", id]));
        assert!(
            shown.contains("grasp-follow.csv (") && shown.contains("grasp-follow-metrics.csv ("),
            "result {id}:\n{shown}"
        );
    }
}
