//! The store on its own thread: a writer the collection job hands samples to.
//!
//! Why a thread: the collection job runs its devices on tokio's clock, which is paused
//! (virtual) for a simulated rig. sqlx does its SQLite work on a thread of its own, so
//! awaiting it from the job would let virtual time run on during every write. Here
//! the [`Store`] lives on a dedicated thread with its own real-time runtime, and the
//! job talks to it over a bounded channel: a blocked hand-off stops the job's thread
//! (and so virtual time) instead of idling its runtime.
//!
//! Samples and events are *submitted*: the writer encodes the frame as PNG and
//! commits the sample in one transaction while the job takes the next one, so storage
//! runs on the second core. The channel holds one operation, so at most two samples
//! are uncommitted at any moment (the one being written and the one handed over); a
//! kill loses those and nothing else, and never leaves a half-written sample. A write
//! error is reported by the next call, and no later sample is committed after it (a
//! resume takes every missing index, so nothing is left out for good).

use super::{
    Appended, EventLevel, FrameRecord, LeaseHolder, LeaseTaken, NewRun, RunId, RunRecord,
    RunStatus, Store, StoreError,
};
use crate::WrenchColumns;
use softtouch_drivers::Frame;
use softtouch_schemas::{FrameFormat, FrameMeta, FtReading, Medium, Sample, TimestampNs};
use std::sync::mpsc;
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

mod serve;
use serve::*;

type Reply<T> = mpsc::SyncSender<Result<T, StoreError>>;

enum Op {
    CreateRun {
        run: OwnedNewRun,
        reply: Reply<RunId>,
    },
    RunRecord {
        run_id: RunId,
        reply: Reply<RunRecord>,
    },
    NextIndex {
        run_id: RunId,
        reply: Reply<u64>,
    },
    MissingIndices {
        run_id: RunId,
        planned: u64,
        reply: Reply<Vec<u64>>,
    },
    AcquireLease {
        run_id: RunId,
        holder: LeaseHolder,
        reply: Reply<LeaseTaken>,
    },
    Heartbeat {
        run_id: RunId,
        holder: LeaseHolder,
    },
    ReleaseLease {
        run_id: RunId,
        holder: LeaseHolder,
        reply: Reply<()>,
    },
    Append {
        run_id: RunId,
        sample: Box<Sample>,
        frame: Option<Frame>,
        window: Vec<FtReading>,
        time_base: Option<TimestampNs>,
    },
    RunTimeBase {
        run_id: RunId,
        reply: Reply<Option<TimestampNs>>,
    },
    CheckPaired {
        run_id: RunId,
        source: RunId,
        reply: Reply<u64>,
    },
    SetRig {
        run_id: RunId,
        rig_toml: String,
        reply: Reply<()>,
    },
    RestFrames {
        run_id: RunId,
        frames: Vec<(FrameMeta, Vec<u8>)>,
        reply: Reply<u64>,
    },
    Event {
        run_id: RunId,
        index: Option<u64>,
        t: Option<TimestampNs>,
        level: EventLevel,
        kind: String,
        message: String,
    },
    Status {
        run_id: RunId,
        status: RunStatus,
        reply: Reply<()>,
    },
    Flush {
        reply: Reply<WriterStats>,
    },
    Labels {
        run_id: RunId,
        reply: Reply<Vec<LabelRow>>,
    },
}

/// A sample's label as stored, for benchmarks and checks.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct LabelRow {
    /// Index.
    pub sample_index: i64,
    /// Rod.
    pub rod: String,
    /// `ok` or `rejected`.
    pub status: String,
    /// Commanded pose.
    pub cmd_x_m: f64,
    /// Commanded pose.
    pub cmd_z_m: f64,
    /// Commanded pose.
    pub cmd_theta_rad: f64,
    /// The label: mean force and torque over the window, sensor frame.
    #[sqlx(flatten)]
    pub wrench: WrenchColumns,
}

