//! Figure 5's twist on the simulated soft grasp: a gripped cylinder turned about the
//! fingers' axis and back while the force loop holds the grip, run without and with
//! the wrist loop on the model's τz estimate; the τz RMS of both (estimate and
//! truth), its CSV and two-panel chart.

use std::path::Path;
use std::time::Duration;

use softtouch_drivers::Clock;
use softtouch_grasp::{Cycle, ExitAction, WristConfig, WristLoop};
use softtouch_schemas::{SceneSpec, TimestampNs};
use softtouch_sim::GraspObject;

use super::disturb::line;
use super::sim::{SimWrist, TruthSample};
use super::soft::{GraspRunError, LoopSettings, Setup, prepare, t_s, write_text};
use softtouch_collector::plot::two_panel_chart;

/// What `grasp twist` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct TwistSettings {
    /// The loop.
    pub loop_settings: LoopSettings,
    /// The grip force held, N.
    pub target_n: f64,
    /// How far the object turns (then back), degrees.
    pub turn_deg: f64,
    /// How long the force is held before the turn, s.
    pub settle_s: f64,
    /// How long each turn takes, s.
    pub turn_s: f64,
    /// How long the turned object is held before it turns back, and after, s.
    pub hold_s: f64,
    /// The wrist loop.
    pub wrist: WristConfig,
}

/// One run of the twist: the cycles and the simulator's τz and wrist log.
#[derive(Debug, Clone)]
pub struct TwistRun {
    /// When the first turn starts (the numbers count from here).
    pub from: TimestampNs,
    /// Every cycle.
    pub cycles: Vec<Cycle>,
    /// The truth at each cycle it could read.
    pub truth: Vec<TruthSample>,
    /// The object's yaw at each truth sample, rad.
    pub object_yaw_rad: Vec<f64>,
}

/// Runs the twist twice on the simulated soft grasp of `object`, without and with the
/// wrist loop (a paused tokio clock). Returns the setup (the same both times), the
/// runs, and the stop request that ended it early: a request on `stop` ends the run in
/// hand after its cycle (fingers opened) and skips the next, so one run may come back.
///
/// # Errors
/// As [`prepare`], a wrist loop that cannot work, the loop, the simulator.
pub async fn twist_sim(
    settings: &TwistSettings,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: &GraspObject,
    calibration: &super::calibration::Calibrated,
    stop: Option<softtouch_grasp::StopRequest>,
) -> Result<(Setup, Vec<TwistRun>, Option<&'static str>), GraspRunError> {
    let wrist_loop = WristLoop::new(settings.wrist)
        .map_err(|e| GraspRunError::Invalid(format!("--wrist-gain / --wrist-deadband-nmm: {e}")))?;
    let mut runs = Vec::new();
    let mut setup = None;
    let mut stopped: Option<&'static str> = None;
    for with_wrist in [false, true] {
        let p = prepare(
            &settings.loop_settings,
            model_bytes,
            scene,
            object.clone(),
            &[settings.target_n],
            ExitAction::Open,
            calibration,
            true,
        )
        .await?;
        setup.get_or_insert(p.setup);
        let start = p.clock.now();
        let at = |s: f64| TimestampNs(start.0 + (s * 1e9) as u64);
        let turn_rad = settings.turn_deg.to_radians();
        p.handle
            .schedule_object_yaw(at(settings.settle_s), turn_rad, settings.turn_s)?;
        p.handle.schedule_object_yaw(
            at(settings.settle_s + settings.turn_s + settings.hold_s),
            0.0,
            settings.turn_s,
        )?;
        let total_s = settings.settle_s + 2.0 * (settings.turn_s + settings.hold_s);
        let mut controller = if with_wrist {
            p.controller
                .with_wrist(Box::new(SimWrist(p.handle.clone())), wrist_loop)
        } else {
            p.controller
        };
        if let Some(stop) = &stop {
            controller = controller.with_stop(stop.clone());
        }
        let (cycles, stop_name) = controller
            .follow_until_stopped(&[(settings.target_n, Duration::from_secs_f64(total_s))])
            .await?;
        stopped = stopped.or(stop_name);
        let truth = p
            .truth_log
            .lock()
            .map_err(|_| GraspRunError::Failed("truth log poisoned".into()))?
            .clone();
        let object_yaw_rad = truth
            .iter()
            .map(|s| p.handle.object_yaw(s.t))
            .collect::<Result<_, _>>()?;
        runs.push(TwistRun {
            from: at(settings.settle_s),
            cycles,
            truth,
            object_yaw_rad,
        });
        if stopped.is_some() {
            break;
        }
    }
    let setup = setup.ok_or_else(|| GraspRunError::Failed("no run".into()))?;
    Ok((setup, runs, stopped))
}

