//! `softtouch rig check`'s checks: every device the rig config names exercised briefly,
//! each with a typed result ([`Measured`] or a [`CheckFailure`] saying what was
//! expected and what happened).
//!
//! Each device is opened and checked on its own, so one dead device fails its row and
//! the others are still checked: the arm's state (pose, fault flag), the force/torque
//! stream (rate over a short window against the configured rate, status words,
//! finite values), a frame from each finger camera (size, format, byte count), and
//! the gripper (activation, a small close and open with the gPR echo, status). A
//! simulated device is the simulator's twin of the real one; with every device
//! simulated the check runs on tokio's paused clock and takes no real time.

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use softtouch_drivers::open::{real_arm_for_rig, real_camera, real_force_sensor, real_gripper};
use softtouch_drivers::{
    Arm, Camera, Clock, DeviceError, ForceSensor, Gripper, GripperCommand, ObjectStatus, TokioClock,
};
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use softtouch_schemas::{FrameFormat, RigConfig};
use softtouch_sim::SimRig;

mod devices;
use devices::*;

/// One device's row.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckRow {
    /// Which device (`arm`, `force_sensor`, `camera`, `second_camera`, `gripper`, or
    /// `simulator` when the simulated twins cannot be built).
    pub device: &'static str,
    /// Its driver.
    pub driver: String,
    /// What was measured, or why it failed.
    pub outcome: Result<Measured, CheckFailure>,
}

impl CheckRow {
    /// Whether the device passed.
    #[must_use]
    pub fn pass(&self) -> bool {
        self.outcome.is_ok()
    }
}

/// Why a device failed its check.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckFailure {
    /// What was expected and what happened.
    #[error("{0}")]
    Failed(String),
    /// The check did not finish in time.
    #[error(
        "expected the check to finish within {:.1} s (--timeout-s); the device did not answer in time",
        .0.as_secs_f64()
    )]
    TimedOut(Duration),
}

/// What a passed check measured, per kind of device.
#[derive(Debug, Clone, PartialEq)]
pub enum Measured {
    /// The arm.
    Arm(ArmCheck),
    /// The force/torque stream.
    ForceSensor(StreamCheck),
    /// A camera.
    Camera(FrameCheck),
    /// The gripper.
    Gripper(GripperCheck),
    /// The host's real-time facts, and whether the rig needs them.
    Host(HostCheck),
}

/// The host, for a real arm's 1 kHz loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostCheck {
    /// What the host offers.
    pub realtime: softtouch_drivers::realtime::HostRealtime,
    /// Why it is not required (no real arm, or `realtime = "ignore"`); `None`: required.
    pub not_required: Option<&'static str>,
}

impl From<HostCheck> for Measured {
    fn from(c: HostCheck) -> Self {
        Self::Host(c)
    }
}

/// The arm's state: a valid pose and no fault.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmCheck {
    /// The finger's position in the base frame, m.
    pub translation_m: [f64; 3],
    /// How far the check moved it up and back, mm.
    pub moved_mm: f64,
    /// The larger distance from target at which the two moves ended, mm.
    pub worst_arrival_mm: f64,
    /// Share of the real-time commands that reached the robot (a Franka's).
    pub command_success_rate: Option<f64>,
    /// The robot's mode at connect, and the recovery run if it was in reflex (a
    /// Franka's).
    pub found_at_connect: Option<String>,
}

/// The force/torque stream over the window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamCheck {
    /// Readings in the window.
    pub readings: usize,
    /// The window's length, s.
    pub elapsed_s: f64,
    /// Readings per second measured.
    pub measured_hz: f64,
    /// The configured rate, Hz.
    pub rate_hz: f64,
    /// Readings the link reports lost.
    pub lost: u64,
    /// Readings with a warning status.
    pub warnings: usize,
    /// Mean Fz, N.
    pub mean_fz_n: f64,
}

/// One frame of a camera.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameCheck {
    /// Its sequence number.
    pub sequence: u64,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Pixel format.
    pub format: FrameFormat,
    /// Bytes of data.
    pub bytes: usize,
    /// Frames the camera reports dropped.
    pub dropped: u64,
    /// The mode and image settings the device holds (a real camera's).
    pub settings: Option<String>,
}

