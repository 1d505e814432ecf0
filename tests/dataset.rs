//! End-to-end tests of `softtouch dataset …`: create (filters, splits), stats,
//! export, import (both layouts, malformed input), and the export → import → export
//! round trip. The data is made here with the store API: two runs with small real PNG,
//! raw RGB and JPEG frames, varied rods, media, statuses and wrenches.
//!
//! Malformed inputs of the paper's layout are files under `tests/dataset_cases/paper/`:
//! each case folder holds a `data_frame.csv` and an `expected.txt` with the text the
//! error must contain (images `img0.png` … `img3.png` are written beside it here).

use crate::common;
use common::{fails_with, ok, softtouch, tempdir, text};

use softtouch_collector::dataset::export::sha256_hex;
use softtouch_collector::dataset::{self, Filters, NewDataset, SplitRatio};
use softtouch_collector::store::{RunStatus, Store};
use softtouch_collector::testing::{RunPlan, block_on, frame, seeded_run};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{FrameFormat, Medium, SampleStatus};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn write(path: &Path, bytes: impl AsRef<[u8]>) {
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// A `w`×`h` PNG of the test pattern.
fn png(seed: u64, w: u32, h: u32) -> Vec<u8> {
    frame(seed, w, h, FrameFormat::Png).data
}

fn jpeg(seed: u64, w: u32, h: u32) -> Vec<u8> {
    frame(seed, w, h, FrameFormat::Jpeg).data
}

/// How one test run looks.
struct RunSpec {
    medium: Medium,
    samples: u64,
    rods: &'static [&'static str],
    /// Frame format by sample index.
    format: fn(u64) -> FrameFormat,
    seed: u64,
}

/// Write a run with the store API; returns its id. Every 10th sample is rejected
/// (saturated), sample 5 is rejected without a frame, readings and skew vary.
async fn make_run(store: &Store, spec: &RunSpec, width: u32, height: u32) -> i64 {
    let plan = RunPlan {
        rods: spec.rods.iter().map(|r| (*r).to_owned()).collect(),
        rod_block: 1,
        medium: spec.medium,
        scene_name: if spec.medium == Medium::Air {
            "on-land"
        } else {
            "underwater"
        }
        .into(),
        ..RunPlan::new(spec.seed, spec.samples)
    };
    let run = seeded_run(store, &plan, spec.samples, |sample, rng| {
        let index = sample.index();
        let status = if index % 10 == 9 {
            SampleStatus::Rejected(RejectReason::Saturated)
        } else if index == 5 {
            SampleStatus::Rejected(RejectReason::FrameTimeout)
        } else {
            SampleStatus::Ok
        };
        let wrench = rng.wrench();
        let t = 1_000_000 * index;
        let sample = sample
            .wrench(wrench)
            .pose(rng.pose())
            .readings(10 + u32::try_from(index % 30).unwrap_or(0))
            .times(t, t, t + 25_000)
            .skew_ns(i64::try_from(index % 7).unwrap_or(0) * 500_000 - 1_500_000)
            .status(status);
        let format = (spec.format)(index);
        let image = (index != 5).then(|| frame(spec.seed * 1000 + index, width, height, format));
        (sample, image)
    })
    .await;
    store
        .set_run_status(run, RunStatus::Completed)
        .await
        .unwrap_or_else(|e| panic!("{e}"));
    run
}

/// Run 1: air, 120 samples, PNG frames, two rods. Run 2: water, 60 samples, raw RGB
/// and JPEG frames, three rods.
fn lab() -> (tempfile::TempDir, PathBuf) {
    block_on(async {
        let dir = softtouch_collector::testing::tempdir();
        let store = common::open_store(&dir.path().join("lab.db")).await;
        let air = RunSpec {
            medium: Medium::Air,
            samples: 120,
            rods: &["circle-10", "square-10"],
            format: |_| FrameFormat::Png,
            seed: 1,
        };
        let water = RunSpec {
            medium: Medium::Water,
            samples: 60,
            rods: &["circle-10", "hexagon-8", "oval, big"],
            format: |i| {
                if i % 2 == 0 {
                    FrameFormat::Rgb8
                } else {
                    FrameFormat::Jpeg
                }
            },
            seed: 2,
        };
        assert_eq!(make_run(&store, &air, 32, 24).await, 1);
        assert_eq!(make_run(&store, &water, 32, 24).await, 2);
        let db = dir.path().join("lab.db");
        store.close().await;
        (dir, db)
    })
}

