//! Training throughput (`softtouch bench train`): the very step [`super::train`] runs
//! (batch assembly, latent noise, forward and loss read back, backward, Adam), timed
//! per phase at a fixed batch size, with the process's CPU time to say how many cores
//! it kept busy. The PyTorch peer (`bench/torch_peer.py`) times the same
//! step the same way: images/s from the total time of the timed steps.

use std::time::Instant;

use burn::optim::{AdamConfig, ModuleOptimizer};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::{Example, backward_step, batch_noise, batch_tensors, forward_loss, init_net};
use crate::TrainError;
use crate::labels::{LabelNorm, WrenchLabel};
use crate::model::ModelConfig;

/// How long to time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrainBenchConfig {
    /// Images per step (training's default: 64).
    pub batch: usize,
    /// Untimed steps first (allocations, caches).
    pub warmup: usize,
    /// Timed steps.
    pub steps: usize,
    /// Seed of the weights, the batches and the noise.
    pub seed: u64,
}

impl Default for TrainBenchConfig {
    fn default() -> Self {
        Self {
            batch: 64,
            warmup: 5,
            steps: 60,
            seed: 1,
        }
    }
}

/// Mean time per step of each phase, ms.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PhaseMs {
    /// Gathering the batch and drawing the noise.
    pub batch: f64,
    /// Forward pass and loss, read back.
    pub forward: f64,
    /// Gradients.
    pub backward: f64,
    /// The Adam update.
    pub optimiser: f64,
}

/// What [`bench_train`] measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrainBench {
    pub batch: usize,
    pub steps: usize,
    /// Images over the total time of the timed steps, per s.
    pub images_per_s: f64,
    pub step_ms_median: f64,
    pub phase_ms: PhaseMs,
    /// The process's CPU time over the wall time of the timed steps (`None` where the
    /// platform has no process clock).
    pub cores_used: Option<f64>,
    /// Floating-point work of one image's training step, GFLOP (2 per multiply–add;
    /// the backward pass counted as twice the forward, less the stem's input gradient).
    pub gflop_per_image: f64,
    /// That work per second of the timed steps, GFLOP/s.
    pub gflop_per_s: f64,
    pub loss_first: f64,
    pub loss_last: f64,
}

/// `n` images of uniform noise in [0, 1] and standard-normal labels: what the PyTorch
/// peer trains on, so the two time the same arithmetic.
#[must_use]
pub fn synthetic_examples(config: &ModelConfig, n: usize, seed: u64) -> Vec<Example> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let len = config.preprocess.input_len();
    (0..n)
        .map(|_| {
            let image: Vec<f32> = (0..len).map(|_| rng.random::<f32>()).collect();
            let label: WrenchLabel =
                std::array::from_fn(|_| rng.sample::<f32, _>(rand_distr::StandardNormal));
            Example { image, label }
        })
        .collect()
}

/// The process's CPU time so far, s.
fn process_cpu_s() -> Option<f64> {
    let t = nix::time::clock_gettime(nix::time::ClockId::CLOCK_PROCESS_CPUTIME_ID).ok()?;
    Some(t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9)
}

