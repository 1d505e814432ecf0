//! The rig config: which driver drives each device, where the arm may go, the force
//! limits, and the timings of the collection procedure.

use crate::config::{Check, Validate};
use crate::geometry::{ArmPose, ContactPose, Range};
use crate::scene::Medium;
use serde::{Deserialize, Serialize};

/// A whole rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigConfig {
    /// The arm that presses the finger on the rod.
    pub arm: ArmDevice,
    /// The force/torque sensor under the finger (the labels).
    pub force_sensor: ForceSensorDevice,
    /// The camera inside the finger.
    pub camera: CameraDevice,
    /// The gripper for grasp trials.
    pub gripper: GripperDevice,
    /// The camera of a second sensorised finger on the gripper (grasp trials only;
    /// absent: one sensorised finger, whose camera is `camera`). Same driver as
    /// `camera`, another device.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub second_camera: Option<CameraDevice>,
    /// Where the arm may go.
    pub workspace: WorkspaceBounds,
    /// Force limits and the sensor's range.
    pub limits: ForceLimits,
    /// Timings of one sample.
    pub procedure: Procedure,
}

/// The arm's driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "driver", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ArmDevice {
    /// The simulated arm.
    Sim {
        /// Contact force above which the simulated arm raises a reflex, N.
        reflex_force_n: f64,
    },
    /// A Franka Emika Panda (FCI v5) or Franka Research 3 (FCI v10) over FCI
    /// (franka-rs): the version is the one the robot answers with.
    Franka {
        /// The robot's address, e.g. `172.16.0.2`.
        address: String,
        /// Upper force threshold of the collision behaviour, N: above it the robot
        /// reflex-stops. The library's defaults are below what pressing reaches.
        reflex_force_n: f64,
        /// Upper Cartesian torque threshold of the collision behaviour, N·m. Absent:
        /// 0.1 m × `reflex_force_n` (a force at the end effector makes no torque about
        /// it; set `end_effector` so that the contact is there).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reflex_torque_nm: Option<f64>,
        /// The control thread's scheduling: `enforce` (default: a PREEMPT_RT kernel and
        /// SCHED_FIFO priority, or the connection is refused) or `ignore` (any kernel;
        /// the 1 kHz loop misses cycles under load and the robot ends in
        /// `communication_constraints_violation`: for a first look, never for a night).
        #[serde(default)]
        realtime: Realtime,
        /// The finger's contact frame in the frame of the end effector Desk is set to
        /// (`NE_T_EE`, applied with `set_ee` at connect). Absent: Desk's end effector
        /// is used as it is, and must then be the finger.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        end_effector: Option<Box<ArmPose>>,
        /// What hangs on the flange beyond Desk's end effector (the finger, its mount,
        /// the F/T sensor), applied with `set_load` at connect so that it does not bias
        /// the external-force estimate. Absent: none.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        payload: Option<Box<Payload>>,
    },
}

/// How the Franka's control thread is scheduled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Realtime {
    /// A real-time kernel and SCHED_FIFO priority are required.
    #[default]
    Enforce,
    /// Run on any kernel, warned about at every connect.
    Ignore,
}

/// A load on the flange (libfranka's `setLoad`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Payload {
    /// Mass, kg (a Panda carries at most 3).
    pub mass_kg: f64,
    /// Centre of mass in the flange frame, m.
    pub com_in_flange_m: [f64; 3],
    /// Inertia about the centre of mass, kg·m², a symmetric 3×3 (row- and column-major
    /// alike). Absent: a point mass.
    #[serde(default)]
    pub inertia_kg_m2: [f64; 9],
}

/// The most a Panda's flange carries, kg.
pub const FRANKA_MAX_PAYLOAD_KG: f64 = 3.0;