/// Accepted samples with frames: run 1 has 120 − 12 rejected − 1 without frame = 107;
/// run 2 has 60 − 6 − 1 = 53.
const RUN1_OK: usize = 107;
const RUN2_OK: usize = 53;

fn members(db: &Path, name: &str) -> Vec<(i64, i64, i64, String)> {
    block_on(async {
        let store = common::open_store(db).await;
        let rows: Vec<(i64, i64, i64, String)> = sqlx::query_as(store.dialect().sql(
            "SELECT m.position, m.run_id, m.sample_index, m.split FROM dataset_members m
             JOIN datasets d ON d.dataset_id = m.dataset_id WHERE d.name = ? ORDER BY m.position",
        ))
        .bind(name)
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
        rows
    })
}

fn count_rows(db: &Path, table: &'static str) -> i64 {
    let sql = match table {
        "runs" => "SELECT COUNT(*) FROM runs",
        "datasets" => "SELECT COUNT(*) FROM datasets",
        "samples" => "SELECT COUNT(*) FROM samples",
        _ => panic!("{table}"),
    };
    block_on(async {
        let store = common::open_store(db).await;
        let n: i64 = sqlx::query_scalar(store.dialect().sql(sql))
            .fetch_one(store.pool())
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
        n
    })
}

#[test]
fn help_of_every_dataset_verb_has_an_example() {
    let dir = tempdir();
    ok(&softtouch(dir.path(), &["dataset", "--help"]));
    for verb in ["create", "list", "stats", "export", "import"] {
        let help = ok(&softtouch(dir.path(), &["dataset", verb, "--help"]));
        assert!(help.contains("softtouch dataset "), "{verb}: {help}");
    }
}

#[test]
fn create_splits_7_1_2_and_refuses_duplicates_unknown_runs_and_tiny_selections() {
    let (dir, _db) = lab();
    let d = dir.path();
    let out = ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2", "--seed", "9",
        ],
    ));
    let n = RUN1_OK + RUN2_OK; // 160: 112, 16, 32 exactly
    assert!(
        out.contains(&format!("{n} samples (train 112, val 16, test 32)")),
        "{out}"
    );

    let m = members(&d.join("lab.db"), "all");
    assert_eq!(m.len(), n);
    let positions: Vec<i64> = m.iter().map(|r| r.0).collect();
    assert_eq!(positions, (0..n as i64).collect::<Vec<_>>());
    // Ordered by run then index, each sample once.
    let keys: Vec<(i64, i64)> = m.iter().map(|r| (r.1, r.2)).collect();
    let mut sorted = keys.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(keys, sorted);

    fails_with(
        &softtouch(
            d,
            &["--db", "lab.db", "dataset", "create", "all", "--runs", "1"],
        ),
        2,
        "a dataset named `all` already exists",
    );
    fails_with(
        &softtouch(
            d,
            &["--db", "lab.db", "dataset", "create", "x", "--runs", "1,7"],
        ),
        2,
        "no run 7",
    );
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "create", "x", "--runs", "1", "--rod", "nope",
            ],
        ),
        2,
        "the selection is empty",
    );
    // Five samples cannot be split 7:1:2 without an empty validation split.
    fails_with(
        &softtouch(
            d,
            &[
                "--db",
                "lab.db",
                "dataset",
                "create",
                "x",
                "--runs",
                "1",
                "--max-force-n",
                "1.3",
            ],
        ),
        2,
        "too few for split 7:1:2",
    );
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "create", "x", "--runs", "1", "--split", "7:1",
            ],
        ),
        2,
        "bad split ratio",
    );
    // A missing file (on PostgreSQL every test path stands for a database that exists).
    if !common::on_postgres() {
        fails_with(
            &softtouch(
                d,
                &[
                    "--db",
                    "nowhere.db",
                    "dataset",
                    "create",
                    "x",
                    "--runs",
                    "1",
                ],
            ),
            2,
            "no database",
        );
    }
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "create", "../evil", "--runs", "1",
            ],
        ),
        2,
        "bad dataset name",
    );
    assert_eq!(count_rows(&d.join("lab.db"), "datasets"), 1);

    let list = ok(&softtouch(d, &["--db", "lab.db", "dataset", "list"]));
    assert!(list.contains("all") && list.contains("112"), "{list}");
}

