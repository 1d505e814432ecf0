//! The page: one maud template per section. maud checks the markup at compile time
//! and escapes every interpolated value; only the SVG figures (whose text plotters has
//! escaped) go in as they are.

use super::csv::{SweepFile, SweepKind};
use super::data::{DatasetData, RunData, config_hash};
use super::svg::{self, Panel, Xy};
use super::{Content, ModelData, ReportError};
use crate::store::rows::seed_from_sql;
use maud::{DOCTYPE, Markup, PreEscaped, html};
use softtouch_collector::plot::{Series, SeriesStyle};
use softtouch_trainer::metrics::RangeError;
use softtouch_trainer::{AXES, UNITS};
use std::collections::BTreeSet;

/// A row of the paper's Table 1: model, α (SVAE rows), image MSE, mean R² in %.
type PaperRow = (&'static str, Option<f64>, Option<f64>, Option<f64>);

/// The paper's Table 1.
const PAPER_TABLE1: [PaperRow; 8] = [
    ("ConvNet", None, None, Some(96.04)),
    ("SVAE", Some(0.001), Some(5.19e-2), Some(99.53)),
    ("SVAE", Some(0.01), Some(5.17e-2), Some(99.52)),
    ("SVAE", Some(0.1), Some(2.02e-2), Some(99.53)),
    ("SVAE", Some(1.0), Some(9.47e-3), Some(99.45)),
    ("SVAE", Some(10.0), Some(6.68e-3), Some(96.22)),
    ("SVAE", Some(100.0), Some(5.65e-3), Some(61.46)),
    ("VAE", None, Some(5.36e-3), None),
];
/// The paper's error standard deviation per force range [0,2) … [8,10) N (Fig. 2c).
const PAPER_FORCE_STD_N: [f64; 5] = [0.07, 0.06, 0.09, 0.12, 0.24];
/// The same per torque range [0,120) … [480,600) N·mm.
const PAPER_TORQUE_STD_NMM: [f64; 5] = [4.6, 3.9, 6.0, 9.1, 20.3];

const CSS: &str = "
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:0;color:#1b1b1b;background:#fafafa;line-height:1.4}
header,main,footer{max-width:1180px;margin:0 auto;padding:0 20px}
header{padding-top:18px}
h1{margin:0 0 4px 0;font-size:1.7em}
h2{border-bottom:2px solid #0072b2;padding-bottom:3px;margin-top:34px}
h3{margin:22px 0 6px 0}
nav a{margin-right:14px}
.prov{font-size:.86em;color:#555}
.prov code{font-size:.95em}
.todo{background:#fff4d6;border-left:4px solid #e69f00;padding:8px 12px}
.note{font-size:.9em;color:#444}
table{border-collapse:collapse;margin:6px 0 10px 0;font-size:.88em;display:block;overflow-x:auto;max-width:100%}
th{font-weight:600}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right;background:#fff}
th{background:#eef3f8}
td.l,th.l{text-align:left}
td.nw{white-space:nowrap}
.figs{display:flex;flex-wrap:wrap;gap:8px}
.figs svg{background:#fff;border:1px solid #e3e3e3;max-width:100%;height:auto}
code{background:#f0f0f0;padding:0 3px}
";

fn f(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".into(), |v| f(v, digits))
}

fn sci(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite())
        .map_or_else(|| "–".into(), |v| format!("{v:.2e}"))
}

fn figure(svg: Option<String>) -> Markup {
    html! { @if let Some(svg) = svg { (PreEscaped(svg)) } }
}

/// What to run, as a highlighted note.
fn todo(text: &str, commands: &[&str]) -> Markup {
    html! {
        div.todo {
            (text)
            @for c in commands { br; code { (c) } }
        }
    }
}

/// Renders the page.
pub(crate) fn render(c: &Content) -> Result<String, ReportError> {
    let version = env!("CARGO_PKG_VERSION");
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { "softtouch report: " (c.db.display().to_string()) }
                style { (PreEscaped(CSS)) }
            }
            body {
                header {
                    h1 { "softtouch report" }
                    p.prov {
                        "Database " code { (c.db.display().to_string()) }
                        " (schema " (c.schema_version) "), written by softtouch " (version)
                        " at " (c.generated_at) ". "
                        @if let Some(runs) = &c.options.runs {
                            "Runs: " (join(runs.iter())) ". "
                        } @else { "All runs. " }
                        @if let Some(models) = &c.options.models {
                            "Models: " (models.join(", ")) ". "
                        } @else { "All models. " }
                        "Forces in N, torques in N·mm, sensor frame."
                    }
                    nav {
                        a href="#runs" { "Runs" }
                        a href="#datasets" { "Datasets" }
                        a href="#models" { "Models" }
                        a href="#sweeps" { "Sweeps" }
                        a href="#land-to-water" { "Land to water" }
                        a href="#grasping" { "Grasping" }
                    }
                }
                main {
                    (runs_section(c)?)
                    (datasets_section(c)?)
                    (models_section(c)?)
                    (sweeps_section(c)?)
                    (land_to_water_section())
                    (grasping_section())
                }
                footer {
                    p.prov {
                        "Made by " code { "softtouch report" } " " (version)
                        " from the database alone (read-only) and the result files named above. No scripts, no network."
                    }
                }
            }
        }
    };
    Ok(page.into_string())
}

fn join<T: std::fmt::Display>(items: impl Iterator<Item = T>) -> String {
    items.map(|x| x.to_string()).collect::<Vec<_>>().join(", ")
}

// ---------------------------------------------------------------- Runs

fn runs_section(c: &Content) -> Result<Markup, ReportError> {
    let mut per_run = Vec::new();
    for r in &c.runs {
        per_run.push(run_detail(r)?);
    }
    let bench = collection_figures(c)?;
    Ok(html! {
        section #runs {
            h2 { "Runs" }
            @if c.runs.is_empty() {
                (todo("No runs in this database yet. Collect samples (on the simulated rig without a config):",
                      &["softtouch collect --samples 300 --seed 1"]))
            } @else {
                p.prov { "Provenance: each run's seed, and under each run the SHA-256 prefix of its resolved rig and scene TOML and the softtouch version that collected it." }
                table {
                    tr {
                        th { "run" } th.l { "status" } th.l { "scene" } th.l { "medium" } th { "seed" }
                        th { "planned" } th { "ok" } th { "rejected" } th { "retried" } th { "accepted, %" }
                        th { "rate, ok samples/h (run clock)" } th { "wall time, h" } th { "events" } th { "warnings + errors" }
                    }
                    @for d in &c.runs {
                        @let r = &d.row;
                        @let id = r.counts.run_id;
                        @let taken = r.counts.ok + r.counts.rejected;
                        tr {
                            td data-k=(format!("run-{id}-id")) { (id) }
                            td.l { (r.counts.status) }
                            td.l data-k=(format!("run-{id}-scene")) { (r.counts.scene_name) }
                            td.l { (r.counts.medium) }
                            td data-k=(format!("run-{id}-seed")) { (seed_from_sql(r.counts.seed)) }
                            td { (r.counts.samples_planned) }
                            td data-k=(format!("run-{id}-ok")) { (r.counts.ok) }
                            td data-k=(format!("run-{id}-rejected")) { (r.counts.rejected) }
                            td data-k=(format!("run-{id}-retried")) { (r.counts.retried) }
                            td { @if taken > 0 { (f(100.0 * r.counts.ok as f64 / taken as f64, 1)) } @else { "–" } }
                            td data-k=(format!("run-{id}-rate")) { (run_rate(r).map_or_else(|| "–".into(), |v| f(v, 0))) }
                            td { (f(r.counts.hours, 3)) }
                            td data-k=(format!("run-{id}-events")) { (r.counts.events) }
                            td { (r.counts.faults) }
                        }
                    }
                }
                @for m in per_run { (m) }
            }
            h3 { "Accuracy against time (bench collection)" }
            (bench)
        }
    })
}

/// Accepted samples per hour of run clock, from the first frame to the last.
fn run_rate(r: &super::data::RunRow) -> Option<f64> {
    let span_h = (r.last_t_ns? - r.first_t_ns?) as f64 / 3.6e12;
    (span_h > 0.0).then(|| r.counts.ok as f64 / span_h)
}

fn run_detail(d: &RunData) -> Result<Markup, ReportError> {
    let r = &d.row;
    let id = r.counts.run_id;
    let origin = r
        .first_t_ns
        .into_iter()
        .chain(d.timeline.iter().map(|e| e.0))
        .min()
        .unwrap_or(0);
    let hours = |t: i64| (t - origin) as f64 / 3.6e12;
    let progress = [
        Series {
            label: "accepted".into(),
            points: d
                .progress
                .iter()
                .map(|p| (hours(p.0), p.1 as f64))
                .collect(),
            style: SeriesStyle::Line,
        },
        Series {
            label: "rejected".into(),
            points: d
                .progress
                .iter()
                .map(|p| (hours(p.0), p.2 as f64))
                .collect(),
            style: SeriesStyle::Line,
        },
    ];
    let progress_title = format!("Run {id}: samples taken");
    let progress_svg = svg::xy(
        &Xy {
            title: &progress_title,
            x_label: "run clock since the first frame, h",
            y_label: "samples so far",
            series: &progress,
            diagonal: false,
            y_range: None,
            marker_px: 2,
        },
        (560, 300),
    )?;
    let kinds: Vec<String> = d
        .timeline
        .iter()
        .map(|e| e.1.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let timeline_svg = if d.timeline.is_empty() {
        None
    } else {
        let events: Vec<(f64, usize, String)> = d
            .timeline
            .iter()
            .map(|(t, kind, level)| {
                (
                    hours(*t),
                    kinds.iter().position(|k| k == kind).unwrap_or(0),
                    level.clone(),
                )
            })
            .collect();
        let (lo, hi) = events
            .iter()
            .map(|e| e.0)
            .chain(d.progress.iter().map(|p| hours(p.0)))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(x), b.max(x))
            });
        let rows = kinds.len() as u32;
        Some(svg::timeline(
            &format!("Run {id}: events"),
            &kinds,
            &events,
            (lo, hi),
            (560, (110 + 26 * rows).min(520)),
        )?)
    };
    Ok(html! {
        h3 id=(format!("run-{id}")) { "Run " (id) ": " (r.counts.scene_name) ", " (r.counts.medium) }
        p.prov {
            "seed " (seed_from_sql(r.counts.seed)) " · rig " code { (config_hash(&r.rig_toml)) }
            " · scene " code { (config_hash(&r.scene_toml)) } " · softtouch " (r.software_version)
            " · created " (r.counts.created_at) " · last change " (r.counts.updated_at)
        }
        div.figs {
            (figure(progress_svg))
            (figure(timeline_svg))
        }
        @if d.timeline.len() as i64 >= super::data::MAX_TIMELINE {
            p.note { "The timeline shows the first " (super::data::MAX_TIMELINE) " events with a run-clock time; the counts below have them all." }
        }
        div.figs {
            table {
                tr { th.l { "reject reason" } th { "samples" } }
                @if d.rejects.is_empty() { tr { td.l colspan="2" { "none rejected" } } }
                @for (reason, n) in &d.rejects {
                    tr { td.l { (reason) } td data-k=(format!("run-{id}-reject-{reason}")) { (n) } }
                }
            }
            table {
                tr { th.l { "event" } th.l { "level" } th { "count" } }
                @if d.event_counts.is_empty() { tr { td.l colspan="3" { "no events" } } }
                @for ((kind, level), n) in &d.event_counts {
                    tr { td.l { (kind) } td.l { (level) } td data-k=(format!("run-{id}-event-{kind}-{level}")) { (n) } }
                }
            }
        }
        @if !d.latest.is_empty() {
            table {
                tr { th { "sample" } th.l { "when (UTC)" } th.l { "level" } th.l { "event" } th.l { "message" } }
                @for (sample, at, level, kind, message) in &d.latest {
                    tr {
                        td { (sample.map_or_else(|| "–".to_owned(), |s| s.to_string())) }
                        td.l.nw { (at) } td.l { (level) } td.l { (kind) } td.l { (message) }
                    }
                }
            }
        }
    })
}

fn collection_figures(c: &Content) -> Result<Markup, ReportError> {
    let Some(file) = &c.collection else {
        return Ok(todo(
            "No collection benchmark given. Measure label error against samples per hour over settle time and window length, then pass its CSV:",
            &[
                "softtouch bench collection --out bench-out",
                "softtouch report --out report.html --bench-collection bench-out/collection-sweep.csv",
            ],
        ));
    };
    let windows: BTreeSet<u64> = file.points.iter().map(|p| p.window_s.to_bits()).collect();
    let series_of = |pick: fn(&super::csv::CollectionPoint) -> f64| -> Vec<Series> {
        windows
            .iter()
            .map(|&w| {
                let w = f64::from_bits(w);
                let mut pts: Vec<(f64, f64)> = file
                    .points
                    .iter()
                    .filter(|p| p.window_s.to_bits() == w.to_bits())
                    .map(|p| (p.samples_per_hour, pick(p)))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                Series {
                    label: format!("window {} ms", f(w * 1e3, 0)),
                    points: pts,
                    style: SeriesStyle::LinePoints,
                }
            })
            .collect()
    };
    let force = series_of(|p| p.force_rmse_n);
    let torque = series_of(|p| p.torque_rmse_nmm);
    let fig = |title: &str, y: &str, s: &[Series]| {
        svg::xy(
            &Xy {
                title,
                x_label: "samples per hour (rig clock)",
                y_label: y,
                series: s,
                diagonal: false,
                y_range: None,
                marker_px: 3,
            },
            (560, 340),
        )
    };
    let force_svg = fig("Force label error against speed", "force RMSE, N", &force)?;
    let torque_svg = fig(
        "Torque label error against speed",
        "torque RMSE, N·mm",
        &torque,
    )?;
    Ok(html! {
        p.prov { "From " code { (file.path.display().to_string()) } " (sha256 " code { (file.hash) } "), "
            (file.points.len()) " points; each line is one window length, its points the settle times." }
        div.figs { (figure(force_svg)) (figure(torque_svg)) }
        table {
            tr { th { "settle, s" } th { "window, s" } th { "samples" } th { "accepted" } th { "force RMSE, N" } th { "torque RMSE, N·mm" } th { "samples/h" } }
            @for p in &file.points {
                tr { td { (p.settle_s) } td { (p.window_s) } td { (p.samples) } td { (p.accepted) }
                     td { (f(p.force_rmse_n, 4)) } td { (f(p.torque_rmse_nmm, 3)) } td { (f(p.samples_per_hour, 0)) } }
            }
        }
    })
}

// ---------------------------------------------------------------- Datasets

fn datasets_section(c: &Content) -> Result<Markup, ReportError> {
    let mut figs = Vec::new();
    for d in &c.datasets {
        figs.push(dataset_figure(d)?);
    }
    Ok(html! {
        section #datasets {
            h2 { "Datasets" }
            @if c.datasets.is_empty() {
                (todo("No datasets yet. Make one over collected runs (seeded 7:1:2 split):",
                      &["softtouch dataset create land-v1 --runs 1 --split 7:1:2 --seed 1"]))
            } @else {
                p.prov { "Provenance: the split seed, the runs drawn on, the SHA-256 prefix of the stored definition (runs, filters, ratio, seed, algorithm) and the softtouch version that made it." }
                table {
                    tr { th.l { "dataset" } th { "samples" } th { "train" } th { "val" } th { "test" } th.l { "ratio" }
                         th { "split seed" } th.l { "runs" } th.l { "definition hash" } th.l { "software" } th.l { "created (UTC)" } }
                    @for d in &c.datasets {
                        @let id = d.dataset_id;
                        tr {
                            td.l data-k=(format!("dataset-{id}-name")) { (d.name) }
                            td data-k=(format!("dataset-{id}-samples")) { (d.sample_count) }
                            td data-k=(format!("dataset-{id}-train")) { (d.splits[0]) }
                            td data-k=(format!("dataset-{id}-val")) { (d.splits[1]) }
                            td data-k=(format!("dataset-{id}-test")) { (d.splits[2]) }
                            td.l { (d.split_ratio) }
                            td { (seed_from_sql(d.seed)) }
                            td.l { (join(d.runs.iter())) }
                            td.l { code { (config_hash(&d.definition_json)) } }
                            td.l { (d.software_version) }
                            td.l { (d.created_at) }
                        }
                    }
                }
                p.note { "Histograms of the labels (the paper's Figure S1e: forces within about ±10 N, torques within about ±600 N·mm)." }
                @for (d, fig) in c.datasets.iter().zip(figs) {
                    h3 { "Dataset " (d.name) }
                    div.figs { (PreEscaped(fig)) }
                }
            }
        }
    })
}

