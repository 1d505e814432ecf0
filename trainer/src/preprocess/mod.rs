//! Image preprocessing shared by training and inference (one function, so the two can
//! never disagree): the colour threshold of the paper's Method S3 keeps only the
//! finger's pixels, then a box filter squashes the frame to the model's input size and
//! scales it to [0, 1].
//!
//! The threshold works in HSV: a pixel is the finger's when its hue lies in
//! `[hue_min_deg, hue_max_deg]` and its saturation and value are high enough. The
//! finger is orange in air and yellow-green through water; background, caustics and
//! bubbles are blue or grey and fall outside. Kept pixels carry their brightness
//! or their chroma (channels = 1, see [`Signal`]) or their RGB (channels = 3); the
//! rest become 0.

use serde::{Deserialize, Serialize};

use crate::TrainError;

pub mod augment;
mod rule;
pub mod tare;

/// Parameters of [`Preprocess::apply`]; stored in every model artifact.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preprocess {
    /// Output width and height in pixels (the frame is squashed, not cropped, as in
    /// the reference code).
    pub size_px: usize,
    /// 1: brightness of the finger's pixels; 3: their RGB.
    pub channels: usize,
    /// Hue window of the finger's pixels, degrees in [0, 360).
    pub hue_min_deg: f32,
    pub hue_max_deg: f32,
    /// Minimum HSV saturation and value, in [0, 1].
    pub saturation_min: f32,
    pub value_min: f32,
    /// What a kept pixel carries in one channel. Absent from older artifacts and
    /// left out when it is the default, so they read and write as before.
    #[serde(default, skip_serializing_if = "Signal::is_brightness")]
    pub signal: Signal,
}

/// What one channel carries of a kept pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Signal {
    /// The mean of its channels, (r + g + b) / 3: the paper's grey image.
    #[default]
    Brightness,
    /// Its chroma, max − min of its channels: the same under white light added to
    /// every channel alike (caustics, glare, a grey veil), which brightness is not.
    Chroma,
}

impl Signal {
    fn is_brightness(&self) -> bool {
        *self == Self::Brightness
    }

    /// The value summed for one kept pixel, three times the signal so that both
    /// fit the same sums (at most 765): `r + g + b`, or `3·(max − min)`.
    #[inline(always)]
    fn times_three(self, r: u16, g: u16, b: u16) -> u16 {
        match self {
            Self::Brightness => r + g + b,
            Self::Chroma => 3 * (r.max(g).max(b) - r.min(g).min(b)),
        }
    }
}

impl std::str::FromStr for Signal {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "brightness" => Ok(Self::Brightness),
            "chroma" => Ok(Self::Chroma),
            other => Err(format!(
                "signal `{other}`: expected `brightness` or `chroma`"
            )),
        }
    }
}

impl std::fmt::Display for Signal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Brightness => "brightness",
            Self::Chroma => "chroma",
        })
    }
}

impl Default for Preprocess {
    fn default() -> Self {
        Self {
            // 32×32: as accurate as 64×64 on the simulated finger, in air and in water,
            // at 4.5× the training throughput and a sixth of the latency (`softtouch
            // bench model`, trainer/README.md).
            size_px: 32,
            channels: 1,
            hue_min_deg: 10.0,
            hue_max_deg: 75.0,
            saturation_min: 0.35,
            value_min: 0.2,
            signal: Signal::Brightness,
        }
    }
}

impl Preprocess {
    /// Values the output tensor holds: channels × size × size.
    pub fn input_len(&self) -> usize {
        self.channels * self.size_px * self.size_px
    }