/// One run's numbers, N·mm for torques. Every number counts from the first turn (the
/// settle before it is left out): the terminal, the stored summary,
/// `grasp-twist-metrics.csv` and the report all show these, computed here once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistRow {
    /// Whether the wrist loop ran.
    pub wrist_loop: bool,
    /// When the scored part starts (the first turn), s on the CSV's clock.
    pub scored_from_s: f64,
    /// Cycles in the scored part.
    pub cycles_scored: usize,
    /// RMS of the estimated τz from the first turn on, N·mm.
    pub tz_rms_nmm: f64,
    /// RMS of the true τz, N·mm.
    pub true_tz_rms_nmm: f64,
    /// Largest |true τz|, N·mm.
    pub true_tz_peak_nmm: f64,
    /// RMS of the true grip force's error, N.
    pub true_force_rms_n: f64,
    /// Largest |wrist yaw|, degrees.
    pub wrist_max_deg: f64,
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

/// The numbers of each run (without, then with the wrist loop).
#[must_use]
pub fn twist_rows(runs: &[TwistRun]) -> Vec<TwistRow> {
    let row = |i: usize| {
        let run = &runs[i];
        let est: Vec<f64> = run
            .cycles
            .iter()
            .filter(|cy| cy.t >= run.from)
            .filter_map(|cy| cy.torque_z_nm)
            .map(|t| t * 1000.0)
            .collect();
        let tru: Vec<f64> = run
            .truth
            .iter()
            .filter(|s| s.t >= run.from)
            .map(|s| s.torque_z_nm * 1000.0)
            .collect();
        let force_err: Vec<f64> = run
            .cycles
            .iter()
            .filter(|cy| cy.t >= run.from)
            .filter_map(|cy| Some(cy.true_n? - cy.target_n))
            .collect();
        TwistRow {
            wrist_loop: i == 1,
            scored_from_s: t_s(run.from),
            cycles_scored: run.cycles.iter().filter(|cy| cy.t >= run.from).count(),
            tz_rms_nmm: rms(&est),
            true_tz_rms_nmm: rms(&tru),
            true_tz_peak_nmm: tru.iter().fold(0.0_f64, |m, t| m.max(t.abs())),
            true_force_rms_n: rms(&force_err),
            wrist_max_deg: run
                .truth
                .iter()
                .fold(0.0_f64, |m, s| m.max(s.wrist_rad.abs()))
                .to_degrees(),
        }
    };
    (0..runs.len()).map(row).collect()
}

/// The header of `grasp-twist-metrics.csv`.
pub const TWIST_METRICS_HEADER: &str = "wrist_loop,scored_from_s,cycles_scored,tz_rms_nmm,true_tz_rms_nmm,true_tz_peak_nmm,true_force_rms_n,wrist_max_deg";

/// `grasp-twist-metrics.csv`: each run's numbers ([`twist_rows`]), one line a run.
///
/// # Errors
/// The file cannot be written.
pub fn write_twist_metrics_csv(path: &Path, rows: &[TwistRow]) -> Result<(), GraspRunError> {
    let mut text = format!("{TWIST_METRICS_HEADER}\n");
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            if r.wrist_loop { "on" } else { "off" },
            r.scored_from_s,
            r.cycles_scored,
            r.tz_rms_nmm,
            r.true_tz_rms_nmm,
            r.true_tz_peak_nmm,
            r.true_force_rms_n,
            r.wrist_max_deg
        ));
    }
    write_text(path, &text)
}