fn dataset_figure(d: &DatasetData) -> Result<String, ReportError> {
    let panels: Vec<Panel> = (0..6)
        .map(|axis| Panel {
            x_label: format!("{}, {}", AXES[axis], UNITS[axis]),
            bins: softtouch_collector::plot::bin(&d.values[axis], 40),
        })
        .collect();
    svg::histograms(
        &format!("{}: label histograms ({} samples)", d.name, d.sample_count),
        &panels,
        3,
        (1000, 460),
    )
}

// ---------------------------------------------------------------- Models

fn models_section(c: &Content) -> Result<Markup, ReportError> {
    let mut details = Vec::new();
    for m in &c.models {
        details.push(model_detail(m)?);
    }
    Ok(html! {
        section #models {
            h2 { "Models" }
            @if c.models.is_empty() {
                (todo("No models yet. Train one on a dataset (it is stored with its metrics and per-epoch history):",
                      &["softtouch train --dataset land-v1"]))
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
                p.note { "The paper: R² above 0.98 on every axis of the test set; Table 1 gives 99.45 % mean R² for the SVAE at α = 1." }
                @for d in details { (d) }
            }
        }
    })
}

fn model_detail(m: &ModelData) -> Result<Markup, ReportError> {
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
            p.note { "Standard deviation of predicted − true, pooled over the three axes, per range of |true| on the whole test split; the paper's values beside." }
            div.figs { (PreEscaped(force)) (PreEscaped(torque)) }
        } @else {
            p.note { "No wrench errors stored (the VAE predicts none)." }
        }
    })
}

