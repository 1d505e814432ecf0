//! Every example the docs and the help texts show, run (`#[ignore]`d: about 14 minutes
//! on 2 cores). `docs.rs` checks that each parses; this runs each, in the order its page
//! or help text shows it, and checks that it exits 0 and writes the file its `--out`
//! names.
//!
//! - **Groups.** One group per `docs/` page and one per command's help (`dataset
//!   stats`, `grasp trials`, …). A group runs in a copy of a small lab: three runs
//!   (1 and 2 on land, 300 and 100 samples; 3 underwater, run 1's poses) and the rig
//!   and scene files the examples name. What a group's examples take for granted (a
//!   dataset, a model, a stored session) is made first, in [`ASSUMES`]; the README
//!   has its own walk (`docs::the_readme_runs_top_to_bottom`).
//! - **Sizes and places.** [`CHANGED`] lists every change made to an example before
//!   it runs (an overnight sample count cut to 300, a lab's absolute path, a
//!   placeholder), each with its reason.
//! - **Not run here.** [`NOT_RUN`] lists what needs something this machine lacks
//!   (PyTorch, fixed ports, a Hand-E on a serial port), each with where else it is
//!   tested. PostgreSQL's examples run when `SOFTTOUCH_TEST_POSTGRES` is set
//!   (`scripts/test-postgres.sh`), against a database of their own on that server,
//!   and are said to be skipped otherwise.
//!
//! A table entry that matches no example fails `the_walks_tables_match_the_docs` (in
//! the default tier; it runs nothing), so the tables cannot outlive the docs.
//!
//! `cargo test --release --test end_to_end -- --ignored docs_walk::`

use crate::common::text;
use crate::docs::{Step, doc_texts, fenced_steps, help_examples};
use clap::CommandFactory;
use softtouch_cli::Cli;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::Instant;

/// The rig and scene files the examples name, each written by the program itself
/// (`config show`); `lab.toml` gains the `[grasp]` section of docs/RIG.md.
const FILES: &[(&str, &str)] = &[
    ("rig.toml", "config show rig"),
    ("lab.toml", "config show rig"),
    ("lab-rig.toml", "config show rig"),
    ("rods.toml", "config show scene land"),
    ("water.toml", "config show scene water"),
    ("scenes/water.toml", "config show scene water"),
    ("scenes/grasp.toml", "config show scene grasp"),
    ("scenes/grasp-water.toml", "config show scene grasp-water"),
];

/// The lab every group but those in [`FROM_FILES_ONLY`] starts from.
const LAB_RUNS: &[&str] = &[
    "collect --samples 300 --seed 1",
    "collect --samples 100 --seed 2",
    "collect --scene scenes/water.toml --poses-from 1",
];
// (300 samples: a model trained on fewer may never feel the grasp objects, and
// `grasp calibrate` rightly refuses it.)

/// Groups that make their own runs from nothing (their examples number the runs).
const FROM_FILES_ONLY: &[&str] = &["transfer"];

const LAND_V1: &[&str] = &["dataset create land-v1 --runs 1,2"];
const LAND_V1_MODEL: &[&str] = &[
    "dataset create land-v1 --runs 1,2",
    "train --dataset land-v1",
];
const AIR_MODEL: &[&str] = &["dataset create air --runs 1", "train --dataset air"];
const LAND_AND_WATER: &[&str] = &[
    "dataset create land --runs 1",
    "dataset create water --runs 3",
    "train --dataset land",
];
/// Stored results 1 to 4, the fourth a `grasp follow`, and 12 grasp trials.
const RESULTS_STORED: &[&str] = &[
    "dataset create land-v1 --runs 1,2",
    "train --dataset land-v1",
    "grasp trials --model land-v1-svae --objects ball --trials 3 --accept-calibration",
    "latent land-v1-svae --dataset land-v1",
    "grasp disturb --model land-v1-svae",
    "grasp twist --model land-v1-svae",
    "grasp follow --model land-v1-svae",
];
/// Sessions 1 to 3 on the simulator, as the example's `--resume 3` names them. The
/// walk's model learned 400 samples, too few for the calibration check in water
/// (`--accept-calibration` runs past it; the setups here store sessions, not rates).
const SESSIONS_1_TO_3: &[&str] = &[
    "dataset create land-v1 --runs 1,2",
    "train --dataset land-v1",
    "grasp trials --model land-v1-svae --objects ball --trials 1 --accept-calibration",
    "grasp trials --model land-v1-svae --objects ball --trials 1 --accept-calibration",
    "grasp trials --model land-v1-svae --objects ball --trials 1 --accept-calibration",
];
const SWEEPS_STORED: &[&str] = &[
    "dataset create land-v1 --runs 1,2",
    "train --dataset land-v1",
    "sweep alpha --dataset land-v1 --alphas 1 --epochs 1 --out sweep-out",
    "sweep latent --dataset land-v1 --latents 8 --epochs 1 --out sweep-out",
    "bench collection --samples 10 --settle 0.1 --window 0.05 --out bench-out",
];

