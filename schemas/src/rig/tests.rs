use super::*;

fn ati(baud: u32) -> ForceSensorDevice {
    ForceSensorDevice::AtiSerial {
        port: "/dev/ttyUSB0".into(),
        baud,
        counts_per_force: 1.0,
        counts_per_torque: 1.0,
        latency_s: None,
    }
}

#[test]
fn the_default_skew_limit_follows_the_slowest_the_sensor_streams() {
    let p = crate::defaults::rig().procedure;
    assert!(p.max_skew_s.is_none());
    // A 1 kHz stream: the 5 ms floor.
    let sim = ForceSensorDevice::Sim { rate_hz: 1000.0 };
    assert!((p.max_skew_s_for(sim.least_rate_hz()) - DEFAULT_MAX_SKEW_S).abs() < 1e-12);
    // A serial box at 9600 baud carries 15 lines/s: two periods, 133 ms.
    let slow = ati(9600);
    assert!((slow.least_rate_hz() - 15.0).abs() < 1e-9);
    assert!((p.max_skew_s_for(slow.least_rate_hz()) - 2.0 / 15.0).abs() < 1e-9);
    // Faster links: never above the 7000 Hz the box can stream at most.
    assert!((ati(115_200).least_rate_hz() - 180.0).abs() < 1e-9);
    assert!(ati(u32::MAX).least_rate_hz() <= 7000.0);
    // A configured limit wins.
    let set = Procedure {
        max_skew_s: Some(0.002),
        ..p
    };
    assert!((set.max_skew_s_for(slow.least_rate_hz()) - 0.002).abs() < 1e-12);
}

/// The fields a rig's check refuses, in order.
fn refused(rig: &RigConfig) -> Vec<String> {
    let mut c = crate::config::Check::default();
    rig.validate(&mut c);
    c.problems().iter().map(|p| p.field.clone()).collect()
}

#[test]
fn a_serial_sensor_is_checked_against_what_its_baud_rate_carries() {
    // The defaults (25 readings in 50 ms, stale after 0.1 s) suit a 1 kHz stream,
    // not the 15 readings a second an ATI serial box sends at 9600 baud.
    let mut rig = crate::defaults::rig();
    assert!(refused(&rig).is_empty());
    rig.force_sensor = ati(9600);
    assert_eq!(
        refused(&rig),
        ["procedure.min_window_readings", "procedure.ft_stale_s"]
    );
    // What the messages suggest works: a 2 s window of 20 readings, 0.2 s stale.
    rig.procedure.ft_window_s = 2.0;
    rig.procedure.min_window_readings = 20;
    rig.procedure.ft_stale_s = 0.2;
    assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));
    // Just under three periods is refused; a skew limit under half a period too.
    rig.procedure.ft_stale_s = 0.199;
    rig.procedure.max_skew_s = Some(0.03);
    assert_eq!(
        refused(&rig),
        ["procedure.ft_stale_s", "procedure.max_skew_s"]
    );
    // A faster link carries more, but 180 lines a second still not 25 in 50 ms.
    let mut fast = crate::defaults::rig();
    fast.force_sensor = ati(115_200);
    assert_eq!(refused(&fast), ["procedure.min_window_readings"]);
}

#[test]
fn a_franka_table_carries_its_end_effector_payload_and_real_time_setting() {
    let toml = r#"
driver = "franka"
address = "172.16.0.2"
reflex_force_n = 30.0
realtime = "ignore"
[end_effector]
translation_m = [0.0, 0.0, 0.12]
rotation_wxyz = [1.0, 0.0, 0.0, 0.0]
[payload]
mass_kg = 0.35
com_in_flange_m = [0.0, 0.0, 0.06]
"#;
    let arm: ArmDevice = toml::from_str(toml).unwrap_or_else(|e| panic!("{e}"));
    let ArmDevice::Franka {
        realtime,
        end_effector,
        payload,
        reflex_torque_nm,
        ..
    } = &arm
    else {
        panic!("not franka: {arm:?}");
    };
    assert_eq!(*realtime, Realtime::Ignore);
    assert_eq!(
        end_effector.as_deref().map(|p| p.translation_m[2]),
        Some(0.12)
    );
    assert_eq!(payload.as_deref().map(|p| p.inertia_kg_m2), Some([0.0; 9]));
    assert!(reflex_torque_nm.is_none());
    // Left out, real time is enforced.
    let plain: ArmDevice =
        toml::from_str("driver = \"franka\"\naddress = \"a\"\nreflex_force_n = 30.0\n")
            .unwrap_or_else(|e| panic!("{e}"));
    assert!(matches!(
        plain,
        ArmDevice::Franka {
            realtime: Realtime::Enforce,
            ..
        }
    ));
    let mut rig = crate::defaults::rig();
    rig.arm = arm;
    assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));
    // A translation beyond reach of any finger, a zero rotation, NaN inertia.
    if let ArmDevice::Franka {
        end_effector,
        payload,
        ..
    } = &mut rig.arm
    {
        *end_effector = Some(Box::new(ArmPose {
            translation_m: [0.0, 0.0, 2.0],
            rotation_wxyz: [0.0; 4],
        }));
        if let Some(p) = payload.as_deref_mut() {
            p.inertia_kg_m2[4] = f64::NAN;
        }
    }
    assert_eq!(
        refused(&rig),
        ["arm.end_effector", "arm.payload.inertia_kg_m2"]
    );
}

