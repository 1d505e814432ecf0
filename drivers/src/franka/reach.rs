//! Whether the arm can reach a rig's poses within the robot's limits, checked before
//! anything moves (`config check`, and at connect from the joints the arm is at).
//!
//! Each pose is solved for the joints by damped least squares on franka-rs's
//! kinematics (the FER's, which the FR3 shares), and every straight move between the
//! poses is followed in small steps as the robot's own Cartesian motion follows it:
//! each joint against its range, and its velocity at the move's speed against the
//! position-dependent velocity limits. On an FR3 those limits shrink toward both ends
//! of each joint's range (`v ≤ √(2·a·(q_max − q)) − offset`), so a move that turns a
//! joint quickly toward its end is aborted by the robot with
//! `joint_velocity_violation`; this names it first.
//!
//! The robot's own inverse kinematics is not published: a redundant arm may take
//! another elbow than the one found here. A pose refused here is out of reach or too
//! fast on the way found from the arm's joints; one accepted is very likely fine, and
//! the robot remains the last judge.

use nalgebra::{Matrix6, SMatrix, Vector3, Vector6};
use softtouch_schemas::ArmPose;
use softtouch_schemas::rig::WorkspaceBounds;

/// The robot model whose joint limits apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Robot {
    /// Franka Research 3 (FCI v10): position-dependent velocity limits.
    Fr3,
    /// Franka Emika Robot / Panda (FCI v5): constant velocity limits.
    Fer,
}

impl Robot {
    /// Its name in messages.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Fr3 => "FR3",
            Self::Fer => "Panda",
        }
    }

    /// Joint position limits `(lower, upper)`, rad (libfranka's, as franka-rs ports them).
    #[must_use]
    pub const fn position_limits(self) -> ([f64; 7], [f64; 7]) {
        match self {
            Self::Fr3 => franka::rate_limiting::JOINT_POSITION_LIMITS,
            Self::Fer => franka::rate_limiting::fer::JOINT_POSITION_LIMITS,
        }
    }

    /// Joint velocity limits `(lower, upper)` at `q`, rad/s.
    #[must_use]
    pub fn velocity_limits(self, q: &[f64; 7]) -> ([f64; 7], [f64; 7]) {
        match self {
            Self::Fr3 => (
                franka::compute_lower_limits_joint_velocity(q),
                franka::compute_upper_limits_joint_velocity(q),
            ),
            Self::Fer => (
                franka::rate_limiting::fer::MIN_JOINT_VELOCITY,
                franka::rate_limiting::fer::MAX_JOINT_VELOCITY,
            ),
        }
    }

    /// The robot an FCI version serves.
    #[must_use]
    pub const fn of(version: franka::FciVersion) -> Self {
        match version {
            franka::FciVersion::V10 => Self::Fr3,
            franka::FciVersion::V5 => Self::Fer,
        }
    }
}

/// The share of each joint velocity limit a planned move may use: the robot's own
/// inverse kinematics is not the one here, and its OTG overshoots the cruise speed.
pub const VELOCITY_MARGIN: f64 = 0.8;

/// The share of each joint acceleration limit a planned move may use (jerk has its
/// own, [`JERK_MARGIN`]). The
/// robot judges a Cartesian pose stream on the joint acceleration and jerk of its own
/// inverse kinematics of each commanded pose, differenced at 1 kHz; its redundancy
/// resolution is not the one here, and a cycle lost under load is differenced against
/// an extrapolation. With 0.8 the estimate here bounded joint 4 at 8 rad/s² on a move
/// franka-sim measured at 10.9 rad/s² and aborted (FR3 limit 10; seen once in CI on
/// a busy 2-core machine, 2026-11-28): 0.5 leaves twice the room.
pub const RATE_MARGIN: f64 = 0.5;

/// The share of each jerk limit, joint and Cartesian, a planned move may use. A lost
/// cycle is extrapolated at constant acceleration, and the resumed command is
/// differenced against that guess, which reads a few times the plan's jerk (franka-sim,
/// traced: joint 2 planned at about 1 700 rad/s³, at 0.5 of its limit's share, read
/// 5 583 after one lost cycle, limit 5 000). At 0.2 one lost cycle stays within the
/// limit; the ramps it lengthens last milliseconds.
pub const JERK_MARGIN: f64 = 0.2;