#[test]
fn the_same_definition_and_seed_give_the_same_split_and_another_seed_another() {
    let (dir, db) = lab();
    let d = dir.path();
    for (name, seed) in [("a", "5"), ("b", "5"), ("c", "6")] {
        ok(&softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "create", name, "--runs", "2,1", "--seed", seed,
            ],
        ));
    }
    let (a, b, c) = (members(&db, "a"), members(&db, "b"), members(&db, "c"));
    assert_eq!(a, b);
    assert_ne!(a, c);
    let keys = |m: &[(i64, i64, i64, String)]| m.iter().map(|r| (r.1, r.2)).collect::<Vec<_>>();
    assert_eq!(
        keys(&a),
        keys(&c),
        "the selection does not depend on the seed"
    );
}

/// status, medium, rod, Fx, Fy, Fz, Tx, Ty, Tz, skew, readings.
type MemberRow = (
    String,
    String,
    String,
    f64,
    f64,
    f64,
    f64,
    f64,
    f64,
    i64,
    i64,
);

#[test]
fn filters_select_what_they_say() {
    let (_dir, db) = lab();
    let counts = block_on(async {
        let store = common::open_store(&db).await;
        let mut out = BTreeMap::new();
        let cases: Vec<(&str, Filters)> = vec![
            ("default", Filters::default()),
            (
                "rejected",
                Filters {
                    include_rejected: true,
                    ..Filters::default()
                },
            ),
            (
                "water",
                Filters {
                    medium: Some(Medium::Water),
                    ..Filters::default()
                },
            ),
            (
                "hexagon",
                Filters {
                    rods: vec!["hexagon-8".into()],
                    ..Filters::default()
                },
            ),
            (
                "two-rods",
                Filters {
                    rods: vec!["hexagon-8".into(), "square-10".into()],
                    ..Filters::default()
                },
            ),
            (
                "force",
                Filters {
                    max_force_n: Some(5.0),
                    ..Filters::default()
                },
            ),
            (
                "torque",
                Filters {
                    max_torque_nmm: Some(300.0),
                    ..Filters::default()
                },
            ),
            (
                "skew",
                Filters {
                    max_skew_ms: Some(0.5),
                    ..Filters::default()
                },
            ),
            (
                "readings",
                Filters {
                    min_readings: Some(30),
                    ..Filters::default()
                },
            ),
        ];
        for (name, filters) in cases {
            let info = dataset::create(
                &store,
                &NewDataset {
                    name: name.into(),
                    runs: vec![1, 2],
                    filters: filters.clone(),
                    ratio: SplitRatio { parts: [1, 0, 0] },
                    seed: 0,
                },
            )
            .await
            .unwrap_or_else(|e| panic!("{name}: {e}"));
            // Check each member against the filter from the stored sample.
            let rows: Vec<MemberRow> =
                sqlx::query_as(store.dialect().sql(
                    "SELECT s.status, s.medium, s.rod, s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm,
                            s.sync_skew_ns, s.reading_count
                     FROM dataset_members m JOIN samples s USING (run_id, sample_index)
                     WHERE m.dataset_id = ?"),
                )
                .bind(info.dataset_id)
                .fetch_all(store.pool())
                .await
                .unwrap_or_else(|e| panic!("{e}"));
            for r in &rows {
                assert!(filters.include_rejected || r.0 == "ok", "{name}");
                assert!(filters.medium.is_none_or(|m| m.as_str() == r.1), "{name}");
                assert!(
                    filters.rods.is_empty() || filters.rods.contains(&r.2),
                    "{name}"
                );
                assert!(
                    filters
                        .max_force_n
                        .is_none_or(|f| r.3.abs() <= f && r.4.abs() <= f && r.5.abs() <= f)
                );
                assert!(
                    filters
                        .max_torque_nmm
                        .is_none_or(|t| [r.6, r.7, r.8].iter().all(|v| (v * 1000.0).abs() <= t))
                );
                assert!(
                    filters
                        .max_skew_ms
                        .is_none_or(|s| (r.9 as f64).abs() <= s * 1e6)
                );
                assert!(filters.min_readings.is_none_or(|n| r.10 >= i64::from(n)));
            }
            out.insert(name, rows.len());
        }
        store.close().await;
        out
    });
    assert_eq!(counts["default"], RUN1_OK + RUN2_OK);
    // Rejected samples with frames come in; the one without a frame never does.
    assert_eq!(counts["rejected"], 119 + 59);
    assert_eq!(counts["water"], RUN2_OK);
    for name in ["hexagon", "two-rods", "force", "torque", "skew", "readings"] {
        assert!(
            counts[name] > 0 && counts[name] < counts["default"],
            "{name}: {counts:?}"
        );
    }
    assert!(counts["two-rods"] > counts["hexagon"]);
}

#[test]
fn stats_prints_a_table_and_writes_six_histograms() {
    let (dir, _db) = lab();
    let d = dir.path();
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2",
        ],
    ));
    let out = ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "stats", "all", "--out", "plots",
        ],
    ));
    for needle in [
        "train",
        "val",
        "test",
        "rod circle-10",
        "rod oval, big",
        "medium water",
        "Fx",
        "Tz",
        "N·mm",
        "histograms:",
    ] {
        assert!(out.contains(needle), "`{needle}` missing from:\n{out}");
    }
    let all_row = out
        .lines()
        .find(|l| l.starts_with("all "))
        .unwrap_or_default();
    assert_eq!(
        all_row.split_whitespace().collect::<Vec<_>>(),
        ["all", "112", "16", "32", "160"],
        "{out}"
    );
    let png = d.join("plots/all-histograms.png");
    let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
    assert_eq!((img.width(), img.height()), (1500, 860));
    fails_with(
        &softtouch(d, &["--db", "lab.db", "dataset", "stats", "nope"]),
        2,
        "no dataset named `nope`",
    );
}

