//! Stiffness calibration from the finger's own estimate: what a rig (which has no
//! truth) measures before a force loop, and what the simulator measures the same way.
//!
//! The fingers close on a reference object one count at a time. At each count the
//! request is sent, the gPR echo and the end of the move awaited, and the newest frame
//! after that read: its estimate, projected on the grip axis (Method S3), is recorded
//! against the measured position P_m. From the curve:
//! - **first touch**: the first of [`StiffnessConfig::touch_run`] counts in a row whose
//!   estimate rises [`StiffnessConfig::touch_n`], and 4 robust σ of the estimates
//!   before it, above the no-contact baseline (the median of at least `touch_run`
//!   estimates before it);
//! - **Λ(P) = ΔF_est/ΔP**, N/mm, by a Theil–Sen fit (the median of the pairwise slopes)
//!   over a window of [`StiffnessConfig::window_counts`] counts sliding from the touch
//!   to the top of the range the loop will use: one count's estimate noise, or a frame
//!   the model misreads, moves a median by little where it would swing a least-squares
//!   slope;
//! - **Λ_max**, the largest windowed Λ, with the interquartile range of that window's
//!   pairwise slopes as its spread.
//!
//! NaN or missing estimates are recorded as such and left out of every fit; a
//! saturated one ends the closing (the estimate no longer follows the force). The
//! fingers always end back at the start count, on every path out.

use std::time::Duration;

use softtouch_drivers::{Camera, Clock, DeviceError, Gripper, GripperCommand, ObjectStatus};
use softtouch_schemas::TimestampNs;

use crate::GraspError;
use crate::estimator::ForceEstimator;
use crate::projection::Projection;
use crate::stepper::Stroke;

/// How the closing is done and read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessConfig {
    /// The count the closing starts from (open enough to clear the object).
    pub start_count: u8,
    /// Stop once the estimate reaches this, N (the top of the loop's range: 1.5 × the
    /// largest target).
    pub top_n: f64,
    /// Rise above the no-contact baseline that counts as a touch, N.
    pub touch_n: f64,
    /// Counts in a row above it for a touch (one misread frame is not a touch).
    pub touch_run: usize,
    /// Counts per Theil–Sen window.
    pub window_counts: usize,
    /// Frames averaged per count.
    pub frames_per_count: usize,
    /// An estimate at or above this is saturated, N.
    pub saturation_n: f64,
    /// rSP and rFR of the closing (slow and gentle).
    pub speed: u8,
    /// rFR.
    pub force: u8,
    /// Longest wait for one count's move.
    pub move_timeout: Duration,
    /// Status polling period.
    pub poll: Duration,
    /// Longest wait for a frame, ms.
    pub frame_timeout_ms: u64,
}

impl Default for StiffnessConfig {
    /// From the open end, up to 4.5 N (1.5 × the paper's 3 N), a touch at 0.05 N held
    /// for 3 counts, 7-count windows, 2 frames a count, saturation at 20 N, slow and
    /// gentle moves, 1 s per count, 5 ms polls, 200 ms per frame.
    fn default() -> Self {
        Self {
            start_count: 0,
            top_n: 4.5,
            touch_n: 0.05,
            touch_run: 3,
            window_counts: 7,
            frames_per_count: 2,
            saturation_n: 20.0,
            speed: 64,
            force: 20,
            move_timeout: Duration::from_secs(1),
            poll: Duration::from_millis(5),
            frame_timeout_ms: 200,
        }
    }
}

impl StiffnessConfig {
    fn validate(&self) -> Result<(), GraspError> {
        let bad = |m: String| Err(GraspError::Config(m));
        if !(self.top_n.is_finite() && self.top_n > 0.0) {
            return bad(format!(
                "top_n {}: expected a positive force, N",
                self.top_n
            ));
        }
        if !(self.touch_n.is_finite() && self.touch_n > 0.0 && self.touch_n < self.top_n) {
            return bad(format!(
                "touch_n {}: expected a positive force below top_n {} N",
                self.touch_n, self.top_n
            ));
        }
        if self.touch_run == 0 || self.window_counts < 3 || self.frames_per_count == 0 {
            return bad(format!(
                "touch_run {}, window_counts {}, frames_per_count {}: expected at least 1, 3 and 1",
                self.touch_run, self.window_counts, self.frames_per_count
            ));
        }
        if self.move_timeout.is_zero() || self.poll.is_zero() {
            return bad("move_timeout and poll: expected positive durations".into());
        }
        Ok(())
    }
}

