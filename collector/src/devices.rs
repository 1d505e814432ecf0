//! Building a rig of boxed devices from the rig config: the simulated twin for a
//! device whose driver is `sim`, the real driver otherwise. Real and simulated
//! devices mix (a real sensor on a simulated arm, for instance). This is the one
//! place that names both kinds; everything past it takes the drivers' traits.

use softtouch_drivers::open::{real_arm_for_rig, real_camera, real_force_sensor, real_gripper};
use softtouch_drivers::{Arm, Camera, Clock, DeviceError, ForceSensor, Gripper, TokioClock};
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use softtouch_schemas::{RigConfig, SceneSpec};
use softtouch_sim::{SimError, SimHandle, SimRig};
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
    let arm = real_arm_for_rig(rig, shared.clone())
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
    // A real arm among simulated devices: the simulated world follows its measured
    // pose, so the simulated sensor and camera see the finger where the arm put it.
    if let (Some(real), Some(h)) = (&arm, &handle)
        && let Some(feed) = real.pose_feed()
    {
        tokio::spawn(follow_arm(feed, h.clone()));
    }
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

/// Hands each pose a real arm measures to the simulated world, until the arm is gone.
pub async fn follow_arm(mut feed: softtouch_drivers::PoseFeed, sim: SimHandle) {
    loop {
        let latest = *feed.borrow_and_update();
        // The only error is a world poisoned by a panic elsewhere, which every
        // simulated device then reports on its own.
        if let Some((t, pose)) = latest
            && sim.follow_arm(t, pose).is_err()
        {
            return;
        }
        if feed.changed().await.is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_drivers::netft::{NetFtServer, ServerConfig};
    use softtouch_schemas::defaults;

    #[tokio::test(start_paused = true)]
    async fn an_all_simulated_rig_builds_from_the_defaults() {
        let mut d = build(&defaults::rig(), &defaults::scene(), 1, TokioClock::new())
            .await
            .expect("build");
        assert!(d.sim.is_some());
        d.force_sensor.start().await.expect("start");
        let mut out = Vec::new();
        assert!(d.force_sensor.read(&mut out).await.expect("read") > 0);
        d.gripper.activate().await.expect("activate");
    }

    #[tokio::test]
    async fn a_net_ft_entry_connects_to_a_server_at_host_port() {
        let mut cfg = ServerConfig::at(([127, 0, 0, 1], 0).into());
        cfg.calibration_bind = None;
        let sim =
            SimRig::new(&defaults::rig(), &defaults::scene(), 1, TokioClock::new()).expect("sim");
        let server = NetFtServer::bind(sim.force_sensor, cfg)
            .await
            .expect("bind");
        let addr = server.rdt_addr().expect("addr");
        tokio::spawn(server.run(std::future::pending()));
        let mut rig = defaults::rig();
        rig.force_sensor = ForceSensorDevice::NetFt {
            address: addr.to_string(),
            rate_hz: 1000.0,
            counts_per_force: Some(1e6),
            counts_per_torque: Some(1e6),
            latency_s: None,
        };
        let mut d = build(&rig, &defaults::scene(), 1, TokioClock::new())
            .await
            .expect("build");
        d.force_sensor.start().await.expect("start");
        let mut out = Vec::new();
        assert!(d.force_sensor.read(&mut out).await.expect("read") > 0);
        assert_eq!(out[0].rdt_sequence, 1, "readings came over RDT");
    }

    #[tokio::test]
    async fn real_devices_that_are_not_there_fail_with_the_device_named() {
        let mut rig = defaults::rig();
        rig.gripper = GripperDevice::HandE {
            port: "/dev/does-not-exist".into(),
            slave_id: 9,
        };
        let e = build(&rig, &defaults::scene(), 1, TokioClock::new())
            .await
            .expect_err("no port");
        assert!(
            matches!(
                e,
                SelectError::Device {
                    device: "gripper",
                    source: DeviceError::Link { .. }
                }
            ),
            "{e}"
        );
        let mut rig = defaults::rig();
        rig.camera = CameraDevice::V4l {
            device: "/dev/does-not-exist".into(),
            latency_s: None,
            image: None,
        };
        let e = build(&rig, &defaults::scene(), 1, TokioClock::new())
            .await
            .expect_err("no camera");
        assert!(
            matches!(
                e,
                SelectError::Device {
                    device: "camera",
                    ..
                }
            ),
            "{e}"
        );
    }
}
