//! The reach check on its hard cases: the kinematics against franka-sim's FR3, a solve
//! round trip, the franka-sim tier's rig passing and the same rig with a full turn of
//! the wrist refused by joint, a pose out of reach, a singular start, NaN.

use super::*;
use softtouch_schemas::rig::WorkspaceBounds;
use softtouch_schemas::{ContactPose, Range};

/// franka-sim's FR3 home keyframe (`rigs/fr3/fr3_nomesh.xml`), its digits as
/// the file writes them.
#[allow(clippy::approx_constant)]
const SIM_HOME_Q: [f64; 7] = [0.0, 0.0, 0.0, -1.57079, 0.0, 1.57079, -0.7853];

fn flange() -> Kinematics {
    Kinematics::new(IDENTITY)
}

#[test]
fn the_kinematics_put_the_flange_where_franka_sim_reports_it_but_for_its_link7() {
    // What franka-sim's O_T_EE read at that keyframe (the franka-sim tier prints it).
    // With an MJCF that has no link8 it reports the body `fr3_link7` (its own
    // docstring: "the flange is whichever body this backend reports as O_T_EE
    // (link7)"): the documented flange lies 0.107 m further along the axis and is
    // turned -90° about it. The check takes the robot's own report at connect
    // (see `check_reach`); this pins the difference (TESTING.md).
    let sim = ArmPose {
        translation_m: [0.554_434, 0.0, 0.731_806],
        rotation_wxyz: [0.0, 0.923_955_7, -0.382_499_5, 0.0],
    };
    let flange = flange().pose(&SIM_HOME_Q);
    let sim_to_flange = sim.inverse().compose(&flange);
    let t = sim_to_flange.translation_m;
    assert!(
        t[0].abs() < 1e-3 && t[1].abs() < 1e-3 && (t[2] - 0.107).abs() < 1e-3,
        "{t:?}"
    );
    let turn = ArmPose::from_translation_yaw([0.0; 3], -std::f64::consts::FRAC_PI_2);
    assert!(sim_to_flange.angle_to(&turn) < 0.01, "{sim_to_flange:?}");
}

#[test]
fn a_solved_pose_gives_its_pose_back() {
    let k = flange();
    let q = [0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.5];
    let target = k.pose(&q);
    let seed = READY_Q;
    let solved = k.solve(&target, &seed).expect("reachable");
    let at = k.pose(&solved);
    assert!(at.distance_to(&target) < 1e-4 && at.angle_to(&target) < 1e-3);
    // Out of reach: 2 m from the base.
    let far = ArmPose {
        translation_m: [2.0, 0.0, 0.5],
        ..target
    };
    assert_eq!(k.solve(&far, &seed), None);
    // Not a pose, or not joints: no answer rather than a panic.
    let nan = ArmPose {
        translation_m: [f64::NAN, 0.0, 0.5],
        ..target
    };
    assert_eq!(k.solve(&nan, &seed), None);
    assert_eq!(k.solve(&target, &[f64::NAN; 7]), None);
    // From the stretched-out singularity (all joints 0: the arm straight up) a pose
    // in front is still found, and it is finite.
    let from_singular = k.solve(&k.pose(&SIM_HOME_Q), &[0.0; 7]);
    assert!(from_singular.is_none_or(|q| q.iter().all(|v| v.is_finite())));
}

/// The franka-sim tier's rig (tests/fcisim/mod.rs) with rotations over `theta`.
fn tier_workspace(theta: Range) -> WorkspaceBounds {
    WorkspaceBounds {
        x_m: Range::new(-0.01, 0.06),
        z_m: Range::new(-0.06, 0.06),
        theta_rad: theta,
        base_from_rod: ArmPose {
            translation_m: [0.58, 0.0, 0.6],
            rotation_wxyz: [0.0, 0.923_879_532_511_286_7, -0.382_683_432_365_089_8, 0.0],
        },
        home: ContactPose {
            x_m: -0.03,
            z_m: 0.0,
            theta_rad: 0.0,
        },
        reach_in_base_m: [
            Range::new(0.25, 0.75),
            Range::new(-0.2, 0.2),
            Range::new(0.1, 0.8),
        ],
    }
}

