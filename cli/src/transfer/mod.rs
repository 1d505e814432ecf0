//! `softtouch transfer`: how a model fares on land and underwater, and how alike its
//! latents are for the same deformation in both media (Figure 3, Method S2).

mod plot;
mod tare;

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
use std::path::PathBuf;
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
    /// Fit an image tare from the rest frames of both datasets' runs (the finger at
    /// rest, taken at each run's start; no water label) and score the water side
    /// with it as well: R², CKA and cosines with and without it
    /// (docs/land-to-water.md).
    #[arg(long)]
    pub tare: bool,
    /// With `--tare`: the scale, gain and offset only, no per-pixel gain map.
    #[arg(long, requires = "tare")]
    pub no_gain_map: bool,
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
    let land = test_split(&store, &args.land, &table, None).await?;
    let water = test_split(&store, &args.water, &table, None).await?;
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
    let mut csv = String::from("section,model,tested_on,axis,metric,value\n");
    // The water side again through the image tare (`--tare`).
    let tared = if args.tare {
        Some(tare::fit_and_load(&store, &args, &land, &table, preprocess, out, &mut csv).await?)
    } else {
        None
    };

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
    let on_tared = match &tared {
        Some((split, _)) => Some(score(&artifact, &split.examples, &device)?),
        None => None,
    };
    match (&on_land.r2, &on_water.r2, &on_land.rmse, &on_water.rmse) {
        (Some(rl), Some(rw), Some(el), Some(ew)) => {
            let rt = on_tared.as_ref().and_then(|m| m.r2);
            let et = on_tared.as_ref().and_then(|m| m.rmse);
            writeln!(
                out,
                "axis   R² land   R² water   drop      RMSE land   RMSE water  unit{}",
                if rt.is_some() {
                    "   R² water, tare   RMSE water, tare"
                } else {
                    ""
                }
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
                if let (Some(rt), Some(et)) = (&rt, &et) {
                    writeln!(
                        out,
                        "{:<6} with the tare: R² {:.5} (drop {:+.5}), RMSE {:.4} {}",
                        axis.name,
                        rt[i].r2,
                        rl[i].r2 - rt[i].r2,
                        et[i],
                        axis.report_unit
                    )
                    .map_err(w)?;
                    csv.push_str(&format!(
                        "accuracy,{},water_tare,{},r2,{}\naccuracy,{},water_tare,{},rmse,{}\n",
                        args.model, axis.key, rt[i].r2, args.model, axis.key, et[i]
                    ));
                }
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

    // The same through the tare.
    let tared_latents = match &tared {
        Some((_, tp)) => Some(tare::latents(
            &artifact,
            tp,
            &args.model,
            &device,
            out,
            &mut csv,
        )?),
        None => None,
    };

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
    if let Some(m) = on_tared {
        scored.push(Scored {
            model: args.model.clone(),
            tested_on: "water_tare",
            metrics: m,
        });
    }
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
            let l = test_split(&store, &args.land, &t, None).await?;
            let wa = test_split(&store, &args.water, &t, None).await?;
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
    let (cos_path, png) = plot::write_files(&args.out, &csv, &cosines, &scored)?;
    writeln!(
        out,
        "wrote {}, {} and {} in {:.1} s",
        args.out.display(),
        cos_path.display(),
        png.display(),
        started.elapsed().as_secs_f64()
    )
    .map_err(w)?;
    let mut drop_mean = match (scored[0].metrics.r2_mean, scored[1].metrics.r2_mean) {
        (Some(l), Some(wa)) => format!("R² mean {l:.4} on land, {wa:.4} on water"),
        _ => "no R² (a VAE)".into(),
    };
    if let Some(m) = scored.iter().find(|s| s.tested_on == "water_tare") {
        let (cos, cka) = tared_latents.unwrap_or((f64::NAN, f64::NAN));
        drop_mean.push_str(&format!(
            " ({} with the image tare: CKA {cka:.3}, cosine mean {cos:.3})",
            m.metrics
                .r2_mean
                .map_or_else(|| "-".into(), |v| format!("{v:.4}"))
        ));
    }
    super::results::Recorder::new("transfer")
        .model(&args.model)
        .dataset(&args.land)
        .setting("land", args.land.as_str())
        .setting("water", args.water.as_str())
        .setting("water_model", args.water_model.clone())
        .setting("both_model", args.both_model.clone())
        .setting("permutations", args.permutations)
        .setting("seed", args.seed)
        .setting("tare", args.tare)
        .setting("no_gain_map", args.no_gain_map)
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