/// One count of the closing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPoint {
    /// The count requested.
    pub request: u8,
    /// P_m, the count the gripper reports.
    pub measured: u8,
    /// F_est projected on the grip axis, N (mean over the count's frames; `None`: no
    /// usable estimate).
    pub estimate_n: Option<f64>,
}

/// What the closing found.
#[derive(Debug, Clone, PartialEq)]
pub struct StiffnessCalibration {
    /// Every count read, in order.
    pub points: Vec<CalibrationPoint>,
    /// The estimate with no contact (median before the touch), N.
    pub baseline_n: f64,
    /// The first count (P_m) of the touch.
    pub touch_count: u8,
    /// Λ(P): the window's centre count and its Theil–Sen slope, N/mm.
    pub lambda_curve: Vec<(u8, f64)>,
    /// Λ_max, N/mm.
    pub lambda_max_n_per_mm: f64,
    /// The interquartile range of the pairwise slopes in Λ_max's window, N/mm.
    pub lambda_max_iqr: (f64, f64),
    /// Counts from the touch to the last count read.
    pub counts_spanned: u8,
    /// Why the closing stopped.
    pub ended: CalibrationEnd,
}

/// Why the closing stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibrationEnd {
    /// The estimate reached `top_n`.
    ReachedTop,
    /// The estimate saturated.
    Saturated,
    /// The fingers reached the closed end of the stroke.
    ClosedEnd,
    /// The fingers stopped on the object (gOBJ contact) and would not close further.
    ContactStop,
}

impl CalibrationEnd {
    /// A short name for tables and the database.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ReachedTop => "reached_top",
            Self::Saturated => "saturated",
            Self::ClosedEnd => "closed_end",
            Self::ContactStop => "contact_stop",
        }
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    let (a, b) = (sorted[lo], sorted[hi]);
    a + (b - a) * (pos - lo as f64)
}

/// A rise counts as a touch only past this many robust σ of the no-contact estimates
/// as well as past `touch_n`. At rest a land model reads water frames with a wander
/// (the caustics drift across the finger): ±0.1 N over a closing through the tare,
/// where 0.05 N alone fired 10 mm before the object. On land the wander is a few
/// mN, so `touch_n` decides as before.
const TOUCH_SIGMAS: f64 = 4.0;

/// 1.4826 × the median absolute deviation from `median` of `sorted`: σ for Gaussian
/// values, and one misread count moves it little.
fn robust_sigma(sorted: &[f64], median: f64) -> f64 {
    let mut dev: Vec<f64> = sorted.iter().map(|v| (v - median).abs()).collect();
    dev.sort_by(f64::total_cmp);
    1.4826 * quantile(&dev, 0.5)
}

/// The pairwise slopes ΔF/ΔP (N per mm) of `points` (P in counts, F in N), sorted;
/// pairs at the same P are skipped.
fn pairwise_slopes(points: &[(f64, f64)], mm_per_count: f64) -> Vec<f64> {
    let mut slopes = Vec::new();
    for (i, a) in points.iter().enumerate() {
        for b in points.get(i + 1..).unwrap_or(&[]) {
            let dp_mm = (b.0 - a.0) * mm_per_count;
            if dp_mm.abs() > 0.0 {
                let s = (b.1 - a.1) / dp_mm;
                if s.is_finite() {
                    slopes.push(s);
                }
            }
        }
    }
    slopes.sort_by(f64::total_cmp);
    slopes
}

/// The Theil–Sen slope of `points` (the median of the pairwise slopes Δy/Δx), with the
/// number of pairs it took; `None` with no pair of distinct, finite x.
#[must_use]
pub fn theil_sen_slope(points: &[(f64, f64)]) -> Option<(f64, usize)> {
    let finite: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let slopes = pairwise_slopes(&finite, 1.0);
    (!slopes.is_empty()).then(|| (quantile(&slopes, 0.5), slopes.len()))
}