#[test]
fn a_v4l_camera_locks_its_image_settings_from_the_camera_image_table() {
    let toml = r#"
driver = "v4l"
device = "/dev/video0"
[image]
exposure_us = 5000
white_balance_k = 4600
gain = 12
"#;
    let camera: CameraDevice = toml::from_str(toml).unwrap_or_else(|e| panic!("{e}"));
    let CameraDevice::V4l { image, .. } = &camera else {
        panic!("not v4l: {camera:?}");
    };
    assert_eq!(
        *image,
        Some(ImageSettings {
            exposure_us: Some(5000),
            white_balance_k: Some(4600),
            gain: Some(12),
        })
    );
    let mut rig = crate::defaults::rig();
    rig.camera = camera.clone();
    assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));
    // Below one V4L2 step, an impossible colour temperature; the second camera too.
    rig.camera = CameraDevice::V4l {
        device: "/dev/video0".into(),
        latency_s: None,
        image: Some(ImageSettings {
            exposure_us: Some(50),
            white_balance_k: Some(100_000),
            gain: None,
        }),
    };
    rig.second_camera = Some(CameraDevice::V4l {
        device: "/dev/video2".into(),
        latency_s: None,
        image: Some(ImageSettings {
            exposure_us: Some(2_000_000),
            white_balance_k: None,
            gain: None,
        }),
    });
    assert_eq!(
        refused(&rig),
        [
            "camera.image.exposure_us",
            "camera.image.white_balance_k",
            "second_camera.image.exposure_us"
        ]
    );
    // A misspelt or negative setting does not parse.
    for bad in ["exposure = 5000", "gain = -1", "exposure_us = \"fast\""] {
        let text = format!("driver = \"v4l\"\ndevice = \"/dev/video0\"\n[image]\n{bad}\n");
        assert!(
            toml::from_str::<CameraDevice>(&text).is_err(),
            "{bad} parsed"
        );
    }
}

/// A `[grasp]` section on the default rig's workspace (reach x 0.3–0.7, y ±0.2,
/// z 0.1–0.6 m), gripper pointing down.
const GRASP_TOML: &str = r#"
medium = "air"
safe_pose = { translation_m = [0.45, 0.0, 0.4], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }
approach_height_m = 0.08
speed_m_s = 0.2

[[objects]]
name = "bottle"
base_from_grasp = { translation_m = [0.5, 0.1, 0.2], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }
open_width_mm = 38.0
lift_mm = 50.0

[[objects]]
name = "ball"
base_from_grasp = { translation_m = [0.5, -0.1, 0.2], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }
open_width_mm = 30.0
lift_mm = 50.0
place = { translation_m = [0.55, -0.1, 0.2], rotation_wxyz = [0.0, 1.0, 0.0, 0.0] }
"#;