fn labels(dir: &Path) -> Vec<Vec<String>> {
    let text = String::from_utf8(read(&dir.join("labels.csv"))).unwrap_or_else(|e| panic!("{e}"));
    text.lines()
        .map(|l| {
            // Only the rod `oval, big` is quoted in these tests.
            let l = l.replace("\"oval, big\"", "oval;big");
            l.split(',').map(str::to_owned).collect()
        })
        .collect()
}

#[test]
fn export_writes_images_labels_and_a_manifest_with_checksums() {
    let (dir, db) = lab();
    let d = dir.path();
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2",
        ],
    ));
    let out = ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "export", "all", "--out", "exp/all",
        ],
    ));
    assert!(out.contains("exported 160 samples"), "{out}");
    let exp = d.join("exp/all");
    // Nothing partial left beside it.
    let siblings: Vec<String> = std::fs::read_dir(d.join("exp"))
        .unwrap_or_else(|e| panic!("{e}"))
        .map(|e| {
            e.map(|e| e.file_name().to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect();
    assert_eq!(siblings, ["all"]);

    let rows = labels(&exp);
    assert_eq!(
        rows[0].join(","),
        "image,fx_n,fy_n,fz_n,tx_nmm,ty_nmm,tz_nmm,x_m,z_m,theta_rad,rod,medium,split,run,index"
    );
    assert_eq!(rows.len(), 161);
    let manifest: serde_json::Value =
        serde_json::from_slice(&read(&exp.join("manifest.json"))).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(manifest["format"], "softtouch-dataset");
    assert_eq!(manifest["dataset"]["name"], "all");
    assert_eq!(manifest["dataset"]["definition"]["split"], "7:1:2");
    assert_eq!(manifest["runs"].as_array().map(Vec::len), Some(2));
    assert!(
        manifest["runs"][0]["rig_toml"]
            .as_str()
            .is_some_and(|t| t.contains("[arm]"))
    );
    let sums = manifest["sha256"].as_object().cloned().unwrap_or_default();
    assert_eq!(sums.len(), 161);
    assert_eq!(
        sums["labels.csv"],
        sha256_hex(&read(&exp.join("labels.csv")))
    );

    let stored: BTreeMap<(i64, i64), (String, Vec<u8>, f64)> = block_on(async {
        let store = common::open_store(&db).await;
        let rows: Vec<(i64, i64, String, Vec<u8>, f64)> = sqlx::query_as(store.dialect().sql(
            "SELECT f.run_id, f.sample_index, f.format, f.data, s.tx_nm FROM frames f JOIN samples s USING (run_id, sample_index)"),
        )
        .fetch_all(store.pool())
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        store.close().await;
        rows.into_iter()
            .map(|r| ((r.0, r.1), (r.2, r.3, r.4)))
            .collect()
    });
    let mut splits = BTreeMap::new();
    for row in &rows[1..] {
        assert_eq!(row.len(), 15, "{row:?}");
        let bytes = read(&exp.join(&row[0]));
        assert_eq!(sums[&row[0]], sha256_hex(&bytes));
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .unwrap_or_else(|e| panic!("{}: {e}", row[0]));
        assert_eq!((img.width(), img.height()), (32, 24));
        let run: i64 = row[13].parse().unwrap_or_else(|e| panic!("{e}"));
        let index: i64 = row[14].parse().unwrap_or_else(|e| panic!("{e}"));
        let (format, data, tx_nm) = &stored[&(run, index)];
        match format.as_str() {
            "png" => assert_eq!(&bytes, data, "PNG frames are copied verbatim"),
            "rgb8" => assert_eq!(
                img.to_rgb8().into_raw(),
                *data,
                "raw frames are encoded losslessly"
            ),
            _ => {
                let jpeg = image::load_from_memory(data).unwrap_or_else(|e| panic!("{e}"));
                assert_eq!(
                    img.to_rgb8(),
                    jpeg.to_rgb8(),
                    "JPEG frames are decoded once, then lossless"
                );
            }
        }
        let tx_nmm: f64 = row[4].parse().unwrap_or_else(|e| panic!("{e}"));
        assert!((tx_nmm - tx_nm * 1000.0).abs() < 1e-9, "torque in N·mm");
        *splits.entry(row[12].clone()).or_insert(0) += 1;
    }
    assert_eq!(
        splits,
        BTreeMap::from([
            ("test".into(), 32),
            ("train".into(), 112),
            ("val".into(), 16)
        ])
    );

    // An existing, non-empty folder is refused; an empty one is used.
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "export", "all", "--out", "exp/all",
            ],
        ),
        2,
        "already exists",
    );
    std::fs::create_dir(d.join("empty")).unwrap_or_else(|e| panic!("{e}"));
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "export", "all", "--out", "empty",
        ],
    ));
    fails_with(
        &softtouch(
            d,
            &["--db", "lab.db", "dataset", "export", "nope", "--out", "x"],
        ),
        2,
        "no dataset named",
    );
}

