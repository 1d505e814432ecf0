//! Unit tests of the soft grasp's objects and physics (virtual time).

use super::touch::{Grip, SqueezeAlongShift, Strips, finger_contact};
use super::*;
use crate::SceneSim;
use softtouch_schemas::scene::ObjectProfile;
use softtouch_schemas::{ContactPose, Effect, RodShape};
use std::time::Duration;

fn land() -> SceneSpec {
    softtouch_schemas::defaults::scene()
}

fn with_effects(effects: Vec<Effect>) -> SceneSpec {
    let mut s = land();
    s.effects.extend(effects);
    s
}

fn ms(t: u64) -> TimestampNs {
    TimestampNs(t * 1_000_000)
}

fn squeeze(obj: &GraspObject, k: usize, opening_m: f64) -> f64 {
    contact(
        obj,
        k,
        Grip {
            opening_m,
            ..Grip::default()
        },
    )
    .squeeze_n()
}

/// Commands the fingers to `position` at `speed` with full force and waits `wait_s`.
async fn close_to(g: &mut SoftGripper, position: u8, speed: u8, wait_s: u64) {
    g.command(GripperCommand {
        position,
        speed,
        force: 255,
    })
    .await
    .expect("sent");
    tokio::time::sleep(Duration::from_secs(wait_s)).await;
}

/// Activates, closes to `count` at full speed and waits 1 s.
async fn grip_at(
    scene: &SceneSpec,
    obj: GraspObject,
    count: u8,
) -> (SoftGripper, SoftGraspHandle, TokioClock) {
    let clock = TokioClock::new();
    let (mut g, _, h) = soft_grasp(scene, obj, 60.0, 1, clock).expect("builds");
    g.activate().await.expect("activates");
    close_to(&mut g, count, 255, 1).await;
    g.status().await.expect("status");
    (g, h, clock)
}

/// The count at which the squeeze on one finger first reaches `force_n`.
fn count_for(h: &SoftGraspHandle, force_n: f64) -> u8 {
    let counts: Vec<u8> = (0..=255).collect();
    h.grip_force_curve(&counts)
        .expect("curve")
        .into_iter()
        .find(|(_, f)| *f >= force_n)
        .map(|(p, _)| p)
        .expect("reachable")
}

/// The count at which the squeeze first reaches `force_n`, and the squeeze there.
fn grip_for(obj: &GraspObject, force_n: f64) -> (u8, f64) {
    let (_, _, h) = soft_grasp(&land(), obj.clone(), 60.0, 1, TokioClock::new()).expect("builds");
    let p = count_for(&h, force_n);
    let f = h.grip_force_curve(&[p]).expect("curve")[0].1;
    (p, f)
}

fn cylinder_standing() -> GraspObject {
    GraspObject::standing(
        "cylinder",
        RodShape::Circle,
        0.03,
        1.0,
        ObjectProfile::Prism { height_m: 0.03 },
    )
}

#[test]
fn a_lying_cylinder_presses_like_the_rod_of_the_same_section() {
    // Same law, same finger: the grasp's strip model and the rod presses agree.
    let obj = GraspObject::cylinder("rod", 0.02);
    let sim = SceneSim::new(
        &SceneSpec {
            rods: vec![obj.face_rod()],
            ..land()
        },
        0,
    )
    .expect("scene");
    let p = ContactParams::default();
    for penetration_m in [0.0005, 0.001, 0.002] {
        let x_m = (penetration_m - p.penetration_at_zero_m) / p.penetration_per_m;
        let pose = ContactPose {
            x_m,
            z_m: 0.0,
            theta_rad: 0.0,
        };
        let rod = -sim.wrench("rod", &pose).expect("wrench").force_n[0];
        let grasp = squeeze(&obj, 0, 0.02 - 2.0 * penetration_m);
        assert!(
            (grasp - rod).abs() < 0.05 * rod,
            "{penetration_m}: grasp {grasp} N, rod {rod} N"
        );
    }
}

#[test]
fn profiles_give_the_width_at_each_height() {
    // A sphere's chord.
    let ball = GraspObject::standing(
        "ball",
        RodShape::Circle,
        0.04,
        1.0,
        ObjectProfile::Sphere {},
    );
    assert!((ball.grasp_height_m - 0.02).abs() < 1e-12);
    for q in [0.0, 0.01, -0.015, 0.0199] {
        let (r, y) = ball.half_width_at(q, 0.0, 0).expect("inside");
        assert!(
            (r - (0.02_f64.powi(2) - q * q).sqrt()).abs() < 1e-12,
            "{q}: {r}"
        );
        assert!(y.abs() < 1e-15);
    }
    assert!(ball.half_width_at(0.021, 0.0, 0).is_none());
    // A taper's width at the contact height: 40 mm at the bottom, 20 mm at the top.
    let bottle = GraspObject::standing(
        "bottle",
        RodShape::Circle,
        0.04,
        1.0,
        ObjectProfile::Taper {
            height_m: 0.1,
            top_width_m: 0.02,
        },
    );
    let (r, _) = bottle.half_width_at(0.0, 0.0, 1).expect("mid");
    assert!((r - 0.015).abs() < 1e-12, "{r}");
    let (r, _) = bottle.half_width_at(-0.05, 0.0, 1).expect("top");
    assert!((r - 0.01).abs() < 1e-12, "{r}");
    assert!(bottle.half_width_at(0.051, 0.0, 1).is_none());
    // An oval tube turned a quarter: its depth is now across the fingers, and the
    // contact moves off-centre in between.
    let tube = GraspObject::standing(
        "tube",
        RodShape::Oval,
        0.03,
        0.5,
        ObjectProfile::Prism { height_m: 0.05 },
    );
    let (r0, y0) = tube.half_width_at(0.0, 0.0, 0).expect("in");
    let (r90, _) = tube
        .half_width_at(0.0, std::f64::consts::FRAC_PI_2, 0)
        .expect("in");
    let (r45, y45) = tube
        .half_width_at(0.0, std::f64::consts::FRAC_PI_4, 0)
        .expect("in");
    assert!((r0 - 0.015).abs() < 1e-12 && y0.abs() < 1e-12);
    assert!((r90 - 0.0075).abs() < 1e-12, "{r90}");
    assert!(r45 < r0 && r45 > r90 && y45.abs() > 1e-3, "{r45} {y45}");
    // The two fingers meet diametrically opposite points.
    let (_, y45_other) = tube
        .half_width_at(0.0, std::f64::consts::FRAC_PI_4, 1)
        .expect("in");
    assert!((y45 + y45_other).abs() < 1e-12);
    // Defaults from geometry.
    assert!((ball.volume_m3 - 4.0 / 3.0 * std::f64::consts::PI * 0.02_f64.powi(3)).abs() < 1e-12);
    assert!((tube.grasp_width_m - 0.028).abs() < 1e-12);
}

#[test]
fn turning_an_oval_tube_changes_the_squeeze_and_the_contact_side() {
    let tube = GraspObject::standing(
        "tube",
        RodShape::Oval,
        0.03,
        0.6,
        ObjectProfile::Prism { height_m: 0.05 },
    );
    let at = |yaw: f64| {
        finger_contact(
            &FingerGeometry::default(),
            &ContactParams::default(),
            &tube,
            0,
            &Grip {
                opening_m: 0.026,
                shift_m: 0.0,
                yaw_rad: yaw,
            },
            [0.0; 2],
        )
        .expect("contact")
    };
    let (straight, turned) = (at(0.0), at(0.5));
    assert!(turned.squeeze_n() < straight.squeeze_n());
    // Straight, it meets the fingers as a round tube of its width does, to the last
    // bit: a stiffness calibration (a closing at yaw 0) cannot tell the two apart.
    let round = GraspObject::standing(
        "round",
        RodShape::Circle,
        0.03,
        1.0,
        ObjectProfile::Prism { height_m: 0.05 },
    );
    let round_contact = finger_contact(
        &FingerGeometry::default(),
        &ContactParams::default(),
        &round,
        0,
        &Grip {
            opening_m: 0.026,
            shift_m: 0.0,
            yaw_rad: 0.0,
        },
        [0.0; 2],
    )
    .expect("contact");
    assert_eq!(
        round_contact.squeeze_n().to_bits(),
        straight.squeeze_n().to_bits()
    );
    // Turned, only the oval changes (`grasp disturb` tells them apart).
    let half = |o: &GraspObject| o.half_width_at(0.0, 0.5, 0).expect("in").0;
    assert!((half(&round) - 0.015).abs() < 1e-12 && half(&tube) < 0.0149);
    assert!(straight.contact.azimuth.abs() < 1e-9);
    assert!(
        turned.contact.azimuth.abs() > 0.05,
        "{}",
        turned.contact.azimuth
    );
}

