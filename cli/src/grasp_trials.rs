//! `softtouch grasp trials`: parses the flags, starts or resumes a session of
//! [`softtouch_lab::grasp::trials`], runs it with a progress line per trial, and prints the
//! timing table and the success table (Wilson 95 % intervals beside the paper's);
//! the library writes the CSVs and charts to `--out-dir`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use softtouch_grasp::Mode;
use softtouch_schemas::Medium;

use super::grasp_loop::bad;
use super::{Failure, io_failure, open_existing};
use softtouch_lab::grasp::trials::table::{Cell, Paired, paired, summarise, write_outputs};
use softtouch_lab::grasp::trials::{
    TrialPlan, TrialTiming, TrialsError, load_scenes, medium_name, resume_session, run_trials,
    start_session, swept_scenes,
};
use softtouch_schemas::overrides::{Override, Sweep};

/// Options of `grasp trials`.
#[derive(Debug, Clone, Args)]
pub struct TrialsArgs {
    /// Stored model whose estimate closes the loop (and is recorded in open loop).
    #[arg(long, required_unless_present_any = ["resume", "models"])]
    pub model: Option<String>,
    /// Several stored models (comma-separated, e.g. three training seeds): the same
    /// trials (same plan, seed and perturbations) for each, one session each (its
    /// files under --out-dir/MODEL), then the spread of the success rates across them.
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["model", "resume", "rig"])]
    pub models: Vec<String>,
    /// Scene file, one per medium (repeat the flag); default: the built-in land and
    /// water scenes (`scenes/grasp.toml`, `scenes/grasp-water.toml`).
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Objects (`[[objects]]` names, comma-separated); default: every object of the
    /// first scene.
    #[arg(long, value_delimiter = ',')]
    pub objects: Vec<String>,
    /// Trials per object, mode, medium and σ.
    #[arg(long, default_value_t = 10)]
    pub trials: u32,
    /// σ of the grasp point's perturbation per axis, mm.
    #[arg(long, default_value_t = 5.0)]
    pub sigma_mm: f64,
    /// Run the trials at each of these σ, mm (comma-separated), and plot success
    /// against σ; replaces --sigma-mm.
    #[arg(long, value_delimiter = ',')]
    pub sweep_sigma: Vec<f64>,
    /// Set one value of every scene that has it for this session, validated as the
    /// file is (repeatable): `--set objects.bottle.wet_friction=0.2`,
    /// `--set effects.object_flow.mean_m_s=0.1`. Lists of tables are entered by an
    /// entry's name, kind or index. The session stores the scenes as set.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub set: Vec<Override>,
    /// Run the same trials (same perturbations) at each value of one scene value, and
    /// print, store and plot success against it: `--sweep
    /// objects.bottle.wet_friction=0.05,0.1,0.2`. `--sweep sigma_mm=0,2,5` sweeps the
    /// perturbation σ (as --sweep-sigma).
    #[arg(long, value_name = "PATH=V1,V2,…", conflicts_with = "sweep_sigma")]
    pub sweep: Option<Sweep>,
    /// Modes, comma-separated: open, closed.
    #[arg(long, value_delimiter = ',', default_value = "open,closed")]
    pub modes: Vec<String>,
    /// Seed of the perturbations and the simulated scenes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Continue a stored session (its settings are the stored ones, so the settings'
    /// flags are refused beside it; --out-dir may change).
    #[arg(
        long,
        conflicts_with_all = [
            "model", "scene", "objects", "trials", "sigma_mm", "sweep_sigma", "set", "sweep", "modes", "seed",
            "fps", "target_n", "tolerance", "confirm_s", "close_timeout_s", "lift_mm",
            "hold_s", "open_width_mm",
        ]
    )]
    pub resume: Option<i64>,
    /// Camera rate, Hz (one control cycle per frame).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// Closed loop: the grip force F_ref, N.
    #[arg(long, default_value_t = 1.5)]
    pub target_n: f64,
    /// Closed loop: the tolerance δ, N.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Closed loop: how long |F_ref − F_est| ≤ δ must hold before the lift, s.
    #[arg(long, default_value_t = 0.25)]
    pub confirm_s: f64,
    /// Closed loop: how long the loop may take to confirm, s.
    #[arg(long, default_value_t = 4.0)]
    pub close_timeout_s: f64,
    /// How high the object is lifted, mm.
    #[arg(long, default_value_t = 50.0)]
    pub lift_mm: f64,
    /// How long it is held after the lift, s.
    #[arg(long, default_value_t = 2.0)]
    pub hold_s: f64,
    /// Open loop: close every object to this opening, mm, instead of its predefined
    /// gripping width.
    #[arg(long)]
    pub open_width_mm: Option<f64>,
    /// Rig file: run the trials on its real arm, Hand-E and finger camera at the grasp
    /// poses, widths, lifts and set-down places of its `[grasp]` section (the scene
    /// flags do not apply). With --resume: the rig of the stored session.
    #[arg(long, conflicts_with_all = ["scene", "open_width_mm", "lift_mm", "set", "sweep"])]
    pub rig: Option<PathBuf>,
    /// On a rig: take the rig judge's verdict without asking the operator (the
    /// operator still confirms each return of the object to its place).
    #[arg(long, requires = "rig")]
    pub no_confirm: bool,
    /// Folder for `grasp-trials.csv`, `grasp-trials-rows.csv`, `grasp-trials.png`,
    /// with --sweep-sigma `grasp-trials-sigma.png`, and with --sweep
    /// `grasp-trials-sweep.csv` and `grasp-trials-sweep.png`.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
}

