//! `softtouch bench train`: training images/s of the SVAE at each input size and
//! width, where the step's time goes and how many cores it kept busy; with
//! `--torch PYTHON`, the PyTorch peer's same step, interleaved, and the ratio.

use super::train::load;
use super::{Failure, io_failure};
use anyhow::anyhow;
use clap::Args;
use softtouch_trainer::train::{TrainBench, TrainBenchConfig, bench_train, synthetic_examples};
use softtouch_trainer::{ModelConfig, Preprocess};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `softtouch bench train`.
#[derive(Debug, Args)]
pub struct BenchTrainArgs {
    /// Input sizes, px.
    #[arg(long, value_delimiter = ',', default_value = "32,64")]
    pub sizes: Vec<usize>,
    /// Encoder widths.
    #[arg(long, value_delimiter = ',', default_value = "16,8")]
    pub widths: Vec<usize>,
    /// Train on this stored dataset's training split (preprocessed at each size);
    /// default: 2240 images of uniform noise, what the PyTorch peer trains on.
    #[arg(long)]
    pub dataset: Option<String>,
    /// Images per step.
    #[arg(long, default_value_t = 64)]
    pub batch: usize,
    /// Untimed steps before each measurement.
    #[arg(long, default_value_t = 5)]
    pub warmup: usize,
    /// Timed steps per measurement.
    #[arg(long, default_value_t = 60)]
    pub steps: usize,
    /// Measurements per configuration (the median is reported); with --torch the
    /// order alternates between softtouch and PyTorch.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// A Python interpreter with PyTorch: also run the peer's same step.
    #[arg(long)]
    pub torch: Option<PathBuf>,
    /// The PyTorch peer.
    #[arg(long, default_value = "../shared/peers/torch_light_bench.py")]
    pub torch_script: PathBuf,
    /// Threads PyTorch may use (this machine's cores).
    #[arg(long, default_value_t = 2)]
    pub torch_threads: usize,
    /// Where `bench-train.csv` goes.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
}

/// The PyTorch peer's figures for one configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TorchRun {
    images_per_s: f64,
    cores_used: Option<f64>,
}

/// One configuration's measurements.
struct Row {
    size: usize,
    width: usize,
    ours: Vec<TrainBench>,
    torch: Vec<TorchRun>,
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Reads the peer's JSON line: its images/s over the total time of the timed steps.
fn parse_torch(stdout: &str) -> Result<TorchRun, String> {
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
        .ok_or_else(|| "no JSON line in its output".to_owned())?;
    let v: serde_json::Value =
        serde_json::from_str(line).map_err(|e| format!("its JSON line does not parse: {e}"))?;
    let images_per_s = v
        .get("train_img_per_s_total")
        .and_then(serde_json::Value::as_f64)
        .filter(|x| x.is_finite() && *x > 0.0)
        .ok_or_else(|| "its JSON has no positive train_img_per_s_total".to_owned())?;
    Ok(TorchRun {
        images_per_s,
        cores_used: v
            .get("train_cores_used")
            .and_then(serde_json::Value::as_f64),
    })
}

fn run_torch(
    args: &BenchTrainArgs,
    python: &Path,
    size: usize,
    width: usize,
) -> Result<TorchRun, Failure> {
    let output = Command::new(python)
        .arg(&args.torch_script)
        .args(["--sizes", &size.to_string(), "--widths", &width.to_string()])
        .args(["--batch", &args.batch.to_string()])
        .args(["--warmup", &args.warmup.to_string()])
        .args(["--steps", &args.steps.to_string()])
        .args(["--train-threads", &args.torch_threads.to_string()])
        .arg("--skip-infer")
        .output()
        .map_err(|e| {
            Failure::BadInput(anyhow!("--torch {}: cannot run it: {e}", python.display()))
        })?;
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        let tail: Vec<&str> = err.lines().rev().take(5).collect();
        return Err(Failure::Runtime(anyhow!(
            "the PyTorch peer ({} {}) failed ({}): {}",
            python.display(),
            args.torch_script.display(),
            output.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        )));
    }
    parse_torch(&String::from_utf8_lossy(&output.stdout))
        .map_err(|e| Failure::Runtime(anyhow!("the PyTorch peer at {size}×{size}/{width}: {e}")))
}

