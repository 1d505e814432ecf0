//! `softtouch grasp twist`: Figure 5's turn about the fingers' axis with the wrist loop,
//! on the simulator or a rig's real wrist; checks its flags, calls
//! [`softtouch_lab::grasp::twist`] and prints the table.

use std::io::Write;
use std::path::Path;

use clap::Args;
use softtouch_grasp::WristConfig;

use super::setup::{
    LoopArgs, bad, check_duration, create_out_dir, load_model_calibrate_and_pause, loop_settings,
    print_setup, scene_for,
};
use crate::Failure;
use crate::io_failure;
use softtouch_lab::grasp::soft::named_object;
use softtouch_lab::grasp::twist::{
    TwistSettings, print_twist_table, twist_rows, twist_sim, twist_summary, write_twist_csv,
    write_twist_metrics_csv, write_twist_png,
};

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
    /// Rig file: hold `--object` at its grasp pose from the rig's `[grasp]` on the real
    /// arm, Hand-E and finger camera while you turn it by hand, once without and once
    /// with the wrist loop turning the arm's flange (K from the object's stored
    /// `grasp calibrate --rig`; `--turn-deg`, `--settle-s`, `--turn-s`, `--hold-s`
    /// and the scene do not apply).
    #[arg(long)]
    pub rig: Option<std::path::PathBuf>,
    /// On a rig: how long each run holds the object, s.
    #[arg(long, default_value_t = 10.0, requires = "rig")]
    pub duration_s: f64,
    /// Shared loop options.
    #[command(flatten)]
    pub common: LoopArgs,
}

pub(super) async fn run(
    args: TwistArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if let Some(rig) = args.rig.clone() {
        return twist_rig(args, &rig, db, out).await;
    }
    let c = &args.common;
    let loop_settings = loop_settings(c)?;
    if !(args.turn_deg.is_finite() && args.turn_deg.abs() <= 90.0) {
        return Err(bad(format!(
            "--turn-deg {}: expected a turn within ±90°",
            args.turn_deg
        )));
    }
    check_duration("--settle-s", args.settle_s, true)?;
    check_duration("--turn-s", args.turn_s, true)?;
    check_duration("--hold-s", args.hold_s, false)?;
    let wrist = WristConfig {
        gain_rad_per_nm_s: args.wrist_gain,
        deadband_nm: args.wrist_deadband_nmm / 1000.0,
        ..WristConfig::default()
    };
    wrist
        .validate()
        .map_err(|e| bad(format!("--wrist-gain / --wrist-deadband-nmm: {e}")))?;
    let scene = scene_for(c)?;
    let object = named_object(&scene, &args.object)?;
    // The same config check as the loop's, before anything is built.
    softtouch_lab::grasp::settings::check_target_n(
        "--target",
        args.target,
        loop_settings.tolerance_n,
    )?;
    // Ctrl-C, SIGTERM or SIGHUP ends the run in hand after its cycle (fingers open)
    // and skips the next; the table and files show what ran. Watched before the
    // calibration (see `grasp follow`).
    let signals = crate::signals::SignalWatch::start();
    let (model, calibrated) =
        load_model_calibrate_and_pause(c, db, &scene, &object, args.target).await?;
    let settings = TwistSettings {
        loop_settings,
        target_n: args.target,
        turn_deg: args.turn_deg,
        settle_s: args.settle_s,
        turn_s: args.turn_s,
        hold_s: args.hold_s,
        wrist,
    };
    let (setup, runs, stopped) = twist_sim(
        &settings,
        &model,
        &scene,
        &object,
        &calibrated,
        Some(signals.request()),
    )
    .await?;
    // The same grasp twice: its setup and warnings are printed once.
    print_setup(&args.object, &setup, &loop_settings, out)?;
    if let Some(last) = runs.last() {
        super::setup::print_stopped(stopped, &last.cycles, out)?;
    }
    let w = io_failure;
    writeln!(
        out,
        "turning `{}` by {}° and back while holding {} N",
        args.object, args.turn_deg, args.target
    )
    .map_err(w)?;
    let rows = twist_rows(&runs);
    writeln!(
        out,
        "numbers count from the first turn ({} s after the grasp; the settle before it is left out)",
        args.settle_s
    )
    .map_err(w)?;
    print_twist_table(&rows, out).map_err(w)?;
    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-twist.csv");
    write_twist_csv(&csv, &runs)?;
    let metrics = c.out_dir.join("grasp-twist-metrics.csv");
    write_twist_metrics_csv(&metrics, &rows)?;
    let png = c.out_dir.join("grasp-twist.png");
    let drawn = if runs.iter().all(|r| r.cycles.is_empty()) {
        " (no cycle ran: no chart)".to_owned()
    } else {
        write_twist_png(&png, &runs)?;
        format!(" and {}", png.display())
    };
    writeln!(out, "wrote {}, {}{drawn}", csv.display(), metrics.display()).map_err(w)?;
    let grips: Vec<String> = runs
        .iter()
        .map(|r| {
            softtouch_lab::grasp::soft::grip_words(
                &r.cycles,
                (setup.touch, softtouch_drivers::gripper::STROKE_MM / 255.0),
            )
        })
        .collect();
    let summary = twist_summary(&rows, &grips);
    twist_recorder(&args)
        .setting("turn_deg", args.turn_deg)
        .setting("settle_s", args.settle_s)
        .setting("turn_s", args.turn_s)
        .setting("hold_s", args.hold_s)
        .setting("gain_n_per_mm", setup.gain)
        .setting("stopped_by", stopped)
        .scene_hash(super::setup::scene_hash(&scene, c))
        .table(&csv)
        .table(&metrics)
        .store(db, summary, out)
        .await
        .map(drop)
}

