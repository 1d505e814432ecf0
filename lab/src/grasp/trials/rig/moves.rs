//! The rig's moves and its safe exit, shared by the trials and the twist: the arm
//! moved with the Hand-E kept alive, the object set down, and the exit that every
//! path takes (the arm stopped; an object in the air set down before the fingers
//! open; a faulted arm leaves the gripper holding; then the safe pose).

use std::future::Future;
use std::sync::Arc;

use softtouch_drivers::{DeviceError, GripperCommand};
use softtouch_grasp::{CalibrationConfig, GraspError, SharedArm, move_to_end};
use softtouch_schemas::ArmPose;
use softtouch_schemas::rig::raised;

use super::RigTrialDevices;
use crate::grasp::trials::TrialsError;

/// Where the object is, for the safe exit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Holding {
    /// Nothing between the fingers that the arm must mind.
    Clear,
    /// The gripper stands at the object on its support (it may have closed on it).
    AtObject,
    /// Lifted `height_m` above the grasp; `place` is where it goes down.
    InAir {
        /// Where it goes down.
        place: ArmPose,
        /// How high above the grasp it hangs, m.
        height_m: f64,
    },
}

/// Runs `future` unless `level` stop requests come first (`None`).
pub(crate) async fn until_stop<T>(
    stop: &tokio::sync::watch::Receiver<u32>,
    level: u32,
    future: impl Future<Output = T>,
) -> Option<T> {
    let mut rx = stop.clone();
    let reached = async move {
        while *rx.borrow_and_update() < level {
            if rx.changed().await.is_err() {
                std::future::pending::<()>().await;
            }
        }
    };
    tokio::select! {
        biased;
        v = future => Some(v),
        () = reached => None,
    }
}

/// Runs `future` unless a second stop request comes first.
pub(crate) async fn or_stop<T>(
    stop: &tokio::sync::watch::Receiver<u32>,
    future: impl Future<Output = T>,
) -> Result<T, TrialsError> {
    until_stop(stop, 2, future)
        .await
        .ok_or(TrialsError::Interrupted)
}

pub(crate) fn device(e: DeviceError) -> TrialsError {
    TrialsError::Grasp(GraspError::Device(e))
}

/// The rig's speed and heights, and what the gripper last heard.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Moves {
    pub(crate) speed_m_s: f64,
    pub(crate) approach_m: f64,
    pub(crate) open: GripperCommand,
    /// The gripper's standing request, re-sent while the arm moves (`None` before
    /// the gripper is activated).
    pub(crate) hold: Option<GripperCommand>,
}

impl Moves {
    /// The rig's speed and approach height; the fingers' open end (count 0) until
    /// the ends are calibrated, and nothing heard yet.
    pub(crate) const fn for_setup(setup: &softtouch_schemas::rig::GraspSetup) -> Self {
        Self {
            speed_m_s: setup.speed_m_s,
            approach_m: setup.approach_height_m,
            open: GripperCommand {
                position: 0,
                speed: 64,
                force: 20,
            },
            hold: None,
        }
    }

    /// The slow speed of a descent onto the object or its place.
    pub(crate) fn slow(&self) -> f64 {
        self.speed_m_s / 4.0
    }
}

/// Moves the arm to `pose`, re-sending the gripper's standing request every
/// [`softtouch_grasp::KEEP_ALIVE`] meanwhile (a move may take longer than the Hand-E's
/// 1 s watchdog). A gripper that fails meanwhile is reported once the arm stands.
pub(crate) async fn arm_to(
    devices: &mut RigTrialDevices,
    moves: &Moves,
    pose: &ArmPose,
    speed_m_s: f64,
) -> Result<(), TrialsError> {
    let arm = Arc::clone(&devices.arm);
    let moving = async move { arm.lock().await.move_to(pose, speed_m_s).await };
    tokio::pin!(moving);
    let mut tick = tokio::time::interval(softtouch_grasp::KEEP_ALIVE);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut gripper_failed = None;
    let moved = loop {
        tokio::select! {
            moved = &mut moving => break moved,
            _ = tick.tick() => {
                if let (Some(hold), None) = (moves.hold, &gripper_failed)
                    && let Err(e) = devices.gripper.command(hold).await
                {
                    gripper_failed = Some(e);
                }
            }
        }
    };
    moved.map_err(device)?;
    gripper_failed.map_or(Ok(()), |e| Err(device(e)))
}

pub(crate) async fn arm_here(arm: &SharedArm) -> Result<ArmPose, TrialsError> {
    Ok(arm
        .lock()
        .await
        .state()
        .await
        .map_err(device)?
        .base_from_finger)
}

