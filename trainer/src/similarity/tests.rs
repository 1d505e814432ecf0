use super::*;
use rand_distr::{Distribution as _, StandardNormal};

fn normal(n: usize, d: usize, shift: f64, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            (0..d)
                .map(|_| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    z + shift
                })
                .collect()
        })
        .collect()
}

/// A random orthogonal d × d matrix: the identity through many Givens rotations by
/// random angles.
fn rotation(d: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q: Vec<Vec<f64>> = (0..d)
        .map(|i| (0..d).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for _ in 0..4 {
        for i in 0..d {
            for j in (i + 1)..d {
                let angle: f64 = StandardNormal.sample(&mut rng);
                let (s, c) = angle.sin_cos();
                for row in &mut q {
                    let (a, b) = (row[i], row[j]);
                    row[i] = c * a - s * b;
                    row[j] = s * a + c * b;
                }
            }
        }
    }
    q
}

fn matmul(x: &[Vec<f64>], q: &[Vec<f64>]) -> Vec<Vec<f64>> {
    x.iter()
        .map(|row| {
            (0..q[0].len())
                .map(|j| row.iter().zip(q).map(|(a, qr)| a * qr[j]).sum())
                .collect()
        })
        .collect()
}

#[test]
fn cka_of_a_set_with_itself_is_one() {
    let x = normal(200, 8, 0.0, 1);
    let cka = linear_cka(&x, &x).expect("a result");
    assert!((cka - 1.0).abs() < 1e-12, "{cka}");
}

#[test]
fn cka_is_invariant_to_rotation() {
    let x = normal(300, 8, 0.5, 2);
    let q = rotation(8, 3);
    // The rotation really is orthogonal and not the identity.
    for i in 0..8 {
        for j in 0..8 {
            let dot: f64 = (0..8).map(|k| q[k][i] * q[k][j]).sum();
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-12);
        }
    }
    assert!((0..8).any(|i| (q[i][i] - 1.0).abs() > 0.1));
    let rotated = matmul(&x, &q);
    let cka = linear_cka(&x, &rotated).expect("a result");
    assert!((cka - 1.0).abs() < 1e-12, "{cka}");
}

#[test]
fn cka_is_invariant_to_scaling() {
    let x = normal(300, 8, 0.0, 4);
    let scaled: Vec<Vec<f64>> = x
        .iter()
        .map(|r| r.iter().map(|v| 3.7 * v).collect())
        .collect();
    let cka = linear_cka(&x, &scaled).expect("a result");
    assert!((cka - 1.0).abs() < 1e-12, "{cka}");
}

#[test]
fn cka_of_independent_noise_is_small() {
    let x = normal(500, 8, 0.0, 5);
    let y = normal(500, 8, 0.0, 6);
    let cka = linear_cka(&x, &y).expect("a result");
    assert!((0.0..0.2).contains(&cka), "{cka}");
    // A partial relation lands in between.
    let mixed: Vec<Vec<f64>> = x
        .iter()
        .zip(&y)
        .map(|(a, b)| a.iter().zip(b).map(|(p, q)| p + q).collect())
        .collect();
    let partial = linear_cka(&x, &mixed).expect("a result");
    assert!(partial > 0.3 && partial < 0.9, "{partial}");
}

#[test]
fn cka_allows_different_widths() {
    let x = normal(100, 8, 0.0, 7);
    let y: Vec<Vec<f64>> = x.iter().map(|r| r[..3].to_vec()).collect();
    let cka = linear_cka(&x, &y).expect("a result");
    assert!(cka > 0.0 && cka < 1.0, "{cka}");
}

#[test]
fn cka_rejects_constant_latents() {
    let x = normal(10, 4, 0.0, 8);
    let constant = vec![vec![0.1, -2.5, 7.0, 0.0]; 10];
    assert_eq!(
        linear_cka(&constant, &x),
        Err(SimilarityError::ConstantLatents { side: Side::Land })
    );
    assert_eq!(
        linear_cka(&x, &constant),
        Err(SimilarityError::ConstantLatents { side: Side::Water })
    );
    // One varying column is enough.
    let mut one = constant.clone();
    one[3][1] = 1.0;
    assert!(linear_cka(&one, &x).is_ok());
}

#[test]
fn too_few_samples_are_rejected() {
    let x = normal(2, 4, 0.0, 9);
    let big = normal(50, 4, 0.0, 10);
    let err = linear_cka(&x, &x).expect_err("an error");
    assert_eq!(
        err,
        SimilarityError::TooFewSamples {
            side: Side::Land,
            found: 2
        }
    );
    assert_eq!(
        err.to_string(),
        "fewer than 3 samples in land: found 2 (CKA and MMD need at least 3)"
    );
    assert_eq!(
        mmd_permutation_test(&big, &x, 10, 0),
        Err(SimilarityError::TooFewSamples {
            side: Side::Water,
            found: 2
        })
    );
    assert_eq!(
        mmd_permutation_test(&[], &big, 10, 0),
        Err(SimilarityError::TooFewSamples {
            side: Side::Land,
            found: 0
        })
    );
}