fn range_label(r: &RangeError) -> String {
    match r.upper {
        Some(u) => format!("[{}, {})", r.lower, u),
        None => format!("≥ {}", r.lower),
    }
}

fn spread_figure(
    name: &str,
    what: &str,
    unit: &str,
    ours: &[RangeError],
    paper: &[f64],
) -> Result<String, ReportError> {
    let categories: Vec<String> = ours.iter().map(range_label).collect();
    let series = vec![
        (
            name.to_owned(),
            ours.iter()
                .map(|r| if r.count > 1 { r.error_std } else { f64::NAN })
                .collect(),
        ),
        (
            "paper".to_owned(),
            (0..ours.len())
                .map(|i| paper.get(i).copied().unwrap_or(f64::NAN))
                .collect(),
        ),
    ];
    svg::bars(
        &format!("{name}: {what} error spread"),
        &format!("|true {what}|, {unit}"),
        &format!("error std, {unit}"),
        &categories,
        &series,
        (520, 300),
    )
}

// ---------------------------------------------------------------- Sweeps

fn sweeps_section(c: &Content) -> Result<Markup, ReportError> {
    let mut parts = Vec::new();
    for s in &c.sweeps {
        parts.push(sweep_part(s)?);
    }
    let has = |k: SweepKind| c.sweeps.iter().any(|s| s.kind == k);
    Ok(html! {
        section #sweeps {
            h2 { "Sweeps" }
            p.note { "Sweep rows are not stored in the database: the sweep verbs write CSV files, which the report reads when given with --sweep." }
            @for p in parts { (p) }
            @if !has(SweepKind::Alpha) {
                (todo("No Table 1 (α sweep) given. Run it on a dataset, then pass its CSV:",
                      &["softtouch sweep alpha --dataset land-v1 --out sweep-out",
                        "softtouch report --out report.html --sweep sweep-out/sweep-alpha.csv"]))
            }
            @if !has(SweepKind::Latent) {
                (todo("No latent-size sweep (Method S2) given. Run it, then pass its CSV:",
                      &["softtouch sweep latent --dataset land-v1 --out sweep-out",
                        "softtouch report --out report.html --sweep sweep-out/sweep-latent.csv"]))
            }
        }
    })
}

