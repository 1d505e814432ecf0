//! Builds a big synthetic database for measuring `softtouch dataset export`:
//!
//! ```sh
//! cargo run --release -p softtouch-collector --example make_bench_db -- /tmp/bench.db 30000
//! ```
//!
//! Arguments: the database to create (must not exist) and the sample count (default
//! 30 000). One run in air of 640×480 PNG frames (64 distinct noisy images of about
//! 200 KB, reused), then a dataset `bench` over it: several gigabytes at the default.

use softtouch_collector::dataset::{self, Filters, NewDataset, SplitRatio};
use softtouch_collector::store::Store;
use softtouch_collector::testing::{RunPlan, block_on, frame, seeded_run};
use softtouch_schemas::FrameFormat;
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(db) = args.next().map(PathBuf::from) else {
        eprintln!("usage: make_bench_db DB [SAMPLES]");
        std::process::exit(2);
    };
    let samples: u64 = args.next().map_or(30_000, |s| {
        s.parse().unwrap_or_else(|e| panic!("SAMPLES: `{s}`: {e}"))
    });
    if db.exists() {
        eprintln!("{} exists already", db.display());
        std::process::exit(2);
    }
    block_on(async {
        let store = Store::open(&db).await.unwrap_or_else(|e| panic!("{e}"));
        let frames: Vec<_> = (0..64)
            .map(|k| frame(k, 640, 480, FrameFormat::Png))
            .collect();
        let mean = frames.iter().map(|f| f.data.len()).sum::<usize>() / frames.len();
        eprintln!("frames of {mean} bytes on average");
        let plan = RunPlan {
            scene_name: "bench".into(),
            ..RunPlan::new(7, samples)
        };
        let run = seeded_run(&store, &plan, samples, |sample, rng| {
            let index = sample.index();
            let wrench = rng.wrench();
            let sample = sample.wrench(wrench).pose(rng.pose()).readings(25);
            let image = frames[usize::try_from(index % 64).unwrap_or(0)].clone();
            (sample, Some(image))
        })
        .await;
        dataset::create(
            &store,
            &NewDataset {
                name: "bench".into(),
                runs: vec![run],
                filters: Filters::default(),
                ratio: SplitRatio::PAPER,
                seed: 0,
            },
        )
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
    });
    eprintln!(
        "wrote {samples} samples and dataset `bench` to {}",
        db.display()
    );
}