#[test]
fn placements_that_miss_are_none_and_near_ones_are_met() {
    let obj = cylinder_standing();
    assert!(obj.placed([0.0; 3]).is_some());
    assert!(obj.placed([0.005, 0.002, 0.003]).is_some());
    // An open finger lands on it. The stroke leaves (50 − 30) / 2 = 10 mm either side
    // at the grasp height, less where the finger's section stands forward of its
    // front there (towards its base): about 8 mm for this 30 mm tall prism.
    assert!(obj.placed([0.007, 0.0, 0.0]).is_some());
    assert!(obj.placed([-0.007, 0.0, 0.0]).is_some());
    assert!(obj.placed([0.0095, 0.0, 0.0]).is_none());
    assert!(obj.placed([-0.0095, 0.0, 0.0]).is_none());
    assert!(obj.placed([0.0101, 0.0, 0.0]).is_none());
    // Off the fingers' faces across (their half-width is at most 16 mm).
    assert!(obj.placed([0.0, 0.03, 0.0]).is_none());
    // Far above or below the fingers along z.
    assert!(obj.placed([0.0, 0.0, 0.1]).is_none());
    assert!(obj.placed([0.0, 0.0, -0.1]).is_none());
    assert!(obj.placed([f64::NAN, 0.0, 0.0]).is_none());
    // Offsets add up.
    let twice = obj
        .placed([0.006, 0.0, 0.0])
        .and_then(|o| o.placed([0.006, 0.0, 0.0]));
    assert!(twice.is_none());
    // An object exactly as wide as the stroke is refused, one just under is met.
    let mut wide = GraspObject::cylinder("wide", 0.05);
    assert!(wide.validate().is_err());
    wide.width_m = 0.0499;
    assert!(wide.validate().is_ok());
    // Valid, but the open fingers stand further forward elsewhere along their length
    // than at the grasp height, so they land on it even centred.
    assert!(wide.placed([0.0; 3]).is_none());
    wide.width_m = 0.046;
    assert!(wide.placed([0.0; 3]).is_some());
    assert!(wide.placed([0.003, 0.0, 0.0]).is_none());
}

#[tokio::test(start_paused = true)]
async fn it_rests_until_the_lift_and_is_held_with_enough_friction() {
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    let (_, h, clock) = grip_at(&land(), obj, count).await;
    assert_eq!(h.hold_state().expect("state"), HoldState::Resting);
    let now = clock.now();
    let t0 = h.true_wrench(now).expect("truth");
    h.start_lift(TimestampNs(now.0 + 10_000_000), 0.1, 0.1, 1.0)
        .expect("lift");
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(h.hold_state().expect("state"), HoldState::Held);
    // The fingers carry the weight in friction: a shear along z on each.
    let w = h.true_wrench(clock.now()).expect("truth");
    let weight_n = 0.05 * G_M_S2;
    assert!(
        (w.force_n[2] - t0.force_n[2] - weight_n / 2.0).abs() < 0.02,
        "{w:?}"
    );
    assert!(h.start_lift(now, 0.1, 0.1, 1.0).is_err(), "one lift");
}

#[tokio::test(start_paused = true)]
async fn zero_friction_or_a_huge_mass_slips_at_the_lift() {
    for (friction, mass_kg) in [(0.0, 0.05), (0.5, 9.0)] {
        let obj = GraspObject {
            friction,
            mass_kg,
            ..cylinder_standing()
        };
        let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
        let count = count_for(&probe, 1.5);
        let (_, h, clock) = grip_at(&land(), obj, count).await;
        let start = TimestampNs(clock.now().0 + 5_000_000);
        h.start_lift(start, 0.1, 0.1, 1.0).expect("lift");
        tokio::time::sleep(Duration::from_millis(500)).await;
        match h.hold_state().expect("state") {
            HoldState::Slipped { t } => {
                assert!(t >= start && t.0 <= start.0 + STEP_NS, "{t:?} vs {start:?}")
            }
            other => panic!("μ = {friction}, m = {mass_kg}: {other:?}"),
        }
        // It fell: the fingers feel nothing.
        let w = h.true_wrench(clock.now()).expect("truth");
        assert_eq!(w, Wrench::ZERO);
        assert!(!h.has_object().expect("state"));
    }
}

#[tokio::test(start_paused = true)]
async fn a_load_or_a_current_that_is_not_a_number_is_an_error_not_an_outcome() {
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    // A drag coefficient that is not a number reaches the load only on the lift.
    let (_, h, clock) = grip_at(&with_effects(vec![drag_effect()]), obj.clone(), count).await;
    if let Ok(mut s) = h.state.lock()
        && let Some(o) = s.object.as_mut()
    {
        // The lift's drag is the end-on one.
        o.lift_drag_coefficient = f64::NAN;
    }
    h.start_lift(TimestampNs(clock.now().0 + 5_000_000), 0.1, 0.1, 1.0)
        .expect("lift");
    tokio::time::sleep(Duration::from_millis(200)).await;
    let err = h
        .hold_state()
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("on the lift: the load (NaN N)"), "{err}");
    // A scene whose current is not a number is refused before anything moves.
    let nan_flow = with_effects(vec![Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: f64::NAN,
        gust_m_s: 0.0,
        period_s: 1.0,
        spectrum: None,
    }]);
    let err = soft_grasp(&nan_flow, obj.clone(), 60.0, 1, TokioClock::new())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("mean_m_s"), "{err}");
    // So is a gust period of 0 (it would divide).
    let zero_period = with_effects(vec![Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: 0.05,
        gust_m_s: 0.02,
        period_s: 0.0,
        spectrum: None,
    }]);
    let err = soft_grasp(&zero_period, obj, 60.0, 1, TokioClock::new())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("period_s"), "{err}");
}

fn drag_effect() -> Effect {
    Effect::ObjectDrag {
        fluid_density_kg_m3: 1000.0,
    }
}

/// The digest of [`land_physics_is_pinned_bit_for_bit`]'s record.
const LAND_DIGEST: &str = "41bf822ce55f0644cef77c86fe4f2b33c374cb0b25840406dfb6bb5cc6dda16a";

/// Land physics, pinned: every object of `scenes/grasp.toml`, placed 3 mm off centre
/// on its tray, closed on at 1.5 N, a frame read, lifted 50 mm and held, its true
/// wrench and hold state recorded every 10 ms. Water effects are modelled only where a
/// scene declares them, at no cost otherwise: a change to them (or to anything else)
/// that moves a land bit changes this digest. If land physics was changed on purpose,
/// the failure prints the new digest to pin.
#[tokio::test(start_paused = true)]
async fn land_physics_is_pinned_bit_for_bit() {
    use sha2::Digest as _;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scene: SceneSpec =
        softtouch_schemas::config::load_toml(&root.join("scenes/grasp.toml")).expect("loads");
    let mut digest = sha2::Sha256::new();
    for spec in &scene.objects {
        let template = GraspObject::from_spec(spec);
        let obj = template.placed([0.003, 0.0, 0.0]).expect("placed");
        let clock = TokioClock::new();
        let (mut g, mut camera, h) = soft_grasp(&scene, obj, 60.0, 5, clock).expect("builds");
        g.activate().await.expect("activates");
        let count = count_for(&h, 1.5);
        close_to(&mut g, count, 255, 1).await;
        let frame = camera
            .latest_frame_after(clock.now(), 1000)
            .await
            .expect("a frame");
        digest.update(&frame.data);
        h.start_lift(clock.now(), 0.05, 0.1, 1.0).expect("lift");
        for _ in 0..100 {
            tokio::time::sleep(Duration::from_millis(10)).await;
            let now = clock.now();
            let record = format!(
                "{} {count} {:?} {:?}\n",
                spec.name,
                h.true_wrench(now).expect("truth"),
                h.hold_state().expect("state")
            );
            digest.update(record.as_bytes());
        }
    }
    let hex: String = digest
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(
        hex, LAND_DIGEST,
        "land physics changed; if on purpose, pin the new digest in LAND_DIGEST"
    );
}

