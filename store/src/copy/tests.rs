//! The copier's tests: its pieces, and whole copies on both engines (the destination
//! on PostgreSQL in the PostgreSQL tier, [`crate::testing::fresh_target`]).

use super::*;
use crate::NewResult;

#[test]
fn names_are_quoted_so_they_are_never_read_as_sql() {
    assert_eq!(quoted("fx_n"), "\"fx_n\"");
    assert_eq!(
        quoted("a\"; DROP TABLE runs; --"),
        "\"a\"\"; DROP TABLE runs; --\""
    );
    assert_eq!(quoted(""), "\"\"");
}

#[test]
fn a_row_digest_covers_names_and_values_and_skips_what_it_is_told() {
    let row = |v: i64| -> Cells {
        vec![
            ("id".into(), Cell::Int(v)),
            ("name".into(), Cell::Text("a".into())),
            ("x".into(), Cell::Real(0.5)),
            ("n".into(), Cell::Null(AnyTypeInfoKind::Double)),
        ]
    };
    assert_ne!(row_digest(&row(1), &[]), row_digest(&row(2), &[]));
    assert_eq!(row_digest(&row(1), &["id"]), row_digest(&row(2), &["id"]));
    // The same value in another column is another row.
    let a: Cells = vec![("a".into(), Cell::Int(1)), ("b".into(), Cell::Int(2))];
    let b: Cells = vec![("a".into(), Cell::Int(2)), ("b".into(), Cell::Int(1))];
    assert_ne!(row_digest(&a, &[]), row_digest(&b, &[]));
    assert!(differences(&a, &a, &[]).is_empty());
    assert_eq!(differences(&a, &b, &["b"]), vec!["a: 1 here, 2 there"]);
    assert!(differences(&a, &Vec::new(), &[])[0].contains("not at the destination"));
    // Empty rows and tables.
    assert_eq!(
        row_digest(&Vec::new(), &[]),
        row_digest(&Vec::new(), &["x"])
    );
}

#[test]
fn a_reference_to_what_was_not_copied_is_emptied_and_said_where_allowed() {
    let mut maps: Maps = HashMap::new();
    maps.entry("run").or_default().insert(1, 10);
    let mut model: Cells = vec![("dataset_id".into(), Cell::Int(4))];
    let said = map_refs(&mut model, &[("dataset_id", "dataset")], &maps, "models")
        .expect("a model's dataset may be left empty");
    assert_eq!(
        said,
        vec!["models.dataset_id = 4: that dataset was not copied; left empty"]
    );
    assert!(matches!(model[0].1, Cell::Null(_)));
    let mut member: Cells = vec![("run_id".into(), Cell::Int(2))];
    assert!(
        map_refs(&mut member, &[("run_id", "run")], &maps, "dataset_members").is_err(),
        "a member's run must be there"
    );
    let mut sample: Cells = vec![("run_id".into(), Cell::Int(1))];
    assert!(
        map_refs(&mut sample, &[("run_id", "run")], &maps, "samples")
            .expect("mapped")
            .is_empty()
    );
    assert!(matches!(sample[0].1, Cell::Int(10)));
}

/// Names that sort differently by bytes than by a language's collation (PostgreSQL's
/// ICU `en-US`: lower case first, and glibc's `en_US.UTF-8`: punctuation ignored).
const NAMES: [&str; 4] = [
    "grasp-follow.csv",
    "grasp-follow-metrics.csv",
    "a.csv",
    "B.csv",
];

fn result_named(verb: &str) -> NewResult {
    NewResult {
        verb: verb.into(),
        settings_json: "{}".into(),
        summary: format!("{verb}: one line"),
        tables: NAMES
            .iter()
            .map(|n| ((*n).to_owned(), format!("name\n{n}\n")))
            .collect(),
        figures: vec![
            ("b.png".into(), b"\x89PNG\r\n\x1a\nb".to_vec()),
            ("A.png".into(), b"\x89PNG\r\n\x1a\nA".to_vec()),
        ],
        ..NewResult::default()
    }
}

async fn file_store(dir: &std::path::Path, name: &str) -> Store {
    Store::open(dir.join(name)).await.expect("a SQLite store")
}

async fn fleet(dir: &std::path::Path) -> Store {
    Store::open(crate::testing::fresh_target(dir, "fleet.db").await)
        .await
        .expect("the destination")
}

async fn copy(from: &Store, to: &Store) -> Result<CopyReport, StoreError> {
    from.copy_into(to, &mut |_| {}).await
}

#[tokio::test]
async fn results_are_read_back_and_copied_in_byte_order_whatever_the_servers_collation() {
    let dir = tempfile::tempdir().expect("test step");
    let rig = file_store(dir.path(), "rig.db").await;
    let id = rig
        .insert_result(&result_named("grasp follow"))
        .await
        .expect("stored");
    let fleet = fleet(dir.path()).await;
    let first = copy(&rig, &fleet).await.expect("copied");
    assert_eq!(first.new, vec![("result".to_owned(), 1)]);
    // Every row checked: the result's own, 4 tables, 2 figures.
    assert_eq!(
        first.checked,
        vec![
            ("results".to_owned(), 1),
            ("result_tables".to_owned(), 4),
            ("result_figures".to_owned(), 2)
        ]
    );
    // Again: nothing new, and nothing refused (the hashes do not depend on order).
    let again = copy(&rig, &fleet).await.expect("copied again");
    assert!(again.new.is_empty(), "{again:?}");
    let mut bytes: Vec<&str> = NAMES.to_vec();
    bytes.sort_unstable();
    let stored = rig.result(id).await.expect("read").expect("there");
    let names: Vec<&str> = stored.tables.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, bytes);
    let copied = fleet.results().await.expect("listed");
    let there = fleet
        .result(copied[0].result_id)
        .await
        .expect("read")
        .expect("there");
    assert_eq!(there.tables, stored.tables, "{}", fleet.dialect().name());
    assert_eq!(there.figures, stored.figures);
    assert_eq!(
        there
            .figures
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>(),
        ["A.png", "b.png"]
    );
    rig.close().await;
    fleet.close().await;
}

