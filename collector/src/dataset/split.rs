//! Splitting a selection into train / validation / test (algorithm `split-v1`).
//!
//! 1. Counts: largest-remainder rounding of `n · part / total` in exact integer
//!    arithmetic; the samples left over after flooring go to the splits with the
//!    largest remainders, ties to the earlier split (train, then val, then test). Every
//!    count is within one sample of its exact share, and the counts add up to `n`.
//! 2. Assignment: the list `[train × c_train, val × c_val, test × c_test]` is shuffled
//!    with a Fisher–Yates shuffle driven by SplitMix64 seeded with the dataset's seed
//!    (unbiased bounded draws by rejection), and sample `i` of the selection (in
//!    `(run, index)` order) gets entry `i`.
//!
//! The generator is written out here rather than taken from a crate so a seed gives
//! the same split whatever dependency versions a later build uses.
//!
//! Tiny selections: a split whose part of the ratio is zero is empty by design
//! (`8:2:0`); a split whose part is not zero must get at least one sample, or the
//! dataset is refused with [`SplitError::TooSmall`], which names the smallest
//! selection size that would work. An empty selection is refused too.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which part of a dataset a sample belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Training.
    Train,
    /// Validation.
    Val,
    /// Test.
    Test,
}

impl Split {
    /// The three splits in ratio order.
    pub const ALL: [Self; 3] = [Self::Train, Self::Val, Self::Test];

    /// Name as stored and exported.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Train => "train",
            Self::Val => "val",
            Self::Test => "test",
        }
    }

    /// Position in [`Split::ALL`].
    #[must_use]
    pub const fn ordinal(self) -> usize {
        match self {
            Self::Train => 0,
            Self::Val => 1,
            Self::Test => 2,
        }
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Split {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|x| x.as_str() == s)
            .ok_or_else(|| format!("unknown split `{s}`, expected train, val or test"))
    }
}

/// A `train:val:test` ratio of whole numbers, e.g. `7:1:2`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SplitRatio {
    /// Parts of train, val and test.
    pub parts: [u32; 3],
}

impl SplitRatio {
    /// The paper's 7:1:2.
    pub const PAPER: Self = Self { parts: [7, 1, 2] };

    fn total(self) -> u64 {
        self.parts.iter().map(|&p| u64::from(p)).sum()
    }
}

impl Default for SplitRatio {
    fn default() -> Self {
        Self::PAPER
    }
}

impl fmt::Display for SplitRatio {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c] = self.parts;
        write!(f, "{a}:{b}:{c}")
    }
}

/// Largest ratio total accepted (keeps the arithmetic far from overflow).
const MAX_TOTAL: u64 = 1_000_000;

impl FromStr for SplitRatio {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || {
            format!(
                "bad split ratio `{s}`: expected three whole numbers train:val:test, e.g. 7:1:2"
            )
        };
        let fields: Vec<&str> = s.split(':').collect();
        let [a, b, c] = fields.as_slice() else {
            return Err(bad());
        };
        let parse = |t: &str| t.trim().parse::<u32>().map_err(|_| bad());
        let ratio = Self {
            parts: [parse(a)?, parse(b)?, parse(c)?],
        };
        match ratio.total() {
            0 => Err(format!("bad split ratio `{s}`: all parts are zero")),
            t if t > MAX_TOTAL => Err(format!(
                "bad split ratio `{s}`: parts add up to more than {MAX_TOTAL}"
            )),
            _ => Ok(ratio),
        }
    }
}

/// A selection cannot be split as asked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SplitError {
    /// Nothing selected.
    #[error("the selection is empty: no sample passes the filters")]
    Empty,
    /// A split with a non-zero part would be empty.
    #[error(
        "{n} selected sample(s) are too few for split {ratio}: the {empty} split would be empty \
         (at least {min_needed} samples are needed, or give that split a zero part, e.g. --split {suggest})"
    )]
    TooSmall {
        /// Samples selected.
        n: usize,
        /// The ratio asked for.
        ratio: SplitRatio,
        /// The first split that would be empty.
        empty: Split,
        /// The smallest selection size for which no such split is empty.
        min_needed: usize,
        /// The ratio with the empty splits' parts set to zero.
        suggest: SplitRatio,
    },
}