impl TrialsArgs {
    /// The σ of the session: --sweep-sigma, --sweep sigma_mm=…, or --sigma-mm.
    fn sigmas_mm(&self) -> Result<Vec<f64>, Failure> {
        match &self.sweep {
            Some(s) if s.path == "sigma_mm" => s
                .values
                .iter()
                .map(|v| {
                    v.as_float()
                        .or_else(|| v.as_integer().map(|i| i as f64))
                        .ok_or_else(|| {
                            bad(format!(
                                "--sweep sigma_mm: `{}` is not a number of mm",
                                softtouch_schemas::overrides::shown(v)
                            ))
                        })
                })
                .collect(),
            _ if !self.sweep_sigma.is_empty() => Ok(self.sweep_sigma.clone()),
            _ => Ok(vec![self.sigma_mm]),
        }
    }

    /// The sweep of a scene value (not σ, which is the plan's own).
    fn scene_sweep(&self) -> Option<&Sweep> {
        self.sweep.as_ref().filter(|s| s.path != "sigma_mm")
    }

    /// The session's settings from the flags (checked when the session starts).
    fn plan(&self) -> Result<TrialPlan, Failure> {
        Ok(TrialPlan {
            objects: self.objects.clone(),
            modes: self.modes.clone(),
            trials: self.trials,
            sigmas_mm: self.sigmas_mm()?,
            fps: self.fps,
            target_n: self.target_n,
            tolerance_n: self.tolerance,
            confirm_s: self.confirm_s,
            close_timeout_s: self.close_timeout_s,
            lift_mm: self.lift_mm,
            hold_s: self.hold_s,
            open_width_mm: self.open_width_mm,
            ..TrialPlan::default()
        })
    }
}

