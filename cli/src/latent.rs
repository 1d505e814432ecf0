//! `softtouch latent`: the latent-space figures of Figure 3 for one or more stored
//! models (several: e.g. the models of a latent sweep, one set of figures each).

use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::Args;
use softtouch_collector::plot::{Heatmap, heatmap};
use softtouch_lab::latent::{
    column_means, draw_pairs, mean_off_diagonal, strongest_dims, traversal_values, wrench_rows,
    write_traversal,
};
use softtouch_lab::models;
use softtouch_lab::transfer::{Pairs, TestSplit, paired_test, test_split};
use softtouch_schemas::wrench::AXES;
use softtouch_trainer::similarity::{cosine_similarities, cross_correlation};
use softtouch_trainer::{FingerTable, ModelArtifact, Preprocess, latent_means};
use std::io::Write;
use std::path::PathBuf;

/// `softtouch latent`.
#[derive(Debug, Args)]
pub struct LatentArgs {
    /// The stored models; each gets its own figures, named after it.
    #[arg(required = true, value_name = "MODEL")]
    pub models: Vec<String>,
    /// The dataset whose test split the correlation maps are computed on.
    #[arg(long)]
    pub dataset: String,
    /// A water dataset whose runs repeat poses of `--dataset`'s runs (`collect
    /// --poses-from`): the latent values of paired instances on land and underwater.
    #[arg(long)]
    pub water: Option<String>,
    /// Latent dimensions to traverse (default: for each wrench axis, the dimension
    /// most correlated with it).
    #[arg(long, value_delimiter = ',')]
    pub dims: Vec<usize>,
    /// Each traversed latent goes from −SPAN to +SPAN, the others held at their mean
    /// over the test split.
    #[arg(long, default_value_t = 5.0)]
    pub span: f64,
    /// Images per traversal row.
    #[arg(long, default_value_t = 11)]
    pub steps: usize,
    /// Paired instances shown with --water.
    #[arg(long, default_value_t = 5)]
    pub pairs: usize,
    /// Where the PNGs and the CSV go.
    #[arg(long, default_value = "latent-out")]
    pub out: PathBuf,
}

fn check(args: &LatentArgs) -> Result<(), Failure> {
    let mut problems = Vec::new();
    if !(args.span.is_finite() && args.span > 0.0) {
        problems.push(format!("--span {}: expected a finite value > 0", args.span));
    }
    if !(2..=41).contains(&args.steps) {
        problems.push(format!("--steps {}: expected 2 to 41", args.steps));
    }
    if !(1..=20).contains(&args.pairs) {
        problems.push(format!("--pairs {}: expected 1 to 20", args.pairs));
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(Failure::BadInput(anyhow!(
            "invalid settings:\n  {}",
            problems.join("\n  ")
        )))
    }
}

