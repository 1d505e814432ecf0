//! Image preprocessing shared by training and inference (one function, so the two can
//! never disagree): the colour threshold of the paper's Method S3 keeps only the
//! finger's pixels, then a box filter squashes the frame to the model's input size and
//! scales it to [0, 1].
//!
//! The threshold works in HSV: a pixel is the finger's when its hue lies in
//! `[hue_min_deg, hue_max_deg]` and its saturation and value are high enough. The
//! finger is orange in air and yellow-green through water; background, caustics and
//! bubbles are blue or grey and fall outside. Kept pixels carry their brightness
//! (channels = 1) or their RGB (channels = 3); the rest become 0.

use serde::{Deserialize, Serialize};

use crate::TrainError;

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
}

impl Default for Preprocess {
    fn default() -> Self {
        Self {
            size_px: 64,
            channels: 1,
            hue_min_deg: 10.0,
            hue_max_deg: 75.0,
            saturation_min: 0.35,
            value_min: 0.2,
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

    /// Whether an RGB pixel (0..=255 per channel) is the finger's.
    pub fn is_finger(&self, r: u8, g: u8, b: u8) -> bool {
        let (h, s, v) = hsv(r, g, b);
        v >= self.value_min && s >= self.saturation_min && self.hue_in_window(h)
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
        let mut acc = vec![[0.0f32; 3]; n];
        for oy in 0..n {
            let (y0, y1) = bounds(oy, height);
            acc.iter_mut().for_each(|a| *a = [0.0; 3]);
            for y in y0..y1 {
                let row = &rgb[y * width * 3..(y + 1) * width * 3];
                for (ox, a) in acc.iter_mut().enumerate() {
                    let (x0, x1) = bounds(ox, width);
                    for px in row[x0 * 3..x1 * 3].chunks_exact(3) {
                        let (r, g, b) = (px[0], px[1], px[2]);
                        if self.is_finger(r, g, b) {
                            a[0] += f32::from(r);
                            a[1] += f32::from(g);
                            a[2] += f32::from(b);
                        }
                    }
                }
            }
            for (ox, a) in acc.iter().enumerate() {
                let (x0, x1) = bounds(ox, width);
                let count = ((x1 - x0) * (y1 - y0)) as f32 * 255.0;
                let at = oy * n + ox;
                if self.channels == 1 {
                    // Brightness as HSV value would need a max per pixel; the mean of
                    // the channels is as informative here and cheaper.
                    out[at] = (a[0] + a[1] + a[2]) / (3.0 * count);
                } else {
                    for c in 0..3 {
                        out[c * plane + at] = a[c] / count;
                    }
                }
            }
        }
        Ok(())
    }
}

/// HSV of an RGB8 pixel: hue in degrees [0, 360), saturation and value in [0, 1].
fn hsv(r: u8, g: u8, b: u8) -> (f32, f32, f32) {
    // Which channel is largest is decided on the integers (exact).
    let max_u = r.max(g).max(b);
    let min_u = r.min(g).min(b);
    let (rf, gf, bf) = (f32::from(r), f32::from(g), f32::from(b));
    let max = f32::from(max_u);
    let delta = f32::from(max_u - min_u);
    let value = max / 255.0;
    if max_u == 0 || max_u == min_u {
        return (0.0, 0.0, value);
    }
    let saturation = delta / max;
    let sector = if max_u == r {
        ((gf - bf) / delta).rem_euclid(6.0)
    } else if max_u == g {
        (bf - rf) / delta + 2.0
    } else {
        (rf - gf) / delta + 4.0
    };
    (sector * 60.0, saturation, value)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solid(w: usize, h: usize, px: [u8; 3]) -> Vec<u8> {
        px.iter().copied().cycle().take(w * h * 3).collect()
    }

    #[test]
    fn hues_of_primary_and_finger_colours() {
        let close = |a: f32, b: f32| (a - b).abs() < 0.5;
        assert!(close(hsv(255, 0, 0).0, 0.0));
        assert!(close(hsv(0, 255, 0).0, 120.0));
        assert!(close(hsv(0, 0, 255).0, 240.0));
        assert!(close(hsv(255, 0, 128).0, 330.0));
        let p = Preprocess::default();
        assert!(p.is_finger(230, 130, 40), "orange finger in air");
        assert!(p.is_finger(180, 150, 50), "yellow finger through water");
        assert!(!p.is_finger(30, 45, 70), "dark blue background");
        assert!(!p.is_finger(200, 200, 200), "grey bubble");
    }

    #[test]
    fn all_black_and_all_white_images_give_zeros_and_finite_values() {
        let p = Preprocess::default();
        for px in [[0, 0, 0], [255, 255, 255]] {
            let out = p
                .apply(640, 480, &solid(640, 480, px))
                .expect("valid image");
            assert_eq!(out.len(), 64 * 64);
            assert!(
                out.iter().all(|v| *v == 0.0),
                "{px:?} holds no finger pixels"
            );
        }
        let out = p
            .apply(640, 480, &solid(640, 480, [255, 128, 0]))
            .expect("valid image");
        assert!(out.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
        assert!((out[0] - (255.0 + 128.0) / (3.0 * 255.0)).abs() < 1e-5);
    }

    #[test]
    fn box_filter_keeps_the_mean_and_handles_tiny_and_odd_images() {
        let p = Preprocess {
            channels: 3,
            size_px: 8,
            ..Preprocess::default()
        };
        // Left half finger-orange, right half background: the left half of the output
        // is orange, the right half zero.
        let (w, h) = (80, 60);
        let mut rgb = solid(w, h, [20, 30, 60]);
        for y in 0..h {
            for x in 0..w / 2 {
                rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[250, 140, 20]);
            }
        }
        let out = p.apply(w, h, &rgb).expect("valid image");
        assert!((out[0] - 250.0 / 255.0).abs() < 1e-5);
        assert!(out[7].abs() < 1e-6);
        // Images smaller than the output and of odd sizes still fill every value.
        for (w, h) in [(1, 1), (3, 5), (7, 2)] {
            let out = p.apply(w, h, &solid(w, h, [250, 140, 20])).expect("valid");
            for (plane, value) in out.chunks(64).zip([250.0, 140.0, 20.0]) {
                assert!(plane.iter().all(|v| (*v - value / 255.0).abs() < 1e-6));
            }
        }
    }

    #[test]
    fn malformed_inputs_are_errors_not_panics() {
        let p = Preprocess::default();
        assert!(p.apply(0, 10, &[]).is_err());
        assert!(p.apply(10, 10, &[0; 299]).is_err());
        let mut short = vec![0.0; 10];
        assert!(p.apply_into(1, 1, &[0, 0, 0], &mut short).is_err());
        let bad = Preprocess {
            size_px: 48,
            channels: 2,
            hue_min_deg: f32::NAN,
            ..Preprocess::default()
        };
        assert_eq!(bad.problems().len(), 3, "{:?}", bad.problems());
        assert!(Preprocess::default().problems().is_empty());
    }

    #[test]
    fn a_hue_window_across_zero_keeps_reds() {
        let p = Preprocess {
            hue_min_deg: 340.0,
            hue_max_deg: 20.0,
            ..Preprocess::default()
        };
        assert!(p.is_finger(255, 0, 10));
        assert!(p.is_finger(255, 40, 0));
        assert!(!p.is_finger(0, 255, 0));
    }
}
