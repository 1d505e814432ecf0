//! The `softtouch` binary: parse arguments, set up logging, run, map the outcome to
//! an exit code (0 ok, 1 runtime failure, 2 bad input).
//!
//! Logging: warnings and errors go to stderr. The long jobs (`collect`, `train`,
//! `sweep`) also append everything from level info up — every run event, the start
//! and the outcome — to a log file beside the database (`softtouch.db.log` for
//! `softtouch.db`), written by tracing-appender's worker thread so that a slow disk
//! never stalls the job. `RUST_LOG` overrides both filters.

use clap::Parser as _;
use softtouch_cli::{self as cli, Cli, Command};
use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use tracing_subscriber::filter::{FilterExt as _, filter_fn};
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use tracing_subscriber::{EnvFilter, Layer as _};

/// mimalloc rather than glibc's allocator. Training allocates and frees tensors of
/// hundreds of kB every operation; glibc hands each such block to the kernel and back
/// (mmap/munmap: page faults, zeroing, TLB shootdowns across both cores), which took
/// a quarter of a training step. mimalloc keeps freed pages for reuse: `softtouch
/// bench train` at 32×32/16 went from about 1600 to 2200 images/s (see the trainer's
/// README for the table).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// sqlx warns of "slow statements" when a streamed query (a dataset's frames, read
/// while they are preprocessed) stays open for over a second: expected, not a fault,
/// so its statement log is off unless `RUST_LOG` asks.
const STDERR_FILTER: &str = "warn,sqlx::query=error,softtouch::event=off";
const FILE_FILTER: &str = "info,sqlx::query=error";

/// The log file of a database: its path with `.log` appended; for a PostgreSQL
/// server, `softtouch.log` in the working folder (each rig keeps its own).
fn log_path(db: &softtouch_store::DbTarget) -> PathBuf {
    let Some(path) = db.file() else {
        return PathBuf::from("softtouch.log");
    };
    let mut p = OsString::from(path.as_os_str());
    p.push(".log");
    PathBuf::from(p)
}

/// Whether this invocation writes the log file: the long jobs, and only where their
/// database is or will be (a resume of a missing database leaves no stray log).
fn wants_log_file(cli: &Cli) -> bool {
    let parent_exists = cli
        .db
        .file()
        .and_then(std::path::Path::parent)
        .is_none_or(|d| d.as_os_str().is_empty() || d.is_dir());
    match &cli.command {
        Command::Collect(args) if args.resume.is_some() => {
            cli.db.file().is_none_or(std::path::Path::is_file)
        }
        Command::Collect(_) | Command::Train(_) | Command::Sweep(_) => parent_exists,
        _ => false,
    }
}

fn filter(default: &str) -> EnvFilter {
    EnvFilter::try_from_default_env().unwrap_or_else(|_| default.into())
}

/// Whether an event may be written anywhere: not the PostgreSQL driver's option
/// parser's events that carry what the user wrote (an unrecognised URL option's value,
/// a malformed password-file line: either may be a password), whatever `RUST_LOG` asks.
fn shows_no_secret(meta: &tracing::Metadata<'_>) -> bool {
    !(meta.target().starts_with("sqlx_postgres::options")
        && (meta.fields().field("value").is_some() || meta.fields().field("line").is_some()))
}

/// Install the subscribers; the guard flushes the log file when dropped.
fn init_logging(cli: &Cli) -> Option<tracing_appender::non_blocking::WorkerGuard> {
    // Colour only for a person at a terminal, never into a file or a pipe.
    let stderr = tracing_subscriber::fmt::layer()
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .with_filter(filter(STDERR_FILTER).and(filter_fn(shows_no_secret)));
    let path = log_path(&cli.db);
    let file = if wants_log_file(cli) {
        match std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
        {
            Ok(f) => Some(f),
            Err(e) => {
                eprintln!(
                    "warning: cannot open the log file {}: {e}; logging to stderr only",
                    path.display()
                );
                None
            }
        }
    } else {
        None
    };
    let (file_layer, guard) = match file {
        Some(f) => {
            let (writer, guard) = tracing_appender::non_blocking(f);
            let layer = tracing_subscriber::fmt::layer()
                .with_ansi(false)
                .with_writer(writer)
                .with_filter(filter(FILE_FILTER).and(filter_fn(shows_no_secret)));
            (Some(layer), Some(guard))
        }
        None => (None, None),
    };
    tracing_subscriber::registry()
        .with(stderr)
        .with(file_layer)
        .init();
    guard
}

