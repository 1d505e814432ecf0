//! Building a rig of boxed devices from the rig config: the simulated twin for a
//! device whose driver is `sim`, the real driver otherwise. Real and simulated
//! devices mix (a real sensor on a simulated arm, for instance).

use crate::arm::Arm;
use crate::camera::Camera;
use crate::clock::{Clock, TokioClock};
use crate::error::DeviceError;
use crate::force::ForceSensor;
use crate::gripper::Gripper;
use crate::sim::{SimError, SimHandle, SimRig};
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use softtouch_schemas::{RigConfig, SceneSpec};
use std::net::SocketAddr;
use std::sync::Arc;

/// The devices of a rig.
pub struct Devices {
    /// The arm.
    pub arm: Box<dyn Arm>,
    /// The force/torque sensor.
    pub force_sensor: Box<dyn ForceSensor>,
    /// The camera.
    pub camera: Box<dyn Camera>,
    /// The gripper.
    pub gripper: Box<dyn Gripper>,
    /// The simulated world, when any device is simulated.
    pub sim: Option<SimHandle>,
}

impl std::fmt::Debug for Devices {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Devices")
            .field("sim", &self.sim)
            .finish_non_exhaustive()
    }
}

/// Why a rig could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SelectError {
    /// The simulator could not be built.
    #[error("simulated rig: {0}")]
    Sim(#[from] SimError),
    /// A real device could not be opened.
    #[error("{device}: {source}")]
    Device {
        /// Which device (`arm`, `force_sensor`, `camera`, `gripper`).
        device: &'static str,
        /// What went wrong.
        source: DeviceError,
    },
}

fn dev(device: &'static str) -> impl FnOnce(DeviceError) -> SelectError {
    move |source| SelectError::Device { device, source }
}

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
        ArmDevice::Franka {
            address,
            reflex_force_n,
        } => {
            let config = crate::franka::FrankaConfig {
                address: address.clone(),
                reflex_force_n: *reflex_force_n,
                limits: crate::franka::MotionLimits::default(),
            };
            Some(Box::new(
                crate::franka::FrankaArm::connect(config, clock).await?,
            ))
        }
    })
}

/// A real camera (`None` for `sim`). Without feature `v4l` a V4L2 camera is refused.
pub async fn real_camera(
    d: &CameraDevice,
    clock: Arc<dyn Clock>,
) -> Result<Option<Box<dyn Camera>>, DeviceError> {
    match d {
        CameraDevice::Sim { .. } => Ok(None),
        #[cfg(feature = "v4l")]
        CameraDevice::V4l { device, latency_s } => Ok(Some(Box::new(
            crate::v4l_camera::V4lCamera::open_with_latency(device, clock, latency(*latency_s))?,
        ))),
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

/// The rig config with every real device replaced by a simulated one (so the
/// simulator can be built for the devices that are simulated).
fn all_sim(rig: &RigConfig) -> RigConfig {
    let mut r = rig.clone();
    if let ArmDevice::Franka { reflex_force_n, .. } = r.arm {
        r.arm = ArmDevice::Sim { reflex_force_n };
    }
    match r.force_sensor {
        ForceSensorDevice::Sim { .. } => {}
        ForceSensorDevice::NetFt { rate_hz, .. } => {
            r.force_sensor = ForceSensorDevice::Sim { rate_hz }
        }
        ForceSensorDevice::AtiSerial { .. } => {
            r.force_sensor = ForceSensorDevice::Sim { rate_hz: 1000.0 }
        }
    }
    if let CameraDevice::V4l { .. } = r.camera {
        r.camera = CameraDevice::Sim { fps: 120.0 };
    }
    if let GripperDevice::HandE { .. } = r.gripper {
        r.gripper = GripperDevice::Sim {};
    }
    r
}

fn any_sim(rig: &RigConfig) -> bool {
    matches!(rig.arm, ArmDevice::Sim { .. })
        || matches!(rig.force_sensor, ForceSensorDevice::Sim { .. })
        || matches!(rig.camera, CameraDevice::Sim { .. })
        || matches!(rig.gripper, GripperDevice::Sim {})
}

/// Build every device of `rig`: simulated ones from [`SimRig`] on one world (seeded
/// by `seed`, with `scene`), real ones from their drivers. Every device reads `clock`.
pub async fn build(
    rig: &RigConfig,
    scene: &SceneSpec,
    seed: u64,
    clock: TokioClock,
) -> Result<Devices, SelectError> {
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let arm = real_arm(&rig.arm, shared.clone())
        .await
        .map_err(dev("arm"))?;
    let force_sensor = real_force_sensor(&rig.force_sensor, shared.clone())
        .await
        .map_err(dev("force_sensor"))?;
    let camera = real_camera(&rig.camera, shared.clone())
        .await
        .map_err(dev("camera"))?;
    let gripper = real_gripper(&rig.gripper, shared)
        .await
        .map_err(dev("gripper"))?;
    let sim = if any_sim(rig) {
        Some(SimRig::new(&all_sim(rig), scene, seed, clock)?)
    } else {
        None
    };
    let handle = sim.as_ref().map(|s| s.handle.clone());
    let (sa, sf, sc, sg) = match sim {
        Some(s) => (
            Some(s.arm),
            Some(s.force_sensor),
            Some(s.camera),
            Some(s.gripper),
        ),
        None => (None, None, None, None),
    };
    // A device is either real or simulated; `any_sim` guarantees the simulated one exists.
    let missing = |device: &'static str| SelectError::Device {
        device,
        source: DeviceError::InvalidCommand {
            device: device.into(),
            message: "no driver selected".into(),
        },
    };
    Ok(Devices {
        arm: match arm {
            Some(a) => a,
            None => Box::new(sa.ok_or_else(|| missing("arm"))?),
        },
        force_sensor: match force_sensor {
            Some(f) => f,
            None => Box::new(sf.ok_or_else(|| missing("force_sensor"))?),
        },
        camera: match camera {
            Some(c) => c,
            None => Box::new(sc.ok_or_else(|| missing("camera"))?),
        },
        gripper: match gripper {
            Some(g) => g,
            None => Box::new(sg.ok_or_else(|| missing("gripper"))?),
        },
        sim: handle,
    })
}
