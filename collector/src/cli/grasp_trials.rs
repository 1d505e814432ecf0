//! `softtouch grasp trials`: the grasp success-rate trials of Figure 4 on the simulated
//! soft-finger Hand-E, open loop against closed loop, per object and medium, each trial
//! stored as it ends (one transaction) so a session resumes where it stopped.
//!
//! A session's plan is its model, scenes (one per medium), seed, objects, modes, trial
//! count, σ list and loop settings; trial `i` of an object is a pure function of
//! `(seed, object, i)` and σ, so it replays alone. The table gives each object × mode
//! its success rate with the Wilson 95 % interval, with the paper's overall figures
//! beside the overall rows; a CSV and a PNG bar chart (Figure 4f) go to `--out-dir`,
//! and a σ sweep adds success against σ.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::anyhow;
use clap::Args;
use serde::{Deserialize, Serialize};
use softtouch_drivers::gripper::{STROKE_MM, opening_mm, position_for_opening};
use softtouch_drivers::{Clock, TokioClock};
use softtouch_grasp::{
    ControllerConfig, FailReason, GraspError, LiftPlan, Mode, TrialConfig, TrialDevices,
    TrialResult, Z_95, perturbation_m, run_trial, trial_seed, wilson_interval,
};
use softtouch_schemas::config::{ConfigSource, parse_toml};
use softtouch_schemas::{Medium, SceneSpec};
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::Predictor;

use super::{Failure, io_failure, open_existing};
use crate::dataset::export::sha256_hex;
use crate::grasp::settings;
use crate::grasp::sim::{SimJudge, SimLift, SimTruth, projection, stiffness};
use crate::plot::{BarChart, BarSeries, Series, SeriesStyle, XyChart, bar_chart, xy_chart};
use crate::store::{GraspTrace, GraspTrialKey, GraspTrialRow};

/// The built-in scenes: on land and underwater, five objects each.
const LAND_TOML: &str = include_str!("../../../scenes/grasp.toml");
const WATER_TOML: &str = include_str!("../../../scenes/grasp-water.toml");

/// The paper's overall success rates (Figure 4): (medium, mode) → rate.
fn paper_rate(medium: Medium, mode: Mode) -> f64 {
    match (medium, mode) {
        (Medium::Air, Mode::Open) => 0.44,
        (Medium::Air, Mode::Closed) => 1.0,
        (Medium::Water, Mode::Open) => 0.30,
        (Medium::Water, Mode::Closed) => 0.90,
    }
}

fn medium_name(m: Medium) -> &'static str {
    match m {
        Medium::Air => "land",
        Medium::Water => "water",
    }
}

/// Options of `grasp trials`.
#[derive(Debug, Args)]
pub struct TrialsArgs {
    /// Stored model whose estimate closes the loop (and is recorded in open loop).
    #[arg(long, required_unless_present = "resume")]
    pub model: Option<String>,
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
            "model", "scene", "objects", "trials", "sigma_mm", "sweep_sigma", "modes", "seed",
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
    /// Folder for `grasp-trials.csv`, `grasp-trials-rows.csv`, `grasp-trials.png` and,
    /// with --sweep-sigma, `grasp-trials-sigma.png`.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
}

/// A session's settings, stored as JSON with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Plan {
    objects: Vec<String>,
    modes: Vec<String>,
    trials: u32,
    sigmas_mm: Vec<f64>,
    fps: f64,
    target_n: f64,
    tolerance_n: f64,
    gain_over_lambda: f64,
    confirm_s: f64,
    close_timeout_s: f64,
    lift_mm: f64,
    lift_speed_m_s: f64,
    lift_accel_m_s2: f64,
    hold_s: f64,
    open_width_mm: Option<f64>,
    pregrasp_margin_mm: f64,
}

fn bad(m: String) -> Failure {
    Failure::BadInput(anyhow!(m))
}

