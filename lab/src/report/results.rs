//! The experiment verbs' stored results (`softtouch results`), as the page reads them:
//! the latest result of each verb, and its tables parsed by column name. A table that
//! does not parse costs its part of the page (a note says what), never the page.

use crate::store::{ResultRow, StoredResult};

/// Every stored result, oldest first.
#[derive(Debug, Clone, Default)]
pub(crate) struct Results {
    pub all: Vec<StoredResult>,
}

impl Results {
    /// The newest result of `verb`.
    pub(crate) fn latest(&self, verb: &str) -> Option<&StoredResult> {
        self.all.iter().rev().find(|r| r.row.verb == verb)
    }

    /// Every result of `verb`, oldest first.
    pub(crate) fn of<'a>(&'a self, verb: &'a str) -> impl Iterator<Item = &'a StoredResult> {
        self.all.iter().filter(move |r| r.row.verb == verb)
    }
}

/// A stored CSV table, by column.
#[derive(Debug, Clone)]
pub(crate) struct Columns {
    source: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Columns {
    /// Table `name` of result `r`, parsed.
    pub(crate) fn of(r: &StoredResult, name: &str) -> Result<Self, String> {
        let source = format!("result {} table {name}", r.row.result_id);
        let text = r
            .table(name)
            .ok_or_else(|| format!("{source}: not stored"))?;
        Self::parse(source, text)
    }

    /// Parses CSV text (no quoting: the verbs' tables hold none).
    pub(crate) fn parse(source: String, text: &str) -> Result<Self, String> {
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header: Vec<String> = lines
            .next()
            .ok_or_else(|| format!("{source}: empty, expected a header line"))?
            .split(',')
            .map(|c| c.trim().to_owned())
            .collect();
        let mut rows = Vec::new();
        for (i, line) in lines.enumerate() {
            let fields: Vec<String> = line.split(',').map(|c| c.trim().to_owned()).collect();
            if fields.len() != header.len() {
                return Err(format!(
                    "{source}, line {}: {} fields, expected {} as in the header",
                    i + 2,
                    fields.len(),
                    header.len()
                ));
            }
            rows.push(fields);
        }
        Ok(Self {
            source,
            header,
            rows,
        })
    }

    /// Rows.
    pub(crate) fn len(&self) -> usize {
        self.rows.len()
    }

    fn index(&self, column: &str) -> Result<usize, String> {
        self.header
            .iter()
            .position(|c| c == column)
            .ok_or_else(|| format!("{}: no column `{column}`", self.source))
    }

    /// A column as text.
    pub(crate) fn text(&self, column: &str) -> Result<Vec<&str>, String> {
        let i = self.index(column)?;
        Ok(self.rows.iter().map(|r| r[i].as_str()).collect())
    }

    /// A column as numbers; an empty field or `–` is NaN.
    pub(crate) fn num(&self, column: &str) -> Result<Vec<f64>, String> {
        let i = self.index(column)?;
        self.rows
            .iter()
            .enumerate()
            .map(|(line, r)| match r[i].as_str() {
                "" | "–" | "-" => Ok(f64::NAN),
                v => v.parse::<f64>().map_err(|_| {
                    format!(
                        "{}, line {}: column `{column}`: `{v}` is not a number",
                        self.source,
                        line + 2
                    )
                }),
            })
            .collect()
    }
}

/// Provenance of a result in one line: verb, id, when, model and its hash, dataset,
/// scene or rig, software.
pub(crate) fn provenance(r: &ResultRow) -> String {
    let short = |s: &Option<String>| {
        s.as_deref()
            .map(|h| h[..12.min(h.len())].to_owned())
            .unwrap_or_default()
    };
    let mut parts = vec![format!(
        "softtouch {}, result {}, stored {}",
        r.verb, r.result_id, r.created_at
    )];
    if let Some(m) = &r.model {
        parts.push(format!("model {m} (sha256 {})", short(&r.model_sha256)));
    }
    if let Some(d) = &r.dataset {
        parts.push(format!("dataset {d}"));
    }
    if r.scene_hash.is_some() {
        parts.push(format!("scene {}", short(&r.scene_hash)));
    }
    if r.rig_hash.is_some() {
        parts.push(format!("rig {}", short(&r.rig_hash)));
    }
    parts.push(format!(
        "softtouch {}{}",
        r.software_version,
        r.software_commit
            .as_deref()
            .map_or_else(String::new, |c| format!(" ({})", &c[..10.min(c.len())]))
    ));
    parts.push(format!("settings: {}", settings_line(&r.settings_json)));
    parts.join("; ")
}

/// A settings object as `name = value` pairs (unset ones left out), so that a long
/// one wraps.
pub(crate) fn settings_line(json: &str) -> String {
    match serde_json::from_str::<serde_json::Value>(json) {
        Ok(serde_json::Value::Object(map)) => map
            .iter()
            .filter(|(_, v)| !v.is_null())
            .map(|(k, v)| match v {
                serde_json::Value::String(s) => format!("{k} = {s}"),
                other => format!("{k} = {other}").replace(',', ", "),
            })
            .collect::<Vec<_>>()
            .join(", "),
        _ => json.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_read_by_name_and_bad_tables_say_where() {
        let t = Columns::parse("t".into(), "a,b\n1,\n2.5,x\n").expect("test step");
        assert_eq!(t.len(), 2);
        let a = t.num("a").expect("test step");
        assert!((a[1] - 2.5).abs() < 1e-12);
        assert_eq!(t.text("b").expect("test step"), ["", "x"]);
        let e = t.num("b").expect_err("must fail");
        assert!(e.contains("line 3") && e.contains("`b`"), "{e}");
        assert!(t.num("c").expect_err("must fail").contains("no column `c`"));
        assert!(Columns::parse("t".into(), "").is_err());
        let e = Columns::parse("t".into(), "a,b\n1\n").expect_err("must fail");
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn settings_read_as_pairs_without_the_unset_ones() {
        assert_eq!(
            settings_line(r#"{"a":[1,2],"b":null,"c":"x"}"#),
            "a = [1, 2], c = x"
        );
        assert_eq!(settings_line("[1]"), "[1]");
    }
}