#[tokio::test]
async fn a_copied_store_written_on_its_own_is_refused_until_it_has_an_identity_of_its_own() {
    let dir = tempfile::tempdir().expect("test step");
    let a = file_store(dir.path(), "a.db").await;
    a.insert_result(&result_named("sweep alpha"))
        .await
        .expect("stored");
    let fleet = fleet(dir.path()).await;
    copy(&a, &fleet).await.expect("copied");
    a.close().await;
    // A copy of the file (or a backup restored elsewhere): the same identity.
    std::fs::copy(dir.path().join("a.db"), dir.path().join("b.db")).expect("copied file");
    let a = file_store(dir.path(), "a.db").await;
    let b = file_store(dir.path(), "b.db").await;
    assert_eq!(a.uid().await.expect("uid"), b.uid().await.expect("uid"));
    // Each writes its own result 2.
    a.insert_result(&result_named("grasp follow"))
        .await
        .expect("stored");
    b.insert_result(&result_named("grasp twist"))
        .await
        .expect("stored");
    let from_a = copy(&a, &fleet).await.expect("the original copies");
    assert_eq!(from_a.new, vec![("result".to_owned(), 1)]);
    let refused = copy(&b, &fleet)
        .await
        .expect_err("the clone is refused")
        .to_string();
    assert!(
        refused.contains("result 2 is not as it was copied from this store before")
            && refused.contains("verb: \"grasp twist\" here, \"grasp follow\" there")
            && refused.contains("db new-identity"),
        "{refused}"
    );
    assert_eq!(
        fleet.results().await.expect("listed").len(),
        2,
        "nothing of b written"
    );
    // With an identity of its own, b is another store: both its results are new.
    let (old, new) = b.new_identity().await.expect("new identity");
    assert_ne!(old, new);
    assert_eq!(b.uid().await.expect("uid"), new);
    let from_b = copy(&b, &fleet)
        .await
        .expect("copied as a store of its own");
    assert_eq!(from_b.new, vec![("result".to_owned(), 2)]);
    // A row changed since it was copied (a store rewound and written again).
    sqlx::query("UPDATE result_tables SET csv = 'changed' WHERE name = 'a.csv' AND result_id = 1")
        .execute(a.pool())
        .await
        .expect("changed");
    let refused = copy(&a, &fleet).await.expect_err("refused").to_string();
    assert!(
        refused.contains("result_tables of result 1 is not as it was copied")
            && refused.contains("4 rows here, 4 there; 1 only here, 1 only there"),
        "{refused}"
    );
    for s in [a, b, fleet] {
        s.close().await;
    }
}

#[tokio::test]
async fn a_models_dataset_skipped_for_its_name_is_said_and_linked_once_it_is_copied() {
    let dir = tempfile::tempdir().expect("test step");
    let rig = file_store(dir.path(), "rig.db").await;
    let fleet = fleet(dir.path()).await;
    let dataset = |store: &Store, name: &'static str| {
        let store = store.clone();
        async move {
            sqlx::query(store.dialect().sql(
                "INSERT INTO datasets (name, definition_json, seed, split_ratio, sample_count, \
                 software_version, schema_version, created_at) \
                 VALUES (?, '{}', 1, '1:0:0', 1, 'test', 1, '2026-11-28T00:00:00Z')",
            ))
            .bind(name)
            .execute(store.pool())
            .await
            .expect("a dataset");
        }
    };
    dataset(&rig, "both").await;
    sqlx::query(
        "INSERT INTO models (name, dataset_id, dataset_name, kind, config_json, train_json, \
         metrics_json, history_json, artifact, software_version, created_at) \
         VALUES ('m', 1, 'both', 'svae', '{}', '{}', '{}', '[]', zeroblob(32), 'test', \
         '2026-11-28T00:00:00Z')",
    )
    .execute(rig.pool())
    .await
    .expect("a model");
    // The fleet already has a dataset of that name: the rig's is skipped, and the
    // model is copied without it, said.
    dataset(&fleet, "both").await;
    let first = copy(&rig, &fleet).await.expect("copied");
    assert_eq!(first.new, vec![("model".to_owned(), 1)], "{first:?}");
    assert!(
        first.skipped.iter().any(|s| s.contains("dataset 1 `both`"))
            && first.skipped.iter().any(|s| s.contains(
                "model 1: models.dataset_id = 1: that dataset was not copied; left empty"
            )),
        "{:?}",
        first.skipped
    );
    // The name freed at the destination: the dataset is copied, and the model linked
    // to it (not taken for a clone's).
    sqlx::query(
        fleet
            .dialect()
            .sql("UPDATE datasets SET name = 'both-fleet' WHERE name = 'both'"),
    )
    .execute(fleet.pool())
    .await
    .expect("renamed");
    let second = copy(&rig, &fleet).await.expect("copied again");
    assert_eq!(second.new, vec![("dataset".to_owned(), 1)], "{second:?}");
    let linked: Option<i64> = sqlx::query_scalar(
        fleet
            .dialect()
            .sql("SELECT m.dataset_id FROM models m JOIN datasets d ON d.dataset_id = m.dataset_id WHERE d.name = 'both'"),
    )
    .fetch_optional(fleet.pool())
    .await
    .expect("read");
    assert!(
        linked.is_some(),
        "the model's dataset is linked once copied"
    );
    rig.close().await;
    fleet.close().await;
}