pub async fn run(
    args: BenchTrainArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if args.sizes.is_empty() || args.widths.is_empty() || args.repeats == 0 {
        return Err(Failure::BadInput(anyhow!(
            "--sizes, --widths and --repeats: expected at least one of each"
        )));
    }
    if let Some(python) = &args.torch {
        if !args.torch_script.is_file() {
            return Err(Failure::BadInput(anyhow!(
                "--torch-script {}: not a file (the peer is shared/peers/torch_light_bench.py beside the checkout)",
                args.torch_script.display()
            )));
        }
        writeln!(
            out,
            "PyTorch: {} {}",
            python.display(),
            args.torch_script.display()
        )
        .map_err(io_failure)?;
    }
    // A mistyped SOFTTOUCH_BACKEND or SOFTTOUCH_CONV is said before the header.
    softtouch_trainer::backend::device().map_err(|e| Failure::BadInput(anyhow!(e)))?;
    writeln!(
        out,
        "convolutions and batch norm: {}",
        softtouch_trainer::kernels::describe()
    )
    .map_err(io_failure)?;
    let store = match &args.dataset {
        Some(_) => Some(super::open_existing(db).await?),
        None => None,
    };
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out.display())))?;
    let mut rows = Vec::new();
    for &size in &args.sizes {
        let preprocess = Preprocess {
            size_px: size,
            ..Preprocess::default()
        };
        let examples = match (&store, &args.dataset) {
            (Some(store), Some(name)) => load(store, name, &preprocess, out).await?.train,
            _ => synthetic_examples(
                &ModelConfig {
                    preprocess,
                    ..ModelConfig::default()
                },
                2240,
                1,
            ),
        };
        for &width in &args.widths {
            let config = ModelConfig {
                width,
                preprocess,
                ..ModelConfig::default()
            };
            let bench = TrainBenchConfig {
                batch: args.batch,
                warmup: args.warmup,
                steps: args.steps,
                seed: 1,
            };
            let mut row = Row {
                size,
                width,
                ours: Vec::new(),
                torch: Vec::new(),
            };
            for r in 0..args.repeats {
                // Alternate who goes first: the machine's state drifts.
                let torch_first = r % 2 == 1;
                if torch_first && let Some(python) = &args.torch {
                    row.torch.push(run_torch(&args, python, size, width)?);
                }
                let b = bench_train(&config, &examples, &bench)
                    .map_err(|e| Failure::BadInput(anyhow!("{size}×{size}/{width}: {e}")))?;
                row.ours.push(b);
                if !torch_first && let Some(python) = &args.torch {
                    row.torch.push(run_torch(&args, python, size, width)?);
                }
            }
            let ours = median(row.ours.iter().map(|b| b.images_per_s).collect());
            let torch = median(row.torch.iter().map(|t| t.images_per_s).collect());
            writeln!(
                out,
                "{size}×{size}/{width}: softtouch {:.0} img/s{}",
                ours.unwrap_or(f64::NAN),
                torch.map_or(String::new(), |t| format!(", PyTorch {t:.0} img/s"))
            )
            .map_err(io_failure)?;
            rows.push(row);
        }
    }
    if let Some(store) = store {
        store.close().await;
    }
    let table = render(&rows, args.batch);
    out.write_all(table.as_bytes()).map_err(io_failure)?;
    let csv = args.out.join("bench-train.csv");
    std::fs::write(&csv, csv_text(&rows))
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", csv.display())))?;
    writeln!(out, "wrote {}", csv.display()).map_err(io_failure)?;
    Ok(())
}