/// The FR3's and Panda's "ready" joints (libfranka's examples): where `config check`
/// starts when no arm tells it where it is.
pub const READY_Q: [f64; 7] = [
    0.0,
    -std::f64::consts::FRAC_PI_4,
    0.0,
    -3.0 * std::f64::consts::FRAC_PI_4,
    0.0,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_4,
];

/// One straight move of a route: to `pose` (end effector in the base frame) at
/// `speed_m_s`, named for messages.
#[derive(Debug, Clone, PartialEq)]
pub struct Leg {
    /// What the pose is (`home`, `x = 0.06 m, z = -0.06 m, θ = 3.14 rad`).
    pub name: String,
    /// The end effector's pose in the base frame.
    pub pose: ArmPose,
    /// The move's speed, m/s.
    pub speed_m_s: f64,
}

/// The arm's kinematics with its end effector: `F_T_EE` (flange to end effector,
/// column-major).
#[derive(Debug)]
pub struct Kinematics {
    model: franka::Model,
    f_t_ee: [f64; 16],
}

/// The identity transform, column-major (libfranka's layout).
pub const IDENTITY: [f64; 16] = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

impl Kinematics {
    /// The FER/FR3 kinematics with `f_t_ee` as the end effector.
    #[must_use]
    pub fn new(f_t_ee: [f64; 16]) -> Self {
        Self {
            model: franka::Model::native_fer(),
            f_t_ee,
        }
    }

    /// The same kinematics with `f_t_ee` as the end effector (the model is kept: it is
    /// parsed from a URDF).
    #[must_use]
    pub fn with_end_effector(self, f_t_ee: [f64; 16]) -> Self {
        Self { f_t_ee, ..self }
    }

    /// The end effector's pose at joints `q`.
    #[must_use]
    pub fn pose(&self, q: &[f64; 7]) -> ArmPose {
        ArmPose::from_matrix(&self.model.pose_q(
            franka::Frame::EndEffector,
            q,
            &self.f_t_ee,
            &IDENTITY,
        ))
    }

    fn jacobian(&self, q: &[f64; 7]) -> SMatrix<f64, 6, 7> {
        let j = self
            .model
            .zero_jacobian_q(franka::Frame::EndEffector, q, &self.f_t_ee, &IDENTITY);
        SMatrix::<f64, 6, 7>::from_column_slice(&j)
    }

    /// Joints that put the end effector at `target`, found from `seed` (the nearest
    /// solution it converges to), or `None` when none is found within 0.1 mm and
    /// 0.001 rad (out of reach, or a singularity on the way).
    #[must_use]
    pub fn solve(&self, target: &ArmPose, seed: &[f64; 7]) -> Option<[f64; 7]> {
        if !target.is_valid() || seed.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let want = target.normalised();
        let mut q = *seed;
        for _ in 0..200 {
            let at = self.pose(&q);
            let dp = Vector3::from(want.translation_m) - Vector3::from(at.translation_m);
            let dr = rotation_error(&want, &at);
            if dp.norm() < 1e-5 && dr.norm() < 1e-5 {
                return Some(q);
            }

            let e = Vector6::new(dp[0], dp[1], dp[2], dr[0], dr[1], dr[2]);
            let j = self.jacobian(&q);
            // Damped least squares: steady near singularities, exact away from them.
            let damping = 1e-4;
            let jjt: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * damping;
            let y = jjt.lu().solve(&e)?;
            let mut dq = j.transpose() * y;
            // Small steps: the nearest solution, not a jump to another branch.
            let step = dq.amax();
            if step > 0.2 {
                dq *= 0.2 / step;
            }
            for (qi, d) in q.iter_mut().zip(dq.iter()) {
                *qi += d;
            }
            if q.iter().any(|v| !v.is_finite()) {
                return None;
            }
        }
        let at = self.pose(&q);
        (at.distance_to(&want) < 1e-4 && at.angle_to(&want) < 1e-3).then_some(q)
    }
}

