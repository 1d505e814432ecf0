//! The rig config: which driver drives each device, where the arm may go, the force
//! limits, and the timings of the collection procedure.

use crate::config::{Check, Validate};
use crate::geometry::{ArmPose, ContactPose, Range};
use crate::scene::Medium;
use serde::{Deserialize, Serialize};

mod grasp;
mod validate;
pub use grasp::{GraspObjectSetup, GraspSetup, raised};
pub use validate::MAX_SENSOR_LATENCY_S;

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
    /// Grasp trials on this rig (`grasp trials --rig`): the objects' grasp poses,
    /// widths, lifts and set-down places. Absent: the rig runs no grasp trials.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp: Option<GraspSetup>,
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
        /// Upper joint torque thresholds of the collision behaviour, N·m, joints 1–7
        /// (half of each the lower one). Each must lie below that joint's torque
        /// limit ([`FRANKA_JOINT_TORQUE_LIMITS_NM`]), or the joint reflex never acts.
        /// Absent: [`FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM`].
        #[serde(default, skip_serializing_if = "Option::is_none")]
        joint_torque_thresholds_nm: Option<[f64; 7]>,
        /// The share of the robot's Cartesian velocity, acceleration and jerk limits
        /// (FR3 or Panda, by the FCI version it answers with) that moves use, in
        /// (0, 1]. Absent: [`FRANKA_DEFAULT_MOTION_MARGIN`].
        #[serde(default, skip_serializing_if = "Option::is_none")]
        motion_margin: Option<f64>,
    },
}

/// Default of the Franka's `motion_margin`: moves use 30 % of the robot's Cartesian
/// limits (FR3: 0.9 m/s, 2.7 m/s², 0.75 rad/s; Panda: 0.51 m/s, 3.9 m/s²), which
/// franka-sim's enforced limits pass with room for the robot's own inverse kinematics.
pub const FRANKA_DEFAULT_MOTION_MARGIN: f64 = 0.3;

/// The Panda's and FR3's joint torque limits, N·m (FCI documentation, "Robot and
/// interface specifications": τ_max).
pub const FRANKA_JOINT_TORQUE_LIMITS_NM: [f64; 7] = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0];

/// Whether upper joint torque thresholds lie above 0 and below each joint's torque
/// limit; the first that does not, named. The rig's validation and the Franka driver's
/// connect both ask this.
pub fn check_joint_thresholds(upper_nm: &[f64; 7]) -> Result<(), String> {
    for (i, (v, limit)) in upper_nm
        .iter()
        .zip(FRANKA_JOINT_TORQUE_LIMITS_NM)
        .enumerate()
    {
        if !(v.is_finite() && *v > 0.0 && *v < limit) {
            return Err(format!(
                "expected joint {}'s threshold above 0 and below its torque limit {limit} N·m, found {}",
                i + 1,
                crate::config::readable(*v)
            ));
        }
    }
    Ok(())
}

/// Default upper joint torque thresholds, N·m: libfranka's examples' values
/// (20, 20, 18, 18 on the big joints), capped below the wrist joints' 12 N·m limit.
/// Pressing a finger with a few newtons 0.1 m from the flange asks for under 1 N·m.
pub const FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM: [f64; 7] =
    [20.0, 20.0, 18.0, 18.0, 10.0, 10.0, 10.0];

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
        /// Image settings locked at open and read back (`[camera.image]`). Absent:
        /// the camera's own automatic exposure, white balance and gain, which drift
        /// with the light and change the images a model was trained on.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        image: Option<ImageSettings>,
    },
}