/// The force/torque sensor's driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "driver", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ForceSensorDevice {
    /// The simulated sensor.
    Sim {
        /// Readings per second (up to 7000).
        rate_hz: f64,
    },
    /// ATI Net F/T over UDP RDT.
    NetFt {
        /// The sensor's IP address (RDT on UDP 49152, calibration on TCP 49151).
        address: String,
        /// Readings per second as configured on the sensor (up to 7000).
        rate_hz: f64,
        /// Counts per N; read from the sensor when absent.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        counts_per_force: Option<f64>,
        /// Counts per N·m; read from the sensor when absent.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        counts_per_torque: Option<f64>,
        /// Fixed delay from a reading's sample instant to the host receiving it, s
        /// (network/serial transfer and the box's filtering; measure it once, e.g. by
        /// tapping the finger in view of the camera). Subtracted from every reading's
        /// stamp, so readings and frames share one time base. Absent: 0.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        latency_s: Option<f64>,
    },
    /// ATI serial F/T controller (ASCII protocol).
    AtiSerial {
        /// Serial port, e.g. `/dev/ttyUSB0`.
        port: String,
        /// Baud rate (new boxes default to 9600; 38400 is common).
        baud: u32,
        /// Counts per N (the serial box reports counts only).
        counts_per_force: f64,
        /// Counts per N·m.
        counts_per_torque: f64,
        /// Fixed delay from a reading's sample instant to the host receiving it, s
        /// (network/serial transfer and the box's filtering; measure it once, e.g. by
        /// tapping the finger in view of the camera). Subtracted from every reading's
        /// stamp, so readings and frames share one time base. Absent: 0.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        latency_s: Option<f64>,
    },
}

/// The in-finger camera's driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "driver", rename_all = "kebab-case", deny_unknown_fields)]
pub enum CameraDevice {
    /// The simulated camera rendering the scene.
    Sim {
        /// Frames per second.
        fps: f64,
    },
    /// A V4L2 camera.
    V4l {
        /// Device path, e.g. `/dev/video0`.
        device: String,
        /// Fixed delay from a frame's exposure to the driver's timestamp of it, s
        /// (readout and USB transfer; measure it once, e.g. by tapping the finger in
        /// view of the camera). Subtracted from every frame's stamp, as the force
        /// sensor's `latency_s` is from its readings. Absent: 0.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        latency_s: Option<f64>,
    },
}

/// The gripper's driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "driver", rename_all = "kebab-case", deny_unknown_fields)]
pub enum GripperDevice {
    /// The simulated Hand-E.
    Sim {},
    /// A Robotiq Hand-E over Modbus RTU (115200 8N1).
    HandE {
        /// Serial port, e.g. `/dev/ttyUSB1`.
        port: String,
        /// Modbus slave id (9 from the factory).
        slave_id: u8,
    },
}

/// Where the arm may go. Every command is checked against these before it is sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkspaceBounds {
    /// Allowed contact offsets along the approach axis, m.
    pub x_m: Range,
    /// Allowed contact offsets along the rod axis, m.
    pub z_m: Range,
    /// Allowed rotations about the rod axis, rad.
    pub theta_rad: Range,
    /// Where the rod stands in the arm's base frame.
    pub base_from_rod: ArmPose,
    /// Safe pose between samples, in the rod frame (clear of the rod).
    pub home: ContactPose,
    /// Box the flange must stay in, arm base frame, m: `[x, y, z]` ranges.
    pub reach_in_base_m: [Range; 3],
}

impl WorkspaceBounds {
    /// The contact pose lies inside the contact bounds.
    #[must_use]
    pub fn contains_contact(&self, p: &ContactPose) -> bool {
        self.x_m.contains(p.x_m) && self.z_m.contains(p.z_m) && self.theta_rad.contains(p.theta_rad)
    }

    /// The arm pose lies inside the reach box.
    #[must_use]
    pub fn contains_arm(&self, p: &ArmPose) -> bool {
        p.is_valid() && (0..3).all(|i| self.reach_in_base_m[i].contains(p.translation_m[i]))
    }
}

