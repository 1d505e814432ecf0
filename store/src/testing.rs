//! Where a test's new database goes: one place for the store's own tests and the
//! collector's fixtures (`softtouch_collector::testing`), so that every test tier runs
//! on SQLite files or, with [`TEST_POSTGRES_ENV`] set, on a PostgreSQL server.

use crate::{DbTarget, Store};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The environment variable that runs the tests against PostgreSQL: a URL of a server
/// database the user may create databases from (`postgres://USER@HOST:PORT/postgres`).
/// Unset, the tests use SQLite files.
pub const TEST_POSTGRES_ENV: &str = "SOFTTOUCH_TEST_POSTGRES";

/// Whether the tests run against PostgreSQL ([`TEST_POSTGRES_ENV`]).
#[must_use]
pub fn on_postgres() -> bool {
    std::env::var_os(TEST_POSTGRES_ENV).is_some()
}

/// `dir/file` (SQLite), or, with [`TEST_POSTGRES_ENV`] set, a new database of its own on
/// that server (named from the process, a counter and the clock, so that test binaries
/// running at once never meet). Panics on any error: it is a test fixture.
pub async fn fresh_target(dir: &Path, file: &str) -> DbTarget {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let Ok(server) = std::env::var(TEST_POSTGRES_ENV) else {
        return DbTarget::File(dir.join(file));
    };
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let name = format!(
        "t{}_{}_{nanos}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    );
    Store::create_postgres_database(&server, &name)
        .await
        .unwrap_or_else(|e| panic!("{e}"))
}