/// The wall time of the trials this invocation ran, per medium and mode: cycles (one
/// a frame), ms per cycle, mean and slowest trial and how many took at most 1 s.
fn print_timings(timings: &[TrialTiming], fps: f64, out: &mut dyn Write) -> Result<(), Failure> {
    let w = io_failure;
    writeln!(
        out,
        "\nwall time of the trials run now ({fps} Hz on virtual time):\n{:<7}{:<8}{:>7}{:>9}{:>10}{:>8}{:>8}{:>9}",
        "medium", "mode", "trials", "cycles", "ms/cycle", "mean s", "max s", "≤ 1 s"
    )
    .map_err(w)?;
    let mut groups: Vec<(Medium, Mode)> = Vec::new();
    for t in timings {
        if !groups.contains(&(t.medium, t.mode)) {
            groups.push((t.medium, t.mode));
        }
    }
    for (medium, mode) in groups {
        let of: Vec<&TrialTiming> = timings
            .iter()
            .filter(|t| t.medium == medium && t.mode == mode)
            .collect();
        let wall_s: f64 = of.iter().map(|t| t.wall_s).sum();
        let cycles: usize = of.iter().map(|t| t.cycles).sum();
        let max_s = of.iter().map(|t| t.wall_s).fold(0.0, f64::max);
        let within = of.iter().filter(|t| t.wall_s <= 1.0).count();
        let per_cycle = if cycles == 0 {
            "–".to_owned()
        } else {
            format!("{:.3}", 1e3 * wall_s / cycles as f64)
        };
        writeln!(
            out,
            "{:<7}{:<8}{:>7}{:>9}{:>10}{:>8.3}{:>8.3}{:>9}",
            medium_name(medium),
            mode.as_str(),
            of.len(),
            cycles,
            per_cycle,
            wall_s / of.len() as f64,
            max_s,
            format!("{within}/{}", of.len())
        )
        .map_err(w)?;
    }
    Ok(())
}

fn fmt_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

/// The session's first line (id, model, seed, trials planned, stored and to run) and
/// its setup lines, before any trial runs.
fn print_header(
    out: &mut dyn Write,
    what: &str,
    (id, model, sha256, seed): (i64, &str, &str, u64),
    (planned, todo): (usize, usize),
    setup: &[String],
) -> Result<(), Failure> {
    let w = io_failure;
    writeln!(
        out,
        "{what} {id}: model `{model}` (sha256 {}), seed {seed}, {planned} {} planned, {} stored, {todo} to run",
        &sha256[..12.min(sha256.len())],
        if planned == 1 { "trial" } else { "trials" },
        planned - todo,
    )
    .map_err(w)?;
    for line in setup {
        writeln!(out, "{line}").map_err(w)?;
    }
    Ok(())
}

/// The rig's Franka, Hand-E and finger camera for `grasp VERB --rig`; a rig whose
/// gripper or arm is simulated is refused, naming what to run instead.
///
/// # Errors
/// A simulated device (bad input), a device that does not open.
pub(super) async fn open_rig_devices(
    rig: &softtouch_schemas::RigConfig,
    rig_path: &Path,
    verb: &str,
) -> Result<softtouch_lab::grasp::trials::rig::RigTrialDevices, Failure> {
    if !softtouch_lab::grasp::devices::has_real_gripper(rig) {
        return Err(super::grasp_loop::bad(format!(
            "--rig {}: its gripper is simulated: run the simulated {verb} without --rig",
            rig_path.display()
        )));
    }
    let clock: std::sync::Arc<dyn softtouch_drivers::Clock> =
        std::sync::Arc::new(softtouch_drivers::TokioClock::new());
    let arm = softtouch_drivers::open::real_arm(&rig.arm, clock.clone())
        .await
        .map_err(|e| Failure::Runtime(anyhow::anyhow!("arm: {e}")))?
        .ok_or_else(|| {
            super::grasp_loop::bad(format!(
                "--rig {}: its arm is simulated: expected arm.driver = \"franka\"",
                rig_path.display()
            ))
        })?;
    let grasp = softtouch_lab::grasp::devices::real_grasp_devices(rig, clock.clone())
        .await
        .map_err(|e| Failure::Runtime(anyhow::anyhow!("{e}")))?;
    Ok(softtouch_lab::grasp::trials::rig::RigTrialDevices {
        arm: std::sync::Arc::new(tokio::sync::Mutex::new(arm)),
        gripper: grasp.gripper,
        camera: grasp.camera,
        clock,
    })
}

