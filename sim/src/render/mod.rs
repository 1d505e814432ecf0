//! The in-finger camera's view: a pinhole camera under the finger's base looking
//! along the finger, lit by the finger's LEDs, seeing the lattice beams (drawn as
//! thick anti-aliased lines, far to near) against a precomputed background seen
//! through the translucent finger.
//!
//! Cost model: everything that does not change between frames (background, clutter,
//! skin tint, per-effect tables) is computed once in [`Renderer::new`]; a frame is a
//! copy of the background, ~450 line rasterisations, and one pass per declared
//! per-pixel effect. Effects the scene does not declare are skipped by one branch.
//! The drawn lattice of the last frame is kept: a finger whose nodes have not moved
//! (at rest, or a steady hold) is not redrawn. A frame is made in two row bands, one
//! on the caller and one on [`crate::second_core`], each band start to end
//! (background, beams, then the effects written as its copy into the output, a few
//! rows at a time so that they run in cache); the bands split where the work (the
//! beams' pixels and each row's copies and effects) halves. The per-pixel effects are written as
//! straight runs over precomputed rows so that they vectorise.

use super::contact::FingerGeometry;
use super::effects::ImageEffects;
use super::lattice::{BeamKind, Deformed, Lattice};
use super::rng;
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

mod bands;
use bands::*;
mod frame;
pub(crate) use frame::FrameBuffers;
use frame::*;
mod raster;
use raster::*;

/// Frame width, px.
pub const WIDTH: u32 = 640;
/// Frame height, px.
pub const HEIGHT: u32 = 480;
const W: usize = WIDTH as usize;
const H: usize = HEIGHT as usize;

/// Focal length of the in-finger camera, px.
const FOCAL_PX: f64 = 720.0;
/// Distance of the camera under the finger's base, m.
const CAMERA_BELOW_BASE_M: f64 = 0.040;
/// Distance of the background seen through the finger, m.
const BACKGROUND_M: f64 = 0.25;
/// Distance at which the LEDs light a beam at nominal brightness, m.
const LED_REF_M: f64 = 0.035;
/// Scale of the veiling light's growth with distance (turbidity), m.
const TURBIDITY_M: f64 = 0.08;
/// Offsets a frame's camera noise can start at: the table holds this many values
/// beyond one frame's worth, and each frame reads one frame's worth from a random
/// offset (a straight run, so the add vectorises; no frame sees a value twice).
const NOISE_OFFSETS: usize = 1 << 18;

/// The finger's material colour (orange silicone), far from any background colour:
/// a colour threshold keeps pixels with R > 150 and R − B > 90.
pub const FINGER_RGB: [u8; 3] = [255, 140, 36];

/// Precomputed state of the renderer of one scene.
#[derive(Debug, Clone)]
pub(crate) struct Renderer {
    effects: ImageEffects,
    seed: u64,
    focal: f64,
    z_cam: f64,
    background: Arc<[u8]>,
    caustic: Option<Caustic>,
    noise: Option<NoiseTable>,
    exposure: Option<[u8; 256]>,
    drawn: DrawnCache,
    balance: BandBalance,
}

/// The caustic pattern: a `period`-pixel square tile, stored as RGB rows of
/// `W + period` pixels (the tile repeated), so that any horizontal shift of a row is
/// one contiguous slice of `3·W` bytes.
#[derive(Debug, Clone)]
struct Caustic {
    rows: Vec<u8>,
    period: usize,
    period_px: f32,
}

impl Caustic {
    const ROW: usize = W * 3;

    fn new(strength: f64, period_px: f64) -> Self {
        let p = (period_px.round() as usize).clamp(2, 1024);
        let k = std::f64::consts::TAU / p as f64;
        let stride = (W + p) * 3;
        let mut rows = vec![0u8; p * stride];
        for y in 0..p {
            for x in 0..W + p {
                let (fx, fy) = ((x % p) as f64 * k, y as f64 * k);
                let a = 0.5 + 0.5 * (fx + 0.9 * (fy + 0.5).sin()).cos();
                let b = 0.5 + 0.5 * (fy + 0.9 * (fx * 1.0 + 1.3).sin()).cos();
                let v = ((a * b).powi(3) * strength * 255.0)
                    .round()
                    .clamp(0.0, 255.0) as u8;
                rows[y * stride + x * 3..y * stride + x * 3 + 3].fill(v);
            }
        }
        Self {
            rows,
            period: p,
            period_px: period_px as f32,
        }
    }

