//! Grasp trials on a lab's rig (`grasp trials --rig`): the arm (behind [`softtouch_drivers::Arm`])
//! places the gripper at each trial's perturbed grasp pose from the rig file, the
//! fingers close open loop or closed loop on the finger's estimate, the arm lifts
//! while the loop keeps cycling ([`ArmLift`]), [`RigJudge`] reads gOBJ, position and
//! estimate and the operator confirms or corrects it, then the arm sets the object
//! down at its place, the fingers open and the gripper rises clear.
//!
//! The same code runs a simulated rig: only the devices handed in differ (in the
//! tests, [`softtouch_sim::SoftGraspArm`], the Hand-E protocol over a pty to the
//! project's Modbus server, and the soft finger's camera).
//!
//! Safety, on every exit (an error, a stop request, a closed operator input, a store
//! failure): the arm stops; an object in the air is set down at its place before the
//! fingers open; a faulted arm leaves the gripper holding where it is, and the output
//! says so; then the arm returns to the safe pose. While the operator is asked
//! anything the arm stands still and the Hand-E hears its command every
//! [`softtouch_grasp::KEEP_ALIVE`]. A perturbed pose outside the workspace moves
//! nothing: the trial is stored as `refused`, counted in no rate.

use std::collections::HashMap;
use std::io::Write;
use std::sync::Arc;
use std::time::{Duration, Instant};

use softtouch_drivers::{Camera, Clock, Gripper, GripperCommand};
use softtouch_grasp::{
    ArmLift, CalibrationConfig, ControllerConfig, EndCalibration, FailReason, LiftPlan, NoTruth,
    OperatorInput, RigJudge, SharedArm, Stroke, TrialConfig, TrialDevices, Verdict, calibrate_ends,
    perturbation_m, run_trial,
};
use softtouch_schemas::rig::{GraspObjectSetup, raised};
use softtouch_schemas::{ArmPose, Medium, RigConfig};
use softtouch_trainer::Predictor;

mod moves;
pub mod twist;

use super::run::{ObjectSetup, tolerance_for};
use super::{
    Planned, Progress, RigPlan, RunEnd, TrialDone, TrialPlan, TrialTiming, TrialsError, invalid,
    medium_name, pack_trace, planned,
};
use crate::grasp::calibration::{Calibrated, rig_setup_hash};
use crate::store::{GraspTrace, GraspTrialRow, Store};
use moves::{Holding, Moves, arm_to, exit_safe, open_fingers, or_stop, set_down, until_stop};
use softtouch_collector::dataset::export::sha256_hex;

/// The devices of a rig's trials.
pub struct RigTrialDevices {
    /// The arm carrying the gripper (shared with each trial's lift).
    pub arm: SharedArm,
    /// The Hand-E.
    pub gripper: Box<dyn Gripper>,
    /// The sensorised finger's camera.
    pub camera: Box<dyn Camera>,
    /// The clock the devices run on.
    pub clock: Arc<dyn Clock>,
}

impl std::fmt::Debug for RigTrialDevices {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RigTrialDevices").finish_non_exhaustive()
    }
}

/// The operator: answers, where questions go, and whether every verdict is put to them.
pub struct Operator {
    /// The answers.
    pub input: OperatorInput,
    /// Where questions and the safe exit's report go.
    pub output: Box<dyn Write + Send>,
    /// Ask the operator to confirm or correct every verdict (a crush only a person
    /// sees); `false`: [`RigJudge`]'s verdict stands. The object's return to its
    /// place is confirmed either way.
    pub confirm_verdicts: bool,
}

impl std::fmt::Debug for Operator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Operator")
            .field("confirm_verdicts", &self.confirm_verdicts)
            .finish_non_exhaustive()
    }
}

/// A rig session ready to run.
#[derive(Debug)]
pub struct RigSession {
    /// Its id in the store.
    pub id: i64,
    /// The model's name.
    pub model: String,
    /// The sha256 of the model's artifact.
    pub model_sha256: String,
    /// Seed of the perturbations.
    pub seed: u64,
    /// Its settings (with the rig's part).
    pub plan: TrialPlan,
    model_bytes: Vec<u8>,
    /// Each object's stored stiffness calibration and the closed loop's δ on it.
    pub calibrations: HashMap<String, ObjectSetup>,
}

