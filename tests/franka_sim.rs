//! The rig in a box: the real Franka driver (franka-rs over FCI) drives franka-sim, an
//! independent FCI server (PyPI; MuJoCo's FR3), with the robot's motion limits and
//! communication constraints enforced, beside the simulated force sensor and camera
//! (which follow the arm's measured pose), the Hand-E over a pty against the project's
//! Modbus server and the Net F/T server.
//!
//! Wall clock (a real 1 kHz loop), one server per test, one test at a time:
//! `#[ignore]`d, run by `.ci/run` as
//! `cargo test --workspace --release --test end_to_end -- --ignored --test-threads=1 franka_sim::`
//! with `SOFTTOUCH_FRANKA_SIM_PYTHON` set (TESTING.md, the franka-sim tier).

use crate::common;
use crate::fcisim;

use common::{runtime, tempdir, text};
use fcisim::{FrankaSim, LIMITS, SIM_DEVICES, home_in_base, python, rig_toml, wait_until};
use sqlx::Row;
use std::path::Path;
use std::process::{Output, Stdio};
use std::sync::Arc;
use std::time::Duration;

use softtouch_drivers::franka::{FrankaArm, FrankaConfig, MotionLimits};
use softtouch_drivers::{Arm, TokioClock};
use softtouch_schemas::{ArmPose, FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM, Realtime};

/// `softtouch ARGS` in `dir` (database `dir/softtouch.db`).
fn run(dir: &Path, args: &[&str]) -> Output {
    common::command(dir)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run softtouch: {e}"))
}

fn ok(out: &Output, sim: &FrankaSim) -> String {
    assert!(
        out.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}\nfranka-sim:\n{}",
        out.status.code(),
        text(&out.stdout),
        text(&out.stderr),
        sim.log_tail()
    );
    text(&out.stdout)
}

/// The driver's connection to `sim`, as a rig file with `realtime = "ignore"` makes it
/// (at the rigs' default `motion_margin`, 0.3 of the FR3's limits).
async fn connect(sim: &FrankaSim) -> FrankaArm {
    connect_with(sim, MotionLimits::default(), Some(0.3)).await
}

/// The driver's connection to `sim` with `limits`, or with `margin` of the robot's
/// limits where given.
async fn connect_with(sim: &FrankaSim, limits: MotionLimits, margin: Option<f64>) -> FrankaArm {
    let config = FrankaConfig {
        address: sim.address(),
        reflex_force_n: 30.0,
        reflex_torque_nm: 3.0,
        realtime: Realtime::Ignore,
        ne_t_ee: None,
        payload: None,
        joint_torque_thresholds_nm: FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM,
        limits,
        motion_margin: margin,
        route: Vec::new(),
    };
    FrankaArm::connect(config, Arc::new(TokioClock::new()))
        .await
        .unwrap_or_else(|e| panic!("connect: {e}\n{}", sim.log_tail()))
}

/// The arm after a run has let go of it: a new connection reads it, twice 300 ms
/// apart. Returns where it is, and asserts it is still and not in a reflex.
fn still_arm(sim: &FrankaSim) -> ArmPose {
    runtime().block_on(async {
        let mut arm = connect(sim).await;
        let a = arm.state().await.expect("state");
        tokio::time::sleep(Duration::from_millis(300)).await;
        let b = arm.state().await.expect("state");
        let moved = a.base_from_finger.distance_to(&b.base_from_finger);
        assert!(
            moved < 1e-4,
            "the arm still moves: {:.3} mm in 300 ms",
            moved * 1000.0
        );
        assert!(!b.faulted, "the arm is in a reflex");
        b.base_from_finger
    })
}

/// A franka-sim of its own and a folder holding the tier's rig (with `limits`) and
/// scene.
fn tier(limits: &str) -> (tempfile::TempDir, FrankaSim) {
    tier_with(limits, &[])
}

/// [`tier`], with more arguments for the loopback script.
fn tier_with(limits: &str, args: &[&str]) -> (tempfile::TempDir, FrankaSim) {
    let py = python();
    let dir = tempdir();
    let sim = FrankaSim::start_with(&py, dir.path(), args);
    fcisim::write_rig(dir.path(), &rig_toml(&sim.address(), SIM_DEVICES, limits));
    (dir, sim)
}

/// The arm ended at the rigs' home, still; `context` is shown if not.
fn ends_home_and_still(sim: &FrankaSim, context: &str) {
    ends_at_and_still(sim, &home_in_base(), context);
}

/// The arm ended at `home` (base frame), still; `context` is shown if not.
fn ends_at_and_still(sim: &FrankaSim, home: &ArmPose, context: &str) {
    let at = still_arm(sim);
    assert!(
        at.distance_to(home) < 1e-3 && at.angle_to(home) < 1e-2,
        "ended at {at:?}, not at {home:?}\n{context}"
    );
}

struct RunRow {
    status: String,
    events: Vec<(String, String)>,
    /// `(index, status, reject reason, cmd x z θ, meas x z θ, fx fy fz)`.
    samples: Vec<SampleRow>,
}

#[derive(Debug, Clone, PartialEq)]
struct SampleRow {
    index: i64,
    status: String,
    reason: Option<String>,
    cmd: [f64; 3],
    meas: [Option<f64>; 3],
    force_n: [f64; 3],
}

fn stored(db: &Path, run: i64) -> RunRow {
    runtime().block_on(async {
        let store = common::open_store(db).await;
        let status = store.run_record(run).await.expect("run").status;
        let events = store
            .events(run, 10_000)
            .await
            .expect("events")
            .into_iter()
            .map(|e| (e.kind, e.message))
            .collect();
        let samples = sqlx::query(store.dialect().sql(
            "SELECT sample_index, status, reject_reason, cmd_x_m, cmd_z_m, cmd_theta_rad,
                    meas_x_m, meas_z_m, meas_theta_rad, fx_n, fy_n, fz_n
             FROM samples WHERE run_id = ? ORDER BY sample_index",
        ))
        .bind(run)
        .fetch_all(store.pool())
        .await
        .expect("samples")
        .iter()
        .map(|r| SampleRow {
            index: r.get(0),
            status: r.get(1),
            reason: r.get(2),
            cmd: [r.get(3), r.get(4), r.get(5)],
            meas: [r.get(6), r.get(7), r.get(8)],
            force_n: [r.get(9), r.get(10), r.get(11)],
        })
        .collect();
        store.close().await;
        RunRow {
            status,
            events,
            samples,
        }
    })
}

impl RunRow {
    fn kinds(&self, kind: &str) -> Vec<&str> {
        self.events
            .iter()
            .filter(|e| e.0 == kind)
            .map(|e| e.1.as_str())
            .collect()
    }
}

fn count(db: &Path) -> i64 {
    runtime().block_on(common::samples_in(db, 1))
}

/// `collect` of `samples` with the folder's `rig.toml` and `scene.toml`, seed `seed`.
fn collect_args<'a>(samples: &'a str, seed: &'a str) -> [&'a str; 9] {
    [
        "collect",
        "--rig",
        "rig.toml",
        "--scene",
        "scene.toml",
        "--samples",
        samples,
        "--seed",
        seed,
    ]
}