#[tokio::test(start_paused = true)]
async fn the_acceleration_decides_a_marginal_hold() {
    // Friction carries the weight plus a gentle start but not a hard one.
    let obj = cylinder_standing();
    let (count, squeeze_n) = grip_for(&obj, 1.0);
    // 2·μ·F ≈ 1.2 · m·g (the normal force is a little above the squeeze).
    let obj = GraspObject {
        mass_kg: 2.0 * 0.5 * squeeze_n / (1.2 * G_M_S2),
        ..obj
    };
    for (accel, slips) in [(0.5, false), (5.0, true)] {
        let (_, h, clock) = grip_at(&land(), obj.clone(), count).await;
        h.start_lift(clock.now(), 0.05, 0.2, accel).expect("lift");
        tokio::time::sleep(Duration::from_secs(1)).await;
        let state = h.hold_state().expect("state");
        assert_eq!(
            matches!(state, HoldState::Slipped { .. }),
            slips,
            "a = {accel}: {state:?}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_fragile_object_is_crushed_and_reported() {
    let obj = GraspObject {
        crush_force_n: Some(1.0),
        ..cylinder_standing()
    };
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 2.0);
    let (_, h, _) = grip_at(&land(), obj, count).await;
    assert!(matches!(
        h.hold_state().expect("state"),
        HoldState::Crushed { .. }
    ));
    assert!(h.crushed().expect("state"));
    h.set_object(false).expect("removes");
    assert_eq!(h.hold_state().expect("state"), HoldState::Absent);
}

#[tokio::test(start_paused = true)]
async fn buoyancy_and_drag_change_the_outcome_only_when_declared() {
    let water_buoyancy = with_effects(vec![Effect::ObjectBuoyancy {
        fluid_density_kg_m3: 1000.0,
    }]);
    let water_drag = with_effects(vec![Effect::ObjectDrag {
        fluid_density_kg_m3: 1000.0,
    }]);
    let lift = |h: &SoftGraspHandle, t: TimestampNs, height: f64, speed: f64, accel: f64| {
        h.start_lift(t, height, speed, accel).expect("lift")
    };
    let outcome = |h: &SoftGraspHandle| {
        let state = h.hold_state().expect("state");
        assert!(
            matches!(state, HoldState::Held | HoldState::Slipped { .. }),
            "{state:?}"
        );
        matches!(state, HoldState::Slipped { .. })
    };
    // Too heavy for a light grip on land; the water it displaces (0.21 N for this
    // 30 × 30 mm cylinder) carries enough of it.
    let obj = cylinder_standing();
    let (count, squeeze_n) = grip_for(&obj, 0.3);
    let capacity_n = 2.0 * obj.friction * squeeze_n;
    let buoyancy_n = 1000.0 * G_M_S2 * obj.volume_m3;
    assert!(
        capacity_n < 0.6 && buoyancy_n > 0.2,
        "{capacity_n} {buoyancy_n}"
    );
    let heavy = GraspObject {
        mass_kg: 1.3 * capacity_n / (G_M_S2 + 2.0),
        ..obj.clone()
    };
    for (scene, slips) in [(land(), true), (water_buoyancy, false)] {
        let (_, h, clock) = grip_at(&scene, heavy.clone(), count).await;
        lift(&h, clock.now(), 0.2, 0.1, 2.0);
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert_eq!(outcome(&h), slips);
    }
    // Lifted fast: held on land, dragged out of the grip in water (½·ρ·C_d·A·v² at
    // 1.5 m/s on 7.1 cm² is 0.8 N).
    let (count, squeeze_n) = grip_for(&obj, 1.0);
    let capacity_n = 2.0 * obj.friction * squeeze_n;
    let peak_land_n = obj.mass_kg * (G_M_S2 + 5.0);
    assert!(
        capacity_n > peak_land_n * 1.05 && capacity_n < obj.mass_kg * G_M_S2 + 0.7,
        "{capacity_n}"
    );
    for (scene, slips) in [(land(), false), (water_drag, true)] {
        let (_, h, clock) = grip_at(&scene, obj.clone(), count).await;
        lift(&h, clock.now(), 1.0, 1.5, 5.0);
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert_eq!(outcome(&h), slips);
    }
}

#[tokio::test(start_paused = true)]
async fn wet_contact_grips_with_the_wet_friction_only_when_declared() {
    let wet = with_effects(vec![Effect::WetContact {}]);
    // Dry μ 0.6, wet a tenth of it (a hydrophilic surface).
    let obj = GraspObject {
        friction: 0.6,
        wet_friction: Some(0.06),
        ..cylinder_standing()
    };
    let (count, squeeze_n) = grip_for(&obj, 1.0);
    // Light enough for the dry grip, too heavy for the wet one (slow lift, 0.5 m/s²).
    let dry_capacity_n = 2.0 * 0.6 * squeeze_n;
    let wet_capacity_n = 2.0 * 0.06 * squeeze_n;
    let load = |m: f64| m * (G_M_S2 + 0.5);
    let mass = 0.5 * (dry_capacity_n + wet_capacity_n) / (G_M_S2 + 0.5);
    assert!(load(mass) < 0.9 * dry_capacity_n && load(mass) > 1.1 * wet_capacity_n);
    let obj = GraspObject {
        mass_kg: mass,
        ..obj
    };
    let mut outcomes = Vec::new();
    for scene in [land(), wet.clone()] {
        let (_, h, clock) = grip_at(&scene, obj.clone(), count).await;
        h.start_lift(clock.now(), 0.05, 0.05, 0.5).expect("lift");
        tokio::time::sleep(Duration::from_secs(2)).await;
        outcomes.push(h.hold_state().expect("state"));
    }
    assert_eq!(outcomes[0], HoldState::Held, "dry: {outcomes:?}");
    assert!(
        matches!(outcomes[1], HoldState::Slipped { .. }),
        "wet: {outcomes:?}"
    );
    // An object with a wet friction in a scene that declares no wet contact: exactly
    // the object without one (the same truth at every instant).
    let plain = GraspObject {
        wet_friction: None,
        ..obj.clone()
    };
    let (_, a, clock_a) = grip_at(&land(), obj.clone(), count).await;
    let (_, b, clock_b) = grip_at(&land(), plain, count).await;
    for i in 0..5 {
        let ta = TimestampNs(clock_a.now().0 + i * 10_000_000);
        let tb = TimestampNs(clock_b.now().0 + i * 10_000_000);
        assert_eq!(
            a.true_wrench_on(0, ta).expect("truth"),
            b.true_wrench_on(0, tb).expect("truth")
        );
    }
    // Declared, but an object without its wet friction: refused, by name.
    let Err(e) = soft_grasp(
        &wet,
        GraspObject {
            wet_friction: None,
            ..obj
        },
        60.0,
        1,
        TokioClock::new(),
    ) else {
        panic!("an object without its wet friction in a wet scene is refused")
    };
    assert!(e.to_string().contains("no wet_friction"), "{e}");
}

#[test]
fn a_current_meets_the_outline_it_sees_not_the_top() {
    // A standing cylinder 30 mm across and 50 mm tall: 30 × 50 mm² from the side,
    // π/4 · 30² mm² from above.
    let tall = GraspObject::standing(
        "tall",
        RodShape::Circle,
        0.03,
        1.0,
        ObjectProfile::Prism { height_m: 0.05 },
    );
    assert!((tall.flow_area_m2 - 0.03 * 0.05).abs() < 1e-12);
    assert!((tall.drag_area_m2 - std::f64::consts::PI / 4.0 * 0.03 * 0.03).abs() < 1e-12);
    // An oval 30 mm across the fingers and 18 mm deep shows the current 18 × 50 mm².
    let oval = GraspObject::standing(
        "oval",
        RodShape::Oval,
        0.03,
        0.6,
        ObjectProfile::Prism { height_m: 0.05 },
    );
    assert!((oval.flow_area_m2 - 0.018 * 0.05).abs() < 1e-12);
    // A ball: its disc either way; a taper: the trapezoid of its side.
    let ball = GraspObject::standing(
        "ball",
        RodShape::Circle,
        0.04,
        1.0,
        ObjectProfile::Sphere {},
    );
    assert!((ball.flow_area_m2 - ball.drag_area_m2).abs() < 1e-15);
    let bottle = GraspObject::standing(
        "bottle",
        RodShape::Circle,
        0.04,
        1.0,
        ObjectProfile::Taper {
            height_m: 0.08,
            top_width_m: 0.025,
        },
    );
    assert!((bottle.flow_area_m2 - 0.5 * (0.04 + 0.025) * 0.08).abs() < 1e-12);
}

#[tokio::test(start_paused = true)]
async fn a_taller_object_is_pushed_harder_by_the_same_current() {
    let flow = with_effects(vec![Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: 0.3,
        gust_m_s: 0.0,
        period_s: 0.5,
        spectrum: None,
    }]);
    let spread_of = |height_m: f64| {
        let flow = flow.clone();
        async move {
            let obj = GraspObject::standing(
                "c",
                RodShape::Circle,
                0.03,
                1.0,
                ObjectProfile::Prism { height_m },
            );
            let obj = GraspObject {
                grasp_height_m: 0.015,
                ..obj
            };
            let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
            let count = count_for(&probe, 1.5);
            let (_, h, clock) = grip_at(&flow, obj, count).await;
            let t = clock.now();
            let a = -h.true_wrench_on(0, t).expect("truth").force_n[0];
            let b = -h.true_wrench_on(1, t).expect("truth").force_n[0];
            b - a
        }
    };
    let short = spread_of(0.03).await;
    let tall = spread_of(0.06).await;
    // Twice the side: twice the push for the fingers to balance.
    assert!(short > 0.01 && tall > 1.5 * short, "{short} {tall}");
}

