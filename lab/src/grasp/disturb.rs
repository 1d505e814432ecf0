//! Figure 5's disturbance on the simulated soft grasp: a force held while the
//! simulator turns the object about its axis, phase by phase; per turn the peak
//! deviation, the recovery time to within δ and the RMS error (estimate and truth);
//! its CSV and two-panel chart.

use std::path::Path;
use std::time::Duration;

use softtouch_drivers::Clock;
use softtouch_grasp::{Cycle, ExitAction};
use softtouch_schemas::{SceneSpec, TimestampNs};
use softtouch_sim::GraspObject;

use super::soft::{GraspRunError, LoopSettings, Setup, prepare, t_s, write_text};
use softtouch_collector::plot::{Series, SeriesStyle, two_panel_chart};

/// What `grasp disturb` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct DisturbSettings {
    /// The loop.
    pub loop_settings: LoopSettings,
    /// The force held, N.
    pub target_n: f64,
    /// The turns, degrees, each relative to the last.
    pub turns_deg: Vec<f64>,
    /// How long the force is held before the first turn, s.
    pub settle_s: f64,
    /// How long each turn takes, s.
    pub turn_s: f64,
    /// From one turn's start to the next, s.
    pub phase_s: f64,
}

/// One phase: its turn, the yaw it ends at, and when it starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phase {
    /// The turn, degrees.
    pub turn_deg: f64,
    /// The object's yaw after it, degrees.
    pub yaw_deg: f64,
    /// When the turn starts, s on the devices' clock.
    pub start_s: f64,
}

/// A disturbance as it ran.
#[derive(Debug, Clone)]
pub struct DisturbRun {
    /// What the setup measured and chose.
    pub setup: Setup,
    /// Every cycle.
    pub cycles: Vec<Cycle>,
    /// The object's yaw at each cycle, degrees.
    pub yaws_deg: Vec<f64>,
    /// The phases.
    pub phases: Vec<Phase>,
    /// The stop request that ended it early, by name (the cycles are what ran).
    pub stopped: Option<&'static str>,
}

/// Runs the disturbance on the simulated soft grasp of `object` (a paused tokio
/// clock). A request on `stop` ends it after the cycle in hand, the fingers opened.
///
/// # Errors
/// As [`prepare`], the loop, the simulator.
pub async fn disturb_sim(
    settings: &DisturbSettings,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: GraspObject,
    calibration: &super::calibration::Calibrated,
    stop: Option<softtouch_grasp::StopRequest>,
) -> Result<DisturbRun, GraspRunError> {
    let p = prepare(
        &settings.loop_settings,
        model_bytes,
        scene,
        object,
        &[settings.target_n],
        ExitAction::Open,
        calibration,
        true,
    )
    .await?;
    let start = p.clock.now();
    let at = |s: f64| TimestampNs(start.0 + (s * 1e9) as u64);
    let mut yaw_deg = 0.0;
    let mut phases = Vec::new();
    for (i, turn) in settings.turns_deg.iter().enumerate() {
        let t0 = at(settings.settle_s + i as f64 * settings.phase_s);
        yaw_deg += turn;
        p.handle
            .schedule_object_yaw(t0, f64::to_radians(yaw_deg), settings.turn_s)?;
        phases.push(Phase {
            turn_deg: *turn,
            yaw_deg,
            start_s: t_s(t0),
        });
    }
    let total_s = settings.settle_s + settings.turns_deg.len() as f64 * settings.phase_s;
    let mut controller = match stop {
        Some(stop) => p.controller.with_stop(stop),
        None => p.controller,
    };
    let (cycles, stopped) = controller
        .follow_until_stopped(&[(settings.target_n, Duration::from_secs_f64(total_s))])
        .await?;
    let yaws_deg = cycles
        .iter()
        .map(|cy| p.handle.object_yaw(cy.t).map(f64::to_degrees))
        .collect::<Result<_, _>>()?;
    Ok(DisturbRun {
        setup: p.setup,
        cycles,
        yaws_deg,
        phases,
        stopped,
    })
}

