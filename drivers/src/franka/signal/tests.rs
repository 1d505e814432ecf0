use super::*;
use crate::franka::{MotionLimits, path_limits};
use reach::{IDENTITY, READY_Q};

fn kin() -> Kinematics {
    Kinematics::new(IDENTITY)
}

/// The ready pose, and a pose 6 cm down with the wrist turned 0.3 rad: reachable.
fn from_and_to() -> (ArmPose, ArmPose) {
    let k = kin();
    let from = k.pose(&READY_Q);
    let mut q = READY_Q;
    q[3] += 0.15;
    q[6] += 0.3;
    (from, k.pose(&q))
}

/// The commands of one straight move as the driver plans it (run_path: franka-rs's
/// OTG on the path parameter, the pose slerped), one per cycle from message `first`.
fn planned(limits: &MotionLimits, speed_m_s: f64, first: u64) -> Vec<Commanded> {
    let (from, to) = from_and_to();
    let lim = path_limits(from.distance_to(&to), from.angle_to(&to), speed_m_s, limits);
    let mut otg = franka::Otg::new(0.0, lim).expect("otg");
    otg.set_target(1.0).expect("target");
    let mut out = Vec::new();
    let mut id = first;
    loop {
        let s = otg.step(CYCLE_S);
        out.push(Commanded {
            message_id: id,
            pose: from.slerp(&to, s),
            q_measured: (id == first).then_some(READY_Q),
            q_commanded: None,
        });
        id += 1;
        if s >= 1.0 - 1e-12 && otg.velocity().abs() < 1e-12 {
            break;
        }
        assert!(out.len() < 100_000, "the plan never ends");
    }
    out
}

fn peak<'a>(v: &'a Verdict, what: &str) -> &'a Peak {
    v.peaks
        .iter()
        .find(|p| p.what.starts_with(what))
        .unwrap_or_else(|| panic!("no {what}: {v:?}"))
}

/// A move planned at a rig's limits (0.3 of the FR3's) holds, and reads the jerk it
/// was planned with: the check differences what the plan commanded.
#[test]
fn a_move_planned_at_a_rigs_limits_holds_and_reads_its_planned_jerk() {
    let limits = MotionLimits::for_robot(Robot::Fr3, 0.3);
    let cmds = planned(&limits, 0.2, 1000);
    let v = judge(&cmds, Robot::Fr3, &kin());
    assert!(v.holds(), "{}", v.table());
    assert_eq!(v.runs, 1);
    assert_eq!(v.commands, cmds.len());
    let j = peak(&v, "translational jerk");
    // Within a few % of the plan's 900 m/s³ (its rotation may set the pace instead).
    assert!(j.value <= limits.jerk_m_s3 * 1.05, "{}", v.table());
    let a = peak(&v, "translational acceleration");
    assert!(a.value <= limits.accel_m_s2 * 1.05, "{}", v.table());
    // The joints were solved and differenced: a joint moved.
    assert!(peak(&v, "joint 7 velocity").value > 0.01, "{}", v.table());
    assert!(peak(&v, "joint 7 jerk").value.is_finite(), "{}", v.table());
}

/// The same move with its jerk three times the robot's limit is caught, by the jerk.
#[test]
fn a_plan_with_its_jerk_scaled_three_times_past_the_limit_is_caught() {
    let [_, a, j, _, ra, rj] = cartesian_limits(Robot::Fr3);
    let broken = MotionLimits {
        accel_m_s2: a,
        jerk_m_s3: 3.0 * j,
        rot_accel_rad_s2: ra,
        rot_jerk_rad_s3: 3.0 * rj,
        ..MotionLimits::for_robot(Robot::Fr3, 1.0)
    };
    let v = judge(&planned(&broken, 0.5, 7), Robot::Fr3, &kin());
    assert!(!v.holds(), "{}", v.table());
    let over: Vec<&str> = v.over().iter().map(|p| p.what.as_str()).collect();
    assert!(
        over.iter().any(|w| w.contains("jerk")),
        "{over:?}\n{}",
        v.table()
    );
}

/// A cycle the driver did not answer splits the signal: nothing is differenced across
/// it, so a lost cycle never reads as jerk. The same commands renumbered as if no
/// cycle were missing (a step the robot would see) are caught.
#[test]
fn a_gap_in_the_cycles_is_not_differenced_across_but_a_hidden_one_is_caught() {
    let limits = MotionLimits::for_robot(Robot::Fr3, 0.3);
    let mut cmds = planned(&limits, 0.2, 1);
    // Drop ten cycles from the middle of the move (at cruise, where it moves most).
    let mid = cmds.len() / 2;
    cmds.drain(mid..mid + 10);
    let v = judge(&cmds, Robot::Fr3, &kin());
    assert!(v.holds(), "{}", v.table());
    assert_eq!(v.runs, 2);
    for (i, c) in cmds.iter_mut().enumerate() {
        c.message_id = i as u64 + 1;
    }
    let hidden = judge(&cmds, Robot::Fr3, &kin());
    assert_eq!(hidden.runs, 1);
    assert!(!hidden.holds(), "{}", hidden.table());
}

/// No commands, one command and a still arm: nothing to difference, nothing over.
#[test]
fn empty_single_and_constant_signals_hold() {
    let v = judge(&[], Robot::Fr3, &kin());
    assert!(v.holds());
    assert_eq!((v.commands, v.runs), (0, 0));
    let (from, _) = from_and_to();
    let still: Vec<Commanded> = (0..50)
        .map(|i| Commanded {
            message_id: 100 + i,
            pose: from,
            q_measured: Some(READY_Q),
            q_commanded: None,
        })
        .collect();
    for cmds in [&still[..1], &still[..]] {
        let v = judge(cmds, Robot::Fr3, &kin());
        assert!(v.holds(), "{}", v.table());
        assert!(
            v.peaks.iter().all(|p| p.value.abs() < 1e-6),
            "{}",
            v.table()
        );
    }
    // Repeated and shuffled ids: each cycle once, in order.
    let mut twice: Vec<Commanded> = still.iter().rev().cloned().collect();
    twice.extend(still.iter().cloned());
    let v = judge(&twice, Robot::Fr3, &kin());
    assert_eq!((v.commands, v.runs), (50, 1));
}

/// A non-finite command or a pose out of reach is reported, never a panic.
#[test]
fn a_nan_command_and_an_unreachable_pose_are_reported() {
    let (from, _) = from_and_to();
    let mut nan = from;
    nan.translation_m[0] = f64::NAN;
    let cmds: Vec<Commanded> = (0..5)
        .map(|i| Commanded {
            message_id: i,
            pose: if i == 3 { nan } else { from },
            q_measured: Some(READY_Q),
            q_commanded: None,
        })
        .collect();
    let v = judge(&cmds, Robot::Fr3, &kin());
    assert!(!v.holds(), "{}", v.table());
    assert_eq!(v.unsolved, vec![3]);
    assert!(peak(&v, "translational velocity").over(), "{}", v.table());
    let mut far = from;
    far.translation_m = [3.0, 0.0, 0.5];
    let v = judge(
        &[Commanded {
            message_id: 1,
            pose: far,
            q_measured: None,
            q_commanded: None,
        }],
        Robot::Fr3,
        &kin(),
    );
    assert_eq!(v.unsolved, vec![1]);
    assert!(v.table().contains("no joint solution"), "{}", v.table());
}