/// Sample counts per split for `n` samples (largest remainder; see the module docs).
#[must_use]
pub fn split_counts(n: usize, ratio: SplitRatio) -> [usize; 3] {
    let total = u128::from(ratio.total().max(1));
    let n128 = n as u128;
    let mut counts = [0usize; 3];
    let mut remainders = [0u128; 3];
    for (i, &p) in ratio.parts.iter().enumerate() {
        let exact = n128 * u128::from(p);
        // Both fit: the floor is at most n.
        counts[i] = usize::try_from(exact / total).unwrap_or(n);
        remainders[i] = exact % total;
    }
    let mut left = n - counts.iter().sum::<usize>();
    // At most two leftovers (three remainders each < total add up to < 3·total).
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| remainders[b].cmp(&remainders[a]).then(a.cmp(&b)));
    for i in order {
        if left == 0 {
            break;
        }
        counts[i] += 1;
        left -= 1;
    }
    counts
}

/// Counts per split, refusing an empty selection or an empty split whose part is not
/// zero.
pub fn checked_counts(n: usize, ratio: SplitRatio) -> Result<[usize; 3], SplitError> {
    if n == 0 {
        return Err(SplitError::Empty);
    }
    let counts = split_counts(n, ratio);
    let empty = |c: &[usize; 3]| (0..3).find(|&i| ratio.parts[i] > 0 && c[i] == 0);
    let Some(first) = empty(&counts) else {
        return Ok(counts);
    };
    // With n ≥ total every non-zero part gets ≥ 1, so the search ends by `total`.
    let total = usize::try_from(ratio.total()).unwrap_or(usize::MAX);
    let min_needed = (n + 1..=total.max(n + 1))
        .find(|&m| empty(&split_counts(m, ratio)).is_none())
        .unwrap_or(total);
    let mut suggest = ratio;
    for (part, &count) in suggest.parts.iter_mut().zip(&counts) {
        if count == 0 {
            *part = 0;
        }
    }
    Err(SplitError::TooSmall {
        n,
        ratio,
        empty: Split::ALL[first],
        min_needed,
        suggest,
    })
}

/// The split of each of `n` samples, for a ratio and a seed (see the module docs).
pub fn assign(n: usize, ratio: SplitRatio, seed: u64) -> Result<Vec<Split>, SplitError> {
    let counts = checked_counts(n, ratio)?;
    let mut labels = Vec::with_capacity(n);
    for (split, &count) in Split::ALL.iter().zip(&counts) {
        labels.extend(std::iter::repeat_n(*split, count));
    }
    let mut rng = SplitMix64(seed);
    for i in (1..labels.len()).rev() {
        let j = rng.below(i as u64 + 1);
        labels.swap(i, usize::try_from(j).unwrap_or(i));
    }
    Ok(labels)
}

