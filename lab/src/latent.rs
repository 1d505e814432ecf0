//! The latent-space figures of the paper's Figure 3 (issue 18), for `softtouch latent`:
//! the correlation map of the latent dimensions (3b), the latent-to-wrench correlation
//! map (3d), decoder traversals with one latent varied over [−5, 5] (3c, Method S2),
//! and the latent values of paired land and water instances (3a).
//!
//! The numbers come from `softtouch_trainer::similarity::cross_correlation`; this
//! module decodes and draws.

use burn::prelude::*;
use plotters::prelude::*;
use softtouch_collector::plot::{FONT_FAMILY, PALETTE, PlotError, register_font};
use softtouch_trainer::{Example, ModelArtifact, TrainError};
use std::path::Path;

/// Each example's label as a row of f64 (Fx … Tz), to correlate latents with.
#[must_use]
pub fn wrench_rows(examples: &[Example]) -> Vec<Vec<f64>> {
    examples
        .iter()
        .map(|e| e.label.iter().map(|v| f64::from(*v)).collect())
        .collect()
}

/// The latent values a traversal shows: `steps` values evenly over `[-span, span]`.
#[must_use]
pub fn traversal_values(span: f64, steps: usize) -> Vec<f64> {
    match steps {
        0 => Vec::new(),
        1 => vec![0.0],
        _ => (0..steps)
            .map(|i| -span + 2.0 * span * i as f64 / (steps - 1) as f64)
            .collect(),
    }
}

/// For each wrench axis (column of `latent_to_wrench`, rows are latent dimensions),
/// the latent dimension with the largest |r|, and that r; `None` for an axis no
/// dimension correlates with (every r missing).
#[must_use]
pub fn strongest_dims(latent_to_wrench: &[Vec<Option<f64>>]) -> Vec<Option<(usize, f64)>> {
    let axes = latent_to_wrench.first().map_or(0, Vec::len);
    (0..axes)
        .map(|a| {
            latent_to_wrench
                .iter()
                .enumerate()
                .filter_map(|(d, row)| row[a].map(|r| (d, r)))
                .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
        })
        .collect()
}

