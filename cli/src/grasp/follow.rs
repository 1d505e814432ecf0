//! `softtouch grasp follow`: hold each target force in turn (Figure 5), on the
//! simulated soft-finger Hand-E or on a rig's; prints the table per target and writes
//! the CSVs and the chart.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::anyhow;
use clap::Args;
use softtouch_grasp::{ControllerConfig, Cycle};
use softtouch_trainer::Predictor;

use super::setup::{
    LoopArgs, bad, check_duration, create_out_dir, grasp_failure, load_model_calibrate_and_pause,
    loop_settings, print_setup, print_stopped, scene_for,
};
use crate::{Failure, io_failure, open_existing};
use softtouch_lab::grasp::follow::{
    FollowSettings, follow_rows, follow_sim, object_for, write_follow_csv,
    write_follow_metrics_csv, write_follow_png,
};
use softtouch_lab::grasp::soft::projections;

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
    /// finger), after an end calibration with nothing between the fingers; the squeeze
    /// bound, and K unless `--gain`, then come from the latest `grasp calibrate --rig`
    /// of `--object` (required) with this model and rig file. A rig with a simulated
    /// gripper runs the simulated soft grasp.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Shared loop options.
    #[command(flatten)]
    pub common: LoopArgs,
}

pub(super) async fn run(
    args: FollowArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let c = &args.common;
    if args.targets.is_empty() {
        return Err(bad("--targets: expected at least one force in N".into()));
    }
    check_duration("--hold-s", args.hold_s, false)?;
    let loop_settings = loop_settings(c)?;
    if let Some(rig_path) = &args.rig {
        // The rig alone: a grasp uses none of a collection scene's poses.
        let rig = softtouch_collector::configs::rig(Some(rig_path))?.0;
        if softtouch_lab::grasp::devices::has_real_gripper(&rig) {
            return follow_on_rig(&args, &rig, db, out).await;
        }
    }
    // The targets before anything else: a calibration for an unreachable one is
    // neither made nor refused in its place.
    for t in &args.targets {
        softtouch_lab::grasp::settings::check_target_n("--targets", *t, c.tolerance)
            .map_err(|e| bad(e.to_string()))?;
    }
    let scene = scene_for(c)?;
    let object = object_for(&scene, args.object.as_deref())?;
    let largest = args.targets.iter().copied().fold(0.0, f64::max);
    // Ctrl-C, SIGTERM or SIGHUP ends the loop after its cycle, the fingers open; the
    // table and files then show what ran. Watched before the calibration, so that a
    // signal during it ends the verb the same way (after the calibration, which is
    // stored whole) instead of killing it with the database open.
    let signals = crate::signals::SignalWatch::start();
    let (model, calibrated) =
        load_model_calibrate_and_pause(c, db, &scene, &object, largest).await?;
    let settings = FollowSettings {
        loop_settings,
        targets_n: args.targets.clone(),
        hold_s: args.hold_s,
    };
    let name = object.name.clone();
    let (setup, cycles, stopped) = follow_sim(
        &settings,
        &model,
        &scene,
        object,
        &calibrated,
        Some(signals.request()),
    )
    .await?;
    print_setup(&name, &setup, &loop_settings, out)?;
    print_stopped(stopped, &cycles, out)?;
    let (files, summary) = print_follow(
        &cycles,
        &args.targets,
        c.tolerance,
        (setup.touch, softtouch_drivers::gripper::STROKE_MM / 255.0),
        &c.out_dir,
        out,
    )?;
    follow_recorder(&args, &name, stopped, files)
        .setting("gain_n_per_mm", setup.gain)
        .scene_hash(super::setup::scene_hash(&scene, c))
        .store(db, summary, out)
        .await
        .map(drop)
}

/// What `grasp follow` stores: its settings, the model, the tables it wrote.
fn follow_recorder(
    args: &FollowArgs,
    object: &str,
    stopped: Option<&'static str>,
    files: [PathBuf; 2],
) -> crate::results::Recorder {
    super::setup::loop_recorder("grasp follow", &args.common)
        .setting("targets_n", args.targets.clone())
        .setting("hold_s", args.hold_s)
        .setting("object", object)
        .setting("rig", args.rig.as_ref().map(|p| p.display().to_string()))
        .setting("stopped_by", stopped)
        .table(&files[0])
        .table(&files[1])
}

