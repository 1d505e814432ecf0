//! The image tare for a medium: what a lab can do with a real finger to let a model
//! trained on land read water frames without any water label. Frames of the finger at
//! rest (no contact) in the new medium are compared with the rest frames of the runs
//! the model learned from, and a correction is fitted: a scale about the principal
//! point (a flat port's refraction magnifies the image by the water's index, about
//! 1.33), a gain and offset per channel (the water's attenuation and veiling light)
//! and a gain per pixel. A model that reads chroma gets one gain for the three
//! channels ([`TareGains::White`]), so white light added in the water stays white.
//! The correction is applied to each raw frame before preprocessing.
//!
//! The fit: the rest frames of each side are averaged (the camera's noise cancels);
//! for each scale on a grid from [`SCALE_RANGE`] the best gain and offset per channel
//! are the least-squares line between the corrected water mean and the land mean,
//! and the scale whose residual is least is refined by golden-section search. It runs
//! on the means shrunk [`FIT_SHRINK`]× (a few ms).

use serde::{Deserialize, Serialize};

mod prepared;
pub use prepared::PreparedTare;

/// The scales tried: from a frame shrunk 2× to one magnified 2×.
pub const SCALE_RANGE: (f64, f64) = (0.5, 2.0);
/// Grid step of the first search over the scale.
const SCALE_STEP: f64 = 0.01;
/// The means are shrunk this many times per side (box filter) before the fit.
const FIT_SHRINK: usize = 4;
/// A scale is judged on the pixels whose source lies inside the frame: at least this
/// share of them, or the scale is not considered.
const MIN_INSIDE: f64 = 0.25;

/// How the tare's gains are fitted: what it must leave unchanged decides it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TareGains {
    /// A gain per channel and a gain map per channel: the closest colours, for a
    /// model that reads brightness.
    #[default]
    PerChannel,
    /// One gain for the three channels and one map value per pixel, the map fitted
    /// on chroma (max − min), for a model that reads chroma: white light added in
    /// the water (caustics) stays white, so chroma stays blind to it. Gains that
    /// differ per channel would tint it (R 1.44 against B 0.81 for the shipped
    /// water: 0.6 of the light's crest in chroma).
    White,
}

impl TareGains {
    /// The gains a model whose input carries `signal` needs.
    #[must_use]
    pub fn for_signal(signal: super::Signal) -> Self {
        match signal {
            super::Signal::Brightness => Self::PerChannel,
            super::Signal::Chroma => Self::White,
        }
    }
}

/// A correction of raw RGB8 frames: output pixel `p` takes the input at
/// `principal_px + (p − principal_px) · scale` (bilinear; black outside the frame),
/// then `gain[c] · v + offset[c]` per channel, rounded and clamped to 0..=255.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageTare {
    /// Magnification undone (the water frame's, relative to land), dimensionless.
    pub scale: f64,
    /// The point the scale is about (the image centre: the renderer's and a centred
    /// port's principal point), px, pixel centres at `i + 0.5`.
    pub principal_px: [f64; 2],
    /// Per-channel gain (R, G, B).
    pub gain: [f64; 3],
    /// Per-channel offset (R, G, B), in 0–255 units.
    pub offset: [f64; 3],
    /// What is left per pixel after the global gain and offset, where the finger is
    /// at rest (a flat field: the water's attenuation grows with each pixel's light
    /// path, which a global gain cannot follow); `None`: none fitted.
    pub gain_map: Option<GainMap>,
}

/// A gain per pixel and channel on a coarse grid (the frame shrunk `shrink`×),
/// sampled bilinearly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GainMap {
    pub shrink: usize,
    pub width: usize,
    pub height: usize,
    /// RGB triples, row-major.
    pub gains: Vec<f32>,
}

