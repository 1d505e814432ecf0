//! `softtouch db copy`: runs, datasets, models, grasp sessions, calibrations and results
//! from one store into another, between any two engines, checked and never twice.
//!
//! - **Identities.** Ids are the destination's own (PostgreSQL's identities, SQLite's
//!   rowids): several rigs' runs 1 never collide. The destination records each copied
//!   object in `copied` (the source store's `uid`, the kind, the source id, the new id),
//!   in the same transaction as the object, so a killed copy leaves each object whole or
//!   absent, and a second copy skips what is there. A run copied while it was still
//!   being collected gets its new samples, frames, windows and events on the next copy
//!   (samples are keyed by their index), and its status and times refreshed.
//! - **Back again.** Copying B into A skips B's objects that B got from A: they map to
//!   A's originals.
//! - **Checked.** After each object, every table's rows for it are read back from both
//!   stores and hashed (sha256 over every column but the ids, with references mapped),
//!   frames and windows byte for byte; a difference is an error naming the table.
//! - **What is not copied:** leases (a live collector's, on its own store) and the
//!   `copied` bookkeeping itself. A dataset or model whose name the destination already
//!   uses for something else is skipped and reported (names are unique per store).
//!
//! The copier is generic over tables: it reads each row as typed cells and writes the
//! same columns, so a column added by a migration is copied without touching this file.

use crate::{Dialect, Store, StoreError, query_err};
use futures_util::TryStreamExt as _;
use sha2::{Digest as _, Sha256};
use sqlx::any::{AnyArguments, AnyRow, AnyTypeInfoKind};
use sqlx::{Any, AnyConnection, Column as _, Row as _, ValueRef as _};
use std::collections::HashMap;

/// A child table of a copied object.
#[derive(Debug)]
struct Child {
    table: &'static str,
    /// Selects the child rows of the object whose id is bound once.
    select_where: &'static str,
    /// Row order, for hashing both sides alike.
    order: &'static str,
    /// The conflict target of its natural key (re-copies add only what is new), or its
    /// own identity column and the kind it is recorded as in `copied`.
    key: ChildKey,
    /// Columns that refer to other copied objects, and those objects' kinds.
    refs: &'static [(&'static str, &'static str)],
}

impl Child {
    /// The child rows of object `parent` in `store`, in [`Child::order`].
    fn rows_of<'a>(
        &self,
        store: &'a Store,
        parent: i64,
    ) -> futures_util::stream::BoxStream<'a, Result<AnyRow, sqlx::Error>> {
        sqlx::query(store.dialect.sql_owned(format!(
            "SELECT * FROM {} WHERE {} ORDER BY {}",
            self.table, self.select_where, self.order
        )))
        .bind(parent)
        .fetch(&store.pool)
    }
}

#[derive(Debug, Clone, Copy)]
enum ChildKey {
    Natural(&'static str),
    Identity(&'static str, &'static str),
}

/// A kind of object copied whole: its row and its children.
#[derive(Debug)]
struct Kind {
    kind: &'static str,
    table: &'static str,
    id: &'static str,
    /// A unique name column: another object of that name at the destination blocks it.
    name: Option<&'static str>,
    refs: &'static [(&'static str, &'static str)],
    /// Columns brought up to date on a re-copy (a run that was still being collected).
    refresh: &'static [&'static str],
    children: &'static [Child],
}