/// Force limits, and the range of the sensor (readings at it are saturated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceLimits {
    /// Abort an approach when the contact force exceeds this, N.
    pub max_force_n: f64,
    /// Abort an approach when any torque exceeds this, N·m.
    pub max_torque_nm: f64,
    /// The sensor's calibrated range per force axis, N (Nano17 SI-25: 25, 25, 35).
    pub sensor_range_force_n: [f64; 3],
    /// The sensor's calibrated range per torque axis, N·m (Nano17 SI-25: 0.25).
    pub sensor_range_torque_nm: [f64; 3],
}

impl ForceLimits {
    /// The sensor's range per axis in storage order `[Fx, Fy, Fz, Tx, Ty, Tz]` (N, N·m).
    #[must_use]
    pub fn sensor_range(&self) -> [f64; 6] {
        let [fx, fy, fz] = self.sensor_range_force_n;
        let [tx, ty, tz] = self.sensor_range_torque_nm;
        [fx, fy, fz, tx, ty, tz]
    }
}

/// Timings and retry policy of one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Procedure {
    /// Approach speed, m/s.
    pub approach_speed_m_s: f64,
    /// Wait after reaching the pose before recording, s.
    pub settle_s: f64,
    /// Length of the force/torque window around the frame's time, s.
    pub ft_window_s: f64,
    /// Fewest readings a window may hold and still be a label.
    pub min_window_readings: u32,
    /// Retreat speed, m/s.
    pub retreat_speed_m_s: f64,
    /// Longest wait for a frame, s.
    pub frame_timeout_s: f64,
    /// Tries per sample before it is stored as rejected.
    pub max_attempts: u32,
    /// Consecutive failed samples that trigger a safe stop.
    pub max_consecutive_failures: u32,
    /// The approach guard stops the arm when no force/torque reading arrives for this
    /// long, s (the stream is stale). Absent: [`DEFAULT_FT_STALE_S`].
    #[serde(default = "default_ft_stale_s")]
    pub ft_stale_s: f64,
    /// Largest gap between a frame's time and the nearest reading on each side of it,
    /// s: a sample whose frame is not covered by readings this close before and after
    /// it is rejected (`clock_skew`): its label would come from another moment than
    /// its image. Absent: [`Procedure::max_skew_s_for`], the larger of 2 sensor
    /// periods and [`DEFAULT_MAX_SKEW_S`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_skew_s: Option<f64>,
    /// When the force/torque sensor is zeroed at home: `none`, `per-run` or
    /// `per-sample`. Absent: what suits the scene's medium ([`Tare::for_medium`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tare: Option<Tare>,
}

/// When the force/torque sensor is zeroed (tared, "biased"): always at home, clear of
/// the rod, so that the labels carry no offset (buoyancy, pressure, mounting) and no
/// zero drift accumulated since the last tare.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tare {
    /// Never: labels keep the sensor's offset and drift.
    None,
    /// Once, at home before the first sample of a run (or of a resumed run). A
    /// resumed run's tare is taken at another time than the run's first: with drift
    /// declared (a scene's `ft_drift`) its labels then differ from an uninterrupted
    /// run's by the drift between the two tares, where `per-sample` and `none` (and
    /// `per-run` without drift) resume bit-identically.
    PerRun,
    /// At home before every attempt at a sample: removes drift as it accumulates.
    PerSample,
}

impl Tare {
    /// The default for a medium: underwater the zero drifts and the buoyancy/pressure
    /// offset changes with depth, so every sample is tared; in air once per run.
    #[must_use]
    pub const fn for_medium(medium: Medium) -> Self {
        match medium {
            Medium::Air => Self::PerRun,
            Medium::Water => Self::PerSample,
        }
    }

    /// Name as in the config.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::PerRun => "per-run",
            Self::PerSample => "per-sample",
        }
    }
}

/// Floor of the default [`Procedure::max_skew_s`], s: at 1 kHz, 5 sensor periods.
pub const DEFAULT_MAX_SKEW_S: f64 = 0.005;

