//! `softtouch grasp follow|disturb|twist`: the grasp experiments of Figure 5 on the
//! simulated Hand-E with soft fingers, closed by a stored model's estimate.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_drivers::{Clock, TokioClock};
use softtouch_grasp::{
    Controller, ControllerConfig, Cycle, ExitAction, GainCheck, GraspError, Projection,
    WristConfig, WristLoop, check_gain, check_tolerance, hold_metrics,
};
use softtouch_schemas::{ArmPose, Medium, SceneSpec, TimestampNs};
use softtouch_sim::{GraspObject, SoftFingerCamera, SoftGraspHandle, SoftGripper, soft_grasp};
use softtouch_trainer::Predictor;

use super::{Failure, io_failure, open_existing};
use crate::grasp::settings;
use crate::grasp::sim::{LoggedTruth, SimWrist, TruthSample};
use crate::plot::{Series, SeriesStyle, XyChart, xy_chart};

/// The grasp scene shipped in `scenes/grasp.toml`: the default for `disturb` and
/// `twist` (its oval tube and cylinder).
const GRASP_SCENE_TOML: &str = include_str!("../../../scenes/grasp.toml");

/// The grasp experiments.
#[derive(Debug, Subcommand)]
pub enum GraspCommand {
    /// Hold each target force in turn on the simulated soft-finger Hand-E, the model's
    /// estimate closing the loop (Algorithm 1); prints rise time, settling time,
    /// overshoot, steady-state and RMS error per target; writes a CSV and a PNG.
    #[command(
        after_help = "Example:\n  softtouch grasp follow --model land-v1-svae --targets 0.4,1.6,3\n  softtouch grasp follow --model land-v1-svae --scene scenes/grasp.toml --object ball --fingers 2\n  softtouch grasp follow --model land-v1-svae --rig lab.toml --gain 4 --targets 0.4,1.6   # a real Hand-E"
    )]
    Follow(FollowArgs),
    /// Hold 0.4 N on land or 1.6 N in water (the scene's medium) on an oval tube while
    /// the simulator turns it about its axis by 45°, then 60°, then −90°; prints per
    /// turn the peak deviation, the recovery time to within δ and the RMS error;
    /// writes `grasp-disturb.csv` and `grasp-disturb.png`.
    #[command(
        after_help = "Example:\n  softtouch grasp disturb --model land-v1-svae\n  softtouch grasp disturb --model water-v1-svae --scene scenes/grasp-water.toml --fingers 2"
    )]
    Disturb(DisturbArgs),
    /// Hold a grip force on a cylinder that the simulator turns about the fingers'
    /// axis, and hold the torque τz ≈ 0 by turning the wrist on the model's τz
    /// estimate; runs with and without the wrist loop and prints the τz RMS of both;
    /// writes `grasp-twist.csv` and `grasp-twist.png`.
    #[command(
        after_help = "Example:\n  softtouch grasp twist --model land-v1-svae\n  softtouch grasp twist --model land-v1-svae --turn-deg 30 --wrist-gain 1000"
    )]
    Twist(TwistArgs),
    /// Grasp success-rate trials (Figure 4): per object, mode (open, closed) and medium
    /// (one scene each; default land and water), `--trials` grasps with the grasp point
    /// perturbed by N(0, σ²) per axis, lift and hold; the physics decides held, slip,
    /// crush, miss or timeout. Each trial is stored as it ends; `--resume SESSION`
    /// continues. Prints success rates with Wilson 95 % intervals beside the paper's;
    /// writes `grasp-trials.csv`, `grasp-trials-rows.csv` and `grasp-trials.png`.
    #[command(after_help = "Example:
  softtouch grasp trials --model land-v1-svae --trials 10 --sigma-mm 5 --modes open,closed
  softtouch grasp trials --model land-v1-svae --objects cake,ball --scene scenes/grasp.toml
  softtouch grasp trials --resume 3
  softtouch grasp trials --model land-v1-svae --sweep-sigma 0,2,5,8,12 --trials 5")]
    Trials(super::grasp_trials::TrialsArgs),
}

