//! Land to water from the stored results: the latest `transfer` (R² per axis on both
//! media and the drop, the paired latents' cosine distribution, CKA, MMD with its
//! p-value, models trained on land, water and both), `sweep finetune` (fine-tuned
//! against scratch over n) and `latent` (the correlation maps of Figure 3).

use super::*;
use crate::report::results::{Columns, provenance};
use crate::store::StoredResult;
use base64::Engine as _;

fn prov(r: &StoredResult) -> Markup {
    html! { p.prov { (provenance(&r.row)) } }
}

fn unreadable(what: &str, why: &str) -> Markup {
    html! { p.todo { "Could not read " (what) ": " (why) } }
}

pub(super) fn land_to_water_section(c: &Content) -> Result<Markup, ReportError> {
    let transfer = c.results.latest("transfer");
    let finetune = c.results.latest("sweep finetune");
    let latent = c.results.latest("latent");
    // The water dataset the hints name: the stored comparison's, else one to create.
    let water = transfer
        .and_then(|r| serde_json::from_str::<serde_json::Value>(&r.row.settings_json).ok())
        .and_then(|v| v.get("water").and_then(|w| w.as_str()).map(str::to_owned))
        .unwrap_or_else(|| "water-v1".to_owned());
    let finetune_hint = format!("softtouch sweep finetune --init {{model}} --dataset {water}");
    let latent_hint = format!("softtouch latent {{model}} --dataset {{dataset}} --water {water}");
    Ok(html! {
        section #land-to-water {
            h2 { "Land to water" }
            p.note { "The latest stored result of each verb (" code { "softtouch results" } " lists them all). Water runs repeat a land run's poses (" code { "collect --poses-from" } "), so each water test sample has its land partner." }
            h3 { "The same model on both media" }
            @match transfer {
                Some(r) => (transfer_part(r)?),
                None => (todo_in(c, "No land-to-water comparison stored. Collect the water run with the land run's poses, then:",
                              &["softtouch collect --scene water --poses-from 1",
                                "softtouch dataset create water-v1 --runs 2",
                                "softtouch transfer --model {model} --land {dataset} --water water-v1 --tare"])),
            }
            h3 { "Fine-tuning on water" }
            @match finetune {
                Some(r) => (finetune_part(r)?),
                None => (todo_in(c, "No fine-tuning curve stored:", &[&finetune_hint])),
            }
            h3 { "Latent correlation maps (Figure 3)" }
            @match latent {
                Some(r) => (latent_part(r)),
                None => (todo_in(c, "No latent maps stored:", &[&latent_hint])),
            }
        }
    })
}

/// `transfer.csv`'s rows: section, model, tested_on, axis, metric, value.
struct TransferRows {
    rows: Vec<(String, String, String, String, String, f64)>,
}

impl TransferRows {
    fn get(&self, section: &str, model: &str, on: &str, axis: &str, metric: &str) -> f64 {
        self.rows
            .iter()
            .find(|r| r.0 == section && r.1 == model && r.2 == on && r.3 == axis && r.4 == metric)
            .map_or(f64::NAN, |r| r.5)
    }
}

/// The lowest R² the land-to-water bars draw to (a model worse than the mean by more
/// is labelled with its value at the axis's end).
const R2_FLOOR: f64 = -1.0;

