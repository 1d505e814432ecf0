//! End-to-end tests of `softtouch rig check`, `softtouch live` and `softtouch bench
//! grasp`: the rig check passes on the simulated rig and fails a Net F/T sensor that
//! never answers; `live` runs its scripted press on the simulated rig beside the
//! simulated sensor; `bench grasp` writes its table, CSV and PNG.

use crate::common;
use common::{fails_with, ok, softtouch, tempdir, text, tiny_model};

#[test]
fn rig_check_passes_every_device_of_the_simulated_rig() {
    let dir = tempdir();
    let out = ok(&softtouch(dir.path(), &["rig", "check"]));
    for device in ["host", "arm", "force_sensor", "camera", "gripper"] {
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("{device} ")))
            .unwrap_or_else(|| panic!("no {device} row: {out}"));
        assert!(line.contains(" pass "), "{line}");
    }
    assert!(!out.contains("FAIL"), "{out}");
    // The stream's measured rate is printed against the configured 1000 Hz.
    assert!(out.contains("of 1000 Hz configured"), "{out}");
    // The arm has moved, not only answered.
    assert!(out.contains("moved 1 mm up and back"), "{out}");
}

#[test]
fn rig_check_fails_a_net_ft_sensor_that_never_answers() {
    let dir = tempdir();
    // Bound, never answering: the sensor's address with nothing behind it.
    let silent = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
    let port = silent.local_addr().expect("addr").port();
    let rig = softtouch_schemas::defaults::RIG_TOML.replace(
        "[force_sensor]\ndriver = \"sim\"",
        &format!(
            "[force_sensor]\ndriver = \"net-ft\"\naddress = \"127.0.0.1:{port}\"\ncounts_per_force = 1000000.0\ncounts_per_torque = 1000000.0"
        ),
    );
    assert!(rig.contains("net-ft"), "the default rig's layout changed");
    std::fs::write(dir.path().join("rig.toml"), rig).expect("write");
    let out = softtouch(
        dir.path(),
        &["rig", "check", "--rig", "rig.toml", "--timeout-s", "3"],
    );
    fails_with(&out, 1, "1 of 5 checks failed");
    let stdout = text(&out.stdout);
    let row = stdout
        .lines()
        .find(|l| l.starts_with("force_sensor "))
        .unwrap_or_else(|| panic!("no sensor row: {stdout}"));
    assert!(row.contains("FAIL") && row.contains("net-ft"), "{row}");
    assert!(
        row.contains("expected"),
        "the row says what was expected: {row}"
    );
    for device in ["arm ", "camera ", "gripper "] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(device))
            .unwrap_or_else(|| panic!("no {device}row: {stdout}"));
        assert!(line.contains(" pass "), "{line}");
    }
    drop(silent);
}

