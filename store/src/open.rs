//! Opening a store: a SQLite file (created, checked to be a database, migrated) or a
//! PostgreSQL server (connected, its database made if asked, migrated), with each
//! engine's pool settings and a failed connection said as the user should read it.

use super::*;

impl Store {
    /// Open (creating if missing) and migrate the database at `target` (a path, or a
    /// PostgreSQL URL: see [`DbTarget`]). An empty file is set up as a new database,
    /// with a warning saying so; a file that is not a database is refused.
    ///
    /// # Errors
    /// [`StoreError::NotADatabase`], or the engine's refusal to open or migrate it.
    pub async fn open(target: impl Into<DbTarget>) -> Result<Self, StoreError> {
        let target = target.into();
        let DbTarget::File(path) = &target else {
            return Self::connect(target).await;
        };
        match sqlite_file::inspect(path)? {
            sqlite_file::DbFile::NotSqlite { starts_with } => {
                return Err(sqlite_file::not_a_database(path, starts_with));
            }
            sqlite_file::DbFile::Empty => tracing::warn!(
                "{} is an empty file: setting it up as a new database",
                path.display()
            ),
            sqlite_file::DbFile::Missing | sqlite_file::DbFile::Sqlite => {}
        }
        Self::connect(target).await
    }

    /// Open and migrate the database that must already be at `target`: a missing or
    /// empty file is an error (a mistyped `--db` leaves no new database behind). A
    /// PostgreSQL database must exist on its server (this never creates one).
    ///
    /// # Errors
    /// [`StoreError::NoDatabase`], [`StoreError::EmptyFile`],
    /// [`StoreError::NotADatabase`], or the engine's refusal.
    pub async fn open_existing(target: impl Into<DbTarget>) -> Result<Self, StoreError> {
        let target = target.into();
        let DbTarget::File(path) = &target else {
            return Self::connect(target).await;
        };
        match sqlite_file::inspect(path)? {
            sqlite_file::DbFile::Sqlite => Self::connect(target).await,
            sqlite_file::DbFile::Missing => Err(StoreError::NoDatabase(path.clone())),
            sqlite_file::DbFile::Empty => Err(StoreError::EmptyFile { path: path.clone() }),
            sqlite_file::DbFile::NotSqlite { starts_with } => {
                Err(sqlite_file::not_a_database(path, starts_with))
            }
        }
    }

    async fn connect(target: DbTarget) -> Result<Self, StoreError> {
        sqlx::any::install_default_drivers();
        let shown = target.display().to_string();
        let (url, dialect) = target.url_and_dialect("rwc");
        let migrator = match dialect {
            Dialect::Sqlite => &MIGRATOR,
            Dialect::Postgres => &PG_MIGRATOR,
        };
        if dialect == Dialect::Postgres {
            // One connection first, so that a server that is not there, a refused login
            // or a missing database is said at once (the pool would retry for its whole
            // acquire timeout).
            use sqlx::Connection as _;
            let conn = sqlx::AnyConnection::connect(&url)
                .await
                .map_err(|source| connect_error(&shown, source))?;
            let _ = conn.close().await;
        }
        // Two processes opening a new database at once race: switching a new SQLite file
        // to WAL can find it locked, and both try the first migration (the loser fails on
        // a table that now exists; on PostgreSQL sqlx's advisory lock serialises them).
        // Once the winner is done, a second look succeeds.
        let mut attempt = 0u64;
        let pool = loop {
            attempt += 1;
            let result = match pool_options(dialect).connect(&url).await {
                Ok(pool) => match migrator.run(&pool).await {
                    Ok(()) => Ok(pool),
                    Err(source) => Err(StoreError::Migrate {
                        db: shown.clone(),
                        source,
                    }),
                },
                Err(source) => Err(connect_error(&shown, source)),
            };
            match result {
                Ok(pool) => break pool,
                Err(e @ StoreError::Refused { .. }) => return Err(e),
                Err(_) if attempt < 5 => {
                    tokio::time::sleep(Duration::from_millis(40 * attempt)).await
                }
                Err(e) => return Err(e),
            }
        };
        Ok(Self {
            pool,
            dialect,
            target,
        })
    }

    /// Create the database `name` on the PostgreSQL server of `server_url` (a URL of
    /// any database there the user may connect to, usually `postgres`); the new
    /// database's URL. The user needs `CREATEDB`. What a lab runs once per server (and
    /// what the tests run for each test).
    ///
    /// # Errors
    /// The server refuses (the name is taken, no right to create), or cannot be reached.
    pub async fn create_postgres_database(
        server_url: &str,
        name: &str,
    ) -> Result<DbTarget, StoreError> {
        use sqlx::Connection as _;
        let shown = target::redact(server_url);
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        {
            return Err(StoreError::Invalid {
                what: "database name",
                why: format!("`{name}`: use lower-case letters, digits and _"),
            });
        }
        let mut conn = sqlx::PgConnection::connect(server_url)
            .await
            .map_err(|source| connect_error(&shown, source))?;
        sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
            .execute(&mut conn)
            .await
            .map_err(query_err("creating a database"))?;
        let _ = conn.close().await;
        Ok(DbTarget::Postgres(
            target::with_database(server_url, name).into(),
        ))
    }
}

/// The pool's settings per engine. SQLite: WAL, NORMAL sync, foreign keys, a 10 s busy
/// wait, on every connection. PostgreSQL: the URL's settings; up to 4 connections per
/// process (a collector writes from one thread), 10 s to get one.
pub(super) fn pool_options(dialect: Dialect) -> AnyPoolOptions {
    let options = AnyPoolOptions::new()
        .max_connections(4)
        .acquire_timeout(Duration::from_secs(10));
    match dialect {
        Dialect::Postgres => options,
        Dialect::Sqlite => options.after_connect(|conn, _meta| {
            Box::pin(async move {
                // NORMAL in WAL mode: a killed process loses nothing committed; a power
                // cut may lose the last commits but never corrupts the file.
                conn.execute(
                    "PRAGMA busy_timeout = 10000; PRAGMA journal_mode = WAL; \
                     PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;",
                )
                .await?;
                Ok(())
            })
        }),
    }
}

/// A failed connection as the user should read it: a wrong password, an unknown user
/// or database, a malformed URL is bad input ([`StoreError::Refused`]); a server that
/// does not answer is a runtime failure ([`StoreError::Open`]).
pub(super) fn connect_error(shown: &str, source: sqlx::Error) -> StoreError {
    let refused = match &source {
        sqlx::Error::Configuration(e) => Some(format!("bad connection settings: {e}")),
        sqlx::Error::Database(e) => match e.code().as_deref() {
            // invalid_password, invalid_authorization_specification
            Some("28P01" | "28000") => {
                Some(format!("the server refused the login: {}", e.message()))
            }
            // invalid_catalog_name
            Some("3D000") => Some(format!(
                "{} (create it on the server first: `createdb NAME`)",
                e.message()
            )),
            _ => None,
        },
        _ => None,
    };
    match refused {
        Some(why) => StoreError::Refused {
            db: shown.to_owned(),
            why,
        },
        None => StoreError::Open {
            db: shown.to_owned(),
            source,
        },
    }
}