    /// Row `y` of the pattern shifted by `ox` pixels: `3·W` bytes.
    fn row(&self, y: usize, ox: usize) -> &[u8] {
        let start = y * (W + self.period) * 3 + ox * 3;
        &self.rows[start..start + Self::ROW]
    }
}

/// The last drawn lattice (before the per-frame effects) and the nodes it was drawn
/// from. Shared by the threads that render with one renderer; a thread that finds it
/// busy draws without it.
#[derive(Debug, Default)]
struct DrawnCache(Mutex<Option<Drawn>>);

/// A drawn lattice and the nodes it was drawn from.
#[derive(Debug)]
struct Drawn {
    nodes: Vec<[f64; 3]>,
    image: Vec<u8>,
}

impl Clone for DrawnCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

/// Per-channel colour in 0–255, as floats.
type Rgb = [f32; 3];

impl Renderer {
    pub(crate) fn new(finger: &FingerGeometry, effects: &ImageEffects, seed: u64) -> Self {
        let focal = FOCAL_PX * effects.refraction_index.unwrap_or(1.0);
        let z_cam = finger.base_height_m - CAMERA_BELOW_BASE_M;
        let mut r = Self {
            effects: effects.clone(),
            seed,
            focal,
            z_cam,
            background: Arc::from([]),
            caustic: None,
            noise: None,
            exposure: None,
            drawn: DrawnCache::default(),
            balance: BandBalance::default(),
        };
        // The background and caustics beside the noise table (a new renderer per
        // grasp trial: about 10, 5 and 15–20 ms), from their own random streams.
        let (mut background, mut noise, mut caustic) = (Vec::new(), None, None);
        crate::second_core::join(
            || {
                background = r.make_background(finger);
                caustic = effects
                    .caustics
                    .map(|(strength, period)| Caustic::new(strength, period));
            },
            || {
                noise = effects.noise_sigma.map(|sigma| {
                    let mut g = rng::stream(seed, "camera-noise-table");
                    NoiseTable::new(
                        (0..NOISE_OFFSETS + W * H * 3)
                            .map(|_| {
                                let z: f64 = StandardNormal.sample(&mut g);
                                (z * sigma).round().clamp(-255.0, 255.0) as i16
                            })
                            .collect(),
                    )
                });
            },
        );
        (r.background, r.noise, r.caustic) = (background.into(), noise, caustic);
        if let Some(gain) = effects.exposure_gain {
            let mut lut = [0u8; 256];
            for (i, v) in lut.iter_mut().enumerate() {
                *v = (i as f64 * gain).round().clamp(0.0, 255.0) as u8;
            }
            r.exposure = Some(lut);
        }
        r
    }

    /// Colour after the light path `d` (m) through the medium, for declared effects.
    fn medium(&self, c: Rgb, d: f64) -> Rgb {
        self.medium_at(d).apply(c)
    }

    /// What the light path `d` (m) through the medium does to a colour: worked out
    /// once for a distance that many pixels share (the background's).
    fn medium_at(&self, d: f64) -> Medium {
        Medium {
            // LED → object → camera: twice the distance.
            attenuation: self
                .effects
                .attenuation_per_m
                .map(|k| k.map(|k| (-k * 2.0 * d).exp() as f32)),
            veil: self.effects.turbidity.map(|(b, veil)| {
                let v = (b * (1.0 - (-d / TURBIDITY_M).exp())) as f32;
                (v, veil.map(f32::from))
            }),
        }
    }

