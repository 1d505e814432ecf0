//! `softtouch db copy`: runs, datasets, models, grasp sessions, calibrations and results
//! from one store into another, between any two engines, checked and never twice.
//!
//! - **One snapshot.** Everything is read from the source in one read transaction
//!   (REPEATABLE READ on PostgreSQL; one read transaction on SQLite), so a run still
//!   being collected is copied as it stood at one instant: a sample with its frame and
//!   window, never a sample without them. The next copy takes what came since.
//! - **Identities.** Ids are the destination's own (PostgreSQL's identities, SQLite's
//!   rowids): several rigs' runs 1 never collide. The destination records each copied
//!   object in `copied` (the source store's `uid`, the kind, the source id, the new id),
//!   in the same transaction as the object, so a killed copy leaves each object whole or
//!   absent, and a second copy skips what is there. A run copied while it was still
//!   being collected gets its new samples, frames, windows and events on the next copy
//!   (samples are keyed by their index), and its status, times and `rig_toml` (a
//!   resume rewrites it) refreshed.
//! - **Back again.** Copying B into A skips B's objects that B got from A: they map to
//!   A's originals.
//! - **Checked before commit.** Within the destination's transaction, the object's own
//!   row and every child table's rows for it are read back and hashed (sha256 over
//!   every column but the destination's ids, with references mapped), each row on its
//!   own, and compared as sets with the snapshot's: the order a server's collation
//!   gives text does not matter. A difference rolls the object back and names the table.
//! - **Clones and rewound stores.** Stores are told apart by `store_identity.uid`. A
//!   copied file or a restored backup has its original's uid; when it then differs from
//!   what was copied from that uid (an object's fixed columns, or rows copied before),
//!   the copy stops and says so: `softtouch db new-identity` gives such a store an
//!   identity of its own.
//! - **What is not copied:** leases (a live collector's, on its own store) and the
//!   `copied` bookkeeping itself. A dataset or model whose name the destination already
//!   uses for something else is skipped and reported (names are unique per store); a
//!   reference to something not copied (a model's skipped dataset) is left empty and
//!   reported.
//!
//! The copier is generic over tables: it reads each row as typed cells and writes the
//! same columns (quoted: a name is never read as SQL), so a column added by a
//! migration is copied without touching this file.

use crate::{Dialect, Store, StoreError, query_err};
use futures_util::TryStreamExt as _;
use sha2::{Digest as _, Sha256};
use sqlx::any::{AnyArguments, AnyRow, AnyTypeInfoKind};
use sqlx::{Any, AnyConnection, Column as _, Row as _, ValueRef as _};
use std::collections::HashMap;

mod cells;
mod check;
mod kinds;

use cells::*;
use check::*;
use kinds::*;

/// What a copy did, for the report.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CopyReport {
    /// Objects written new, per kind (`run`, `dataset`, …).
    pub new: Vec<(String, u64)>,
    /// Objects already there from an earlier copy (or the destination's own, copied
    /// back), per kind.
    pub already: Vec<(String, u64)>,
    /// Child rows written (samples, frames, …), per table.
    pub rows: Vec<(String, u64)>,
    /// Rows checked equal on both sides by sha256, per table.
    pub checked: Vec<(String, u64)>,
    /// What was left out, and why.
    pub skipped: Vec<String>,
}

fn add(list: &mut Vec<(String, u64)>, key: &str, n: u64) {
    match list.iter_mut().find(|(k, _)| k == key) {
        Some((_, v)) => *v += n,
        None => list.push((key.to_owned(), n)),
    }
}

/// Per kind: source id → destination id.
type Maps = HashMap<&'static str, HashMap<i64, i64>>;