impl RigSession {
    /// The rig's part of the plan.
    ///
    /// # Errors
    /// A stored plan without it (not a rig session).
    pub fn rig(&self) -> Result<&RigPlan, TrialsError> {
        self.plan
            .rig
            .as_ref()
            .ok_or_else(|| TrialsError::Failed(format!("session {}: not a rig session", self.id)))
    }

    /// The one medium of the session (the table's only scene).
    #[must_use]
    pub fn media(&self) -> Vec<Medium> {
        self.plan
            .rig
            .as_ref()
            .map_or_else(Vec::new, |r| vec![r.grasp.medium])
    }

    /// The plan's trials and those still to run.
    ///
    /// # Errors
    /// A damaged stored plan, the store.
    pub async fn progress(&self, store: &Store) -> Result<Progress, TrialsError> {
        let modes = self.plan.parsed_modes()?;
        let planned = planned(&self.plan, 1, &modes);
        let done = store.grasp_trial_keys(self.id).await?;
        let todo = planned
            .iter()
            .filter(|p| !done.contains(&p.key))
            .cloned()
            .collect();
        Ok(Progress { planned, todo })
    }

    /// One line per object: the calibration used, K, δ and Method S4's verdict.
    #[must_use]
    pub fn setup_lines(&self) -> Vec<String> {
        let mut names: Vec<&String> = self.calibrations.keys().collect();
        names.sort();
        names
            .into_iter()
            .filter_map(|name| {
                let o = self.calibrations.get(name)?;
                let c = &o.calibration.row;
                let gain = self.plan.gain_over_lambda * c.lambda_max_n_per_mm.max(0.05);
                let s4 = match softtouch_grasp::check_gain(gain, c.lambda_max_n_per_mm) {
                    Ok(softtouch_grasp::GainCheck::Converges { contraction_at_max }) => format!(
                        "S4: K > Λ_max/2, the error × {contraction_at_max:.2} a step at Λ_max"
                    ),
                    Ok(softtouch_grasp::GainCheck::MayNotConverge { amplification }) => format!(
                        "warning (S4, calibration #{}): K ≤ Λ_max/2, the loop may oscillate (× {amplification:.2} a step)",
                        c.calibration_id
                    ),
                    Ok(softtouch_grasp::GainCheck::NoStiffness) | Err(_) => format!(
                        "warning (S4, calibration #{}): no usable stiffness",
                        c.calibration_id
                    ),
                };
                Some(format!(
                    "`{name}`: calibration #{} ({}): first touch at count {}, Λ_max = {:.3} N/mm from the model's estimate; K = {gain:.3} N/mm, δ = {} N{}; {s4}",
                    c.calibration_id,
                    c.created_at,
                    c.touch_count,
                    c.lambda_max_n_per_mm,
                    o.tolerance_n,
                    if o.tolerance_n > self.plan.tolerance_n {
                        format!(
                            " (widened from {} N: one count is {:.3} N here)",
                            self.plan.tolerance_n, o.count_n
                        )
                    } else {
                        String::new()
                    }
                ))
            })
            .collect()
    }
}

/// The rig's `[grasp]` section, or why there is none.
fn grasp_of(rig: &RigConfig) -> Result<&softtouch_schemas::rig::GraspSetup, TrialsError> {
    rig.grasp.as_ref().ok_or_else(|| {
        invalid(
            "the rig file has no [grasp] section: expected the objects' grasp poses, widths, lifts and set-down places (docs/RIG.md, \"Grasp trials\")".into(),
        )
    })
}

/// Each object's latest stored calibration on this rig with this model, or a
/// message naming the command that makes it.
async fn rig_calibrations(
    store: &Store,
    plan: &TrialPlan,
    rig: &RigPlan,
    model: &str,
    model_sha256: &str,
) -> Result<HashMap<String, ObjectSetup>, TrialsError> {
    let mut out = HashMap::new();
    for name in &plan.objects {
        let row = store
            .latest_grasp_calibration(&rig.setup_hash, model_sha256, name)
            .await?
            .ok_or_else(|| {
                invalid(format!(
                    "no stiffness calibration of `{name}` with model `{model}` on this rig's gripper and cameras: run `softtouch grasp calibrate --rig FILE --model {model} --object {name}` first"
                ))
            })?;
        // One count's force at Λ_max on this rig's stroke.
        let count_n = row.lambda_max_n_per_mm * row.mm_per_count;
        out.insert(
            name.clone(),
            ObjectSetup {
                tolerance_n: tolerance_for(plan.tolerance_n, count_n),
                count_n,
                calibration: Calibrated {
                    row,
                    fresh: false,
                    accepted_against: None,
                },
            },
        );
    }
    Ok(out)
}

