//! Algorithm 1 (the paper's reference motion generator) as a pure stepper:
//!
//! ```text
//! if |F_ref − F_est| > δ:  P_ref = P_m + (F_ref − F_est) / K
//! else:                    P_ref = P_m
//! ```
//!
//! Positions are gripper counts (Hand-E rPR/gPO: 0 open … 255 closed), so `P` grows
//! as the fingers close and a positive force error closes them. A step is truncated
//! towards zero to whole counts, and a step under one count while the error is outside
//! δ moves one count: otherwise a large K would stall short of the target forever.
//! Every request is clamped to the calibrated stroke. A NaN or saturated estimate
//! holds position.
//!
//! Method S4: with contact stiffness `Λ = ∂F/∂P ≥ 0` the error evolves as
//! `e ← (1 − Λ/K)·e`, which shrinks when `K > Λ/2`. Truncating keeps that true on
//! whole counts (a truncated step is a fraction in (½, 1] of the exact one, so the
//! factor stays in (1 − Λ/K, 1)), and the one-count minimum step changes the force by
//! `Λ·mm_per_count`, which lands within δ rather than past it when
//! `δ ≥ Λ·mm_per_count/2` ([`check_tolerance`]). [`check_gain`] checks K for a
//! measured Λ and warns when `K ≤ Λ_max/2`.

use crate::GraspError;

/// The calibrated travel of a gripper in counts, and the opening per count.
///
/// The usable count range of a Hand-E is narrower than 0–255 and is measured per
/// gripper (docs/PROTOCOLS.md §2.x); the loop never commands outside it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stroke {
    /// Count of the fully open end.
    pub open_count: u8,
    /// Count of the fully closed end.
    pub closed_count: u8,
    /// Change of the opening per count, mm (Hand-E: 50 mm / 255 ≈ 0.196 mm).
    pub mm_per_count: f64,
}

impl Default for Stroke {
    /// The whole Hand-E scale; real grippers are calibrated instead.
    fn default() -> Self {
        Self {
            open_count: 0,
            closed_count: 255,
            mm_per_count: softtouch_drivers::gripper::STROKE_MM / 255.0,
        }
    }
}

impl Stroke {
    /// A list of what is wrong (empty when usable).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.open_count >= self.closed_count {
            out.push(format!(
                "stroke: open_count {} must be below closed_count {}",
                self.open_count, self.closed_count
            ));
        }
        if !(self.mm_per_count.is_finite() && self.mm_per_count > 0.0) {
            out.push(format!(
                "stroke: mm_per_count {}: expected a finite value above 0",
                self.mm_per_count
            ));
        }
        out
    }

    /// `count` clamped into the stroke.
    #[must_use]
    pub fn clamp(&self, count: i64) -> u8 {
        count.clamp(i64::from(self.open_count), i64::from(self.closed_count)) as u8
    }
}

/// Gain, tolerance and limits of Algorithm 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepperConfig {
    /// K, N per mm of closing: a force error of K newtons moves the fingers 1 mm.
    pub gain_n_per_mm: f64,
    /// δ, N: errors within it hold position. 0 is allowed (the loop then dithers by
    /// one count around the target).
    pub tolerance_n: f64,
    /// Estimates at or beyond this magnitude are saturated (outside what the model
    /// was trained on) and hold position, N.
    pub saturation_n: f64,
    /// The calibrated stroke.
    pub stroke: Stroke,
}

impl Default for StepperConfig {
    fn default() -> Self {
        Self {
            gain_n_per_mm: 4.0,
            tolerance_n: 0.1,
            // The paper's labels span about ±10 N.
            saturation_n: 10.0,
            stroke: Stroke::default(),
        }
    }
}

impl StepperConfig {
    /// Rejects unusable settings with an error naming the field and what it expects.
    pub fn validate(&self) -> Result<(), GraspError> {
        let mut out = self.stroke.problems();
        if !(self.gain_n_per_mm.is_finite() && self.gain_n_per_mm > 0.0) {
            out.push(format!(
                "gain_n_per_mm (K) {}: expected a finite value above 0",
                self.gain_n_per_mm
            ));
        }
        if !(self.tolerance_n.is_finite() && self.tolerance_n >= 0.0) {
            out.push(format!(
                "tolerance_n (δ) {}: expected a finite value ≥ 0",
                self.tolerance_n
            ));
        }
        if !(self.saturation_n.is_finite() && self.saturation_n > 0.0) {
            out.push(format!(
                "saturation_n {}: expected a finite value above 0",
                self.saturation_n
            ));
        }
        if out.is_empty() {
            Ok(())
        } else {
            Err(GraspError::Config(out.join("; ")))
        }
    }

