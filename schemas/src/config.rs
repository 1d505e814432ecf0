//! Loading TOML configs with validation.
//!
//! Errors name the file, the field (as a path such as `procedure.settle_s` or
//! `effects[2].probability`), the line where the parser knows it, and what was
//! expected. Unknown fields are rejected by every config type.

use serde::de::DeserializeOwned;
use std::fmt;
use std::path::{Path, PathBuf};

/// Where a config's text came from, for error messages and provenance.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// A file the user gave.
    File(PathBuf),
    /// One of the embedded defaults, by name.
    Embedded(&'static str),
    /// Text stored elsewhere, e.g. a run's config in the database.
    Stored(String),
}

impl fmt::Display for ConfigSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File(p) => write!(f, "{}", p.display()),
            Self::Embedded(name) => write!(f, "<embedded default {name}>"),
            Self::Stored(what) => write!(f, "<{what}>"),
        }
    }
}

/// One thing wrong with a config.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Path of the field, e.g. `procedure.settle_s`; empty for the whole file.
    pub field: String,
    /// 1-based line in the file, where known.
    pub line: Option<usize>,
    /// What is wrong and what was expected.
    pub message: String,
}

/// A config that could not be read, parsed or validated; lists every problem found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct ConfigError {
    /// The file (or embedded default) at fault.
    pub file: ConfigSource,
    /// Everything wrong with it (at least one).
    pub problems: Vec<Problem>,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, p) in self.problems.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{}", self.file)?;
            if let Some(line) = p.line {
                write!(f, ":{line}")?;
            }
            if p.field.is_empty() {
                write!(f, ": {}", p.message)?;
            } else {
                write!(f, ": field `{}`: {}", p.field, p.message)?;
            }
        }
        Ok(())
    }
}

/// Range and consistency checks a config runs after parsing.
pub trait Validate {
    /// Record every problem found in `check`.
    fn validate(&self, check: &mut Check);
}

/// Collects validation problems with their field paths.
#[derive(Debug, Default)]
pub struct Check {
    problems: Vec<Problem>,
}

impl Check {
    /// Record a problem with `field`.
    pub fn fail(&mut self, field: impl Into<String>, message: impl Into<String>) {
        self.problems.push(Problem {
            field: field.into(),
            line: None,
            message: message.into(),
        });
    }

    /// `v` must be finite and `> 0`.
    pub fn positive(&mut self, field: &str, v: f64, unit: &str) {
        if !(v.is_finite() && v > 0.0) {
            self.fail(
                field,
                format!("expected a finite value > 0 {unit}, found {v}"),
            );
        }
    }

    /// `v` must be finite and `>= 0`.
    pub fn non_negative(&mut self, field: &str, v: f64, unit: &str) {
        if !(v.is_finite() && v >= 0.0) {
            self.fail(
                field,
                format!("expected a finite value >= 0 {unit}, found {v}"),
            );
        }
    }

    /// `v` must lie in `[lo, hi]`.
    pub fn within(&mut self, field: &str, v: f64, lo: f64, hi: f64, unit: &str) {
        if !(v.is_finite() && v >= lo && v <= hi) {
            self.fail(
                field,
                format!(
                    "expected a value in [{}, {}] {unit}, found {}",
                    readable(lo),
                    readable(hi),
                    readable(v)
                ),
            );
        }
    }

    /// `r` must be a finite range with `min <= max`.
    pub fn range(&mut self, field: &str, r: &crate::Range, unit: &str) {
        if !r.is_valid() {
            self.fail(
                field,
                format!(
                    "expected [min, max] with finite min <= max in {unit}, found [{}, {}]",
                    readable(r.min),
                    readable(r.max)
                ),
            );
        }
    }

    /// Problems found so far.
    #[must_use]
    pub fn problems(&self) -> &[Problem] {
        &self.problems
    }

    /// Turn the collected problems into a result for `source`.
    pub fn finish(self, source: &ConfigSource) -> Result<(), ConfigError> {
        if self.problems.is_empty() {
            Ok(())
        } else {
            Err(ConfigError {
                file: source.clone(),
                problems: self.problems,
            })
        }
    }
}

/// Parse and validate a config from TOML text.
pub fn parse_toml<T>(text: &str, source: &ConfigSource) -> Result<T, ConfigError>
where
    T: DeserializeOwned + Validate,
{
    let fail = |field: String, err: &toml::de::Error| {
        let line = err.span().map(|span| line_of(text, span.start));
        let mut message = cut(err.message().trim());
        // A duplicate key: say which (the parser gives only its line).
        if message.contains("duplicate key")
            && let Some(key) = line
                .and_then(|l| text.lines().nth(l.saturating_sub(1)))
                .and_then(duplicate_key_in)
        {
            message = format!("{message} `{}`", cut(&key));
        }
        ConfigError {
            file: source.clone(),
            problems: vec![Problem {
                field,
                line,
                message,
            }],
        }
    };
    let de = toml::Deserializer::parse(text).map_err(|e| fail(String::new(), &e))?;
    let value: T = serde_path_to_error::deserialize(de).map_err(|e| {
        let field = field_path(e.path());
        let message = e.inner().message().trim().to_owned();
        // Inside an entry of a list of tagged tables (`[[effects]]`) serde sees the
        // entry only as a whole: find the field and the entry's own line.
        if let Some((field, line)) = entry_problem(text, &field, &message) {
            let line = line.or_else(|| e.inner().span().map(|span| line_of(text, span.start)));
            return ConfigError {
                file: source.clone(),
                problems: vec![Problem {
                    field,
                    line,
                    message: cut(&message),
                }],
            };
        }
        fail(field, e.inner())
    })?;
    let mut check = Check::default();
    value.validate(&mut check);
    check.finish(source)?;
    Ok(value)
}

