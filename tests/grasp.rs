//! End-to-end test of `softtouch grasp follow`: a tiny model trained on a small
//! simulated collection closes the loop on the simulated soft-finger Hand-E; the verb
//! prints one row per target and writes the CSV and the PNG; bad input exits 2.

mod common;
use common::{fails_with, ok, simulated_dataset, softtouch, tempdir};

#[test]
fn grasp_follow_prints_a_row_per_target_and_writes_csv_and_png() {
    let dir = tempdir();
    let d = dir.path();
    simulated_dataset(d, "120", "5", "air");
    ok(&softtouch(
        d,
        &[
            "train",
            "--dataset",
            "air",
            "--size",
            "16",
            "--width",
            "4",
            "--latent",
            "8",
            "--epochs",
            "2",
            "--batch",
            "32",
            "--patience",
            "0",
        ],
    ));
    let out = ok(&softtouch(
        d,
        &[
            "grasp",
            "follow",
            "--model",
            "air-svae",
            "--targets",
            "0.4,1.6",
            "--fps",
            "30",
            "--hold-s",
            "1",
            "--out-dir",
            "g",
        ],
    ));
    assert!(out.contains("measured Λ_max"), "{out}");
    assert!(out.contains("target N"), "{out}");
    for row in ["    0.40 ", "    1.60 "] {
        assert!(
            out.lines().any(|l| l.starts_with(row)),
            "no row {row:?}: {out}"
        );
    }
    let csv = std::fs::read_to_string(d.join("g/grasp-follow.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert!(
        rows[0].starts_with("t_s,frame,target_n,estimate_n,true_n"),
        "{}",
        rows[0]
    );
    // One row per camera frame: 2 s at 30 Hz.
    assert!((58..=62).contains(&(rows.len() - 1)), "{}", rows.len());
    assert!(rows[1..].iter().all(|r| r.split(',').count() == 9));
    let png = std::fs::read(d.join("g/grasp-follow.png")).expect("png");
    assert!(png.starts_with(b"\x89PNG"));

    fails_with(
        &softtouch(
            d,
            &["grasp", "follow", "--model", "air-svae", "--targets", "12"],
        ),
        2,
        "target 12 N is unreachable",
    );
    fails_with(
        &softtouch(d, &["grasp", "follow", "--model", "nope"]),
        2,
        "nope",
    );
    fails_with(
        &softtouch(
            d,
            &["grasp", "follow", "--model", "air-svae", "--object", "vase"],
        ),
        2,
        "--object vase",
    );
}
