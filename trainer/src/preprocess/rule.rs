//! The colour threshold as integer comparisons, so that the vector unit decides many
//! pixels at once where [`super::FingerTable`]'s lookup decides one at a time.
//!
//! A non-grey pixel's hue divided by 60° is a fraction `n / delta` of two small
//! integers: `n` is the sector's base times `delta` plus the signed difference of
//! the other two channels (`n` in `[0, 6·delta)`). Its saturation is `delta / max`.
//! Each float test of [`Preprocess::is_finger`] is monotone in its fraction, and
//! distinct fractions of integers up to 1530 over 255 lie further apart than an
//! f32's rounding, so each test keeps one interval of fractions (or, for a hue
//! window across 0°, everything outside one). [`IntegerRule::derive`] finds the
//! interval ends by asking the float tests themselves, and [`super::FingerTable`]
//! uses the rule only after it has decided all 2²⁴ colours exactly as the float
//! tests do; any other parameters keep the lookup.

use super::{Preprocess, Signal};

/// `num / den`, both small and non-negative; compared by cross-multiplication.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Fraction {
    num: i32,
    den: i32,
}

impl Fraction {
    fn cmp(self, other: Self) -> std::cmp::Ordering {
        (i64::from(self.num) * i64::from(other.den))
            .cmp(&(i64::from(other.num) * i64::from(self.den)))
    }
}

/// A fraction `whole + num / den` with `num < den ≤ 255`, so that comparing it with
/// `n / delta` needs only products below 2¹⁶ (16-bit lanes: twice as many pixels per
/// instruction as 32-bit ones).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Bound {
    whole: u16,
    num: u16,
    den: u16,
}

impl Bound {
    fn new(f: Fraction) -> Option<Self> {
        let whole = f.num.div_euclid(f.den);
        Some(Self {
            whole: u16::try_from(whole).ok()?,
            num: u16::try_from(f.num - whole * f.den).ok()?,
            den: u16::try_from(f.den).ok().filter(|&d| d <= 255)?,
        })
    }

    /// `self ≤ n / delta` for `n < 6·delta`, `0 < delta ≤ 255`: `n ≥ whole·delta`,
    /// and the rest `m = n − whole·delta` is a whole `delta` or more, or
    /// `m / delta ≥ num / den`. (Where a test is already decided, the wrapped
    /// products are never looked at.)
    #[inline(always)]
    fn at_most(self, n: u16, delta: u16) -> bool {
        let floor = self.whole.wrapping_mul(delta);
        let m = n.wrapping_sub(floor);
        (n >= floor) & ((m >= delta) | (m.wrapping_mul(self.den) >= self.num.wrapping_mul(delta)))
    }

    /// `self ≥ n / delta`, likewise.
    #[inline(always)]
    fn at_least(self, n: u16, delta: u16) -> bool {
        let floor = self.whole.wrapping_mul(delta);
        let m = n.wrapping_sub(floor);
        (n < floor) | ((m < delta) & (m.wrapping_mul(self.den) <= self.num.wrapping_mul(delta)))
    }
}

/// [`Preprocess::is_finger`] as integer comparisons (see the module's docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct IntegerRule {
    /// The least largest channel kept (256: none).
    value_min: u16,
    /// Whether a grey pixel (all channels equal) that passes the value test is kept.
    grey_kept: bool,
    /// Kept saturations: `delta / max ≥ num / den`, as `delta · den ≥ num · max`.
    saturation_num: u16,
    saturation_den: u16,
    /// Kept hues: `hue_lo ≤ n / delta ≤ hue_hi` when `hue_inside`, else either.
    hue_lo: Bound,
    hue_hi: Bound,
    hue_inside: bool,
    /// What one channel sums: `r + g + b`, or `3·delta` for chroma.
    signal: Signal,
}

/// A fraction no `n / delta` reaches (`n < 6·delta`), the lower end of an empty
/// interval (whose upper end is then never looked at).
const ABOVE_ALL: Fraction = Fraction { num: 7, den: 1 };
const ZERO: Fraction = Fraction { num: 0, den: 1 };

