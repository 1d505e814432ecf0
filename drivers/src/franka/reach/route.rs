//! The route check: a route's straight moves followed from the arm's joints, each step
//! against the joints' ranges and velocity limits; the route a collection takes through
//! a workspace; and [`walk_leg`], the one walk along a straight move that both this
//! check and path scaling take.

use super::*;

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
        let steps = steps_along(dist, angle, 2000);
        let dt = duration_s / steps as f64;
        q = walk_leg(kin, robot, q, &from, &to, steps, |q, next| {
            let (lower, upper) = robot.velocity_limits(q);
            for j in 0..7 {
                let v = (next[j] - q[j]) / dt;
                let (lo, hi) = (lower[j] * VELOCITY_MARGIN, upper[j] * VELOCITY_MARGIN);
                if v > hi || v < lo {
                    let limit = if v > hi { upper[j] } else { lower[j] };
                    return Err(format!(
                        "moving there at {} m/s and {} rad/s, joint {} would turn at {:.2} rad/s at {:.3} rad, where the {}'s limit is {:.2} rad/s ({:.0} % of it allowed); narrow the workspace's theta_rad or turn the rod frame so the wrist turns less",
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
            Ok(())
        })
        .map_err(|e| format!("{}: {e}", leg.name))?;
        from = to;
    }
    Ok(q)
}

/// Steps of a walk along a straight move of `dist_m` and `angle_rad`: one per 2 mm and
/// per 0.01 rad, at least 1 and at most `most`.
pub(super) fn steps_along(dist_m: f64, angle_rad: f64, most: usize) -> usize {
    ((dist_m / 0.002).max(angle_rad / 0.01).ceil() as usize).clamp(1, most)
}

/// Follows the straight move `from` → `to` (translation interpolated, rotation slerped)
/// in `steps` equal steps of the path parameter, from joints `q` (at or near `from`):
/// each pose solved from the joints of the last, each joint checked against its range,
/// then `visit` sees the step's joints before and after it. Returns the joints at `to`.
/// The route check and path scaling both walk a move this way, so the two read the
/// same joint path.
///
/// # Errors
/// A pose the arm cannot reach, a joint outside its range, or what `visit` refuses.
pub fn walk_leg(
    kin: &Kinematics,
    robot: Robot,
    mut q: [f64; 7],
    from: &ArmPose,
    to: &ArmPose,
    steps: usize,
    mut visit: impl FnMut(&[f64; 7], &[f64; 7]) -> Result<(), String>,
) -> Result<[f64; 7], String> {
    let (q_min, q_max) = robot.position_limits();
    let steps = steps.max(1);
    for k in 1..=steps {
        let pose = from.slerp(to, k as f64 / steps as f64);
        let Some(next) = kin.solve(&pose, &q) else {
            return Err(format!(
                "the arm cannot reach the pose at {:?} m on the way from {:?} m to {:?} m (out of reach or through a singularity)",
                pose.translation_m, from.translation_m, to.translation_m
            ));
        };
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
        }
        visit(&q, &next)?;
        q = next;
    }
    Ok(q)
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