impl ImageTare {
    /// The correction that changes nothing, for a frame `width × height`.
    #[must_use]
    pub fn identity(width: usize, height: usize) -> Self {
        Self {
            scale: 1.0,
            principal_px: [width as f64 / 2.0, height as f64 / 2.0],
            gain: [1.0; 3],
            offset: [0.0; 3],
            gain_map: None,
        }
    }

    /// One line for people: `scale 1.333 about (320, 240) px, gain R 1.41 G 1.38 B
    /// 1.22, offset R −3.1 G −2.0 B −9.5, a gain map 160×120 (0.82–1.31)`.
    #[must_use]
    pub fn describe(&self) -> String {
        let map = self.gain_map.as_ref().map_or_else(String::new, |m| {
            let (lo, hi) = m
                .gains
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
                    (lo.min(g), hi.max(g))
                });
            format!(", a gain map {}×{} ({lo:.2}–{hi:.2})", m.width, m.height)
        });
        format!(
            "scale {:.4} about ({:.0}, {:.0}) px, gain R {:.3} G {:.3} B {:.3}, offset R {:+.1} G {:+.1} B {:+.1}{map}",
            self.scale,
            self.principal_px[0],
            self.principal_px[1],
            self.gain[0],
            self.gain[1],
            self.gain[2],
            self.offset[0],
            self.offset[1],
            self.offset[2]
        )
    }

    /// Corrects an RGB8 frame (`width × height × 3`, row-major) into a new one of the
    /// same size.
    ///
    /// # Errors
    /// A buffer of another size than the frame's, an empty frame, or a tare whose
    /// numbers are not finite.
    pub fn apply(&self, width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>, TareError> {
        check_frame(width, height, rgb.len())?;
        let mut out = Vec::new();
        PreparedTare::new(self, width, height)?.apply_into(width, height, rgb, &mut out)?;
        Ok(out)
    }

    fn check(&self) -> Result<(), TareError> {
        let all = [self.scale, self.principal_px[0], self.principal_px[1]]
            .into_iter()
            .chain(self.gain)
            .chain(self.offset);
        let map_bad = self
            .gain_map
            .as_ref()
            .is_some_and(|m| m.gains.iter().any(|g| !g.is_finite() || *g < 0.0));
        if all.into_iter().any(|v| !v.is_finite()) || self.scale <= 0.0 || map_bad {
            return Err(TareError::Invalid(format!(
                "{self:?}: expected finite numbers and a positive scale"
            )));
        }
        Ok(())
    }

    /// Where output pixel (x, y) reads from, in a frame shrunk `shrink`× (pixel
    /// coordinates whose centres are integers).
    fn source(&self, x: usize, y: usize, shrink: f64) -> (f64, f64) {
        let [cx, cy] = [self.principal_px[0] / shrink, self.principal_px[1] / shrink];
        (
            cx + (x as f64 + 0.5 - cx) * self.scale - 0.5,
            cy + (y as f64 + 0.5 - cy) * self.scale - 0.5,
        )
    }
}

impl GainMap {
    /// The map as a plane over a `width × height` frame, and its shrink.
    fn plane(&self, width: usize, height: usize) -> Result<(Plane, f64), TareError> {
        if self.shrink == 0
            || self.width == 0
            || self.height == 0
            || self.gains.len() != self.width * self.height * 3
            || width / self.shrink != self.width
            || height / self.shrink != self.height
        {
            return Err(TareError::Size(format!(
                "a gain map of {}×{} (shrink {}, {} gains) for a {width}×{height} frame: it was fitted on frames of another size",
                self.width,
                self.height,
                self.shrink,
                self.gains.len()
            )));
        }
        Ok((
            Plane {
                width: self.width,
                height: self.height,
                data: self.gains.clone(),
            },
            self.shrink as f64,
        ))
    }
}

/// One rest frame: raw RGB8, `width × height × 3`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RestFrame {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
}