/// The stored calibration of `object` on `rig` with the model whose artifact is
/// `model_bytes`, and the closed loop's δ on it (`tolerance_n`, widened as the trials
/// widen it): what `grasp twist --rig` holds with.
///
/// # Errors
/// No `[grasp]`, no such object in it, no calibration (the message names the
/// command that makes one), the store.
pub async fn object_setup_on_rig(
    store: &Store,
    rig: &RigConfig,
    model: &str,
    model_bytes: &[u8],
    object: &str,
    tolerance_n: f64,
) -> Result<ObjectSetup, TrialsError> {
    let grasp = grasp_of(rig)?;
    if grasp.object(object).is_none() {
        return Err(invalid(format!(
            "--object: the rig file's [grasp] has no object `{object}`"
        )));
    }
    let plan = TrialPlan {
        objects: vec![object.to_owned()],
        tolerance_n,
        ..TrialPlan::default()
    };
    let rig_plan = RigPlan {
        setup_hash: rig_setup_hash(rig).map_err(|e| TrialsError::Failed(e.to_string()))?,
        grasp: grasp.clone(),
        workspace: rig.workspace.clone(),
    };
    let mut all =
        rig_calibrations(store, &plan, &rig_plan, model, &sha256_hex(model_bytes)).await?;
    all.remove(object)
        .ok_or_else(|| TrialsError::Failed(format!("no calibration of `{object}`")))
}

