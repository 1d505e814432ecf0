//! One value of a config set from the command line (`--set PATH=VALUE`) or swept
//! (`--sweep PATH=V1,V2,…`), then checked exactly as the file is.
//!
//! A path names tables by key and entries of a list of tables by their `name` or
//! `kind` (or their index): `objects.bottle.wet_friction`,
//! `effects.object_flow.mean_m_s`, `effects.3.strength`. A value is TOML (`0.2`,
//! `[0.1, 0.2]`, `"glass"`, `true`); a word that is no TOML value is taken as text. The
//! last key may be one the file leaves out (an optional field), never one the config
//! does not know.

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::config::{Check, ConfigError, ConfigSource, Problem, Validate};

/// The longest value echoed back in a message, characters.
const ECHO_CHARS: usize = 60;

/// `PATH=VALUE`, parsed.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// Dotted path of the value.
    pub path: String,
    /// The value.
    pub value: toml::Value,
}

/// The text of `s`, cut to [`ECHO_CHARS`] for a message.
fn echo(s: &str) -> String {
    if s.chars().count() > ECHO_CHARS {
        format!(
            "{}… ({} characters)",
            s.chars().take(ECHO_CHARS).collect::<String>(),
            s.chars().count()
        )
    } else {
        s.to_owned()
    }
}

/// A message that may quote a whole value, cut to a few lines.
fn echo_long(s: &str) -> String {
    let cap = 4 * ECHO_CHARS;
    if s.chars().count() > cap {
        format!("{}…", s.chars().take(cap).collect::<String>())
    } else {
        s.to_owned()
    }
}

/// A value as typed: TOML where it is TOML, else the text itself.
fn parse_value(text: &str) -> toml::Value {
    format!("v = {text}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_owned()))
}

/// The path of `PATH=...`, checked: dotted keys, none empty.
fn parse_path(text: &str, whole: &str) -> Result<String, String> {
    let path = text.trim();
    if path.is_empty() || path.split('.').any(|k| k.trim().is_empty()) {
        return Err(format!(
            "`{}`: expected PATH=VALUE with a dotted path such as objects.bottle.wet_friction",
            echo(whole)
        ));
    }
    Ok(path.split('.').map(str::trim).collect::<Vec<_>>().join("."))
}

impl std::str::FromStr for Override {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let Some((path, value)) = s.split_once('=') else {
            return Err(format!(
                "`{}`: expected PATH=VALUE, for example objects.bottle.wet_friction=0.2",
                echo(s)
            ));
        };
        let value = value.trim();
        if value.is_empty() {
            return Err(format!("`{}`: expected a value after `=`", echo(s)));
        }
        Ok(Self {
            path: parse_path(path, s)?,
            value: parse_value(value),
        })
    }
}

impl std::fmt::Display for Override {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}={}", self.path, shown(&self.value))
    }
}

/// A value as a person typed it (text unquoted).
#[must_use]
pub fn shown(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// `PATH=V1,V2,…`: one path and the values it takes in turn.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// Dotted path of the value.
    pub path: String,
    /// The values, in order (at least two, none twice).
    pub values: Vec<toml::Value>,
}

impl std::str::FromStr for Sweep {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let Some((path, list)) = s.split_once('=') else {
            return Err(format!(
                "`{}`: expected PATH=V1,V2,…, for example objects.bottle.wet_friction=0.05,0.1,0.2",
                echo(s)
            ));
        };
        let path = parse_path(path, s)?;
        let mut values: Vec<toml::Value> = Vec::new();
        for item in list.split(',').map(str::trim) {
            if item.is_empty() {
                return Err(format!(
                    "`{}`: expected values separated by commas, none empty",
                    echo(s)
                ));
            }
            let v = parse_value(item);
            if values.contains(&v) {
                return Err(format!("`{}`: the value {item} is given twice", echo(s)));
            }
            values.push(v);
        }
        if values.len() < 2 {
            return Err(format!(
                "`{}`: expected at least two values to sweep (one is --set)",
                echo(s)
            ));
        }
        if values.len() > 50 {
            return Err(format!(
                "`{}`: expected at most 50 values, found {}",
                echo(s),
                values.len()
            ));
        }
        Ok(Self { path, values })
    }
}

impl Sweep {
    /// The override of its `i`-th value.
    #[must_use]
    pub fn at(&self, i: usize) -> Option<Override> {
        Some(Override {
            path: self.path.clone(),
            value: self.values.get(i)?.clone(),
        })
    }
}

/// Where a path's walk ended short: the key it did not find and what was there.
fn walk<'a>(root: &'a mut toml::Value, keys: &[&str]) -> Result<&'a mut toml::Value, String> {
    let mut here = root;
    let mut at = String::new();
    for key in keys {
        let name = if at.is_empty() {
            (*key).to_owned()
        } else {
            format!("{at}.{key}")
        };
        here = match here {
            toml::Value::Table(t) => {
                let known: Vec<String> = t.keys().cloned().collect();
                t.get_mut(*key).ok_or_else(|| {
                    format!(
                        "no `{name}` (there: {})",
                        if known.is_empty() {
                            "nothing".into()
                        } else {
                            known.join(", ")
                        }
                    )
                })?
            }
            toml::Value::Array(items) => {
                let label = |v: &toml::Value| {
                    v.get("name")
                        .or_else(|| v.get("kind"))
                        .and_then(toml::Value::as_str)
                        .map(str::to_owned)
                };
                let labels: Vec<String> = items
                    .iter()
                    .enumerate()
                    .map(|(i, v)| label(v).unwrap_or_else(|| i.to_string()))
                    .collect();
                let found: Vec<usize> = match key.parse::<usize>() {
                    Ok(i) if i < items.len() => vec![i],
                    _ => labels
                        .iter()
                        .enumerate()
                        .filter(|(_, l)| l.as_str() == *key)
                        .map(|(i, _)| i)
                        .collect(),
                };
                match found.as_slice() {
                    [i] => &mut items[*i],
                    [] => {
                        return Err(format!(
                            "no entry `{key}` in `{at}` (its entries by name, kind or index: {})",
                            if labels.is_empty() {
                                "none".into()
                            } else {
                                labels.join(", ")
                            }
                        ));
                    }
                    _ => {
                        return Err(format!(
                            "`{key}` names {} entries of `{at}`: give its index",
                            found.len()
                        ));
                    }
                }
            }
            _ => {
                return Err(format!(
                    "`{at}` is a value, not a table: nothing inside it to set"
                ));
            }
        };
        at = name;
    }
    Ok(here)
}

