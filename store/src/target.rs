//! Where the database is: a SQLite file (the embedded default) or a PostgreSQL server
//! (the fleet database), as `--db` and `SOFTTOUCH_DB` name it.
//!
//! - `postgres://USER[:PASSWORD]@HOST[:PORT]/DB[?OPTIONS]` (or `postgresql://`):
//!   PostgreSQL. The options are libpq's as sqlx reads them: `sslmode`,
//!   `sslrootcert`, `connect_timeout`, `application_name`, …
//! - `sqlite:PATH` or `sqlite://PATH`: that file.
//! - anything else: a file path, as it always was.
//!
//! A password never prints: the URL is held in [`PgUrl`], whose `Debug` and `Display`
//! show it with the password as `***` ([`redact`]); only [`PgUrl::expose`] hands the
//! text to the driver. Whatever prints a target prints [`DbTarget::display`].
//!
//! On a shared host, leave the password out of the URL (every user reads a process's
//! command line in `/proc/*/cmdline`): the driver takes it, as libpq does, from
//! `PGPASSWORD` or from the password file (`PGPASSFILE`, else `~/.pgpass`, lines of
//! `host:port:database:user:password`).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// A database's location.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DbTarget {
    /// A SQLite file.
    File(PathBuf),
    /// A PostgreSQL server's URL, as given (a password in it prints as `***`).
    Postgres(PgUrl),
}

/// A PostgreSQL URL that may hold a password: printed (`{}` or `{:?}`) only with the
/// password as `***`; [`PgUrl::expose`] gives the text itself, for the driver alone.
#[derive(Clone, PartialEq, Eq)]
pub struct PgUrl(String);

impl PgUrl {
    /// The URL as given, password included: for connecting, never for printing.
    #[must_use]
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl From<String> for PgUrl {
    fn from(url: String) -> Self {
        Self(url)
    }
}

impl From<&str> for PgUrl {
    fn from(url: &str) -> Self {
        Self(url.to_owned())
    }
}

impl fmt::Debug for PgUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("PgUrl").field(&redact(&self.0)).finish()
    }
}

impl fmt::Display for PgUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&redact(&self.0))
    }
}

impl DbTarget {
    /// The SQLite file, if this is one.
    #[must_use]
    pub fn file(&self) -> Option<&Path> {
        match self {
            Self::File(path) => Some(path),
            Self::Postgres(_) => None,
        }
    }

    /// For messages: the path, or the URL with its password replaced by `***`.
    #[must_use]
    pub fn display(&self) -> Shown<'_> {
        Shown(self)
    }

    /// The URL sqlx's `Any` driver connects by, and the engine behind it; a SQLite file
    /// is opened in `sqlite_mode` (`rwc`, `rw`, `ro`: see [`crate::sqlite_file::sqlite_url`]).
    pub(crate) fn url_and_dialect(&self, sqlite_mode: &str) -> (String, crate::Dialect) {
        match self {
            Self::File(path) => (
                crate::sqlite_file::sqlite_url(path, sqlite_mode),
                crate::Dialect::Sqlite,
            ),
            Self::Postgres(url) => (url.expose().to_owned(), crate::Dialect::Postgres),
        }
    }

    /// Whether this is a PostgreSQL server.
    #[must_use]
    pub const fn is_postgres(&self) -> bool {
        matches!(self, Self::Postgres(_))
    }
}

/// A target as shown to people (see [`DbTarget::display`]).
#[derive(Debug, Clone, Copy)]
pub struct Shown<'a>(&'a DbTarget);

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            DbTarget::File(path) => write!(f, "{}", path.display()),
            DbTarget::Postgres(url) => fmt::Display::fmt(url, f),
        }
    }
}