/// SplitMix64 (Steele, Lea, Flood 2014): small, fast, well mixed, fixed forever here.
#[derive(Debug, Clone)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..bound` (`bound > 0`), without modulo bias.
    fn below(&mut self, bound: u64) -> u64 {
        let zone = u64::MAX - (u64::MAX % bound);
        loop {
            let v = self.next();
            if v < zone {
                return v % bound;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ratio(a: u32, b: u32, c: u32) -> SplitRatio {
        SplitRatio { parts: [a, b, c] }
    }

    #[test]
    fn the_papers_ratio_on_round_numbers_is_exact() {
        assert_eq!(
            split_counts(30_000, SplitRatio::PAPER),
            [21_000, 3_000, 6_000]
        );
        assert_eq!(split_counts(10, SplitRatio::PAPER), [7, 1, 2]);
    }

    #[test]
    fn leftovers_go_to_the_largest_remainders_then_to_the_earlier_split() {
        // 11 · 7/10 = 7.7, 11 · 1/10 = 1.1, 11 · 2/10 = 2.2 → 7, 1, 2 + 1 to train.
        assert_eq!(split_counts(11, SplitRatio::PAPER), [8, 1, 2]);
        // 5: 3.5, 0.5, 1.0 → tie between train and val goes to train.
        assert_eq!(split_counts(5, SplitRatio::PAPER), [4, 0, 1]);
        assert_eq!(split_counts(2, ratio(1, 1, 1)), [1, 1, 0]);
    }

    #[test]
    fn tiny_selections_are_refused_with_the_size_that_would_work() {
        assert_eq!(checked_counts(0, SplitRatio::PAPER), Err(SplitError::Empty));
        let err = checked_counts(5, SplitRatio::PAPER);
        let Err(SplitError::TooSmall {
            empty,
            min_needed,
            suggest,
            ..
        }) = err
        else {
            panic!("{err:?}");
        };
        assert_eq!(empty, Split::Val);
        assert_eq!(min_needed, 6);
        assert_eq!(suggest, ratio(7, 0, 2));
        assert_eq!(checked_counts(6, SplitRatio::PAPER), Ok([4, 1, 1]));
        // A zero part is an empty split by design.
        assert_eq!(checked_counts(1, ratio(1, 0, 0)), Ok([1, 0, 0]));
        assert_eq!(checked_counts(3, ratio(8, 2, 0)), Ok([2, 1, 0]));
    }

    #[test]
    fn ratios_parse_and_print() {
        assert_eq!("7:1:2".parse(), Ok(SplitRatio::PAPER));
        assert_eq!(SplitRatio::PAPER.to_string(), "7:1:2");
        for bad in [
            "7:1",
            "7:1:2:0",
            "a:b:c",
            "-1:1:1",
            "0:0:0",
            "0.7:0.1:0.2",
            "",
        ] {
            assert!(bad.parse::<SplitRatio>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_known_seed_gives_a_known_split() {
        // Pins the algorithm: a change here changes every dataset created from now on.
        let got: String = assign(10, SplitRatio::PAPER, 42)
            .unwrap_or_else(|e| panic!("{e}"))
            .iter()
            .map(|s| match s {
                Split::Train => 'r',
                Split::Val => 'v',
                Split::Test => 'e',
            })
            .collect();
        assert_eq!(got.len(), 10);
        assert_eq!(got, KNOWN_SPLIT_SEED_42);
    }

    const KNOWN_SPLIT_SEED_42: &str = "rererrvrrr";

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn counts_cover_the_selection_and_respect_the_ratio(
            n in 0usize..5_000, a in 0u32..20, b in 0u32..20, c in 0u32..20,
        ) {
            prop_assume!(a + b + c > 0);
            let r = ratio(a, b, c);
            let counts = split_counts(n, r);
            prop_assert_eq!(counts.iter().sum::<usize>(), n);
            let total = f64::from(a + b + c);
            for (i, &p) in r.parts.iter().enumerate() {
                let exact = n as f64 * f64::from(p) / total;
                prop_assert!((counts[i] as f64 - exact).abs() < 1.0, "{counts:?} vs {exact}");
            }
        }

        #[test]
        fn assignment_is_deterministic_disjoint_and_exact_or_refused(
            n in 0usize..400, a in 0u32..10, b in 0u32..10, c in 0u32..10, seed in any::<u64>(),
        ) {
            prop_assume!(a + b + c > 0);
            let r = ratio(a, b, c);
            match assign(n, r, seed) {
                Ok(labels) => {
                    prop_assert_eq!(labels.len(), n);
                    let again = assign(n, r, seed);
                    prop_assert_eq!(Ok(labels.clone()), again);
                    let counts = split_counts(n, r);
                    for s in Split::ALL {
                        let got = labels.iter().filter(|&&l| l == s).count();
                        prop_assert_eq!(got, counts[s.ordinal()]);
                        if r.parts[s.ordinal()] > 0 {
                            prop_assert!(got > 0);
                        } else {
                            prop_assert_eq!(got, 0);
                        }
                    }
                }
                Err(SplitError::Empty) => prop_assert_eq!(n, 0),
                Err(SplitError::TooSmall { min_needed, .. }) => {
                    prop_assert!(n > 0 && min_needed > n);
                    prop_assert!(checked_counts(min_needed, r).is_ok());
                    for m in n..min_needed {
                        prop_assert!(checked_counts(m, r).is_err());
                    }
                }
            }
        }
    }
}
