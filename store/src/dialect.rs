//! One text per query, two engines: the store's SQL is written once, in SQLite's
//! spelling, and [`Dialect::sql`] hands it to PostgreSQL with the few differences
//! rewritten.
//!
//! Why a rewrite and not two sets of queries: the store has about a hundred queries and
//! every one of them means the same on both engines once three things are spelled
//! PostgreSQL's way. Keeping one text keeps one place to read and review a query; the
//! rewrite is small, tested below, and never touches SQLite's text (SQLite runs exactly
//! what is written).
//!
//! What is rewritten for PostgreSQL:
//! - placeholders: `?NNN` becomes `$NNN`, and `?` one more than the largest number
//!   so far (SQLite's rule), so `?2, ?` is `$2, $3` on both;
//! - byte order: `COLLATE BINARY` (SQLite's default) becomes `COLLATE "C"`, so that
//!   an `ORDER BY` of text is the same on both engines whatever the server's
//!   collation;
//! - "now" as text: the store's ISO-8601 UTC timestamps
//!   ([`crate::rows::now_sql`]) become `to_char(clock_timestamp() …)` of the same
//!   format;
//! - nothing inside a quoted string or identifier, or a comment (`--`, `/* */`).
//!
//! What is written portably instead (both engines accept it): `ON CONFLICT … DO
//! NOTHING`, `RETURNING`, `COALESCE`, `CASE`, `CAST(… AS BIGINT)` around `SUM` (which
//! PostgreSQL widens to `numeric`), and `CAST(… AS DOUBLE PRECISION)`. `julianday` is
//! defined as a function in PostgreSQL's schema (`migrations/postgres`), with SQLite's
//! meaning. What has no common spelling (PRAGMAs, sizes, integrity checks) is a method
//! with one arm per engine.

use sqlx::AnyConnection;
use sqlx::Database;
use sqlx::any::{Any, AnyTypeInfo};
use sqlx::encode::{Encode, IsNull};
use sqlx::{AssertSqlSafe, SqlSafeStr, SqlStr};

/// Which engine a connection speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// SQLite: the embedded default, one file.
    Sqlite,
    /// PostgreSQL: the fleet database.
    Postgres,
}

/// The store's "now" as SQLite writes it, and PostgreSQL's same text.
const NOW_REWRITES: [(&str, &str); 2] = [
    (
        "strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
        "to_char(clock_timestamp() AT TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS.MS\"Z\"')",
    ),
    (
        "strftime('%Y-%m-%d %H:%M:%SZ', 'now')",
        "to_char(clock_timestamp() AT TIME ZONE 'UTC', 'YYYY-MM-DD HH24:MI:SS\"Z\"')",
    ),
];

impl Dialect {
    /// The engine behind a connection.
    #[must_use]
    pub fn of(conn: &AnyConnection) -> Self {
        Self::named(conn.backend_name())
    }

    /// The engine by sqlx's backend name (`SQLite`, `PostgreSQL`).
    #[must_use]
    pub fn named(backend: &str) -> Self {
        if backend.eq_ignore_ascii_case("postgresql") || backend.eq_ignore_ascii_case("postgres") {
            Self::Postgres
        } else {
            Self::Sqlite
        }
    }

    /// A short name for messages.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Sqlite => "SQLite",
            Self::Postgres => "PostgreSQL",
        }
    }

    /// The query text this engine runs for the store's `text` (see the module's docs).
    #[must_use]
    pub fn sql(self, text: &'static str) -> SqlStr {
        match self {
            Self::Sqlite => text.into_sql_str(),
            Self::Postgres => AssertSqlSafe(to_postgres(text)).into_sql_str(),
        }
    }
}

/// A nullable double to bind: `Option<f64>` itself cannot be bound on PostgreSQL
/// through sqlx 0.9.0's `Any`, whose NULL of a double becomes a 4-byte `real` NULL
/// (`AnyArguments::convert_into` swaps the two float kinds); the statement is then
/// prepared with a `real` parameter and the next non-NULL double is refused ("incorrect
/// binary data format"). This binds NULL as the kind that arrives as an 8-byte `double
/// precision` (a `real`'s NULL, which sqlx swaps to a double's). The PostgreSQL runs of the store's tests (TESTING.md) catch a sqlx that
/// changes this.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NullableF64(pub Option<f64>);

