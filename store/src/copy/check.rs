//! The object check: an object's row and its child tables' rows read back inside the
//! destination's transaction and compared with the snapshot's, as sets of digests;
//! and the error a copy stops with when its source diverged from what was copied.

use super::*;

/// Why a copy stops at an object its source no longer holds as copied: the store is a
/// clone or a restored backup of the one first copied under its uid.
pub(super) fn diverged(uid: &str, what: &str, why: &str) -> StoreError {
    StoreError::Invalid {
        what: "copy",
        why: format!(
            "{what} is not as it was copied from this store before ({why}). \
             The destination had it from a store of the same identity ({uid}): this store \
             is a copy of that one (a copied file, a restored backup) and has been written \
             since, or was rewound. Nothing of it was written. If it is a copy, give it an \
             identity of its own (`softtouch --db THIS_STORE db new-identity`) and copy \
             again: its objects are then copied as new ones"
        ),
    }
}

/// What a read of the destination inside the copy's transaction is doing.
pub(super) const READ_BACK: &str = "reading a copied object back";

/// The object `id`'s row on `conn` (the source's snapshot, or the destination inside
/// the copy's transaction), its columns as stored.
pub(super) async fn object_row(
    conn: &mut AnyConnection,
    kind: &Kind,
    id: i64,
    doing: &'static str,
) -> Result<Option<Cells>, StoreError> {
    let d = Dialect::of(conn);
    let row = sqlx::query(d.sql_owned(format!(
        "SELECT * FROM {} WHERE {} = ?",
        quoted(kind.table),
        quoted(kind.id)
    )))
    .bind(id)
    .fetch_optional(&mut *conn)
    .await
    .map_err(query_err(doing))?;
    row.as_ref().map(read_cells).transpose()
}

/// sha256 of each of a child table's rows of `parent` on `conn` (columns `skip` left
/// out; references mapped with `maps` for the source's rows), sorted: the rows as a
/// set, whatever order the server gives.
pub(super) async fn child_digests(
    conn: &mut AnyConnection,
    child: &Child,
    parent: i64,
    skip: &[&str],
    maps: Option<&Maps>,
) -> Result<Vec<[u8; 32]>, StoreError> {
    let mut digests = Vec::new();
    let mut rows = child.rows_of(conn, parent);
    while let Some(row) = rows
        .try_next()
        .await
        .map_err(query_err("reading rows to check"))?
    {
        let mut cells = read_cells(&row)?;
        if let Some(maps) = maps {
            map_refs(&mut cells, child.refs, maps, child.table)?;
        }
        digests.push(row_digest(&cells, skip));
    }
    digests.sort_unstable();
    Ok(digests)
}