/// The rotation vector (axis × angle, base frame) that turns `at` into `want`: from
/// the quaternion `want · at⁻¹`, finite at zero angle (where a matrix's `acos` is not).
fn rotation_error(want: &ArmPose, at: &ArmPose) -> Vector3<f64> {
    let [w1, x1, y1, z1] = want.rotation_wxyz;
    let [w2, x2, y2, z2] = at.normalised().rotation_wxyz;
    // want · conj(at)
    let (x2, y2, z2) = (-x2, -y2, -z2);
    let mut w = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2;
    let mut v = Vector3::new(
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    );
    // The short way round.
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let s = v.norm();
    if s < 1e-12 {
        return 2.0 * v;
    }
    v * (2.0 * s.atan2(w) / s)
}

/// Follows `route` from joints `start_q` (the arm's, or [`READY_Q`] offline): each leg
/// a straight move from the previous pose (the first from where `start_q` puts the
/// end effector) at its speed, and rotations at `rot_speed_rad_s`. Returns the joints
/// at the end, or what would break, naming the leg's pose and the limit.
pub fn check_route(
    kin: &Kinematics,
    robot: Robot,
    start_q: &[f64; 7],
    route: &[Leg],
    rot_speed_rad_s: f64,
) -> Result<[f64; 7], String> {
    let (q_min, q_max) = robot.position_limits();
    let mut q = *start_q;
    let mut from = kin.pose(&q);
    for leg in route {
        let to = leg.pose.normalised();
        let dist = from.distance_to(&to);
        let angle = from.angle_to(&to);
        if !(dist.is_finite() && angle.is_finite()) {
            return Err(format!(
                "{}: the pose is not finite: {:?}",
                leg.name, leg.pose
            ));
        }
        // At cruise the path takes this long (the driver's path limits).
        let speed = leg.speed_m_s.max(1e-6);
        let duration_s = (dist / speed).max(angle / rot_speed_rad_s.max(1e-6));
        let steps = ((dist / 0.002).max(angle / 0.01).ceil() as usize).clamp(1, 2000);
        let dt = duration_s / steps as f64;
        for k in 1..=steps {
            let target = from.slerp(&to, k as f64 / steps as f64);
            let Some(next) = kin.solve(&target, &q) else {
                return Err(format!(
                    "{}: the arm cannot reach the pose at {:?} m on the way from {:?} m (out of reach or through a singularity)",
                    leg.name, target.translation_m, from.translation_m
                ));
            };
            for j in 0..7 {
                if next[j] < q_min[j] || next[j] > q_max[j] {
                    return Err(format!(
                        "{}: joint {} would be at {:.3} rad, outside the {}'s range [{:.4}, {:.4}] rad",
                        leg.name,
                        j + 1,
                        next[j],
                        robot.name(),
                        q_min[j],
                        q_max[j]
                    ));
                }
            }
            let (lower, upper) = robot.velocity_limits(&q);
            for j in 0..7 {
                let v = (next[j] - q[j]) / dt;
                let (lo, hi) = (lower[j] * VELOCITY_MARGIN, upper[j] * VELOCITY_MARGIN);
                if v > hi || v < lo {
                    let limit = if v > hi { upper[j] } else { lower[j] };
                    return Err(format!(
                        "{}: moving there at {} m/s and {} rad/s, joint {} would turn at {:.2} rad/s at {:.3} rad, where the {}'s limit is {:.2} rad/s ({:.0} % of it allowed); narrow the workspace's theta_rad or turn the rod frame so the wrist turns less",
                        leg.name,
                        leg.speed_m_s,
                        rot_speed_rad_s,
                        j + 1,
                        v,
                        q[j],
                        robot.name(),
                        limit,
                        VELOCITY_MARGIN * 100.0
                    ));
                }
            }
            q = next;
        }
        from = to;
    }
    Ok(q)
}

/// How much of a move's planned path limits its joints allow ([`path_scale`]): each
/// in (0, 1], 1 where the move is within the joints' limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathScale {
    /// Share of the path's velocity.
    pub velocity: f64,
    /// Share of the path's acceleration.
    pub acceleration: f64,
    /// Share of the path's jerk.
    pub jerk: f64,
}

/// Joint acceleration and jerk limits `(rad/s², rad/s³)` of `robot` (libfranka's, as
/// franka-rs ports them: the FR3's uniform, the Panda's per joint).
#[must_use]
pub const fn joint_rate_limits(robot: Robot) -> ([f64; 7], [f64; 7]) {
    match robot {
        Robot::Fr3 => (
            franka::rate_limiting::MAX_JOINT_ACCELERATION,
            franka::rate_limiting::MAX_JOINT_JERK,
        ),
        Robot::Fer => (
            franka::rate_limiting::fer::MAX_JOINT_ACCELERATION,
            franka::rate_limiting::fer::MAX_JOINT_JERK,
        ),
    }
}