/// The fingers open fully, waited for.
pub(crate) async fn open_fingers(
    devices: &mut RigTrialDevices,
    moves: &mut Moves,
) -> Result<(), TrialsError> {
    moves.hold = Some(moves.open);
    let config = CalibrationConfig::default();
    move_to_end(
        devices.gripper.as_mut(),
        devices.clock.as_ref(),
        &config,
        moves.open.position,
    )
    .await?;
    Ok(())
}

/// Sets a held object down (in the air: at its place; on its support: where it
/// stands), opens the fingers and raises the gripper clear.
pub(crate) async fn set_down(
    devices: &mut RigTrialDevices,
    holding: &mut Holding,
    moves: &mut Moves,
) -> Result<(), TrialsError> {
    match *holding {
        Holding::Clear => return Ok(()),
        Holding::InAir { place, height_m } => {
            arm_to(devices, moves, &raised(&place, height_m), moves.speed_m_s).await?;
            arm_to(devices, moves, &place, moves.slow()).await?;
            *holding = Holding::AtObject;
        }
        Holding::AtObject => {}
    }
    open_fingers(devices, moves).await?;
    let here = arm_here(&devices.arm).await?;
    arm_to(
        devices,
        moves,
        &raised(&here, moves.approach_m),
        moves.speed_m_s,
    )
    .await?;
    *holding = Holding::Clear;
    Ok(())
}

/// The safe exit: stop the arm; a faulted arm leaves the gripper holding; otherwise
/// set a held object down, open, and return to the safe pose. Says what it did.
async fn end_safe(
    devices: &mut RigTrialDevices,
    holding: &mut Holding,
    moves: &mut Moves,
    safe_pose: &ArmPose,
) -> (Vec<String>, Option<String>) {
    let mut lines = Vec::new();
    let faulted = {
        let mut arm = devices.arm.lock().await;
        if let Err(e) = arm.stop().await {
            lines.push(format!("safe exit: stopping the arm failed: {e}"));
        }
        arm.state().await.map_or(true, |s| s.faulted)
    };
    if faulted {
        let held = *holding != Holding::Clear;
        if held {
            // The object may hang in the air: open fingers would drop it.
            let hold = match devices.gripper.status().await {
                Ok(s) => devices
                    .gripper
                    .command(GripperCommand {
                        position: s.position,
                        ..moves.open
                    })
                    .await
                    .map_err(|e| e.to_string()),
                Err(e) => Err(e.to_string()),
            };
            let m = format!(
                "safe exit: the arm is faulted (a reflex or a lost link) with the object between the fingers: the gripper holds it where it is ({}); clear the reflex, then take the object out by hand",
                hold.map_or_else(
                    |e| format!("its hold command failed: {e}"),
                    |()| "hold sent".into()
                )
            );
            lines.push(m.clone());
            return (lines, Some(m));
        }
        let m = "safe exit: the arm is faulted; nothing between the fingers; clear the reflex before the next session".to_owned();
        lines.push(m.clone());
        return (lines, Some(m));
    }
    let was = *holding;
    if let Err(e) = set_down(devices, holding, moves).await {
        let m = format!("safe exit: setting the object down and opening failed: {e}");
        lines.push(m.clone());
        // Still try to leave the fingers open with nothing in the air.
        if *holding == Holding::Clear || *holding == Holding::AtObject {
            let _ = open_fingers(devices, moves).await;
        }
        return (lines, Some(m));
    }
    if was != Holding::Clear {
        lines.push("safe exit: the object was set down and the fingers opened".into());
    }
    if let Err(e) = arm_to(devices, moves, safe_pose, moves.speed_m_s).await {
        let m = format!("safe exit: the arm did not reach the safe pose: {e}");
        lines.push(m.clone());
        return (lines, Some(m));
    }
    (lines, None)
}

/// Ends a run through the safe exit ([`end_safe`]), whatever `ran` was: says on
/// `output` what the exit did, and keeps `ran`'s error first, with an exit that
/// could not finish added to its message (a stop at once stays
/// [`TrialsError::Interrupted`]).
///
/// # Errors
/// `ran`'s error, or the safe exit's.
pub(crate) async fn exit_safe<T>(
    ran: Result<T, TrialsError>,
    devices: &mut RigTrialDevices,
    holding: &mut Holding,
    moves: &mut Moves,
    safe_pose: &ArmPose,
    output: &mut (dyn std::io::Write + Send),
) -> Result<T, TrialsError> {
    let (lines, failed) = end_safe(devices, holding, moves, safe_pose).await;
    for l in &lines {
        let _ = writeln!(output, "{l}");
    }
    let _ = output.flush();
    match (ran, failed) {
        (Ok(end), None) => Ok(end),
        (Ok(_), Some(m)) => Err(TrialsError::Failed(m)),
        (Err(TrialsError::Interrupted), _) => Err(TrialsError::Interrupted),
        (Err(e), None) => Err(e),
        (Err(e), Some(m)) => Err(TrialsError::Failed(format!("{e}; then {m}"))),
    }
}
