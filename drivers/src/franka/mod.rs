//! The Franka Emika Panda (FER, FCI v5) and Franka Research 3 (FCI v10) through
//! franka-rs (library `franka`), which connects as v10 and falls back to v5 when the
//! robot answers so; any other version is refused with both versions named.
//!
//! franka-rs is synchronous and runs a 1 kHz loop, so the robot lives on its own
//! thread; [`FrankaArm`] talks to it over channels. A move is a straight line in
//! Cartesian space (translation interpolated, rotation slerped) along one path
//! parameter driven by franka-rs's jerk-limited OTG, with limits chosen so the
//! translation stays within the velocity/acceleration/jerk of [`MotionLimits`] and
//! the rotation within its rotational limits (PROTOCOLS.md §3). The first setpoint is
//! seeded from the commanded pose `O_T_EE_c`. Dropping a move's future (a timeout, a
//! cancelled task) or [`Arm::stop`] aborts the motion: it brakes to rest within the
//! acceleration and jerk limits ([`Brake`]), then ends.
//!
//! The finger's pose is the robot's end-effector frame `O_T_EE`: the rig's
//! `end_effector` is applied with `set_ee` at connect (else Desk's end effector must be
//! the finger), and its `payload` with `set_load`, so that the unmodelled finger, mount
//! and sensor do not bias the robot's external-force estimate.
//!
//! The stiffness frame `K` is set to the end effector (`EE_T_K` = identity, read back
//! at connect), so the robot's external wrench estimate is taken at the finger whatever
//! Desk left there.
//!
//! A move is cancelled by generation: each move sent gets the next number, and
//! dropping its future or [`Arm::stop`] cancels every move up to that number. A move
//! still queued behind another when it is cancelled never reaches the robot; one
//! running brakes to rest. (A single abort flag, cleared when a move was taken from the
//! queue, let a cancelled queued move run in full with nobody waiting on it.)
//!
//! `control_command_success_rate` is zero whenever no motion runs (libfranka's
//! documentation), so the share of commands that reached the robot is sampled inside
//! the move's control loop and returned with the move's state.
//!
//! Real time: by default the control thread must get SCHED_FIFO on a PREEMPT_RT
//! kernel (franka-rs's `RealtimeConfig::Enforce`), or the connection is refused with
//! the reason; a rig may relax this (`realtime = "ignore"`), warned about at every
//! connect.

use crate::arm::{Arm, ArmState, PoseFeed};
use crate::clock::Clock;
use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::{ArmPose, Wrench};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use tokio::sync::{oneshot, watch};

/// The measured pose's publisher (every [`FEED_EVERY`] control cycles, and every state
/// read).
type FeedTx = Arc<watch::Sender<Option<(softtouch_schemas::TimestampNs, ArmPose)>>>;

/// Control cycles between two poses published on the feed (4 ms at 1 kHz).
const FEED_EVERY: usize = 4;

const DEVICE: &str = "franka";

/// Limits of a move (defaults: franka-rs target control's conservative ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Translational acceleration, m/s² (FCI allows 13; one FER refused 2.5).
    pub accel_m_s2: f64,
    /// Translational jerk, m/s³ (FCI allows 6500).
    pub jerk_m_s3: f64,
    /// Rotational velocity, rad/s (FCI allows 2.5).
    pub rot_speed_rad_s: f64,
    /// Rotational acceleration, rad/s² (FCI allows 25).
    pub rot_accel_rad_s2: f64,
    /// Rotational jerk, rad/s³ (FCI allows 12500).
    pub rot_jerk_rad_s3: f64,
    /// Translational deceleration when a move is aborted (the force guard's stop),
    /// m/s²: harder than a move's own, so the arm stops short of the reflex.
    pub brake_accel_m_s2: f64,
    /// Translational jerk when a move is aborted, m/s³.
    pub brake_jerk_m_s3: f64,
    /// Translational speed a move is held to, m/s (a faster request is slowed).
    pub max_speed_m_s: f64,
}

impl Default for MotionLimits {
    fn default() -> Self {
        Self {
            accel_m_s2: 0.5,
            jerk_m_s3: 20.0,
            rot_speed_rad_s: 0.5,
            rot_accel_rad_s2: 1.0,
            rot_jerk_rad_s3: 20.0,
            // What one FER accepted near the ready pose (PROTOCOLS.md: 1.5 m/s² with
            // 200 m/s³ passed where 2.5 m/s² was refused): from the 0.05 m/s approach
            // it stops in about 41 ms and 1 mm, against 125 ms and 3 mm at the move's
            // own 0.5 m/s² and 20 m/s³.
            brake_accel_m_s2: 1.5,
            brake_jerk_m_s3: 200.0,
            max_speed_m_s: MAX_SPEED_M_S,
        }
    }
}