impl sqlx::Type<Any> for NullableF64 {
    fn type_info() -> AnyTypeInfo {
        <f64 as sqlx::Type<Any>>::type_info()
    }
}

impl Encode<'_, Any> for NullableF64 {
    fn encode_by_ref(
        &self,
        buf: &mut <Any as Database>::ArgumentBuffer,
    ) -> Result<IsNull, sqlx::error::BoxDynError> {
        match self.0 {
            Some(v) => <f64 as Encode<'_, Any>>::encode_by_ref(&v, buf),
            None => <Option<f32> as Encode<'_, Any>>::encode_by_ref(&None, buf),
        }
    }
}

impl Dialect {
    /// [`Dialect::sql`] of a text made at run time (the copier's, from the schema's own
    /// table and column names: never from input).
    #[must_use]
    pub fn sql_owned(self, text: String) -> SqlStr {
        match self {
            Self::Sqlite => AssertSqlSafe(text).into_sql_str(),
            Self::Postgres => AssertSqlSafe(to_postgres(&text)).into_sql_str(),
        }
    }
}

/// SQLite's text in PostgreSQL's spelling: placeholders numbered as SQLite numbers
/// them, "now" and byte-order collation rewritten, quoted text and comments left alone.
///
/// Numbering follows SQLite's rule: `?NNN` is parameter NNN, and a bare `?` is one
/// more than the largest number given so far (`?2, ?` is `$2, $3`).
#[must_use]
pub fn to_postgres(text: &str) -> String {
    let mut text = std::borrow::Cow::Borrowed(text);
    for (sqlite, postgres) in NOW_REWRITES {
        if text.contains(sqlite) {
            text = std::borrow::Cow::Owned(text.replace(sqlite, postgres));
        }
    }
    let mut out = String::with_capacity(text.len() + 16);
    let mut largest = 0u64;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            // Quoted text and identifiers (SQLite also quotes with ` and [ ]).
            '\'' | '"' | '`' | '[' => {
                let close = if c == '[' { ']' } else { c };
                out.push(c);
                for d in chars.by_ref() {
                    out.push(d);
                    if d == close {
                        break;
                    }
                }
            }
            '-' if chars.peek() == Some(&'-') => {
                out.push(c);
                for d in chars.by_ref() {
                    out.push(d);
                    if d == '\n' {
                        break;
                    }
                }
            }
            '/' if chars.peek() == Some(&'*') => {
                out.push(c);
                out.extend(chars.next());
                let mut previous = ' ';
                for d in chars.by_ref() {
                    out.push(d);
                    if previous == '*' && d == '/' {
                        break;
                    }
                    previous = d;
                }
            }
            '?' => {
                let mut digits = String::new();
                while let Some(d) = chars.next_if(char::is_ascii_digit) {
                    digits.push(d);
                }
                let number = if digits.is_empty() {
                    largest.saturating_add(1)
                } else {
                    digits.parse().unwrap_or(u64::MAX)
                };
                largest = largest.max(number);
                out.push('$');
                out.push_str(&number.to_string());
            }
            'C' | 'c' if starts_with_word(&chars, c, "COLLATE BINARY") => {
                // Byte order: SQLite's BINARY, PostgreSQL's "C" (a server's default
                // collation, e.g. en_US.UTF-8, orders `a-b` and `a.b` otherwise).
                for _ in 1.."COLLATE BINARY".len() {
                    chars.next();
                }
                out.push_str("COLLATE \"C\"");
            }
            _ => out.push(c),
        }
    }
    out
}

