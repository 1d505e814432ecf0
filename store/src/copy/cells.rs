//! Cells: a row read as typed (column, value) pairs that both engines store alike,
//! bound back into an insert, hashed and compared.

use super::*;

/// One column's value, typed as both engines store it.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Cell {
    /// NULL, with its column's type (PostgreSQL wants a typed NULL).
    Null(AnyTypeInfoKind),
    Int(i64),
    Real(f64),
    Text(String),
    Blob(Vec<u8>),
}

impl Cell {
    pub(super) fn hash_into(&self, h: &mut Sha256) {
        match self {
            Self::Null(_) => h.update([0u8]),
            Self::Int(v) => {
                h.update([1u8]);
                h.update(v.to_le_bytes());
            }
            Self::Real(v) => {
                h.update([2u8]);
                h.update(v.to_bits().to_le_bytes());
            }
            Self::Text(v) => {
                h.update([3u8]);
                h.update((v.len() as u64).to_le_bytes());
                h.update(v.as_bytes());
            }
            Self::Blob(v) => {
                h.update([4u8]);
                h.update((v.len() as u64).to_le_bytes());
                h.update(v);
            }
        }
    }
}

/// A row as (column, cell) pairs.
pub(super) type Cells = Vec<(String, Cell)>;

pub(super) fn read_cells(row: &AnyRow) -> Result<Cells, StoreError> {
    let damaged = |why: String| StoreError::Damaged {
        what: "row being copied",
        why,
    };
    let mut out = Vec::with_capacity(row.columns().len());
    for (i, column) in row.columns().iter().enumerate() {
        let name = column.name().to_owned();
        let raw = row
            .try_get_raw(i)
            .map_err(|e| damaged(format!("{name}: {e}")))?;
        let declared = column.type_info().kind();
        let cell = if raw.is_null() {
            Cell::Null(declared)
        } else {
            let kind = raw.type_info().kind();
            let get = |e: sqlx::Error| damaged(format!("{name}: {e}"));
            match kind {
                AnyTypeInfoKind::Bool
                | AnyTypeInfoKind::SmallInt
                | AnyTypeInfoKind::Integer
                | AnyTypeInfoKind::BigInt => Cell::Int(row.try_get::<i64, _>(i).map_err(get)?),
                AnyTypeInfoKind::Real | AnyTypeInfoKind::Double => {
                    Cell::Real(row.try_get::<f64, _>(i).map_err(get)?)
                }
                AnyTypeInfoKind::Text => Cell::Text(row.try_get::<String, _>(i).map_err(get)?),
                AnyTypeInfoKind::Blob => Cell::Blob(row.try_get::<Vec<u8>, _>(i).map_err(get)?),
                AnyTypeInfoKind::Null => Cell::Null(declared),
            }
        };
        out.push((name, cell));
    }
    Ok(out)
}

pub(super) type Query<'q> = sqlx::query::Query<'q, Any, AnyArguments>;

pub(super) fn bind(q: Query<'_>, cell: Cell) -> Query<'_> {
    match cell {
        Cell::Int(v) => q.bind(v),
        Cell::Real(v) => q.bind(v),
        Cell::Text(v) => q.bind(v),
        Cell::Blob(v) => q.bind(v),
        Cell::Null(kind) => match kind {
            AnyTypeInfoKind::Real | AnyTypeInfoKind::Double => {
                q.bind(crate::dialect::NullableF64(None))
            }
            AnyTypeInfoKind::Text => q.bind(None::<String>),
            AnyTypeInfoKind::Blob => q.bind(None::<Vec<u8>>),
            _ => q.bind(None::<i64>),
        },
    }
}

/// A table or column name as SQL reads it: in double quotes, inner quotes doubled
/// (both engines), so a name is never read as SQL.
pub(super) fn quoted(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

/// sha256 of a row's cells, leaving out the columns `skip`.
pub(super) fn row_digest(cells: &Cells, skip: &[&str]) -> [u8; 32] {
    let mut h = Sha256::new();
    for (column, cell) in cells {
        if !skip.contains(&column.as_str()) {
            h.update((column.len() as u64).to_le_bytes());
            h.update(column.as_bytes());
            cell.hash_into(&mut h);
        }
    }
    h.finalize().into()
}

/// Whether two cells hold the same value (bit for bit; a NULL of any declared type is
/// NULL).
pub(super) fn same(a: &Cell, b: &Cell) -> bool {
    let digest = |c: &Cell| {
        let mut h = Sha256::new();
        c.hash_into(&mut h);
        h.finalize()
    };
    digest(a) == digest(b)
}

/// The cells that differ between two rows (columns `skip` aside), as `column: a ≠ b`.
pub(super) fn differences(a: &Cells, b: &Cells, skip: &[&str]) -> Vec<String> {
    let show = |c: &Cell| match c {
        Cell::Null(_) => "NULL".to_owned(),
        Cell::Int(v) => v.to_string(),
        Cell::Real(v) => v.to_string(),
        Cell::Text(v) if v.chars().count() > 40 => {
            format!("{:?}…", v.chars().take(40).collect::<String>())
        }
        Cell::Text(v) => format!("{v:?}"),
        Cell::Blob(v) => format!("{} bytes", v.len()),
    };
    a.iter()
        .filter(|(column, _)| !skip.contains(&column.as_str()))
        .filter_map(|(column, x)| {
            let y = b.iter().find(|(c, _)| c == column).map(|(_, y)| y);
            match y {
                Some(y) if same(x, y) => None,
                Some(y) => Some(format!("{column}: {} here, {} there", show(x), show(y))),
                None => Some(format!("{column}: not at the destination")),
            }
        })
        .collect()
}

pub(super) fn columns_and_marks(cells: &Cells) -> (String, String) {
    let columns: Vec<String> = cells.iter().map(|(c, _)| quoted(c)).collect();
    let marks = vec!["?"; cells.len()].join(", ");
    (columns.join(", "), marks)
}

/// `INSERT INTO table (its cells' columns) VALUES (…) tail`, the cells bound.
pub(super) fn insert(d: Dialect, table: &str, cells: Cells, tail: &str) -> Query<'static> {
    let (columns, marks) = columns_and_marks(&cells);
    let mut q = sqlx::query(d.sql_owned(format!(
        "INSERT INTO {} ({columns}) VALUES ({marks}) {tail}",
        quoted(table)
    )));
    for (_, cell) in cells {
        q = bind(q, cell);
    }
    q
}

pub(super) async fn insert_returning(
    tx: &mut AnyConnection,
    d: Dialect,
    table: &str,
    id_col: &str,
    cells: Cells,
) -> Result<i64, StoreError> {
    insert(d, table, cells, &format!("RETURNING {}", quoted(id_col)))
        .fetch_one(&mut *tx)
        .await
        .map_err(query_err("copying an object"))?
        .try_get::<i64, _>(0)
        .map_err(query_err("reading a new id"))
}