#[tokio::test(start_paused = true)]
async fn a_declared_current_squeezes_one_finger_more_than_the_other() {
    let flow = with_effects(vec![Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: 0.3,
        gust_m_s: 0.2,
        period_s: 0.5,
        spectrum: None,
    }]);
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    let mut spreads = Vec::new();
    for scene in [land(), flow] {
        let (_, h, clock) = grip_at(&scene, obj.clone(), count).await;
        let mut spread = Vec::new();
        for i in 0..20 {
            let t = TimestampNs(clock.now().0 + i * 50_000_000);
            let a = -h.true_wrench_on(0, t).expect("truth").force_n[0];
            let b = -h.true_wrench_on(1, t).expect("truth").force_n[0];
            spread.push(a - b);
        }
        spreads.push(spread);
    }
    assert!(
        spreads[0].iter().all(|d| d.abs() < 1e-9),
        "{:?}",
        spreads[0]
    );
    // Pushed towards finger 1 (+x): finger 1 squeezed harder on the whole, by a
    // varying amount (the gusts' inertia, Morison's ρV(1 + C_a)·du/dt, pushes back
    // while the current slows, more than the drag at these gusts).
    let mean = spreads[1].iter().sum::<f64>() / spreads[1].len() as f64;
    assert!(mean < -0.01, "{mean}: {:?}", spreads[1]);
    assert!(
        spreads[1].iter().filter(|d| **d < 0.0).count() >= 15,
        "{:?}",
        spreads[1]
    );
    let (lo, hi) = spreads[1]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), d| {
            (l.min(*d), h.max(*d))
        });
    assert!(hi - lo > 0.01, "the gusts vary: {lo} … {hi}");
}

#[tokio::test(start_paused = true)]
async fn the_balance_bracketed_near_the_last_shift_is_the_balance_bracketed_over_the_reach() {
    // The balance starts its bracket at the last step's shift: from any last shift
    // (none, near, far, at and past the reach's end, not a number) it finds the shift
    // the whole-reach bracket finds, for pushes small, large and beyond what the grip
    // holds (the object then sits at the reach's end).
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    let (_, h, _) = grip_at(&land(), obj.clone(), count).await;
    let mut s = h.state.lock().expect("state");
    let reach = 0.25 * obj.max_width_m();
    for push_n in [0.0, 0.01, -0.2, 0.7, -1.4, 50.0, -50.0] {
        s.shift_m = f64::NAN;
        let whole = s.balance_shift(push_n).expect("balance");
        assert!(whole.abs() <= reach, "push {push_n}: {whole}");
        // Gripped by both fingers: a push moves the object.
        assert!(
            push_n.abs() < 1e-3 || whole.abs() > 1e-7,
            "push {push_n}: {whole}"
        );
        for last_m in [
            0.0,
            whole + 3e-6,
            whole - 2e-4,
            0.9 * reach,
            reach,
            -2.0 * reach,
        ] {
            s.shift_m = last_m;
            let warm = s.balance_shift(push_n).expect("balance");
            assert!(
                (warm - whole).abs() <= 1e-9,
                "push {push_n} N from {last_m} m: {warm} against {whole}"
            );
        }
    }
}

#[test]
fn the_squeeze_along_the_shift_is_the_whole_contacts_bit_for_bit() {
    // The balance's iterations ask only for the squeeze as the shift changes: the
    // shortcut must give the whole contact's bits, for every shipped object (standing,
    // lying, tapered), both fingers, turned, sheared, pressed in and not touching.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scene: SceneSpec =
        softtouch_schemas::config::load_toml(&root.join("scenes/grasp.toml")).expect("loads");
    let mut objects: Vec<GraspObject> = scene.objects.iter().map(GraspObject::from_spec).collect();
    objects.push(GraspObject::cylinder("lying", 0.01));
    let finger = FingerGeometry::default();
    let params = ContactParams::default();
    let mut compared = 0;
    let mut pressed = 0;
    for obj in &objects {
        let reach = 0.25 * obj.max_width_m();
        for k in 0..2 {
            for (opening_m, yaw_rad, shear_n) in [
                (obj.grasp_width_m, 0.0, [0.0, 0.0]),
                (obj.grasp_width_m - 0.002, 0.3, [0.2, -1.5]),
                (obj.max_width_m() + 0.01, -0.7, [0.0, 0.4]),
                (0.5 * obj.grasp_width_m, 1.2, [-3.0, 2.0]),
            ] {
                let grip = Grip {
                    opening_m,
                    shift_m: 0.0,
                    yaw_rad,
                };
                let strips = Arc::new(Strips::new(&finger, &params, obj, k, yaw_rad));
                let along =
                    SqueezeAlongShift::new(strips, &params, obj, &grip, shear_n).expect("finite");
                for shift_m in [0.0, -0.0, 1e-9, -3e-6, 2e-4, -reach, reach, 0.37 * reach] {
                    let whole = finger_contact(
                        &finger,
                        &params,
                        obj,
                        k,
                        &Grip { shift_m, ..grip },
                        shear_n,
                    )
                    .expect("contact");
                    let (normal_n, squeeze_n) = along.at(shift_m).expect("finite");
                    let what = format!("{} finger {k} at {grip:?} shifted {shift_m}", obj.name);
                    assert_eq!(squeeze_n.to_bits(), whole.squeeze_n().to_bits(), "{what}");
                    assert_eq!(normal_n.to_bits(), whole.normal_n.to_bits(), "{what}");
                    compared += 1;
                    pressed += usize::from(normal_n > 0.0);
                }
            }
        }
    }
    assert!(
        pressed > compared / 3 && pressed < compared,
        "{pressed} of {compared}"
    );
    // Not finite: no answer from the shortcut, an error from the whole contact.
    let obj = &objects[0];
    let grip = Grip {
        opening_m: obj.grasp_width_m,
        ..Grip::default()
    };
    let strips = |k| Arc::new(Strips::new(&finger, &params, obj, k, 0.0));
    let along = SqueezeAlongShift::new(strips(0), &params, obj, &grip, [0.0; 2]).expect("finite");
    assert!(along.at(f64::NAN).is_none());
    assert!(along.at(f64::INFINITY).is_none());
    let nan_grip = Grip {
        opening_m: f64::NAN,
        ..grip
    };
    assert!(SqueezeAlongShift::new(strips(0), &params, obj, &nan_grip, [0.0; 2]).is_err());
    assert!(SqueezeAlongShift::new(strips(1), &params, obj, &grip, [f64::NAN, 0.0]).is_err());
}

#[tokio::test(start_paused = true)]
async fn turning_a_gripped_cylinder_makes_a_torque_about_z_that_the_wrist_removes() {
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 2.0);
    let run = |follow: bool| {
        let obj = obj.clone();
        async move {
            let (_, h, clock) = grip_at(&land(), obj, count).await;
            let now = clock.now();
            let tz0 = h.true_wrench(now).expect("truth").torque_nm[2];
            h.schedule_object_yaw(now, 0.05, 0.5).expect("turn");
            if follow {
                h.set_wrist_target(0.05).expect("wrist");
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
            let now = clock.now();
            let w0 = h.true_wrench_on(0, now).expect("truth");
            let w1 = h.true_wrench_on(1, now).expect("truth");
            (
                w0.torque_nm[2] - tz0,
                w1.torque_nm[2] - tz0,
                h.wrist_yaw(now).expect("wrist"),
            )
        }
    };
    let (tz0, tz1, wrist) = run(false).await;
    assert!(wrist.abs() < 1e-15);
    // Measured from the shear, not assumed: both fingers, the same sign.
    assert!(tz0 < -1e-4 && tz1 < -1e-4, "{tz0} {tz1}");
    let (fz0, fz1, wrist) = run(true).await;
    assert!((wrist - 0.05).abs() < 1e-9);
    assert!(
        fz0.abs() < 0.05 * tz0.abs() && fz1.abs() < 0.05 * tz1.abs(),
        "{fz0} {fz1}"
    );
}

#[tokio::test(start_paused = true)]
async fn the_second_finger_has_its_own_camera_and_mirrors_the_first() {
    let obj = cylinder_standing();
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    let (_, h, clock) = grip_at(&land(), obj, count).await;
    let now = clock.now();
    let (w0, w1) = (
        h.true_wrench_on(0, now).expect("truth"),
        h.true_wrench_on(1, now).expect("truth"),
    );
    for i in 0..6 {
        assert!(
            (w0.to_array()[i] - w1.to_array()[i]).abs() < 1e-9,
            "{w0:?} {w1:?}"
        );
    }
    assert!(h.true_wrench_on(2, now).is_err());
    let mut cam = h.second_camera().expect("camera");
    let frame = cam.frame_after(now, 100).await.expect("frame");
    assert_eq!(frame.data.len(), 640 * 480 * 3);
    assert!(frame.meta.t >= now);
}

