//! End-to-end tests of the `softtouch` CLI: the binary as a user runs it.

use crate::common;
use crate::fcisim;
use common::{command, softtouch, tempdir, text};

use softtouch_collector::store::RunStatus;
use softtouch_collector::testing::{RunPlan, block_on, frame, seeded_run, temp_store};
use softtouch_schemas::{
    ConfigSource, FrameFormat, RigConfig, SceneSpec, config::parse_toml, defaults,
};
use std::process::Command;

#[test]
fn help_lists_only_working_verbs_and_each_verb_has_an_example() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["--help"]);
    assert!(out.status.success());
    let help = text(&out.stdout);
    for verb in [
        "config", "db", "runs", "collect", "status", "dataset", "sim", "bench",
    ] {
        assert!(help.contains(verb), "{help}");
    }
    assert!(
        help.contains("Exit codes: 0 success, 1 runtime failure"),
        "{help}"
    );
    for verb in [
        &["config", "show"][..],
        &["config", "check"],
        &["db", "init"],
        &["runs"],
    ] {
        let mut args = verb.to_vec();
        args.push("--help");
        let out = softtouch(dir.path(), &args);
        assert!(out.status.success(), "{verb:?}");
        assert!(
            text(&out.stdout).contains("softtouch "),
            "{verb:?} help has no example:\n{}",
            text(&out.stdout)
        );
    }
}