#[test]
fn the_tier_rig_passes_and_a_full_turn_of_the_wrist_is_refused_by_joint() {
    let k = flange();
    let ok = workspace_route(&tier_workspace(Range::new(-0.4, 0.4)), 0.05, 0.1);
    assert_eq!(ok.len(), 1 + 2 * 12, "home, then 12 corners and back");
    check_route(&k, Robot::Fr3, &SIM_HOME_Q, &ok, 0.5).expect("the tier's rig");
    // θ over the full circle: joint 7 turns a half turn either way from its home
    // value -0.785 rad, past its range of ±3.0196 rad (or too fast near its end).
    let full = workspace_route(
        &tier_workspace(Range::new(-std::f64::consts::PI, std::f64::consts::PI)),
        0.05,
        0.1,
    );
    let e = check_route(&k, Robot::Fr3, &SIM_HOME_Q, &full, 0.5).expect_err("refused");
    assert!(e.contains("θ = -3.14") || e.contains("θ = 3.14"), "{e}");
    assert!(e.contains("joint 7"), "{e}");
    assert!(e.contains("FR3"), "{e}");
}

#[test]
fn a_move_fast_toward_the_end_of_a_joints_range_is_refused_with_its_limit() {
    let k = flange();
    // Joint 7 at 0.3 rad from its lower end, then a turn of 0.25 rad toward it at
    // 2 rad/s: the FR3's limit there is about √(2·17·0.05) − 0.35 ≈ 0.95 rad/s.
    let (q_min, _) = Robot::Fr3.position_limits();
    let mut q = SIM_HOME_Q;
    q[6] = q_min[6] + 0.3;
    let mut toward = q;
    toward[6] -= 0.25;
    let leg = Leg {
        name: "toward the end".into(),
        pose: k.pose(&toward),
        speed_m_s: 0.1,
    };
    let e = check_route(&k, Robot::Fr3, &q, std::slice::from_ref(&leg), 2.0)
        .expect_err("too fast near the end");
    assert!(
        e.contains("toward the end: moving there") && e.contains("joint 7"),
        "{e}"
    );
    // Slowly, the same move is fine.
    check_route(&k, Robot::Fr3, &q, &[leg], 0.2).expect("slowly");
}

#[test]
fn a_route_that_does_not_move_and_one_with_a_nan_pose() {
    let k = flange();
    let here = Leg {
        name: "here".into(),
        pose: k.pose(&SIM_HOME_Q),
        speed_m_s: 0.1,
    };
    let q = check_route(
        &k,
        Robot::Fr3,
        &SIM_HOME_Q,
        std::slice::from_ref(&here),
        0.5,
    )
    .expect("no motion");
    assert!(q.iter().zip(SIM_HOME_Q).all(|(a, b)| (a - b).abs() < 1e-3));
    assert!(check_route(&k, Robot::Fr3, &SIM_HOME_Q, &[], 0.5).is_ok());
    let nan = Leg {
        pose: ArmPose {
            translation_m: [f64::NAN; 3],
            ..here.pose
        },
        ..here
    };
    let e = check_route(&k, Robot::Fr3, &SIM_HOME_Q, &[nan], 0.5).expect_err("nan");
    assert!(e.contains("not finite"), "{e}");
    // The Panda's limits are constant, its ranges wider on joint 7.
    let (fer_min, _) = Robot::Fer.position_limits();
    let (fr3_min, _) = Robot::Fr3.position_limits();
    assert!(fer_min[5] < fr3_min[5], "joint 6 reaches lower on a Panda");
    assert_eq!(Robot::of(franka::FciVersion::V10), Robot::Fr3);
}

