//! Comparing two sets of latent means: the same finger deformations seen on land and
//! underwater (issue "Land to water").
//!
//! Inputs are row-major matrices given as `&[Vec<f64>]`, one row per sample (what
//! [`latent_means`](crate::latent_means) returns). The first argument of every function
//! is called *land* and the second *water* in error messages ([`Side`]).
//!
//! - [`linear_cka`]: linear centred kernel alignment (Kornblith et al. 2019) between
//!   paired sets, invariant to rotation and isotropic scaling of either set.
//! - [`mmd_permutation_test`]: unbiased MMD² with a Gaussian kernel and a permutation
//!   p-value: do the two sets come from the same distribution (pairing ignored)?
//! - [`cosine_similarities`]: the cosine of each paired row, summarised by
//!   [`Distribution::of`].
//!
//! Every function returns finite numbers or a [`SimilarityError`]; none panics.

use std::fmt;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// The fewest samples (rows) [`linear_cka`] and [`mmd_permutation_test`] accept.
pub const MIN_SAMPLES: usize = 3;

/// The most rows per side [`mmd_permutation_test`] uses; larger sets are subsampled
/// by a seeded shuffle. The pooled kernel matrix then holds at most 2000 × 2000 values
/// (32 MB).
pub const MMD_MAX_PER_SIDE: usize = 1000;

/// Which input a [`SimilarityError`] is about: the first argument (land) or the second
/// (water).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The first argument (`x`).
    Land,
    /// The second argument (`y`).
    Water,
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Land => "land",
            Self::Water => "water",
        })
    }
}

/// Why two latent sets could not be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SimilarityError {
    /// A set has fewer rows than [`MIN_SAMPLES`].
    #[error("fewer than 3 samples in {side}: found {found} (CKA and MMD need at least 3)")]
    TooFewSamples {
        /// The set that is too small.
        side: Side,
        /// Its number of rows.
        found: usize,
    },
    /// Paired comparisons need the same number of rows on both sides.
    #[error("mismatched pairs: land has {land} rows, water has {water}")]
    MismatchedPairs {
        /// Rows of the first set.
        land: usize,
        /// Rows of the second set.
        water: usize,
    },
    /// The comparison needs the same number of columns on both sides.
    #[error("column counts differ: land has {land}, water has {water}")]
    ColumnMismatch {
        /// Columns of the first set.
        land: usize,
        /// Columns of the second set.
        water: usize,
    },
    /// A row's length differs from the first row's.
    #[error("ragged rows: row {row} of {side} has {found} values, expected {expected} (as row 0)")]
    RaggedRow {
        /// The set with the ragged row.
        side: Side,
        /// The row's index.
        row: usize,
        /// The row's length.
        found: usize,
        /// The first row's length.
        expected: usize,
    },
    /// A set has rows but no columns.
    #[error("{side} has no columns: every latent is empty")]
    NoColumns {
        /// The set without columns.
        side: Side,
    },
    /// Every column of a set is constant, so its centred Gram matrix is zero.
    #[error("constant latents: every column of {side} has zero variance (CKA is undefined)")]
    ConstantLatents {
        /// The constant set.
        side: Side,
    },
    /// An input value is NaN or infinite.
    #[error("non-finite value in {side} at row {row}, column {column}")]
    NonFinite {
        /// The set holding the value.
        side: Side,
        /// The value's row.
        row: usize,
        /// The value's column.
        column: usize,
    },
    /// A row has zero length, so its cosine similarity is undefined.
    #[error("zero-length latent at row {row} of {side} (its cosine similarity is undefined)")]
    ZeroLength {
        /// The set holding the row.
        side: Side,
        /// The row's index.
        row: usize,
    },
    /// The median pairwise distance of the pooled sample is zero (at least half of the
    /// pairs are identical), so the median-heuristic bandwidth is undefined.
    #[error(
        "zero bandwidth: the median pairwise distance of the pooled land and water samples is 0 \
         (mostly identical rows), so the Gaussian kernel's bandwidth is undefined"
    )]
    ZeroBandwidth,
    /// [`Distribution::of`] was given no values.
    #[error("empty distribution: no values to summarise")]
    EmptyDistribution,
    /// [`Distribution::of`] was given a NaN or infinite value.
    #[error("non-finite value at index {index} (a distribution needs finite values)")]
    NonFiniteValue {
        /// The value's index.
        index: usize,
    },
    /// An intermediate result overflowed (inputs near `f64::MAX`).
    #[error("{what} is not finite: the input values are too large")]
    Overflow {
        /// The quantity that overflowed.
        what: &'static str,
    },
}

