//! `softtouch bench grasp`: the force loop on the simulated soft grasp, measured over
//! the gain K (as a multiple of the stiffness Λ_max the model's calibration measures, including
//! values below Λ_max/2 where Method S4 says it may not settle), the tolerance δ, the
//! camera rate and the model. One factor is varied at a time around a baseline (K =
//! 0.75 Λ_max, δ = 0.1 N, 120 Hz); each run holds one target from a pre-grasp a few
//! counts before contact and reports settling time, overshoot and steady-state error
//! of the estimate and of the simulator's truth.
//!
//! Virtual time is exact: the loop runs one cycle per frame whatever it costs. The
//! wall-clock mode runs the baseline on real time, where the rendering of the
//! simulated camera, the model and the loop share the real period: it reports the
//! achieved cycle rate, frames skipped and frames handled more than one period after
//! their exposure (late).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::sim::{SimTruth, projection, sim_err};
use softtouch_drivers::{Clock, Frame, TokioClock};
use softtouch_grasp::{
    Controller, ControllerConfig, ForceEstimator, GraspError, HoldMetrics, hold_metrics,
};
use softtouch_schemas::{SceneSpec, Wrench};
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::Predictor;

/// Records, per frame, how long after its exposure the estimate was ready (on the
/// loop's clock): the lateness of the cycle.
struct Timed<E> {
    inner: E,
    clock: Arc<dyn Clock>,
    lateness_ns: Arc<Mutex<Vec<u64>>>,
}

impl<E: ForceEstimator> ForceEstimator for Timed<E> {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        let out = self.inner.estimate(frame);
        let late = self.clock.now().0.saturating_sub(frame.meta.t.0);
        if let Ok(mut v) = self.lateness_ns.lock() {
            v.push(late);
        }
        out
    }
}

/// One run's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Which factor this point varies (`baseline`, `K`, `δ`, `fps`, `wall-clock`).
    pub varied: &'static str,
    /// K / Λ_max.
    pub gain_over_lambda: f64,
    /// δ, N.
    pub tolerance_n: f64,
    /// Camera rate, Hz.
    pub fps: f64,
}

/// One run's results.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The settings.
    pub point: Point,
    /// Λ_max, N/mm, measured on the simulator for this object and target.
    pub lambda_n_per_mm: f64,
    /// K, N/mm.
    pub gain_n_per_mm: f64,
    /// Control cycles run.
    pub cycles: usize,
    /// Cycles completed per second of the loop's clock.
    pub cycle_rate_hz: f64,
    /// Frames the loop skipped (gaps in the frame sequence).
    pub skipped_frames: u64,
    /// Cycles whose estimate was ready more than one frame period after exposure.
    pub late_frames: u64,
    /// Median and largest time from a frame's exposure to its estimate, ms.
    pub lateness_ms: (f64, f64),
    /// The estimate's numbers.
    pub estimate: Option<HoldMetrics>,
    /// The truth's numbers.
    pub truth: Option<HoldMetrics>,
    /// (t s, true force N) of every cycle, for the plot.
    pub true_trace: Vec<(f64, f64)>,
}

/// What every run shares.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Scene (medium, effects).
    pub scene: SceneSpec,
    /// The object gripped.
    pub object: GraspObject,
    /// The target force, N.
    pub target_n: f64,
    /// How long the target is held, s.
    pub hold_s: f64,
    /// Seed of the scene's effects.
    pub seed: u64,
}