const KINDS: &[Kind] = &[
    Kind {
        kind: "run",
        table: "runs",
        id: "run_id",
        name: None,
        refs: &[("poses_from_run_id", "run")],
        refresh: &["status", "updated_at", "finished_at", "time_base_ns"],
        children: &[
            Child {
                table: "samples",
                select_where: "run_id = ?",
                order: "sample_index",
                key: ChildKey::Natural("(run_id, sample_index)"),
                refs: &[("run_id", "run")],
            },
            Child {
                table: "frames",
                select_where: "run_id = ?",
                order: "sample_index",
                key: ChildKey::Natural("(run_id, sample_index)"),
                refs: &[("run_id", "run")],
            },
            Child {
                table: "ft_windows",
                select_where: "run_id = ?",
                order: "sample_index",
                key: ChildKey::Natural("(run_id, sample_index)"),
                refs: &[("run_id", "run")],
            },
            Child {
                table: "events",
                select_where: "run_id = ?",
                order: "event_id",
                key: ChildKey::Identity("event_id", "event"),
                refs: &[("run_id", "run")],
            },
            Child {
                table: "run_imports",
                select_where: "run_id = ?",
                order: "run_id",
                key: ChildKey::Natural("(run_id)"),
                refs: &[("run_id", "run")],
            },
        ],
    },
    Kind {
        kind: "dataset",
        table: "datasets",
        id: "dataset_id",
        name: Some("name"),
        refs: &[],
        refresh: &[],
        children: &[Child {
            table: "dataset_members",
            select_where: "dataset_id = ?",
            order: "position",
            key: ChildKey::Natural("(dataset_id, position)"),
            refs: &[("dataset_id", "dataset"), ("run_id", "run")],
        }],
    },
    Kind {
        kind: "model",
        table: "models",
        id: "model_id",
        name: Some("name"),
        refs: &[("dataset_id", "dataset")],
        refresh: &[],
        children: &[],
    },
    Kind {
        kind: "calibration",
        table: "grasp_calibrations",
        id: "calibration_id",
        name: None,
        refs: &[],
        refresh: &[],
        children: &[],
    },
    Kind {
        kind: "session",
        table: "grasp_sessions",
        id: "session_id",
        name: None,
        refs: &[],
        refresh: &[],
        children: &[
            Child {
                table: "grasp_trials",
                select_where: "session_id = ?",
                order: "trial_id",
                key: ChildKey::Identity("trial_id", "trial"),
                refs: &[("session_id", "session")],
            },
            Child {
                table: "grasp_traces",
                select_where: "trial_id IN (SELECT trial_id FROM grasp_trials WHERE session_id = ?)",
                order: "trial_id",
                key: ChildKey::Natural("(trial_id)"),
                refs: &[("trial_id", "trial")],
            },
            Child {
                table: "grasp_trial_frames",
                select_where: "trial_id IN (SELECT trial_id FROM grasp_trials WHERE session_id = ?)",
                order: "trial_id, moment",
                key: ChildKey::Natural("(trial_id, moment)"),
                refs: &[("trial_id", "trial")],
            },
        ],
    },
    Kind {
        kind: "result",
        table: "results",
        id: "result_id",
        name: None,
        refs: &[],
        refresh: &[],
        children: &[
            Child {
                table: "result_tables",
                select_where: "result_id = ?",
                order: "name",
                key: ChildKey::Natural("(result_id, name)"),
                refs: &[("result_id", "result")],
            },
            Child {
                table: "result_figures",
                select_where: "result_id = ?",
                order: "name",
                key: ChildKey::Natural("(result_id, name)"),
                refs: &[("result_id", "result")],
            },
        ],
    },
];

/// One column's value, typed as both engines store it.
#[derive(Debug, Clone, PartialEq)]
enum Cell {
    /// NULL, with its column's type (PostgreSQL wants a typed NULL).
    Null(AnyTypeInfoKind),
    Int(i64),
    Real(f64),
    Text(String),
    Blob(Vec<u8>),
}

