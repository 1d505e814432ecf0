//! Figure 5's twist on a lab's rig (`grasp twist --rig`): the gripper comes down on an
//! object at its grasp pose from the rig file, the force loop holds F_ref, and while
//! someone turns the object about the fingers' axis by hand the wrist loop turns the
//! arm's flange on the model's τz estimate ([`ArmWrist`]: capped steps, the target
//! inside ±`max_yaw_rad`, the start pose checked against the reach box; a missing or
//! non-finite τz never moves it). Run it with and without the wrist loop to compare
//! the τz the finger feels. The same safe exit as the trials: the object set down
//! where it stands, the fingers open, the arm back at the safe pose.

use std::sync::Arc;
use std::time::Duration;

use softtouch_drivers::GripperCommand;
use softtouch_grasp::{
    ArmWrist, CalibrationConfig, Controller, ControllerConfig, Cycle, ExitAction, NoTruth,
    StopRequest, WristConfig, WristLoop, calibrate_ends,
};
use softtouch_schemas::rig::{GraspSetup, WorkspaceBounds, raised};
use softtouch_trainer::Predictor;

use super::moves::{Holding, Moves, arm_to, exit_safe, open_fingers};
use super::{Operator, RigTrialDevices};
use crate::grasp::trials::run::ObjectSetup;
use crate::grasp::trials::{TrialsError, invalid};

/// What a twist on the rig runs.
#[derive(Debug, Clone, PartialEq)]
pub struct RigTwistSettings {
    /// The object (a `[[grasp.objects]]` name).
    pub object: String,
    /// The grip force held, N.
    pub target_n: f64,
    /// How long the grip is held (the object turned meanwhile), s.
    pub duration_s: f64,
    /// K as a multiple of the calibrated Λ_max.
    pub gain_over_lambda: f64,
    /// The wrist loop (`None`: off, the run to compare with).
    pub wrist: Option<WristConfig>,
    /// Largest turn of one wrist move, rad.
    pub wrist_step_rad: f64,
    /// The pre-grasp opening: this many mm short of the calibrated first touch.
    pub pregrasp_margin_mm: f64,
}

/// What the twist did.
#[derive(Debug, Clone)]
pub struct RigTwist {
    /// Every cycle (τz estimate and wrist target included).
    pub cycles: Vec<Cycle>,
    /// The stop request that ended it early, by name.
    pub stopped: Option<&'static str>,
}

/// Runs the twist on the rig's devices (see the module), asking the operator to set
/// the object in place first (the Hand-E kept alive meanwhile).
///
/// # Errors
/// An unknown object, bad settings, a device, the model, the operator's input
/// closing; a safe exit that could not finish is added to the message.
#[allow(clippy::too_many_arguments)] // the rig's parts, as the trials take them
pub async fn twist_on_rig(
    setup: &GraspSetup,
    workspace: &WorkspaceBounds,
    calibration: &ObjectSetup,
    devices: &mut RigTrialDevices,
    operator: &mut Operator,
    predictor: Predictor,
    settings: &RigTwistSettings,
    stop: StopRequest,
) -> Result<RigTwist, TrialsError> {
    let object = setup.object(&settings.object).ok_or_else(|| {
        invalid(format!(
            "--object: the rig file's [grasp] has no object `{}`",
            settings.object
        ))
    })?;
    if !(settings.duration_s.is_finite() && settings.duration_s > 0.0) {
        return Err(invalid(format!(
            "--duration-s {}: expected a time above 0 s",
            settings.duration_s
        )));
    }
    let wrist_loop = settings
        .wrist
        .map(WristLoop::new)
        .transpose()
        .map_err(|e| invalid(format!("the wrist loop: {e}")))?;
    let mut moves = Moves::for_setup(setup);
    let mut holding = Holding::Clear;
    let ran = async {
        arm_to(devices, &moves, &setup.safe_pose, moves.speed_m_s).await?;
        let ends = calibrate_ends(
            devices.gripper.as_mut(),
            devices.clock.as_ref(),
            &CalibrationConfig::default(),
        )
        .await?;
        let stroke = ends.stroke;
        moves.open.position = stroke.open_count;
        open_fingers(devices, &mut moves).await?;
        let question = format!(
            "twist: set `{}` in its place, clear of the fingers, then press Enter; once the fingers hold it, turn it about the fingers' axis by hand",
            object.name
        );
        // A stop request while the question waits ends the twist before anything moves.
        let mut stop_rx = stop.clone();
        let asked = tokio::select! {
            answer = operator.input.ask(
                &question,
                operator.output.as_mut(),
                devices.gripper.as_mut(),
                moves.open,
            ) => Some(answer),
            _ = stop_rx.wait_for(Option::is_some) => None,
        };
        match asked {
            Some(answer) => {
                answer?;
            }
            None => {
                return Ok(RigTwist {
                    cycles: Vec::new(),
                    stopped: *stop.borrow(),
                });
            }
        }
        let pose = object.base_from_grasp;
        arm_to(
            devices,
            &moves,
            &raised(&pose, moves.approach_m),
            moves.speed_m_s,
        )
        .await?;
        holding = Holding::AtObject;
        arm_to(devices, &moves, &pose, moves.slow()).await?;

        let mut config = ControllerConfig::new(crate::grasp::sim::projection()?)
            .with_squeeze(calibration.calibration.squeeze()?);
        config.stepper.gain_n_per_mm =
            settings.gain_over_lambda * calibration.calibration.lambda_max().max(0.05);
        config.stepper.tolerance_n = calibration.tolerance_n;
        config.stepper.stroke = stroke;
        config.on_exit = ExitAction::Hold;
        let margin = (settings.pregrasp_margin_mm / stroke.mm_per_count.max(1e-6)).round() as i64;
        let pregrasp = stroke.clamp(i64::from(calibration.calibration.touch()) - margin);
        let mut ctl = Controller::new(
            devices.gripper.as_mut(),
            devices.camera.as_mut(),
            predictor,
            NoTruth,
            Arc::clone(&devices.clock),
            config,
        )?
        .with_stop(stop);
        if let (Some(l), Some(w)) = (wrist_loop, settings.wrist) {
            let wrist = ArmWrist::start(
                Arc::clone(&devices.arm),
                pose,
                workspace,
                moves.speed_m_s,
                settings.wrist_step_rad,
                w.max_yaw_rad,
            )?;
            ctl = ctl.with_wrist(Box::new(wrist), l);
        }
        ctl.approach(pregrasp, Duration::from_secs(5)).await?;
        let (cycles, stopped) = ctl
            .follow_until_stopped(&[(
                settings.target_n,
                Duration::from_secs_f64(settings.duration_s),
            )])
            .await?;
        // The wrist's task ends with the controller; the gripper keeps its last request.
        drop(ctl);
        if let Some(last) = cycles.last() {
            moves.hold = Some(GripperCommand {
                position: last.position_request,
                ..moves.open
            });
        }
        Ok::<_, TrialsError>(RigTwist { cycles, stopped })
    }
    .await;
    exit_safe(
        ran,
        devices,
        &mut holding,
        &mut moves,
        &setup.safe_pose,
        operator.output.as_mut(),
    )
    .await
}

