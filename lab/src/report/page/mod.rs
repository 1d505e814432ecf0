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
                    (grasping_section(c)?)
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
