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

mod datasets;
use datasets::*;
mod models;
use models::*;
mod runs;
use runs::*;
mod sweeps;
use sweeps::*;
mod grasping;
use grasping::*;
mod figure5;
use figure5::*;
mod land_water;
use land_water::*;

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
/// The paper's mean test R² of the SVAE at α = 1 (the default model), %: Table 1's row,
/// quoted once wherever the page quotes it.
fn paper_svae_r2_pct() -> f64 {
    PAPER_TABLE1
        .iter()
        .find(|(n, a, _, _)| *n == "SVAE" && *a == Some(1.0))
        .and_then(|row| row.3)
        .unwrap_or(f64::NAN)
}

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
.trial{display:flex;flex-wrap:wrap;gap:8px;align-items:flex-start}
.frames{display:flex;flex-wrap:wrap;gap:6px;max-width:340px}
.frames figure{margin:0;font-size:.8em;color:#444;text-align:center}
.frames img{display:block;border:1px solid #ccc;image-rendering:auto}
table.heat td{padding:2px 4px;font-size:.8em;text-align:center}
table.heat caption{text-align:left;font-size:.9em;padding:2px 0}
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
/// A hint's command with the database's own names: `{model}` the best stored SVAE by
/// test R² (else any stored model, else `land-v1-svae`, what `train --dataset land-v1`
/// names), `{dataset}` that model's dataset (else the first stored dataset, else
/// `land-v1`). A hint names what the database has where it has it.
fn hint(c: &Content, command: &str) -> String {
    let best = |kind: Option<&str>| {
        c.models
            .iter()
            .filter(|m| kind.is_none_or(|k| m.row.kind == k))
            .max_by(|a, b| {
                let r2 = |m: &ModelData| m.row.test_r2_mean.filter(|v| v.is_finite());
                r2(a)
                    .unwrap_or(f64::NEG_INFINITY)
                    .total_cmp(&r2(b).unwrap_or(f64::NEG_INFINITY))
            })
    };
    let model = best(Some("svae")).or_else(|| best(None));
    let model_name = model.map_or("land-v1-svae", |m| m.row.name.as_str());
    let dataset = model
        .map(|m| m.row.dataset_name.as_str())
        .filter(|d| !d.is_empty())
        .or_else(|| c.datasets.first().map(|d| d.name.as_str()))
        .unwrap_or("land-v1");
    command
        .replace("{model}", model_name)
        .replace("{dataset}", dataset)
}

/// [`todo`] with each command's names the database's own ([`hint`]).
fn todo_in(c: &Content, text: &str, commands: &[&str]) -> Markup {
    let commands: Vec<String> = commands.iter().map(|cmd| hint(c, cmd)).collect();
    let refs: Vec<&str> = commands.iter().map(String::as_str).collect();
    todo(text, &refs)
}

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
                title { "softtouch report: " (c.db) }
                style { (PreEscaped(CSS)) }
            }
            body {
                header {
                    h1 { "softtouch report" }
                    p.prov {
                        "Database " code { (c.db) }
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
                        a href="#summary" { "Summary" }
                        a href="#runs" { "Runs" }
                        a href="#datasets" { "Datasets" }
                        a href="#models" { "Models" }
                        a href="#sweeps" { "Sweeps" }
                        a href="#land-to-water" { "Land to water" }
                        a href="#grasping" { "Grasping" }
                        a href="#figure-5" { "Figure 5" }
                    }
                }
                main {
                    (summary_section(c))
                    (runs_section(c)?)
                    (datasets_section(c)?)
                    (models_section(c)?)
                    (sweeps_section(c)?)
                    (land_to_water_section(c)?)
                    (grasping_section(c)?)
                    (figure5_section(c)?)
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

/// One screen: what was collected, the best model, the latest grasp table, what else
/// is stored.
fn summary_section(c: &Content) -> Markup {
    let ok: i64 = c.runs.iter().map(|r| r.row.counts.ok).sum();
    let mut media: Vec<(String, i64, usize)> = Vec::new();
    for r in &c.runs {
        let m = &r.row.counts.medium;
        match media.iter_mut().find(|x| &x.0 == m) {
            Some(x) => {
                x.1 += r.row.counts.ok;
                x.2 += 1;
            }
            None => media.push((m.clone(), r.row.counts.ok, 1)),
        }
    }
    let best = c
        .models
        .iter()
        .filter_map(|m| Some((m, m.row.test_r2_mean.filter(|v| v.is_finite())?)))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    let worst_axis = best.and_then(|(m, _)| {
        let r2 = m.summary.as_ref()?.test.r2?;
        r2.iter()
            .enumerate()
            .min_by(|a, b| a.1.r2.total_cmp(&b.1.r2))
            .map(|(i, a)| (AXES[i], a.r2))
    });
    let latest = c.grasp.iter().rev().find(|g| !g.rows.is_empty());
    let mut verbs: Vec<(&str, usize)> = Vec::new();
    for r in &c.results.all {
        match verbs.iter_mut().find(|v| v.0 == r.row.verb) {
            Some(v) => v.1 += 1,
            None => verbs.push((&r.row.verb, 1)),
        }
    }
    html! {
        section #summary {
            h2 { "Summary" }
            ul {
                li {
                    "Collected: " span data-k="summary-ok" { (ok) } " accepted samples in " (c.runs.len()) " run(s)"
                    @if !media.is_empty() {
                        " (" (media.iter().map(|(m, n, runs)| format!("{m}: {n} in {runs} run(s)")).collect::<Vec<_>>().join(", ")) ")"
                    }
                    "; " (c.datasets.len()) " dataset(s), " (c.models.len()) " model(s)."
                }
                li {
                    @match best {
                        Some((m, r2)) => {
                            "Best model by test R² (mean of 6 axes): " code { (m.row.name) } " on " code { (m.row.dataset_name) } ", "
                            span data-k="summary-best-r2" { (f(r2, 4)) }
                            @if let Some((axis, v)) = worst_axis { " (worst axis " (axis) " " (f(v, 4)) ")" }
                            "; the paper's SVAE at α = 1: "
                            span data-k="summary-paper-r2" { (f(paper_svae_r2_pct() / 100.0, 4)) }
                            " (Table 1: " (f(paper_svae_r2_pct(), 2)) " %)."
                        }
                        None => { "No model that reads force yet: " code { "softtouch train --dataset NAME" } "." }
                    }
                }
                li {
                    @match latest {
                        Some(g) => {
                            "Latest grasp session (" a href=(format!("#grasp-session-{}", g.session.session_id)) { (g.session.session_id) } ", " (g.kind()) ", model " code { (g.session.model) } "): "
                            (g.cells.iter().filter(|cell| cell.object.is_none()).map(|cell| format!(
                                "σ {} mm {} {} {}/{} ({})",
                                cell.sigma_mm,
                                crate::report::grasp_sessions::medium(cell.medium),
                                cell.mode.as_str(),
                                cell.held,
                                cell.trials,
                                cell.rate().map_or_else(|| "–".to_owned(), |r| format!("{:.0} %, Wilson [{:.0}, {:.0}] %", 100.0 * r, 100.0 * cell.interval[0], 100.0 * cell.interval[1]))
                            )).collect::<Vec<_>>().join("; "))
                            "; the paper at σ 5 mm: land 44 → 100 %, water 30 → 90 % (open → closed)."
                        }
                        None => { "No grasp trials yet: " code { "softtouch grasp trials --model NAME" } "." }
                    }
                }
                li {
                    "Stored results: "
                    @if verbs.is_empty() { "none yet (the experiment verbs store theirs as they end)." }
                    @else {
                        (verbs.iter().map(|(v, n)| format!("{v} ×{n}")).collect::<Vec<_>>().join(", "))
                        " (" code { "softtouch results" } " lists them)."
                    }
                }
            }
        }
    }
}