/// Options every grasp experiment shares.
#[derive(Debug, Args)]
pub struct LoopArgs {
    /// Stored model whose estimate closes the loop.
    #[arg(long)]
    pub model: String,
    /// Scene file (medium, effects, `[[objects]]`); default: the built-in scene
    /// (`follow`) or `scenes/grasp.toml` (`disturb`, `twist`).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Gain K, N/mm; default: 0.75 × the stiffness Λ_max measured on the simulator.
    #[arg(long)]
    pub gain: Option<f64>,
    /// Tolerance δ, N.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Camera rate, Hz (one control cycle per frame).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// Sensorised fingers the loop reads: 1, or 2 (the second mirrors the first; the
    /// estimate is the mean of both, or the one left when the other gives none).
    #[arg(long, default_value_t = 1)]
    pub fingers: u8,
    /// Folder for the CSV and the PNG.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
    /// Seed of the simulated scene's effects.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Options of `grasp follow`.
#[derive(Debug, Args)]
pub struct FollowArgs {
    /// Target forces, N, held in turn.
    #[arg(long, value_delimiter = ',', default_value = "0.4,1.6,3")]
    pub targets: Vec<f64>,
    /// Object to grasp (a `[[objects]]` name); default: the scene's first object,
    /// else a cylinder of the scene's first rod.
    #[arg(long)]
    pub object: Option<String>,
    /// How long each target is held, s.
    #[arg(long, default_value_t = 3.0)]
    pub hold_s: f64,
    /// Rig file: when it names a real gripper (`driver = "hand-e"`), the loop runs on
    /// the real Hand-E and finger cameras (`camera`, and `second_camera` for a second
    /// finger), after an end calibration with nothing between the fingers; `--gain` is
    /// then required. A rig with a simulated gripper runs the simulated soft grasp.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Shared loop options.
    #[command(flatten)]
    pub common: LoopArgs,
}

/// Options of `grasp disturb`.
#[derive(Debug, Args)]
pub struct DisturbArgs {
    /// Force held, N; default: 0.4 on land, 1.6 in water (the scene's medium).
    #[arg(long)]
    pub target: Option<f64>,
    /// Object turned (a `[[objects]]` name).
    #[arg(long, default_value = "oval-tube")]
    pub object: String,
    /// The turns, degrees, one after the other (each relative to the last).
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        default_value = "45,60,-90"
    )]
    pub turns_deg: Vec<f64>,
    /// How long the force is held before the first turn, s.
    #[arg(long, default_value_t = 2.0)]
    pub settle_s: f64,
    /// How long each turn takes, s.
    #[arg(long, default_value_t = 0.5)]
    pub turn_s: f64,
    /// Time from one turn's start to the next (each phase), s.
    #[arg(long, default_value_t = 3.0)]
    pub phase_s: f64,
    /// Shared loop options.
    #[command(flatten)]
    pub common: LoopArgs,
}

/// Options of `grasp twist`.
#[derive(Debug, Args)]
pub struct TwistArgs {
    /// Grip force held, N.
    #[arg(long, default_value_t = 1.0)]
    pub target: f64,
    /// Object turned (a `[[objects]]` name).
    #[arg(long, default_value = "cylinder")]
    pub object: String,
    /// How far the simulator turns the object about the fingers' axis, degrees (then
    /// back).
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub turn_deg: f64,
    /// How long the force is held before the turn, s.
    #[arg(long, default_value_t = 2.0)]
    pub settle_s: f64,
    /// How long each turn (out and back) takes, s.
    #[arg(long, default_value_t = 1.0)]
    pub turn_s: f64,
    /// How long the turned object is held before it turns back, and after, s.
    #[arg(long, default_value_t = 2.0)]
    pub hold_s: f64,
    /// Wrist loop gain, rad/s per N·m of τz.
    #[arg(long, default_value_t = 500.0)]
    pub wrist_gain: f64,
    /// Wrist loop dead band, N·mm of τz.
    #[arg(long, default_value_t = 0.5)]
    pub wrist_deadband_nmm: f64,
    /// Shared loop options.
    #[command(flatten)]
    pub common: LoopArgs,
}

/// Finger 0's sensor +x faces the object, so its push (−x) is the world's +y, the
/// paper's gripping direction. Finger 1 is turned half a turn about z: its push is the
/// world's −y, which counts as squeezing for it.
fn projections() -> Result<[Projection; 2], GraspError> {
    let half_pi = std::f64::consts::FRAC_PI_2;
    Ok([
        Projection::along_world_y(ArmPose::from_translation_yaw([0.0; 3], -half_pi))?,
        Projection::new(
            ArmPose::from_translation_yaw([0.0; 3], half_pi),
            [0.0, -1.0, 0.0],
        )?,
    ])
}

fn grasp_failure(e: GraspError) -> Failure {
    match e {
        GraspError::Config(_) | GraspError::UnreachableTarget { .. } => Failure::BadInput(e.into()),
        GraspError::Device(_) | GraspError::Estimate(_) | GraspError::Interrupted(_) => {
            Failure::Runtime(e.into())
        }
    }
}

fn sim_failure(e: softtouch_sim::SimError) -> Failure {
    Failure::Runtime(e.into())
}

fn bad(m: String) -> Failure {
    Failure::BadInput(anyhow!(m))
}

/// Run a grasp verb.
pub async fn run(cmd: GraspCommand, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        GraspCommand::Follow(args) => follow(args, db, out).await,
        GraspCommand::Disturb(args) => disturb(args, db, out).await,
        GraspCommand::Twist(args) => twist(args, db, out).await,
        GraspCommand::Trials(args) => super::grasp_trials::run(args, db, out).await,
    }
}

type SimController = Controller<SoftGripper, SoftFingerCamera, Predictor, LoggedTruth>;

/// A loop made ready on the simulated soft grasp: approached to just before the
/// first touch.
struct Prepared {
    controller: SimController,
    handle: SoftGraspHandle,
    clock: TokioClock,
    truth_log: Arc<std::sync::Mutex<Vec<TruthSample>>>,
}

fn check_common(c: &LoopArgs) -> Result<(), Failure> {
    settings::FPS_HZ.check("--fps", c.fps)?;
    settings::TOLERANCE_N.check("--tolerance", c.tolerance)?;
    settings::check_fingers(c.fingers)?;
    Ok(())
}

fn check_duration(flag: &str, v: f64, zero_allowed: bool) -> Result<(), Failure> {
    settings::duration_s(zero_allowed).check(flag, v)?;
    Ok(())
}