/// The gripper's small move and back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GripperCheck {
    /// Where it started, counts.
    pub start: u8,
    /// Where the move reached, counts.
    pub reached: u8,
    /// Where it came back to, counts.
    pub back: u8,
    /// gOBJ at the end.
    pub object: ObjectStatus,
    /// Motor current at the end, mA.
    pub current_ma: u32,
    /// Move-and-status exchanges a second, measured over [`LINK_TEST_EXCHANGES`]
    /// exchanges holding the fingers where they are (`None` when no time passed, as
    /// on the simulator's paused clock).
    pub exchanges_hz: Option<f64>,
    /// The USB-serial adapter's latency timer, ms (`None`: not such an adapter).
    pub latency_timer_ms: Option<u32>,
}

impl From<ArmCheck> for Measured {
    fn from(c: ArmCheck) -> Self {
        Self::Arm(c)
    }
}
impl From<StreamCheck> for Measured {
    fn from(c: StreamCheck) -> Self {
        Self::ForceSensor(c)
    }
}
impl From<FrameCheck> for Measured {
    fn from(c: FrameCheck) -> Self {
        Self::Camera(c)
    }
}
impl From<GripperCheck> for Measured {
    fn from(c: GripperCheck) -> Self {
        Self::Gripper(c)
    }
}

impl fmt::Display for StreamCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} readings in {:.2} s: {:.0} Hz of {:.0} Hz configured, {} lost, {} warnings, mean Fz {:.3} N",
            self.readings,
            self.elapsed_s,
            self.measured_hz,
            self.rate_hz,
            self.lost,
            self.warnings,
            self.mean_fz_n
        )
    }
}

impl fmt::Display for Measured {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Arm(a) => {
                let [x, y, z] = a.translation_m;
                write!(
                    f,
                    "pose ({x:.3}, {y:.3}, {z:.3}) m in the base frame, no fault; moved {} mm up and back, within {:.3} mm",
                    a.moved_mm, a.worst_arrival_mm
                )?;
                if let Some(rate) = a.command_success_rate {
                    write!(f, "; {:.1} % of real-time commands arrived", rate * 100.0)?;
                }
                if let Some(found) = &a.found_at_connect {
                    write!(f, "; mode at connect: {found}")?;
                }
                Ok(())
            }
            Self::Host(h) => {
                let r = &h.realtime;
                let limit = |v: Option<u64>, unit: &str| {
                    v.map_or_else(|| "unlimited".to_owned(), |n| format!("{n}{unit}"))
                };
                write!(
                    f,
                    "kernel {} ({}), real-time priority up to {} (ulimit -r), memlock {} (ulimit -l){}",
                    r.kernel_release,
                    if r.preempt_rt {
                        "PREEMPT_RT"
                    } else {
                        "not PREEMPT_RT"
                    },
                    limit(r.rtprio_limit, ""),
                    r.memlock_limit_bytes.map_or_else(
                        || "unlimited".to_owned(),
                        softtouch_collector::collect::disk::human_bytes
                    ),
                    h.not_required
                        .map_or_else(String::new, |why| format!("; not required: {why}"))
                )
            }
            Self::ForceSensor(s) => s.fmt(f),
            Self::Camera(c) => {
                write!(
                    f,
                    "frame {} {}×{} {:?}, {} bytes, {} dropped",
                    c.sequence, c.width, c.height, c.format, c.bytes, c.dropped
                )?;
                if let Some(held) = &c.settings {
                    write!(f, "; {held}")?;
                }
                Ok(())
            }
            Self::Gripper(g) => {
                write!(
                    f,
                    "activated; moved {} → {} → {} counts, gOBJ {:?}, current {} mA, no fault",
                    g.start, g.reached, g.back, g.object, g.current_ma
                )?;
                if let Some(hz) = g.exchanges_hz {
                    write!(f, "; link {hz:.0} exchanges/s")?;
                }
                if let Some(ms) = g.latency_timer_ms {
                    write!(f, ", adapter latency timer {ms} ms")?;
                }
                Ok(())
            }
        }
    }
}

/// How far the force/torque stream's period may be from the configured one, as a
/// fraction of it, either way (the host's clock over the window, lost readings counted
/// as sent): the driver's own ([`softtouch_drivers::netft::client::RATE_REFUSED`]).
use softtouch_drivers::netft::client::RATE_REFUSED;
/// Counts of the gripper's test move.
const GRIPPER_TEST_COUNTS: u8 = 20;
/// Exchanges timed to measure the gripper link's rate.
pub const LINK_TEST_EXCHANGES: u32 = 20;
/// Highest USB-serial latency timer the gripper check accepts, ms.
pub const MAX_LATENCY_TIMER_MS: u32 = 1;