pub async fn run_latent(
    args: LatentArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    check(&args)?;
    let store = open_existing(db).await?;
    let device = softtouch_trainer::backend::device()?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out.display())))?;
    // The test split (and the land/water pairs) preprocessed for the last model's
    // input; made again only when the next model reads another input.
    let mut loaded: Option<(Preprocess, TestSplit, Option<Pairs>)> = None;
    let mut tables = Vec::new();
    let mut figures = Vec::new();
    for name in &args.models {
        let bytes = models::artifact(&store, name).await?;
        let artifact = ModelArtifact::from_bytes(&bytes, &device)?;
        let h = &artifact.header;
        let preprocess = h.config.preprocess;
        if loaded.as_ref().is_none_or(|(p, _, _)| *p != preprocess) {
            let table = FingerTable::new(&preprocess);
            let land = test_split(&store, &args.dataset, &table, None).await?;
            let pairs = match &args.water {
                Some(w) => {
                    let water = test_split(&store, w, &table, None).await?;
                    Some(paired_test(&store, &land, &water, &table).await?)
                }
                None => None,
            };
            loaded = Some((preprocess, land, pairs));
        }
        let Some((_, land, pairs)) = loaded.as_ref() else {
            continue;
        };
        if land.examples.len() < 3 {
            return Err(Failure::BadInput(anyhow!(
                "dataset `{}` has {} test samples: the correlation maps need at least 3",
                args.dataset,
                land.examples.len()
            )));
        }
        if let Some(d) = args.dims.iter().find(|d| **d >= h.config.latent) {
            return Err(Failure::BadInput(anyhow!(
                "--dims {d}: model {name} has latent dimensions 0 to {}",
                h.config.latent - 1
            )));
        }
        writeln!(
            out,
            "model {name} ({} latent dimensions) on `{}` ({} test samples)",
            h.config.latent,
            args.dataset,
            land.examples.len()
        )
        .map_err(io_failure)?;
        let latents = latent_means(&artifact.net, &h.config, &h.norm, &land.examples, &device);
        let wrench = wrench_rows(&land.examples);
        let bad = |e| Failure::BadInput(anyhow!("model {name} on `{}`: {e}", args.dataset));
        let map = cross_correlation(&latents, &latents).map_err(bad)?;
        let to_wrench = cross_correlation(&latents, &wrench).map_err(bad)?;
        let dim_labels: Vec<String> = (0..h.config.latent).map(|d| format!("z{d}")).collect();
        let axis_labels: Vec<String> = AXES.iter().map(|a| a.name.to_owned()).collect();
        let mut written = Vec::new();

        // Figure 3b: how the latent dimensions correlate with each other.
        let png = args.out.join(format!("{name}-latent-correlation.png"));
        let title = format!(
            "{name}: correlation of the latent dimensions ({})",
            args.dataset
        );
        heatmap(
            &png,
            &Heatmap {
                title: &title,
                row_labels: &dim_labels,
                column_labels: &dim_labels,
                values: &map,
            },
            (900, 820),
        )
        .map_err(|e| Failure::Runtime(e.into()))?;
        written.push(png);

        // Figure 3d: how each latent dimension correlates with each wrench axis.
        let png = args.out.join(format!("{name}-latent-wrench.png"));
        let title = format!(
            "{name}: latent dimensions against the wrench ({})",
            args.dataset
        );
        heatmap(
            &png,
            &Heatmap {
                title: &title,
                row_labels: &dim_labels,
                column_labels: &axis_labels,
                values: &to_wrench,
            },
            (640, 900),
        )
        .map_err(|e| Failure::Runtime(e.into()))?;
        written.push(png);

        let strongest = strongest_dims(&to_wrench);
        writeln!(out, "  axis  strongest latent  r").map_err(io_failure)?;
        for (axis, s) in AXES.iter().zip(&strongest) {
            match s {
                Some((d, r)) => writeln!(out, "  {:<5} z{:<16} {r:+.3}", axis.name, d),
                None => writeln!(out, "  {:<5} (no latent varies)", axis.name),
            }
            .map_err(io_failure)?;
        }
        if let Some(m) = mean_off_diagonal(&map) {
            writeln!(
                out,
                "  mean |r| between latent dimensions: {m:.3} (0: uncorrelated)"
            )
            .map_err(io_failure)?;
        }

        // Figure 3c: the decoder's images with one latent varied.
        let png = args.out.join(format!("{name}-traversal.png"));
        let title = format!(
            "{name}: decoder images, one latent from −{s} to +{s}, others at their test mean (brightness stretched)",
            s = args.span
        );
        let values = traversal_values(args.span, args.steps);
        let base = column_means(&latents, h.config.latent);
        match write_traversal(
            &png, &title, &artifact, &strongest, &args.dims, &base, &values,
        )
        .map_err(|e| Failure::Runtime(e.into()))?
        {
            Some(_) => written.push(png),
            None if h.config.kind.has_decoder() => {
                writeln!(out, "  (no latent varies: no traversal)").map_err(io_failure)?;
            }
            None => writeln!(out, "  ({} has no decoder: no traversal)", h.config.kind)
                .map_err(io_failure)?,
        }

        // Figure 3a: paired instances, land against water.
        if let Some(pairs) = pairs {
            let k = args.pairs.min(pairs.land.len());
            let l = latent_means(&artifact.net, &h.config, &h.norm, &pairs.land[..k], &device);
            let w = latent_means(
                &artifact.net,
                &h.config,
                &h.norm,
                &pairs.water[..k],
                &device,
            );
            let cosines = cosine_similarities(&l, &w)
                .map_err(|e| Failure::BadInput(anyhow!("paired latents of model {name}: {e}")))?;
            let titles: Vec<String> = cosines
                .iter()
                .enumerate()
                .map(|(i, c)| format!("pair {}: cosine similarity {c:.3}", i + 1))
                .collect();
            let png = args.out.join(format!("{name}-paired.png"));
            let title = format!("{name}: latent means of {k} paired deformations, land and water");
            draw_pairs(&png, &title, &l, &w, &titles).map_err(|e| Failure::Runtime(e.into()))?;
            written.push(png);
        }

        // The two maps as numbers.
        let mut csv = String::from("map,row,column,r\n");
        for (map_name, m, cols) in [
            ("latent", &map, &dim_labels),
            ("wrench", &to_wrench, &axis_labels),
        ] {
            for (i, row) in m.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    csv.push_str(&format!(
                        "{map_name},z{i},{},{}\n",
                        cols[j],
                        v.map_or(String::new(), |v| format!("{v:.6}"))
                    ));
                }
            }
        }
        let csv_path = args.out.join(format!("{name}-latent.csv"));
        std::fs::write(&csv_path, csv)
            .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", csv_path.display())))?;
        // The images the maps' numbers cannot redraw go with the result too.
        for png in written.iter().filter(|p| {
            p.to_string_lossy().ends_with("-traversal.png")
                || p.to_string_lossy().ends_with("-paired.png")
        }) {
            figures.push(png.clone());
        }
        tables.push(csv_path.clone());
        written.push(csv_path);
        for p in written {
            writeln!(out, "  wrote {}", p.display()).map_err(io_failure)?;
        }
    }
    store.close().await;
    let mut recorder = super::results::Recorder::new("latent")
        .model(&args.models[0])
        .dataset(&args.dataset)
        .setting("models", args.models.clone())
        .setting("water", args.water.clone())
        .setting("dims", args.dims.clone())
        .setting("span", args.span)
        .setting("steps", args.steps)
        .setting("pairs", args.pairs);
    for t in &tables {
        recorder = recorder.table(t);
    }
    for f in &figures {
        recorder = recorder.figure(f);
    }
    recorder
        .store(
            db,
            format!(
                "latent correlation maps of {} model(s) on `{}`",
                args.models.len(),
                args.dataset
            ),
            out,
        )
        .await
        .map(drop)
}
