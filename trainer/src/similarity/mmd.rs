//! Maximum mean discrepancy with a permutation test: are two sets of embeddings drawn from one distribution?

use super::*;

/// The outcome of [`mmd_permutation_test`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MmdResult {
    /// The unbiased MMD² estimate between the (subsampled) sets; it can be slightly
    /// negative when the distributions match.
    pub mmd2: f64,
    /// `(1 + #{permutation statistics ≥ mmd2}) / (1 + permutations)`, in `(0, 1]`.
    pub p_value: f64,
    /// The Gaussian kernel's bandwidth σ (median pairwise distance of the pooled
    /// sample); the kernel is `exp(−‖a − b‖² / (2σ²))`.
    pub bandwidth: f64,
    /// The per-side cap as applied: `min(max(rows of land, rows of water),
    /// MMD_MAX_PER_SIDE)`. With equally sized sides this is the rows used from each.
    pub used_per_side: usize,
    /// Rows used from land: `min(rows of land, MMD_MAX_PER_SIDE)`.
    pub used_x: usize,
    /// Rows used from water: `min(rows of water, MMD_MAX_PER_SIDE)`.
    pub used_y: usize,
}

/// A two-sample test of whether `x` (land) and `y` (water) come from the same
/// distribution: the unbiased MMD² with a Gaussian RBF kernel, its bandwidth by the
/// median heuristic on the pooled sample, and a permutation p-value.
///
/// Rows are not paired and the sides may differ in size (not in columns). A side with
/// more than [`MMD_MAX_PER_SIDE`] rows is subsampled by a shuffle seeded with `seed`
/// ([`ChaCha8Rng`]); the pooled kernel matrix is computed once and each of the
/// `permutations` relabellings only re-reads it. The same inputs and seed give the
/// same result. With `permutations == 0` the p-value is 1.
///
/// # Errors
/// Ragged rows, non-finite values, column counts that differ, no columns, fewer than
/// [`MIN_SAMPLES`] rows on a side, or a median pairwise distance of zero.
pub fn mmd_permutation_test(
    x: &[Vec<f64>],
    y: &[Vec<f64>],
    permutations: usize,
    seed: u64,
) -> Result<MmdResult, SimilarityError> {
    let d = check_matrix(x, Side::Land)?;
    let e = check_matrix(y, Side::Water)?;
    check_min_samples(x.len(), Side::Land)?;
    check_min_samples(y.len(), Side::Water)?;
    if d != e {
        return Err(SimilarityError::ColumnMismatch { land: d, water: e });
    }
    if d == 0 {
        return Err(SimilarityError::NoColumns { side: Side::Land });
    }

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let xs = subsample(x, &mut rng);
    let ys = subsample(y, &mut rng);
    let (m, n) = (xs.len(), ys.len());
    let total = m + n;
    let mut pooled: Vec<f64> = xs
        .iter()
        .chain(&ys)
        .flat_map(|row| row.iter().copied())
        .collect();
    // The test is scale-invariant (the bandwidth scales with the data), so the pooled
    // sample is divided by its largest magnitude: no squared distance overflows or
    // underflows. The bandwidth is reported in the input's units.
    let scale = max_abs(&pooled);
    if scale <= 0.0 {
        return Err(SimilarityError::ZeroBandwidth);
    }
    for v in &mut pooled {
        *v /= scale;
    }

    // Squared distances first (into the kernel matrix), the bandwidth from their median,
    // then the kernel in place.
    let mut kernel = vec![0.0; total * total];
    let mut upper = Vec::with_capacity(total * (total - 1) / 2);
    for (i, a) in pooled.chunks_exact(d).enumerate() {
        for (j, b) in pooled.chunks_exact(d).enumerate().skip(i + 1) {
            let sq: f64 = a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum();
            kernel[i * total + j] = sq;
            kernel[j * total + i] = sq;
            upper.push(sq);
        }
    }
    let scaled_bandwidth = median_distance(&mut upper).ok_or(SimilarityError::ZeroBandwidth)?;
    let gamma = 1.0 / (2.0 * scaled_bandwidth * scaled_bandwidth);
    if !(scaled_bandwidth > 0.0 && gamma.is_finite()) {
        return Err(SimilarityError::ZeroBandwidth);
    }
    let bandwidth = scaled_bandwidth * scale;
    if !bandwidth.is_finite() {
        return Err(SimilarityError::Overflow {
            what: "the bandwidth",
        });
    }
    for (i, row) in kernel.chunks_exact_mut(total).enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            // exp(0) is exactly 1 on the diagonal, which `permuted_mmd2` relies on.
            *v = if i == j { 1.0 } else { (-*v * gamma).exp() };
        }
    }
    let row_sums: Vec<f64> = kernel.chunks_exact(total).map(|r| r.iter().sum()).collect();

    // 1.0 marks a land row, 0.0 a water row.
    let mut mask: Vec<f64> = std::iter::repeat_n(1.0, m)
        .chain(std::iter::repeat_n(0.0, n))
        .collect();
    let mmd2 = permuted_mmd2(&kernel, &row_sums, &mask, m, n);
    if !mmd2.is_finite() {
        return Err(SimilarityError::Overflow { what: "MMD²" });
    }
    let mut at_least = 0usize;
    for _ in 0..permutations {
        mask.shuffle(&mut rng);
        if permuted_mmd2(&kernel, &row_sums, &mask, m, n) >= mmd2 {
            at_least += 1;
        }
    }
    let p_value = (1 + at_least) as f64 / (1 + permutations) as f64;
    Ok(MmdResult {
        mmd2,
        p_value,
        bandwidth,
        used_per_side: m.max(n),
        used_x: m,
        used_y: n,
    })
}

