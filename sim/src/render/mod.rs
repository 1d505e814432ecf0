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

/// The camera noise, in whole levels, from which each frame reads one frame's worth
/// at its offset. A frame reads a megabyte or two of it, mostly from memory rather
/// than cache: one byte a value where every value fits (a σ of a few levels), else two.
#[derive(Debug, Clone)]
enum NoiseTable {
    Narrow(Vec<i8>),
    Wide(Vec<i16>),
}

impl NoiseTable {
    fn new(levels: Vec<i16>) -> Self {
        let narrow: Option<Vec<i8>> = levels.iter().map(|&v| i8::try_from(v).ok()).collect();
        match narrow {
            Some(narrow) => Self::Narrow(narrow),
            None => Self::Wide(levels),
        }
    }

    /// Add the table from `at` on to `dst`, saturating at 0 and 255.
    fn add_to(&self, dst: &mut [u8], at: usize) {
        match self {
            Self::Narrow(table) => add_levels(dst, &table[at..at + dst.len()]),
            Self::Wide(table) => add_levels(dst, &table[at..at + dst.len()]),
        }
    }
}

/// `dst` + `levels`, saturating at 0 and 255: one loop, compiled for each width.
fn add_levels<T: Copy + Into<i16>>(dst: &mut [u8], levels: &[T]) {
    for (v, &n) in dst.iter_mut().zip(levels) {
        *v = (i16::from(*v) + n.into()).clamp(0, 255) as u8;
    }
}

/// The medium's effect along one light path: per-channel attenuation, then the veil
/// of scattered light (its weight and colour), each when declared.
#[derive(Debug, Clone, Copy)]
struct Medium {
    attenuation: Option<[f32; 3]>,
    veil: Option<(f32, Rgb)>,
}

impl Medium {
    fn apply(&self, mut c: Rgb) -> Rgb {
        if let Some(a) = self.attenuation {
            for i in 0..3 {
                c[i] *= a[i];
            }
        }
        if let Some((v, veil)) = self.veil {
            for i in 0..3 {
                c[i] = c[i] * (1.0 - v) + veil[i] * v;
            }
        }
        c
    }
}

/// A copy of the background to draw a frame's lattice on, made before the frame's
/// nodes are known: a grasp camera makes it on the second core while the caller
/// works out the finger's contact and lattice, so the copy is off the caller's path.
/// The lattice it replaces becomes the frame's output, so no output is zeroed either.
#[derive(Debug)]
pub(crate) struct FrameBuffers {
    canvas: Vec<u8>,
}

impl FrameBuffers {
    /// The canvas for a renderer whose [`Renderer::background`] is `background`.
    pub(crate) fn new(background: &[u8]) -> Self {
        Self {
            canvas: background.to_vec(),
        }
    }
}

/// One beam as drawn: end points (px), half width (px), colour.
type Line = ((f32, f32), (f32, f32), f32, Rgb);

/// What the declared effects do in one frame: the caustics' shift (px), the bubbles
/// (centre and radius, px) and where the frame's camera noise starts in the table.
#[derive(Debug)]
struct FrameEffects {
    caustic_offset: Option<(usize, usize)>,
    bubbles: Vec<(f32, f32, f32)>,
    noise_start: Option<usize>,
}

