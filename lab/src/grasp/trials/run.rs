//! Running a session's trials: each on a fresh simulated grasp on virtual time, on
//! its own thread with the model, stored as it ends.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use softtouch_drivers::gripper::{opening_mm, position_for_opening};
use softtouch_drivers::{Clock, TokioClock};
use softtouch_grasp::{
    ControllerConfig, GraspError, Mode, Stroke, TrialConfig, TrialDevices, TrialResult,
    one_count_force_n, perturbation_m, run_trial, trial_seed,
};
use softtouch_schemas::{Medium, SceneSpec};
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::Predictor;

use super::{Planned, Session, TrialsError, invalid, medium_name, objects_of};
use crate::grasp::calibration::{Calibrated, calibration_for, top_for};
use crate::grasp::sim::{BothFingersTruth, SimJudge, SimLift, projection};
use crate::grasp::soft::GraspRunError;
use crate::store::{GraspTrace, GraspTrialRow, Store, TraceFrame};

/// One trial, as it ends: its stored row and its timing.
#[derive(Debug, Clone)]
pub struct TrialDone {
    /// The stored row.
    pub row: GraspTrialRow,
    /// Its medium and mode, and how many cycles it ran (for the timing table).
    pub timing: TrialTiming,
}

/// One trial's wall time, for the timing table.
#[derive(Debug, Clone, Copy)]
pub struct TrialTiming {
    /// The scene's medium.
    pub medium: Medium,
    /// Open or closed loop.
    pub mode: Mode,
    /// Wall time, s.
    pub wall_s: f64,
    /// Control cycles (one a frame).
    pub cycles: usize,
}

/// How a run of trials ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunEnd {
    /// Every trial of `todo` ran and was stored.
    Completed,
    /// A stop request (the first signal) ended it after the trial in hand, which was
    /// stored; this many of `todo` ran.
    Stopped {
        /// Trials run and stored before the stop.
        ran: usize,
    },
}

