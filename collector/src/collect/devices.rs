//! The devices of a collection, built from the rig config.

use super::rods::{RodChanger, TerminalOperator};
use crate::devices::SelectError;
use softtouch_drivers::{Arm, Camera, ForceSensor, TokioClock};
use softtouch_schemas::{
    ArmDevice, CameraDevice, ForceSensorDevice, RigConfig, SceneSpec, TimestampNs,
};

/// The devices a collection needs.
pub struct CollectDevices {
    /// The arm.
    pub arm: Box<dyn Arm>,
    /// The force/torque sensor.
    pub force_sensor: Box<dyn ForceSensor>,
    /// The in-finger camera.
    pub camera: Box<dyn Camera>,
    /// Who changes the rod.
    pub rods: Box<dyn RodChanger>,
}

impl std::fmt::Debug for CollectDevices {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollectDevices").finish_non_exhaustive()
    }
}

/// Whether every device that takes part in collection (arm, sensor, camera) is
/// simulated, so the run can use virtual time.
#[must_use]
pub fn all_simulated(rig: &RigConfig) -> bool {
    matches!(rig.arm, ArmDevice::Sim { .. })
        && matches!(rig.force_sensor, ForceSensorDevice::Sim { .. })
        && matches!(rig.camera, CameraDevice::Sim { .. })
}

/// Devices for `rig`, real or simulated per its config, and the clock they read. When
/// [`all_simulated`], tokio's clock is paused first: it stands still while code runs
/// and jumps to the next timer when everything waits, so a simulated run takes no
/// real time waiting.
///
/// # Errors
/// A device that cannot be opened, or a simulator that cannot be built.
///
/// # Panics
/// With a simulated rig, unless called on a current-thread tokio runtime (as
/// [`tokio::time::pause`] needs).
pub async fn build_devices(
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
) -> Result<(CollectDevices, TokioClock), SelectError> {
    build_devices_at(rig, scene, seed, TimestampNs::ZERO).await
}

/// [`build_devices`] on a clock that reads `start` now: a resumed run's clock, which
/// continues the run's device time (see [`super::clock_start`]).
///
/// # Errors
/// As [`build_devices`].
///
/// # Panics
/// As [`build_devices`].
pub async fn build_devices_at(
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
    start: TimestampNs,
) -> Result<(CollectDevices, TokioClock), SelectError> {
    if all_simulated(rig) {
        tokio::time::pause();
    }
    let clock = TokioClock::starting_at(start);
    let devices = crate::devices::build(rig, scene, seed, clock).await?;
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