/// The row above which lies `top_share` of a frame's estimated work (a half:
/// 0.5): each beam's pixels (length × width) spread evenly over the rows it spans,
/// plus `row_cost` (in beam pixels) in every row for the copies and effects. The
/// first row of the lower band, in `1..H`.
fn split_row(lines: &[Line], row_cost: f32, top_share: f32) -> usize {
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
fn timed(f: impl FnOnce()) -> f64 {
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
struct BandBalance(AtomicU32);

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
    const REACH: f32 = 0.3;

    fn top_share(&self) -> f32 {
        f32::from_bits(self.0.load(Ordering::Relaxed))
    }

    /// The bands split at `share` took `top_s` and `bottom_s` seconds.
    fn learn(&self, share: f32, top_s: f64, bottom_s: f64) {
        let next = next_share(share, top_s, bottom_s);
        self.0.store(next.to_bits(), Ordering::Relaxed);
    }
}

/// The top band's next share, halfway from `share` towards the share at which bands
/// costing what these took per unit of estimated work would take equally long. A
/// time that is not a positive number (a band with nothing in it, a clock that did
/// not move) teaches nothing.
fn next_share(share: f32, top_s: f64, bottom_s: f64) -> f32 {
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

/// Blend `c` into pixel `(x, y)` with coverage `a`.
#[inline]
fn blend(img: &mut [u8], x: i32, y: i32, c: Rgb, a: f32) {
    if x < 0 || y < 0 || x >= W as i32 || y >= H as i32 || a <= 0.0 {
        return;
    }
    let o = (y as usize * W + x as usize) * 3;
    for i in 0..3 {
        let p = f32::from(img[o + i]);
        // `as u8` saturates; +0.5 rounds.
        img[o + i] = (p + (c[i] - p) * a + 0.5) as u8;
    }
}

/// `x.floor()` as an integer, without the libm call that `floor` is on baseline
/// x86-64 (no SSE4.1). Saturates far outside `i32`, as `as` does.
#[inline]
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_sub(i32::from((t as f32) > x))
}

/// `x.ceil()` as an integer (see [`floor_i32`]).
#[inline]
fn ceil_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_add(i32::from((t as f32) < x))
}

/// Blend `solid` into the pixel at byte offset `o` with coverage `a` in (0, 1), in
/// integers (coverage in 1/256ths): within one level of [`blend`], at a fraction of
/// its cost. The line rasteriser clips to its band, so `o` is always inside it.
#[inline]
fn blend_at(img: &mut [u8], o: usize, solid: [u8; 3], a: f32) {
    blend_256(&mut img[o..o + 3], solid, coverage_256(a));
}

/// A coverage in [0, 1] in 1/256ths, as [`blend_at`] works it out (256: the
/// colour itself, 0: no change).
#[inline(always)]
fn coverage_256(cov: f32) -> i32 {
    (cov * 256.0) as i32
}

/// Blend `solid` into the pixel `px` (3 bytes) with coverage `a` in 1/256ths.
#[inline(always)]
fn blend_256(px: &mut [u8], solid: [u8; 3], a: i32) {
    for (p, &c) in px.iter_mut().zip(&solid) {
        let v = i32::from(*p);
        *p = (v + (((i32::from(c) - v) * a + 128) >> 8)) as u8;
    }
}

/// A thick anti-aliased segment: walks the major axis and, for each column, covers
/// the pixels of the band around the line by their perpendicular distance to it
/// (exact distance to the segment only past its ends). No trigonometry per pixel.
fn draw_line(
    band: &mut [u8],
    rows: (i32, i32),
    p0: (f32, f32),
    p1: (f32, f32),
    half_w: f32,
    c: Rgb,
) {
    let (dx, dy) = (p1.0 - p0.0, p1.1 - p0.1);
    if dx.abs() >= dy.abs() {
        draw_line_along::<true>(band, rows, p0, p1, half_w, c);
    } else {
        draw_line_along::<false>(band, rows, p0, p1, half_w, c);
    }
}