/// Runs `todo` (from [`Session::progress`]) one trial at a time, each stored as it
/// ends; `done` hears of each (to print progress; its error stops the session).
/// `stop` counts stop requests: at 1 the run ends after the trial in hand (stored),
/// at 2 it ends at once with [`TrialsError::Interrupted`] and that trial is not stored
/// (a simulated trial moves nothing real: its thread is left to finish unseen).
/// K per (scene, object) is 0.75 × Λ_max from the stiffness calibration on the
/// model's own estimate ([`crate::grasp::calibration`]: the latest stored, else one
/// made on the unperturbed object and stored), all made before any trial; the
/// closed loop's confirmation accepts one count's dither at that Λ_max.
///
/// # Errors
/// A trial that fails (a device, the model), the store, or `done`.
pub async fn run_trials(
    store: &Store,
    session: &Session,
    todo: &[Planned],
    stop: &tokio::sync::watch::Receiver<u32>,
    done: &mut dyn FnMut(&TrialDone) -> Result<(), TrialsError>,
) -> Result<RunEnd, TrialsError> {
    let plan = &session.plan;
    let scenes = &session.scenes;
    let seed = session.seed;
    let objects = objects_of(plan, scenes)?;
    let mut predictor = Predictor::from_bytes(&session.model_bytes)?;
    // A trial is one frame at a time: its drawing, preprocessing and the model's
    // larger convolutions take the second core for half of each frame's work, and
    // the rest of the model runs on one (burn's rayon workers spinning on both cores
    // would only get in their way).
    predictor.split_frames(Some(Arc::new(SecondCore)));
    let inference_pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| TrialsError::Failed(format!("cannot build a thread pool: {e}")))?,
    );
    let mut predictor = Some(predictor);
    let mut stop = stop.clone();
    for (ran, p) in todo.iter().enumerate() {
        if *stop.borrow_and_update() >= 1 {
            return Ok(RunEnd::Stopped { ran });
        }
        let si = p.key.scene_index as usize;
        let scene = &scenes[si];
        let oi = plan
            .objects
            .iter()
            .position(|o| *o == p.key.object)
            .unwrap_or(0);
        let template = objects[si][oi].clone();
        let Some(setup) = session
            .calibrations
            .get(&(p.key.scene_index, p.key.object.clone()))
        else {
            return Err(TrialsError::Failed(format!(
                "no calibration of `{}` was made",
                p.key.object
            )));
        };
        let gain = plan.gain_over_lambda * setup.calibration.lambda_max().max(0.05);
        let dither_n = setup.count_n;
        let tolerance_n = setup.tolerance_n;
        let squeeze = setup.calibration.squeeze()?;
        let mut controller = ControllerConfig::new(projection()?).with_squeeze(squeeze.clone());
        controller.stepper.gain_n_per_mm = gain;
        controller.stepper.tolerance_n = tolerance_n;
        let grasp_mm = plan
            .open_width_mm
            .unwrap_or(template.grasp_width_m * 1000.0);
        let trial = TrialConfig {
            mode: p.mode,
            grasp_position: position_for_opening(grasp_mm),
            pregrasp_position: if plan.pregrasp_from_touch {
                // The margin short of where the finger's own estimate first felt it.
                let stroke = Stroke::default();
                let margin = (plan.pregrasp_margin_mm / stroke.mm_per_count).round() as i64;
                stroke.clamp(i64::from(setup.calibration.touch()) - margin)
            } else {
                position_for_opening(grasp_mm + plan.pregrasp_margin_mm)
            },
            target_n: plan.target_n,
            confirm: Duration::from_secs_f64(plan.confirm_s),
            dither_n,
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
        let Some(mut pred) = predictor.take() else {
            return Err(TrialsError::Failed(
                "the model was lost by a failed trial".into(),
            ));
        };
        pred.set_tare(plan.tare_of(si).cloned());
        let pool = Arc::clone(&inference_pool);
        let handle = tokio::task::spawn_blocking(move || pool.install(|| run_job(job, pred)));
        let at_once = async {
            while *stop.borrow_and_update() < 2 {
                if stop.changed().await.is_err() {
                    // No more requests can come: never stop at once.
                    std::future::pending::<()>().await;
                }
            }
        };
        let (pred, result) = tokio::select! {
            joined = handle => {
                joined.map_err(|e| TrialsError::Failed(format!("a trial's thread failed: {e}")))?
            }
            () = at_once => return Err(TrialsError::Interrupted),
        };
        predictor = Some(pred);
        let result = result?;
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
            past_touch_mm: result.deepest_position().map(|c| squeeze.past_touch_mm(c)),
            success: result.verdict.success(),
            reason: result.verdict.reason().map(|r| r.as_str().to_owned()),
            detail: result.detail.clone(),
            confirmed_after_s: result.confirmed_after_ns.map(|n| n as f64 * 1e-9),
            wall_s,
        };
        store
            .append_grasp_trial(session.id, &row, &pack_trace(&result))
            .await?;
        done(&TrialDone {
            timing: TrialTiming {
                medium: scene.medium,
                mode: p.mode,
                wall_s,
                cycles: result.trace.len(),
            },
            row,
        })?;
    }
    Ok(RunEnd::Completed)
}

/// An object's calibration and the closed loop's δ on it.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectSetup {
    /// The stiffness calibration (K = gain_over_lambda × its Λ_max).
    pub calibration: Calibrated,
    /// The force of one count at its Λ_max, N (the confirmation's dither allowance).
    pub count_n: f64,
    /// δ, N: the plan's, widened to a quarter of one count where that is larger.
    pub tolerance_n: f64,
}

/// δ on an object whose one count is `count_n`: the confirmation accepts one count's
/// dither whose mean lies within δ, which confirms a target anywhere between two
/// counts only while one count is at most 4δ; a smaller δ is widened to that
/// (rounded up to the mN).
#[must_use]
pub(super) fn tolerance_for(plan_tolerance_n: f64, count_n: f64) -> f64 {
    if count_n.is_finite() && count_n > 4.0 * plan_tolerance_n {
        (count_n / 4.0 * 1000.0).ceil() / 1000.0
    } else {
        plan_tolerance_n
    }
}

