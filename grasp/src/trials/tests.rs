#![allow(clippy::float_cmp)] // exact values are the point of some checks

use super::*;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn wilson_intervals_match_known_values() {
    assert_eq!(wilson_interval(0, 0, Z_95).ok(), Some([0.0, 1.0]));
    // All failures: [0, z²/(n+z²)]; all successes: its mirror.
    let [lo, hi] = wilson_interval(0, 10, Z_95).unwrap_or_default();
    assert_eq!(lo, 0.0);
    assert!(close(hi, 0.2775, 1e-4), "{hi}");
    let [lo, hi] = wilson_interval(10, 10, Z_95).unwrap_or_default();
    assert!(close(lo, 0.7225, 1e-4), "{lo}");
    assert_eq!(hi, 1.0);
    // Newcombe (1998), Statistics in Medicine 17:857, Table I, method 3.
    for (k, n, lo_want, hi_want) in [
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ] {
        let [lo, hi] = wilson_interval(k, n, Z_95).unwrap_or_default();
        assert!(
            close(lo, lo_want, 1e-4) && close(hi, hi_want, 1e-4),
            "{k}/{n}: {lo} {hi}"
        );
    }
    assert!(wilson_interval(11, 10, Z_95).is_err());
    assert!(wilson_interval(1, 10, f64::NAN).is_err());
    assert!(wilson_interval(1, 10, 0.0).is_err());
    // Huge counts stay finite and inside [0, 1].
    let [lo, hi] = wilson_interval(u64::MAX / 2, u64::MAX, Z_95).unwrap_or_default();
    assert!(lo.is_finite() && hi.is_finite() && lo <= 0.5 && hi >= 0.5);
}

#[test]
fn perturbations_are_a_function_of_seed_object_and_trial() {
    let a = perturbation_m(7, "cake", 3, 0.005);
    assert_eq!(a, perturbation_m(7, "cake", 3, 0.005));
    assert_ne!(a, perturbation_m(7, "cake", 4, 0.005));
    assert_ne!(a, perturbation_m(7, "ball", 3, 0.005));
    assert_ne!(a, perturbation_m(8, "cake", 3, 0.005));
    // σ scales the same draws; σ = 0 (or garbage) is no perturbation.
    let b = perturbation_m(7, "cake", 3, 0.010);
    for i in 0..3 {
        assert!(close(b[i], 2.0 * a[i], 1e-15));
    }
    assert_eq!(perturbation_m(7, "cake", 3, 0.0), [0.0; 3]);
    assert_eq!(perturbation_m(7, "cake", 3, f64::NAN), [0.0; 3]);
    // Over many trials each axis has about the asked σ.
    let n = 4000;
    let sd: Vec<f64> = (0..3)
        .map(|axis| {
            let v: Vec<f64> = (0..n)
                .map(|t| perturbation_m(1, "x", t, 0.005)[axis])
                .collect();
            (v.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt()
        })
        .collect();
    assert!(sd.iter().all(|s| close(*s, 0.005, 0.0003)), "{sd:?}");
}

#[test]
fn names_parse_back_and_bad_ones_say_what_is_expected() {
    for m in [Mode::Open, Mode::Closed] {
        assert_eq!(Mode::parse(m.as_str()), Ok(m));
    }
    for r in FailReason::ALL {
        assert_eq!(FailReason::parse(r.as_str()), Ok(r));
    }
    assert!(Mode::parse("half").is_err_and(|e| e.contains("open or closed")));
    assert!(FailReason::parse("").is_err_and(|e| e.contains("slip")));
}

#[test]
fn lift_durations_are_trapezoids_or_triangles() {
    let long = LiftPlan {
        height_m: 0.05,
        speed_m_s: 0.1,
        accel_m_s2: 1.0,
    };
    assert!(close(long.duration_s(), 0.6, 1e-12));
    let short = LiftPlan {
        height_m: 0.001,
        speed_m_s: 1.0,
        accel_m_s2: 1.0,
    };
    assert!(close(short.duration_s(), 2.0 * 0.001_f64.sqrt(), 1e-12));
    assert!(
        LiftPlan {
            height_m: 0.0,
            ..long
        }
        .validate()
        .is_err()
    );
    assert!(
        LiftPlan {
            accel_m_s2: f64::INFINITY,
            ..long
        }
        .validate()
        .is_err()
    );
}

#[test]
fn mcnemar_exact_p_matches_the_binomial_tail_on_hard_cases() {
    // No discordant pair: nothing to say.
    assert_eq!(mcnemar_exact_p(0, 0), 1.0);
    // All discordant pairs one way: 2 · 2^-n.
    assert!(close(mcnemar_exact_p(0, 10), 2.0 / 1024.0, 1e-15));
    assert!(close(mcnemar_exact_p(10, 0), 2.0 / 1024.0, 1e-15));
    // 1 against 9: 2 · (1 + 10) / 1024.
    assert!(close(mcnemar_exact_p(1, 9), 22.0 / 1024.0, 1e-15));
    // An even split, and one short of it, give 1 (capped).
    assert_eq!(mcnemar_exact_p(5, 5), 1.0);
    assert!(close(mcnemar_exact_p(4, 5), 1.0, 1e-12));
    // R's binom.test(3, 15)$p.value = 0.03515625.
    assert!(close(mcnemar_exact_p(3, 12), 0.035_156_25, 1e-12));
    // Large counts stay finite, in [0, 1], and symmetric (2^-3000 underflows a
    // direct sum).
    for (b, c) in [(0, 3000), (1400, 1600), (100_000, 100_000)] {
        let p = mcnemar_exact_p(b, c);
        assert!((0.0..=1.0).contains(&p), "{b} {c}: {p}");
        assert_eq!(p, mcnemar_exact_p(c, b));
    }
    assert_eq!(mcnemar_exact_p(0, 3000), 0.0);
    assert!(mcnemar_exact_p(1400, 1600) < 0.001);
}
