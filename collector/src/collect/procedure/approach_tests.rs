//! The approach's free leg, the retreat plane and the slow end.

use super::*;

/// Free space is crossed fast up to the stand-off short of the first touch, only
/// where that point lies between the retreat plane and the pose.
#[test]
fn free_space_ends_a_stand_off_short_of_the_first_touch() {
    let mut p = softtouch_schemas::defaults::rig().procedure;
    let touch = softtouch_sim::ContactParams::default()
        .first_touch_x_m()
        .expect("the model's first touch");
    // The default finger first touches 3.57 mm short of x = 0.
    assert!((touch + 0.0003 / 0.084).abs() < 1e-12, "{touch}");
    let pose = |x_m: f64| ContactPose {
        x_m,
        z_m: 0.01,
        theta_rad: 0.3,
    };
    let x = standoff_x_m(-0.03, &pose(0.02), &p).expect("a free leg");
    assert!((x - (touch - 0.005)).abs() < 1e-12);
    // A pose short of the stand-off, or a retreat plane past it: no free leg.
    assert_eq!(standoff_x_m(-0.03, &pose(touch - 0.006), &p), None);
    assert_eq!(standoff_x_m(touch - 0.004, &pose(0.02), &p), None);
    // A stand-off beyond the retreat plane: none either; NaN never makes a pose.
    p.standoff_m = 0.05;
    assert_eq!(standoff_x_m(-0.03, &pose(0.02), &p), None);
    p.standoff_m = f64::NAN;
    assert_eq!(standoff_x_m(-0.03, &pose(0.02), &p), None);
    p.standoff_m = 0.0;
    assert!(standoff_x_m(-0.03, &pose(0.02), &p).is_some());
}

/// The retreat plane: the stand-off and a wrist turn's clearance (4 mm for the
/// default finger) short of the first touch, never beyond home's x.
#[test]
fn the_retreat_plane_is_a_stand_off_and_a_turn_short_of_the_first_touch() {
    let mut p = softtouch_schemas::defaults::rig().procedure;
    let touch = softtouch_sim::ContactParams::default()
        .first_touch_x_m()
        .expect("the model's first touch");
    let turn = softtouch_sim::FingerGeometry::default().turn_clearance_m();
    assert!((turn - 0.004).abs() < 1e-12, "{turn}");
    let x = retreat_x_m(-0.03, &p);
    assert!((x - (touch - 0.005 - 0.004)).abs() < 1e-12, "{x}");
    assert!((x + 0.012_571_428_571).abs() < 1e-9, "{x}");
    // The stand-off's own leg fits between the plane and a pose at x = 0.
    let pose = ContactPose {
        x_m: 0.0,
        z_m: 0.0,
        theta_rad: 1.0,
    };
    assert!(standoff_x_m(x, &pose, &p).is_some_and(|s| s - x > 0.0039));
    // Home nearer the rod than that: home. A stand-off that puts the plane past
    // home, or a NaN one: home too.
    assert!((retreat_x_m(-0.01, &p) + 0.01).abs() < 1e-15);
    p.standoff_m = 0.05;
    assert!((retreat_x_m(-0.03, &p) + 0.03).abs() < 1e-15);
    p.standoff_m = f64::NAN;
    assert!((retreat_x_m(-0.03, &p) + 0.03).abs() < 1e-15);
}

#[test]
#[allow(clippy::float_cmp)] // the speeds are copied, not computed
fn the_last_millimetres_of_an_approach_are_slow() {
    let mut p = softtouch_schemas::defaults::rig().procedure;
    let from = ArmPose {
        translation_m: [0.4, 0.0, 0.3],
        rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
    };
    let mut target = from;
    target.translation_m[0] += 0.03;
    let legs = approach_legs(&from, &target, &p);
    assert_eq!(legs.len(), 2);
    // 27 mm fast, then the last 3 mm slow.
    assert!(
        (legs[0].0.translation_m[0] - 0.427).abs() < 1e-12,
        "{legs:?}"
    );
    assert_eq!(legs[0].1, p.approach_speed_m_s);
    assert_eq!(legs[1], (target, p.slow_approach_speed_m_s));
    // A short path is all slow; a zero slow end is one move at full speed.
    let mut near = from;
    near.translation_m[0] += 0.002;
    assert_eq!(
        approach_legs(&from, &near, &p),
        vec![(near, p.slow_approach_speed_m_s)]
    );
    assert_eq!(approach_legs(&from, &from, &p).len(), 1);
    p.slow_approach_m = 0.0;
    assert_eq!(
        approach_legs(&from, &target, &p),
        vec![(target, p.approach_speed_m_s)]
    );
    // A NaN setting (refused by the rig's check anyway) never yields a NaN pose.
    p.slow_approach_m = f64::NAN;
    assert_eq!(
        approach_legs(&from, &target, &p),
        vec![(target, p.approach_speed_m_s)]
    );
}
