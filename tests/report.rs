//! End-to-end tests of `softtouch report`: on a small simulated collection with a
//! dataset and two tiny models, the page parses as HTML5, has every section, shows the
//! database's numbers, escapes names and leaves the database untouched; an empty
//! database gives a page of verbs to run; bad options exit 2.

use crate::common;
use common::{TINY, fails_with, ok, runtime, simulated_dataset, softtouch, tempdir};

use scraper::{Html, Selector};
use sqlx::Row as _;
use sqlx::sqlite::{SqliteConnectOptions, SqlitePoolOptions};
use std::path::Path;

/// `samples` simulated samples, dataset `air` over them, and `models` tiny models.
fn lab(dir: &Path, samples: &str, models: &[&str]) {
    simulated_dataset(dir, samples, "4", "air");
    for kind in models {
        let mut args = vec!["train", "--dataset", "air", "--model", kind];
        args.extend(TINY);
        ok(&softtouch(dir, &args));
    }
}

/// The page, which must parse as HTML5 without a single parse error.
fn parse(path: &Path) -> (String, Html) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{e}"));
    let html = Html::parse_document(&text);
    assert!(
        html.errors.is_empty(),
        "HTML5 parse errors: {:?}",
        html.errors
    );
    (text, html)
}

fn select(html: &Html, css: &str) -> Vec<String> {
    let selector = Selector::parse(css).unwrap_or_else(|e| panic!("{css}: {e}"));
    html.select(&selector)
        .map(|e| e.text().collect::<String>().trim().to_owned())
        .collect()
}

/// The text of the element with `data-k="key"`.
fn value(html: &Html, key: &str) -> String {
    let found = select(html, &format!("[data-k=\"{key}\"]"));
    assert_eq!(found.len(), 1, "one element with data-k={key}: {found:?}");
    found[0].clone()
}

fn sha256_of(path: &Path) -> String {
    softtouch_collector::dataset::export::sha256_hex(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{e}")),
    )
}

/// Runs SQL against the database (read-write, for setting up cases).
fn sql(db: &Path, statement: &str) {
    runtime().block_on(async {
        let pool = SqlitePoolOptions::new()
            .connect_with(SqliteConnectOptions::new().filename(db))
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        sqlx::query(sqlx::AssertSqlSafe(statement.to_owned()))
            .execute(&pool)
            .await
            .unwrap_or_else(|e| panic!("{statement}: {e}"));
        pool.close().await;
    });
}

/// One row of integers.
fn ints(db: &Path, query: &str) -> Vec<i64> {
    runtime().block_on(async {
        let pool = SqlitePoolOptions::new()
            .connect_with(SqliteConnectOptions::new().filename(db).read_only(true))
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let row = sqlx::query(sqlx::AssertSqlSafe(query.to_owned()))
            .fetch_one(&pool)
            .await
            .unwrap_or_else(|e| panic!("{query}: {e}"));
        let out = (0..row.len()).map(|i| row.get::<i64, _>(i)).collect();
        pool.close().await;
        out
    })
}

const SWEEP_CSV: &str = "label,model,alpha,beta,latent,width,size_px,epochs,seconds_per_epoch,train_images_per_s,latency_ms,frame_latency_ms,image_mse,r2_mean,r2_fx,r2_fy,r2_fz,r2_tx,r2_ty,r2_tz
ConvNet,convnet,1,0.1,32,16,32,12,26.855,813.0,–,–,–,0.997958,0.998837,0.998474,0.996635,0.998842,0.998938,0.996021
SVAE α=1,svae,1,0.1,32,16,32,12,35.869,602.4,–,–,1.362125e-2,0.998041,0.998781,0.998420,0.996722,0.999016,0.998832,0.996476
VAE,vae,1,0.1,32,16,32,12,30.1,700.0,–,–,1.1e-3,–,–,–,–,–,–,–
";

const COLLECTION_CSV: &str =
    "settle_s,window_s,samples,accepted,force_rmse_n,torque_rmse_nmm,samples_per_hour,wall_s
0,0.005,40,40,0.1547,6.796,912.9,0.18
0.1,0.005,40,40,0.0547,2.796,812.9,0.18
0,0.02,40,40,0.1468,6.455,911.2,0.17
";