fn all_simulated(rig: &RigConfig) -> bool {
    matches!(rig.arm, ArmDevice::Sim { .. })
        && matches!(rig.force_sensor, ForceSensorDevice::Sim { .. })
        && matches!(rig.camera, CameraDevice::Sim { .. })
        && matches!(rig.second_camera, None | Some(CameraDevice::Sim { .. }))
        && matches!(rig.gripper, GripperDevice::Sim {})
}

/// The rig with every real device replaced by its simulated twin.
fn simulated_twin(rig: &RigConfig) -> RigConfig {
    let mut r = rig.clone();
    if let ArmDevice::Franka { reflex_force_n, .. } = r.arm {
        r.arm = ArmDevice::Sim { reflex_force_n };
    }
    r.force_sensor = ForceSensorDevice::Sim {
        rate_hz: rig.force_sensor.rate_hz(),
    };
    if let CameraDevice::V4l { .. } = r.camera {
        r.camera = CameraDevice::Sim { fps: 120.0 };
    }
    r.second_camera = None;
    r.gripper = GripperDevice::Sim {};
    r
}

fn where_arm(d: &ArmDevice) -> String {
    match d {
        ArmDevice::Sim { .. } => "the simulator".into(),
        ArmDevice::Franka { address, .. } => address.clone(),
    }
}

fn where_sensor(d: &ForceSensorDevice) -> String {
    match d {
        ForceSensorDevice::Sim { .. } => "the simulator".into(),
        ForceSensorDevice::NetFt { address, .. } => format!(
            "{address} (Net F/T: RDT over UDP, calibration over TCP unless counts_per_force and counts_per_torque are given)"
        ),
        ForceSensorDevice::AtiSerial { port, baud, .. } => format!("{port} at {baud} baud"),
    }
}

fn where_camera(d: &CameraDevice) -> String {
    match d {
        CameraDevice::Sim { .. } => "the simulator".into(),
        CameraDevice::V4l { device, .. } => device.clone(),
    }
}

fn where_gripper(d: &GripperDevice) -> String {
    match d {
        GripperDevice::Sim {} => "the simulator".into(),
        GripperDevice::HandE { port, slave_id } => {
            format!("{port}, Modbus RTU slave {slave_id} at 115200 baud")
        }
    }
}

fn driver_of_arm(d: &ArmDevice) -> &'static str {
    match d {
        ArmDevice::Sim { .. } => "sim",
        ArmDevice::Franka { .. } => "franka",
    }
}

fn driver_of_sensor(d: &ForceSensorDevice) -> &'static str {
    match d {
        ForceSensorDevice::Sim { .. } => "sim",
        ForceSensorDevice::NetFt { .. } => "net-ft",
        ForceSensorDevice::AtiSerial { .. } => "ati-serial",
    }
}

fn driver_of_camera(d: &CameraDevice) -> &'static str {
    match d {
        CameraDevice::Sim { .. } => "sim",
        CameraDevice::V4l { .. } => "v4l",
    }
}

fn driver_of_gripper(d: &GripperDevice) -> &'static str {
    match d {
        GripperDevice::Sim {} => "sim",
        GripperDevice::HandE { .. } => "hand-e",
    }
}