#[test]
fn config_show_prints_defaults_that_parse_back_to_the_defaults() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["config", "show", "rig"]);
    assert!(out.status.success());
    let rig: RigConfig = parse_toml(&text(&out.stdout), &ConfigSource::Embedded("stdout"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rig, defaults::rig());

    let out = softtouch(dir.path(), &["config", "show", "scene"]);
    let scene: SceneSpec = parse_toml(&text(&out.stdout), &ConfigSource::Embedded("stdout"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene, defaults::scene());
}

#[test]
fn an_edited_config_file_is_shown_resolved() {
    let dir = tempdir();
    let edited = defaults::RIG_TOML.replace("settle_s = 0.3", "settle_s = 0.75");
    std::fs::write(dir.path().join("rig.toml"), edited).unwrap_or_else(|e| panic!("{e}"));
    let out = softtouch(dir.path(), &["config", "show", "rig", "--rig", "rig.toml"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("settle_s = 0.75"));
}

#[test]
fn a_malformed_config_exits_2_naming_file_line_and_field() {
    let dir = tempdir();
    let bad = defaults::RIG_TOML.replace("settle_s = 0.3", "settle = 0.3");
    std::fs::write(dir.path().join("rig.toml"), bad).unwrap_or_else(|e| panic!("{e}"));
    let out = softtouch(dir.path(), &["config", "check", "--rig", "rig.toml"]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.contains("rig.toml:"), "{err}");
    assert!(
        err.contains("field `procedure.settle`: unknown field `settle`, expected one of"),
        "{err}"
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn a_scene_outside_the_rigs_workspace_exits_2() {
    let dir = tempdir();
    let scene = defaults::SCENE_TOML.replace("x_m = [0.0, 0.05]", "x_m = [0.0, 0.09]");
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap_or_else(|e| panic!("{e}"));
    let out = softtouch(dir.path(), &["config", "check", "--scene", "scene.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr)
            .contains("field `poses.x_m`: range [0, 0.09] lies outside the rig's workspace")
    );

    let out = softtouch(dir.path(), &["config", "check"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).starts_with("ok: rig <embedded default rig>"));
}

/// A Franka rig whose workspace asks for a half turn of the wrist either way (θ over
/// the full circle about a rod frame pointing the finger down) is refused before
/// anything moves: `config check` names the pose, the joint and its limit. The same
/// rig within ±0.4 rad passes. (Connect checks again from the arm's own joints: the
/// franka-sim tier.)
#[test]
fn config_check_refuses_a_franka_workspace_beyond_the_fr3s_joint_limits() {
    let dir = tempdir();
    let full = "[-3.141592653589793, 3.141592653589793]";
    let rig = fcisim::rig_toml("172.16.0.2", fcisim::SIM_DEVICES, fcisim::LIMITS);
    fcisim::write_rig(dir.path(), &rig);
    let ok = softtouch(
        dir.path(),
        &[
            "config",
            "check",
            "--rig",
            "rig.toml",
            "--scene",
            "scene.toml",
        ],
    );
    assert!(ok.status.success(), "{}", text(&ok.stderr));
    assert!(
        text(&ok.stdout).contains("12 corners within the FR3's joint ranges"),
        "{}",
        text(&ok.stdout)
    );
    std::fs::write(
        dir.path().join("full.toml"),
        rig.replace("theta_rad = [-0.4, 0.4]", &format!("theta_rad = {full}")),
    )
    .expect("write");
    std::fs::write(
        dir.path().join("full-scene.toml"),
        fcisim::SCENE.replace("theta_rad = [-0.4, 0.4]", &format!("theta_rad = {full}")),
    )
    .expect("write");
    let out = softtouch(
        dir.path(),
        &[
            "config",
            "check",
            "--rig",
            "full.toml",
            "--scene",
            "full-scene.toml",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stdout));
    let e = text(&out.stderr);
    assert!(
        e.contains("full.toml: arm: workspace corner")
            && e.contains("θ = 3.14")
            && e.contains("joint 7")
            && e.contains("FR3's limit"),
        "{e}"
    );
}

#[test]
fn built_in_scenes_are_reachable_by_name_from_any_folder() {
    // A folder with no scenes/ in it.
    let dir = tempdir();
    for (name, text_toml) in defaults::BUILTIN_SCENES {
        let out = softtouch(dir.path(), &["config", "show", "scene", name]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        assert_eq!(text(&out.stdout), text_toml, "{name} as shipped");
        let out = softtouch(dir.path(), &["config", "check", "--scene", name]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        assert!(
            text(&out.stdout).contains(&format!("scene <embedded default {name}>")),
            "{}",
            text(&out.stdout)
        );
    }
    let out = softtouch(dir.path(), &["config", "check", "--scene", "water"]);
    assert!(
        text(&out.stdout).contains("medium water"),
        "{}",
        text(&out.stdout)
    );
    // A file of that name wins over the built-in scene.
    std::fs::write(dir.path().join("water"), "not = \"a scene\"\n").expect("write");
    let out = softtouch(dir.path(), &["config", "check", "--scene", "water"]);
    assert_eq!(out.status.code(), Some(2));
    // Unknown names say which exist.
    for args in [
        &["config", "show", "scene", "sea"][..],
        &["config", "check", "--scene", "sea"],
    ] {
        let out = softtouch(dir.path(), args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(
            text(&out.stderr).contains("land, water, grasp, grasp-water"),
            "{}",
            text(&out.stderr)
        );
    }
    let out = softtouch(dir.path(), &["config", "show", "rig", "water"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("no built-in rig `water`: expected one of sim, fr3"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_missing_config_file_exits_2() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["config", "show", "--rig", "nope.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("nope.toml: cannot read"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn unknown_verbs_and_flags_exit_2() {
    let dir = tempdir();
    assert_eq!(softtouch(dir.path(), &["fly"]).status.code(), Some(2));
    assert_eq!(
        softtouch(dir.path(), &["runs", "--bogus"]).status.code(),
        Some(2)
    );
}

#[test]
fn runs_without_a_database_exits_2_and_creates_nothing() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["runs"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("softtouch db init"));
    assert!(!dir.path().join("softtouch.db").exists());
}

#[test]
fn db_init_creates_the_database_in_the_working_directory_and_runs_lists_it() {
    let dir = tempdir();
    let out = softtouch(dir.path(), &["db", "init"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("integrity ok"));
    assert!(dir.path().join("softtouch.db").exists());
    let out = softtouch(dir.path(), &["runs"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).starts_with("no runs"));
    // init is idempotent
    assert!(softtouch(dir.path(), &["db", "init"]).status.success());
}

#[test]
fn runs_shows_each_runs_status_and_counts() {
    let dir = block_on(async {
        let (dir, store) = temp_store("lab.db").await;
        // 3 planned, 2 written (the second retried once), then stopped.
        let plan = RunPlan::new(42, 3);
        let run = seeded_run(&store, &plan, 2, |sample, _| {
            let index = sample.index();
            let attempts = 1 + u32::try_from(index).unwrap_or(0);
            (
                sample.attempts(attempts),
                Some(frame(index, 1, 1, FrameFormat::Rgb8)),
            )
        })
        .await;
        store
            .set_run_status(run, RunStatus::Stopped)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
        dir
    });
    let out = softtouch(dir.path(), &["--db", "lab.db", "runs"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let table = text(&out.stdout);
    let row = table.lines().nth(1).unwrap_or_default();
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(
        &cols[..9],
        ["1", "stopped", "on-land", "air", "42", "3", "2", "0", "1"],
        "{table}"
    );
}

#[test]
fn sim_netft_serves_the_simulated_sensor_to_a_real_net_ft_client() {
    use softtouch_drivers::netft::client::{NetFtClient, NetFtConfig, Scaling};
    use softtouch_drivers::{Clock, ForceSensor as _, TokioClock};
    use std::io::BufRead as _;
    use std::sync::Arc;

    let dir = tempdir();
    let mut child = Command::new(env!("CARGO_BIN_EXE_softtouch"))
        .args([
            "sim",
            "netft",
            "--bind",
            "127.0.0.1:0",
            "--pose",
            "0.04,0.0,0.3",
            "--rate-hz",
            "2000",
        ])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"));
    let mut line = String::new();
    let stdout = child.stdout.take().unwrap_or_else(|| panic!("no stdout"));
    std::io::BufReader::new(stdout)
        .read_line(&mut line)
        .unwrap_or_else(|e| panic!("{e}"));
    let addr = |scheme: &str| -> std::net::SocketAddr {
        let start = line
            .find(scheme)
            .unwrap_or_else(|| panic!("no {scheme} in {line}"))
            + scheme.len();
        let rest = &line[start..];
        let end = rest.find([',', ';', ' ']).unwrap_or(rest.len());
        rest[..end]
            .parse()
            .unwrap_or_else(|e| panic!("{e}: {line}"))
    };
    let (rdt, cal) = (addr("udp://"), addr("tcp://"));

    let readings = block_on(async {
        let clock: Arc<dyn Clock> = Arc::new(TokioClock::new());
        let mut config = NetFtConfig::new(rdt, 2000.0);
        config.scaling = Scaling::CalibrationRequest(cal);
        let mut client = NetFtClient::connect(config, clock)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        client.start().await.unwrap_or_else(|e| panic!("{e}"));
        let mut out = Vec::new();
        while out.len() < 400 {
            client
                .read(&mut out)
                .await
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let _ = client.stop().await;
        out
    });
    let _ = child.kill();
    let _ = child.wait();
    assert!(readings.iter().all(|r| r.status.is_ok()));
    let force = readings[0].wrench_in_sensor.force_norm_n();
    assert!(
        force > 0.5 && force < 20.0,
        "the finger is pressed: {force} N"
    );
    assert!(
        readings
            .windows(2)
            .all(|w| w[1].rdt_sequence == w[0].rdt_sequence.wrapping_add(1))
    );
}

#[test]
fn a_file_that_is_not_a_database_is_named_as_such_and_left_as_it_was() {
    let dir = tempdir();
    let d = dir.path();
    let db = d.join("softtouch.db");
    std::fs::write(&db, "lab notes, not a database\n").unwrap_or_else(|e| panic!("{e}"));
    for args in [
        &["runs"][..],
        &["status"],
        &["report", "--out", "r.html"],
        &["db", "init"],
        &["collect", "--samples", "2"],
        &["dataset", "list"],
    ] {
        let out = softtouch(d, args);
        common::fails_with(&out, 2, "softtouch.db is not a SQLite database");
        assert!(
            text(&out.stderr).contains("it starts with \"lab notes, not a"),
            "{args:?}: {}",
            text(&out.stderr)
        );
    }
    assert_eq!(
        std::fs::read_to_string(&db).unwrap_or_default(),
        "lab notes, not a database\n"
    );
    assert!(!d.join("r.html").exists());
}

#[test]
fn an_empty_file_is_refused_by_readers_and_set_up_by_db_init_saying_so() {
    let dir = tempdir();
    let d = dir.path();
    let db = d.join("softtouch.db");
    std::fs::write(&db, "").unwrap_or_else(|e| panic!("{e}"));
    for args in [&["runs"][..], &["report", "--out", "r.html"], &["models"]] {
        common::fails_with(
            &softtouch(d, args),
            2,
            "softtouch.db is an empty file, not a database: `softtouch --db softtouch.db db init` sets it up",
        );
    }
    assert_eq!(std::fs::metadata(&db).map(|m| m.len()).unwrap_or(1), 0);
    let out = softtouch(d, &["db", "init"]);
    assert!(common::ok(&out).contains("ready"));
    assert!(
        text(&out.stderr)
            .contains("softtouch.db is an empty file: setting it up as a new database"),
        "{}",
        text(&out.stderr)
    );
    assert!(common::ok(&softtouch(d, &["runs"])).contains("no runs"));
}

#[test]
fn collect_says_the_disk_it_needs_status_the_size_per_sample_and_the_db_file_alone_is_complete() {
    let dir = tempdir();
    let d = dir.path();
    let db = d.join("softtouch.db");
    let out = common::ok(&softtouch(d, &["collect", "--samples", "3", "--seed", "1"]));
    // No samples yet: a frame of the scene is rendered and encoded, the rest assumed.
    assert!(
        out.contains("kB for 3 samples (")
            && out.contains(" kB a sample: its frame one of scene `on-land` rendered and encoded, the rest assumed until the database holds samples);"),
        "{out}"
    );
    let status = common::ok(&softtouch(d, &["status"]));
    let first = status.lines().next().unwrap_or_default();
    assert!(first.starts_with("database softtouch.db: "), "{status}");
    assert!(first.contains(", 3 samples, "), "{status}");
    assert!(first.ends_with(" a sample"), "{status}");
    // A second run measures on the database itself.
    let out = common::ok(&softtouch(d, &["collect", "--samples", "2", "--seed", "2"]));
    assert!(
        out.contains(
            "its frame measured over 3 of scene `on-land`, the rest measured over 3 samples"
        ),
        "{out}"
    );
    // The `.db` file alone holds every commit once the binary has exited.
    assert_eq!(
        softtouch_collector::store::sqlite_file::db_size(&db).wal_bytes,
        0
    );
    let backup = d.join("backup.db");
    std::fs::copy(&db, &backup).unwrap_or_else(|e| panic!("{e}"));
    let status = common::ok(&softtouch(d, &["--db", "backup.db", "status"]));
    assert!(status.contains(", 5 samples, "), "{status}");
}

#[test]
fn bench_train_times_a_tiny_net_beside_a_peer_and_names_what_it_cannot_run() {
    let dir = tempdir();
    let d = dir.path();
    let tiny = [
        "bench",
        "train",
        "--sizes",
        "16",
        "--widths",
        "4",
        "--steps",
        "2",
        "--warmup",
        "0",
        "--repeats",
        "1",
        "--batch",
        "8",
        "--out",
        "o",
    ];
    let out = softtouch(d, &tiny);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("16×16/4"),
        "{}",
        text(&out.stdout)
    );
    // The header names the kernels; SOFTTOUCH_CONV picks burn's or is refused by name.
    for (value, code, says) in [
        ("softtouch", 0, "softtouch's kernels"),
        ("burn", 0, "burn's own"),
        ("flex", 2, "SOFTTOUCH_CONV=flex"),
    ] {
        let out = command(d)
            .env("SOFTTOUCH_CONV", value)
            .args(tiny)
            .output()
            .expect("run softtouch");
        let all = format!("{}{}", text(&out.stdout), text(&out.stderr));
        assert_eq!(out.status.code(), Some(code), "{value}: {all}");
        assert!(all.contains(says), "{value}: {all}");
    }
    let csv = std::fs::read_to_string(d.join("o/bench-train.csv")).expect("csv");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}");
    assert!(lines[0].starts_with("size_px,width,images_per_s") && lines[1].starts_with("16,4,"));
    // A stand-in for the PyTorch peer: any program that prints its JSON line.
    let peer = d.join("peer.sh");
    std::fs::write(
        &peer,
        "#!/bin/sh\necho '{\"train_img_per_s_total\": 1000.0, \"train_cores_used\": 2.0}'\n",
    )
    .expect("peer");
    let failing = d.join("failing.sh");
    std::fs::write(&failing, "#!/bin/sh\necho 'no torch here' >&2\nexit 1\n").expect("peer");
    for p in [&peer, &failing] {
        let mut perms = std::fs::metadata(p).expect("meta").permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
        std::fs::set_permissions(p, perms).expect("chmod");
    }
    std::fs::write(d.join("script.py"), "").expect("script");
    let with = |python: &str, script: &str| {
        let mut args = tiny.to_vec();
        args.extend(["--torch", python, "--torch-script", script]);
        softtouch(d, &args)
    };
    let out = with(&peer.display().to_string(), "script.py");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let csv = std::fs::read_to_string(d.join("o/bench-train.csv")).expect("csv");
    let row: Vec<&str> = csv.lines().nth(1).expect("row").split(',').collect();
    let ours: f64 = row[2].parse().expect("ours");
    let ratio: f64 = row[11].parse().expect("ratio");
    assert!(
        (row[9] == "1000") && (ratio - ours / 1000.0).abs() < 1e-9,
        "{csv}"
    );
    // What cannot run is named: no script (2), no interpreter (2), a peer that fails (1).
    let out = with(&peer.display().to_string(), "missing.py");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("missing.py"),
        "{}",
        text(&out.stderr)
    );
    let out = with("/nonexistent/python", "script.py");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("/nonexistent/python"),
        "{}",
        text(&out.stderr)
    );
    let out = with(&failing.display().to_string(), "script.py");
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("no torch here"),
        "{}",
        text(&out.stderr)
    );
}

/// A refused `collect` names the flag at fault and leaves nothing behind: no new
/// database, no log file (`--samples 0` used to store an empty completed run; `-1` was
/// an unknown argument; a bad rod or rig made an empty database and a log first).
#[test]
fn a_refused_collect_names_its_flag_and_leaves_no_database_nor_log() {
    let dir = tempdir();
    let d = dir.path();
    for (args, says) in [
        (
            &["collect", "--samples", "0"][..],
            "invalid value '0' for '--samples",
        ),
        (
            &["collect", "--samples", "-1"],
            "invalid value '-1' for '--samples",
        ),
        (
            &["collect", "--samples", "3", "--rods", "nosuch"],
            "--rods: no rod `nosuch`",
        ),
        (
            &["collect", "--samples", "3", "--rig", "missing.toml"],
            "missing.toml",
        ),
        (
            &["collect", "--samples", "3", "--block", "0"],
            "--block: expected at least 1",
        ),
        (
            &["collect", "--poses-from", "1"],
            "--poses-from 1: no database",
        ),
    ] {
        let out = softtouch(d, args);
        common::fails_with(&out, 2, says);
        let left: Vec<_> = std::fs::read_dir(d)
            .map(|r| r.filter_map(Result::ok).map(|e| e.file_name()).collect())
            .unwrap_or_default();
        assert!(left.is_empty(), "{args:?} left {left:?}");
        assert!(
            text(&out.stdout).is_empty(),
            "{args:?}: {}",
            text(&out.stdout)
        );
    }
}
