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

mod mmd;
pub use mmd::*;

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
mod tests;