/// Whether `first` followed by `rest` spells `word` (ASCII, any case).
fn starts_with_word(
    rest: &std::iter::Peekable<std::str::Chars<'_>>,
    first: char,
    word: &str,
) -> bool {
    std::iter::once(first)
        .chain(rest.clone())
        .take(word.len())
        .map(|c| c.to_ascii_uppercase())
        .eq(word.chars())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_are_numbered_in_order_and_numbered_ones_kept() {
        assert_eq!(
            to_postgres("SELECT a FROM t WHERE b = ? AND c = ? LIMIT ?"),
            "SELECT a FROM t WHERE b = $1 AND c = $2 LIMIT $3"
        );
        assert_eq!(
            to_postgres("VALUES (?1, ?2, ?12, ?1)"),
            "VALUES ($1, $2, $12, $1)"
        );
    }

    #[test]
    fn quoted_text_and_identifiers_are_left_alone() {
        assert_eq!(
            to_postgres("SELECT '?', \"a?b\" FROM t WHERE x = ? AND y = 'it''s ?'"),
            "SELECT '?', \"a?b\" FROM t WHERE x = $1 AND y = 'it''s ?'"
        );
    }

    #[test]
    fn now_is_rewritten_with_the_same_format() {
        let pg = to_postgres(concat!("UPDATE runs SET updated_at = ", crate::now_sql!()));
        assert!(pg.contains("clock_timestamp()"), "{pg}");
        assert!(!pg.contains("strftime"), "{pg}");
        // The format's quotes do not open a placeholder-free zone that swallows the rest.
        assert_eq!(
            to_postgres(concat!("SELECT ", crate::now_sql!(), ", ?"))
                .matches("$1")
                .count(),
            1
        );
    }

    #[test]
    fn numbered_and_bare_placeholders_mix_as_sqlite_numbers_them() {
        // SQLite: a bare ? is one more than the largest number assigned so far.
        assert_eq!(to_postgres("?2, ?"), "$2, $3");
        assert_eq!(to_postgres("?, ?5, ?, ?1, ?"), "$1, $5, $6, $1, $7");
        assert_eq!(to_postgres("?3 ?3"), "$3 $3");
    }

    #[test]
    fn comments_are_left_alone() {
        assert_eq!(
            to_postgres("SELECT ? -- is it? yes\nFROM t /* a ? here */ WHERE x = ?"),
            "SELECT $1 -- is it? yes\nFROM t /* a ? here */ WHERE x = $2"
        );
        // Unterminated: the rest is comment.
        assert_eq!(to_postgres("SELECT ? /* open ?"), "SELECT $1 /* open ?");
        assert_eq!(to_postgres("SELECT ? -- ?"), "SELECT $1 -- ?");
        // Not comments: a lone - or /.
        assert_eq!(to_postgres("SELECT 1 - ?, 2 / ?"), "SELECT 1 - $1, 2 / $2");
        assert_eq!(
            to_postgres("SELECT `a?`, [b?] FROM t WHERE c = ?"),
            "SELECT `a?`, [b?] FROM t WHERE c = $1"
        );
    }

    #[test]
    fn byte_order_collation_is_spelled_for_postgres() {
        assert_eq!(
            to_postgres("SELECT name FROM t ORDER BY name COLLATE BINARY, id"),
            "SELECT name FROM t ORDER BY name COLLATE \"C\", id"
        );
        assert_eq!(
            to_postgres("ORDER BY n collate binary"),
            "ORDER BY n COLLATE \"C\""
        );
        assert_eq!(to_postgres("'COLLATE BINARY'"), "'COLLATE BINARY'");
        assert_eq!(to_postgres("COLLATE"), "COLLATE");
    }

    #[test]
    fn empty_and_unterminated_text_is_passed_through() {
        assert_eq!(to_postgres(""), "");
        assert_eq!(to_postgres("SELECT 'open ?"), "SELECT 'open ?");
        assert_eq!(to_postgres("?"), "$1");
    }

    #[test]
    fn sqlite_runs_what_is_written() {
        let text = "SELECT ? FROM t";
        assert_eq!(Dialect::Sqlite.sql(text).as_str(), text);
        assert_eq!(Dialect::Postgres.sql(text).as_str(), "SELECT $1 FROM t");
        assert_eq!(Dialect::named("PostgreSQL"), Dialect::Postgres);
        assert_eq!(Dialect::named("SQLite"), Dialect::Sqlite);
    }
}