    fn make_background(&self, finger: &FingerGeometry) -> Vec<u8> {
        let mut bg = vec![0u8; W * H * 3];
        let mag = self.focal / FOCAL_PX;
        // A dim lab scene: vertical gradient with soft bands (computed once).
        let mut row_col = vec![[0f32; 3]; H];
        for (y, rc) in row_col.iter_mut().enumerate() {
            let v = ((y as f64 - H as f64 / 2.0) / mag + H as f64 / 2.0) / H as f64;
            *rc = [
                (30.0 + 18.0 * v) as f32,
                (44.0 + 22.0 * v) as f32,
                (62.0 + 30.0 * v) as f32,
            ];
        }
        let mut col_mod = vec![0f32; W];
        for (x, m) in col_mod.iter_mut().enumerate() {
            let u = ((x as f64 - W as f64 / 2.0) / mag + W as f64 / 2.0) / W as f64;
            *m = (0.9 + 0.1 * (u * 9.0).sin() * (u * 2.3).cos()) as f32;
        }
        let mut shapes: Vec<(f32, f32, f32, f32, bool, Rgb)> = Vec::new();
        if let Some(n) = self.effects.clutter_objects {
            let mut g = rng::stream(self.seed, "background-clutter");
            // Blues, greens, greys, purples: never the finger's orange.
            let palette: [Rgb; 6] = [
                [40.0, 70.0, 140.0],
                [50.0, 110.0, 70.0],
                [95.0, 95.0, 100.0],
                [80.0, 50.0, 120.0],
                [20.0, 25.0, 30.0],
                [60.0, 120.0, 130.0],
            ];
            for _ in 0..n {
                let cx = g.random_range(0.0..W as f32);
                let cy = g.random_range(0.0..H as f32);
                let hw = g.random_range(10.0..80.0f32);
                let hh = g.random_range(10.0..80.0f32);
                let round = g.random_bool(0.5);
                let c = palette[g.random_range(0..palette.len())];
                shapes.push((cx, cy, hw, hh, round, c));
            }
        }
        let (a0, b0, _, _) = finger.semi_axes(finger.base_height_m);
        let d0 = finger.base_height_m - self.z_cam;
        let (ea, eb) = ((self.focal * a0 / d0) as f32, (self.focal * b0 / d0) as f32);
        let (cx, cy) = (W as f32 / 2.0, H as f32 / 2.0);
        let skin = self.medium(FINGER_RGB.map(f32::from), 0.02);
        let through_water = self.medium_at(BACKGROUND_M);
        for y in 0..H {
            for x in 0..W {
                let mut c = row_col[y].map(|v| v * col_mod[x]);
                let (bx, by) = (
                    (x as f32 - cx) / mag as f32 + cx,
                    (y as f32 - cy) / mag as f32 + cy,
                );
                for &(sx, sy, hw, hh, round, sc) in &shapes {
                    let (dx, dy) = ((bx - sx) / hw, (by - sy) / hh);
                    let inside = if round {
                        dx * dx + dy * dy <= 1.0
                    } else {
                        dx.abs() <= 1.0 && dy.abs() <= 1.0
                    };
                    if inside {
                        c = sc;
                    }
                }
                c = through_water.apply(c);
                // Seen through the translucent skin inside the base ring.
                let (ex, ey) = ((x as f32 + 0.5 - cx) / eb, (y as f32 + 0.5 - cy) / ea);
                let e = ex * ex + ey * ey;
                let tint = if e < 1.0 { 0.22 * (1.0 - e * e) } else { 0.0 };
                let o = (y * W + x) * 3;
                for i in 0..3 {
                    bg[o + i] = (c[i] * (1.0 - tint) + skin[i] * tint)
                        .round()
                        .clamp(0.0, 255.0) as u8;
                }
            }
        }
        bg
    }

    pub(crate) fn background_copy(&self) -> Vec<u8> {
        self.background.to_vec()
    }

    /// The background, shared: what [`FrameBuffers::new`] copies.
    pub(crate) fn background(&self) -> Arc<[u8]> {
        Arc::clone(&self.background)
    }

    fn project(&self, p: [f64; 3]) -> Option<(f32, f32, f64)> {
        let d = p[2] - self.z_cam;
        if d.is_nan() || d <= 1e-4 {
            return None;
        }
        let u = W as f64 / 2.0 + self.focal * p[1] / d;
        let v = H as f64 / 2.0 + self.focal * p[0] / d;
        Some((u as f32, v as f32, d))
    }