/// A fitted tare and how well it fits.
#[derive(Debug, Clone, PartialEq)]
pub struct TareFit {
    pub tare: ImageTare,
    /// RMS difference, 0–255 units over the three channels, between the land mean
    /// and the water mean as it is, and corrected by the scale, gain and offset; on
    /// the pixels the corrected frame sees (shrunk [`FIT_SHRINK`]×) that are the
    /// finger's in the land mean (all of them without a `keep`).
    pub rms_before: f64,
    pub rms_after: f64,
    /// The same with the gain map too (0 where it holds at rest by construction, up
    /// to its clamp).
    pub rms_after_map: f64,
    /// Rest frames averaged on each side.
    pub land_frames: usize,
    pub water_frames: usize,
}

/// Why no tare.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TareError {
    #[error("no {0} rest frames: a tare needs at least one on each side")]
    NoFrames(&'static str),
    #[error("{0}")]
    Size(String),
    /// Rest frames with no structure to match (a lens cap, a dead camera).
    #[error(
        "the {0} rest frames are flat (every pixel alike): nothing to fit a scale to; is the camera capped or dark?"
    )]
    Flat(&'static str),
    #[error("invalid tare {0}")]
    Invalid(String),
}

fn check_frame(width: usize, height: usize, len: usize) -> Result<(), TareError> {
    if width == 0 || height == 0 {
        return Err(TareError::Size(format!(
            "a {width}×{height} frame: expected a non-empty image"
        )));
    }
    if len != width * height * 3 {
        return Err(TareError::Size(format!(
            "a frame buffer of {len} bytes: a {width}×{height} RGB8 frame has {}",
            width * height * 3
        )));
    }
    Ok(())
}

/// An image of f32 RGB triples.
struct Plane {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl Plane {
    /// The mean of `frames` shrunk `k`× per side (box filter; a last partial box
    /// dropped).
    fn mean_shrunk(frames: &[RestFrame], k: usize) -> Self {
        let (w, h) = (frames[0].width, frames[0].height);
        let (sw, sh) = ((w / k).max(1), (h / k).max(1));
        let mut data = vec![0f64; sw * sh * 3];
        for f in frames {
            for y in 0..(sh * k).min(h) {
                for x in 0..(sw * k).min(w) {
                    let at = ((y / k) * sw + x / k) * 3;
                    for c in 0..3 {
                        data[at + c] += f64::from(f.rgb[(y * w + x) * 3 + c]);
                    }
                }
            }
        }
        let per = (frames.len() * k.min(w) * k.min(h)) as f64;
        Self {
            width: sw,
            height: sh,
            data: data.iter().map(|v| (v / per) as f32).collect(),
        }
    }

    fn at(&self, x: usize, y: usize) -> [f32; 3] {
        let i = (y * self.width + x) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Bilinear sample at (sx, sy), pixel centres at integers; black beyond the
    /// frame's edge pixels' centres by more than half a pixel.
    fn bilinear(&self, sx: f64, sy: f64) -> [f32; 3] {
        self.inside(sx, sy).map_or([0.0; 3], |(x0, y0, fx, fy)| {
            let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
            let (a, b, c, d) = (
                self.at(x0, y0),
                self.at(x1, y0),
                self.at(x0, y1),
                self.at(x1, y1),
            );
            std::array::from_fn(|k| {
                let top = a[k] + (b[k] - a[k]) * fx;
                let bottom = c[k] + (d[k] - c[k]) * fx;
                top + (bottom - top) * fy
            })
        })
    }

    /// The cell (x0, y0) and fractions of a sample point inside the frame.
    fn inside(&self, sx: f64, sy: f64) -> Option<(usize, usize, f32, f32)> {
        let (w, h) = (self.width as f64, self.height as f64);
        if !(sx >= -0.5 && sx <= w - 0.5 && sy >= -0.5 && sy <= h - 0.5) {
            return None;
        }
        let (cx, cy) = (sx.clamp(0.0, w - 1.0), sy.clamp(0.0, h - 1.0));
        let (x0, y0) = (cx.floor() as usize, cy.floor() as usize);
        Some((x0, y0, (cx - x0 as f64) as f32, (cy - y0 as f64) as f32))
    }

    /// Whether each channel holds one value everywhere, within a 0–255 unit.
    fn is_flat(&self) -> bool {
        (0..3).all(|c| {
            let (lo, hi) = self.data[c..]
                .iter()
                .step_by(3)
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                });
            hi - lo < 1.0
        })
    }
}