/// `url` with the password (in the user part, or an option whose name holds `pass`:
/// `password=`, a mistyped `passwd=`) as `***`.
#[must_use]
pub fn redact(url: &str) -> String {
    let (scheme, rest) = url.split_once("://").unwrap_or(("", url));
    let has_scheme = url.contains("://");
    let authority_end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    let (authority, tail) = rest.split_at(authority_end);
    let authority = match authority.rsplit_once('@') {
        Some((user_info, host)) => match user_info.split_once(':') {
            Some((user, _password)) => format!("{user}:***@{host}"),
            None => format!("{user_info}@{host}"),
        },
        None => authority.to_owned(),
    };
    let tail = match tail.split_once('?') {
        Some((path, query)) => {
            let query: Vec<String> = query
                .split('&')
                .map(|pair| match pair.split_once('=') {
                    // `password`, and anything like it (`passwd`, `pass`): better a
                    // hidden option than a shown secret.
                    Some((key, _)) if key.to_ascii_lowercase().contains("pass") => {
                        format!("{key}=***")
                    }
                    _ => pair.to_owned(),
                })
                .collect();
            format!("{path}?{}", query.join("&"))
        }
        None => tail.to_owned(),
    };
    if has_scheme {
        format!("{scheme}://{authority}{tail}")
    } else {
        format!("{authority}{tail}")
    }
}