/// What a group's examples take for granted, made before they run.
const ASSUMES: &[(&str, &[&str])] = &[
    ("db copy", &["--db rig2.db db init"]),
    ("db new-identity", &["--db rig2-restored.db db init"]),
    ("runs", &["--db lab.db db init"]),
    ("dataset stats", LAND_V1),
    ("dataset export", LAND_V1),
    (
        // Exported from another database: the first example keeps the dataset's name.
        "dataset import",
        &[
            "--db other.db collect --samples 100 --seed 1",
            "--db other.db dataset create land-v1 --runs 1",
            "--db other.db dataset export land-v1 --out exports/land-v1",
            "--db other.db dataset export land-v1 --out paper-data",
        ],
    ),
    ("grasp follow", LAND_V1_MODEL),
    ("grasp twist", LAND_V1_MODEL),
    ("grasp calibrate", LAND_V1_MODEL),
    (
        "grasp disturb",
        &[
            "dataset create land-v1 --runs 1,2",
            "train --dataset land-v1",
            "dataset create water-v1 --runs 3",
            "train --dataset water-v1",
        ],
    ),
    ("grasp trials", SESSIONS_1_TO_3),
    ("live", AIR_MODEL),
    (
        "bench grasp",
        &[
            "dataset create air --runs 1",
            "train --dataset air",
            "train --dataset air --name air-small --width 8",
        ],
    ),
    ("bench model", &["dataset create air --runs 1"]),
    (
        "train",
        &[
            "dataset create air --runs 1",
            "dataset create land --runs 1",
            "dataset create water --runs 3",
            "train --dataset land",
        ],
    ),
    (
        "eval",
        &[
            "dataset create air --runs 1",
            "dataset create water --runs 3",
            "train --dataset air",
            "train --dataset air --name air-file --out model.stm",
        ],
    ),
    (
        "latent",
        &[
            "dataset create land --runs 1",
            "dataset create water --runs 3",
            "train --dataset land",
            "train --dataset land --latent 6 --name land-l6",
            "train --dataset land --latent 16 --name land-l16",
            "train --dataset land --latent 32 --name land-l32",
        ],
    ),
    ("sweep alpha", &["dataset create air --runs 1"]),
    ("sweep latent", &["dataset create air --runs 1"]),
    (
        // `--samples 0,300,3000` needs a train split of 3 000: a water run of 4 300.
        "sweep finetune",
        &[
            "collect --scene scenes/water.toml --samples 4300 --seed 3",
            "dataset create land --runs 1",
            "dataset create water --runs 4",
            "train --dataset land",
        ],
    ),
    ("report", SWEEPS_STORED),
    ("results", RESULTS_STORED),
    ("results show", RESULTS_STORED),
    ("results trace", RESULTS_STORED),
    ("docs/report.md", SWEEPS_STORED),
    ("docs/land-to-water.md", LAND_AND_WATER),
];

