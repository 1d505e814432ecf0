//! The page's sweeps (Table 1, the latent sweep, the model benchmark) beside the paper's figures.

use super::*;

pub(super) fn sweeps_section(c: &Content) -> Result<Markup, ReportError> {
    let mut parts = Vec::new();
    // The nth sweep of a kind keys its cells `sweep{n}-…` from the second on: every
    // number on the page has one key.
    let mut seen: Vec<SweepKind> = Vec::new();
    for s in &c.sweeps {
        seen.push(s.kind);
        let n = seen.iter().filter(|k| **k == s.kind).count();
        parts.push(sweep_part(s, n)?);
    }
    let has = |k: SweepKind| c.sweeps.iter().any(|s| s.kind == k);
    Ok(html! {
        section #sweeps {
            h2 { "Sweeps" }
            p.note { "Each sweep is stored as it ends (" code { "softtouch results" } " lists them); every stored sweep is shown, then any older CSV given with --sweep." }
            @for p in &c.result_problems { p.todo { "Could not read: " (p) } }
            @for p in parts { (p) }
            @if !has(SweepKind::Alpha) {
                (todo_in(c, "No Table 1 (α sweep) stored. Run it on a dataset:",
                      &["softtouch sweep alpha --dataset {dataset}"]))
            }
            @if !has(SweepKind::Latent) {
                (todo_in(c, "No latent-size sweep (Method S2) stored. Run it:",
                      &["softtouch sweep latent --dataset {dataset}"]))
            }
        }
    })
}

pub(super) fn paper_row(row: &crate::report::csv::SweepRow) -> Option<(Option<f64>, Option<f64>)> {
    let name = match row.model.as_str() {
        "convnet" => "ConvNet",
        "vae" => "VAE",
        _ => "SVAE",
    };
    PAPER_TABLE1
        .iter()
        .find(|(n, a, _, _)| {
            *n == name
                && (name != "SVAE" || a.is_some_and(|a| (a - row.alpha).abs() <= 1e-9 * a.max(1.0)))
        })
        .map(|(_, _, mse, r2)| (*mse, *r2))
}

pub(super) fn sweep_part(s: &SweepFile, nth: usize) -> Result<Markup, ReportError> {
    let key = if nth > 1 {
        format!("sweep{nth}")
    } else {
        "sweep".to_owned()
    };
    // Each sweep's title says where it came from: a stored result or a CSV file.
    let origin = s.path.display().to_string();
    let source = html! {
        p.prov { "From " code { (s.path.display().to_string()) } " (sha256 " code { (s.hash) } "), " (s.rows.len()) " rows (the sweep verbs train every row on one dataset's split)." }
    };
    Ok(match s.kind {
        SweepKind::Alpha => {
            let ours = [
                Series {
                    label: "this sweep".into(),
                    points: s
                        .rows
                        .iter()
                        .filter(|r| r.model == "svae")
                        .map(|r| {
                            (
                                r.alpha.max(1e-9).log10(),
                                r.r2_mean.map_or(f64::NAN, |v| v * 100.0),
                            )
                        })
                        .collect(),
                    style: SeriesStyle::LinePoints,
                },
                Series {
                    label: "paper".into(),
                    points: PAPER_TABLE1
                        .iter()
                        .filter_map(|(_, a, _, r2)| Some((a.as_ref()?.log10(), (*r2)?)))
                        .collect(),
                    style: SeriesStyle::LinePoints,
                },
            ];
            let svg = svg::xy(
                &Xy {
                    title: "SVAE: test R² against α",
                    x_label: "log10 α",
                    y_label: "test R², mean of 6 axes, %",
                    series: &ours,
                    diagonal: false,
                    y_range: None,
                    marker_px: 3,
                },
                (560, 330),
            )?;
            html! {
                h3 { "Table 1: α sweep — " (origin) }
                (source)
                table {
                    tr { th.l { "row" } th { "epochs" } th { "image MSE" } th { "paper image MSE" } th { "R², mean, %" } th { "paper R², %" } }
                    @for (i, r) in s.rows.iter().enumerate() {
                        @let paper = paper_row(r);
                        tr {
                            td.l { (r.label) } td { (r.epochs) }
                            td data-k=(format!("{key}-alpha-{i}-mse")) { (sci(r.image_mse)) }
                            td { (sci(paper.and_then(|p| p.0))) }
                            td data-k=(format!("{key}-alpha-{i}-r2")) { (opt(r.r2_mean.map(|v| v * 100.0), 2)) }
                            td { (opt(paper.and_then(|p| p.1), 2)) }
                        }
                    }
                }
                div.figs { (figure(svg)) }
            }
        }
        SweepKind::Latent => {
            let series = [Series {
                label: "this sweep".into(),
                points: s
                    .rows
                    .iter()
                    .map(|r| (r.latent.max(1.0).log2(), r.r2_mean.unwrap_or(f64::NAN)))
                    .collect(),
                style: SeriesStyle::LinePoints,
            }];
            let svg = svg::xy(
                &Xy {
                    title: "SVAE: test R² against latent size",
                    x_label: "log2 latent dimensions",
                    y_label: "test R², mean of 6 axes",
                    series: &series,
                    diagonal: false,
                    y_range: None,
                    marker_px: 3,
                },
                (560, 330),
            )?;
            html! {
                h3 { "Latent-size sweep (Method S2) — " (origin) }
                (source)
                p.note { "The paper compares 6, 16, 32, 64, 128 and 256 latent dimensions and chooses 32; it publishes no numbers for the others." }
                table {
                    tr { th { "latent" } th { "epochs" } th { "image MSE" } th { "R², mean" } @for a in AXES { th { "R² " (a) } } }
                    @for (i, r) in s.rows.iter().enumerate() {
                        tr {
                            td { (r.latent) } td { (r.epochs) } td { (sci(r.image_mse)) }
                            td data-k=(format!("{key}-latent-{i}-r2")) { (opt(r.r2_mean, 4)) }
                            @for v in r.r2 { td { (opt(v, 4)) } }
                        }
                    }
                }
                div.figs { (figure(svg)) }
            }
        }
        SweepKind::Model => html! {
            h3 { "Model benchmark — " (origin) }
            (source)
            table {
                tr { th.l { "row" } th { "input, px" } th { "width" } th { "latent" } th { "epochs" } th { "latency, ms" } th { "image MSE" } th { "R², mean" } }
                @for r in &s.rows {
                    tr { td.l { (r.label) } td { (r.size_px) } td { (r.width) } td { (r.latent) } td { (r.epochs) }
                         td { (opt(r.latency_ms, 3)) } td { (sci(r.image_mse)) } td { (opt(r.r2_mean, 4)) } }
                }
            }
        },
    })
}