/// [`draw_line`] along the x axis or the y axis: one copy of the walk for each, so
/// that the step from one pixel of a column to the next is a constant.
#[inline(always)]
fn draw_line_along<const X_MAJOR: bool>(
    band: &mut [u8],
    (y0, y1): (i32, i32),
    p0: (f32, f32),
    p1: (f32, f32),
    half_w: f32,
    c: Rgb,
) {
    let x_major = X_MAJOR;
    // Swap axes so the walk is always along the major axis ("a").
    let (a0, b0, a1, b1) = if x_major {
        (p0.0, p0.1, p1.0, p1.1)
    } else {
        (p0.1, p0.0, p1.1, p1.0)
    };
    let (da, db) = (a1 - a0, b1 - b0);
    let len2 = da * da + db * db;
    let inv_len2 = 1.0 / len2;
    // A segment this short is a dot: its caps measure from its first end.
    let degenerate = len2 <= 1e-12;
    let slope = if da.abs() > 1e-6 { db / da } else { 0.0 };
    let norm = (1.0 + slope * slope).sqrt();
    let inv_norm = 1.0 / norm;
    let reach = half_w + 1.0;
    let across = reach * norm + 0.5;
    let (amin, amax) = (a0.min(a1), a0.max(a1));
    // The band holds rows y0..y1: y is b when x is major, a otherwise.
    let (a_range, b_range) = if x_major {
        ((0, W as i32), (y0, y1))
    } else {
        ((y0, y1), (0, W as i32))
    };
    // Byte offset in the band of (a, b).
    let at = |ia: i32, ib: i32| {
        let (x, y) = if x_major { (ia, ib) } else { (ib, ia) };
        ((y - y0) as usize * W + x as usize) * 3
    };
    let step = if x_major { W * 3 } else { 3 };
    let mut lo = floor_i32(amin - reach).max(a_range.0);
    let mut hi = ceil_i32(amax + reach).min(a_range.1 - 1);
    if x_major {
        // A column reaches the rows within `across` of its centre `bc` (less inside
        // the segment): skip a band the line does not reach, and walk only the
        // columns whose centre is within `m` of the band (the band's rows are b).
        let m = across + 2.0;
        let (y0f, y1f) = (y0 as f32, y1 as f32);
        if b0.max(b1) + m < y0f || b0.min(b1) - m > y1f {
            return;
        }
        if slope.abs() > 1e-3 {
            let (e0, e1) = (a0 + (y0f - m - b0) / slope, a0 + (y1f + m - b0) / slope);
            let (c0, c1) = (e0.min(e1), e0.max(e1));
            // Past its ends a column's centre stays at the end's: keep the caps then.
            if c0 > amin {
                lo = lo.max(floor_i32(c0 - 1.0));
            }
            if c1 < amax {
                hi = hi.min(ceil_i32(c1 + 1.0));
            }
        }
    }
    let edge = half_w + 0.5;
    // Distance (and its square) from which coverage rounds to no change (edge ≥ 1).
    let no_change = edge - 0.5 / 256.0;
    let no_change_2 = no_change * no_change;
    // A pixel the band covers fully takes the colour itself, without arithmetic.
    let solid = c.map(|v| (v + 0.5) as u8);
    // A row of solid pixels, copied whole into a y-major line's full run.
    const RUN_PX: usize = 16;
    let mut run = [0u8; 3 * RUN_PX];
    for px in run.chunks_exact_mut(3) {
        px.copy_from_slice(&solid);
    }
    for ia in lo..=hi {
        let ac = ia as f32 + 0.5;
        let inside = ac >= amin && ac <= amax;
        if inside {
            let bc = b0 + (ac - a0) * slope;
            // Across the line: pixels nearer than `edge − 1` (perpendicular) are
            // covered fully, those nearer than `edge` partly, the rest not at all.
            let span = edge * norm;
            let blo = floor_i32(bc - span - 0.5).max(b_range.0);
            let bhi = ceil_i32(bc + span - 0.5).min(b_range.1 - 1);
            if blo > bhi {
                continue;
            }
            let first = at(ia, blo);
            let partial = |band: &mut [u8], ib: i32| {
                let d = (ib as f32 + 0.5 - bc).abs() * inv_norm;
                let cov = (edge - d).clamp(0.0, 1.0);
                if cov > 0.0 {
                    blend_at(band, first + (ib - blo) as usize * step, solid, cov);
                }
            };
            let full = (edge - 1.0) * norm;
            let flo = ceil_i32(bc - full - 0.5).max(blo);
            let fhi = floor_i32(bc + full - 0.5).min(bhi);
            if flo <= fhi {
                (blo..flo).for_each(|ib| partial(band, ib));
                // The fully covered run, one bounds check for all of it: down a
                // column a row apart (x-major), or along a row in one copy.
                let o = first + (flo - blo) as usize * step;
                let n = (fhi - flo) as usize + 1;
                if X_MAJOR {
                    for px in band[o..o + (n - 1) * step + 3].chunks_mut(step) {
                        px[..3].copy_from_slice(&solid);
                    }
                } else if n <= RUN_PX {
                    band[o..o + 3 * n].copy_from_slice(&run[..3 * n]);
                } else {
                    for px in band[o..o + 3 * n].chunks_exact_mut(3) {
                        px.copy_from_slice(&solid);
                    }
                }
                (fhi + 1..=bhi).for_each(|ib| partial(band, ib));
            } else {
                (blo..=bhi).for_each(|ib| partial(band, ib));
            }
            continue;
        }
        // Past an end. A pixel `edge − ½⁄256` or farther from the segment gets a
        // coverage under 1⁄256, which rounds to no change; a column that far beyond
        // the end is skipped whole (every point of the segment is at least that far
        // along the walk).
        if (amin - ac).max(ac - amax) >= no_change {
            continue;
        }
        let bc = b0 + (ac.clamp(amin, amax) - a0) * slope;
        let blo = floor_i32(bc - across).max(b_range.0);
        let bhi = ceil_i32(bc + across).min(b_range.1 - 1);
        if blo > bhi {
            continue;
        }
        blend_lanes(band, at(ia, blo), step, (blo, bhi), solid, |ib| {
            let pb = ib as f32 + 0.5;
            let t = if degenerate {
                0.0
            } else {
                (((ac - a0) * da + (pb - b0) * db) * inv_len2).clamp(0.0, 1.0)
            };
            let (ea, eb) = (a0 + t * da - ac, b0 + t * db - pb);
            let d2 = ea * ea + eb * eb;
            if d2 >= no_change_2 {
                0
            } else {
                coverage_256((edge - d2.sqrt()).clamp(0.0, 1.0))
            }
        });
    }
}