#[test]
fn bad_lifts_and_turns_are_refused_with_the_field() {
    let (_, _, h) =
        soft_grasp(&land(), cylinder_standing(), 30.0, 0, TokioClock::new()).expect("builds");
    for (height, speed, accel, field) in [
        (f64::NAN, 0.1, 1.0, "height_m"),
        (0.1, 0.0, 1.0, "speed_m_s"),
        (0.1, 0.1, -1.0, "accel_m_s2"),
    ] {
        let err = h
            .start_lift(TimestampNs::ZERO, height, speed, accel)
            .expect_err("refused");
        assert!(err.to_string().contains(field), "{err}");
    }
    assert!(h.schedule_object_yaw(ms(0), f64::INFINITY, 1.0).is_err());
    h.schedule_object_yaw(ms(100), 0.5, 1.0).expect("turn");
    let err = h
        .schedule_object_yaw(ms(500), 0.0, 1.0)
        .expect_err("overlap");
    assert!(err.to_string().contains("overlaps"), "{err}");
    assert!(h.set_wrist_target(f64::NAN).is_err());
}

#[test]
fn the_shipped_scenes_declare_five_graspable_objects() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for file in [
        "scenes/grasp.toml",
        "scenes/water.toml",
        "scenes/grasp-water.toml",
    ] {
        let scene: SceneSpec =
            softtouch_schemas::config::load_toml(&root.join(file)).expect("loads and validates");
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(
            names,
            ["cylinder", "oval-tube", "ball", "bottle", "cake"],
            "{file}"
        );
        for spec in &scene.objects {
            let obj = GraspObject::from_spec(spec);
            let (_, _, h) = soft_grasp(&scene, obj.clone(), 30.0, 0, TokioClock::new())
                .unwrap_or_else(|e| panic!("{file} {}: {e}", spec.name));
            let touch = h.contact_count(0.02).expect("curve");
            assert!(touch.is_some(), "{file} {}: never touched", spec.name);
            // Only what the fingers' faces pass can be landed on: the bottle's 40 mm
            // base stands below the fingertips, so the room is the neck's, not
            // (50 − 40) / 2 = 5 mm.
            if spec.name == "bottle" {
                assert!(obj.placed([0.008, 0.0, 0.0]).is_some(), "{file}");
            }
            // The open-loop grasp width squeezes it.
            let f = squeeze(&obj, 0, obj.grasp_width_m);
            assert!(f > 0.05, "{file} {}: {f} N at the grasp width", spec.name);
        }
    }
}

#[tokio::test(start_paused = true)]
async fn a_loop_slower_than_the_camera_gets_the_newest_frame_not_the_next_queued_one() {
    let clock = TokioClock::new();
    let (_, mut cam, _) =
        soft_grasp(&land(), cylinder_standing(), 120.0, 0, clock).expect("builds");
    let first = cam
        .latest_frame_after(TimestampNs::ZERO, 100)
        .await
        .expect("frame");
    assert_eq!(first.meta.sequence, 0);
    // The loop took 50 ms (six frames at 120 Hz) to act on it.
    tokio::time::sleep(Duration::from_millis(50)).await;
    let after = TimestampNs(first.meta.t.0 + 1);
    let newest = cam.latest_frame_after(after, 100).await.expect("frame");
    assert_eq!(
        newest.meta.sequence, 6,
        "exposed at 50 ms, the last before now"
    );
    assert!(newest.meta.t <= clock.now());
    let queued = cam.frame_after(after, 100).await.expect("frame");
    assert_eq!(
        queued.meta.sequence, 1,
        "what frame_after (collection) still gives"
    );
    // Keeping up: the next frame, waited for, as before.
    let next = cam
        .latest_frame_after(TimestampNs(newest.meta.t.0 + 1), 100)
        .await
        .expect("frame");
    assert_eq!(next.meta.sequence, 7);
}

/// The objects the contact is tried on: the grasp scene's five shapes and a lying rod.
fn contact_objects() -> Vec<GraspObject> {
    vec![
        GraspObject::cylinder("rod", 0.02),
        cylinder_standing(),
        GraspObject::standing(
            "oval",
            RodShape::Oval,
            0.03,
            0.6,
            ObjectProfile::Prism { height_m: 0.05 },
        ),
        GraspObject::standing(
            "ball",
            RodShape::Circle,
            0.04,
            1.0,
            ObjectProfile::Sphere {},
        ),
        GraspObject::standing(
            "bottle",
            RodShape::Circle,
            0.04,
            1.0,
            ObjectProfile::Taper {
                height_m: 0.08,
                top_width_m: 0.025,
            },
        ),
        GraspObject::standing(
            "box",
            RodShape::Square,
            0.03,
            1.0,
            ObjectProfile::Prism { height_m: 0.03 },
        ),
    ]
}

fn contact(obj: &GraspObject, k: usize, grip: Grip) -> super::touch::FingerContact {
    finger_contact(
        &FingerGeometry::default(),
        &ContactParams::default(),
        obj,
        k,
        &grip,
        [0.0; 2],
    )
    .expect("contact")
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 200, .. proptest::prelude::ProptestConfig::default() })]

    /// Over random objects, offsets (across and along the finger), turns, shifts and
    /// openings: every force finite, the squeeze and the normal force never negative.
    #[test]
    fn the_grasp_contact_is_finite_and_never_pulls(
        which in 0usize..6,
        dy in -0.02..0.02f64,
        dz in -0.02..0.02f64,
        yaw in -1.6..1.6f64,
        shift in -0.005..0.005f64,
        opening in 0.0..0.05f64,
        k in 0usize..2,
    ) {
        let mut obj = contact_objects()[which].clone();
        obj.offset_m = [0.0, dy, dz];
        let c = contact(&obj, k, Grip { opening_m: opening, shift_m: shift, yaw_rad: yaw });
        let w = c.contact.wrench;
        proptest::prop_assert!(w.is_finite(), "{w:?}");
        proptest::prop_assert!(c.normal_n.is_finite() && c.normal_n >= 0.0, "{}", c.normal_n);
        proptest::prop_assert!(c.squeeze_n() >= -1e-12, "pulls: {}", c.squeeze_n());
        proptest::prop_assert!(w.force_norm_n() < 1e4);
    }

    /// A grazing contact: as the opening closes through the object's width the squeeze
    /// rises from exactly 0 without a jump (penetration → 0⁺ gives force → 0⁺).
    #[test]
    #[allow(clippy::float_cmp)] // exactly no force outside the object
    fn a_grazing_contact_starts_from_zero(which in 0usize..6, eps_um in 0.01..2.0f64) {
        let obj = contact_objects()[which].clone();
        // The widest opening with any contact, found by bisection on the squeeze.
        let at = |opening: f64| contact(&obj, 0, Grip { opening_m: opening, ..Grip::default() }).squeeze_n();
        let (mut lo, mut hi) = (0.0, 0.05);
        proptest::prop_assume!(at(lo) > 0.0 && at(hi) == 0.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if at(mid) > 0.0 { lo = mid } else { hi = mid }
        }
        let eps = eps_um * 1e-6;
        // Just outside: nothing; just inside: a force that shrinks with the depth.
        proptest::prop_assert_eq!(at(hi + eps), 0.0);
        let inside = at(lo - eps);
        proptest::prop_assert!(inside > 0.0 && inside < 0.05, "{} µm in: {inside} N", eps_um);
        proptest::prop_assert!(at(lo - 2.0 * eps) >= inside);
    }
}

#[test]
#[allow(clippy::float_cmp)] // exactly no force without contact
fn a_contact_at_the_finger_edge_and_no_contact_at_all() {
    let obj = cylinder_standing();
    let grip = Grip {
        opening_m: 0.026,
        ..Grip::default()
    };
    let centred = contact(&obj, 0, grip);
    assert!(centred.normal_n > 0.0);
    // Moved across the finger's face to its edge (the face is 32 mm wide at its base)
    // and beyond: less contact, then none; never a negative or non-finite force.
    let mut last = centred.normal_n;
    for dy_mm in [4.0, 8.0, 12.0, 16.0, 20.0, 30.0, 40.0] {
        let mut o = obj.clone();
        o.offset_m = [0.0, dy_mm / 1000.0, 0.0];
        let c = contact(&o, 0, grip);
        assert!(c.contact.wrench.is_finite(), "{dy_mm} mm");
        assert!(
            c.normal_n >= 0.0 && c.normal_n <= last + 1e-9,
            "{dy_mm} mm: {} > {last}",
            c.normal_n
        );
        last = c.normal_n;
    }
    assert_eq!(last, 0.0, "30 mm clear of the face's edge: no contact");
    // Fingers wider than the object: no contact, a zero wrench.
    let open = contact(
        &obj,
        1,
        Grip {
            opening_m: 0.045,
            ..Grip::default()
        },
    );
    assert_eq!(open.normal_n, 0.0);
    assert_eq!(open.squeeze_n(), 0.0);
}