/// The operator at this terminal: answers on stdin, questions on stderr.
pub(super) fn terminal_operator(
    confirm_verdicts: bool,
) -> softtouch_lab::grasp::trials::rig::Operator {
    softtouch_lab::grasp::trials::rig::Operator {
        input: softtouch_grasp::OperatorInput::from_reader(std::io::BufReader::new(
            std::io::stdin(),
        )),
        output: Box::new(std::io::stderr()),
        confirm_verdicts,
    }
}

/// Run `grasp trials`.
pub async fn run(
    args: TrialsArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if let Some(rig) = args.rig.clone() {
        return run_on_rig(args, &rig, db, out).await;
    }
    if !args.models.is_empty() {
        return run_models(args, db, out).await;
    }
    run_sim(args, db, out).await.map(drop)
}

/// What one simulated session ended with: whether a stop request cut it short, its
/// σ list and the table it printed.
struct SimRun {
    stopped: bool,
    sigmas_mm: Vec<f64>,
    table: Vec<Cell>,
}

/// `grasp trials --models A,B,C`: the same trials for each model, then the spread.
async fn run_models(
    args: TrialsArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let mut names: Vec<String> = Vec::new();
    for m in &args.models {
        if m.is_empty() {
            return Err(super::grasp_loop::bad(
                "--models: expected stored model names, comma-separated".into(),
            ));
        }
        if !names.contains(m) {
            names.push(m.clone());
        }
    }
    // Every model is there before any trial runs.
    {
        let store = open_existing(db).await?;
        for m in &names {
            let found = softtouch_lab::models::force_artifact(&store, m).await;
            if let Err(e) = found {
                store.close().await;
                return Err(e.into());
            }
        }
        store.close().await;
    }
    let mut runs = Vec::with_capacity(names.len());
    for m in &names {
        writeln!(out, "\n===== model {m} =====").map_err(io_failure)?;
        let one = TrialsArgs {
            model: Some(m.clone()),
            models: Vec::new(),
            out_dir: args.out_dir.join(m),
            ..args.clone()
        };
        let run = run_sim(one, db, out).await?;
        let stopped = run.stopped;
        runs.push((m.clone(), run));
        if stopped {
            writeln!(out, "stopped: the models after `{m}` are not run").map_err(io_failure)?;
            break;
        }
    }
    print_spread(&model_spread(&runs), out)
}

/// A row of the spread: its σ, medium and mode, and each model's `(name, held, n)`.
type SpreadRow = (String, Vec<(String, u64, u64)>);

/// Per σ, medium and mode (all objects): each model's held/n, from the tables its
/// session printed.
fn model_spread(runs: &[(String, SimRun)]) -> Vec<SpreadRow> {
    let mut rows: Vec<SpreadRow> = Vec::new();
    for (model, run) in runs {
        for c in run.table.iter().filter(|c| c.object.is_none()) {
            let key = format!(
                "σ {} mm {} {}",
                run.sigmas_mm[c.sigma_index as usize],
                medium_name(c.medium),
                c.mode.as_str()
            );
            let i = rows.iter().position(|r| r.0 == key).unwrap_or_else(|| {
                rows.push((key, Vec::new()));
                rows.len() - 1
            });
            rows[i].1.push((model.clone(), c.held, c.trials));
        }
    }
    rows
}

fn print_spread(rows: &[SpreadRow], out: &mut dyn Write) -> Result<(), Failure> {
    let w = io_failure;
    writeln!(
        out,
        "\nacross models (all objects; sd: sample standard deviation of the models' rates):"
    )
    .map_err(w)?;
    for (key, per) in rows {
        let rates: Vec<f64> = per
            .iter()
            .filter(|(_, _, n)| *n > 0)
            .map(|(_, h, n)| *h as f64 / *n as f64)
            .collect();
        let mean = rates.iter().sum::<f64>() / rates.len().max(1) as f64;
        let sd = if rates.len() > 1 {
            (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (rates.len() - 1) as f64)
                .sqrt()
        } else {
            f64::NAN
        };
        let (lo, hi) = rates
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
                (a.min(*r), b.max(*r))
            });
        let each: Vec<String> = per.iter().map(|(m, h, n)| format!("{m} {h}/{n}")).collect();
        let p = |v: f64| {
            if v.is_finite() {
                format!("{:.0} %", 100.0 * v)
            } else {
                "–".into()
            }
        };
        writeln!(
            out,
            "{key:<26} mean {:>5}  sd {:>5}  range {}–{}  {}",
            p(mean),
            p(sd),
            p(lo),
            p(hi),
            each.join(", ")
        )
        .map_err(w)?;
    }
    Ok(())
}

