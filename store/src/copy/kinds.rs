//! The kinds table: what `db copy` copies as one object (a run, a dataset, a model, a
//! grasp session, a calibration, a result), its row's references and its child tables.

use super::*;

/// A child table of a copied object.
#[derive(Debug)]
pub(super) struct Child {
    pub(super) table: &'static str,
    /// Selects the child rows of the object whose id is bound once.
    pub(super) select_where: &'static str,
    /// Row order as written (byte order for text: `COLLATE BINARY`, which PostgreSQL
    /// reads as `"C"`); the check compares rows as sets, whatever the order.
    pub(super) order: &'static str,
    /// The conflict target of its natural key (re-copies add only what is new), or its
    /// own identity column and the kind it is recorded as in `copied`.
    pub(super) key: ChildKey,
    /// Columns that refer to other copied objects, and those objects' kinds.
    pub(super) refs: &'static [(&'static str, &'static str)],
}

impl Child {
    /// The child rows of object `parent` on `conn`, in [`Child::order`].
    pub(super) fn rows_of<'a>(
        &self,
        conn: &'a mut AnyConnection,
        parent: i64,
    ) -> futures_util::stream::BoxStream<'a, Result<AnyRow, sqlx::Error>> {
        let d = Dialect::of(conn);
        sqlx::query(d.sql_owned(format!(
            "SELECT * FROM {} WHERE {} ORDER BY {}",
            quoted(self.table),
            self.select_where,
            self.order
        )))
        .bind(parent)
        .fetch(conn)
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) enum ChildKey {
    Natural(&'static str),
    Identity(&'static str, &'static str),
}

/// A kind of object copied whole: its row and its children.
#[derive(Debug)]
pub(super) struct Kind {
    pub(super) kind: &'static str,
    pub(super) table: &'static str,
    pub(super) id: &'static str,
    /// A unique name column: another object of that name at the destination blocks it.
    pub(super) name: Option<&'static str>,
    pub(super) refs: &'static [(&'static str, &'static str)],
    /// Columns brought up to date on a re-copy (a run that was still being collected).
    pub(super) refresh: &'static [&'static str],
    pub(super) children: &'static [Child],
}

pub(super) const KINDS: &[Kind] = &[
    Kind {
        kind: "run",
        table: "runs",
        id: "run_id",
        name: None,
        refs: &[("poses_from_run_id", "run")],
        refresh: &[
            "status",
            "updated_at",
            "finished_at",
            "time_base_ns",
            "rig_toml",
        ],
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
                table: "rest_frames",
                select_where: "run_id = ?",
                order: "rest_index",
                key: ChildKey::Natural("(run_id, rest_index)"),
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
                order: "trial_id, moment COLLATE BINARY",
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
                order: "name COLLATE BINARY",
                key: ChildKey::Natural("(result_id, name)"),
                refs: &[("result_id", "result")],
            },
            Child {
                table: "result_figures",
                select_where: "result_id = ?",
                order: "name COLLATE BINARY",
                key: ChildKey::Natural("(result_id, name)"),
                refs: &[("result_id", "result")],
            },
        ],
    },
];

pub(super) fn kind_name(kind: &str) -> Option<&'static str> {
    KINDS
        .iter()
        .map(|k| k.kind)
        .chain(["event", "trial"])
        .find(|k| *k == kind)
}