/// Runs `check` under `timeout`; a timeout or an error fails the row.
async fn row<F, M>(device: &'static str, driver: &str, timeout: Duration, check: F) -> CheckRow
where
    F: std::future::Future<Output = Result<M, String>>,
    M: Into<Measured>,
{
    let outcome = match tokio::time::timeout(timeout, check).await {
        Ok(Ok(m)) => Ok(m.into()),
        Ok(Err(why)) => Err(CheckFailure::Failed(why)),
        Err(_) => Err(CheckFailure::TimedOut(timeout)),
    };
    CheckRow {
        device,
        driver: driver.to_owned(),
        outcome,
    }
}

/// Checks every device of `rig`; simulated ones run on the simulator built from
/// `scene`. Never fails as a whole: every problem is a failed row.
pub async fn check_rig(
    rig: &RigConfig,
    scene: &softtouch_schemas::SceneSpec,
    window: Duration,
    timeout: Duration,
) -> Vec<CheckRow> {
    if all_simulated(rig) {
        tokio::time::pause();
    }
    let clock = TokioClock::new();
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut rows = Vec::new();
    let sim = match SimRig::new(&simulated_twin(rig), scene, 0, clock) {
        Ok(s) => Some(s),
        Err(e) => {
            rows.push(CheckRow {
                device: "simulator",
                driver: "sim".into(),
                outcome: Err(CheckFailure::Failed(format!(
                    "the simulated devices cannot be built: {e}"
                ))),
            });
            None
        }
    };
    let (mut sim_arm, mut sim_sensor, mut sim_camera, mut sim_gripper, handle) = match sim {
        Some(s) => (
            Some(s.arm),
            Some(s.force_sensor),
            Some(s.camera),
            Some(s.gripper),
            Some(s.handle),
        ),
        None => (None, None, None, None, None),
    };
    let no_sim = || "the simulator is not available (see the simulator row)".to_owned();

    rows.push(
        row("host", "linux", timeout, async {
            let realtime = softtouch_drivers::realtime::host_realtime();
            let not_required = match &rig.arm {
                ArmDevice::Sim { .. } => Some("no real arm"),
                ArmDevice::Franka {
                    realtime: softtouch_schemas::Realtime::Ignore,
                    ..
                } => Some("the franka table says realtime = \"ignore\""),
                ArmDevice::Franka { .. } => None,
            };
            let problems = realtime.problems();
            if not_required.is_none() && !problems.is_empty() {
                return Err(format!(
                    "expected a real-time host for the Panda's 1 kHz loop: {} (docs/RIG.md; realtime = \"ignore\" runs anyway, for a first look only)",
                    problems.join("; ")
                ));
            }
            Ok(HostCheck {
                realtime,
                not_required,
            })
        })
        .await,
    );
    rows.push(
        row("arm", driver_of_arm(&rig.arm), timeout, async {
            let arm: Box<dyn Arm> =
                match real_arm_for_rig(rig, shared.clone()).await.map_err(|e| {
                    format!("expected the arm answering at {}: {e}", where_arm(&rig.arm))
                })? {
                    Some(a) => a,
                    None => Box::new(sim_arm.take().ok_or_else(no_sim)?),
                };
            check_arm(arm, &rig.workspace).await
        })
        .await,
    );
    rows.push(
        row(
            "force_sensor",
            driver_of_sensor(&rig.force_sensor),
            timeout,
            async {
                let sensor: Box<dyn ForceSensor> =
                    match real_force_sensor(&rig.force_sensor, shared.clone())
                        .await
                        .map_err(|e| {
                            format!(
                                "expected the sensor answering at {}: {e}",
                                where_sensor(&rig.force_sensor)
                            )
                        })? {
                        Some(s) => s,
                        None => Box::new(sim_sensor.take().ok_or_else(no_sim)?),
                    };
                check_force_sensor(sensor, rig.force_sensor.rate_hz(), window, &*shared).await
            },
        )
        .await,
    );
    rows.push(
        row("camera", driver_of_camera(&rig.camera), timeout, async {
            let camera: Box<dyn Camera> = match real_camera(&rig.camera, shared.clone())
                .await
                .map_err(|e| format!("expected a camera at {}: {e}", where_camera(&rig.camera)))?
            {
                Some(c) => c,
                None => Box::new(sim_camera.take().ok_or_else(no_sim)?),
            };
            check_camera(camera, &*shared).await
        })
        .await,
    );
    if let Some(second) = &rig.second_camera {
        rows.push(
            row("second_camera", driver_of_camera(second), timeout, async {
                let camera: Box<dyn Camera> = match real_camera(second, shared.clone())
                    .await
                    .map_err(|e| format!("expected a camera at {}: {e}", where_camera(second)))?
                {
                    Some(c) => c,
                    // The rod-press simulator has one finger camera; its twin stands in.
                    None => Box::new(
                        SimRig::new(&simulated_twin(rig), scene, 1, clock)
                            .map_err(|e| format!("simulated camera: {e}"))?
                            .camera,
                    ),
                };
                check_camera(camera, &*shared).await
            })
            .await,
        );
    }
    rows.push(
        row("gripper", driver_of_gripper(&rig.gripper), timeout, async {
            let gripper: Box<dyn Gripper> = match real_gripper(&rig.gripper, shared.clone())
                .await
                .map_err(|e| {
                format!("expected a gripper at {}: {e}", where_gripper(&rig.gripper))
            })? {
                Some(g) => g,
                None => Box::new(sim_gripper.take().ok_or_else(no_sim)?),
            };
            let port = match &rig.gripper {
                GripperDevice::HandE { port, .. } => Some(port.as_str()),
                GripperDevice::Sim {} => None,
            };
            let latency_timer_ms = port.and_then(softtouch_drivers::hande::latency_timer_ms);
            check_gripper(gripper, &*shared, latency_timer_ms).await
        })
        .await,
    );
    drop(handle);
    rows
}