/// How one phase of a disturbance went, from `(t_s, force_n)` samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseNumbers {
    /// Largest |F − target|, N.
    pub peak_deviation_n: f64,
    /// From the phase's start until F is within δ for the rest of the phase, s
    /// (`None`: still outside at its end).
    pub recovery_s: Option<f64>,
    /// RMS of F − target over the phase, N.
    pub rms_error_n: f64,
}

/// The numbers of the samples in `[t0_s, t1_s)`; `None` when none is finite there.
#[must_use]
pub fn phase_numbers(
    samples: &[(f64, f64)],
    t0_s: f64,
    t1_s: f64,
    target_n: f64,
    tolerance_n: f64,
) -> Option<PhaseNumbers> {
    let s: Vec<(f64, f64)> = samples
        .iter()
        .copied()
        .filter(|(t, f)| *t >= t0_s && *t < t1_s && f.is_finite())
        .collect();
    if s.is_empty() {
        return None;
    }
    let errors: Vec<f64> = s.iter().map(|(_, f)| f - target_n).collect();
    let peak_deviation_n = errors.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
    let rms_error_n = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let recovery_s = match errors.iter().rposition(|e| e.abs() > tolerance_n) {
        None => Some(0.0),
        Some(last) if last + 1 < s.len() => Some(s[last + 1].0 - t0_s),
        Some(_) => None,
    };
    Some(PhaseNumbers {
        peak_deviation_n,
        recovery_s,
        rms_error_n,
    })
}

/// One phase's numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisturbRow {
    /// The phase.
    pub phase: Phase,
    /// From the estimate (`None`: no usable estimate).
    pub estimate: Option<PhaseNumbers>,
    /// From the simulator's truth.
    pub truth: Option<PhaseNumbers>,
}

fn series(cycles: &[Cycle], f: fn(&Cycle) -> Option<f64>) -> Vec<(f64, f64)> {
    cycles
        .iter()
        .filter_map(|cy| Some((t_s(cy.t), f(cy)?)))
        .collect()
}

/// The numbers per phase.
#[must_use]
pub fn disturb_rows(run: &DisturbRun, settings: &DisturbSettings) -> Vec<DisturbRow> {
    let (est, tru) = (
        series(&run.cycles, |c| c.estimate_n),
        series(&run.cycles, |c| c.true_n),
    );
    let tol = settings.loop_settings.tolerance_n;
    run.phases
        .iter()
        .map(|phase| {
            let t1 = phase.start_s + settings.phase_s;
            DisturbRow {
                phase: *phase,
                estimate: phase_numbers(&est, phase.start_s, t1, settings.target_n, tol),
                truth: phase_numbers(&tru, phase.start_s, t1, settings.target_n, tol),
            }
        })
        .collect()
}

/// `grasp-disturb.csv`: one line per cycle.
///
/// # Errors
/// The file cannot be written.
pub fn write_disturb_csv(path: &Path, run: &DisturbRun) -> Result<(), GraspRunError> {
    let mut text = String::from(
        "t_s,target_n,estimate_n,true_n,object_yaw_deg,finger0_estimate_n,finger1_estimate_n,measured_count,request_count,outcome\n",
    );
    let o = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for (cy, yaw) in run.cycles.iter().zip(&run.yaws_deg) {
        text.push_str(&format!(
            "{},{},{},{},{yaw},{},{},{},{},{}\n",
            t_s(cy.t),
            cy.target_n,
            o(cy.estimate_n),
            o(cy.true_n),
            o(cy.finger_estimates_n[0]),
            o(cy.finger_estimates_n[1]),
            cy.measured_position,
            cy.position_request,
            cy.outcome.map_or("awaiting_echo", |x| x.as_str()),
        ));
    }
    write_text(path, &text)
}

pub(crate) fn line(label: &str, points: Vec<(f64, f64)>) -> Series {
    Series {
        label: label.into(),
        points,
        style: SeriesStyle::Line,
    }
}

