//! Figure 5's force following on the simulated soft grasp: each target held in turn,
//! with rise and settling time, overshoot, steady-state and RMS error per target, for
//! the estimate and for the simulator's truth; its CSV and chart.

use std::path::Path;
use std::time::Duration;

use softtouch_grasp::{Cycle, ExitAction, HoldMetrics, hold_metrics};
use softtouch_schemas::SceneSpec;
use softtouch_sim::GraspObject;

use super::soft::{GraspRunError, LoopSettings, Setup, named_object, prepare, t_s, write_text};
use softtouch_collector::plot::{Series, SeriesStyle, XyChart, xy_chart};

/// What `grasp follow` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowSettings {
    /// The loop.
    pub loop_settings: LoopSettings,
    /// Target forces, N, held in turn.
    pub targets_n: Vec<f64>,
    /// How long each is held, s.
    pub hold_s: f64,
}

/// The object to follow on: `name` from the scene, else its first object, else a
/// cylinder of its first rod.
///
/// # Errors
/// An unknown name, or a scene with neither objects nor rods.
pub fn object_for(scene: &SceneSpec, name: Option<&str>) -> Result<GraspObject, GraspRunError> {
    match (name, scene.objects.first(), scene.rods.first()) {
        (Some(name), ..) => named_object(scene, name),
        (None, Some(o), _) => Ok(GraspObject::from_spec(o)),
        (None, None, Some(rod)) => Ok(GraspObject {
            shape: rod.shape,
            aspect: rod.aspect,
            ..GraspObject::cylinder(&rod.name, rod.size_m)
        }),
        (None, None, None) => Err(GraspRunError::Invalid(
            "the scene has neither objects nor rods".into(),
        )),
    }
}

/// Runs the targets on the simulated soft grasp of `object` (a paused tokio clock).
/// A request on `stop` ends it after the cycle in hand, the fingers opened: the cycles
/// run so far come back with the request's name.
///
/// # Errors
/// As [`prepare`], and the loop.
pub async fn follow_sim(
    settings: &FollowSettings,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: GraspObject,
    calibration: &super::calibration::Calibrated,
    stop: Option<softtouch_grasp::StopRequest>,
) -> Result<(Setup, Vec<Cycle>, Option<&'static str>), GraspRunError> {
    let p = prepare(
        &settings.loop_settings,
        model_bytes,
        scene,
        object,
        &settings.targets_n,
        ExitAction::Open,
        calibration,
        false,
    )
    .await?;
    let hold = Duration::from_secs_f64(settings.hold_s);
    let targets: Vec<(f64, Duration)> = settings.targets_n.iter().map(|t| (*t, hold)).collect();
    let mut controller = match stop {
        Some(stop) => p.controller.with_stop(stop),
        None => p.controller,
    };
    let (cycles, stopped) = controller.follow_until_stopped(&targets).await?;
    Ok((p.setup, cycles, stopped))
}

/// One target's numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowRow {
    /// The target, N.
    pub target_n: f64,
    /// From the estimate (`None`: no usable estimate during the hold).
    pub estimate: Option<HoldMetrics>,
    /// From the simulator's truth (`None` on a rig).
    pub truth: Option<HoldMetrics>,
    /// The largest true force of the hold, N (`None` on a rig): what a crush would show.
    pub peak_true_n: Option<f64>,
    /// How far past the calibrated first touch the fingers closed during the hold, mm
    /// (`None`: no cycle): on a rig, how deep past contact the grip went.
    pub past_touch_mm: Option<f64>,
}

/// The numbers per target of a run's cycles; `touch` is the calibrated first touch,
/// counts, and the opening per count, mm.
#[must_use]
pub fn follow_rows(
    cycles: &[Cycle],
    targets_n: &[f64],
    tolerance_n: f64,
    touch: (u8, f64),
) -> Vec<FollowRow> {
    targets_n
        .iter()
        .enumerate()
        .map(|(i, target)| {
            let hold: Vec<&Cycle> = cycles.iter().filter(|c| c.hold == i).collect();
            let series = |f: fn(&Cycle) -> Option<f64>| -> Vec<(f64, f64)> {
                hold.iter()
                    .filter_map(|c| Some((t_s(c.t), f(c)?)))
                    .collect()
            };
            FollowRow {
                target_n: *target,
                estimate: hold_metrics(&series(|c| c.estimate_n), *target, tolerance_n),
                truth: hold_metrics(&series(|c| c.true_n), *target, tolerance_n),
                peak_true_n: hold
                    .iter()
                    .filter_map(|c| c.true_n)
                    .filter(|f| f.is_finite())
                    .reduce(f64::max),
                past_touch_mm: hold
                    .iter()
                    .map(|c| c.measured_position)
                    .max()
                    .map(|c| softtouch_grasp::squeeze::past_touch_mm(c, touch.0, touch.1)),
            }
        })
        .collect()
}

/// `grasp-follow.csv`: one line per cycle.
///
/// # Errors
/// The file cannot be written.
pub fn write_follow_csv(path: &Path, cycles: &[Cycle]) -> Result<(), GraspRunError> {
    let mut text = String::from(
        "t_s,frame,target_n,estimate_n,true_n,measured_count,request_count,outcome,gripper_object_status\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for c in cycles {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:?}\n",
            t_s(c.t),
            c.frame_sequence,
            c.target_n,
            opt(c.estimate_n),
            opt(c.true_n),
            c.measured_position,
            c.position_request,
            c.outcome.map_or("awaiting_echo", |o| o.as_str()),
            c.object
        ));
    }
    write_text(path, &text)
}

