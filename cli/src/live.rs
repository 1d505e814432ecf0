//! `softtouch live`: the model's estimate at camera rate beside the force/torque
//! sensor (the paper's Movie S2). Every frame is run through the stored model and paired
//! with the sensor reading nearest its exposure; a line is printed every few frames and
//! every frame goes to a CSV (t, the estimated 6 axes, the sensor's 6 axes).
//!
//! The devices are the ones `collect` builds from the rig config. With a simulated arm
//! (the embedded rig) the arm runs a scripted press on the scene's rod: home, approach,
//! press in, hold, out, home. On a real rig it only watches unless `--press` asks for
//! the script. Every command is checked against the workspace, the sensor is guarded
//! against the rig's force and torque limits, and any error or an early end stops the
//! arm before the verb returns.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::anyhow;
use clap::Args;
use softtouch_drivers::{Arm, ForceSensor};
use softtouch_schemas::rig::{ArmDevice, CameraDevice};

use super::{Failure, io_failure, open_existing};

/// Options of `live`.
#[derive(Debug, Args)]
pub struct LiveArgs {
    /// Stored model whose estimate is shown.
    #[arg(long)]
    pub model: String,
    /// Rig file; default: the embedded all-simulated rig.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Scene file; default: the built-in scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// How long to watch, s; default: the scripted press and half a second, or 10 s
    /// when only watching. Ending before the script does stops the arm where it is.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Run the scripted press on a real arm too (a simulated arm always runs it).
    #[arg(long)]
    pub press: bool,
    /// How deep the press goes past first contact, m (contact offset x of the rod frame).
    #[arg(long, default_value_t = 0.03)]
    pub depth_m: f64,
    /// Print a line every this many frames.
    #[arg(long, default_value_t = 12)]
    pub every: u64,
    /// The CSV of every frame.
    #[arg(long, default_value = "live.csv")]
    pub out: PathBuf,
    /// Seed of the simulated devices.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Run `softtouch live`.
pub async fn run(
    args: LiveArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let bad = |m: String| Failure::BadInput(anyhow!(m));
    if let Some(d) = args.duration_s
        && !(d.is_finite() && d > 0.0 && d <= 3600.0)
    {
        return Err(bad(format!(
            "--duration-s {d}: expected a time in (0, 3600] s"
        )));
    }
    if args.every == 0 {
        return Err(bad("--every 0: expected at least 1 frame".into()));
    }
    if !args.depth_m.is_finite() {
        return Err(bad(format!(
            "--depth-m {}: expected a finite depth in m",
            args.depth_m
        )));
    }
    let resolved =
        softtouch_collector::configs::resolve(args.rig.as_deref(), args.scene.as_deref())?;
    let rig = resolved.rig;
    let press = args.press || matches!(rig.arm, ArmDevice::Sim { .. });
    let steps = if press {
        softtouch_lab::live::press_script(&rig, args.depth_m).map_err(bad)?
    } else {
        Vec::new()
    };
    // Without --duration-s: the whole script and half a second (failing if the script
    // takes far longer than planned), or 10 s of watching.
    let until = match (args.duration_s, press) {
        (Some(d), _) => softtouch_lab::live::Until::For(Duration::from_secs_f64(d)),
        (None, true) => softtouch_lab::live::Until::ScriptDone {
            tail: Duration::from_secs_f64(softtouch_lab::live::TAIL_S),
            limit: Duration::from_secs_f64(
                3.0 * softtouch_lab::live::script_s(&rig, &steps) + 10.0,
            ),
        },
        (None, false) => softtouch_lab::live::Until::For(Duration::from_secs(10)),
    };
    let store = open_existing(db).await?;
    let bytes = softtouch_lab::models::force_artifact(&store, &args.model).await?;
    let mut predictor = softtouch_trainer::Predictor::from_bytes(&bytes)?;
    drop(store);
    let camera_rate = match &rig.camera {
        CameraDevice::Sim { fps } => format!("{fps} Hz simulated camera"),
        CameraDevice::V4l { device, .. } => format!("camera {device} at its own rate"),
    };

    let (devices, clock) =
        softtouch_collector::collect::build_devices(&rig, &resolved.scene, args.seed)
            .await
            .map_err(|e| Failure::Runtime(e.into()))?;
    let softtouch_collector::collect::CollectDevices {
        mut arm,
        mut force_sensor,
        mut camera,
        ..
    } = devices;
    // From here on the devices are open: a signal ends the session through the same
    // exit as an error (the arm is stopped, the CSV flushed).
    let signals = super::signals::SignalWatch::start();
    let file = std::fs::File::create(&args.out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out.display())))?;
    let mut csv = std::io::BufWriter::new(file);
    let session = softtouch_lab::live::Session {
        rig: &rig,
        steps: &steps,
        until,
        every: args.every,
        frame_timeout_ms: (rig.procedure.frame_timeout_s * 1000.0).ceil() as u64,
        clock: &clock,
        stop: signals.request(),
    };
    writeln!(
        out,
        "live: model `{}`, {camera_rate}, {}; {}",
        args.model,
        if press {
            "scripted press"
        } else {
            "watching (no motion)"
        },
        match until {
            softtouch_lab::live::Until::For(d) => format!("{:.1} s", d.as_secs_f64()),
            // No total is promised: the moves take what the arm's own limits allow.
            softtouch_lab::live::Until::ScriptDone { tail, .. } => format!(
                "until the script ends ({} moves, {:.1} s held; at least {:.1} s at the commanded speeds) and {:.1} s more",
                steps.iter().filter(|s| matches!(s, softtouch_lab::live::Step::Move(..))).count(),
                softtouch_lab::live::HOLD_S,
                softtouch_lab::live::script_s(&rig, &steps),
                tail.as_secs_f64()
            ),
        }
    )
    .map_err(io_failure)?;
    let result = session
        .run(
            arm.as_mut(),
            force_sensor.as_mut(),
            camera.as_mut(),
            &mut predictor,
            &mut csv,
            out,
        )
        .await;
    // The arm ends still on every path; a stop that fails is reported beside the cause.
    let stopped = arm.stop().await;
    let _ = force_sensor.stop().await;
    let flushed = csv.flush();
    let summary = result.map_err(|e| match &stopped {
        Ok(()) => Failure::Runtime(anyhow!("{e} (the arm was stopped)")),
        Err(s) => Failure::Runtime(anyhow!("{e}; stopping the arm failed too: {s}")),
    })?;
    stopped.map_err(|e| Failure::Runtime(anyhow!("stopping the arm: {e}")))?;
    flushed.map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", args.out.display())))?;
    summary.print(out).map_err(io_failure)?;
    writeln!(out, "wrote {}", args.out.display()).map_err(io_failure)?;
    let png = args.out.with_extension("png");
    plot_csv(&args.out, &png, &args.model)?;
    writeln!(out, "wrote {}", png.display()).map_err(io_failure)?;
    Ok(())
}