/// Maps the reference columns `refs` of a row to the destination's ids. A reference to
/// something not copied becomes NULL where the schema allows it (a run's
/// `poses_from_run_id`, a model's `dataset_id`) and comes back as a line saying so;
/// elsewhere it is an error.
fn map_refs(
    cells: &mut Cells,
    refs: &[(&str, &str)],
    maps: &Maps,
    table: &str,
) -> Result<Vec<String>, StoreError> {
    let mut emptied = Vec::new();
    for (column, kind) in refs {
        let Some((_, cell)) = cells.iter_mut().find(|(c, _)| c == column) else {
            continue;
        };
        if let Cell::Int(id) = cell {
            match maps.get(kind).and_then(|m| m.get(id)) {
                Some(to) => *id = *to,
                None if *column == "poses_from_run_id"
                    || *column == "dataset_id" && table == "models" =>
                {
                    emptied.push(format!(
                        "{table}.{column} = {id}: that {kind} was not copied; left empty"
                    ));
                    *cell = Cell::Null(AnyTypeInfoKind::BigInt);
                }
                None => {
                    return Err(StoreError::Damaged {
                        what: "reference being copied",
                        why: format!("{table}.{column} = {id}: no such {kind} copied"),
                    });
                }
            }
        }
    }
    Ok(emptied)
}

/// The source, read as one snapshot for a whole copy.
type Snapshot = sqlx::Transaction<'static, Any>;

impl Store {
    /// This store's identity for copies (made once, kept in `store_identity`).
    ///
    /// # Errors
    /// A query failure.
    pub async fn uid(&self) -> Result<String, StoreError> {
        sqlx::query(self.dialect.sql(
            "INSERT INTO store_identity (singleton, uid) VALUES (1, ?) ON CONFLICT (singleton) DO NOTHING",
        ))
        .bind(new_uid())
        .execute(&self.pool)
        .await
        .map_err(query_err("recording the store's identity"))?;
        // The stored one: this candidate, an earlier one, or another process's.
        sqlx::query_scalar(
            self.dialect
                .sql("SELECT uid FROM store_identity WHERE singleton = 1"),
        )
        .fetch_one(&self.pool)
        .await
        .map_err(query_err("reading the store's identity"))
    }

    /// Give this store a new identity for copies (a copied file or a restored backup
    /// that has been written since, and is now a store of its own); the old and the
    /// new uid. What it holds is then copied anywhere as new objects, even where its
    /// original's copies are.
    ///
    /// # Errors
    /// A query failure.
    pub async fn new_identity(&self) -> Result<(String, String), StoreError> {
        let old = self.uid().await?;
        let new = new_uid();
        sqlx::query(
            self.dialect
                .sql("UPDATE store_identity SET uid = ? WHERE singleton = 1"),
        )
        .bind(&new)
        .execute(&self.pool)
        .await
        .map_err(query_err("giving the store a new identity"))?;
        Ok((old, new))
    }

    /// Copy everything this store holds into `to` (see the module's docs); `say` gets a
    /// line per object.
    ///
    /// # Errors
    /// A query failure on either side, the two being one store, a source that is a
    /// clone or a rewound copy of the store first copied under its identity, or a copy
    /// that does not read back equal.
    pub async fn copy_into(
        &self,
        to: &Self,
        say: &mut (dyn FnMut(&str) + Send),
    ) -> Result<CopyReport, StoreError> {
        let from_uid = self.uid().await?;
        let to_uid = to.uid().await?;
        if from_uid == to_uid {
            return Err(StoreError::Invalid {
                what: "copy",
                why: "--from and --to are the same store (or one is a copy of the other's \
                      file: give it an identity of its own with `softtouch db new-identity`)"
                    .into(),
            });
        }
        let mut report = CopyReport::default();
        let mut maps: Maps = HashMap::new();
        // What was copied before: source id → destination id.
        let rows: Vec<(String, i64, i64)> = sqlx::query_as(
            to.dialect
                .sql("SELECT kind, source_id, dest_id FROM copied WHERE source_uid = ?"),
        )
        .bind(&from_uid)
        .fetch_all(&to.pool)
        .await
        .map_err(query_err("reading earlier copies"))?;
        for (kind, s, d) in rows {
            if let Some(k) = kind_name(&kind) {
                maps.entry(k).or_default().insert(s, d);
            }
        }
        let begin = match self.dialect {
            Dialect::Postgres => {
                self.pool
                    .begin_with("BEGIN ISOLATION LEVEL REPEATABLE READ, READ ONLY")
                    .await
            }
            Dialect::Sqlite => self.pool.begin().await,
        };
        let mut source: Snapshot = begin.map_err(query_err("starting a snapshot of the source"))?;
        // What this store got from the destination: its own originals, not copied back.
        let back: Vec<(String, i64, i64)> = sqlx::query_as(
            self.dialect
                .sql("SELECT kind, source_id, dest_id FROM copied WHERE source_uid = ?"),
        )
        .bind(&to_uid)
        .fetch_all(&mut *source)
        .await
        .map_err(query_err("reading earlier copies"))?;
        let mut originals: HashMap<&'static str, HashMap<i64, i64>> = HashMap::new();
        for (kind, their, ours) in back {
            if let Some(k) = kind_name(&kind) {
                originals.entry(k).or_default().insert(ours, their);
                maps.entry(k).or_default().insert(ours, their);
            }
        }
        for kind in KINDS {
            let ids: Vec<i64> = sqlx::query_scalar(self.dialect.sql_owned(format!(
                "SELECT {id} FROM {} ORDER BY {id}",
                quoted(kind.table),
                id = quoted(kind.id),
            )))
            .fetch_all(&mut *source)
            .await
            .map_err(query_err("listing what to copy"))?;
            for id in ids {
                if originals
                    .get(kind.kind)
                    .is_some_and(|m| m.contains_key(&id))
                {
                    add(&mut report.already, kind.kind, 1);
                    continue;
                }
                let mut copy = ObjectCopy {
                    source: &mut source,
                    to,
                    from_uid: &from_uid,
                    maps: &mut maps,
                    report: &mut report,
                    say: &mut *say,
                };
                copy.object(kind, id).await?;
            }
        }
        // Read only: nothing to commit.
        let _ = source.rollback().await;
        Ok(report)
    }
}