/// Changes made to an example before it runs: (what the example says, what runs, why).
const CHANGED: &[(&str, &str, &str)] = &[
    (
        "--samples 30000",
        "--samples 300",
        "the paper's overnight count: the same command at a hundredth",
    ),
    (
        "--samples 6000",
        "--samples 300",
        "a transfer study's count: the same command at a twentieth",
    ),
    (
        "--samples 5000",
        "--samples 300",
        "a rig's night: the same command at a sixtieth",
    ),
    (
        "/data/lab.db",
        "lab.db",
        "a lab's absolute path: a file in the group's folder",
    ),
    (
        "--model NAME",
        "--model land-v1-svae",
        "docs/RIG.md's placeholder: the group's model",
    ),
    (
        "trials --model land-svae ",
        "trials --model land-svae --accept-calibration ",
        "the group's model learned 300 samples, and the calibration check refuses its \
         closings (the estimate stops short of 3 N): the friction sweeps run past it",
    ),
    (
        "trials --model land-v1-svae --trials 10 --sigma-mm",
        "trials --model land-v1-svae --accept-calibration --trials 10 --sigma-mm",
        "the group's 400-sample model, refused in water by the calibration check",
    ),
    (
        "trials --model land-v1-svae --sweep-sigma",
        "trials --model land-v1-svae --accept-calibration --sweep-sigma",
        "the group's 400-sample model, refused in water by the calibration check",
    ),
];

/// Examples not run here: (pieces the example holds, all of them; why, and where it is
/// tested instead). A `\n` at a piece's end marks the example's end.
const NOT_RUN: &[(&[&str], &str)] = &[
    (
        &["sim netft"],
        "serves until stopped, on the Net F/T's fixed ports; the same server on port 0 \
         is tested in drivers/tests/netft.rs and tests/live.rs",
    ),
    (
        &["--torch "],
        "needs PyTorch; the peer's run is tested with a stand-in in tests/cli.rs",
    ),
    (
        &["config check --rig rig.toml\n"],
        "shows the error for a misspelt field; the message is tested by \
         schemas/tests/cases/rig",
    ),
    (
        &["grasp ", "--rig lab.toml"],
        "a rig grasp needs a Hand-E on a serial port (trials and twist also a Franka over \
         FCI); the same lab code runs against the Hand-E server on a pty pair in \
         tests/grasp_rig_trials.rs, and the Franka driver against franka-sim in \
         tests/franka_sim.rs",
    ),
];

/// The folder the walk's fixtures and groups live in, made empty once per run.
fn walk_root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("docs-walk");
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).unwrap_or_else(|e| panic!("{}: {e}", root.display()));
        root
    })
}

/// The program in `dir`, its database `dir/softtouch.db` unless an example says
/// otherwise; stdin answers every operator question with Enter.
fn run(dir: &Path, args: &[String], env: &[(String, String)]) -> (bool, String) {
    use std::io::Write;
    let mut child = Command::new(env!("CARGO_BIN_EXE_softtouch"))
        .current_dir(dir)
        .env_remove("SOFTTOUCH_DB")
        .envs(env.iter().map(|(k, v)| (k, v)))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run softtouch: {e}"));
    if let Some(mut stdin) = child.stdin.take() {
        // A closed pipe (the program did not read) is fine.
        let _ = stdin.write_all(&b"\n".repeat(4000));
    }
    let out = child
        .wait_with_output()
        .unwrap_or_else(|e| panic!("softtouch: {e}"));
    let said = format!("{}{}", text(&out.stdout), text(&out.stderr));
    (out.status.success(), said)
}

/// Runs a setup command that must succeed.
fn must(dir: &Path, line: &str) {
    let args: Vec<String> = line.split_whitespace().map(str::to_owned).collect();
    let (ok, said) = run(dir, &args, &[]);
    assert!(
        ok,
        "{}: setup `softtouch {line}` failed:\n{said}",
        dir.display()
    );
}

/// A fixture folder, made once: the files, and (with `runs`) the lab's three runs.
fn fixture(runs: bool) -> &'static Path {
    static FILES_ONLY: OnceLock<PathBuf> = OnceLock::new();
    static LAB: OnceLock<PathBuf> = OnceLock::new();
    let cell = if runs { &LAB } else { &FILES_ONLY };
    cell.get_or_init(|| {
        let dir = walk_root().join(if runs { "lab" } else { "files" });
        std::fs::create_dir_all(dir.join("scenes"))
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for (file, line) in FILES {
            let args: Vec<String> = line.split_whitespace().map(str::to_owned).collect();
            let (ok, mut said) = run(&dir, &args, &[]);
            assert!(ok, "`softtouch {line}`: {said}");
            if *file == "lab.toml" {
                said.push_str(&rig_grasp_section());
            }
            std::fs::write(dir.join(file), said).unwrap_or_else(|e| panic!("{file}: {e}"));
        }
        if runs {
            for line in LAB_RUNS {
                must(&dir, line);
            }
        }
        dir
    })
}