    /// The finger at rest or deformed, with the per-frame effects of frame
    /// `frame_index` exposed at `t_s` seconds. Raw RGB8, 640×480.
    ///
    /// The frame is made in two row bands, one on [`crate::second_core`] (when there
    /// are two cores), each band start to end: background, beams, then the effects, written
    /// as the copy into the output. Every pixel gets the same operations in the same
    /// order as in one pass, so the bytes do not depend on the split.
    ///
    /// `buffers`, when given, hold this frame's canvas, made beforehand (see
    /// [`FrameBuffers`]); the bytes are the same either way.
    pub(crate) fn render(
        &self,
        lattice: &Lattice,
        deformed: &Deformed,
        frame_index: u64,
        t_s: f64,
        buffers: Option<FrameBuffers>,
    ) -> Vec<u8> {
        // The effects write every byte of the output, so any buffer of the frame's
        // size serves, zeroed or not.
        let fresh = || vec![0u8; W * H * 3];
        let canvas = buffers.map(|b| b.canvas).filter(|c| c.len() == W * H * 3);
        let effects = self.frame_effects(frame_index, t_s);
        let Ok(mut cache) = self.drawn.0.try_lock() else {
            // Another thread renders with this renderer: draw without the cache.
            return self.draw_anew(lattice, deformed, canvas, &effects).1;
        };
        match cache.as_mut() {
            // The same nodes, bit for bit: the same drawn lattice.
            Some(d) if d.nodes == deformed.nodes => {
                let mut out = canvas.unwrap_or_else(fresh);
                self.paint(&mut d.image, None, &mut out, &effects);
                out
            }
            Some(d) => {
                let lines = self.lines(lattice, deformed);
                d.nodes.clone_from(&deformed.nodes);
                // Drawn on the made canvas, which holds the background already, or on
                // the last drawn lattice, which each band first copies it over.
                let on_background = canvas.is_some();
                // The last drawn lattice, no longer needed, becomes the output.
                let mut out = match canvas {
                    Some(canvas) => std::mem::replace(&mut d.image, canvas),
                    None => fresh(),
                };
                self.paint(
                    &mut d.image,
                    Some((&lines, on_background)),
                    &mut out,
                    &effects,
                );
                out
            }
            None => {
                let (image, out) = self.draw_anew(lattice, deformed, canvas, &effects);
                *cache = Some(Drawn {
                    nodes: deformed.nodes.clone(),
                    image,
                });
                out
            }
        }
    }

    /// The lattice drawn on a new buffer (the made canvas when there is one) and the
    /// frame made from it: (drawn lattice, frame).
    fn draw_anew(
        &self,
        lattice: &Lattice,
        deformed: &Deformed,
        canvas: Option<Vec<u8>>,
        effects: &FrameEffects,
    ) -> (Vec<u8>, Vec<u8>) {
        let lines = self.lines(lattice, deformed);
        let on_background = canvas.is_some();
        let mut drawn = canvas.unwrap_or_else(|| vec![0u8; W * H * 3]);
        let mut out = vec![0u8; W * H * 3];
        self.paint(&mut drawn, Some((&lines, on_background)), &mut out, effects);
        (drawn, out)
    }

