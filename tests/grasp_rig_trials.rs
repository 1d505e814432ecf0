//! `grasp trials --rig` end to end, through the code a lab's rig runs
//! ([`softtouch_lab::grasp::trials::rig`]): only the devices differ. The arm is the
//! simulated grasp arm behind `Arm`; the Hand-E is the real Modbus RTU client over a
//! pty pair (socat) talking to the project's Hand-E server, which is backed by the
//! simulated soft-finger gripper (with its 1 s watchdog); the camera is the soft
//! finger's. The operator's answers are scripted. Wall clock (a pty is real I/O): a
//! stop request is the watch channel the CLI's signal handler feeds (`grasp trials`'
//! own SIGTERM handling is tested end to end in `grasp_trials.rs`).
//!
//! One test, several sessions on the same rig (the model is trained once): a session
//! that runs and is judged with the operator correcting a verdict; a stop during a
//! lift (the trial finishes, is stored, the object is set down); a second stop
//! during a lift (at once: not stored, set down before the fingers open); a closed
//! operator input; perturbed poses outside the workspace (refused, stored as such,
//! nothing moves); the twist with the wrist loop turning the arm's flange; the Hand-E
//! server stopping mid-trial. Needs `socat` (skipped with
//! a message when missing; with `CI` set a missing socat fails the test).

use crate::common;
use crate::pty;
use pty::pty_pair;

use common::hand_e_rig::{HandERig, calibrated_hand_e};
use common::{tempdir, tiny_model};

use std::io::Write;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use softtouch_drivers::{Arm, Clock, Gripper};
use softtouch_grasp::{OperatorInput, WristConfig};
use softtouch_lab::grasp::trials::rig::twist::{RigTwistSettings, twist_on_rig};
use softtouch_lab::grasp::trials::rig::{
    Operator, RigSession, RigTrialDevices, object_setup_on_rig, resume_rig_session, run_rig_trials,
    start_rig_session,
};
use softtouch_lab::grasp::trials::{RunEnd, TrialPlan, TrialsError, load_scenes};
use softtouch_schemas::rig::{GraspObjectSetup, GraspSetup};
use softtouch_schemas::{ArmPose, Medium, RigConfig, TimestampNs};
use softtouch_sim::{GraspObject, HoldState, SoftGraspArm, SoftGraspHandle};
use softtouch_store::Store;
use softtouch_trainer::Predictor;

const MODEL: &str = "air-svae";
const OBJECT: &str = "cylinder";

/// What the operator's output shows, shared with the test.
#[derive(Clone, Default)]
struct Shown(Arc<Mutex<Vec<u8>>>);

impl Write for Shown {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("lock").extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Shown {
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.0.lock().expect("lock")).into_owned()
    }
}

fn operator(answers: &str, confirm: bool) -> (Operator, Shown) {
    let shown = Shown::default();
    (
        Operator {
            input: OperatorInput::from_reader(std::io::Cursor::new(answers.as_bytes().to_vec())),
            output: Box::new(shown.clone()),
            confirm_verdicts: confirm,
        },
        shown,
    )
}

/// Gripper pointing down (180° about x): its x along base x, z along base −z.
const DOWN: [f64; 4] = [0.0, 1.0, 0.0, 0.0];
const GRASP_AT: [f64; 3] = [0.5, 0.0, 0.2];
const SAFE_AT: [f64; 3] = [0.5, 0.0, 0.3];

fn rig(port: &str, width_mm: f64) -> RigConfig {
    let mut rig = softtouch_schemas::defaults::rig();
    rig.gripper = softtouch_schemas::rig::GripperDevice::HandE {
        port: port.into(),
        slave_id: 9,
    };
    rig.grasp = Some(GraspSetup {
        medium: Medium::Air,
        safe_pose: ArmPose {
            translation_m: SAFE_AT,
            rotation_wxyz: DOWN,
        },
        approach_height_m: 0.04,
        speed_m_s: 0.4,
        objects: vec![GraspObjectSetup {
            name: OBJECT.into(),
            base_from_grasp: ArmPose {
                translation_m: GRASP_AT,
                rotation_wxyz: DOWN,
            },
            open_width_mm: width_mm,
            lift_mm: 20.0,
            place: None,
        }],
    });
    let mut c = softtouch_schemas::config::Check::default();
    softtouch_schemas::config::Validate::validate(&rig, &mut c);
    assert!(c.problems().is_empty(), "{:?}", c.problems());
    rig
}