/// `grasp follow --rig FILE` on a real Hand-E: the squeeze bound, and K unless
/// `--gain`, from the latest `grasp calibrate --rig FILE` of `--object` with this
/// model (the rig's gripper and cameras and the model's artifact must be the same);
/// no truth column; the stroke comes from the end calibration.
async fn follow_on_rig(
    args: &FollowArgs,
    rig: &softtouch_schemas::RigConfig,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let c = &args.common;
    if c.fingers == 2 && rig.second_camera.is_none() {
        return Err(bad(
            "--fingers 2: the rig has no second_camera for the second finger".into(),
        ));
    }
    let store = open_existing(db).await?;
    let bytes = softtouch_lab::models::force_artifact(&store, &c.model).await?;
    // The calibration always: every force loop takes its squeeze bound from it, and K
    // too unless --gain is given.
    let object = args.object.as_deref().ok_or_else(|| {
        bad("--object: on a real gripper the loop's squeeze bound (and K = 0.75 Λ_max, unless --gain) comes from the latest `grasp calibrate --rig` of --object with this model".into())
    })?;
    let rig_path = args.rig.as_deref().unwrap_or_else(|| Path::new(""));
    let sha = softtouch_collector::dataset::export::sha256_hex;
    let setup = softtouch_lab::grasp::calibration::rig_setup_hash(rig)
        .map_err(|e| Failure::Runtime(anyhow!("{e}")))?;
    let cal = store
        .latest_grasp_calibration(&setup, &sha(&bytes), object)
        .await
        .map_err(|e| Failure::Runtime(anyhow!("{e}")))?
        .ok_or_else(|| {
            bad(format!(
                "no calibration of `{object}` with model `{}` on this rig's gripper and cameras: run `softtouch grasp calibrate --rig {} --model {} --object {object}` first",
                c.model,
                rig_path.display(),
                c.model
            ))
        })?;
    let squeeze = softtouch_lab::grasp::calibration::squeeze_of_row(&cal)
        .map_err(|e| Failure::Runtime(anyhow!("{e}")))?;
    let gain = c.gain.unwrap_or(0.75 * cal.lambda_max_n_per_mm);
    let touch_count = cal.touch_count;
    let largest = args.targets.iter().copied().fold(0.0, f64::max);
    writeln!(
        out,
        "calibration #{} (stored, {}): first touch at count {}, Λ_max = {:.3} N/mm from the model's estimate; K = {}; squeeze bound for {largest} N: count {} ({:.2} mm past the touch, {} × the calibrated squeeze + {} counts)",
        cal.calibration_id,
        cal.created_at,
        cal.touch_count,
        cal.lambda_max_n_per_mm,
        if c.gain.is_some() { "--gain" } else { "0.75 Λ_max" },
        squeeze.limit_count(largest),
        squeeze.limit_mm(largest),
        squeeze.factor,
        squeeze.floor_counts
    )
    .map_err(io_failure)?;
    store.close().await;
    let predictor = Predictor::from_bytes(&bytes)?;
    let projections = projections().map_err(grasp_failure)?;
    let mut config = ControllerConfig::new(projections[0]).with_squeeze(squeeze);
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
    let signals = crate::signals::SignalWatch::start();
    let run = softtouch_lab::grasp::devices::follow_on_rig(
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
        softtouch_lab::grasp::devices::RigFollowError::Open(e) => Failure::Runtime(anyhow!("{e}")),
        softtouch_lab::grasp::devices::RigFollowError::Grasp(e) => grasp_failure(e),
    })?;
    let cal = run.calibration;
    writeln!(
        out,
        "calibrated: reached counts {} (open) and {} (closed); stroke {}–{} at {:.4} mm per count",
        cal.open_reached,
        cal.closed_reached,
        cal.stroke.open_count,
        cal.stroke.closed_count,
        cal.stroke.mm_per_count
    )
    .map_err(io_failure)?;
    print_stopped(run.stopped, &run.cycles, out)?;
    let (files, summary) = print_follow(
        &run.cycles,
        &args.targets,
        c.tolerance,
        (touch_count, cal.stroke.mm_per_count),
        &c.out_dir,
        out,
    )?;
    let rig_hash = softtouch_lab::grasp::calibration::rig_setup_hash(rig).ok();
    follow_recorder(
        args,
        args.object.as_deref().unwrap_or("-"),
        run.stopped,
        files,
    )
    .setting("gain_n_per_mm", gain)
    .rig_hash(rig_hash)
    .store(db, summary, out)
    .await
    .map(drop)
}

/// `grasp follow`'s table per target, then its CSVs (cycles, metrics) and chart;
/// returns the CSVs and a one-line summary: per target the estimate's steady-state
/// error beside the peak true force where the simulator knows it, else the closing
/// past the calibrated touch (`touch`: its count and mm per count).
fn print_follow(
    cycles: &[Cycle],
    targets: &[f64],
    tolerance_n: f64,
    touch: (u8, f64),
    out_dir: &Path,
    out: &mut dyn Write,
) -> Result<([PathBuf; 2], String), Failure> {
    let rows = follow_rows(cycles, targets, tolerance_n, touch);
    softtouch_lab::grasp::follow::print_follow_table(&rows, tolerance_n, out)
        .map_err(io_failure)?;
    create_out_dir(out_dir)?;
    let csv = out_dir.join("grasp-follow.csv");
    write_follow_csv(&csv, cycles)?;
    let metrics = out_dir.join("grasp-follow-metrics.csv");
    write_follow_metrics_csv(&metrics, &rows)?;
    // A stop before the first cycle leaves nothing to draw: the CSVs say so (headers
    // only) and no chart is written.
    let png = out_dir.join("grasp-follow.png");
    let drawn = if cycles.is_empty() {
        " (no cycle ran: no chart)".to_owned()
    } else {
        write_follow_png(&png, cycles)?;
        format!(" and {}", png.display())
    };
    writeln!(out, "wrote {}, {}{drawn}", csv.display(), metrics.display(),).map_err(io_failure)?;
    let summary = rows
        .iter()
        .map(|r| {
            let grip = match (r.peak_true_n, r.past_touch_mm) {
                (Some(p), _) => format!(", peak true {p:.2} N"),
                (None, Some(mm)) => format!(", closed {mm:.2} mm past the touch"),
                (None, None) => String::new(),
            };
            r.estimate.map_or_else(
                || format!("{:.2} N: no estimate{grip}", r.target_n),
                |m| {
                    format!(
                        "{:.2} N: ss error {:.3} N{grip}",
                        r.target_n, m.steady_state_error_n
                    )
                },
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    Ok(([csv, metrics], summary))
}