/// Read, parse and validate a config file.
pub fn load_toml<T>(path: &Path) -> Result<T, ConfigError>
where
    T: DeserializeOwned + Validate,
{
    let source = ConfigSource::File(path.to_owned());
    let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
        file: source.clone(),
        problems: vec![Problem {
            field: String::new(),
            line: None,
            message: format!("cannot read: {e}"),
        }],
    })?;
    parse_toml(&text, &source)
}

/// Serialise a config as TOML (for `config show` and provenance).
pub fn to_toml<T: serde::Serialize>(value: &T) -> String {
    // Our config types are plain structs of numbers, strings, arrays and tables: they
    // always serialise. Fall back to a TOML comment rather than panic if one day not.
    toml::to_string_pretty(value).unwrap_or_else(|e| format!("# cannot serialise config: {e}\n"))
}

/// A message cut to a few lines (a value of 20 000 characters is not echoed whole).
fn cut(s: &str) -> String {
    const MAX: usize = 300;
    if s.chars().count() > MAX {
        format!(
            "{}… ({} characters in all)",
            s.chars().take(MAX).collect::<String>(),
            s.chars().count()
        )
    } else {
        s.to_owned()
    }
}

/// The first key given twice on one line (`{ a = 1, a = 2 }`), if any.
fn duplicate_key_in(line: &str) -> Option<String> {
    let mut seen: Vec<&str> = Vec::new();
    for part in line.split([',', '{']) {
        let Some((key, _)) = part.split_once('=') else {
            continue;
        };
        let key = key.trim().trim_matches('"');
        if key.is_empty() {
            continue;
        }
        if seen.contains(&key) {
            return Some(key.to_owned());
        }
        seen.push(key);
    }
    None
}

/// For a problem placed at a whole entry of a list of tables (`effects[12]`): the
/// field inside it the message points at, where it can be told (a missing field in a
/// list of tables inside the entry, an empty list), and the line of the entry's own
/// `[[key]]` header. `None` for any other problem.
fn entry_problem(text: &str, field: &str, message: &str) -> Option<(String, Option<usize>)> {
    let (key, rest) = field.split_once('[')?;
    let index: usize = rest.strip_suffix(']')?.parse().ok()?;
    if key.contains(['.', '[']) {
        return None;
    }
    let table: toml::Table = text.parse().ok()?;
    let entry = table.get(key)?.as_array()?.get(index)?.as_table()?;
    let header = format!("[[{key}]]");
    let line = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.trim_start().starts_with(&header))
        .nth(index)
        .map(|(i, _)| i + 1);
    let quoted = |m: &str| m.split('`').nth(1).map(str::to_owned);
    let mut inner = None;
    if message.starts_with("missing field") {
        let missing = quoted(message)?;
        // In a list of tables inside the entry, an item that lacks it.
        for (k, v) in entry {
            if let Some(items) = v.as_array() {
                for (i, item) in items.iter().enumerate() {
                    if item.as_table().is_some_and(|t| !t.contains_key(&missing)) {
                        inner = Some(format!("{k}[{i}].{missing}"));
                    }
                }
            }
        }
        inner = inner.or(Some(missing));
    } else if message.starts_with("invalid length 0") {
        inner = entry
            .iter()
            .find(|(_, v)| v.as_array().is_some_and(Vec::is_empty))
            .map(|(k, _)| k.clone());
    } else if let Some(unknown) = message.strip_prefix("unknown field ").and_then(quoted) {
        inner = Some(unknown);
    }
    let kind = entry
        .get("kind")
        .and_then(toml::Value::as_str)
        .map_or_else(String::new, |k| format!(" ({k})"));
    let at = match inner {
        Some(f) => format!("{key}[{index}]{kind}.{f}"),
        None => format!("{key}[{index}]{kind}"),
    };
    Some((at, line))
}

fn field_path(path: &serde_path_to_error::Path) -> String {
    let s = path.to_string();
    if s == "." { String::new() } else { s }
}

fn line_of(text: &str, byte: usize) -> usize {
    let end = byte.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// A number as a person reads it in a message: plain where that is short, in
/// scientific notation where plain would run to hundreds of digits (`5e-324`,
/// `1e308`).
#[must_use]
pub fn readable(v: f64) -> String {
    let a = v.abs();
    if a.classify() == std::num::FpCategory::Zero || !v.is_finite() || (1e-4..1e15).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(super::readable(5e-324), "5e-324");
        assert_eq!(super::readable(1e308), "1e308");
        assert_eq!(super::readable(-2.5e-7), "-2.5e-7");
        assert_eq!(super::readable(0.0001), "0.0001");
        assert_eq!(super::readable(10.0), "10");
        assert_eq!(super::readable(0.0), "0");
        assert_eq!(super::readable(f64::NAN), "NaN");
        assert_eq!(super::readable(f64::NEG_INFINITY), "-inf");
    }

    use super::*;

    #[test]
    fn line_numbers_are_one_based_and_clamped() {
        assert_eq!(line_of("a\nb\nc", 0), 1);
        assert_eq!(line_of("a\nb\nc", 2), 2);
        assert_eq!(line_of("a\nb\nc", 999), 3);
    }
}
