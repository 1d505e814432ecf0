//! The page's models: the table, each model's metrics, predicted-against-true and error-spread figures.

use super::*;

pub(super) fn models_section(c: &Content) -> Result<Markup, ReportError> {
    let mut details = Vec::new();
    for m in &c.models {
        details.push(model_detail(m)?);
    }
    Ok(html! {
        section #models {
            h2 { "Models" }
            @if c.models.is_empty() {
                (todo_in(c, "No models yet. Train one on a dataset (it is stored with its metrics and per-epoch history):",
                      &["softtouch train --dataset {dataset}"]))
            } @else {
                p.prov { "Provenance: the training seed, the SHA-256 prefix of the stored model and training configs, and the softtouch version that trained it. Test metrics are on the whole test split, as stored at training time." }
                table {
                    tr {
                        th.l { "model" } th.l { "kind" } th.l { "dataset" } th { "epochs" } th { "test R², mean" }
                        @for a in AXES { th { "R² " (a) } }
                        th { "image MSE" } th { "train seed" } th.l { "config hash" } th.l { "software" }
                    }
                    @for m in &c.models {
                        @let r = &m.row;
                        @let id = r.model_id;
                        @let s = m.summary.as_ref();
                        tr {
                            td.l data-k=(format!("model-{id}-name")) { (r.name) }
                            td.l { (r.kind) }
                            td.l { (r.dataset_name) }
                            td { (s.map_or_else(|| "–".into(), |s| s.epochs_run.to_string())) }
                            td data-k=(format!("model-{id}-r2")) { (opt(r.test_r2_mean, 4)) }
                            @for axis in 0..6 {
                                td data-k=(format!("model-{id}-r2-{}", AXES[axis].to_lowercase())) {
                                    (opt(s.and_then(|s| s.test.r2).map(|r2| r2[axis].r2), 4))
                                }
                            }
                            td { (sci(r.test_image_mse)) }
                            td { (s.map_or_else(|| "–".into(), |s| s.train.seed.to_string())) }
                            td.l { code { (config_hash(&format!("{}\n{}", r.config_json, r.train_json))) } }
                            td.l { (r.software_version) }
                        }
                    }
                }
                p.note {
                    "The paper: R² above 0.98 on every axis of the test set; Table 1 gives "
                    span data-k="models-paper-r2" { (f(paper_svae_r2_pct() / 100.0, 4)) }
                    " (" (f(paper_svae_r2_pct(), 2)) " %) mean R² for the SVAE at α = 1."
                }
                @for d in details { (d) }
            }
        }
    })
}