/// The kept values of a monotone test, as the ends of one interval of sorted
/// fractions: `(lo, hi, inside)`, where `inside` keeps `[lo, hi]` and `!inside`
/// keeps `≥ lo` or `≤ hi`. `None` when the kept fractions are in more pieces, or when
/// one fraction is kept in one spelling and not in another.
fn interval(mut tested: Vec<(Fraction, bool)>) -> Option<(Fraction, Fraction, bool)> {
    tested.sort_by(|a, b| a.0.cmp(b.0));
    // Equal fractions must agree, then each run of equal answers is one piece.
    let mut runs: Vec<(Fraction, Fraction, bool)> = Vec::new();
    for (i, &(f, kept)) in tested.iter().enumerate() {
        if i > 0 && tested[i - 1].0.cmp(f).is_eq() && tested[i - 1].1 != kept {
            return None;
        }
        match runs.last_mut() {
            Some(run) if run.2 == kept => run.1 = f,
            _ => runs.push((f, f, kept)),
        }
    }
    let kept: Vec<_> = runs.iter().filter(|r| r.2).collect();
    match (kept.as_slice(), runs.len()) {
        ([], _) => Some((ABOVE_ALL, ZERO, true)),
        ([only], _) => Some((only.0, only.1, true)),
        // Kept at both ends, dropped in the middle: the window across 0°.
        ([first, last], 3) if runs[0].2 => Some((last.0, first.1, false)),
        _ => None,
    }
}

impl IntegerRule {
    /// The rule for these parameters, or `None` where some test does not keep one
    /// interval of its fractions. The caller still checks it on every colour.
    pub(super) fn derive(p: &Preprocess) -> Option<Self> {
        let value_min = (0..=255u8)
            .find(|&m| f32::from(m) / 255.0 >= p.value_min)
            .map_or(256, u16::from);
        let grey_kept = 0.0 >= p.saturation_min && p.hue_in_window(0.0);

        let mut saturations = Vec::with_capacity(255 * 256 / 2);
        for max in 1..=255u8 {
            for delta in 1..=max {
                let kept = f32::from(delta) / f32::from(max) >= p.saturation_min;
                let f = Fraction {
                    num: i32::from(delta),
                    den: i32::from(max),
                };
                saturations.push((f, kept));
            }
        }
        let (saturation, top, inside) = interval(saturations)?;
        // Kept from some saturation up to 1 (or none kept at all): one comparison.
        let full = Fraction { num: 1, den: 1 };
        if !inside || !(top.cmp(full).is_eq() || saturation == ABOVE_ALL) {
            return None;
        }

        // Every (n, delta) as a pixel whose largest channel is 255, built in the
        // sector that `n` names, and asked of the float hue.
        let mut hues = Vec::with_capacity(6 * 255 * 256 / 2);
        for delta in 1..=255i32 {
            let min = 255 - delta;
            for n in 0..6 * delta {
                let (r, g, b) = if n <= delta {
                    (255, min + n, min)
                } else if n <= 3 * delta {
                    let s = n - 2 * delta;
                    if s >= 0 {
                        (min, 255, min + s)
                    } else {
                        (min - s, 255, min)
                    }
                } else if n < 5 * delta {
                    let s = n - 4 * delta;
                    if s >= 0 {
                        (min + s, min, 255)
                    } else {
                        (min, min - s, 255)
                    }
                } else {
                    (255, min, min + 6 * delta - n)
                };
                let [r, g, b] = [r, g, b].map(|c| u8::try_from(c).unwrap_or(0));
                let hue = super::hue_deg(r, g, b, 255, delta as f32);
                hues.push((Fraction { num: n, den: delta }, p.hue_in_window(hue)));
            }
        }
        let (hue_lo, hue_hi, hue_inside) = interval(hues)?;
        Some(Self {
            value_min,
            grey_kept,
            saturation_num: u16::try_from(saturation.num).ok()?,
            saturation_den: u16::try_from(saturation.den).ok()?,
            hue_lo: Bound::new(hue_lo)?,
            hue_hi: Bound::new(hue_hi)?,
            hue_inside,
            signal: p.signal,
        })
    }