impl Cell {
    fn hash_into(&self, h: &mut Sha256) {
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
type Cells = Vec<(String, Cell)>;

fn read_cells(row: &AnyRow) -> Result<Cells, StoreError> {
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

type Query<'q> = sqlx::query::Query<'q, Any, AnyArguments>;

fn bind(q: Query<'_>, cell: Cell) -> Query<'_> {
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

fn map_refs(
    cells: &mut Cells,
    refs: &[(&str, &str)],
    maps: &Maps,
    table: &str,
) -> Result<(), StoreError> {
    for (column, kind) in refs {
        let Some((_, cell)) = cells.iter_mut().find(|(c, _)| c == column) else {
            continue;
        };
        if let Cell::Int(id) = cell {
            match maps.get(kind).and_then(|m| m.get(id)) {
                Some(to) => *id = *to,
                // A reference to something not copied (a run deleted since): none.
                None if *column == "poses_from_run_id"
                    || *column == "dataset_id" && table == "models" =>
                {
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
    Ok(())
}

impl Store {
    /// This store's identity for copies (made once, kept in `store_identity`).
    ///
    /// # Errors
    /// A query failure.
    pub async fn uid(&self) -> Result<String, StoreError> {
        use std::hash::{BuildHasher as _, Hasher as _};
        // A candidate, kept only where the store has none yet: 128 random bits from the standard library's randomly keyed hashers.
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
        let uid = format!("{:016x}{:016x}", words[0], words[1]);
        sqlx::query(self.dialect.sql(
            "INSERT INTO store_identity (singleton, uid) VALUES (1, ?) ON CONFLICT (singleton) DO NOTHING",
        ))
        .bind(&uid)
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

    /// Copy everything this store holds into `to` (see the module's docs); `say` gets a
    /// line per object.
    ///
    /// # Errors
    /// A query failure on either side, the two being one store, or a copy that does
    /// not read back equal.
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
                why: "--from and --to are the same store".into(),
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
        // What this store got from the destination: its own originals, not copied back.
        let back: Vec<(String, i64, i64)> = sqlx::query_as(
            self.dialect
                .sql("SELECT kind, source_id, dest_id FROM copied WHERE source_uid = ?"),
        )
        .bind(&to_uid)
        .fetch_all(&self.pool)
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
                "SELECT {} FROM {} ORDER BY {}",
                kind.id, kind.table, kind.id
            )))
            .fetch_all(&self.pool)
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
                self.copy_object(kind, id, to, &from_uid, &mut maps, &mut report, say)
                    .await?;
            }
        }
        Ok(report)
    }

    #[allow(
        clippy::too_many_arguments,
        reason = "one object's copy and its bookkeeping"
    )]
    async fn copy_object(
        &self,
        kind: &'static Kind,
        id: i64,
        to: &Self,
        from_uid: &str,
        maps: &mut Maps,
        report: &mut CopyReport,
        say: &mut (dyn FnMut(&str) + Send),
    ) -> Result<(), StoreError> {
        let d = to.dialect;
        let row = sqlx::query(self.dialect.sql_owned(format!(
            "SELECT * FROM {} WHERE {} = ?",
            kind.table, kind.id
        )))
        .bind(id)
        .fetch_one(&self.pool)
        .await
        .map_err(query_err("reading an object to copy"))?;
        let mut cells = read_cells(&row)?;
        cells.retain(|(c, _)| c != kind.id);
        map_refs(&mut cells, kind.refs, maps, kind.table)?;
        let mut tx = to
            .pool
            .begin()
            .await
            .map_err(query_err("starting a copy"))?;
        let existing = maps.get(kind.kind).and_then(|m| m.get(&id)).copied();
        let dest_id = match existing {
            Some(dest) => {
                if !kind.refresh.is_empty() {
                    let set: Vec<String> =
                        kind.refresh.iter().map(|c| format!("{c} = ?")).collect();
                    let mut q = sqlx::query(d.sql_owned(format!(
                        "UPDATE {} SET {} WHERE {} = ?",
                        kind.table,
                        set.join(", "),
                        kind.id
                    )));
                    for c in kind.refresh {
                        if let Some((_, cell)) = cells.iter().find(|(n, _)| n == c) {
                            q = bind(q, cell.clone());
                        }
                    }
                    q.bind(dest)
                        .execute(&mut *tx)
                        .await
                        .map_err(query_err("refreshing a copied object"))?;
                }
                add(&mut report.already, kind.kind, 1);
                dest
            }
            None => {
                if let Some(name_col) = kind.name
                    && let Some((_, Cell::Text(name))) = cells.iter().find(|(c, _)| c == name_col)
                {
                    let taken: Option<i64> = sqlx::query_scalar(d.sql_owned(format!(
                        "SELECT {} FROM {} WHERE {name_col} = ?",
                        kind.id, kind.table
                    )))
                    .bind(name.clone())
                    .fetch_optional(&mut *tx)
                    .await
                    .map_err(query_err("looking for a name"))?;
                    if taken.is_some() {
                        let why = format!(
                            "{} `{name}`: the destination has another of that name; not copied",
                            kind.kind
                        );
                        say(&why);
                        report.skipped.push(why);
                        return Ok(());
                    }
                }
                let dest = insert_returning(&mut tx, d, kind.table, kind.id, cells).await?;
                record(&mut tx, d, from_uid, kind.kind, id, dest).await?;
                maps.entry(kind.kind).or_default().insert(id, dest);
                add(&mut report.new, kind.kind, 1);
                dest
            }
        };
        let mut written = Vec::new();
        for child in kind.children {
            let n = self
                .copy_children(child, id, &mut tx, d, from_uid, maps)
                .await?;
            written.push((child.table, n));
        }
        tx.commit().await.map_err(query_err("committing a copy"))?;
        // Read back and compare, table by table.
        let mut checked = Vec::new();
        for child in kind.children {
            let n = self.check_children(child, id, dest_id, to, maps).await?;
            add(&mut report.checked, child.table, n);
            checked.push((child.table, n));
        }
        for (table, n) in &written {
            add(&mut report.rows, table, *n);
        }
        let detail: Vec<String> = written
            .iter()
            .zip(&checked)
            .map(|((t, n), (_, c))| format!("{t} +{n} ({c} checked)"))
            .collect();
        say(&format!(
            "{} {id} → {dest_id}{}{}",
            kind.kind,
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
        &self,
        child: &Child,
        parent: i64,
        tx: &mut AnyConnection,
        d: Dialect,
        from_uid: &str,
        maps: &mut Maps,
    ) -> Result<u64, StoreError> {
        let mut rows = child.rows_of(self, parent);
        let mut n = 0u64;
        while let Some(row) = rows
            .try_next()
            .await
            .map_err(query_err("reading rows to copy"))?
        {
            let mut cells = read_cells(&row)?;
            match child.key {
                ChildKey::Natural(conflict) => {
                    map_refs(&mut cells, child.refs, maps, child.table)?;
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
                    if maps.get(kind).is_some_and(|m| m.contains_key(&source_id)) {
                        continue;
                    }
                    cells.retain(|(c, _)| c != id_col);
                    map_refs(&mut cells, child.refs, maps, child.table)?;
                    let dest = insert_returning(tx, d, child.table, id_col, cells).await?;
                    record(tx, d, from_uid, kind, source_id, dest).await?;
                    maps.entry(kind).or_default().insert(source_id, dest);
                    n += 1;
                }
            }
        }
        Ok(n)
    }

    /// Hash a child table's rows of the object on both sides (references mapped, ids
    /// left out) and compare; the rows checked.
    async fn check_children(
        &self,
        child: &Child,
        parent: i64,
        dest_parent: i64,
        to: &Self,
        maps: &Maps,
    ) -> Result<u64, StoreError> {
        let mut ours = Sha256::new();
        let mut theirs = Sha256::new();
        let skip = match child.key {
            ChildKey::Identity(id_col, _) => Some(id_col),
            ChildKey::Natural(_) => None,
        };
        let mut n = 0u64;
        for (store, parent, hash, mapped) in [
            (self, parent, &mut ours, true),
            (to, dest_parent, &mut theirs, false),
        ] {
            let mut rows = child.rows_of(store, parent);
            let mut count = 0u64;
            while let Some(row) = rows
                .try_next()
                .await
                .map_err(query_err("reading copied rows back"))?
            {
                let mut cells = read_cells(&row)?;
                if let Some(id_col) = skip {
                    cells.retain(|(c, _)| c != id_col);
                }
                if mapped {
                    map_refs(&mut cells, child.refs, maps, child.table)?;
                }
                for (_, cell) in &cells {
                    cell.hash_into(hash);
                }
                count += 1;
            }
            n = count;
        }
        if ours.finalize() != theirs.finalize() {
            return Err(StoreError::Damaged {
                what: "copy",
                why: format!(
                    "{} of {parent} does not read back as written (sha256 differs)",
                    child.table
                ),
            });
        }
        Ok(n)
    }
}

fn kind_name(kind: &str) -> Option<&'static str> {
    KINDS
        .iter()
        .map(|k| k.kind)
        .chain(["event", "trial"])
        .find(|k| *k == kind)
}

fn columns_and_marks(cells: &Cells) -> (String, String) {
    let columns: Vec<&str> = cells.iter().map(|(c, _)| c.as_str()).collect();
    let marks = vec!["?"; cells.len()].join(", ");
    (columns.join(", "), marks)
}

/// `INSERT INTO table (its cells' columns) VALUES (…) tail`, the cells bound.
fn insert(d: Dialect, table: &str, cells: Cells, tail: &str) -> Query<'static> {
    let (columns, marks) = columns_and_marks(&cells);
    let mut q = sqlx::query(d.sql_owned(format!(
        "INSERT INTO {table} ({columns}) VALUES ({marks}) {tail}"
    )));
    for (_, cell) in cells {
        q = bind(q, cell);
    }
    q
}

async fn insert_returning(
    tx: &mut AnyConnection,
    d: Dialect,
    table: &str,
    id_col: &str,
    cells: Cells,
) -> Result<i64, StoreError> {
    insert(d, table, cells, &format!("RETURNING {id_col}"))
        .fetch_one(&mut *tx)
        .await
        .map_err(query_err("copying an object"))?
        .try_get::<i64, _>(0)
        .map_err(query_err("reading a new id"))
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
