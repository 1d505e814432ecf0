//! The session tables' own tests: cells, pairs, summaries, CSVs.

#![allow(clippy::float_cmp)] // exact p-values of exact counts

use super::*;
use crate::store::GraspTrialKey;

/// A swept session's summary (5 values of a water value, the land scene replayed at
/// each, two σ) keeps every σ and scene apart: 5 × 2 land trials are five n = 2,
/// never one n = 10.
#[test]
fn a_sessions_summary_never_pools_sigmas_or_scenes() {
    let mut rows = Vec::new();
    for sigma_index in 0..2u32 {
        for scene in 0..10u32 {
            for trial in 0..2 {
                let mut r = row("cylinder", "closed", trial, None);
                r.key.sigma_index = sigma_index;
                r.sigma_m = [0.002, 0.005][sigma_index as usize];
                r.key.scene_index = scene;
                r.medium = if scene % 2 == 0 { "land" } else { "water" }.into();
                rows.push(r);
            }
        }
    }
    let summary = session_summary(&rows);
    assert_eq!(summary.matches("/2").count(), 20, "{summary}");
    assert!(
        !summary.contains("/10") && !summary.contains("/20"),
        "{summary}"
    );
    assert!(
        summary.starts_with("land closed σ 2 mm scene 0 2/2, water closed σ 2 mm scene 1 2/2"),
        "{summary}"
    );
    // One σ and one scene per medium: the short form.
    let one = vec![
        row("cylinder", "open", 0, None),
        row("cylinder", "open", 1, Some("slip")),
    ];
    assert_eq!(session_summary(&one), "land open 1/2");
}

fn row(object: &str, mode: &str, trial: u32, reason: Option<&str>) -> GraspTrialRow {
    GraspTrialRow {
        key: GraspTrialKey {
            sigma_index: 0,
            scene_index: 0,
            object: object.into(),
            mode: mode.into(),
            trial,
        },
        medium: "land".into(),
        sigma_m: 0.005,
        offset_m: [0.0; 3],
        commanded_width_m: 0.02,
        final_width_m: 0.02,
        peak_estimate_n: None,
        peak_true_n: None,
        past_touch_mm: None,
        success: reason.is_none(),
        reason: reason.map(str::to_owned),
        detail: None,
        confirmed_after_s: None,
        wall_s: 0.1,
    }
}

#[test]
fn open_and_closed_pair_by_object_and_trial_and_refused_trials_pair_with_nothing() {
    let plan = TrialPlan::default();
    let rows = vec![
        row("ball", "open", 0, None),
        row("ball", "closed", 0, None),
        row("ball", "open", 1, Some("slip")),
        row("ball", "closed", 1, None),
        row("cake", "open", 0, None),
        row("cake", "closed", 0, Some("crush")),
        row("cake", "open", 1, Some("miss")),
        row("cake", "closed", 1, Some("miss")),
        row("cake", "open", 2, Some("miss")),
        row("cake", "closed", 2, None),
        // Unpaired: no closed trial 3; a refused one.
        row("cake", "open", 3, None),
        row("cake", "open", 4, None),
        row("cake", "closed", 4, Some("refused")),
    ];
    let p = paired(&plan, &[Medium::Air], &rows);
    assert_eq!(p.len(), 1);
    let p = &p[0];
    assert_eq!(
        (p.pairs, p.both, p.open_only, p.closed_only, p.neither),
        (5, 1, 1, 2, 1)
    );
    assert_eq!(p.p, softtouch_grasp::mcnemar_exact_p(1, 2));
    assert_eq!(p.p, 1.0);
    // One mode only: nothing to pair.
    let open_only: Vec<GraspTrialRow> = rows
        .iter()
        .filter(|r| r.key.mode == "open")
        .cloned()
        .collect();
    assert!(paired(&plan, &[Medium::Air], &open_only).is_empty());
    assert!(paired(&plan, &[Medium::Air], &[]).is_empty());
}

#[test]
fn the_papers_rates_stand_beside_the_papers_sigma_only() {
    let plan = TrialPlan {
        sigmas_mm: vec![0.0, 5.0, 8.0],
        ..TrialPlan::default()
    };
    let cells = summarise(&plan, &[Medium::Air, Medium::Water], &[]).expect("cells");
    for c in &cells {
        let expected = (c.object.is_none() && (c.sigma_mm - 5.0).abs() < 1e-12)
            .then(|| paper_rate(c.medium, c.mode));
        assert_eq!(c.paper(), expected, "{c:?}");
        assert_eq!(
            c.sigma_mm.to_bits(),
            plan.sigmas_mm[c.sigma_index as usize].to_bits()
        );
    }
    assert_eq!(cells.iter().filter(|c| c.paper().is_some()).count(), 4);
}

/// A cell's grip is the firmest of its counted trials: the true force where the
/// simulator gave one, else the closing past the touch; a refused trial, a NaN and
/// a cell with no trial add nothing.
#[test]
fn a_cells_grip_is_its_firmest_counted_trial() {
    let plan = TrialPlan {
        objects: vec!["ball".into(), "cake".into()],
        ..TrialPlan::default()
    };
    let with = |mut r: GraspTrialRow, true_n: Option<f64>, mm: Option<f64>| {
        r.peak_true_n = true_n;
        r.past_touch_mm = mm;
        r
    };
    let rows = vec![
        with(row("ball", "closed", 0, None), Some(1.6), Some(2.0)),
        with(row("ball", "closed", 1, Some("slip")), Some(2.4), Some(3.0)),
        with(row("ball", "closed", 2, None), Some(f64::NAN), Some(9.0)),
        // Refused: nothing moved, whatever it says.
        with(
            row("ball", "closed", 3, Some("refused")),
            Some(99.0),
            Some(99.0),
        ),
        // A rig's trials: no truth.
        with(row("cake", "closed", 0, None), None, Some(1.25)),
        with(row("cake", "closed", 1, None), None, None),
    ];
    let cells = summarise(&plan, &[Medium::Air], &rows).expect("cells");
    let cell = |object: Option<&str>, mode: Mode| {
        cells
            .iter()
            .find(|c| c.object.as_deref() == object && c.mode == mode)
            .expect("cell")
    };
    let ball = cell(Some("ball"), Mode::Closed);
    assert_eq!(ball.peak_true_max_n, Some(2.4));
    assert_eq!(ball.past_touch_max_mm, Some(9.0));
    assert_eq!(ball.grip_text(), "2.40 N");
    let cake = cell(Some("cake"), Mode::Closed);
    assert_eq!(cake.peak_true_max_n, None);
    assert_eq!(cake.grip_text(), "1.25 mm");
    assert_eq!(cell(None, Mode::Closed).peak_true_max_n, Some(2.4));
    let empty = cell(Some("ball"), Mode::Open);
    assert_eq!((empty.trials, empty.grip_text().as_str()), (0, "–"));
}