impl Procedure {
    /// The skew limit for a sensor streaming at `rate_hz`: the configured one, else
    /// the larger of 2 sensor periods and [`DEFAULT_MAX_SKEW_S`].
    #[must_use]
    pub fn max_skew_s_for(&self, rate_hz: f64) -> f64 {
        self.max_skew_s.unwrap_or_else(|| {
            let periods = if rate_hz.is_finite() && rate_hz > 0.0 {
                2.0 / rate_hz
            } else {
                0.0
            };
            periods.max(DEFAULT_MAX_SKEW_S)
        })
    }

    /// The tare policy of a run in `medium`: the configured one, else the medium's default.
    #[must_use]
    pub fn tare_for(&self, medium: Medium) -> Tare {
        self.tare.unwrap_or(Tare::for_medium(medium))
    }
}

/// Seconds of readings the collector's force/torque ring holds (at the sensor's rate).
/// A label window must fit in half of it, leaving the rest for the wait for a frame.
pub const FT_BUFFER_S: f64 = 4.0;

/// Longest duration a config may give, s (one day). Far beyond any sensible wait, and
/// far below what overflows a `std::time::Duration` or a nanosecond timestamp.
pub const MAX_DURATION_S: f64 = 86_400.0;

impl ForceSensorDevice {
    /// Readings per second: the configured rate, or for an ATI serial box (which does
    /// not report its rate) the most it streams, 7000.
    #[must_use]
    pub fn rate_hz(&self) -> f64 {
        match self {
            Self::Sim { rate_hz } | Self::NetFt { rate_hz, .. } => *rate_hz,
            Self::AtiSerial { .. } => 7000.0,
        }
    }

    /// The slowest a working sensor may stream, readings per second: the configured
    /// rate, or for an ATI serial box what its baud rate carries of ASCII lines of at
    /// most [`ATI_LINE_CHARS`] characters (10 bits each): about 15 Hz at 9600 baud,
    /// 180 Hz at 115200. The default skew limit is taken from this rate, so a slow
    /// serial box does not reject every sample.
    #[must_use]
    pub fn least_rate_hz(&self) -> f64 {
        match self {
            Self::AtiSerial { baud, .. } => {
                (f64::from(*baud) / (10.0 * ATI_LINE_CHARS)).min(self.rate_hz())
            }
            _ => self.rate_hz(),
        }
    }
}

/// Longest ASCII line an ATI serial box streams, characters (status and six values,
/// comma-separated, with CR LF), for [`ForceSensorDevice::least_rate_hz`].
pub const ATI_LINE_CHARS: f64 = 64.0;

/// Default of [`Procedure::ft_stale_s`], s: 100 readings at 1 kHz, five times the
/// longest packet of the simulated sensor (20 ms) and of a Net F/T's RDT burst.
pub const DEFAULT_FT_STALE_S: f64 = 0.1;

const fn default_ft_stale_s() -> f64 {
    DEFAULT_FT_STALE_S
}

/// The Franka's translational velocity limit (FCI), m/s.
pub const FRANKA_MAX_SPEED_M_S: f64 = 1.7;