#[test]
fn the_page_parses_has_every_section_and_shows_the_databases_numbers() {
    let dir = tempdir();
    let d = dir.path();
    lab(d, "120", &["svae", "convnet"]);
    std::fs::write(d.join("sweep-alpha.csv"), SWEEP_CSV).unwrap_or_else(|e| panic!("{e}"));
    std::fs::write(d.join("collection.csv"), COLLECTION_CSV).unwrap_or_else(|e| panic!("{e}"));
    let db = d.join("softtouch.db");
    let before = sha256_of(&db);

    let said = ok(&softtouch(
        d,
        &[
            "report",
            "--out",
            "report.html",
            "--sweep",
            "sweep-alpha.csv",
            "--bench-collection",
            "collection.csv",
        ],
    ));
    assert!(said.contains("1 runs, 1 datasets, 2 models"), "{said}");
    // It reads and never writes.
    assert_eq!(sha256_of(&db), before, "the database changed");

    let (text, html) = parse(&d.join("report.html"));
    for id in [
        "summary",
        "runs",
        "datasets",
        "models",
        "sweeps",
        "land-to-water",
        "grasping",
        "figure-5",
    ] {
        assert_eq!(
            select(&html, &format!("section#{id} > h2")).len(),
            1,
            "section {id}"
        );
    }
    // Self-contained: no scripts, no external resources (images inline only).
    assert!(select(&html, "script, link, iframe").is_empty());
    assert!(
        text.matches("src=").count() == text.matches("src=\"data:image/png;base64,").count()
            && !text.contains("href=\"http")
    );
    assert!(select(&html, "svg").len() >= 12, "figures inline");

    // Runs: the counts as stored.
    let run = ints(
        &db,
        "SELECT SUM(status = 'ok'), SUM(status = 'rejected'), SUM(attempts - 1),
                (SELECT COUNT(*) FROM events WHERE run_id = 1), (SELECT seed FROM runs WHERE run_id = 1)
         FROM samples WHERE run_id = 1",
    );
    assert_eq!(value(&html, "run-1-ok"), run[0].to_string());
    assert_eq!(value(&html, "run-1-rejected"), run[1].to_string());
    assert_eq!(value(&html, "run-1-retried"), run[2].to_string());
    assert_eq!(value(&html, "run-1-events"), run[3].to_string());
    assert_eq!(value(&html, "run-1-seed"), "4");
    assert_eq!(run[4], 4);
    // Its pace, by one definition each (accepted samples per hour of run clock and of
    // wall clock), is what `status` prints.
    let status = ok(&softtouch(d, &["status"]));
    let said = format!(
        "ok samples/h: {} run clock (first frame to last), {} wall clock (start to last update)",
        value(&html, "run-1-rate"),
        value(&html, "run-1-wall-rate")
    );
    assert!(status.contains(&said), "`{said}` in:\n{status}");
    assert_ne!(value(&html, "run-1-rate"), "–");
    // The summary: the accepted samples, the best model's R² as stored.
    assert_eq!(value(&html, "summary-ok"), run[0].to_string());
    let best: f64 = runtime().block_on(async {
        let pool = SqlitePoolOptions::new()
            .connect_with(SqliteConnectOptions::new().filename(&db).read_only(true))
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let v = sqlx::query_scalar("SELECT MAX(test_r2_mean) FROM models")
            .fetch_one(&pool)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        pool.close().await;
        v
    });
    assert_eq!(value(&html, "summary-best-r2"), format!("{best:.4}"));
    // The hints for what is not stored name this database's model and dataset.
    let todo = select(&html, ".todo").join("\n");
    for hinted in [
        "softtouch grasp follow --model air-svae --targets",
        "softtouch transfer --model air-svae --land air --water water-v1",
        "softtouch collect --scene water --poses-from 1",
    ] {
        assert!(todo.contains(hinted), "`{hinted}` in: {todo}");
    }
    assert!(!todo.contains("land-v1"), "{todo}");
    // The paper's SVAE (Table 1, α = 1: 99.45 %) has one value wherever it is quoted.
    assert_eq!(value(&html, "summary-paper-r2"), "0.9945");
    assert_eq!(value(&html, "models-paper-r2"), "0.9945");

    // Datasets: the splits as stored.
    let splits = ints(
        &db,
        "SELECT SUM(split = 'train'), SUM(split = 'val'), SUM(split = 'test'), COUNT(*)
         FROM dataset_members WHERE dataset_id = 1",
    );
    assert_eq!(splits, [84, 12, 24, 120]);
    assert_eq!(value(&html, "dataset-1-train"), "84");
    assert_eq!(value(&html, "dataset-1-val"), "12");
    assert_eq!(value(&html, "dataset-1-test"), "24");
    assert_eq!(value(&html, "dataset-1-samples"), "120");

    // Models: test R² per axis as stored in metrics_json.
    runtime().block_on(async {
        let pool = SqlitePoolOptions::new()
            .connect_with(SqliteConnectOptions::new().filename(&db).read_only(true))
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let rows: Vec<(i64, String, String)> =
            sqlx::query_as("SELECT model_id, name, metrics_json FROM models ORDER BY model_id")
                .fetch_all(&pool)
                .await
                .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rows.len(), 2);
        for (id, name, metrics) in rows {
            assert_eq!(value(&html, &format!("model-{id}-name")), name);
            let m: serde_json::Value =
                serde_json::from_str(&metrics).unwrap_or_else(|e| panic!("{e}"));
            let mean = m["test"]["r2_mean"].as_f64().unwrap_or(f64::NAN);
            assert_eq!(
                value(&html, &format!("model-{id}-r2")),
                format!("{mean:.4}")
            );
            for (i, axis) in ["fx", "fy", "fz", "tx", "ty", "tz"].iter().enumerate() {
                let r2 = m["test"]["r2"][i]["r2"].as_f64().unwrap_or(f64::NAN);
                assert_eq!(
                    value(&html, &format!("model-{id}-r2-{axis}")),
                    format!("{r2:.4}")
                );
            }
            // Figure 2c: each range's n as stored: above its bar, or under the range
            // where fewer than 2 labels leave no bar.
            for range in m["test"]["force_error_by_range"]
                .as_array()
                .unwrap_or_else(|| panic!("force ranges in {metrics}"))
            {
                let n = range["count"].as_u64().unwrap_or(0);
                assert!(
                    text.contains(&format!("n={n}\n")),
                    "n={n} on model {id}'s force spread"
                );
            }
            // Figure 2b: every one of the 24 test samples (fewer than the default cap).
            let scatter = value(&html, &format!("model-{id}-scatter"));
            assert!(
                scatter.starts_with("24 of the 24 test samples"),
                "{scatter}"
            );
        }
        pool.close().await;
    });

    // Sweeps: Table 1 beside the paper; the collection benchmark's figures.
    assert_eq!(value(&html, "sweep-alpha-1-r2"), "99.80");
    assert_eq!(value(&html, "sweep-alpha-1-mse"), "1.36e-2");
    assert!(text.contains("99.45"), "the paper's α = 1 row beside");
    assert!(text.contains("Force label error against speed"));
    // Units on the axes.
    for label in [
        "true Fx, N",
        "predicted Tz, N·mm",
        "force RMSE, N",
        "Tx, N·mm",
    ] {
        assert!(text.contains(label), "axis label `{label}`");
    }

    // A smaller page: one model, no scatter.
    ok(&softtouch(
        d,
        &[
            "report",
            "--out",
            "one.html",
            "--runs",
            "1",
            "--models",
            "air-convnet",
            "--scatter-points",
            "0",
        ],
    ));
    let (_, one) = parse(&d.join("one.html"));
    assert_eq!(
        select(&one, "[data-k$=\"-name\"]").len(),
        2,
        "one dataset and one model"
    );
    assert!(select(&one, "[data-k$=\"-scatter\"]").is_empty());
    assert_eq!(sha256_of(&db), before, "the database changed");
}

