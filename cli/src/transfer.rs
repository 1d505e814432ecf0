//! `softtouch transfer`: how a model fares on land and underwater, and how alike its
//! latents are for the same deformation in both media (Figure 3, Method S2).

use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::Args;
use softtouch_lab::models;
use softtouch_lab::transfer::{TransferError, paired_test, test_split};
use softtouch_schemas::wrench::AXES;
use softtouch_trainer::similarity::{
    Distribution, cosine_similarities, linear_cka, mmd_permutation_test,
};
use softtouch_trainer::{Example, FingerTable, Metrics, ModelArtifact, evaluate, latent_means};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `softtouch transfer`.
#[derive(Debug, Args)]
pub struct TransferArgs {
    /// The model to compare (typically trained on land).
    #[arg(long)]
    pub model: String,
    /// The land dataset (its test split; pairs may come from any of its splits).
    #[arg(long)]
    pub land: String,
    /// The water dataset: its test split, and the pairs among it whose runs were
    /// collected with `--poses-from` a run of the land dataset.
    #[arg(long)]
    pub water: String,
    /// A model trained on water, for the trained-on × tested-on table.
    #[arg(long)]
    pub water_model: Option<String>,
    /// A model trained on land and water together, for the same table.
    #[arg(long)]
    pub both_model: Option<String>,
    /// Permutations of the MMD test.
    #[arg(long, default_value_t = 200)]
    pub permutations: usize,
    /// Seed of the MMD test's subsample and permutations.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The CSV written (long format: section, model, tested_on, axis, metric, value).
    #[arg(long, default_value = "transfer.csv")]
    pub out: PathBuf,
}