/// docs/RIG.md's `[grasp]` section (the fenced TOML block that starts with it), with a
/// second object, `ball`, as the examples name both.
fn rig_grasp_section() -> String {
    let rig = std::fs::read_to_string(crate::docs::root().join("docs/RIG.md"))
        .unwrap_or_else(|e| panic!("docs/RIG.md: {e}"));
    let start = rig
        .find("```toml\n[grasp]")
        .unwrap_or_else(|| panic!("docs/RIG.md shows a [grasp] section"));
    let body = &rig[start + "```toml\n".len()..];
    let block = &body[..body.find("```").unwrap_or(body.len())];
    let ball = block
        .split("[[grasp.objects]]")
        .nth(1)
        .unwrap_or_else(|| panic!("docs/RIG.md's [grasp] has an object"))
        .replace("\"bottle\"", "\"ball\"")
        .replace("0.10, 0.20]", "-0.10, 0.20]");
    format!("\n{block}\n[[grasp.objects]]{ball}")
}

/// Copies a folder's files (one level of subfolders deep is all the fixtures have).
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap_or_else(|e| panic!("{}: {e}", to.display()));
    for entry in std::fs::read_dir(from).unwrap_or_else(|e| panic!("{}: {e}", from.display())) {
        let path = entry.unwrap_or_else(|e| panic!("{e}")).path();
        let dest = to.join(path.file_name().unwrap_or_default());
        if path.is_dir() {
            copy_dir(&path, &dest);
        } else {
            std::fs::copy(&path, &dest).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
    }
}

/// One example as it will run.
struct Example {
    /// Where it is shown: `docs/grasping.md:41` or `grasp trials --help`.
    at: String,
    step: Step,
}

/// Applies [`CHANGED`] to an example's words; `used` counts each entry's uses.
fn changed(args: &[String], used: &mut [usize]) -> Vec<String> {
    let mut line = args.join(" ");
    for (k, (from, to, _)) in CHANGED.iter().enumerate() {
        if line.contains(from) {
            line = line.replace(from, to);
            used[k] += 1;
        }
    }
    line.split(' ').map(str::to_owned).collect()
}

/// Which [`NOT_RUN`] entry an example falls under (a `\n` in the entry marks the
/// example's end).
fn not_run(args: &[String]) -> Option<usize> {
    let line = format!("{}\n", args.join(" "));
    NOT_RUN
        .iter()
        .position(|(pieces, _)| pieces.iter().all(|piece| line.contains(piece)))
}

/// The PostgreSQL server the walk's PostgreSQL examples use, if any.
fn postgres_server() -> Option<String> {
    std::env::var("SOFTTOUCH_TEST_POSTGRES").ok()
}

/// A `postgres://…@db.lab/NAME` of an example, made the test server's: `…/postgres`
/// (a server to make databases on) is the server itself; any other a database of the
/// group's own, the same for every example of the group.
fn on_test_server(arg: &str, server: &str, group_db: &mut Option<String>, dir: &Path) -> String {
    let Some(rest) = arg.strip_prefix("postgres://") else {
        return arg.to_owned();
    };
    if rest.ends_with("/postgres") {
        return server.to_owned();
    }
    group_db
        .get_or_insert_with(|| crate::common::db_arg(&dir.join("walk.db")))
        .clone()
}