/// Starts `softtouch ARGS` and waits until run 1 holds `at_least` samples.
fn collect_until(dir: &Path, args: &[&str], at_least: i64, sim: &FrankaSim) -> std::process::Child {
    let mut child = common::command(dir)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"));
    let db = dir.join("softtouch.db");
    let reached = wait_until(Duration::from_secs(600), || {
        if let Ok(Some(status)) = child.try_wait() {
            let out = child.wait_with_output_ref();
            panic!(
                "collect ended early ({status}): {out}\nfranka-sim:\n{}",
                sim.log_tail()
            );
        }
        count(&db) >= at_least
    });
    assert!(reached, "no {at_least} samples in 10 minutes");
    child
}

/// What a child that ended printed.
trait OutputOf {
    fn wait_with_output_ref(&mut self) -> String;
}

impl OutputOf for std::process::Child {
    fn wait_with_output_ref(&mut self) -> String {
        use std::io::Read;
        let mut s = String::new();
        if let Some(o) = self.stdout.as_mut() {
            let _ = o.read_to_string(&mut s);
        }
        if let Some(e) = self.stderr.as_mut() {
            let _ = e.read_to_string(&mut s);
        }
        s
    }
}

// ------------------------------------------------------------------- the driver

/// A move whose future is dropped while it waits behind another (a timeout around
/// `move_to`, a cancelled task) must never run: before moves carried a generation, the
/// robot thread cleared the one abort flag as it took the next command, and the
/// cancelled move then ran in full with nobody waiting for it.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_move_cancelled_while_queued_never_reaches_the_robot() {
    let py = python();
    let dir = tempdir();
    let sim = FrankaSim::start(&py, dir.path());
    // At franka-rs's conservative defaults, and at a rig's own limits (0.3 of the
    // FR3's: 2.7 m/s², 900 m/s³), where the moves a night makes run.
    for (limits, margin) in [
        (MotionLimits::default(), None),
        (MotionLimits::default(), Some(0.3)),
    ] {
        eprintln!("limits {limits:?}, margin {margin:?}");
        runtime().block_on(cancelled_while_queued(&sim, limits, margin));
    }
    sim.judge();
}

async fn cancelled_while_queued(sim: &FrankaSim, limits: MotionLimits, margin: Option<f64>) {
    let mut arm = connect_with(sim, limits, margin).await;
    let start = arm.state().await.expect("state").base_from_finger;
    eprintln!("franka-sim starts at {start:?}");
    // A: 5 cm down at 2 cm/s, given up after 400 ms: the robot thread brakes it.
    let mut a = start;
    a.translation_m[2] -= 0.05;
    let r = tokio::time::timeout(Duration::from_millis(400), arm.move_to(&a, 0.02)).await;
    assert!(r.is_err(), "move A ended within 400 ms: {r:?}");
    // B: 5 cm along x, sent while A still brakes and given up at once: it waits in
    // the queue behind A when it is cancelled.
    let mut b = start;
    b.translation_m[0] += 0.05;
    let r = tokio::time::timeout(Duration::from_millis(1), arm.move_to(&b, 0.05)).await;
    assert!(r.is_err(), "move B ended within 1 ms: {r:?}");
    // Long enough for B to have run in full (5 cm at 5 cm/s).
    tokio::time::sleep(Duration::from_secs(3)).await;
    let now = arm.state().await.expect("state").base_from_finger;
    let along_x = now.translation_m[0] - start.translation_m[0];
    assert!(
        along_x.abs() < 0.002,
        "the cancelled move B ran: the arm moved {:.1} mm along x",
        along_x * 1000.0
    );
    let down = start.translation_m[2] - now.translation_m[2];
    assert!(
        down > 0.001 && down < 0.02,
        "A moved {:.1} mm down before it was braked",
        down * 1000.0
    );
    // A brake that met lost cycles may have been aborted (the host's: `judge` holds
    // that a cycle was lost before it); recovered from as a run does.
    if arm.state().await.expect("state").faulted {
        eprintln!("franka-sim aborted the brake: recovering");
        arm.recover().await.expect("recover");
    }
    // The next move is not cancelled by the old ones.
    let back = arm.move_to(&start, 0.05).await.expect("a new move runs");
    assert!(back.base_from_finger.distance_to(&start) < 5e-4);
    assert!(
        back.command_success_rate.is_some_and(|r| r > 0.95),
        "the success rate is sampled during the move: {:?}",
        back.command_success_rate
    );
    // Between moves the robot reports 0 % (libfranka: no control loop runs).
    let idle = arm.state().await.expect("state").command_success_rate;
    assert!(idle.is_some_and(|r| r < 0.5), "{idle:?}");
}

/// A plan broken on purpose (its acceleration and jerk three times the FR3's own
/// Cartesian limits, every check skipped, through the driver's test-only
/// `test_rate_scale`) is caught twice. With the limits enforced, franka-sim aborts it
/// with no cycle lost before: the driver's abort. With them off, the whole signal is
/// recorded and the check of the commanded signal finds it over the limits on its own,
/// whatever the server did and on any host.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_plan_with_rates_past_the_robots_limits_is_caught_by_the_signal_check() {
    use softtouch_drivers::franka::reach::Robot;
    let py = python();
    let broken = MotionLimits {
        test_rate_scale: BROKEN_RATE_SCALE,
        ..MotionLimits::for_robot(Robot::Fr3, 1.0)
    };
    let broken_move = |sim: &FrankaSim| {
        runtime().block_on(async {
            let mut arm = connect_with(sim, broken, None).await;
            let start = arm.state().await.expect("state").base_from_finger;
            let mut to = start;
            to.translation_m[2] -= 0.08;
            arm.move_to(&to, 0.5).await
        })
    };

    let dir = tempdir();
    let enforced = FrankaSim::start(&py, dir.path());
    let moved = broken_move(&enforced);
    assert!(
        moved.is_err(),
        "franka-sim let the broken plan run: {moved:?}"
    );
    let rec = enforced.recorded();
    assert!(!rec.aborts.is_empty(), "no abort recorded");
    assert!(
        rec.aborts.iter().all(|a| !rec.is_the_hosts(a)),
        "the broken plan's abort was put down to the host: {:?} (lost {:?})",
        rec.aborts,
        rec.lost
    );
    eprintln!("enforced: {:?}", rec.aborts);

    let dir = tempdir();
    let open = FrankaSim::start_with(&py, dir.path(), &["--no-enforce"]);
    let moved = broken_move(&open);
    eprintln!("not enforced, the broken move: {moved:?}");
    let rec = open.recorded();
    assert!(rec.aborts.is_empty(), "{:?}", rec.aborts);
    let verdict = rec.judge();
    eprintln!("{}", verdict.table());
    assert!(
        !verdict.holds(),
        "the broken plan passed:\n{}",
        verdict.table()
    );
    let over: Vec<&str> = verdict.over().iter().map(|p| p.what.as_str()).collect();
    assert!(
        over.iter().any(|w| w.contains("translational jerk")),
        "{over:?}"
    );
}