/// Fits a closing: the touch, Λ(P), Λ_max and its spread. Pure, so a stored curve can
/// be refitted and the fit tested on its hard cases.
///
/// # Errors
/// No touch (the estimate never rose `touch_n` above its baseline for `touch_run`
/// counts), or too few usable counts after it for one window.
pub fn fit(
    points: &[CalibrationPoint],
    config: &StiffnessConfig,
    stroke: &Stroke,
    ended: CalibrationEnd,
) -> Result<StiffnessCalibration, GraspError> {
    config.validate()?;
    let usable: Vec<(u8, f64)> = points
        .iter()
        .filter_map(|p| {
            p.estimate_n
                .filter(|f| f.is_finite())
                .map(|f| (p.measured, f))
        })
        .collect();
    // The touch: `touch_run` counts in a row above the baseline of at least as many
    // before, by `touch_n` and by the wander of those before.
    let mut touch = None;
    for i in config.touch_run..usable.len() {
        let mut before: Vec<f64> = usable.get(..i).unwrap_or(&[]).iter().map(|p| p.1).collect();
        before.sort_by(f64::total_cmp);
        let baseline = quantile(&before, 0.5);
        let rise = config
            .touch_n
            .max(TOUCH_SIGMAS * robust_sigma(&before, baseline));
        let run = usable.get(i..i + config.touch_run);
        if run.is_some_and(|r| {
            r.len() == config.touch_run && r.iter().all(|p| p.1 - baseline >= rise)
        }) {
            touch = Some((i, baseline));
            break;
        }
    }
    let Some((first, baseline_n)) = touch else {
        return Err(GraspError::Config(format!(
            "no touch: the estimate never rose {} N above its no-contact level for {} counts in a row over {} counts read ({} usable); is the object between the fingers, and the model the finger's?",
            config.touch_n,
            config.touch_run,
            points.len(),
            usable.len()
        )));
    };
    let contact = usable.get(first..).unwrap_or(&[]);
    let w = config.window_counts;
    if contact.len() < w {
        return Err(GraspError::Config(format!(
            "{} usable counts from the touch: expected at least {w} (window_counts) before the estimate reached {} N; open further or lower window_counts",
            contact.len(),
            config.top_n
        )));
    }
    let mut lambda_curve = Vec::new();
    let mut best: Option<(f64, (f64, f64))> = None;
    for window in contact.windows(w) {
        let pts: Vec<(f64, f64)> = window.iter().map(|p| (f64::from(p.0), p.1)).collect();
        let slopes = pairwise_slopes(&pts, stroke.mm_per_count);
        if slopes.is_empty() {
            // The fingers did not move over the window (a contact stop).
            continue;
        }
        let lambda = quantile(&slopes, 0.5);
        let centre = window[w / 2].0;
        lambda_curve.push((centre, lambda));
        if best.is_none_or(|(b, _)| lambda > b) {
            best = Some((lambda, (quantile(&slopes, 0.25), quantile(&slopes, 0.75))));
        }
    }
    let Some((lambda_max, iqr)) = best else {
        return Err(GraspError::Config(
            "the fingers did not move after the touch: no slope to fit".into(),
        ));
    };
    let touch_count = contact[0].0;
    let last = contact.last().map_or(touch_count, |p| p.0);
    Ok(StiffnessCalibration {
        points: points.to_vec(),
        baseline_n,
        touch_count,
        lambda_curve,
        lambda_max_n_per_mm: lambda_max,
        lambda_max_iqr: iqr,
        counts_spanned: last.saturating_sub(touch_count),
        ended,
    })
}

fn elapsed(clock: &dyn Clock, since: TimestampNs) -> Duration {
    Duration::from_nanos(clock.now().0.saturating_sub(since.0))
}