#[test]
fn mismatched_pairs_are_rejected() {
    let x = normal(10, 4, 0.0, 11);
    let y = normal(9, 4, 0.0, 12);
    let err = linear_cka(&x, &y).expect_err("an error");
    assert_eq!(
        err.to_string(),
        "mismatched pairs: land has 10 rows, water has 9"
    );
    assert_eq!(
        cosine_similarities(&x, &y),
        Err(SimilarityError::MismatchedPairs { land: 10, water: 9 })
    );
    // MMD does not pair rows.
    assert!(mmd_permutation_test(&x, &y, 10, 0).is_ok());
}

#[test]
fn column_mismatch_is_rejected() {
    let x = normal(10, 32, 0.0, 13);
    let y = normal(10, 16, 0.0, 14);
    let want = SimilarityError::ColumnMismatch {
        land: 32,
        water: 16,
    };
    assert_eq!(mmd_permutation_test(&x, &y, 10, 0), Err(want.clone()));
    assert_eq!(cosine_similarities(&x, &y), Err(want.clone()));
    assert_eq!(
        want.to_string(),
        "column counts differ: land has 32, water has 16"
    );
}

#[test]
fn ragged_and_empty_rows_are_rejected() {
    let mut x = normal(10, 4, 0.0, 15);
    x[5].pop();
    assert_eq!(
        linear_cka(&x, &x),
        Err(SimilarityError::RaggedRow {
            side: Side::Land,
            row: 5,
            found: 3,
            expected: 4
        })
    );
    let empty = vec![Vec::new(); 5];
    assert_eq!(
        linear_cka(&empty, &empty),
        Err(SimilarityError::NoColumns { side: Side::Land })
    );
    assert_eq!(
        mmd_permutation_test(&empty, &empty, 10, 0),
        Err(SimilarityError::NoColumns { side: Side::Land })
    );
}

#[test]
fn non_finite_input_is_rejected() {
    let x = normal(10, 8, 0.0, 16);
    let mut bad = x.clone();
    bad[4][7] = f64::NAN;
    let want = SimilarityError::NonFinite {
        side: Side::Water,
        row: 4,
        column: 7,
    };
    assert_eq!(linear_cka(&x, &bad), Err(want.clone()));
    assert_eq!(mmd_permutation_test(&x, &bad, 10, 0), Err(want.clone()));
    assert_eq!(cosine_similarities(&x, &bad), Err(want.clone()));
    assert_eq!(
        want.to_string(),
        "non-finite value in water at row 4, column 7"
    );
    bad[4][7] = f64::INFINITY;
    assert_eq!(linear_cka(&x, &bad), Err(want));
    assert_eq!(
        Distribution::of(&[0.5, f64::NAN]),
        Err(SimilarityError::NonFiniteValue { index: 1 })
    );
}

#[test]
fn huge_and_tiny_values_stay_finite() {
    let x = normal(50, 4, 0.0, 17);
    let huge: Vec<Vec<f64>> = x
        .iter()
        .map(|r| r.iter().map(|v| v * 1e300).collect())
        .collect();
    let tiny: Vec<Vec<f64>> = x
        .iter()
        .map(|r| r.iter().map(|v| v * 1e-300).collect())
        .collect();
    let cka = linear_cka(&huge, &tiny).expect("a result");
    assert!((cka - 1.0).abs() < 1e-12, "{cka}");
    for c in cosine_similarities(&huge, &tiny).expect("a result") {
        assert!((c - 1.0).abs() < 1e-12, "{c}");
    }
    // MMD is as scale-invariant as its median-heuristic bandwidth.
    let plain = mmd_permutation_test(&x, &x, 10, 0).expect("a result");
    for (set, factor) in [(&huge, 1e300), (&tiny, 1e-300)] {
        let r = mmd_permutation_test(set, set, 10, 0).expect("a result");
        assert!((r.mmd2 - plain.mmd2).abs() < 1e-9, "{r:?} {plain:?}");
        assert!((r.bandwidth / factor / plain.bandwidth - 1.0).abs() < 1e-9);
    }
}

#[test]
fn mmd_of_the_same_distribution_is_not_significant() {
    let x = normal(200, 4, 0.0, 20);
    let y = normal(200, 4, 0.0, 21);
    let r = mmd_permutation_test(&x, &y, 200, 7).expect("a result");
    assert!(r.p_value > 0.05, "{r:?}");
    assert!(r.mmd2.abs() < 0.02, "{r:?}");
    assert!(r.bandwidth > 0.0);
    assert_eq!((r.used_per_side, r.used_x, r.used_y), (200, 200, 200));
}