/// Linear CKA between `x` (n × d, land) and `y` (n × e, water), paired by row:
/// with every column centred, `‖YᵀX‖²_F / (‖XᵀX‖_F · ‖YᵀY‖_F)`, in `[0, 1]`.
///
/// 1 means the two sets are the same up to a rotation and an isotropic scaling; near 0
/// means unrelated. Costs O(n·(d² + e² + d·e)) through the d × e, d × d and e × e
/// cross-products (no n × n Gram matrices). `d` and `e` may differ.
///
/// # Errors
/// Ragged rows, non-finite values, row counts that differ, fewer than [`MIN_SAMPLES`]
/// rows, no columns, or a set whose every column is constant.
pub fn linear_cka(x: &[Vec<f64>], y: &[Vec<f64>]) -> Result<f64, SimilarityError> {
    let d = check_matrix(x, Side::Land)?;
    let e = check_matrix(y, Side::Water)?;
    let n = check_pairs(x, y)?;
    check_min_samples(n, Side::Land)?;
    let cx = centred_scaled(x, d, Side::Land)?;
    let cy = centred_scaled(y, e, Side::Water)?;

    let mut xtx = vec![0.0; d * d];
    let mut yty = vec![0.0; e * e];
    let mut xty = vec![0.0; d * e];
    for (xr, yr) in cx.chunks_exact(d).zip(cy.chunks_exact(e)) {
        accumulate_outer(&mut xtx, xr, xr);
        accumulate_outer(&mut yty, yr, yr);
        accumulate_outer(&mut xty, xr, yr);
    }
    let hsic: f64 = xty.iter().map(|v| v * v).sum();
    let norm_x = xtx.iter().map(|v| v * v).sum::<f64>().sqrt();
    let norm_y = yty.iter().map(|v| v * v).sum::<f64>().sqrt();
    // Both sets are non-constant and scaled to a largest magnitude of 1, so the norms
    // are positive and moderate; the guard keeps the promise of a finite result anyway.
    if norm_x <= 0.0 {
        return Err(SimilarityError::ConstantLatents { side: Side::Land });
    }
    if norm_y <= 0.0 {
        return Err(SimilarityError::ConstantLatents { side: Side::Water });
    }
    let cka = hsic / (norm_x * norm_y);
    if !cka.is_finite() {
        return Err(SimilarityError::Overflow { what: "CKA" });
    }
    // Cauchy–Schwarz bounds CKA to [0, 1]; clamp away rounding at the ends.
    Ok(cka.clamp(0.0, 1.0))
}

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

/// The cosine similarity of every paired row: `cos(x_i, y_i)`, in `[−1, 1]`.
///
/// # Errors
/// Ragged rows, non-finite values, row or column counts that differ, or a row of zero
/// length (named by its index).
pub fn cosine_similarities(x: &[Vec<f64>], y: &[Vec<f64>]) -> Result<Vec<f64>, SimilarityError> {
    let d = check_matrix(x, Side::Land)?;
    let e = check_matrix(y, Side::Water)?;
    check_pairs(x, y)?;
    if d != e {
        return Err(SimilarityError::ColumnMismatch { land: d, water: e });
    }
    x.iter()
        .zip(y)
        .enumerate()
        .map(|(row, (a, b))| {
            // Scaling each row by its largest magnitude keeps the norms from
            // overflowing or underflowing; the cosine does not change.
            let sa = max_abs(a);
            if sa <= 0.0 {
                return Err(SimilarityError::ZeroLength {
                    side: Side::Land,
                    row,
                });
            }
            let sb = max_abs(b);
            if sb <= 0.0 {
                return Err(SimilarityError::ZeroLength {
                    side: Side::Water,
                    row,
                });
            }
            let (mut dot, mut na, mut nb) = (0.0, 0.0, 0.0);
            for (p, q) in a.iter().zip(b) {
                let (p, q) = (p / sa, q / sb);
                dot += p * q;
                na += p * p;
                nb += q * q;
            }
            let cos = dot / (na.sqrt() * nb.sqrt());
            if cos.is_finite() {
                Ok(cos.clamp(-1.0, 1.0))
            } else {
                Err(SimilarityError::Overflow {
                    what: "a cosine similarity",
                })
            }
        })
        .collect()
}

/// A summary of a set of values (such as [`cosine_similarities`]) for printing.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Distribution {
    /// How many values.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// Their sample standard deviation (divisor `n − 1`; 0 for a single value).
    pub std: f64,
    /// The smallest value.
    pub min: f64,
    /// The 25th percentile (linear interpolation between order statistics).
    pub p25: f64,
    /// The median.
    pub median: f64,
    /// The 75th percentile.
    pub p75: f64,
    /// The largest value.
    pub max: f64,
}