/// The medians of one row: (img/s, GFLOP/s, cores, phases ms, PyTorch img/s, its cores).
struct Medians {
    images_per_s: f64,
    gflop_per_s: f64,
    cores: Option<f64>,
    phases: [f64; 4],
    torch: Option<f64>,
    torch_cores: Option<f64>,
}

fn medians(row: &Row) -> Medians {
    let m = |f: &dyn Fn(&TrainBench) -> f64| {
        median(row.ours.iter().map(f).collect()).unwrap_or(f64::NAN)
    };
    Medians {
        images_per_s: m(&|b| b.images_per_s),
        gflop_per_s: m(&|b| b.gflop_per_s),
        cores: median(row.ours.iter().filter_map(|b| b.cores_used).collect()),
        phases: [
            m(&|b| b.phase_ms.batch),
            m(&|b| b.phase_ms.forward),
            m(&|b| b.phase_ms.backward),
            m(&|b| b.phase_ms.optimiser),
        ],
        torch: median(row.torch.iter().map(|t| t.images_per_s).collect()),
        torch_cores: median(row.torch.iter().filter_map(|t| t.cores_used).collect()),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "–".to_owned(), |x| format!("{x:.digits$}"))
}

fn render(rows: &[Row], batch: usize) -> String {
    let mut s = format!(
        "\ntraining, batch {batch} (medians; phases in ms per step):\ninput/width   img/s  GFLOP/s  cores   batch  forward  backward  optimiser   PyTorch img/s  cores   ratio\n"
    );
    for row in rows {
        let m = medians(row);
        let ratio = m.torch.map(|t| m.images_per_s / t);
        s.push_str(&format!(
            "{:<12} {:>6.0} {:>8.1} {:>6} {:>7.2} {:>8.2} {:>9.2} {:>10.2}   {:>13} {:>6} {:>7}\n",
            format!("{}×{}/{}", row.size, row.size, row.width),
            m.images_per_s,
            m.gflop_per_s,
            opt(m.cores, 2),
            m.phases[0],
            m.phases[1],
            m.phases[2],
            m.phases[3],
            opt(m.torch, 0),
            opt(m.torch_cores, 2),
            opt(ratio, 2),
        ));
    }
    s
}

fn csv_text(rows: &[Row]) -> String {
    let mut s = String::from(
        "size_px,width,images_per_s,gflop_per_s,cores_used,batch_ms,forward_ms,backward_ms,optimiser_ms,torch_images_per_s,torch_cores_used,ratio\n",
    );
    let o = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map_or(String::new(), |x| x.to_string())
    };
    for row in rows {
        let m = medians(row);
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}\n",
            row.size,
            row.width,
            m.images_per_s,
            m.gflop_per_s,
            o(m.cores),
            m.phases[0],
            m.phases[1],
            m.phases[2],
            m.phases[3],
            o(m.torch),
            o(m.torch_cores),
            o(m.torch.map(|t| m.images_per_s / t)),
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peers_json_line_is_read_or_refused_by_name() {
        let good = "loading\n{\"size\": 32, \"train_img_per_s_total\": 2666.5, \"train_cores_used\": 1.9}\n";
        let t = parse_torch(good).expect("parses");
        assert!((t.images_per_s - 2666.5).abs() < 1e-9 && t.cores_used == Some(1.9));
        for (bad, why) in [
            ("", "no JSON line"),
            ("{not json", "does not parse"),
            ("{\"train_img_per_s\": 1.0}", "train_img_per_s_total"),
            ("{\"train_img_per_s_total\": -3}", "train_img_per_s_total"),
            (
                "{\"train_img_per_s_total\": \"fast\"}",
                "train_img_per_s_total",
            ),
        ] {
            let Err(e) = parse_torch(bad) else {
                panic!("{bad}: accepted");
            };
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn medians_skip_what_is_not_a_number() {
        assert_eq!(median(vec![]), None);
        assert_eq!(median(vec![f64::NAN]), None);
        assert_eq!(median(vec![3.0, f64::NAN, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0]), Some(2.5));
    }
}