/// The calibration of every (scene, object) in `pairs`, before any trial runs (the
/// latest stored, else one made and stored), with the δ the closed loop uses there.
///
/// # Errors
/// An object the fingers never touch, the model, the store.
#[allow(clippy::too_many_arguments)] // a session's parts, before the session exists
pub(super) async fn calibrate_all(
    store: &Store,
    model: &str,
    model_bytes: &[u8],
    seed: u64,
    plan: &super::TrialPlan,
    scenes: &[SceneSpec],
    objects: &[Vec<GraspObject>],
    pairs: impl IntoIterator<Item = (u32, String)>,
) -> Result<HashMap<(u32, String), ObjectSetup>, TrialsError> {
    let mut out: HashMap<(u32, String), ObjectSetup> = HashMap::new();
    for key in pairs {
        if out.contains_key(&key) {
            continue;
        }
        let si = key.0 as usize;
        let (Some(scene), Some(list)) = (scenes.get(si), objects.get(si)) else {
            return Err(TrialsError::Failed(format!("no scene {si} in the session")));
        };
        let Some(object) = list.iter().find(|o| o.name == key.1) else {
            return Err(invalid(format!("object `{}` is not in scene {si}", key.1)));
        };
        let calibration = calibration_for(
            store,
            model,
            model_bytes,
            scene,
            object,
            plan.fps,
            seed,
            top_for(plan.target_n),
            plan.accept_calibration,
            plan.tare_of(si),
        )
        .await
        .map_err(|e| {
            // A calibration read through a tare says which: a lab then knows what the
            // model saw.
            let through = plan.scene_tare(si).map_or_else(String::new, |t| {
                format!(" (reading the frames through the {})", t.describe())
            });
            match e {
                GraspRunError::Invalid(m) => {
                    invalid(format!("calibrating `{}`{through}: {m}", object.name))
                }
                e => TrialsError::Failed(format!("calibrating `{}`{through}: {e}", object.name)),
            }
        })?;
        let count_n = one_count_force_n(calibration.lambda_max(), &Stroke::default());
        out.insert(
            key,
            ObjectSetup {
                calibration,
                count_n,
                tolerance_n: tolerance_for(plan.tolerance_n, count_n),
            },
        );
    }
    Ok(out)
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
    let rt = match crate::grasp::sim::paused_runtime() {
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
        // The row's peak true force is either finger's (the verdict's fingers); the
        // trace keeps the loop's finger beside its estimate.
        let peak_n = Arc::new(Mutex::new(None));
        let devices = TrialDevices {
            gripper,
            camera,
            estimator: &mut predictor,
            truth: BothFingersTruth {
                handle: handle.clone(),
                projections: [
                    job.controller.projection,
                    crate::grasp::soft::projections()?[1],
                ],
                peak_n: Arc::clone(&peak_n),
            },
            lift: SimLift {
                handle: handle.clone(),
                clock: Arc::clone(&shared),
            },
            judge: SimJudge(handle),
            clock: shared,
        };
        let mut result = run_trial(devices, job.controller, &job.trial).await?;
        let both = peak_n.lock().ok().and_then(|p| *p);
        if both.is_some() {
            result.peak_true_n = both;
        }
        Ok(result)
    });
    (predictor, result)
}

/// A trial's trace as the store packs it.
#[must_use]
pub fn pack_trace(r: &TrialResult) -> GraspTrace {
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
        // On the trace's time axis (s after its first cycle).
        frames: r
            .snapshots
            .iter()
            .map(|s| TraceFrame {
                moment: s.moment.as_str().to_owned(),
                t_s: (s.t.0 as f64 - t0 as f64) * 1e-9,
                png: s.png.clone(),
            })
            .collect(),
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