/// Sends `count` and waits for the echo and the end of the move (arrival, or a stop
/// on the object). The status it ended on.
async fn move_to<G: Gripper + ?Sized>(
    gripper: &mut G,
    clock: &dyn Clock,
    config: &StiffnessConfig,
    count: u8,
) -> Result<softtouch_drivers::GripperStatus, GraspError> {
    let cmd = GripperCommand {
        position: count,
        speed: config.speed,
        force: config.force,
    };
    let start = clock.now();
    let mut s = gripper.command_and_status(cmd).await?;
    loop {
        if s.fault != 0 {
            return Err(GraspError::Device(DeviceError::Fault {
                device: "gripper".into(),
                code: Some(u32::from(s.fault)),
                message: format!(
                    "during the stiffness calibration: {}",
                    softtouch_drivers::hande::regs::describe_fault(s.fault)
                ),
            }));
        }
        if s.requested_position == count && s.object != ObjectStatus::Moving {
            return Ok(s);
        }
        if elapsed(clock, start) > config.move_timeout {
            return Err(GraspError::Device(DeviceError::Timeout {
                device: "gripper".into(),
                timeout_ms: u64::try_from(config.move_timeout.as_millis()).unwrap_or(u64::MAX),
            }));
        }
        tokio::time::sleep(config.poll).await;
        // Each poll re-sends the request: the keep-alive, at no extra transaction.
        s = gripper.command_and_status(cmd).await?;
    }
}

/// Closes on the object between the fingers one count at a time from
/// `config.start_count`, reading the estimate at each, until it reaches `top_n`,
/// saturates, or the fingers reach the closed end or stop on the object; then fits
/// the curve ([`fit`]). The fingers are sent back to the start count on every path.
///
/// # Errors
/// A device error, a fault, or a curve with no touch.
#[allow(clippy::too_many_arguments)] // the loop's devices and settings, as a controller has them
pub async fn calibrate_stiffness<G, C, E>(
    gripper: &mut G,
    camera: &mut C,
    estimator: &mut E,
    projection: &Projection,
    stroke: &Stroke,
    clock: &dyn Clock,
    config: &StiffnessConfig,
) -> Result<StiffnessCalibration, GraspError>
where
    G: Gripper + ?Sized,
    C: Camera + ?Sized,
    E: ForceEstimator + ?Sized,
{
    config.validate()?;
    gripper.activate().await?;
    let closing = close_and_read(
        gripper, camera, estimator, projection, stroke, clock, config,
    )
    .await;
    // Back to the start, whatever happened (a failure here is reported only when the
    // closing itself went well).
    let back = move_to(gripper, clock, config, config.start_count).await;
    let (points, ended) = closing?;
    back?;
    fit(&points, config, stroke, ended)
}

