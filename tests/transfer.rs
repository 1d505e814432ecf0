//! End-to-end test of `softtouch transfer`: a land run and a water run with the same
//! poses (`collect --poses-from`), a tiny model trained on each, the comparison printed
//! and written as a CSV; unpaired datasets and bad options exit 2.

mod common;
use common::{fails_with, ok, softtouch, tempdir};
use std::path::Path;

const TINY: [&str; 14] = [
    "--size", "16", "--width", "4", "--latent", "8", "--epochs", "2", "--batch", "32",
    "--patience", "0", "--seed", "1",
];

fn train(d: &Path, dataset: &str) {
    let mut args = vec!["train", "--dataset", dataset];
    args.extend(TINY);
    ok(&softtouch(d, &args));
}

#[test]
fn transfer_compares_a_land_model_on_paired_land_and_water_samples() {
    let dir = tempdir();
    let d = dir.path();
    let water = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/water.toml");
    let water = water.to_str().unwrap_or_default();
    ok(&softtouch(d, &["db", "init"]));
    ok(&softtouch(d, &["collect", "--samples", "150", "--seed", "4"]));
    ok(&softtouch(d, &["collect", "--scene", water, "--poses-from", "1"]));
    // A water run of its own, with no partner on land.
    ok(&softtouch(
        d,
        &["collect", "--scene", water, "--samples", "40", "--seed", "9"],
    ));
    ok(&softtouch(d, &["dataset", "create", "land", "--runs", "1"]));
    ok(&softtouch(d, &["dataset", "create", "water", "--runs", "2"]));
    ok(&softtouch(d, &["dataset", "create", "lonely", "--runs", "3"]));
    train(d, "land");
    train(d, "water");

    let out = ok(&softtouch(
        d,
        &[
            "transfer",
            "--model",
            "land-svae",
            "--land",
            "land",
            "--water",
            "water",
            "--water-model",
            "water-svae",
            "--out",
            "t.csv",
        ],
    ));
    for needle in [
        "model land-svae on land `land` (30 test samples) and water `water` (30 test samples)",
        "axis   R² land   R² water   drop",
        "paired latents (30 pairs; water run 2 ↔ land run 1; every pose checked)",
        "cosine similarity per pair: mean",
        "linear CKA land against water:",
        "permutation p =",
        "land-svae             land",
        "water-svae            water",
    ] {
        assert!(out.contains(needle), "expected `{needle}` in:\n{out}");
    }
    let cka: f64 = out
        .lines()
        .find_map(|l| l.trim().strip_prefix("linear CKA land against water: "))
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    assert!((0.0..=1.0).contains(&cka), "{out}");
    let csv = std::fs::read_to_string(d.join("t.csv")).expect("t.csv");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "section,model,tested_on,axis,metric,value");
    // 6 axes × 2 media × (R², RMSE), 10 latent statistics, 4 table rows.
    assert_eq!(lines.len(), 1 + 24 + 10 + 4, "{csv}");
    assert!(csv.contains("latents,land-svae,paired,,cka,"), "{csv}");
    assert!(csv.contains("table,water-svae,water,,r2_mean,"), "{csv}");
    for line in &lines[1..] {
        let value: f64 = line.rsplit(',').next().and_then(|v| v.parse().ok()).unwrap_or(f64::NAN);
        assert!(value.is_finite(), "{line}");
    }

    // Split with another seed, the water test samples' partners are partly in the land
    // dataset's train and val splits: they are loaded too, and every test sample pairs.
    ok(&softtouch(
        d,
        &["dataset", "create", "water-b", "--runs", "2", "--seed", "7"],
    ));
    let out = ok(&softtouch(
        d,
        &[
            "transfer", "--model", "land-svae", "--land", "land", "--water", "water-b", "--out",
            "b.csv",
        ],
    ));
    assert!(out.contains("paired latents (30 pairs;"), "{out}");

    // No pairs, unknown names, bad options: exit 2.
    fails_with(
        &softtouch(
            d,
            &["transfer", "--model", "land-svae", "--land", "land", "--water", "lonely"],
        ),
        2,
        "no test sample of dataset `lonely` pairs with a sample of dataset `land`",
    );
    fails_with(
        &softtouch(
            d,
            &["transfer", "--model", "nope", "--land", "land", "--water", "water"],
        ),
        2,
        "no model named `nope`",
    );
    fails_with(
        &softtouch(
            d,
            &["transfer", "--model", "land-svae", "--land", "land", "--water", "sea"],
        ),
        2,
        "sea",
    );
    fails_with(
        &softtouch(
            d,
            &[
                "transfer",
                "--model",
                "land-svae",
                "--land",
                "land",
                "--water",
                "water",
                "--permutations",
                "0",
            ],
        ),
        2,
        "--permutations 0",
    );
}