/// Short trials: quick confirmation, a short hold.
fn plan(modes: &[&str], trials: u32, sigma_mm: f64) -> TrialPlan {
    TrialPlan {
        objects: vec![OBJECT.into()],
        modes: modes.iter().map(|m| (*m).to_owned()).collect(),
        trials,
        sigmas_mm: vec![sigma_mm],
        fps: 30.0,
        confirm_s: 0.1,
        close_timeout_s: 1.5,
        hold_s: 0.2,
        ..TrialPlan::default()
    }
}

async fn run(
    store: &Store,
    session: &RigSession,
    devices: &mut RigTrialDevices,
    operator: &mut Operator,
    stop: &tokio::sync::watch::Receiver<u32>,
) -> Result<RunEnd, TrialsError> {
    let todo = session.progress(store).await.expect("progress").todo;
    run_rig_trials(store, session, devices, operator, &todo, stop, &mut |_| {
        Ok(())
    })
    .await
}

/// Sends `level` stop requests once the physics says the object is lifted and held;
/// the task's output keeps the sender (a closed channel is no request) until it is
/// awaited.
type Lifted = tokio::task::JoinHandle<(bool, tokio::sync::watch::Sender<u32>)>;

fn stop_when_lifted(
    handle: SoftGraspHandle,
    level: u32,
) -> (tokio::sync::watch::Receiver<u32>, Lifted) {
    let (tx, rx) = tokio::sync::watch::channel(0u32);
    let task = tokio::spawn(async move {
        for _ in 0..3000 {
            if handle.hold_state().ok() == Some(HoldState::Held) {
                let _ = tx.send(level);
                return (true, tx);
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        (false, tx)
    });
    (rx, task)
}

async fn at_safe_pose(devices: &RigTrialDevices) {
    let s = devices.arm.lock().await.state().await.expect("arm state");
    let d: f64 = (0..3)
        .map(|i| (s.base_from_finger.translation_m[i] - SAFE_AT[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(d < 1e-6, "the arm ended {d} m from the safe pose");
}

async fn fingers_open(devices: &mut RigTrialDevices) {
    let s = devices.gripper.status().await.expect("status");
    assert!(s.position <= 5, "the fingers ended at count {}", s.position);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rig_session_runs_judges_stops_and_ends_safe_on_the_simulated_rig() {
    let dir = tempdir();
    let d = dir.path();
    // The model, trained through the CLI before any clock or link starts.
    let t0 = std::time::Instant::now();
    tokio::task::block_in_place(|| tiny_model(d));
    let lap = |what: &str| eprintln!("{what}: at {:.1} s", t0.elapsed().as_secs_f64());
    lap("model trained");
    let Some(pair) = pty_pair() else {
        return;
    };
    let db = d.join("softtouch.db");
    let store = Store::open(&db).await.expect("store");
    let bytes = softtouch_lab::models::force_artifact(&store, MODEL)
        .await
        .expect("model");
    let scene = load_scenes(&[], &[]).expect("scenes").remove(0);
    let object = GraspObject::from_spec(scene.object(OBJECT).expect("cylinder"));
    // The open-loop width squeezes the 30 mm cylinder by 8 mm (the tiny model's
    // estimate shows a grip well above the rig judge's least force there).
    let rig = rig(&pair.a, object.width_m * 1000.0 - 8.0);

    // The soft grasp behind the Hand-E server, with the object resting between the
    // open fingers for `grasp calibrate --rig`'s closing, over the pty: the session's
    // K comes from it.
    let HandERig {
        hand_e,
        camera,
        handle,
        service,
        server,
        server_stop,
        clock,
        shared,
    } = calibrated_hand_e(
        &pair,
        &scene,
        (OBJECT, &object),
        (MODEL, &bytes),
        &rig,
        &store,
    )
    .await;

    lap("calibrated over the pty");
    // The arm starts at the safe pose, over the object's place (the object is taken
    // away: it is set in place before each trial).
    let arm = SoftGraspArm::new(
        handle.clone(),
        clock,
        ArmPose {
            translation_m: GRASP_AT,
            rotation_wxyz: DOWN,
        },
        ArmPose {
            translation_m: SAFE_AT,
            rotation_wxyz: DOWN,
        },
    );
    handle.set_object(false).expect("clear");
    let moves = arm.moves();
    let mut devices = RigTrialDevices {
        arm: Arc::new(tokio::sync::Mutex::new(Box::new(arm) as Box<dyn Arm>)),
        gripper: hand_e,
        camera,
        clock: shared.clone(),
    };
    let (_never, no_stop) = tokio::sync::watch::channel(0u32);

    // 1. Two trials a mode, σ = 2 mm; the operator keeps the judge's verdicts, except
    //    that they call the last a crush.
    let session = start_rig_session(&store, MODEL, 3, plan(&["open", "closed"], 2, 2.0), &rig)
        .await
        .expect("starts");
    let (mut op, shown) = operator("\n\n\n\n\n\n\ncrush\n", true);
    let end = run(&store, &session, &mut devices, &mut op, &no_stop)
        .await
        .unwrap_or_else(|e| panic!("{e}\n{}", shown.text()));
    assert_eq!(end, RunEnd::Completed);
    let rows = store.grasp_trials(session.id).await.expect("rows");
    for r in &rows {
        eprintln!(
            "{} #{}: {} (peak estimate {:?} N, final {:.1} mm, {:.2} s)",
            r.key.mode,
            r.key.trial,
            r.reason.as_deref().unwrap_or("held"),
            r.peak_estimate_n,
            r.final_width_m * 1e3,
            r.wall_s
        );
    }
    assert_eq!(rows.len(), 4, "{}", shown.text());
    assert_eq!(
        rows[3].reason.as_deref(),
        Some("crush"),
        "the operator's word"
    );
    assert!(
        rows.iter().any(|r| r.success),
        "nothing held: {rows:?}\n{}",
        shown.text()
    );
    for r in &rows {
        let trace = store
            .grasp_trace(session.id, &r.key)
            .await
            .expect("trace")
            .expect("stored");
        assert!(!trace.t_s.is_empty(), "{:?} has no cycles", r.key);
        assert!(r.peak_true_n.is_none(), "a rig records no truth");
    }
    assert_eq!(shown.text().matches("the judge says").count(), 4);
    assert_eq!(
        shown.text().matches("set the object in its place").count(),
        4
    );
    assert_eq!(service.watchdog_faults(), 0, "the Hand-E was kept alive");
    at_safe_pose(&devices).await;
    fingers_open(&mut devices).await;

    lap("session 1 (4 trials) done");
    // 2. One stop request during the first lift: that trial finishes and is stored,
    //    the object is set down, and the run ends before the next.
    let session = start_rig_session(&store, MODEL, 4, plan(&["open"], 2, 0.0), &rig)
        .await
        .expect("starts");
    let (stop, lifted) = stop_when_lifted(handle.clone(), 1);
    let (mut op, shown) = operator("\n\n\n\n", false);
    let end = run(&store, &session, &mut devices, &mut op, &stop)
        .await
        .unwrap_or_else(|e| panic!("{e}\n{}", shown.text()));
    assert!(
        lifted.await.expect("join").0,
        "never lifted: {}\n{:?}",
        shown.text(),
        store.grasp_trials(session.id).await
    );
    assert_eq!(end, RunEnd::Stopped { ran: 1 });
    assert_eq!(store.grasp_trials(session.id).await.expect("rows").len(), 1);
    at_safe_pose(&devices).await;
    fingers_open(&mut devices).await;
    assert_ne!(handle.hold_state().ok(), Some(HoldState::Held));

    lap("session 2 (stop once) done");
    // 3. Two stop requests during the lift: at once, the trial in hand not stored, the
    //    object set down before the fingers open.
    let (stop, lifted) = stop_when_lifted(handle.clone(), 2);
    let resumed = resume_rig_session(&store, session.id, None, &rig)
        .await
        .expect("resumes");
    let (mut op, shown) = operator("\n\n", false);
    let end = run(&store, &resumed, &mut devices, &mut op, &stop).await;
    assert!(lifted.await.expect("join").0);
    assert!(matches!(end, Err(TrialsError::Interrupted)), "{end:?}");
    assert_eq!(store.grasp_trials(session.id).await.expect("rows").len(), 1);
    assert!(
        shown.text().contains("set down and the fingers opened"),
        "{}",
        shown.text()
    );
    at_safe_pose(&devices).await;
    fingers_open(&mut devices).await;

    lap("session 3 (stop at once) done");
    // 4. The operator's input closes after one trial: the session stops, safe.
    let session = start_rig_session(&store, MODEL, 5, plan(&["open"], 3, 0.0), &rig)
        .await
        .expect("starts");
    let (mut op, shown) = operator("\n\n", true);
    let end = run(&store, &session, &mut devices, &mut op, &no_stop).await;
    assert!(
        matches!(&end, Err(e) if e.to_string().contains("operator's input")),
        "{end:?}\n{}",
        shown.text()
    );
    assert_eq!(store.grasp_trials(session.id).await.expect("rows").len(), 1);
    at_safe_pose(&devices).await;
    fingers_open(&mut devices).await;

    lap("session 4 (input closed) done");
    // 5. Perturbed poses outside the workspace: refused, stored, nothing moves. The
    //    reach box is cut to 1 mm around the grasp along x; σ = 20 mm.
    let mut tight = rig.clone();
    tight.workspace.reach_in_base_m[0] =
        softtouch_schemas::Range::new(GRASP_AT[0] - 0.001, GRASP_AT[0] + 0.001);
    tight.grasp.as_mut().expect("grasp").safe_pose.translation_m[0] = GRASP_AT[0];
    let session = start_rig_session(&store, MODEL, 6, plan(&["open"], 4, 20.0), &tight)
        .await
        .expect("starts");
    let before = moves.load(Ordering::Relaxed);
    let (mut op, shown) = operator("", true);
    let end = run(&store, &session, &mut devices, &mut op, &no_stop)
        .await
        .unwrap_or_else(|e| panic!("{e}\n{}", shown.text()));
    assert_eq!(end, RunEnd::Completed);
    let rows = store.grasp_trials(session.id).await.expect("rows");
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().all(|r| {
        r.reason.as_deref() == Some("refused")
            && r.detail
                .as_deref()
                .is_some_and(|d| d.contains("nothing moved"))
    }));
    // The safe pose at the start and at the end, nothing else.
    assert_eq!(moves.load(Ordering::Relaxed) - before, 2);
    let table =
        softtouch_lab::grasp::trials::table::summarise(&session.plan, &session.media(), &rows)
            .expect("table");
    assert!(
        table.iter().all(|c| c.trials == 0),
        "refused trials count in no rate"
    );

    lap("session 5 (refused) done");
    // 6. The twist on the rig's wrist: held at 1 N, once without and once with the
    //    wrist loop (no dead band: the loop acts on any τz the finger reads); in the
    //    second the object is turned 0.3 rad about the fingers' axis "by hand".
    let calibrated = object_setup_on_rig(&store, &rig, MODEL, &bytes, OBJECT, 0.1)
        .await
        .expect("the stored calibration");
    let grasp = rig.grasp.clone().expect("grasp");
    let (_signal, no_signal) = tokio::sync::watch::channel(None::<&'static str>);
    let mut twists = Vec::new();
    for with_wrist in [false, true] {
        if with_wrist {
            let soon = TimestampNs(clock.now().0 + 2_500_000_000);
            handle
                .schedule_object_yaw(soon, 0.3, 0.5)
                .expect("a turn by hand");
        }
        let before = moves.load(Ordering::Relaxed);
        let (mut op, shown) = operator("\n", false);
        let run = twist_on_rig(
            &grasp,
            &rig.workspace,
            &calibrated,
            &mut devices,
            &mut op,
            Predictor::from_bytes(&bytes).expect("loads"),
            &RigTwistSettings {
                object: OBJECT.into(),
                target_n: 1.0,
                duration_s: 3.5,
                gain_over_lambda: 0.75,
                wrist: with_wrist.then_some(WristConfig {
                    deadband_nm: 0.0,
                    ..WristConfig::default()
                }),
                wrist_step_rad: 0.05,
                pregrasp_margin_mm: 6.0,
            },
            no_signal.clone(),
        )
        .await
        .unwrap_or_else(|e| panic!("{e}\n{}", shown.text()));
        at_safe_pose(&devices).await;
        fingers_open(&mut devices).await;
        twists.push((run, moves.load(Ordering::Relaxed) - before));
    }
    let turned = |r: &softtouch_lab::grasp::trials::rig::twist::RigTwist| {
        r.cycles
            .iter()
            .filter_map(|c| c.wrist_target_rad)
            .fold(0.0_f64, |m, y| m.max(y.abs()))
    };
    for (r, m) in &twists {
        let tz: Vec<f64> = r.cycles.iter().filter_map(|c| c.torque_z_nm).collect();
        eprintln!(
            "twist: {} cycles, {m} arm moves, τz RMS {:.3} N·mm (estimate), wrist up to {:.1}°",
            r.cycles.len(),
            (tz.iter().map(|t| (t * 1e3).powi(2)).sum::<f64>() / tz.len().max(1) as f64).sqrt(),
            turned(r).to_degrees()
        );
    }
    assert!(
        twists
            .iter()
            .all(|(r, _)| r.cycles.len() > 30 && r.stopped.is_none())
    );
    assert!(
        twists[0]
            .0
            .cycles
            .iter()
            .all(|c| c.wrist_target_rad.is_none()),
        "no wrist loop, no wrist target"
    );
    assert!(turned(&twists[1].0) > 0.01, "the wrist loop never turned");
    assert!(
        twists[1].1 > twists[0].1,
        "the flange never moved: {} moves against {}",
        twists[1].1,
        twists[0].1
    );
    lap("twist on the rig done");
    // 7. The Hand-E server stops mid-trial: a device fault, stored; the session
    //    stops with the error, the arm not left moving.
    let session = start_rig_session(&store, MODEL, 7, plan(&["closed"], 2, 0.0), &rig)
        .await
        .expect("starts");
    let watcher = {
        let handle = handle.clone();
        tokio::spawn(async move {
            // Once the fingers close on the object, the server goes.
            for _ in 0..6000 {
                if handle
                    .opening_mm()
                    .is_ok_and(|o| o < object.max_width_m() * 1000.0 + 1.0)
                    && handle.has_object().unwrap_or(false)
                {
                    let _ = server_stop.send(());
                    return true;
                }
                tokio::time::sleep(Duration::from_millis(2)).await;
            }
            false
        })
    };
    let (mut op, shown) = operator("\n\n\n\n", false);
    let end = run(&store, &session, &mut devices, &mut op, &no_stop).await;
    assert!(watcher.await.expect("join"));
    assert!(
        matches!(&end, Err(e) if e.to_string().contains("device fault")),
        "{end:?}\n{}",
        shown.text()
    );
    let rows = store.grasp_trials(session.id).await.expect("rows");
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].reason.as_deref(), Some("device_fault"));
    server.await.expect("join").expect("server");
    drop(pair);
}