/// The CSV `live` wrote, as a plot: per axis, the model's estimate and the sensor over
/// time (torques in N·mm).
fn plot_csv(csv: &Path, png: &Path, model: &str) -> Result<(), Failure> {
    use softtouch_collector::plot::{Series, SeriesStyle, TimePanel, time_grid};
    let text = std::fs::read_to_string(csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot read {}: {e}", csv.display())))?;
    // 14 columns: t, frame, the estimate's 6 axes, the sensor's 6 (empty: none).
    let mut est: [Vec<(f64, f64)>; 6] = Default::default();
    let mut ft: [Vec<(f64, f64)>; 6] = Default::default();
    for line in text.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let Some(t) = cells.first().and_then(|c| c.parse::<f64>().ok()) else {
            continue;
        };
        // Torques are in N·mm already (the header says `_nmm`).
        for axis in 0..6 {
            let at = |i: usize| {
                cells
                    .get(i)
                    .and_then(|c| c.parse::<f64>().ok())
                    .unwrap_or(f64::NAN)
            };
            est[axis].push((t, at(2 + axis)));
            ft[axis].push((t, at(8 + axis)));
        }
    }
    let names = softtouch_trainer::AXES;
    let labels: Vec<String> = (0..6)
        .map(|a| format!("{}, {}", names[a], softtouch_trainer::UNITS[a]))
        .collect();
    let panels: Vec<TimePanel<'_>> = (0..6)
        .map(|a| {
            (
                names[a],
                labels[a].as_str(),
                vec![
                    Series {
                        label: "model".into(),
                        points: std::mem::take(&mut est[a]),
                        style: SeriesStyle::Line,
                    },
                    Series {
                        label: "sensor".into(),
                        points: std::mem::take(&mut ft[a]),
                        style: SeriesStyle::Line,
                    },
                ],
            )
        })
        .collect();
    time_grid(
        png,
        &format!("live: model `{model}` (blue) beside the force/torque sensor (orange)"),
        &panels,
        3,
    )
    .map_err(|e| Failure::Runtime(anyhow!("{e}")))
}