fn check_range(flag: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Result<(), Failure> {
    if v.is_finite() && v > lo && v <= hi {
        Ok(())
    } else {
        Err(bad(format!(
            "{flag} {v}: expected a value in ({lo}, {hi}] {unit}"
        )))
    }
}

impl Plan {
    fn from_args(args: &TrialsArgs) -> Result<Self, Failure> {
        settings::FPS_HZ.check("--fps", args.fps)?;
        check_range("--target-n", args.target_n, 0.0, 50.0, "N")?;
        settings::TOLERANCE_N.check("--tolerance", args.tolerance)?;
        check_range("--confirm-s", args.confirm_s, 0.0, 60.0, "s")?;
        check_range("--close-timeout-s", args.close_timeout_s, 0.0, 600.0, "s")?;
        check_range("--lift-mm", args.lift_mm, 0.0, 500.0, "mm")?;
        settings::duration_s(false).check("--hold-s", args.hold_s)?;
        if args.trials == 0 || args.trials > 10_000 {
            return Err(bad(format!(
                "--trials {}: expected 1 to 10000 trials per object and mode",
                args.trials
            )));
        }
        let sigmas_mm = if args.sweep_sigma.is_empty() {
            vec![args.sigma_mm]
        } else {
            args.sweep_sigma.clone()
        };
        for s in &sigmas_mm {
            if !(s.is_finite() && (0.0..=50.0).contains(s)) {
                return Err(bad(format!(
                    "σ {s} mm (--sigma-mm / --sweep-sigma): expected a value in [0, 50] mm"
                )));
            }
        }
        let mut modes = Vec::new();
        for m in &args.modes {
            let mode = Mode::parse(m).map_err(|e| bad(format!("--modes: {e}")))?;
            if !modes.contains(&mode.as_str().to_owned()) {
                modes.push(mode.as_str().to_owned());
            }
        }
        if modes.is_empty() {
            return Err(bad("--modes: expected open, closed or both".into()));
        }
        if let Some(w) = args.open_width_mm {
            check_range("--open-width-mm", w, 0.0, STROKE_MM, "mm")?;
        }
        // Each object once, in the order first given (a repeat would run its trials
        // twice, the second time as already stored).
        let mut objects: Vec<String> = Vec::new();
        for o in &args.objects {
            if !objects.contains(o) {
                objects.push(o.clone());
            }
        }
        Ok(Self {
            objects,
            modes,
            trials: args.trials,
            sigmas_mm,
            fps: args.fps,
            target_n: args.target_n,
            tolerance_n: args.tolerance,
            gain_over_lambda: 0.75,
            confirm_s: args.confirm_s,
            close_timeout_s: args.close_timeout_s,
            lift_mm: args.lift_mm,
            lift_speed_m_s: 0.1,
            lift_accel_m_s2: 2.0,
            hold_s: args.hold_s,
            open_width_mm: args.open_width_mm,
            pregrasp_margin_mm: 6.0,
        })
    }

    fn modes(&self) -> Result<Vec<Mode>, Failure> {
        self.modes
            .iter()
            .map(|m| Mode::parse(m).map_err(|e| Failure::Runtime(anyhow!("stored plan: {e}"))))
            .collect()
    }

    fn lift(&self) -> LiftPlan {
        LiftPlan {
            height_m: self.lift_mm / 1000.0,
            speed_m_s: self.lift_speed_m_s,
            accel_m_s2: self.lift_accel_m_s2,
        }
    }
}

fn load_scenes(paths: &[PathBuf]) -> Result<Vec<SceneSpec>, Failure> {
    if paths.is_empty() {
        return [
            ("built-in land scene", LAND_TOML),
            ("built-in water scene", WATER_TOML),
        ]
        .iter()
        .map(|(name, text)| {
            parse_toml::<SceneSpec>(text, &ConfigSource::Embedded(name))
                .map_err(|e| Failure::Runtime(e.into()))
        })
        .collect();
    }
    paths
        .iter()
        .map(|p| Ok(crate::configs::resolve(None, Some(p))?.scene))
        .collect()
}

/// The objects of the plan in every scene, checked: known, and inside the stroke.
fn objects_of(plan: &Plan, scenes: &[SceneSpec]) -> Result<Vec<Vec<GraspObject>>, Failure> {
    scenes
        .iter()
        .map(|scene| {
            let known: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
            if known.is_empty() {
                return Err(bad(format!(
                    "scene `{}` declares no [[objects]]: expected the objects to grasp",
                    scene.name
                )));
            }
            plan.objects
                .iter()
                .map(|name| {
                    let spec = scene.object(name).ok_or_else(|| {
                        bad(format!(
                            "--objects: scene `{}` declares no object `{name}` (it has: {})",
                            scene.name,
                            known.join(", ")
                        ))
                    })?;
                    let object = GraspObject::from_spec(spec);
                    let widest_mm = object.max_width_m() * 1000.0;
                    let grasp_mm = plan
                        .open_width_mm
                        .unwrap_or(object.grasp_width_m * 1000.0);
                    if widest_mm >= STROKE_MM || grasp_mm >= STROKE_MM {
                        return Err(bad(format!(
                            "object `{name}` of scene `{}` is {widest_mm:.1} mm at its widest (open-loop width {grasp_mm:.1} mm): outside the Hand-E's {STROKE_MM} mm stroke; objects inside it: {}",
                            scene.name,
                            scene
                                .objects
                                .iter()
                                .filter(|o| GraspObject::from_spec(o).max_width_m() * 1000.0 < STROKE_MM)
                                .map(|o| o.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )));
                    }
                    Ok(object)
                })
                .collect()
        })
        .collect()
}

/// One planned trial.
#[derive(Debug, Clone)]
struct Planned {
    key: GraspTrialKey,
    mode: Mode,
    sigma_m: f64,
}

fn planned(plan: &Plan, scenes: usize, modes: &[Mode]) -> Vec<Planned> {
    let mut out = Vec::new();
    for (si, sigma) in plan.sigmas_mm.iter().enumerate() {
        for scene_index in 0..scenes {
            for object in &plan.objects {
                for mode in modes {
                    for trial in 0..plan.trials {
                        out.push(Planned {
                            key: GraspTrialKey {
                                sigma_index: si as u32,
                                scene_index: scene_index as u32,
                                object: object.clone(),
                                mode: mode.as_str().to_owned(),
                                trial,
                            },
                            mode: *mode,
                            sigma_m: sigma / 1000.0,
                        });
                    }
                }
            }
        }
    }
    out
}

fn grasp_failure(e: GraspError) -> Failure {
    match e {
        GraspError::Config(_) | GraspError::UnreachableTarget { .. } => Failure::BadInput(e.into()),
        GraspError::Device(_) | GraspError::Estimate(_) | GraspError::Interrupted(_) => {
            Failure::Runtime(e.into())
        }
    }
}

/// Everything one simulated trial needs, owned (it runs on its own thread and paused
/// clock).
struct Job {
    scene: SceneSpec,
    template: GraspObject,
    offset_m: [f64; 3],
    seed: u64,
    fps: f64,
    controller: ControllerConfig,
    trial: TrialConfig,
}

/// Runs one trial on a fresh simulated grasp, on virtual time.
fn run_job(job: Job, mut predictor: Predictor) -> (Predictor, Result<TrialResult, GraspError>) {
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            return (
                predictor,
                Err(GraspError::Config(format!(
                    "cannot start a trial's runtime: {e}"
                ))),
            );
        }
    };
    let result = rt.block_on(async {
        let clock = TokioClock::new();
        let placed = job.template.placed(job.offset_m);
        let sim_err = |e: softtouch_sim::SimError| {
            GraspError::Config(format!("object `{}`: {e}", job.template.name))
        };
        let (gripper, camera, handle) = soft_grasp(
            &job.scene,
            placed.clone().unwrap_or_else(|| job.template.clone()),
            job.fps,
            job.seed,
            clock,
        )
        .map_err(sim_err)?;
        if placed.is_none() {
            // The fingers miss it: nothing between them.
            handle.set_object(false).map_err(sim_err)?;
        }
        let shared: Arc<dyn Clock> = Arc::new(clock);
        let devices = TrialDevices {
            gripper,
            camera,
            estimator: &mut predictor,
            truth: SimTruth(handle.clone(), job.controller.projection),
            lift: SimLift {
                handle: handle.clone(),
                clock: Arc::clone(&shared),
            },
            judge: SimJudge(handle),
            clock: shared,
        };
        run_trial(devices, job.controller, &job.trial).await
    });
    (predictor, result)
}