/// How many times the robot's limits the broken plan's acceleration and jerk are.
const BROKEN_RATE_SCALE: f64 = 3.0;

// -------------------------------------------------------------------- rig check

/// A one-worker runtime for the servers a test runs beside the CLI.
fn server_runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime")
}

/// The project's Hand-E Modbus server (slave 9) on `port`, the far end of a pty pair,
/// backed by the simulated gripper; spawned on the runtime it is called within. The
/// handle shares the server's state (its request count).
fn serve_hand_e(port: &str) -> softtouch_drivers::hande::HandEService<softtouch_sim::SimGripper> {
    use softtouch_drivers::hande::{self, HandEService};
    let rig = softtouch_schemas::defaults::rig();
    let scene = softtouch_schemas::defaults::scene();
    let gripper_rig = softtouch_sim::SimRig::new(&rig, &scene, 2, TokioClock::new()).expect("sim");
    let service = HandEService::new(gripper_rig.gripper, 9);
    tokio::spawn(hande::serve_serial(
        service.clone(),
        hande::open_port(port).expect("open pty b"),
        std::future::pending(),
    ));
    service
}

/// `rig check` with every row real but the camera: the Franka on franka-sim, a Net F/T
/// server (the simulated sensor behind the real protocol), the Hand-E's Modbus server
/// over a pty pair. Every row passes, the arm's with the share of real-time commands
/// measured during its move (libfranka reports 0 % once a move has ended).
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn rig_check_passes_every_row_with_the_arm_on_franka_sim() {
    use softtouch_drivers::netft::{NetFtServer, ServerConfig};
    let py = python();
    let pair = fcisim::pty();
    let dir = tempdir();
    let sim = FrankaSim::start(&py, dir.path());
    let rt = server_runtime();
    let rdt = rt.block_on(async {
        let clock = TokioClock::new();
        let rig = softtouch_schemas::defaults::rig();
        let scene = softtouch_schemas::defaults::scene();
        let sensor_rig = softtouch_sim::SimRig::new(&rig, &scene, 1, clock).expect("sim");
        let mut cfg = ServerConfig::at(([127, 0, 0, 1], 0).into());
        cfg.calibration_bind = None;
        let server = NetFtServer::bind(sensor_rig.force_sensor, cfg)
            .await
            .expect("bind");
        let rdt = server.rdt_addr().expect("addr");
        tokio::spawn(server.run(std::future::pending()));
        serve_hand_e(&pair.b);
        rdt
    });
    let devices = format!(
        r#"[force_sensor]
driver = "net-ft"
address = "{rdt}"
rate_hz = 1000.0
counts_per_force = 1000000.0
counts_per_torque = 1000000.0

[camera]
driver = "sim"
fps = 120.0

[gripper]
driver = "hand-e"
port = "{}"
slave_id = 9
"#,
        pair.a
    );
    fcisim::write_rig(dir.path(), &rig_toml(&sim.address(), &devices, LIMITS));
    let out = run(
        dir.path(),
        &["rig", "check", "--rig", "rig.toml", "--scene", "scene.toml"],
    );
    let table = ok(&out, &sim);
    for row in ["host", "arm", "force_sensor", "camera", "gripper"] {
        assert!(
            table.lines().any(|l| l.trim_start().starts_with(row)),
            "no {row} row:\n{table}"
        );
    }
    let arm_row = table
        .lines()
        .find(|l| l.trim_start().starts_with("arm"))
        .unwrap_or_default();
    assert!(arm_row.contains("% of real-time commands"), "{arm_row}");
    assert!(arm_row.contains("mode at connect: Idle"), "{arm_row}");
    eprintln!("{table}");
    drop(rt);
    sim.judge();
}

/// The FR3 rig a lab gets from `config show rig fr3`, as a lab edits it for a grasp:
/// `config check` passes it as shown; with the arm's two lines set for this host
/// (franka-sim's address, `realtime = "ignore"`: no PREEMPT_RT kernel here) and the
/// gripper on the Hand-E's pty, `rig check` passes with the arm on franka-sim; with
/// the gripper and the camera set (two edits) `grasp calibrate --rig` reads the
/// Hand-E's status over the pty and stops at the camera this host lacks, naming it,
/// having moved nothing and stored nothing.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn the_fr3_rig_from_config_show_passes_rig_check_and_reaches_the_grasp_devices() {
    let py = python();
    let pair = fcisim::pty();
    let dir = tempdir();
    let sim = FrankaSim::start(&py, dir.path());
    let rt = server_runtime();
    let service = rt.block_on(async { serve_hand_e(&pair.b) });
    let shown = ok(&run(dir.path(), &["config", "show", "rig", "fr3"]), &sim);
    std::fs::write(dir.path().join("fr3.toml"), &shown).expect("write");
    ok(
        &run(dir.path(), &["config", "check", "--rig", "fr3.toml"]),
        &sim,
    );
    let edit = |text: &str, from: &str, to: &str| -> String {
        assert_eq!(text.matches(from).count(), 1, "`{from}` once in:\n{text}");
        text.replace(from, to)
    };
    let gripper = |text: &str| {
        edit(
            text,
            "driver = \"sim\"            # or \"hand-e\"",
            &format!("driver = \"hand-e\"\nport = \"{}\"\nslave_id = 9 #", pair.a),
        )
    };
    // The arm as this host reaches it, and the gripper on the pty: every row passes.
    let arm = edit(
        &edit(&shown, "172.16.0.2", &sim.address()),
        "# realtime = \"ignore\"",
        "realtime = \"ignore\"",
    );
    std::fs::write(dir.path().join("checked.toml"), gripper(&arm)).expect("write");
    let table = ok(
        &run(dir.path(), &["rig", "check", "--rig", "checked.toml"]),
        &sim,
    );
    for row in ["arm", "gripper"] {
        let line = table
            .lines()
            .find(|l| l.trim_start().starts_with(row))
            .unwrap_or_default();
        assert_eq!(
            line.split_whitespace().nth(2),
            Some("pass"),
            "{row}: {table}"
        );
    }
    // The grasp's two edits: the gripper's section and the finger camera's (a V4L2
    // camera runs at its own rate: no `fps`).
    let absent = dir.path().join("video-absent");
    let grasp = edit(
        &gripper(&shown),
        "driver = \"sim\"            # or \"v4l\" with device = \"/dev/video0\"\nfps = 120.0               # the simulated camera's rate (a \"v4l\" camera has its own: no fps)",
        &format!("driver = \"v4l\"\ndevice = \"{}\"", absent.display()),
    );
    std::fs::write(dir.path().join("grasp.toml"), grasp).expect("write");
    common::simulated_dataset(dir.path(), "64", "3", "air");
    let mut train = vec!["train", "--dataset", "air"];
    train.extend(common::TINY);
    ok(&run(dir.path(), &train), &sim);
    let before = service.requests();
    let out = run(
        dir.path(),
        &[
            "grasp",
            "calibrate",
            "--rig",
            "grasp.toml",
            "--model",
            "air-svae",
            "--object",
            "cylinder",
        ],
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}\n{}", text(&out.stdout));
    assert!(
        err.contains("camera") && err.contains(&absent.display().to_string()),
        "the refusal names the camera and its device: {err}"
    );
    assert!(
        service.requests() > before,
        "the Hand-E's status was read over the pty before the camera: {err}"
    );
    let stored: i64 = runtime().block_on(async {
        use sqlx::Connection as _;
        let url = format!(
            "sqlite://{}?mode=ro",
            dir.path().join("softtouch.db").display()
        );
        let mut conn = sqlx::SqliteConnection::connect(&url).await.expect("db");
        sqlx::query_scalar("SELECT COUNT(*) FROM grasp_calibrations")
            .fetch_one(&mut conn)
            .await
            .expect("count")
    });
    assert_eq!(stored, 0, "nothing stored");
    eprintln!("{table}\n{err}");
    drop(rt);
    sim.judge();
}

