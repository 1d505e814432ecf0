//! The frame's two row bands: where the work halves, and the balance learnt from how long each band took.

use super::*;

/// The row above which lies `top_share` of a frame's estimated work (a half:
/// 0.5): each beam's pixels (length × width) spread evenly over the rows it spans,
/// plus `row_cost` (in beam pixels) in every row for the copies and effects. The
/// first row of the lower band, in `1..H`.
pub(super) fn split_row(lines: &[Line], row_cost: f32, top_share: f32) -> usize {
    let top_share = if top_share.is_finite() {
        top_share.clamp(0.0, 1.0)
    } else {
        0.5
    };
    let mut per_row = vec![0f32; H + 1];
    if row_cost.is_finite() && row_cost > 0.0 {
        per_row[0] += row_cost;
        per_row[H] -= row_cost;
    }
    for &(p0, p1, half_w, _) in lines {
        let reach = half_w + 1.0;
        let lo = (p0.1.min(p1.1) - reach).clamp(0.0, H as f32) as usize;
        let hi = ((p0.1.max(p1.1) + reach).clamp(0.0, H as f32) as usize).max(lo);
        if hi == lo {
            continue;
        }
        let len = ((p1.0 - p0.0).powi(2) + (p1.1 - p0.1).powi(2)).sqrt();
        let cost = (len + 2.0 * reach) * 2.0 * reach;
        if !cost.is_finite() {
            continue;
        }
        let per = cost / (hi - lo) as f32;
        per_row[lo] += per;
        per_row[hi] -= per;
    }
    let mut running = 0.0;
    let cumulative: Vec<f32> = per_row[..H]
        .iter()
        .map(|d| {
            running += d;
            running.max(0.0)
        })
        .collect();
    let total: f32 = cumulative.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return H / 2;
    }
    let mut sum = 0.0;
    for (y, c) in cumulative.iter().enumerate() {
        sum += c;
        if sum >= total * top_share {
            return (y + 1).clamp(1, H - 1);
        }
    }
    H / 2
}

/// Seconds `f` took.
pub(super) fn timed(f: impl FnOnce()) -> f64 {
    let t = std::time::Instant::now();
    f();
    t.elapsed().as_secs_f64()
}

/// The share of a frame's estimated work that the top band gets, learnt from how
/// long the bands took. The estimate counts pixels; a pixel's cost depends on the
/// beams' directions and widths, and so on where the finger is, so in a grasp trial
/// the calling thread's band took up to half as long again as the other (1026 against
/// 669 µs a frame over a water trial). Correcting the share from the last frames'
/// times evens them out. Only the split moves: the bytes do not depend on it.
#[derive(Debug)]
pub(super) struct BandBalance(pub(super) AtomicU32);

impl Default for BandBalance {
    fn default() -> Self {
        Self(AtomicU32::new(0.5f32.to_bits()))
    }
}

impl Clone for BandBalance {
    fn clone(&self) -> Self {
        Self(AtomicU32::new(self.top_share().to_bits()))
    }
}

impl BandBalance {
    /// The share is kept within this much of a half.
    pub(super) const REACH: f32 = 0.3;

    pub(super) fn top_share(&self) -> f32 {
        f32::from_bits(self.0.load(Ordering::Relaxed))
    }

    /// The bands split at `share` took `top_s` and `bottom_s` seconds.
    pub(super) fn learn(&self, share: f32, top_s: f64, bottom_s: f64) {
        let next = next_share(share, top_s, bottom_s);
        self.0.store(next.to_bits(), Ordering::Relaxed);
    }
}

/// The top band's next share, halfway from `share` towards the share at which bands
/// costing what these took per unit of estimated work would take equally long. A
/// time that is not a positive number (a band with nothing in it, a clock that did
/// not move) teaches nothing.
pub(super) fn next_share(share: f32, top_s: f64, bottom_s: f64) -> f32 {
    let (lo, hi) = (0.5 - BandBalance::REACH, 0.5 + BandBalance::REACH);
    let share = if share.is_finite() {
        share.clamp(lo, hi)
    } else {
        0.5
    };
    let positive = |t: f64| t.is_finite() && t > 0.0;
    if !(positive(top_s) && positive(bottom_s)) {
        return share;
    }
    // Seconds per unit of estimated work in each band.
    let top_rate = top_s / f64::from(share);
    let bottom_rate = bottom_s / f64::from(1.0 - share);
    let balanced = (bottom_rate / (top_rate + bottom_rate)) as f32;
    (share + 0.5 * (balanced - share)).clamp(lo, hi)
}