fn pack_trace(r: &TrialResult) -> GraspTrace {
    let t0 = r.trace.first().map_or(0, |c| c.t.0);
    let f = |v: Option<f64>| v.map_or(f32::NAN, |x| x as f32);
    GraspTrace {
        t_s: r
            .trace
            .iter()
            .map(|c| (c.t.0.saturating_sub(t0) as f64 * 1e-9) as f32)
            .collect(),
        estimate_n: r.trace.iter().map(|c| f(c.estimate_n)).collect(),
        true_n: r.trace.iter().map(|c| f(c.true_n)).collect(),
        measured_count: r.trace.iter().map(|c| c.measured_position).collect(),
        request_count: r.trace.iter().map(|c| c.position_request).collect(),
    }
}

/// One trial's wall time, for the timing table.
#[derive(Debug, Clone, Copy)]
struct TrialTiming {
    medium: Medium,
    mode: Mode,
    wall_s: f64,
    cycles: usize,
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

/// Run `grasp trials`.
pub async fn run(args: TrialsArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let (session_id, model, seed, plan, scenes, bytes, model_sha256) = match args.resume {
        Some(id) => {
            let s = store.grasp_session(id).await?.ok_or_else(|| {
                bad(format!(
                    "--resume {id}: no grasp session {id} in {}",
                    db.display()
                ))
            })?;
            if let Some(m) = &args.model
                && *m != s.model
            {
                return Err(bad(format!(
                    "--model {m}: session {id} runs model `{}` (leave --model out to resume it)",
                    s.model
                )));
            }
            let plan: Plan = serde_json::from_str(&s.config_json).map_err(|e| {
                Failure::Runtime(anyhow!(
                    "grasp session {id}: stored settings do not read back: {e}"
                ))
            })?;
            let scenes: Vec<SceneSpec> = serde_json::from_str(&s.scenes_json).map_err(|e| {
                Failure::Runtime(anyhow!(
                    "grasp session {id}: stored scenes do not read back: {e}"
                ))
            })?;
            let bytes = crate::models::force_artifact(&store, &s.model).await?;
            let now = sha256_hex(&bytes);
            if let Some(then) = &s.model_sha256
                && *then != now
            {
                return Err(bad(format!(
                    "--resume {id}: model `{}` has changed since the session started (sha256 {} then, {} now); start a new session",
                    s.model,
                    &then[..then.len().min(12)],
                    &now[..12]
                )));
            }
            (id, s.model, s.seed, plan, scenes, bytes, now)
        }
        None => {
            let mut plan = Plan::from_args(&args)?;
            let scenes = load_scenes(&args.scene)?;
            if plan.objects.is_empty() {
                plan.objects = scenes
                    .first()
                    .map(|s| s.objects.iter().map(|o| o.name.clone()).collect())
                    .unwrap_or_default();
            }
            let model = args.model.clone().unwrap_or_default();
            objects_of(&plan, &scenes)?; // checked before anything is stored
            // The model must exist before a session names it.
            let bytes = crate::models::force_artifact(&store, &model).await?;
            let model_sha256 = sha256_hex(&bytes);
            let config_json = serde_json::to_string(&plan)
                .map_err(|e| Failure::Runtime(anyhow!("cannot encode the settings: {e}")))?;
            let scenes_json = serde_json::to_string(&scenes)
                .map_err(|e| Failure::Runtime(anyhow!("cannot encode the scenes: {e}")))?;
            let id = store
                .create_grasp_session(&model, &model_sha256, args.seed, &scenes_json, &config_json)
                .await?;
            (id, model, args.seed, plan, scenes, bytes, model_sha256)
        }
    };
    let objects = objects_of(&plan, &scenes)?;
    let modes = plan.modes()?;
    let mut predictor = Predictor::from_bytes(&bytes)?;
    // A trial is one frame at a time: its drawing, preprocessing and the model's
    // larger convolutions take the second core for half of each frame's work, and
    // the rest of the model runs on one (burn's rayon workers spinning on both cores
    // would only get in their way).
    predictor.split_frames(Some(Arc::new(SecondCore)));
    let inference_pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| Failure::Runtime(anyhow!("cannot build a thread pool: {e}")))?,
    );
    let mut predictor = Some(predictor);

    let all = planned(&plan, scenes.len(), &modes);
    let done = store.grasp_trial_keys(session_id).await?;
    let todo: Vec<&Planned> = all.iter().filter(|p| !done.contains(&p.key)).collect();
    let w = io_failure;
    writeln!(
        out,
        "grasp session {session_id}: model `{model}` (sha256 {}), seed {seed}, {} trials planned, {} stored, {} to run",
        &model_sha256[..12],
        all.len(),
        all.len() - todo.len(),
        todo.len()
    )
    .map_err(w)?;

    // K per (scene, object): 0.75 × Λ_max measured on the simulator's contact physics
    // (before any trial, on the unperturbed object).
    let mut gains: HashMap<(u32, String), f64> = HashMap::new();
    let bar = crate::progress::progress_bar(todo.len() as u64, true, "trials");
    let started = Instant::now();
    let mut timings = Vec::with_capacity(todo.len());
    for (i, p) in todo.iter().enumerate() {
        let si = p.key.scene_index as usize;
        let scene = &scenes[si];
        let oi = plan
            .objects
            .iter()
            .position(|o| *o == p.key.object)
            .unwrap_or(0);
        let template = objects[si][oi].clone();
        let gain_key = (p.key.scene_index, p.key.object.clone());
        let gain = match gains.get(&gain_key) {
            Some(g) => *g,
            None => {
                let (_, _, handle) =
                    soft_grasp(scene, template.clone(), plan.fps, seed, TokioClock::new())
                        .map_err(|e| bad(format!("object `{}`: {e}", template.name)))?;
                let (_, lambda) = stiffness(&handle, plan.target_n).map_err(grasp_failure)?;
                let g = plan.gain_over_lambda * lambda.max(0.05);
                gains.insert(gain_key, g);
                g
            }
        };
        let mut controller = ControllerConfig::new(projection().map_err(grasp_failure)?);
        controller.stepper.gain_n_per_mm = gain;
        controller.stepper.tolerance_n = plan.tolerance_n;
        let grasp_mm = plan
            .open_width_mm
            .unwrap_or(template.grasp_width_m * 1000.0);
        let trial = TrialConfig {
            mode: p.mode,
            grasp_position: position_for_opening(grasp_mm),
            pregrasp_position: position_for_opening(grasp_mm + plan.pregrasp_margin_mm),
            target_n: plan.target_n,
            confirm: Duration::from_secs_f64(plan.confirm_s),
            close_timeout: Duration::from_secs_f64(plan.close_timeout_s),
            move_timeout: Duration::from_secs(5),
            lift: plan.lift(),
            hold: Duration::from_secs_f64(plan.hold_s),
        };
        let offset_m = perturbation_m(seed, &p.key.object, u64::from(p.key.trial), p.sigma_m);
        let job = Job {
            scene: scene.clone(),
            template,
            offset_m,
            seed: trial_seed(seed, &p.key.object, u64::from(p.key.trial)),
            fps: plan.fps,
            controller,
            trial,
        };
        let t0 = Instant::now();
        let Some(pred) = predictor.take() else {
            return Err(Failure::Runtime(anyhow!(
                "the model was lost by a failed trial"
            )));
        };
        let pool = Arc::clone(&inference_pool);
        let (pred, result) =
            tokio::task::spawn_blocking(move || pool.install(|| run_job(job, pred)))
                .await
                .map_err(|e| Failure::Runtime(anyhow!("a trial's thread failed: {e}")))?;
        predictor = Some(pred);
        let result = result.map_err(grasp_failure)?;
        let wall_s = t0.elapsed().as_secs_f64();
        let row = GraspTrialRow {
            key: p.key.clone(),
            medium: medium_name(scene.medium).to_owned(),
            sigma_m: p.sigma_m,
            offset_m,
            commanded_width_m: opening_mm(result.commanded_position) / 1000.0,
            final_width_m: opening_mm(result.final_position) / 1000.0,
            peak_estimate_n: result.peak_estimate_n,
            peak_true_n: result.peak_true_n,
            success: result.verdict.success(),
            reason: result.verdict.reason().map(|r| r.as_str().to_owned()),
            detail: result.detail.clone(),
            confirmed_after_s: result.confirmed_after_ns.map(|n| n as f64 * 1e-9),
            wall_s,
        };
        store
            .append_grasp_trial(session_id, &row, &pack_trace(&result))
            .await?;
        timings.push(TrialTiming {
            medium: scene.medium,
            mode: p.mode,
            wall_s,
            cycles: result.trace.len(),
        });
        bar.inc(1);
        let per = started.elapsed().as_secs_f64() / (i + 1) as f64;
        let opt = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |f| format!("{f:.2}"));
        bar.suspend(|| {
            writeln!(
                out,
                "[{:>4}/{}] σ {} mm {} {} {} #{}: {} (peak est {} N, true {} N) {:.2} s, eta {}",
                i + 1,
                todo.len(),
                plan.sigmas_mm[p.key.sigma_index as usize],
                row.medium,
                p.key.object,
                p.key.mode,
                p.key.trial,
                row.reason.as_deref().unwrap_or("held"),
                opt(row.peak_estimate_n),
                opt(row.peak_true_n),
                wall_s,
                fmt_duration(per * (todo.len() - i - 1) as f64)
            )
        })
        .map_err(w)?;
    }
    bar.finish_and_clear();
    if !todo.is_empty() {
        writeln!(
            out,
            "ran {} trials in {:.1} s wall ({:.2} s per trial)",
            todo.len(),
            started.elapsed().as_secs_f64(),
            started.elapsed().as_secs_f64() / todo.len() as f64
        )
        .map_err(w)?;
        print_timings(&timings, plan.fps, out)?;
    }

    let rows = store.grasp_trials(session_id).await?;
    let table = summarise(&plan, &scenes, &modes, &rows)?;
    print_table(&table, &plan, out)?;
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out_dir.display())))?;
    let csv = args.out_dir.join("grasp-trials.csv");
    write_summary_csv(&csv, &table)?;
    let rows_csv = args.out_dir.join("grasp-trials-rows.csv");
    write_rows_csv(&rows_csv, &rows)?;
    let png = args.out_dir.join("grasp-trials.png");
    write_bars(&png, &table, &plan)?;
    writeln!(
        out,
        "wrote {}, {} and {}",
        csv.display(),
        rows_csv.display(),
        png.display()
    )
    .map_err(w)?;
    if plan.sigmas_mm.len() > 1 {
        let sweep = args.out_dir.join("grasp-trials-sigma.png");
        write_sweep(&sweep, &table, &plan)?;
        writeln!(out, "wrote {}", sweep.display()).map_err(w)?;
    }
    Ok(())
}

