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
    // Without a tare the water scene's frames go to the model as they come, and the
    // header says so; with one it says the tare (and the land scene, none).
    assert!(
        line("`grasp-underwater`: no image tare").contains("as they come"),
        "{lines:?}"
    );
    assert!(
        !lines.iter().any(|l| l.starts_with("`grasp-land`")),
        "{lines:?}"
    );
    let mut tared = session;
    let mut tare = softtouch_trainer::ImageTare::identity(640, 480);
    tare.scale = 1.333;
    tared.plan.tare = true;
    tared.plan.scene_tares = vec![
        None,
        Some(crate::grasp::tare::SceneTare {
            against: "land".into(),
            tare,
            rms_before: 47.9,
            rms_after: 6.5,
            land_frames: 8,
            scene_frames: 8,
        }),
    ];
    let lines = tared.setup_lines();
    assert!(
        lines.iter().any(|l| l.starts_with(
            "`grasp-underwater`: image tare from 8 rest frames of the finger camera against 8 of dataset `land`: scale 1.3330"
        )),
        "{lines:?}"
    );
    assert!(!lines.iter().any(|l| l.starts_with("--tare:")), "{lines:?}");

    // Stored and read back with the session; a session stored before tares reads
    // back with none.
    let json = serde_json::to_string(&tared.plan).unwrap_or_else(|e| panic!("{e}"));
    let back: TrialPlan = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back, tared.plan);
    assert_eq!(back.tare_of(1).map(|t| t.scale), Some(1.333));
    assert_eq!(back.tare_of(0), None);
    let old = serde_json::to_string(&TrialPlan::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(!old.contains("tare"), "{old}");
    let old: TrialPlan = serde_json::from_str(&old).unwrap_or_else(|e| panic!("{e}"));
    assert!(!old.tare && old.scene_tares.is_empty());
    // `--tare` on land alone fits nothing, and says so.
    let mut land_only = tared;
    land_only.scenes.truncate(1);
    land_only.plan.scene_tares = vec![None];
    let lines = land_only.setup_lines();
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("--tare: no water scene in this session")),
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

/// `--set` and `--sweep` on one path are refused (the set would never apply and be
/// shown as the value the scenes ship with); on different paths both apply.
#[test]
fn a_set_and_a_sweep_of_one_path_are_refused() {
    let set: Override = "objects.bottle.wet_friction=0.3"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    let sweep: Sweep = "objects.bottle.wet_friction=0.05,0.2"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    let err =
        set_and_sweep_apart(std::slice::from_ref(&set), Some(&sweep)).expect_err("the same path");
    let said = err.to_string();
    assert!(
        said.contains("--set objects.bottle.wet_friction=0.3")
            && said.contains("--sweep objects.bottle.wet_friction"),
        "{said}"
    );
    let other: Sweep = "objects.bottle.friction=0.3,0.9"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(set_and_sweep_apart(std::slice::from_ref(&set), Some(&other)).is_ok());
    assert!(set_and_sweep_apart(&[set], None).is_ok());
}

/// `--models A,B --sweep …`: the spread across models is one row per swept value, each
/// with one rate per model; values are never averaged as if they were models.
#[test]
fn the_spread_across_models_keeps_each_swept_value_apart() {
    let cell = water_closed_cell;
    let sweep = SceneSweep {
        path: "objects.bottle.wet_friction".into(),
        values: vec!["0.05".into(), "0.2".into()],
        per_value: 1,
        shipped: Some("0.05".into()),
    };
    let run = |held: [u64; 2]| super::experiment::SimRun {
        stopped: false,
        sigmas_mm: vec![5.0],
        table: vec![cell(0, held[0]), cell(1, held[1])],
        sweep: Some(sweep.clone()),
    };
    let runs = vec![("a".to_owned(), run([2, 9])), ("b".to_owned(), run([4, 7]))];
    let rows = super::text::model_spread(&runs);
    assert_eq!(rows.len(), 2, "{rows:?}");
    for (row, want) in rows.iter().zip([[2, 4], [9, 7]]) {
        assert_eq!(row.1.len(), 2, "one rate per model: {row:?}");
        assert_eq!(
            row.1
                .iter()
                .map(|(m, h, _)| (m.as_str(), *h))
                .collect::<Vec<_>>(),
            vec![("a", want[0]), ("b", want[1])]
        );
    }
    assert!(
        rows[0].0.contains("wet_friction=0.05 (shipped)"),
        "{}",
        rows[0].0
    );
    assert!(rows[1].0.ends_with("wet_friction=0.2"), "{}", rows[1].0);
}