#[tokio::test(start_paused = true)]
#[allow(clippy::float_cmp)] // exactly no force without contact
async fn a_lift_with_no_contact_and_no_load_is_not_held() {
    // The fingers left open: nothing touches the object, nothing carries it.
    let (_, h, clock) = grip_at(&land(), cylinder_standing(), 0).await;
    let t = clock.now();
    assert_eq!(h.true_wrench_on(0, t).expect("truth").force_n, [0.0; 3]);
    h.start_lift(t, 0.05, 0.1, 1.0).expect("lift");
    tokio::time::sleep(Duration::from_secs(1)).await;
    let state = h.hold_state().expect("state");
    assert!(!matches!(state, HoldState::Held), "{state:?}");
}

#[test]
fn the_added_mass_of_a_spheroid_follows_lambs_table() {
    // A sphere's ½ both ways; Lamb's (1932, §373) prolate values at 2:1 and 3:1.
    let close = |a: f64, b: f64, tol: f64| (a - b).abs() < tol;
    assert_eq!(spheroid_added_mass(1.0), (0.5, 0.5));
    let (along, across) = spheroid_added_mass(2.0);
    assert!(
        close(along, 0.210, 5e-4) && close(across, 0.704, 5e-4),
        "{along} {across}"
    );
    let (along, across) = spheroid_added_mass(3.0);
    assert!(
        close(along, 0.122, 5e-4) && close(across, 0.804, 5e-4),
        "{along} {across}"
    );
    // α₀ + 2β₀ = 2 for every spheroid, prolate and oblate, and continuous through 1.
    for ratio in [
        1e-3,
        0.1,
        0.5,
        0.999,
        0.999_999_9,
        1.000_000_1,
        1.001,
        1.7,
        10.0,
        1e3,
    ] {
        let (along, across) = spheroid_added_mass(ratio);
        let alpha = 2.0 * along / (1.0 + along);
        let beta = 2.0 * across / (1.0 + across);
        assert!(
            close(alpha + 2.0 * beta, 2.0, 1e-9),
            "{ratio}: {along} {across}"
        );
        if (ratio - 1.0).abs() < 1e-2 {
            assert!(
                close(along, 0.5, 1e-2) && close(across, 0.5, 1e-2),
                "{ratio}"
            );
        }
    }
    // Longer: less fluid to push ahead along the axis, more across it.
    assert!(spheroid_added_mass(4.0).0 < spheroid_added_mass(2.0).0);
    assert!(spheroid_added_mass(0.5).0 > 0.5 && spheroid_added_mass(0.5).1 < 0.5);
    // Needles, discs and what is not a ratio: finite.
    for ratio in [0.0, -1.0, 1e-300, 1e300, f64::NAN, f64::INFINITY] {
        let (along, across) = spheroid_added_mass(ratio);
        assert!(
            along.is_finite() && across.is_finite() && along >= 0.0,
            "{ratio}"
        );
    }
}

#[test]
fn a_ball_carries_half_its_volume_of_fluid_both_ways() {
    // Its equivalent spheroid is itself: length over diameter 1, C_a = ½ along and
    // across (a cylinder's volume relation made it 1.22 and 0.39/0.56).
    for d in [0.01, 0.04, 0.2] {
        let ball =
            GraspObject::standing("ball", RodShape::Circle, d, 1.0, ObjectProfile::Sphere {});
        for c in ball.added_mass_xz {
            assert!((c - 0.5).abs() < 1e-9, "{d}: {:?}", ball.added_mass_xz);
        }
    }
    // A standing cylinder as tall as twice its width: the spheroid of its volume and
    // height is prolate, lighter along its axis than across it.
    let tall = GraspObject::standing(
        "tall",
        RodShape::Circle,
        0.02,
        1.0,
        ObjectProfile::Prism { height_m: 0.04 },
    );
    let [across, along] = tall.added_mass_xz;
    assert!(along < 0.5 && across > 0.5, "{:?}", tall.added_mass_xz);
    // The water scene's cylinder (30 mm wide, 50 mm tall) carries what its comment
    // says: 0.343 along its axis, 0.593 across (the comment once said 0.27 and 0.65).
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scene: SceneSpec =
        softtouch_schemas::config::load_toml(&root.join("scenes/grasp-water.toml")).expect("loads");
    let cylinder = GraspObject::from_spec(scene.object("cylinder").expect("a cylinder"));
    let [across, along] = cylinder.added_mass_xz;
    assert!(
        (along - 0.343).abs() < 5e-4 && (across - 0.593).abs() < 5e-4,
        "{:?}",
        cylinder.added_mass_xz
    );
    let text = std::fs::read_to_string(root.join("scenes/grasp-water.toml")).expect("reads");
    assert!(text.contains("0.343 for the cylinder") && text.contains("0.593 for the cylinder"));
}

#[test]
fn an_object_lighter_than_the_fluid_is_refused_not_floated() {
    // 35 cm³ of cylinder: it floats under 35 g.
    let light = GraspObject {
        mass_kg: 0.02,
        ..cylinder_standing()
    };
    let water = with_effects(vec![buoyancy()]);
    let err = soft_grasp(&water, light.clone(), 60.0, 1, TokioClock::new())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        err.contains("object `cylinder`: 20.0 g in ") && err.contains("floats"),
        "{err}"
    );
    // On land it stands.
    assert!(soft_grasp(&land(), light.clone(), 60.0, 1, TokioClock::new()).is_ok());
    let heavy = GraspObject {
        mass_kg: 0.05,
        ..light
    };
    assert!(soft_grasp(&water, heavy, 60.0, 1, TokioClock::new()).is_ok());
    // The shipped water scene's objects all sink; its cake dry would not.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut scene: SceneSpec =
        softtouch_schemas::config::load_toml(&root.join("scenes/grasp-water.toml")).expect("loads");
    crate::check_scene_objects(&scene).expect("every object sinks");
    if let Some(cake) = scene.objects.iter_mut().find(|o| o.name == "cake") {
        cake.mass_kg = 0.02;
    }
    let err = crate::check_scene_objects(&scene)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        err.contains("object `cake`") && err.contains("floats"),
        "{err}"
    );
}

#[test]
fn drag_coefficients_follow_the_section() {
    let sphere = GraspObject::standing("b", RodShape::Circle, 0.04, 1.0, ObjectProfile::Sphere {});
    assert!((sphere.drag_coefficient - 0.47).abs() < 1e-12);
    assert!((sphere.lift_drag_coefficient - 0.47).abs() < 1e-12);
    // A short body, not an infinite one (White 2011, Table 7.3): a 60 mm × 30 mm
    // standing cylinder (L/D 2) sees 0.68 across, not 1.2, and 0.85 end-on on its lift;
    // a square prism the same share of its 2.1.
    let prism = ObjectProfile::Prism { height_m: 0.06 };
    let o = |shape| GraspObject::standing("o", shape, 0.03, 1.0, prism);
    assert!((o(RodShape::Circle).drag_coefficient - 0.68).abs() < 1e-12);
    assert!((o(RodShape::Circle).lift_drag_coefficient - 0.85).abs() < 1e-12);
    assert!((o(RodShape::Square).drag_coefficient - 2.1 * 0.68 / 1.2).abs() < 1e-12);
    // Between the table's rows, along ln(L/D): 0.64 at 1 and 0.68 at 2 give 0.66 at √2.
    let [across, _] = default_drag_coefficients(RodShape::Circle, Some(prism), 2f64.sqrt());
    assert!((across - 0.66).abs() < 1e-12, "{across}");
    // Beyond its ends it holds them; a slenderness that is no number is a cube's.
    let cd = |l_d: f64| default_drag_coefficients(RodShape::Circle, Some(prism), l_d);
    assert!((cd(0.1)[0] - 0.64).abs() < 1e-12 && (cd(0.1)[1] - 1.15).abs() < 1e-12);
    assert!((cd(1e9)[0] - 1.2).abs() < 1e-12 && (cd(1e9)[1] - 0.99).abs() < 1e-12);
    for bad in [f64::NAN, f64::INFINITY, 0.0, -1.0] {
        assert_eq!(
            cd(bad).map(f64::to_bits),
            cd(1.0).map(f64::to_bits),
            "{bad}"
        );
    }
    // A lying cylinder as long as it is wide: 0.64 across, its lift across it too.
    let lying = GraspObject::cylinder("c", 0.03);
    assert!((lying.drag_coefficient - 0.64).abs() < 1e-12);
    assert!((lying.lift_drag_coefficient - 0.64).abs() < 1e-12);
    // A scene's own value wins.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scene: SceneSpec =
        softtouch_schemas::config::load_toml(&root.join("scenes/grasp.toml")).expect("loads");
    let mut spec = softtouch_schemas::scene::ObjectSpec {
        drag_coefficient: Some(0.8),
        ..scene.objects.first().cloned().expect("an object")
    };
    assert!((GraspObject::from_spec(&spec).drag_coefficient - 0.8).abs() < 1e-12);
    assert!((GraspObject::from_spec(&spec).lift_drag_coefficient - 0.8).abs() < 1e-12);
    spec.drag_coefficient = None;
    assert!(GraspObject::from_spec(&spec).drag_coefficient > 0.4);
}

