//! End-to-end test of `softtouch transfer`: a land run and a water run with the same
//! poses (`collect --poses-from`), a tiny model trained on each, the comparison printed
//! and written as a CSV; unpaired datasets and bad options exit 2.

use crate::common;
use common::{TINY, fails_with, ok, runtime, softtouch, tempdir};
use std::path::Path;

/// A database with a land run (run 1, `samples` samples, seed 4) and a water run
/// with its poses (run 2, `collect --poses-from 1`), and datasets `land` and `water`
/// of them; returns the water scene's path.
fn paired_land_and_water(d: &Path, samples: &str) -> String {
    let water = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/water.toml");
    let water = water.to_str().unwrap_or_default().to_owned();
    ok(&softtouch(d, &["db", "init"]));
    ok(&softtouch(
        d,
        &["collect", "--samples", samples, "--seed", "4"],
    ));
    ok(&softtouch(
        d,
        &["collect", "--scene", &water, "--poses-from", "1"],
    ));
    ok(&softtouch(d, &["dataset", "create", "land", "--runs", "1"]));
    ok(&softtouch(
        d,
        &["dataset", "create", "water", "--runs", "2"],
    ));
    water
}

fn train(d: &Path, dataset: &str) {
    let mut args = vec!["train", "--dataset", dataset];
    args.extend(TINY);
    ok(&softtouch(d, &args));
}

#[test]
fn transfer_compares_a_land_model_on_paired_land_and_water_samples() {
    let dir = tempdir();
    let d = dir.path();
    let water = paired_land_and_water(d, "150");
    let water = water.as_str();
    // A water run of its own, with no partner on land.
    ok(&softtouch(
        d,
        &[
            "collect",
            "--scene",
            water,
            "--samples",
            "40",
            "--seed",
            "9",
        ],
    ));
    ok(&softtouch(
        d,
        &["dataset", "create", "lonely", "--runs", "3"],
    ));
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
    // The table as a plot: R² per axis of each model on each medium.
    assert!(
        out.contains("wrote t.csv, t-cosines.csv and t.png"),
        "{out}"
    );
    assert!(out.contains("stored as result 1"), "{out}");
    let png = image::open(d.join("t.png")).expect("the transfer plot");
    assert_eq!((png.width(), png.height()), (1100, 520));
    let csv = std::fs::read_to_string(d.join("t.csv")).expect("t.csv");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "section,model,tested_on,axis,metric,value");
    // 6 axes × 2 media × (R², RMSE), 10 latent statistics, 4 table rows.
    assert_eq!(lines.len(), 1 + 24 + 10 + 4, "{csv}");
    assert!(csv.contains("latents,land-svae,paired,,cka,"), "{csv}");
    assert!(csv.contains("table,water-svae,water,,r2_mean,"), "{csv}");
    for line in &lines[1..] {
        let value: f64 = line
            .rsplit(',')
            .next()
            .and_then(|v| v.parse().ok())
            .unwrap_or(f64::NAN);
        assert!(value.is_finite(), "{line}");
    }

    stored_transfer_is_the_export_and_the_report_shows_it(d, &csv);

    // Split with another seed, the water test samples' partners are partly in the land
    // dataset's train and val splits: they are loaded too, and every test sample pairs.
    ok(&softtouch(
        d,
        &["dataset", "create", "water-b", "--runs", "2", "--seed", "7"],
    ));
    let out = ok(&softtouch(
        d,
        &[
            "transfer",
            "--model",
            "land-svae",
            "--land",
            "land",
            "--water",
            "water-b",
            "--out",
            "b/b.csv",
        ],
    ));
    assert!(out.contains("paired latents (30 pairs;"), "{out}");

    // The image tare, fitted from the runs' rest frames (8 each).
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
            "--tare",
            "--out",
            "tare/t.csv",
        ],
    ));
    for needle in [
        "image tare of `water` against `land` (8 water and 8 land rest frames): scale 1.3",
        "Fz     with the tare: R²",
        "with the image tare: cosine mean",
        "land-svae             water_tare",
    ] {
        assert!(out.contains(needle), "expected `{needle}` in:\n{out}");
    }
    // The scene's refraction index, 1.333, found from the rest frames alone.
    let csv = std::fs::read_to_string(d.join("tare/t.csv")).expect("tare/t.csv");
    let scale: f64 = csv
        .lines()
        .find_map(|l| l.strip_prefix("tare,,water,,scale,"))
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    assert!((scale - 1.333).abs() < 0.01, "{csv}");
    for needle in [
        "accuracy,land-svae,water_tare,fz,r2,",
        "latents,land-svae,paired_tare,,cka,",
        "table,land-svae,water_tare,,r2_mean,",
    ] {
        assert!(csv.contains(needle), "expected `{needle}` in:\n{csv}");
    }
    // Water grasp trials through the tare: fitted against the model's dataset's rest
    // frames, said in the session's header, stored with the session.
    let grasp_water = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/grasp-water.toml");
    let grasp_water = grasp_water.to_str().unwrap_or_default();
    let trials = |extra: &[&str]| {
        let mut args = vec![
            "grasp",
            "trials",
            "--model",
            "land-svae",
            "--scene",
            grasp_water,
            "--objects",
            "cylinder",
            "--modes",
            "open",
            "--trials",
            "1",
            "--accept-calibration",
            "--out-dir",
            "gt",
        ];
        args.extend(extra);
        softtouch(d, &args)
    };
    // The tiny model finds no touch in water, so the calibration stops the session;
    // its error says the tare it read the frames through, fitted from the rest frames.
    fails_with(
        &trials(&["--tare"]),
        2,
        "calibrating `cylinder` (reading the frames through the image tare from 8 rest frames of the finger camera against 8 of dataset `land`: scale 1.33",
    );
    // A dataset whose runs kept no rest frame (collected before they were kept).
    runtime().block_on(async {
        let store = common::open_store(&d.join("softtouch.db")).await;
        sqlx::raw_sql("DELETE FROM rest_frames WHERE run_id = 1")
            .execute(store.pool())
            .await
            .expect("delete");
        store.close().await;
    });
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
                "--tare",
            ],
        ),
        2,
        "dataset `land` has no rest frames",
    );
    fails_with(
        &trials(&["--tare"]),
        2,
        "--tare: model `land-svae`'s dataset: dataset `land` has no rest frames",
    );

    // No pairs, unknown names, bad options: exit 2.
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
                "lonely",
            ],
        ),
        2,
        "no test sample of dataset `lonely` pairs with a sample of dataset `land`",
    );
    fails_with(
        &softtouch(
            d,
            &[
                "transfer", "--model", "nope", "--land", "land", "--water", "water",
            ],
        ),
        2,
        "no model named `nope`",
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
                "sea",
            ],
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

