//! What a frame is drawn into and with: the buffers, the per-pixel effect tables (noise, the medium's attenuation).

use super::*;

/// The camera noise, in whole levels, from which each frame reads one frame's worth
/// at its offset. A frame reads a megabyte or two of it, mostly from memory rather
/// than cache: one byte a value where every value fits (a σ of a few levels), else two.
#[derive(Debug, Clone)]
pub(super) enum NoiseTable {
    Narrow(Vec<i8>),
    Wide(Vec<i16>),
}

impl NoiseTable {
    pub(super) fn new(levels: Vec<i16>) -> Self {
        let narrow: Option<Vec<i8>> = levels.iter().map(|&v| i8::try_from(v).ok()).collect();
        match narrow {
            Some(narrow) => Self::Narrow(narrow),
            None => Self::Wide(levels),
        }
    }

    /// Add the table from `at` on to `dst`, saturating at 0 and 255.
    pub(super) fn add_to(&self, dst: &mut [u8], at: usize) {
        match self {
            Self::Narrow(table) => add_levels(dst, &table[at..at + dst.len()]),
            Self::Wide(table) => add_levels(dst, &table[at..at + dst.len()]),
        }
    }
}

/// `dst` + `levels`, saturating at 0 and 255: one loop, compiled for each width.
pub(super) fn add_levels<T: Copy + Into<i16>>(dst: &mut [u8], levels: &[T]) {
    for (v, &n) in dst.iter_mut().zip(levels) {
        *v = (i16::from(*v) + n.into()).clamp(0, 255) as u8;
    }
}

/// The medium's effect along one light path: per-channel attenuation, then the veil
/// of scattered light (its weight and colour), each when declared.
#[derive(Debug, Clone, Copy)]
pub(super) struct Medium {
    pub(super) attenuation: Option<[f32; 3]>,
    pub(super) veil: Option<(f32, Rgb)>,
}

impl Medium {
    pub(super) fn apply(&self, mut c: Rgb) -> Rgb {
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
    pub(super) canvas: Vec<u8>,
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
pub(super) type Line = ((f32, f32), (f32, f32), f32, Rgb);

/// What the declared effects do in one frame: the caustics' shift (px), the bubbles
/// (centre and radius, px) and where the frame's camera noise starts in the table.
#[derive(Debug)]
pub(super) struct FrameEffects {
    pub(super) caustic_offset: Option<(usize, usize)>,
    pub(super) bubbles: Vec<(f32, f32, f32)>,
    pub(super) noise_start: Option<usize>,
}