/// `grasp-follow-metrics.csv`: one line per target (`est_`: from the estimate,
/// `true_`: from the simulator's truth; empty where there is none), with the hold's
/// peak true force and its deepest closing past the calibrated touch.
///
/// # Errors
/// The file cannot be written.
pub fn write_follow_metrics_csv(path: &Path, rows: &[FollowRow]) -> Result<(), GraspRunError> {
    let mut text = String::from(
        "target_n,est_rise_s,est_settle_s,est_overshoot_n,est_ss_error_n,est_rms_n,true_rise_s,true_settle_s,true_overshoot_n,true_ss_error_n,true_rms_n,peak_true_n,past_touch_mm\n",
    );
    let opt = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    let cells = |m: Option<HoldMetrics>| {
        m.map_or_else(
            || ",,,,".to_owned(),
            |m| {
                format!(
                    "{},{},{},{},{}",
                    opt(m.rise_time_s),
                    opt(m.settling_time_s),
                    m.overshoot_n,
                    m.steady_state_error_n,
                    m.rms_error_n
                )
            },
        )
    };
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{}\n",
            r.target_n,
            cells(r.estimate),
            cells(r.truth),
            opt(r.peak_true_n),
            opt(r.past_touch_mm)
        ));
    }
    write_text(path, &text)
}

/// `grasp-follow.png`: commanded, estimated and true force over time.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_follow_png(path: &Path, cycles: &[Cycle]) -> Result<(), GraspRunError> {
    let t = |c: &Cycle| t_s(c.t);
    let series = [
        Series {
            label: "commanded F_ref".into(),
            points: cycles.iter().map(|c| (t(c), c.target_n)).collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "estimated F_est".into(),
            points: cycles
                .iter()
                .filter_map(|c| Some((t(c), c.estimate_n?)))
                .collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "true (simulator)".into(),
            points: cycles
                .iter()
                .filter_map(|c| Some((t(c), c.true_n?)))
                .collect(),
            style: SeriesStyle::Line,
        },
    ];
    xy_chart(
        path,
        &XyChart {
            title: "Force following",
            x_label: "time (s)",
            y_label: "grip force (N)",
            series: &series,
        },
        (900, 500),
    )
    .map_err(|e| GraspRunError::Failed(e.to_string()))
}

/// `grasp follow`'s table: per target, the rise, settle, overshoot, steady-state and
/// RMS errors of the estimate beside the truth's, then what "within δ", "not reached"
/// and "not yet" mean where one is shown.
///
/// # Errors
/// The writer's.
pub fn print_follow_table(
    rows: &[FollowRow],
    tolerance_n: f64,
    out: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    // A rise the hold never made is said apart from one it had no need of (a step
    // smaller than δ), and a settle not made by the end of the hold as such.
    let rise = |m: &softtouch_grasp::HoldMetrics| match m.rise_time_s {
        Some(s) => format!("{s:.3}"),
        None if m.started_within(tolerance_n) => "within δ".to_owned(),
        None => "not reached".to_owned(),
    };
    let settle = |v: Option<f64>| v.map_or_else(|| "not yet".to_owned(), |s| format!("{s:.3}"));
    writeln!(
        out,
        "{:>8} {:>9} {:>10} {:>11} {:>11} {:>9} {:>13} {:>10} {:>11} {:>14}",
        "target N",
        "rise s",
        "settle s",
        "overshoot N",
        "ss error N",
        "RMS N",
        "true ss err N",
        "true RMS N",
        "peak true N",
        "past touch mm"
    )?;
    let opt = |v: Option<f64>, digits: usize| {
        v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
    };
    for row in rows {
        let target = row.target_n;
        let tru = row.truth;
        let grip = format!(
            "{:>11} {:>14}",
            opt(row.peak_true_n, 2),
            opt(row.past_touch_mm, 2)
        );
        match row.estimate {
            Some(m) => writeln!(
                out,
                "{:>8.2} {:>9} {:>10} {:>11.3} {:>11.3} {:>9.3} {:>13} {:>10} {grip}",
                target,
                rise(&m),
                settle(m.settling_time_s),
                m.overshoot_n,
                m.steady_state_error_n,
                m.rms_error_n,
                tru.map_or_else(|| "-".into(), |t| format!("{:.3}", t.steady_state_error_n)),
                tru.map_or_else(|| "-".into(), |t| format!("{:.3}", t.rms_error_n)),
            ),
            None => writeln!(out, "{target:>8.2} (no usable estimate) {grip}"),
        }?;
    }
    let said = |word: &str| {
        rows.iter()
            .filter_map(|r| r.estimate)
            .any(|m| rise(&m) == word || settle(m.settling_time_s) == word)
    };
    for (word, meaning) in [
        (
            "within δ",
            "rise s within δ: the force started within δ of the target, a step too small to time a rise",
        ),
        (
            "not reached",
            "rise s not reached: the force never came 90 % of the way to the target",
        ),
        (
            "not yet",
            "settle s not yet: the force was still outside δ at the end of the hold",
        ),
    ] {
        if said(word) {
            writeln!(out, "{meaning}")?;
        }
    }
    Ok(())
}
