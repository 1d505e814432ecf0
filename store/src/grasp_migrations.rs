//! The grasp tables' migrations that rebuild them to widen a CHECK: every trial,
//! trace and frame survives. (Tests of `grasp.rs`, apart to keep that file small.)

use sqlx::{ConnectOptions, Connection, SqliteConnection};

/// A new SQLite database in `dir` with every migration before the one whose
/// description contains `named` applied, and that migration's index.
async fn migrated_before(dir: &std::path::Path, named: &str) -> (SqliteConnection, usize) {
    let mut conn = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(dir.join("old.db"))
        .create_if_missing(true)
        .foreign_keys(true)
        .connect()
        .await
        .expect("connects");
    let all: Vec<&sqlx::migrate::Migration> = crate::MIGRATOR.iter().collect();
    let at = all
        .iter()
        .position(|m| m.description.contains(named))
        .expect("the migration is embedded");
    run(&mut conn, &all[..at]).await;
    (conn, at)
}

/// Applies the migrations from index `at` on.
async fn migrate_from(conn: &mut SqliteConnection, at: usize) {
    let all: Vec<&sqlx::migrate::Migration> = crate::MIGRATOR.iter().collect();
    run(conn, &all[at..]).await;
}

async fn run(conn: &mut SqliteConnection, migrations: &[&sqlx::migrate::Migration]) {
    for m in migrations {
        sqlx::raw_sql(sqlx::AssertSqlSafe(m.sql.as_str().to_owned()))
            .execute(&mut *conn)
            .await
            .unwrap_or_else(|e| panic!("{}: {e}", m.description));
    }
}

/// The migration that lets a refused trial be stored rebuilds both grasp tables:
/// on a database made before it, every trial and its trace survive, and a refused
/// trial (never counted as held) can then be written.
#[tokio::test]
async fn the_refused_reason_migration_keeps_every_trial_and_trace() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (mut conn, at) = migrated_before(dir.path(), "grasp trial refused").await;
    sqlx::raw_sql(
        "INSERT INTO grasp_sessions (session_id, created_at, model, seed, scenes_json, config_json, software_version) VALUES (1, 'then', 'm', 0, '[]', '{}', 'v');
         INSERT INTO grasp_trials VALUES (7, 1, 0, 0, 'cake', 'open', 0, 'land', 0.005, 0.001, 0.0, 0.0, 0.02, 0.02, 1.2, NULL, 0, 'slip', NULL, NULL, 0.4, 'then');
         INSERT INTO grasp_traces VALUES (7, 2, 'f32le-v1', x'0000000000000040', x'0000000000000040', x'0000c07f0000c07f', x'0102', x'0304');",
    )
    .execute(&mut conn)
    .await
    .expect("an old session");
    let refused = "INSERT INTO grasp_trials (trial_id, session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m, dx_m, dy_m, dz_m, commanded_width_m, final_width_m, peak_estimate_n, peak_true_n, success, reason, detail, confirmed_after_s, wall_s, created_at) \
         VALUES (8, 1, 0, 0, 'cake', 'open', 1, 'land', 0.005, 0.9, 0.0, 0.0, 0.0, 0.0, NULL, NULL, 0, 'refused', 'outside', NULL, 0.0, 'now')";
    assert!(
        sqlx::raw_sql(refused).execute(&mut conn).await.is_err(),
        "refused is new"
    );
    migrate_from(&mut conn, at).await;
    sqlx::raw_sql(refused)
        .execute(&mut conn)
        .await
        .expect("a refused trial is stored");
    let kept: (i64, String, Vec<u8>) = sqlx::query_as(
        "SELECT t.trial_id, t.reason, c.measured_count FROM grasp_trials t JOIN grasp_traces c USING (trial_id)",
    )
    .fetch_one(&mut conn)
    .await
    .expect("the old trial and its trace");
    assert_eq!(kept, (7, "slip".to_owned(), vec![1, 2]));
    // The traces still cascade from their trials.
    sqlx::raw_sql("DELETE FROM grasp_trials WHERE trial_id = 7")
        .execute(&mut conn)
        .await
        .expect("deletes");
    let left: (i64,) = sqlx::query_as("SELECT COUNT(*) FROM grasp_traces")
        .fetch_one(&mut conn)
        .await
        .expect("counts");
    assert_eq!(left.0, 0);
    conn.close().await.expect("closes");
}

