//! Helpers shared by the end-to-end tests (each test file is its own crate and uses
//! its own subset of these).
#![allow(dead_code)]

pub(crate) mod hand_e_rig;

use softtouch_collector::store::DbTarget;
use std::path::{Path, PathBuf};
use std::process::Output;

/// Whether this run of the tests is against PostgreSQL (`SOFTTOUCH_TEST_POSTGRES`, see
/// TESTING.md): every database path a test names stands for a database of its own on
/// that server.
pub(crate) fn on_postgres() -> bool {
    softtouch_collector::testing::on_postgres()
}

/// The database the path `db` stands for: the file itself, or (on PostgreSQL) a
/// database of its own on the test server, created on first use.
pub(crate) fn target_of(db: &Path) -> DbTarget {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    if !on_postgres() {
        return DbTarget::File(db.to_owned());
    }
    static MADE: OnceLock<Mutex<HashMap<PathBuf, DbTarget>>> = OnceLock::new();
    let key = std::path::absolute(db).unwrap_or_else(|_| db.to_owned());
    let made = MADE.get_or_init(Mutex::default);
    let mut made = made
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    made.entry(key.clone())
        .or_insert_with(|| {
            let dir = key.parent().unwrap_or(Path::new(".")).to_owned();
            // Its own thread: a test inside a runtime may ask.
            std::thread::spawn(move || {
                softtouch_collector::testing::block_on(softtouch_collector::testing::fresh_target(
                    &dir,
                    "softtouch.db",
                ))
            })
            .join()
            .unwrap_or_else(|_| panic!("cannot create a test database"))
        })
        .clone()
}

/// Samples of run `run` in the database `db` stands for, read from outside while a
/// collector writes it (0 while there is no database or no schema yet; nothing is
/// created).
pub(crate) async fn samples_in(db: &Path, run: i64) -> i64 {
    use sqlx::Connection as _;
    match target_of(db) {
        DbTarget::File(path) => {
            let options = sqlx::sqlite::SqliteConnectOptions::new()
                .filename(path)
                .read_only(true);
            let Ok(mut conn) = sqlx::ConnectOptions::connect(&options).await else {
                return 0;
            };
            sqlx::query_scalar("SELECT COUNT(*) FROM samples WHERE run_id = ?")
                .bind(run)
                .fetch_one(&mut conn)
                .await
                .unwrap_or(0)
        }
        DbTarget::Postgres(url) => {
            let Ok(mut conn) = sqlx::PgConnection::connect(url.expose()).await else {
                return 0;
            };
            let n = sqlx::query_scalar("SELECT COUNT(*) FROM samples WHERE run_id = $1")
                .bind(run)
                .fetch_one(&mut conn)
                .await
                .unwrap_or(0);
            let _ = conn.close().await;
            n
        }
    }
}

/// Whether a test of the SQLite file itself (its path, its log, its write-ahead log)
/// is skipped: on PostgreSQL there is no file. Says so on stderr.
pub(crate) fn skip_on_postgres(test: &str) -> bool {
    let skip = on_postgres();
    if skip {
        eprintln!("{test}: about the SQLite file; not run against PostgreSQL");
    }
    skip
}

/// SQL that makes every sample insert from index `from` on fail as a full disk would
/// (the trigger `injected_full`), in the engine's own spelling; [`stop_failing`] undoes it.
pub(crate) fn fail_inserts_from(from: u32) -> String {
    if on_postgres() {
        format!(
            "CREATE FUNCTION injected_full() RETURNS trigger LANGUAGE plpgsql AS $$
             BEGIN
                 IF NEW.sample_index >= {from} THEN
                     RAISE EXCEPTION 'database or disk is full (injected)';
                 END IF;
                 RETURN NEW;
             END $$;
             CREATE TRIGGER injected_full BEFORE INSERT ON samples
                 FOR EACH ROW EXECUTE FUNCTION injected_full();"
        )
    } else {
        format!(
            "CREATE TRIGGER injected_full BEFORE INSERT ON samples
             WHEN NEW.sample_index >= {from} BEGIN SELECT RAISE(ABORT, 'database or disk is full (injected)'); END;"
        )
    }
}

/// Drops [`fail_inserts_from`]'s trigger.
pub(crate) fn stop_failing() -> &'static str {
    if on_postgres() {
        "DROP TRIGGER injected_full ON samples"
    } else {
        "DROP TRIGGER injected_full"
    }
}

/// The store `db` stands for ([`target_of`]), opened (and created) or the test fails.
pub(crate) async fn open_store(db: &Path) -> softtouch_collector::store::Store {
    softtouch_collector::store::Store::open(target_of(db))
        .await
        .unwrap_or_else(|e| panic!("{e}"))
}

/// `target_of` as `--db` takes it.
pub(crate) fn db_arg(db: &Path) -> String {
    match target_of(db) {
        DbTarget::File(path) => path.display().to_string(),
        DbTarget::Postgres(url) => url.expose().to_owned(),
    }
}

/// The `softtouch` binary to run in `dir`, its database `dir/softtouch.db` (or that
/// path's database on the PostgreSQL test server), no `SOFTTOUCH_DB` from outside.
pub(crate) fn command(dir: &Path) -> std::process::Command {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_softtouch"));
    command.current_dir(dir).env_remove("SOFTTOUCH_DB");
    if on_postgres() {
        command.env("SOFTTOUCH_DB", db_arg(&dir.join("softtouch.db")));
    }
    command
}

/// Run the `softtouch` binary in `dir` with `args` (see [`command`]); on PostgreSQL a
/// `--db PATH` stands for that path's database there.
pub(crate) fn softtouch(dir: &Path, args: &[&str]) -> Output {
    let mut args: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
    if on_postgres() {
        for i in 1..args.len() {
            if args[i - 1] == "--db" {
                args[i] = db_arg(&dir.join(&args[i]));
            }
        }
    }
    command(dir)
        .args(&args)
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
/// loops with. Its estimate must follow the contact well enough for the stiffness
/// calibration the grasp verbs start from to pass its check (`check_calibration`):
/// on 120 samples it rose only 1.6 N before the gripper's contact stop and was
/// refused; on 600 (5 s more to collect) it reads the grasp scene's objects within
/// the check (cylinder Λ_max 2.07 N/mm against the simulator's 1.99).
pub(crate) fn tiny_model(d: &Path) {
    simulated_dataset(d, "600", "5", "air");
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

/// Sends signal `name` (`TERM`, `HUP`, …) to `child` with `kill`, or the test fails.
pub(crate) fn signal(child: &std::process::Child, name: &str) {
    let ok = std::process::Command::new("kill")
        .args([&format!("-{name}"), &child.id().to_string()])
        .status()
        .unwrap_or_else(|e| panic!("kill: {e}"))
        .success();
    assert!(ok, "kill -{name} failed");
}