/// [`NewRun`] with owned fields, to cross threads.
#[derive(Debug, Clone)]
pub struct OwnedNewRun {
    /// Seed.
    pub seed: u64,
    /// Samples planned.
    pub samples_planned: u64,
    /// Rods in order.
    pub rod_schedule: Vec<String>,
    /// Samples per rod.
    pub rod_block: u64,
    /// Scene name.
    pub scene_name: String,
    /// Medium.
    pub medium: Medium,
    /// Resolved rig.
    pub rig_toml: String,
    /// Resolved scene.
    pub scene_toml: String,
    /// The run whose poses and rods this one repeats (`collect --poses-from`).
    pub poses_from: Option<RunId>,
}

/// What the writer did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Samples committed.
    pub inserted: u64,
    /// Samples that were already stored (a resume overlapping its run).
    pub already_present: u64,
    /// Time spent encoding frames.
    pub encode: Duration,
    /// Time spent in the database.
    pub write: Duration,
    /// Samples dropped because an earlier one failed to commit (never committed past
    /// the gap). They are not a failure of their own: the first failure, which the
    /// caller is told of, already stops the run, and a resume takes them.
    pub refused_after_failure: u64,
}

#[derive(Debug, Default)]
struct Shared {
    /// The first error of a submitted operation, reported by the next call.
    failed: Option<StoreError>,
    /// A sample failed to commit: later samples are refused, not committed past the
    /// gap (events and status changes still go through, for the safe stop).
    append_failed: bool,
    stats: WriterStats,
}

/// A [`Store`] on its own thread.
#[derive(Debug)]
pub struct SyncStore {
    tx: Option<mpsc::SyncSender<Op>>,
    shared: Arc<Mutex<Shared>>,
    thread: Option<JoinHandle<()>>,
}

fn gone() -> StoreError {
    StoreError::Invalid {
        what: "request",
        why: "the store thread has stopped".into(),
    }
}

