//! `softtouch collect` and `softtouch status`.

use super::{Failure, io_failure, open_existing};
use crate::collect::rods::{RodChanger, TerminalOperator};
use crate::collect::sampler::RodSchedule;
use crate::collect::{CollectDevices, CollectPlan, Counters, Outcome, Progress, collect};
use crate::configs;
use crate::store::{OwnedNewRun, RunStatus, SyncStore};
use anyhow::anyhow;
use clap::Args;
use softtouch_drivers::TokioClock;
use softtouch_schemas::config::{ConfigSource, parse_toml, to_toml};
use softtouch_schemas::{ArmDevice, CameraDevice, ForceSensorDevice, RigConfig, SceneSpec};
use std::io::{IsTerminal as _, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `softtouch collect`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:
  softtouch collect --samples 200 --seed 1          # simulated rig, on-land scene
  softtouch collect --scene scenes/water.toml --samples 30000
  softtouch collect --rig lab-rig.toml --scene rods.toml --rods circle-10 --samples 5000
  softtouch collect --resume 3                      # continue run 3 where it stopped

Ctrl-C finishes the current sample, retreats and exits 0 (resume later with --resume);
a second Ctrl-C stops at once. A log is written beside the database (DB.log).")]
pub struct CollectArgs {
    /// Rig config (default: the embedded all-simulated rig).
    #[arg(long, conflicts_with = "resume")]
    pub rig: Option<PathBuf>,
    /// Scene (default: the embedded on-land scene).
    #[arg(long, conflicts_with = "resume")]
    pub scene: Option<PathBuf>,
    /// Samples to take.
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    pub samples: Option<u64>,
    /// Seed of the pose sampler and the simulation (default: from the clock; printed
    /// and stored with the run).
    #[arg(long, conflicts_with = "resume")]
    pub seed: Option<u64>,
    /// Rods to use, in order, comma-separated (default: every rod of the scene).
    #[arg(long, value_delimiter = ',', conflicts_with = "resume")]
    pub rods: Vec<String>,
    /// Samples per rod before changing to the next (default: an equal share each).
    #[arg(long, conflicts_with = "resume")]
    pub block: Option<u64>,
    /// Continue run RUN at its next sample, with its stored seed, rig and scene.
    #[arg(long, value_name = "RUN")]
    pub resume: Option<i64>,
}

/// Devices for a rig, real or simulated per its config. When every device that takes
/// part in collection (arm, sensor, camera) is simulated, the run uses virtual time.
async fn build_devices(
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
) -> Result<(CollectDevices, TokioClock), Failure> {
    let virtual_time = matches!(rig.arm, ArmDevice::Sim { .. })
        && matches!(rig.force_sensor, ForceSensorDevice::Sim { .. })
        && matches!(rig.camera, CameraDevice::Sim { .. });
    if virtual_time {
        // The clock stands still while code runs and jumps to the next timer when
        // everything waits; main() runs a current-thread runtime, as pause() needs.
        tokio::time::pause();
    }
    let clock = TokioClock::new();
    let devices = softtouch_drivers::select::build(rig, scene, seed, clock)
        .await
        .map_err(|e| Failure::Runtime(anyhow!("cannot set up the rig: {e}")))?;
    // The rod is part of the simulated world when the arm is simulated; on a real rig
    // an operator changes it.
    let rods: Box<dyn RodChanger> = match (&rig.arm, devices.sim) {
        (ArmDevice::Sim { .. }, Some(handle)) => Box::new(handle),
        _ => Box::new(TerminalOperator::default()),
    };
    Ok((
        CollectDevices {
            arm: devices.arm,
            force_sensor: devices.force_sensor,
            camera: devices.camera,
            rods,
        },
        clock,
    ))
}

struct BarProgress {
    bar: indicatif::ProgressBar,
}

impl Progress for BarProgress {
    fn sample_done(&mut self, _index: u64, c: &Counters) {
        self.bar.inc(1);
        self.bar.set_message(format!(
            "ok {} rejected {} retries {}",
            c.ok, c.rejected, c.retries
        ));
    }
    fn note(&mut self, message: &str) {
        self.bar.println(message);
    }
}

/// Log lines for a log file or CI: at most one every 10 s, and the last.
struct LineProgress {
    started: Instant,
    last: Instant,
    done: u64,
    total: u64,
}

impl Progress for LineProgress {
    fn sample_done(&mut self, index: u64, c: &Counters) {
        self.done += 1;
        let now = Instant::now();
        if now.duration_since(self.last).as_secs() >= 10 || self.done == self.total {
            self.last = now;
            let secs = now.duration_since(self.started).as_secs_f64().max(1e-9);
            let rate = self.done as f64 / secs;
            let eta = (self.total - self.done) as f64 / rate.max(1e-9);
            eprintln!(
                "sample {index}: {}/{} done ({:.1}/s, ETA {:.0} s), ok {} rejected {} retries {}",
                self.done, self.total, rate, eta, c.ok, c.rejected, c.retries
            );
        }
    }
    fn note(&mut self, message: &str) {
        eprintln!("{message}");
    }
}

pub async fn run_collect(args: CollectArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let store = SyncStore::open(db)?;
    let (run_id, plan_seed, start_index, end_index, schedule, rig, scene) =
        if let Some(run_id) = args.resume {
            let record = store.run_record(run_id)?;
            if record.status == RunStatus::Completed.as_str() {
                writeln!(out, "run {run_id} is already complete").map_err(io_failure)?;
                return Ok(());
            }
            let rig: RigConfig = parse_toml(
                &record.rig_toml,
                &ConfigSource::Stored(format!("run {run_id} rig")),
            )?;
            let scene: SceneSpec = parse_toml(
                &record.scene_toml,
                &ConfigSource::Stored(format!("run {run_id} scene")),
            )?;
            let rods: Vec<String> = record.rod_schedule.split(',').map(str::to_owned).collect();
            let schedule = RodSchedule::new(rods, u64::try_from(record.rod_block).unwrap_or(1))
                .ok_or_else(|| Failure::Runtime(anyhow!("run {run_id} has no rod schedule")))?;
            let start = store.next_index(run_id)?;
            let end = u64::try_from(record.samples_planned).unwrap_or(0);
            store.set_run_status(run_id, RunStatus::Running)?;
            store.log_event(
                run_id,
                Some(start),
                None,
                crate::store::EventLevel::Info,
                "resumed",
                &format!("resumed at sample {start}"),
            )?;
            (run_id, record.seed_u64(), start, end, schedule, rig, scene)
        } else {
            let resolved = configs::resolve(args.rig.as_deref(), args.scene.as_deref())?;
            let samples = args.samples.unwrap_or(0);
            let rods = if args.rods.is_empty() {
                resolved
                    .scene
                    .rods
                    .iter()
                    .map(|r| r.name.clone())
                    .collect::<Vec<_>>()
            } else {
                for r in &args.rods {
                    if resolved.scene.rod(r).is_none() {
                        return Err(Failure::BadInput(anyhow!(
                            "--rods: no rod `{r}` in scene {} (it has: {})",
                            resolved.scene_source,
                            resolved
                                .scene
                                .rods
                                .iter()
                                .map(|r| r.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )));
                    }
                }
                args.rods.clone()
            };
            let n_rods = rods.len() as u64;
            let block = match args.block {
                Some(0) => {
                    return Err(Failure::BadInput(anyhow!(
                        "--block: expected at least 1 sample per rod"
                    )));
                }
                Some(b) => b,
                None => samples.div_ceil(n_rods).max(1),
            };
            let schedule = RodSchedule::new(rods, block)
                .ok_or_else(|| Failure::BadInput(anyhow!("no rods to use")))?;
            let seed = args.seed.unwrap_or_else(|| {
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos() as u64)
            });
            let run_id = store.create_run(OwnedNewRun {
                seed,
                samples_planned: samples,
                rod_schedule: schedule.rods().to_vec(),
                rod_block: schedule.block(),
                scene_name: resolved.scene.name.clone(),
                medium: resolved.scene.medium,
                rig_toml: to_toml(&resolved.rig),
                scene_toml: to_toml(&resolved.scene),
            })?;
            (
                run_id,
                seed,
                0,
                samples,
                schedule,
                resolved.rig,
                resolved.scene,
            )
        };

    let (devices, clock) = build_devices(&rig, &scene, plan_seed).await?;
    let total = end_index.saturating_sub(start_index);
    writeln!(
        out,
        "run {run_id}: samples {start_index}..{end_index} of scene `{}` ({}), seed {plan_seed}",
        scene.name, scene.medium
    )
    .map_err(io_failure)?;
    let plan = CollectPlan {
        run_id,
        seed: plan_seed,
        start_index,
        end_index,
        rods: schedule,
        rig,
        scene,
    };

    let (stop_tx, stop_rx) = tokio::sync::watch::channel(0u32);
    let signals = tokio::spawn(async move {
        let mut presses = 0;
        while tokio::signal::ctrl_c().await.is_ok() {
            presses += 1;
            if presses == 1 {
                eprintln!("\nstopping after this sample (Ctrl-C again to stop at once)");
            }
            if stop_tx.send(presses).is_err() {
                break;
            }
        }
    });

    let mut progress: Box<dyn Progress> = if std::io::stderr().is_terminal() {
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{elapsed_precise} [{bar:40}] {pos}/{len} samples {per_sec} ETA {eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Box::new(BarProgress { bar })
    } else {
        let now = Instant::now();
        Box::new(LineProgress {
            started: now,
            last: now,
            done: 0,
            total,
        })
    };
    let started = Instant::now();
    let result = collect(&store, &plan, devices, clock, stop_rx, progress.as_mut()).await;
    signals.abort();
    drop(progress);
    store.close();
    let (outcome, counters) = result.map_err(|e| Failure::Runtime(e.into()))?;
    let wall = started.elapsed().as_secs_f64();
    let summary = format!(
        "run {run_id}: {} ok, {} rejected, {} retries, {} arm faults, {} frame timeouts in {wall:.1} s wall, {:.1} s on the rig's clock",
        counters.ok,
        counters.rejected,
        counters.retries,
        counters.arm_faults,
        counters.frame_timeouts,
        softtouch_drivers::Clock::now(&clock).as_secs_f64()
    );
    match outcome {
        Outcome::Completed => writeln!(out, "{summary}; complete").map_err(io_failure),
        Outcome::Stopped => {
            writeln!(out, "{summary}; stopped (resume with --resume {run_id})").map_err(io_failure)
        }
        Outcome::SafeStop { reason } => Err(Failure::Runtime(anyhow!("{reason}").context(
            format!("{summary}; safe stop (fix the cause, then --resume {run_id})"),
        ))),
    }
}

pub async fn run_status(db: &Path, run: Option<i64>, out: &mut dyn Write) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let runs = store.runs().await?;
    let mut text = String::new();
    let mut any = false;
    for r in runs.iter().filter(|r| run.is_none_or(|id| id == r.run_id)) {
        any = true;
        let hours = r.hours;
        let done = r.ok + r.rejected;
        let rate = if hours > 0.0 {
            format!("{:.0} samples/h", done as f64 / hours)
        } else {
            "-".into()
        };
        text.push_str(&format!(
            "run {} [{}] scene {} ({}): {done}/{} samples, {} ok, {} rejected, {} retries, {} faults; {rate}; updated {}\n",
            r.run_id, r.status, r.scene_name, r.medium, r.samples_planned, r.ok, r.rejected, r.retried, r.faults, r.updated_at
        ));
        let limit = if run.is_some() { 20 } else { 3 };
        for e in store.events(r.run_id, limit).await? {
            let at = e
                .sample_index
                .map(|i| format!(" sample {i}"))
                .unwrap_or_default();
            text.push_str(&format!(
                "    {} {:<5} {}{at}: {}\n",
                e.created_at, e.level, e.kind, e.message
            ));
        }
    }
    store.close().await;
    if let Some(id) = run
        && !any
    {
        return Err(Failure::BadInput(anyhow!(
            "no run {id} in {}",
            db.display()
        )));
    }
    if !any {
        text = format!("no runs in {}\n", db.display());
    }
    out.write_all(text.as_bytes()).map_err(io_failure)
}