/// `grasp-twist.csv`: one line per cycle of each run.
///
/// # Errors
/// The file cannot be written.
pub fn write_twist_csv(path: &Path, runs: &[TwistRun]) -> Result<(), GraspRunError> {
    let mut text = String::from(
        "wrist_loop,t_s,target_n,estimate_n,true_n,tz_estimate_nmm,tz_true_nmm,object_yaw_deg,wrist_yaw_deg\n",
    );
    let o = |v: Option<f64>| v.map_or_else(String::new, |f| format!("{f}"));
    for (i, run) in runs.iter().enumerate() {
        for cy in &run.cycles {
            // The truth is logged per frame, skipping any it could not read: match by
            // the frame's time, not by position.
            let truth = run
                .truth
                .binary_search_by_key(&cy.t, |s| s.t)
                .ok()
                .map(|k| (&run.truth[k], run.object_yaw_rad[k]));
            text.push_str(&format!(
                "{},{},{},{},{},{},{},{},{}\n",
                if i == 0 { "off" } else { "on" },
                t_s(cy.t),
                cy.target_n,
                o(cy.estimate_n),
                o(cy.true_n),
                o(cy.torque_z_nm.map(|t| t * 1000.0)),
                o(truth.map(|(s, _)| s.torque_z_nm * 1000.0)),
                o(truth.map(|(_, yaw)| yaw.to_degrees())),
                o(truth.map(|(s, _)| s.wrist_rad.to_degrees())),
            ));
        }
    }
    write_text(path, &text)
}

/// `grasp-twist.png`: τz (true without and with the wrist loop, estimated with it)
/// above, the object's and the wrist's yaw below.
///
/// # Errors
/// The chart cannot be drawn or written.
pub fn write_twist_png(path: &Path, runs: &[TwistRun]) -> Result<(), GraspRunError> {
    let torque_series = |run: &TwistRun, label: &str| {
        line(
            label,
            run.truth
                .iter()
                .map(|s| (t_s(s.t), s.torque_z_nm * 1000.0))
                .collect(),
        )
    };
    let Some(off) = runs.first() else {
        return Err(GraspRunError::Failed("no twist run to draw".into()));
    };
    let mut torques = vec![torque_series(off, "true τz, wrist loop off")];
    // The run with the wrist loop (the first, when a stop skipped it).
    let on = match runs.get(1) {
        Some(on) => {
            torques.push(torque_series(on, "true τz, wrist loop on"));
            torques.push(line(
                "estimated τz, wrist loop on",
                on.cycles
                    .iter()
                    .filter_map(|cy| Some((t_s(cy.t), cy.torque_z_nm? * 1000.0)))
                    .collect(),
            ));
            on
        }
        None => off,
    };
    let angles = [
        line(
            "object yaw",
            on.truth
                .iter()
                .zip(&on.object_yaw_rad)
                .map(|(s, y)| (t_s(s.t), y.to_degrees()))
                .collect(),
        ),
        line(
            "wrist yaw",
            on.truth
                .iter()
                .map(|s| (t_s(s.t), s.wrist_rad.to_degrees()))
                .collect(),
        ),
    ];
    two_panel_chart(
        path,
        "Twist: τz held by the wrist",
        (&torques, "τz (N·mm)"),
        (&angles, "yaw (°)"),
    )
    .map_err(|e| GraspRunError::Failed(e.to_string()))
}

/// The terminal's table of a twist: one row per run (without, then with the wrist
/// loop), counted from the first turn.
///
/// # Errors
/// The writer's.
pub fn print_twist_table(rows: &[TwistRow], out: &mut dyn std::io::Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:>14} {:>8} {:>14} {:>15} {:>16} {:>15} {:>14}",
        "wrist loop",
        "cycles",
        "τz RMS N·mm",
        "true τz RMS",
        "true τz peak",
        "true F RMS N",
        "wrist max °"
    )?;
    for row in rows {
        writeln!(
            out,
            "{:>14} {:>8} {:>14.3} {:>15.3} {:>16.3} {:>15.3} {:>14.2}",
            if row.wrist_loop { "on" } else { "off" },
            row.cycles_scored,
            row.tz_rms_nmm,
            row.true_tz_rms_nmm,
            row.true_tz_peak_nmm,
            row.true_force_rms_n,
            row.wrist_max_deg
        )?;
    }
    Ok(())
}

/// A twist in one line, as the results table stores it: the true τz RMS from the
/// first turn, without and with the wrist loop, and each run's grip at its firmest
/// (`grips`: [`super::soft::grip_words`] per run, in the rows' order).
#[must_use]
pub fn twist_summary(rows: &[TwistRow], grips: &[String]) -> String {
    rows.iter()
        .zip(grips)
        .map(|(r, grip)| {
            format!(
                "wrist loop {}: true τz RMS {:.3} N·mm from the first turn, {grip}",
                if r.wrist_loop { "on" } else { "off" },
                r.true_tz_rms_nmm
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}