/// The land scene with the object on a support of friction `mu`, plus `more`.
fn on_support(mu: f64, more: Vec<Effect>) -> SceneSpec {
    let mut effects = vec![Effect::ObjectSupport { friction: mu }];
    effects.extend(more);
    with_effects(effects)
}

fn buoyancy() -> Effect {
    Effect::ObjectBuoyancy {
        fluid_density_kg_m3: 1000.0,
    }
}

/// Places `obj` `offset_x_m` along +x in `scene`, closes the fingers at the slowest
/// speed to `count` and waits 2 s: (the object's x before and after, m, the squeeze
/// on finger 0 and on finger 1 at the end, N).
async fn push_by_closing(
    scene: &SceneSpec,
    obj: GraspObject,
    offset_x_m: f64,
    count: u8,
) -> (f64, f64, [f64; 2]) {
    let clock = TokioClock::new();
    let (mut g, _, h) = soft_grasp(scene, obj, 60.0, 1, clock).expect("builds");
    assert!(h.place_object([offset_x_m, 0.0, 0.0]).expect("placed"));
    let before = h.object_x_m().expect("x");
    g.activate().await.expect("activates");
    close_to(&mut g, count, 0, 2).await;
    let after = h.object_x_m().expect("x");
    let t = clock.now();
    let squeeze = [0, 1].map(|k| -h.true_wrench_on(k, t).expect("truth").force_n[0]);
    (before, after, squeeze)
}

#[tokio::test(start_paused = true)]
async fn the_first_finger_pushes_a_light_wet_object_further_than_a_heavy_dry_one() {
    let light = GraspObject {
        mass_kg: 0.03,
        ..cylinder_standing()
    };
    let heavy = GraspObject {
        mass_kg: 0.3,
        ..cylinder_standing()
    };
    let (_, probe, _) = grip_at(&land(), light.clone(), 0).await;
    let count = count_for(&probe, 1.5);
    // 4 mm towards finger 1: finger 1 touches first and pushes it along −x.
    let offset = 0.004;
    let mu = 0.4;
    let water = on_support(mu, vec![buoyancy()]);
    let (b0, light_x, light_sq) = push_by_closing(&water, light.clone(), offset, count).await;
    let (_, heavy_x, heavy_sq) =
        push_by_closing(&on_support(mu, vec![]), heavy.clone(), offset, count).await;
    assert!((b0 - offset).abs() < 1e-12, "placed at {b0}");
    let pushed_light = offset - light_x;
    let pushed_heavy = offset - heavy_x;
    assert!(
        pushed_light > pushed_heavy + 1e-4 && pushed_heavy > 0.0,
        "light {pushed_light} m, heavy {pushed_heavy} m"
    );
    // The light one slid until the other finger met it: the fingers' difference is
    // what its support holds, μ·(m·g − ρ·g·V). The heavy one ends held by static
    // friction: a difference within what its support holds, and most of it.
    let hold =
        |o: &GraspObject, rho: f64| mu * (o.mass_kg * G_M_S2 - rho * G_M_S2 * o.volume_m3).max(0.0);
    let diff_light = light_sq[1] - light_sq[0];
    let diff_heavy = heavy_sq[1] - heavy_sq[0];
    let (hold_light, hold_heavy) = (hold(&light, 1000.0), hold(&heavy, 0.0));
    assert!(
        (diff_light - hold_light).abs() < 0.01,
        "{diff_light} vs {hold_light}"
    );
    assert!(
        diff_heavy <= hold_heavy + 1e-6 && diff_heavy > 0.5 * hold_heavy,
        "{diff_heavy} vs {hold_heavy}"
    );
    assert!(pushed_light > 0.9 * offset, "{pushed_light}");
    // A frictionless support (the effect absent): centred, no difference.
    let (_, x, sq) = push_by_closing(&land(), heavy, offset, count).await;
    assert!(
        x.abs() < 1e-12 && (sq[0] - sq[1]).abs() < 1e-9,
        "{x} {sq:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_current_sways_a_floating_object_by_what_its_drag_and_added_mass_predict() {
    // Neutrally buoyant (ρ·V = m), so its support holds nothing; a steady current
    // u along +x starts it from rest. m_eff·dv/dt = k·(u − v)² with k = ½·ρ·C_d·A:
    // x(t) = u·t − (m_eff/k)·ln(1 + k·u·t/m_eff), until it meets finger 1.
    let u = 0.05;
    let obj = cylinder_standing();
    let obj = GraspObject {
        mass_kg: 1000.0 * obj.volume_m3,
        ..obj
    };
    let flow = Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: u,
        gust_m_s: 0.0,
        period_s: 1.0,
        spectrum: None,
    };
    let added = Effect::ObjectAddedMass {
        fluid_density_kg_m3: 1000.0,
    };
    let k = 0.5 * 1000.0 * obj.drag_coefficient * obj.flow_area_m2;
    let predicted = |m_eff: f64, t: f64| u * t - m_eff / k * (1.0 + k * u * t / m_eff).ln();
    for (more, m_eff) in [
        (vec![], obj.mass_kg),
        (vec![added], obj.mass_kg * (1.0 + obj.added_mass_xz[0])),
    ] {
        let mut effects = vec![buoyancy(), flow.clone()];
        effects.extend(more);
        let scene = on_support(0.5, effects);
        let clock = TokioClock::new();
        let (_, _, h) = soft_grasp(&scene, obj.clone(), 60.0, 1, clock).expect("builds");
        for t_ms in [100, 200, 300] {
            tokio::time::sleep_until(tokio::time::Instant::now() + Duration::from_millis(100))
                .await;
            let x = h.object_x_m().expect("x");
            let want = predicted(m_eff, t_ms as f64 * 1e-3);
            assert!(
                (x - want).abs() < 0.03 * want,
                "m_eff {m_eff} kg at {t_ms} ms: {x} m, predicted {want} m"
            );
        }
    }
    // On a support with friction, a heavier object the current cannot move stays put.
    let heavy = GraspObject {
        mass_kg: 0.2,
        ..cylinder_standing()
    };
    let scene = on_support(0.5, vec![buoyancy(), flow]);
    let (_, _, h) = soft_grasp(&scene, heavy, 60.0, 1, TokioClock::new()).expect("builds");
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(h.object_x_m().expect("x").abs() < 1e-15);
}

/// The largest lift acceleration (m/s², to 0.1) the grip holds `obj` through.
async fn largest_held_accel(scene: &SceneSpec, obj: &GraspObject, count: u8) -> f64 {
    let (mut lo, mut hi) = (0.1, 100.0);
    while hi - lo > 0.1 {
        let a = 0.5 * (lo + hi);
        let (_, h, clock) = grip_at(scene, obj.clone(), count).await;
        h.start_lift(clock.now(), 0.01, 0.5, a).expect("lift");
        tokio::time::sleep(Duration::from_millis(200)).await;
        if matches!(h.hold_state().expect("state"), HoldState::Held) {
            lo = a;
        } else {
            hi = a;
        }
    }
    lo
}

#[tokio::test(start_paused = true)]
async fn added_mass_lowers_the_lift_acceleration_the_grip_holds_in_proportion() {
    // The grip's friction carries m·(g + a) + m_a·a − ρ·g·V: the acceleration at the
    // edge of a slip scales by m / (m + m_a) once the weight less buoyancy is taken out.
    let obj = GraspObject {
        mass_kg: 0.03,
        ..cylinder_standing()
    };
    let (_, probe, _) = grip_at(&land(), obj.clone(), 0).await;
    let count = count_for(&probe, 0.6);
    let without = largest_held_accel(&with_effects(vec![buoyancy()]), &obj, count).await;
    let with = largest_held_accel(
        &with_effects(vec![
            buoyancy(),
            Effect::ObjectAddedMass {
                fluid_density_kg_m3: 1000.0,
            },
        ]),
        &obj,
        count,
    )
    .await;
    let m_a = 1000.0 * obj.added_mass_xz[1] * obj.volume_m3;
    let ratio = with / without;
    let want = obj.mass_kg / (obj.mass_kg + m_a);
    assert!(
        without > 1.0 && (ratio - want).abs() < 0.03,
        "{without} → {with}: {ratio} vs {want}"
    );
}

