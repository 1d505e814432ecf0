//! `softtouch eval` and `softtouch models`.

use super::{Failure, io_failure, open_existing, train::load_where};
use anyhow::anyhow;
use clap::Args;
use softtouch_lab::models;
use softtouch_trainer::{ModelArtifact, evaluate};
use std::io::Write;
use std::path::Path;

/// `softtouch eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A stored model's name, or the path of a model file.
    pub model: String,
    /// The dataset (default: the one a stored model was trained on).
    #[arg(long)]
    pub dataset: Option<String>,
    /// Which split: test, val, train or all (only its images are preprocessed).
    #[arg(long, value_enum, default_value_t = EvalSplit::Test)]
    pub split: EvalSplit,
    /// Folder for `MODEL-SPLIT-eval.png`, predicted against true per axis (created if
    /// missing).
    #[arg(long, default_value = "eval-out")]
    pub out: std::path::PathBuf,
}

/// A dataset's split to score: checked by clap before anything is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EvalSplit {
    /// The test split.
    Test,
    /// The validation split.
    Val,
    /// The training split.
    Train,
    /// Every member.
    All,
}

impl EvalSplit {
    /// As typed and printed.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Test => "test",
            Self::Val => "val",
            Self::Train => "train",
            Self::All => "all",
        }
    }

    /// Whether a member of split `split` is scored.
    #[must_use]
    pub fn takes(self, split: &str) -> bool {
        self == Self::All || split == self.as_str()
    }
}

pub async fn run_eval(
    args: EvalArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let device = burn_device()?;
    let (artifact, trained_on) = match models::find(&store, &args.model).await? {
        Some(info) => {
            let bytes = models::artifact(&store, &info.name).await?;
            (
                ModelArtifact::from_bytes(&bytes, &device)?,
                Some(info.dataset_name),
            )
        }
        None if Path::new(&args.model).is_file() => {
            if args.dataset.is_none() {
                return Err(Failure::BadInput(anyhow!(
                    "a model file needs --dataset NAME to evaluate on"
                )));
            }
            (ModelArtifact::load(Path::new(&args.model), &device)?, None)
        }
        None => {
            return Err(Failure::BadInput(anyhow!(
                "`{}` is neither a stored model (see `softtouch models`) nor a model file",
                args.model
            )));
        }
    };
    let Some(dataset) = args.dataset.clone().or(trained_on) else {
        return Err(Failure::BadInput(anyhow!(
            "a model file needs --dataset NAME to evaluate on"
        )));
    };
    let split = args.split;
    let splits = load_where(
        &store,
        &dataset,
        &artifact.header.config.preprocess,
        &|s| split.takes(s),
        out,
    )
    .await?;
    let examples = match split {
        EvalSplit::Test => splits.test,
        EvalSplit::Val => splits.val,
        EvalSplit::Train => splits.train,
        EvalSplit::All => [splits.train, splits.val, splits.test].concat(),
    };
    if examples.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "the {} split of {dataset} is empty",
            split.as_str()
        )));
    }
    let h = &artifact.header;
    let (metrics, predictions) = evaluate(&artifact.net, &h.config, &h.norm, &examples, &device)?;
    writeln!(
        out,
        "model {} ({}), {dataset} {} split",
        args.model,
        h.config.describe(),
        split.as_str()
    )
    .map_err(io_failure)?;
    write!(out, "{}", metrics.render()).map_err(io_failure)?;
    store.close().await;
    // What it printed, to look at: predicted against true per axis (none for a VAE).
    if let Some(predicted) = predictions {
        let name = Path::new(&args.model)
            .file_stem()
            .map_or_else(|| args.model.clone(), |s| s.to_string_lossy().into_owned());
        let name: String = name
            .chars()
            .map(|c| {
                if c.is_alphanumeric() || "-_.".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        std::fs::create_dir_all(&args.out)
            .map_err(|e| Failure::Runtime(anyhow!("{}: {e}", args.out.display())))?;
        let png = args.out.join(format!("{name}-{}-eval.png", split.as_str()));
        let panels: Vec<softtouch_collector::plot::PredictedPanel<'_>> = (0..6)
            .map(|axis| {
                (
                    softtouch_trainer::AXES[axis],
                    softtouch_trainer::UNITS[axis],
                    examples
                        .iter()
                        .zip(&predicted)
                        .map(|(e, p)| (f64::from(e.label[axis]), f64::from(p[axis])))
                        .collect(),
                )
            })
            .collect();
        softtouch_collector::plot::predicted_grid(
            &png,
            &format!(
                "{}: predicted against true, {dataset} {} split ({} samples)",
                args.model,
                split.as_str(),
                examples.len()
            ),
            &panels,
            3,
        )
        .map_err(|e| Failure::Runtime(anyhow!("{e}")))?;
        writeln!(out, "wrote {}", png.display()).map_err(io_failure)?;
    }
    Ok(())
}

fn burn_device() -> Result<burn::prelude::Device, Failure> {
    Ok(softtouch_trainer::backend::device()?)
}

/// `softtouch models`.
pub async fn run_models(
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let list = models::list(&store).await?;
    if list.is_empty() {
        writeln!(out, "no models yet (softtouch train --dataset NAME)").map_err(io_failure)?;
    } else {
        writeln!(
            out,
            "{:<28} {:<8} {:<20} {:>10} {:>11}  created",
            "name", "kind", "dataset", "test R²", "image MSE"
        )
        .map_err(io_failure)?;
        for m in list {
            writeln!(
                out,
                "{:<28} {:<8} {:<20} {:>10} {:>11}  {}",
                m.name,
                m.kind,
                m.dataset_name,
                m.test_r2_mean
                    .map_or_else(|| "–".into(), |v| format!("{v:.5}")),
                m.test_image_mse
                    .map_or_else(|| "–".into(), |v| format!("{v:.3e}")),
                m.created_at
            )
            .map_err(io_failure)?;
        }
    }
    store.close().await;
    Ok(())
}