impl Distribution {
    /// Summarises `values`.
    ///
    /// # Errors
    /// No values, a non-finite value, or a summary that overflows.
    pub fn of(values: &[f64]) -> Result<Self, SimilarityError> {
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(SimilarityError::NonFiniteValue { index });
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let (Some(&min), Some(&max)) = (sorted.first(), sorted.last()) else {
            return Err(SimilarityError::EmptyDistribution);
        };
        // Welford's update: no sum that overflows before the mean does.
        let (mut mean, mut m2) = (0.0f64, 0.0f64);
        for (k, &v) in sorted.iter().enumerate() {
            let delta = v - mean;
            mean += delta / (k + 1) as f64;
            m2 += delta * (v - mean);
        }
        let n = sorted.len();
        let std = if n > 1 {
            (m2 / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        let summary = Self {
            n,
            mean,
            std,
            min,
            p25: quantile(&sorted, 0.25),
            median: quantile(&sorted, 0.5),
            p75: quantile(&sorted, 0.75),
            max,
        };
        let fields = [
            summary.mean,
            summary.std,
            summary.p25,
            summary.median,
            summary.p75,
        ];
        if fields.iter().all(|v| v.is_finite()) {
            Ok(summary)
        } else {
            Err(SimilarityError::Overflow {
                what: "the distribution summary",
            })
        }
    }
}

impl fmt::Display for Distribution {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "n={} mean={:.4} std={:.4} min={:.4} p25={:.4} median={:.4} p75={:.4} max={:.4}",
            self.n, self.mean, self.std, self.min, self.p25, self.median, self.p75, self.max
        )
    }
}

/// Pearson correlation between every column of `x` and every column of `y` (rows
/// paired): `r[i][j]` correlates column `i` of `x` with column `j` of `y`. Pass the
/// same set twice for its correlation map. A column that is constant (or too small
/// to centre) has no correlation: `None` in every cell it touches.
///
/// Computed from columns centred and scaled to a largest magnitude of 1, so values
/// near `f64::MAX` or `f64::MIN_POSITIVE` give finite results; each `r` is clamped
/// to `[-1, 1]` against rounding.
///
/// # Errors
/// Ragged rows, non-finite values, row counts that differ, fewer than [`MIN_SAMPLES`]
/// rows, or no columns.
pub fn cross_correlation(
    x: &[Vec<f64>],
    y: &[Vec<f64>],
) -> Result<Vec<Vec<Option<f64>>>, SimilarityError> {
    let d = check_matrix(x, Side::Land)?;
    let e = check_matrix(y, Side::Water)?;
    let n = check_pairs(x, y)?;
    check_min_samples(n, Side::Land)?;
    if d == 0 {
        return Err(SimilarityError::NoColumns { side: Side::Land });
    }
    if e == 0 {
        return Err(SimilarityError::NoColumns { side: Side::Water });
    }
    let cx = standardised_columns(x, d);
    let cy = standardised_columns(y, e);
    Ok(cx
        .iter()
        .map(|a| {
            cy.iter()
                .map(|b| match (a, b) {
                    (Some(a), Some(b)) => {
                        let r = dot(a, b);
                        r.is_finite().then(|| r.clamp(-1.0, 1.0))
                    }
                    _ => None,
                })
                .collect()
        })
        .collect())
}

/// Each column centred and scaled to unit Euclidean norm (so that a dot product is a
/// correlation), or `None` for a column with no spread.
fn standardised_columns(rows: &[Vec<f64>], cols: usize) -> Vec<Option<Vec<f64>>> {
    let n = rows.len() as f64;
    (0..cols)
        .map(|c| {
            let column: Vec<f64> = rows.iter().map(|r| r[c]).collect();
            // Scale first: squares of values near f64::MAX would overflow.
            let scale = max_abs(&column);
            if !(scale > 0.0 && scale.is_finite()) {
                return None;
            }
            let scaled: Vec<f64> = column.iter().map(|v| v / scale).collect();
            let mean = scaled.iter().sum::<f64>() / n;
            let centred: Vec<f64> = scaled.iter().map(|v| v - mean).collect();
            let norm = centred.iter().map(|v| v * v).sum::<f64>().sqrt();
            // A spread at rounding level is no spread: its "correlation" would be noise.
            (norm > 1e-12 * n.sqrt()).then(|| centred.iter().map(|v| v / norm).collect())
        })
        .collect()
}