/// All rows when there are at most [`MMD_MAX_PER_SIDE`], otherwise that many chosen by
/// a shuffle drawn from `rng`.
pub(super) fn subsample<'a>(rows: &'a [Vec<f64>], rng: &mut ChaCha8Rng) -> Vec<&'a Vec<f64>> {
    if rows.len() <= MMD_MAX_PER_SIDE {
        return rows.iter().collect();
    }
    let mut picked: Vec<&Vec<f64>> = rows.iter().collect();
    picked.shuffle(rng);
    picked.truncate(MMD_MAX_PER_SIDE);
    picked
}

/// The median of the distances whose squares are `squared` (reordered in place);
/// `None` for no pairs.
pub(super) fn median_distance(squared: &mut [f64]) -> Option<f64> {
    let len = squared.len();
    if len == 0 {
        return None;
    }
    let mid = len / 2;
    let (below, &mut upper_mid, _) = squared.select_nth_unstable_by(mid, f64::total_cmp);
    let upper_mid = upper_mid.sqrt();
    if len % 2 == 1 {
        return Some(upper_mid);
    }
    // The largest value below the upper middle is the lower middle.
    let lower_mid = below
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
        .sqrt();
    Some(0.5 * lower_mid + 0.5 * upper_mid)
}

/// The unbiased MMD² for the labelling `mask` (1.0 = land, 0.0 = water) of the pooled
/// kernel matrix `kernel` (whose diagonal is exactly 1), with `m` land and `n` water
/// rows. One pass of matrix–vector products: for each row, its kernel sum over land.
pub(super) fn permuted_mmd2(
    kernel: &[f64],
    row_sums: &[f64],
    mask: &[f64],
    m: usize,
    n: usize,
) -> f64 {
    let (mut land_land, mut land_water, mut water_water) = (0.0, 0.0, 0.0);
    for ((row, &label), &row_sum) in kernel.chunks_exact(mask.len()).zip(mask).zip(row_sums) {
        let to_land = dot(row, mask);
        if label > 0.5 {
            land_land += to_land;
        } else {
            land_water += to_land;
            water_water += row_sum - to_land;
        }
    }
    // Drop the diagonal (k(a, a) = 1) from the within-side sums.
    let (mf, nf) = (m as f64, n as f64);
    let within_land = (land_land - mf) / (mf * (mf - 1.0));
    let within_water = (water_water - nf) / (nf * (nf - 1.0));
    within_land + within_water - 2.0 * land_water / (mf * nf)
}
