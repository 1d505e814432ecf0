//! How well a target was held: the step-response numbers of Figure 5.

/// Step-response numbers of one held target, from `(t_s, force_n)` samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldMetrics {
    /// The target, N.
    pub target_n: f64,
    /// The first sample's force, N (where the step starts).
    pub start_n: f64,
    /// 10 % → 90 % of the way from the first sample to the target, s (`None`: never;
    /// [`HoldMetrics::started_within`] tells a step smaller than δ, which has no rise).
    pub rise_time_s: Option<f64>,
    /// From the first sample until the force enters the δ band for good, s (`None`:
    /// the last sample is still outside).
    pub settling_time_s: Option<f64>,
    /// Largest excursion past the target in the direction of the step, N (≥ 0).
    pub overshoot_n: f64,
    /// Mean error (force − target) over the last fifth of the hold, N.
    pub steady_state_error_n: f64,
    /// Root mean square error over the whole hold, N.
    pub rms_error_n: f64,
    /// Samples used (non-finite ones are skipped).
    pub samples: usize,
}

impl HoldMetrics {
    /// Whether the hold started within `tolerance_n` of its target: a step smaller
    /// than δ, which has nothing to rise through.
    #[must_use]
    pub fn started_within(&self, tolerance_n: f64) -> bool {
        (self.target_n - self.start_n).abs() <= tolerance_n
    }
}

/// The numbers for samples `(t_s, force_n)` of one hold; `None` without finite samples.
#[must_use]
pub fn hold_metrics(
    samples: &[(f64, f64)],
    target_n: f64,
    tolerance_n: f64,
) -> Option<HoldMetrics> {
    let s: Vec<(f64, f64)> = samples
        .iter()
        .copied()
        .filter(|(t, f)| t.is_finite() && f.is_finite())
        .collect();
    let (t0, f0) = *s.first()?;
    let span = target_n - f0;
    let dir = if span >= 0.0 { 1.0 } else { -1.0 };
    let progress = |f: f64| {
        if span.abs() > 1e-12 {
            (f - f0) / span
        } else {
            1.0
        }
    };
    let t10 = s.iter().find(|(_, f)| progress(*f) >= 0.1).map(|(t, _)| *t);
    let t90 = s.iter().find(|(_, f)| progress(*f) >= 0.9).map(|(t, _)| *t);
    let rise_time_s = match (t10, t90) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let last_outside = s
        .iter()
        .rposition(|(_, f)| (f - target_n).abs() > tolerance_n);
    let settling_time_s = match last_outside {
        None => Some(0.0),
        Some(i) if i + 1 < s.len() => Some(s[i + 1].0 - t0),
        Some(_) => None,
    };
    let overshoot_n = s
        .iter()
        .map(|(_, f)| (f - target_n) * dir)
        .fold(0.0, f64::max);
    let tail = &s[s.len() - (s.len() / 5).max(1)..];
    let steady_state_error_n =
        tail.iter().map(|(_, f)| f - target_n).sum::<f64>() / tail.len() as f64;
    let rms_error_n =
        (s.iter().map(|(_, f)| (f - target_n).powi(2)).sum::<f64>() / s.len() as f64).sqrt();
    Some(HoldMetrics {
        target_n,
        start_n: f0,
        rise_time_s,
        settling_time_s,
        overshoot_n,
        steady_state_error_n,
        rms_error_n,
        samples: s.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_first_order_step_gives_the_textbook_numbers() {
        // f = 2·(1 − e^(−t/τ)), τ = 0.1 s, sampled at 1 kHz for 1 s.
        let tau = 0.1;
        let s: Vec<(f64, f64)> = (0..1000)
            .map(|i| {
                let t = f64::from(i) * 1e-3;
                (t, 2.0 * (1.0 - (-t / tau).exp()))
            })
            .collect();
        let m = hold_metrics(&s, 2.0, 0.04).expect("samples");
        // 10–90 % rise of a first-order system: τ·ln 9.
        let rise = m.rise_time_s.expect("rises");
        assert!((rise - tau * 9f64.ln()).abs() < 2e-3, "{rise}");
        // Within 2 % (0.04 of 2 N) after τ·ln 50.
        let settle = m.settling_time_s.expect("settles");
        assert!((settle - tau * 50f64.ln()).abs() < 2e-3, "{settle}");
        assert!(m.overshoot_n.abs() < 1e-12);
        assert!(m.steady_state_error_n.abs() < 1e-3);
        assert!(m.rms_error_n > 0.1 && m.rms_error_n < 1.0);
    }

    #[test]
    fn overshoot_and_never_settling_are_reported() {
        let s = [(0.0, 0.0), (0.1, 2.5), (0.2, 1.8), (0.3, 2.4)];
        let m = hold_metrics(&s, 2.0, 0.1).expect("samples");
        assert!((m.overshoot_n - 0.5).abs() < 1e-12);
        assert_eq!(m.settling_time_s, None);
        // Stepping down: overshoot is below the target.
        let s = [(0.0, 3.0), (0.1, 1.2), (0.2, 1.6)];
        let m = hold_metrics(&s, 1.6, 0.1).expect("samples");
        assert!((m.overshoot_n - 0.4).abs() < 1e-12);
        assert_eq!(m.settling_time_s, Some(0.2));
        assert!(hold_metrics(&[(0.0, f64::NAN)], 1.0, 0.1).is_none());
    }

    #[test]
    fn a_step_smaller_than_delta_is_told_from_a_rise_never_made() {
        // Starts 0.05 N under a 0.4 N target with δ = 0.1 and wanders inside the band
        // without ever reaching 90 % of the step: no rise, and none was needed.
        let s = [(0.0, 0.35), (0.1, 0.37), (0.2, 0.36), (0.3, 0.38)];
        let m = hold_metrics(&s, 0.4, 0.1).expect("samples");
        assert_eq!(m.rise_time_s, None);
        assert!(m.started_within(0.1));
        assert_eq!(m.settling_time_s, Some(0.0));
        // A real step that stalls half way: no rise, and it was needed.
        let s = [(0.0, 0.0), (0.1, 0.5), (0.2, 1.0), (0.3, 1.0)];
        let m = hold_metrics(&s, 2.0, 0.1).expect("samples");
        assert_eq!(m.rise_time_s, None);
        assert!(!m.started_within(0.1));
    }
}
