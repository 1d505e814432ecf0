//! A `grasp trials` request carried out: on the simulator or on a rig, for one model or
//! several, new or resumed. The verb parses its flags into a [`TrialsRequest`] and
//! calls [`run`]; every branch of the experiment is here, and its text goes to the
//! writer it is given.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use softtouch_schemas::Medium;
use softtouch_schemas::overrides::{Override, Sweep};
use tokio::sync::watch;

use super::rig::{
    Operator, RigTrialDevices, resume_rig_session, run_rig_trials, start_rig_session,
};
use super::table::{Cell, paired, summarise, write_outputs};
use super::text::{
    fmt_duration, model_spread, print_header, print_paired, print_spread, print_sweep, print_table,
    print_timings,
};
use super::{
    RunEnd, SceneSweep, TrialDone, TrialPlan, TrialsError, load_scenes, resume_session, run_trials,
    set_and_sweep_apart, start_session, swept_scenes,
};
use crate::store::Store;

/// What `grasp trials` asks for.
#[derive(Debug, Clone, Default)]
pub struct TrialsRequest {
    /// The model whose estimate closes the loop (one session).
    pub model: Option<String>,
    /// Several models: the same trials for each, then the spread of their rates.
    pub models: Vec<String>,
    /// A stored session to continue (its stored settings apply).
    pub resume: Option<i64>,
    /// The session's settings, unchecked (checked when a session starts).
    pub plan: TrialPlan,
    /// Seed of the perturbations and the simulated scenes.
    pub seed: u64,
    /// Scene files, one per medium (empty: the built-in land and water scenes).
    pub scenes: Vec<PathBuf>,
    /// Scene values set for this session.
    pub sets: Vec<Override>,
    /// A scene value swept (σ is the plan's own list).
    pub sweep: Option<Sweep>,
    /// A rig file: the trials run on its devices instead of the simulator.
    pub rig: Option<PathBuf>,
    /// Where the CSVs and charts go.
    pub out_dir: PathBuf,
}

/// Where the text goes, what stops a session and who answers a rig's questions.
#[allow(missing_debug_implementations)] // a writer and the operator's input
pub struct Terminal<'a> {
    /// The session's text.
    pub out: &'a mut dyn Write,
    /// Stop requests counted (1: finish the trial in hand; 2: stop at once).
    pub stop: watch::Receiver<u32>,
    /// The operator at a rig (asked nothing on the simulator).
    pub operator: Operator,
}

/// What one simulated session ended with: whether a stop request cut it short, its
/// σ list and its summary table.
#[derive(Debug)]
pub struct SimRun {
    /// A stop request ended it before its last trial.
    pub stopped: bool,
    /// The plan's σ list, mm.
    pub sigmas_mm: Vec<f64>,
    /// Its cells per scene, σ, object and mode.
    pub table: Vec<Cell>,
    /// The scene value it swept, if any (which value each scene has).
    pub sweep: Option<SceneSweep>,
}

fn written(e: std::io::Error) -> TrialsError {
    TrialsError::Failed(format!("cannot write output: {e}"))
}

/// Carry out a request: a rig session, several models' sessions, or one simulated
/// session (each new or resumed), printing as it goes.
///
/// # Errors
/// A request that cannot work ([`TrialsError::is_bad_input`]), the store, a device, a
/// second stop request ([`TrialsError::Interrupted`]).
pub async fn run(
    request: &TrialsRequest,
    store: &Store,
    terminal: &mut Terminal<'_>,
) -> Result<(), TrialsError> {
    if let Some(rig) = &request.rig {
        return run_on_rig(request, rig, store, terminal).await;
    }
    if !request.models.is_empty() {
        return run_models(request, store, terminal).await;
    }
    run_sim(request, store, terminal).await.map(drop)
}

/// Several models: the same trials for each (files under `out_dir/MODEL`), then the
/// spread of their rates.
async fn run_models(
    request: &TrialsRequest,
    store: &Store,
    terminal: &mut Terminal<'_>,
) -> Result<(), TrialsError> {
    let mut names: Vec<String> = Vec::new();
    for m in &request.models {
        if m.is_empty() {
            return Err(TrialsError::Invalid(
                "--models: expected stored model names, comma-separated".into(),
            ));
        }
        if !names.contains(m) {
            names.push(m.clone());
        }
    }
    // Every model is there before any trial runs.
    for m in &names {
        crate::models::force_artifact(store, m).await?;
    }
    let mut runs = Vec::with_capacity(names.len());
    for m in &names {
        writeln!(terminal.out, "\n===== model {m} =====").map_err(written)?;
        let one = TrialsRequest {
            model: Some(m.clone()),
            models: Vec::new(),
            out_dir: request.out_dir.join(m),
            ..request.clone()
        };
        let run = run_sim(&one, store, terminal).await?;
        let stopped = run.stopped;
        runs.push((m.clone(), run));
        if stopped {
            writeln!(terminal.out, "stopped: the models after `{m}` are not run")
                .map_err(written)?;
            break;
        }
    }
    print_spread(&model_spread(&runs), terminal.out).map_err(written)
}