/// The best gain and offset per channel at `scale`, and the RMS residual with them
/// and without any correction (`None`: too few pixels inside the frame).
fn fit_at(
    land: &Plane,
    water: &Plane,
    scale: f64,
    mask: Option<&[bool]>,
    gains: TareGains,
) -> Option<([f64; 3], [f64; 3], f64, f64)> {
    let mut t = ImageTare::identity(land.width * FIT_SHRINK, land.height * FIT_SHRINK);
    t.scale = scale;
    // Per channel: n, Σx, Σy, Σxx, Σxy, Σyy (x the corrected water, y the land); and
    // Σ(land − water as it is)² on the same pixels.
    let mut s = [[0f64; 6]; 3];
    let mut raw = 0f64;
    for y in 0..land.height {
        for x in 0..land.width {
            let (sx, sy) = t.source(x, y, FIT_SHRINK as f64);
            if water.inside(sx, sy).is_none() || mask.is_some_and(|m| !m[y * land.width + x]) {
                continue;
            }
            let v = water.bilinear(sx, sy);
            let l = land.at(x, y);
            let w0 = water.at(x.min(water.width - 1), y.min(water.height - 1));
            for c in 0..3 {
                let (a, b) = (f64::from(v[c]), f64::from(l[c]));
                let e = &mut s[c];
                e[0] += 1.0;
                e[1] += a;
                e[2] += b;
                e[3] += a * a;
                e[4] += a * b;
                e[5] += b * b;
                raw += (b - f64::from(w0[c])).powi(2);
            }
        }
    }
    let n = s[0][0];
    let enough = match mask {
        Some(m) => MIN_INSIDE * m.iter().filter(|&&k| k).count() as f64,
        None => MIN_INSIDE * (land.width * land.height) as f64,
    };
    if n < enough.max(1.0) {
        return None;
    }
    let (mut gain, mut offset, mut sse) = ([1.0; 3], [0.0; 3], 0.0);
    // One gain for all: the pooled line of the three channels, each its own offset.
    let pooled = |f: fn(&[f64; 6]) -> f64| s.iter().map(f).sum::<f64>();
    let var_all = pooled(|e| e[3] - e[1] * e[1] / e[0]);
    let cov_all = pooled(|e| e[4] - e[1] * e[2] / e[0]);
    for c in 0..3 {
        let [n, sx, sy, sxx, sxy, syy] = s[c];
        let (var_x, cov) = match gains {
            TareGains::PerChannel => (sxx - sx * sx / n, sxy - sx * sy / n),
            TareGains::White => (var_all / 3.0, cov_all / 3.0),
        };
        // A channel with no spread in the water frame (flat at this scale): an offset
        // alone.
        let g = if var_x > 1e-9 * n { cov / var_x } else { 0.0 };
        let o = (sy - g * sx) / n;
        // Σ(y − g·x − o)² expanded.
        let e = syy + g * g * sxx + o * o * n - 2.0 * g * sxy - 2.0 * o * sy + 2.0 * g * o * sx;
        (gain[c], offset[c]) = (g, o);
        sse += e.max(0.0);
    }
    Some((
        gain,
        offset,
        (sse / (3.0 * n)).sqrt(),
        (raw / (3.0 * n)).sqrt(),
    ))
}