/// The migration that lets a stalled estimate be stored rebuilds the trials, their
/// traces and their frames: every row survives, the children still cascade, and a
/// trial failed with `estimate_stalled` can then be written.
#[tokio::test]
async fn the_estimate_stalled_migration_keeps_every_trial_trace_and_frame() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (mut conn, at) = migrated_before(dir.path(), "grasp trial estimate stalled").await;
    sqlx::raw_sql(
        "INSERT INTO grasp_sessions (session_id, created_at, model, seed, scenes_json, config_json, software_version) VALUES (1, 'then', 'm', 0, '[]', '{}', 'v');
         INSERT INTO grasp_trials VALUES (7, 1, 0, 0, 'cake', 'closed', 0, 'land', 0.005, 0.001, 0.0, 0.0, 0.02, 0.02, 1.2, NULL, 0, 'crush', NULL, NULL, 0.4, 'then');
         INSERT INTO grasp_traces VALUES (7, 2, 'f32le-v1', x'0000000000000040', x'0000000000000040', x'0000c07f0000c07f', x'0102', x'0304');
         INSERT INTO grasp_trial_frames VALUES (7, 'contact', 0.1, x'89504e470d0a1a0a00');",
    )
    .execute(&mut conn)
    .await
    .expect("an old session");
    let stalled = "INSERT INTO grasp_trials (trial_id, session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m, dx_m, dy_m, dz_m, commanded_width_m, final_width_m, peak_estimate_n, peak_true_n, success, reason, detail, confirmed_after_s, wall_s, created_at) \
         VALUES (8, 1, 0, 0, 'cake', 'closed', 1, 'land', 0.005, 0.0, 0.0, 0.0, 0.02, 0.01, 0.2, 30.0, 0, 'estimate_stalled', 'bound', NULL, 0.5, 'now')";
    assert!(
        sqlx::raw_sql(stalled).execute(&mut conn).await.is_err(),
        "estimate_stalled is new"
    );
    migrate_from(&mut conn, at).await;
    sqlx::raw_sql(stalled)
        .execute(&mut conn)
        .await
        .expect("a stalled trial is stored");
    let kept: (i64, String, Vec<u8>, Vec<u8>) = sqlx::query_as(
        "SELECT t.trial_id, t.reason, c.measured_count, f.png FROM grasp_trials t JOIN grasp_traces c USING (trial_id) JOIN grasp_trial_frames f USING (trial_id)",
    )
    .fetch_one(&mut conn)
    .await
    .expect("the old trial, its trace and its frame");
    assert_eq!(kept.0, 7);
    assert_eq!(kept.1, "crush");
    assert_eq!(kept.2, vec![1, 2]);
    assert_eq!(kept.3.len(), 9);
    sqlx::raw_sql("DELETE FROM grasp_trials WHERE trial_id = 7")
        .execute(&mut conn)
        .await
        .expect("deletes");
    let left: (i64, i64) = sqlx::query_as(
        "SELECT (SELECT COUNT(*) FROM grasp_traces), (SELECT COUNT(*) FROM grasp_trial_frames)",
    )
    .fetch_one(&mut conn)
    .await
    .expect("counts");
    assert_eq!(left, (0, 0));
    conn.close().await.expect("closes");
}

/// The migration that lets a false confirmation be stored rebuilds the trials, their
/// traces and their frames again: every row survives with its `past_touch_mm`, the
/// children still cascade, and a trial failed with `false_confirm` can be written.
#[tokio::test]
async fn the_false_confirm_migration_keeps_every_trial_trace_frame_and_past_touch() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (mut conn, at) = migrated_before(dir.path(), "grasp trial false confirm").await;
    sqlx::raw_sql(
        "INSERT INTO grasp_sessions (session_id, created_at, model, seed, scenes_json, config_json, software_version) VALUES (1, 'then', 'm', 0, '[]', '{}', 'v');
         INSERT INTO grasp_trials VALUES (7, 1, 0, 0, 'cake', 'closed', 0, 'water', 0.005, 0.001, 0.0, 0.0, 0.02, 0.02, 1.2, NULL, 0, 'miss', NULL, 0.3, 0.4, 'then', 2.5);
         INSERT INTO grasp_traces VALUES (7, 2, 'f32le-v1', x'0000000000000040', x'0000000000000040', x'0000c07f0000c07f', x'0102', x'0304');
         INSERT INTO grasp_trial_frames VALUES (7, 'contact', 0.1, x'89504e470d0a1a0a00');",
    )
    .execute(&mut conn)
    .await
    .expect("an old session");
    let phantom = "INSERT INTO grasp_trials (trial_id, session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m, dx_m, dy_m, dz_m, commanded_width_m, final_width_m, peak_estimate_n, peak_true_n, success, reason, detail, confirmed_after_s, wall_s, created_at) \
         VALUES (8, 1, 0, 0, 'cake', 'closed', 1, 'water', 0.005, 0.0, 0.0, 0.0, 0.02, 0.01, 1.5, 0.01, 0, 'false_confirm', NULL, 0.3, 0.5, 'now')";
    assert!(
        sqlx::raw_sql(phantom).execute(&mut conn).await.is_err(),
        "false_confirm is new"
    );
    migrate_from(&mut conn, at).await;
    sqlx::raw_sql(phantom)
        .execute(&mut conn)
        .await
        .expect("a false confirmation is stored");
    let kept: (i64, String, Option<f64>, Vec<u8>, Vec<u8>) = sqlx::query_as(
        "SELECT t.trial_id, t.reason, t.past_touch_mm, c.measured_count, f.png FROM grasp_trials t JOIN grasp_traces c USING (trial_id) JOIN grasp_trial_frames f USING (trial_id)",
    )
    .fetch_one(&mut conn)
    .await
    .expect("the old trial, its trace and its frame");
    assert_eq!((kept.0, kept.1.as_str(), kept.2), (7, "miss", Some(2.5)));
    assert_eq!((kept.3, kept.4.len()), (vec![1, 2], 9));
    sqlx::raw_sql("DELETE FROM grasp_trials WHERE trial_id = 7")
        .execute(&mut conn)
        .await
        .expect("deletes");
    let left: (i64, i64) = sqlx::query_as(
        "SELECT (SELECT COUNT(*) FROM grasp_traces), (SELECT COUNT(*) FROM grasp_trial_frames)",
    )
    .fetch_one(&mut conn)
    .await
    .expect("counts");
    assert_eq!(left, (0, 0));
    conn.close().await.expect("closes");
}
