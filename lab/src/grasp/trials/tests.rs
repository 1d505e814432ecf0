//! The trial sessions' own tests: plans, scenes, sessions stored and resumed.

#![allow(clippy::float_cmp)] // exact stored and published values

use super::*;

#[test]
fn a_sweep_marks_the_value_the_scenes_ship_with_and_sigma_the_papers() {
    let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
    let sweep: Sweep = "objects.bottle.wet_friction=0.05,0.2"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    // Only the water scene has the value (land has no wet friction): it is the one.
    let (_, stored) = swept_scenes(&scenes, &sweep).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(stored.shipped.as_deref(), Some("0.05"));
    assert_eq!(stored.value_label(0), "0.05 (shipped)");
    assert_eq!(stored.value_label(1), "0.2");
    assert_eq!(stored.value_label(7), "?");
    // Scenes that disagree have no one shipped value to mark.
    let both: Sweep = "objects.bottle.friction=0.3,0.9"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    let mut differing = scenes.clone();
    differing[1]
        .objects
        .iter_mut()
        .for_each(|o| o.friction += 0.01);
    let (_, stored) = swept_scenes(&differing, &both).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(stored.shipped, None);
    // A session stored before the mark existed reads back without one.
    let old: SceneSweep = serde_json::from_str(r#"{"path":"a.b","values":["1"],"per_value":1}"#)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(old.shipped, None);
    assert_eq!(sigma_label(PAPER_SIGMA_MM), "σ 5 mm (paper)");
    assert_eq!(sigma_label(2.0), "σ 2 mm");
}

#[test]
fn the_built_in_scenes_load_with_objects_inside_the_stroke() {
    let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scenes.len(), 2);
    assert_eq!(scenes[0].medium, Medium::Air);
    assert_eq!(scenes[1].medium, Medium::Water);
    let mut plan = TrialPlan {
        modes: vec!["open".into(), "closed".into(), "open".into()],
        ..TrialPlan::default()
    }
    .checked()
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(plan.modes, ["open", "closed"]);
    plan.objects = scenes[0].objects.iter().map(|o| o.name.clone()).collect();
    assert_eq!(plan.objects.len(), 5);
    let objects = objects_of(&plan, &scenes).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(objects[1].len(), 5);
    // The full table: 2 σ-free media × 5 objects × 2 modes × 10 trials.
    assert_eq!(planned(&plan, 2, &[Mode::Open, Mode::Closed]).len(), 200);
    plan.objects.push("vase".into());
    let err = objects_of(&plan, &scenes).err().map(|e| e.to_string());
    assert!(err.is_some_and(|e| e.contains("vase") && e.contains("cylinder")));
}

#[test]
fn objects_that_close_alike_are_said_to() {
    let setup = |object: &str, points: &str| run::ObjectSetup {
        calibration: crate::grasp::calibration::Calibrated {
            row: crate::store::GraspCalibrationRow {
                calibration_id: 1,
                created_at: String::new(),
                setup_kind: "scene".into(),
                setup_hash: String::new(),
                model: "m".into(),
                model_sha256: String::new(),
                object: object.into(),
                touch_count: 100,
                lambda_max_n_per_mm: 1.0,
                lambda_iqr_n_per_mm: (0.9, 1.1),
                counts_spanned: 10,
                baseline_n: 0.0,
                mm_per_count: 0.2,
                ended: "top".into(),
                points_json: points.into(),
                lambda_json: "[]".into(),
                true_lambda_max_n_per_mm: None,
            },
            fresh: true,
            accepted_against: None,
        },
        count_n: 0.2,
        tolerance_n: 0.1,
    };
    let mut calibrations = std::collections::HashMap::new();
    for (scene, object, points) in [
        (0, "cylinder", "[[100,100,0.5]]"),
        (0, "oval-tube", "[[100,100,0.5]]"),
        (0, "ball", "[[100,100,0.7]]"),
        // Another medium's scene is never compared with the first's.
        (1, "cylinder", "[[100,100,0.6]]"),
        (1, "oval-tube", "[[100,100,0.5]]"),
    ] {
        calibrations.insert((scene, object.to_owned()), setup(object, points));
    }
    let session = Session {
        id: 1,
        model: "m".into(),
        model_sha256: String::new(),
        seed: 0,
        plan: TrialPlan::default(),
        scenes: load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}")),
        model_bytes: Vec::new(),
        calibrations,
    };
    let lines = session.setup_lines();
    let line = |prefix: &str| {
        lines
            .iter()
            .find(|l| l.starts_with(prefix))
            .cloned()
            .unwrap_or_else(|| panic!("no `{prefix}` in {lines:?}"))
    };
    let twin = "the same closing as `cylinder`'s, count for count";
    assert!(line("`oval-tube` (land)").contains(twin), "{lines:?}");
    assert!(!line("`oval-tube` (water)").contains(twin), "{lines:?}");
    assert!(
        !line("`ball` (land)").contains("the same closing"),
        "{lines:?}"
    );
    assert!(
        !line("`cylinder` (land)").contains("the same closing"),
        "{lines:?}"
    );
}

#[test]
fn settings_out_of_range_name_their_flag() {
    for (plan, flag) in [
        (
            TrialPlan {
                tolerance_n: 0.0,
                ..TrialPlan::default()
            },
            "--tolerance 0",
        ),
        (
            TrialPlan {
                fps: 0.5,
                ..TrialPlan::default()
            },
            "--fps 0.5",
        ),
        (
            TrialPlan {
                trials: 0,
                ..TrialPlan::default()
            },
            "--trials 0",
        ),
        (
            TrialPlan {
                modes: vec![],
                ..TrialPlan::default()
            },
            "--modes",
        ),
        (
            TrialPlan {
                sigmas_mm: vec![f64::NAN],
                ..TrialPlan::default()
            },
            "σ NaN",
        ),
        (
            TrialPlan {
                hold_s: 1e308,
                ..TrialPlan::default()
            },
            "--hold-s 1e308",
        ),
    ] {
        let e = plan.checked().expect_err(flag);
        assert!(e.is_bad_input(), "{e}");
        assert!(e.to_string().starts_with(flag), "{e}");
    }
}

#[test]
fn a_session_stored_before_the_calibrated_pregrasp_keeps_its_own_on_resume() {
    let mut json = serde_json::to_value(TrialPlan::default()).expect("encodes");
    assert_eq!(
        json["pregrasp_from_touch"], true,
        "new sessions start from the touch"
    );
    json.as_object_mut()
        .expect("an object")
        .remove("pregrasp_from_touch");
    let old: TrialPlan = serde_json::from_value(json).expect("an older session reads");
    assert!(
        !old.pregrasp_from_touch,
        "it keeps the grasp width plus the margin"
    );
    assert!(old.rig.is_none());
}

#[test]
fn the_paper_figures_are_the_published_ones() {
    assert_eq!(paper_rate(Medium::Air, Mode::Open), 0.44);
    assert_eq!(paper_rate(Medium::Water, Mode::Closed), 0.90);
    assert_eq!(table::csv_field("a,b"), "\"a,b\"");
}