#[test]
fn a_move_too_fast_for_a_joint_is_slowed_to_its_limits_and_one_out_of_reach_refused() {
    let kin = flange();
    let q0 = SIM_HOME_Q;
    let from = kin.pose(&q0);
    // A turn of 1 rad about the flange's own axis is mostly joint 7: at 6 rad/s of path
    // speed (joint 7's limit is 5.26 rad/s) it must be slowed to 80 % of the FR3's
    // limit there, and 20 rad/s² (joint 7's limit is 10) to within 80 % of 10.
    let turn = from.compose(&ArmPose::from_translation_yaw([0.0; 3], 1.0));
    let s = path_scale(&kin, Robot::Fr3, &q0, &from, &turn, [6.0, 20.0, 500.0]).expect("reachable");
    let (lower, upper) = Robot::Fr3.velocity_limits(&q0);
    let allowed = VELOCITY_MARGIN * upper[6].min(-lower[6]);
    assert!(
        s.velocity < 1.0 && 6.0 * s.velocity <= allowed + 0.05,
        "{s:?}"
    );
    assert!(6.0 * s.velocity > 0.5 * allowed, "slowed too far: {s:?}");
    let a = 20.0 * s.acceleration;
    assert!(a <= 8.0 + 1e-9 && a > 4.0, "{s:?}");
    assert!((s.jerk - 1.0).abs() < 1e-12, "{s:?}");
    // Slowly, the same move needs no slowing; nor does staying put.
    let slow = path_scale(&kin, Robot::Fr3, &q0, &from, &turn, [0.2, 1.0, 100.0]).expect("ok");
    assert_eq!(
        slow,
        PathScale {
            velocity: 1.0,
            acceleration: 1.0,
            jerk: 1.0
        }
    );
    let still = path_scale(&kin, Robot::Fer, &q0, &from, &from, [5.0, 50.0, 5000.0]).expect("ok");
    assert!((still.velocity - 1.0).abs() < 1e-12, "{still:?}");
    // Out of reach, and NaN: refused, never a scale.
    let far = ArmPose {
        translation_m: [2.0, 0.0, 0.5],
        ..from
    };
    assert!(path_scale(&kin, Robot::Fr3, &q0, &from, &far, [0.1, 1.0, 10.0]).is_err());
    let nan = ArmPose {
        translation_m: [f64::NAN, 0.0, 0.5],
        ..from
    };
    assert!(path_scale(&kin, Robot::Fr3, &q0, &from, &nan, [0.1, 1.0, 10.0]).is_err());
    assert!(path_scale(&kin, Robot::Fr3, &q0, &from, &turn, [f64::NAN, 1.0, 10.0]).is_err());
}

/// A long move asked for at a speed its path's curvature cannot carry: the speed is
/// lowered (not only the acceleration and jerk) until the curvature alone takes at
/// most [`CURVATURE_SHARE`] of every joint's acceleration share, checked by
/// differencing the joints along the path at the scaled cruise speed.
#[test]
fn a_move_whose_curvature_breaks_a_share_is_slowed() {
    let kin = flange();
    let q0 = SIM_HOME_Q;
    let from = kin.pose(&q0);
    // Half a metre sideways and down, turning: the elbow bends along it.
    let mut to = from.compose(&ArmPose::from_translation_yaw([0.0; 3], 0.8));
    to.translation_m[1] += 0.35;
    to.translation_m[2] -= 0.2;
    let path = [40.0, 400.0, 40_000.0];
    let s = path_scale(&kin, Robot::Fr3, &q0, &from, &to, path).expect("reachable");
    assert!(s.velocity < 1.0, "{s:?}");
    let v = path[0] * s.velocity;
    let steps = 400;
    let mut qs = vec![kin.solve(&from, &q0).expect("start")];
    walk_leg(&kin, Robot::Fr3, qs[0], &from, &to, steps, |_, next| {
        qs.push(*next);
        Ok(())
    })
    .expect("walk");
    let ds = 1.0 / steps as f64;
    let (acc_max, _) = joint_rate_limits(Robot::Fr3);
    let mut worst = 0.0f64;
    for w in qs.windows(3) {
        for j in 0..7 {
            let q2 = (w[2][j] - 2.0 * w[1][j] + w[0][j]) / (ds * ds);
            worst = worst.max(q2.abs() * v * v / (acc_max[j] * RATE_MARGIN));
        }
    }
    assert!(
        worst > 0.0 && worst <= CURVATURE_SHARE + 0.05,
        "{worst} of the share, {s:?}"
    );
    // The shares left for acceleration and jerk are real ones, not a floor.
    assert!(s.acceleration > 0.0 && s.jerk > 0.0, "{s:?}");
}