/// One simulated session (new or resumed): what it ended with.
async fn run_sim(
    args: TrialsArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<SimRun, Failure> {
    let store = open_existing(db).await?;
    // Closed (the log checkpointed into the file) on every path.
    let ran = run_sim_on(&store, args, out).await;
    store.close().await;
    ran
}

async fn run_sim_on(
    store: &softtouch_store::Store,
    args: TrialsArgs,
    out: &mut dyn Write,
) -> Result<SimRun, Failure> {
    let store = store.clone();
    // The first Ctrl-C, SIGTERM or SIGHUP finishes the trial in hand (or the session's
    // start and calibrations, then none) and ends with the summary of what ran (exit
    // 0); a second stops at once. Watched from the first instruction, so that no
    // signal kills the verb with the database open.
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(0u32);
    let signals = tokio::spawn(super::signals::count_stop_signals(stop_tx, "trial"));
    let ran = run_session(&store, args, &stop_rx, out).await;
    signals.abort();
    ran
}

async fn run_session(
    store: &softtouch_store::Store,
    args: TrialsArgs,
    stop_rx: &tokio::sync::watch::Receiver<u32>,
    out: &mut dyn Write,
) -> Result<SimRun, Failure> {
    let store = store.clone();
    let session = match args.resume {
        Some(id) => resume_session(&store, id, args.model.as_deref()).await?,
        None => {
            // Settings are checked before the scenes are read or anything is stored.
            let mut plan = args.plan()?.checked()?;
            let mut scenes = load_scenes(&args.scene, &args.set)?;
            if let Some(sweep) = args.scene_sweep() {
                let (swept, stored) = swept_scenes(&scenes, sweep)?;
                scenes = swept;
                plan.sweep = Some(stored);
            }
            let model = args.model.clone().unwrap_or_default();
            start_session(&store, &model, args.seed, plan, scenes).await?
        }
    };
    let progress = session.progress(&store).await?;
    let todo = progress.todo;
    let w = io_failure;
    print_header(
        out,
        "grasp session",
        (
            session.id,
            &session.model,
            &session.model_sha256,
            session.seed,
        ),
        (progress.planned.len(), todo.len()),
        &session.setup_lines(),
    )?;

    let bar = softtouch_collector::progress::progress_bar(todo.len() as u64, true, "trials");
    let started = Instant::now();
    let mut timings = Vec::with_capacity(todo.len());
    let mut on_trial = |t: &softtouch_lab::grasp::trials::TrialDone| -> Result<(), TrialsError> {
        timings.push(t.timing);
        let i = timings.len();
        bar.inc(1);
        let per = started.elapsed().as_secs_f64() / i as f64;
        let opt = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |f| format!("{f:.2}"));
        let row = &t.row;
        bar.suspend(|| {
            writeln!(
                out,
                "[{:>4}/{}] σ {} mm {} {} {} #{}: {} (peak est {} N, true {} N) {:.2} s, eta {}",
                i,
                todo.len(),
                session.plan.sigmas_mm[row.key.sigma_index as usize],
                row.medium,
                row.key.object,
                row.key.mode,
                row.key.trial,
                row.reason.as_deref().unwrap_or("held"),
                opt(row.peak_estimate_n),
                opt(row.peak_true_n),
                t.timing.wall_s,
                fmt_duration(per * (todo.len() - i) as f64)
            )
        })
        .map_err(|e| TrialsError::Failed(format!("cannot write output: {e}")))
    };
    let ran = run_trials(&store, &session, &todo, stop_rx, &mut on_trial).await;
    bar.finish_and_clear();
    let ran = match ran {
        Err(TrialsError::Interrupted) => {
            return Err(Failure::Runtime(anyhow::anyhow!(
                "grasp session {}: stopped at once by a second stop request; the trials before it are stored (resume with --resume {})",
                session.id,
                session.id
            )));
        }
        other => other?,
    };
    let stopped = matches!(ran, softtouch_lab::grasp::trials::RunEnd::Stopped { .. });
    let todo = match ran {
        softtouch_lab::grasp::trials::RunEnd::Completed => &todo[..],
        softtouch_lab::grasp::trials::RunEnd::Stopped { ran } => {
            writeln!(
                out,
                "stopped after {ran} of {} trials (a stop request; resume with --resume {})",
                todo.len(),
                session.id
            )
            .map_err(w)?;
            todo.get(..ran).unwrap_or(&[])
        }
    };
    if !todo.is_empty() {
        writeln!(
            out,
            "ran {} trials in {:.1} s wall ({:.2} s per trial)",
            todo.len(),
            started.elapsed().as_secs_f64(),
            started.elapsed().as_secs_f64() / todo.len() as f64
        )
        .map_err(w)?;
        print_timings(&timings, session.plan.fps, out)?;
    }

    let rows = store.grasp_trials(session.id).await?;
    let media: Vec<Medium> = session.scenes.iter().map(|s| s.medium).collect();
    let table = summarise(&session.plan, &media, &rows)?;
    print_table(&table, &session.plan, out)?;
    print_sweep(&table, &session.plan, out)?;
    print_paired(&paired(&session.plan, &media, &rows), &session.plan, out)?;
    let written = write_outputs(&args.out_dir, &table, &rows, &session.plan)?;
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    match names.as_slice() {
        [csv, rows_csv, png, rest @ ..] => {
            writeln!(out, "wrote {csv}, {rows_csv} and {png}").map_err(w)?;
            for r in rest {
                writeln!(out, "wrote {r}").map_err(w)?;
            }
        }
        _ => writeln!(out, "wrote {}", names.join(", ")).map_err(w)?,
    }
    Ok(SimRun {
        stopped,
        sigmas_mm: session.plan.sigmas_mm.clone(),
        table,
    })
}