/// A swept session's CSVs carry each row's scene and its swept value: rows of
/// different values are never the same row repeated.
#[test]
fn a_swept_sessions_csvs_say_each_rows_value() {
    let cell = |scene_index: u32| water_closed_cell(scene_index, 9);
    let sweep = SceneSweep {
        path: "objects.bottle.wet_friction".into(),
        values: vec!["0.05".into(), "0.2".into()],
        per_value: 1,
        shipped: None,
    };
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("s.csv");
    super::table::write_summary_csv(&path, &[cell(0), cell(1)], Some(&sweep))
        .unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{e}"));
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].ends_with(",scene_index,scene_value"), "{text}");
    assert!(
        lines[1].ends_with(",0,0.05") && lines[2].ends_with(",1,0.2"),
        "{text}"
    );
    assert_ne!(lines[1], lines[2]);
    // Without a sweep the value is empty, the scene still there.
    super::table::write_summary_csv(&path, &[cell(1)], None).unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        text.lines().nth(1).is_some_and(|l| l.ends_with(",1,")),
        "{text}"
    );
    // The rows' file alike.
    let row = |scene_index: u32| crate::store::GraspTrialRow {
        key: crate::store::GraspTrialKey {
            sigma_index: 0,
            scene_index,
            object: "bottle".into(),
            mode: "closed".into(),
            trial: 0,
        },
        medium: "water".into(),
        sigma_m: 0.005,
        offset_m: [0.0; 3],
        commanded_width_m: 0.03,
        final_width_m: 0.03,
        peak_estimate_n: Some(1.5),
        peak_true_n: Some(1.4),
        past_touch_mm: None,
        success: true,
        reason: None,
        detail: None,
        confirmed_after_s: Some(0.5),
        wall_s: 1.0,
    };
    super::table::write_rows_csv(&path, &[row(0), row(1)], Some(&sweep))
        .unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{e}"));
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].ends_with(",scene_index,scene_value"), "{text}");
    assert!(
        lines[1].ends_with(",0,0.05") && lines[2].ends_with(",1,0.2"),
        "{text}"
    );
}

/// `--set medium=water` would relabel the land scene's trials as water ones without any
/// of water's physics: refused, saying what to choose instead.
#[test]
fn a_set_medium_is_refused_not_relabelled() {
    let set: Override = "medium=water".parse().unwrap_or_else(|e| panic!("{e}"));
    let err = load_scenes(&[], &[set]).expect_err("refused");
    let said = err.to_string();
    assert!(
        said.contains("--set medium=water") && said.contains("--scene water"),
        "{said}"
    );
    let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
    let sweep: Sweep = "medium=air,water".parse().unwrap_or_else(|e| panic!("{e}"));
    let said = swept_scenes(&scenes, &sweep)
        .expect_err("refused")
        .to_string();
    assert!(said.contains("--sweep medium"), "{said}");
}

/// Figure 4f of a swept session: each group says its value (no two read alike) and the
/// paper's tick stands only beside the value the scenes ship with.
#[test]
fn figure_4f_names_each_swept_value_and_ticks_the_paper_at_the_shipped_one() {
    let plan = TrialPlan {
        sweep: Some(SceneSweep {
            path: "objects.bottle.wet_friction".into(),
            values: vec!["0.05".into(), "0.2".into()],
            per_value: 2,
            shipped: Some("0.05".into()),
        }),
        ..TrialPlan::default()
    };
    use super::table::{bar_group_name, paper_tick_applies};
    assert_eq!(
        bar_group_name(&plan, "water", 1, None),
        "water/all, wet_friction=0.05 (shipped)"
    );
    assert_eq!(
        bar_group_name(&plan, "water", 3, Some("bottle")),
        "water/bottle, wet_friction=0.2"
    );
    assert_ne!(
        bar_group_name(&plan, "water", 1, None),
        bar_group_name(&plan, "water", 3, None)
    );
    assert!(paper_tick_applies(&plan, 1) && !paper_tick_applies(&plan, 3));
    // Without a sweep: the plain name, the paper beside every bar.
    let plain = TrialPlan::default();
    assert_eq!(bar_group_name(&plain, "land", 0, None), "land/all");
    assert!(paper_tick_applies(&plain, 0));
}

/// The all-objects closed-loop water cell of scene `scene_index`, `held` of 10.
fn water_closed_cell(scene_index: u32, held: u64) -> super::table::Cell {
    super::table::Cell {
        sigma_index: 0,
        sigma_mm: 5.0,
        scene_index,
        medium: Medium::Water,
        object: None,
        mode: Mode::Closed,
        trials: 10,
        held,
        interval: [0.0, 1.0],
        reasons: std::collections::BTreeMap::new(),
        peak_true_max_n: None,
        past_touch_max_mm: None,
    }
}