#[test]
fn a_grasp_section_reads_and_is_checked_against_the_reach_box() {
    let mut rig = crate::defaults::rig();
    assert!(rig.grasp.is_none(), "the default rig runs no grasp trials");
    let grasp: GraspSetup = toml::from_str(GRASP_TOML).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(grasp.objects.len(), 2);
    assert_eq!(
        grasp.object("bottle").map(GraspObjectSetup::place_pose),
        Some(grasp.objects[0].base_from_grasp),
        "no place: set down where it was grasped"
    );
    rig.grasp = Some(grasp.clone());
    assert!(refused(&rig).is_empty(), "{:?}", refused(&rig));

    // Each mistake is refused by its field.
    type Spoil = Box<dyn Fn(&mut GraspSetup)>;
    let cases: Vec<(Spoil, &str)> = vec![
        (
            Box::new(|g| g.objects[0].base_from_grasp.translation_m[0] = 0.9),
            "grasp.objects[0].base_from_grasp",
        ),
        (
            // The grasp is inside, but 0.45 m above it is not (z up to 0.6 m).
            Box::new(|g| g.objects[1].lift_mm = 450.0),
            "grasp.objects[1].base_from_grasp raised by lift_mm",
        ),
        (
            Box::new(|g| g.objects[0].open_width_mm = f64::NAN),
            "grasp.objects[0].open_width_mm",
        ),
        (
            Box::new(|g| g.objects[1].name = "bottle".into()),
            "grasp.objects[1].name",
        ),
        (Box::new(|g| g.objects.clear()), "grasp.objects"),
        (
            Box::new(|g| g.safe_pose.rotation_wxyz = [0.0; 4]),
            "grasp.safe_pose",
        ),
        (Box::new(|g| g.speed_m_s = 0.0), "grasp.speed_m_s"),
        (
            Box::new(|g| {
                g.objects[1]
                    .place
                    .as_mut()
                    .map_or((), |p| p.translation_m[2] = 0.05)
            }),
            "grasp.objects[1].place",
        ),
    ];
    for (spoil, field) in cases {
        let mut g = grasp.clone();
        spoil(&mut g);
        rig.grasp = Some(g);
        let fields = refused(&rig);
        assert!(fields.iter().any(|f| f == field), "{field}: {fields:?}");
    }

    // Malformed text is an error, not a panic.
    for bad in [
        GRASP_TOML.replace("lift_mm = 50.0\n\n", "lift_mm = \"high\"\n\n"),
        GRASP_TOML.replace("open_width_mm = 38.0", "open_width_mm = 38.0\nwidth = 1"),
        GRASP_TOML.replace("medium = \"air\"", "medium = \"oil\""),
        GRASP_TOML.replace("speed_m_s = 0.2", ""),
    ] {
        assert!(toml::from_str::<GraspSetup>(&bad).is_err(), "{bad}");
    }
}

#[test]
fn the_visit_order_travel_speed_and_motion_margin_are_read_and_checked() {
    let rig = crate::defaults::rig();
    assert_eq!(rig.procedure.visit_order, VisitOrder::Planned);
    assert!((rig.procedure.travel_speed_m_s - DEFAULT_TRAVEL_SPEED_M_S).abs() < 1e-12);
    let text = crate::defaults::RIG_TOML
        .replace("visit_order = \"planned\"", "visit_order = \"index\"")
        .replace("travel_speed_m_s = 0.5", "travel_speed_m_s = 0.8");
    let parsed: RigConfig = toml::from_str(&text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(parsed.procedure.visit_order, VisitOrder::Index);
    assert!((parsed.procedure.travel_speed_m_s - 0.8).abs() < 1e-12);
    assert_eq!(parsed.procedure.visit_order.as_str(), "index");
    // An unknown order names the ones there are.
    let bad =
        crate::defaults::RIG_TOML.replace("visit_order = \"planned\"", "visit_order = \"random\"");
    let e = toml::from_str::<RigConfig>(&bad).map_err(|e| e.to_string());
    assert!(
        e.as_ref()
            .is_err_and(|m| m.contains("planned") && m.contains("index")),
        "{e:?}"
    );
    for speed in [0.0, -1.0, 2.0, f64::NAN] {
        let mut r = rig.clone();
        r.procedure.travel_speed_m_s = speed;
        assert_eq!(refused(&r), ["procedure.travel_speed_m_s"], "{speed}");
    }
    let franka = |margin: Option<f64>| ArmDevice::Franka {
        address: "172.16.0.2".into(),
        reflex_force_n: 30.0,
        reflex_torque_nm: None,
        realtime: Realtime::Enforce,
        end_effector: None,
        payload: None,
        joint_torque_thresholds_nm: None,
        motion_margin: margin,
    };
    for (margin, ok) in [
        (None, true),
        (Some(0.3), true),
        (Some(1.0), true),
        (Some(0.0), false),
        (Some(1.5), false),
        (Some(f64::INFINITY), false),
    ] {
        let mut r = rig.clone();
        r.arm = franka(margin);
        let got = refused(&r);
        assert_eq!(got.is_empty(), ok, "{margin:?}: {got:?}");
        if !ok {
            assert_eq!(got, ["arm.motion_margin"]);
        }
    }
}