/// A robot's Cartesian limits (libfranka's `rate_limiting.h`; franka-sim enforces the
/// same): `(velocity m/s, acceleration m/s², jerk m/s³, rotational velocity rad/s,
/// rotational acceleration rad/s², rotational jerk rad/s³)`.
#[must_use]
pub const fn cartesian_limits(robot: reach::Robot) -> [f64; 6] {
    match robot {
        reach::Robot::Fr3 => [3.0, 9.0, 4500.0, 2.5, 17.0, 8500.0],
        reach::Robot::Fer => [1.7, 13.0, 6500.0, 2.5, 25.0, 12500.0],
    }
}

impl MotionLimits {
    /// `margin` (in (0, 1]; anything else is taken as the default) of `robot`'s
    /// Cartesian limits. An abort brakes as the default does (1.5 m/s², 200 m/s³: what
    /// one FER accepted), or softer where the joints need it (`run_move`).
    #[must_use]
    pub fn for_robot(robot: reach::Robot, margin: f64) -> Self {
        let m = if margin.is_finite() && margin > 0.0 && margin <= 1.0 {
            margin
        } else {
            softtouch_schemas::FRANKA_DEFAULT_MOTION_MARGIN
        };
        let [v, a, j, rv, ra, rj] = cartesian_limits(robot);
        let d = Self::default();
        Self {
            accel_m_s2: a * m,
            // Jerk within what one lost cycle leaves room for (reach::JERK_MARGIN).
            jerk_m_s3: j * m.min(reach::JERK_MARGIN),
            rot_speed_rad_s: rv * m,
            rot_accel_rad_s2: ra * m,
            rot_jerk_rad_s3: rj * m.min(reach::JERK_MARGIN),
            brake_accel_m_s2: d.brake_accel_m_s2,
            brake_jerk_m_s3: d.brake_jerk_m_s3,
            max_speed_m_s: (v * m).min(MAX_SPEED_M_S),
        }
    }

    /// The limits an aborted move brakes with: the brake's translation, the move's
    /// rotation (no braking rotation has been measured on a Panda).
    #[must_use]
    pub const fn braking(&self) -> Self {
        Self {
            accel_m_s2: self.brake_accel_m_s2,
            jerk_m_s3: self.brake_jerk_m_s3,
            ..*self
        }
    }
}

/// The FCI's translational velocity limit used here (frankx's 1.7 m/s), m/s.
pub const MAX_SPEED_M_S: f64 = 1.7;

/// Connection settings.
#[derive(Debug, Clone, PartialEq)]
pub struct FrankaConfig {
    /// The robot's address (`172.16.0.2`, optionally `:port`).
    pub address: String,
    /// Upper force threshold of the collision behaviour, N (half of it the lower one).
    pub reflex_force_n: f64,
    /// Upper Cartesian torque threshold, N·m (half of it the lower one).
    pub reflex_torque_nm: f64,
    /// Whether real-time scheduling is required.
    pub realtime: softtouch_schemas::Realtime,
    /// `NE_T_EE` for `set_ee`, column-major; `None` leaves Desk's end effector.
    pub ne_t_ee: Option<[f64; 16]>,
    /// The payload for `set_load`: mass (kg), centre of mass in the flange frame (m),
    /// inertia (kg·m²); `None` sets none.
    pub payload: Option<(f64, [f64; 3], [f64; 9])>,
    /// Upper joint torque thresholds of the collision behaviour, N·m (half of each
    /// the lower one); each below the joint's torque limit.
    pub joint_torque_thresholds_nm: [f64; 7],
    /// Move limits.
    pub limits: MotionLimits,
    /// The route to check against the robot's joint ranges and velocity limits at
    /// connect, from the joints the arm is at ([`reach`]); empty: none.
    pub route: Vec<reach::Leg>,
    /// `Some(m)`: at connect, `limits` become `m` of the Cartesian limits of the robot
    /// the FCI version names ([`MotionLimits::for_robot`]); `None`: `limits` as given.
    pub motion_margin: Option<f64>,
}

impl FrankaConfig {
    /// The settings a rig's `franka` table gives.
    #[must_use]
    pub fn from_rig(d: &softtouch_schemas::ArmDevice) -> Option<Self> {
        let softtouch_schemas::ArmDevice::Franka {
            address,
            reflex_force_n,
            reflex_torque_nm,
            realtime,
            end_effector,
            payload,
            joint_torque_thresholds_nm,
            motion_margin,
        } = d
        else {
            return None;
        };
        Some(Self {
            address: address.clone(),
            reflex_force_n: *reflex_force_n,
            reflex_torque_nm: reflex_torque_nm.unwrap_or(0.1 * reflex_force_n),
            realtime: *realtime,
            ne_t_ee: end_effector.as_deref().map(|p| p.normalised().to_matrix()),
            payload: payload
                .as_deref()
                .map(|p| (p.mass_kg, p.com_in_flange_m, p.inertia_kg_m2)),
            joint_torque_thresholds_nm: joint_torque_thresholds_nm
                .unwrap_or(softtouch_schemas::FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM),
            limits: MotionLimits::default(),
            route: Vec::new(),
            motion_margin: Some(
                motion_margin.unwrap_or(softtouch_schemas::FRANKA_DEFAULT_MOTION_MARGIN),
            ),
        })
    }