/// The folder a group starts from: the lab (or the files only) with the group's
/// [`ASSUMES`] made, built once for each distinct list and copied for each group.
fn start_of(group: &str) -> PathBuf {
    use std::collections::HashMap;
    use std::sync::Mutex;
    /// A start folder for each (from the lab's runs?, setup lines).
    type Starts = HashMap<(bool, Vec<&'static str>), PathBuf>;
    static BUILT: OnceLock<Mutex<Starts>> = OnceLock::new();
    let runs = !FROM_FILES_ONLY.contains(&group);
    let setup: Vec<&'static str> = ASSUMES
        .iter()
        .filter(|(g, _)| *g == group)
        .flat_map(|(_, lines)| lines.iter().copied())
        .collect();
    if setup.is_empty() {
        return fixture(runs).to_owned();
    }
    let built = BUILT.get_or_init(Mutex::default);
    let mut built = built
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let n = built.len();
    built
        .entry((runs, setup.clone()))
        .or_insert_with(|| {
            let dir = walk_root().join(format!("setup-{n}"));
            copy_dir(fixture(runs), &dir);
            let started = Instant::now();
            for line in &setup {
                must(&dir, line);
            }
            eprintln!("{group}: setup {} s", started.elapsed().as_secs());
            dir
        })
        .clone()
}

/// Runs one group's examples in a fresh copy of its start; returns what failed.
fn walk_group(group: &str, examples: &[Example]) -> Vec<String> {
    let started = Instant::now();
    let dir = walk_root()
        .join("groups")
        .join(group.replace([' ', '/', '.'], "-"));
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(&start_of(group), &dir);
    // Paths from the repository's root (docs/bench/…) as the docs write them.
    #[cfg(unix)]
    std::os::unix::fs::symlink(crate::docs::root().join("docs"), dir.join("docs"))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let server = postgres_server();
    let mut group_db = None;
    let mut env: Vec<(String, String)> = Vec::new();
    let mut wrong = Vec::new();
    for example in examples {
        let args = match &example.step {
            Step::Env(name, value) => {
                let value = match &server {
                    Some(server) => on_test_server(value, server, &mut group_db, &dir),
                    None => value.clone(),
                };
                env.push((name.clone(), value));
                continue;
            }
            // (What each table entry matched is counted by `stale_tables`.)
            Step::Run(args) => changed(&args[1..], &mut [0; CHANGED.len()]),
        };
        let shown = format!("{}: `softtouch {}`", example.at, args.join(" "));
        if let Some(k) = not_run(&args) {
            eprintln!("{shown}: not run here ({})", NOT_RUN[k].1);
            continue;
        }
        let wants_postgres = args.iter().any(|a| a.starts_with("postgres://"))
            || env.iter().any(|(_, v)| v.starts_with("postgres://"));
        let args: Vec<String> = match (&server, wants_postgres) {
            (None, true) => {
                eprintln!(
                    "{shown}: not run (no SOFTTOUCH_TEST_POSTGRES; scripts/test-postgres.sh runs it)"
                );
                continue;
            }
            (Some(server), true) => args
                .iter()
                .map(|a| on_test_server(a, server, &mut group_db, &dir))
                .collect(),
            _ => args,
        };
        let t0 = Instant::now();
        let (ok, said) = run(&dir, &args, &env);
        if !ok {
            wrong.push(format!("{shown} failed:\n{said}"));
            continue;
        }
        if let Some(out) = args
            .iter()
            .position(|a| a == "--out")
            .and_then(|i| args.get(i + 1))
            && !dir.join(out).exists()
        {
            wrong.push(format!("{shown}: wrote nothing at {out}:\n{said}"));
            continue;
        }
        eprintln!("{shown}: ok, {:.1} s", t0.elapsed().as_secs_f64());
    }
    eprintln!("{group}: {} s", started.elapsed().as_secs());
    let _ = std::fs::remove_dir_all(&dir);
    wrong
}

/// Runs every group, or those `SOFTTOUCH_WALK_ONLY` names (comma-separated).
fn walk(groups: &BTreeMap<String, Vec<Example>>) {
    let only: Option<Vec<String>> = std::env::var("SOFTTOUCH_WALK_ONLY")
        .ok()
        .map(|v| v.split(',').map(|g| g.trim().to_owned()).collect());
    let mut wrong = Vec::new();
    for (group, examples) in groups {
        if only.as_ref().is_some_and(|only| !only.contains(group)) {
            continue;
        }
        wrong.extend(walk_group(group, examples));
    }
    assert!(
        wrong.is_empty(),
        "{} examples failed:\n\n{}",
        wrong.len(),
        wrong.join("\n\n")
    );
}

/// The table entries ([`ASSUMES`], [`CHANGED`], [`NOT_RUN`]) that no group or example
/// matches any more. Read from the examples' words alone, as the walk reads them.
fn stale_tables(groups: &BTreeMap<String, Vec<Example>>) -> Vec<String> {
    let mut used = vec![0; CHANGED.len()];
    let mut skipped = vec![0; NOT_RUN.len()];
    for example in groups.values().flatten() {
        if let Step::Run(args) = &example.step
            && let Some(k) = not_run(&changed(&args[1..], &mut used))
        {
            skipped[k] += 1;
        }
    }
    let mut stale: Vec<String> = ASSUMES
        .iter()
        .filter(|(group, _)| !groups.contains_key(*group))
        .map(|(group, _)| format!("ASSUMES: no group `{group}`"))
        .collect();
    stale.extend(
        CHANGED
            .iter()
            .zip(&used)
            .filter(|(_, n)| **n == 0)
            .map(|((from, ..), _)| format!("CHANGED: no example holds `{from}`")),
    );
    stale.extend(
        NOT_RUN
            .iter()
            .zip(&skipped)
            .filter(|(_, n)| **n == 0)
            .map(|((pieces, _), _)| {
                format!("NOT_RUN: no example holds `{}`", pieces.join("…").trim())
            }),
    );
    stale
}

/// Fails, naming each, when [`stale_tables`] finds entries.
fn assert_tables_match(groups: &BTreeMap<String, Vec<Example>>) {
    let stale = stale_tables(groups);
    assert!(
        stale.is_empty(),
        "tables that outlived the docs (tests/docs_walk.rs):\n{}",
        stale.join("\n")
    );
}

/// The examples of every `docs/` page and every `--help`, grouped.
fn all_groups() -> BTreeMap<String, Vec<Example>> {
    let mut groups = page_groups();
    groups.extend(help_groups());
    groups
}

/// In the default tier: the walk's tables still match the docs (a group, an example
/// for each change and each example not run), so an example renamed or removed from
/// the docs takes its table entry with it. Nothing is run.
#[test]
fn the_walks_tables_match_the_docs() {
    let groups = all_groups();
    assert_tables_match(&groups);
    let examples: usize = groups.values().map(Vec::len).sum();
    assert!(examples >= 100, "only {examples} examples found");
    let mut with_stray = groups;
    with_stray.insert(
        "a group no table names".into(),
        vec![Example {
            at: "here".into(),
            step: Step::Run(vec!["softtouch".into(), "nope".into()]),
        }],
    );
    assert_eq!(stale_tables(&with_stray), Vec::<String>::new());
    with_stray.remove("sim netft");
    assert_eq!(
        stale_tables(&with_stray),
        ["NOT_RUN: no example holds `sim netft`"],
        "an entry whose example is gone is named"
    );
}

/// Every example of the `docs/` pages and of every `--help`, run.
#[test]
#[ignore = "every example of the docs and the help texts, about 14 minutes"]
fn every_example_in_the_docs_and_the_help_runs() {
    let groups = all_groups();
    assert_tables_match(&groups);
    walk(&groups);
}

/// `docs/` pages' groups, each page's fenced commands in order.
fn page_groups() -> BTreeMap<String, Vec<Example>> {
    let mut groups = BTreeMap::new();
    for (name, _, text) in doc_texts() {
        if !name.starts_with("docs/") {
            continue;
        }
        let steps: Vec<Example> = fenced_steps(&text)
            .into_iter()
            .map(|(line, step)| Example {
                at: format!("{name}:{line}"),
                step,
            })
            .collect();
        if steps.iter().any(|e| matches!(e.step, Step::Run(_))) {
            groups.insert(name, steps);
        }
    }
    groups
}

/// The help texts' groups, one per command with examples.
fn help_groups() -> BTreeMap<String, Vec<Example>> {
    let mut found = Vec::new();
    help_examples(&Cli::command(), "softtouch", &mut found);
    let mut groups: BTreeMap<String, Vec<Example>> = BTreeMap::new();
    for (path, args) in found {
        let group = path.trim_start_matches("softtouch").trim().to_owned();
        groups.entry(group.clone()).or_default().push(Example {
            at: format!("{path} --help"),
            step: Step::Run(args),
        });
    }
    groups
}
