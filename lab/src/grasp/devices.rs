//! The devices of a grasp on a real rig, built from the rig config: a Robotiq Hand-E
//! over Modbus RTU and the camera of each sensorised finger (`camera`, and
//! `second_camera` when the rig has two), behind the same [`Gripper`] and [`Camera`]
//! traits as the simulated soft grasp, so the force loop is one code path. Before a
//! loop the gripper's ends are calibrated ([`softtouch_grasp::calibrate_ends`]).

use std::sync::Arc;

use softtouch_collector::devices::SelectError;
use softtouch_drivers::open::{real_camera, real_gripper};
use std::time::Duration;

use softtouch_drivers::{Camera, Clock, DeviceError, Gripper, TokioClock};
use softtouch_grasp::{
    CalibrationConfig, Controller, ControllerConfig, Cycle, EndCalibration, GraspError, NoTruth,
    Projection, StopRequest, calibrate_ends,
};
use softtouch_schemas::RigConfig;
use softtouch_schemas::rig::{CameraDevice, GripperDevice};
use softtouch_trainer::Predictor;

/// A real gripper and its finger cameras.
pub struct GraspRig {
    /// The Hand-E.
    pub gripper: Box<dyn Gripper>,
    /// Finger 0's camera (`camera` in the rig).
    pub camera: Box<dyn Camera>,
    /// Finger 1's camera (`second_camera`), when the rig has a second sensorised finger.
    pub second_camera: Option<Box<dyn Camera>>,
}

impl std::fmt::Debug for GraspRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GraspRig")
            .field("second_camera", &self.second_camera.is_some())
            .finish_non_exhaustive()
    }
}

/// Whether the rig names a real gripper (then a grasp runs on real devices).
#[must_use]
pub fn has_real_gripper(rig: &RigConfig) -> bool {
    matches!(rig.gripper, GripperDevice::HandE { .. })
}

fn refuse(device: &'static str, message: String) -> SelectError {
    SelectError::Device {
        device,
        source: DeviceError::InvalidCommand {
            device: device.into(),
            message,
        },
    }
}

/// Opens the Hand-E and the finger cameras the rig names. A real gripper needs real
/// finger cameras (`driver = "v4l"`): a simulated camera would show a finger that is
/// not the one being squeezed. The gripper is opened first and its status read (a
/// read moves nothing), so a lab learns whether the Modbus link answers before a
/// camera is tried; nothing moves until every device has opened.
///
/// # Errors
/// The rig's gripper is simulated, a camera is simulated, the gripper does not
/// answer, or a device cannot be opened.
pub async fn real_grasp_devices(
    rig: &RigConfig,
    clock: Arc<dyn Clock>,
) -> Result<GraspRig, SelectError> {
    if !has_real_gripper(rig) {
        return Err(refuse(
            "gripper",
            "the rig's gripper is simulated (driver = \"sim\"): expected driver = \"hand-e\" for a real grasp".into(),
        ));
    }
    for (field, device) in [
        ("camera", Some(&rig.camera)),
        ("second_camera", rig.second_camera.as_ref()),
    ] {
        if let Some(CameraDevice::Sim { .. }) = device {
            return Err(refuse(
                field,
                format!(
                    "a real Hand-E needs the finger's real camera: expected {field}.driver = \"v4l\" with a device"
                ),
            ));
        }
    }
    let open_camera = |d: CameraDevice, name: &'static str| {
        let clock = clock.clone();
        async move {
            real_camera(&d, clock)
                .await
                .map_err(|source| SelectError::Device {
                    device: name,
                    source,
                })?
                .ok_or_else(|| refuse(name, "expected a real camera".into()))
        }
    };
    let as_gripper = |source| SelectError::Device {
        device: "gripper",
        source,
    };
    let mut gripper = real_gripper(&rig.gripper, clock.clone())
        .await
        .map_err(as_gripper)?
        .ok_or_else(|| refuse("gripper", "expected a real gripper".into()))?;
    gripper.status().await.map_err(as_gripper)?;
    let camera = open_camera(rig.camera.clone(), "camera").await?;
    let second_camera = match &rig.second_camera {
        Some(d) => Some(open_camera(d.clone(), "second_camera").await?),
        None => None,
    };
    Ok(GraspRig {
        gripper,
        camera,
        second_camera,
    })
}

/// Calibrates the ends of the rig's gripper (nothing between the fingers): the
/// stroke the force loop is clamped to.
///
/// # Errors
/// A fault, a gripper that does not move, or a contact while closing.
pub async fn calibrate(
    rig: &mut GraspRig,
    clock: &dyn Clock,
) -> Result<EndCalibration, GraspError> {
    calibrate_ends(rig.gripper.as_mut(), clock, &CalibrationConfig::default()).await
}

/// What a force-following run on real devices did.
#[derive(Debug)]
pub struct RigFollow {
    /// The ends found before the loop.
    pub calibration: EndCalibration,
    /// Every cycle.
    pub cycles: Vec<Cycle>,
    /// The stop request that ended it early, by name.
    pub stopped: Option<&'static str>,
}

