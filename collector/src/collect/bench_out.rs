//! What `bench collection` and `bench ingest` measure beside the sweep itself: the
//! sweep's table, CSV and charts, and the store's ingest rate on rendered frames.

use super::bench::{BenchError, Breakdown, SweepPoint};
use crate::plot::{Series, SeriesStyle, XyChart, xy_chart};
use crate::store::{OwnedNewRun, SyncStore};
use crate::synthetic::SampleBuilder;
use softtouch_drivers::Frame;
use softtouch_schemas::{ContactPose, FrameFormat, FrameMeta, Medium, TimestampNs};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The sweep as a person reads it: where a sample's time goes at the rig's defaults,
/// then one line per (settle, window) point.
#[must_use]
pub fn sweep_table(points: &[SweepPoint], b: &Breakdown, default_point: (f64, f64)) -> String {
    let mut table = format!(
        "Where a sample's time goes (rig defaults: settle {} s, window {} s; {} samples):\n\
         \x20 job thread, median per sample: {:.2} ms wall = {:.2} ms in device code (simulation) + {:.3} ms orchestration (p95 {:.3} ms)\n\
         \x20 writer thread (second core), mean per sample: {:.2} ms PNG encode + {:.2} ms SQLite\n\n",
        default_point.0,
        default_point.1,
        b.samples,
        b.wall_ms,
        b.device_ms,
        b.orchestration_ms,
        b.orchestration_p95_ms,
        b.encode_ms,
        b.write_ms
    );
    table.push_str(
        "settle    settle_s  mean_s  window_s  accepted  force_rmse_N  torque_rmse_Nmm  samples_per_hour\n",
    );
    for p in points {
        table.push_str(&format!(
            "{:<8}  {:>8}  {:>6.3}  {:>8}  {:>4}/{:<3}  {:>12.5}  {:>15.3}  {:>16.0}\n",
            p.settle_end.as_str(),
            p.settle_s,
            p.mean_settle_s,
            p.window_s,
            p.accepted,
            p.samples,
            p.force_rmse_n,
            p.torque_rmse_nmm,
            p.samples_per_hour
        ));
    }
    table
}

/// Writes `collection-sweep.csv` and one chart per label (force, torque) of error
/// against throughput into `dir`; returns the paths written.
///
/// # Errors
/// [`BenchError::Output`] naming the file that could not be written or drawn.
pub fn write_sweep_files(dir: &Path, points: &[SweepPoint]) -> Result<Vec<PathBuf>, BenchError> {
    let mut csv = String::from(
        "settle_end,settle_s,mean_settle_s,window_s,samples,accepted,force_rmse_n,torque_rmse_nmm,samples_per_hour,wall_s\n",
    );
    for p in points {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{}\n",
            p.settle_end.as_str(),
            p.settle_s,
            p.mean_settle_s,
            p.window_s,
            p.samples,
            p.accepted,
            p.force_rmse_n,
            p.torque_rmse_nmm,
            p.samples_per_hour,
            p.wall_s
        ));
    }
    let csv_path = dir.join("collection-sweep.csv");
    std::fs::write(&csv_path, csv)
        .map_err(|e| BenchError::Output(format!("cannot write {}: {e}", csv_path.display())))?;
    let mut windows: Vec<f64> = points.iter().map(|p| p.window_s).collect();
    windows.sort_by(f64::total_cmp);
    windows.dedup();
    let fixed = |p: &&SweepPoint| p.settle_end == softtouch_schemas::rig::SettleEnd::Fixed;
    let mut written = vec![csv_path];
    for (name, unit, pick) in [
        (
            "force",
            "N",
            (|p: &SweepPoint| p.force_rmse_n) as fn(&SweepPoint) -> f64,
        ),
        ("torque", "N·mm", |p: &SweepPoint| p.torque_rmse_nmm),
    ] {
        let mut series: Vec<Series> = windows
            .iter()
            .map(|w| Series {
                label: format!("window {w} s"),
                points: points
                    .iter()
                    .filter(fixed)
                    .filter(|p| p.window_s.total_cmp(w).is_eq())
                    .map(|p| (p.samples_per_hour, pick(p)))
                    .collect(),
                style: SeriesStyle::LinePoints,
            })
            .collect();
        // The signal-ended settles: one point per window, apart from the fixed lines.
        let signal: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| !fixed(p))
            .map(|p| (p.samples_per_hour, pick(p)))
            .collect();
        if !signal.is_empty() {
            series.push(Series {
                label: "settle ended by the signal".into(),
                points: signal,
                style: SeriesStyle::Points,
            });
        }
        let path = dir.join(format!("collection-sweep-{name}.png"));
        let title = format!("{name} label error vs throughput (lines: fixed settle times)");
        let y = format!("{name} RMS error [{unit}]");
        xy_chart(
            &path,
            &XyChart {
                title: &title,
                x_label: "samples per hour (rig clock)",
                y_label: &y,
                series: &series,
            },
            (900, 600),
        )
        .map_err(|e| BenchError::Output(e.to_string()))?;
        written.push(path);
    }
    Ok(written)
}