#[test]
fn mmd_detects_a_shift() {
    let x = normal(200, 4, 0.0, 22);
    let y = normal(200, 4, 1.0, 23);
    let r = mmd_permutation_test(&x, &y, 200, 7).expect("a result");
    assert!(r.p_value < 0.01, "{r:?}");
    assert!(r.mmd2 > 0.0, "{r:?}");
    // The smallest p-value 200 permutations can give.
    assert!((r.p_value - 1.0 / 201.0).abs() < 1e-15, "{r:?}");
}

#[test]
fn mmd_is_reproducible_and_subsamples() {
    let x = normal(1100, 3, 0.0, 24);
    let y = normal(40, 3, 0.3, 25);
    let a = mmd_permutation_test(&x, &y, 50, 99).expect("a result");
    let b = mmd_permutation_test(&x, &y, 50, 99).expect("a result");
    assert_eq!(a, b);
    assert_eq!(
        (a.used_per_side, a.used_x, a.used_y),
        (MMD_MAX_PER_SIDE, MMD_MAX_PER_SIDE, 40)
    );
    let zero = mmd_permutation_test(&x, &y, 0, 99).expect("a result");
    assert!((zero.p_value - 1.0).abs() < f64::EPSILON);
}

#[test]
fn mmd_matches_a_direct_computation() {
    let x = normal(7, 3, 0.0, 28);
    let y = normal(5, 3, 0.5, 29);
    let r = mmd_permutation_test(&x, &y, 20, 3).expect("a result");
    // The bandwidth is the median of the 66 pooled pairwise distances.
    let pooled: Vec<&Vec<f64>> = x.iter().chain(&y).collect();
    let dist = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q) * (p - q))
            .sum::<f64>()
            .sqrt()
    };
    let mut all = Vec::new();
    for i in 0..pooled.len() {
        for j in (i + 1)..pooled.len() {
            all.push(dist(pooled[i], pooled[j]));
        }
    }
    all.sort_by(f64::total_cmp);
    let median = 0.5 * (all[32] + all[33]);
    assert!((r.bandwidth - median).abs() < 1e-12, "{r:?} {median}");
    let k = |a: &[f64], b: &[f64]| (-dist(a, b).powi(2) / (2.0 * median * median)).exp();
    let mean_within = |s: &[Vec<f64>]| {
        let mut sum = 0.0;
        for (i, a) in s.iter().enumerate() {
            for (j, b) in s.iter().enumerate() {
                if i != j {
                    sum += k(a, b);
                }
            }
        }
        sum / (s.len() * (s.len() - 1)) as f64
    };
    let cross: f64 = x
        .iter()
        .flat_map(|a| y.iter().map(|b| k(a, b)))
        .sum::<f64>()
        / 35.0;
    let want = mean_within(&x) + mean_within(&y) - 2.0 * cross;
    assert!((r.mmd2 - want).abs() < 1e-12, "{} vs {want}", r.mmd2);
}

#[test]
fn mmd_rejects_identical_samples() {
    let same = vec![vec![1.0, 2.0]; 10];
    assert_eq!(
        mmd_permutation_test(&same, &same, 10, 0),
        Err(SimilarityError::ZeroBandwidth)
    );
}

#[test]
fn cosine_of_a_row_with_itself_and_its_negative() {
    let x = normal(20, 6, 0.3, 26);
    let neg: Vec<Vec<f64>> = x.iter().map(|r| r.iter().map(|v| -v).collect()).collect();
    for c in cosine_similarities(&x, &x).expect("a result") {
        assert!((c - 1.0).abs() < 1e-12, "{c}");
    }
    for c in cosine_similarities(&x, &neg).expect("a result") {
        assert!((c + 1.0).abs() < 1e-12, "{c}");
    }
    let orthogonal = cosine_similarities(&[vec![1.0, 0.0]], &[vec![0.0, 2.0]]).expect("a result");
    assert_eq!(orthogonal.len(), 1);
    assert!(orthogonal[0].abs() < 1e-15);
}

#[test]
fn cosine_rejects_zero_length_rows() {
    let x = normal(6, 3, 0.0, 27);
    let mut y = x.clone();
    y[3] = vec![0.0; 3];
    let err = cosine_similarities(&x, &y).expect_err("an error");
    assert_eq!(
        err,
        SimilarityError::ZeroLength {
            side: Side::Water,
            row: 3
        }
    );
    assert!(err.to_string().starts_with("zero-length latent at row 3"));
}