/// `grasp trials --rig FILE`: the rig's devices opened, then the trials of a new or
/// resumed rig session, each stored as it ends; questions to the operator on stderr,
/// answers on stdin.
async fn run_on_rig(
    args: TrialsArgs,
    rig_path: &Path,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    use softtouch_lab::grasp::trials::rig::{
        resume_rig_session, run_rig_trials, start_rig_session,
    };
    let rig = softtouch_collector::configs::resolve(Some(rig_path), None)?.rig;
    let store = open_existing(db).await?;
    let session = match args.resume {
        Some(id) => resume_rig_session(&store, id, args.model.as_deref(), &rig).await?,
        None => {
            let plan = args.plan()?.checked()?;
            let model = args.model.clone().unwrap_or_default();
            start_rig_session(&store, &model, args.seed, plan, &rig).await?
        }
    };
    let progress = session.progress(&store).await?;
    let todo = progress.todo;
    let w = io_failure;
    print_header(
        out,
        "rig grasp session",
        (
            session.id,
            &session.model,
            &session.model_sha256,
            session.seed,
        ),
        (progress.planned.len(), todo.len()),
        &session.setup_lines(),
    )?;
    out.flush().map_err(w)?;
    if !todo.is_empty() {
        let mut devices = open_rig_devices(&rig, rig_path, "trials").await?;
        let mut operator = terminal_operator(!args.no_confirm);
        let mut on_trial =
            |t: &softtouch_lab::grasp::trials::TrialDone| -> Result<(), TrialsError> {
                let row = &t.row;
                writeln!(
                    out,
                    "σ {} mm {} {} #{}: {}{} ({:.1} s)",
                    row.sigma_m * 1000.0,
                    row.key.object,
                    row.key.mode,
                    row.key.trial,
                    row.reason.as_deref().unwrap_or("held"),
                    row.detail
                        .as_deref()
                        .map_or_else(String::new, |d| format!(": {d}")),
                    t.timing.wall_s
                )
                .map_err(|e| TrialsError::Failed(format!("cannot write output: {e}")))
            };
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(0u32);
        let signals = tokio::spawn(super::signals::count_stop_signals(stop_tx, "trial"));
        let ran = run_rig_trials(
            &store,
            &session,
            &mut devices,
            &mut operator,
            &todo,
            &stop_rx,
            &mut on_trial,
        )
        .await;
        signals.abort();
        match ran {
            Err(TrialsError::Interrupted) => {
                return Err(Failure::Runtime(anyhow::anyhow!(
                    "rig grasp session {}: stopped at once by a second stop request, through the safe exit; the trials before it are stored (resume with --rig {} --resume {})",
                    session.id,
                    rig_path.display(),
                    session.id
                )));
            }
            Err(e) => return Err(e.into()),
            Ok(softtouch_lab::grasp::trials::RunEnd::Stopped { ran }) => writeln!(
                out,
                "stopped after {ran} of {} trials (a stop request; resume with --rig {} --resume {})",
                todo.len(),
                rig_path.display(),
                session.id
            )
            .map_err(w)?,
            Ok(softtouch_lab::grasp::trials::RunEnd::Completed) => {}
        }
    }
    let rows = store.grasp_trials(session.id).await?;
    let table = summarise(&session.plan, &session.media(), &rows)?;
    print_table(&table, &session.plan, out)?;
    print_sweep(&table, &session.plan, out)?;
    print_paired(
        &paired(&session.plan, &session.media(), &rows),
        &session.plan,
        out,
    )?;
    let written = write_outputs(&args.out_dir, &table, &rows, &session.plan)?;
    for p in written {
        writeln!(out, "wrote {}", p.display()).map_err(w)?;
    }
    store.close().await;
    Ok(())
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "–".to_owned(), |v| format!("{:.0}%", 100.0 * v))
}