#[test]
fn export_import_export_gives_the_same_labels_and_images_byte_for_byte() {
    let (dir, _db) = lab();
    let d = dir.path();
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2", "--seed", "3",
        ],
    ));
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "export", "all", "--out", "first",
        ],
    ));

    // Into a fresh database: the dataset keeps its name, runs get new ids there.
    let out = ok(&softtouch(
        d,
        &["--db", "copy.db", "dataset", "import", "first"],
    ));
    assert!(
        out.contains("imported 160 samples (softtouch-export)"),
        "{out}"
    );
    ok(&softtouch(
        d,
        &[
            "--db", "copy.db", "dataset", "export", "all", "--out", "second",
        ],
    ));
    // Into the same database under another name (runs 3 and 4 there).
    let out = ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "import", "first", "--name", "again",
        ],
    ));
    assert!(out.contains("run(s) 3,4"), "{out}");
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "export", "again", "--out", "third",
        ],
    ));
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "first", "--name", "again",
            ],
        ),
        2,
        "already exists",
    );

    for other in ["second", "third"] {
        assert_eq!(
            read(&d.join("first/labels.csv")),
            read(&d.join(other).join("labels.csv")),
            "{other}"
        );
        let names = |p: &Path| {
            let mut v: Vec<_> = std::fs::read_dir(p.join("images"))
                .unwrap_or_else(|e| panic!("{e}"))
                .map(|e| e.map(|e| e.file_name()).unwrap_or_default())
                .collect();
            v.sort();
            v
        };
        let first = names(&d.join("first"));
        assert_eq!(first.len(), 160);
        assert_eq!(first, names(&d.join(other)));
        for n in &first {
            assert_eq!(
                read(&d.join("first/images").join(n)),
                read(&d.join(other).join("images").join(n))
            );
        }
        let m: serde_json::Value =
            serde_json::from_slice(&read(&d.join(other).join("manifest.json")))
                .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            m["runs"][0]["imported"]["layout"], "softtouch-export",
            "{other}"
        );
        assert_eq!(m["dataset"]["definition"]["seed"], 3);
    }
    // Same stats on both sides.
    let a = ok(&softtouch(
        d,
        &["--db", "lab.db", "dataset", "stats", "all"],
    ));
    let b = ok(&softtouch(
        d,
        &["--db", "lab.db", "dataset", "stats", "again"],
    ));
    let body = |s: &str| {
        s.lines()
            .skip(1)
            .filter(|l| !l.starts_with("histograms"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&a), body(&b));
}

