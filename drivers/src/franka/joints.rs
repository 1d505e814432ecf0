//! A move in joint space: the elbow back where it was. Every other move is a straight
//! line in Cartesian space that leaves the arm's redundancy to the robot, and over a
//! night the elbow drifts; a move to a stored joint configuration (the rig's home, as
//! the arm first reached it) resets it. One path parameter through franka-rs's OTG,
//! the joints interpolated linearly, limits so that every joint stays within its
//! shares of the robot's velocity (at its position along the way), acceleration and
//! jerk limits; an abort brakes as a Cartesian move's does ([`Brake`]).

use super::*;

/// The share of each joint's velocity limit a joint-space move may use: a reset of
/// the elbow at a block's end is a few tenths of a radian, not worth hurrying.
pub const JOINT_MOVE_VELOCITY_SHARE: f64 = 0.2;

/// Limits of the path parameter s ∈ [0, 1] of a joint-space move from `q0` to `q1`,
/// each joint within [`JOINT_MOVE_VELOCITY_SHARE`] of its velocity limit along the
/// way and within the reach margins of its acceleration and jerk limits. Refused where
/// the target leaves a joint's range or a joint could not move at all.
///
/// # Errors
/// A target that is not finite, outside the joints' ranges, or a joint whose limit
/// toward the target is zero on the way.
pub fn joint_path_limits(
    robot: reach::Robot,
    q0: &[f64; 7],
    q1: &[f64; 7],
) -> Result<franka::OtgLimits, String> {
    let (lo, hi) = robot.position_limits();
    for j in 0..7 {
        if !(q0[j].is_finite() && q1[j].is_finite()) {
            return Err(format!("joint {}: {} rad is not finite", j + 1, q1[j]));
        }
        if !(lo[j] < q1[j] && q1[j] < hi[j]) {
            return Err(format!(
                "joint {} at {:.3} rad lies outside the {}'s range [{:.3}, {:.3}] rad",
                j + 1,
                q1[j],
                robot.name(),
                lo[j],
                hi[j]
            ));
        }
    }
    let (acc, jerk) = reach::joint_rate_limits(robot);
    let (mut v, mut a, mut jk) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    const SAMPLES: usize = 64;
    for k in 0..=SAMPLES {
        let s = k as f64 / SAMPLES as f64;
        let q: [f64; 7] = std::array::from_fn(|j| q0[j] + s * (q1[j] - q0[j]));
        let (lower, upper) = robot.velocity_limits(&q);
        for j in 0..7 {
            let d = q1[j] - q0[j];
            if d.abs() < 1e-12 {
                continue;
            }
            let limit = if d > 0.0 { upper[j] } else { -lower[j] };
            if limit.is_nan() || limit <= 0.0 {
                return Err(format!(
                    "joint {} at {:.3} rad cannot turn toward {:.3} rad (the {}'s limit there is 0 rad/s)",
                    j + 1,
                    q[j],
                    q1[j],
                    robot.name()
                ));
            }
            v = v.min(limit * JOINT_MOVE_VELOCITY_SHARE / d.abs());
            a = a.min(acc[j] * reach::RATE_MARGIN / d.abs());
            jk = jk.min(jerk[j] * reach::JERK_MARGIN / d.abs());
        }
    }
    let finite = |x: f64| if x.is_finite() { x } else { 1e6 };
    Ok(franka::OtgLimits {
        max_velocity: finite(v),
        max_acceleration: finite(a),
        max_jerk: finite(jk),
    })
}

/// One joint-space move to `q1` on the robot thread, seeded from the commanded joints
/// of its first cycle; cancelled and braked as a Cartesian move is.
pub(super) fn run_joint_move(
    robot: &franka::Robot,
    q1: &[f64; 7],
    kind: reach::Robot,
    job: &mut worker::MoveJob<'_>,
) -> Result<(), DeviceError> {
    let start = robot.read_once().map_err(err)?;
    let path =
        joint_path_limits(kind, &start.q_d, q1).map_err(|message| DeviceError::InvalidCommand {
            device: DEVICE.into(),
            message: format!("joint move refused before it was sent: {message}"),
        })?;
    let mut otg = franka::Otg::new(0.0, path).map_err(err)?;
    otg.set_target(1.0).map_err(err)?;
    let mut seed: Option<[f64; 7]> = None;
    let mut brake: Option<Brake> = None;
    let mut aborted = false;
    let q1 = *q1;
    robot
        .control_joint_positions(
            |state, dt| {
                let q0 = *seed.get_or_insert(state.q_d);
                job.tick(state);
                if !aborted && job.cancelled() {
                    aborted = true;
                    let b = Brake::new(
                        otg.position(),
                        otg.velocity(),
                        otg.acceleration(),
                        path.max_acceleration,
                        path.max_jerk,
                    );
                    if b.stops_before(1.0) {
                        brake = Some(b);
                    }
                }
                let (s, done) = match brake.as_mut() {
                    Some(b) => (b.step(dt.as_secs_f64()), b.finished()),
                    None => {
                        let s = otg.step(dt.as_secs_f64());
                        (s, s >= 1.0 - 1e-9 && otg.velocity().abs() < 1e-9)
                    }
                };
                let cmd = franka::JointPositions::new(std::array::from_fn(|j| {
                    q0[j] + s * (q1[j] - q0[j])
                }));
                if done {
                    franka::motion_finished(cmd)
                } else {
                    cmd
                }
            },
            franka::ControllerMode::JointImpedance,
            false,
            franka::MAX_CUTOFF_FREQUENCY,
        )
        .map_err(err)
}