    /// Checks a target force: finite, positive (the fingers push, never pull) and
    /// below what the estimate can report (minus δ, so "within δ" is observable).
    pub fn check_target(&self, target_n: f64) -> Result<(), GraspError> {
        let hi = self.saturation_n - self.tolerance_n;
        if target_n.is_finite() && target_n > 0.0 && target_n < hi {
            Ok(())
        } else {
            Err(GraspError::UnreachableTarget {
                target_n,
                reachable_n: [0.0, hi.max(0.0)],
                why: "the finger only pushes, and the estimate saturates at saturation_n − δ",
            })
        }
    }
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StepOutcome {
    /// The error was outside δ: the request moved.
    Stepped,
    /// The error was within δ: position held.
    WithinTolerance,
    /// The estimate was NaN or infinite (or missing): position held.
    HeldNonFinite,
    /// The estimate reached the saturation limit: position held.
    HeldSaturated,
    /// The step wanted to go past the open end; the request stops there.
    ClampedOpen,
    /// The step wanted to go past the closed end (e.g. no object between the fingers);
    /// the request stops there.
    ClampedClosed,
    /// The step wanted to close past the squeeze bound ([`crate::SqueezeBound`]); the
    /// request stops at the bound.
    ClampedSqueeze,
}

impl StepOutcome {
    /// Name used in CSV traces.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Stepped => "stepped",
            Self::WithinTolerance => "within_tolerance",
            Self::HeldNonFinite => "held_non_finite",
            Self::HeldSaturated => "held_saturated",
            Self::ClampedOpen => "clamped_open",
            Self::ClampedClosed => "clamped_closed",
            Self::ClampedSqueeze => "clamped_squeeze",
        }
    }

    /// Whether the estimate was unusable this step.
    pub fn is_flagged(self) -> bool {
        matches!(self, Self::HeldNonFinite | Self::HeldSaturated)
    }
}

/// One step's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// P_ref, counts, inside the stroke.
    pub position_request: u8,
    /// What happened.
    pub outcome: StepOutcome,
}

/// Algorithm 1 with validated settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stepper {
    config: StepperConfig,
}

impl Stepper {
    /// A stepper; fails with an error naming the bad field.
    pub fn new(config: StepperConfig) -> Result<Self, GraspError> {
        config.validate()?;
        Ok(Self { config })
    }

    /// Its settings.
    pub fn config(&self) -> &StepperConfig {
        &self.config
    }

    /// One step from the measured position `p_measured` (counts), the target and the
    /// estimate (`None` when there is none). Within δ the request is the measured
    /// position clamped into the stroke. A NaN, missing or saturated estimate requests
    /// the measured position itself, even outside the stroke (fully open before the
    /// first grasp, say): an estimate that cannot be trusted never moves the fingers.
    #[must_use]
    pub fn step(&self, p_measured: u8, target_n: f64, estimate_n: Option<f64>) -> Step {
        let c = &self.config;
        let hold = |outcome| Step {
            position_request: c.stroke.clamp(i64::from(p_measured)),
            outcome,
        };
        let stay = |outcome| Step {
            position_request: p_measured,
            outcome,
        };
        let Some(f_est) = estimate_n.filter(|f| f.is_finite()) else {
            return stay(StepOutcome::HeldNonFinite);
        };
        if !target_n.is_finite() {
            return stay(StepOutcome::HeldNonFinite);
        }
        if f_est.abs() >= c.saturation_n {
            return stay(StepOutcome::HeldSaturated);
        }
        let error_n = target_n - f_est;
        if error_n.abs() <= c.tolerance_n {
            return hold(StepOutcome::WithinTolerance);
        }
        let counts = error_n / c.gain_n_per_mm / c.stroke.mm_per_count;
        let mut n = counts.trunc();
        if n == 0.0 {
            n = counts.signum();
        }
        // Far beyond the stroke anyway: the clamp below takes it from here.
        let n = n.clamp(-512.0, 512.0) as i64;
        let want = i64::from(p_measured) + n;
        let position_request = c.stroke.clamp(want);
        let outcome = if want > i64::from(position_request) {
            StepOutcome::ClampedClosed
        } else if want < i64::from(position_request) {
            StepOutcome::ClampedOpen
        } else {
            StepOutcome::Stepped
        };
        Step {
            position_request,
            outcome,
        }
    }
}