    /// The settings of a rig's arm, with its workspace's route to check at connect
    /// (home, each corner and back, at the procedure's speeds).
    #[must_use]
    pub fn for_rig(rig: &softtouch_schemas::RigConfig) -> Option<Self> {
        let mut c = Self::from_rig(&rig.arm)?;
        c.route = reach::workspace_route(
            &rig.workspace,
            rig.procedure.approach_speed_m_s,
            rig.procedure.retreat_speed_m_s,
        );
        Some(c)
    }
}

type Reply<T> = oneshot::Sender<Result<T, DeviceError>>;

enum Cmd {
    Move {
        target: ArmPose,
        speed: f64,
        /// This move's number: cancelled once [`Cancel::through`] reaches it.
        generation: u64,
        reply: Reply<ArmState>,
    },
    State {
        reply: Reply<ArmState>,
    },
    Recover {
        reply: Reply<()>,
    },
    Stop {
        reply: Reply<()>,
    },
}

/// Which moves are cancelled: every move whose generation is at most `through`.
/// Shared between the handle (which numbers moves and cancels them) and the robot
/// thread (which skips a cancelled move it takes from the queue and brakes a running
/// one). Generations only grow, so a cancel never reaches a later move.
#[derive(Debug, Default)]
pub struct Cancel {
    through: AtomicU64,
}

impl Cancel {
    /// Cancel every move up to and including `generation`.
    pub fn cancel_through(&self, generation: u64) {
        self.through.fetch_max(generation, Ordering::SeqCst);
    }

    /// Whether the move numbered `generation` is cancelled.
    #[must_use]
    pub fn is_cancelled(&self, generation: u64) -> bool {
        self.through.load(Ordering::SeqCst) >= generation
    }
}

/// A Panda behind a worker thread. Implements [`Arm`].
#[derive(Debug)]
pub struct FrankaArm {
    tx: mpsc::Sender<Cmd>,
    cancel: Arc<Cancel>,
    /// The last move's generation (moves are numbered from 1).
    generation: u64,
    clock: Arc<dyn Clock>,
    feed: PoseFeed,
}

impl std::fmt::Debug for Cmd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Move { .. } => "Move",
            Self::State { .. } => "State",
            Self::Recover { .. } => "Recover",
            Self::Stop { .. } => "Stop",
        })
    }
}

fn err(e: franka::FrankaError) -> DeviceError {
    use franka::FrankaError as F;
    match e {
        F::Control(c) => DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: format!("{} (errors: {})", c.message, c.last_motion_errors),
        },
        F::Command(m) => DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: m,
        },
        F::Network(m) => DeviceError::Link {
            device: DEVICE.into(),
            message: m,
        },
        F::Protocol(m) => DeviceError::Protocol {
            device: DEVICE.into(),
            message: m,
        },
        F::IncompatibleVersion {
            server_version,
            library_version,
        } => DeviceError::Link {
            device: DEVICE.into(),
            message: format!(
                "incompatible FCI version: server {server_version}, library {library_version}"
            ),
        },
        F::Realtime(m) => DeviceError::Link {
            device: DEVICE.into(),
            message: format!("{m}: {}", crate::realtime::REFUSED_ADVICE),
        },
        F::InvalidArgument(m) | F::InvalidOperation(m) => DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: m,
        },
        other => DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: other.to_string(),
        },
    }
}

fn gone() -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: "the robot thread has stopped".into(),
    }
}

/// Limits of the path parameter s ∈ [0, 1] for a move of `dist_m` and `angle_rad`,
/// such that translation and rotation both stay within theirs.
#[must_use]
pub fn path_limits(
    dist_m: f64,
    angle_rad: f64,
    speed_m_s: f64,
    l: &MotionLimits,
) -> franka::OtgLimits {
    let per = |lin: f64, rot: f64| {
        let a = if dist_m > 1e-9 {
            lin / dist_m
        } else {
            f64::INFINITY
        };
        let b = if angle_rad > 1e-9 {
            rot / angle_rad
        } else {
            f64::INFINITY
        };
        let v = a.min(b);
        if v.is_finite() { v } else { 1e6 }
    };
    franka::OtgLimits {
        max_velocity: per(
            speed_m_s.min(l.max_speed_m_s).min(MAX_SPEED_M_S),
            l.rot_speed_rad_s,
        ),
        max_acceleration: per(l.accel_m_s2, l.rot_accel_rad_s2),
        max_jerk: per(l.jerk_m_s3, l.rot_jerk_rad_s3),
    }
}

