//! Train a model on images drawn straight from the simulated finger (no database):
//! the quickest way to try an architecture or a setting.
//!
//! `cargo run --release -p softtouch-trainer --example sim_train -- [samples] [epochs] [width] [size] [latent] [kind]`

use rand::{RngExt, SeedableRng};
use softtouch_schemas::ContactPose;
use softtouch_sim::SceneSim;
use softtouch_trainer::labels::label_from_si;
use softtouch_trainer::train::Observer;
use softtouch_trainer::{EpochReport, Example, ModelConfig, Preprocess, Splits, TrainConfig};

struct Print;
impl Observer for Print {
    fn epoch(&mut self, r: &EpochReport) {
        println!(
            "epoch {:>3} lr {:.2e} loss {:.4} val R² mean {:.5} min {:.5} img mse {:?} {:.1} img/s {:.1}s{}",
            r.epoch,
            r.learning_rate,
            r.train_loss,
            r.val_r2_mean.unwrap_or(f64::NAN),
            r.val_r2_min.unwrap_or(f64::NAN),
            r.val_image_mse,
            r.train_images_per_s,
            r.seconds,
            if r.best { " *" } else { "" }
        );
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let samples = arg(0, 3000);
    let epochs = arg(1, 20);
    let defaults = ModelConfig::default();
    let config = ModelConfig {
        width: arg(2, defaults.width),
        latent: arg(4, defaults.latent),
        kind: args.get(5).map_or(Ok(defaults.kind), |s| s.parse())?,
        preprocess: Preprocess {
            size_px: arg(3, defaults.preprocess.size_px),
            ..defaults.preprocess
        },
        ..defaults
    };
    let scene = softtouch_schemas::defaults::scene();
    let sim = SceneSim::new(&scene, 1)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let t = std::time::Instant::now();
    let mut examples = Vec::with_capacity(samples);
    let mut frame: Option<(usize, usize, Vec<u8>)> = None;
    for i in 0..samples {
        let pose = ContactPose {
            x_m: rng.random_range(scene.poses.x_m.min..=scene.poses.x_m.max),
            z_m: rng.random_range(scene.poses.z_m.min..=scene.poses.z_m.max),
            theta_rad: rng.random_range(scene.poses.theta_rad.min..=scene.poses.theta_rad.max),
        };
        let rod = &scene.rods[i % scene.rods.len()].name;
        let r = sim.render(rod, &pose, i as u64, 0.0)?;
        if i + 1 == samples {
            // The last frame is in the test split: the raw frame for the latency.
            frame = Some((
                r.image.width() as usize,
                r.image.height() as usize,
                r.image.as_raw().clone(),
            ));
        }
        let image = config.preprocess.apply(
            r.image.width() as usize,
            r.image.height() as usize,
            r.image.as_raw(),
        )?;
        examples.push(Example {
            image,
            label: label_from_si(r.wrench_in_sensor.force_n, r.wrench_in_sensor.torque_nm),
        });
    }
    println!("rendered {samples} in {:.1}s", t.elapsed().as_secs_f64());
    let n_test = samples / 5;
    let n_val = samples / 10;
    let test = examples.split_off(samples - n_test);
    let val = examples.split_off(examples.len() - n_val);
    let splits = Splits {
        train: examples,
        val,
        test,
    };
    let train_config = TrainConfig {
        epochs,
        ..TrainConfig::default()
    };
    let trained = softtouch_trainer::train(&config, &train_config, &splits, None, &mut Print)?;
    let summary = trained
        .artifact
        .header
        .training
        .clone()
        .ok_or("no summary")?;
    println!("test:\n{}", summary.test.render());
    let image = splits.test[0].image.clone();
    let mut predictor = softtouch_trainer::Predictor::new(trained.artifact);
    for threads in [1, 2] {
        let l = softtouch_trainer::measure_latency(&predictor, &image, 500, threads)?;
        println!(
            "inference, batch 1, {threads} thread(s): median {:.3} ms, p95 {:.3} ms, mean {:.3} ms over {} runs",
            l.median_ms, l.p95_ms, l.mean_ms, l.runs
        );
        if let Some((w, h, rgb)) = &frame {
            let l = softtouch_trainer::measure_frame_latency(
                &mut predictor,
                (*w, *h, rgb),
                500,
                threads,
            )?;
            println!(
                "raw {w}×{h} frame → wrench, {threads} thread(s): median {:.3} ms, p95 {:.3} ms, mean {:.3} ms over {} runs",
                l.median_ms, l.p95_ms, l.mean_ms, l.runs
            );
        }
    }
    println!(
        "backend {}: {:.1} train images/s (mean over epochs)",
        std::env::var(softtouch_trainer::backend::ENV).unwrap_or_else(|_| "flex".into()),
        summary.train_images_per_s
    );
    Ok(())
}