#[test]
fn live_presses_on_the_simulated_rig_and_bench_grasp_writes_its_table() {
    let dir = tempdir();
    let d = dir.path();
    tiny_model(d);
    let out = ok(&softtouch(
        d,
        &["live", "--model", "air-svae", "--out", "live.csv"],
    ));
    assert!(out.contains("scripted press"), "{out}");
    assert!(out.contains("script done"), "{out}");
    assert!(out.contains("RMS estimate − sensor"), "{out}");
    let csv = std::fs::read_to_string(d.join("live.csv")).expect("csv");
    let mut lines = csv.lines();
    let header = lines.next().expect("header");
    assert!(header.starts_with("t_s,frame,est_fx_n"), "{header}");
    // Torques in N·mm, as everywhere else.
    assert!(
        header.contains("est_tz_nmm") && header.ends_with("ft_tz_nmm"),
        "{header}"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|c| c.parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    // One row per frame at 120 Hz over a script of a few seconds.
    assert!(rows.len() > 240, "{} rows", rows.len());
    assert!(rows.iter().all(|r| r.len() == 14));
    // Every frame has a finite estimate and a sensor reading.
    assert!(rows.iter().all(|r| r[2..14].iter().all(|v| v.is_finite())));
    // The press shows on the sensor: clear of the rod first, then newtons.
    let force = |r: &Vec<f64>| (r[8] * r[8] + r[9] * r[9] + r[10] * r[10]).sqrt();
    assert!(force(&rows[0]) < 0.3, "{:?}", rows[0]);
    let peak = rows.iter().map(force).fold(0.0, f64::max);
    assert!(peak > 1.0, "peak {peak} N");
    // The press's torques reach tens of N·mm (in N·m they would stay below 1).
    let torque_peak = rows
        .iter()
        .map(|r| r[11].abs().max(r[12].abs()).max(r[13].abs()))
        .fold(0.0, f64::max);
    assert!(torque_peak > 1.0, "peak torque {torque_peak} N·mm");
    // Frames in order, on the 120 Hz grid.
    assert!(rows.windows(2).all(|w| w[1][0] > w[0][0]));
    // And as a plot: the estimate beside the sensor, one panel per axis (3 × 2).
    assert!(out.contains("wrote live.png"), "{out}");
    let png = image::open(d.join("live.png")).expect("the live plot");
    assert_eq!((png.width(), png.height()), (1560, 720));

    let out = ok(&softtouch(
        d,
        &[
            "bench",
            "grasp",
            "--model",
            "air-svae",
            "--gains",
            "0.3,0.75",
            "--tolerances",
            "0.1",
            "--fps",
            "30,120",
            "--hold-s",
            "1",
            "--out",
            "b",
        ],
    ));
    assert!(out.contains("settle s"), "{out}");
    for varied in ["baseline", "K ", "fps "] {
        assert!(out.contains(varied), "no {varied} row: {out}");
    }
    let csv = std::fs::read_to_string(d.join("b/grasp-bench.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 1 + 3, "{csv}");
    assert!(d.join("b/grasp-bench.png").is_file());
    fails_with(
        &softtouch(
            d,
            &["bench", "grasp", "--model", "air-svae", "--gains", "0"],
        ),
        2,
        "--gains",
    );
    fails_with(
        &softtouch(d, &["live", "--model", "air-svae", "--depth-m", "0.5"]),
        2,
        "workspace",
    );

    // `grasp follow --rig` with a real Hand-E: K is --gain or the rig's calibration of
    // --object (no simulator to measure Λ), and a device that cannot be opened is a
    // runtime failure.
    let rig = with_real_hand_e_and_camera(softtouch_schemas::defaults::RIG_TOML);
    assert!(
        rig.contains("hand-e") && rig.contains("v4l"),
        "the default rig's layout changed"
    );
    std::fs::write(d.join("real.toml"), rig).expect("write");
    let follow = [
        "grasp",
        "follow",
        "--model",
        "air-svae",
        "--rig",
        "real.toml",
    ];
    fails_with(&softtouch(d, &follow), 2, "--object: on a real gripper");
    // --gain sets K only: the squeeze bound still needs the object's calibration.
    let mut with_gain = follow.to_vec();
    with_gain.extend(["--gain", "4"]);
    fails_with(&softtouch(d, &with_gain), 2, "--object: on a real gripper");
    // K from the rig's calibration of the object: none yet, then one stored (as
    // `grasp calibrate --rig` stores it), which takes the verb as far as the devices.
    let mut with_object = follow.to_vec();
    with_object.extend(["--object", "bottle"]);
    fails_with(
        &softtouch(d, &with_object),
        2,
        "no calibration of `bottle` with model `air-svae` on this rig's gripper and cameras",
    );
    common::runtime().block_on(async {
        let store = softtouch_collector::store::Store::open(&d.join("softtouch.db"))
            .await
            .expect("open");
        let (artifact, _) = store
            .model_artifact("air-svae")
            .await
            .expect("query")
            .expect("stored model");
        let sha = softtouch_collector::dataset::export::sha256_hex;
        // Keyed by the rig's gripper and finger cameras, as `grasp calibrate --rig` keys it.
        let rig = softtouch_collector::configs::resolve(Some(&d.join("real.toml")), None)
            .expect("the rig reads")
            .rig;
        let setup_hash = softtouch_lab::grasp::calibration::rig_setup_hash(&rig).expect("hash");
        store
            .insert_grasp_calibration(&softtouch_collector::store::GraspCalibrationRow {
                calibration_id: 0,
                created_at: String::new(),
                setup_kind: "rig".into(),
                setup_hash,
                model: "air-svae".into(),
                model_sha256: sha(&artifact),
                object: "bottle".into(),
                touch_count: 120,
                lambda_max_n_per_mm: 2.0,
                lambda_iqr_n_per_mm: (1.8, 2.2),
                counts_spanned: 15,
                baseline_n: 0.0,
                mm_per_count: 0.196,
                ended: "reached_top".into(),
                points_json: "[]".into(),
                lambda_json: "[]".into(),
                true_lambda_max_n_per_mm: None,
            })
            .await
            .expect("insert");
        store.close().await;
    });
    let out = softtouch(d, &with_object);
    assert!(
        text(&out.stdout).contains("Λ_max = 2.000 N/mm from the model's estimate; K = 0.75 Λ_max"),
        "{}",
        text(&out.stdout)
    );
    // The gripper is opened first (its status read): its port is not there.
    fails_with(&out, 1, "gripper: serial /dev/softtouch-no-such-port");
}

#[test]
fn rig_check_holds_a_real_arm_to_a_real_time_host() {
    let dir = tempdir();
    // A Panda that enforces real time (the default), at an address where nothing
    // listens: the arm row fails either way; the host row fails unless this machine
    // runs a PREEMPT_RT kernel with real-time priority allowed.
    let rig = softtouch_schemas::defaults::RIG_TOML.replace(
        "[arm]\ndriver = \"sim\"",
        "[arm]\ndriver = \"franka\"\naddress = \"127.0.0.1\"",
    );
    assert!(rig.contains("franka"), "the default rig's layout changed");
    std::fs::write(dir.path().join("rig.toml"), rig).expect("write");
    let out = softtouch(
        dir.path(),
        &["rig", "check", "--rig", "rig.toml", "--timeout-s", "3"],
    );
    let stdout = text(&out.stdout);
    let host = stdout
        .lines()
        .find(|l| l.starts_with("host "))
        .unwrap_or_else(|| panic!("no host row: {stdout}"));
    let here = softtouch_drivers::realtime::host_realtime();
    if here.problems().is_empty() {
        assert!(
            host.contains(" pass ") && host.contains("PREEMPT_RT"),
            "{host}"
        );
    } else {
        assert!(host.contains("FAIL"), "{host}");
        assert!(host.contains("expected a real-time host"), "{host}");
        assert!(
            host.contains("realtime = \"ignore\""),
            "the way out is named: {host}"
        );
    }
    assert_eq!(out.status.code(), Some(1), "{stdout}");
}

/// A Franka FR3 rig in one edit: `config show rig fr3` with the robot's address passes
/// `config check` alone, and with a scene narrowed to its θ (one more edit, in the
/// scene); the default rig switched to a Franka is refused naming the fields to change
/// and values that pass. With the gripper and finger camera made real, `grasp calibrate
/// --rig` (beside `--scene`) gets past every file check to opening the devices: the
/// gripper is opened first (its status read, nothing moved) and its port is not there,
/// a runtime failure (exit 1). The franka-sim tier goes on from there with the Hand-E on
/// a pty: `franka_sim::the_fr3_rig_from_config_show_passes_rig_check_and_reaches_the_grasp_devices`.
#[test]
fn an_fr3_rig_from_config_show_passes_its_check_and_grasp_calibrate_reaches_the_devices() {
    let dir = tempdir();
    let d = dir.path();
    let shown = ok(&softtouch(d, &["config", "show", "rig", "fr3"]));
    let rig = shown.replace("address = \"172.16.0.2\"", "address = \"127.0.0.1\"");
    assert_ne!(rig, shown, "the FR3 rig's address line changed");
    std::fs::write(d.join("fr3.toml"), &rig).expect("write");
    let out = ok(&softtouch(d, &["config", "check", "--rig", "fr3.toml"]));
    assert!(
        out.contains("corners within the FR3's joint ranges") && out.contains("ok: rig"),
        "{out}"
    );
    let full = "theta_rad = [-3.141592653589793, 3.141592653589793]";
    let scene = softtouch_schemas::defaults::SCENE_TOML.replace(full, "theta_rad = [-0.4, 0.4]");
    assert!(!scene.contains(full), "the default scene's θ line changed");
    std::fs::write(d.join("scene.toml"), scene).expect("write");
    ok(&softtouch(
        d,
        &[
            "config",
            "check",
            "--rig",
            "fr3.toml",
            "--scene",
            "scene.toml",
        ],
    ));
    // The default rig with a Franka: refused, naming what to change.
    let franka = softtouch_schemas::defaults::RIG_TOML.replace(
        "driver = \"sim\"            # or \"franka\" with address = \"172.16.0.2\"",
        "driver = \"franka\"\naddress = \"127.0.0.1\"",
    );
    assert!(
        franka.contains("\"franka\""),
        "the default rig's arm line changed"
    );
    std::fs::write(d.join("franka.toml"), franka).expect("write");
    let out = softtouch(d, &["config", "check", "--rig", "franka.toml"]);
    fails_with(&out, 2, "workspace.base_from_rod = {");
    let e = text(&out.stderr);
    assert!(
        e.contains("workspace.theta_rad = [-0.4, 0.4]") && e.contains("config show rig fr3"),
        "{e}"
    );

    tiny_model(d);
    let real = with_real_hand_e_and_camera(&rig);
    assert!(
        real.contains("hand-e") && real.contains("v4l"),
        "the FR3 rig's layout changed"
    );
    std::fs::write(d.join("real.toml"), real).expect("write");
    let calibrate = [
        "grasp",
        "calibrate",
        "--rig",
        "real.toml",
        "--model",
        "air-svae",
        "--object",
        "bottle",
        "--scene",
        "grasp",
    ];
    let out = softtouch(d, &calibrate);
    fails_with(&out, 1, "/dev/softtouch-no-such-port");
    assert!(
        !text(&out.stderr).contains("outside the rig's workspace"),
        "{}",
        text(&out.stderr)
    );
}

/// `rig` with its simulated gripper and finger camera made a real Hand-E and a v4l
/// camera, at a port and a device that are not there.
fn with_real_hand_e_and_camera(rig: &str) -> String {
    rig.replace(
        "[gripper]\ndriver = \"sim\"",
        "[gripper]\ndriver = \"hand-e\"\nport = \"/dev/softtouch-no-such-port\"\nslave_id = 9\n",
    )
    .replace(
        "[camera]\ndriver = \"sim\"",
        "[camera]\ndriver = \"v4l\"\ndevice = \"/dev/softtouch-no-such-camera\"\n",
    )
    .lines()
    // A V4L2 camera runs at its own rate: the simulated camera's `fps` line goes.
    .filter(|l| !l.starts_with("fps = 120.0"))
    .map(|l| format!("{l}\n"))
    .collect()
}