/// Fine-tuning (`train --init`, `sweep finetune`) and the latent figures (`latent`) on
/// a land run and its paired water run.
#[test]
fn fine_tuning_and_latent_figures_from_a_land_model() {
    let dir = tempdir();
    let d = dir.path();
    paired_land_and_water(d, "120");
    train(d, "land");

    // train --init: the settings come from the starting model; the start is recorded.
    let out = ok(&softtouch(
        d,
        &[
            "train",
            "--dataset",
            "water",
            "--init",
            "land-svae",
            "--epochs",
            "2",
            "--batch",
            "32",
            "--patience",
            "0",
        ],
    ));
    for needle in [
        "training water-from-land-svae: svae width 4 latent 8 input 1×16×16",
        "starting from land-svae (weights ",
        "fine-tuned from land-svae (weights ",
        "stored model `water-from-land-svae`",
    ] {
        assert!(out.contains(needle), "expected `{needle}` in:\n{out}");
    }
    fails_with(
        &softtouch(
            d,
            &[
                "train",
                "--dataset",
                "water",
                "--init",
                "land-svae",
                "--latent",
                "16",
                "--name",
                "x",
            ],
        ),
        2,
        "--init land-svae: that model is a svae width 4 latent 8",
    );
    fails_with(
        &softtouch(d, &["train", "--dataset", "water", "--init", "nope"]),
        2,
        "no model named `nope`",
    );

    // sweep finetune: n = 0 is the land model untouched; each n fine-tuned and scratch.
    let out = ok(&softtouch(
        d,
        &[
            "sweep",
            "finetune",
            "--init",
            "land-svae",
            "--dataset",
            "water",
            "--samples",
            "40,0,20",
            "--epochs",
            "2",
            "--batch",
            "16",
            "--out",
            "ft",
        ],
    ));
    assert!(out.contains("fine-tuning land-svae (weights "), "{out}");
    assert!(
        out.contains("— 20 samples (3 validation), fine-tuned"),
        "{out}"
    );
    assert!(
        out.contains("— 40 samples (6 validation), scratch"),
        "{out}"
    );
    let csv = std::fs::read_to_string(d.join("ft/finetune.csv")).expect("finetune.csv");
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("samples,val_samples,start,epochs_run,best_epoch,epochs_to_target,seconds,r2_mean,r2_min,r2_fx"), "{csv}");
    assert_eq!(lines.len(), 1 + 1 + 2 * 2, "{csv}");
    assert!(lines[1].starts_with("0,0,fine-tuned,0,0,,"), "{csv}");
    assert!(lines[2].starts_with("20,3,fine-tuned,2,"), "{csv}");
    assert!(lines[5].starts_with("40,6,scratch,2,"), "{csv}");
    assert_png(&d.join("ft/finetune.png"));
    for (samples, needle) in [
        ("1", "--samples 1: training needs at least 2"),
        (
            "100000",
            "--samples 100000: the dataset's train split holds 84",
        ),
    ] {
        fails_with(
            &softtouch(
                d,
                &[
                    "sweep",
                    "finetune",
                    "--init",
                    "land-svae",
                    "--dataset",
                    "water",
                    "--samples",
                    samples,
                    "--out",
                    "ft2",
                ],
            ),
            2,
            needle,
        );
    }

    // latent: the two maps, the traversal, the paired instances and the CSV.
    let out = ok(&softtouch(
        d,
        &[
            "latent",
            "land-svae",
            "--dataset",
            "land",
            "--water",
            "water",
            "--out",
            "lat",
        ],
    ));
    assert!(
        out.contains("model land-svae (8 latent dimensions) on `land` (24 test samples)"),
        "{out}"
    );
    assert!(out.contains("axis  strongest latent  r"), "{out}");
    assert!(out.contains("mean |r| between latent dimensions:"), "{out}");
    for file in [
        "land-svae-latent-correlation.png",
        "land-svae-latent-wrench.png",
        "land-svae-traversal.png",
        "land-svae-paired.png",
    ] {
        assert_png(&d.join("lat").join(file));
    }
    let csv = std::fs::read_to_string(d.join("lat/land-svae-latent.csv")).expect("csv");
    // 8 × 8 latent cells and 8 × 6 wrench cells.
    assert_eq!(csv.lines().count(), 1 + 64 + 48, "{csv}");
    assert!(csv.contains("latent,z0,z0,1.000000"), "{csv}");
    assert!(csv.contains("wrench,z7,Tz,"), "{csv}");
    the_report_shows_the_stored_curve_and_maps(d);
    fails_with(
        &softtouch(
            d,
            &["latent", "land-svae", "--dataset", "land", "--dims", "8"],
        ),
        2,
        "--dims 8: model land-svae has latent dimensions 0 to 7",
    );
    fails_with(
        &softtouch(
            d,
            &["latent", "land-svae", "--dataset", "land", "--span", "0"],
        ),
        2,
        "--span 0",
    );
}