    /// Make a frame in two row bands. `lines`: draw them on the background into
    /// `drawn` first (copied into it, unless the flag says it holds it already);
    /// `None`: `drawn` already holds this frame's lattice. Then `out` gets `drawn`
    /// with the frame's effects.
    fn paint(
        &self,
        drawn: &mut [u8],
        lines: Option<(&[Line], bool)>,
        out: &mut [u8],
        effects: &FrameEffects,
    ) {
        // Split where the work is shared as the last frames' times say: the beams'
        // pixels, and the copies and effects that cost the same in every row. The
        // finger's near end, with the longest, widest beams, is rarely in the middle
        // of the frame.
        let share = self.balance.top_share();
        let split = lines.map_or(H / 2, |(lines, _)| split_row(lines, self.row_cost(), share));
        let band = |drawn: &mut [u8], out: &mut [u8], rows: (usize, usize)| {
            if let Some((lines, on_background)) = lines {
                if !on_background {
                    drawn.copy_from_slice(&self.background[rows.0 * W * 3..rows.1 * W * 3]);
                }
                let rows_i32 = (rows.0 as i32, rows.1 as i32);
                for &(p0, p1, half_w, c) in lines {
                    draw_line(drawn, rows_i32, p0, p1, half_w, c);
                }
            }
            self.effects_into(drawn, out, rows.0, effects);
        };
        let (d_top, d_bottom) = drawn.split_at_mut(split * W * 3);
        let (o_top, o_bottom) = out.split_at_mut(split * W * 3);
        // On the second core, kept awake between frames (a thread started per frame
        // began its band 140 µs late).
        let (mut top_s, mut bottom_s) = (0.0, 0.0);
        crate::second_core::join(
            || top_s = timed(|| band(d_top, o_top, (0, split))),
            || bottom_s = timed(|| band(d_bottom, o_bottom, (split, H))),
        );
        // Only frames that draw beams are split by their estimate.
        if lines.is_some() {
            self.balance.learn(share, top_s, bottom_s);
        }
    }

    /// What a row's copies and declared per-pixel effects cost, in beam pixels
    /// drawn (measured with `perf` on water grasp trials: a drawn beam pixel about
    /// 8 ns, a row's two copies about 100 ns, caustics or noise about 150 ns each).
    fn row_cost(&self) -> f32 {
        let per_pixel_effects = [
            self.caustic.is_some(),
            self.noise.is_some(),
            self.exposure.is_some(),
        ];
        13.0 + 20.0 * per_pixel_effects.iter().filter(|on| **on).count() as f32
    }

    /// The beams to draw, far to near as the lattice lists them: end points (px),
    /// half width (px) and colour.
    fn lines(&self, lattice: &Lattice, deformed: &Deformed) -> Vec<Line> {
        // A beam's colour takes a power and a few exponentials (2 % of a water grasp
        // trial's samples in `perf`, all on the caller): half the beams on each
        // core, in order.
        let (first, second) = lattice.beams.split_at(lattice.beams.len() / 2);
        let mut lines = Vec::with_capacity(lattice.beams.len());
        let mut rest = Vec::new();
        crate::second_core::join(
            || self.lines_of(first, deformed, &mut lines),
            || self.lines_of(second, deformed, &mut rest),
        );
        lines.append(&mut rest);
        lines
    }

    /// The visible ones of `beams` as drawn, appended to `lines`.
    fn lines_of(
        &self,
        beams: &[(usize, usize, BeamKind)],
        deformed: &Deformed,
        lines: &mut Vec<Line>,
    ) {
        let base = FINGER_RGB.map(f32::from);
        lines.reserve(beams.len());
        for &(i, j, kind) in beams {
            let (Some(a), Some(b)) = (
                self.project(deformed.nodes[i]),
                self.project(deformed.nodes[j]),
            ) else {
                continue;
            };
            // The cell walls of the metamaterial: rings, longitudinal and surface
            // diagonal beams. Spokes and inner diagonals carry load but are hidden
            // (they would only clutter the view), and so are the clamped base's.
            let (radius_m, shade) = match kind {
                BeamKind::Ring => (0.0008, 1.0),
                BeamKind::Longitudinal => (0.0006, 0.9),
                BeamKind::Diagonal => (0.0003, 0.75),
                BeamKind::Spoke | BeamKind::CrossDiagonal => continue,
            };
            let d = 0.5 * (a.2 + b.2);
            let half_w = ((self.focal * radius_m / d) as f32).clamp(0.5, 3.0);
            let light = ((LED_REF_M / d).powf(0.7).clamp(0.45, 1.2) * shade) as f32;
            let c = self.medium(base.map(|v| (v * light).min(255.0)), d);
            lines.push(((a.0, a.1), (b.0, b.1), half_w, c));
        }
    }