#[test]
#[allow(
    clippy::float_cmp,
    reason = "the seed moves only the phases: the periods and amplitudes are the declared bits"
)]
fn a_declared_gust_spectrum_is_its_components() {
    let flow = |spectrum: Vec<(f64, f64)>| Flow {
        density_kg_m3: 1000.0,
        mean_m_s: 0.05,
        gust_m_s: 0.0,
        period_s: 1.0,
        spectrum,
    };
    // One component: periodic with its period, between mean ± amplitude.
    let one = FlowSeries::new(flow(vec![(0.8, 0.1)]), 3);
    let speeds: Vec<f64> = (0..800)
        .map(|i| one.speed_m_s(f64::from(i) * 1e-3))
        .collect();
    for (i, v) in speeds.iter().enumerate() {
        let later = one.speed_m_s(i as f64 * 1e-3 + 0.8);
        assert!((v - later).abs() < 1e-12);
    }
    let (lo, hi) = speeds
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(
        (hi - 0.15).abs() < 1e-4 && (lo + 0.05).abs() < 1e-4,
        "{lo} {hi}"
    );
    // Two: the mean over a common period is the mean; the seed moves only the phases.
    let two = FlowSeries::new(flow(vec![(0.5, 0.03), (2.0, 0.02)]), 3);
    let mean = (0..2000)
        .map(|i| two.speed_m_s(f64::from(i) * 1e-3))
        .sum::<f64>()
        / 2000.0;
    assert!((mean - 0.05).abs() < 1e-9, "{mean}");
    let other = FlowSeries::new(flow(vec![(0.5, 0.03), (2.0, 0.02)]), 4);
    assert!(
        other
            .waves
            .iter()
            .zip(&two.waves)
            .all(|(a, b)| a.0 == b.0 && a.2 == b.2)
    );
    assert!(other.waves[0].1 != two.waves[0].1);
    // None at all: a steady current.
    let steady = FlowSeries::new(flow(Vec::new()), 3);
    assert!((steady.speed_m_s(12.3) - 0.05).abs() < 1e-15);
    assert!(steady.accel_m_s2(12.3).abs() < 1e-15);
    // The acceleration is the speed's derivative (central differences, 1 µs).
    for series in [&one, &two] {
        for i in 0..50 {
            let t = f64::from(i) * 0.037;
            let numeric = (series.speed_m_s(t + 1e-6) - series.speed_m_s(t - 1e-6)) / 2e-6;
            assert!((series.accel_m_s2(t) - numeric).abs() < 1e-5, "{t}");
        }
    }
}

/// Morison's inertia force: a neutrally buoyant object in an accelerating current, its
/// added mass declared, accelerates with the water (`ρV(1 + C_a)·du/dt` on
/// `m + C_a·ρV` with `m = ρV`); without `object_added_mass` its own inertia is `m`
/// alone and it accelerates `1 + C_a` times as fast. Without the force, a current at
/// rest that speeds up moved nothing in its first step.
#[test]
fn an_accelerating_current_pushes_by_the_water_it_accelerates() {
    let obj = cylinder_standing();
    let obj = GraspObject {
        mass_kg: 1000.0 * obj.volume_m3,
        ..obj
    };
    let flow = Effect::ObjectFlow {
        fluid_density_kg_m3: 1000.0,
        mean_m_s: 0.0,
        gust_m_s: 0.0,
        period_s: 1.0,
        spectrum: None,
    };
    let added = Effect::ObjectAddedMass {
        fluid_density_kg_m3: 1000.0,
    };
    let c_a = obj.added_mass_xz[0];
    assert!(c_a > 0.3, "{c_a}");
    for (effects, want) in [
        (vec![buoyancy(), flow.clone(), added], 1.0),
        (vec![buoyancy(), flow], 1.0 + c_a),
    ] {
        let scene = on_support(0.5, effects);
        let (_, _, h) =
            soft_grasp(&scene, obj.clone(), 60.0, 1, TokioClock::new()).expect("builds");
        let mut s = h.state.lock().expect("state");
        s.opening_mm = 60.0;
        s.shift_m = 0.0;
        s.slide_m_s = 0.0;
        let du_dt = 2.0;
        s.slide_on_support(0.5, 0.0, du_dt, 1e-3).expect("a step");
        // The object's velocity along +x is −slide.
        let accel = -s.slide_m_s / 1e-3;
        assert!(
            (accel - du_dt * want).abs() < 1e-3 * du_dt * want,
            "{accel} m/s², want {}",
            du_dt * want
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_grip_needs_both_fingers_whichever_one_the_loop_watches() {
    // On a tray, 4 mm towards finger 1: closing to a width that finger 1 reaches and
    // finger 0 does not, finger 1 pushes the object and finger 0 never feels it: no
    // grip. Closing on, both fingers press it: a grip, the smaller squeeze of the two.
    let scene = on_support(0.4, vec![]);
    let obj = GraspObject {
        mass_kg: 0.3,
        ..cylinder_standing()
    };
    let clock = TokioClock::new();
    let (mut g, _, h) = soft_grasp(&scene, obj, 60.0, 1, clock).expect("builds");
    assert!(h.place_object([0.004, 0.0, 0.0]).expect("placed"));
    g.activate().await.expect("activates");
    let mut squeezes = Vec::new();
    for opening_mm in [36.0, 28.0] {
        let position = softtouch_drivers::gripper::position_for_opening(opening_mm);
        close_to(&mut g, position, 0, 2).await;
        let t = clock.now();
        let sq = [0, 1].map(|k| -h.true_wrench_on(k, t).expect("truth").force_n[0]);
        squeezes.push((sq, h.peak_grip_n().expect("peak")));
    }
    let ([watched, other], grip) = squeezes[0];
    assert!(
        watched.abs() < 1e-12 && other > 0.05 && grip.abs() < 1e-12,
        "{squeezes:?}"
    );
    let ([a, b], grip) = squeezes[1];
    assert!(
        a > 0.05 && b > 0.05 && grip >= a.min(b) - 1e-12,
        "{squeezes:?}"
    );
    // A fresh placement starts ungripped again.
    assert!(h.place_object([0.0; 3]).expect("placed"));
    assert!(h.peak_grip_n().expect("peak").abs() < 1e-12);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 48, .. proptest::prelude::ProptestConfig::default() })]

    /// The support's law on its hard cases: frictionless to μ = 2, a 0.1 g to 10 kg
    /// object, currents to ±10 m/s either way, steps from 1 ns to 2 ms, fingers apart or
    /// pressing, any start inside the stroke moving at up to ±1 m/s: every step ends
    /// with a finite shift and speed inside the stroke, or the object out of reach.
    #[test]
    fn the_support_law_stays_finite_on_its_hard_cases(
        mu in 0.0..2.0f64,
        mass_kg in 1e-4..10.0f64,
        u in -10.0..10.0f64,
        dt_exp in -9.0..-2.7f64,
        opening_mm in 20.0..50.0f64,
        shift in -0.01..0.01f64,
        speed in -1.0..1.0f64,
        du_dt in -100.0..100.0f64,
    ) {
        let obj = GraspObject { mass_kg, ..cylinder_standing() };
        // The current's drag is in the law only where the scene declares a flow; the
        // drawn `u` is the current the step is given. Buoyancy only on what sinks (the
        // simulator refuses a floating object).
        let mut effects = vec![
            Effect::ObjectAddedMass { fluid_density_kg_m3: 1000.0 },
            Effect::ObjectFlow {
                fluid_density_kg_m3: 1000.0,
                mean_m_s: 0.0,
                gust_m_s: 0.0,
                period_s: 1.0,
                spectrum: None,
            },
        ];
        if mass_kg > 1000.0 * obj.volume_m3 {
            effects.push(buoyancy());
        }
        let scene = on_support(mu, effects);
        let (_, _, h) = soft_grasp(&scene, obj, 60.0, 1, TokioClock::new()).expect("builds");
        let mut s = h.state.lock().expect("state");
        let drag = s.flow.as_ref().map(|f| f.side_drag(s.object.as_ref().expect("placed")));
        proptest::prop_assert!(drag.is_some_and(|d| d > 0.0), "the drag term is exercised: {drag:?}");
        s.opening_mm = opening_mm;
        s.shift_m = shift;
        s.slide_m_s = speed;
        let dt_s = 10f64.powf(dt_exp);
        for _ in 0..5 {
            s.slide_on_support(mu, u, du_dt, dt_s).expect("a step");
            if s.object.is_none() {
                proptest::prop_assert!(matches!(s.hold, HoldState::Absent));
                break;
            }
            proptest::prop_assert!(s.shift_m.is_finite() && s.shift_m.abs() * 1000.0 <= STROKE_MM, "{}", s.shift_m);
            proptest::prop_assert!(s.slide_m_s.is_finite(), "{}", s.slide_m_s);
        }
    }
}