    /// A list of what is wrong with these parameters (empty when usable).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(16..=256).contains(&self.size_px) || !self.size_px.is_power_of_two() {
            out.push(format!(
                "input size {} px: expected a power of two in 16..=256",
                self.size_px
            ));
        }
        if self.channels != 1 && self.channels != 3 {
            out.push(format!("channels {}: expected 1 or 3", self.channels));
        }
        if self.signal != Signal::Brightness && self.channels != 1 {
            out.push(format!(
                "signal {} with {} channels: the signal is one channel's (channels = 1)",
                self.signal, self.channels
            ));
        }
        for (name, v, hi) in [
            ("hue_min_deg", self.hue_min_deg, 360.0),
            ("hue_max_deg", self.hue_max_deg, 360.0),
            ("saturation_min", self.saturation_min, 1.0),
            ("value_min", self.value_min, 1.0),
        ] {
            if !(v.is_finite() && (0.0..=hi).contains(&v)) {
                out.push(format!("{name} = {v}: expected a value in [0, {hi}]"));
            }
        }
        out
    }

    /// Whether an RGB pixel (0..=255 per channel) is the finger's: its HSV value,
    /// saturation and hue pass the thresholds.
    ///
    /// This runs on every pixel of every frame (300 000 per 640×480 frame), so the
    /// cheap tests come first and the hue's division only runs on bright, saturated
    /// pixels; each test is the same float expression as in [`hsv`], so the decision
    /// is identical to thresholding `hsv(r, g, b)` (checked over all 2²⁴ colours).
    pub fn is_finger(&self, r: u8, g: u8, b: u8) -> bool {
        let max_u = r.max(g).max(b);
        let min_u = r.min(g).min(b);
        let max = f32::from(max_u);
        if max / 255.0 < self.value_min {
            return false;
        }
        if max_u == 0 || max_u == min_u {
            // Grey: saturation 0, hue 0.
            return 0.0 >= self.saturation_min && self.hue_in_window(0.0);
        }
        let delta = f32::from(max_u - min_u);
        if delta / max < self.saturation_min {
            return false;
        }
        self.hue_in_window(hue_deg(r, g, b, max_u, delta))
    }

    fn hue_in_window(&self, hue_deg: f32) -> bool {
        if self.hue_min_deg <= self.hue_max_deg {
            (self.hue_min_deg..=self.hue_max_deg).contains(&hue_deg)
        } else {
            // A window across 0° (reds): [min, 360) ∪ [0, max].
            hue_deg >= self.hue_min_deg || hue_deg <= self.hue_max_deg
        }
    }

    /// Threshold and squash an RGB8 frame (`width × height × 3`, row-major) into a
    /// channels × size × size tensor in [0, 1] (channel-major).
    pub fn apply(&self, width: usize, height: usize, rgb: &[u8]) -> Result<Vec<f32>, TrainError> {
        let mut out = vec![0.0; self.input_len()];
        self.apply_into(width, height, rgb, &mut out)?;
        Ok(out)
    }

    /// [`apply`](Self::apply) into a caller's buffer of [`input_len`](Self::input_len) values.
    pub fn apply_into(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut [f32],
    ) -> Result<(), TrainError> {
        self.squash(width, height, rgb, out, None, |row, grey, sums| {
            add_row_per_pixel(row, grey, self.signal, sums, |r, g, b| {
                self.is_finger(r, g, b)
            });
        })
    }

    /// The threshold and box filter. `add_row` adds one source row's kept pixels
    /// into per-column sums (the direct test, a [`FingerTable`]'s lookup, or its
    /// vector rule: the same decisions). `split`: the top and bottom halves of the
    /// output on two threads when there are two cores (the same sums, so the same
    /// output).
    fn squash(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut [f32],
        split: Option<&dyn Fork>,
        add_row: impl Fn(&[u8], bool, &mut [u16]) + Sync,
    ) -> Result<(), TrainError> {
        if width == 0 || height == 0 {
            return Err(TrainError::Input(format!(
                "image is {width}×{height} px: expected a non-empty image"
            )));
        }
        if rgb.len() != width * height * 3 {
            return Err(TrainError::Input(format!(
                "image buffer holds {} bytes: a {width}×{height} RGB8 image needs {}",
                rgb.len(),
                width * height * 3
            )));
        }
        if out.len() != self.input_len() {
            return Err(TrainError::Input(format!(
                "output buffer holds {} values: expected {}",
                out.len(),
                self.input_len()
            )));
        }
        let n = self.size_px;
        let plane = n * n;
        // Box filter: output pixel (ox, oy) averages the source rectangle
        // [x0, x1) × [y0, y1); every source pixel lands in exactly one box (when the
        // image is smaller than the output, boxes repeat a pixel instead).
        let bounds = |o: usize, src: usize| {
            let a = o * src / n;
            let b = ((o + 1) * src / n).max(a + 1).min(src);
            (a.min(src - 1), b)
        };
        let columns: Vec<(usize, usize)> = (0..n).map(|ox| bounds(ox, width)).collect();
        // One channel needs only the sum of the three (in the first of the sums).
        let grey = self.channels == 1;
        let per_pixel = if grey { 1 } else { 3 };
        // Integer sums (at most 255 × the box's pixels) are exact, as f32 sums of
        // integers below 2²⁴ were. Rows are summed down each column first, in u16
        // (the rows of a vector, not of a box), then each box adds its columns.
        // Output rows from `oy0` on, one row of `n` box sums per chunk of `rows`.
        let fill = |rows: &mut [[u32; 3]], oy0: usize| {
            let mut column_sums = vec![0u16; width * per_pixel];
            for (i, boxes) in rows.chunks_exact_mut(n).enumerate() {
                let (y0, y1) = bounds(oy0 + i, height);
                for first in (y0..y1).step_by(ROWS_PER_FLUSH) {
                    column_sums.fill(0);
                    for y in first..(first + ROWS_PER_FLUSH).min(y1) {
                        add_row(
                            &rgb[y * width * 3..(y + 1) * width * 3],
                            grey,
                            &mut column_sums,
                        );
                    }
                    for (a, &(x0, x1)) in boxes.iter_mut().zip(&columns) {
                        let in_box = &column_sums[x0 * per_pixel..x1 * per_pixel];
                        if grey {
                            a[0] += in_box.iter().map(|&v| u32::from(v)).sum::<u32>();
                            continue;
                        }
                        for px in in_box.chunks_exact(3) {
                            for c in 0..3 {
                                a[c] += u32::from(px[c]);
                            }
                        }
                    }
                }
            }
        };
        let mut sums = vec![[0u32; 3]; plane];
        if let Some(fork) = split.filter(|_| n > 1) {
            let (top, bottom) = sums.split_at_mut(n / 2 * n);
            fork.fork(&mut || fill(&mut *top, 0), &mut || {
                fill(&mut *bottom, n / 2)
            });
        } else {
            fill(&mut sums, 0);
        }
        for (oy, row) in sums.chunks_exact(n).enumerate() {
            let (y0, y1) = bounds(oy, height);
            for (ox, (a, &(x0, x1))) in row.iter().zip(&columns).enumerate() {
                let count = ((x1 - x0) * (y1 - y0)) as f32 * 255.0;
                let at = oy * n + ox;
                if grey {
                    // Brightness as HSV value would need a max per pixel; the mean of
                    // the channels is as informative here and cheaper. Both signals
                    // are summed three times over.
                    out[at] = a[0] as f32 / (3.0 * count);
                } else {
                    for c in 0..3 {
                        out[c * plane + at] = a[c] as f32 / count;
                    }
                }
            }
        }
        Ok(())
    }
}

