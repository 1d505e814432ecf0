//! `softtouch grasp follow`: the force-following experiment of Figure 5 on the
//! simulated Hand-E with soft fingers, closed by a stored model's estimate.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_drivers::TokioClock;
use softtouch_drivers::sim::{GraspObject, SoftGraspHandle, soft_grasp};
use softtouch_grasp::{
    Controller, ControllerConfig, Cycle, GainCheck, GraspError, Projection, TrueForce, check_gain,
    check_tolerance, hold_metrics,
};
use softtouch_schemas::{ArmPose, TimestampNs};

use super::{Failure, io_failure, open_existing};
use crate::plot::{Series, SeriesStyle, XyChart, xy_chart};

/// The grasp experiments.
#[derive(Debug, Subcommand)]
pub enum GraspCommand {
    /// Hold each target force in turn on the simulated soft-finger Hand-E, the model's
    /// estimate closing the loop (Algorithm 1); prints rise time, settling time,
    /// overshoot, steady-state and RMS error per target; writes a CSV and a PNG.
    #[command(
        after_help = "Example:\n  softtouch grasp follow --model land-v1 --targets 0.4,1.6,3"
    )]
    Follow(FollowArgs),
}

/// Options of `grasp follow`.
#[derive(Debug, Args)]
pub struct FollowArgs {
    /// Stored model whose estimate closes the loop.
    #[arg(long)]
    pub model: String,
    /// Target forces, N, held in turn.
    #[arg(long, value_delimiter = ',', default_value = "0.4,1.6,3")]
    pub targets: Vec<f64>,
    /// Scene file (medium, effects, `[[objects]]`); default: the built-in scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Object to grasp (a `[[objects]]` name); default: the scene's first object,
    /// else a cylinder of the scene's first rod.
    #[arg(long)]
    pub object: Option<String>,
    /// Gain K, N/mm; default: 0.75 × the stiffness Λ_max measured on the simulator.
    #[arg(long)]
    pub gain: Option<f64>,
    /// Tolerance δ, N.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Camera rate, Hz (one control cycle per frame).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// How long each target is held, s.
    #[arg(long, default_value_t = 3.0)]
    pub hold_s: f64,
    /// Folder for `grasp-follow.csv` and `grasp-follow.png`.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
    /// Seed of the simulated scene's effects.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// The soft finger's sensor +x faces the object, so its push (−x) is the world's +y,
/// the paper's gripping direction.
fn projection() -> Result<Projection, GraspError> {
    Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
}

/// The simulator's truth for the record (the loop never reads it).
#[derive(Debug)]
struct SimTruth(SoftGraspHandle, Projection);

impl TrueForce for SimTruth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        self.0
            .true_wrench(t)
            .ok()
            .and_then(|w| self.1.grip_force_n(&w))
    }
}

fn grasp_failure(e: GraspError) -> Failure {
    match e {
        GraspError::Config(_) | GraspError::UnreachableTarget { .. } => Failure::BadInput(e.into()),
        GraspError::Device(_) | GraspError::Estimate(_) => Failure::Runtime(e.into()),
    }
}

/// Run a grasp verb.
pub async fn run(cmd: GraspCommand, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        GraspCommand::Follow(args) => follow(args, db, out).await,
    }
}