/// A candidate identity: 128 random bits from the standard library's randomly keyed
/// hashers and the clock.
fn new_uid() -> String {
    use std::hash::{BuildHasher as _, Hasher as _};
    let mut words = [0u64; 2];
    for (i, w) in words.iter_mut().enumerate() {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u64(i as u64);
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
        );
        *w = h.finish();
    }
    format!("{:016x}{:016x}", words[0], words[1])
}

/// One copy's state: the source's snapshot, the destination, and what is copied so far.
struct ObjectCopy<'c, 's> {
    source: &'c mut Snapshot,
    to: &'c Store,
    from_uid: &'c str,
    maps: &'c mut Maps,
    report: &'c mut CopyReport,
    say: &'c mut (dyn FnMut(&str) + Send + 's),
}

impl ObjectCopy<'_, '_> {
    /// The object's own row in the source's snapshot, its id left out and its
    /// references mapped; and the references left empty.
    async fn source_row(
        &mut self,
        kind: &'static Kind,
        id: i64,
    ) -> Result<(Cells, Vec<String>), StoreError> {
        let Some(mut cells) =
            object_row(self.source, kind, id, "reading an object to copy").await?
        else {
            return Err(StoreError::Damaged {
                what: "copy",
                why: format!(
                    "{} {id} is listed in the source but cannot be read",
                    kind.kind
                ),
            });
        };
        cells.retain(|(c, _)| c != kind.id);
        let emptied = map_refs(&mut cells, kind.refs, self.maps, kind.table)?;
        Ok((cells, emptied))
    }