/// The mean |r| over the off-diagonal cells of a square correlation map (0: the
/// dimensions are uncorrelated); `None` without two correlated dimensions.
#[must_use]
pub fn mean_off_diagonal(map: &[Vec<Option<f64>>]) -> Option<f64> {
    let values: Vec<f64> = map
        .iter()
        .enumerate()
        .flat_map(|(i, row)| {
            row.iter()
                .enumerate()
                .filter(move |(j, _)| *j != i)
                .filter_map(|(_, v)| v.map(f64::abs))
        })
        .collect();
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// Why a traversal figure could not be made.
#[derive(Debug, thiserror::Error)]
pub enum LatentError {
    /// Decoding failed.
    #[error(transparent)]
    Train(#[from] TrainError),
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// Figure 3c for one model: the decoder's images with each of `dims` set to each of
/// `values` and the other latents at `base` (e.g. their means over a test split, or
/// 0), rows labelled with the wrench axes each dimension
/// is the strongest for (`strongest`, from [`strongest_dims`]). Empty `dims` means the
/// strongest dimension of each axis. `Ok(None)` for a model without a decoder or with
/// nothing to traverse; else the dimensions drawn.
///
/// # Errors
/// A dimension beyond the latent, decoding or drawing failed.
pub fn write_traversal(
    png: &Path,
    title: &str,
    artifact: &ModelArtifact,
    strongest: &[Option<(usize, f64)>],
    dims: &[usize],
    base: &[f32],
    values: &[f64],
) -> Result<Option<Vec<usize>>, LatentError> {
    let latent = artifact.header.config.latent;
    if base.len() != latent {
        return Err(TrainError::Input(format!(
            "the traversal's base holds {} values: the model's latent has {latent}",
            base.len()
        ))
        .into());
    }
    let mut dims: Vec<usize> = if dims.is_empty() {
        strongest.iter().flatten().map(|(d, _)| *d).collect()
    } else {
        dims.to_vec()
    };
    if let Some(d) = dims.iter().find(|d| **d >= latent) {
        return Err(TrainError::Input(format!(
            "latent dimension {d}: the model has 0 to {}",
            latent.saturating_sub(1)
        ))
        .into());
    }
    let mut seen = std::collections::HashSet::new();
    dims.retain(|d| seen.insert(*d));
    if dims.is_empty() || !artifact.header.config.kind.has_decoder() {
        return Ok(None);
    }
    let codes: Vec<Vec<f32>> = dims
        .iter()
        .flat_map(|&d| {
            values.iter().map(move |&v| {
                let mut z = base.to_vec();
                z[d] = v as f32;
                z
            })
        })
        .collect();
    let Some(decoded) = decode(artifact, &codes)? else {
        return Ok(None);
    };
    let axes = softtouch_schemas::wrench::AXES;
    let row_labels: Vec<String> = dims
        .iter()
        .map(|d| {
            let named: Vec<String> = axes
                .iter()
                .zip(strongest)
                .filter_map(|(a, s)| {
                    s.filter(|(sd, _)| sd == d)
                        .map(|(_, r)| format!("{} {r:+.2}", a.name))
                })
                .collect();
            if named.is_empty() {
                format!("z{d}")
            } else {
                format!("z{d} {}", named.join(" "))
            }
        })
        .collect();
    draw_traversal(png, title, &decoded, &row_labels, values)?;
    Ok(Some(dims))
}

/// The mean of each column of `rows` (each row one latent mean), as f32; zeros of
/// length `latent` when there are no rows.
#[must_use]
pub fn column_means(rows: &[Vec<f64>], latent: usize) -> Vec<f32> {
    if rows.is_empty() {
        return vec![0.0; latent];
    }
    let n = rows.len() as f64;
    (0..latent)
        .map(|c| {
            (rows
                .iter()
                .map(|r| r.get(c).copied().unwrap_or(0.0) / n)
                .sum::<f64>()) as f32
        })
        .collect()
}

/// Decoded images, row-major RGB bytes `size × size × 3`.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// Side in pixels.
    pub size: usize,
    /// One image per latent code given, in order.
    pub images: Vec<Vec<u8>>,
}

/// Decodes latent codes (each of the model's latent size) into images, in evaluation
/// mode. `Ok(None)` for a model without a decoder (the ConvNet).
///
/// # Errors
/// A code of the wrong length, or a non-finite value in one.
pub fn decode(artifact: &ModelArtifact, codes: &[Vec<f32>]) -> Result<Option<Decoded>, TrainError> {
    let config = &artifact.header.config;
    if !config.kind.has_decoder() {
        return Ok(None);
    }
    let latent = config.latent;
    if let Some((i, c)) = codes.iter().enumerate().find(|(_, c)| c.len() != latent) {
        return Err(TrainError::Input(format!(
            "latent code {i} holds {} values: the model's latent has {latent}",
            c.len()
        )));
    }
    if codes.iter().flatten().any(|v| !v.is_finite()) {
        return Err(TrainError::Input(
            "a latent code holds a non-finite value".into(),
        ));
    }
    let size = config.preprocess.size_px;
    let channels = config.preprocess.channels;
    let device = softtouch_trainer::backend::device()?;
    let net = artifact.net.valid();
    let mut images = Vec::with_capacity(codes.len());
    for chunk in codes.chunks(64) {
        let flat: Vec<f32> = chunk.iter().flatten().copied().collect();
        let z = Tensor::<2>::from_data(TensorData::new(flat, [chunk.len(), latent]), &device);
        let Some(out) = net.decode(z) else {
            return Ok(None);
        };
        let data = out.into_data();
        let values = data
            .as_slice::<f32>()
            .map_err(|e| TrainError::Input(format!("decoder output: {e:?}")))?;
        let plane = size * size;
        for img in values.chunks_exact(channels * plane) {
            let mut rgb = Vec::with_capacity(plane * 3);
            for p in 0..plane {
                let byte = |c: usize| (img[c * plane + p].clamp(0.0, 1.0) * 255.0).round() as u8;
                if channels == 3 {
                    rgb.extend([byte(0), byte(1), byte(2)]);
                } else {
                    let g = byte(0);
                    rgb.extend([g, g, g]);
                }
            }
            images.push(rgb);
        }
    }
    Ok(Some(Decoded { size, images }))
}

/// Draws a grid of decoded images: one row per `row_labels` entry, one column per
/// `values` entry (the latent value), `decoded.images` row-major, with one
/// brightness stretch over the whole grid.
///
/// # Errors
/// A grid that does not match the images, or drawing failed.
pub fn draw_traversal(
    path: &Path,
    title: &str,
    decoded: &Decoded,
    row_labels: &[String],
    values: &[f64],
) -> Result<(), PlotError> {
    register_font()?;
    let (rows, cols) = (row_labels.len(), values.len());
    let err = |why: String| PlotError::Draw {
        path: path.display().to_string(),
        why,
    };
    if rows == 0 || cols == 0 || decoded.images.len() != rows * cols {
        return Err(PlotError::Invalid {
            path: path.display().to_string(),
            why: format!(
                "{} images for {rows} rows × {cols} values",
                decoded.images.len()
            ),
        });
    }
    // Each image drawn at 96 px or more (a 32×32 decode at 3×).
    let zoom = (96usize).div_ceil(decoded.size.max(1)).max(1);
    let cell = decoded.size * zoom;
    let (left, top, gap) = (170usize, 70usize, 4usize);
    let width = left + cols * (cell + gap) + 10;
    let height = top + rows * (cell + gap) + 10;
    let (w, h) = (
        u32::try_from(width).map_err(|e| err(e.to_string()))?,
        u32::try_from(height).map_err(|e| err(e.to_string()))?,
    );
    // The decoder's images are dim (the finger's brightness after the colour
    // threshold): one brightness stretch over the whole grid keeps them comparable.
    let (lo, hi) = decoded
        .images
        .iter()
        .flatten()
        .fold((u8::MAX, u8::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    let stretch = |v: u8| -> u8 {
        if hi > lo {
            ((f64::from(v - lo) * 255.0 / f64::from(hi - lo)).round()).clamp(0.0, 255.0) as u8
        } else {
            v
        }
    };
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let at = |x: usize, y: usize| (x as i32, y as i32);
    root.draw(&Text::new(
        title.to_owned(),
        at(10, 8),
        (FONT_FAMILY, 20).into_font(),
    ))
    .map_err(|e| err(e.to_string()))?;
    for (c, v) in values.iter().enumerate() {
        root.draw(&Text::new(
            format!("{v:+.1}"),
            at(left + c * (cell + gap) + cell / 2 - 16, top - 24),
            (FONT_FAMILY, 14).into_font(),
        ))
        .map_err(|e| err(e.to_string()))?;
    }
    for (r, label) in row_labels.iter().enumerate() {
        let y0 = top + r * (cell + gap);
        root.draw(&Text::new(
            label.clone(),
            at(8, y0 + cell / 2 - 8),
            (FONT_FAMILY, 14).into_font(),
        ))
        .map_err(|e| err(e.to_string()))?;
        for c in 0..cols {
            let img = &decoded.images[r * cols + c];
            let x0 = left + c * (cell + gap);
            for py in 0..decoded.size {
                for px in 0..decoded.size {
                    let i = (py * decoded.size + px) * 3;
                    let colour =
                        RGBColor(stretch(img[i]), stretch(img[i + 1]), stretch(img[i + 2]));
                    root.draw(&Rectangle::new(
                        [
                            at(x0 + px * zoom, y0 + py * zoom),
                            at(x0 + (px + 1) * zoom, y0 + (py + 1) * zoom),
                        ],
                        colour.filled(),
                    ))
                    .map_err(|e| err(e.to_string()))?;
                }
            }
        }
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// Draws the latent values of paired instances, one panel per pair: latent dimension
/// along x, value along y, land and water as two lines (Figure 3a).
///
/// # Errors
/// Mismatched or empty input, or drawing failed.
pub fn draw_pairs(
    path: &Path,
    title: &str,
    land: &[Vec<f64>],
    water: &[Vec<f64>],
    panel_titles: &[String],
) -> Result<(), PlotError> {
    register_font()?;
    let invalid = |why: String| PlotError::Invalid {
        path: path.display().to_string(),
        why,
    };
    let err = |e: String| PlotError::Draw {
        path: path.display().to_string(),
        why: e,
    };
    let n = land.len();
    if n == 0 || water.len() != n || panel_titles.len() != n {
        return Err(invalid(format!(
            "{n} land, {} water instances, {} titles",
            water.len(),
            panel_titles.len()
        )));
    }
    let dims = land[0].len();
    let all = land.iter().chain(water).flatten().copied();
    let (lo, hi) = all
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    if dims == 0 || lo > hi {
        return Err(invalid("no finite latent values".into()));
    }
    let pad = ((hi - lo) * 0.05).max(0.1);
    let (lo, hi) = (lo - pad, hi + pad);
    let height = 70 + 200 * u32::try_from(n).map_err(|e| err(e.to_string()))?;
    let root = BitMapBackend::new(path, (1000, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let root = root
        .titled(title, (FONT_FAMILY, 20))
        .map_err(|e| err(e.to_string()))?;
    let panels = root.split_evenly((n, 1));
    for (i, area) in panels.iter().enumerate() {
        let mut ctx = ChartBuilder::on(area)
            .caption(&panel_titles[i], (FONT_FAMILY, 14))
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(50)
            .build_cartesian_2d(-0.5f64..dims as f64 - 0.5, lo..hi)
            .map_err(|e| err(e.to_string()))?;
        ctx.configure_mesh()
            .x_desc(if i + 1 == n { "latent dimension" } else { "" })
            .label_style((FONT_FAMILY, 11))
            .axis_desc_style((FONT_FAMILY, 12))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        for (k, (name, set)) in [("land", land), ("water", water)].into_iter().enumerate() {
            let colour = PALETTE[k];
            let pts: Vec<(f64, f64)> = set[i]
                .iter()
                .enumerate()
                .map(|(d, v)| (d as f64, *v))
                .filter(|(_, v)| v.is_finite())
                .collect();
            ctx.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| err(e.to_string()))?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            ctx.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| err(e.to_string()))?;
        }
        ctx.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT_FAMILY, 12))
            .draw()
            .map_err(|e| err(e.to_string()))?;
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// Method S2 b–g: the traversal of one row of the latent sweep (the strongest
/// dimension of each wrench axis on the test split, from −5 to +5, the others at
/// their test mean), or `None` for a
/// model without a decoder.
///
/// # Errors
/// The backend, decoding or drawing failed.
pub fn sweep_traversal(
    dir: &Path,
    trained: &softtouch_trainer::Trained,
    splits: &softtouch_trainer::Splits,
) -> Result<Option<std::path::PathBuf>, LatentError> {
    let artifact = &trained.artifact;
    let h = &artifact.header;
    if !h.config.kind.has_decoder() {
        return Ok(None);
    }
    let device = softtouch_trainer::backend::device()?;
    let latents =
        softtouch_trainer::latent_means(&artifact.net, &h.config, &h.norm, &splits.test, &device);
    let wrench = wrench_rows(&splits.test);
    // Too few test samples or constant latents: traverse the first dimensions instead.
    let strongest = softtouch_trainer::similarity::cross_correlation(&latents, &wrench)
        .map(|m| strongest_dims(&m))
        .unwrap_or_default();
    let dims: Vec<usize> = if strongest.iter().any(Option::is_some) {
        Vec::new()
    } else {
        (0..h.config.latent.min(6)).collect()
    };
    let png = dir.join(format!("sweep-latent-traversal-{}.png", h.config.latent));
    let title = format!(
        "latent {}: decoder images, one latent from −5 to +5, others at their test mean (brightness stretched)",
        h.config.latent
    );
    let drawn = write_traversal(
        &png,
        &title,
        artifact,
        &strongest,
        &dims,
        &column_means(&latents, h.config.latent),
        &traversal_values(5.0, 11),
    )?;
    Ok(drawn.map(|_| png))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traversal_values_span_the_range_evenly() {
        assert_eq!(traversal_values(5.0, 3), vec![-5.0, 0.0, 5.0]);
        assert_eq!(traversal_values(5.0, 1), vec![0.0]);
        assert!(traversal_values(5.0, 0).is_empty());
        let v = traversal_values(5.0, 11);
        assert_eq!(v.len(), 11);
        assert!((v[1] + 4.0).abs() < 1e-12);
    }

    #[test]
    fn column_means_average_each_dimension() {
        let rows = vec![vec![1.0, -2.0], vec![3.0, 2.0]];
        assert_eq!(column_means(&rows, 2), vec![2.0, 0.0]);
        assert_eq!(column_means(&[], 3), vec![0.0; 3]);
    }

    #[test]
    fn strongest_dims_pick_the_largest_magnitude_and_skip_missing() {
        let map = vec![
            vec![Some(0.2), None],
            vec![Some(-0.9), None],
            vec![Some(0.5), None],
        ];
        assert_eq!(strongest_dims(&map), vec![Some((1, -0.9)), None]);
        assert!(strongest_dims(&[]).is_empty());
    }

    #[test]
    fn mean_off_diagonal_ignores_the_diagonal_and_missing_cells() {
        let map = vec![
            vec![Some(1.0), Some(-0.5), None],
            vec![Some(-0.5), Some(1.0), None],
            vec![None, None, None],
        ];
        assert_eq!(mean_off_diagonal(&map), Some(0.5));
        assert_eq!(mean_off_diagonal(&[vec![Some(1.0)]]), None);
    }

    #[test]
    fn decoding_checks_the_codes_and_gives_images_of_the_input_size() {
        let config = softtouch_trainer::ModelConfig {
            width: 4,
            latent: 6,
            preprocess: softtouch_trainer::Preprocess {
                size_px: 16,
                ..softtouch_trainer::Preprocess::default()
            },
            ..softtouch_trainer::ModelConfig::default()
        };
        let artifact = ModelArtifact::untrained(&config, 1).expect("model");
        let codes = vec![vec![0.0f32; 6], vec![5.0; 6]];
        let decoded = decode(&artifact, &codes)
            .expect("decodes")
            .expect("decoder");
        assert_eq!(decoded.size, 16);
        assert_eq!(decoded.images.len(), 2);
        assert!(decoded.images.iter().all(|i| i.len() == 16 * 16 * 3));
        assert!(decode(&artifact, &[vec![0.0; 5]]).is_err(), "wrong length");
        assert!(decode(&artifact, &[vec![f32::NAN; 6]]).is_err(), "NaN");
        let convnet = ModelArtifact::untrained(
            &softtouch_trainer::ModelConfig {
                kind: softtouch_trainer::ModelKind::Convnet,
                ..config
            },
            1,
        )
        .expect("model");
        assert!(decode(&convnet, &codes).expect("no error").is_none());
    }
}