#[test]
fn distribution_summarises() {
    let d = Distribution::of(&[4.0, 1.0, 3.0, 2.0, 5.0]).expect("a result");
    assert_eq!(d.n, 5);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    assert!(close(d.mean, 3.0));
    assert!(close(d.std, 2.5f64.sqrt()));
    assert!(close(d.min, 1.0) && close(d.max, 5.0));
    assert!(close(d.p25, 2.0) && close(d.median, 3.0) && close(d.p75, 4.0));
    let even = Distribution::of(&[1.0, 2.0, 3.0, 4.0]).expect("a result");
    assert!(close(even.median, 2.5) && close(even.p25, 1.75));
    let one = Distribution::of(&[0.7]).expect("a result");
    assert!(close(one.std, 0.0) && close(one.p75, 0.7));
    assert!(d.to_string().contains("median=3.0000"));
}

#[test]
fn empty_distribution_is_an_error() {
    assert_eq!(
        Distribution::of(&[]),
        Err(SimilarityError::EmptyDistribution)
    );
}

/// Times both functions on 6000 × 32 inputs:
/// `cargo test --workspace --release --lib similarity -- --ignored --nocapture`.
#[test]
#[ignore = "timing, not a check"]
fn timing_6000_by_32() {
    let x = normal(6000, 32, 0.0, 30);
    let y = normal(6000, 32, 0.1, 31);
    let t = std::time::Instant::now();
    let cka = linear_cka(&x, &y).expect("a result");
    println!("linear_cka 6000x32: {:?} (cka {cka:.4})", t.elapsed());
    for perms in [0, 200, 1000] {
        let t = std::time::Instant::now();
        let r = mmd_permutation_test(&x, &y, perms, 1).expect("a result");
        println!(
            "mmd_permutation_test 6000x32, {perms} permutations: {:?} ({r:?})",
            t.elapsed()
        );
    }
}
#[test]
fn cross_correlation_of_a_set_with_itself_has_a_unit_diagonal() {
    let x: Vec<Vec<f64>> = (0..20)
        .map(|i| {
            let t = f64::from(i);
            vec![t, -2.0 * t + 1.0, (t * 0.7).sin(), 5.0]
        })
        .collect();
    let r = cross_correlation(&x, &x).expect("correlation");
    for (i, row) in r.iter().enumerate().take(3) {
        let v = row[i].expect("varies");
        assert!((v - 1.0).abs() < 1e-12, "{v}");
    }
    let anti = r[0][1].expect("varies");
    assert!((anti + 1.0).abs() < 1e-12, "{anti}");
    assert!(
        r[3].iter().all(Option::is_none),
        "a constant column has no r"
    );
    assert!(r.iter().all(|row| row[3].is_none()));
}

#[test]
fn cross_correlation_holds_at_extreme_magnitudes() {
    // 9 × MAX/16 is still finite.
    for scale in [f64::MAX / 16.0, 1e-300, f64::MIN_POSITIVE] {
        let x: Vec<Vec<f64>> = (0..10).map(|i| vec![f64::from(i) * scale]).collect();
        let y: Vec<Vec<f64>> = (0..10).map(|i| vec![f64::from(i * i)]).collect();
        let r = cross_correlation(&x, &y).expect("correlation")[0][0].expect("varies");
        assert!(r.is_finite() && r > 0.9 && r <= 1.0, "{scale}: {r}");
    }
    // A column constant up to rounding is not a spread.
    let x: Vec<Vec<f64>> = (0..10).map(|_| vec![0.1 + 0.2]).collect();
    let y: Vec<Vec<f64>> = (0..10).map(|i| vec![f64::from(i)]).collect();
    assert_eq!(cross_correlation(&x, &y).expect("ok")[0][0], None);
}

#[test]
fn cross_correlation_refuses_what_it_cannot_compute() {
    let two = vec![vec![1.0], vec![2.0]];
    assert!(matches!(
        cross_correlation(&two, &two),
        Err(SimilarityError::TooFewSamples { found: 2, .. })
    ));
    let x = vec![vec![1.0], vec![2.0], vec![3.0]];
    let y = vec![vec![1.0], vec![2.0]];
    assert!(matches!(
        cross_correlation(&x, &y),
        Err(SimilarityError::MismatchedPairs { .. })
    ));
    let empty = vec![Vec::new(); 3];
    assert!(matches!(
        cross_correlation(&empty, &x),
        Err(SimilarityError::NoColumns { side: Side::Land })
    ));
    let nan = vec![vec![1.0], vec![f64::NAN], vec![3.0]];
    assert!(matches!(
        cross_correlation(&x, &nan),
        Err(SimilarityError::NonFinite {
            side: Side::Water,
            row: 1,
            ..
        })
    ));
    assert!(cross_correlation(&[], &[]).is_err());
}
