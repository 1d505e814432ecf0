//! The closing limit of a force loop: how far past the first touch the fingers may
//! close for a target, from the stiffness calibration.
//!
//! An estimate that stops rising (a weak model, a dark frame, a finger that lost its
//! marker) is as dangerous as a NaN one: Algorithm 1 reads "below target" and closes
//! on, up to the gripper's own force cap. The bound is the squeeze the calibration's
//! closing needed to reach the target, past its first touch, times [`SQUEEZE_FACTOR`],
//! plus [`SQUEEZE_FLOOR_COUNTS`] (a count's quantisation and the estimate's noise at a
//! small target):
//!
//! ```text
//! limit(F_ref) = anchor + ⌈factor × needed(F_ref)⌉ + floor
//! anchor       = this run's touch, within [touch, touch + search]
//! ```
//!
//! This run's touch is the first measured count at which the estimate read
//! [`RUN_TOUCH_N`] over its no-contact level: a perturbed grasp meets the object
//! later than the calibration did, and a bound from the calibrated touch alone would
//! stop a good model before it touched. An estimate that never rises anchors at the
//! calibrated touch; one that rises late anchors at most [`TOUCH_SEARCH_MM`] past it.
//!
//! where `needed(F)` is the counts past the touch at which the calibrated estimate
//! first rose `F` above its no-contact level, interpolated between counts and beyond
//! the closing's last count extended at Λ_max. The loop never requests past the
//! limit, and once the fingers stand at it with the estimate still below the target
//! it stops with [`crate::GraspError::EstimateStalled`]. Where the calibration read
//! the force right and the estimate then stops rising, the factor bounds the true
//! force at 3× the target on a linear contact, 5.2× on a Hertzian one (F ∝ d^1.5) and
//! 9× on one that stiffens as d² (the simulated 20 mm rod), before the floor's few
//! counts: newtons, where an unbounded loop reached the gripper's 185 N. 1.5 held
//! those to 1.5–2.25×, but stopped a good model's perturbed grasps (on the grasp
//! scene, land, closed loop: 34/50 held against 45/50 unbounded; 3: 43/50), whose
//! contact off the finger's centre reads less force per millimetre than the
//! calibration's.

use crate::GraspError;
use crate::stiffness::StiffnessCalibration;

/// How many times the calibrated squeeze the loop may close (see the module's
/// documentation).
pub const SQUEEZE_FACTOR: f64 = 3.0;

/// Counts added to every limit (0.6 mm of opening on a Hand-E).
pub const SQUEEZE_FLOOR_COUNTS: u8 = 3;

/// How far past the calibrated touch this run's own touch may anchor the bound, mm:
/// a perturbed grasp (σ = 5 mm along and across the fingers) meets a ball, a taper or
/// an off-centre object later than the calibration did. The trials' pre-grasp margin.
pub const TOUCH_SEARCH_MM: f64 = 6.0;

/// The estimate's rise over its no-contact level that marks this run's touch, N (the
/// stiffness calibration's own `touch_n`).
pub const RUN_TOUCH_N: f64 = 0.05;

/// The closing limit of one calibrated setup.
#[derive(Debug, Clone, PartialEq)]
pub struct SqueezeBound {
    /// The calibration's first touch, counts (P_m).
    pub touch_count: u8,
    /// The estimate with no contact, N: a target is reached when the estimate rises
    /// `target − baseline` (the loop compares the estimate itself with the target).
    pub baseline_n: f64,
    /// The calibration's closing from the touch: counts past the touch and the
    /// estimate's rise above the no-contact level, N, in closing order.
    pub rise_n: Vec<(u8, f64)>,
    /// Λ_max, N/mm, for targets beyond the closing's last count.
    pub lambda_max_n_per_mm: f64,
    /// Opening per count, mm.
    pub mm_per_count: f64,
    /// [`SQUEEZE_FACTOR`] unless a caller states another.
    pub factor: f64,
    /// [`SQUEEZE_FLOOR_COUNTS`] unless a caller states another.
    pub floor_counts: u8,
    /// Counts the contact may move while the loop runs, added to the limit (0 unless
    /// the run turns the object: then from its width to its narrowest across the
    /// fingers, [`Self::with_allowance_mm`]).
    pub allowance_counts: u8,
    /// How far past the calibrated touch this run's touch may anchor the bound,
    /// counts ([`TOUCH_SEARCH_MM`]).
    pub search_counts: u8,
}