#[test]
fn a_damaged_export_imports_nothing() {
    let (dir, db) = lab();
    let d = dir.path();
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2",
        ],
    ));
    ok(&softtouch(
        d,
        &["--db", "lab.db", "dataset", "export", "all", "--out", "exp"],
    ));
    let runs_before = count_rows(&db, "runs");
    let samples_before = count_rows(&db, "samples");
    let copy = |name: &str| {
        let to = d.join(name);
        std::fs::create_dir_all(to.join("images")).unwrap_or_else(|e| panic!("{e}"));
        for entry in ["labels.csv", "manifest.json"] {
            write(&to.join(entry), read(&d.join("exp").join(entry)));
        }
        for e in std::fs::read_dir(d.join("exp/images")).unwrap_or_else(|e| panic!("{e}")) {
            let e = e.unwrap_or_else(|e| panic!("{e}"));
            write(&to.join("images").join(e.file_name()), read(&e.path()));
        }
        to
    };
    // A missing image: refused before anything is written.
    let c = copy("missing");
    std::fs::remove_file(c.join("images/000042.png")).unwrap_or_else(|e| panic!("{e}"));
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "missing", "--name", "m",
            ],
        ),
        2,
        "labels.csv: line 44, column 1: image `images/000042.png` is missing",
    );
    // A changed image, found inside the transaction half-way: rolled back.
    let c = copy("changed");
    write(&c.join("images/000150.png"), png(999, 32, 24));
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "changed", "--name", "c",
            ],
        ),
        2,
        "line 152, column 1: image `images/000150.png`: sha256 does not match",
    );
    // An edited labels.csv.
    let c = copy("edited");
    let text = String::from_utf8(read(&c.join("labels.csv"))).unwrap_or_default();
    write(
        &c.join("labels.csv"),
        text.replacen("circle-10", "circle-11", 1),
    );
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "edited", "--name", "e",
            ],
        ),
        2,
        "sha256 does not match the manifest",
    );
    // A manifest that is not JSON.
    let c = copy("bad-manifest");
    write(&c.join("manifest.json"), "{\n  \"format\": softtouch\n}\n");
    fails_with(
        &softtouch(
            d,
            &[
                "--db",
                "lab.db",
                "dataset",
                "import",
                "bad-manifest",
                "--name",
                "b",
            ],
        ),
        2,
        "manifest.json: line 2, column",
    );
    // Labels edited consistently with the manifest's checksum: the values are checked.
    for (case, edit, expected) in [
        (
            "nan",
            ",NaN,",
            "labels.csv: line 2, column 2: fx_n: `NaN` is not finite",
        ),
        (
            "word",
            ",abc,",
            "labels.csv: line 2, column 2: fx_n: `abc` is not a number",
        ),
        (
            "split",
            ",train,",
            "line 2, column 13: split: unknown split `train,x`",
        ),
    ] {
        let c = copy(case);
        let text = String::from_utf8(read(&c.join("labels.csv"))).unwrap_or_default();
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let fields: Vec<&str> = lines[1].split(',').collect();
        lines[1] = match case {
            "split" => lines[1].replacen(fields[12], "\"train,x\"", 1),
            _ => format!("{}{edit}{}", fields[0], fields[2..].join(",")),
        };
        let edited = lines.join("\n") + "\n";
        write(&c.join("labels.csv"), &edited);
        let manifest = String::from_utf8(read(&c.join("manifest.json"))).unwrap_or_default();
        write(
            &c.join("manifest.json"),
            manifest.replace(&sha256_hex(text.as_bytes()), &sha256_hex(edited.as_bytes())),
        );
        fails_with(
            &softtouch(
                d,
                &["--db", "lab.db", "dataset", "import", case, "--name", case],
            ),
            2,
            expected,
        );
    }
    // A manifest from a newer format.
    let c = copy("newer");
    let manifest = String::from_utf8(read(&c.join("manifest.json"))).unwrap_or_default();
    write(
        &c.join("manifest.json"),
        manifest.replace("\"format_version\": 1,", "\"format_version\": 99,"),
    );
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "newer", "--name", "n",
            ],
        ),
        2,
        "format version 99 is newer",
    );
    fails_with(
        &softtouch(d, &["--db", "lab.db", "dataset", "import", "nowhere"]),
        2,
        "is not a folder",
    );
    fails_with(
        &softtouch(d, &["--db", "lab.db", "dataset", "import", "."]),
        2,
        "holds neither",
    );
    assert_eq!(count_rows(&db, "runs"), runs_before);
    assert_eq!(count_rows(&db, "samples"), samples_before);
    assert_eq!(count_rows(&db, "datasets"), 1);
}