/// Which colours are the finger's (the model's threshold, `Preprocess::is_finger`).
pub type Keep<'a> = &'a (dyn Fn(u8, u8, u8) -> bool + Sync);

/// Fits the tare that maps the `water` rest frames onto the `land` ones (both of one
/// size, any number of each): the scale on every pixel, the gain and offset and the
/// gain map on the pixels whose land mean colour `keep` takes (the finger's: the
/// only pixels a model reads; every pixel without `keep`, or where fewer than 1 %
/// are kept).
///
/// # Errors
/// No frames on a side, frames of different sizes or with wrong buffers, flat frames.
pub fn fit_image_tare(
    land: &[RestFrame],
    water: &[RestFrame],
    keep: Option<Keep<'_>>,
    gains: TareGains,
) -> Result<TareFit, TareError> {
    if land.is_empty() {
        return Err(TareError::NoFrames("land"));
    }
    if water.is_empty() {
        return Err(TareError::NoFrames("water"));
    }
    let (w, h) = (land[0].width, land[0].height);
    for (side, frames) in [("land", land), ("water", water)] {
        for (i, f) in frames.iter().enumerate() {
            check_frame(f.width, f.height, f.rgb.len())
                .map_err(|e| TareError::Size(format!("{side} rest frame {}: {e}", i + 1)))?;
            if (f.width, f.height) != (w, h) {
                return Err(TareError::Size(format!(
                    "{side} rest frame {} is {}×{} px, the first land one {w}×{h}: a tare compares frames of one camera",
                    i + 1,
                    f.width,
                    f.height
                )));
            }
        }
    }
    let k = FIT_SHRINK.min(w).min(h);
    let (l, m) = (Plane::mean_shrunk(land, k), Plane::mean_shrunk(water, k));
    if l.is_flat() {
        return Err(TareError::Flat("land"));
    }
    if m.is_flat() {
        return Err(TareError::Flat("water"));
    }
    let cost = |s: f64| fit_at(&l, &m, s, None, gains).map_or(f64::INFINITY, |f| f.2);
    let steps = ((SCALE_RANGE.1 - SCALE_RANGE.0) / SCALE_STEP).round() as usize;
    let grid = (0..=steps).map(|i| SCALE_RANGE.0 + i as f64 * SCALE_STEP);
    let best = grid.fold((1.0, f64::INFINITY), |b, s| {
        let c = cost(s);
        if c < b.1 { (s, c) } else { b }
    });
    // Golden-section search on the best grid cell's neighbours.
    let (mut a, mut b) = (best.0 - SCALE_STEP, best.0 + SCALE_STEP);
    let phi = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..30 {
        let (c, d) = (b - phi * (b - a), a + phi * (b - a));
        if cost(c) < cost(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let mid = (a + b) / 2.0;
    let scale = if cost(mid) <= best.1 { mid } else { best.0 };
    let mask: Option<Vec<bool>> = keep
        .map(|k| {
            (0..l.width * l.height)
                .map(|i| {
                    let v = l.at(i % l.width, i / l.width);
                    let [r, g, b] = v.map(|c| c.round().clamp(0.0, 255.0) as u8);
                    k(r, g, b)
                })
                .collect::<Vec<bool>>()
        })
        .filter(|m| m.iter().filter(|&&k| k).count() * 100 >= m.len());
    let (gain, offset, rms_after, rms_before) = fit_at(&l, &m, scale, mask.as_deref(), gains)
        .or_else(|| fit_at(&l, &m, scale, None, gains))
        .ok_or(TareError::Flat("water"))?;
    let mut tare = ImageTare::identity(w, h);
    (tare.scale, tare.gain, tare.offset) = (scale, gain, offset);
    let map = gain_map(&l, &m, &tare, k, mask.as_deref(), gains);
    tare.gain_map = Some(map);
    let rms_after_map = residual(&l, &m, &tare, k, mask.as_deref());
    Ok(TareFit {
        tare,
        rms_before,
        rms_after,
        rms_after_map,
        land_frames: land.len(),
        water_frames: water.len(),
    })
}

/// The water mean (shrunk `k`×) corrected by `tare`'s scale, gain, offset and map
/// at shrunk pixel (x, y); `None` outside what the water frame saw.
fn corrected(water: &Plane, tare: &ImageTare, k: usize, x: usize, y: usize) -> Option<[f64; 3]> {
    let (sx, sy) = tare.source(x, y, k as f64);
    water.inside(sx, sy)?;
    let v = water.bilinear(sx, sy);
    let m = tare.gain_map.as_ref().map_or([1.0; 3], |g| {
        let i = (y * g.width + x) * 3;
        [g.gains[i], g.gains[i + 1], g.gains[i + 2]]
    });
    Some(std::array::from_fn(|c| {
        (tare.gain[c] * f64::from(v[c]) + tare.offset[c]) * f64::from(m[c])
    }))
}

/// The gain map: per shrunk pixel and channel, land over the globally corrected water
/// where the finger is (and both are brighter than [`MAP_FLOOR`]), else 1; clamped to
/// [`MAP_RANGE`] and smoothed over 3×3 pixels (the camera's noise, the edge's
/// rounding). With [`TareGains::White`], one ratio per pixel for its three channels:
/// land's chroma over the corrected water's.
fn gain_map(
    land: &Plane,
    water: &Plane,
    tare: &ImageTare,
    k: usize,
    mask: Option<&[bool]>,
    gains: TareGains,
) -> GainMap {
    let (w, h) = (land.width, land.height);
    let mut raw = vec![1f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            if mask.is_some_and(|m| !m[y * w + x]) {
                continue;
            }
            let Some(v) = corrected(water, tare, k, x, y) else {
                continue;
            };
            let l = land.at(x, y).map(f64::from);
            let chroma = |p: [f64; 3]| {
                p.iter().copied().fold(f64::MIN, f64::max)
                    - p.iter().copied().fold(f64::MAX, f64::min)
            };
            for c in 0..3 {
                let (a, b) = match gains {
                    TareGains::PerChannel => (v[c], l[c]),
                    TareGains::White => (chroma(v), chroma(l)),
                };
                if a > MAP_FLOOR && b > MAP_FLOOR {
                    raw[(y * w + x) * 3 + c] = (b / a).clamp(MAP_RANGE.0, MAP_RANGE.1) as f32;
                }
            }
        }
    }
    let mut gains = vec![1f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let (mut sum, mut n) = (0f32, 0f32);
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        sum += raw[(yy * w + xx) * 3 + c];
                        n += 1.0;
                    }
                }
                gains[(y * w + x) * 3 + c] = sum / n;
            }
        }
    }
    GainMap {
        shrink: k,
        width: w,
        height: h,
        gains,
    }
}

/// RMS of land − corrected water over the pixels the water saw and `mask` keeps.
fn residual(land: &Plane, water: &Plane, tare: &ImageTare, k: usize, mask: Option<&[bool]>) -> f64 {
    let (mut sse, mut n) = (0f64, 0f64);
    for y in 0..land.height {
        for x in 0..land.width {
            if mask.is_some_and(|m| !m[y * land.width + x]) {
                continue;
            }
            if let Some(v) = corrected(water, tare, k, x, y) {
                let l = land.at(x, y);
                for c in 0..3 {
                    sse += (f64::from(l[c]) - v[c].clamp(0.0, 255.0)).powi(2);
                    n += 1.0;
                }
            }
        }
    }
    if n > 0.0 { (sse / n).sqrt() } else { 0.0 }
}

/// Below this (0–255) a pixel is too dark for its ratio to mean anything.
const MAP_FLOOR: f64 = 8.0;
/// The gain map's clamp.
const MAP_RANGE: (f64, f64) = (0.25, 4.0);

#[cfg(test)]
mod tests;