/// The shares of a straight move's path limits (the path parameter s, 0 at `from` and
/// 1 at `to`: velocity `s_dot` per second, acceleration `s_ddot`, jerk `s_dddot`) at
/// which every joint stays within [`VELOCITY_MARGIN`] of its velocity limit (at its
/// position: the FR3's depend on it), within [`RATE_MARGIN`] of its acceleration limit
/// and within [`JERK_MARGIN`] of its jerk limit, followed from
/// joints `q0` (whose end effector is at or near `from`). A joint's rates are its path
/// derivatives times the path's: `q̇ = q'·ṡ`, `q̈ = q'·s̈ + q''·ṡ²`,
/// `q⃛ ≈ q'·s⃛ + 3·q''·ṡ·s̈`. The robot aborts a motion whose inverse kinematics
/// breaks these (FR3: `cartesian_motion_generator_joint_velocity_discontinuity` past
/// 10 rad/s², `..._acceleration_discontinuity` past 5000 rad/s³); the move is slowed
/// instead. What would break a joint's range, or a pose out of reach, is an error:
/// the move is refused.
pub fn path_scale(
    kin: &Kinematics,
    robot: Robot,
    q0: &[f64; 7],
    from: &ArmPose,
    to: &ArmPose,
    path: [f64; 3],
) -> Result<PathScale, String> {
    path_and_brake_scales(kin, robot, q0, from, to, path, [path[1], path[2]]).map(|(p, _)| p)
}