    /// Whether the pixel is the finger's, in 16-bit arithmetic with bitwise logic
    /// and selects rather than branches, so that a loop of it becomes vector code.
    #[inline(always)]
    pub(super) fn keep(&self, r: u16, g: u16, b: u16) -> bool {
        let max = r.max(g).max(b);
        let delta = max - r.min(g).min(b);
        // hue / 60° = n / delta: the sector's base, then the other two channels'
        // difference (red's sector below 0° wraps to just under 6).
        let red = max == r;
        let green = !red & (max == g);
        let base: u16 = if red {
            if g >= b { 0 } else { 6 }
        } else if green {
            2
        } else {
            4
        };
        let plus = if red {
            g
        } else if green {
            b
        } else {
            r
        };
        let minus = if red {
            b
        } else if green {
            r
        } else {
            g
        };
        let n = base
            .wrapping_mul(delta)
            .wrapping_add(plus)
            .wrapping_sub(minus);
        let above = self.hue_lo.at_most(n, delta);
        let below = self.hue_hi.at_least(n, delta);
        let hue = (above & below) | (!self.hue_inside & (above | below));
        // Products of two values up to 255 fit 16 bits.
        let saturated =
            delta.wrapping_mul(self.saturation_den) >= self.saturation_num.wrapping_mul(max);
        let grey = delta == 0;
        let coloured = (grey & self.grey_kept) | (!grey & hue & saturated);
        (max >= self.value_min) & coloured
    }

    /// Adds one row's kept pixels into per-column sums: three times the signal per pixel
    /// (`grey`), or the three channels, interleaved as the row is. The caller keeps
    /// the sums below `u16::MAX` (at most [`super::ROWS_PER_FLUSH`] rows).
    pub(super) fn add_row(&self, row: &[u8], grey: bool, sums: &mut [u16]) {
        #[cfg(target_arch = "x86_64")]
        if grey {
            if let Some(simd) = pulp::x86::V4::try_new() {
                simd.vectorize(|| {
                    let done = v4::grey_row(simd, self, row, sums);
                    self.add_row_from(done, row, grey, sums);
                });
                return;
            }
            if self.add_grey_row_avx2(row, sums) {
                return;
            }
        }
        self.add_row_from(0, row, grey, sums);
    }

    /// The one-channel row with AVX2 intrinsics, where the machine has AVX2 (`false`,
    /// nothing done, where it has not). [`Self::add_row`] takes it without AVX-512.
    #[cfg(target_arch = "x86_64")]
    pub(super) fn add_grey_row_avx2(&self, row: &[u8], sums: &mut [u16]) -> bool {
        let Some(simd) = pulp::x86::V3::try_new() else {
            return false;
        };
        simd.vectorize(|| {
            let done = v3::grey_row(simd, self, row, sums);
            self.add_row_from(done, row, true, sums);
        });
        true
    }

    /// [`Self::add_row`] from pixel `first` on, compiled for the instruction set
    /// found at run time and vectorised by the compiler.
    fn add_row_from(&self, first: usize, row: &[u8], grey: bool, sums: &mut [u16]) {
        let per_pixel = if grey { 1 } else { 3 };
        let first = first.min(row.len() / 3).min(sums.len() / per_pixel);
        let (row, sums) = (&row[3 * first..], &mut sums[per_pixel * first..]);
        let op = AddRow {
            rule: self,
            row,
            grey,
            sums,
        };
        pulp::Arch::new().dispatch(op);
    }
}

/// [`IntegerRule::add_row`] compiled once per instruction set, chosen at run time
/// (AVX-512, AVX2, or plain x86-64).
struct AddRow<'a> {
    rule: &'a IntegerRule,
    row: &'a [u8],
    grey: bool,
    sums: &'a mut [u16],
}

impl pulp::WithSimd for AddRow<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        let Self {
            rule,
            row,
            grey,
            sums,
        } = self;
        // A copy on the stack: the loop reads it without reloading through a pointer.
        let rule = *rule;
        let pixels = (row.len() / 3).min(sums.len() / if grey { 1 } else { 3 });
        let row = &row[..3 * pixels];
        if grey {
            let sums = &mut sums[..pixels];
            for i in 0..pixels {
                let (r, g, b) = (
                    u16::from(row[3 * i]),
                    u16::from(row[3 * i + 1]),
                    u16::from(row[3 * i + 2]),
                );
                let kept = u16::from(rule.keep(r, g, b)) * rule.signal.times_three(r, g, b);
                sums[i] = sums[i].wrapping_add(kept);
            }
        } else {
            let sums = &mut sums[..3 * pixels];
            for i in 0..pixels {
                let (r, g, b) = (
                    u16::from(row[3 * i]),
                    u16::from(row[3 * i + 1]),
                    u16::from(row[3 * i + 2]),
                );
                let keep = u16::from(rule.keep(r, g, b));
                for c in 0..3 {
                    sums[3 * i + c] =
                        sums[3 * i + c].wrapping_add(u16::from(row[3 * i + c]) * keep);
                }
            }
        }
    }
}

