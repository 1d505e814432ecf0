//! Opening the real driver of a rig entry: `None` for a simulated entry (the
//! simulator, a crate above this one, builds those), the driver connected otherwise.

use crate::arm::Arm;
use crate::camera::Camera;
use crate::clock::Clock;
use crate::error::DeviceError;
use crate::force::ForceSensor;
use crate::gripper::Gripper;
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use std::net::SocketAddr;
use std::sync::Arc;

/// Resolve `host` or `host:port`; without a port, `default_port`.
pub async fn resolve(address: &str, default_port: u16) -> Result<SocketAddr, DeviceError> {
    let with_port = if address.parse::<SocketAddr>().is_ok()
        || (address
            .rsplit_once(':')
            .is_some_and(|(h, p)| !h.contains(':') && p.parse::<u16>().is_ok()))
    {
        address.to_string()
    } else if address.contains(':') && !address.starts_with('[') {
        format!("[{address}]:{default_port}")
    } else {
        format!("{address}:{default_port}")
    };
    tokio::net::lookup_host(&with_port)
        .await
        .map_err(|e| DeviceError::Link {
            device: address.into(),
            message: format!("cannot resolve {with_port}: {e}"),
        })?
        .next()
        .ok_or_else(|| DeviceError::Link {
            device: address.into(),
            message: format!("{with_port} resolves to nothing"),
        })
}

/// The Net F/T client config for a rig entry. The address is `host` (RDT on 49152,
/// calibration on 49151) or `host:port` (RDT on `port`, calibration on `port - 1`,
/// which is what the simulated server binds by default). Counts per unit come from
/// the config when both are given, else from the sensor's calibration request.
pub async fn netft_config(
    address: &str,
    rate_hz: f64,
    counts_per_force: Option<f64>,
    counts_per_torque: Option<f64>,
) -> Result<crate::netft::NetFtConfig, DeviceError> {
    use crate::netft::{NetFtConfig, Scaling, codec};
    let rdt = resolve(address, codec::RDT_PORT).await?;
    let mut c = NetFtConfig::new(rdt, rate_hz);
    c.scaling = match (counts_per_force, counts_per_torque) {
        (Some(f), Some(t)) => Scaling::Given {
            counts_per_force: f,
            counts_per_torque: t,
        },
        _ => Scaling::CalibrationRequest(SocketAddr::new(rdt.ip(), rdt.port().saturating_sub(1))),
    };
    Ok(c)
}

/// A device's configured latency (validated to `[0, 1]` s with the rig).
fn latency(latency_s: Option<f64>) -> std::time::Duration {
    latency_s
        .filter(|s| s.is_finite() && *s > 0.0)
        .map_or(std::time::Duration::ZERO, |s| {
            std::time::Duration::from_secs_f64(s.min(1.0))
        })
}

/// A real force/torque sensor (`None` for `sim`).
pub async fn real_force_sensor(
    d: &ForceSensorDevice,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn ForceSensor>>, DeviceError> {
    Ok(match d {
        ForceSensorDevice::Sim { .. } => None,
        ForceSensorDevice::NetFt {
            address,
            rate_hz,
            counts_per_force,
            counts_per_torque,
            latency_s,
        } => {
            let mut c =
                netft_config(address, *rate_hz, *counts_per_force, *counts_per_torque).await?;
            c.latency = latency(*latency_s);
            Some(Box::new(
                crate::netft::NetFtClient::connect(c, clock).await?,
            ))
        }
        ForceSensorDevice::AtiSerial {
            port,
            baud,
            counts_per_force,
            counts_per_torque,
            latency_s,
        } => {
            let io = crate::ati_serial::open_port(port, *baud)?;
            let mut c =
                crate::ati_serial::AtiSerialConfig::new(*counts_per_force, *counts_per_torque);
            c.latency = latency(*latency_s);
            Some(Box::new(
                crate::ati_serial::AtiSerial::new(io, c, clock).await?,
            ))
        }
    })
}

/// A real arm (`None` for `sim`).
pub async fn real_arm(
    d: &ArmDevice,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn Arm>>, DeviceError> {
    Ok(match d {
        ArmDevice::Sim { .. } => None,
        d @ ArmDevice::Franka { .. } => {
            let config = crate::franka::FrankaConfig::from_rig(d).ok_or_else(|| {
                DeviceError::InvalidCommand {
                    device: "franka".into(),
                    message: "not a franka table".into(),
                }
            })?;
            Some(Box::new(
                crate::franka::FrankaArm::connect(config, clock).await?,
            ))
        }
    })
}

/// A rig's real arm (`None` for `sim`), with its workspace checked at connect against
/// the robot's joint ranges and velocity limits from the joints it is at
/// ([`crate::franka::reach`]): a workspace it cannot reach is refused before any motion.
pub async fn real_arm_for_rig(
    rig: &softtouch_schemas::RigConfig,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn Arm>>, DeviceError> {
    match crate::franka::FrankaConfig::for_rig(rig) {
        None => real_arm(&rig.arm, clock).await,
        Some(config) => Ok(Some(Box::new(
            crate::franka::FrankaArm::connect(config, clock).await?,
        ))),
    }
}

/// A real camera (`None` for `sim`). Without feature `v4l` a V4L2 camera is refused.
pub async fn real_camera(
    d: &CameraDevice,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn Camera>>, DeviceError> {
    match d {
        CameraDevice::Sim { .. } => Ok(None),
        #[cfg(feature = "v4l")]
        CameraDevice::V4l {
            device,
            latency_s,
            image,
        } => Ok(Some(Box::new(crate::v4l_camera::V4lCamera::open_with(
            device,
            clock,
            latency(*latency_s),
            image.as_ref(),
        )?))),
        #[cfg(not(feature = "v4l"))]
        CameraDevice::V4l { device, .. } => {
            let _ = clock;
            Err(DeviceError::InvalidCommand {
                device: device.clone(),
                message:
                    "this build has no V4L2 support: rebuild softtouch-drivers with feature `v4l`"
                        .into(),
            })
        }
    }
}

/// A real gripper (`None` for `sim`).
pub async fn real_gripper(
    d: &GripperDevice,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn Gripper>>, DeviceError> {
    Ok(match d {
        GripperDevice::Sim {} => None,
        GripperDevice::HandE { port, slave_id } => {
            let io = crate::hande::open_port(port)?;
            let config = crate::hande::HandEConfig {
                slave_id: *slave_id,
                ..Default::default()
            };
            Some(Box::new(crate::hande::HandE::new(io, config, clock)))
        }
    })
}
