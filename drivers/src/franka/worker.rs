//! The robot thread: franka-rs's synchronous 1 kHz loop, fed commands over a channel;
//! one move's control loop, its cancellation by generation, the share of commands that
//! arrived, and the measured pose's feed.

use super::*;

pub(super) type Reply<T> = oneshot::Sender<Result<T, DeviceError>>;

pub(super) enum Cmd {
    /// One motion through legs (pose, speed m/s) along a straight line
    /// ([`run_path`]); a plain move is one leg.
    Move {
        legs: Vec<(ArmPose, f64)>,
        /// This move's number: cancelled once [`Cancel::through`] reaches it.
        generation: u64,
        /// The state at the end, and when each leg's end was commanded.
        reply: Reply<(ArmState, Vec<TimestampNs>)>,
    },
    /// A joint-space move ([`super::joints`]).
    MoveJoints {
        q: [f64; 7],
        generation: u64,
        reply: Reply<ArmState>,
    },
    State {
        reply: Reply<ArmState>,
    },
    Joints {
        reply: Reply<[f64; 7]>,
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

impl std::fmt::Debug for Cmd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Move { .. } => "Move",
            Self::MoveJoints { .. } => "MoveJoints",
            Self::State { .. } => "State",
            Self::Joints { .. } => "Joints",
            Self::Recover { .. } => "Recover",
            Self::Stop { .. } => "Stop",
        })
    }
}

pub(super) fn err(e: franka::FrankaError) -> DeviceError {
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

pub(super) fn gone() -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: "the robot thread has stopped".into(),
    }
}

pub(super) fn state_of(s: &franka::RobotState, clock: &dyn Clock) -> ArmState {
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
pub(super) const SUCCESS_RATE_WINDOW: usize = 100;

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
pub(super) struct MoveJob<'a> {
    cancel: &'a Cancel,
    generation: u64,
    success: SuccessRate,
    feed: &'a FeedTx,
    clock: &'a dyn Clock,
}

impl MoveJob<'_> {
    /// One control cycle's bookkeeping: the share of commands that arrived, and the
    /// measured pose published every [`FEED_EVERY`] cycles.
    pub(super) fn tick(&mut self, state: &franka::RobotState) {
        self.success.record(state.control_command_success_rate);
        if self.success.cycles % FEED_EVERY == 1 {
            self.feed.send_replace(Some((
                self.clock.now(),
                ArmPose::from_matrix(&state.O_T_EE),
            )));
        }
    }

    /// Whether this move was cancelled (dropped, or [`Arm::stop`]).
    pub(super) fn cancelled(&self) -> bool {
        self.cancel.is_cancelled(self.generation)
    }
}

/// How far a leg's end may lie off the line from where the robot is to the last leg's
/// end and still be blended, m and rad: a leg's end only says where its speed changes
/// (the commanded poses are on the line), and the robot's commanded pose at rest is
/// the last target only to its own rounding (about 1e-5 rad seen against franka-sim).
const ON_LINE_M: f64 = 5e-4;
const ON_LINE_RAD: f64 = 5e-3;

/// Whether `legs` (poses and speeds) lie in order along the straight line from `from`
/// to the last one, each pose on the line (within [`ON_LINE_M`] and [`ON_LINE_RAD`]):
/// their ends as path parameters, else `None` (the legs are then moved one by one).
pub(super) fn collinear_ends(from: &ArmPose, legs: &[(ArmPose, f64)]) -> Option<Vec<f64>> {
    let target = legs.last()?.0;
    let dist = from.distance_to(&target);
    let angle = from.angle_to(&target);
    if !(dist > 1e-6 && dist.is_finite() && angle.is_finite()) {
        return None;
    }
    let mut ends = Vec::with_capacity(legs.len());
    for (pose, _) in legs {
        let s = from.distance_to(pose) / dist;
        let on = from.slerp(&target, s);
        let after = ends.last().map_or(0.0, |e| *e);
        if !(s.is_finite()
            && s > after
            && on.distance_to(pose) < ON_LINE_M
            && on.angle_to(pose) < ON_LINE_RAD)
        {
            return None;
        }
        ends.push(s);
    }
    Some(ends)
}