/// Braking after an abort: from the path parameter's state `(s, v, a)` to rest within
/// the move's acceleration and jerk limits, as three constant-jerk pieces (the
/// time-optimal transfer to zero velocity that franka-rs's OTG also plans). Freezing
/// the setpoint instead would ask for an instant stop, which a Panda answers with a
/// reflex (`cartesian_motion_generator_velocity_discontinuity`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Brake {
    /// `(jerk, duration)` of each piece.
    pieces: [(f64, f64); 3],
    start: (f64, f64, f64),
    elapsed: f64,
}

impl Brake {
    /// A brake from position `s`, velocity `v` and acceleration `a` (per second) under
    /// `a_max` and `j_max` (> 0; anything else is taken as 1e6, i.e. unconstrained).
    #[must_use]
    pub fn new(s: f64, v: f64, a: f64, a_max: f64, j_max: f64) -> Self {
        let limit = |x: f64| if x.is_finite() && x > 0.0 { x } else { 1e6 };
        let (a_max, j_max) = (limit(a_max), limit(j_max));
        let v = if v.is_finite() { v } else { 0.0 };
        let a = if a.is_finite() {
            a.clamp(-a_max, a_max)
        } else {
            0.0
        };
        // Brake in the direction that also cancels what the acceleration alone would
        // add by ramping to zero (a|a| / 2j); in that frame the transfer decelerates.
        let dv = -v;
        let sign = 1.0f64.copysign(dv - a * a.abs() / (2.0 * j_max));
        let (dv, a0) = (sign * dv, sign * a);
        let a_peak = (j_max * dv + 0.5 * a0 * a0).max(0.0).sqrt().min(a_max);
        let t1 = ((a_peak - a0) / j_max).max(0.0);
        let t3 = a_peak / j_max;
        let t2 = if a_peak > 0.0 {
            ((dv - (2.0 * a_peak * a_peak - a0 * a0) / (2.0 * j_max)) / a_peak).max(0.0)
        } else {
            0.0
        };
        Self {
            pieces: [(sign * j_max, t1), (0.0, t2), (-sign * j_max, t3)],
            start: (s, v, a),
            elapsed: 0.0,
        }
    }

    /// Whether it comes to rest at or before path position `end` (the move's target).
    #[must_use]
    pub fn stops_before(&self, end: f64) -> bool {
        self.state_at(self.duration()).0 <= end + 1e-12
    }

    /// How long braking takes, s.
    #[must_use]
    pub fn duration(&self) -> f64 {
        self.pieces.iter().map(|p| p.1).sum()
    }

    /// Whether the path is at rest.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.elapsed >= self.duration()
    }

    /// `(s, v, a)` at `t` seconds after the abort (at rest after the last piece).
    #[must_use]
    pub fn state_at(&self, t: f64) -> (f64, f64, f64) {
        let (mut p, mut v, mut a) = self.start;
        let mut left = t.max(0.0);
        for &(jerk, duration) in &self.pieces {
            let dt = left.min(duration);
            p += v * dt + a * dt * dt / 2.0 + jerk * dt * dt * dt / 6.0;
            v += a * dt + jerk * dt * dt / 2.0;
            a += jerk * dt;
            left -= dt;
        }
        if t >= self.duration() {
            // The pieces end at rest up to rounding: do not creep on it.
            (v, a) = (0.0, 0.0);
        }
        (p, v, a)
    }

    /// Advance by `dt` seconds (ignored unless finite and positive); the new position.
    pub fn step(&mut self, dt: f64) -> f64 {
        if dt.is_finite() && dt > 0.0 {
            self.elapsed += dt;
        }
        self.state_at(self.elapsed).0
    }
}

fn state_of(s: &franka::RobotState, clock: &dyn Clock) -> ArmState {
    let f = s.O_F_ext_hat_K;
    ArmState {
        t: clock.now(),
        base_from_finger: ArmPose::from_matrix(&s.O_T_EE),
        external_wrench: Some(Wrench {
            force_n: [f[0], f[1], f[2]],
            torque_nm: [f[3], f[4], f[5]],
        }),
        faulted: s.robot_mode == franka::RobotMode::Reflex || s.current_errors.any(),
        command_success_rate: Some(s.control_command_success_rate),
    }
}

/// Cycles libfranka's `control_command_success_rate` is taken over: before that many
/// cycles of a move it describes fewer commands than it says.
const SUCCESS_RATE_WINDOW: usize = 100;

/// The share of commands that reached the robot over a move, from the rate the robot
/// reports in each cycle of it: the lowest once a full window has passed (a dip in the
/// middle of a move counts), else the last reported (a move shorter than the window).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SuccessRate {
    /// Control cycles recorded.
    pub cycles: usize,
    last: Option<f64>,
    lowest_full: Option<f64>,
}

impl SuccessRate {
    /// One control cycle's reported rate (NaN is kept: it fails every check).
    pub fn record(&mut self, rate: f64) {
        self.cycles += 1;
        self.last = Some(rate);
        if self.cycles >= SUCCESS_RATE_WINDOW {
            self.lowest_full = Some(lower(self.lowest_full, rate));
        }
    }