impl From<TransferError> for Failure {
    fn from(e: TransferError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

/// One model on one test set.
struct Scored {
    model: String,
    tested_on: &'static str,
    metrics: Metrics,
}

/// Loads a stored model's artifact (bad input if there is none).
async fn load_model(
    store: &softtouch_store::Store,
    name: &str,
    device: &burn::prelude::Device,
) -> Result<ModelArtifact, Failure> {
    let bytes = models::artifact(store, name).await?;
    Ok(ModelArtifact::from_bytes(&bytes, device)?)
}

fn score(
    artifact: &ModelArtifact,
    examples: &[Example],
    device: &burn::prelude::Device,
) -> Result<Metrics, Failure> {
    let h = &artifact.header;
    Ok(evaluate(&artifact.net, &h.config, &h.norm, examples, device)?.0)
}

pub async fn run_transfer(
    args: TransferArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let started = Instant::now();
    if args.permutations == 0 {
        return Err(Failure::BadInput(anyhow!(
            "--permutations 0: expected at least 1"
        )));
    }
    let store = open_existing(db).await?;
    let device = softtouch_trainer::backend::device()?;
    let artifact = load_model(&store, &args.model, &device).await?;
    let preprocess = &artifact.header.config.preprocess;
    let table = FingerTable::new(preprocess);
    let land = test_split(&store, &args.land, &table).await?;
    let water = test_split(&store, &args.water, &table).await?;
    if land.examples.is_empty() || water.examples.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "an empty test split: `{}` has {}, `{}` has {} test samples",
            args.land,
            land.examples.len(),
            args.water,
            water.examples.len()
        )));
    }
    let pairs = paired_test(&store, &land, &water, &table).await?;
    let w = |e| io_failure(e);

    // 1. The same model on both media.
    let on_land = score(&artifact, &land.examples, &device)?;
    let on_water = score(&artifact, &water.examples, &device)?;
    writeln!(
        out,
        "model {} on land `{}` ({} test samples) and water `{}` ({} test samples)",
        args.model,
        args.land,
        land.examples.len(),
        args.water,
        water.examples.len()
    )
    .map_err(w)?;
    let mut csv = String::from("section,model,tested_on,axis,metric,value\n");
    match (&on_land.r2, &on_water.r2, &on_land.rmse, &on_water.rmse) {
        (Some(rl), Some(rw), Some(el), Some(ew)) => {
            writeln!(
                out,
                "axis   R² land   R² water   drop      RMSE land   RMSE water  unit"
            )
            .map_err(w)?;
            for (i, axis) in AXES.iter().enumerate() {
                writeln!(
                    out,
                    "{:<6} {:>8.5}  {:>9.5}  {:>+8.5}  {:>10.4}  {:>10.4}  {}",
                    axis.name,
                    rl[i].r2,
                    rw[i].r2,
                    rl[i].r2 - rw[i].r2,
                    el[i],
                    ew[i],
                    axis.report_unit
                )
                .map_err(w)?;
                for (tested_on, r2, rmse) in [("land", rl[i].r2, el[i]), ("water", rw[i].r2, ew[i])]
                {
                    csv.push_str(&format!(
                        "accuracy,{},{tested_on},{},r2,{r2}\naccuracy,{},{tested_on},{},rmse,{rmse}\n",
                        args.model, axis.key, args.model, axis.key
                    ));
                }
            }
        }
        _ => writeln!(out, "(model {} reads no force: no R²)", args.model).map_err(w)?,
    }

    // 2. The latents of the same deformation in both media.
    let h = &artifact.header;
    let latent_land = latent_means(&artifact.net, &h.config, &h.norm, &pairs.land, &device);
    let latent_water = latent_means(&artifact.net, &h.config, &h.norm, &pairs.water, &device);
    let bad = |e: softtouch_trainer::similarity::SimilarityError| {
        Failure::BadInput(anyhow!("paired latents: {e}"))
    };
    let cosines = cosine_similarities(&latent_land, &latent_water).map_err(bad)?;
    let cos = Distribution::of(&cosines).map_err(bad)?;
    let cka = linear_cka(&latent_land, &latent_water).map_err(bad)?;
    let mmd = mmd_permutation_test(&latent_land, &latent_water, args.permutations, args.seed)
        .map_err(bad)?;
    let runs: Vec<String> = pairs
        .runs
        .iter()
        .map(|(wr, lr)| format!("water run {wr} ↔ land run {lr}"))
        .collect();
    writeln!(
        out,
        "\npaired latents ({} pairs; {}; every pose checked):",
        cosines.len(),
        runs.join(", ")
    )
    .map_err(w)?;
    writeln!(
        out,
        "  cosine similarity per pair: mean {:.4}, std {:.4}, min {:.4}, quartiles {:.4} / {:.4} / {:.4}, max {:.4}",
        cos.mean, cos.std, cos.min, cos.p25, cos.median, cos.p75, cos.max
    )
    .map_err(w)?;
    writeln!(out, "  linear CKA land against water: {cka:.4}").map_err(w)?;
    writeln!(
        out,
        "  MMD² (RBF, bandwidth {:.4}, {} per side): {:.5}, permutation p = {:.4} ({} permutations, seed {})",
        mmd.bandwidth, mmd.used_per_side, mmd.mmd2, mmd.p_value, args.permutations, args.seed
    )
    .map_err(w)?;
    for (metric, value) in [
        ("cosine_mean", cos.mean),
        ("cosine_std", cos.std),
        ("cosine_min", cos.min),
        ("cosine_p25", cos.p25),
        ("cosine_median", cos.median),
        ("cosine_p75", cos.p75),
        ("cosine_max", cos.max),
        ("cka", cka),
        ("mmd2", mmd.mmd2),
        ("mmd_p", mmd.p_value),
    ] {
        csv.push_str(&format!(
            "latents,{},paired,,{metric},{value}\n",
            args.model
        ));
    }

    // 3. Trained on land, water, both; tested on land and water.
    let mut scored = vec![
        Scored {
            model: args.model.clone(),
            tested_on: "land",
            metrics: on_land,
        },
        Scored {
            model: args.model.clone(),
            tested_on: "water",
            metrics: on_water,
        },
    ];
    for name in [&args.water_model, &args.both_model].into_iter().flatten() {
        let other = load_model(&store, name, &device).await?;
        let (l, wa) = if other.header.config.preprocess == *preprocess {
            (
                score(&other, &land.examples, &device)?,
                score(&other, &water.examples, &device)?,
            )
        } else {
            // Another input size or threshold: its own preprocessing of the same splits.
            let t = FingerTable::new(&other.header.config.preprocess);
            let l = test_split(&store, &args.land, &t).await?;
            let wa = test_split(&store, &args.water, &t).await?;
            (
                score(&other, &l.examples, &device)?,
                score(&other, &wa.examples, &device)?,
            )
        };
        scored.push(Scored {
            model: name.clone(),
            tested_on: "land",
            metrics: l,
        });
        scored.push(Scored {
            model: name.clone(),
            tested_on: "water",
            metrics: wa,
        });
    }
    writeln!(
        out,
        "\nmodel                 tested on   R² mean    worst axis"
    )
    .map_err(w)?;
    for s in &scored {
        let (mean, worst) = match (&s.metrics.r2_mean, &s.metrics.r2) {
            (Some(m), Some(r2)) => {
                let (i, a) = r2
                    .iter()
                    .enumerate()
                    .min_by(|a, b| a.1.r2.total_cmp(&b.1.r2))
                    .map_or((0, f64::NAN), |(i, a)| (i, a.r2));
                (format!("{m:.5}"), format!("{} {a:.5}", AXES[i].name))
            }
            _ => ("-".into(), "-".into()),
        };
        writeln!(
            out,
            "{:<21} {:<10} {mean:>9}    {worst}",
            s.model, s.tested_on
        )
        .map_err(w)?;
        if let Some(m) = s.metrics.r2_mean {
            csv.push_str(&format!("table,{},{},,r2_mean,{m}\n", s.model, s.tested_on));
        }
    }
    store.close().await;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", dir.display())))?;
    }
    std::fs::write(&args.out, csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", args.out.display())))?;
    // The cosine of every pair, for its distribution (the report's histogram).
    let stem = args
        .out
        .file_stem()
        .map_or_else(|| "transfer".into(), |s| s.to_string_lossy().into_owned());
    let cos_path = args.out.with_file_name(format!("{stem}-cosines.csv"));
    let mut cos_csv = String::from("pair,cosine\n");
    for (i, c) in cosines.iter().enumerate() {
        cos_csv.push_str(&format!("{i},{c}\n"));
    }
    std::fs::write(&cos_path, cos_csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", cos_path.display())))?;
    let png = args.out.with_extension("png");
    plot_r2(&png, &scored)?;
    writeln!(
        out,
        "wrote {}, {} and {} in {:.1} s",
        args.out.display(),
        cos_path.display(),
        png.display(),
        started.elapsed().as_secs_f64()
    )
    .map_err(w)?;
    let drop_mean = match (scored[0].metrics.r2_mean, scored[1].metrics.r2_mean) {
        (Some(l), Some(wa)) => format!("R² mean {l:.4} on land, {wa:.4} on water"),
        _ => "no R² (a VAE)".into(),
    };
    super::results::Recorder::new("transfer")
        .model(&args.model)
        .dataset(&args.land)
        .setting("land", args.land.as_str())
        .setting("water", args.water.as_str())
        .setting("water_model", args.water_model.clone())
        .setting("both_model", args.both_model.clone())
        .setting("permutations", args.permutations)
        .setting("seed", args.seed)
        .table(&args.out)
        .table(&cos_path)
        .store(
            db,
            format!(
                "{drop_mean}; {} pairs: cosine median {:.3}, CKA {cka:.3}, MMD p = {:.3}",
                cosines.len(),
                cos.median,
                mmd.p_value
            ),
            out,
        )
        .await
        .map(drop)
}

/// The table as a plot: R² per axis of every model on each medium's test split.
fn plot_r2(png: &Path, scored: &[Scored]) -> Result<(), Failure> {
    use softtouch_collector::plot::{BarChart, BarSeries, bar_chart};
    let groups: Vec<String> = AXES.iter().map(|a| a.name.to_owned()).collect();
    let series: Vec<BarSeries> = scored
        .iter()
        .filter_map(|s| {
            let r2 = s.metrics.r2.as_ref()?;
            Some(BarSeries {
                label: format!("{} on {}", s.model, s.tested_on),
                bars: r2
                    .iter()
                    .map(|a| Some((a.r2, f64::NAN, f64::NAN)))
                    .collect(),
                reference: Vec::new(),
                notes: Vec::new(),
            })
        })
        .collect();
    if series.is_empty() {
        return Ok(());
    }
    // A model that transfers badly has R² below 0: the axis shows how far.
    let lowest = series
        .iter()
        .flat_map(|s| s.bars.iter().flatten().map(|b| b.0))
        .filter(|v| v.is_finite())
        .fold(0.0_f64, f64::min);
    bar_chart(
        png,
        &BarChart {
            title: "Land to water: test R² per axis",
            x_label: Some("axis"),
            y_label: "R², dimensionless",
            groups: &groups,
            series: &series,
            // Beyond −5 a bar ends at the axis, labelled with its value.
            y_range: (lowest.max(-5.0) - 0.05, 1.05),
            y_labels_up_to: Some(1.0),
        },
        (1100, 520),
    )
    .map_err(|e| Failure::Runtime(anyhow!("{e}")))
}