impl Validate for RigConfig {
    fn validate(&self, c: &mut Check) {
        match &self.arm {
            ArmDevice::Sim { reflex_force_n } => {
                c.positive("arm.reflex_force_n", *reflex_force_n, "N")
            }
            ArmDevice::Franka {
                address,
                reflex_force_n,
                reflex_torque_nm,
                realtime: _,
                end_effector,
                payload,
            } => {
                non_empty(c, "arm.address", address);
                c.positive("arm.reflex_force_n", *reflex_force_n, "N");
                if let Some(t) = reflex_torque_nm {
                    c.positive("arm.reflex_torque_nm", *t, "N·m");
                }
                if let Some(ee) = end_effector {
                    let far = ee.translation_m.iter().any(|v| v.abs() > 0.5);
                    if !ee.is_valid() || far {
                        c.fail(
                            "arm.end_effector",
                            format!(
                                "expected finite translation_m within 0.5 m per axis and a finite, non-zero rotation_wxyz (normalised on use), found {:?} m, {:?}",
                                ee.translation_m, ee.rotation_wxyz
                            ),
                        );
                    }
                }
                if let Some(p) = payload {
                    c.within(
                        "arm.payload.mass_kg",
                        p.mass_kg,
                        0.0,
                        FRANKA_MAX_PAYLOAD_KG,
                        "kg",
                    );
                    for (i, v) in p.com_in_flange_m.iter().enumerate() {
                        c.within(
                            &format!("arm.payload.com_in_flange_m[{i}]"),
                            *v,
                            -0.5,
                            0.5,
                            "m",
                        );
                    }
                    if p.inertia_kg_m2.iter().any(|v| !v.is_finite()) {
                        c.fail(
                            "arm.payload.inertia_kg_m2",
                            "expected 9 finite values, kg·m²",
                        );
                    }
                }
            }
        }
        match &self.force_sensor {
            ForceSensorDevice::Sim { rate_hz } => {
                c.within("force_sensor.rate_hz", *rate_hz, 1.0, 7000.0, "Hz")
            }
            ForceSensorDevice::NetFt {
                address,
                rate_hz,
                counts_per_force,
                counts_per_torque,
                latency_s,
            } => {
                latency(c, "force_sensor.latency_s", *latency_s);
                non_empty(c, "force_sensor.address", address);
                c.within("force_sensor.rate_hz", *rate_hz, 1.0, 7000.0, "Hz");
                if let Some(v) = counts_per_force {
                    c.positive("force_sensor.counts_per_force", *v, "counts/N");
                }
                if let Some(v) = counts_per_torque {
                    c.positive("force_sensor.counts_per_torque", *v, "counts/N·m");
                }
            }
            ForceSensorDevice::AtiSerial {
                port,
                baud,
                counts_per_force,
                counts_per_torque,
                latency_s,
            } => {
                latency(c, "force_sensor.latency_s", *latency_s);
                non_empty(c, "force_sensor.port", port);
                if *baud == 0 {
                    c.fail(
                        "force_sensor.baud",
                        "expected a baud rate > 0 (9600 or 38400 typical)",
                    );
                }
                c.positive(
                    "force_sensor.counts_per_force",
                    *counts_per_force,
                    "counts/N",
                );
                c.positive(
                    "force_sensor.counts_per_torque",
                    *counts_per_torque,
                    "counts/N·m",
                );
            }
        }
        match &self.camera {
            CameraDevice::Sim { fps } => c.within("camera.fps", *fps, 1.0, 1000.0, "frames/s"),
            CameraDevice::V4l { device, latency_s } => {
                non_empty(c, "camera.device", device);
                latency(c, "camera.latency_s", *latency_s);
            }
        }
        match (&self.camera, &self.second_camera) {
            (_, None) => {}
            (CameraDevice::Sim { .. }, Some(CameraDevice::Sim { fps })) => {
                c.within("second_camera.fps", *fps, 1.0, 1000.0, "frames/s");
            }
            (
                CameraDevice::V4l { device: first, .. },
                Some(CameraDevice::V4l { device, latency_s }),
            ) => {
                non_empty(c, "second_camera.device", device);
                latency(c, "second_camera.latency_s", *latency_s);
                if device == first {
                    c.fail(
                        "second_camera.device",
                        format!("expected another device than camera.device ({first})"),
                    );
                }
            }
            (_, Some(_)) => c.fail(
                "second_camera.driver",
                "expected the same driver as camera (both \"sim\" or both \"v4l\")",
            ),
        }
        match &self.gripper {
            GripperDevice::Sim {} => {}
            GripperDevice::HandE { port, slave_id } => {
                non_empty(c, "gripper.port", port);
                if !(1..=247).contains(slave_id) {
                    c.fail(
                        "gripper.slave_id",
                        format!("expected a Modbus slave id in [1, 247], found {slave_id}"),
                    );
                }
            }
        }

        let w = &self.workspace;
        c.range("workspace.x_m", &w.x_m, "m");
        c.range("workspace.z_m", &w.z_m, "m");
        c.range("workspace.theta_rad", &w.theta_rad, "rad");
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            c.range(
                &format!("workspace.reach_in_base_m[{i}] ({axis})"),
                &w.reach_in_base_m[i],
                "m",
            );
        }
        if !w.base_from_rod.is_valid() {
            c.fail(
                "workspace.base_from_rod",
                "expected finite translation and a non-zero quaternion",
            );
        } else if !w.home.is_finite() {
            c.fail("workspace.home", "expected finite x_m, z_m, theta_rad");
        } else {
            let home = ArmPose::from_contact(&w.base_from_rod, &w.home);
            if !w.contains_arm(&home) {
                c.fail(
                    "workspace.home",
                    format!(
                        "home maps to {:?} m in the base frame, outside workspace.reach_in_base_m",
                        home.translation_m
                    ),
                );
            }
            // Every corner of the contact box must be reachable.
            if c.problems().is_empty() {
                for x in [w.x_m.min, w.x_m.max] {
                    for z in [w.z_m.min, w.z_m.max] {
                        let corner = ContactPose {
                            x_m: x,
                            z_m: z,
                            theta_rad: 0.0,
                        };
                        let p = ArmPose::from_contact(&w.base_from_rod, &corner);
                        if !w.contains_arm(&p) {
                            c.fail(
                                "workspace.reach_in_base_m",
                                format!("contact corner (x={x} m, z={z} m) maps to {:?} m, outside the reach box", p.translation_m),
                            );
                        }
                    }
                }
            }
        }