/// Coverages [`blend_lanes`] works out together.
const LANES: usize = 16;

/// Blend `solid` into the pixels `blo..=bhi` of one column, `step` bytes apart from
/// byte `first`, pixel `ib` with coverage `coverage(ib)` in 1/256ths (256: the
/// colour itself). The coverages come [`LANES`] at a time, with no branch between
/// pixels, so the compiler works them out side by side (a cap's pixel takes a
/// projection, a square root and several compares); only the pixels they touch are
/// then blended. The same bytes as [`blend_at`] pixel by pixel.
#[inline(always)]
fn blend_lanes(
    band: &mut [u8],
    first: usize,
    step: usize,
    (blo, bhi): (i32, i32),
    solid: [u8; 3],
    coverage: impl Fn(i32) -> i32,
) {
    let mut from = blo;
    while from <= bhi {
        let n = ((bhi - from) as usize + 1).min(LANES);
        let mut lanes = [0i32; LANES];
        for (k, a) in lanes.iter_mut().enumerate() {
            *a = coverage(from + k as i32);
        }
        let o = first + (from - blo) as usize * step;
        let pixels = band[o..o + (n - 1) * step + 3].chunks_mut(step);
        for (px, &a) in pixels.zip(&lanes[..n]) {
            if a != 0 {
                blend_256(&mut px[..3], solid, a);
            }
        }
        from += LANES as i32;
    }
}

