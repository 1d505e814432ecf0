//! `softtouch train`, and what every training verb shares: the model and optimisation
//! arguments and loading a dataset's splits with progress.

use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::Args;
use softtouch_collector::progress::{TrainProgress, progress_bar};
use softtouch_lab::models;
use softtouch_store::Store;
use softtouch_trainer::{
    InitFrom, ModelConfig, ModelKind, Preprocess, Signal, Splits, TrainConfig, Trained,
};
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// The model and optimisation settings every training verb takes.
#[derive(Debug, Clone, Args)]
pub struct ModelArgs {
    /// Which model: svae, vae or convnet.
    #[arg(long, default_value_t = ModelConfig::default().kind)]
    pub model: ModelKind,
    /// Reconstruction weight of the SVAE loss: α/(1+α)·recon + 1/(1+α)·pred + β·KL.
    #[arg(long, default_value_t = ModelConfig::default().alpha)]
    pub alpha: f64,
    /// KL weight β.
    #[arg(long, default_value_t = ModelConfig::default().beta)]
    pub beta: f64,
    /// Latent dimensions.
    #[arg(long, default_value_t = ModelConfig::default().latent)]
    pub latent: usize,
    /// Channels of the encoder's stem (stages double it, up to 8×).
    #[arg(long, default_value_t = ModelConfig::default().width)]
    pub width: usize,
    /// Input size in pixels (square, a power of two in 16..=256).
    #[arg(long, default_value_t = Preprocess::default().size_px)]
    pub size: usize,
    /// Input channels: 1 (one value per finger pixel, see --signal) or 3 (RGB).
    #[arg(long, default_value_t = Preprocess::default().channels)]
    pub channels: usize,
    /// What one channel carries of the finger's pixels: brightness, or chroma
    /// (max − min of R, G, B), which white light added alike to every channel, as
    /// underwater caustics are, leaves as it is (docs/land-to-water.md).
    #[arg(long, default_value_t = Preprocess::default().signal)]
    pub signal: Signal,
    /// Maximum epochs.
    #[arg(long, default_value_t = TrainConfig::default().epochs)]
    pub epochs: usize,
    /// Batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    pub batch: usize,
    /// Adam's initial learning rate (multiplied by --lr-decay after each epoch).
    #[arg(long, default_value_t = TrainConfig::default().learning_rate)]
    pub lr: f64,
    /// Learning-rate factor per epoch.
    #[arg(long, default_value_t = TrainConfig::default().lr_decay)]
    pub lr_decay: f64,
    /// Early stopping: epochs without a better validation score (0: never stop early).
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    pub patience: usize,
    /// Seed of initialisation, shuffling and latent noise.
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
}

impl ModelArgs {
    /// [`Self::configs`] for a training that starts from a model of settings `init`:
    /// the model's settings are `init`'s, and flags that would set others are refused
    /// (flags left at their defaults, or matching `init`, are fine).
    pub(crate) fn configs_from(
        &self,
        init: Option<(&str, &ModelConfig)>,
    ) -> Result<(ModelConfig, TrainConfig), Failure> {
        let (model, train) = self.configs()?;
        let Some((name, init)) = init else {
            return Ok((model, train));
        };
        if model == ModelConfig::default() || model == *init {
            return Ok((*init, train));
        }
        Err(Failure::BadInput(anyhow!(
            "--init {name}: that model is a {}, the flags ask for a {}; \
             leave out --model, --alpha, --beta, --latent, --width, --size, --channels and --signal \
             (the settings come from the starting model)",
            init.describe(),
            model.describe()
        )))
    }

    pub(crate) fn configs(&self) -> Result<(ModelConfig, TrainConfig), Failure> {
        let model = ModelConfig {
            kind: self.model,
            width: self.width,
            latent: self.latent,
            alpha: self.alpha,
            beta: self.beta,
            preprocess: Preprocess {
                size_px: self.size,
                channels: self.channels,
                signal: self.signal,
                ..Preprocess::default()
            },
        };
        let train = TrainConfig {
            epochs: self.epochs,
            batch_size: self.batch,
            learning_rate: self.lr,
            lr_decay: self.lr_decay,
            patience: self.patience,
            seed: self.seed,
        };
        let mut problems = model.problems();
        problems.extend(train.problems());
        if problems.is_empty() {
            Ok((model, train))
        } else {
            Err(Failure::BadInput(anyhow!(
                "invalid settings:\n  {}",
                problems.join("\n  ")
            )))
        }
    }
}

/// `softtouch train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// The dataset to train on (its train split; val for early stopping; test reported).
    #[arg(long)]
    pub dataset: String,
    /// Name the model is stored under (default: DATASET-MODEL).
    #[arg(long)]
    pub name: Option<String>,
    /// Also write the model artifact to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Folder of checkpoints (default: `checkpoints/` beside the database). A training
    /// interrupted there resumes from its last epoch when started again with the same
    /// name and settings.
    #[arg(long)]
    pub checkpoints: Option<PathBuf>,
    /// Discard an existing checkpoint of this name instead of resuming it.
    #[arg(long)]
    pub restart: bool,
    /// Start from this stored model's weights and label normalisation instead of a
    /// fresh initialisation: fine-tuning, e.g. a land model on a little water data.
    /// The model's settings come from it (default name: DATASET-from-MODEL).
    #[arg(long, value_name = "MODEL")]
    pub init: Option<String>,
    /// Also learn N copies of each training frame as a camera in water shows it after
    /// `transfer --tare` (the field narrowed to 0.7–1 of the frame, each channel's
    /// gain and offset jittered): a land model that reads water (docs/land-to-water.md).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub augment_media: usize,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Loads a dataset's splits with a progress bar.