/// A new rig session of `plan` with `model`, stored before any trial runs, once every
/// object is known to the rig file and has a stored calibration. With no objects in
/// the plan, every object of the rig's `[grasp]`.
///
/// # Errors
/// No `[grasp]`, an unknown object, a missing calibration, bad settings, the store.
pub async fn start_rig_session(
    store: &Store,
    model: &str,
    seed: u64,
    plan: TrialPlan,
    rig: &RigConfig,
) -> Result<RigSession, TrialsError> {
    let mut plan = plan.checked()?;
    let grasp = grasp_of(rig)?;
    if plan.objects.is_empty() {
        plan.objects = grasp.objects.iter().map(|o| o.name.clone()).collect();
    }
    for name in &plan.objects {
        if grasp.object(name).is_none() {
            return Err(invalid(format!(
                "--objects: the rig file's [grasp] has no object `{name}` (it has: {})",
                grasp
                    .objects
                    .iter()
                    .map(|o| o.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    let setup_hash = rig_setup_hash(rig).map_err(|e| TrialsError::Failed(e.to_string()))?;
    plan.rig = Some(RigPlan {
        setup_hash,
        grasp: grasp.clone(),
        workspace: rig.workspace.clone(),
    });
    let model_bytes = crate::models::force_artifact(store, model).await?;
    let model_sha256 = sha256_hex(&model_bytes);
    let rig_plan = plan.rig.as_ref().ok_or_else(|| invalid("no rig".into()))?;
    let calibrations = rig_calibrations(store, &plan, rig_plan, model, &model_sha256).await?;
    let config_json = serde_json::to_string(&plan)
        .map_err(|e| TrialsError::Failed(format!("cannot encode the settings: {e}")))?;
    let id = store
        .create_grasp_session(model, &model_sha256, seed, "[]", &config_json)
        .await?;
    Ok(RigSession {
        id,
        model: model.to_owned(),
        model_sha256,
        seed,
        plan,
        model_bytes,
        calibrations,
    })
}

/// Stored rig session `id`, on its stored settings and poses, with `rig`'s devices:
/// the rig's gripper and cameras must be the session's (its calibrations' key), and
/// its `[grasp]` and workspace unchanged (the same poses, or a new session).
///
/// # Errors
/// No such session, not a rig session, another rig, another or changed model, the store.
pub async fn resume_rig_session(
    store: &Store,
    id: i64,
    model: Option<&str>,
    rig: &RigConfig,
) -> Result<RigSession, TrialsError> {
    let (s, plan) = super::stored_session(store, id, model).await?;
    let Some(stored) = plan.rig.as_ref() else {
        return Err(invalid(format!(
            "--resume {id}: session {id} ran on the simulator: resume it without --rig"
        )));
    };
    let now = rig_setup_hash(rig).map_err(|e| TrialsError::Failed(e.to_string()))?;
    if now != stored.setup_hash {
        return Err(invalid(format!(
            "--rig: session {id} ran on another gripper or finger camera (setup {} then, {} now); start a new session",
            &stored.setup_hash[..12.min(stored.setup_hash.len())],
            &now[..12]
        )));
    }
    if rig.grasp.as_ref() != Some(&stored.grasp) || rig.workspace != stored.workspace {
        return Err(invalid(format!(
            "--rig: the rig file's [grasp] or [workspace] changed since session {id} started: its trials must run on the same poses; start a new session"
        )));
    }
    let (model_bytes, model_sha256) = super::unchanged_model(store, &s).await?;
    let calibrations = rig_calibrations(store, &plan, stored, &s.model, &model_sha256).await?;
    Ok(RigSession {
        id,
        model: s.model,
        model_sha256,
        seed: s.seed,
        plan,
        model_bytes,
        calibrations,
    })
}

/// Runs `todo` (from [`RigSession::progress`]) on the rig's devices, each trial stored
/// as it ends. `stop` counts stop requests: at 1 the run ends after the trial in hand
/// (stored, set down); at 2 it ends at once through the safe exit with
/// [`TrialsError::Interrupted`] (the trial in hand not stored). The gripper's ends are
/// calibrated first, at the safe pose. Every exit path ends safe (see the module).
///
/// # Errors
/// A device, the model, the store, the operator's input closing, `done`, a stop at
/// once; a safe exit that could not finish is added to the message.
pub async fn run_rig_trials(
    store: &Store,
    session: &RigSession,
    devices: &mut RigTrialDevices,
    operator: &mut Operator,
    todo: &[Planned],
    stop: &tokio::sync::watch::Receiver<u32>,
    done: &mut dyn FnMut(&TrialDone) -> Result<(), TrialsError>,
) -> Result<RunEnd, TrialsError> {
    let rig = session.rig()?.clone();
    let mut moves = Moves::for_setup(&rig.grasp);
    let mut holding = Holding::Clear;
    let ran = run_inner(
        store,
        session,
        &rig,
        devices,
        operator,
        todo,
        stop,
        done,
        &mut holding,
        &mut moves,
    )
    .await;
    exit_safe(
        ran,
        devices,
        &mut holding,
        &mut moves,
        &rig.grasp.safe_pose,
        operator.output.as_mut(),
    )
    .await
}

/// The opening's count on a calibrated stroke.
fn count_for_opening(stroke: &Stroke, opening_mm: f64) -> u8 {
    let counts = (opening_mm / stroke.mm_per_count.max(1e-6)).round();
    stroke.clamp(i64::from(stroke.closed_count) - counts as i64)
}

#[allow(clippy::too_many_arguments)] // the run's parts, threaded once
async fn run_inner(
    store: &Store,
    session: &RigSession,
    rig: &RigPlan,
    devices: &mut RigTrialDevices,
    operator: &mut Operator,
    todo: &[Planned],
    stop: &tokio::sync::watch::Receiver<u32>,
    done: &mut dyn FnMut(&TrialDone) -> Result<(), TrialsError>,
    holding: &mut Holding,
    moves: &mut Moves,
) -> Result<RunEnd, TrialsError> {
    let plan = &session.plan;
    let mut predictor = Predictor::from_bytes(&session.model_bytes)?;
    let projection = crate::grasp::sim::projection()?;
    // An activated Hand-E faults (0x09) after 1 s without a command, and the move to
    // the safe pose can take longer on a robot: keep its standing request (what it
    // already echoes, so nothing moves) alive meanwhile. Found against franka-sim.
    if moves.hold.is_none()
        && let Ok(s) = devices.gripper.status().await
        && s.activated
    {
        moves.hold = Some(GripperCommand {
            position: s.requested_position,
            ..moves.open
        });
    }
    or_stop(
        stop,
        arm_to(devices, moves, &rig.grasp.safe_pose, moves.speed_m_s),
    )
    .await??;
    writeln!(
        operator.output,
        "calibrating the gripper's ends at the safe pose: nothing may be between the fingers"
    )
    .map_err(|e| TrialsError::Failed(format!("cannot write output: {e}")))?;
    let ends: EndCalibration = or_stop(
        stop,
        calibrate_ends(
            devices.gripper.as_mut(),
            devices.clock.as_ref(),
            &CalibrationConfig::default(),
        ),
    )
    .await??;
    let stroke = ends.stroke;
    moves.open.position = stroke.open_count;
    moves.hold = Some(moves.open);
    for (ran, p) in todo.iter().enumerate() {
        if *stop.borrow() >= 1 {
            return Ok(RunEnd::Stopped { ran });
        }
        let t0 = Instant::now();
        let object: &GraspObjectSetup = rig.grasp.object(&p.key.object).ok_or_else(|| {
            TrialsError::Failed(format!(
                "object `{}` is not in the rig's [grasp]",
                p.key.object
            ))
        })?;
        let setup = session.calibrations.get(&p.key.object).ok_or_else(|| {
            TrialsError::Failed(format!("no calibration of `{}` was found", p.key.object))
        })?;
        let offset_m = perturbation_m(
            session.seed,
            &p.key.object,
            u64::from(p.key.trial),
            p.sigma_m,
        );
        let pose = object.base_from_grasp.compose(&ArmPose {
            translation_m: offset_m,
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
        });
        let lift_m = object.lift_mm / 1000.0;
        let above = raised(&pose, moves.approach_m);
        let top = raised(&pose, lift_m);
        let mut row = GraspTrialRow {
            key: p.key.clone(),
            medium: medium_name(rig.grasp.medium).to_owned(),
            sigma_m: p.sigma_m,
            offset_m,
            commanded_width_m: 0.0,
            final_width_m: 0.0,
            peak_estimate_n: None,
            peak_true_n: None,
            past_touch_mm: None,
            success: false,
            reason: None,
            detail: None,
            confirmed_after_s: None,
            wall_s: 0.0,
        };
        let outside = [("grasp", &pose), ("approach", &above), ("lift", &top)]
            .into_iter()
            .find(|(_, q)| !rig.workspace.contains_arm(q));
        if let Some((what, q)) = outside {
            // Nothing moves: the trial is recorded as refused.
            row.reason = Some(FailReason::Refused.as_str().into());
            row.detail = Some(format!(
                "the perturbed {what} pose {:?} m lies outside workspace.reach_in_base_m: nothing moved",
                q.translation_m
            ));
            row.wall_s = t0.elapsed().as_secs_f64();
            store
                .append_grasp_trial(session.id, &row, &empty_trace())
                .await?;
            done(&TrialDone {
                timing: TrialTiming {
                    medium: rig.grasp.medium,
                    mode: p.mode,
                    wall_s: row.wall_s,
                    cycles: 0,
                },
                row,
            })?;
            continue;
        }
        // The fingers open, the object set in place while the Hand-E is kept alive.
        or_stop(stop, open_fingers(devices, moves)).await??;
        let question = format!(
            "trial {}/{}: `{}` {} #{}: set the object in its place, clear of the fingers, then press Enter",
            ran + 1,
            todo.len(),
            p.key.object,
            p.key.mode,
            p.key.trial
        );
        // A stop request while nothing moves ends the run before this trial.
        let asked = until_stop(
            stop,
            1,
            operator.input.ask(
                &question,
                operator.output.as_mut(),
                devices.gripper.as_mut(),
                moves.open,
            ),
        )
        .await;
        match asked {
            None => return Ok(RunEnd::Stopped { ran }),
            Some(answer) => {
                answer?;
            }
        }
        // Down to the perturbed grasp pose, the last stretch slowly.
        or_stop(stop, arm_to(devices, moves, &above, moves.speed_m_s)).await??;
        *holding = Holding::AtObject;
        or_stop(stop, arm_to(devices, moves, &pose, moves.slow())).await??;

        let gain = plan.gain_over_lambda * setup.calibration.lambda_max().max(0.05);
        let squeeze = setup.calibration.squeeze()?;
        let mut controller = ControllerConfig::new(projection).with_squeeze(squeeze.clone());
        controller.stepper.gain_n_per_mm = gain;
        controller.stepper.tolerance_n = setup.tolerance_n;
        controller.stepper.stroke = stroke;
        // The pre-grasp opening from the calibration: the margin short of first touch.
        let margin_counts =
            (plan.pregrasp_margin_mm / stroke.mm_per_count.max(1e-6)).round() as i64;
        let trial = TrialConfig {
            mode: p.mode,
            grasp_position: count_for_opening(&stroke, object.open_width_mm),
            pregrasp_position: stroke.clamp(i64::from(setup.calibration.touch()) - margin_counts),
            target_n: plan.target_n,
            confirm: Duration::from_secs_f64(plan.confirm_s),
            dither_n: setup.count_n,
            close_timeout: Duration::from_secs_f64(plan.close_timeout_s),
            move_timeout: Duration::from_secs(5),
            lift: LiftPlan {
                height_m: lift_m,
                speed_m_s: moves.speed_m_s,
                accel_m_s2: plan.lift_accel_m_s2,
            },
            hold: Duration::from_secs_f64(plan.hold_s),
        };
        let mut lift = ArmLift::new(devices.arm.clone(), pose, rig.workspace.clone());
        let mut judge = RigJudge {
            min_force_n: plan.target_n / 5.0,
            closed_count: stroke.closed_count,
            closed_margin: 3,
        };
        let ran_trial = or_stop(
            stop,
            run_trial(
                TrialDevices {
                    gripper: devices.gripper.as_mut(),
                    camera: devices.camera.as_mut(),
                    estimator: &mut predictor,
                    truth: NoTruth,
                    lift: &mut lift,
                    judge: &mut judge,
                    clock: Arc::clone(&devices.clock),
                },
                controller,
                &trial,
            ),
        )
        .await;
        if lift.started() {
            *holding = Holding::InAir {
                place: object.place_pose(),
                height_m: lift_m,
            };
        }
        let result = match ran_trial {
            Ok(r) => r?,
            Err(e) => {
                lift.abort();
                return Err(e);
            }
        };
        // A device error ended the trial (run_trial keeps its message): on a rig that is
        // a device fault, whatever the error (a link that times out included).
        let mut verdict = if result.detail.is_some() {
            Verdict::Failed(FailReason::DeviceFault)
        } else {
            result.verdict
        };
        let mut detail = result.detail.clone();
        if let Some(Err(e)) = lift.finish().await {
            verdict = Verdict::Failed(FailReason::DeviceFault);
            detail = Some(format!("the arm's lift failed: {e}"));
        }
        let hold = GripperCommand {
            position: result.commanded_position,
            ..moves.open
        };
        moves.hold = Some(hold);
        if operator.confirm_verdicts && verdict != Verdict::Failed(FailReason::DeviceFault) {
            verdict = or_stop(
                stop,
                operator.input.confirm(
                    verdict,
                    operator.output.as_mut(),
                    devices.gripper.as_mut(),
                    hold,
                ),
            )
            .await??;
        }
        row.commanded_width_m = stroke_opening_m(&stroke, result.commanded_position);
        row.final_width_m = stroke_opening_m(&stroke, result.final_position);
        row.peak_estimate_n = result.peak_estimate_n;
        row.past_touch_mm = result.deepest_position().map(|c| squeeze.past_touch_mm(c));
        row.success = verdict.success();
        row.reason = verdict.reason().map(|r| r.as_str().to_owned());
        row.detail = detail.clone();
        row.confirmed_after_s = result.confirmed_after_ns.map(|n| n as f64 * 1e-9);
        row.wall_s = t0.elapsed().as_secs_f64();
        store
            .append_grasp_trial(session.id, &row, &pack_trace(&result))
            .await?;
        let stopped_by_fault = verdict == Verdict::Failed(FailReason::DeviceFault);
        done(&TrialDone {
            timing: TrialTiming {
                medium: rig.grasp.medium,
                mode: p.mode,
                wall_s: row.wall_s,
                cycles: result.trace.len(),
            },
            row,
        })?;
        if stopped_by_fault {
            return Err(TrialsError::Failed(format!(
                "trial `{}` {} #{} ended in a device fault ({}); it is stored, and the session stops: check the devices, then resume with --resume {}",
                p.key.object,
                p.key.mode,
                p.key.trial,
                detail.unwrap_or_default(),
                session.id
            )));
        }
        or_stop(stop, set_down(devices, holding, moves)).await??;
    }
    // The safe exit takes the arm back to the safe pose.
    Ok(RunEnd::Completed)
}

/// The opening at `count` on a calibrated stroke, m.
fn stroke_opening_m(stroke: &Stroke, count: u8) -> f64 {
    f64::from(stroke.closed_count.saturating_sub(count)) * stroke.mm_per_count / 1000.0
}

fn empty_trace() -> GraspTrace {
    GraspTrace {
        t_s: Vec::new(),
        estimate_n: Vec::new(),
        true_n: Vec::new(),
        measured_count: Vec::new(),
        request_count: Vec::new(),
        frames: Vec::new(),
    }
}
