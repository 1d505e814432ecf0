//! The database file itself, before and after a store has it open: what is at a path
//! (nothing, an empty file, a SQLite database or something else), the checkpoint that
//! leaves the `.db` file complete on its own, its size and the disk it may still take.
//!
//! SQLite in WAL mode keeps recent commits in `NAME-wal` until a checkpoint copies them
//! into `NAME`. A process that ends without the last connection closing cleanly leaves
//! them there: committed and safe, but a backup that copies `NAME` alone misses them.
//! [`checkpoint`] (called when a store closes and once more when the `softtouch`
//! binary exits) copies the log into the file; the log itself goes when the last
//! connection closes. The checkpoint is SQLite's PASSIVE one: it never waits for, nor
//! blocks, another process's writer (a `status` beside a live collection must not stall
//! it); what that process is still writing stays in the log until it closes.

use crate::StoreError;
use sqlx::ConnectOptions as _;
use sqlx::sqlite::SqliteConnectOptions;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The first 16 bytes of every SQLite 3 database.
const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// What lies at a database path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DbFile {
    /// Nothing.
    Missing,
    /// A file of zero bytes (what `touch` leaves, or SQLite before its first write).
    Empty,
    /// A SQLite database (by its header).
    Sqlite,
    /// Something else; the first bytes as a person reads them.
    NotSqlite {
        /// Up to 16 leading bytes, escaped.
        starts_with: String,
    },
}

/// Looks at `path` without opening it as a database.
///
/// # Errors
/// The path exists but cannot be read (a folder, no permission).
pub fn inspect(path: &Path) -> Result<DbFile, StoreError> {
    let io = |e: std::io::Error| StoreError::File {
        path: path.to_owned(),
        why: e.to_string(),
    };
    let mut file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(DbFile::Missing),
        Err(e) => return Err(io(e)),
    };
    if file.metadata().map_err(io)?.is_dir() {
        return Err(StoreError::Folder(path.to_owned()));
    }
    let mut head = Vec::with_capacity(16);
    file.by_ref().take(16).read_to_end(&mut head).map_err(io)?;
    Ok(if head.is_empty() {
        DbFile::Empty
    } else if head.as_slice() == SQLITE_MAGIC {
        DbFile::Sqlite
    } else {
        DbFile::NotSqlite {
            starts_with: head.escape_ascii().to_string(),
        }
    })
}

/// The error for a path that holds something other than a database.
pub(crate) fn not_a_database(path: &Path, starts_with: String) -> StoreError {
    StoreError::NotADatabase {
        path: path.to_owned(),
        starts_with,
    }
}

/// How a checkpoint went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Checkpoint {
    /// Every committed page is in the database file and the log is empty.
    pub complete: bool,
    /// Pages the log held.
    pub log_pages: i64,
}

impl Checkpoint {
    /// From `PRAGMA wal_checkpoint`'s row: (busy, log pages, pages checkpointed).
    const fn from_pragma((busy, log, checkpointed): (i64, i64, i64)) -> Self {
        Self {
            // (0, -1, -1) for a database not in WAL mode: nothing to fold.
            complete: busy == 0 && (log <= 0 || checkpointed == log),
            log_pages: if log > 0 { log } else { 0 },
        }
    }
}

/// The URL sqlx's `Any` driver opens the SQLite file at `path` by: the path
/// percent-encoded where a URL would misread it (`%`, `?`, `#`), and SQLite's open
/// `mode`: `rwc` (create a missing file), `rw` or `ro`. The path is made absolute
/// first: a URL would read `a.db` in `sqlite://a.db` as a host name.
#[must_use]
pub fn sqlite_url(path: &Path, mode: &str) -> String {
    let path = std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
    let mut url = String::from("sqlite://");
    for c in path.to_string_lossy().chars() {
        match c {
            '%' => url.push_str("%25"),
            '?' => url.push_str("%3F"),
            '#' => url.push_str("%23"),
            c => url.push(c),
        }
    }
    url.push_str("?mode=");
    url.push_str(mode);
    url
}

/// `NAME-wal` beside the database `NAME`.
#[must_use]
pub fn wal_path(db: &Path) -> PathBuf {
    let mut p = db.as_os_str().to_owned();
    p.push("-wal");
    PathBuf::from(p)
}