    /// The move's rate, `None` before any cycle.
    #[must_use]
    pub fn rate(&self) -> Option<f64> {
        self.lowest_full.or(self.last)
    }
}

/// The lower of a kept value and a new one; NaN is lowest (it fails every check).
#[must_use]
pub fn lower(kept: Option<f64>, new: f64) -> f64 {
    match kept {
        Some(k) if k.is_nan() || k <= new => k,
        _ => new,
    }
}

/// One move's bookkeeping on the robot thread: whether it is cancelled, the share of
/// commands that arrived, and where the measured pose is published.
struct MoveJob<'a> {
    cancel: &'a Cancel,
    generation: u64,
    success: SuccessRate,
    feed: &'a FeedTx,
    clock: &'a dyn Clock,
}

fn run_move(
    robot: &franka::Robot,
    target: &ArmPose,
    speed: f64,
    limits: &MotionLimits,
    joints: &JointCheck,
    job: &mut MoveJob<'_>,
) -> Result<(), DeviceError> {
    let start = robot.read_once().map_err(err)?;
    let from = ArmPose::from_matrix(&start.O_T_EE_c);
    let dist = from.distance_to(target);
    let angle = from.angle_to(target);
    let mut path = path_limits(dist, angle, speed, limits);
    let mut brake_path = path_limits(dist, angle, speed, &limits.braking());
    // Slowed (or refused) here where a joint would turn faster, or speed up or jerk
    // harder, than its limits allow: the robot would abort the motion (FR3: velocity
    // limits that depend on the joint's position).
    if let Some((kin, robot_kind)) = joints {
        let (scale, brake_scale) = reach::path_and_brake_scales(
            kin,
            *robot_kind,
            &start.q,
            &from,
            target,
            [path.max_velocity, path.max_acceleration, path.max_jerk],
            [brake_path.max_acceleration, brake_path.max_jerk],
        )
        .map_err(|e| DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: format!("move refused before it was sent: {e}"),
        })?;
        if scale.velocity < 1.0 || scale.acceleration < 1.0 || scale.jerk < 1.0 {
            tracing::debug!(
                "franka: move {} slowed to {:.0} % of its speed, {:.0} % of its acceleration and {:.0} % of its jerk to keep every joint within {:.0} % of its limits",
                job.generation,
                scale.velocity * 100.0,
                scale.acceleration * 100.0,
                scale.jerk * 100.0,
                reach::VELOCITY_MARGIN * 100.0
            );
            path.max_velocity *= scale.velocity;
            path.max_acceleration *= scale.acceleration;
            path.max_jerk *= scale.jerk;
        }
        // An abort brakes within the same joint limits as the move.
        brake_path.max_acceleration *= brake_scale.acceleration;
        brake_path.max_jerk *= brake_scale.jerk;
    }
    let mut otg = franka::Otg::new(0.0, path).map_err(err)?;
    otg.set_target(1.0).map_err(err)?;
    let mut seed: Option<ArmPose> = None;
    let mut brake: Option<Brake> = None;
    let mut aborted = false;
    let target = *target;
    robot
        .control_cartesian_pose(
            |state, dt| {
                // Seed from the commanded pose of the first cycle.
                let a = *seed.get_or_insert_with(|| ArmPose::from_matrix(&state.O_T_EE_c));
                job.success.record(state.control_command_success_rate);
                if job.success.cycles % FEED_EVERY == 1 {
                    job.feed
                        .send_replace(Some((job.clock.now(), ArmPose::from_matrix(&state.O_T_EE))));
                }
                // An abort ramps down within the limits; the motion ends at rest. A brake
                // that would only stop past the target is not used: cut off there, it
                // would ask for an instant stop (a reflex); the move's own plan, already
                // slowing, stops at the target sooner and within the move's limits.
                if !aborted && job.cancel.is_cancelled(job.generation) {
                    aborted = true;
                    let b = Brake::new(
                        otg.position(),
                        otg.velocity(),
                        otg.acceleration(),
                        brake_path.max_acceleration,
                        brake_path.max_jerk,
                    );
                    if b.stops_before(1.0) {
                        brake = Some(b);
                    }
                }
                let (s, done) = match brake.as_mut() {
                    Some(b) => (b.step(dt.as_secs_f64()).clamp(0.0, 1.0), b.finished()),
                    None => {
                        let s = otg.step(dt.as_secs_f64());
                        (s, s >= 1.0 - 1e-9 && otg.velocity().abs() < 1e-9)
                    }
                };
                let cmd = franka::CartesianPose::new(a.slerp(&target, s).to_matrix());
                if done {
                    franka::motion_finished(cmd)
                } else {
                    cmd
                }
            },
            franka::ControllerMode::CartesianImpedance,
            // No client-side rate limiter (libfranka 0.21's default: "it could distort
            // your motion"). The plan above is within the limits already and a function
            // of the robot's clock alone, so after a lost cycle the command is where the
            // robot's extrapolation is. The limiter instead steps each command from the
            // pose and derivatives the last state reported, and where those two disagree
            // (franka-sim packing a state while it applies a command) it brakes a smooth
            // plan into the jump it is there to prevent: 17 m/s² read, limit 9.
            false,
            franka::MAX_CUTOFF_FREQUENCY,
        )
        .map_err(err)
}