/// A PNG file that starts with the PNG signature and is not trivially small.
fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.len() > 1000,
        "{} is no PNG",
        path.display()
    );
}

/// The stored result's tables are the files byte for byte; the report's Land to water
/// section shows the stored numbers.
fn stored_transfer_is_the_export_and_the_report_shows_it(d: &Path, csv: &str) {
    let listed = ok(&softtouch(d, &["results"]));
    assert!(
        listed.contains("transfer") && listed.contains("land-svae"),
        "{listed}"
    );
    let stored = ok(&softtouch(d, &["results", "show", "1", "--table", "t.csv"]));
    assert_eq!(stored, csv);
    let cosines = std::fs::read_to_string(d.join("t-cosines.csv")).expect("cosines");
    assert_eq!(
        ok(&softtouch(
            d,
            &["results", "show", "1", "--table", "t-cosines.csv"]
        )),
        cosines
    );
    assert_eq!(cosines.lines().count(), 31, "a line per pair: {cosines}");
    let shown = ok(&softtouch(d, &["results", "show", "1"]));
    for needle in [
        "result 1: transfer",
        "model:     land-svae (artifact sha256 ",
        "dataset:   land",
        "\"permutations\":200",
        "software:  softtouch ",
    ] {
        assert!(shown.contains(needle), "`{needle}` in:\n{shown}");
    }
    fails_with(
        &softtouch(d, &["results", "show", "1", "--table", "nope.csv"]),
        2,
        "result 1 has no table `nope.csv`; it has: t-cosines.csv, t.csv",
    );
    fails_with(&softtouch(d, &["results", "show", "9"]), 2, "no result 9");

    let html = common::report_page(d);
    let cell = |key: &str| common::data_k(&html, key);
    let stored = |prefix: &str| -> f64 {
        csv.lines()
            .find(|l| l.starts_with(prefix))
            .and_then(|l| l.rsplit(',').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{prefix} in {csv}"))
    };
    for (key, prefix) in [
        ("transfer-1-land-fx", "accuracy,land-svae,land,fx,r2,"),
        ("transfer-1-water-tz", "accuracy,land-svae,water,tz,r2,"),
        ("transfer-1-cka", "latents,land-svae,paired,,cka,"),
        ("transfer-1-mmd-p", "latents,land-svae,paired,,mmd_p,"),
    ] {
        assert_eq!(cell(key), format!("{:.4}", stored(prefix)), "{key}");
    }
}

/// The report's fine-tuning table and latent maps are the stored ones.
fn the_report_shows_the_stored_curve_and_maps(d: &Path) {
    let listed = ok(&softtouch(d, &["results", "list"]));
    assert!(
        listed.contains("sweep finetune") && listed.contains("latent"),
        "{listed}"
    );
    let html = common::report_page(d);
    let finetune = std::fs::read_to_string(d.join("ft/finetune.csv")).expect("csv");
    let header: Vec<&str> = finetune.lines().next().unwrap_or("").split(',').collect();
    let col = header
        .iter()
        .position(|c| *c == "r2_mean")
        .expect("r2_mean");
    let sel = scraper::Selector::parse("[data-k^=\"finetune-\"]").expect("selector");
    let shown: Vec<String> = html
        .select(&sel)
        .map(|e| e.text().collect::<String>().trim().to_owned())
        .collect();
    let stored: Vec<String> = finetune
        .lines()
        .skip(1)
        .map(|l| {
            let v: f64 = l
                .split(',')
                .nth(col)
                .and_then(|v| v.parse().ok())
                .unwrap_or(f64::NAN);
            if v.is_finite() {
                format!("{v:.4}")
            } else {
                "–".into()
            }
        })
        .collect();
    assert_eq!(shown, stored);
    // The two maps of land-svae: 8 latent rows each, 8 and 6 columns.
    let rows = scraper::Selector::parse("#land-to-water table.heat tr").expect("selector");
    assert_eq!(html.select(&rows).count(), 2 * (1 + 8));
    let text: String = html
        .select(&scraper::Selector::parse("#land-to-water").expect("selector"))
        .map(|e| e.text().collect::<String>())
        .collect();
    assert!(
        text.contains("No land-to-water comparison stored"),
        "{text}"
    );
    // The traversal and the paired instances, stored byte for byte and shown inline.
    let imgs = scraper::Selector::parse("#land-to-water figure.stored img").expect("selector");
    assert_eq!(html.select(&imgs).count(), 2);
    let id = listed
        .lines()
        .find(|l| l.contains(" latent "))
        .and_then(|l| l.split_whitespace().next())
        .expect("the latent result's id");
    let shown = ok(&softtouch(d, &["results", "show", id]));
    for png in ["land-svae-traversal.png", "land-svae-paired.png"] {
        let bytes = std::fs::read(d.join("lat").join(png)).expect("png");
        assert!(
            shown.contains(&format!("figure {png}: {} bytes of PNG", bytes.len())),
            "{shown}"
        );
    }
}