/// Copies the write-ahead log of the SQLite database at `path` into the file
/// (`PRAGMA wal_checkpoint(PASSIVE)`) through one connection of its own, whose close
/// then removes the log when no other connection is open. Another process writing the
/// database (a live collection) can keep it from completing: that is reported, not
/// waited for (`wait` bounds only the lock needed to open the connection).
///
/// # Errors
/// The file is not a database, or SQLite refuses.
pub async fn checkpoint(path: &Path, wait: Duration) -> Result<Checkpoint, StoreError> {
    match inspect(path)? {
        DbFile::Sqlite => {}
        DbFile::Missing | DbFile::Empty => {
            return Ok(Checkpoint {
                complete: true,
                log_pages: 0,
            });
        }
        DbFile::NotSqlite { starts_with } => return Err(not_a_database(path, starts_with)),
    }
    let open = |source| StoreError::Open {
        db: path.display().to_string(),
        source,
    };
    let mut conn = SqliteConnectOptions::new()
        .filename(path)
        .create_if_missing(false)
        .busy_timeout(wait)
        .connect()
        .await
        .map_err(open)?;
    let done = sqlx::query_as(CHECKPOINT_SQL)
        .fetch_one(&mut conn)
        .await
        .map(Checkpoint::from_pragma)
        .map_err(crate::query_err("checkpointing the write-ahead log"));
    // Closing the last connection of a WAL database also checkpoints; a close error
    // leaves the committed data where it was.
    let _ = sqlx::Connection::close(conn).await;
    done
}

/// The checkpoint PRAGMA, run by [`checkpoint_on`] (a store's pool, through `Any`) and
/// [`checkpoint`] (a connection of SQLite's own, for its busy wait).
const CHECKPOINT_SQL: &str = "PRAGMA wal_checkpoint(PASSIVE)";

/// The checkpoint on a pool the caller holds (a SQLite store's, before it closes).
pub(crate) async fn checkpoint_on(pool: &sqlx::AnyPool) -> Result<Checkpoint, StoreError> {
    sqlx::query_as(CHECKPOINT_SQL)
        .fetch_one(pool)
        .await
        .map(Checkpoint::from_pragma)
        .map_err(crate::query_err("checkpointing the write-ahead log"))
}

/// Bytes on disk: the database file and its write-ahead log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DbSize {
    /// The `.db` file.
    pub file_bytes: u64,
    /// Its `-wal` log (0 when absent).
    pub wal_bytes: u64,
}

impl DbSize {
    /// Both together.
    #[must_use]
    pub const fn total(&self) -> u64 {
        self.file_bytes + self.wal_bytes
    }
}

/// The size of the database at `path` with its log (0 for what is not there).
#[must_use]
pub fn db_size(path: &Path) -> DbSize {
    let len = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    DbSize {
        file_bytes: len(path),
        wal_bytes: len(&wal_path(path)),
    }
}

/// Free bytes for an unprivileged writer on the file system that holds `path` (or
/// would: its folder when the file is not there yet).
///
/// # Errors
/// The file system cannot be asked.
pub fn free_bytes(path: &Path) -> Result<u64, StoreError> {
    let dir = if path.is_dir() {
        path.to_owned()
    } else {
        match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        }
    };
    let st = nix::sys::statvfs::statvfs(&dir).map_err(|e| StoreError::File {
        path: dir.clone(),
        why: format!("cannot read the free space: {e}"),
    })?;
    // The block count and size are u64 here but narrower on some targets.
    #[allow(clippy::useless_conversion)]
    let free = u64::from(st.blocks_available()).saturating_mul(u64::from(st.fragment_size()));
    Ok(free)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_lies_at_a_path_is_told_by_its_header() -> Result<(), StoreError> {
        let dir = tempfile::tempdir().map_err(|e| StoreError::File {
            path: PathBuf::new(),
            why: e.to_string(),
        })?;
        let p = |n: &str| dir.path().join(n);
        let write = |n: &str, b: &[u8]| std::fs::write(p(n), b).ok();
        assert_eq!(inspect(&p("none"))?, DbFile::Missing);
        write("empty", b"");
        assert_eq!(inspect(&p("empty"))?, DbFile::Empty);
        write("text", b"hello\nworld, not a db");
        assert_eq!(
            inspect(&p("text"))?,
            DbFile::NotSqlite {
                starts_with: "hello\\nworld, not".into()
            }
        );
        write("short", b"SQLite");
        assert!(matches!(inspect(&p("short"))?, DbFile::NotSqlite { .. }));
        write("db", b"SQLite format 3\0 and then pages");
        assert_eq!(inspect(&p("db"))?, DbFile::Sqlite);
        assert!(
            matches!(inspect(dir.path()), Err(e @ StoreError::Folder(_)) if e.is_bad_input()),
            "a folder is no database"
        );
        Ok(())
    }

    #[test]
    fn sizes_and_free_space_read_what_is_there() -> Result<(), StoreError> {
        let dir = tempfile::tempdir().map_err(|e| StoreError::File {
            path: PathBuf::new(),
            why: e.to_string(),
        })?;
        let db = dir.path().join("x.db");
        assert_eq!(db_size(&db).total(), 0);
        std::fs::write(&db, [0u8; 100]).ok();
        std::fs::write(wal_path(&db), [0u8; 28]).ok();
        assert_eq!(
            db_size(&db),
            DbSize {
                file_bytes: 100,
                wal_bytes: 28
            }
        );
        assert!(free_bytes(&db)? > 0);
        assert!(free_bytes(&dir.path().join("not-yet.db"))? > 0);
        Ok(())
    }
}