/// The kinematics each move is checked with against the joints' velocity limits
/// (`None`: not checked, as in tests of the control loop alone).
type JointCheck = Option<(reach::Kinematics, reach::Robot)>;

fn worker(
    robot: franka::Robot,
    rx: mpsc::Receiver<Cmd>,
    limits: MotionLimits,
    joints: JointCheck,
    cancel: Arc<Cancel>,
    clock: Arc<dyn Clock>,
    feed: FeedTx,
) {
    let state = |r: &franka::Robot| {
        let s = r
            .read_once()
            .map_err(err)
            .map(|s| state_of(&s, clock.as_ref()))?;
        feed.send_replace(Some((s.t, s.base_from_finger)));
        Ok(s)
    };
    while let Ok(cmd) = rx.recv() {
        match cmd {
            Cmd::Move {
                target,
                speed,
                generation,
                reply,
            } => {
                // Cancelled while it waited: it never reaches the robot.
                if cancel.is_cancelled(generation) {
                    tracing::debug!("franka: move {generation} cancelled before it started");
                    let _ = reply.send(Err(DeviceError::InvalidCommand {
                        device: DEVICE.into(),
                        message: format!("move {generation} was cancelled before it started"),
                    }));
                    continue;
                }
                let mut job = MoveJob {
                    cancel: &cancel,
                    generation,
                    success: SuccessRate::default(),
                    feed: &feed,
                    clock: clock.as_ref(),
                };
                let began = std::time::Instant::now();
                let moved = run_move(&robot, &target, speed, &limits, &joints, &mut job);
                // Where a sample's time goes on a robot: each move's speed and duration
                // (`RUST_LOG=softtouch_drivers::franka=debug`).
                tracing::debug!(
                    "franka: move {generation} at {speed} m/s took {:.0} ms over {} control cycles{}",
                    began.elapsed().as_secs_f64() * 1000.0,
                    job.success.cycles,
                    if moved.is_ok() { "" } else { " (failed)" }
                );
                let r = moved.and_then(|()| state(&robot)).map(|s| ArmState {
                    command_success_rate: job.success.rate(),
                    ..s
                });
                let _ = reply.send(r);
            }
            Cmd::State { reply } => {
                let _ = reply.send(state(&robot));
            }
            Cmd::Recover { reply } => {
                let _ = reply.send(robot.automatic_error_recovery().map_err(err));
            }
            Cmd::Stop { reply } => {
                let _ = reply.send(robot.stop().map_err(err));
            }
        }
    }
}

/// Cancels its move if the move's future is dropped before it completes.
struct CancelOnDrop<'a> {
    cancel: &'a Cancel,
    generation: u64,
    armed: bool,
}

impl Drop for CancelOnDrop<'_> {
    fn drop(&mut self) {
        if self.armed {
            self.cancel.cancel_through(self.generation);
        }
    }
}

/// Whether the robot holds the end effector and payload it was given: what a state
/// read reports beside what was set (`NE_T_EE`, the load's mass and centre of mass).
/// A robot that accepted `set_ee` but reports another frame would put every commanded
/// pose off by the difference.
pub fn check_configured(
    config: &FrankaConfig,
    ne_t_ee: &[f64; 16],
    m_load: f64,
    f_x_cload: &[f64; 3],
) -> Result<(), String> {
    const TOL: f64 = 1e-6;
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= TOL);
    if let Some(want) = &config.ne_t_ee
        && !close(want, ne_t_ee)
    {
        return Err(format!(
            "set_ee was sent but the robot reports NE_T_EE translation ({:.4}, {:.4}, {:.4}) m, expected ({:.4}, {:.4}, {:.4}) m",
            ne_t_ee[12], ne_t_ee[13], ne_t_ee[14], want[12], want[13], want[14]
        ));
    }
    if let Some((mass, com, _)) = &config.payload
        && !((m_load - mass).abs() <= TOL && close(com, f_x_cload))
    {
        return Err(format!(
            "set_load was sent but the robot reports a load of {m_load} kg at {f_x_cload:?} m, expected {mass} kg at {com:?} m"
        ));
    }
    Ok(())
}