fn transfer_part(r: &StoredResult) -> Result<Markup, ReportError> {
    let id = r.row.result_id;
    let main = r.row.model.clone().unwrap_or_default();
    // The CSV's name is the verb's --out; the cosines sit beside it.
    let csv_name = r
        .tables
        .iter()
        .map(|(n, _)| n.as_str())
        .find(|n| !n.ends_with("-cosines.csv"))
        .unwrap_or("transfer.csv")
        .to_owned();
    let read = || -> Result<_, String> {
        let t = Columns::of(r, &csv_name)?;
        let s = |c: &str| {
            t.text(c)
                .map(|v| v.into_iter().map(str::to_owned).collect::<Vec<_>>())
        };
        let (sec, model, on, axis, metric) = (
            s("section")?,
            s("model")?,
            s("tested_on")?,
            s("axis")?,
            s("metric")?,
        );
        let value = t.num("value")?;
        let rows = (0..t.len())
            .map(|i| {
                (
                    sec[i].clone(),
                    model[i].clone(),
                    on[i].clone(),
                    axis[i].clone(),
                    metric[i].clone(),
                    value[i],
                )
            })
            .collect();
        let cos_name = r
            .tables
            .iter()
            .map(|(n, _)| n.as_str())
            .find(|n| n.ends_with("-cosines.csv"));
        let cosines = match cos_name {
            Some(n) => Columns::of(r, n)?.num("cosine")?,
            None => Vec::new(),
        };
        Ok((TransferRows { rows }, cosines))
    };
    let (t, cosines) = match read() {
        Ok(x) => x,
        Err(e) => return Ok(html! { (prov(r)) (unreadable("the comparison", &e)) }),
    };
    let axis_keys: Vec<&str> = softtouch_schemas::wrench::AXES
        .iter()
        .map(|a| a.key)
        .collect();
    let latent = |m: &str| t.get("latents", &main, "paired", "", m);
    let mut models: Vec<String> = Vec::new();
    for row in t.rows.iter().filter(|r| r.0 == "table") {
        if !models.contains(&row.1) {
            models.push(row.1.clone());
        }
    }
    let bins = histogram_bins(&cosines, 20);
    let hist = if bins.is_empty() {
        None
    } else {
        Some(svg::histograms(
            "Cosine similarity of paired latents (land against water)",
            &[svg::Panel {
                x_label: "cosine similarity, dimensionless".into(),
                bins,
            }],
            1,
            (560, 320),
        )?)
    };
    let r2 = |on: &str, i: usize| t.get("accuracy", &main, on, axis_keys[i], "r2");
    // `transfer --tare`: the water side through the image tare too.
    let tared = (0..6).any(|i| r2("water_tare", i).is_finite());
    let tare = |m: &str| t.get("tare", "", "water", "", m);
    let rmse = |on: &str, i: usize| t.get("accuracy", &main, on, axis_keys[i], "rmse");
    let bars_svg = svg::bars(
        "Test R² per axis: land and water",
        "axis",
        "R², dimensionless",
        &AXES.iter().map(|a| (*a).to_owned()).collect::<Vec<_>>(),
        &[
            (
                format!("{main} on land"),
                (0..6).map(|i| r2("land", i)).collect(),
                vec![None; 6],
            ),
            (
                format!("{main} on water"),
                (0..6).map(|i| r2("water", i)).collect(),
                vec![None; 6],
            ),
            (
                format!("{main} on water, image tare"),
                (0..6).map(|i| r2("water_tare", i)).collect(),
                vec![None; 6],
            ),
        ][..if tared { 3 } else { 2 }],
        R2_FLOOR,
        (560, 320),
    )?;
    // Every model of the comparison, not only the one whose latents were paired.
    let table_svg = if models.len() > 1 {
        let mean = |on: &str| -> Vec<f64> {
            models
                .iter()
                .map(|m| t.get("table", m, on, "", "r2_mean"))
                .collect()
        };
        Some(svg::bars(
            "Mean test R² of every model compared: land and water",
            "model",
            "R² (mean of 6 axes), dimensionless",
            &models,
            &[
                ("on land".to_owned(), mean("land"), Vec::new()),
                ("on water".to_owned(), mean("water"), Vec::new()),
            ],
            R2_FLOOR,
            (560, 320),
        )?)
    } else {
        None
    };
    Ok(html! {
        (prov(r))
        table {
            tr { th.l { "axis" } th { "R² land" } th { "R² water" } th { "drop" } th { "RMSE land" } th { "RMSE water" } @if tared { th { "R² water, tare" } th { "drop, tare" } } th.l { "unit" } }
            @for (i, a) in AXES.iter().enumerate() {
                tr {
                    td.l { (a) }
                    td data-k=(format!("transfer-{id}-land-{}", axis_keys[i])) { (f(r2("land", i), 4)) }
                    td data-k=(format!("transfer-{id}-water-{}", axis_keys[i])) { (f(r2("water", i), 4)) }
                    td { (f(r2("land", i) - r2("water", i), 4)) }
                    td { (f(rmse("land", i), 4)) } td { (f(rmse("water", i), 4)) }
                    @if tared {
                        td data-k=(format!("transfer-{id}-water-tare-{}", axis_keys[i])) { (f(r2("water_tare", i), 4)) }
                        td { (f(r2("land", i) - r2("water_tare", i), 4)) }
                    }
                    td.l { (UNITS[i]) }
                }
            }
        }
        table {
            tr { th.l { "paired latents" } th { "value" } }
            tr { td.l { "pairs" } td { (cosines.len()) } }
            tr { td.l { "cosine similarity, median [quartiles]" } td { (f(latent("cosine_median"), 4)) " [" (f(latent("cosine_p25"), 4)) ", " (f(latent("cosine_p75"), 4)) "]" } }
            tr { td.l { "cosine similarity, mean ± std" } td { (f(latent("cosine_mean"), 4)) " ± " (f(latent("cosine_std"), 4)) } }
            tr { td.l { "linear CKA" } td data-k=(format!("transfer-{id}-cka")) { (f(latent("cka"), 4)) } }
            @if tared {
                tr { td.l { "linear CKA, image tare" } td data-k=(format!("transfer-{id}-cka-tare")) { (f(t.get("latents", &main, "paired_tare", "", "cka"), 4)) } }
                tr { td.l { "cosine similarity, mean, image tare" } td { (f(t.get("latents", &main, "paired_tare", "", "cosine_mean"), 4)) } }
            }
            tr { td.l { "MMD² (RBF)" } td { (format!("{:.3e}", latent("mmd2"))) } }
            tr { td.l { "MMD permutation p-value" } td data-k=(format!("transfer-{id}-mmd-p")) { (f(latent("mmd_p"), 4)) } }
        }
        @if models.len() > 1 {
            table {
                tr { th.l { "model" } th { "R² mean on land" } th { "R² mean on water" } }
                @for m in &models {
                    tr { td.l { (m) } td { (f(t.get("table", m, "land", "", "r2_mean"), 4)) } td { (f(t.get("table", m, "water", "", "r2_mean"), 4)) } }
                }
            }
        }
        @if tared {
            p.note {
                "Image tare (from the runs' rest frames, no water label): scale " (f(tare("scale"), 4))
                " about the image centre, gain R " (f(tare("gain_r"), 3)) " G " (f(tare("gain_g"), 3)) " B " (f(tare("gain_b"), 3))
                @if tare("gain_map") > 0.5 { ", a per-pixel gain map" }
                "; the rest frames' RMS difference on the finger " (f(tare("rms_before"), 1)) " → "
                (f(if tare("gain_map") > 0.5 { tare("rms_after_map") } else { tare("rms_after") }, 1)) " (0–255)."
            }
        }
        p.note { "Bars from 0; an R² below 0 is worse than predicting the mean and hangs below the axis; one below −1 is drawn to the axis's end and labelled with its value." }
        div.figs { (PreEscaped(bars_svg)) (figure(table_svg)) (figure(hist)) }
    })
}