#[test]
fn names_with_markup_characters_are_escaped() {
    let dir = tempdir();
    let d = dir.path();
    lab(d, "60", &["svae"]);
    let db = d.join("softtouch.db");
    let nasty = r#"<b>A&B "q" 'r'</b>"#;
    let quoted = nasty.replace('\'', "''");
    sql(&db, &format!("UPDATE runs SET scene_name = '{quoted}'"));
    sql(&db, &format!("UPDATE datasets SET name = 'd{quoted}'"));
    sql(
        &db,
        &format!("UPDATE models SET name = 'm{quoted}', dataset_name = 'd{quoted}'"),
    );
    ok(&softtouch(d, &["report", "--out", "r.html"]));
    let (text, html) = parse(&d.join("r.html"));
    assert!(select(&html, "b").is_empty(), "no element came from a name");
    assert_eq!(value(&html, "run-1-scene"), nasty);
    assert_eq!(value(&html, "dataset-1-name"), format!("d{nasty}"));
    assert_eq!(value(&html, "model-1-name"), format!("m{nasty}"));
    assert!(text.contains("&lt;b&gt;A&amp;B"));
    assert!(!text.contains(nasty));

    // A damaged artifact costs the model its figure, not the page.
    sql(&db, "UPDATE models SET artifact = zeroblob(64)");
    ok(&softtouch(d, &["report", "--out", "r.html"]));
    let (_, html) = parse(&d.join("r.html"));
    let todo = select(&html, "#models .todo").join("\n");
    assert!(todo.contains("cannot load its artifact"), "{todo}");
    assert_eq!(value(&html, "model-1-name"), format!("m{nasty}"));
}