/// Source rows summed down each column in u16 before the boxes take them: 85 rows of
/// `r + g + b ≤ 765` stay below 65 536.
const ROWS_PER_FLUSH: usize = 85;

/// Adds one RGB8 row's kept pixels into per-column sums, deciding each pixel with
/// `is_finger`: three times the `signal` per pixel (`grey`) or the three channels
/// interleaved.
#[inline(always)]
fn add_row_per_pixel(
    row: &[u8],
    grey: bool,
    signal: Signal,
    sums: &mut [u16],
    is_finger: impl Fn(u8, u8, u8) -> bool,
) {
    if grey {
        for (px, sum) in row.chunks_exact(3).zip(sums.iter_mut()) {
            let (r, g, b) = (px[0], px[1], px[2]);
            let all = signal.times_three(u16::from(r), u16::from(g), u16::from(b));
            // On a noisy frame the finger's edge makes the decision a coin toss: a
            // conditional move, never a branch.
            let kept = std::hint::select_unpredictable(is_finger(r, g, b), all, 0);
            *sum = sum.wrapping_add(kept);
        }
    } else {
        for (px, sum) in row.chunks_exact(3).zip(sums.chunks_exact_mut(3)) {
            let keep = u16::from(is_finger(px[0], px[1], px[2]));
            for c in 0..3 {
                sum[c] = sum[c].wrapping_add(u16::from(px[c]) * keep);
            }
        }
    }
}