/// [`path_scale`], and the shares of a brake's acceleration and jerk (`brake`, per
/// second², per second³ of the path parameter) from any point of the move at its
/// scaled speed: an abort brakes within the same joint limits as the move, from one
/// walk of the path.
///
/// # Errors
/// As [`path_scale`].
pub fn path_and_brake_scales(
    kin: &Kinematics,
    robot: Robot,
    q0: &[f64; 7],
    from: &ArmPose,
    to: &ArmPose,
    path: [f64; 3],
    brake: [f64; 2],
) -> Result<(PathScale, PathScale), String> {
    let [s_dot, s_ddot, s_dddot] = path.map(f64::abs);
    let [b_ddot, b_dddot] = brake.map(f64::abs);
    if !(b_ddot.is_finite() && b_dddot.is_finite()) {
        return Err(format!("a brake on the way to {to:?} is not finite"));
    }
    let (dist, angle) = (from.distance_to(to), from.angle_to(to));
    if !(dist.is_finite() && angle.is_finite() && path.iter().all(|v| v.is_finite())) {
        return Err(format!("a move to {to:?} is not finite"));
    }
    let (q_min, q_max) = robot.position_limits();
    let (acc_max, jerk_max) = joint_rate_limits(robot);
    let steps = ((dist / 0.002).max(angle / 0.01).ceil() as usize).clamp(1, 1000);
    let ds = 1.0 / steps as f64;
    // The joints at the commanded start: the measured ones are off it where the arm
    // presses against something (impedance control), and a first step from them would
    // read as a jump.
    let Some(mut q) = kin.solve(from, q0) else {
        return Err(format!(
            "the arm cannot reach its own commanded pose {:?} m from its joints",
            from.translation_m
        ));
    };
    let mut worst_v = 0.0f64;
    // Largest |q'| and |q''| of each joint along the path.
    let (mut d1, mut d2) = ([0.0f64; 7], [0.0f64; 7]);
    let mut last_d1: Option<[f64; 7]> = None;
    for k in 1..=steps {
        let pose = from.slerp(to, k as f64 * ds);
        let Some(next) = kin.solve(&pose, &q) else {
            return Err(format!(
                "the arm cannot reach {:?} m on the way to {:?} m (out of reach or through a singularity)",
                pose.translation_m, to.translation_m
            ));
        };
        let (lower, upper) = robot.velocity_limits(&q);
        let mut dq = [0.0; 7];
        for j in 0..7 {
            if next[j] < q_min[j] || next[j] > q_max[j] {
                return Err(format!(
                    "joint {} would be at {:.3} rad, outside the {}'s range [{:.4}, {:.4}] rad",
                    j + 1,
                    next[j],
                    robot.name(),
                    q_min[j],
                    q_max[j]
                ));
            }
            dq[j] = (next[j] - q[j]) / ds;
            d1[j] = d1[j].max(dq[j].abs());
            if let Some(prev) = last_d1 {
                d2[j] = d2[j].max(((dq[j] - prev[j]) / ds).abs());
            }
            let v = dq[j] * s_dot;
            let limit = if v >= 0.0 { upper[j] } else { -lower[j] };
            if limit > 0.0 {
                worst_v = worst_v.max(v.abs() / (limit * VELOCITY_MARGIN));
            } else if v.abs() > 1e-9 {
                // At a range's end the limit towards it is zero: no speed is safe.
                return Err(format!(
                    "joint {} at {:.3} rad cannot turn further that way (the {}'s limit there is 0 rad/s)",
                    j + 1,
                    q[j],
                    robot.name()
                ));
            }
        }
        last_d1 = Some(dq);
        q = next;
    }
    let velocity = if worst_v > 1.0 { 1.0 / worst_v } else { 1.0 };
    let v = s_dot * velocity;
    // The share of `want` that joint j allows, given what the curvature takes.
    let share = |want: f64, room: f64, g1: f64| -> f64 {
        if want <= 0.0 || g1 * want <= room {
            1.0
        } else {
            // The curvature alone may take the whole limit: crawl rather than stop.
            (room / (g1 * want)).clamp(0.05, 1.0)
        }
    };
    // The shares of an acceleration and a jerk at the (scaled) speed v.
    let rates = |want_a: f64, want_j: f64| -> (f64, f64) {
        let (mut acceleration, mut jerk) = (1.0f64, 1.0f64);
        for j in 0..7 {
            let a_room = acc_max[j] * RATE_MARGIN - d2[j] * v * v;
            acceleration = acceleration.min(share(want_a, a_room, d1[j]));
        }
        let a = want_a * acceleration;
        for j in 0..7 {
            let j_room = jerk_max[j] * JERK_MARGIN - 3.0 * d2[j] * v * a;
            jerk = jerk.min(share(want_j, j_room, d1[j]));
        }
        (acceleration, jerk)
    };
    let (acceleration, jerk) = rates(s_ddot, s_dddot);
    let (brake_acceleration, brake_jerk) = rates(b_ddot, b_dddot);
    Ok((
        PathScale {
            velocity,
            acceleration,
            jerk,
        },
        PathScale {
            velocity: 1.0,
            acceleration: brake_acceleration,
            jerk: brake_jerk,
        },
    ))
}

/// The route a collection takes through `w`, as far as reach goes: home, then each
/// corner of the workspace (x, z and θ at their ends, θ = 0 too) and back home, the
/// approach at `approach_m_s` and the way home at `retreat_m_s`. Poses are the finger's
/// (`flange_from_finger` is the end effector the arm is told).
#[must_use]
pub fn workspace_route(w: &WorkspaceBounds, approach_m_s: f64, retreat_m_s: f64) -> Vec<Leg> {
    let pose = |c: &softtouch_schemas::ContactPose| ArmPose::from_contact(&w.base_from_rod, c);
    let home = Leg {
        name: format!(
            "home (x = {} m, z = {} m, θ = {} rad)",
            w.home.x_m, w.home.z_m, w.home.theta_rad
        ),
        pose: pose(&w.home),
        speed_m_s: retreat_m_s,
    };
    let mut route = vec![home.clone()];
    let mut thetas = vec![w.theta_rad.min, w.theta_rad.max];
    if w.theta_rad.contains(0.0) {
        thetas.insert(1, 0.0);
    }
    for &theta_rad in &thetas {
        for x_m in [w.x_m.min, w.x_m.max] {
            for z_m in [w.z_m.min, w.z_m.max] {
                let c = softtouch_schemas::ContactPose {
                    x_m,
                    z_m,
                    theta_rad,
                };
                route.push(Leg {
                    name: format!("workspace corner x = {x_m} m, z = {z_m} m, θ = {theta_rad} rad"),
                    pose: pose(&c),
                    speed_m_s: approach_m_s,
                });
                route.push(home.clone());
            }
        }
    }
    route
}

#[cfg(test)]
mod tests;