/// One cell of the table: an object (or all of them) × mode × medium × σ.
#[derive(Debug, Clone, PartialEq)]
struct Cell {
    sigma_index: u32,
    scene_index: u32,
    medium: Medium,
    /// `None`: every object together.
    object: Option<String>,
    mode: Mode,
    trials: u64,
    held: u64,
    interval: [f64; 2],
    reasons: BTreeMap<&'static str, u64>,
}

impl Cell {
    fn rate(&self) -> Option<f64> {
        (self.trials > 0).then(|| self.held as f64 / self.trials as f64)
    }
    fn paper(&self) -> Option<f64> {
        self.object
            .is_none()
            .then(|| paper_rate(self.medium, self.mode))
    }
}

fn summarise(
    plan: &Plan,
    scenes: &[SceneSpec],
    modes: &[Mode],
    rows: &[GraspTrialRow],
) -> Result<Vec<Cell>, Failure> {
    let mut cells = Vec::new();
    for si in 0..plan.sigmas_mm.len() as u32 {
        for (ci, scene) in scenes.iter().enumerate() {
            let ci = ci as u32;
            let objects: Vec<Option<&String>> =
                plan.objects.iter().map(Some).chain([None]).collect();
            for object in objects {
                for mode in modes {
                    let mine: Vec<&GraspTrialRow> = rows
                        .iter()
                        .filter(|r| {
                            r.key.sigma_index == si
                                && r.key.scene_index == ci
                                && r.key.mode == mode.as_str()
                                && object.is_none_or(|o| *o == r.key.object)
                        })
                        .collect();
                    let trials = mine.len() as u64;
                    let held = mine.iter().filter(|r| r.success).count() as u64;
                    let mut reasons = BTreeMap::new();
                    for r in &FailReason::ALL {
                        let n = mine
                            .iter()
                            .filter(|row| row.reason.as_deref() == Some(r.as_str()))
                            .count() as u64;
                        reasons.insert(r.as_str(), n);
                    }
                    cells.push(Cell {
                        sigma_index: si,
                        scene_index: ci,
                        medium: scene.medium,
                        object: object.cloned(),
                        mode: *mode,
                        trials,
                        held,
                        interval: wilson_interval(held, trials, Z_95)
                            .map_err(|e| Failure::Runtime(e.into()))?,
                        reasons,
                    });
                }
            }
        }
    }
    Ok(cells)
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "–".to_owned(), |v| format!("{:.0}%", 100.0 * v))
}