        let l = &self.limits;
        c.positive("limits.max_force_n", l.max_force_n, "N");
        c.positive("limits.max_torque_nm", l.max_torque_nm, "N·m");
        for i in 0..3 {
            c.positive(
                &format!("limits.sensor_range_force_n[{i}]"),
                l.sensor_range_force_n[i],
                "N",
            );
            c.positive(
                &format!("limits.sensor_range_torque_nm[{i}]"),
                l.sensor_range_torque_nm[i],
                "N·m",
            );
        }

        let p = &self.procedure;
        c.within(
            "procedure.approach_speed_m_s",
            p.approach_speed_m_s,
            1e-4,
            FRANKA_MAX_SPEED_M_S,
            "m/s",
        );
        c.within(
            "procedure.retreat_speed_m_s",
            p.retreat_speed_m_s,
            1e-4,
            FRANKA_MAX_SPEED_M_S,
            "m/s",
        );
        c.within("procedure.settle_s", p.settle_s, 0.0, MAX_DURATION_S, "s");
        c.within(
            "procedure.ft_window_s",
            p.ft_window_s,
            1e-4,
            FT_BUFFER_S / 2.0,
            "s (half the force/torque buffer)",
        );
        c.positive("procedure.frame_timeout_s", p.frame_timeout_s, "s");
        if p.frame_timeout_s > MAX_DURATION_S {
            c.fail(
                "procedure.frame_timeout_s",
                format!(
                    "expected at most {MAX_DURATION_S} s, found {}",
                    p.frame_timeout_s
                ),
            );
        }
        if p.min_window_readings == 0 {
            c.fail(
                "procedure.min_window_readings",
                "expected at least 1 reading",
            );
        }
        // A window of length w on a grid of period 1/rate holds at most rate·w + 1
        // readings: more can never be met, and every sample would be rejected. The
        // rate is the slowest a working sensor streams (an ATI serial box's baud rate
        // caps it far below what the box can do).
        let rate_hz = self.force_sensor.rate_hz();
        let least_hz = self.force_sensor.least_rate_hz();
        let why = if least_hz < rate_hz {
            format!(
                "the slowest rate of force_sensor: {least_hz:.1} Hz, what its baud rate carries"
            )
        } else {
            format!("force_sensor rate {least_hz} Hz")
        };
        if least_hz.is_finite() && p.ft_window_s.is_finite() && least_hz > 0.0 {
            let most = (least_hz * p.ft_window_s).floor() + 1.0;
            if f64::from(p.min_window_readings) > most {
                let window_s = (f64::from(p.min_window_readings) - 1.0) / least_hz;
                c.fail(
                    "procedure.min_window_readings",
                    format!(
                        "expected at most {most} readings ({why} × procedure.ft_window_s {} s, + 1), found {}: lower it, or lengthen procedure.ft_window_s to {} s",
                        p.ft_window_s,
                        p.min_window_readings,
                        (window_s * 1000.0).ceil() / 1000.0
                    ),
                );
            }
        }
        c.within("procedure.ft_stale_s", p.ft_stale_s, 1e-3, 10.0, "s");
        // The approach guard calls the stream stale after ft_stale_s without a reading:
        // under three periods of the slowest rate, a healthy stream trips it.
        let stale_floor_s = 3.0 / least_hz;
        if least_hz.is_finite()
            && least_hz > 0.0
            && p.ft_stale_s.is_finite()
            && p.ft_stale_s < stale_floor_s
        {
            c.fail(
                "procedure.ft_stale_s",
                format!(
                    "expected at least three sensor periods ({why}: {} s), found {}: a healthy stream would stop every approach as stale",
                    (stale_floor_s * 1000.0).ceil() / 1000.0,
                    p.ft_stale_s
                ),
            );
        }
        if let Some(skew_s) = p.max_skew_s {
            let problems = c.problems().len();
            c.within(
                "procedure.max_skew_s",
                skew_s,
                1e-5,
                FT_BUFFER_S / 2.0,
                "s (half the force/torque buffer)",
            );
            // Readings 1/rate apart cover a frame between them within half a period
            // at best: a smaller limit would reject most frames.
            if c.problems().len() == problems
                && least_hz.is_finite()
                && least_hz > 0.0
                && skew_s * least_hz < 0.5
            {
                c.fail(
                    "procedure.max_skew_s",
                    format!(
                        "expected at least half a sensor period (0.5 / {why} = {} s), found {skew_s}",
                        0.5 / least_hz
                    ),
                );
            }
        }
        if p.max_attempts == 0 {
            c.fail("procedure.max_attempts", "expected at least 1 attempt");
        }
        if p.max_consecutive_failures == 0 {
            c.fail("procedure.max_consecutive_failures", "expected at least 1");
        }
    }
}