/// What connect sets before any motion: the end effector, the payload, the collision
/// thresholds (in that order: the thresholds act on the estimate the other two shape);
/// then the end effector and payload are read back.
fn configure(robot: &franka::Robot, config: &FrankaConfig) -> Result<(), DeviceError> {
    if let Some(ne_t_ee) = config.ne_t_ee {
        robot.set_ee(ne_t_ee).map_err(err)?;
    }
    if let Some((mass, com, inertia)) = config.payload {
        robot.set_load(mass, com, inertia).map_err(err)?;
    }
    if config.ne_t_ee.is_some() || config.payload.is_some() {
        let s = robot.read_once().map_err(err)?;
        check_configured(config, &s.NE_T_EE, s.m_load, &s.F_x_Cload).map_err(|message| {
            DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message,
            }
        })?;
    }
    // The stiffness frame at the end effector: the external wrench the guard can
    // cross-check is then the finger's, not wherever Desk left K.
    robot.set_k(IDENTITY).map_err(err)?;
    let s = robot.read_once().map_err(err)?;
    check_stiffness_frame(&s.EE_T_K).map_err(|message| DeviceError::InvalidCommand {
        device: DEVICE.into(),
        message,
    })?;
    let (upper_q, lower_q) =
        joint_thresholds(&config.joint_torque_thresholds_nm).map_err(|message| {
            DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message,
            }
        })?;
    let (f, t) = (config.reflex_force_n, config.reflex_torque_nm);
    let lower_f = [f * 0.5, f * 0.5, f * 0.5, t * 0.5, t * 0.5, t * 0.5];
    let upper_f = [f, f, f, t, t, t];
    robot
        .set_collision_behavior_simple(lower_q, upper_q, lower_f, upper_f)
        .map_err(err)
}

/// The arm's kinematics with its end effector as the robot reports it: its `O_T_EE`
/// against the model's flange at its joints. On a robot this is `F_T_EE`; a simulator
/// whose reported frame is not the documented flange (franka-sim's link7, TESTING.md)
/// is taken at its word.
fn robot_kinematics(robot: &franka::Robot) -> Result<(reach::Kinematics, [f64; 7]), DeviceError> {
    let s = robot.read_once().map_err(err)?;
    let kin = reach::Kinematics::new(IDENTITY);
    let flange = kin.pose(&s.q);
    let reported = ArmPose::from_matrix(&s.O_T_EE);
    let f_t_ee = flange.inverse().compose(&reported);
    let told = ArmPose::from_matrix(&s.F_T_EE);
    if f_t_ee.distance_to(&told) > 1e-3 || f_t_ee.angle_to(&told) > 0.01 {
        tracing::warn!(
            "franka: the robot's O_T_EE is {:.1} mm and {:.2} rad from its model's flange · F_T_EE: the reach and joint speed checks take the pose it reports",
            f_t_ee.distance_to(&told) * 1000.0,
            f_t_ee.angle_to(&told)
        );
    }
    Ok((kin.with_end_effector(f_t_ee.to_matrix()), s.q))
}

/// The route of `config` from the joints `q` the arm is at, against the limits of
/// `kind`; refused before any motion.
fn check_reach(
    kin: &reach::Kinematics,
    kind: reach::Robot,
    q: &[f64; 7],
    config: &FrankaConfig,
    limits: &MotionLimits,
) -> Result<(), DeviceError> {
    if config.route.is_empty() {
        return Ok(());
    }
    reach::check_route(kin, kind, q, &config.route, limits.rot_speed_rad_s)
        .map(|_| ())
        .map_err(|e| DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: format!(
                "the rig's workspace is beyond the {}'s limits from its joints now, refused before any motion: {e}",
                kind.name()
            ),
        })
}

/// Whether the robot reports the stiffness frame at the end effector (`EE_T_K` the
/// identity), as connect set it.
pub fn check_stiffness_frame(ee_t_k: &[f64; 16]) -> Result<(), String> {
    if ee_t_k
        .iter()
        .zip(IDENTITY)
        .all(|(a, b)| (a - b).abs() <= 1e-6)
    {
        Ok(())
    } else {
        Err(format!(
            "set_k sent the identity but the robot reports EE_T_K translation ({:.4}, {:.4}, {:.4}) m: the external wrench would not be the finger's",
            ee_t_k[12], ee_t_k[13], ee_t_k[14]
        ))
    }
}

/// The collision behaviour's joint torque thresholds, `(upper, lower)` N·m: the
/// configured upper ones (each above 0 and below the joint's torque limit, else the
/// joint reflex could never act) and half of each as the lower.
pub fn joint_thresholds(upper_nm: &[f64; 7]) -> Result<([f64; 7], [f64; 7]), String> {
    softtouch_schemas::rig::check_joint_thresholds(upper_nm)?;
    Ok((*upper_nm, upper_nm.map(|v| 0.5 * v)))
}