/// Equal-width bins over the finite values' range (one bin when they are all equal).
fn histogram_bins(values: &[f64], n: usize) -> Vec<(f64, f64, u64)> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let Some(lo) = finite.iter().copied().reduce(f64::min) else {
        return Vec::new();
    };
    let hi = finite.iter().copied().fold(lo, f64::max);
    if hi - lo <= f64::EPSILON * lo.abs().max(1.0) {
        return vec![(lo - 0.005, lo + 0.005, finite.len() as u64)];
    }
    let width = (hi - lo) / n as f64;
    let mut bins: Vec<(f64, f64, u64)> = (0..n)
        .map(|i| (lo + width * i as f64, lo + width * (i + 1) as f64, 0))
        .collect();
    for v in finite {
        let i = (((v - lo) / width) as usize).min(n - 1);
        bins[i].2 += 1;
    }
    bins
}

fn finetune_part(r: &StoredResult) -> Result<Markup, ReportError> {
    let id = r.row.result_id;
    let read = || -> Result<_, String> {
        let t = Columns::of(r, "finetune.csv")?;
        let start: Vec<String> = t.text("start")?.into_iter().map(str::to_owned).collect();
        Ok((
            start,
            t.num("samples")?,
            t.num("r2_mean")?,
            t.num("r2_min")?,
            t.num("epochs_run")?,
        ))
    };
    let (start, samples, mean, min, epochs) = match read() {
        Ok(x) => x,
        Err(e) => return Ok(html! { (prov(r)) (unreadable("the fine-tuning curve", &e)) }),
    };
    let series: Vec<Series> = ["fine-tuned", "scratch"]
        .iter()
        .map(|kind| Series {
            label: (*kind).into(),
            points: (0..start.len())
                .filter(|&i| start[i] == *kind && samples[i] > 0.0)
                .map(|i| (samples[i].log10(), mean[i]))
                .collect(),
            style: SeriesStyle::LinePoints,
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    let fig = svg::xy(
        &Xy {
            title: "Fine-tuning on water: test R² against training samples",
            x_label: "log10 training samples",
            y_label: "test R², mean of 6 axes",
            series: &series,
            diagonal: false,
            y_range: None,
            marker_px: 3,
        },
        (560, 320),
    )?;
    Ok(html! {
        (prov(r))
        table {
            tr { th { "samples" } th.l { "start" } th { "epochs" } th { "R² mean" } th { "R² worst axis" } }
            @for i in 0..start.len() {
                tr {
                    td { (samples[i]) } td.l { (start[i]) } td { (epochs[i]) }
                    td data-k=(format!("finetune-{id}-{i}-r2")) { (f(mean[i], 4)) }
                    td { (f(min[i], 4)) }
                }
            }
        }
        div.figs { (figure(fig)) }
    })
}

/// A correlation map as a table of coloured cells (blue negative, red positive).
fn heat_table(title: &str, rows: &[String], cols: &[String], r: &[Vec<f64>]) -> Markup {
    let colour = |v: f64| {
        if !v.is_finite() {
            return "background:#eee".to_owned();
        }
        let a = v.abs().min(1.0);
        let (cr, cg, cb) = if v >= 0.0 {
            (213, 94, 0)
        } else {
            (0, 114, 178)
        };
        format!("background:rgba({cr},{cg},{cb},{a:.2})")
    };
    html! {
        table.heat {
            caption { (title) }
            tr { th {} @for c in cols { th { (c) } } }
            @for (i, name) in rows.iter().enumerate() {
                tr {
                    th { (name) }
                    @for v in &r[i] { td style=(colour(*v)) title=(f(*v, 3)) { (f(*v, 2)) } }
                }
            }
        }
    }
}

fn latent_part(r: &StoredResult) -> Markup {
    let mut parts = Vec::new();
    for (name, _) in &r.tables {
        let read = || -> Result<_, String> {
            let t = Columns::of(r, name)?;
            let map: Vec<String> = t.text("map")?.into_iter().map(str::to_owned).collect();
            let row: Vec<String> = t.text("row")?.into_iter().map(str::to_owned).collect();
            let col: Vec<String> = t.text("column")?.into_iter().map(str::to_owned).collect();
            let v = t.num("r")?;
            let mut out = Vec::new();
            for which in ["latent", "wrench"] {
                let mut rows: Vec<String> = Vec::new();
                let mut cols: Vec<String> = Vec::new();
                for i in (0..map.len()).filter(|&i| map[i] == which) {
                    if !rows.contains(&row[i]) {
                        rows.push(row[i].clone());
                    }
                    if !cols.contains(&col[i]) {
                        cols.push(col[i].clone());
                    }
                }
                let mut m = vec![vec![f64::NAN; cols.len()]; rows.len()];
                for i in (0..map.len()).filter(|&i| map[i] == which) {
                    let a = rows.iter().position(|x| *x == row[i]).unwrap_or(0);
                    let b = cols.iter().position(|x| *x == col[i]).unwrap_or(0);
                    m[a][b] = v[i];
                }
                out.push((which, rows, cols, m));
            }
            Ok(out)
        };
        parts.push(match read() {
            Ok(maps) => html! {
                div.figs {
                    @for (which, rows, cols, m) in &maps {
                        (heat_table(&format!("{name}: {} map (Pearson r)", if *which == "latent" { "latent against latent" } else { "latent against wrench" }), rows, cols, m))
                    }
                }
            },
            Err(e) => unreadable(name, &e),
        });
    }
    html! {
        (prov(r))
        @for p in parts { (p) }
        @if r.figures.is_empty() {
            p.note { "This result stored no traversal or paired-instance images (a model without a decoder, or no --water)." }
        } @else {
            p.note { "Decoder traversals (one latent from −span to +span, the others at their test mean) and, with --water, the latent means of paired land and water instances, as " code { "softtouch latent" } " drew them:" }
            @for (name, png) in &r.figures {
                figure.stored {
                    img src=(format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(png)))
                        alt=(name) style="max-width:min(100%,760px);height:auto";
                    figcaption { (name) }
                }
            }
        }
    }
}
