//! The paper's layout: `data_frame.csv` (image, then the wrench with torques in N·mm).

use super::files::{
    check_columns, check_image, malformed, number, parse_records, read_text, torque_nm,
};
use super::{ImportOptions, Item, Layout, NewImportedRun, PAPER_CSV, Plan};
use crate::dataset::{DatasetError, Definition, Filters, SPLIT_ALGORITHM, split};
use crate::store::Store;
use std::path::Path;

/// Read and check the CSV: one new run (medium, rod, ratio and seed from the options),
/// the dataset named by `--name` or the folder.
pub(super) fn plan(
    dir: &Path,
    source: &Path,
    options: &ImportOptions,
) -> Result<Plan, DatasetError> {
    let items = read_paper(dir, options)?;
    let name = match &options.name {
        Some(n) => n.clone(),
        None => source
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "imported".into()),
    };
    let splits = split::assign(items.len(), options.ratio, options.seed)?;
    let definition = Definition {
        runs: Vec::new(),
        filters: Filters::default(),
        split: options.ratio.to_string(),
        seed: options.seed,
        algorithm: SPLIT_ALGORITHM.into(),
        imported_from: Some(serde_json::json!({
            "layout": Layout::PaperCsv.as_str(),
            "path": source.display().to_string(),
            "units": "Fx Fy Fz in N, Tx Ty Tz in N·mm",
        })),
    };
    let run = NewImportedRun {
        origin: None,
        seed: options.seed,
        scene_name: "paper-import".into(),
        medium: options.medium,
        rig_toml: String::new(),
        scene_toml: String::new(),
        software_version: softtouch_schemas::SOFTWARE_VERSION.into(),
        schema_version: Store::schema_version(),
        created_at: None,
        provenance: serde_json::json!({
            "csv": source.join(PAPER_CSV).display().to_string(),
            "rod": options.rod,
            "medium": options.medium.as_str(),
        }),
    };
    Ok(Plan {
        layout: Layout::PaperCsv,
        items,
        runs: vec![run],
        name,
        definition,
        checksums: None,
        splits,
    })
}

fn read_paper(dir: &Path, options: &ImportOptions) -> Result<Vec<Item>, DatasetError> {
    if options.rod.is_empty() {
        return Err(DatasetError::Invalid("--rod must not be empty".into()));
    }
    let path = dir.join(PAPER_CSV);
    let text = read_text(&path)?;
    let records = parse_records(&path, &text)?;
    const HEADERS: [&str; 7] = [
        "image",
        "Fx (N)",
        "Fy (N)",
        "Fz (N)",
        "Tx (N·mm)",
        "Ty (N·mm)",
        "Tz (N·mm)",
    ];
    let mut items = Vec::new();
    for (k, r) in records.iter().enumerate() {
        let f = &r.fields;
        // A first row whose wrench fields are not numbers is a header.
        if k == 0
            && f.iter()
                .skip(1)
                .take(6)
                .all(|x| x.trim().parse::<f64>().is_err())
        {
            check_columns(&path, r.line, f.len(), 7)?;
            continue;
        }
        check_columns(&path, r.line, f.len(), 7)?;
        let mut wrench = [0.0; 6];
        for (c, w) in wrench.iter_mut().enumerate() {
            let (column, header, text) = (c + 2, HEADERS[c + 1], &f[c + 1]);
            *w = if c < 3 {
                number(&path, r.line, column, header, text)?
            } else {
                torque_nm(&path, r.line, column, header, text)?
            };
        }
        check_image(dir, &path, r.line, &f[0])?;
        items.push(Item {
            line: r.line,
            image: f[0].clone(),
            wrench,
            pose: [0.0; 3],
            rod: options.rod.clone(),
            medium: options.medium,
            split: None,
            run: 0,
            index: i64::try_from(items.len()).unwrap_or(i64::MAX),
        });
    }
    if items.is_empty() {
        return Err(malformed(&path, 0, 0, "no samples"));
    }
    Ok(items)
}