/// One run of the loop at `point` with `predictor`, on tokio's clock as it is (paused:
/// virtual time; running: the wall clock). `calibration` is the model's stiffness
/// calibration on the object ([`crate::grasp::calibration`]): the pre-grasp from its
/// first touch, K = `point.gain_over_lambda` × its Λ_max, and the squeeze bound.
pub async fn run_point(
    setup: &Setup,
    predictor: Predictor,
    point: Point,
    calibration: &crate::grasp::calibration::Calibrated,
) -> Result<Outcome, GraspError> {
    let clock = TokioClock::new();
    let (gripper, camera, handle) = soft_grasp(
        &setup.scene,
        setup.object.clone(),
        point.fps,
        setup.seed,
        clock,
    )
    .map_err(sim_err)?;
    let (touch, lambda) = (calibration.touch(), calibration.lambda_max());
    let gain_n_per_mm = point.gain_over_lambda * lambda;
    let squeeze = calibration
        .squeeze()
        .map_err(|e| GraspError::Config(e.to_string()))?;
    let mut config = ControllerConfig::new(projection()?).with_squeeze(squeeze);
    config.stepper.gain_n_per_mm = gain_n_per_mm;
    config.stepper.tolerance_n = point.tolerance_n;
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let lateness = Arc::new(Mutex::new(Vec::new()));
    let estimator = Timed {
        inner: predictor,
        clock: shared.clone(),
        lateness_ns: lateness.clone(),
    };
    let truth = SimTruth(handle.clone(), config.projection);
    let mut controller = Controller::new(gripper, camera, estimator, truth, shared, config)?;
    controller
        .approach(touch.saturating_sub(4), Duration::from_secs(5))
        .await?;
    let loop_start = clock.now();
    let cycles = controller
        .follow(&[(setup.target_n, Duration::from_secs_f64(setup.hold_s))])
        .await?;
    let series = |f: fn(&softtouch_grasp::Cycle) -> Option<f64>| -> Vec<(f64, f64)> {
        let t0 = cycles.first().map_or(0, |c| c.t.0);
        cycles
            .iter()
            .filter_map(|c| Some((c.t.0.saturating_sub(t0) as f64 * 1e-9, f(c)?)))
            .collect()
    };
    let estimate = hold_metrics(&series(|c| c.estimate_n), setup.target_n, point.tolerance_n);
    let true_trace = series(|c| c.true_n);
    let truth = hold_metrics(&true_trace, setup.target_n, point.tolerance_n);
    // Cycles completed per second of the loop's own clock (not of frame stamps: a
    // loop that falls behind still handles frames on the 120 Hz grid, only later).
    let loop_s = clock.now().0.saturating_sub(loop_start.0) as f64 * 1e-9;
    let cycle_rate_hz = if loop_s > 0.0 {
        cycles.len() as f64 / loop_s
    } else {
        0.0
    };
    let skipped_frames = cycles
        .windows(2)
        .map(|w| w[1].frame_sequence.saturating_sub(w[0].frame_sequence + 1))
        .sum();
    let period_ns = (1e9 / point.fps) as u64;
    let mut late: Vec<u64> = lateness.lock().map(|v| v.clone()).unwrap_or_default();
    late.sort_unstable();
    let late_frames = late.iter().filter(|l| **l > period_ns).count() as u64;
    let lateness_ms = (
        late.get(late.len() / 2).map_or(0.0, |l| *l as f64 * 1e-6),
        late.last().map_or(0.0, |l| *l as f64 * 1e-6),
    );
    Ok(Outcome {
        point,
        lambda_n_per_mm: lambda,
        gain_n_per_mm,
        cycles: cycles.len(),
        cycle_rate_hz,
        skipped_frames,
        late_frames,
        lateness_ms,
        estimate,
        truth,
        true_trace,
    })
}

/// The one-factor-at-a-time grid around the baseline (K = 0.75 Λ, δ = 0.1 N, 120 Hz).
#[must_use]
pub fn grid(gains: &[f64], tolerances: &[f64], fps: &[f64]) -> Vec<Point> {
    let base = Point {
        varied: "baseline",
        gain_over_lambda: 0.75,
        tolerance_n: 0.1,
        fps: 120.0,
    };
    let mut out = vec![base];
    let same = |a: f64, b: f64| (a - b).abs() < 1e-12;
    for &g in gains {
        if !same(g, base.gain_over_lambda) {
            out.push(Point {
                varied: "K",
                gain_over_lambda: g,
                ..base
            });
        }
    }
    for &d in tolerances {
        if !same(d, base.tolerance_n) {
            out.push(Point {
                varied: "δ",
                tolerance_n: d,
                ..base
            });
        }
    }
    for &f in fps {
        if !same(f, base.fps) {
            out.push(Point {
                varied: "fps",
                fps: f,
                ..base
            });
        }
    }
    out
}

/// CSV header of [`csv_row`].
pub const CSV_HEADER: &str = "model,model_size_px,model_width,model_latent,varied,gain_over_lambda,gain_n_per_mm,lambda_n_per_mm,tolerance_n,fps,clock,cycles,cycle_rate_hz,skipped_frames,late_frames,settle_s,overshoot_n,ss_error_n,true_settle_s,true_overshoot_n,true_ss_error_n";

/// One CSV row.
#[must_use]
pub fn csv_row(model: &str, shape: (usize, usize, usize), clock: &str, o: &Outcome) -> String {
    let opt = |v: Option<f64>| v.map_or_else(String::new, |x| format!("{x}"));
    let m = |h: &Option<HoldMetrics>| {
        (
            opt(h.and_then(|h| h.settling_time_s)),
            opt(h.map(|h| h.overshoot_n)),
            opt(h.map(|h| h.steady_state_error_n)),
        )
    };
    let (es, eo, ee) = m(&o.estimate);
    let (ts, to, te) = m(&o.truth);
    format!(
        "{model},{},{},{},{},{},{},{},{},{},{clock},{},{},{},{},{es},{eo},{ee},{ts},{to},{te}",
        shape.0,
        shape.1,
        shape.2,
        o.point.varied,
        o.point.gain_over_lambda,
        o.gain_n_per_mm,
        o.lambda_n_per_mm,
        o.point.tolerance_n,
        o.point.fps,
        o.cycles,
        o.cycle_rate_hz,
        o.skipped_frames,
        o.late_frames
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_varies_one_factor_at_a_time_without_repeating_the_baseline() {
        let g = grid(&[0.3, 0.75, 1.5], &[0.05, 0.1], &[30.0, 120.0]);
        let varied: Vec<&str> = g.iter().map(|p| p.varied).collect();
        assert_eq!(varied, ["baseline", "K", "K", "δ", "fps"]);
        assert!(
            g.iter()
                .filter(|p| p.varied == "K")
                .all(|p| (p.fps - 120.0).abs() < 1e-12)
        );
    }
}
