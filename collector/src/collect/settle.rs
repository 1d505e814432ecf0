//! The settle ended by the signal (`procedure.settle_end = "signal"`): after the arm
//! reaches a pose the silicone relaxes (the wrench decays toward its equilibrium), and
//! a label recorded too early carries the excess. The signal has settled when the mean
//! of the last `ft_window_s` of readings differs from the mean of the window before it
//! by at most [`SETTLED_DRIFT_OF_NOISE`] of the sensor's noise, on every axis.
//!
//! The noise is read from the same readings, from the differences of consecutive ones
//! (σ = RMS(r[i+1] − r[i]) / √2): white noise survives differencing, a slow decay
//! hardly does (at 1 kHz the silicone's decay moves a reading by 1/60 of its excess).
//! So the noise is the sensor's as it is at this pose, no time is spent measuring it
//! elsewhere, and a resumed run settles exactly as the uninterrupted one (a noise taken
//! at a tare would be the resumed run's own tare's).
//!
//! Why half the noise: for an exponential decay of time constant τ, the difference of
//! two adjacent means W apart is the excess at the later window's middle times
//! (e^(W/τ) − 1); with the silicone's τ ≈ 0.06 s and W = 0.05 s the excess left at
//! the end of the later window is then about a quarter of the noise (0.25 σ), well
//! within the sensor's own noise, while two means of 50 readings differ by noise alone
//! with a spread of 0.2 σ (a settled signal passes at once). The cost: a press whose
//! excess starts large settles no sooner than a fixed wait would (the simulated 5 N
//! press: about 0.32 s), and `settle_s` bounds it.

use softtouch_schemas::{FtReading, TimestampNs};

use super::window::{WindowRules, window_stats};

/// Largest drift between two adjacent windows' means, as a share of the noise's
/// standard deviation on the same axis, at which the signal counts as settled.
pub const SETTLED_DRIFT_OF_NOISE: f64 = 0.5;

/// Fewest readings a window needs to say anything about the noise or the drift.
pub const MIN_SETTLE_READINGS: usize = 4;

/// How often the settle looks at the signal, s.
pub const SETTLE_POLL_S: f64 = 0.005;

fn finite(r: &FtReading) -> bool {
    r.wrench_in_sensor.to_array().iter().all(|v| v.is_finite())
}

/// The mean of a window (`None`: too few readings, or a non-finite one).
fn mean(readings: &[FtReading]) -> Option<[f64; 6]> {
    if readings.len() < MIN_SETTLE_READINGS || !readings.iter().all(finite) {
        return None;
    }
    let rules = WindowRules {
        min_readings: 0,
        range: [f64::INFINITY; 6],
    };
    let mean = window_stats(readings, TimestampNs(0), &rules)
        .mean
        .to_array();
    mean.iter().all(|v| v.is_finite()).then_some(mean)
}

/// The sensor's white noise per axis (standard deviation, N and N·m) in `readings`,
/// from the differences of consecutive readings; `None` with too few readings or a
/// non-finite one.
#[must_use]
pub fn noise_of(readings: &[FtReading]) -> Option<[f64; 6]> {
    if readings.len() < MIN_SETTLE_READINGS || !readings.iter().all(finite) {
        return None;
    }
    let mut sum = [0.0; 6];
    for pair in readings.windows(2) {
        let (a, b) = (
            pair[0].wrench_in_sensor.to_array(),
            pair[1].wrench_in_sensor.to_array(),
        );
        for i in 0..6 {
            sum[i] += (b[i] - a[i]).powi(2);
        }
    }
    let n = (readings.len() - 1) as f64;
    let sigma = sum.map(|s| (s / n / 2.0).sqrt());
    sigma.iter().all(|v| v.is_finite()).then_some(sigma)
}