/// A V4L2 camera's image settings, each turning its automatic control off. Values the
/// camera does not hold as asked (read back after setting) refuse the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSettings {
    /// Exposure time, µs (V4L2 `exposure_time_absolute`, in 100 µs steps; manual
    /// exposure). At most the frame period, or the camera slows down.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_us: Option<u32>,
    /// White balance temperature, K (automatic white balance off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white_balance_k: Option<u32>,
    /// Gain, in the camera's own units (automatic gain off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<u32>,
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
    /// The last stretch of each approach, m, taken at `slow_approach_speed_m_s`: a
    /// contact that trips the force guard there is met slowly, and the arm stops in a
    /// fraction of a millimetre. Absent: [`DEFAULT_SLOW_APPROACH_M`]; 0 turns it off.
    #[serde(default = "default_slow_approach_m")]
    pub slow_approach_m: f64,
    /// Speed of that last stretch, m/s (at most `approach_speed_m_s`). Absent:
    /// [`DEFAULT_SLOW_APPROACH_SPEED_M_S`].
    #[serde(default = "default_slow_approach_speed_m_s")]
    pub slow_approach_speed_m_s: f64,
    /// Wait after reaching the pose before recording, s: with `settle_end = "signal"`
    /// the longest wait, with `"fixed"` the wait.
    pub settle_s: f64,
    /// What ends the settle: `signal` (default: the force/torque signal has settled,
    /// its drift between the last two `ft_window_s` within half the noise the sensor
    /// showed at its tare, at most `settle_s`) or `fixed` (always `settle_s`). Without
    /// a tare (`tare = "none"`) no noise is known and the settle is fixed.
    #[serde(default)]
    pub settle_end: SettleEnd,
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
    /// The order the samples of a rod's block are taken in: `planned` (default: a tour
    /// that sorts the poses into bands of θ and sweeps z back and forth within each,
    /// visiting each pose from its neighbour's retreat point) or `index` (index order,
    /// every sample from home and back, as before). Either way pose `i` is the same.
    #[serde(default)]
    pub visit_order: VisitOrder,
    /// Speed of the moves clear of the rod (out of a contact to the retreat point, and
    /// between retreat points), m/s; a Franka moves at most its `motion_margin` share
    /// of its limit. Absent: [`DEFAULT_TRAVEL_SPEED_M_S`].
    #[serde(default = "default_travel_speed_m_s")]
    pub travel_speed_m_s: f64,
    /// How far short of the finger's first touch of the rod an approach stops crossing
    /// free space at `travel_speed_m_s`, m (guarded as every move is); from there it
    /// goes on at `approach_speed_m_s`, its last `slow_approach_m` slowly. The first
    /// touch is the finger model's (`softtouch_sim::first_touch_x_m`). Absent:
    /// [`DEFAULT_STANDOFF_M`]; a stand-off past the retreat point leaves the whole
    /// approach at the approach speed.
    #[serde(default = "default_standoff_m")]
    pub standoff_m: f64,
}

/// What ends the settle before a sample is recorded ([`Procedure::settle_end`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SettleEnd {
    /// The signal: settled once its drift is within the sensor's noise (at most
    /// `settle_s`).
    #[default]
    Signal,
    /// Always `settle_s`.
    Fixed,
}

impl SettleEnd {
    /// Name as in the config.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Signal => "signal",
            Self::Fixed => "fixed",
        }
    }
}

/// The order a block's samples are taken in ([`Procedure::visit_order`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VisitOrder {
    /// A planned tour (bands of θ, z back and forth), from retreat point to retreat
    /// point; home only between rods and after an error.
    #[default]
    Planned,
    /// Index order, each sample from home and back home.
    Index,
}

impl VisitOrder {
    /// Name as in the config.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Planned => "planned",
            Self::Index => "index",
        }
    }
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

/// Default length of the slow end of each approach, m.
pub const DEFAULT_SLOW_APPROACH_M: f64 = 0.003;

/// Default speed of the slow end of each approach, m/s: from it a Panda braking at
/// 1.5 m/s² and 200 m/s³ stops within about 0.2 mm (in 21 ms). It costs a real rig
/// about 0.2 s a sample (the slow 3 mm and the stop between the two moves).
pub const DEFAULT_SLOW_APPROACH_SPEED_M_S: f64 = 0.02;

const fn default_slow_approach_m() -> f64 {
    DEFAULT_SLOW_APPROACH_M
}

const fn default_slow_approach_speed_m_s() -> f64 {
    DEFAULT_SLOW_APPROACH_SPEED_M_S
}

/// Default of [`Procedure::travel_speed_m_s`], m/s: within an FR3's 0.9 m/s at the
/// default motion margin; the moves between neighbouring poses are short, so their
/// acceleration, not this speed, sets how long they take.
pub const DEFAULT_TRAVEL_SPEED_M_S: f64 = 0.5;

/// Default [`Procedure::standoff_m`], m.
pub const DEFAULT_STANDOFF_M: f64 = 0.005;

const fn default_standoff_m() -> f64 {
    DEFAULT_STANDOFF_M
}

const fn default_travel_speed_m_s() -> f64 {
    DEFAULT_TRAVEL_SPEED_M_S
}

const fn default_ft_stale_s() -> f64 {
    DEFAULT_FT_STALE_S
}

/// The Franka's translational velocity limit (FCI), m/s.
pub const FRANKA_MAX_SPEED_M_S: f64 = 1.7;

#[cfg(test)]
mod tests;