// ---------------------------------------------------------------------- collect

/// A few dozen samples on one rod through FCI, killed (-9) mid-run and resumed with
/// the robot left in reflex (the loopback's second connection finds it so, as a client
/// that died mid-motion leaves a robot; in reflex it refuses every setting): connect
/// recovers it first, the resume completes, every index once, the commanded poses
/// those the simulated arm is sent for the seed, the arm measured where it was sent,
/// and the labels those the simulated arm gives.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn collect_killed_and_resumed_on_franka_sim_poses_as_the_simulated_arm() {
    let (dir, sim) = tier_with(LIMITS, &["--reflex-on-connect", "2"]);
    let samples = "24";
    let args = collect_args(samples, "11");
    let t0 = std::time::Instant::now();
    let mut child = collect_until(dir.path(), &args, 8, &sim);
    let _ = child.kill(); // SIGKILL, mid-sample wherever it is
    let _ = child.wait();
    let db = dir.path().join("softtouch.db");
    let before = count(&db);
    assert!((8..24).contains(&before), "{before}");
    let out = run(dir.path(), &["collect", "--resume", "1"]);
    ok(&out, &sim);
    let wall_s = t0.elapsed().as_secs_f64();
    let franka = stored(&db, 1);
    assert_eq!(franka.status, "completed");
    assert_eq!(
        franka.samples.iter().map(|s| s.index).collect::<Vec<_>>(),
        (0..24).collect::<Vec<_>>()
    );
    let recovered = franka.kinds("arm_recovered");
    assert!(
        recovered
            .iter()
            .any(|m| m.contains("at connect: Reflex with errors; automatic error recovery run")),
        "the resume found the robot in reflex and recovered it: {:?}",
        franka.events
    );
    eprintln!(
        "franka-sim: 24 samples (killed at {before}, resumed) in {wall_s:.0} s wall: {:.0} samples/h",
        24.0 * 3600.0 / wall_s
    );
    // The same seed on the simulated arm.
    let sim_dir = tempdir();
    fcisim::write_rig(sim_dir.path(), &rig_toml(&sim.address(), SIM_DEVICES, LIMITS).replace(
            &format!(
                "driver = \"franka\"\naddress = \"{}\"\nreflex_force_n = 30.0\nrealtime = \"ignore\"\n# A rig's own share of the FR3's limits (the default, said): 2.7 m/s², 900 m/s³.\nmotion_margin = 0.3",
                sim.address()
            ),
            "driver = \"sim\"\nreflex_force_n = 30.0",
        ));
    let out = run(sim_dir.path(), &collect_args(samples, "11"));
    ok(&out, &sim);
    let simulated = stored(&sim_dir.path().join("softtouch.db"), 1);
    assert_eq!(simulated.status, "completed");
    for (f, s) in franka.samples.iter().zip(&simulated.samples) {
        assert_eq!(
            f.cmd.map(f64::to_bits),
            s.cmd.map(f64::to_bits),
            "sample {}: the commanded pose, bit for bit",
            f.index
        );
        assert_eq!(f.status, "ok", "sample {}: {:?}", f.index, f.reason);
        // Where the arm was measured once settled: where it was sent.
        let meas = f.meas.map(|v| v.expect("measured"));
        assert!(
            (meas[0] - f.cmd[0]).abs() < 5e-4
                && (meas[1] - f.cmd[1]).abs() < 5e-4
                && (meas[2] - f.cmd[2]).abs() < 5e-3,
            "sample {}: sent to {:?}, measured at {meas:?}",
            f.index,
            f.cmd
        );
        // The simulated sensor followed the real arm: the label is the simulated
        // arm's, up to the arm's tracking error.
        for axis in 0..3 {
            let (a, b) = (f.force_n[axis], s.force_n[axis]);
            assert!(
                (a - b).abs() <= 0.25 + 0.15 * b.abs(),
                "sample {} axis {axis}: {a} N on franka-sim, {b} N on the simulated arm",
                f.index
            );
        }
    }
    assert!(
        franka
            .samples
            .iter()
            .any(|s| s.force_n[0].abs() + s.force_n[2].abs() > 0.2),
        "no sample pressed the rod: {:?}",
        franka.samples.first()
    );
    sim.judge();
    ends_home_and_still(&sim, "");
}

/// The tier's rig and scene widened to nearly the largest wrist turn the FR3's joint 7
/// allows (θ within ±2.6 rad, the rod frame turned so that θ = 0 is joint 7 near -0.2
/// rad, its range ±3.02 rad: the robot's own inverse kinematics may take the wrist
/// further than the reach check's), approaching at 0.2 m/s, with the visiting order
/// `order`.
fn wide(rig: &str, order: &str) -> (String, String) {
    let rig = rig
        .replace("theta_rad = [-0.4, 0.4]", "theta_rad = [-2.6, 2.6]")
        .replace(
            "rotation_wxyz = [0.0, 0.9238795325112867, -0.3826834323650898, 0.0]",
            "rotation_wxyz = [0.0, 1.0, 0.0, 0.0]",
        )
        // A rig that approaches at 0.2 m/s (the last 3 mm still at 0.02 m/s).
        .replace("approach_speed_m_s = 0.05", "approach_speed_m_s = 0.2")
        .replace(
            "max_consecutive_failures = 10\n",
            &format!("max_consecutive_failures = 10\nvisit_order = \"{order}\"\n"),
        );
    let scene = fcisim::SCENE.replace("theta_rad = [-0.4, 0.4]", "theta_rad = [-2.6, 2.6]");
    (rig, scene)
}