fn paper_row(row: &super::csv::SweepRow) -> Option<(Option<f64>, Option<f64>)> {
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

fn sweep_part(s: &SweepFile) -> Result<Markup, ReportError> {
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
                h3 { "Table 1: α sweep" }
                (source)
                table {
                    tr { th.l { "row" } th { "epochs" } th { "image MSE" } th { "paper image MSE" } th { "R², mean, %" } th { "paper R², %" } }
                    @for (i, r) in s.rows.iter().enumerate() {
                        @let paper = paper_row(r);
                        tr {
                            td.l { (r.label) } td { (r.epochs) }
                            td data-k=(format!("sweep-alpha-{i}-mse")) { (sci(r.image_mse)) }
                            td { (sci(paper.and_then(|p| p.0))) }
                            td data-k=(format!("sweep-alpha-{i}-r2")) { (opt(r.r2_mean.map(|v| v * 100.0), 2)) }
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
                h3 { "Latent-size sweep (Method S2)" }
                (source)
                p.note { "The paper compares 6, 16, 32, 64, 128 and 256 latent dimensions and chooses 32; it publishes no numbers for the others." }
                table {
                    tr { th { "latent" } th { "epochs" } th { "image MSE" } th { "R², mean" } @for a in AXES { th { "R² " (a) } } }
                    @for (i, r) in s.rows.iter().enumerate() {
                        tr {
                            td { (r.latent) } td { (r.epochs) } td { (sci(r.image_mse)) }
                            td data-k=(format!("sweep-latent-{i}-r2")) { (opt(r.r2_mean, 4)) }
                            @for v in r.r2 { td { (opt(v, 4)) } }
                        }
                    }
                }
                div.figs { (figure(svg)) }
            }
        }
        SweepKind::Model => html! {
            h3 { "Model benchmark" }
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

// ---------------------------------------------------------------- Not landed yet

fn land_to_water_section() -> Markup {
    html! {
        section #land-to-water {
            h2 { "Land to water" }
            (todo("This report does not show the land-to-water comparison yet. Collect the water run with the land run's poses; softtouch transfer prints the comparison and writes a CSV, sweep finetune the fine-tuning curve (CSV, PNG), latent the latent figures (PNGs):",
                  &["softtouch collect --scene scenes/water.toml --poses-from 1",
                    "softtouch dataset create water-v1 --runs 2",
                    "softtouch transfer --model land-v1-svae --land land-v1 --water water-v1",
                    "softtouch sweep finetune --init land-v1-svae --dataset water-v1",
                    "softtouch latent land-v1-svae --dataset land-v1 --water water-v1"]))
        }
    }
}

fn grasping_section() -> Markup {
    html! {
        section #grasping {
            h2 { "Grasping" }
            (todo("This report does not show grasping yet. The verbs print their tables and write CSVs and PNGs (success with Wilson intervals beside the paper's Figure 4f; force following, disturbance and twist traces of Figure 5; the bench grasp trade-offs), and the trials are stored as grasp sessions:",
                  &["softtouch grasp trials --model land-v1-svae --trials 10 --sigma-mm 5",
                    "softtouch grasp follow --model land-v1-svae --targets 0.4,1.6,3",
                    "softtouch bench grasp --model land-v1-svae"]))
        }
    }
}