/// One simulated session, new or resumed.
async fn run_sim(
    request: &TrialsRequest,
    store: &Store,
    terminal: &mut Terminal<'_>,
) -> Result<SimRun, TrialsError> {
    let session = match request.resume {
        Some(id) => resume_session(store, id, request.model.as_deref()).await?,
        None => {
            // Settings are checked before the scenes are read or anything is stored.
            let mut plan = request.plan.clone().checked()?;
            set_and_sweep_apart(&request.sets, request.sweep.as_ref())?;
            let mut scenes = load_scenes(&request.scenes, &request.sets)?;
            plan.sets = request.sets.iter().map(ToString::to_string).collect();
            if let Some(sweep) = &request.sweep {
                let (swept, stored) = swept_scenes(&scenes, sweep)?;
                scenes = swept;
                plan.sweep = Some(stored);
            }
            let model = request.model.clone().unwrap_or_default();
            start_session(store, &model, request.seed, plan, scenes).await?
        }
    };
    let progress = session.progress(store).await?;
    let todo = progress.todo;
    let out = &mut *terminal.out;
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
    )
    .map_err(written)?;

    let bar = softtouch_collector::progress::progress_bar(todo.len() as u64, true, "trials");
    let started = Instant::now();
    let mut timings = Vec::with_capacity(todo.len());
    let mut on_trial = |t: &TrialDone| -> Result<(), TrialsError> {
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
        .map_err(written)
    };
    let ran = run_trials(store, &session, &todo, &terminal.stop, &mut on_trial).await;
    bar.finish_and_clear();
    let ran = match ran {
        Err(TrialsError::Interrupted) => {
            return Err(TrialsError::Failed(format!(
                "grasp session {}: stopped at once by a second stop request; the trials before it are stored (resume with --resume {})",
                session.id, session.id
            )));
        }
        other => other?,
    };
    let out = &mut *terminal.out;
    let stopped = matches!(ran, RunEnd::Stopped { .. });
    let todo = match ran {
        RunEnd::Completed => &todo[..],
        RunEnd::Stopped { ran } => {
            writeln!(
                out,
                "stopped after {ran} of {} trials (a stop request; resume with --resume {})",
                todo.len(),
                session.id
            )
            .map_err(written)?;
            todo.get(..ran).unwrap_or(&[])
        }
    };
    if !todo.is_empty() {
        let wall_s = started.elapsed().as_secs_f64();
        writeln!(
            out,
            "ran {} trials in {wall_s:.1} s wall ({:.2} s per trial)",
            todo.len(),
            wall_s / todo.len() as f64
        )
        .map_err(written)?;
        print_timings(&timings, session.plan.fps, out).map_err(written)?;
    }

    let rows = store.grasp_trials(session.id).await?;
    let media: Vec<Medium> = session.scenes.iter().map(|s| s.medium).collect();
    let table = summarise(&session.plan, &media, &rows)?;
    print_table(&table, &session.plan, out).map_err(written)?;
    // What a perfect force reading could hold at most, beside the paper's rate.
    // (A cap that cannot be worked out is said, not a failure of the trials.)
    match super::cap::scene_caps(&session.plan, &session.scenes) {
        Ok(caps) => {
            for cap in caps {
                writeln!(out, "{}", cap.describe(session.plan.target_n)).map_err(written)?;
            }
        }
        Err(e) => writeln!(out, "physics cap: not worked out: {e}").map_err(written)?,
    }
    print_sweep(&table, &session.plan, out).map_err(written)?;
    print_paired(&paired(&session.plan, &media, &rows), &session.plan, out).map_err(written)?;
    let files = write_outputs(&request.out_dir, &table, &rows, &session.plan)?;
    let names: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
    match names.as_slice() {
        [csv, rows_csv, png, rest @ ..] => {
            writeln!(out, "wrote {csv}, {rows_csv} and {png}").map_err(written)?;
            for r in rest {
                writeln!(out, "wrote {r}").map_err(written)?;
            }
        }
        _ => writeln!(out, "wrote {}", names.join(", ")).map_err(written)?,
    }
    Ok(SimRun {
        stopped,
        sigmas_mm: session.plan.sigmas_mm.clone(),
        table,
        sweep: session.plan.sweep.clone(),
    })
}