    async fn object(&mut self, kind: &'static Kind, id: i64) -> Result<(), StoreError> {
        let to = self.to;
        let d = to.dialect;
        let (cells, emptied) = self.source_row(kind, id).await?;
        let mut tx = to
            .pool
            .begin()
            .await
            .map_err(query_err("starting a copy"))?;
        let existing = self.maps.get(kind.kind).and_then(|m| m.get(&id)).copied();
        let what = format!("{} {id}", kind.kind);
        let dest_id = match existing {
            Some(dest) => {
                // The same object as copied before? Its fixed columns say.
                let there = object_row(&mut tx, kind, dest, READ_BACK).await?;
                let Some(there) = there else {
                    return Err(StoreError::Damaged {
                        what: "copy",
                        why: format!(
                            "the destination recorded {what} as its {} {dest}, which is not there",
                            kind.kind
                        ),
                    });
                };
                // Brought up to date: the refresh columns, and a reference left empty
                // when it was copied (its object not copied then) that now maps.
                let mut refreshed: Vec<&str> = kind.refresh.to_vec();
                for (column, _) in kind.refs {
                    let empty_there = there
                        .iter()
                        .any(|(c, v)| c == column && matches!(v, Cell::Null(_)));
                    let set_here = cells
                        .iter()
                        .any(|(c, v)| c == column && !matches!(v, Cell::Null(_)));
                    if empty_there && set_here {
                        refreshed.push(column);
                    }
                }
                let mut fixed = refreshed.clone();
                fixed.push(kind.id);
                let changed = differences(&cells, &there, &fixed);
                if !changed.is_empty() {
                    return Err(diverged(self.from_uid, &what, &changed.join("; ")));
                }
                let values: Vec<(&str, Cell)> = refreshed
                    .iter()
                    .filter_map(|c| {
                        cells
                            .iter()
                            .find(|(n, _)| n == c)
                            .map(|(_, v)| (*c, v.clone()))
                    })
                    .collect();
                if !values.is_empty() {
                    let set: Vec<String> = values
                        .iter()
                        .map(|(c, _)| format!("{} = ?", quoted(c)))
                        .collect();
                    let mut q = sqlx::query(d.sql_owned(format!(
                        "UPDATE {} SET {} WHERE {} = ?",
                        quoted(kind.table),
                        set.join(", "),
                        quoted(kind.id)
                    )));
                    for (_, cell) in values {
                        q = bind(q, cell);
                    }
                    q.bind(dest)
                        .execute(&mut *tx)
                        .await
                        .map_err(query_err("refreshing a copied object"))?;
                }
                add(&mut self.report.already, kind.kind, 1);
                dest
            }
            None => {
                if let Some(name_col) = kind.name
                    && let Some((_, Cell::Text(name))) = cells.iter().find(|(c, _)| c == name_col)
                {
                    let taken: Option<i64> = sqlx::query_scalar(d.sql_owned(format!(
                        "SELECT {} FROM {} WHERE {} = ?",
                        quoted(kind.id),
                        quoted(kind.table),
                        quoted(name_col)
                    )))
                    .bind(name.clone())
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(query_err("looking for a name"))?;
                    if taken.is_some() {
                        let why = format!(
                            "{what} `{name}`: the destination has another of that name; not copied"
                        );
                        (self.say)(&why);
                        self.report.skipped.push(why);
                        return Ok(());
                    }
                }
                for line in &emptied {
                    let why = format!("{what}: {line}");
                    (self.say)(&why);
                    self.report.skipped.push(why);
                }
                let dest = insert_returning(&mut tx, d, kind.table, kind.id, cells.clone()).await?;
                record(&mut tx, d, self.from_uid, kind.kind, id, dest).await?;
                self.maps.entry(kind.kind).or_default().insert(id, dest);
                add(&mut self.report.new, kind.kind, 1);
                dest
            }
        };
        let mut written = Vec::new();
        for child in kind.children {
            let n = self.copy_children(child, id, &mut tx).await?;
            written.push((child.table, n));
        }
        // Read back within the transaction and compare, before anything is committed.
        let there = object_row(&mut tx, kind, dest_id, READ_BACK)
            .await?
            .unwrap_or_default();
        let changed = differences(&cells, &there, &[kind.id]);
        if !changed.is_empty() {
            return Err(StoreError::Damaged {
                what: "copy",
                why: format!(
                    "{} of {what} does not read back as written: {}",
                    kind.table,
                    changed.join("; ")
                ),
            });
        }
        let mut checked = vec![(kind.table, 1)];
        for child in kind.children {
            let n = self
                .check_children(child, id, dest_id, &mut tx, existing.is_some(), &what)
                .await?;
            checked.push((child.table, n));
        }
        tx.commit().await.map_err(query_err("committing a copy"))?;
        for (table, n) in &checked {
            add(&mut self.report.checked, table, *n);
        }
        for (table, n) in &written {
            add(&mut self.report.rows, table, *n);
        }
        let detail: Vec<String> = written
            .iter()
            .zip(&checked[1..])
            .map(|((t, n), (_, c))| format!("{t} +{n} ({c} checked)"))
            .collect();
        (self.say)(&format!(
            "{what} → {dest_id}{}{}",
            if existing.is_some() {
                " (copied before)"
            } else {
                ""
            },
            if detail.is_empty() {
                String::new()
            } else {
                format!(": {}", detail.join(", "))
            }
        ));
        Ok(())
    }