/// A few real rendered frames of the default scene (raw RGB, 640×480).
///
/// # Errors
/// [`BenchError::Sim`] when the simulator cannot render the default scene.
pub fn rendered_frames() -> Result<Vec<Frame>, BenchError> {
    let scene = softtouch_schemas::defaults::scene();
    (0..4)
        .map(|k| {
            let pose = ContactPose {
                x_m: 0.01 * f64::from(k),
                z_m: 0.01,
                theta_rad: f64::from(k),
            };
            let r = softtouch_sim::render_contact(&scene, "circle-10", &pose, 0)
                .map_err(|e| BenchError::Sim(e.to_string()))?;
            let (w, h) = r.image.dimensions();
            Ok(Frame {
                meta: FrameMeta {
                    t: TimestampNs(0),
                    sequence: u64::try_from(k).unwrap_or(0),
                    width: w,
                    height: h,
                    format: FrameFormat::Rgb8,
                },
                data: r.image.into_raw(),
            })
        })
        .collect()
}

/// Times `samples` samples into `store` twice, each in a run of its own: frames that
/// the writer encodes to PNG, then frames already encoded. Returns the table.
///
/// # Errors
/// The store's, or the simulator's for the frames.
pub fn time_ingest(store: &SyncStore, samples: u64) -> Result<String, BenchError> {
    let raw = rendered_frames()?;
    let mut text = String::from("case                      samples   seconds   samples/s\n");
    for (case, encoded) in [("raw RGB → PNG → SQLite", false), ("PNG → SQLite", true)] {
        let run = bench_run(store, 0, samples, format!("bench ingest: {case}"))?;
        let frames: Vec<Frame> = if encoded {
            raw.iter()
                .map(|f| crate::store::encode_for_store(f).map(|(meta, data)| Frame { meta, data }))
                .collect::<Result<_, _>>()?
        } else {
            raw.clone()
        };
        let started = Instant::now();
        submit_samples(store, run, &frames, samples)?;
        let secs = started.elapsed().as_secs_f64();
        text.push_str(&format!(
            "{case:<24}  {samples:>7}  {secs:>8.2}  {:>10.0}\n",
            samples as f64 / secs
        ));
    }
    Ok(text)
}

/// A run for the ingest bench to write into.
fn bench_run(
    store: &SyncStore,
    seed: u64,
    samples: u64,
    scene_name: String,
) -> Result<crate::store::RunId, BenchError> {
    Ok(store.create_run(OwnedNewRun {
        seed,
        samples_planned: samples,
        rod_schedule: vec!["circle-10".into()],
        rod_block: samples.max(1),
        scene_name,
        medium: Medium::Air,
        rig_toml: String::new(),
        scene_toml: String::new(),
        poses_from: None,
    })?)
}

/// Submits `samples` synthetic samples to `run`, the frames taken in turn, and waits
/// until every one is committed.
fn submit_samples(
    store: &SyncStore,
    run: crate::store::RunId,
    frames: &[Frame],
    samples: u64,
) -> Result<(), BenchError> {
    for i in 0..samples {
        let frame = frames[usize::try_from(i).unwrap_or(0) % frames.len()].clone();
        let sample = SampleBuilder::new(i);
        let window = sample.window();
        store.submit_sample(run, sample.build(), Some(frame), window)?;
    }
    store.flush()?;
    Ok(())
}

/// Several rigs writing one store at once: `rigs` threads, each with a store of its own
/// (its own writer thread and connections, as a collector process has) and a run of
/// its own, each submitting `samples` samples with raw 640×480 frames (PNG-encoded on
/// its writer thread, as collection does). The wall time from the first submission to
/// the last commit, in seconds.
///
/// # Errors
/// A store that fails to open or write.
pub fn time_rigs(
    target: &crate::store::DbTarget,
    rigs: usize,
    samples: u64,
) -> Result<f64, BenchError> {
    let raw = std::sync::Arc::new(rendered_frames()?);
    let stores = (0..rigs)
        .map(|_| SyncStore::open(target.clone()))
        .collect::<Result<Vec<_>, _>>()?;
    let runs = stores
        .iter()
        .enumerate()
        .map(|(i, store)| {
            bench_run(
                store,
                i as u64,
                samples,
                format!("bench ingest: rig {i} of {rigs}"),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let started = Instant::now();
    let results: Vec<Result<(), BenchError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = stores
            .iter()
            .zip(&runs)
            .map(|(store, &run)| {
                let raw = std::sync::Arc::clone(&raw);
                scope.spawn(move || submit_samples(store, run, &raw, samples))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(BenchError::Sim("a rig's thread panicked".into())))
            })
            .collect()
    });
    let secs = started.elapsed().as_secs_f64();
    for store in stores {
        store.close();
    }
    for r in results {
        r?;
    }
    Ok(secs)
}

/// The database's size line under the ingest table: the file and its write-ahead log
/// (measure after the store is closed, when the log has been folded in).
#[must_use]
pub fn db_size_line(db: &Path) -> String {
    let size = crate::store::sqlite_file::db_size(db).total();
    format!(
        "database size: {:.1} MB ({})\n",
        size as f64 / 1e6,
        db.display()
    )
}