/// Samples of the pace check: `SOFTTOUCH_FRANKA_SIM_SAMPLES`, 40 unless set (1 000 for
/// the night's check, TESTING.md).
fn pace_samples() -> u64 {
    std::env::var("SOFTTOUCH_FRANKA_SIM_SAMPLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(40)
}

/// `softtouch collect` of `samples` on `rig` and `scene` in a folder of its own:
/// `(wall seconds, stdout, the run as stored)`.
fn timed_collect(sim: &FrankaSim, rig: &str, scene: &str, samples: u64) -> (f64, String, RunRow) {
    let dir = tempdir();
    std::fs::write(dir.path().join("rig.toml"), rig).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap_or_else(|e| panic!("{e}"));
    let n = samples.to_string();
    let t0 = std::time::Instant::now();
    let out = run(dir.path(), &collect_args(&n, "5"));
    let stdout = ok(&out, sim);
    let wall_s = t0.elapsed().as_secs_f64();
    (wall_s, stdout, stored(&dir.path().join("softtouch.db"), 1))
}

/// Where a sample's time goes on the Franka path, and the pace of a planned run over
/// the widest wrist turn the FR3 allows: the planned order at the robot's speeds
/// takes every sample with no motion aborted by franka-sim's enforced limits while
/// every command arrived (an abort after lost cycles is the host's, recovered), and
/// spends less than half the robot's motion time a sample that index order does (every
/// sample from home, wrist turns of up to 5.2 rad). Motion time is the commands the
/// driver sent, one per 1 ms cycle, so a busy host does not move the verdict (wall
/// time did: 1.92 times beside a busy loop). Prints both phase tables (`--nocapture`).
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_planned_run_on_franka_sim_turns_the_wrist_little_and_breaks_no_limit() {
    let (_dir, sim) = tier(LIMITS);
    let n = pace_samples();
    let base = rig_toml(&sim.address(), SIM_DEVICES, LIMITS);
    let (rig, scene) = wide(&base, "planned");
    let (wall_s, stdout, planned) = timed_collect(&sim, &rig, &scene, n);
    eprintln!("franka-sim, planned order, {n} samples in {wall_s:.1} s wall:\n{stdout}");
    assert_eq!(planned.status, "completed");
    assert_eq!(planned.samples.len() as u64, n);
    let rejected: Vec<_> = planned
        .samples
        .iter()
        .filter(|s| s.status != "ok")
        .collect();
    assert!(rejected.is_empty(), "{rejected:?}");
    assert_eq!(
        planned.kinds("phase_times").len(),
        1,
        "{:?}",
        planned.events
    );
    assert_eq!(planned.kinds("visit_plan").len(), 1, "{:?}", planned.events);
    // An abort while commands were lost is the host's luck (franka-sim misses cycles on
    // 2 cores; the recovery then resets the elbow once more); one with every command
    // arrived is the driver's plan, and fails the tier.
    for fault in planned.kinds("arm_fault") {
        let rate = fault
            .split("control_command_success_rate: ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|r| r.parse::<f64>().ok());
        assert!(
            rate.is_some_and(|r| r < 1.0),
            "an abort with every command arrived: {fault}"
        );
    }
    let elbow = planned.kinds("elbow");
    eprintln!("the elbow: {elbow:?}");
    let at_block_end = elbow
        .iter()
        .filter(|m| m.starts_with("block's end"))
        .count();
    assert_eq!(at_block_end, 1, "{:?}", planned.events);
    // The widened rig's rod frame (turned 180° about x).
    let wide_rod = ArmPose {
        translation_m: [0.58, 0.0, 0.6],
        rotation_wxyz: [0.0, 1.0, 0.0, 0.0],
    };
    assert!(departures_hold(&sim, &wide_rod) >= n as usize);
    let planned_cycles = sim.judge().verdict.commands;
    // Home in the widened rig's rod frame (turned 180° about x).
    let home = ArmPose::from_contact(
        &ArmPose {
            translation_m: [0.58, 0.0, 0.6],
            rotation_wxyz: [0.0, 1.0, 0.0, 0.0],
        },
        &softtouch_schemas::ContactPose {
            x_m: -0.03,
            z_m: 0.0,
            theta_rad: 0.0,
        },
    );
    ends_at_and_still(&sim, &home, &stdout);

    // A few samples in index order, for the comparison.
    let (rig, scene) = wide(&base, "index");
    let few = 6.min(n);
    let (index_wall_s, stdout, index) = timed_collect(&sim, &rig, &scene, few);
    eprintln!("franka-sim, index order, {few} samples in {index_wall_s:.1} s wall:\n{stdout}");
    assert_eq!(index.status, "completed");
    let index_cycles = sim.judge().verdict.commands - planned_cycles;
    let (planned_s, index_s) = (
        planned_cycles as f64 / 1000.0 / n as f64,
        index_cycles as f64 / 1000.0 / few as f64,
    );
    eprintln!(
        "motion a sample: planned {planned_s:.2} s, index order {index_s:.2} s; wall a sample: planned {:.2} s, index order {:.2} s",
        wall_s / n as f64,
        index_wall_s / few as f64
    );
    assert!(
        index_s > 2.0 * planned_s,
        "motion a sample: planned {planned_s:.2} s, index order {index_s:.2} s"
    );
}

// ------------------------------------------------------------------- safe exits

/// The force guard trips on the approach (a limit below the first contact's force),
/// on every sample, across a block's end (two blocks of two), at the tier's approach
/// speed (0.05 m/s) and at 0.2 m/s: every attempt is stopped within
/// [`GUARD_STOP_BOUND_M`] of where the arm was at the trip, every sample is rejected
/// for the force limit, the run completes at home; and every departure from the rod
/// in the commands the driver sent runs straight back along the approach axis, with
/// no turn, to the retreat plane (the table is printed: `--nocapture`).
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_force_guard_trip_on_franka_sim_stops_the_arm_and_rejects_the_sample() {
    // 0.3 N: 24 σ of the Nano17's noise (never tripped by it, where 0.05 N was, on
    // fast travel legs), well below the first contact's force.
    let (dir, sim) = tier("max_force_n = 0.3\nmax_torque_nm = 0.8");
    let mut stops = Vec::new();
    for (run_id, speed) in [(1, "0.05"), (2, "0.2")] {
        let rig = std::fs::read_to_string(dir.path().join("rig.toml")).expect("rig");
        let rig = rig.replace(
            "approach_speed_m_s = 0.05",
            &format!("approach_speed_m_s = {speed}"),
        );
        std::fs::write(dir.path().join("rig.toml"), rig).expect("rig");
        let mut args = collect_args("4", "3").to_vec();
        args.extend(["--block", "2"]);
        let out = run(dir.path(), &args);
        let said = format!("{}{}", text(&out.stdout), text(&out.stderr));
        let s = stored(&dir.path().join("softtouch.db"), run_id);
        assert_eq!(s.status, "completed", "{:?}\n{said}", s.events);
        assert_eq!(s.samples.len(), 4, "{:?}", s.samples);
        assert!(
            s.samples
                .iter()
                .all(|x| x.status != "ok" && x.reason.as_deref() == Some("force_limit")),
            "{:?}",
            s.samples
        );
        let trips = s.kinds("force_limit");
        eprintln!("guard trips at {speed} m/s: {trips:#?}");
        let elbow = s.kinds("elbow");
        eprintln!("the elbow at each block's end: {elbow:#?}");
        assert_eq!(elbow.len(), 2, "one per block's end: {:?}", s.events);
        assert!(
            trips.len() >= 4,
            "a trip per sample: {:?}\n{said}",
            s.events
        );
        let bound_mm = guard_stop_bound_m(speed.parse().expect("a speed")) * 1000.0;
        for trip in &trips {
            let mm = stopped_after_mm(trip)
                .unwrap_or_else(|| panic!("a trip without where the arm came to rest: {trip}"));
            assert!(
                mm <= bound_mm,
                "the arm came to rest {mm} mm past the trip (bound {bound_mm:.2} mm): {trip}"
            );
            stops.push((speed, mm));
        }
        ends_home_and_still(&sim, &said);
    }
    for speed in ["0.05", "0.2"] {
        let mm: Vec<f64> = stops.iter().filter(|s| s.0 == speed).map(|s| s.1).collect();
        eprintln!(
            "guard stopping distance at {speed} m/s: {} trips, {:.2}-{:.2} mm",
            mm.len(),
            mm.iter().copied().fold(f64::INFINITY, f64::min),
            mm.iter().copied().fold(0.0, f64::max)
        );
    }
    // The verdict first: it prints the aborts the departures are measured around.
    sim.judge();
    let ds = departures_hold(&sim, &fcisim::base_from_rod());
    assert!(ds >= 8, "a departure per trip: {ds}");
}

/// Every departure from the rod in the commands the driver sent runs straight back
/// along the approach axis to the retreat plane: at most 0.02 rad of turn and 10° off
/// the axis (the table is printed: `--nocapture`). How many departures.
fn departures_hold(sim: &FrankaSim, base_from_rod: &ArmPose) -> usize {
    // Cartesian commands (a joint-space move of the elbow, at home, starts and ends
    // there).
    let rec = sim.recorded();
    let cartesian: Vec<_> = rec
        .commands
        .iter()
        .filter(|c| c.q_commanded.is_none())
        .collect();
    let poses: Vec<ArmPose> = cartesian.iter().map(|c| c.pose).collect();
    // The first command of each motion: a motion starts from the pose the robot reports
    // as last commanded (`O_T_EE_c`, which libfranka's first command must equal), and
    // franka-sim's is not always the driver's last command (after an abort the robot
    // stopped off it by its tracking error; seen too, on a busy host, between two
    // motions with no abort: 1.8 mrad and a few hundredths of a millimetre). That jump
    // is the server's report, not a way the driver sent: each motion's path is
    // measured from its own start. A motion begins where the cycle ids jump with no
    // lost cycle (cycles the server closed unanswered) in between: the idle between
    // motions.
    let lost_between = |a: u64, b: u64| rec.lost.iter().any(|&id| a < id && id < b);
    let restarts: Vec<usize> = (1..cartesian.len())
        .filter(|&j| {
            let (a, b) = (cartesian[j - 1].message_id, cartesian[j].message_id);
            b > a + 1 && !lost_between(a, b)
                || rec.aborts.iter().any(|x| a <= x.at_id && x.at_id < b)
        })
        .collect();
    eprintln!(
        "departures: {} motions, each measured from its own first command",
        restarts.len() + 1
    );
    // The tier's scene samples x from 0 (within reach of the rod from 5 mm before) and
    // z within ±50 mm.
    // The retreat plane of the tier's rig (home at x = −0.03 m, the default stand-off).
    let plane_x_m = softtouch_collector::collect::retreat_x_m(
        -0.03,
        &softtouch_schemas::defaults::rig().procedure,
    );
    let ds = fcisim::departures::departures(
        &poses,
        &restarts,
        base_from_rod,
        plane_x_m,
        -0.005,
        (-0.06, 0.06),
    );
    eprintln!(
        "departures from the rod (commanded):\n{}",
        fcisim::departures::table(&ds)
    );
    for d in &ds {
        assert!(d.reached_plane, "{d:?}");
        if d.turn_to_plane_rad > 0.02 || d.side_to_plane_deg > 10.0 {
            // Its first commands, relative to where it began (the rod frame), for the
            // failure's message.
            let rod_from_base = base_from_rod.inverse();
            let start = rod_from_base.compose(&poses[d.start_index]);
            let around: Vec<String> = (d.start_index.saturating_sub(5)
                ..(d.start_index + 80).min(poses.len()))
                .step_by(3)
                .map(|j| {
                    let p = rod_from_base.compose(&poses[j]);
                    let t: Vec<String> = (0..3)
                        .map(|i| {
                            format!(
                                "{:+.4}",
                                (p.translation_m[i] - start.translation_m[i]) * 1e3
                            )
                        })
                        .collect();
                    format!(
                        "{j}: {} mm, turn {:.2e} rad",
                        t.join(" "),
                        start.angle_to(&p)
                    )
                })
                .collect();
            panic!(
                "a departure that turns or drags: {d:?}\nits commands from 5 before:\n{}",
                around.join("\n")
            );
        }
    }
    ds.len()
}

/// How far past the trip an approach at `speed_m_s` may carry the arm: the brake's
/// stopping distance at the tier's limits (an FR3 at margin 0.3: the move's 2.7 m/s²
/// and 900 m/s³), its acceleration taken down to the joints' share ([`RATE_MARGIN`]:
/// on the tier's approach the joints hold the move and its brake to about half), and
/// [`GUARD_REACTION_M`] for the guard's reaction (a window of readings, the pose
/// feed's age): about 4 mm from 0.05 m/s, 18 mm from 0.2 m/s.
///
/// [`RATE_MARGIN`]: softtouch_drivers::franka::reach::RATE_MARGIN
fn guard_stop_bound_m(speed_m_s: f64) -> f64 {
    use softtouch_drivers::franka::reach;
    let l = MotionLimits::for_robot(reach::Robot::Fr3, 0.3);
    MotionLimits {
        brake_accel_m_s2: l.brake_accel_m_s2 * reach::RATE_MARGIN,
        ..l
    }
    .stopping_distance_m(speed_m_s)
        + GUARD_REACTION_M
}

/// What the guard's reaction may add to the brake's stopping distance, m.
const GUARD_REACTION_M: f64 = 0.003;

/// The distance a `force_limit` event says the arm came to rest from the trip, mm.
fn stopped_after_mm(message: &str) -> Option<f64> {
    let rest = message.split("came to rest ").nth(1)?;
    rest.split(" mm").next()?.trim().parse().ok()
}

/// SIGTERM mid-run: the sample in hand finishes, the arm goes home, the run is
/// `stopped` (exit 0).
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn sigterm_on_franka_sim_finishes_the_sample_and_leaves_the_arm_home() {
    let (dir, sim) = tier(LIMITS);
    let child = collect_until(dir.path(), &collect_args("200", "4"), 2, &sim);
    common::signal(&child, "TERM");
    let out = child.wait_with_output().expect("wait");
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        text(&out.stderr)
    );
    let s = stored(&dir.path().join("softtouch.db"), 1);
    assert_eq!(s.status, "stopped");
    let n = s.samples.len();
    let mut first: Vec<i64> = plan_order(4, 200).into_iter().take(n).collect();
    first.sort_unstable();
    assert_eq!(
        s.samples.iter().map(|x| x.index).collect::<Vec<_>>(),
        first,
        "no gap: the plan's first {n} samples"
    );
    assert!(
        s.kinds("stopped")
            .iter()
            .any(|m| m.contains("stopped by the operator")),
        "{:?}",
        s.events
    );
    sim.judge();
    assert!(
        departures_hold(&sim, &fcisim::base_from_rod()) >= n,
        "a departure per sample"
    );
    ends_home_and_still(&sim, "");
}

/// The order a run of `samples` samples with `seed` on the tier's rig and scene (one
/// rod, one block) visits its indices.
fn plan_order(seed: u64, samples: u64) -> Vec<i64> {
    use softtouch_collector::collect::{route, sampler};
    use softtouch_schemas::config::{ConfigSource, parse_toml};
    let scene: softtouch_schemas::SceneSpec =
        parse_toml(fcisim::SCENE, &ConfigSource::Embedded("tier scene")).expect("scene");
    let rods = sampler::RodSchedule::new(vec!["circle-10".into()], samples).expect("rods");
    let poses = sampler::PoseSampler::new(seed, scene.poses.clone());
    route::visits(
        softtouch_schemas::rig::VisitOrder::Planned,
        &poses,
        &scene.poses,
        &rods,
        samples,
        0..samples,
    )
    .into_iter()
    .flat_map(|v| v.todo)
    .map(|i| i64::try_from(i).expect("index"))
    .collect()
}

/// The store fails mid-run (inserts refused from index 2, as a full disk): a safe stop,
/// the arm home and still, the run `failed`, nothing stored from the plan's first index
/// of 2 or more on.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_store_failure_on_franka_sim_ends_in_a_safe_stop_at_home() {
    let (dir, sim) = tier(LIMITS);
    let db = dir.path().join("softtouch.db");
    ok(&run(dir.path(), &["db", "init"]), &sim);
    runtime().block_on(async {
        let store = common::open_store(&db).await;
        sqlx::raw_sql(sqlx::AssertSqlSafe(common::fail_inserts_from(2)))
            .execute(store.pool())
            .await
            .expect("trigger");
        store.close().await;
    });
    let out = run(dir.path(), &collect_args("6", "5"));
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let s = stored(&db, 1);
    assert_eq!(s.status, "failed");
    // What the plan visits before its first index from 2 on.
    let mut before_failure: Vec<i64> = plan_order(5, 6)
        .into_iter()
        .take_while(|&i| i < 2)
        .collect();
    before_failure.sort_unstable();
    assert_eq!(
        s.samples.iter().map(|x| x.index).collect::<Vec<_>>(),
        before_failure
    );
    assert!(
        s.kinds("safe_stop")
            .iter()
            .any(|m| m.contains("the store failed")),
        "{:?}",
        s.events
    );
    sim.judge();
    assert!(departures_hold(&sim, &fcisim::base_from_rod()) >= s.samples.len());
    ends_home_and_still(&sim, "");
}