/// Whether `path`'s parent exists in `config` (the override can apply there).
#[must_use]
pub fn applies_to<T: Serialize>(config: &T, path: &str) -> bool {
    let Ok(mut root) = toml::Value::try_from(config) else {
        return false;
    };
    let keys: Vec<&str> = path.split('.').collect();
    let Some((_, parent)) = keys.split_last() else {
        return false;
    };
    matches!(walk(&mut root, parent), Ok(toml::Value::Table(_)))
}

/// The value at `path` in `config`, where there is one (the value a sweep starts from).
#[must_use]
pub fn value_at<T: Serialize>(config: &T, path: &str) -> Option<toml::Value> {
    let mut root = toml::Value::try_from(config).ok()?;
    let keys: Vec<&str> = path.split('.').collect();
    walk(&mut root, &keys).ok().cloned()
}

/// Where `path`'s walk through `config` goes astray (`None`: its parent is there).
#[must_use]
pub fn astray<T: Serialize>(config: &T, path: &str) -> Option<String> {
    let mut root = toml::Value::try_from(config).ok()?;
    let keys: Vec<&str> = path.split('.').collect();
    let (_, parent) = keys.split_last()?;
    match walk(&mut root, parent) {
        Ok(toml::Value::Table(_)) => None,
        Ok(_) => Some(format!("`{}` is not a table", parent.join("."))),
        Err(e) => Some(e),
    }
}

/// `config` with each override set in turn, then read and checked as its file would
/// be. A problem names the override and where the path went astray, under `source`.
///
/// # Errors
/// A path that leads nowhere, a value of the wrong type, or a config that no longer
/// passes its checks.
pub fn apply<T>(config: &T, overrides: &[Override], source: &ConfigSource) -> Result<T, ConfigError>
where
    T: Serialize + DeserializeOwned + Validate,
{
    let fail = |field: String, message: String| ConfigError {
        file: source.clone(),
        problems: vec![Problem {
            field,
            line: None,
            message,
        }],
    };
    let mut root = toml::Value::try_from(config)
        .map_err(|e| fail(String::new(), format!("cannot take the config apart: {e}")))?;
    for o in overrides {
        let keys: Vec<&str> = o.path.split('.').collect();
        let Some((last, parent)) = keys.split_last() else {
            return Err(fail(o.path.clone(), "expected a path".into()));
        };
        let said = format!("--set {}", echo(&o.to_string()));
        match walk(&mut root, parent).map_err(|e| fail(o.path.clone(), format!("{said}: {e}")))? {
            toml::Value::Table(t) => {
                t.insert((*last).to_owned(), o.value.clone());
            }
            _ => {
                return Err(fail(
                    o.path.clone(),
                    format!("{said}: `{}` is not a table", parent.join(".")),
                ));
            }
        }
    }
    let set: Vec<String> = overrides.iter().map(|o| echo(&o.to_string())).collect();
    let set = set.join(", --set ");
    let named = root.clone();
    let value: T = serde_path_to_error::deserialize(root).map_err(|e| {
        let field = e.path().to_string();
        fail(
            if field == "." {
                String::new()
            } else {
                by_name(&named, &field)
            },
            format!("{} (with --set {set})", echo_long(&e.inner().to_string())),
        )
    })?;
    let mut check = Check::default();
    value.validate(&mut check);
    // A value the checks refuse is said as the --set that made it, and by the names
    // the --set path used (`objects.bottle`, not `objects[3]`).
    check.finish(source).map_err(|mut e| {
        for p in &mut e.problems {
            p.field = by_name(&named, &p.field);
            p.message = format!("{} (with --set {set})", p.message);
        }
        e
    })?;
    Ok(value)
}

/// `field` (`objects[3].mass_kg`) with each list entry that has a `name` (or a `kind`)
/// in `root` said by it, as a `--set` path says it: `objects.bottle.mass_kg`. Entries
/// without either, and anything that does not resolve, stay as they are.
fn by_name(root: &toml::Value, field: &str) -> String {
    let mut at = Some(root);
    let mut out: Vec<String> = Vec::new();
    for part in field.split('.') {
        let (key, index) = match part.split_once('[') {
            Some((k, rest)) => (
                k,
                rest.strip_suffix(']').and_then(|i| i.parse::<usize>().ok()),
            ),
            None => (part, None),
        };
        let list = at.and_then(|v| v.get(key));
        match index {
            Some(i) => {
                let entry = list.and_then(|l| l.get(i));
                let name = entry.and_then(|e| {
                    e.get("name")
                        .or_else(|| e.get("kind"))
                        .and_then(toml::Value::as_str)
                });
                match name {
                    Some(n) if !n.contains('.') => out.push(format!("{key}.{n}")),
                    _ => out.push(part.to_owned()),
                }
                at = entry;
            }
            None => {
                out.push(part.to_owned());
                at = list;
            }
        }
    }
    out.join(".")
}