fn print_table(cells: &[Cell], plan: &TrialPlan, out: &mut dyn Write) -> Result<(), Failure> {
    let w = io_failure;
    let mut last = None;
    for c in cells {
        if last != Some((c.sigma_index, c.scene_index)) {
            last = Some((c.sigma_index, c.scene_index));
            let swept = plan
                .sweep
                .as_ref()
                .and_then(|s| Some(format!("; {} = {}", s.path, s.value_of(c.scene_index)?)))
                .unwrap_or_default();
            writeln!(
                out,
                "\nσ = {} mm, {} (scene {}{swept}):\n{:<14} {:<7} {:>7} {:>6} {:>15} {:>7}  failures",
                plan.sigmas_mm[c.sigma_index as usize],
                medium_name(c.medium),
                c.scene_index,
                "object",
                "mode",
                "held/n",
                "rate",
                "Wilson 95%",
                "paper"
            )
            .map_err(w)?;
        }
        writeln!(
            out,
            "{:<14} {:<7} {:>7} {:>6} {:>15} {:>7}  {}",
            c.object.as_deref().unwrap_or("all"),
            c.mode.as_str(),
            format!("{}/{}", c.held, c.trials),
            pct(c.rate()),
            format!(
                "[{:.0}%, {:.0}%]",
                100.0 * c.interval[0],
                100.0 * c.interval[1]
            ),
            pct(c.paper()),
            c.failures_text()
        )
        .map_err(w)?;
    }
    Ok(())
}