/// `grasp twist --rig FILE`: the twist on the rig's real wrist, without then with the
/// wrist loop (each run asks the operator to set the object in place); prints the τz
/// the finger's estimate felt in each and writes `grasp-twist-rig.csv`.
async fn twist_rig(
    args: TwistArgs,
    rig_path: &Path,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    use softtouch_lab::grasp::trials::experiment::open_rig_devices;
    use softtouch_lab::grasp::trials::rig::object_setup_on_rig;
    use softtouch_lab::grasp::trials::rig::twist::{
        RigTwistSettings, twist_without_then_with_wrist,
    };
    let c = &args.common;
    let wrist = WristConfig {
        gain_rad_per_nm_s: args.wrist_gain,
        deadband_nm: args.wrist_deadband_nmm / 1000.0,
        ..WristConfig::default()
    };
    wrist
        .validate()
        .map_err(|e| bad(format!("--wrist-gain / --wrist-deadband-nmm: {e}")))?;
    check_duration("--duration-s", args.duration_s, false)?;
    // The rig alone: a grasp uses none of a collection scene's poses.
    let rig = softtouch_collector::configs::rig(Some(rig_path))?.0;
    let store = crate::open_existing(db).await?;
    let bytes = softtouch_lab::models::force_artifact(&store, &c.model).await?;
    let setup =
        object_setup_on_rig(&store, &rig, &c.model, &bytes, &args.object, c.tolerance).await?;
    let grasp = rig
        .grasp
        .clone()
        .ok_or_else(|| bad("--rig: no [grasp] section".into()))?;
    let mut devices = open_rig_devices(&rig, rig_path, "twist").await?;
    let mut operator = super::trials::terminal_operator(false);
    let signals = crate::signals::SignalWatch::start();
    let settings = RigTwistSettings {
        object: args.object.clone(),
        target_n: args.target,
        duration_s: args.duration_s,
        gain_over_lambda: 0.75,
        wrist: Some(wrist),
        wrist_step_rad: 0.05,
        pregrasp_margin_mm: 6.0,
    };
    let pair = twist_without_then_with_wrist(
        &grasp,
        &rig.workspace,
        &setup,
        &mut devices,
        &mut operator,
        &bytes,
        &settings,
        || signals.request(),
        out,
    )
    .await?;
    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-twist-rig.csv");
    std::fs::write(&csv, pair.csv)
        .map_err(|e| Failure::Runtime(anyhow::anyhow!("{}: {e}", csv.display())))?;
    writeln!(out, "wrote {}", csv.display()).map_err(io_failure)?;
    twist_recorder(&args)
        .setting("duration_s", args.duration_s)
        .setting("rig", rig_path.display().to_string())
        .rig_hash(softtouch_lab::grasp::calibration::rig_setup_hash(&rig).ok())
        .table(&csv)
        .store(db, pair.summary.join("; "), out)
        .await
        .map(drop)
}

/// What `grasp twist` stores on the simulator and on a rig alike: the loop's flags,
/// the object, the force held and the wrist loop's settings.
fn twist_recorder(args: &TwistArgs) -> crate::results::Recorder {
    super::setup::loop_recorder("grasp twist", &args.common)
        .setting("object", args.object.as_str())
        .setting("target_n", args.target)
        .setting("wrist_gain_rad_per_nm_s", args.wrist_gain)
        .setting("wrist_deadband_nmm", args.wrist_deadband_nmm)
}