#[allow(clippy::too_many_arguments)]
async fn close_and_read<G, C, E>(
    gripper: &mut G,
    camera: &mut C,
    estimator: &mut E,
    projection: &Projection,
    stroke: &Stroke,
    clock: &dyn Clock,
    config: &StiffnessConfig,
) -> Result<(Vec<CalibrationPoint>, CalibrationEnd), GraspError>
where
    G: Gripper + ?Sized,
    C: Camera + ?Sized,
    E: ForceEstimator + ?Sized,
{
    let mut points = Vec::new();
    let first = stroke.clamp(i64::from(config.start_count));
    let mut stuck = 0;
    for count in first..=stroke.closed_count {
        let s = move_to(gripper, clock, config, count).await?;
        // Frames exposed after the fingers stopped at this count.
        let mut after = clock.now();
        let mut sum = 0.0;
        let mut n = 0usize;
        let mut saturated = false;
        for _ in 0..config.frames_per_count {
            let frame = camera
                .latest_frame_after(after, config.frame_timeout_ms)
                .await?;
            after = TimestampNs(frame.meta.t.0.saturating_add(1));
            match estimator.estimate(&frame)? {
                Some(w) if w.is_finite() && w.force_norm_n() >= config.saturation_n => {
                    saturated = true;
                }
                Some(w) => {
                    if let Some(f) = projection.grip_force_n(&w).filter(|f| f.is_finite()) {
                        sum += f;
                        n += 1;
                    }
                }
                None => {}
            }
        }
        let estimate_n = (n > 0).then(|| sum / n as f64);
        points.push(CalibrationPoint {
            request: count,
            measured: s.position,
            estimate_n,
        });
        if saturated {
            return Ok((points, CalibrationEnd::Saturated));
        }
        if estimate_n.is_some_and(|f| f >= config.top_n) {
            return Ok((points, CalibrationEnd::ReachedTop));
        }
        // Stopped on the object and not following the requests any more.
        if s.object == ObjectStatus::ContactClosing && s.position < count.saturating_sub(2) {
            stuck += 1;
            if stuck >= 3 {
                return Ok((points, CalibrationEnd::ContactStop));
            }
        } else {
            stuck = 0;
        }
    }
    Ok((points, CalibrationEnd::ClosedEnd))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(
        curve: impl Fn(u8) -> Option<f64>,
        range: std::ops::RangeInclusive<u8>,
    ) -> Vec<CalibrationPoint> {
        range
            .map(|c| CalibrationPoint {
                request: c,
                measured: c,
                estimate_n: curve(c),
            })
            .collect()
    }

    fn stroke() -> Stroke {
        Stroke::default()
    }

    /// A contact from count 100 at 0.5 N per count: Λ = 0.5 / 0.196 mm ≈ 2.55 N/mm.
    fn linear(c: u8) -> Option<f64> {
        Some(0.02 + 0.5 * f64::from(c.saturating_sub(100)))
    }

    #[test]
    fn theil_sen_takes_the_median_slope_and_survives_hard_cases() {
        // y = 2x with one wild outlier: the median slope stays 2.
        let mut pts: Vec<(f64, f64)> = (0..9).map(|i| (f64::from(i), 2.0 * f64::from(i))).collect();
        pts.push((4.5, 1e6));
        let (m, n) = theil_sen_slope(&pts).expect("slope");
        assert!((m - 2.0).abs() < 1e-9, "{m}");
        assert_eq!(n, 45);
        // Empty, one point, all at one x, NaN: no slope.
        assert!(theil_sen_slope(&[]).is_none());
        assert!(theil_sen_slope(&[(1.0, 1.0)]).is_none());
        assert!(theil_sen_slope(&[(1.0, 1.0), (1.0, 5.0)]).is_none());
        assert!(theil_sen_slope(&[(f64::NAN, 1.0), (2.0, f64::INFINITY)]).is_none());
        // A constant y: slope 0.
        let flat = [(0.0, 3.0), (1.0, 3.0), (2.0, 3.0)];
        assert_eq!(theil_sen_slope(&flat).map(|s| s.0), Some(0.0));
    }

    #[test]
    fn a_linear_contact_gives_its_slope_and_its_first_count() {
        let cfg = StiffnessConfig::default();
        let cal = fit(
            &points(linear, 80..=110),
            &cfg,
            &stroke(),
            CalibrationEnd::ReachedTop,
        )
        .expect("fit");
        // 0.5 N at 101 is the first count 0.05 N above the 0.02 N baseline.
        assert_eq!(cal.touch_count, 101);
        assert!((cal.baseline_n - 0.02).abs() < 1e-12);
        let want = 0.5 / stroke().mm_per_count;
        assert!((cal.lambda_max_n_per_mm - want).abs() < 1e-9, "{cal:?}");
        assert!(cal.lambda_max_iqr.0 <= want + 1e-9 && cal.lambda_max_iqr.1 >= want - 1e-9);
        assert_eq!(cal.counts_spanned, 9);
    }

    #[test]
    fn one_misread_count_moves_the_fit_little() {
        let cfg = StiffnessConfig::default();
        let spiked = |c: u8| if c == 105 { Some(40.0) } else { linear(c) };
        let cal = fit(
            &points(spiked, 80..=115),
            &cfg,
            &stroke(),
            CalibrationEnd::ReachedTop,
        )
        .expect("fit");
        let want = 0.5 / stroke().mm_per_count;
        // Theil–Sen over 7 counts: the spike's 6 slopes are outvoted by 15.
        assert!(
            (cal.lambda_max_n_per_mm - want).abs() / want < 0.35,
            "{cal:?}"
        );
        // A lone spike before the contact is not a touch.
        let early = |c: u8| if c == 90 { Some(3.0) } else { linear(c) };
        let cal = fit(
            &points(early, 80..=110),
            &cfg,
            &stroke(),
            CalibrationEnd::ReachedTop,
        )
        .expect("fit");
        assert_eq!(cal.touch_count, 101);
    }

    /// The closing a land model read through the tare in water (cylinder, counts
    /// 51–124): the estimate wanders by 0.17 N with no contact, then rises at 98.
    /// A fixed 0.05 N rise took count 52 for the touch; the wander's σ does not.
    #[test]
    fn a_wandering_no_contact_estimate_is_not_a_touch() {
        let wander = [
            -0.177, -0.107, -0.100, -0.099, -0.078, -0.064, -0.079, -0.087, -0.071, -0.077, -0.090,
            -0.077, -0.089, -0.062, -0.060, -0.038, -0.058, -0.050, -0.050, -0.012, -0.041, -0.030,
            -0.004, -0.020, -0.019, -0.024, -0.006, -0.026, -0.018, -0.002, -0.022, 0.010, -0.013,
            -0.012, -0.018, -0.012, -0.021, -0.044, -0.067, -0.073, -0.083, -0.076, -0.076, -0.076,
            -0.070, -0.063, -0.027, -0.005,
        ];
        let curve = |c: u8| match usize::from(c).checked_sub(51) {
            Some(i) if i < wander.len() => Some(wander[i]),
            _ => Some(0.148 + 0.16 * f64::from(c - 98)),
        };
        let cal = fit(
            &points(curve, 51..=124),
            &StiffnessConfig::default(),
            &stroke(),
            CalibrationEnd::ReachedTop,
        )
        .expect("fit");
        assert_eq!(cal.touch_count, 99, "{cal:?}");
        // On a quiet curve the wander's σ is 0 and `touch_n` alone decides, as before.
        assert!(robust_sigma(&[0.02; 5], 0.02).abs() < 1e-15);
        assert!(robust_sigma(&[], 0.0).is_nan());
    }

    #[test]
    fn nan_missing_and_no_contact_curves_give_finite_results_or_clear_errors() {
        let cfg = StiffnessConfig::default();
        // NaN and missing estimates are left out; the slope stays finite.
        let holes = |c: u8| match c % 4 {
            0 => Some(f64::NAN),
            1 => None,
            _ => linear(c),
        };
        let cal = fit(
            &points(holes, 80..=130),
            &cfg,
            &stroke(),
            CalibrationEnd::ClosedEnd,
        )
        .expect("fit");
        assert!(cal.lambda_max_n_per_mm.is_finite() && cal.lambda_max_n_per_mm > 0.0);
        // No contact at all: a flat, constant curve.
        let e = fit(
            &points(|_| Some(0.01), 0..=255),
            &cfg,
            &stroke(),
            CalibrationEnd::ClosedEnd,
        )
        .expect_err("no touch");
        assert!(e.to_string().contains("no touch"), "{e}");
        // Nothing usable at all; an empty curve.
        assert!(
            fit(
                &points(|_| None, 0..=255),
                &cfg,
                &stroke(),
                CalibrationEnd::ClosedEnd
            )
            .is_err()
        );
        assert!(fit(&[], &cfg, &stroke(), CalibrationEnd::ClosedEnd).is_err());
        // A touch right at the end: too few counts for a window.
        let late = |c: u8| Some(if c >= 253 { 1.0 } else { 0.0 });
        let e = fit(
            &points(late, 200..=255),
            &cfg,
            &stroke(),
            CalibrationEnd::ClosedEnd,
        )
        .expect_err("short");
        assert!(e.to_string().contains("window_counts"), "{e}");
        // Fingers stuck after the touch (P_m constant): no slope, a clear error.
        let stuck: Vec<CalibrationPoint> = (80..=120u8)
            .map(|c| CalibrationPoint {
                request: c,
                measured: c.min(101),
                estimate_n: linear(c.min(101)),
            })
            .collect();
        let e = fit(&stuck, &cfg, &stroke(), CalibrationEnd::ContactStop).expect_err("stuck");
        assert!(e.to_string().contains("did not move"), "{e}");
        // Huge and tiny forces stay finite.
        let huge = |c: u8| Some(1e300 * f64::from(c.saturating_sub(100)));
        let cal = fit(
            &points(huge, 80..=110),
            &cfg,
            &stroke(),
            CalibrationEnd::Saturated,
        )
        .expect("fit");
        assert!(cal.lambda_max_n_per_mm.is_finite());
        // Settings that cannot work are named.
        let bad = StiffnessConfig {
            window_counts: 2,
            ..cfg
        };
        assert!(
            fit(
                &points(linear, 80..=110),
                &bad,
                &stroke(),
                CalibrationEnd::ReachedTop
            )
            .is_err()
        );
    }
}