pub(super) fn model_detail(m: &ModelData) -> Result<Markup, ReportError> {
    let r = &m.row;
    let epochs =
        |pick: fn(&softtouch_trainer::train::EpochReport) -> Option<f64>| -> Vec<(f64, f64)> {
            m.history
                .iter()
                .filter_map(|e| pick(e).map(|v| (e.epoch as f64, v)))
                .collect()
        };
    let loss = [Series {
        label: "training loss".into(),
        points: epochs(|e| Some(e.train_loss)),
        style: SeriesStyle::LinePoints,
    }];
    let val = [Series {
        label: if r.kind == "vae" {
            "validation image MSE".into()
        } else {
            "validation R², mean".into()
        },
        points: if r.kind == "vae" {
            epochs(|e| e.val_image_mse)
        } else {
            epochs(|e| e.val_r2_mean)
        },
        style: SeriesStyle::LinePoints,
    }];
    let loss_title = format!("{}: training loss", r.name);
    let loss_svg = svg::xy(
        &Xy {
            title: &loss_title,
            x_label: "epoch",
            y_label: "loss (standardised labels, dimensionless)",
            series: &loss,
            diagonal: false,
            y_range: None,
            marker_px: 3,
        },
        (420, 280),
    )?;
    let val_title = format!("{}: validation", r.name);
    let val_svg = svg::xy(
        &Xy {
            title: &val_title,
            x_label: "epoch",
            y_label: if r.kind == "vae" {
                "image MSE (pixels in [0,1])"
            } else {
                "R², dimensionless"
            },
            series: &val,
            diagonal: false,
            y_range: None,
            marker_px: 3,
        },
        (420, 280),
    )?;
    let mut scatters = Vec::new();
    if let Some(p) = &m.predictions {
        for axis in 0..6 {
            let series = [Series {
                label: String::new(),
                points: p
                    .pairs
                    .iter()
                    .map(|(t, q)| (f64::from(t[axis]), f64::from(q[axis])))
                    .collect(),
                style: SeriesStyle::Points,
            }];
            let title = format!("{} {}", r.name, AXES[axis]);
            let x_label = format!("true {}, {}", AXES[axis], UNITS[axis]);
            let y_label = format!("predicted {}, {}", AXES[axis], UNITS[axis]);
            scatters.push(svg::xy(
                &Xy {
                    title: &title,
                    x_label: &x_label,
                    y_label: &y_label,
                    series: &series,
                    diagonal: true,
                    y_range: None,
                    marker_px: 2,
                },
                (300, 290),
            )?);
        }
    }
    let spread = match &m.summary {
        Some(s) if !s.test.force_error_by_range.is_empty() => Some((
            spread_figure(
                &r.name,
                "force",
                "N",
                &s.test.force_error_by_range,
                &PAPER_FORCE_STD_N,
            )?,
            spread_figure(
                &r.name,
                "torque",
                "N·mm",
                &s.test.torque_error_by_range,
                &PAPER_TORQUE_STD_NMM,
            )?,
        )),
        _ => None,
    };
    let train_seed = m.summary.as_ref().map(|s| s.train.seed);
    Ok(html! {
        h3 id=(format!("model-{}", r.model_id)) { "Model " (r.name) }
        p.prov {
            (r.kind) " on dataset " (r.dataset_name)
            @if let Some(seed) = train_seed { " · training seed " (seed) }
            " · config " code { (config_hash(&format!("{}\n{}", r.config_json, r.train_json))) }
            " · softtouch " (r.software_version) " · trained " (r.created_at)
        }
        @for problem in &m.problems { p.todo { "Could not use this model's record: " (problem) } }
        h4 { "Training curves (per epoch)" }
        @if m.history.is_empty() {
            p.note { "No per-epoch history stored for this model." }
        } @else {
            div.figs { (figure(loss_svg)) (figure(val_svg)) }
        }
        h4 { "Predicted against true (Figure 2b)" }
        @match &m.predictions {
            Some(p) => {
                p.note data-k=(format!("model-{}-scatter", r.model_id)) {
                    (p.samples) " of the " (p.of) " test samples (evenly spaced), predicted now by the stored model. The paper's Figure 2b: points on the diagonal, R² > 0.98 on every axis."
                }
                div.figs { @for s in scatters { (figure(s)) } }
            }
            None => {
                p.note {
                    @if r.kind == "vae" { "The VAE predicts no wrench." }
                    @else { "No test frames to predict on: the dataset " (r.dataset_name) " is gone or its test split is empty." }
                }
            }
        }
        h4 { "Error spread per range (Figure 2c)" }
        @if let Some((force, torque)) = spread {
            p.note { "Standard deviation of predicted − true, pooled over the three axes, per range of |true| on the whole test split, with the number of labels n above each bar (none drawn where n < 2); the paper's values beside." }
            div.figs { (PreEscaped(force)) (PreEscaped(torque)) }
        } @else {
            p.note { "No wrench errors stored (the VAE predicts none)." }
        }
    })
}

pub(super) fn range_label(r: &RangeError) -> String {
    match r.upper {
        Some(u) => format!("[{}, {})", r.lower, u),
        None => format!("≥ {}", r.lower),
    }
}

pub(super) fn spread_figure(
    name: &str,
    what: &str,
    unit: &str,
    ours: &[RangeError],
    paper: &[f64],
) -> Result<String, ReportError> {
    // A range with no bar says its n under it.
    let categories: Vec<String> = ours
        .iter()
        .map(|r| {
            if r.count >= 2 {
                range_label(r)
            } else {
                format!("{} n={}", range_label(r), r.count)
            }
        })
        .collect();
    let series = vec![
        // No bar where fewer than 2 labels fall in the range: its n says why.
        (
            name.to_owned(),
            ours.iter()
                .map(|r| if r.count >= 2 { r.error_std } else { f64::NAN })
                .collect(),
            ours.iter()
                .map(|r| (r.count >= 2).then(|| format!("n={}", r.count)))
                .collect(),
        ),
        (
            "paper".to_owned(),
            (0..ours.len())
                .map(|i| paper.get(i).copied().unwrap_or(f64::NAN))
                .collect(),
            Vec::new(),
        ),
    ];
    svg::bars(
        &format!("{name}: {what} error spread"),
        &format!("|true {what}|, {unit}"),
        &format!("error std, {unit}"),
        &categories,
        &series,
        0.0,
        (520, 300),
    )
}