fn print_table(cells: &[Cell], plan: &Plan, out: &mut dyn Write) -> Result<(), Failure> {
    let w = io_failure;
    let mut last = None;
    for c in cells {
        if last != Some((c.sigma_index, c.scene_index)) {
            last = Some((c.sigma_index, c.scene_index));
            writeln!(
                out,
                "\nσ = {} mm, {} (scene {}):\n{:<14} {:<7} {:>7} {:>6} {:>15} {:>7}  failures",
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
        let failures: Vec<String> = c
            .reasons
            .iter()
            .filter(|(_, n)| **n > 0)
            .map(|(r, n)| format!("{r} {n}"))
            .collect();
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
            failures.join(", ")
        )
        .map_err(w)?;
    }
    Ok(())
}

fn write_file(path: &Path, text: &str) -> Result<(), Failure> {
    std::fs::write(path, text)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", path.display())))
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

fn write_summary_csv(path: &Path, cells: &[Cell]) -> Result<(), Failure> {
    let mut text = String::from(
        "sigma_index,medium,object,mode,trials,held,rate,wilson_lo,wilson_hi,paper_rate,slip,crush,miss,timeout,device_fault\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for c in cells {
        let r = |k: &str| c.reasons.get(k).copied().unwrap_or(0);
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            c.sigma_index,
            medium_name(c.medium),
            csv_field(c.object.as_deref().unwrap_or("all")),
            c.mode.as_str(),
            c.trials,
            c.held,
            opt(c.rate()),
            c.interval[0],
            c.interval[1],
            opt(c.paper()),
            r("slip"),
            r("crush"),
            r("miss"),
            r("timeout"),
            r("device_fault"),
        ));
    }
    write_file(path, &text)
}