/// Whether this process may use two cores or more, asked once: the answer reads
/// cgroup files, far too slow to ask for every frame.
fn two_cores() -> bool {
    static TWO: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *TWO.get_or_init(|| std::thread::available_parallelism().is_ok_and(|c| c.get() > 1))
}

/// Runs the two halves of one frame's preprocessing, possibly at once, and returns
/// when both are done. The grasp trials pass the drivers' second core, kept awake
/// between frames; [`ScopedThread`] starts a thread per frame.
pub trait Fork: Send + Sync + std::fmt::Debug {
    fn fork(&self, here: &mut (dyn FnMut() + Send), there: &mut (dyn FnMut() + Send));
}

/// A scoped thread per call for the other half, when there are two cores (else
/// both halves on the caller).
#[derive(Debug, Clone, Copy, Default)]
pub struct ScopedThread;

impl Fork for ScopedThread {
    fn fork(&self, here: &mut (dyn FnMut() + Send), there: &mut (dyn FnMut() + Send)) {
        if two_cores() {
            std::thread::scope(|s| {
                s.spawn(there);
                here();
            });
        } else {
            here();
            there();
        }
    }
}

/// [`Preprocess::is_finger`] decided once for each of the 2²⁴ RGB colours, one bit
/// each (2 MiB): preprocessing then looks a pixel up instead of converting it to
/// HSV, which took most of a frame's time (2.0 of 2.9 ms for a 640×480 frame on one
/// core). Building it costs one decision per colour; a [`crate::Predictor`] and the
/// dataset loader build one per model and reuse it for every frame.
///
/// When the same decisions reduce to integer comparisons (`rule.rs`; they did for
/// every parameter set tried), the table checks that on all 2²⁴ colours and then
/// decides 32 pixels per instruction instead: 0.057 ms a 640×480 frame on one
/// AVX-512 core, against 0.29 ms through the lookup (`cargo bench --bench
/// inference`). The bits stay as the reference and the fallback.
#[derive(Clone)]
pub struct FingerTable {
    params: Preprocess,
    bits: Vec<u64>,
    /// The least red channel of any colour kept: a darker red is never the finger,
    /// which answers most background pixels without touching a table.
    min_red: u8,
    /// For each (red, green), the blues kept as one interval `[lo, hi]` (`lo > hi`:
    /// none), when every (red, green) keeps an interval (true for the HSV window
    /// the finger uses): 128 KiB that stay in a core's cache, where the 2 MiB of bits
    /// do not. `None`: some (red, green) keeps blues in pieces; the bits decide.
    blue_runs: Option<Box<[[u8; 2]; 1 << 16]>>,
    /// The same decisions as integer comparisons that run many pixels at once
    /// (`None` for parameters where they would differ on some colour).
    rule: Option<rule::IntegerRule>,
}

impl std::fmt::Debug for FingerTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FingerTable")
            .field("params", &self.params)
            .field(
                "colours_kept",
                &self.bits.iter().map(|w| w.count_ones()).sum::<u32>(),
            )
            .finish()
    }
}

impl FingerTable {
    pub fn new(params: &Preprocess) -> Self {
        let mut bits = vec![0u64; (1 << 24) / 64];
        let mut min_red = u8::MAX;
        for (word_index, word) in bits.iter_mut().enumerate() {
            for bit in 0..64 {
                let colour = word_index * 64 + bit;
                let [_, r, g, b] = (colour as u32).to_be_bytes();
                if params.is_finger(r, g, b) {
                    *word |= 1 << bit;
                    min_red = min_red.min(r);
                }
            }
        }
        let blue_runs = Self::blue_runs(&bits);
        let rule = rule::IntegerRule::derive(params).filter(|rule| Self::agrees(rule, &bits));
        Self {
            params: *params,
            bits,
            min_red,
            blue_runs,
            rule,
        }
    }

    /// Whether the rule keeps exactly the colours the bits keep, all 2²⁴ of them.
    fn agrees(rule: &rule::IntegerRule, bits: &[u64]) -> bool {
        bits.iter().enumerate().all(|(word_index, &word)| {
            let rg = word_index >> 2;
            let (r, g) = ((rg >> 8) as u16, (rg & 0xff) as u16);
            let b0 = (word_index & 3) as u16 * 64;
            let decided = (0..64).fold(0u64, |acc, bit| {
                acc | (u64::from(rule.keep(r, g, b0 + bit)) << bit)
            });
            decided == word
        })
    }