/// Why a run on real devices failed.
#[derive(Debug, thiserror::Error)]
pub enum RigFollowError {
    /// A device could not be opened.
    #[error(transparent)]
    Open(#[from] SelectError),
    /// Calibration or the loop failed (the gripper was left open).
    #[error(transparent)]
    Grasp(#[from] GraspError),
}

/// `grasp follow` on the rig's real Hand-E and finger cameras: open the devices,
/// calibrate the ends (nothing between the fingers), then hold each target from the
/// open end with the fingers' estimate closing the loop (the mean of both when the
/// caller passes `second_projection` for the rig's `second_camera`), on the wall clock. There is no
/// simulator to measure Λ, so the gain is the caller's. The gripper opens at the end
/// (and on every error, [`softtouch_grasp::ExitAction::Open`]), and also when `stop`
/// holds a request (checked every cycle): the cycles run so far then come back with
/// its name. Settings and targets are checked before any
/// device is opened.
///
/// # Errors
/// A device that cannot be opened, a failed calibration, bad settings, an unreachable
/// target, a device error during the loop, or a stop request.
pub async fn follow_on_rig(
    rig: &RigConfig,
    predictor: Predictor,
    mut config: ControllerConfig,
    second_projection: Option<Projection>,
    targets: &[(f64, Duration)],
    stop: StopRequest,
) -> Result<RigFollow, RigFollowError> {
    config.check(targets)?;
    let clock = TokioClock::new();
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut devices = real_grasp_devices(rig, shared.clone()).await?;
    let calibration = calibrate(&mut devices, &clock).await?;
    config.stepper.stroke = calibration.stroke;
    let mut controller = Controller::new(
        devices.gripper,
        devices.camera,
        predictor,
        NoTruth,
        shared,
        config,
    )?
    .with_stop(stop);
    // The second finger only when asked for (`--fingers 2`), even if the rig has one.
    if let (Some(second), Some(projection)) = (devices.second_camera, second_projection) {
        controller = controller.with_second_finger(second, projection);
    }
    let (cycles, stopped) = controller.follow_until_stopped(targets).await?;
    Ok(RigFollow {
        calibration,
        cycles,
        stopped,
    })
}

/// A stiffness calibration on the rig: open the devices, calibrate the ends (nothing
/// between the fingers), then keep the Hand-E alive (the fingers held open, a command
/// every 200 ms, under its 1 s watchdog) until `ready` says the reference object is in
/// place, then close on it one count at a time ([`softtouch_grasp::calibrate_stiffness`]).
/// The fingers end open.
///
/// # Errors
/// A device that cannot be opened, a failed end calibration, `ready`'s error (the
/// operator gave up), a fault, or a closing that finds no touch.
pub async fn stiffness_on_rig(
    rig: &RigConfig,
    mut predictor: Predictor,
    projection: Projection,
    top_n: f64,
    ready: impl std::future::Future<Output = Result<(), String>>,
) -> Result<(EndCalibration, softtouch_grasp::StiffnessCalibration), RigFollowError> {
    let clock = TokioClock::new();
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut devices = real_grasp_devices(rig, shared.clone()).await?;
    let ends = calibrate(&mut devices, &clock).await?;
    let open = softtouch_drivers::GripperCommand {
        position: ends.stroke.open_count,
        speed: 64,
        force: 20,
    };
    tokio::pin!(ready);
    loop {
        tokio::select! {
            r = &mut ready => {
                r.map_err(GraspError::Interrupted)?;
                break;
            }
            () = tokio::time::sleep(Duration::from_millis(200)) => {
                devices.gripper.command_and_status(open).await.map_err(GraspError::Device)?;
            }
        }
    }
    let config = softtouch_grasp::StiffnessConfig {
        start_count: ends.stroke.open_count,
        top_n,
        ..softtouch_grasp::StiffnessConfig::default()
    };
    let cal = softtouch_grasp::calibrate_stiffness(
        devices.gripper.as_mut(),
        devices.camera.as_mut(),
        &mut predictor,
        &projection,
        &ends.stroke,
        shared.as_ref(),
        &config,
    )
    .await?;
    Ok((ends, cal))
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_drivers::TokioClock;
    use softtouch_schemas::defaults;

    #[tokio::test]
    async fn a_simulated_gripper_or_camera_is_refused_with_the_field_to_change() {
        let clock: Arc<dyn Clock> = Arc::new(TokioClock::new());
        let rig = defaults::rig();
        let e = real_grasp_devices(&rig, clock.clone())
            .await
            .expect_err("sim gripper")
            .to_string();
        assert!(e.contains("driver = \"hand-e\""), "{e}");
        let mut rig = defaults::rig();
        rig.gripper = GripperDevice::HandE {
            port: "/dev/null-no-such-port".into(),
            slave_id: 9,
        };
        let e = real_grasp_devices(&rig, clock.clone())
            .await
            .expect_err("sim camera")
            .to_string();
        assert!(e.contains("camera.driver = \"v4l\""), "{e}");
    }
}
