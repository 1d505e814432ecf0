//! End-to-end tests of `softtouch train`, `eval`, `models`, `sweep` and `bench model`
//! on a small simulated collection: the commands chain, the model is stored with its
//! metrics and evaluates from the store or a file, and bad input exits 2.

use crate::common;
use common::{fails_with, ok, simulated_dataset, softtouch, tempdir};

use std::path::Path;

/// A database with 240 simulated samples and a dataset `air` of them.
fn collected(dir: &Path) {
    simulated_dataset(dir, "240", "4", "air");
}

const TINY: [&str; 12] = [
    "--size",
    "16",
    "--width",
    "4",
    "--latent",
    "8",
    "--epochs",
    "3",
    "--batch",
    "32",
    "--patience",
    "0",
];

#[test]
fn train_store_list_and_evaluate_a_model() {
    let dir = tempdir();
    let d = dir.path();
    collected(d);
    let mut args = vec!["train", "--dataset", "air", "--out", "air.stm"];
    args.extend(TINY);
    let out = ok(&softtouch(d, &args));
    assert!(
        out.contains("dataset air: 168 train, 24 val, 48 test"),
        "{out}"
    );
    assert!(out.contains("epoch   3/3"), "{out}");
    assert!(out.contains("stored model `air-svae`"), "{out}");
    assert!(d.join("air.stm").is_file());
    // Training done and recorded: its checkpoint is gone.
    assert!(!d.join("checkpoints/air-svae").exists());

    let list = ok(&softtouch(d, &["models"]));
    assert!(list.contains("air-svae") && list.contains("svae"), "{list}");

    let from_store = ok(&softtouch(d, &["eval", "air-svae"]));
    for needle in ["Fx", "Tz", "mean", "image MSE", "[0, 2)", "[480, 600)"] {
        assert!(from_store.contains(needle), "`{needle}` in {from_store}");
    }
    // Only the split scored is preprocessed.
    assert!(from_store.contains(": 0 train, 0 val, "), "{from_store}");
    // A mistyped split is refused before anything is read or preprocessed.
    let typo = softtouch(d, &["eval", "air-svae", "--split", "tst"]);
    fails_with(&typo, 2, "'tst'");
    assert!(
        common::text(&typo.stderr).contains("test, val, train, all"),
        "{}",
        common::text(&typo.stderr)
    );
    assert!(!common::text(&typo.stdout).contains("preprocessed"));
    let from_file = ok(&softtouch(d, &["eval", "air.stm", "--dataset", "air"]));
    let metrics = |s: &str| {
        s.lines()
            .skip_while(|l| !l.starts_with("samples"))
            .filter(|l| !l.starts_with("wrote "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(metrics(&from_store), metrics(&from_file));
    // What it printed, as a plot: predicted against true, one panel per axis (3 × 2).
    assert!(
        from_store.contains("wrote eval-out/air-svae-test-eval.png"),
        "{from_store}"
    );
    let png = image::open(d.join("eval-out/air-svae-test-eval.png"))
        .unwrap_or_else(|e| panic!("the eval plot: {e}"));
    assert_eq!((png.width(), png.height()), (1260, 840));
    assert!(
        from_file.contains("wrote eval-out/air-test-eval.png"),
        "{from_file}"
    );

    // Same name again: refused, nothing overwritten.
    fails_with(&softtouch(d, &args), 2, "already exists");
    // A ConvNet beside it, under its own default name.
    let mut cnn = vec!["train", "--dataset", "air", "--model", "convnet"];
    cnn.extend(TINY);
    ok(&softtouch(d, &cnn));
    let vae = ok(&softtouch(d, &["eval", "air-convnet", "--split", "all"]));
    assert!(vae.contains("samples: 240"), "{vae}");
}

#[test]
fn bad_input_exits_2_with_a_clear_message() {
    let dir = tempdir();
    let d = dir.path();
    fails_with(
        &softtouch(d, &["train", "--dataset", "air"]),
        2,
        "no database",
    );
    collected(d);
    fails_with(
        &softtouch(d, &["train", "--dataset", "nope"]),
        2,
        "no dataset named `nope`",
    );
    fails_with(
        &softtouch(
            d,
            &["train", "--dataset", "air", "--size", "48", "--alpha=-1"],
        ),
        2,
        "input size 48 px",
    );
    fails_with(
        &softtouch(d, &["train", "--dataset", "air", "--model", "resnet"]),
        2,
        "unknown model",
    );
    fails_with(
        &softtouch(d, &["eval", "missing"]),
        2,
        "neither a stored model",
    );
    std::fs::write(d.join("junk.stm"), b"not a model").expect("write");
    fails_with(
        &softtouch(d, &["eval", "junk.stm", "--dataset", "air"]),
        2,
        "not a softtouch model",
    );
    fails_with(&softtouch(d, &["eval", "junk.stm"]), 2, "model file");
}

#[test]
fn sweeps_and_the_model_benchmark_write_tables_csv_and_png() {
    let dir = tempdir();
    let d = dir.path();
    collected(d);
    let mut args = vec![
        "sweep",
        "alpha",
        "--dataset",
        "air",
        "--alphas",
        "0.1,10",
        "--out",
        "sw",
    ];
    args.extend(TINY);
    let at = args.len() - 5;
    args[at] = "1"; // one epoch each
    let out = ok(&softtouch(d, &args));
    for row in ["ConvNet", "SVAE α=0.1", "SVAE α=10", "VAE"] {
        assert!(out.contains(row), "`{row}` in {out}");
    }
    let csv = std::fs::read_to_string(d.join("sw/sweep-alpha.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(csv.starts_with("label,model,alpha"));
    assert!(d.join("sw/sweep-alpha.png").is_file());

    let mut args = vec![
        "sweep",
        "latent",
        "--dataset",
        "air",
        "--latents",
        "4,8",
        "--out",
        "sw",
    ];
    args.extend(TINY);
    let at = args.len() - 5;
    args[at] = "1";
    let out = ok(&softtouch(d, &args));
    assert!(d.join("sw/sweep-latent.png").is_file());
    // Method S2 b–g: a decoder traversal per latent size.
    for n in [4, 8] {
        let png = d.join(format!("sw/sweep-latent-traversal-{n}.png"));
        assert!(png.is_file(), "{} missing: {out}", png.display());
        assert!(
            out.contains(&format!("sweep-latent-traversal-{n}.png")),
            "{out}"
        );
    }

    let out = ok(&softtouch(
        d,
        &[
            "bench",
            "model",
            "--dataset",
            "air",
            "--sizes",
            "16",
            "--widths",
            "2,4",
            "--latents",
            "8",
            "--epochs",
            "1",
            "--batch",
            "32",
            "--runs",
            "20",
            "--out",
            "bm",
        ],
    ));
    assert!(
        out.contains("model ms") && out.contains("frame ms") && out.contains("16px w4 l8"),
        "{out}"
    );
    let csv = std::fs::read_to_string(d.join("bm/bench-model.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert!(
        csv.starts_with("label,") && csv.contains(",latency_ms,frame_latency_ms,"),
        "{csv}"
    );
    assert!(d.join("bm/bench-model.png").is_file());
}

/// The full-size run behind the README's accuracy figures: 30 000 simulated samples
/// of the default scene, a 7:1:2 dataset, the default SVAE (α = 1, β = 0.1, 32×32,
/// width 16, latent 32, 12 epochs); every test axis must reach R² ≥ 0.99. About
/// 11 minutes on 2 cores (collection 4, preprocessing 1, training 6):
/// `cargo test --release --test end_to_end -- --ignored --nocapture train::full_size`
#[test]
#[ignore = "full-size training, ~11 min on 2 cores"]
fn full_size_svae_reaches_r2_0_99_on_every_test_axis() {
    let dir = tempdir();
    let d = dir.path();
    simulated_dataset(d, "30000", "1", "air30k");
    let out = ok(&softtouch(d, &["train", "--dataset", "air30k"]));
    println!("{out}");
    let r2: Vec<f64> = out
        .lines()
        .skip_while(|l| !l.starts_with("test split"))
        .filter(|l| {
            ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]
                .iter()
                .any(|a| l.starts_with(a))
        })
        .filter_map(|l| l.split_whitespace().nth(1)?.parse().ok())
        .collect();
    assert_eq!(r2.len(), 6, "{out}");
    assert!(r2.iter().all(|v| *v >= 0.99), "test R² per axis {r2:?}");
}