/// What Method S4 says about a gain for a measured contact stiffness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GainCheck {
    /// `K > Λ_max/2`: the error shrinks every step wherever `0 < Λ ≤ Λ_max`.
    Converges {
        /// `|1 − Λ_max/K|` (below 1): the error's factor per step at the stiffest
        /// contact. Softer contacts shrink it by `1 − Λ/K`, slower as Λ → 0.
        contraction_at_max: f64,
    },
    /// `K ≤ Λ_max/2`: steps overshoot by at least as much as they correct.
    MayNotConverge {
        /// `|1 − Λ_max/K|` (≥ 1).
        amplification: f64,
    },
    /// `Λ = 0`: the force does not change with position; no gain reaches a target
    /// (the fingers travel to the stroke's end).
    NoStiffness,
}

/// Method S4 for a gain `K` (N/mm) and the largest contact stiffness `Λ_max` (N/mm)
/// seen over the targets; logs a warning when `K ≤ Λ_max/2`.
pub fn check_gain(
    gain_n_per_mm: f64,
    max_stiffness_n_per_mm: f64,
) -> Result<GainCheck, GraspError> {
    if !(gain_n_per_mm.is_finite() && gain_n_per_mm > 0.0) {
        return Err(GraspError::Config(format!(
            "gain_n_per_mm (K) {gain_n_per_mm}: expected a finite value above 0"
        )));
    }
    if !(max_stiffness_n_per_mm.is_finite() && max_stiffness_n_per_mm >= 0.0) {
        return Err(GraspError::Config(format!(
            "stiffness Λ {max_stiffness_n_per_mm} N/mm: expected a finite value ≥ 0"
        )));
    }
    // No logging here: the caller says what the verdict means, once, to its user.
    if max_stiffness_n_per_mm == 0.0 {
        return Ok(GainCheck::NoStiffness);
    }
    let ratio = max_stiffness_n_per_mm / gain_n_per_mm;
    if gain_n_per_mm > max_stiffness_n_per_mm / 2.0 {
        Ok(GainCheck::Converges {
            contraction_at_max: (1.0 - ratio).abs(),
        })
    } else {
        Ok(GainCheck::MayNotConverge {
            amplification: (1.0 - ratio).abs(),
        })
    }
}

/// Whether δ resolves one count: with `δ < Λ_max·mm_per_count/2` a one-count step can
/// jump over the tolerance band and the loop dithers around the target (δ = 0 always
/// does). Returns whether the band is wide enough; the caller warns its user.
pub fn check_tolerance(tolerance_n: f64, max_stiffness_n_per_mm: f64, stroke: &Stroke) -> bool {
    tolerance_n >= one_count_force_n(max_stiffness_n_per_mm, stroke) / 2.0
}