/// `grasp-disturb.png`: commanded, estimated and true force above, the object's
/// rotation below.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_disturb_png(path: &Path, run: &DisturbRun) -> Result<(), GraspRunError> {
    let forces = [
        line("commanded F_ref", series(&run.cycles, |c| Some(c.target_n))),
        line("estimated F_est", series(&run.cycles, |c| c.estimate_n)),
        line("true (simulator)", series(&run.cycles, |c| c.true_n)),
    ];
    let angle = [line(
        "object yaw",
        run.cycles
            .iter()
            .zip(&run.yaws_deg)
            .map(|(cy, y)| (t_s(cy.t), *y))
            .collect(),
    )];
    two_panel_chart(
        path,
        "Disturbance: the tube turned about its axis",
        (&forces, "grip force (N)"),
        (&angle, "rotation (°)"),
    )
    .map_err(|e| GraspRunError::Failed(e.to_string()))
}

/// The terminal's table of a disturbance run: one row per phase, the estimate's
/// numbers beside the truth's.
///
/// # Errors
/// The writer's.
pub fn print_disturb_table(
    rows: &[DisturbRow],
    out: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    let opt = |v: Option<f64>| v.map_or_else(|| "never".to_owned(), |s| format!("{s:.3}"));
    writeln!(
        out,
        "{:>5} {:>7} {:>6} {:>11} {:>10} {:>9} {:>12} {:>11} {:>10}",
        "phase",
        "turn °",
        "yaw °",
        "peak dev N",
        "recover s",
        "RMS N",
        "true peak N",
        "true rec s",
        "true RMS N"
    )?;
    for (i, row) in rows.iter().enumerate() {
        let (turn, yaw) = (row.phase.turn_deg, row.phase.yaw_deg);
        let r = row.truth;
        let Some(e) = row.estimate else {
            writeln!(
                out,
                "{:>5} {turn:>7.1} {yaw:>6.1} (no usable estimate)",
                i + 1
            )?;
            continue;
        };
        writeln!(
            out,
            "{:>5} {turn:>7.1} {yaw:>6.1} {:>11.3} {:>10} {:>9.3} {:>12} {:>11} {:>10}",
            i + 1,
            e.peak_deviation_n,
            opt(e.recovery_s),
            e.rms_error_n,
            r.map_or_else(|| "-".into(), |r| format!("{:.3}", r.peak_deviation_n)),
            r.map_or_else(|| "-".into(), |r| opt(r.recovery_s)),
            r.map_or_else(|| "-".into(), |r| format!("{:.3}", r.rms_error_n)),
        )?;
    }
    Ok(())
}

/// A disturbance run in one line, as the results table stores it: the force held, the
/// turns, the largest deviation (the truth's where the simulator has it) and the grip
/// at its firmest (`grip`: [`super::soft::grip_words`]).
#[must_use]
pub fn disturb_summary(rows: &[DisturbRow], target_n: f64, grip: &str) -> String {
    let worst = rows
        .iter()
        .filter_map(|r| r.truth.or(r.estimate))
        .map(|m| m.peak_deviation_n)
        .fold(f64::NAN, f64::max);
    format!(
        "{target_n} N held through {} turns; largest force deviation {} N; {grip}",
        rows.len(),
        if worst.is_finite() {
            format!("{worst:.3}")
        } else {
            "-".into()
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phase_recovers_when_it_stays_within_the_band_to_its_end() {
        let s = [(0.0, 1.0), (0.1, 1.5), (0.2, 1.05), (0.3, 0.98), (0.4, 9.0)];
        let p = phase_numbers(&s, 0.0, 0.4, 1.0, 0.1).expect("samples");
        assert!((p.peak_deviation_n - 0.5).abs() < 1e-12);
        assert_eq!(p.recovery_s, Some(0.2));
        // Still outside at its end: never recovered.
        let p = phase_numbers(&s, 0.0, 0.5, 1.0, 0.1).expect("samples");
        assert_eq!(p.recovery_s, None);
        // No finite sample in the phase.
        assert_eq!(phase_numbers(&[(0.0, f64::NAN)], 0.0, 1.0, 1.0, 0.1), None);
        assert_eq!(phase_numbers(&[], 0.0, 1.0, 1.0, 0.1), None);
        // Within δ throughout: recovered at once.
        let p = phase_numbers(&[(0.0, 1.0), (0.1, 1.0)], 0.0, 1.0, 1.0, 0.1).expect("samples");
        assert_eq!(p.recovery_s, Some(0.0));
        assert!(p.rms_error_n.abs() < 1e-12);
    }
}