fn write_case_images(dir: &Path) {
    for i in 0..4 {
        write(&dir.join(format!("img{i}.png")), png(i, 8, 6));
    }
}

#[test]
fn the_papers_layout_imports_with_torque_in_nmm() {
    let dir = tempdir();
    let d = dir.path();
    let data = d.join("paper");
    std::fs::create_dir(&data).unwrap_or_else(|e| panic!("{e}"));
    write_case_images(&data);
    write(&data.join("img9.jpg"), jpeg(9, 8, 6));
    let mut csv = String::from("image,Fx,Fy,Fz,Tx,Ty,Tz\n");
    for i in 0..20 {
        let img = if i == 19 {
            "img9.jpg".to_owned()
        } else {
            format!("img{}.png", i % 4)
        };
        csv.push_str(&format!(
            "{img},{}.5,-1.25,-{i},{}.125,-250,0.001\n",
            i % 3,
            i * 10
        ));
    }
    write(&data.join("data_frame.csv"), &csv);
    let out = ok(&softtouch(
        d,
        &[
            "--db", "p.db", "dataset", "import", "paper", "--medium", "water", "--rod", "tube",
            "--seed", "4",
        ],
    ));
    assert!(
        out.contains("imported 20 samples (paper-csv) as run(s) 1 and dataset paper"),
        "{out}"
    );
    let m = members(&d.join("p.db"), "paper");
    let count = |s: &str| m.iter().filter(|r| r.3 == s).count();
    assert_eq!((count("train"), count("val"), count("test")), (14, 2, 4));

    ok(&softtouch(
        d,
        &["--db", "p.db", "dataset", "export", "paper", "--out", "exp"],
    ));
    let rows = labels(&d.join("exp"));
    assert_eq!(rows.len(), 21);
    assert_eq!(
        rows[3][1..7],
        ["2.5", "-1.25", "-2", "20.125", "-250", "0.001"]
    );
    assert_eq!(rows[3][10..12], ["tube", "water"]);
    assert_eq!(rows[3][13..15], ["1", "2"]);
    // The JPEG was re-encoded as PNG.
    let last = read(&d.join("exp").join(&rows[20][0]));
    assert!(image::load_from_memory_with_format(&last, image::ImageFormat::Png).is_ok());
    // Without a header row too.
    let headless = d.join("headless");
    std::fs::create_dir(&headless).unwrap_or_else(|e| panic!("{e}"));
    write_case_images(&headless);
    write(&headless.join("img9.jpg"), jpeg(9, 8, 6));
    write(
        &headless.join("data_frame.csv"),
        csv.lines().skip(1).collect::<Vec<_>>().join("\n"),
    );
    let out = ok(&softtouch(
        d,
        &["--db", "p.db", "dataset", "import", "headless"],
    ));
    assert!(out.contains("imported 20 samples"), "{out}");
}