/// The one-channel row (the default model's) with AVX-512 intrinsics through
/// `pulp`'s safe wrappers: 32 pixels per step. The compiler's own vector code for
/// [`IntegerRule::keep`] took 75 µs a 640×480 frame, this 57 µs: the hue's two
/// comparisons are one multiply-add each, and the pixels are unpacked in 11
/// shuffles rather than 19.
#[cfg(target_arch = "x86_64")]
mod v4 {
    use pulp::cast;
    use pulp::x86::V4;
    use std::arch::x86_64::__m512i;

    use super::IntegerRule;

    /// Adds the kept pixels' `r + g + b` (or `3·delta`) of whole steps of 32 pixels into `sums`;
    /// returns how many pixels it did (the caller does the rest).
    #[inline(always)]
    pub(super) fn grey_row(simd: V4, rule: &IntegerRule, row: &[u8], sums: &mut [u16]) -> usize {
        let (bw, f) = (simd.avx512bw, simd.avx512f);
        let (pixel_steps, _) = row.as_chunks::<96>();
        let (sum_steps, _) = sums.as_chunks_mut::<32>();
        // Each 128-bit lane L takes four pixels (12 bytes) of 8L.. and four of 8L + 4..,
        // as 32-bit words from the step's first 64 bytes (0–15) and its last 64
        // (16–31 for words 8–23), so that no load runs past the step.
        let four_at = |pixel: i32| {
            let word = pixel * 3 / 4;
            let from = |w: i32| if w < 16 { w } else { w - 8 + 16 };
            [from(word), from(word + 1), from(word + 2), 0]
        };
        let lanes_low: __m512i = cast([0, 8, 16, 24].map(four_at));
        let lanes_high: __m512i = cast([4, 12, 20, 28].map(four_at));
        // Within a lane: red and green as 16-bit words 0–3 and 4–7, blue as words 0–3.
        const Z: i8 = -1;
        let red_green: __m512i = cast([[0i8, Z, 3, Z, 6, Z, 9, Z, 1, Z, 4, Z, 7, Z, 10, Z]; 4]);
        let blue: __m512i = cast([[2i8, Z, 5, Z, 8, Z, 11, Z, Z, Z, Z, Z, Z, Z, Z, Z]; 4]);
        let splat = |v: u16| f._mm512_set1_epi16(v as i16);
        // `n / delta` against `p / q` as one multiply-add of the pairs (n, delta):
        // `n·q − p·delta ≥ 0` above the lower end, `p·delta − n·q ≥ 0` below the upper.
        let whole_num = |b: super::Bound| (b.whole * b.den + b.num) as i16;
        let (lo, hi) = (rule.hue_lo, rule.hue_hi);
        let lo_coef: __m512i = cast([[lo.den as i16, -whole_num(lo)]; 16]);
        let hi_coef: __m512i = cast([[-(hi.den as i16), whole_num(hi)]; 16]);
        let (value_min, sat_num, sat_den) = (
            splat(rule.value_min),
            splat(rule.saturation_num),
            splat(rule.saturation_den),
        );
        let (two, four, six) = (splat(2), splat(4), splat(6));
        let grey_kept: u32 = if rule.grey_kept { !0 } else { 0 };
        let outside: u32 = if rule.hue_inside { 0 } else { !0 };
        let zero = f._mm512_setzero_si512();
        for (step, sum) in pixel_steps.iter().zip(sum_steps.iter_mut()) {
            let (Some(first), Some(last)) = (step.first_chunk::<64>(), step.last_chunk::<64>())
            else {
                continue;
            };
            let (first, last): (__m512i, __m512i) = (cast(*first), cast(*last));
            let low = f._mm512_permutex2var_epi32(first, lanes_low, last);
            let high = f._mm512_permutex2var_epi32(first, lanes_high, last);
            let (rg_low, rg_high) = (
                bw._mm512_shuffle_epi8(low, red_green),
                bw._mm512_shuffle_epi8(high, red_green),
            );
            let r = f._mm512_unpacklo_epi64(rg_low, rg_high);
            let g = f._mm512_unpackhi_epi64(rg_low, rg_high);
            let b = f._mm512_unpacklo_epi64(
                bw._mm512_shuffle_epi8(low, blue),
                bw._mm512_shuffle_epi8(high, blue),
            );

            let max = bw._mm512_max_epu16(bw._mm512_max_epu16(r, g), b);
            let min = bw._mm512_min_epu16(bw._mm512_min_epu16(r, g), b);
            let delta = bw._mm512_sub_epi16(max, min);
            let red = bw._mm512_cmpeq_epi16_mask(max, r);
            let green = !red & bw._mm512_cmpeq_epi16_mask(max, g);
            let red_wraps = red & bw._mm512_cmplt_epu16_mask(g, b);
            // hue / 60° = n / delta, as in IntegerRule::keep.
            let base = bw._mm512_mask_mov_epi16(four, green, two);
            let base = bw._mm512_mask_mov_epi16(base, red, zero);
            let base = bw._mm512_mask_mov_epi16(base, red_wraps, six);
            let difference = bw._mm512_mask_mov_epi16(
                bw._mm512_mask_mov_epi16(
                    bw._mm512_sub_epi16(r, g),
                    green,
                    bw._mm512_sub_epi16(b, r),
                ),
                red,
                bw._mm512_sub_epi16(g, b),
            );
            let n = bw._mm512_add_epi16(bw._mm512_mullo_epi16(base, delta), difference);
            let (pairs_low, pairs_high) = (
                bw._mm512_unpacklo_epi16(n, delta),
                bw._mm512_unpackhi_epi16(n, delta),
            );
            // Packing the 32-bit results back to 16 bits saturates but keeps the sign,
            // and restores the order the unpacking split.
            let over_lo = bw._mm512_packs_epi32(
                bw._mm512_madd_epi16(pairs_low, lo_coef),
                bw._mm512_madd_epi16(pairs_high, lo_coef),
            );
            let under_hi = bw._mm512_packs_epi32(
                bw._mm512_madd_epi16(pairs_low, hi_coef),
                bw._mm512_madd_epi16(pairs_high, hi_coef),
            );
            let above = bw._mm512_cmpge_epi16_mask(over_lo, zero);
            let below = bw._mm512_cmpge_epi16_mask(under_hi, zero);
            let hue = (above & below) | (outside & (above | below));
            let saturated = bw._mm512_cmpge_epu16_mask(
                bw._mm512_mullo_epi16(delta, sat_den),
                bw._mm512_mullo_epi16(max, sat_num),
            );
            let grey = bw._mm512_cmpeq_epi16_mask(delta, zero);
            let keep = bw._mm512_cmpge_epu16_mask(max, value_min)
                & ((grey & grey_kept) | (!grey & hue & saturated));
            let all = if rule.signal == super::Signal::Chroma {
                bw._mm512_add_epi16(bw._mm512_add_epi16(delta, delta), delta)
            } else {
                bw._mm512_add_epi16(bw._mm512_add_epi16(r, g), b)
            };
            let before: __m512i = cast(*sum);
            *sum = cast(bw._mm512_mask_add_epi16(before, keep, before, all));
        }
        pixel_steps.len().min(sum_steps.len()) * 32
    }
}

