//! [`StoreError`]: what the store says when it fails, and which of its failures are
//! the user's input (exit 2) rather than the machine's (exit 1).

use super::*;

/// The store failed.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The path holds something other than a SQLite database.
    #[error(
        "{} is not a SQLite database (it starts with \"{starts_with}\", not \"SQLite format 3\"): pass --db with the database's path, or move this file away",
        path.display()
    )]
    NotADatabase {
        /// The file.
        path: PathBuf,
        /// Its first bytes, escaped.
        starts_with: String,
    },
    /// The path is an empty file where a database was expected.
    #[error(
        "{} is an empty file, not a database: `softtouch --db {} db init` sets it up as a new one",
        path.display(), path.display()
    )]
    EmptyFile {
        /// The file.
        path: PathBuf,
    },
    /// The file (not the database in it) cannot be read or asked about.
    #[error("{}: {why}", path.display())]
    File {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// Opening or migrating the database failed.
    #[error("cannot open database {db}: {source}")]
    Open {
        /// The database, as shown (a URL without its password).
        db: String,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// The server refused the URL: a wrong user or password, a database that is not
    /// there, a malformed option.
    #[error("{db}: {why}")]
    Refused {
        /// The database, as shown (a URL without its password).
        db: String,
        /// The server's words.
        why: String,
    },
    /// Migrating the database failed.
    #[error("cannot migrate database {db}: {source}")]
    Migrate {
        /// The database, as shown.
        db: String,
        /// Why.
        #[source]
        source: sqlx::migrate::MigrateError,
    },
    /// A query failed.
    #[error("database error while {doing}: {source}")]
    Query {
        /// What we were doing.
        doing: &'static str,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// A value cannot be stored (e.g. an index beyond SQLite's integer range).
    #[error("cannot store {what}: {why}")]
    Invalid {
        /// Which value.
        what: &'static str,
        /// Why.
        why: String,
    },
    /// A stored value does not read back (a damaged database, or one written by
    /// something else).
    #[error("damaged {what} in the database: {why}")]
    Damaged {
        /// Which value.
        what: &'static str,
        /// Where, and what was found instead of what was expected.
        why: String,
    },
    /// A folder where a database file was expected.
    #[error(
        "{} is a folder, not a database file: pass --db with a file's path (e.g. {}/softtouch.db)",
        .0.display(), .0.display()
    )]
    Folder(PathBuf),
    /// No database where one must be.
    #[error("no database at {}: create it with `softtouch db init` (or pass --db PATH)", .0.display())]
    NoDatabase(PathBuf),
    /// No such run.
    #[error("no run {0} in this database")]
    NoSuchRun(RunId),
    /// Another live process is collecting the run.
    #[error(
        "run {run_id} is being collected by {holder}; stop that process first \
         (a lease is taken over once its process is gone, or after {} s without a heartbeat from another host)",
        runs::LEASE_STALE_S
    )]
    Leased {
        /// The run.
        run_id: RunId,
        /// Who holds it.
        holder: LeaseRow,
    },
    /// Another process took this job's lease over (it found ours stale).
    #[error(
        "lost the lease on run {run_id} to another process; stopping so that one writer remains"
    )]
    LeaseLost {
        /// The run.
        run_id: RunId,
    },
    /// A run meant to repeat another's poses (`collect --poses-from`) does not.
    #[error("run {run_id} does not pair with run {from_run}: {why}")]
    Unpaired {
        /// The paired run.
        run_id: RunId,
        /// The run whose poses it should repeat.
        from_run: RunId,
        /// The first difference.
        why: String,
    },
}

impl StoreError {
    /// Whether the user's input is at fault (a path or run that is not there, a file
    /// that is not a database) rather than the machine.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::NoSuchRun(_)
                | Self::NoDatabase(_)
                | Self::Folder(_)
                | Self::EmptyFile { .. }
                | Self::NotADatabase { .. }
                | Self::Refused { .. }
        )
    }
}

/// Maps a query's error to [`StoreError::Query`], saying what was being done.
pub fn query_err(doing: &'static str) -> impl FnOnce(sqlx::Error) -> StoreError {
    move |source| StoreError::Query { doing, source }
}