/// `text` (a command line, a message) with every URL's password as `***`: each word
/// holding `://` is redacted from its scheme on (`--db=postgres://u:pw@h/d` keeps
/// `--db=`).
#[must_use]
pub fn redact_words(text: &str) -> String {
    text.split(' ')
        .map(|word| match word.find("://") {
            Some(at) => {
                let scheme_start = word[..at]
                    .char_indices()
                    .rev()
                    .find(|&(_, c)| !(c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.')))
                    .map_or(0, |(i, c)| i + c.len_utf8());
                format!("{}{}", &word[..scheme_start], redact(&word[scheme_start..]))
            }
            None => word.to_owned(),
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// `url` naming the database `name` on the same server, with the same options.
#[must_use]
pub fn with_database(url: &str, name: &str) -> String {
    let (scheme, rest) = url.split_once("://").unwrap_or(("postgres", url));
    let (before_query, query) = match rest.split_once('?') {
        Some((a, q)) => (a, Some(q)),
        None => (rest, None),
    };
    let authority = before_query.split('/').next().unwrap_or("");
    let mut out = format!("{scheme}://{authority}/{name}");
    if let Some(q) = query {
        out.push('?');
        out.push_str(q);
    }
    out
}

impl FromStr for DbTarget {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.get(..13).unwrap_or(s).to_ascii_lowercase();
        if lower.starts_with("postgres://") || lower.starts_with("postgresql://") {
            let rest = s.split_once("://").map_or("", |(_, rest)| rest);
            let host = rest
                .split(['/', '?'])
                .next()
                .unwrap_or("")
                .rsplit('@')
                .next()
                .unwrap_or("");
            if host.is_empty() && !rest.contains("host=") {
                return Err(format!(
                    "{}: no server in the URL; expected postgres://USER@HOST[:PORT]/DATABASE",
                    redact(s)
                ));
            }
            return Ok(Self::Postgres(PgUrl(s.to_owned())));
        }
        if lower.starts_with("postgres:") || lower.starts_with("postgresql:") {
            return Err(format!(
                "{}: expected postgres://USER@HOST[:PORT]/DATABASE",
                redact(s)
            ));
        }
        if let Some(path) = s
            .strip_prefix("sqlite://")
            .or_else(|| s.strip_prefix("sqlite:"))
        {
            if path.is_empty() {
                return Err("sqlite: names no file; expected sqlite:PATH".to_owned());
            }
            return Ok(Self::File(PathBuf::from(path)));
        }
        if s.is_empty() {
            return Err("an empty database path; expected a file or postgres://…".to_owned());
        }
        Ok(Self::File(PathBuf::from(s)))
    }
}

impl From<&Path> for DbTarget {
    fn from(path: &Path) -> Self {
        Self::File(path.to_owned())
    }
}

impl From<PathBuf> for DbTarget {
    fn from(path: PathBuf) -> Self {
        Self::File(path)
    }
}

impl From<&PathBuf> for DbTarget {
    fn from(path: &PathBuf) -> Self {
        Self::File(path.clone())
    }
}

impl From<&Self> for DbTarget {
    fn from(target: &Self) -> Self {
        target.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_and_paths_are_told_apart() -> Result<(), String> {
        assert_eq!(
            "postgres://rig@db.lab/softtouch".parse::<DbTarget>()?,
            DbTarget::Postgres("postgres://rig@db.lab/softtouch".into())
        );
        assert!("POSTGRESQL://rig@db/x".parse::<DbTarget>()?.is_postgres());
        assert_eq!(
            "softtouch.db".parse::<DbTarget>()?,
            DbTarget::File("softtouch.db".into())
        );
        assert_eq!(
            "sqlite:/data/a.db".parse::<DbTarget>()?,
            DbTarget::File("/data/a.db".into())
        );
        assert_eq!(
            "sqlite:///data/a.db".parse::<DbTarget>()?,
            DbTarget::File("/data/a.db".into())
        );
        Ok(())
    }

    #[test]
    fn malformed_targets_are_refused_by_what_is_missing() {
        for bad in ["", "sqlite:", "postgres:db", "postgres:///x", "postgres://"] {
            let e = bad.parse::<DbTarget>();
            assert!(e.is_err(), "{bad:?} parsed as {e:?}");
        }
        let e = "postgres:///db?password=hunter2".parse::<DbTarget>();
        assert!(matches!(&e, Err(m) if !m.contains("hunter2")), "{e:?}");
    }

    #[test]
    fn another_database_on_the_same_server_keeps_the_options() {
        assert_eq!(
            with_database("postgres://u:p@h:5/postgres?sslmode=require", "t1"),
            "postgres://u:p@h:5/t1?sslmode=require"
        );
        assert_eq!(with_database("postgres://h", "t2"), "postgres://h/t2");
    }

    #[test]
    fn passwords_never_show() {
        assert_eq!(
            redact("postgres://rig:s3cr%40t@db.lab:5432/softtouch?sslmode=require"),
            "postgres://rig:***@db.lab:5432/softtouch?sslmode=require"
        );
        assert_eq!(
            redact("postgres://rig@db/x?password=pw&application_name=a"),
            "postgres://rig@db/x?password=***&application_name=a"
        );
        assert_eq!(redact("postgres://db/x"), "postgres://db/x");
        assert_eq!(
            redact("postgres://db/x?PassWd=pw&sslmode=require"),
            "postgres://db/x?PassWd=***&sslmode=require"
        );
        // A password holding '@' or ':' is cut at the last '@' of the authority.
        assert_eq!(redact("postgres://u:p@ss:w@h/d"), "postgres://u:***@h/d");
        let target = DbTarget::Postgres("postgres://u:pw@h/d".into());
        assert_eq!(target.display().to_string(), "postgres://u:***@h/d");
        // Unprintable by type: Debug of the target, and of anything holding it.
        let debug = format!("{target:?} {:?}", Some(&target));
        assert!(!debug.contains("pw@"), "{debug}");
        assert!(debug.contains("u:***@h"), "{debug}");
        let DbTarget::Postgres(url) = &target else {
            unreachable!()
        };
        assert_eq!(url.to_string(), "postgres://u:***@h/d");
        assert_eq!(url.expose(), "postgres://u:pw@h/d");
    }

    #[test]
    fn command_lines_are_shown_without_passwords() {
        assert_eq!(
            redact_words("--db postgres://rig:hunter2@db/x collect --samples 3"),
            "--db postgres://rig:***@db/x collect --samples 3"
        );
        assert_eq!(
            redact_words("db copy --from=POSTGRESQL://a:b@h/d --to x.db"),
            "db copy --from=POSTGRESQL://a:***@h/d --to x.db"
        );
        assert_eq!(
            redact_words("--to postgres://h/d?password=p&sslmode=require"),
            "--to postgres://h/d?password=***&sslmode=require"
        );
        assert_eq!(redact_words(""), "");
        assert_eq!(redact_words("://"), "://");
        assert_eq!(redact_words("a :// b"), "a :// b");
        assert_eq!(redact_words("é://u:p@h"), "é://u:***@h");
    }
}
