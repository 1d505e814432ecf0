//! Path scaling: the shares of a straight move's path velocity, acceleration and jerk
//! (and of the brake's) at which every joint stays within its margins of the robot's
//! limits, from one walk along the move.

use super::*;

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

/// The share of a joint's acceleration and jerk room the path's curvature may take at
/// a move's speed (the rest is left to the path's own acceleration and jerk).
pub const CURVATURE_SHARE: f64 = 0.5;

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
    let (acc_max, jerk_max) = joint_rate_limits(robot);
    let steps = steps_along(dist, angle, 1000);
    let ds = 1.0 / steps as f64;
    // The joints at the commanded start: the measured ones are off it where the arm
    // presses against something (impedance control), and a first step from them would
    // read as a jump.
    let Some(q) = kin.solve(from, q0) else {
        return Err(format!(
            "the arm cannot reach its own commanded pose {:?} m from its joints",
            from.translation_m
        ));
    };
    let mut worst_v = 0.0f64;
    // Largest |q'| and |q''| of each joint along the path.
    let (mut d1, mut d2) = ([0.0f64; 7], [0.0f64; 7]);
    let mut last_d1: Option<[f64; 7]> = None;
    walk_leg(kin, robot, q, from, to, steps, |q, next| {
        let (lower, upper) = robot.velocity_limits(q);
        let mut dq = [0.0; 7];
        for j in 0..7 {
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
        Ok(())
    })?;
    let mut v = s_dot * if worst_v > 1.0 { 1.0 / worst_v } else { 1.0 };
    // Where the path's curvature alone would take more than half a joint's share of
    // acceleration (q''·ṡ²) or jerk (3·q''·ṡ·s̈, at the largest s̈ asked for), the
    // speed is lowered until it takes half: the move is slowed, never run with its
    // acceleration and jerk cut while its speed breaks the bound.
    for j in 0..7 {
        if d2[j] > 0.0 {
            v = v.min((CURVATURE_SHARE * acc_max[j] * RATE_MARGIN / d2[j]).sqrt());
            let a_most = s_ddot.max(b_ddot);
            if a_most > 0.0 {
                v = v.min(CURVATURE_SHARE * jerk_max[j] * JERK_MARGIN / (3.0 * d2[j] * a_most));
            }
        }
    }
    let velocity = if s_dot > 0.0 {
        (v / s_dot).min(1.0)
    } else {
        1.0
    };
    // The share of `want` that joint j allows, given what the curvature takes (at most
    // half the room, above).
    let share = |want: f64, room: f64, g1: f64| -> f64 {
        if want <= 0.0 || g1 * want <= room {
            1.0
        } else {
            (room / (g1 * want)).clamp(1e-6, 1.0)
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
