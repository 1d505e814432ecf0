//! Training-time augmentation for another medium (`train --augment-media N`): each
//! training frame is also learned as a camera in water would show it after the
//! image tare ([`super::tare`]): the field of view narrowed (a flat port's refraction
//! magnifies the image; undone, the edge it no longer sees is black) and each
//! channel's gain and offset changed. Drawn per frame from the seed, so a training
//! repeats exactly.

use rand::SeedableRng as _;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution as _, StandardUniform};
use serde::{Deserialize, Serialize};

/// How many copies of each training frame, and how far they stray.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MediaAugment {
    /// Augmented copies per training frame (the frame itself is kept as well).
    pub copies: usize,
    /// The narrowest field kept, a fraction of the frame's width and height about its
    /// centre (water: 1/1.333 = 0.75).
    pub field_min: f64,
    /// A channel's gain is drawn from [1/(1 + j), 1 + j].
    pub gain_jitter: f64,
    /// A channel's offset is drawn from [−o, o], 0–255 units.
    pub offset_jitter: f64,
    /// Seed of the draws.
    pub seed: u64,
}

impl MediaAugment {
    /// `copies` copies at the ranges measured for water (docs/land-to-water.md).
    #[must_use]
    pub fn water(copies: usize, seed: u64) -> Self {
        Self {
            copies,
            field_min: 0.7,
            gain_jitter: 0.25,
            offset_jitter: 15.0,
            seed,
        }
    }

    /// A list of what is wrong with these settings (empty when usable).
    #[must_use]
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(self.field_min.is_finite() && self.field_min > 0.0 && self.field_min <= 1.0) {
            out.push(format!(
                "field_min {}: expected a fraction in (0, 1]",
                self.field_min
            ));
        }
        for (name, v) in [
            ("gain_jitter", self.gain_jitter),
            ("offset_jitter", self.offset_jitter),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                out.push(format!("{name} {v}: expected a finite value ≥ 0"));
            }
        }
        out
    }

    /// Copy `copy` of frame `key` (run, sample index): RGB8 `width × height`.
    #[must_use]
    pub fn frame(
        &self,
        key: (i64, i64),
        copy: usize,
        width: usize,
        height: usize,
        rgb: &[u8],
    ) -> Vec<u8> {
        let mut g = ChaCha8Rng::seed_from_u64(
            self.seed
                ^ (key.0 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (key.1 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ (copy as u64 + 1).wrapping_mul(0x1656_67B1_9E37_79F9),
        );
        let mut between = |a: f64, b: f64| {
            let u: f64 = StandardUniform.sample(&mut g);
            a + (b - a) * u
        };
        let field = between(self.field_min, 1.0);
        let j = 1.0 + self.gain_jitter;
        let gain: [f64; 3] = std::array::from_fn(|_| between(1.0 / j, j));
        let offset: [f64; 3] =
            std::array::from_fn(|_| between(-self.offset_jitter, self.offset_jitter));
        let (hw, hh) = (field * width as f64 / 2.0, field * height as f64 / 2.0);
        let (cx, cy) = (width as f64 / 2.0, height as f64 / 2.0);
        let mut out = vec![0u8; rgb.len().min(width * height * 3)];
        for y in 0..height {
            let dy = (y as f64 + 0.5 - cy).abs();
            for x in 0..width {
                let dx = (x as f64 + 0.5 - cx).abs();
                if dx > hw || dy > hh {
                    continue;
                }
                let i = (y * width + x) * 3;
                for c in 0..3 {
                    if let (Some(&v), Some(o)) = (rgb.get(i + c), out.get_mut(i + c)) {
                        *o = (gain[c] * f64::from(v) + offset[c])
                            .round()
                            .clamp(0.0, 255.0) as u8;
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copy_is_the_frame_narrowed_and_recoloured_and_repeats_from_its_seed() {
        let (w, h) = (40, 30);
        let rgb = vec![100u8; w * h * 3];
        let a = MediaAugment::water(2, 7);
        let one = a.frame((1, 5), 0, w, h, &rgb);
        assert_eq!(one, a.frame((1, 5), 0, w, h, &rgb));
        assert_ne!(one, a.frame((1, 5), 1, w, h, &rgb));
        // The centre kept (recoloured within the jitter), a corner cut at most 0.7.
        let c = &one[(15 * w + 20) * 3..(15 * w + 20) * 3 + 3];
        assert!(c.iter().all(|&v| (60..=140).contains(&v)), "{c:?}");
        // Nothing strays: no jitter and the whole field is the frame itself.
        let none = MediaAugment {
            copies: 1,
            field_min: 1.0,
            gain_jitter: 0.0,
            offset_jitter: 0.0,
            seed: 0,
        };
        assert_eq!(none.frame((0, 0), 0, w, h, &rgb), rgb);
        assert!(none.problems().is_empty());
        // A short buffer never panics.
        assert_eq!(a.frame((0, 0), 0, w, h, &rgb[..10]).len(), 10);
    }

    #[test]
    fn bad_settings_are_named() {
        let mut a = MediaAugment::water(1, 0);
        a.field_min = 0.0;
        a.gain_jitter = f64::NAN;
        let p = a.problems();
        assert_eq!(p.len(), 2, "{p:?}");
        assert!(p[0].contains("field_min 0"));
    }
}