/// What the twist without, then with the wrist loop gave on a rig: the cycles as CSV
/// (`wrist_loop,t_s,estimate_n,torque_z_nmm,wrist_target_deg`) and a line per run.
#[derive(Debug, Clone)]
pub struct RigTwistPair {
    /// Every cycle of both runs.
    pub csv: String,
    /// "wrist loop on: estimated τz RMS … N·mm", one per run that ran.
    pub summary: Vec<String>,
}

/// The twist on the rig, without then with the wrist loop (`settings.wrist` is the
/// loop of the second run), a table row printed after each; a stop request skips the
/// runs after it.
///
/// # Errors
/// As [`twist_on_rig`]; the writer's.
#[allow(clippy::too_many_arguments)] // the rig's parts, as the trials take them
pub async fn twist_without_then_with_wrist(
    setup: &GraspSetup,
    workspace: &WorkspaceBounds,
    calibration: &ObjectSetup,
    devices: &mut RigTrialDevices,
    operator: &mut Operator,
    model: &[u8],
    settings: &RigTwistSettings,
    stop: impl Fn() -> StopRequest,
    out: &mut dyn std::io::Write,
) -> Result<RigTwistPair, TrialsError> {
    let written = |e: std::io::Error| TrialsError::Failed(format!("cannot write output: {e}"));
    let mut csv = String::from("wrist_loop,t_s,estimate_n,torque_z_nmm,wrist_target_deg\n");
    let mut summary = Vec::new();
    writeln!(
        out,
        "{:>11} {:>8} {:>13} {:>13}",
        "wrist loop", "cycles", "τz RMS N·mm", "wrist max °"
    )
    .map_err(written)?;
    for with_wrist in [false, true] {
        let settings = RigTwistSettings {
            wrist: settings.wrist.filter(|_| with_wrist),
            ..settings.clone()
        };
        let predictor = Predictor::from_bytes(model)?;
        let run = twist_on_rig(
            setup,
            workspace,
            calibration,
            devices,
            operator,
            predictor,
            &settings,
            stop(),
        )
        .await?;
        let on_off = if with_wrist { "on" } else { "off" };
        let t0 = run.cycles.first().map_or(0, |cy| cy.t.0);
        let tz: Vec<f64> = run.cycles.iter().filter_map(|cy| cy.torque_z_nm).collect();
        let rms = if tz.is_empty() {
            f64::NAN
        } else {
            (tz.iter().map(|t| (t * 1000.0).powi(2)).sum::<f64>() / tz.len() as f64).sqrt()
        };
        let wrist_max = run
            .cycles
            .iter()
            .filter_map(|cy| cy.wrist_target_rad)
            .fold(0.0_f64, |m, y| m.max(y.abs().to_degrees()));
        for cy in &run.cycles {
            let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v}"));
            csv.push_str(&format!(
                "{on_off},{},{},{},{}\n",
                cy.t.0.saturating_sub(t0) as f64 * 1e-9,
                opt(cy.estimate_n),
                opt(cy.torque_z_nm.map(|t| t * 1000.0)),
                opt(cy.wrist_target_rad.map(f64::to_degrees))
            ));
        }
        let squeeze = calibration.calibration.squeeze()?;
        let grip = crate::grasp::soft::grip_words(
            &run.cycles,
            (squeeze.touch_count, squeeze.mm_per_count),
        );
        summary.push(format!(
            "wrist loop {on_off}: estimated τz RMS {rms:.3} N·mm, {grip}"
        ));
        writeln!(
            out,
            "{on_off:>11} {:>8} {rms:>13.3} {wrist_max:>13.2}",
            run.cycles.len()
        )
        .map_err(written)?;
        if let Some(name) = run.stopped {
            writeln!(out, "stopped by {name}: the runs after it are skipped").map_err(written)?;
            break;
        }
    }
    Ok(RigTwistPair { csv, summary })
}