/// How far `position` lies past the first touch at `touch_count`, mm (0 short of it),
/// at `mm_per_count`: the grip a rig can show without a true force.
#[must_use]
pub fn past_touch_mm(position: u8, touch_count: u8, mm_per_count: f64) -> f64 {
    f64::from(position.saturating_sub(touch_count)) * mm_per_count
}

impl SqueezeBound {
    /// How far `position` lies past the calibrated first touch, mm ([`past_touch_mm`]).
    #[must_use]
    pub fn past_touch_mm(&self, position: u8) -> f64 {
        past_touch_mm(position, self.touch_count, self.mm_per_count)
    }
    /// The bound of a calibration: its touch, its closing and its Λ_max.
    #[must_use]
    pub fn from_calibration(cal: &StiffnessCalibration, mm_per_count: f64) -> Self {
        let points: Vec<(u8, Option<f64>)> = cal
            .points
            .iter()
            .map(|p| (p.measured, p.estimate_n))
            .collect();
        Self::from_points(
            cal.touch_count,
            cal.baseline_n,
            &points,
            cal.lambda_max_n_per_mm,
            mm_per_count,
        )
    }

    /// The bound of a stored calibration: its touch, its no-contact level, its points
    /// as `(P_m, estimate)`, Λ_max and the opening per count. Points before the touch
    /// and without a finite estimate are left out.
    #[must_use]
    pub fn from_points(
        touch_count: u8,
        baseline_n: f64,
        points: &[(u8, Option<f64>)],
        lambda_max_n_per_mm: f64,
        mm_per_count: f64,
    ) -> Self {
        let baseline_n = if baseline_n.is_finite() {
            baseline_n
        } else {
            0.0
        };
        let rise_n = points
            .iter()
            .filter(|(p, _)| *p >= touch_count)
            .filter_map(|(p, f)| {
                f.filter(|f| f.is_finite())
                    .map(|f| (p - touch_count, f - baseline_n))
            })
            .collect();
        Self {
            touch_count,
            baseline_n,
            rise_n,
            lambda_max_n_per_mm,
            mm_per_count,
            factor: SQUEEZE_FACTOR,
            floor_counts: SQUEEZE_FLOOR_COUNTS,
            allowance_counts: 0,
            search_counts: whole_counts(TOUCH_SEARCH_MM, mm_per_count),
        }
    }

    /// Where the bound is measured from: this run's touch (`run_touch`, the first
    /// count at which the estimate rose [`RUN_TOUCH_N`]) held within the calibrated
    /// touch and [`Self::search_counts`] past it; the calibrated touch without one.
    #[must_use]
    pub fn anchor_count(&self, run_touch: Option<u8>) -> u8 {
        let hi = self.touch_count.saturating_add(self.search_counts);
        run_touch.map_or(self.touch_count, |t| t.clamp(self.touch_count, hi))
    }

    /// The same bound with `mm` of opening allowed for a contact that moves (an
    /// object turned between the fingers to a narrower side), in whole counts.
    #[must_use]
    pub fn with_allowance_mm(mut self, mm: f64) -> Self {
        self.allowance_counts = whole_counts(mm, self.mm_per_count);
        self
    }

    /// Rejects a bound that cannot work, naming the field.
    ///
    /// # Errors
    /// A factor under 1 or not finite, an opening per count that is not positive.
    pub fn validate(&self) -> Result<(), GraspError> {
        if !(self.factor.is_finite() && self.factor >= 1.0) {
            return Err(GraspError::Config(format!(
                "squeeze factor {}: expected a finite value ≥ 1 (the bound never closes less than the calibrated squeeze)",
                self.factor
            )));
        }
        if !(self.mm_per_count.is_finite() && self.mm_per_count > 0.0) {
            return Err(GraspError::Config(format!(
                "squeeze mm_per_count {}: expected a finite value above 0",
                self.mm_per_count
            )));
        }
        Ok(())
    }