/// Checks that every row has the first row's length and every value is finite;
/// returns the column count (0 for an empty set).
fn check_matrix(rows: &[Vec<f64>], side: Side) -> Result<usize, SimilarityError> {
    let cols = rows.first().map_or(0, Vec::len);
    for (row, values) in rows.iter().enumerate() {
        if values.len() != cols {
            return Err(SimilarityError::RaggedRow {
                side,
                row,
                found: values.len(),
                expected: cols,
            });
        }
        if let Some(column) = values.iter().position(|v| !v.is_finite()) {
            return Err(SimilarityError::NonFinite { side, row, column });
        }
    }
    Ok(cols)
}

/// The shared row count of a paired comparison.
fn check_pairs(x: &[Vec<f64>], y: &[Vec<f64>]) -> Result<usize, SimilarityError> {
    if x.len() == y.len() {
        Ok(x.len())
    } else {
        Err(SimilarityError::MismatchedPairs {
            land: x.len(),
            water: y.len(),
        })
    }
}

fn check_min_samples(found: usize, side: Side) -> Result<(), SimilarityError> {
    if found < MIN_SAMPLES {
        Err(SimilarityError::TooFewSamples { side, found })
    } else {
        Ok(())
    }
}

/// The n × `cols` set flattened row-major with every column centred, exactly constant
/// columns set to exactly zero, and the whole divided by its largest magnitude (CKA is
/// scale-invariant; this keeps the cross-products far from overflow and underflow).
fn centred_scaled(rows: &[Vec<f64>], cols: usize, side: Side) -> Result<Vec<f64>, SimilarityError> {
    if cols == 0 {
        return Err(SimilarityError::NoColumns { side });
    }
    let n = rows.len() as f64;
    let mut means = vec![0.0; cols];
    let mut lo = vec![f64::INFINITY; cols];
    let mut hi = vec![f64::NEG_INFINITY; cols];
    for row in rows {
        for (((mean, l), h), &v) in means.iter_mut().zip(&mut lo).zip(&mut hi).zip(row) {
            // Dividing each term keeps the sum of large values from overflowing.
            *mean += v / n;
            *l = l.min(v);
            *h = h.max(v);
        }
    }
    let varies: Vec<bool> = lo.iter().zip(&hi).map(|(l, h)| h > l).collect();
    if !varies.iter().any(|&v| v) {
        return Err(SimilarityError::ConstantLatents { side });
    }
    let mut flat = Vec::with_capacity(rows.len() * cols);
    for row in rows {
        for ((&v, &mean), &var) in row.iter().zip(&means).zip(&varies) {
            flat.push(if var { v - mean } else { 0.0 });
        }
    }
    let scale = max_abs(&flat);
    if !scale.is_finite() {
        return Err(SimilarityError::Overflow {
            what: "a centred value",
        });
    }
    if scale <= 0.0 {
        return Err(SimilarityError::ConstantLatents { side });
    }
    for v in &mut flat {
        *v /= scale;
    }
    Ok(flat)
}

/// `acc += a bᵀ` for `acc` of `a.len()` × `b.len()`, row-major.
fn accumulate_outer(acc: &mut [f64], a: &[f64], b: &[f64]) {
    for (acc_row, &ai) in acc.chunks_exact_mut(b.len()).zip(a) {
        for (slot, &bj) in acc_row.iter_mut().zip(b) {
            *slot += ai * bj;
        }
    }
}

fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// All rows when there are at most [`MMD_MAX_PER_SIDE`], otherwise that many chosen by
/// a shuffle drawn from `rng`.
fn subsample<'a>(rows: &'a [Vec<f64>], rng: &mut ChaCha8Rng) -> Vec<&'a Vec<f64>> {
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
fn median_distance(squared: &mut [f64]) -> Option<f64> {
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
fn permuted_mmd2(kernel: &[f64], row_sums: &[f64], mask: &[f64], m: usize, n: usize) -> f64 {
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

/// A dot product with four running sums, which the compiler can vectorise.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(p, q)| p * q)
        .sum();
    for (pa, pb) in ca.zip(cb) {
        for ((s, p), q) in acc.iter_mut().zip(pa).zip(pb) {
            *s += p * q;
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// The `p` quantile of non-empty `sorted` by linear interpolation between order
/// statistics (type 7).
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let last = sorted.len().saturating_sub(1);
    let pos = p * last as f64;
    let lo = (pos.floor() as usize).min(last);
    let hi = (lo + 1).min(last);
    let frac = pos - lo as f64;
    match (sorted.get(lo), sorted.get(hi)) {
        (Some(&a), Some(&b)) if frac > 0.0 => a + (b - a) * frac,
        (Some(&a), _) => a,
        _ => f64::NAN,
    }
}

#[cfg(test)]
mod tests {
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
        let orthogonal =
            cosine_similarities(&[vec![1.0, 0.0]], &[vec![0.0, 2.0]]).expect("a result");
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
}