pub(crate) async fn load(
    store: &Store,
    dataset: &str,
    preprocess: &Preprocess,
    out: &mut dyn Write,
) -> Result<Splits, Failure> {
    load_where(store, dataset, preprocess, &|_| true, out).await
}

/// [`load`] of the members whose split `keep` takes (the others are not decoded).
pub(crate) async fn load_where(
    store: &Store,
    dataset: &str,
    preprocess: &Preprocess,
    keep: &(dyn Fn(&str) -> bool + Sync),
    out: &mut dyn Write,
) -> Result<Splits, Failure> {
    let started = Instant::now();
    let bar = progress_bar(0, true, "loading");
    let splits = models::load_splits_where(store, dataset, preprocess, keep, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })
    .await?;
    bar.finish_and_clear();
    writeln!(
        out,
        "dataset {dataset}: {} train, {} val, {} test images, preprocessed to {}×{}×{} in {:.1} s",
        splits.train.len(),
        splits.val.len(),
        splits.test.len(),
        preprocess.channels,
        preprocess.size_px,
        preprocess.size_px,
        started.elapsed().as_secs_f64()
    )
    .map_err(io_failure)?;
    Ok(splits)
}

fn default_checkpoints(db: &softtouch_store::DbTarget) -> PathBuf {
    match db.file().and_then(std::path::Path::parent) {
        Some(p) if !p.as_os_str().is_empty() => p.join("checkpoints"),
        _ => PathBuf::from("checkpoints"),
    }
}

/// `softtouch train`.
pub async fn run_train(
    args: TrainArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let init = match &args.init {
        Some(init_name) => {
            let device = softtouch_trainer::backend::device()?;
            let bytes = models::artifact(&store, init_name).await?;
            let artifact = softtouch_trainer::ModelArtifact::from_bytes(&bytes, &device)?;
            Some(InitFrom::from_artifact(init_name, &artifact)?)
        }
        None => None,
    };
    let (model, train) = args
        .model
        .configs_from(args.init.as_deref().zip(init.as_ref().map(|i| &i.config)))?;
    let name = args.name.clone().unwrap_or_else(|| match &args.init {
        Some(init) => format!("{}-from-{init}", args.dataset),
        None => format!("{}-{}", args.dataset, model.kind),
    });
    softtouch_collector::dataset::validate_name(&name).map_err(|e| Failure::BadInput(e.into()))?;
    if models::find(&store, &name).await?.is_some() {
        return Err(Failure::BadInput(anyhow!(
            "a model named `{name}` already exists: pass --name to choose another"
        )));
    }
    let mut splits = load(&store, &args.dataset, &model.preprocess, out).await?;
    if args.augment_media > 0 {
        let augment = softtouch_trainer::MediaAugment::water(args.augment_media, train.seed);
        let bar = progress_bar(0, true, "augmenting");
        let extra = models::augmented_train(
            &store,
            &args.dataset,
            &model.preprocess,
            &augment,
            &|done, total| {
                bar.set_length(total);
                bar.set_position(done);
            },
        )
        .await?;
        bar.finish_and_clear();
        writeln!(
            out,
            "augmented: {} more training images ({augment:?})",
            extra.len()
        )
        .map_err(io_failure)?;
        splits.train.extend(extra);
    }
    let dir = args
        .checkpoints
        .clone()
        .unwrap_or_else(|| default_checkpoints(db))
        .join(&name);
    if args.restart {
        softtouch_trainer::train::discard_checkpoint(&dir)?;
    }
    writeln!(
        out,
        "training {name}: {}, batch {}, up to {} epochs{} (checkpoints in {})",
        model.describe(),
        train.batch_size,
        train.epochs,
        init.as_ref()
            .map(|i| format!(", starting from {}", i.label))
            .unwrap_or_default(),
        dir.display()
    )
    .map_err(io_failure)?;
    let trained = {
        let mut progress = TrainProgress::new(out, train.epochs, true);
        softtouch_trainer::train_from(
            &model,
            &train,
            &splits,
            Some(&dir),
            init.as_ref(),
            &mut progress,
        )?
    };
    report_trained(&trained, out)?;
    models::record(&store, &name, &args.dataset, &trained).await?;
    if let Some(path) = &args.out {
        trained.artifact.save(path)?;
        writeln!(out, "wrote {}", path.display()).map_err(io_failure)?;
    }
    // Recorded: the checkpoint has served its purpose.
    softtouch_trainer::train::discard_checkpoint(&dir)?;
    writeln!(out, "stored model `{name}` (softtouch eval {name})").map_err(io_failure)?;
    store.close().await;
    Ok(())
}

fn report_trained(trained: &Trained, out: &mut dyn Write) -> Result<(), Failure> {
    if let Some(s) = &trained.artifact.header.training {
        writeln!(
            out,
            "best epoch {} of {}{}; {:.0} s in all, {:.0} train images/s",
            s.best_epoch,
            s.epochs_run,
            if s.stopped_early {
                " (stopped early)"
            } else {
                ""
            },
            s.seconds,
            s.train_images_per_s
        )
        .map_err(io_failure)?;
        if let Some(init) = &s.init_from {
            writeln!(out, "fine-tuned from {init}").map_err(io_failure)?;
        }
        write!(out, "test split:\n{}", s.test.render()).map_err(io_failure)?;
    }
    Ok(())
}