fn main() -> ExitCode {
    let cli = Cli::parse(); // exits 2 on bad arguments, 0 on --help
    // A verb refused before it made its database leaves no log file of its own.
    let log_file = log_path(&cli.db);
    let stray_log = wants_log_file(&cli) && !log_file.exists();
    let log_guard = init_logging(&cli);
    // The command line as logged: a URL's password as ***.
    let args: Vec<String> = std::env::args_os()
        .skip(1)
        .map(|a| softtouch_store::target::redact_words(&a.to_string_lossy()))
        .collect();
    tracing::info!(
        version = env!("CARGO_PKG_VERSION"),
        pid = std::process::id(),
        "softtouch {} started",
        args.join(" ")
    );
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            tracing::error!("cannot start the async runtime: {e}");
            return ExitCode::from(cli::EXIT_RUNTIME);
        }
    };
    let db = cli.db.clone();
    let mut stdout = std::io::stdout().lock();
    let result = runtime.block_on(cli::run(cli, &mut stdout));
    // Every connection the verb left is gone with its runtime.
    drop(runtime);
    fold_write_ahead_log(&db);
    match result {
        Ok(()) => {
            tracing::info!("finished");
            ExitCode::from(cli::EXIT_OK)
        }
        Err(failure) => {
            let message = cli::error_text(failure.error());
            eprintln!("error: {message}");
            // Not `error!`: stderr already has it; the file gets it at info.
            tracing::info!(exit_code = failure.exit_code(), "failed: {message}");
            if stray_log && db.file().is_some_and(|p| !p.exists()) {
                drop(log_guard);
                let _ = std::fs::remove_file(&log_file);
            }
            ExitCode::from(failure.exit_code())
        }
    }
}

/// However the verb ended, the `.db` file alone holds every commit once the binary
/// exits, so a backup may copy it alone: the write-ahead log is copied into it and,
/// when no other process has the database open, removed (on a fresh runtime: the
/// verb's clock may have been paused). A live collection's log stays; it is folded in
/// when that one closes.
fn fold_write_ahead_log(db: &softtouch_store::DbTarget) {
    let Some(path) = db.file() else {
        return;
    };
    // A reader (`report`, opened read-only) leaves an empty `-wal` and a `-shm` it may
    // not remove: a connection of our own that closes last removes them.
    let beside = |suffix: &str| {
        let mut p = path.as_os_str().to_owned();
        p.push(suffix);
        PathBuf::from(p).exists()
    };
    if !beside("-wal") && !beside("-shm") {
        return;
    }
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    else {
        return;
    };
    let wait = std::time::Duration::from_millis(200);
    match rt.block_on(softtouch_store::sqlite_file::checkpoint(path, wait)) {
        Ok(c) if !c.complete => tracing::info!(
            "{}: another process is writing the database; its write-ahead log stays until that one closes",
            db.display()
        ),
        Ok(_) => {}
        Err(e) => tracing::debug!("checkpoint of {} at exit: {e}", db.display()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_sits_beside_the_database() {
        use softtouch_store::DbTarget;
        use std::path::Path;
        assert_eq!(
            log_path(&DbTarget::File("runs/softtouch.db".into())),
            Path::new("runs/softtouch.db.log")
        );
        assert_eq!(
            log_path(&DbTarget::File("lab".into())),
            Path::new("lab.log")
        );
        assert_eq!(
            log_path(&DbTarget::Postgres("postgres://rig@db/softtouch".into())),
            Path::new("softtouch.log")
        );
    }
}
