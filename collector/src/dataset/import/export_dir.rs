//! The softtouch export layout: `manifest.json`, `labels.csv`, `images/`.

use super::files::{
    check_columns, check_image, integer, malformed, number, parse_records, read_text, torque_nm,
};
use super::{ImportOptions, Item, Layout, NewImportedRun, Plan};
use crate::dataset::export::sha256_hex;
use crate::dataset::manifest::{LABEL_COLUMNS, MANIFEST_FORMAT, Manifest};
use crate::dataset::{DatasetError, EXPORT_FORMAT_VERSION, Split};
use softtouch_schemas::Medium;
use std::collections::HashSet;
use std::path::Path;

/// Read and check an export: the manifest's runs and dataset (renamed by `--name`),
/// members in file order with their splits.
pub(super) fn plan(
    dir: &Path,
    source: &Path,
    options: &ImportOptions,
) -> Result<Plan, DatasetError> {
    let (manifest, items) = read_export(dir)?;
    let name = options
        .name
        .clone()
        .unwrap_or_else(|| manifest.dataset.name.clone());
    let mut definition = manifest.dataset.definition.clone();
    definition.imported_from = Some(serde_json::json!({
        "layout": Layout::SofttouchExport.as_str(),
        "path": source.display().to_string(),
        "dataset": manifest.dataset.name,
        "runs": definition.runs,
        "exported_at": manifest.exported_at,
        "software_version": manifest.software_version,
    }));
    let runs = manifest_runs(&manifest, &items, &dir.join("manifest.json"))?;
    let splits = items
        .iter()
        .map(|i| i.split.unwrap_or(Split::Train))
        .collect();
    Ok(Plan {
        layout: Layout::SofttouchExport,
        items,
        runs,
        name,
        definition,
        checksums: Some(manifest.sha256),
        splits,
    })
}

fn read_export(dir: &Path) -> Result<(Manifest, Vec<Item>), DatasetError> {
    let manifest_path = dir.join("manifest.json");
    let text = read_text(&manifest_path)?;
    let manifest: Manifest = serde_json::from_str(&text)
        .map_err(|e| malformed(&manifest_path, e.line(), e.column(), e.to_string()))?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(malformed(
            &manifest_path,
            0,
            0,
            format!(
                "format is `{}`, expected `{MANIFEST_FORMAT}`",
                manifest.format
            ),
        ));
    }
    if manifest.format_version > EXPORT_FORMAT_VERSION {
        return Err(malformed(
            &manifest_path,
            0,
            0,
            format!(
                "format version {} is newer than this build reads ({EXPORT_FORMAT_VERSION})",
                manifest.format_version
            ),
        ));
    }
    let labels_path = dir.join("labels.csv");
    let text = read_text(&labels_path)?;
    if let Some(expected) = manifest.sha256.get("labels.csv")
        && *expected != sha256_hex(text.as_bytes())
    {
        return Err(malformed(
            &labels_path,
            0,
            0,
            "sha256 does not match the manifest: the file was changed or damaged",
        ));
    }
    let records = parse_records(&labels_path, &text)?;
    let mut records = records.into_iter();
    let header = records
        .next()
        .ok_or_else(|| malformed(&labels_path, 1, 0, "empty file: no header"))?;
    for (i, expected) in LABEL_COLUMNS.iter().enumerate() {
        let got = header.fields.get(i).map(String::as_str);
        if got != Some(expected) {
            return Err(malformed(
                &labels_path,
                header.line,
                i + 1,
                format!(
                    "header: expected `{expected}`, found {}",
                    got.map_or("nothing".into(), |g| format!("`{g}`"))
                ),
            ));
        }
    }
    if header.fields.len() != LABEL_COLUMNS.len() {
        return Err(malformed(
            &labels_path,
            header.line,
            LABEL_COLUMNS.len() + 1,
            format!(
                "header: expected {} columns, found {}",
                LABEL_COLUMNS.len(),
                header.fields.len()
            ),
        ));
    }
    let known_runs: HashSet<i64> = manifest.runs.iter().map(|r| r.run).collect();
    let mut seen = HashSet::new();
    let mut items = Vec::new();
    for r in records {
        let f = &r.fields;
        check_columns(&labels_path, r.line, f.len(), LABEL_COLUMNS.len())?;
        let num = |c: usize| number(&labels_path, r.line, c + 1, LABEL_COLUMNS[c], &f[c]);
        let nm = |c: usize| torque_nm(&labels_path, r.line, c + 1, LABEL_COLUMNS[c], &f[c]);
        let wrench = [num(1)?, num(2)?, num(3)?, nm(4)?, nm(5)?, nm(6)?];
        let pose = [num(7)?, num(8)?, num(9)?];
        let rod = f[10].clone();
        if rod.is_empty() {
            return Err(malformed(&labels_path, r.line, 11, "rod: empty"));
        }
        let medium: Medium = f[11]
            .parse()
            .map_err(|e: String| malformed(&labels_path, r.line, 12, format!("medium: {e}")))?;
        let split: Split = f[12]
            .parse()
            .map_err(|e: String| malformed(&labels_path, r.line, 13, format!("split: {e}")))?;
        let run = integer(&labels_path, r.line, 14, "run", &f[13])?;
        if !known_runs.contains(&run) {
            return Err(malformed(
                &labels_path,
                r.line,
                14,
                format!("run {run} is not among the manifest's runs"),
            ));
        }
        let index = integer(&labels_path, r.line, 15, "index", &f[14])?;
        if !seen.insert((run, index)) {
            return Err(malformed(
                &labels_path,
                r.line,
                15,
                format!("run {run} index {index} appears twice"),
            ));
        }
        check_image(dir, &labels_path, r.line, &f[0])?;
        items.push(Item {
            line: r.line,
            image: f[0].clone(),
            wrench,
            pose,
            rod,
            medium,
            split: Some(split),
            run,
            index,
        });
    }
    if items.is_empty() {
        return Err(malformed(&labels_path, 0, 0, "no samples"));
    }
    Ok((manifest, items))
}

fn manifest_runs(
    manifest: &Manifest,
    items: &[Item],
    manifest_path: &Path,
) -> Result<Vec<NewImportedRun>, DatasetError> {
    let used: HashSet<i64> = items.iter().map(|i| i.run).collect();
    let mut runs = Vec::new();
    let mut seen = HashSet::new();
    for r in &manifest.runs {
        if !used.contains(&r.run) || !seen.insert(r.run) {
            continue;
        }
        let medium: Medium = r.medium.parse().map_err(DatasetError::Invalid)?;
        let created_at = super::files::created_at(&r.created_at).map_err(|e| {
            DatasetError::Invalid(format!(
                "{}: run {}: field `created_at`: {e}",
                manifest_path.display(),
                r.run
            ))
        })?;
        runs.push(NewImportedRun {
            origin: Some(r.run),
            seed: r.seed,
            scene_name: r.scene_name.clone(),
            medium,
            rig_toml: r.rig_toml.clone(),
            scene_toml: r.scene_toml.clone(),
            software_version: r.software_version.clone(),
            schema_version: r.schema_version,
            created_at: Some(created_at),
            provenance: serde_json::to_value(r)
                .map(|mut v| {
                    // The configs are in the run row already.
                    if let Some(o) = v.as_object_mut() {
                        o.remove("rig_toml");
                        o.remove("scene_toml");
                    }
                    v
                })
                .unwrap_or(serde_json::Value::Null),
        });
    }
    Ok(runs)
}