    /// The blues kept for each (red, green) as one interval, if each is one.
    fn blue_runs(bits: &[u64]) -> Option<Box<[[u8; 2]; 1 << 16]>> {
        // Fixed length, so that indexing by (red, green) needs no bounds check.
        let mut runs: Box<[[u8; 2]; 1 << 16]> = vec![[1u8, 0u8]; 1 << 16].try_into().ok()?;
        for (rg, run) in runs.iter_mut().enumerate() {
            // The 256 blues of one (red, green) are four words.
            let words = &bits[rg * 4..rg * 4 + 4];
            let kept = words.iter().map(|w| w.count_ones()).sum::<u32>();
            if kept == 0 {
                continue;
            }
            let first = (0..256).find(|&b| (words[b / 64] >> (b % 64)) & 1 == 1)?;
            let last = first + kept as usize - 1;
            // One interval: every blue from the first kept to first + count − 1.
            if (first..=last).any(|b| b > 255 || (words[b / 64] >> (b % 64)) & 1 == 0) {
                return None;
            }
            *run = [first as u8, last as u8];
        }
        Some(runs)
    }

    /// The parameters the table was built from.
    pub fn params(&self) -> &Preprocess {
        &self.params
    }

    /// The same answer as [`Preprocess::is_finger`], by lookup.
    #[inline]
    pub fn contains(&self, r: u8, g: u8, b: u8) -> bool {
        if let Some(runs) = &self.blue_runs {
            // No branch: on a noisy frame the answer is a coin toss for the predictor.
            // One sign test (b − lo and hi − b both ≥ 0) rather than two comparisons,
            // which the compiler turned into a branch and a conditional move.
            let [lo, hi] = runs[(usize::from(r) << 8) | usize::from(g)];
            let (b, lo, hi) = (i32::from(b), i32::from(lo), i32::from(hi));
            return ((b - lo) | (hi - b)) >= 0;
        }
        if r < self.min_red {
            return false;
        }
        let colour = (usize::from(r) << 16) | (usize::from(g) << 8) | usize::from(b);
        (self.bits[colour >> 6] >> (colour & 63)) & 1 == 1
    }

    /// [`Preprocess::apply_into`] with the lookup: the same output, faster.
    pub fn apply_into(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut [f32],
    ) -> Result<(), TrainError> {
        self.apply_into_on(width, height, rgb, out, None)
    }

    /// [`Self::apply_into`], with `split`: the output's halves through that
    /// [`Fork`] (for one frame's latency, not for a loader that already keeps every
    /// core busy). The same output either way.
    pub fn apply_into_on(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut [f32],
        split: Option<&dyn Fork>,
    ) -> Result<(), TrainError> {
        match &self.rule {
            Some(rule) => self
                .params
                .squash(width, height, rgb, out, split, |row, grey, sums| {
                    rule.add_row(row, grey, sums);
                }),
            None => self
                .params
                .squash(width, height, rgb, out, split, |row, grey, sums| {
                    add_row_per_pixel(row, grey, self.params.signal, sums, |r, g, b| {
                        self.contains(r, g, b)
                    });
                }),
        }
    }

    /// [`Preprocess::apply`] with the lookup.
    pub fn apply(&self, width: usize, height: usize, rgb: &[u8]) -> Result<Vec<f32>, TrainError> {
        let mut out = vec![0.0; self.params.input_len()];
        self.apply_into(width, height, rgb, &mut out)?;
        Ok(out)
    }
}

/// The hue in degrees of a pixel that is not grey (`delta` = max − min > 0).
fn hue_deg(r: u8, g: u8, b: u8, max_u: u8, delta: f32) -> f32 {
    let (rf, gf, bf) = (f32::from(r), f32::from(g), f32::from(b));
    let sector = if max_u == r {
        ((gf - bf) / delta).rem_euclid(6.0)
    } else if max_u == g {
        (bf - rf) / delta + 2.0
    } else {
        (rf - gf) / delta + 4.0
    };
    sector * 60.0
}

#[cfg(test)]
mod tests;