/// Times `bench.steps` training steps of `config` on batches drawn in turn from
/// `examples` (at least two images, each of the config's input size).
pub fn bench_train(
    config: &ModelConfig,
    examples: &[Example],
    bench: &TrainBenchConfig,
) -> Result<TrainBench, TrainError> {
    let problems = config.problems();
    if !problems.is_empty() {
        return Err(TrainError::Config(problems.join("; ")));
    }
    let len = config.preprocess.input_len();
    if let Some(bad) = examples.iter().position(|e| e.image.len() != len) {
        return Err(TrainError::Input(format!(
            "bench image {bad} has {} values; the model reads {len}",
            examples[bad].image.len()
        )));
    }
    if bench.batch < 2 || examples.len() < bench.batch {
        return Err(TrainError::Config(format!(
            "a batch of {} from {} images: expected at least 2 per batch, and a batch's worth of images",
            bench.batch,
            examples.len()
        )));
    }
    if bench.steps == 0 {
        return Err(TrainError::Config(
            "0 timed steps: expected at least 1".into(),
        ));
    }
    let device = crate::backend::device()?.autodiff();
    let labels: Vec<WrenchLabel> = examples.iter().map(|e| e.label).collect();
    let norm = LabelNorm::fit(&labels)?;
    let mut net = init_net(config, bench.seed, &device);
    let mut optimizer: ModuleOptimizer = AdamConfig::new().init();
    let per_epoch = examples.len() / bench.batch;
    let lr = 2e-3;
    let mut phases = PhaseMs::default();
    let mut step_ms = Vec::with_capacity(bench.steps);
    let (mut loss_first, mut loss_last) = (f64::NAN, f64::NAN);
    let mut cpu_start = None;
    let mut timed_from = Instant::now();
    for k in 0..bench.warmup + bench.steps {
        if k == bench.warmup {
            cpu_start = process_cpu_s();
            timed_from = Instant::now();
        }
        let t0 = Instant::now();
        let first = (k % per_epoch) * bench.batch;
        let indices: Vec<usize> = (first..first + bench.batch).collect();
        let (images, targets) = batch_tensors(examples, &indices, config, &norm, &device);
        let noise = batch_noise(config, bench.batch, bench.seed, 0, k, &device);
        let t1 = Instant::now();
        let (terms, loss) = forward_loss(&net, config, images, targets, noise, &device);
        let t2 = Instant::now();
        if !loss.total.is_finite() {
            return Err(TrainError::NonFinite {
                epoch: 1,
                step: k + 1,
                detail: format!("bench loss {}", loss.total),
            });
        }
        let (next, backward, optimiser) = backward_step(net, &mut optimizer, terms.total, lr);
        net = next;
        if k >= bench.warmup {
            phases.batch += (t1 - t0).as_secs_f64();
            phases.forward += (t2 - t1).as_secs_f64();
            phases.backward += backward.as_secs_f64();
            phases.optimiser += optimiser.as_secs_f64();
            step_ms.push(t0.elapsed().as_secs_f64() * 1e3);
            if loss_first.is_nan() {
                loss_first = loss.total;
            }
            loss_last = loss.total;
        }
    }
    let wall_s = timed_from.elapsed().as_secs_f64();
    let cores_used = match (cpu_start, process_cpu_s()) {
        (Some(a), Some(b)) if wall_s > 0.0 => Some((b - a) / wall_s),
        _ => None,
    };
    let n = bench.steps as f64;
    let per_step_ms = |s: f64| s * 1e3 / n;
    step_ms.sort_by(f64::total_cmp);
    let gflop_per_image = config.train_gflop_per_image();
    let images_per_s = (bench.batch * bench.steps) as f64 / wall_s.max(1e-12);
    Ok(TrainBench {
        batch: bench.batch,
        steps: bench.steps,
        images_per_s,
        step_ms_median: step_ms[step_ms.len() / 2],
        phase_ms: PhaseMs {
            batch: per_step_ms(phases.batch),
            forward: per_step_ms(phases.forward),
            backward: per_step_ms(phases.backward),
            optimiser: per_step_ms(phases.optimiser),
        },
        cores_used,
        gflop_per_image,
        gflop_per_s: gflop_per_image * images_per_s,
        loss_first,
        loss_last,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preprocess::Preprocess;

    fn tiny() -> ModelConfig {
        ModelConfig {
            width: 4,
            preprocess: Preprocess {
                size_px: 16,
                ..Preprocess::default()
            },
            ..ModelConfig::default()
        }
    }

    #[test]
    fn the_bench_trains_and_accounts_for_its_time() {
        let config = tiny();
        let examples = synthetic_examples(&config, 40, 3);
        let bench = TrainBenchConfig {
            batch: 8,
            warmup: 1,
            steps: 6,
            seed: 2,
        };
        let b = bench_train(&config, &examples, &bench).expect("bench");
        assert!(b.images_per_s.is_finite() && b.images_per_s > 0.0);
        let p = b.phase_ms;
        let phases = p.batch + p.forward + p.backward + p.optimiser;
        // The phases are the step, less what falls between the clocks.
        let mean_step = 1e3 * 8.0 / b.images_per_s;
        assert!(
            phases <= mean_step * 1.01 && phases > 0.5 * mean_step,
            "{p:?} vs {mean_step}"
        );
        assert!(b.loss_first.is_finite() && b.loss_last.is_finite());
        assert!(b.gflop_per_image > 0.0 && b.gflop_per_s > 0.0);
        if let Some(c) = b.cores_used {
            assert!(c > 0.0 && c < 64.0, "{c}");
        }
    }

    #[test]
    fn the_bench_refuses_what_it_cannot_time() {
        let config = tiny();
        let examples = synthetic_examples(&config, 4, 3);
        for (batch, steps) in [(1, 3), (8, 3), (2, 0)] {
            let bench = TrainBenchConfig {
                batch,
                warmup: 0,
                steps,
                seed: 1,
            };
            assert!(
                bench_train(&config, &examples, &bench).is_err(),
                "{batch} {steps}"
            );
        }
        let mut wrong = examples;
        wrong[1].image.pop();
        let Err(e) = bench_train(
            &config,
            &wrong,
            &TrainBenchConfig {
                batch: 2,
                ..TrainBenchConfig::default()
            },
        ) else {
            panic!("a short image");
        };
        assert!(e.to_string().contains("bench image 1"), "{e}");
    }
}