/// One motion through `legs` (poses along one straight line from where the robot is,
/// each at up to its speed, [`super::blend`]); a single leg is a plain move. When each
/// leg's end was commanded, on the rig's clock. Legs that are not along one line are
/// moved one by one.
pub(super) fn run_path(
    robot: &franka::Robot,
    legs: &[(ArmPose, f64)],
    limits: &MotionLimits,
    joints: &JointCheck,
    job: &mut MoveJob<'_>,
) -> Result<Vec<TimestampNs>, DeviceError> {
    let Some(&(target, _)) = legs.last() else {
        return Ok(Vec::new());
    };
    let start = robot.read_once().map_err(err)?;
    let from = ArmPose::from_matrix(&start.O_T_EE_c);
    let ends = if legs.len() == 1 {
        vec![1.0]
    } else {
        match collinear_ends(&from, legs) {
            Some(ends) => ends,
            None => {
                tracing::debug!(
                    "franka: move {}: its legs are not along one line from {from:?}; moved one by one",
                    job.generation
                );
                let mut stamps = Vec::with_capacity(legs.len());
                for leg in legs {
                    stamps.extend(run_path(
                        robot,
                        std::slice::from_ref(leg),
                        limits,
                        joints,
                        job,
                    )?);
                }
                return Ok(stamps);
            }
        }
    };
    let fastest = legs.iter().map(|l| l.1).fold(0.0, f64::max);
    let dist = from.distance_to(&target);
    let angle = from.angle_to(&target);
    let mut path = path_limits(dist, angle, fastest, limits);
    let mut brake_path = path_limits(dist, angle, fastest, &limits.braking());
    // Slowed (or refused) here where a joint would turn faster, or speed up or jerk
    // harder, than its limits allow: the robot would abort the motion (FR3: velocity
    // limits that depend on the joint's position). Checked at the fastest leg's speed.
    if let Some((kin, robot_kind)) = joints {
        let (scale, brake_scale) = reach::path_and_brake_scales(
            kin,
            *robot_kind,
            &start.q,
            &from,
            &target,
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
    let k = limits.test_rate_scale;
    if k.is_finite() && k > 0.0 && (k - 1.0).abs() > f64::EPSILON {
        // Test only (1 on every rig): a broken plan, its acceleration and jerk `k`
        // times the robot's own Cartesian limits, every check above skipped.
        let robot_kind = joints.as_ref().map_or(reach::Robot::Fr3, |(_, r)| *r);
        let [_, a, j, _, ra, rj] = cartesian_limits(robot_kind);
        let broken = MotionLimits {
            accel_m_s2: a * k,
            jerk_m_s3: j * k,
            rot_accel_rad_s2: ra * k,
            rot_jerk_rad_s3: rj * k,
            ..*limits
        };
        let p = path_limits(dist, angle, fastest, &broken);
        path.max_acceleration = p.max_acceleration;
        path.max_jerk = p.max_jerk;
    }
    // Each leg's speed in path units, within the fastest leg's as the joints allow it
    // (a joint's velocity is the path's times a factor of the pose alone, so every
    // speed below the allowed one is allowed).
    let legs_s: Vec<(f64, f64)> = ends
        .iter()
        .zip(legs)
        .map(|(end, (_, speed))| {
            let v = path_limits(dist, angle, *speed, limits).max_velocity;
            (*end, v.min(path.max_velocity))
        })
        .collect();
    // Each leg's brake within the joints' limits at that leg's own speed: the room a
    // joint has to brake shrinks with the speed squared (the path's curvature), so the
    // fast leg's share would stretch a brake in the slow legs, where the guard trips
    // (franka-sim: 20 mm from 0.2 m/s against the 18 mm bound).
    let mut leg_brakes = vec![(brake_path.max_acceleration, brake_path.max_jerk); legs_s.len()];
    if let Some((kin, robot_kind)) = joints {
        let unscaled = path_limits(dist, angle, fastest, &limits.braking());
        for (k, (_, v)) in legs_s.iter().enumerate() {
            if let Ok((_, b)) = reach::path_and_brake_scales(
                kin,
                *robot_kind,
                &start.q,
                &from,
                &target,
                [*v, path.max_acceleration, path.max_jerk],
                [unscaled.max_acceleration, unscaled.max_jerk],
            ) {
                leg_brakes[k] = (
                    unscaled.max_acceleration * b.acceleration,
                    unscaled.max_jerk * b.jerk,
                );
            }
        }
    }
    let mut blend =
        super::blend::Blend::new(legs_s, path).ok_or_else(|| DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: format!("legs {legs:?} do not form a path from {from:?}"),
        })?;
    let leg_ends: Vec<f64> = blend.ends().collect();
    let mut stamps: Vec<TimestampNs> = Vec::with_capacity(legs.len());
    let mut seed: Option<ArmPose> = None;
    let mut brake: Option<Brake> = None;
    let mut aborted = false;
    robot
        .control_cartesian_pose(
            |state, dt| {
                // Seed from the commanded pose of the first cycle.
                let a = *seed.get_or_insert_with(|| ArmPose::from_matrix(&state.O_T_EE_c));
                job.tick(state);
                // An abort ramps down within the limits; the motion ends at rest. A brake
                // that would only stop past the target is not used: cut off there, it
                // would ask for an instant stop (a reflex); the move's own plan, already
                // slowing, stops at the target sooner and within the move's limits.
                if !aborted && job.cancelled() {
                    aborted = true;
                    let o = blend.otg();
                    let (brake_accel, brake_jerk) = leg_brakes[blend.leg()];
                    let b = Brake::new(
                        o.position(),
                        o.velocity(),
                        o.acceleration(),
                        brake_accel,
                        brake_jerk,
                    );
                    if b.stops_before(1.0) {
                        brake = Some(b);
                    }
                }
                let (s, done) = match brake.as_mut() {
                    // `stops_before` holds it within [s, 1] all the way to rest.
                    Some(b) => (b.step(dt.as_secs_f64()), b.finished()),
                    None => {
                        let s = blend.step(dt.as_secs_f64());
                        (s, blend.finished())
                    }
                };
                // Each leg's end, as it is commanded (the last at rest there).
                while stamps.len() + 1 < leg_ends.len() && s >= leg_ends[stamps.len()] {
                    stamps.push(job.clock.now());
                }
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
        .map_err(err)?;
    stamps.push(job.clock.now());
    Ok(stamps)
}

/// The kinematics each move is checked with against the joints' velocity limits
/// (`None`: not checked, as in tests of the control loop alone).
pub(super) type JointCheck = Option<(reach::Kinematics, reach::Robot)>;

pub(super) fn worker(
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
                legs,
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
                let moved = run_path(&robot, &legs, &limits, &joints, &mut job);
                // Where a sample's time goes on a robot: each move's speeds and duration
                // (`RUST_LOG=softtouch_drivers::franka=debug`).
                tracing::debug!(
                    "franka: move {generation} at {:?} m/s took {:.0} ms over {} control cycles{}",
                    legs.iter().map(|l| l.1).collect::<Vec<_>>(),
                    began.elapsed().as_secs_f64() * 1000.0,
                    job.success.cycles,
                    if moved.is_ok() { "" } else { " (failed)" }
                );
                let r = moved.and_then(|stamps| {
                    state(&robot).map(|s| {
                        let s = ArmState {
                            command_success_rate: job.success.rate(),
                            ..s
                        };
                        (s, stamps)
                    })
                });
                let _ = reply.send(r);
            }
            Cmd::MoveJoints {
                q,
                generation,
                reply,
            } => {
                if cancel.is_cancelled(generation) {
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
                let kind = joints
                    .as_ref()
                    .map_or_else(|| reach::Robot::of(robot.fci_version()), |(_, k)| *k);
                let moved = super::joints::run_joint_move(&robot, &q, kind, &mut job);
                let r = moved.and_then(|()| state(&robot)).map(|s| ArmState {
                    command_success_rate: job.success.rate(),
                    ..s
                });
                let _ = reply.send(r);
            }
            Cmd::State { reply } => {
                let _ = reply.send(state(&robot));
            }
            Cmd::Joints { reply } => {
                let _ = reply.send(robot.read_once().map(|s| s.q).map_err(err));
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