/// A scene sweep's summary: success against the value per medium and mode (all
/// objects), then per object, medium and mode the first value held in at least 90 %
/// of its trials.
fn print_sweep(cells: &[Cell], plan: &TrialPlan, out: &mut dyn Write) -> Result<(), Failure> {
    let Some(sweep) = &plan.sweep else {
        return Ok(());
    };
    let w = io_failure;
    for (si, sigma) in plan.sigmas_mm.iter().enumerate() {
        writeln!(
            out,
            "\nsuccess against {} (σ = {sigma} mm, all objects):\n{:>10} {:<7} {:<7} {:>7} {:>6} {:>15}  failures",
            sweep.path, "value", "medium", "mode", "held/n", "rate", "Wilson 95%"
        )
        .map_err(w)?;
        let here = |c: &&Cell| c.sigma_index as usize == si;
        for c in cells.iter().filter(here).filter(|c| c.object.is_none()) {
            writeln!(
                out,
                "{:>10} {:<7} {:<7} {:>7} {:>6} {:>15}  {}",
                sweep.value_of(c.scene_index).unwrap_or("?"),
                medium_name(c.medium),
                c.mode.as_str(),
                format!("{}/{}", c.held, c.trials),
                pct(c.rate()),
                format!(
                    "[{:.0}%, {:.0}%]",
                    100.0 * c.interval[0],
                    100.0 * c.interval[1]
                ),
                c.failures_text()
            )
            .map_err(w)?;
        }
        writeln!(
            out,
            "first value held in at least 90 % of trials (σ = {sigma} mm; values in the order swept):"
        )
        .map_err(w)?;
        let mut keys: Vec<(String, u32, Mode)> = Vec::new();
        for c in cells.iter().filter(here) {
            let key = (
                c.object.clone().unwrap_or_else(|| "all".into()),
                c.scene_index % sweep.per_value.max(1),
                c.mode,
            );
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        for (object, base, mode) in &keys {
            let mine: Vec<&Cell> = cells
                .iter()
                .filter(here)
                .filter(|c| {
                    c.object.clone().unwrap_or_else(|| "all".into()) == *object
                        && c.scene_index % sweep.per_value.max(1) == *base
                        && c.mode == *mode
                })
                .collect();
            let Some(medium) = mine.first().map(|c| medium_name(c.medium)) else {
                continue;
            };
            let first = mine
                .iter()
                .find(|c| c.trials > 0 && c.held * 10 >= c.trials * 9)
                .map_or_else(
                    || "none".to_owned(),
                    |c| {
                        format!(
                            "{} ({}/{})",
                            sweep.value_of(c.scene_index).unwrap_or("?"),
                            c.held,
                            c.trials
                        )
                    },
                );
            writeln!(
                out,
                "  {object:<14} {medium:<7} {:<7} {first}",
                mode.as_str()
            )
            .map_err(w)?;
        }
    }
    Ok(())
}

/// Open against closed on the same perturbations, with McNemar's exact test.
fn print_paired(pairs: &[Paired], plan: &TrialPlan, out: &mut dyn Write) -> Result<(), Failure> {
    if pairs.is_empty() {
        return Ok(());
    }
    let w = io_failure;
    writeln!(
        out,
        "\nopen against closed on the same perturbations (pairs by object and trial; McNemar's exact test):\n{:>6} {:<7} {:>6} {:>6} {:>10} {:>12} {:>8} {:>9}",
        "σ mm", "medium", "pairs", "both", "open only", "closed only", "neither", "p"
    )
    .map_err(w)?;
    for p in pairs {
        writeln!(
            out,
            "{:>6} {:<7} {:>6} {:>6} {:>10} {:>12} {:>8} {:>9.4}",
            plan.sigmas_mm[p.sigma_index as usize],
            match plan.sweep.as_ref().and_then(|s| s.value_of(p.scene_index)) {
                Some(v) => format!("{} at {v}", medium_name(p.medium)),
                None => medium_name(p.medium).to_owned(),
            },
            p.pairs,
            p.both,
            p.open_only,
            p.closed_only,
            p.neither,
            p.p
        )
        .map_err(w)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_as_minutes_and_seconds() {
        assert_eq!(fmt_duration(125.4), "2m05s");
        assert_eq!(fmt_duration(59.4), "59s");
        assert_eq!(fmt_duration(-3.0), "0s");
    }
}
