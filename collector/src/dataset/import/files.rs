//! Reading and checking the input files: text, CSV records, fields (numbers, torques
//! in N·mm, indices), image paths and the images themselves. Every error names the
//! file, line and column.

use super::{Item, Layout, PAPER_CSV};
use crate::dataset::export::{encode_png, sha256_hex};
use crate::dataset::{DatasetError, csv};
use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

pub(super) fn malformed(
    path: &Path,
    line: usize,
    column: usize,
    message: impl Into<String>,
) -> DatasetError {
    DatasetError::Malformed {
        path: path.to_owned(),
        line,
        column,
        message: message.into(),
    }
}

pub(super) fn read_text(path: &Path) -> Result<String, DatasetError> {
    let bytes = std::fs::read(path).map_err(DatasetError::io("read", path))?;
    String::from_utf8(bytes).map_err(|e| malformed(path, 0, 0, format!("not UTF-8 text: {e}")))
}

pub(super) fn parse_records(path: &Path, text: &str) -> Result<Vec<csv::Record>, DatasetError> {
    csv::parse(text).map_err(|e| malformed(path, e.line, e.column, e.message))
}

/// A finite number, or an error naming the line, the column and its header.
pub(super) fn number(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<f64, DatasetError> {
    let v: f64 = text.trim().parse().map_err(|_| {
        malformed(
            path,
            line,
            column,
            format!("{header}: `{text}` is not a number"),
        )
    })?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(malformed(
            path,
            line,
            column,
            format!("{header}: `{text}` is not finite"),
        ))
    }
}

/// A finite torque in N·mm as text, converted exactly to N·m.
pub(super) fn torque_nm(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<f64, DatasetError> {
    number(path, line, column, header, text)?;
    csv::nmm_text_to_nm(text)
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            malformed(
                path,
                line,
                column,
                format!("{header}: `{text}` is out of range"),
            )
        })
}

pub(super) fn integer(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<i64, DatasetError> {
    text.trim()
        .parse::<i64>()
        .ok()
        .filter(|v| *v >= 0)
        .ok_or_else(|| {
            malformed(
                path,
                line,
                column,
                format!("{header}: `{text}` is not a whole number ≥ 0"),
            )
        })
}

/// An image path inside `dir`: relative, no `..`, and the file exists.
pub(super) fn check_image(
    dir: &Path,
    csv_path: &Path,
    line: usize,
    image: &str,
) -> Result<(), DatasetError> {
    let rel = Path::new(image);
    if image.is_empty()
        || rel.is_absolute()
        || rel
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(malformed(
            csv_path,
            line,
            1,
            format!("image path `{image}` must be relative to the folder, without `..`"),
        ));
    }
    if !dir.join(rel).is_file() {
        return Err(malformed(
            csv_path,
            line,
            1,
            format!(
                "image `{image}` is missing ({} not found)",
                dir.join(rel).display()
            ),
        ));
    }
    Ok(())
}

pub(super) fn check_columns(
    path: &Path,
    line: usize,
    found: usize,
    expected: usize,
) -> Result<(), DatasetError> {
    if found == expected {
        return Ok(());
    }
    Err(malformed(
        path,
        line,
        found.min(expected) + 1,
        format!("expected {expected} columns, found {found}"),
    ))
}

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// Read an item's image: PNG bytes as they are (dimensions from the header), anything
/// else decoded and re-encoded as PNG. Checks the manifest's sha256 where given.
pub(super) fn load_image(
    dir: &Path,
    item: &Item,
    layout: Layout,
    checksums: Option<&BTreeMap<String, String>>,
) -> Result<(Vec<u8>, u32, u32), DatasetError> {
    let path: PathBuf = dir.join(&item.image);
    let csv_name = match layout {
        Layout::SofttouchExport => dir.join("labels.csv"),
        Layout::PaperCsv => dir.join(PAPER_CSV),
    };
    let bad = |message: String| malformed(&csv_name, item.line, 1, message);
    let bytes = std::fs::read(&path).map_err(DatasetError::io("read", &path))?;
    if let Some(sums) = checksums {
        match sums.get(&item.image) {
            Some(expected) if *expected == sha256_hex(&bytes) => {}
            Some(_) => {
                return Err(bad(format!(
                    "image `{}`: sha256 does not match the manifest",
                    item.image
                )));
            }
            None => {
                return Err(bad(format!(
                    "image `{}` has no sha256 in the manifest",
                    item.image
                )));
            }
        }
    }
    if bytes.starts_with(&PNG_SIGNATURE) {
        let (w, h) =
            image::ImageReader::with_format(std::io::Cursor::new(&bytes), image::ImageFormat::Png)
                .into_dimensions()
                .map_err(|e| bad(format!("image `{}`: {e}", item.image)))?;
        return Ok((bytes, w, h));
    }
    let rgb = image::load_from_memory(&bytes)
        .map_err(|e| bad(format!("image `{}` does not decode: {e}", item.image)))?
        .to_rgb8();
    let (w, h) = rgb.dimensions();
    let png = encode_png(&rgb).map_err(|e| bad(format!("image `{}`: {e}", item.image)))?;
    Ok((png, w, h))
}