#[test]
fn malformed_paper_files_are_refused_naming_line_and_column() {
    let cases = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/dataset_cases/paper");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&cases)
        .unwrap_or_else(|e| panic!("{}: {e}", cases.display()))
        .map(|e| e.map(|e| e.path()).unwrap_or_default())
        .collect();
    names.sort();
    assert!(names.len() >= 8, "{names:?}");
    let dir = tempdir();
    let d = dir.path();
    for case in names {
        let name = case
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let target = d.join(&name);
        std::fs::create_dir(&target).unwrap_or_else(|e| panic!("{e}"));
        write_case_images(&target);
        write(
            &target.join("data_frame.csv"),
            read(&case.join("data_frame.csv")),
        );
        let expected = String::from_utf8(read(&case.join("expected.txt"))).unwrap_or_default();
        let out = softtouch(d, &["--db", "cases.db", "dataset", "import", &name]);
        assert_eq!(out.status.code(), Some(2), "{name}: {}", text(&out.stderr));
        let err = text(&out.stderr);
        assert!(
            err.contains(expected.trim()),
            "{name}: expected `{}` in: {err}",
            expected.trim()
        );
    }
    assert_eq!(count_rows(&d.join("cases.db"), "samples"), 0);
    assert_eq!(count_rows(&d.join("cases.db"), "runs"), 0);
}

/// Imports check what would otherwise break the database later: a run's `created_at`
/// in a manifest must be a UTC timestamp (one bad value broke `runs` and `status` for
/// every run), and the paper's images, which carry no checksum, must decode in full
/// (a PNG cut short after an intact header was taken).
#[test]
fn imports_refuse_a_bad_created_at_and_a_truncated_paper_image() {
    let (dir, db) = lab();
    let d = dir.path();
    ok(&softtouch(
        d,
        &[
            "--db", "lab.db", "dataset", "create", "all", "--runs", "1,2",
        ],
    ));
    ok(&softtouch(
        d,
        &["--db", "lab.db", "dataset", "export", "all", "--out", "exp"],
    ));
    let runs_before = count_rows(&db, "runs");
    let manifest_path = d.join("exp/manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&read(&manifest_path)).unwrap_or_else(|e| panic!("{e}"));
    manifest["runs"][0]["created_at"] = serde_json::Value::from("yesterday");
    write(
        &manifest_path,
        serde_json::to_vec_pretty(&manifest).unwrap_or_default(),
    );
    fails_with(
        &softtouch(
            d,
            &[
                "--db", "lab.db", "dataset", "import", "exp", "--name", "again",
            ],
        ),
        2,
        "field `created_at`: `yesterday` is not a UTC timestamp YYYY-MM-DDTHH:MM:SS[.fff]Z",
    );
    assert_eq!(count_rows(&db, "runs"), runs_before);
    ok(&softtouch(d, &["--db", "lab.db", "runs"]));

    let paper = d.join("paper");
    std::fs::create_dir(&paper).unwrap_or_else(|e| panic!("{e}"));
    write_case_images(&paper);
    let whole = png(7, 64, 48);
    write(&paper.join("img3.png"), &whole[..whole.len() * 2 / 3]);
    let mut csv = String::from("image,Fx,Fy,Fz,Tx,Ty,Tz\n");
    for i in 0..20 {
        csv.push_str(&format!("img{}.png,1,2,3,4,5,6\n", i % 4));
    }
    write(&paper.join("data_frame.csv"), &csv);
    fails_with(
        &softtouch(d, &["--db", "lab.db", "dataset", "import", "paper"]),
        2,
        "image `img3.png` does not decode",
    );
    assert_eq!(count_rows(&db, "runs"), runs_before);
}
