//! Helpers shared by the end-to-end tests (each test file is its own crate and uses
//! its own subset of these).
#![allow(dead_code)]

use std::path::Path;
use std::process::Output;

/// Run the `softtouch` binary in `dir` with `args`, with no `SOFTTOUCH_DB` from the
/// environment.
pub(crate) fn softtouch(dir: &Path, args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_softtouch"))
        .args(args)
        .current_dir(dir)
        .env_remove("SOFTTOUCH_DB")
        .output()
        .unwrap_or_else(|e| panic!("cannot run softtouch: {e}"))
}

/// Output bytes as text.
pub(crate) fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

pub(crate) use softtouch_collector::testing::tempdir;

/// A current-thread tokio runtime for store checks.
pub(crate) fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The stdout of a command that must succeed (its output is shown if it does not).
pub(crate) fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}",
        out.status.code(),
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// Asserts a command exited with `code` and said `needle` on stderr.
pub(crate) fn fails_with(out: &Output, code: i32, needle: &str) {
    let err = text(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(code),
        "stderr: {err}\nstdout: {}",
        text(&out.stdout)
    );
    assert!(err.contains(needle), "expected `{needle}` in: {err}");
}

/// A database in `dir` with `samples` simulated samples (seed `seed`, run 1) and a
/// dataset `name` over them: what the training, grasp and report tests start from.
pub(crate) fn simulated_dataset(dir: &Path, samples: &str, seed: &str, name: &str) {
    ok(&softtouch(dir, &["db", "init"]));
    ok(&softtouch(
        dir,
        &["collect", "--samples", samples, "--seed", seed],
    ));
    ok(&softtouch(dir, &["dataset", "create", name, "--runs", "1"]));
}

/// The settings of a tiny model (16×16, width 4, latent 8, 2 epochs, batch 32, no
/// early stopping): quick to train, enough to close loops and fill reports with.
pub(crate) const TINY: [&str; 12] = [
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
];

/// [`simulated_dataset`] (120 samples, dataset `air`) with a tiny model `air-svae`
/// ([`TINY`], but 30 epochs) trained on it: what the grasp and live tests close their
/// loops with. Its estimate must rise with the contact, or the stiffness calibration
/// the grasp verbs start from finds no touch (2 epochs do not: a flat estimate); 30
/// take well under a second and see it, at about a third of the true Λ_max.
pub(crate) fn tiny_model(d: &Path) {
    simulated_dataset(d, "120", "5", "air");
    let mut args = vec!["train", "--dataset", "air"];
    args.extend(TINY);
    if let Some(i) = args.iter().position(|a| *a == "--epochs") {
        args[i + 1] = "30";
    }
    ok(&softtouch(d, &args));
}

/// `softtouch report --out r.html` in `d`, the page parsed (it must parse as HTML5
/// without an error).
pub(crate) fn report_page(d: &Path) -> scraper::Html {
    ok(&softtouch(d, &["report", "--out", "r.html"]));
    let page = std::fs::read_to_string(d.join("r.html")).unwrap_or_else(|e| panic!("{e}"));
    let html = scraper::Html::parse_document(&page);
    assert!(html.errors.is_empty(), "{:?}", html.errors);
    html
}

/// The text of the one element with `data-k="key"`.
pub(crate) fn data_k(html: &scraper::Html, key: &str) -> String {
    let sel =
        scraper::Selector::parse(&format!("[data-k=\"{key}\"]")).unwrap_or_else(|e| panic!("{e}"));
    let found: Vec<String> = html
        .select(&sel)
        .map(|e| e.text().collect::<String>().trim().to_owned())
        .collect();
    assert_eq!(found.len(), 1, "one element with data-k={key}: {found:?}");
    found[0].clone()
}