    /// Draw the lattice on `img`, a copy of the background (benchmarks and tests; a
    /// frame is [`Self::render`]).
    pub(crate) fn draw_lattice(&self, img: &mut [u8], lattice: &Lattice, deformed: &Deformed) {
        for &(p0, p1, half_w, c) in &self.lines(lattice, deformed) {
            draw_line(img, (0, H as i32), p0, p1, half_w, c);
        }
    }

    /// Apply frame `frame_index`'s effects to a whole frame in place (benchmarks).
    pub(crate) fn apply_effects(&self, img: &mut [u8], frame_index: u64, t_s: f64) {
        let drawn = img.to_vec();
        self.effects_into(&drawn, img, 0, &self.frame_effects(frame_index, t_s));
    }

    /// What the declared per-frame effects do in frame `frame_index` at `t_s`.
    fn frame_effects(&self, frame_index: u64, t_s: f64) -> FrameEffects {
        let caustic_offset = self.caustic.as_ref().map(|caustic| {
            let p = caustic.period;
            let shift = (t_s * 0.5 * f64::from(caustic.period_px)) as usize;
            (shift % p, (shift * 7 / 10) % p)
        });
        let mut bubbles = Vec::new();
        if let Some((per_frame, max_r)) = self.effects.bubbles {
            let slots = per_frame.ceil() as u64;
            let frac = per_frame - per_frame.floor();
            for slot in 0..slots {
                let mut g = rng::indexed(self.seed, "bubbles", slot);
                let alive = slot + 1 < slots || frac == 0.0 || g.random_bool(frac.clamp(0.0, 1.0));
                let u0 = g.random_range(0.0..W as f64);
                let v0 = g.random_range(0.0..H as f64);
                let r = g.random_range(0.3..=1.0) * max_r;
                let speed = g.random_range(40.0..160.0);
                if !alive {
                    continue;
                }
                let span = H as f64 + 4.0 * max_r;
                let v = (v0 - speed * t_s).rem_euclid(span) - 2.0 * max_r;
                let u = u0 + 6.0 * (t_s * 2.0 + slot as f64).sin();
                bubbles.push((u as f32, v as f32, r as f32));
            }
        }
        let noise_start = self.noise.as_ref().map(|_| {
            let mut g = rng::indexed(self.seed, "camera-noise", frame_index);
            g.random_range(0..NOISE_OFFSETS)
        });
        FrameEffects {
            caustic_offset,
            bubbles,
            noise_start,
        }
    }

    /// `out` = rows `y0..` of `drawn` with the frame's effects, in their order:
    /// caustics (as the copy), bubbles, exposure, noise. A few rows at a time, so
    /// the passes after the first find their bytes in cache.
    fn effects_into(&self, drawn: &[u8], out: &mut [u8], y0: usize, fx: &FrameEffects) {
        const ROWS: usize = 16;
        const ROW: usize = W * 3;
        for (i, (src, dst)) in drawn
            .chunks(ROWS * ROW)
            .zip(out.chunks_mut(ROWS * ROW))
            .enumerate()
        {
            let first = y0 + i * ROWS;
            let rows = (first, first + dst.len() / ROW);
            match (&self.caustic, fx.caustic_offset) {
                (Some(caustic), Some((ox, oy))) => {
                    let p = caustic.period;
                    for (y, (s, d)) in src
                        .chunks_exact(ROW)
                        .zip(dst.chunks_exact_mut(ROW))
                        .enumerate()
                    {
                        let add = caustic.row((rows.0 + y + oy) % p, ox);
                        for ((d, &s), &a) in d.iter_mut().zip(s).zip(add) {
                            *d = s.saturating_add(a);
                        }
                    }
                }
                _ => dst.copy_from_slice(src),
            }
            for &(u, v, r) in &fx.bubbles {
                draw_bubble(dst, rows, u, v, r);
            }
            if let Some(lut) = &self.exposure {
                for v in dst.iter_mut() {
                    *v = lut[usize::from(*v)];
                }
            }
            if let (Some(table), Some(start)) = (&self.noise, fx.noise_start) {
                table.add_to(dst, start + rows.0 * ROW);
            }
        }
    }
}

#[cfg(test)]
mod tests;
