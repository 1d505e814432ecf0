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

/// Read an item's image: PNG bytes as they are (a softtouch export's checked by sha256
/// and header, the paper's decoded in full), anything else decoded and re-encoded as
/// PNG. Checks the manifest's sha256 where given.
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
        // Stored byte for byte. A softtouch export's sha256 vouches for the bytes we
        // wrote, so its header suffices; the paper's files carry no checksum, so they
        // are decoded in full: a truncated or corrupt image is refused here, not found
        // by training later.
        let (w, h) = match layout {
            Layout::SofttouchExport => image::ImageReader::with_format(
                std::io::Cursor::new(&bytes),
                image::ImageFormat::Png,
            )
            .into_dimensions()
            .map_err(|e| bad(format!("image `{}`: {e}", item.image)))?,
            Layout::PaperCsv => {
                let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
                    .map_err(|e| bad(format!("image `{}` does not decode: {e}", item.image)))?;
                (img.width(), img.height())
            }
        };
        return Ok((bytes, w, h));
    }
    let rgb = image::load_from_memory(&bytes)
        .map_err(|e| bad(format!("image `{}` does not decode: {e}", item.image)))?
        .to_rgb8();
    let (w, h) = rgb.dimensions();
    let png = encode_png(&rgb).map_err(|e| bad(format!("image `{}`: {e}", item.image)))?;
    Ok((png, w, h))
}

/// Checks a run's `created_at` from a manifest and returns it in the store's form
/// (`YYYY-MM-DDTHH:MM:SS.fffZ`, UTC): an RFC 3339 UTC timestamp
/// `YYYY-MM-DDTHH:MM:SS[.fraction]Z` with a real calendar date. Anything else would
/// be stored as is and break every query that orders or measures runs by time.
pub(super) fn created_at(text: &str) -> Result<String, String> {
    let expected = || {
        format!(
            "`{}` is not a UTC timestamp YYYY-MM-DDTHH:MM:SS[.fff]Z",
            text.chars().take(40).collect::<String>()
        )
    };
    let b = text.as_bytes();
    let digits = |r: std::ops::Range<usize>| -> Option<u32> {
        let s = text.get(r)?;
        if s.bytes().all(|c| c.is_ascii_digit()) {
            s.parse().ok()
        } else {
            None
        }
    };
    if b.len() < 20
        || b[4] != b'-'
        || b[7] != b'-'
        || !(b[10] == b'T' || b[10] == b't')
        || b[13] != b':'
        || b[16] != b':'
        || !(b[b.len() - 1] == b'Z' || b[b.len() - 1] == b'z')
    {
        return Err(expected());
    }
    let (Some(year), Some(month), Some(day), Some(hour), Some(minute), Some(second)) = (
        digits(0..4),
        digits(5..7),
        digits(8..10),
        digits(11..13),
        digits(14..16),
        digits(17..19),
    ) else {
        return Err(expected());
    };
    // A fraction of one or more digits, or none.
    let fraction = &text[19..text.len() - 1];
    let millis = match fraction.strip_prefix('.') {
        None if fraction.is_empty() => 0,
        Some(f) if !f.is_empty() && f.bytes().all(|c| c.is_ascii_digit()) => {
            let mut ms = 0u32;
            for (i, c) in f.bytes().take(3).enumerate() {
                ms += u32::from(c - b'0') * [100, 10, 1][i];
            }
            ms
        }
        _ => return Err(expected()),
    };
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    let days = match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return Err(format!("{}: month {month} does not exist", expected())),
    };
    if !(1..=days).contains(&day) || hour > 23 || minute > 59 || second > 59 {
        return Err(format!("{}: no such date or time of day", expected()));
    }
    Ok(format!(
        "{year:04}-{month:02}-{day:02}T{hour:02}:{minute:02}:{second:02}.{millis:03}Z"
    ))
}

#[cfg(test)]
mod tests {
    use super::created_at;

    #[test]
    fn created_at_takes_utc_timestamps_and_refuses_the_rest() {
        for (given, stored) in [
            ("2026-11-24T07:01:37.123Z", "2026-11-24T07:01:37.123Z"),
            ("2026-11-24T07:01:37Z", "2026-11-24T07:01:37.000Z"),
            ("2024-02-29t23:59:59.9999z", "2024-02-29T23:59:59.999Z"),
        ] {
            assert_eq!(created_at(given).as_deref(), Ok(stored), "{given}");
        }
        for bad in [
            "",
            "yesterday",
            "now",
            "2026-11-24",
            "2026-11-24 07:01:37",
            "2026-11-24T07:01:37+02:00",
            "2026-13-01T00:00:00Z",
            "2025-02-29T00:00:00Z",
            "2026-04-31T00:00:00Z",
            "2026-11-24T24:00:00Z",
            "2026-11-24T07:60:00Z",
            "2026-11-24T07:01:37.Z",
            "2026-11-24T07:01:37.12aZ",
            "+026-11-24T07:01:37Z",
            "2026-11-24T07:01:37Zjunk",
            "2026-11-24T07:01:3\u{e9}Z",
        ] {
            let e = created_at(bad).expect_err(bad);
            assert!(e.contains("not a UTC timestamp"), "{e}");
        }
    }
}
