//! `softtouch rig check`: checks the flags, runs [`softtouch_lab::rig_check::check_rig`] and
//! prints its pass/fail table (exit 0 only when every row passes).

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::anyhow;
use clap::{Args, Subcommand};

use super::{Failure, io_failure};
use softtouch_lab::rig_check::{CheckRow, check_rig};

/// Rig verbs.
#[derive(Debug, Subcommand)]
pub enum RigCommand {
    /// Exercise every configured device briefly: arm state, force/torque stream rate and
    /// status, a frame from each camera, gripper activation with a small close/open.
    /// Prints a pass/fail table; exit 0 only if every device passes, 1 otherwise.
    #[command(after_help = "Examples:
  softtouch rig check                      # the embedded all-simulated rig
  softtouch rig check --rig lab.toml --window-s 1")]
    Check(CheckArgs),
}

/// Options of `rig check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Rig file; default: the embedded all-simulated rig.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Scene file for the simulated devices, checked against the rig; default: the
    /// built-in scene (its poses not checked: only its physics is used).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// How long the force/torque stream is read, s.
    #[arg(long, default_value_t = 0.5)]
    pub window_s: f64,
    /// Longest time one device's check may take (opening included), s.
    #[arg(long, default_value_t = 5.0)]
    pub timeout_s: f64,
}

/// Run a rig verb.
pub async fn run(cmd: RigCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        RigCommand::Check(args) => check_verb(args, out).await,
    }
}

async fn check_verb(args: CheckArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let bad = |m: String| Failure::BadInput(anyhow!(m));
    if !(args.window_s.is_finite() && args.window_s > 0.0 && args.window_s <= 60.0) {
        return Err(bad(format!(
            "--window-s {}: expected a time in (0, 60] s",
            args.window_s
        )));
    }
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0 && args.timeout_s <= 600.0) {
        return Err(bad(format!(
            "--timeout-s {}: expected a time in (0, 600] s",
            args.timeout_s
        )));
    }
    if args.timeout_s <= args.window_s {
        return Err(bad(format!(
            "--timeout-s {} must exceed --window-s {} (the stream is read for the window)",
            args.timeout_s, args.window_s
        )));
    }
    // A named scene must fit the rig (its poses are the ones a collection would visit);
    // without one the built-in scene only gives the simulated devices their physics,
    // and its poses (θ over ±π) are not held against a rig that turns less (an FR3's).
    let (rig, scene) = match args.scene.as_deref() {
        Some(_) => {
            let r =
                softtouch_collector::configs::resolve(args.rig.as_deref(), args.scene.as_deref())?;
            (r.rig, r.scene)
        }
        None => (
            softtouch_collector::configs::rig(args.rig.as_deref())?.0,
            softtouch_collector::configs::scene(None)?.0,
        ),
    };
    let rows = check_rig(
        &rig,
        &scene,
        Duration::from_secs_f64(args.window_s),
        Duration::from_secs_f64(args.timeout_s),
    )
    .await;
    print_rows(&rows, out)?;
    let failed = rows.iter().filter(|r| !r.pass()).count();
    if failed == 0 {
        Ok(())
    } else {
        Err(Failure::Runtime(anyhow!(
            "rig check: {failed} of {} checks failed (the host and each device)",
            rows.len()
        )))
    }
}

fn print_rows(rows: &[CheckRow], out: &mut dyn Write) -> Result<(), Failure> {
    writeln!(
        out,
        "{:<14} {:<11} {:<6} detail",
        "device", "driver", "result"
    )
    .map_err(io_failure)?;
    for r in rows {
        writeln!(
            out,
            "{:<14} {:<11} {:<6} {}",
            r.device,
            r.driver,
            if r.pass() { "pass" } else { "FAIL" },
            match &r.outcome {
                Ok(m) => m.to_string(),
                Err(e) => e.to_string(),
            }
        )
        .map_err(io_failure)?;
    }
    Ok(())
}