/// The robot's connection is lost mid-run (the server killed): the run ends in a safe
/// stop, marked `failed` with the link named, exit 1, well before the run would end.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_lost_robot_connection_ends_the_run_in_a_safe_stop() {
    let (dir, mut sim) = tier(LIMITS);
    let child = collect_until(dir.path(), &collect_args("200", "6"), 1, &sim);
    // Mid-move: samples are mostly moves.
    std::thread::sleep(Duration::from_millis(700));
    sim.kill();
    let t0 = std::time::Instant::now();
    let out = child.wait_with_output().expect("wait");
    assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let s = stored(&dir.path().join("softtouch.db"), 1);
    assert_eq!(s.status, "failed", "{:?}", s.events);
    let stops = s.kinds("safe_stop");
    assert!(
        stops.iter().any(|m| m.contains("franka")
            && (m.contains("link failed") || m.contains("no answer"))),
        "the safe stop does not name the robot's link: {:?}",
        s.events
    );
    eprintln!("safe stop: {stops:?}");
    // What the driver sent up to the kill (franka-sim cannot show where a robot that
    // lost its client stops: it goes idle; TESTING.md).
    sim.judge();
}

// ------------------------------------------------------------- grasp trials --rig

/// The arm of `grasp trials --rig` through FCI: every move goes to franka-sim first,
/// and once the arm got there the simulated grasp world is told the same move (its
/// physics decides what the fingers hold). The arm's state is the robot's.
struct ThroughFci {
    real: FrankaArm,
    world: softtouch_sim::SoftGraspArm,
}