/// The force one count of position changes at stiffness Λ, N.
#[must_use]
pub fn one_count_force_n(max_stiffness_n_per_mm: f64, stroke: &Stroke) -> f64 {
    max_stiffness_n_per_mm * stroke.mm_per_count
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A linear contact: no force until `contact` counts, then Λ N/mm.
    fn linear(stiffness_n_per_mm: f64, contact: u8, stroke: &Stroke) -> impl Fn(u8) -> f64 {
        let res = stroke.mm_per_count;
        move |p| stiffness_n_per_mm * res * (f64::from(p) - f64::from(contact)).max(0.0)
    }

    /// Runs the stepper on a plant that reaches every request at once; returns the
    /// errors after each step and the requests.
    fn run(
        stepper: &Stepper,
        plant: &dyn Fn(u8) -> f64,
        target_n: f64,
        steps: usize,
    ) -> (Vec<f64>, Vec<u8>) {
        let mut p = stepper.config().stroke.open_count;
        let mut errors = Vec::new();
        let mut requests = Vec::new();
        for _ in 0..steps {
            let s = stepper.step(p, target_n, Some(plant(p)));
            p = s.position_request;
            requests.push(p);
            errors.push(target_n - plant(p));
        }
        (errors, requests)
    }

    fn stepper(gain_n_per_mm: f64, tolerance_n: f64) -> Stepper {
        Stepper::new(StepperConfig {
            gain_n_per_mm,
            tolerance_n,
            saturation_n: 1e6,
            stroke: Stroke {
                open_count: 10,
                closed_count: 230,
                mm_per_count: 0.2,
            },
        })
        .expect("valid")
    }

    proptest! {
        /// Method S4: K > Λ/2 reaches every feasible target within δ (δ resolving one
        /// count) and stays there.
        #[test]
        fn a_gain_above_half_the_stiffness_reaches_every_feasible_target(
            stiffness in 0.05f64..20.0,
            gain_over_half_stiffness in 1.01f64..20.0,
            tolerance_over_count in 0.5f64..3.0,
            contact in 10u8..150,
            target_frac in 0.05f64..0.95,
        ) {
            let k = gain_over_half_stiffness * stiffness / 2.0;
            let res = 0.2;
            let delta = tolerance_over_count * stiffness * res;
            let s = stepper(k, delta);
            let plant = linear(stiffness, contact, &s.config().stroke);
            let f_max = plant(230);
            let target = target_frac * f_max;
            prop_assume!(target > delta);
            let converges = matches!(check_gain(k, stiffness), Ok(GainCheck::Converges { .. }));
            prop_assert!(converges);
            prop_assert!(check_tolerance(delta, stiffness, &s.config().stroke));
            let (errors, requests) = run(&s, &plant, target, 400);
            let first = errors.iter().position(|e| e.abs() <= delta);
            let tail = &errors[errors.len() - 5..];
            prop_assert!(first.is_some(), "never within δ: {:?}", tail);
            let first = first.unwrap_or_default();
            prop_assert!(errors[first..].iter().all(|e| e.abs() <= delta), "left the band");
            prop_assert!(requests.iter().all(|p| (10..=230).contains(p)));
        }

        /// K below Λ/2: every step overshoots by more than it corrects, so from a large
        /// error the loop never settles within δ (it bangs between the stroke's ends).
        #[test]
        fn a_gain_below_half_the_stiffness_does_not_converge(
            stiffness in 0.5f64..20.0,
            gain_over_half_stiffness in 0.125f64..0.9,
            contact in 10u8..60,
            target_frac in 0.35f64..0.65,
        ) {
            let k = gain_over_half_stiffness * stiffness / 2.0;
            let res = 0.2;
            let delta = stiffness * res;
            let s = stepper(k, delta);
            let plant = linear(stiffness, contact, &s.config().stroke);
            let target = target_frac * plant(230);
            // Errors of tens of counts (the regime S4 speaks of, not one-count dither).
            prop_assume!(target.min(plant(230) - target) > 40.0 * k * res);
            let diverges = matches!(check_gain(k, stiffness), Ok(GainCheck::MayNotConverge { .. }));
            prop_assert!(diverges);
            let (errors, requests) = run(&s, &plant, target, 200);
            prop_assert!(errors.iter().all(|e| e.abs() > delta), "settled: {:?}", errors);
            prop_assert!(requests.iter().all(|p| (10..=230).contains(p)));
        }

        /// Whatever the estimates (NaN, huge, negative), requests stay in the stroke,
        /// or stay exactly where the fingers are when the estimate is not usable.
        #[test]
        fn requests_never_leave_the_calibrated_stroke(
            p in 0u8..=255,
            estimate in prop::option::of(prop_oneof![Just(f64::NAN), Just(f64::INFINITY), -1e9f64..1e9]),
            target in -10.0f64..10.0,
            gain in 0.001f64..100.0,
        ) {
            let s = stepper(gain, 0.0);
            let step = s.step(p, target, estimate);
            if step.outcome.is_flagged() {
                prop_assert_eq!(step.position_request, p, "{:?}", step);
            } else {
                prop_assert!((10..=230).contains(&step.position_request), "{step:?}");
            }
        }
    }

    #[test]
    fn a_nan_missing_or_saturated_estimate_holds_position_and_is_flagged() {
        let s = Stepper::new(StepperConfig::default()).expect("valid");
        for (est, outcome) in [
            (Some(f64::NAN), StepOutcome::HeldNonFinite),
            (Some(f64::NEG_INFINITY), StepOutcome::HeldNonFinite),
            (None, StepOutcome::HeldNonFinite),
            (Some(10.0), StepOutcome::HeldSaturated),
            (Some(-12.0), StepOutcome::HeldSaturated),
        ] {
            let step = s.step(120, 1.6, est);
            assert_eq!(
                step,
                Step {
                    position_request: 120,
                    outcome
                },
                "{est:?}"
            );
            assert!(step.outcome.is_flagged());
        }
        // A NaN target holds too.
        assert_eq!(
            s.step(120, f64::NAN, Some(1.0)).outcome,
            StepOutcome::HeldNonFinite
        );
    }

    #[test]
    fn no_object_drives_to_the_closed_end_and_never_beyond() {
        let s = stepper(1.0, 0.05);
        // Λ = 0: nothing between the fingers, the estimate stays 0.
        let plant = |_: u8| 0.0;
        let (errors, requests) = run(&s, &plant, 1.6, 100);
        assert!(errors.iter().all(|e| (e - 1.6).abs() < 1e-12));
        assert_eq!(requests.last(), Some(&230));
        assert!(requests.windows(2).all(|w| w[0] <= w[1]), "{requests:?}");
        assert_eq!(
            s.step(230, 1.6, Some(0.0)).outcome,
            StepOutcome::ClampedClosed
        );
        assert_eq!(check_gain(1.0, 0.0).expect("valid"), GainCheck::NoStiffness);
        // A measured position outside the stroke is pulled back in, not followed.
        assert_eq!(s.step(250, 1.6, Some(1.6)).position_request, 230);
        assert_eq!(s.step(0, 1.6, Some(1.6)).position_request, 10);
        // Too much force: it opens, clamped at the open end.
        assert_eq!(
            s.step(12, 0.4, Some(8.0)),
            Step {
                position_request: 10,
                outcome: StepOutcome::ClampedOpen
            }
        );
    }

    #[test]
    fn a_zero_tolerance_dithers_by_one_count_around_the_target() {
        let s = stepper(2.0, 0.0);
        let plant = linear(1.0, 50, &s.config().stroke);
        assert!(!check_tolerance(0.0, 1.0, &s.config().stroke));
        // 1.5 N lies between counts (0.2 N per count): the loop cannot hold it exactly.
        let (errors, requests) = run(&s, &plant, 1.5, 200);
        let tail = &errors[150..];
        assert!(tail.iter().all(|e| e.abs() <= 0.2 + 1e-9), "{tail:?}");
        let (lo, hi) = requests[150..]
            .iter()
            .fold((u8::MAX, 0), |(l, h), p| (l.min(*p), h.max(*p)));
        assert!(hi - lo <= 1, "{lo}..{hi}");
    }

    #[test]
    fn bad_settings_and_unreachable_targets_are_clear_errors() {
        let bad = StepperConfig {
            gain_n_per_mm: 0.0,
            tolerance_n: -0.1,
            stroke: Stroke {
                open_count: 200,
                closed_count: 100,
                mm_per_count: 0.2,
            },
            ..StepperConfig::default()
        };
        let err = Stepper::new(bad).expect_err("bad").to_string();
        for field in ["gain_n_per_mm", "tolerance_n", "open_count"] {
            assert!(err.contains(field), "{err}");
        }
        let c = StepperConfig::default();
        for t in [0.0, -1.0, 9.95, 50.0, f64::NAN] {
            let err = c.check_target(t).expect_err("unreachable").to_string();
            assert!(err.contains("target"), "{err}");
        }
        c.check_target(3.0).expect("reachable");
        assert!(check_gain(f64::NAN, 1.0).is_err());
        assert!(check_gain(1.0, -1.0).is_err());
    }
}