    /// Counts past the touch at which the calibrated estimate first read `target_n`
    /// (rose `target_n − baseline_n`; interpolated between counts; past the
    /// closing's end, extended at Λ_max). A closing that never rose that far with no
    /// usable Λ_max gives its last count: the bound then allows only what was seen.
    #[must_use]
    pub fn needed_counts(&self, target_n: f64) -> f64 {
        let target_n = target_n - self.baseline_n;
        let mut prev: Option<(f64, f64)> = None;
        // The running peak, so a noisy dip after a rise does not push the bound out.
        let mut peak = f64::NEG_INFINITY;
        for &(c, rise) in &self.rise_n {
            let c = f64::from(c);
            if rise >= target_n {
                return match prev {
                    Some((c0, r0)) if rise > r0 => c0 + (target_n - r0) / (rise - r0) * (c - c0),
                    _ => c,
                };
            }
            if rise > peak {
                peak = rise;
                prev = Some((c, rise));
            }
        }
        let (last_c, last_rise) = match (self.rise_n.last(), prev) {
            (Some(&(c, _)), Some((_, r))) => (f64::from(c), r),
            _ => (0.0, 0.0),
        };
        let per_count_n = self.lambda_max_n_per_mm * self.mm_per_count;
        if per_count_n.is_finite() && per_count_n > 0.0 {
            last_c + (target_n - last_rise).max(0.0) / per_count_n
        } else {
            last_c
        }
    }

    /// The furthest count the loop may request for `target_n`, measured from the
    /// calibrated touch (a run that has not touched yet).
    #[must_use]
    pub fn limit_count(&self, target_n: f64) -> u8 {
        self.limit_from(target_n, None)
    }

    /// The furthest count the loop may request for `target_n`, measured from
    /// [`Self::anchor_count`] of `run_touch`.
    #[must_use]
    pub fn limit_from(&self, target_n: f64, run_touch: Option<u8>) -> u8 {
        // A hair under a whole count is that count (float noise in the rise).
        let extra = (self.factor * self.needed_counts(target_n) - 1e-9).ceil();
        let limit = f64::from(self.anchor_count(run_touch))
            + f64::from(self.allowance_counts)
            + extra
            + f64::from(self.floor_counts);
        if limit.is_finite() {
            limit.clamp(0.0, 255.0) as u8
        } else {
            u8::MAX
        }
    }

    /// The squeeze the limit allows past the calibrated touch, mm.
    #[must_use]
    pub fn limit_mm(&self, target_n: f64) -> f64 {
        f64::from(self.limit_count(target_n).saturating_sub(self.touch_count)) * self.mm_per_count
    }
}