#[async_trait::async_trait]
impl Arm for ThroughFci {
    async fn move_to(
        &mut self,
        target: &ArmPose,
        speed_m_s: f64,
    ) -> Result<softtouch_drivers::ArmState, softtouch_drivers::DeviceError> {
        let reached = self.real.move_to(target, speed_m_s).await?;
        self.world.move_to(target, speed_m_s).await?;
        Ok(reached)
    }
    async fn state(
        &mut self,
    ) -> Result<softtouch_drivers::ArmState, softtouch_drivers::DeviceError> {
        self.real.state().await
    }
    async fn recover(&mut self) -> Result<(), softtouch_drivers::DeviceError> {
        self.real.recover().await?;
        self.world.recover().await
    }
    async fn stop(&mut self) -> Result<(), softtouch_drivers::DeviceError> {
        let real = self.real.stop().await;
        let world = self.world.stop().await;
        real.and(world)
    }
}

/// `grasp trials --rig`'s library path with the arm through FCI: two open-loop and two
/// closed-loop trials of the cylinder, the Hand-E over a pty against the project's
/// Modbus server (watchdog armed) backed by the soft-finger gripper, the finger's
/// simulated camera, K from a calibration made over the pty. The FR3 lifts and sets
/// down every trial at the rig's grasp poses; the session ends at the safe pose, the
/// arm still, the fingers open, no motion aborted by the robot.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
async fn grasp_trials_on_the_rig_lift_and_set_down_through_fci() {
    use common::hand_e_rig::{HandERig, calibrated_hand_e};
    use softtouch_grasp::OperatorInput;
    use softtouch_lab::grasp::trials::rig::{
        Operator, RigTrialDevices, run_rig_trials, start_rig_session,
    };
    use softtouch_lab::grasp::trials::{RunEnd, TrialPlan, load_scenes};
    use softtouch_schemas::Medium;
    use softtouch_schemas::rig::{GraspObjectSetup, GraspSetup};
    use softtouch_sim::{GraspObject, SoftGraspArm};
    use softtouch_store::Store;

    const MODEL: &str = "air-svae";
    const OBJECT: &str = "cylinder";
    let py = python();
    let dir = tempdir();
    let d = dir.path();
    tokio::task::block_in_place(|| common::tiny_model(d));
    let pair = fcisim::pty();
    let sim = FrankaSim::start(&py, d);

    let db = d.join("softtouch.db");
    let store = Store::open(&db).await.expect("store");
    let bytes = softtouch_lab::models::force_artifact(&store, MODEL)
        .await
        .expect("model");
    let scene = load_scenes(&[], &[]).expect("scenes").remove(0);
    let object = GraspObject::from_spec(scene.object(OBJECT).expect("cylinder"));
    // The gripper as the FR3's flange points at franka-sim's home keyframe (down,
    // turned 45° about its axis), in front of the robot.
    let down = [0.0, 0.923_879_532_511_286_7, -0.382_683_432_365_089_8, 0.0];
    let grasp_at = [0.5, 0.0, 0.35];
    let safe_at = [0.5, 0.0, 0.45];
    let mut rig = softtouch_schemas::defaults::rig();
    rig.arm = softtouch_schemas::rig::ArmDevice::Franka {
        address: sim.address(),
        reflex_force_n: 30.0,
        reflex_torque_nm: None,
        realtime: Realtime::Ignore,
        end_effector: None,
        payload: None,
        joint_torque_thresholds_nm: None,
        motion_margin: None,
    };
    rig.workspace.reach_in_base_m = [
        softtouch_schemas::Range::new(0.25, 0.75),
        softtouch_schemas::Range::new(-0.2, 0.2),
        softtouch_schemas::Range::new(0.1, 0.8),
    ];
    rig.gripper = softtouch_schemas::rig::GripperDevice::HandE {
        port: pair.a.clone(),
        slave_id: 9,
    };
    rig.grasp = Some(GraspSetup {
        medium: Medium::Air,
        safe_pose: ArmPose {
            translation_m: safe_at,
            rotation_wxyz: down,
        },
        approach_height_m: 0.04,
        speed_m_s: 0.2,
        objects: vec![GraspObjectSetup {
            name: OBJECT.into(),
            base_from_grasp: ArmPose {
                translation_m: grasp_at,
                rotation_wxyz: down,
            },
            open_width_mm: object.width_m * 1000.0 - 8.0,
            lift_mm: 20.0,
            place: None,
        }],
    });

    // The soft grasp behind the Hand-E server; the calibration over the pty.
    let HandERig {
        hand_e,
        camera,
        handle,
        service,
        clock,
        shared,
        // Held to the end: the server stops when it is dropped.
        server_stop: _server_stop,
        ..
    } = calibrated_hand_e(
        &pair,
        &scene,
        (OBJECT, &object),
        (MODEL, &bytes),
        &rig,
        &store,
    )
    .await;

    // The arm: the real driver on franka-sim, the grasp world told every move.
    let real = connect(&sim).await;
    let world = SoftGraspArm::new(
        handle.clone(),
        clock,
        ArmPose {
            translation_m: grasp_at,
            rotation_wxyz: down,
        },
        ArmPose {
            translation_m: safe_at,
            rotation_wxyz: down,
        },
    );
    handle.set_object(false).expect("clear");
    let mut devices = RigTrialDevices {
        arm: Arc::new(tokio::sync::Mutex::new(
            Box::new(ThroughFci { real, world }) as Box<dyn Arm>,
        )),
        gripper: hand_e,
        camera,
        clock: shared.clone(),
    };
    let plan = TrialPlan {
        objects: vec![OBJECT.into()],
        modes: vec!["open".into(), "closed".into()],
        trials: 2,
        sigmas_mm: vec![2.0],
        fps: 30.0,
        confirm_s: 0.1,
        close_timeout_s: 1.5,
        hold_s: 0.2,
        ..TrialPlan::default()
    };
    let session = start_rig_session(&store, MODEL, 3, plan, &rig)
        .await
        .expect("starts");
    let mut operator = Operator {
        // Enter at each "set the object in its place" (and to spare).
        input: OperatorInput::from_reader(std::io::Cursor::new(b"\n".repeat(16))),
        output: Box::new(std::io::sink()),
        confirm_verdicts: false,
    };
    let (_never, no_stop) = tokio::sync::watch::channel(0u32);
    let todo = session.progress(&store).await.expect("progress").todo;
    let t0 = std::time::Instant::now();
    let end = run_rig_trials(
        &store,
        &session,
        &mut devices,
        &mut operator,
        &todo,
        &no_stop,
        &mut |_| Ok(()),
    )
    .await
    .unwrap_or_else(|e| panic!("{e}\nfranka-sim:\n{}", sim.log_tail()));
    assert_eq!(end, RunEnd::Completed);
    let rows = store.grasp_trials(session.id).await.expect("rows");
    for r in &rows {
        eprintln!(
            "{} #{}: {} (final {:.1} mm, {:.2} s)",
            r.key.mode,
            r.key.trial,
            r.reason.as_deref().unwrap_or("held"),
            r.final_width_m * 1e3,
            r.wall_s
        );
    }
    eprintln!(
        "4 rig trials through FCI in {:.0} s",
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().any(|r| r.success), "nothing held: {rows:?}");
    assert_eq!(service.watchdog_faults(), 0, "the Hand-E was kept alive");
    let s = devices.arm.lock().await.state().await.expect("state");
    let safe = ArmPose {
        translation_m: safe_at,
        rotation_wxyz: down,
    };
    assert!(
        s.base_from_finger.distance_to(&safe) < 1e-3,
        "ended at {:?}",
        s.base_from_finger
    );
    let status = devices.gripper.status().await.expect("status");
    assert!(status.position <= 5, "fingers at count {}", status.position);
    drop(devices);
    sim.judge();
    store.close().await;
}