fn write_rows_csv(path: &Path, rows: &[GraspTrialRow]) -> Result<(), Failure> {
    let mut text = String::from(
        "sigma_m,medium,object,mode,trial,dx_m,dy_m,dz_m,commanded_width_m,final_width_m,peak_estimate_n,peak_true_n,success,reason,confirmed_after_s,wall_s\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.sigma_m,
            r.medium,
            csv_field(&r.key.object),
            r.key.mode,
            r.key.trial,
            r.offset_m[0],
            r.offset_m[1],
            r.offset_m[2],
            r.commanded_width_m,
            r.final_width_m,
            opt(r.peak_estimate_n),
            opt(r.peak_true_n),
            u8::from(r.success),
            r.reason.as_deref().unwrap_or(""),
            opt(r.confirmed_after_s),
            r.wall_s
        ));
    }
    write_file(path, &text)
}

/// Figure 4f: the first σ's success rates with their intervals, per medium and object.
fn write_bars(path: &Path, cells: &[Cell], plan: &Plan) -> Result<(), Failure> {
    let first: Vec<&Cell> = cells.iter().filter(|c| c.sigma_index == 0).collect();
    let mut groups: Vec<(u32, Option<String>)> = Vec::new();
    for c in &first {
        let g = (c.scene_index, c.object.clone());
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    let mut modes: Vec<Mode> = Vec::new();
    for c in &first {
        if !modes.contains(&c.mode) {
            modes.push(c.mode);
        }
    }
    let names: Vec<String> = groups
        .iter()
        .map(|(si, o)| {
            let medium = first
                .iter()
                .find(|c| c.scene_index == *si)
                .map_or("?", |c| medium_name(c.medium));
            format!("{medium}/{}", o.as_deref().unwrap_or("all"))
        })
        .collect();
    let series: Vec<BarSeries> = modes
        .iter()
        .map(|m| {
            let cell = |g: &(u32, Option<String>)| {
                first
                    .iter()
                    .find(|c| c.mode == *m && c.scene_index == g.0 && c.object == g.1)
            };
            BarSeries {
                label: format!("{} loop (paper: black tick)", m.as_str()),
                bars: groups
                    .iter()
                    .map(|g| cell(g).and_then(|c| Some((c.rate()?, c.interval[0], c.interval[1]))))
                    .collect(),
                reference: groups
                    .iter()
                    .map(|g| cell(g).and_then(|c| c.paper()))
                    .collect(),
            }
        })
        .collect();
    let title = format!(
        "Grasp success, σ = {} mm (Wilson 95 % intervals)",
        plan.sigmas_mm.first().copied().unwrap_or(0.0)
    );
    bar_chart(
        path,
        &BarChart {
            title: &title,
            y_label: "success rate",
            groups: &names,
            series: &series,
            // Headroom above 100 % for the legend.
            y_range: (0.0, 1.3),
        },
        ((180 * names.len() as u32).clamp(640, 2400), 520),
    )
    .map_err(|e| Failure::Runtime(e.into()))
}

/// Success of all objects against σ, per medium and mode.
fn write_sweep(path: &Path, cells: &[Cell], plan: &Plan) -> Result<(), Failure> {
    let mut keys: Vec<(u32, Medium, Mode)> = Vec::new();
    for c in cells.iter().filter(|c| c.object.is_none()) {
        if !keys.contains(&(c.scene_index, c.medium, c.mode)) {
            keys.push((c.scene_index, c.medium, c.mode));
        }
    }
    let series: Vec<Series> = keys
        .iter()
        .map(|(si, medium, mode)| Series {
            label: format!("{} {} loop", medium_name(*medium), mode.as_str()),
            points: cells
                .iter()
                .filter(|c| c.object.is_none() && c.scene_index == *si && c.mode == *mode)
                .filter_map(|c| Some((plan.sigmas_mm[c.sigma_index as usize], c.rate()?)))
                .collect(),
            style: SeriesStyle::LinePoints,
        })
        .collect();
    xy_chart(
        path,
        &XyChart {
            title: "Grasp success against the grasp point's perturbation",
            x_label: "σ per axis (mm)",
            y_label: "success rate (all objects)",
            series: &series,
        },
        (900, 520),
    )
    .map_err(|e| Failure::Runtime(e.into()))
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact stored and published values
mod tests {
    use super::*;

    #[test]
    fn the_built_in_scenes_load_with_objects_inside_the_stroke() {
        let scenes = load_scenes(&[]).unwrap_or_else(|e| panic!("{}", e.error()));
        assert_eq!(scenes.len(), 2);
        assert_eq!(scenes[0].medium, Medium::Air);
        assert_eq!(scenes[1].medium, Medium::Water);
        let mut plan = Plan::from_args(&TrialsArgs {
            model: Some("m".into()),
            scene: vec![],
            objects: vec![],
            trials: 10,
            sigma_mm: 5.0,
            sweep_sigma: vec![],
            modes: vec!["open".into(), "closed".into(), "open".into()],
            seed: 0,
            resume: None,
            fps: 120.0,
            target_n: 1.5,
            tolerance: 0.1,
            confirm_s: 0.25,
            close_timeout_s: 4.0,
            lift_mm: 50.0,
            hold_s: 2.0,
            open_width_mm: None,
            out_dir: PathBuf::from("x"),
        })
        .unwrap_or_else(|e| panic!("{}", e.error()));
        assert_eq!(plan.modes, ["open", "closed"]);
        plan.objects = scenes[0].objects.iter().map(|o| o.name.clone()).collect();
        assert_eq!(plan.objects.len(), 5);
        let objects = objects_of(&plan, &scenes).unwrap_or_else(|e| panic!("{}", e.error()));
        assert_eq!(objects[1].len(), 5);
        // The full table: 2 σ-free media × 5 objects × 2 modes × 10 trials.
        assert_eq!(planned(&plan, 2, &[Mode::Open, Mode::Closed]).len(), 200);
        plan.objects.push("vase".into());
        let err = objects_of(&plan, &scenes)
            .err()
            .map(|e| e.error().to_string());
        assert!(err.is_some_and(|e| e.contains("vase") && e.contains("cylinder")));
    }

    #[test]
    fn the_paper_figures_are_the_published_ones() {
        assert_eq!(paper_rate(Medium::Air, Mode::Open), 0.44);
        assert_eq!(paper_rate(Medium::Water, Mode::Closed), 0.90);
        assert_eq!(fmt_duration(125.4), "2m05s");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
    }
}

/// The drivers' second core (kept awake between frames) for the other half of the
/// preprocessing and of the model's larger convolutions: the one helper the
/// simulated camera's drawing uses too.
#[derive(Debug)]
struct SecondCore;

impl softtouch_trainer::Fork for SecondCore {
    fn fork(&self, here: &mut (dyn FnMut() + Send), there: &mut (dyn FnMut() + Send)) {
        softtouch_sim::second_core::join(here, there);
    }
}