/// `mm` of opening in whole counts (rounded up), 0 for a negative or non-finite one.
fn whole_counts(mm: f64, mm_per_count: f64) -> u8 {
    let counts = (mm.max(0.0) / mm_per_count).ceil();
    if counts.is_finite() {
        counts.min(255.0) as u8
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MM: f64 = 50.0 / 255.0;

    /// A linear contact from count 100 at 0.1 N a count, read up to 4.5 N.
    fn linear() -> SqueezeBound {
        let points: Vec<(u8, Option<f64>)> = (90..=145)
            .map(|c: u8| (c, Some(0.1 * f64::from(c.saturating_sub(100)))))
            .collect();
        SqueezeBound::from_points(100, 0.0, &points, 0.1 / MM, MM)
    }

    #[test]
    fn the_closing_past_the_touch_is_zero_short_of_it() {
        let b = linear();
        assert!((b.past_touch_mm(110) - 10.0 * MM).abs() < 1e-12);
        assert!(b.past_touch_mm(100).abs() < 1e-12);
        assert!(b.past_touch_mm(0).abs() < 1e-12);
        assert!((b.past_touch_mm(255) - 155.0 * MM).abs() < 1e-12);
    }

    #[test]
    fn a_linear_contact_needs_the_target_over_its_stiffness() {
        let b = linear();
        assert!(
            (b.needed_counts(1.0) - 10.0).abs() < 1e-9,
            "{}",
            b.needed_counts(1.0)
        );
        assert!((b.needed_counts(0.25) - 2.5).abs() < 1e-9);
        // 100 + 3 × 10 + 3.
        assert_eq!(b.limit_count(1.0), 133);
        assert!((b.limit_mm(1.0) - 33.0 * MM).abs() < 1e-12);
        // Beyond the closing's end (4.5 N at count 145): extended at Λ_max.
        assert!(
            (b.needed_counts(6.0) - 60.0).abs() < 1e-9,
            "{}",
            b.needed_counts(6.0)
        );
    }

    #[test]
    fn a_noisy_dip_does_not_push_the_bound_out_and_nan_points_are_skipped() {
        let pts = [
            (100, Some(0.0)),
            (101, Some(0.5)),
            (102, Some(0.2)),
            (103, None),
            (104, Some(f64::NAN)),
            (105, Some(1.5)),
        ];
        let b = SqueezeBound::from_points(100, 0.0, &pts, 2.0, MM);
        // 1 N lies between 0.5 (count 1) and 1.5 (count 5): count 3.
        assert!(
            (b.needed_counts(1.0) - 3.0).abs() < 1e-9,
            "{}",
            b.needed_counts(1.0)
        );
    }

    #[test]
    fn a_flat_closing_with_no_stiffness_allows_only_what_was_seen() {
        // The weak model's case: the estimate never rose, Λ_max 0.
        let pts: Vec<(u8, Option<f64>)> = (100..=120).map(|c| (c, Some(0.01))).collect();
        let b = SqueezeBound::from_points(100, 0.0, &pts, 0.0, MM);
        assert!((b.needed_counts(1.0) - 20.0).abs() < 1e-9);
        assert_eq!(b.limit_count(1.0), 163);
        // No point at all, NaN Λ: the floor alone.
        let empty = SqueezeBound::from_points(100, 0.0, &[], f64::NAN, MM);
        assert_eq!(empty.limit_count(1.0), 103);
        // A huge target on a tiny stiffness stays inside the scale.
        let tiny = SqueezeBound::from_points(250, 0.0, &pts, 1e-12, MM);
        assert_eq!(tiny.limit_count(5.0), 255);
    }

    #[test]
    fn a_target_is_read_from_the_no_contact_level() {
        // The estimate reads −0.15 N with no contact: 1 N is a rise of 1.15 N.
        let points: Vec<(u8, Option<f64>)> = (100..=145)
            .map(|c: u8| (c, Some(-0.15 + 0.1 * f64::from(c - 100))))
            .collect();
        let b = SqueezeBound::from_points(100, -0.15, &points, 0.1 / MM, MM);
        assert!(
            (b.needed_counts(1.0) - 11.5).abs() < 1e-9,
            "{}",
            b.needed_counts(1.0)
        );
        // A NaN level is taken as 0.
        let b = SqueezeBound::from_points(100, f64::NAN, &points, 0.1 / MM, MM);
        assert!(b.baseline_n.abs() < f64::EPSILON);
        assert!(b.rise_n.iter().all(|r| r.1.is_finite()));
    }

    #[test]
    fn an_allowance_moves_the_limit_by_whole_counts() {
        let b = linear().with_allowance_mm(12.0);
        // 12 mm at 50/255 mm a count: 61.2, so 62 counts.
        assert_eq!(b.allowance_counts, 62);
        assert_eq!(b.limit_count(1.0), 133 + 62);
        assert_eq!(linear().with_allowance_mm(-1.0).allowance_counts, 0);
        assert_eq!(linear().with_allowance_mm(f64::NAN).allowance_counts, 0);
        assert_eq!(linear().with_allowance_mm(1e9).limit_count(1.0), 255);
    }

    #[test]
    fn the_runs_own_touch_anchors_the_bound_within_the_search() {
        let b = linear();
        // 6 mm at 50/255 mm a count: 30.6, so 31 counts.
        assert_eq!(b.search_counts, 31);
        assert_eq!(b.anchor_count(None), 100);
        assert_eq!(b.anchor_count(Some(110)), 110);
        // Never before the calibrated touch (noise at the pre-grasp), never past the
        // search (a touch read late from a weak estimate).
        assert_eq!(b.anchor_count(Some(80)), 100);
        assert_eq!(b.anchor_count(Some(200)), 131);
        assert_eq!(b.limit_from(1.0, Some(110)), 143);
        assert_eq!(b.limit_from(1.0, None), b.limit_count(1.0));
    }

    #[test]
    fn bad_settings_are_named() {
        let mut b = linear();
        b.factor = 0.5;
        assert!(
            b.validate()
                .expect_err("factor")
                .to_string()
                .contains("squeeze factor")
        );
        b.factor = f64::NAN;
        assert!(b.validate().is_err());
        let mut b = linear();
        b.mm_per_count = 0.0;
        assert!(
            b.validate()
                .expect_err("mm")
                .to_string()
                .contains("mm_per_count")
        );
    }
}