/// The one-channel row with AVX2 intrinsics, for machines without AVX-512: the
/// same steps as [`v4`] on 16 pixels at a time, with vector masks for its mask
/// registers and `max(a, b) == a` for its unsigned comparisons. The compiler's own
/// AVX2 code for [`IntegerRule::keep`] took 173 µs a 640×480 frame.
#[cfg(target_arch = "x86_64")]
mod v3 {
    use pulp::cast;
    use pulp::x86::V3;
    use std::arch::x86_64::__m256i;

    use super::IntegerRule;

    /// Adds the kept pixels' `r + g + b` (or `3·delta`) of whole steps of 16 pixels into `sums`;
    /// returns how many pixels it did (the caller does the rest).
    #[inline(always)]
    pub(super) fn grey_row(simd: V3, rule: &IntegerRule, row: &[u8], sums: &mut [u16]) -> usize {
        let (x2, x) = (simd.avx2, simd.avx);
        let (pixel_steps, _) = row.as_chunks::<48>();
        let (sum_steps, _) = sums.as_chunks_mut::<16>();
        // Four pixels (12 bytes) per 128-bit lane, as 32-bit words of the step's first
        // 32 bytes (words 0–7) or its last 32 (words 4–11): lanes of pixels 0–3 and
        // 8–11, then of 4–7 and 12–15.
        let low_first: __m256i = cast([0i32, 1, 2, 0, 0, 0, 0, 0]);
        let low_last: __m256i = cast([0i32, 0, 0, 0, 2, 3, 4, 0]);
        let high_first: __m256i = cast([3i32, 4, 5, 0, 0, 0, 0, 0]);
        let high_last: __m256i = cast([0i32, 0, 0, 0, 5, 6, 7, 0]);
        const Z: i8 = -1;
        let red_green: __m256i = cast([[0i8, Z, 3, Z, 6, Z, 9, Z, 1, Z, 4, Z, 7, Z, 10, Z]; 2]);
        let blue: __m256i = cast([[2i8, Z, 5, Z, 8, Z, 11, Z, Z, Z, Z, Z, Z, Z, Z, Z]; 2]);
        let splat = |v: i16| x._mm256_set1_epi16(v);
        let whole_num = |b: super::Bound| (b.whole * b.den + b.num) as i16;
        let (lo, hi) = (rule.hue_lo, rule.hue_hi);
        let lo_coef: __m256i = cast([[lo.den as i16, -whole_num(lo)]; 8]);
        let hi_coef: __m256i = cast([[-(hi.den as i16), whole_num(hi)]; 8]);
        // All values are at most 1785, so signed comparisons serve, except for the
        // saturation's products (up to 65 025).
        let value_above = splat(rule.value_min as i16 - 1);
        let (sat_num, sat_den) = (
            splat(rule.saturation_num as i16),
            splat(rule.saturation_den as i16),
        );
        let (two, four, six, below_zero) = (splat(2), splat(4), splat(6), splat(-1));
        let all_or_none = |on: bool| splat(if on { -1 } else { 0 });
        let (grey_kept, outside) = (all_or_none(rule.grey_kept), all_or_none(!rule.hue_inside));
        let zero = x._mm256_setzero_si256();
        for (step, sum) in pixel_steps.iter().zip(sum_steps.iter_mut()) {
            let (Some(first), Some(last)) = (step.first_chunk::<32>(), step.last_chunk::<32>())
            else {
                continue;
            };
            let (first, last): (__m256i, __m256i) = (cast(*first), cast(*last));
            let low = x2._mm256_blend_epi32::<0xF0>(
                x2._mm256_permutevar8x32_epi32(first, low_first),
                x2._mm256_permutevar8x32_epi32(last, low_last),
            );
            let high = x2._mm256_blend_epi32::<0xF0>(
                x2._mm256_permutevar8x32_epi32(first, high_first),
                x2._mm256_permutevar8x32_epi32(last, high_last),
            );
            let (rg_low, rg_high) = (
                x2._mm256_shuffle_epi8(low, red_green),
                x2._mm256_shuffle_epi8(high, red_green),
            );
            let r = x2._mm256_unpacklo_epi64(rg_low, rg_high);
            let g = x2._mm256_unpackhi_epi64(rg_low, rg_high);
            let b = x2._mm256_unpacklo_epi64(
                x2._mm256_shuffle_epi8(low, blue),
                x2._mm256_shuffle_epi8(high, blue),
            );

            let max = x2._mm256_max_epu16(x2._mm256_max_epu16(r, g), b);
            let min = x2._mm256_min_epu16(x2._mm256_min_epu16(r, g), b);
            let delta = x2._mm256_sub_epi16(max, min);
            let red = x2._mm256_cmpeq_epi16(max, r);
            let green = x2._mm256_andnot_si256(red, x2._mm256_cmpeq_epi16(max, g));
            let red_wraps = x2._mm256_and_si256(red, x2._mm256_cmpgt_epi16(b, g));
            // hue / 60° = n / delta, as in IntegerRule::keep.
            let base = x2._mm256_blendv_epi8(four, two, green);
            let base = x2._mm256_blendv_epi8(base, zero, red);
            let base = x2._mm256_blendv_epi8(base, six, red_wraps);
            let difference = x2._mm256_blendv_epi8(
                x2._mm256_blendv_epi8(x2._mm256_sub_epi16(r, g), x2._mm256_sub_epi16(b, r), green),
                x2._mm256_sub_epi16(g, b),
                red,
            );
            let n = x2._mm256_add_epi16(x2._mm256_mullo_epi16(base, delta), difference);
            let (pairs_low, pairs_high) = (
                x2._mm256_unpacklo_epi16(n, delta),
                x2._mm256_unpackhi_epi16(n, delta),
            );
            let over_lo = x2._mm256_packs_epi32(
                x2._mm256_madd_epi16(pairs_low, lo_coef),
                x2._mm256_madd_epi16(pairs_high, lo_coef),
            );
            let under_hi = x2._mm256_packs_epi32(
                x2._mm256_madd_epi16(pairs_low, hi_coef),
                x2._mm256_madd_epi16(pairs_high, hi_coef),
            );
            let above = x2._mm256_cmpgt_epi16(over_lo, below_zero);
            let below = x2._mm256_cmpgt_epi16(under_hi, below_zero);
            let hue = x2._mm256_or_si256(
                x2._mm256_and_si256(above, below),
                x2._mm256_and_si256(outside, x2._mm256_or_si256(above, below)),
            );
            let (sat_have, sat_need) = (
                x2._mm256_mullo_epi16(delta, sat_den),
                x2._mm256_mullo_epi16(max, sat_num),
            );
            let saturated =
                x2._mm256_cmpeq_epi16(x2._mm256_max_epu16(sat_have, sat_need), sat_have);
            let grey = x2._mm256_cmpeq_epi16(delta, zero);
            let coloured = x2._mm256_or_si256(
                x2._mm256_and_si256(grey, grey_kept),
                x2._mm256_andnot_si256(grey, x2._mm256_and_si256(hue, saturated)),
            );
            let keep = x2._mm256_and_si256(x2._mm256_cmpgt_epi16(max, value_above), coloured);
            let all = if rule.signal == super::Signal::Chroma {
                x2._mm256_add_epi16(x2._mm256_add_epi16(delta, delta), delta)
            } else {
                x2._mm256_add_epi16(x2._mm256_add_epi16(r, g), b)
            };
            let before: __m256i = cast(*sum);
            *sum = cast(x2._mm256_add_epi16(before, x2._mm256_and_si256(all, keep)));
        }
        pixel_steps.len().min(sum_steps.len()) * 16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_rule_is_the_expected_fractions() {
        let rule = IntegerRule::derive(&Preprocess::default()).expect("one interval each");
        // value ≥ 0.2 → max ≥ 51; saturation ≥ 0.35 → 7/20; hue in [10°, 75°] → n/δ
        // in [1/6, 5/4].
        assert_eq!(rule.value_min, 51);
        assert!(!rule.grey_kept);
        let saturation = Fraction {
            num: i32::from(rule.saturation_num),
            den: i32::from(rule.saturation_den),
        };
        assert!(saturation.cmp(Fraction { num: 7, den: 20 }).is_eq());
        assert!(rule.hue_inside);
        let ratio = |b: Bound| Fraction {
            num: i32::from(b.whole * b.den + b.num),
            den: i32::from(b.den),
        };
        assert!(ratio(rule.hue_lo).cmp(Fraction { num: 1, den: 6 }).is_eq());
        assert!(ratio(rule.hue_hi).cmp(Fraction { num: 5, den: 4 }).is_eq());
    }

    #[test]
    fn intervals_are_found_or_refused() {
        let f = |num| Fraction { num, den: 10 };
        let pieces = |flags: &[bool]| {
            interval(
                flags
                    .iter()
                    .enumerate()
                    .map(|(i, &k)| (f(i as i32), k))
                    .collect(),
            )
        };
        assert_eq!(
            pieces(&[false, true, true, false]),
            Some((f(1), f(2), true))
        );
        assert_eq!(
            pieces(&[true, false, false, true]),
            Some((f(3), f(0), false))
        );
        assert_eq!(pieces(&[false, false]), Some((ABOVE_ALL, ZERO, true)));
        assert_eq!(pieces(&[true, false, true, false, true]), None);
        assert_eq!(pieces(&[false, true, false, true]), None);
        // One fraction answered both ways (1/2 = 5/10): no rule.
        let clash = vec![
            (Fraction { num: 1, den: 2 }, true),
            (Fraction { num: 5, den: 10 }, false),
        ];
        assert_eq!(interval(clash), None);
    }
}