/// A bubble: a bright anti-aliased rim with a faint fill, on the rows `y0..y1` of
/// the frame that `band` holds.
fn draw_bubble(band: &mut [u8], (y0, y1): (usize, usize), cx: f32, cy: f32, r: f32) {
    let rim = [235.0, 245.0, 255.0];
    let lo_x = (cx - r - 2.0).floor() as i32;
    let hi_x = (cx + r + 2.0).ceil() as i32;
    let lo_y = ((cy - r - 2.0).floor() as i32).max(y0 as i32);
    let hi_y = ((cy + r + 2.0).ceil() as i32).min(y1 as i32 - 1);
    for y in lo_y..=hi_y {
        for x in lo_x..=hi_x {
            let (ddx, ddy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            let d = (ddx * ddx + ddy * ddy).sqrt();
            let ring = (1.2 - (d - r).abs()).clamp(0.0, 1.0) * 0.8;
            let fill = if d < r { 0.12 } else { 0.0 };
            blend(band, x, y - y0 as i32, rim, ring.max(fill));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(y_a: f32, y_b: f32) -> Line {
        ((100.0, y_a), (400.0, y_b), 3.0, [255.0, 140.0, 36.0])
    }

    #[test]
    fn the_split_halves_the_beams_pixels() {
        // Nothing to draw: the middle.
        assert_eq!(split_row(&[], 0.0, 0.5), H / 2);
        // Two equal beams: between them.
        let s = split_row(&[line(100.0, 100.0), line(380.0, 380.0)], 0.0, 0.5);
        assert!((100..=380).contains(&s), "split at {s}");
        // All the work near the top: the split follows it.
        let top = [line(10.0, 10.0), line(20.0, 20.0), line(30.0, 30.0)];
        let s = split_row(&top, 0.0, 0.5);
        assert!((10..=30).contains(&s), "split at {s}");
        // One long beam down the whole frame: about the middle.
        let s = split_row(&[((320.0, -50.0), (320.0, 530.0), 3.0, [0.0; 3])], 0.0, 0.5);
        assert!(s.abs_diff(H / 2) <= 2, "split at {s}");
    }

    #[test]
    fn the_split_counts_the_rows_copies_and_effects() {
        // Rows alone: the middle.
        assert_eq!(split_row(&[], 53.0, 0.5), H / 2);
        // Beams near the top pull the split up, less the more a row costs: three
        // beams of about 2 460 px near the top and 480 rows of 53 put half the work
        // in the first ~170 rows.
        let top = [line(10.0, 10.0), line(20.0, 20.0), line(30.0, 30.0)];
        let beams_only = split_row(&top, 0.0, 0.5);
        let cheap_rows = split_row(&top, 1.0, 0.5);
        let dear_rows = split_row(&top, 53.0, 0.5);
        assert!(
            beams_only < cheap_rows && cheap_rows < dear_rows && dear_rows < H / 2,
            "splits {beams_only}, {cheap_rows}, {dear_rows}"
        );
        assert!((150..=190).contains(&dear_rows), "split at {dear_rows}");
        // A cost that is not a number or not positive counts as none.
        for bad in [f32::NAN, f32::INFINITY, -5.0, 0.0] {
            assert_eq!(split_row(&top, bad, 0.5), beams_only, "row cost {bad}");
        }
    }

    #[test]
    fn the_split_gives_the_top_band_its_share() {
        // Rows alone: the share of the rows.
        for (share, row) in [(0.5, H / 2), (0.25, H / 4), (0.75, 3 * H / 4)] {
            assert_eq!(split_row(&[], 53.0, share), row, "share {share}");
        }
        // A smaller share moves the split up, never out of the frame.
        let beams = [line(100.0, 100.0), line(200.0, 200.0), line(380.0, 380.0)];
        let splits: Vec<usize> = [0.0, 0.2, 0.5, 0.8, 1.0]
            .iter()
            .map(|&share| split_row(&beams, 13.0, share))
            .collect();
        assert!(splits.is_sorted(), "splits {splits:?}");
        assert!(splits[1] < splits[2] && splits[2] < splits[3], "{splits:?}");
        assert!(splits.iter().all(|s| (1..H).contains(s)), "{splits:?}");
        // A share that is not a number is a half; one outside [0, 1] is clamped.
        assert_eq!(split_row(&beams, 13.0, f32::NAN), splits[2]);
        assert_eq!(split_row(&beams, 13.0, -3.0), splits[0]);
        assert_eq!(split_row(&beams, 13.0, 7.0), splits[4]);
    }

    #[test]
    fn the_bands_shares_follow_their_times() {
        // Equal times: the share stays.
        assert_eq!(next_share(0.5, 1e-3, 1e-3).to_bits(), 0.5f32.to_bits());
        assert!((next_share(0.4, 1e-3, 1e-3) - 0.4).abs() < 1e-6);
        // Times in proportion to the shares: the bands cost the same per unit of
        // work, and the split goes halfway back to a half.
        assert!((next_share(0.4, 0.4e-3, 0.6e-3) - 0.45).abs() < 1e-6);
        // The top band slower: it gets less, halfway to where the times would match
        // (a top band 1.5× as dear per unit of work balances at 0.4).
        let s = next_share(0.5, 1.5e-3, 1e-3);
        assert!((s - 0.45).abs() < 1e-6, "share {s}");
        // Repeated, it settles where the times match.
        let mut s = 0.5f32;
        for _ in 0..40 {
            let (top, bottom) = (1.5 * f64::from(s), f64::from(1.0 - s));
            s = next_share(s, top, bottom);
        }
        assert!((s - 0.4).abs() < 1e-4, "share {s}");
        // Never past the reach, however lopsided the times.
        let (mut up, mut down) = (0.5f32, 0.5f32);
        for _ in 0..10 {
            up = next_share(up, 1e-9, 1.0);
            down = next_share(down, 1.0, 1e-9);
        }
        assert_eq!(down.to_bits(), (0.5 - BandBalance::REACH).to_bits());
        assert_eq!(up.to_bits(), (0.5 + BandBalance::REACH).to_bits());
        // Times that teach nothing leave the share as it was (within reach).
        for (top, bottom) in [
            (0.0, 1e-3),
            (1e-3, 0.0),
            (f64::NAN, 1e-3),
            (1e-3, f64::INFINITY),
            (-1e-3, 1e-3),
        ] {
            assert_eq!(
                next_share(0.45, top, bottom).to_bits(),
                0.45f32.to_bits(),
                "{top} {bottom}"
            );
        }
        assert_eq!(next_share(f32::NAN, 1e-3, 1e-3).to_bits(), 0.5f32.to_bits());
        assert_eq!(
            next_share(0.99, 0.0, 0.0).to_bits(),
            (0.5 + BandBalance::REACH).to_bits()
        );
        // What a renderer learns starts at a half and is what it then uses.
        let balance = BandBalance::default();
        assert_eq!(balance.top_share().to_bits(), 0.5f32.to_bits());
        balance.learn(0.5, 1.5e-3, 1e-3);
        assert!((balance.top_share() - 0.45).abs() < 1e-6);
    }

    #[test]
    fn the_split_stays_inside_the_frame_on_extreme_beams() {
        let far = 1e30_f32;
        for lines in [
            vec![((0.0, f32::NAN), (10.0, f32::NAN), 3.0, [0.0; 3])],
            vec![((0.0, -far), (10.0, -far), 3.0, [0.0; 3])],
            vec![((0.0, far), (10.0, far), 3.0, [0.0; 3])],
            vec![((-far, -far), (far, far), 3.0, [0.0; 3])],
            vec![((f32::INFINITY, 0.0), (0.0, 479.0), 3.0, [0.0; 3])],
            vec![((5.0, 0.0), (5.0, 0.0), 0.5, [0.0; 3])],
            vec![((5.0, 479.9), (600.0, 479.9), 3.0, [0.0; 3])],
        ] {
            for row_cost in [0.0, 53.0] {
                let s = split_row(&lines, row_cost, 0.5);
                assert!((1..H).contains(&s), "split at {s} for {lines:?}");
            }
        }
    }

    #[test]
    fn a_line_drawn_in_bands_is_the_line_drawn_whole() {
        // Steep, shallow, flat, reversed, past the frame's edges, a dot: every split
        // row gives the bytes of one pass.
        let lines: [Line; 7] = [
            ((10.0, 5.0), (600.0, 470.0), 3.0, [250.0, 140.0, 30.0]),
            ((620.0, 30.0), (15.0, 90.0), 2.2, [200.0, 120.0, 20.0]),
            ((100.0, 240.5), (500.0, 240.5), 3.0, [255.0, 255.0, 255.0]),
            ((300.0, -40.0), (310.0, 520.0), 1.5, [90.0, 200.0, 10.0]),
            ((-80.0, 200.0), (700.0, 260.0), 0.5, [255.0, 0.0, 0.0]),
            ((320.0, 239.0), (320.2, 239.1), 3.0, [0.0, 255.0, 0.0]),
            ((50.0, 470.0), (630.0, 478.0), 3.0, [10.0, 20.0, 255.0]),
        ];
        let mut whole = vec![40u8; W * H * 3];
        for &(p0, p1, hw, c) in &lines {
            draw_line(&mut whole, (0, H as i32), p0, p1, hw, c);
        }
        for split in [1, 7, 100, 239, 240, 241, 400, 479] {
            let mut banded = vec![40u8; W * H * 3];
            let (top, bottom) = banded.split_at_mut(split * W * 3);
            for &(p0, p1, hw, c) in &lines {
                draw_line(top, (0, split as i32), p0, p1, hw, c);
                draw_line(bottom, (split as i32, H as i32), p0, p1, hw, c);
            }
            assert!(banded == whole, "split at row {split}");
        }
    }

    /// FNV-1a over a frame's bytes: pins a drawing to the bytes it had.
    fn fnv1a(bytes: &[u8]) -> u64 {
        bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        })
    }

    #[test]
    fn lines_draw_the_bytes_they_always_drew() {
        // Beams of every width and direction, ends inside and past the frame, and a
        // dot, over each other.
        let mut frame = vec![40u8; W * H * 3];
        for k in 0..60 {
            let t = k as f32;
            let p0 = ((t * 37.0) % 700.0 - 30.0, (t * 53.0) % 540.0 - 30.0);
            let p1 = (
                p0.0 + ((k * 41) % 181) as f32 - 90.0,
                p0.1 + ((k * 29) % 141) as f32 - 70.0,
            );
            let half_w = 0.5 + (k % 6) as f32 * 0.5;
            let c = [255.0 - t * 3.0, 140.0, 36.0 + t * 2.0];
            draw_line(&mut frame, (0, H as i32), p0, p1, half_w, c);
        }
        draw_line(
            &mut frame,
            (0, H as i32),
            (320.0, 239.0),
            (320.2, 239.1),
            3.0,
            [0.0, 255.0, 0.0],
        );
        // The digest of these bytes as drawn before the caps' pixels were worked out
        // in lanes (and since): any change to how a beam is drawn shows here.
        assert_eq!(fnv1a(&frame), 0xd9b0_49db_b8a5_3163);
    }

    #[test]
    fn pixels_in_lanes_blend_as_one_at_a_time() {
        // Columns shorter and longer than a block of lanes, along a row and down a
        // column, with coverages from none to full.
        let coverage = |ib: i32| [0, 1, 128, 255, 256, 7, 0, 200][(ib.rem_euclid(8)) as usize];
        for (step, len) in [(3, 40 * 3), (W * 3, 40 * W * 3)] {
            for (blo, bhi) in [(0, 0), (3, 17), (0, 15), (0, 16), (5, 39), (2, 33)] {
                let mut lanes: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
                let mut one_by_one = lanes.clone();
                let first = blo as usize * step;
                let solid = [250, 3, 128];
                blend_lanes(&mut lanes, first, step, (blo, bhi), solid, coverage);
                for ib in blo..=bhi {
                    let o = ib as usize * step;
                    blend_256(&mut one_by_one[o..o + 3], solid, coverage(ib));
                }
                assert!(lanes == one_by_one, "step {step}, pixels {blo}..={bhi}");
            }
        }
        // A full coverage gives the colour, none leaves the pixel.
        let mut px = [10u8, 200, 99];
        blend_256(&mut px, [250, 3, 128], 256);
        assert_eq!(px, [250, 3, 128]);
        blend_256(&mut px, [0, 0, 0], 0);
        assert_eq!(px, [250, 3, 128]);
    }

    #[test]
    fn camera_noise_is_the_same_in_one_byte_or_two() {
        assert!(matches!(
            NoiseTable::new(vec![-128, 0, 127]),
            NoiseTable::Narrow(_)
        ));
        assert!(matches!(
            NoiseTable::new(vec![-129, 0]),
            NoiseTable::Wide(_)
        ));
        assert!(matches!(NoiseTable::new(vec![0, 128]), NoiseTable::Wide(_)));
        let levels: Vec<i16> = vec![-128, -5, 0, 3, 127, -1, 100, -100];
        let narrow = NoiseTable::new(levels.clone());
        let wide = NoiseTable::Wide(levels);
        // Saturation at both ends, from two offsets.
        let frame = [0u8, 2, 255, 254, 130, 0, 200, 50];
        for at in [0, 2] {
            let (mut a, mut b) = (frame[..6].to_vec(), frame[..6].to_vec());
            narrow.add_to(&mut a, at);
            wide.add_to(&mut b, at);
            assert_eq!(a, b, "offset {at}");
        }
        let mut a = frame.to_vec();
        narrow.add_to(&mut a, 0);
        assert_eq!(a, [0, 0, 255, 255, 255, 0, 255, 0]);
    }
}