impl FrankaArm {
    /// Connect (the FCI version the robot answers with; real time as the config says),
    /// set the end effector, payload and collision behaviour, and start the robot
    /// thread.
    pub async fn connect(config: FrankaConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        if !(config.reflex_force_n.is_finite() && config.reflex_force_n > 0.0) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "reflex_force_n must be positive".into(),
            });
        }
        let (tx, rx) = mpsc::channel::<Cmd>();
        let (ready_tx, ready_rx) = oneshot::channel::<Result<(), DeviceError>>();
        let cancel = Arc::new(Cancel::default());
        let (cancel2, clock2) = (cancel.clone(), clock.clone());
        let (feed_tx, feed) = watch::channel(None);
        let feed_tx = Arc::new(feed_tx);
        std::thread::Builder::new()
            .name("franka".into())
            .spawn(move || {
                // One core for the 1 kHz loop: it does not migrate while the other
                // core decodes frames and encodes PNGs.
                match crate::realtime::pin_to_last_core() {
                    Ok(core) => tracing::info!("franka: control thread pinned to core {core}"),
                    Err(e) => tracing::warn!("franka: control thread not pinned: {e}"),
                }
                let realtime = match config.realtime {
                    softtouch_schemas::Realtime::Enforce => franka::RealtimeConfig::Enforce,
                    softtouch_schemas::Realtime::Ignore => {
                        tracing::warn!(
                            "franka: real time is not enforced (rig `realtime = \"ignore\"`): the 1 kHz loop will miss cycles under load and may end in communication_constraints_violation"
                        );
                        franka::RealtimeConfig::Ignore
                    }
                };
                // FCI v10 (FR3) first, then v5 (Panda) when the robot answers so.
                let options = franka::RobotOptions::new(realtime)
                    .with_version(franka::VersionPolicy::Auto);
                let robot = match franka::Robot::with_options(&config.address, options) {
                    Ok(r) => r,
                    Err(e) => {
                        let _ = ready_tx.send(Err(err(e)));
                        return;
                    }
                };
                // The robot's own Cartesian limits, by the FCI version it answered with.
                let kind = reach::Robot::of(robot.fci_version());
                let limits = config
                    .motion_margin
                    .map_or(config.limits, |m| MotionLimits::for_robot(kind, m));
                let set = configure(&robot, &config)
                    .and_then(|()| robot_kinematics(&robot))
                    .and_then(|(kin, q)| {
                        check_reach(&kin, kind, &q, &config, &limits)?;
                        Ok(kin)
                    });
                let kin = match set {
                    Ok(kin) => {
                        let _ = ready_tx.send(Ok(()));
                        kin
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                tracing::info!(
                    "franka: {} moves at {:.2} m/s, {:.1} m/s², {:.2} rad/s, {:.1} rad/s² at most",
                    kind.name(),
                    limits.max_speed_m_s,
                    limits.accel_m_s2,
                    limits.rot_speed_rad_s,
                    limits.rot_accel_rad_s2
                );
                worker(
                    robot,
                    rx,
                    limits,
                    Some((kin, kind)),
                    cancel2,
                    clock2,
                    feed_tx,
                );
            })
            .map_err(|e| DeviceError::Link {
                device: DEVICE.into(),
                message: format!("cannot start the robot thread: {e}"),
            })?;
        ready_rx.await.map_err(|_| gone())??;
        Ok(Self {
            tx,
            cancel,
            generation: 0,
            clock,
            feed,
        })
    }

    async fn ask<T>(&self, make: impl FnOnce(Reply<T>) -> Cmd) -> Result<T, DeviceError> {
        let (reply, rx) = oneshot::channel();
        self.tx.send(make(reply)).map_err(|_| gone())?;
        rx.await.map_err(|_| gone())?
    }

    /// The clock the states are stamped with.
    #[must_use]
    pub fn clock(&self) -> &Arc<dyn Clock> {
        &self.clock
    }
}

#[async_trait]
impl Arm for FrankaArm {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        if !(target.is_valid()
            && speed_m_s.is_finite()
            && speed_m_s > 0.0
            && speed_m_s <= MAX_SPEED_M_S)
        {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!(
                    "invalid target {target:?} or speed {speed_m_s} m/s (at most {MAX_SPEED_M_S})"
                ),
            });
        }
        self.generation += 1;
        let generation = self.generation;
        let target = *target;
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(Cmd::Move {
                target,
                speed: speed_m_s,
                generation,
                reply,
            })
            .map_err(|_| gone())?;
        let mut guard = CancelOnDrop {
            cancel: &self.cancel,
            generation,
            armed: true,
        };
        let r = rx.await.map_err(|_| gone())?;
        guard.armed = false;
        r
    }

    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        self.ask(|reply| Cmd::State { reply }).await
    }

    async fn recover(&mut self) -> Result<(), DeviceError> {
        self.ask(|reply| Cmd::Recover { reply }).await
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        // Every move sent so far: the running one brakes, queued ones never start.
        self.cancel.cancel_through(self.generation);
        self.ask(|reply| Cmd::Stop { reply }).await
    }

    fn pose_feed(&self) -> Option<PoseFeed> {
        Some(self.feed.clone())
    }
}

pub mod reach;
use reach::IDENTITY;

#[cfg(test)]
mod tests;
