//! `softtouch grasp disturb`: Figure 5's turn of the gripped object about its own axis
//! while the loop holds the force; checks its flags, calls
//! [`softtouch_lab::grasp::disturb`] and prints the table.

use std::io::Write;

use clap::Args;
use softtouch_schemas::Medium;

use super::setup::{
    LoopArgs, bad, check_duration, create_out_dir, load_model_calibrate_and_pause, loop_settings,
    print_setup, scene_for,
};
use crate::Failure;
use crate::io_failure;
use softtouch_lab::grasp::disturb::{
    DisturbSettings, disturb_rows, disturb_sim, disturb_summary, print_disturb_table,
    write_disturb_csv, write_disturb_png,
};
use softtouch_lab::grasp::soft::named_object;

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

pub(super) async fn run(
    args: DisturbArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let c = &args.common;
    let loop_settings = loop_settings(c)?;
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
    let scene = scene_for(c)?;
    let target = args.target.unwrap_or(match scene.medium {
        Medium::Air => 0.4,
        Medium::Water => 1.6,
    });
    let object = named_object(&scene, &args.object)?;
    softtouch_lab::grasp::settings::check_target_n("--target", target, loop_settings.tolerance_n)?;
    // Ctrl-C, SIGTERM or SIGHUP ends the loop after its cycle, the fingers open; the
    // table and files then show what ran. Watched before the calibration (see `grasp
    // follow`).
    let signals = crate::signals::SignalWatch::start();
    let (model, calibrated) =
        load_model_calibrate_and_pause(c, db, &scene, &object, target).await?;
    let settings = DisturbSettings {
        loop_settings,
        target_n: target,
        turns_deg: args.turns_deg.clone(),
        settle_s: args.settle_s,
        turn_s: args.turn_s,
        phase_s: args.phase_s,
    };
    let run = disturb_sim(
        &settings,
        &model,
        &scene,
        object,
        &calibrated,
        Some(signals.request()),
    )
    .await?;
    print_setup(&args.object, &run.setup, &loop_settings, out)?;
    super::setup::print_stopped(run.stopped, &run.cycles, out)?;
    let w = io_failure;
    writeln!(
        out,
        "holding {target} N ({} medium) on `{}`",
        scene.medium, args.object
    )
    .map_err(w)?;
    print_disturb_table(&disturb_rows(&run, &settings), out).map_err(w)?;
    let flagged = run
        .cycles
        .iter()
        .filter(|c| c.single_finger.is_some())
        .count();
    if c.fingers == 2 && flagged > 0 {
        writeln!(
            out,
            "{flagged} cycles ran on one finger's estimate (the other gave none)"
        )
        .map_err(w)?;
    }
    create_out_dir(&c.out_dir)?;
    let csv = c.out_dir.join("grasp-disturb.csv");
    write_disturb_csv(&csv, &run)?;
    let png = c.out_dir.join("grasp-disturb.png");
    let drawn = if run.cycles.is_empty() {
        " (no cycle ran: no chart)".to_owned()
    } else {
        write_disturb_png(&png, &run)?;
        format!(" and {}", png.display())
    };
    writeln!(out, "wrote {}{drawn}", csv.display()).map_err(w)?;
    let grip = softtouch_lab::grasp::soft::grip_words(
        &run.cycles,
        (
            run.setup.touch,
            softtouch_drivers::gripper::STROKE_MM / 255.0,
        ),
    );
    let summary = disturb_summary(&disturb_rows(&run, &settings), target, &grip);
    super::setup::loop_recorder("grasp disturb", c)
        .setting("object", args.object.as_str())
        .setting("target_n", target)
        .setting("turns_deg", args.turns_deg.clone())
        .setting("settle_s", args.settle_s)
        .setting("turn_s", args.turn_s)
        .setting("phase_s", args.phase_s)
        .setting("gain_n_per_mm", run.setup.gain)
        .setting("stopped_by", run.stopped)
        .scene_hash(super::setup::scene_hash(&scene, c))
        .table(&csv)
        .store(db, summary, out)
        .await
        .map(drop)
}