/// Whether the signal has settled: the means of `earlier` and `later` (adjacent
/// windows, oldest first) differ by at most [`SETTLED_DRIFT_OF_NOISE`] × the noise of
/// both ([`noise_of`]) on every axis. Too few readings, or a non-finite one, is not
/// settled; a noiseless signal settles only when it stops moving.
#[must_use]
pub fn settled(earlier: &[FtReading], later: &[FtReading]) -> bool {
    let both: Vec<FtReading> = earlier.iter().chain(later).copied().collect();
    let (Some(a), Some(b), Some(noise)) = (mean(earlier), mean(later), noise_of(&both)) else {
        return false;
    };
    a.iter()
        .zip(b)
        .zip(noise)
        .all(|((a, b), sigma)| (b - a).abs() <= SETTLED_DRIFT_OF_NOISE * sigma)
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_schemas::{FtStatus, Wrench};

    fn reading(i: u64, fz: f64) -> FtReading {
        FtReading {
            t: TimestampNs(i * 1_000_000),
            rdt_sequence: i as u32,
            ft_sequence: i as u32,
            status: FtStatus::OK,
            wrench_in_sensor: Wrench::from_array([0.0, 0.0, fz, 0.0, 0.0, 0.0]),
        }
    }

    /// White noise of standard deviation σ on a level (a fixed seed: the same draws
    /// every run).
    fn noisy(from: u64, n: u64, level: impl Fn(u64) -> f64, sigma: f64) -> Vec<FtReading> {
        use rand::SeedableRng as _;
        use rand_distr::Distribution as _;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(from);
        let normal = rand_distr::Normal::new(0.0, sigma.max(0.0)).expect("σ ≥ 0");
        (from..from + n)
            .map(|i| reading(i, level(i) + normal.sample(&mut rng)))
            .collect()
    }

    #[test]
    fn the_noise_is_read_from_consecutive_readings_and_a_slow_decay_hardly_enters() {
        let sigma = 0.0125;
        let still = noise_of(&noisy(0, 400, |_| 1.0, sigma)).expect("noise");
        assert!((still[2] / sigma - 1.0).abs() < 0.1, "{still:?}");
        assert!(still[0].abs() < 1e-15);
        // A press relaxing fast (τ = 60 ms from 0.6 N of excess) reads about the same.
        let decaying =
            noise_of(&noisy(0, 400, |i| 0.6 * (-(i as f64) / 60.0).exp(), sigma)).expect("noise");
        assert!((decaying[2] / sigma - 1.0).abs() < 0.15, "{decaying:?}");
        // Empty, too short and non-finite windows measure nothing.
        assert_eq!(noise_of(&[]), None);
        assert_eq!(noise_of(&noisy(0, 3, |_| 0.0, 0.01)), None);
        let mut bad = noisy(0, 50, |_| 0.0, 0.01);
        bad[7].wrench_in_sensor.force_n[1] = f64::NAN;
        assert_eq!(noise_of(&bad), None);
    }

    /// A relaxation e^(−t/τ) is settled once the drift between two windows is within
    /// half the noise, not long before; a still signal is settled at once.
    #[test]
    fn a_decaying_press_settles_once_its_drift_is_within_the_noise() {
        let sigma = 0.0125;
        let press = |i: u64| 5.0 * (1.0 + 0.12 * (-(i as f64) / 60.0).exp());
        let settled_at = (100..1000)
            .step_by(5)
            .find(|&end| {
                let all = noisy(0, end, press, sigma);
                let n = all.len();
                settled(&all[n - 100..n - 50], &all[n - 50..])
            })
            .expect("settles");
        // The excess left there is within the noise.
        let excess = press(settled_at) - 5.0;
        assert!(excess <= 0.6 * sigma, "{settled_at} ms: {excess}");
        assert!(
            settled_at >= 250,
            "not before the drift fell: {settled_at} ms"
        );
        let flat = noisy(0, 100, |_| 2.0, sigma);
        assert!(settled(&flat[..50], &flat[50..]));
        // No noise asks for no drift; too few readings or an infinite one never settle.
        let quiet = noisy(0, 100, |i| 2.0 + 1e-4 * i as f64, 0.0);
        assert!(!settled(&quiet[..50], &quiet[50..]));
        let still = noisy(0, 100, |_| 2.0, 0.0);
        assert!(settled(&still[..50], &still[50..]));
        assert!(!settled(&flat[..3], &flat[3..6]));
        assert!(!settled(&[], &flat));
        let mut bad = flat.clone();
        bad[0].wrench_in_sensor.torque_nm[2] = f64::INFINITY;
        assert!(!settled(&bad[..50], &bad[50..]));
    }
}