/// The scene of `--scene`, else `fallback` (the embedded default or grasp scene).
fn scene_for(c: &LoopArgs, grasp_default: bool) -> Result<SceneSpec, Failure> {
    if c.scene.is_none() && grasp_default {
        return softtouch_schemas::config::parse_toml(
            GRASP_SCENE_TOML,
            &softtouch_schemas::ConfigSource::Embedded("grasp scene"),
        )
        .map_err(|e| Failure::Runtime(anyhow!("the embedded grasp scene: {e}")));
    }
    Ok(crate::configs::resolve(None, c.scene.as_deref())?.scene)
}

fn named_object(scene: &SceneSpec, name: &str) -> Result<GraspObject, Failure> {
    scene
        .object(name)
        .map(GraspObject::from_spec)
        .ok_or_else(|| {
            bad(format!(
                "--object {name}: the scene declares no such object (it has: {})",
                scene
                    .objects
                    .iter()
                    .map(|o| o.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

/// Loads the model, builds the soft grasp of `object`, measures Λ_max from first touch
/// to `top_n` (1.5 × the largest force asked for), configures Algorithm 1 and
/// approaches to four counts before the touch.
/// The stored model's bytes; then tokio's clock is paused, for the simulated gripper
/// and cameras (the database is read first: its pool's timeouts need real time).
async fn load_model_and_pause(c: &LoopArgs, db: &Path) -> Result<Vec<u8>, Failure> {
    let store = open_existing(db).await?;
    let bytes = crate::models::force_artifact(&store, &c.model).await?;
    drop(store);
    tokio::time::pause();
    Ok(bytes)
}

async fn prepare(
    c: &LoopArgs,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: GraspObject,
    targets_n: &[f64],
    on_exit: ExitAction,
    out: &mut dyn Write,
) -> Result<Prepared, Failure> {
    // The targets first: K is derived from them, so a bad target must not read as a
    // bad K (a flag the user never gave).
    let probe = softtouch_grasp::StepperConfig {
        tolerance_n: c.tolerance,
        ..softtouch_grasp::StepperConfig::default()
    };
    for t in targets_n {
        probe
            .check_target(*t)
            .map_err(|e| bad(format!("--targets: {e}")))?;
    }
    // Λ is measured up to half again the largest target.
    let top_n = 1.5 * targets_n.iter().copied().fold(0.0, f64::max);
    let predictor = Predictor::from_bytes(model_bytes)?;
    let clock = TokioClock::new();
    let (gripper, camera, handle) = soft_grasp(scene, object.clone(), c.fps, c.seed, clock)
        .map_err(|e| bad(format!("object `{}`: {e}", object.name)))?;
    let touch = handle
        .contact_count(0.02)
        .map_err(sim_failure)?
        .ok_or_else(|| {
            bad(format!(
                "object `{}` is never touched by the closing fingers",
                object.name
            ))
        })?;
    let counts: Vec<u8> = (touch..=255).collect();
    let curve = handle.grip_force_curve(&counts).map_err(sim_failure)?;
    let end = curve
        .iter()
        .find(|(_, f)| *f > top_n)
        .map_or(255, |(p, _)| *p);
    let lambda_max = handle
        .max_stiffness_n_per_mm(touch, end)
        .map_err(sim_failure)?;
    let gain = c.gain.unwrap_or(0.75 * lambda_max);
    if c.gain.is_none() && !(gain.is_finite() && gain > 0.0) {
        return Err(bad(format!(
            "object `{}`: the stiffness measured from first touch up to {top_n:.3} N (1.5 × the largest target) is {lambda_max} N/mm, so K = 0.75 Λ_max is unusable; ask for a larger target or give --gain",
            object.name
        )));
    }
    let projections = projections().map_err(grasp_failure)?;
    let mut config = ControllerConfig::new(projections[0]);
    config.stepper.gain_n_per_mm = gain;
    config.stepper.tolerance_n = c.tolerance;
    config.on_exit = on_exit;
    // Every setting and target is checked before the fingers move.
    let checked: Vec<(f64, Duration)> = targets_n.iter().map(|t| (*t, Duration::ZERO)).collect();
    config.check(&checked).map_err(grasp_failure)?;
    let w = |e| io_failure(e);
    writeln!(
        out,
        "object `{}`: first touch at count {touch}; measured Λ_max = {lambda_max:.3} N/mm; K = {gain:.3} N/mm, δ = {} N, {} Hz, {} finger(s)",
        object.name, c.tolerance, c.fps, c.fingers
    )
    .map_err(w)?;
    match check_gain(gain, lambda_max).map_err(grasp_failure)? {
        GainCheck::MayNotConverge { amplification } => writeln!(
            out,
            "warning: K ≤ Λ_max/2 (Method S4): the loop may oscillate (|1 − Λ/K| = {amplification:.2})"
        )
        .map_err(w)?,
        GainCheck::NoStiffness => {
            writeln!(out, "warning: Λ = 0: the force does not follow position").map_err(w)?;
        }
        GainCheck::Converges { .. } => {}
    }
    if !check_tolerance(c.tolerance, lambda_max, &config.stepper.stroke) {
        let one_count_n = softtouch_grasp::one_count_force_n(lambda_max, &config.stepper.stroke);
        writeln!(
            out,
            "warning: δ = {} N is below half the force of one count ({one_count_n:.3} N at Λ_max): expect dithering; --tolerance {:.3} or more avoids it",
            c.tolerance,
            (one_count_n / 2.0 * 1000.0).ceil() / 1000.0
        )
        .map_err(w)?;
    }
    let fingers = usize::from(c.fingers);
    let truth_log = Arc::new(std::sync::Mutex::new(Vec::new()));
    let truth = LoggedTruth {
        handle: handle.clone(),
        projections,
        fingers,
        log: Arc::clone(&truth_log),
    };
    let mut controller =
        Controller::new(gripper, camera, predictor, truth, Arc::new(clock), config)
            .map_err(grasp_failure)?;
    if fingers == 2 {
        let second = handle.second_camera().map_err(sim_failure)?;
        controller = controller.with_second_finger(Box::new(second), projections[1]);
    }
    controller
        .approach(touch.saturating_sub(4), Duration::from_secs(5))
        .await
        .map_err(grasp_failure)?;
    Ok(Prepared {
        controller,
        handle,
        clock,
        truth_log,
    })
}

fn create_out_dir(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", dir.display())))
}

async fn follow(args: FollowArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let c = &args.common;
    if args.targets.is_empty() {
        return Err(bad("--targets: expected at least one force in N".into()));
    }
    check_duration("--hold-s", args.hold_s, false)?;
    check_common(c)?;
    if let Some(rig_path) = &args.rig {
        let rig = crate::configs::resolve(Some(rig_path), None)?.rig;
        if crate::grasp::devices::has_real_gripper(&rig) {
            return follow_on_rig(&args, &rig, db, out).await;
        }
    }
    let scene = scene_for(c, false)?;
    let object = match (&args.object, scene.objects.first(), scene.rods.first()) {
        (Some(name), ..) => named_object(&scene, name)?,
        (None, Some(o), _) => GraspObject::from_spec(o),
        (None, None, Some(rod)) => GraspObject {
            shape: rod.shape,
            aspect: rod.aspect,
            ..GraspObject::cylinder(&rod.name, rod.size_m)
        },
        (None, None, None) => return Err(bad("the scene has neither objects nor rods".into())),
    };
    let model = load_model_and_pause(c, db).await?;
    let mut p = prepare(
        c,
        &model,
        &scene,
        object,
        &args.targets,
        ExitAction::Open,
        out,
    )
    .await?;
    let hold = Duration::from_secs_f64(args.hold_s);
    let targets: Vec<(f64, Duration)> = args.targets.iter().map(|t| (*t, hold)).collect();
    let cycles = p.controller.follow(&targets).await.map_err(grasp_failure)?;

    print_table(&cycles, &args.targets, args.common.tolerance, out)?;
    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-follow.csv");
    write_csv(&csv, &cycles)?;
    let png = c.out_dir.join("grasp-follow.png");
    write_png(&png, &cycles)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}

/// `grasp follow --rig FILE` on a real Hand-E: no simulator, so no measured Λ (the
/// gain is given) and no truth column; the stroke comes from the end calibration.
async fn follow_on_rig(
    args: &FollowArgs,
    rig: &softtouch_schemas::RigConfig,
    db: &Path,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let c = &args.common;
    let gain = c.gain.ok_or_else(|| {
        bad("--gain: expected K in N/mm on a real gripper (there is no simulator to measure the stiffness Λ)".into())
    })?;
    if c.fingers == 2 && rig.second_camera.is_none() {
        return Err(bad(
            "--fingers 2: the rig has no second_camera for the second finger".into(),
        ));
    }
    let store = open_existing(db).await?;
    let bytes = crate::models::force_artifact(&store, &c.model).await?;
    drop(store);
    let predictor = Predictor::from_bytes(&bytes)?;
    let projections = projections().map_err(grasp_failure)?;
    let mut config = ControllerConfig::new(projections[0]);
    config.stepper.gain_n_per_mm = gain;
    config.stepper.tolerance_n = c.tolerance;
    let hold = Duration::from_secs_f64(args.hold_s);
    let targets: Vec<(f64, Duration)> = args.targets.iter().map(|t| (*t, hold)).collect();
    writeln!(
        out,
        "real Hand-E: calibrating the ends (nothing may be between the fingers), then K = {gain} N/mm, δ = {} N",
        c.tolerance
    )
    .map_err(io_failure)?;
    let second = (c.fingers == 2).then_some(projections[1]);
    let signals = super::signals::SignalWatch::start();
    let run = crate::grasp::devices::follow_on_rig(
        rig,
        predictor,
        config,
        second,
        &targets,
        signals.request(),
    )
    .await
    .map_err(|e| match e {
        // Its Display already names the device and the cause.
        crate::grasp::devices::RigFollowError::Open(e) => Failure::Runtime(anyhow!("{e}")),
        crate::grasp::devices::RigFollowError::Grasp(e) => grasp_failure(e),
    })?;
    let cal = run.calibration;
    writeln!(
        out,
        "calibrated: reached counts {} (open) and {} (closed); stroke {}..={} at {:.4} mm per count",
        cal.open_reached,
        cal.closed_reached,
        cal.stroke.open_count,
        cal.stroke.closed_count,
        cal.stroke.mm_per_count
    )
    .map_err(io_failure)?;
    print_table(&run.cycles, &args.targets, c.tolerance, out)?;
    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-follow.csv");
    write_csv(&csv, &run.cycles)?;
    let png = c.out_dir.join("grasp-follow.png");
    write_png(&png, &run.cycles)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}

fn print_table(
    cycles: &[Cycle],
    targets: &[f64],
    tolerance_n: f64,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let opt = |v: Option<f64>| v.map_or_else(|| "never".to_owned(), |s| format!("{s:.3}"));
    writeln!(
        out,
        "{:>8} {:>9} {:>10} {:>11} {:>11} {:>9} {:>13} {:>10}",
        "target N",
        "rise s",
        "settle s",
        "overshoot N",
        "ss error N",
        "RMS N",
        "true ss err N",
        "true RMS N"
    )
    .map_err(io_failure)?;
    for (i, target) in targets.iter().enumerate() {
        let hold: Vec<&Cycle> = cycles.iter().filter(|c| c.hold == i).collect();
        let series = |f: fn(&Cycle) -> Option<f64>| -> Vec<(f64, f64)> {
            hold.iter()
                .filter_map(|c| Some((c.t.0 as f64 * 1e-9, f(c)?)))
                .collect()
        };
        let est = hold_metrics(&series(|c| c.estimate_n), *target, tolerance_n);
        let tru = hold_metrics(&series(|c| c.true_n), *target, tolerance_n);
        match est {
            Some(m) => writeln!(
                out,
                "{:>8.2} {:>9} {:>10} {:>11.3} {:>11.3} {:>9.3} {:>13} {:>10}",
                target,
                opt(m.rise_time_s),
                opt(m.settling_time_s),
                m.overshoot_n,
                m.steady_state_error_n,
                m.rms_error_n,
                tru.map_or_else(|| "-".into(), |t| format!("{:.3}", t.steady_state_error_n)),
                tru.map_or_else(|| "-".into(), |t| format!("{:.3}", t.rms_error_n)),
            ),
            None => writeln!(out, "{target:>8.2} (no usable estimate)"),
        }
        .map_err(io_failure)?;
    }
    Ok(())
}

fn write_csv(path: &Path, cycles: &[Cycle]) -> Result<(), Failure> {
    let mut text = String::from(
        "t_s,frame,target_n,estimate_n,true_n,measured_count,request_count,outcome,gripper_object_status\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for c in cycles {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:?}\n",
            c.t.0 as f64 * 1e-9,
            c.frame_sequence,
            c.target_n,
            opt(c.estimate_n),
            opt(c.true_n),
            c.measured_position,
            c.position_request,
            c.outcome.map_or("awaiting_echo", |o| o.as_str()),
            c.object
        ));
    }
    std::fs::write(path, text)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", path.display())))
}

fn write_png(path: &Path, cycles: &[Cycle]) -> Result<(), Failure> {
    let t = |c: &Cycle| c.t.0 as f64 * 1e-9;
    let series = [
        Series {
            label: "commanded F_ref".into(),
            points: cycles.iter().map(|c| (t(c), c.target_n)).collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "estimated F_est".into(),
            points: cycles
                .iter()
                .filter_map(|c| Some((t(c), c.estimate_n?)))
                .collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "true (simulator)".into(),
            points: cycles
                .iter()
                .filter_map(|c| Some((t(c), c.true_n?)))
                .collect(),
            style: SeriesStyle::Line,
        },
    ];
    xy_chart(
        path,
        &XyChart {
            title: "Force following",
            x_label: "time (s)",
            y_label: "grip force (N)",
            series: &series,
        },
        (900, 500),
    )
    .map_err(|e| Failure::Runtime(e.into()))
}

/// How one phase of a disturbance went, from `(t_s, force_n)` samples.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PhaseNumbers {
    /// Largest |F − target|, N.
    peak_deviation_n: f64,
    /// From the phase's start until F is within δ for the rest of the phase, s
    /// (`None`: still outside at its end).
    recovery_s: Option<f64>,
    /// RMS of F − target over the phase, N.
    rms_error_n: f64,
}

fn phase_numbers(
    samples: &[(f64, f64)],
    t0_s: f64,
    t1_s: f64,
    target_n: f64,
    tolerance_n: f64,
) -> Option<PhaseNumbers> {
    let s: Vec<(f64, f64)> = samples
        .iter()
        .copied()
        .filter(|(t, f)| *t >= t0_s && *t < t1_s && f.is_finite())
        .collect();
    if s.is_empty() {
        return None;
    }
    let errors: Vec<f64> = s.iter().map(|(_, f)| f - target_n).collect();
    let peak_deviation_n = errors.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
    let rms_error_n = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let recovery_s = match errors.iter().rposition(|e| e.abs() > tolerance_n) {
        None => Some(0.0),
        Some(last) if last + 1 < s.len() => Some(s[last + 1].0 - t0_s),
        Some(_) => None,
    };
    Some(PhaseNumbers {
        peak_deviation_n,
        recovery_s,
        rms_error_n,
    })
}

fn t_s(t: TimestampNs) -> f64 {
    t.0 as f64 * 1e-9
}

async fn disturb(args: DisturbArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let c = &args.common;
    check_common(c)?;
    if args.turns_deg.is_empty() || args.turns_deg.len() > 20 {
        return Err(bad(format!(
            "--turns-deg: expected 1 to 20 turns in degrees, found {}",
            args.turns_deg.len()
        )));
    }
    if let Some(t) = args
        .turns_deg
        .iter()
        .find(|t| !(t.is_finite() && t.abs() <= 360.0))
    {
        return Err(bad(format!("--turns-deg {t}: expected turns within ±360°")));
    }
    check_duration("--settle-s", args.settle_s, true)?;
    check_duration("--turn-s", args.turn_s, true)?;
    check_duration("--phase-s", args.phase_s, false)?;
    if args.phase_s <= args.turn_s {
        return Err(bad(format!(
            "--phase-s {}: expected longer than --turn-s {} (a phase holds after its turn)",
            args.phase_s, args.turn_s
        )));
    }
    let scene = scene_for(c, true)?;
    let target = args.target.unwrap_or(match scene.medium {
        Medium::Air => 0.4,
        Medium::Water => 1.6,
    });
    let object = named_object(&scene, &args.object)?;
    let model = load_model_and_pause(c, db).await?;
    let mut p = prepare(c, &model, &scene, object, &[target], ExitAction::Open, out).await?;
    let start = p.clock.now();
    let at = |s: f64| TimestampNs(start.0 + (s * 1e9) as u64);
    let mut yaw_deg = 0.0;
    let mut phases = Vec::new();
    for (i, turn) in args.turns_deg.iter().enumerate() {
        let t0 = at(args.settle_s + i as f64 * args.phase_s);
        yaw_deg += turn;
        p.handle
            .schedule_object_yaw(t0, yaw_deg.to_radians(), args.turn_s)
            .map_err(sim_failure)?;
        phases.push((*turn, yaw_deg, t_s(t0)));
    }
    let total_s = args.settle_s + args.turns_deg.len() as f64 * args.phase_s;
    let cycles = p
        .controller
        .follow(&[(target, Duration::from_secs_f64(total_s))])
        .await
        .map_err(grasp_failure)?;
    let yaws: Vec<f64> = cycles
        .iter()
        .map(|cy| p.handle.object_yaw(cy.t).map(f64::to_degrees))
        .collect::<Result<_, _>>()
        .map_err(sim_failure)?;

    let series = |f: fn(&Cycle) -> Option<f64>| -> Vec<(f64, f64)> {
        cycles
            .iter()
            .filter_map(|cy| Some((t_s(cy.t), f(cy)?)))
            .collect()
    };
    let (est, tru) = (series(|c| c.estimate_n), series(|c| c.true_n));
    let opt = |v: Option<f64>| v.map_or_else(|| "never".to_owned(), |s| format!("{s:.3}"));
    writeln!(
        out,
        "holding {target} N ({} medium) on `{}`",
        scene.medium, args.object
    )
    .map_err(io_failure)?;
    writeln!(
        out,
        "{:>5} {:>7} {:>6} {:>11} {:>10} {:>9} {:>12} {:>11} {:>10}",
        "phase",
        "turn °",
        "yaw °",
        "peak dev N",
        "recover s",
        "RMS N",
        "true peak N",
        "true rec s",
        "true RMS N"
    )
    .map_err(io_failure)?;
    for (i, (turn, yaw, t0)) in phases.iter().enumerate() {
        let t1 = t0 + args.phase_s;
        let e = phase_numbers(&est, *t0, t1, target, c.tolerance);
        let r = phase_numbers(&tru, *t0, t1, target, c.tolerance);
        let Some(e) = e else {
            writeln!(
                out,
                "{:>5} {turn:>7.1} {yaw:>6.1} (no usable estimate)",
                i + 1
            )
            .map_err(io_failure)?;
            continue;
        };
        writeln!(
            out,
            "{:>5} {turn:>7.1} {yaw:>6.1} {:>11.3} {:>10} {:>9.3} {:>12} {:>11} {:>10}",
            i + 1,
            e.peak_deviation_n,
            opt(e.recovery_s),
            e.rms_error_n,
            r.map_or_else(|| "-".into(), |r| format!("{:.3}", r.peak_deviation_n)),
            r.map_or_else(|| "-".into(), |r| opt(r.recovery_s)),
            r.map_or_else(|| "-".into(), |r| format!("{:.3}", r.rms_error_n)),
        )
        .map_err(io_failure)?;
    }
    let flagged = cycles.iter().filter(|c| c.single_finger.is_some()).count();
    if c.fingers == 2 && flagged > 0 {
        writeln!(
            out,
            "{flagged} cycles ran on one finger's estimate (the other gave none)"
        )
        .map_err(io_failure)?;
    }

    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-disturb.csv");
    let mut text = String::from(
        "t_s,target_n,estimate_n,true_n,object_yaw_deg,finger0_estimate_n,finger1_estimate_n,measured_count,request_count,outcome\n",
    );
    let o = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for (cy, yaw) in cycles.iter().zip(&yaws) {
        text.push_str(&format!(
            "{},{},{},{},{yaw},{},{},{},{},{}\n",
            t_s(cy.t),
            cy.target_n,
            o(cy.estimate_n),
            o(cy.true_n),
            o(cy.finger_estimates_n[0]),
            o(cy.finger_estimates_n[1]),
            cy.measured_position,
            cy.position_request,
            cy.outcome.map_or("awaiting_echo", |x| x.as_str()),
        ));
    }
    write_text(&csv, &text)?;
    let png = c.out_dir.join("grasp-disturb.png");
    let forces = [
        line("commanded F_ref", series(|c| Some(c.target_n))),
        line("estimated F_est", est),
        line("true (simulator)", tru),
    ];
    let angle = [line(
        "object yaw",
        cycles
            .iter()
            .zip(&yaws)
            .map(|(cy, y)| (t_s(cy.t), *y))
            .collect(),
    )];
    two_panels(
        &png,
        "Disturbance: the tube turned about its axis",
        (&forces, "grip force (N)"),
        (&angle, "rotation (°)"),
    )?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}

/// One run of `grasp twist`: the cycles and the simulator's τz and wrist log.
struct TwistRun {
    cycles: Vec<Cycle>,
    truth: Vec<TruthSample>,
    object_yaw_rad: Vec<f64>,
}

async fn twist(args: TwistArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let c = &args.common;
    check_common(c)?;
    if !(args.turn_deg.is_finite() && args.turn_deg.abs() <= 90.0) {
        return Err(bad(format!(
            "--turn-deg {}: expected a turn within ±90°",
            args.turn_deg
        )));
    }
    check_duration("--settle-s", args.settle_s, true)?;
    check_duration("--turn-s", args.turn_s, true)?;
    check_duration("--hold-s", args.hold_s, false)?;
    let wrist_config = WristConfig {
        gain_rad_per_nm_s: args.wrist_gain,
        deadband_nm: args.wrist_deadband_nmm / 1000.0,
        ..WristConfig::default()
    };
    let wrist_loop = WristLoop::new(wrist_config)
        .map_err(|e| bad(format!("--wrist-gain / --wrist-deadband-nmm: {e}")))?;
    let scene = scene_for(c, true)?;
    let object = named_object(&scene, &args.object)?;
    // The same config check as the loop's, before anything is built.
    ControllerConfig::new(projections().map_err(grasp_failure)?[0])
        .stepper
        .check_target(args.target)
        .map_err(grasp_failure)?;
    let model = load_model_and_pause(c, db).await?;
    let mut runs = Vec::new();
    for with_wrist in [false, true] {
        // The same grasp twice: its setup and warnings are printed once.
        let mut sink = std::io::sink();
        let setup_out: &mut dyn Write = if with_wrist { &mut sink } else { &mut *out };
        let p = prepare(
            c,
            &model,
            &scene,
            object.clone(),
            &[args.target],
            ExitAction::Open,
            setup_out,
        )
        .await?;
        let start = p.clock.now();
        let at = |s: f64| TimestampNs(start.0 + (s * 1e9) as u64);
        let turn_rad = args.turn_deg.to_radians();
        p.handle
            .schedule_object_yaw(at(args.settle_s), turn_rad, args.turn_s)
            .map_err(sim_failure)?;
        p.handle
            .schedule_object_yaw(
                at(args.settle_s + args.turn_s + args.hold_s),
                0.0,
                args.turn_s,
            )
            .map_err(sim_failure)?;
        let total_s = args.settle_s + 2.0 * (args.turn_s + args.hold_s);
        let mut controller = if with_wrist {
            p.controller
                .with_wrist(Box::new(SimWrist(p.handle.clone())), wrist_loop)
        } else {
            p.controller
        };
        let cycles = controller
            .follow(&[(args.target, Duration::from_secs_f64(total_s))])
            .await
            .map_err(grasp_failure)?;
        let truth = p
            .truth_log
            .lock()
            .map_err(|_| Failure::Runtime(anyhow!("truth log poisoned")))?
            .clone();
        let object_yaw_rad = truth
            .iter()
            .map(|s| p.handle.object_yaw(s.t))
            .collect::<Result<_, _>>()
            .map_err(sim_failure)?;
        runs.push((
            at(args.settle_s),
            TwistRun {
                cycles,
                truth,
                object_yaw_rad,
            },
        ));
    }
    let rms = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
        }
    };
    writeln!(
        out,
        "turning `{}` by {}° and back while holding {} N",
        args.object, args.turn_deg, args.target
    )
    .map_err(io_failure)?;
    writeln!(
        out,
        "{:>14} {:>14} {:>15} {:>16} {:>15} {:>14}",
        "wrist loop", "τz RMS N·mm", "true τz RMS", "true τz peak", "true F RMS N", "wrist max °"
    )
    .map_err(io_failure)?;
    for (i, (from, run)) in runs.iter().enumerate() {
        let est: Vec<f64> = run
            .cycles
            .iter()
            .filter(|cy| cy.t >= *from)
            .filter_map(|cy| cy.torque_z_nm)
            .map(|t| t * 1000.0)
            .collect();
        let tru: Vec<f64> = run
            .truth
            .iter()
            .filter(|s| s.t >= *from)
            .map(|s| s.torque_z_nm * 1000.0)
            .collect();
        let force_err: Vec<f64> = run
            .cycles
            .iter()
            .filter(|cy| cy.t >= *from)
            .filter_map(|cy| Some(cy.true_n? - cy.target_n))
            .collect();
        let wrist_max = run
            .truth
            .iter()
            .fold(0.0_f64, |m, s| m.max(s.wrist_rad.abs()))
            .to_degrees();
        writeln!(
            out,
            "{:>14} {:>14.3} {:>15.3} {:>16.3} {:>15.3} {:>14.2}",
            if i == 0 { "off" } else { "on" },
            rms(&est),
            rms(&tru),
            tru.iter().fold(0.0_f64, |m, t| m.max(t.abs())),
            rms(&force_err),
            wrist_max
        )
        .map_err(io_failure)?;
    }

    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-twist.csv");
    let mut text = String::from(
        "wrist_loop,t_s,target_n,estimate_n,true_n,tz_estimate_nmm,tz_true_nmm,object_yaw_deg,wrist_yaw_deg\n",
    );
    let o = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for (i, (_, run)) in runs.iter().enumerate() {
        for cy in &run.cycles {
            // The truth is logged per frame, skipping any it could not read: match by
            // the frame's time, not by position.
            let truth = run
                .truth
                .binary_search_by_key(&cy.t, |s| s.t)
                .ok()
                .map(|k| (&run.truth[k], run.object_yaw_rad[k]));
            text.push_str(&format!(
                "{},{},{},{},{},{},{},{},{}\n",
                if i == 0 { "off" } else { "on" },
                t_s(cy.t),
                cy.target_n,
                o(cy.estimate_n),
                o(cy.true_n),
                o(cy.torque_z_nm.map(|t| t * 1000.0)),
                o(truth.map(|(s, _)| s.torque_z_nm * 1000.0)),
                o(truth.map(|(_, yaw)| yaw.to_degrees())),
                o(truth.map(|(s, _)| s.wrist_rad.to_degrees())),
            ));
        }
    }
    write_text(&csv, &text)?;
    let png = c.out_dir.join("grasp-twist.png");
    let torque_series = |i: usize, label: &str| {
        line(
            label,
            runs[i]
                .1
                .truth
                .iter()
                .map(|s| (t_s(s.t), s.torque_z_nm * 1000.0))
                .collect(),
        )
    };
    let torques = [
        torque_series(0, "true τz, wrist loop off"),
        torque_series(1, "true τz, wrist loop on"),
        line(
            "estimated τz, wrist loop on",
            runs[1]
                .1
                .cycles
                .iter()
                .filter_map(|cy| Some((t_s(cy.t), cy.torque_z_nm? * 1000.0)))
                .collect(),
        ),
    ];
    let on = &runs[1].1;
    let angles = [
        line(
            "object yaw",
            on.truth
                .iter()
                .zip(&on.object_yaw_rad)
                .map(|(s, y)| (t_s(s.t), y.to_degrees()))
                .collect(),
        ),
        line(
            "wrist yaw (loop on)",
            on.truth
                .iter()
                .map(|s| (t_s(s.t), s.wrist_rad.to_degrees()))
                .collect(),
        ),
    ];
    two_panels(
        &png,
        "Twist: τz held by the wrist",
        (&torques, "τz (N·mm)"),
        (&angles, "yaw (°)"),
    )?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}

fn line(label: &str, points: Vec<(f64, f64)>) -> Series {
    Series {
        label: label.into(),
        points,
        style: SeriesStyle::Line,
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), Failure> {
    std::fs::write(path, text)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", path.display())))
}

/// Two charts over the same time axis, one above the other, in one PNG.
fn two_panels(
    path: &Path,
    title: &str,
    top: (&[Series], &str),
    bottom: (&[Series], &str),
) -> Result<(), Failure> {
    use plotters::prelude::*;
    let fail = |e: String| Failure::Runtime(anyhow!("cannot draw {}: {e}", path.display()));
    crate::plot::register_font().map_err(|e| fail(e.to_string()))?;
    let finite = |s: &[Series]| -> Vec<(f64, f64)> {
        s.iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect()
    };
    let (all_top, all_bottom) = (finite(top.0), finite(bottom.0));
    let bounds = |p: &[(f64, f64)], axis: usize| {
        let v = p.iter().map(|q| if axis == 0 { q.0 } else { q.1 });
        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(x), h.max(x))
        });
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        let m = if hi > lo { (hi - lo) * 0.05 } else { 0.5 };
        (lo - m, hi + m)
    };
    let both: Vec<(f64, f64)> = all_top.iter().chain(&all_bottom).copied().collect();
    let (x0, x1) = bounds(&both, 0);
    let root = BitMapBackend::new(path, (900, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let root = root
        .titled(title, (crate::plot::FONT_FAMILY, 22))
        .map_err(|e| fail(e.to_string()))?;
    let (upper, lower) = root.split_vertically(390);
    for (area, (series, y_label), points) in [(upper, top, &all_top), (lower, bottom, &all_bottom)]
    {
        let (y0, y1) = bounds(points, 1);
        let mut ctx = ChartBuilder::on(&area)
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(e.to_string()))?;
        ctx.configure_mesh()
            .x_desc("time (s)")
            .y_desc(y_label)
            .label_style((crate::plot::FONT_FAMILY, 13))
            .axis_desc_style((crate::plot::FONT_FAMILY, 15))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        for (i, s) in series.iter().enumerate() {
            let colour = crate::plot::PALETTE[i % crate::plot::PALETTE.len()];
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            ctx.draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                .map_err(|e| fail(e.to_string()))?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
        }
        ctx.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((crate::plot::FONT_FAMILY, 13))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
    }
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}
