//! The writer thread's side: each request carried out on the store, in order, with the failure rule (nothing committed past a failed sample).

use super::*;

pub(super) async fn serve(store: &Store, op: Op, shared: &Mutex<Shared>) {
    let fail = |e: StoreError| {
        let mut s = lock(shared);
        if s.failed.is_none() {
            s.failed = Some(e);
        }
    };
    // A closed reply channel means the caller is gone; nothing to tell it.
    match op {
        Op::CreateRun { run, reply } => {
            let new = NewRun {
                seed: run.seed,
                samples_planned: run.samples_planned,
                rod_schedule: &run.rod_schedule,
                rod_block: run.rod_block,
                scene_name: &run.scene_name,
                medium: run.medium,
                rig_toml: &run.rig_toml,
                scene_toml: &run.scene_toml,
                poses_from: run.poses_from,
            };
            let _ = reply.send(store.create_run(&new).await);
        }
        Op::RunRecord { run_id, reply } => {
            let _ = reply.send(store.run_record(run_id).await);
        }
        Op::NextIndex { run_id, reply } => {
            let _ = reply.send(store.next_index(run_id).await);
        }
        Op::MissingIndices {
            run_id,
            planned,
            reply,
        } => {
            let _ = reply.send(store.missing_indices(run_id, planned).await);
        }
        Op::AcquireLease {
            run_id,
            holder,
            reply,
        } => {
            let _ = reply.send(store.acquire_lease(run_id, &holder).await);
        }
        Op::Heartbeat { run_id, holder } => {
            if let Err(e) = store.heartbeat(run_id, &holder).await {
                fail(e);
            }
        }
        Op::ReleaseLease {
            run_id,
            holder,
            reply,
        } => {
            let _ = reply.send(store.release_lease(run_id, &holder).await);
        }
        Op::Append {
            run_id,
            sample,
            frame,
            window,
            time_base,
        } => {
            {
                // Reported once, as the first failure: whether a later sample reached
                // the writer before the job saw that failure is a matter of timing, and
                // must not change what the run reports.
                let mut s = lock(shared);
                if s.append_failed {
                    s.stats.refused_after_failure += 1;
                    drop(s);
                    tracing::warn!(
                        sample = sample.index,
                        "sample not written: an earlier sample failed to commit, and later \
                         ones are not committed past the gap"
                    );
                    return;
                }
            }
            let started = Instant::now();
            let encoded = match frame.as_ref().map(encode_for_store).transpose() {
                Ok(e) => e,
                Err(e) => {
                    lock(shared).append_failed = true;
                    return fail(e);
                }
            };
            let encoded_at = Instant::now();
            let record = encoded
                .as_ref()
                .map(|(meta, data)| FrameRecord { meta: *meta, data });
            let result = store
                .append_sample_at(run_id, &sample, record, &window, time_base)
                .await;
            let mut s = lock(shared);
            s.stats.encode += encoded_at - started;
            s.stats.write += encoded_at.elapsed();
            match result {
                Ok(Appended::Inserted) => s.stats.inserted += 1,
                Ok(Appended::AlreadyPresent) => s.stats.already_present += 1,
                Err(e) => {
                    s.append_failed = true;
                    drop(s);
                    fail(e);
                }
            }
        }
        Op::RunTimeBase { run_id, reply } => {
            let _ = reply.send(store.run_time_base(run_id).await);
        }
        Op::CheckPaired {
            run_id,
            source,
            reply,
        } => {
            let _ = reply.send(store.check_paired_poses(run_id, source).await);
        }
        Op::SetRig {
            run_id,
            rig_toml,
            reply,
        } => {
            let _ = reply.send(store.set_run_rig(run_id, &rig_toml).await);
        }
        Op::RestFrames {
            run_id,
            frames,
            reply,
        } => {
            let records: Vec<crate::FrameRecord<'_>> = frames
                .iter()
                .map(|(meta, data)| crate::FrameRecord { meta: *meta, data })
                .collect();
            let _ = reply.send(store.insert_rest_frames(run_id, &records).await);
        }
        Op::Event {
            run_id,
            index,
            t,
            level,
            kind,
            message,
        } => {
            if let Err(e) = store
                .log_event(run_id, index, t, level, &kind, &message)
                .await
            {
                fail(e);
            }
        }
        Op::Status {
            run_id,
            status,
            reply,
        } => {
            let _ = reply.send(store.set_run_status(run_id, status).await);
        }
        Op::Labels { run_id, reply } => {
            let rows = sqlx::query_as::<_, LabelRow>(store.dialect().sql(
                "SELECT sample_index, rod, status, cmd_x_m, cmd_z_m, cmd_theta_rad,
                        fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm
                 FROM samples WHERE run_id = ? ORDER BY sample_index",
            ))
            .bind(run_id)
            .fetch_all(store.pool())
            .await
            .map_err(|source| StoreError::Query {
                doing: "reading labels",
                source,
            });
            let _ = reply.send(rows);
        }
        Op::Flush { reply } => {
            let stats = lock(shared).stats;
            let _ = reply.send(Ok(stats));
        }
    }
}