/// The most a sensor's configured latency may be, s: far beyond any real link, and a
/// bound that keeps stamps from being moved by seconds through a typo.
pub const MAX_SENSOR_LATENCY_S: f64 = 1.0;

fn latency(c: &mut Check, field: &str, v: Option<f64>) {
    if let Some(v) = v {
        c.within(field, v, 0.0, MAX_SENSOR_LATENCY_S, "s");
    }
}

fn non_empty(c: &mut Check, field: &str, v: &str) {
    if v.trim().is_empty() {
        c.fail(field, "expected a non-empty string");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ati(baud: u32) -> ForceSensorDevice {
        ForceSensorDevice::AtiSerial {
            port: "/dev/ttyUSB0".into(),
            baud,
            counts_per_force: 1.0,
            counts_per_torque: 1.0,
            latency_s: None,
        }
    }

    #[test]
    fn the_default_skew_limit_follows_the_slowest_the_sensor_streams() {
        let p = crate::defaults::rig().procedure;
        assert!(p.max_skew_s.is_none());
        // A 1 kHz stream: the 5 ms floor.
        let sim = ForceSensorDevice::Sim { rate_hz: 1000.0 };
        assert!((p.max_skew_s_for(sim.least_rate_hz()) - DEFAULT_MAX_SKEW_S).abs() < 1e-12);
        // A serial box at 9600 baud carries 15 lines/s: two periods, 133 ms.
        let slow = ati(9600);
        assert!((slow.least_rate_hz() - 15.0).abs() < 1e-9);
        assert!((p.max_skew_s_for(slow.least_rate_hz()) - 2.0 / 15.0).abs() < 1e-9);
        // Faster links: never above the 7000 Hz the box can stream at most.
        assert!((ati(115_200).least_rate_hz() - 180.0).abs() < 1e-9);
        assert!(ati(u32::MAX).least_rate_hz() <= 7000.0);
        // A configured limit wins.
        let set = Procedure {
            max_skew_s: Some(0.002),
            ..p
        };
        assert!((set.max_skew_s_for(slow.least_rate_hz()) - 0.002).abs() < 1e-12);
    }

    /// The fields a rig's check refuses, in order.
    fn refused(rig: &RigConfig) -> Vec<String> {
        let mut c = crate::config::Check::default();
        rig.validate(&mut c);
        c.problems().iter().map(|p| p.field.clone()).collect()
    }

    #[test]
    fn a_serial_sensor_is_checked_against_what_its_baud_rate_carries() {
        // The defaults (25 readings in 50 ms, stale after 0.1 s) suit a 1 kHz stream,
        // not the 15 readings a second an ATI serial box sends at 9600 baud.
        let mut rig = crate::defaults::rig();
        assert!(refused(&rig).is_empty());
        rig.force_sensor = ati(9600);
        assert_eq!(
            refused(&rig),
            ["procedure.min_window_readings", "procedure.ft_stale_s"]
        );
        // What the messages suggest works: a 2 s window of 20 readings, 0.2 s stale.
        rig.procedure.ft_window_s = 2.0;
        rig.procedure.min_window_readings = 20;
        rig.procedure.ft_stale_s = 0.2;
        assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));
        // Just under three periods is refused; a skew limit under half a period too.
        rig.procedure.ft_stale_s = 0.199;
        rig.procedure.max_skew_s = Some(0.03);
        assert_eq!(
            refused(&rig),
            ["procedure.ft_stale_s", "procedure.max_skew_s"]
        );
        // A faster link carries more, but 180 lines a second still not 25 in 50 ms.
        let mut fast = crate::defaults::rig();
        fast.force_sensor = ati(115_200);
        assert_eq!(refused(&fast), ["procedure.min_window_readings"]);
    }

    #[test]
    fn a_franka_table_carries_its_end_effector_payload_and_real_time_setting() {
        let toml = r#"
driver = "franka"
address = "172.16.0.2"
reflex_force_n = 30.0
realtime = "ignore"
[end_effector]
translation_m = [0.0, 0.0, 0.12]
rotation_wxyz = [1.0, 0.0, 0.0, 0.0]
[payload]
mass_kg = 0.35
com_in_flange_m = [0.0, 0.0, 0.06]
"#;
        let arm: ArmDevice = toml::from_str(toml).unwrap_or_else(|e| panic!("{e}"));
        let ArmDevice::Franka {
            realtime,
            end_effector,
            payload,
            reflex_torque_nm,
            ..
        } = &arm
        else {
            panic!("not franka: {arm:?}");
        };
        assert_eq!(*realtime, Realtime::Ignore);
        assert_eq!(
            end_effector.as_deref().map(|p| p.translation_m[2]),
            Some(0.12)
        );
        assert_eq!(payload.as_deref().map(|p| p.inertia_kg_m2), Some([0.0; 9]));
        assert!(reflex_torque_nm.is_none());
        // Left out, real time is enforced.
        let plain: ArmDevice =
            toml::from_str("driver = \"franka\"\naddress = \"a\"\nreflex_force_n = 30.0\n")
                .unwrap_or_else(|e| panic!("{e}"));
        assert!(matches!(
            plain,
            ArmDevice::Franka {
                realtime: Realtime::Enforce,
                ..
            }
        ));
        let mut rig = crate::defaults::rig();
        rig.arm = arm;
        assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));
        // A translation beyond reach of any finger, a zero rotation, NaN inertia.
        if let ArmDevice::Franka {
            end_effector,
            payload,
            ..
        } = &mut rig.arm
        {
            *end_effector = Some(Box::new(ArmPose {
                translation_m: [0.0, 0.0, 2.0],
                rotation_wxyz: [0.0; 4],
            }));
            if let Some(p) = payload.as_deref_mut() {
                p.inertia_kg_m2[4] = f64::NAN;
            }
        }
        assert_eq!(
            refused(&rig),
            ["arm.end_effector", "arm.payload.inertia_kg_m2"]
        );
    }
}