    async fn copy_children(
        &mut self,
        child: &Child,
        parent: i64,
        tx: &mut AnyConnection,
    ) -> Result<u64, StoreError> {
        let d = Dialect::of(tx);
        let mut rows = child.rows_of(self.source, parent);
        let mut n = 0u64;
        while let Some(row) = rows
            .try_next()
            .await
            .map_err(query_err("reading rows to copy"))?
        {
            let mut cells = read_cells(&row)?;
            match child.key {
                ChildKey::Natural(conflict) => {
                    map_refs(&mut cells, child.refs, self.maps, child.table)?;
                    let done = insert(
                        d,
                        child.table,
                        cells,
                        &format!("ON CONFLICT {conflict} DO NOTHING"),
                    )
                    .execute(&mut *tx)
                    .await
                    .map_err(query_err("copying rows"))?;
                    n += done.rows_affected();
                }
                ChildKey::Identity(id_col, kind) => {
                    let Some(Cell::Int(source_id)) = cells
                        .iter()
                        .find(|(c, _)| c == id_col)
                        .map(|(_, c)| c.clone())
                    else {
                        continue;
                    };
                    if self
                        .maps
                        .get(kind)
                        .is_some_and(|m| m.contains_key(&source_id))
                    {
                        continue;
                    }
                    cells.retain(|(c, _)| c != id_col);
                    map_refs(&mut cells, child.refs, self.maps, child.table)?;
                    let dest = insert_returning(tx, d, child.table, id_col, cells).await?;
                    record(tx, d, self.from_uid, kind, source_id, dest).await?;
                    self.maps.entry(kind).or_default().insert(source_id, dest);
                    n += 1;
                }
            }
        }
        Ok(n)
    }

    /// Each of a child table's rows of the object, hashed on both sides (references
    /// mapped, the destination's ids left out), compared as sets; the rows checked.
    async fn check_children(
        &mut self,
        child: &Child,
        parent: i64,
        dest_parent: i64,
        tx: &mut AnyConnection,
        copied_before: bool,
        what: &str,
    ) -> Result<u64, StoreError> {
        let skip: &[&str] = match &child.key {
            ChildKey::Identity(id_col, _) => std::slice::from_ref(id_col),
            ChildKey::Natural(_) => &[],
        };
        let ours = child_digests(self.source, child, parent, skip, Some(self.maps)).await?;
        let theirs = child_digests(tx, child, dest_parent, skip, None).await?;
        if ours == theirs {
            return Ok(ours.len() as u64);
        }
        let only_here = ours
            .iter()
            .filter(|h| theirs.binary_search(h).is_err())
            .count();
        let only_there = theirs
            .iter()
            .filter(|h| ours.binary_search(h).is_err())
            .count();
        let counts = format!(
            "{} rows here, {} there; {only_here} only here, {only_there} only there",
            ours.len(),
            theirs.len()
        );
        Err(if copied_before {
            diverged(
                self.from_uid,
                &format!("{} of {what}", child.table),
                &counts,
            )
        } else {
            StoreError::Damaged {
                what: "copy",
                why: format!(
                    "{} of {what} does not read back as written (sha256 differs: {counts})",
                    child.table
                ),
            }
        })
    }
}

async fn record(
    tx: &mut AnyConnection,
    d: Dialect,
    from_uid: &str,
    kind: &str,
    source_id: i64,
    dest_id: i64,
) -> Result<(), StoreError> {
    sqlx::query(
        d.sql("INSERT INTO copied (source_uid, kind, source_id, dest_id) VALUES (?, ?, ?, ?)"),
    )
    .bind(from_uid.to_owned())
    .bind(kind.to_owned())
    .bind(source_id)
    .bind(dest_id)
    .execute(&mut *tx)
    .await
    .map_err(query_err("recording a copy"))?;
    Ok(())
}

#[cfg(test)]
mod tests;