fn lock(shared: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Encode a frame for storage: raw RGB becomes PNG (lossless, fast compression);
/// encoded frames (PNG, JPEG) are kept as they came.
pub fn encode_for_store(frame: &Frame) -> Result<(FrameMeta, Vec<u8>), StoreError> {
    use image::ImageEncoder as _;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    match frame.meta.format {
        FrameFormat::Rgb8 => {
            let (w, h) = (frame.meta.width, frame.meta.height);
            if frame.data.len() as u64 != u64::from(w) * u64::from(h) * 3 {
                return Err(StoreError::Invalid {
                    what: "frame",
                    why: format!("{} bytes is not {w}×{h} RGB", frame.data.len()),
                });
            }
            let mut png = Vec::with_capacity(frame.data.len() / 2);
            PngEncoder::new_with_quality(&mut png, CompressionType::Fast, FilterType::Sub)
                .write_image(&frame.data, w, h, image::ExtendedColorType::Rgb8)
                .map_err(|e| StoreError::Invalid {
                    what: "frame",
                    why: e.to_string(),
                })?;
            Ok((
                FrameMeta {
                    format: FrameFormat::Png,
                    ..frame.meta
                },
                png,
            ))
        }
        FrameFormat::Png | FrameFormat::Jpeg => Ok((frame.meta, frame.data.clone())),
    }
}

impl SyncStore {
    /// Open (creating and migrating) the database at `path` on a new thread.
    pub fn open(target: impl Into<crate::DbTarget>) -> Result<Self, StoreError> {
        let (tx, rx) = mpsc::sync_channel::<Op>(1);
        let (ready_tx, ready_rx) = mpsc::sync_channel::<Result<(), StoreError>>(1);
        let shared = Arc::new(Mutex::new(Shared::default()));
        let target = target.into();
        let writer_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("softtouch-store".into())
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        let _ = ready_tx.send(Err(StoreError::Invalid {
                            what: "store runtime",
                            why: e.to_string(),
                        }));
                        return;
                    }
                };
                let store = match rt.block_on(Store::open(target)) {
                    Ok(s) => {
                        let _ = ready_tx.send(Ok(()));
                        s
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                for op in rx {
                    rt.block_on(serve(&store, op, &writer_shared));
                }
                rt.block_on(store.close());
            })
            .map_err(|e| StoreError::Invalid {
                what: "store thread",
                why: e.to_string(),
            })?;
        ready_rx.recv().map_err(|_| gone())??;
        Ok(Self {
            tx: Some(tx),
            shared,
            thread: Some(thread),
        })
    }

    /// The error of a submitted operation not yet reported, if any (taking it: the
    /// next call will not report it again).
    pub fn take_failure(&self) -> Option<StoreError> {
        lock(&self.shared).failed.take()
    }

    fn check(&self) -> Result<(), StoreError> {
        match lock(&self.shared).failed.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    fn send(&self, op: Op) -> Result<(), StoreError> {
        self.check()?;
        self.tx
            .as_ref()
            .ok_or_else(gone)?
            .send(op)
            .map_err(|_| gone())
    }

    fn call<T>(&self, make: impl FnOnce(Reply<T>) -> Op) -> Result<T, StoreError> {
        let (reply, answer) = mpsc::sync_channel(1);
        self.send(make(reply))?;
        let result = answer.recv().map_err(|_| gone())?;
        self.check()?;
        result
    }

    /// See [`Store::create_run`].
    pub fn create_run(&self, run: OwnedNewRun) -> Result<RunId, StoreError> {
        self.call(|reply| Op::CreateRun { run, reply })
    }

    /// See [`Store::run_record`].
    pub fn run_record(&self, run_id: RunId) -> Result<RunRecord, StoreError> {
        self.call(|reply| Op::RunRecord { run_id, reply })
    }

    /// See [`Store::next_index`] (after every submitted sample is committed).
    pub fn next_index(&self, run_id: RunId) -> Result<u64, StoreError> {
        self.call(|reply| Op::NextIndex { run_id, reply })
    }

    /// See [`Store::missing_indices`] (after every submitted sample is committed).
    pub fn missing_indices(&self, run_id: RunId, planned: u64) -> Result<Vec<u64>, StoreError> {
        self.call(|reply| Op::MissingIndices {
            run_id,
            planned,
            reply,
        })
    }

    /// See [`Store::acquire_lease`].
    pub fn acquire_lease(
        &self,
        run_id: RunId,
        holder: &LeaseHolder,
    ) -> Result<LeaseTaken, StoreError> {
        self.call(|reply| Op::AcquireLease {
            run_id,
            holder: holder.clone(),
            reply,
        })
    }

    /// Hand a lease renewal to the writer (see [`Store::heartbeat`]); a lost lease is
    /// reported by the next call.
    pub fn heartbeat(&self, run_id: RunId, holder: &LeaseHolder) -> Result<(), StoreError> {
        self.send(Op::Heartbeat {
            run_id,
            holder: holder.clone(),
        })
    }

    /// See [`Store::release_lease`] (after everything submitted is written).
    pub fn release_lease(&self, run_id: RunId, holder: &LeaseHolder) -> Result<(), StoreError> {
        self.call(|reply| Op::ReleaseLease {
            run_id,
            holder: holder.clone(),
            reply,
        })
    }

    /// Hand a sample to the writer: its frame is encoded and the sample, frame and
    /// window committed in one transaction (see [`Store::append_sample`]). Blocks only
    /// while the writer is busy with the previous one.
    pub fn submit_sample(
        &self,
        run_id: RunId,
        sample: Sample,
        frame: Option<Frame>,
        window: Vec<FtReading>,
    ) -> Result<(), StoreError> {
        self.submit_sample_at(run_id, sample, frame, window, None)
    }

    /// [`SyncStore::submit_sample`], also recording the run's time base in the same
    /// transaction (see [`Store::append_sample_at`]).
    pub fn submit_sample_at(
        &self,
        run_id: RunId,
        sample: Sample,
        frame: Option<Frame>,
        window: Vec<FtReading>,
        time_base: Option<TimestampNs>,
    ) -> Result<(), StoreError> {
        self.send(Op::Append {
            run_id,
            sample: Box::new(sample),
            frame,
            window,
            time_base,
        })
    }

    /// See [`Store::set_run_rig`].
    pub fn set_run_rig(&self, run_id: RunId, rig_toml: &str) -> Result<(), StoreError> {
        self.call(|reply| Op::SetRig {
            run_id,
            rig_toml: rig_toml.to_owned(),
            reply,
        })
    }

    /// See [`Store::insert_rest_frames`]: `frames` as [`encode_for_store`] gives them.
    pub fn insert_rest_frames(
        &self,
        run_id: RunId,
        frames: Vec<(FrameMeta, Vec<u8>)>,
    ) -> Result<u64, StoreError> {
        self.call(|reply| Op::RestFrames {
            run_id,
            frames,
            reply,
        })
    }

    /// See [`Store::run_time_base`] (after every submitted sample is committed).
    pub fn run_time_base(&self, run_id: RunId) -> Result<Option<TimestampNs>, StoreError> {
        self.call(|reply| Op::RunTimeBase { run_id, reply })
    }

    /// See [`Store::check_paired_poses`] (after every submitted sample is committed).
    pub fn check_paired_poses(&self, run_id: RunId, source: RunId) -> Result<u64, StoreError> {
        self.call(|reply| Op::CheckPaired {
            run_id,
            source,
            reply,
        })
    }

    /// Hand an event to the writer (see [`Store::log_event`]); events and samples are
    /// written in the order they were submitted.
    pub fn log_event(
        &self,
        run_id: RunId,
        index: Option<u64>,
        t: Option<TimestampNs>,
        level: EventLevel,
        kind: &str,
        message: &str,
    ) -> Result<(), StoreError> {
        // Also to the log file (before the store, which may be what failed); the
        // binary keeps target `softtouch::event` off stderr.
        let t_s = t.map(|t| t.as_secs_f64());
        match level {
            EventLevel::Info => {
                tracing::info!(target: "softtouch::event", run = ?run_id, sample = ?index, t_s = ?t_s, kind, "{message}");
            }
            EventLevel::Warn => {
                tracing::warn!(target: "softtouch::event", run = ?run_id, sample = ?index, t_s = ?t_s, kind, "{message}");
            }
            EventLevel::Error => {
                tracing::error!(target: "softtouch::event", run = ?run_id, sample = ?index, t_s = ?t_s, kind, "{message}");
            }
        }
        self.send(Op::Event {
            run_id,
            index,
            t,
            level,
            kind: kind.to_owned(),
            message: message.to_owned(),
        })
    }

    /// See [`Store::set_run_status`] (after everything submitted is written).
    pub fn set_run_status(&self, run_id: RunId, status: RunStatus) -> Result<(), StoreError> {
        self.call(|reply| Op::Status {
            run_id,
            status,
            reply,
        })
    }

    /// Wait until everything submitted is committed; what the writer did so far.
    pub fn flush(&self) -> Result<WriterStats, StoreError> {
        self.call(|reply| Op::Flush { reply })
    }

    /// Every sample's label in a run (after everything submitted is written).
    pub fn labels(&self, run_id: RunId) -> Result<Vec<LabelRow>, StoreError> {
        self.call(|reply| Op::Labels { run_id, reply })
    }

    /// Close the database and join its thread.
    pub fn close(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.tx = None; // ends the thread's loop once the queue is written
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for SyncStore {
    fn drop(&mut self) {
        self.shutdown();
    }
}