/// A rig whose workspace the arm cannot reach within the FR3's limits from the joints
/// it is at is refused at connect, naming the pose and the limit, and nothing moves.
#[test]
#[ignore = "franka-sim tier: needs SOFTTOUCH_FRANKA_SIM_PYTHON (TESTING.md)"]
fn a_workspace_beyond_the_fr3s_limits_is_refused_at_connect_before_any_motion() {
    let py = python();
    let dir = tempdir();
    let sim = FrankaSim::start(&py, dir.path());
    let full = "theta_rad = [-3.141592653589793, 3.141592653589793]";
    fcisim::write_rig(
        dir.path(),
        &rig_toml(&sim.address(), SIM_DEVICES, LIMITS).replace("theta_rad = [-0.4, 0.4]", full),
    );
    std::fs::write(
        dir.path().join("scene.toml"),
        fcisim::SCENE.replace("theta_rad = [-0.4, 0.4]", full),
    )
    .expect("write");
    let before = still_arm(&sim);
    let out = run(
        dir.path(),
        &[
            "collect",
            "--rig",
            "rig.toml",
            "--scene",
            "scene.toml",
            "--samples",
            "2",
        ],
    );
    assert_ne!(out.status.code(), Some(0));
    let e = text(&out.stderr);
    assert!(
        e.contains("beyond the FR3's limits") && e.contains("refused before any motion"),
        "{e}"
    );
    assert!(e.contains("joint 7"), "{e}");
    let after = still_arm(&sim);
    assert!(
        after.distance_to(&before) < 1e-4 && after.angle_to(&before) < 1e-3,
        "the arm moved: {before:?} -> {after:?}"
    );
}