#[test]
fn stored_sweeps_show_without_their_csv_and_a_bad_stored_table_costs_only_its_part() {
    let dir = tempdir();
    let d = dir.path();
    ok(&softtouch(d, &["db", "init"]));
    let db = d.join("softtouch.db");
    runtime().block_on(async {
        let store = softtouch_store::Store::open(&db)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        for (verb, csv) in [
            ("sweep alpha", SWEEP_CSV.to_owned()),
            ("sweep latent", "label,model\nx,svae\n".to_owned()),
        ] {
            store
                .insert_result(&softtouch_store::NewResult {
                    verb: verb.into(),
                    settings_json: "{}".into(),
                    dataset: Some("air".into()),
                    summary: "s".into(),
                    tables: vec![(format!("{}.csv", verb.replace(' ', "-")), csv)],
                    ..softtouch_store::NewResult::default()
                })
                .await
                .unwrap_or_else(|e| panic!("{e}"));
        }
        store.close().await;
    });
    // An older α sweep as a CSV beside the stored one (its SVAE row at 99.10 %).
    std::fs::write(
        d.join("old-alpha.csv"),
        SWEEP_CSV.replace("0.998041,0.998781", "0.991000,0.998781"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    ok(&softtouch(
        d,
        &["report", "--out", "s.html", "--sweep", "old-alpha.csv"],
    ));
    let (_, html) = parse(&d.join("s.html"));
    assert_eq!(value(&html, "sweep-alpha-1-r2"), "99.80");
    assert_eq!(value(&html, "sweep-alpha-1-mse"), "1.36e-2");
    // The stored sweep first, then the file, each titled by where it came from, each
    // number under its own key.
    let titles = select(&html, "#sweeps h3");
    let alpha: Vec<&String> = titles.iter().filter(|t| t.contains("α sweep")).collect();
    assert_eq!(alpha.len(), 2, "{titles:?}");
    assert!(
        alpha[0].contains("result 1 (sweep-alpha.csv)") && alpha[1].contains("old-alpha.csv"),
        "{titles:?}"
    );
    assert_eq!(value(&html, "sweep2-alpha-1-r2"), "99.10");
    let sweeps = select(&html, "#sweeps").join("\n");
    assert!(
        sweeps.contains("result 1 (sweep-alpha.csv)")
            && sweeps.contains("Could not read: result 2 (sweep-latent.csv):1: no column `alpha`"),
        "{sweeps}"
    );
    let summary = select(&html, "#summary").join("\n");
    assert!(
        summary.contains("sweep alpha ×1, sweep latent ×1"),
        "{summary}"
    );
}

#[test]
fn an_empty_database_gives_a_page_saying_which_verbs_to_run() {
    let dir = tempdir();
    let d = dir.path();
    ok(&softtouch(d, &["db", "init"]));
    let said = ok(&softtouch(d, &["report", "--out", "empty.html"]));
    assert!(said.contains("0 runs, 0 datasets, 0 models"), "{said}");
    // The .db alone remains (a read-only reader's empty log and shared memory gone).
    for left in ["softtouch.db-wal", "softtouch.db-shm"] {
        assert!(!d.join(left).exists(), "{left} left behind by report");
    }
    let (_, html) = parse(&d.join("empty.html"));
    let todo = select(&html, ".todo").join("\n");
    for verb in [
        "softtouch collect",
        "softtouch dataset create",
        "softtouch train",
        "softtouch sweep alpha",
        "softtouch sweep latent",
        "softtouch bench collection",
        "softtouch collect --scene water --poses-from",
        "softtouch transfer",
        "softtouch sweep finetune --init",
        "softtouch latent",
        "softtouch grasp trials",
        "softtouch bench grasp",
    ] {
        assert!(todo.contains(verb), "`{verb}` in: {todo}");
    }
    // The sections with nothing stored say so, and what to run.
    for said in [
        "No grasp sessions in this database yet",
        "No force following stored",
        "softtouch grasp follow --model",
        "softtouch grasp disturb --model",
        "softtouch grasp twist --model",
        "No land-to-water comparison stored",
        "No fine-tuning curve stored",
        "No latent maps stored",
    ] {
        assert!(todo.contains(said), "`{said}` in: {todo}");
    }
    let summary = select(&html, "#summary").join("\n");
    // With nothing stored, the hints name what the first verbs would make.
    assert!(
        todo.contains("softtouch grasp follow --model land-v1-svae"),
        "{todo}"
    );
    assert!(todo.contains("--land land-v1 --water water-v1"), "{todo}");
    assert!(
        summary.contains("Collected: 0 accepted samples in 0 run(s)")
            && summary.contains("No model that reads force yet")
            && summary.contains("No grasp trials yet")
            && summary.contains("Stored results: none yet"),
        "{summary}"
    );
}

/// A 2×2 PNG.
fn tiny_png() -> Vec<u8> {
    let mut png = Vec::new();
    image::RgbImage::from_pixel(2, 2, image::Rgb([200, 100, 0]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap_or_else(|e| panic!("{e}"));
    png
}

/// A stored grasp session: 2 trials a mode of the cylinder on land (open: both held;
/// closed: a slip and a timeout) and one refused, each with a short trace.
async fn grasp_session(db: &Path) -> i64 {
    use softtouch_lab::grasp::trials::{TrialPlan, load_scenes};
    use softtouch_store::{GraspTrace, GraspTrialKey, GraspTrialRow, Store};
    let store = Store::open(db).await.unwrap_or_else(|e| panic!("{e}"));
    let plan = TrialPlan {
        objects: vec!["cylinder".into()],
        trials: 2,
        ..TrialPlan::default()
    };
    let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
    let id = store
        .create_grasp_session(
            "m",
            "0123456789abcdef",
            7,
            &serde_json::to_string(&scenes).unwrap_or_else(|e| panic!("{e}")),
            &serde_json::to_string(&plan).unwrap_or_else(|e| panic!("{e}")),
        )
        .await
        .unwrap_or_else(|e| panic!("{e}"));
    for (mode, trial, reason) in [
        ("open", 0, None),
        ("open", 1, None),
        ("closed", 0, Some("slip")),
        ("closed", 1, Some("timeout")),
        ("closed", 2, Some("refused")),
    ] {
        let row = GraspTrialRow {
            key: GraspTrialKey {
                sigma_index: 0,
                scene_index: 0,
                object: "cylinder".into(),
                mode: mode.into(),
                trial,
            },
            medium: "land".into(),
            sigma_m: 0.005,
            offset_m: [0.001, 0.0, 0.0],
            commanded_width_m: 0.022,
            final_width_m: 0.022,
            peak_estimate_n: Some(1.4),
            // The refused trial's 9 N would show if it were counted.
            peak_true_n: Some(if reason == Some("refused") {
                9.0
            } else {
                1.5 + 0.25 * f64::from(trial)
            }),
            past_touch_mm: Some(0.5),
            success: reason.is_none(),
            reason: reason.map(str::to_owned),
            detail: None,
            // The slip confirmed its force first (and then lost the object).
            confirmed_after_s: (reason == Some("slip")).then_some(0.9),
            wall_s: 0.25,
        };
        let n = if reason == Some("refused") { 0 } else { 40 };
        let trace = GraspTrace {
            t_s: (0..n).map(|i| i as f32 / 30.0).collect(),
            estimate_n: (0..n).map(|i| (i as f32 / 20.0).min(1.5)).collect(),
            true_n: (0..n).map(|i| (i as f32 / 19.0).min(1.6)).collect(),
            measured_count: (0..n).map(|i| 100 + i as u8).collect(),
            request_count: (0..n).map(|i| 101 + i as u8).collect(),
            // The held open trials' frames at contact and end: a 2×2 PNG each.
            frames: match reason {
                None => ["contact", "end"]
                    .iter()
                    .enumerate()
                    .map(|(i, m)| softtouch_store::TraceFrame {
                        moment: (*m).into(),
                        t_s: i as f64,
                        png: tiny_png(),
                    })
                    .collect(),
                Some("slip") => vec![softtouch_store::TraceFrame {
                    moment: "confirmed".into(),
                    t_s: 0.9,
                    png: tiny_png(),
                }],
                Some(_) => Vec::new(),
            },
        };
        store
            .append_grasp_trial(id, &row, &trace)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
    }
    store.close().await;
    id
}

#[test]
fn the_grasping_section_shows_each_stored_session_and_draws_chosen_trials() {
    let dir = tempdir();
    let d = dir.path();
    ok(&softtouch(d, &["db", "init"]));
    let db = d.join("softtouch.db");
    let id = runtime().block_on(grasp_session(&db));
    ok(&softtouch(d, &["report", "--out", "g.html"]));
    let (text, html) = parse(&d.join("g.html"));
    // The table `grasp trials` prints, from the database's rows.
    assert_eq!(value(&html, &format!("grasp-{id}-stored")), "5");
    assert_eq!(
        value(&html, &format!("grasp-{id}-0-0-cylinder-open")),
        "2/2"
    );
    assert_eq!(
        value(&html, &format!("grasp-{id}-0-0-cylinder-closed")),
        "0/2",
        "the refused trial counts in no cell"
    );
    assert_eq!(value(&html, &format!("grasp-{id}-0-0-all-closed")), "0/2");
    // The grip at its firmest: the largest true force of the counted trials.
    assert_eq!(
        value(&html, &format!("grasp-{id}-0-0-cylinder-closed-grip")),
        "1.75 N"
    );
    assert_eq!(value(&html, &format!("grasp-{id}-0-1-all-open-grip")), "–");
    // Open held both, closed held neither: 2 discordant pairs one way, p = 2 · 2⁻² = 0.5
    // (the refused closed trial 2 pairs with nothing).
    assert_eq!(value(&html, &format!("grasp-{id}-0-0-mcnemar")), "0.5000");
    assert_eq!(
        value(&html, &format!("grasp-{id}-0-1-all-open")),
        "0/0",
        "the water scene ran nothing"
    );
    let counted = ints(
        &db,
        "SELECT COUNT(*) FROM grasp_trials WHERE mode = 'open' AND success = 1",
    );
    assert_eq!(counted, vec![2]);
    let section = select(&html, "section#grasping").join("\n");
    for said in [
        "Session 1: simulator",
        "refused 1, slip 1, timeout 1",
        "still between the fingers after the lift and the hold",
        "Wilson 95 %",
        "44 %",
        "100 %",
    ] {
        assert!(section.contains(said), "`{said}` in: {section}");
    }
    // The viewer: one success (open, land) and the first slip and timeout, two
    // figures each; the refused trial has no trace and is not drawn.
    // Plus the success per object with its intervals (one σ: no σ figure).
    assert_eq!(select(&html, "section#grasping svg").len(), 7, "{section}");
    assert!(
        text.contains("F_ref ± δ"),
        "the closed loop's band is drawn"
    );
    // The success drawn has its frames, inline, with their moments.
    let srcs: Vec<String> = {
        let sel = Selector::parse("section#grasping img").unwrap_or_else(|e| panic!("{e}"));
        html.select(&sel)
            .filter_map(|e| e.value().attr("src").map(str::to_owned))
            .collect()
    };
    assert_eq!(srcs.len(), 3, "{srcs:?}");
    assert!(
        srcs.iter()
            .all(|s| s.starts_with("data:image/png;base64,iVBORw0KGgo"))
    );
    let captions = select(&html, "section#grasping figcaption");
    assert_eq!(
        captions,
        ["contact, 0.00 s", "end, 1.00 s", "confirmed, 0.90 s"]
    );
    // A trial's confirmation time is one number: its stored value (the rows CSV's
    // `confirmed_after_s`) is the viewer's position title, the force chart's marker
    // and the confirmed frame's caption.
    let viewers = select(&html, "section#grasping div.trial");
    let slip = viewers
        .iter()
        .find(|v| v.contains("cylinder closed #0"))
        .unwrap_or_else(|| panic!("the slip is drawn: {viewers:?}"));
    for said in [
        "confirmed after 0.90 s",
        "confirmed (0.90 s)",
        "confirmed, 0.90 s",
    ] {
        assert!(slip.contains(said), "`{said}` in: {slip}");
    }
    // The estimate is drawn as its mean over 0.1 s with its range, never raw.
    assert!(slip.contains("estimate, mean over 0.1 s") && slip.contains("estimate, its range"));
}

#[test]
fn bad_input_exits_2_naming_what_is_wrong() {
    let dir = tempdir();
    let d = dir.path();
    fails_with(
        &softtouch(d, &["report", "--out", "r.html"]),
        2,
        "no database at",
    );
    ok(&softtouch(d, &["db", "init"]));
    fails_with(
        &softtouch(d, &["report", "--out", "r.html", "--runs", "9"]),
        2,
        "no run 9",
    );
    fails_with(
        &softtouch(d, &["report", "--out", "r.html", "--models", "nope"]),
        2,
        "no model named `nope`",
    );
    fails_with(
        &softtouch(d, &["report", "--out", "r.html", "--sweep", "missing.csv"]),
        2,
        "cannot read missing.csv",
    );
    std::fs::write(d.join("bad.csv"), "settle_s,window_s\n0,1\n").unwrap_or_else(|e| panic!("{e}"));
    fails_with(
        &softtouch(
            d,
            &["report", "--out", "r.html", "--bench-collection", "bad.csv"],
        ),
        2,
        "bad.csv:1: no column `samples`",
    );
    fails_with(
        &softtouch(d, &["report", "--out", "softtouch.db"]),
        2,
        "is the database itself",
    );
    assert!(!d.join("r.html").exists(), "nothing written on bad input");
    // A folder is no database: bad input, named as such.
    std::fs::create_dir(d.join("lab")).unwrap_or_else(|e| panic!("{e}"));
    fails_with(
        &softtouch(d, &["--db", "lab", "report", "--out", "r.html"]),
        2,
        "lab is a folder, not a database file",
    );
    // An empty file is no database: named as such, and left empty.
    std::fs::write(d.join("other.db"), b"").unwrap_or_else(|e| panic!("{e}"));
    fails_with(
        &softtouch(d, &["--db", "other.db", "report", "--out", "r.html"]),
        2,
        "other.db is an empty file, not a database",
    );
    assert_eq!(
        std::fs::metadata(d.join("other.db"))
            .map(|m| m.len())
            .unwrap_or(1),
        0
    );
    // A SQLite database that is not a softtouch one (or older than this build):
    // refused, not migrated.
    let foreign = d.join("foreign.db");
    runtime().block_on(async {
        let options = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(&foreign)
            .create_if_missing(true);
        let mut conn = sqlx::ConnectOptions::connect(&options)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        sqlx::query("CREATE TABLE notes (text TEXT)")
            .execute(&mut conn)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        sqlx::Connection::close(conn).await.ok();
    });
    let before = std::fs::read(&foreign).unwrap_or_default();
    fails_with(
        &softtouch(d, &["--db", "foreign.db", "report", "--out", "r.html"]),
        2,
        "is at schema 0",
    );
    assert_eq!(std::fs::read(&foreign).unwrap_or_default(), before);
}