async fn follow(args: FollowArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let bad = |m: String| Failure::BadInput(anyhow!(m));
    if args.targets.is_empty() {
        return Err(bad("--targets: expected at least one force in N".into()));
    }
    if !(args.hold_s.is_finite() && args.hold_s > 0.0 && args.hold_s <= 600.0) {
        return Err(bad(format!(
            "--hold-s {}: expected a time in (0, 600] s",
            args.hold_s
        )));
    }
    if !(args.fps.is_finite() && (1.0..=1000.0).contains(&args.fps)) {
        return Err(bad(format!(
            "--fps {}: expected a rate in [1, 1000] Hz",
            args.fps
        )));
    }
    let resolved = crate::configs::resolve(None, args.scene.as_deref())?;
    let scene = resolved.scene;
    let object = match (&args.object, scene.objects.first(), scene.rods.first()) {
        (Some(name), ..) => GraspObject::from_spec(scene.object(name).ok_or_else(|| {
            bad(format!(
                "--object {name}: the scene declares no such object (it has: {})",
                scene
                    .objects
                    .iter()
                    .map(|o| o.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?),
        (None, Some(o), _) => GraspObject::from_spec(o),
        (None, None, Some(rod)) => GraspObject {
            shape: rod.shape,
            aspect: rod.aspect,
            ..GraspObject::cylinder(&rod.name, rod.size_m)
        },
        (None, None, None) => return Err(bad("the scene has neither objects nor rods".into())),
    };
    let store = open_existing(db).await?;
    let bytes = crate::models::artifact(&store, &args.model).await?;
    let predictor = softtouch_trainer::Predictor::from_bytes(&bytes)?;
    drop(store);

    tokio::time::pause(); // virtual time for the simulated gripper and camera
    let clock = TokioClock::new();
    let (gripper, camera, handle) = soft_grasp(&scene, object.clone(), args.fps, args.seed, clock)
        .map_err(|e| bad(format!("object `{}`: {e}", object.name)))?;
    let sim_err = |e: softtouch_drivers::sim::SimError| Failure::Runtime(e.into());
    let touch = handle
        .contact_count(0.02)
        .map_err(sim_err)?
        .ok_or_else(|| {
            bad(format!(
                "object `{}` is never touched by the closing fingers",
                object.name
            ))
        })?;
    // Λ_max from first touch to 1.5 × the largest target, on the contact physics.
    let top_n = 1.5 * args.targets.iter().copied().fold(0.0, f64::max);
    let counts: Vec<u8> = (touch..=255).collect();
    let curve = handle.grip_force_curve(&counts).map_err(sim_err)?;
    let end = curve
        .iter()
        .find(|(_, f)| *f > top_n)
        .map_or(255, |(p, _)| *p);
    let lambda_max = handle.max_stiffness_n_per_mm(touch, end).map_err(sim_err)?;
    let gain = args.gain.unwrap_or(0.75 * lambda_max);
    let mut config = ControllerConfig::new(projection().map_err(grasp_failure)?);
    config.stepper.gain_n_per_mm = gain;
    config.stepper.tolerance_n = args.tolerance;
    let w = |e| io_failure(e);
    writeln!(
        out,
        "object `{}`: first touch at count {touch}; measured Λ_max = {lambda_max:.3} N/mm; K = {gain:.3} N/mm, δ = {} N, {} Hz",
        object.name, args.tolerance, args.fps
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
    if !check_tolerance(args.tolerance, lambda_max, &config.stepper.stroke) {
        writeln!(
            out,
            "warning: δ is below half the force of one count: expect dithering"
        )
        .map_err(w)?;
    }
    let truth = SimTruth(handle.clone(), config.projection);
    let mut controller =
        Controller::new(gripper, camera, predictor, truth, Arc::new(clock), config)
            .map_err(grasp_failure)?;
    controller
        .approach(touch.saturating_sub(4), Duration::from_secs(5))
        .await
        .map_err(grasp_failure)?;
    let hold = Duration::from_secs_f64(args.hold_s);
    let targets: Vec<(f64, Duration)> = args.targets.iter().map(|t| (*t, hold)).collect();
    let cycles = controller.follow(&targets).await.map_err(grasp_failure)?;

    print_table(&cycles, &args.targets, args.tolerance, out)?;
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out_dir.display())))?;
    let csv = args.out_dir.join("grasp-follow.csv");
    write_csv(&csv, &cycles)?;
    let png = args.out_dir.join("grasp-follow.png");
    write_png(&png, &cycles)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(w)?;
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
        "{:>8} {:>9} {:>10} {:>11} {:>11} {:>9} {:>12} {:>10}",
        "target N",
        "rise s",
        "settle s",
        "overshoot N",
        "ss error N",
        "RMS N",
        "true ss N",
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
                "{:>8.2} {:>9} {:>10} {:>11.3} {:>11.3} {:>9.3} {:>12} {:>10}",
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
        "t_s,frame,target_n,estimate_n,true_n,measured_count,request_count,outcome,object\n",
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