/// The rig's Franka, Hand-E and finger camera for `grasp VERB --rig`; a rig whose
/// gripper or arm is simulated is refused, naming what to run instead.
///
/// # Errors
/// A simulated device (bad input), a device that does not open.
pub async fn open_rig_devices(
    rig: &softtouch_schemas::RigConfig,
    rig_path: &Path,
    verb: &str,
) -> Result<RigTrialDevices, TrialsError> {
    if !crate::grasp::devices::has_real_gripper(rig) {
        return Err(TrialsError::Invalid(format!(
            "--rig {}: its gripper is simulated: run the simulated {verb} without --rig",
            rig_path.display()
        )));
    }
    let clock: Arc<dyn softtouch_drivers::Clock> = Arc::new(softtouch_drivers::TokioClock::new());
    let arm = softtouch_drivers::open::real_arm(&rig.arm, clock.clone())
        .await
        .map_err(|e| TrialsError::Failed(format!("arm: {e}")))?
        .ok_or_else(|| {
            TrialsError::Invalid(format!(
                "--rig {}: its arm is simulated: expected arm.driver = \"franka\"",
                rig_path.display()
            ))
        })?;
    let grasp = crate::grasp::devices::real_grasp_devices(rig, clock.clone())
        .await
        .map_err(|e| TrialsError::Failed(e.to_string()))?;
    Ok(RigTrialDevices {
        arm: Arc::new(tokio::sync::Mutex::new(arm)),
        gripper: grasp.gripper,
        camera: grasp.camera,
        clock,
    })
}

/// A rig session, new or resumed: the rig's devices opened when trials remain, each
/// trial stored as it ends; questions to the operator.
async fn run_on_rig(
    request: &TrialsRequest,
    rig_path: &Path,
    store: &Store,
    terminal: &mut Terminal<'_>,
) -> Result<(), TrialsError> {
    // The rig alone: a grasp uses none of a collection scene's poses.
    let rig = softtouch_collector::configs::rig(Some(rig_path))?.0;
    let session = match request.resume {
        Some(id) => resume_rig_session(store, id, request.model.as_deref(), &rig).await?,
        None => {
            let plan = request.plan.clone().checked()?;
            let model = request.model.clone().unwrap_or_default();
            start_rig_session(store, &model, request.seed, plan, &rig).await?
        }
    };
    let progress = session.progress(store).await?;
    let todo = progress.todo;
    let out = &mut *terminal.out;
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
    )
    .map_err(written)?;
    out.flush().map_err(written)?;
    if !todo.is_empty() {
        let mut devices = open_rig_devices(&rig, rig_path, "trials").await?;
        let mut on_trial = |t: &TrialDone| -> Result<(), TrialsError> {
            let row = &t.row;
            writeln!(
                out,
                "σ {} mm {} {} #{}: {}{}{} ({:.1} s)",
                row.sigma_m * 1000.0,
                row.key.object,
                row.key.mode,
                row.key.trial,
                row.reason.as_deref().unwrap_or("held"),
                row.detail
                    .as_deref()
                    .map_or_else(String::new, |d| format!(": {d}")),
                // The grip a rig can show: no true force, the closing past the touch.
                row.past_touch_mm.map_or_else(String::new, |mm| format!(
                    ", closed {mm:.2} mm past the touch"
                )),
                t.timing.wall_s
            )
            .map_err(written)
        };
        let ran = run_rig_trials(
            store,
            &session,
            &mut devices,
            &mut terminal.operator,
            &todo,
            &terminal.stop,
            &mut on_trial,
        )
        .await;
        let out = &mut *terminal.out;
        match ran {
            Err(TrialsError::Interrupted) => {
                return Err(TrialsError::Failed(format!(
                    "rig grasp session {}: stopped at once by a second stop request, through the safe exit; the trials before it are stored (resume with --rig {} --resume {})",
                    session.id,
                    rig_path.display(),
                    session.id
                )));
            }
            Err(e) => return Err(e),
            Ok(RunEnd::Stopped { ran }) => writeln!(
                out,
                "stopped after {ran} of {} trials (a stop request; resume with --rig {} --resume {})",
                todo.len(),
                rig_path.display(),
                session.id
            )
            .map_err(written)?,
            Ok(RunEnd::Completed) => {}
        }
    }
    let out = &mut *terminal.out;
    let rows = store.grasp_trials(session.id).await?;
    let table = summarise(&session.plan, &session.media(), &rows)?;
    print_table(&table, &session.plan, out).map_err(written)?;
    print_sweep(&table, &session.plan, out).map_err(written)?;
    print_paired(
        &paired(&session.plan, &session.media(), &rows),
        &session.plan,
        out,
    )
    .map_err(written)?;
    for p in write_outputs(&request.out_dir, &table, &rows, &session.plan)? {
        writeln!(out, "wrote {}", p.display()).map_err(written)?;
    }
    Ok(())
}
