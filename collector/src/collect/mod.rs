//! The collection job: sample contact poses, move the arm, pair a frame with a window
//! of force/torque readings, store each sample durably, and survive faults.
//!
//! One sample is a small state machine, `approach → settle → record → retreat`:
//! - **approach**: the target is checked against the workspace before it reaches the
//!   arm; free space is crossed at the travel speed up to `standoff_m` short of the
//!   finger's first touch, then the approach speed, the last millimetres slow; every
//!   move races a force guard (contact force or torque over the rig's limit stops the
//!   arm and aborts the attempt);
//! - **settle**: until the force/torque signal has settled (its drift within the
//!   sensor's noise, [`settle`]), at most `settle_s`; or `settle_s` (`settle_end =
//!   "fixed"`);
//! - **record**: ask the camera for the first frame after settling, and take the
//!   force/torque readings in a window around that frame's time;
//! - **retreat**: straight back along the approach axis (the rod frame's x, z and θ
//!   kept) at the retreat speed to the sample's retreat point (home's x), guarded;
//!   only then does anything turn or travel: on to the next sample of the [`route`],
//!   or home between rods and after an error (with `visit_order = "index"`, home
//!   after every sample). Every
//!   approach starts from its retreat point, so it runs along the approach axis alone.
//!   From wherever the finger may touch the rod (a guard trip, a fault, a stop, the end
//!   of a run, a start after a crash) the arm leaves the same way; a force that rises
//!   while it leaves (the finger caught) stops it and ends the run safely.
//!
//! Faults: an arm reflex is recovered automatically with backoff and the sample tried
//! again; a sensor fault, a bad window or a frame timeout retries the sample; when the
//! attempts run out the sample is stored as rejected with its reason. After too many
//! failed samples in a row the run stops safely (stop, retreat, flush, event, error).
//! Everything that goes wrong is an event in the store, a stop the arm refused included.
//!
//! Time: a run's device time continues across a resume. Each sample is stored with the
//! run's time base (the clock when its retreat ended, where the next sample begins);
//! a resumed job's clock starts [`RESUME_STARTUP_NS`] before it ([`clock_start`]), does
//! its startup (stream, home, a per-run tare) and waits until the time base before its
//! first sample. On a simulated rig (virtual time) that wait is free and the resumed
//! run is bit-identical to an uninterrupted one; on a real rig it is a few seconds
//! once per resume, and a run's timestamps stay monotonic.
//!
//! # Layout
//! - this module: the job loop (rods, samples in order, failures in a row);
//! - `finish`: the safe stop at its end, whatever ended it (stop, retreat, stream
//!   counts, completeness, the run's final status, the lease), and every move that is
//!   not an approach: leaving the rod along the approach axis, travel and homing
//!   (guarded against a force that rises), the elbow back to home's joints;
//! - `procedure`: one sample's state machine, its retries, and storing it;
//! - [`plan`]: what to collect, for a new run or the rest of a stored one;
//! - [`devices`]: the devices of a collection, built from the rig config;
//! - [`sampler`]: contact poses and the rod schedule;
//! - [`window`]: the force/torque stream and a sample's label window;
//! - [`settle`]: when the signal has settled (the settle ended by the signal);
//! - [`route`]: the order a rod's block is visited in, and the retreat points;
//! - [`phases`]: where a sample's time goes;
//! - [`rods`]: changing the rod (an operator, or the simulator);
//! - [`bench`](mod@bench): what collection costs, and where its time goes.

pub mod bench;
pub mod bench_out;
pub mod devices;
pub mod disk;
mod finish;
pub mod phases;
pub mod plan;
mod procedure;
mod rest;
pub use procedure::retreat_x_m;
pub use rest::{REST_FRAMES, REST_SPACING_S, rest_frames};
pub mod rods;
pub mod route;
pub mod sampler;
pub mod settle;
pub mod window;

pub use devices::{CollectDevices, build_devices, build_devices_at};
pub use plan::{CollectPlan, NewRunRequest, PlanError, Resumed};

use crate::devices::SelectError;
use crate::store::{EventKind, EventLevel, RunId, RunStatus, StoreError, SyncStore};
use procedure::SampleEnd;
use rods::RodChanger;
use sampler::PoseSampler;
pub use softtouch_drivers::GuardTrip;
use softtouch_drivers::{Arm, Camera, Clock, DeviceError, TokioClock};
use softtouch_schemas::rig::{FT_BUFFER_S, Tare, VisitOrder};
use softtouch_schemas::{ArmPose, ContactPose, SampleStatus, TimestampNs};
use std::time::Duration;
use tokio::sync::watch;
use window::{FtStream, WindowRules};

/// How a collection ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Every planned sample is stored.
    Completed,
    /// The operator stopped it (Ctrl-C); it can be resumed.
    Stopped,
    /// A safe stop after faults; it can be resumed once the cause is fixed.
    SafeStop {
        /// Why.
        reason: String,
    },
}

/// Counts of what happened, for progress and the final report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Samples stored as accepted.
    pub ok: u64,
    /// Samples stored as rejected.
    pub rejected: u64,
    /// Samples that were already stored (resume overlap), known at the end.
    pub already_present: u64,
    /// Extra attempts.
    pub retries: u64,
    /// Arm reflexes.
    pub arm_faults: u64,
    /// Frame timeouts.
    pub frame_timeouts: u64,
    /// Windows refused (any reason) before retrying.
    pub bad_windows: u64,
    /// Where the samples' time went.
    pub phases: phases::PhaseTimes,
}

/// Where progress goes (a bar on a terminal, log lines otherwise).
pub trait Progress: Send {
    /// A sample is done (stored or skipped).
    fn sample_done(&mut self, index: u64, counters: &Counters);
    /// Something worth telling the operator.
    fn note(&mut self, message: &str);
}

/// Stop requests: the count of Ctrl-C presses (1 = finish the sample and stop,
/// 2 = stop now).
pub type StopSignal = watch::Receiver<u32>;

/// A collection that could not go on. The store and devices are left safe.
#[derive(Debug, thiserror::Error)]
pub enum CollectError {
    /// The store failed: nothing more can be recorded.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A device failed in a way the job cannot handle (e.g. the sensor would not start).
    #[error(transparent)]
    Device(#[from] DeviceError),
}

/// Logs a run's events, stamped with the rig's clock. Apart from the job so that it
/// still works while the job is being taken apart at the end.
#[derive(Clone, Copy)]
struct RunEvents<'a> {
    store: &'a SyncStore,
    run: RunId,
    clock: TokioClock,
}

impl RunEvents<'_> {
    fn log(
        &self,
        kind: EventKind,
        level: EventLevel,
        sample: Option<u64>,
        message: &str,
    ) -> Result<(), StoreError> {
        self.store.log_event(
            self.run,
            sample,
            Some(self.clock.now()),
            level,
            kind.as_str(),
            message,
        )
    }
}

struct Job<'a> {
    store: &'a SyncStore,
    plan: &'a CollectPlan,
    events: RunEvents<'a>,
    clock: TokioClock,
    arm: Box<dyn Arm>,
    camera: Box<dyn Camera>,
    ft: FtStream,
    rules: WindowRules,
    home: ArmPose,
    counters: Counters,
    stop: StopSignal,
    /// The sample being taken (or the next one): where a forced stop cut in.
    next_index: u64,
    /// A store error met where the job could not stop for it (a retreat goes on
    /// whatever the store does); the sample loop stops on it.
    store_failed: Option<StoreError>,
    /// The contact pose whose approach began and whose leave has not ended: where the
    /// finger may touch the rod. A retreat from anywhere leaves along its approach
    /// axis first.
    near_rod: Option<ContactPose>,
    /// The arm's joints where the run first reached home (an arm with joints): the
    /// elbow goes back to them at each block's end (`reset_elbow`).
    home_joints: Option<[f64; 7]>,
}

/// How long before a resumed run's time base its job's clock starts, ns: room for the
/// startup before the first sample (the sensor's stream, the move home, a per-run
/// tare). A startup that takes longer makes the resumed samples begin late (logged).
pub const RESUME_STARTUP_NS: u64 = 10_000_000_000;

/// Where the clock of a job collecting `run` starts: 0 for a run with nothing stored,
/// else [`RESUME_STARTUP_NS`] before the run's time base (clamped at 0).
///
/// # Errors
/// The store failed, or has no such run.
pub fn clock_start(store: &SyncStore, run: RunId) -> Result<TimestampNs, StoreError> {
    Ok(store.run_time_base(run)?.map_or(TimestampNs::ZERO, |base| {
        TimestampNs(base.0.saturating_sub(RESUME_STARTUP_NS))
    }))
}

/// Why the devices of a job could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// A device could not be opened, or the simulator built.
    #[error(transparent)]
    Devices(#[from] SelectError),
    /// The run's time base could not be read.
    #[error("cannot read where the run's device time continues: {0}")]
    Store(#[from] StoreError),
}

/// The devices of `plan` on a clock that continues the run's device time
/// ([`clock_start`]); what `softtouch collect` uses, for new and resumed runs alike.
///
/// # Errors
/// A device that cannot be opened, a simulator that cannot be built, a store error.
///
/// # Panics
/// As [`build_devices`].
pub async fn build_run_devices(
    store: &SyncStore,
    plan: &CollectPlan,
) -> Result<(CollectDevices, TokioClock), SetupError> {
    let start = clock_start(store, plan.run_id)?;
    Ok(build_devices_at(&plan.rig, &plan.scene, plan.seed, start).await?)
}

/// Backoff before the `n`th recovery attempt (1-based): 0.5 s doubling, at most 8 s.
#[must_use]
pub fn recovery_backoff(n: u32) -> Duration {
    Duration::from_millis(500u64.saturating_mul(1 << n.saturating_sub(1).min(4)))
}

/// Run the collection `plan` on `devices`, storing into `store`. Returns how it ended;
/// the run's status in the store says the same where the store still accepted it.
///
/// Every way out goes through the same end: the arm is stopped and (unless a forced
/// stop asked otherwise) sent home, the stream stopped, the end recorded (a
/// `safe_stop` event and status `failed` after any fault, a store error included),
/// and the run's lease given back. A second stop request (see [`StopSignal`])
/// interrupts whatever the job awaits (a move, a wait, the operator's prompt) and
/// stops the arm at once. A run ends `completed` only when the store holds every
/// planned index.
pub async fn collect(
    store: &SyncStore,
    plan: &CollectPlan,
    devices: CollectDevices,
    clock: TokioClock,
    stop: StopSignal,
    progress: &mut dyn Progress,
) -> (Outcome, Counters) {
    let rate_hz = match &plan.rig.force_sensor {
        softtouch_schemas::ForceSensorDevice::Sim { rate_hz }
        | softtouch_schemas::ForceSensorDevice::NetFt { rate_hz, .. } => *rate_hz,
        softtouch_schemas::ForceSensorDevice::AtiSerial { .. } => 7000.0,
    };
    // Hold seconds of readings: the rig check keeps every window within half of it.
    let capacity = (rate_hz * FT_BUFFER_S).ceil().max(1024.0) as usize;
    let ft = match FtStream::spawn(devices.force_sensor, capacity).await {
        Ok(ft) => ft,
        Err(e) => {
            let reason = format!("force_sensor: cannot start the stream: {e}");
            let reason = abandon(store, plan, &reason);
            return (Outcome::SafeStop { reason }, Counters::default());
        }
    };
    let l = &plan.rig.limits;
    let w = &plan.rig.workspace;
    let mut job = Job {
        store,
        plan,
        events: RunEvents {
            store,
            run: plan.run_id,
            clock,
        },
        clock,
        arm: devices.arm,
        camera: devices.camera,
        ft,
        rules: WindowRules {
            min_readings: plan.rig.procedure.min_window_readings,
            range: l.sensor_range(),
        },
        home: ArmPose::from_contact(&w.base_from_rod, &w.home),
        counters: Counters::default(),
        stop: stop.clone(),
        next_index: plan.indices().next().unwrap_or(plan.end_index),
        store_failed: None,
        near_rod: None,
        home_joints: None,
    };
    let ended = tokio::select! {
        ended = job.run_samples(devices.rods, progress) => ended,
        // Drops the sample loop wherever it waits; `finish` stops the arm first thing.
        () = forced_stop(stop) => Ok((Outcome::Stopped, job.next_index)),
    };
    let outcome = match ended {
        Ok((outcome, _)) => outcome,
        Err(CollectError::Store(e)) => Outcome::SafeStop {
            reason: format!("the store failed: {e}"),
        },
        Err(CollectError::Device(e)) => Outcome::SafeStop {
            reason: format!("a device failed: {e}"),
        },
    };
    job.finish(outcome).await
}

/// Log an event; a store error is kept in `failed` (the first one) instead of
/// stopping the caller.
fn keep_log(
    events: &RunEvents<'_>,
    failed: &mut Option<StoreError>,
    kind: EventKind,
    level: EventLevel,
    sample: Option<u64>,
    message: &str,
) {
    if let Err(e) = events.log(kind, level, sample, message) {
        failed.get_or_insert(e);
    }
}

/// Returns once a second stop request has come (never, if the sender is gone first).
async fn forced_stop(mut stop: StopSignal) {
    loop {
        if *stop.borrow_and_update() >= 2 {
            return;
        }
        if stop.changed().await.is_err() {
            std::future::pending::<()>().await;
        }
    }
}

/// End a run whose devices could not be set up or started: nothing moved and nothing
/// was collected. Records a `start_failed` event with `reason` (which names the
/// device), marks the run failed and gives its lease back, so that no empty `running`
/// run is left. Returns the reason to report (with the store's error, if it failed).
pub fn abandon(store: &SyncStore, plan: &CollectPlan, reason: &str) -> String {
    let recorded = store
        .log_event(
            plan.run_id,
            None,
            None,
            EventLevel::Error,
            EventKind::StartFailed.as_str(),
            reason,
        )
        .and_then(|()| store.set_run_status(plan.run_id, RunStatus::Failed))
        .and_then(|()| {
            plan.lease
                .as_ref()
                .map_or(Ok(()), |l| store.release_lease(plan.run_id, l))
        })
        .and_then(|()| store.flush().map(drop));
    match recorded {
        Ok(()) => reason.to_owned(),
        Err(e) => format!("{reason}; and the store could not record it: {e}"),
    }
}

impl<'a> Job<'a> {
    /// Take the planned samples in order, changing rods between blocks. Returns how
    /// the loop ended and the index of the next sample it would have taken.
    async fn run_samples(
        &mut self,
        mut rods: Box<dyn RodChanger>,
        progress: &mut dyn Progress,
    ) -> Result<(Outcome, u64), CollectError> {
        let plan: &'a CollectPlan = self.plan;
        let sampler = PoseSampler::new(plan.seed, plan.scene.poses.clone());
        let order = plan.rig.procedure.visit_order;
        let visits = route::visits(
            order,
            &sampler,
            &plan.scene.poses,
            &plan.rods,
            plan.end_index,
            plan.indices(),
        );
        let max_failures = plan.rig.procedure.max_consecutive_failures;
        let mut consecutive_failures = 0u32;
        let mut current_rod: Option<&str> = None;
        let mut index = visits
            .first()
            .and_then(|v| v.todo.first().copied())
            .unwrap_or(plan.end_index);
        self.next_index = index;
        // A robot a crash left in reflex was recovered at connect: said in the run's log.
        if let Some(found) = self.arm.found_at_connect()
            && found.contains("recovery")
        {
            self.events.log(
                EventKind::ArmRecovered,
                EventLevel::Warn,
                None,
                &format!("the arm at connect: {found}"),
            )?;
        }
        // A start after a crash may find the finger on the rod: it leaves along the
        // approach axis before anything turns (`go_home` leaves first).
        if let Err(e) = self.go_home(None).await {
            let reason = format!("cannot move the arm home before starting: {e}");
            return Ok((Outcome::SafeStop { reason }, index));
        }
        // Home's joints, as the run first reaches it: where the elbow returns to.
        match self.arm.joints_rad().await {
            Ok(q) => self.home_joints = q,
            Err(e) => {
                let reason = format!("cannot read the arm's joints at home: {e}");
                return Ok((Outcome::SafeStop { reason }, index));
            }
        }
        if plan.rig.procedure.tare_for(plan.scene.medium) == Tare::PerRun
            && let Err(e) = self.ft.bias().await
        {
            let reason = format!("cannot zero the force/torque sensor at home: {e}");
            return Ok((Outcome::SafeStop { reason }, index));
        }
        // The finger at rest (home, no contact), once per run: what a tare for another
        // medium is fitted against.
        self.take_rest_frames().await?;
        // A run resumed within a block starts where the uninterrupted run was: at the
        // retreat point of the sample before it in the plan (checked against the
        // workspace as every sample's is; one outside it is never sent).
        if order == VisitOrder::Planned
            && let Some(v) = visits.first()
            && let Some(prev) = v.todo.first().and_then(|&i| v.before(i))
            && let clear = self.retreat_pose(&sampler.pose(prev))
            && plan.rig.workspace.contains_arm(&clear)
            && let Err(e) = self.go_to(&clear, true, None).await
        {
            let reason = format!(
                "cannot move the arm to the retreat point of sample {prev}, where the run continues: {e}"
            );
            return Ok((Outcome::SafeStop { reason }, index));
        }
        self.check_store()?;
        self.continue_run_time().await?;
        for visit in &visits {
            let Some(&first) = visit.todo.first() else {
                continue;
            };
            let rod = plan.rods.rod_for(first);
            self.events.log(
                EventKind::VisitPlan,
                EventLevel::Info,
                Some(first),
                &format!(
                    "rod `{rod}`, samples {}..{}: {} order (fingerprint {}); {} to take, from sample {first}",
                    visit.block.start,
                    visit.block.end,
                    order.as_str(),
                    visit.fingerprint(),
                    visit.todo.len()
                ),
            )?;
            for &i in &visit.todo {
                index = i;
                self.next_index = i;
                if *self.stop.borrow() > 0 {
                    return Ok((Outcome::Stopped, index));
                }
                let rod = plan.rods.rod_for(index);
                if current_rod != Some(rod) {
                    // The rod is changed with the arm at home (where a block's last
                    // sample ends; not so after a gap).
                    if current_rod.is_some()
                        && let Err(e) = self.go_home(Some(index)).await
                    {
                        let reason = format!("cannot move the arm home to change the rod: {e}");
                        return Ok((Outcome::SafeStop { reason }, index));
                    }
                    if let Err(e) = rods.change_rod(rod).await {
                        let reason = format!("cannot change to rod `{rod}`: {e}");
                        return Ok((Outcome::SafeStop { reason }, index));
                    }
                    let message = format!("rod `{rod}` in place");
                    self.events.log(
                        EventKind::RodChange,
                        EventLevel::Info,
                        Some(index),
                        &message,
                    )?;
                    progress.note(&message);
                    current_rod = Some(rod);
                }
                let last_of_block = visit.order.last() == Some(&i);
                match self
                    .sample(index, rod, sampler.pose(index), last_of_block)
                    .await?
                {
                    SampleEnd::Stored(SampleStatus::Ok) => consecutive_failures = 0,
                    SampleEnd::Stored(SampleStatus::Rejected(_)) => consecutive_failures += 1,
                    SampleEnd::Interrupted => return Ok((Outcome::Stopped, index)),
                    SampleEnd::Fatal(reason) => {
                        return Ok((Outcome::SafeStop { reason }, index));
                    }
                }
                // A retreat's store error, met where the job would not stop for it.
                self.check_store()?;
                // Renewed per sample; refused (and the job stopped) if another process
                // took the lease over meanwhile.
                if let Some(lease) = &plan.lease {
                    self.store.heartbeat(plan.run_id, lease)?;
                }
                progress.sample_done(index, &self.counters);
                if consecutive_failures >= max_failures {
                    let reason = format!(
                        "{consecutive_failures} samples in a row failed (limit procedure.max_consecutive_failures = {max_failures})"
                    );
                    return Ok((Outcome::SafeStop { reason }, index));
                }
            }
        }
        Ok((Outcome::Completed, plan.end_index))
    }

    /// Before the first sample: wait until the run's time base (where its device time
    /// left off), so that a resumed run's samples are taken at the device times an
    /// uninterrupted run takes them (no wait for a new run, or when the clock is
    /// already past the time base).
    async fn continue_run_time(&mut self) -> Result<(), CollectError> {
        let base = self.store.run_time_base(self.plan.run_id)?;
        let now = self.clock.now();
        let mut until = None;
        match base {
            None => {}
            Some(base) if now <= base && base.0 - now.0 <= RESUME_STARTUP_NS => {
                self.events.log(
                    EventKind::Resumed,
                    EventLevel::Info,
                    None,
                    &format!(
                        "device time continues at the run's time base {:.6} s (startup done at {:.6} s)",
                        base.as_secs_f64(),
                        now.as_secs_f64()
                    ),
                )?;
                until = Some(self.clock.instant_at(base));
            }
            // A clock not started by `clock_start` (a caller's own): waiting could take
            // hours on a rig, so the run's timestamps restart earlier instead.
            Some(base) if now < base => self.events.log(
                EventKind::Resumed,
                EventLevel::Warn,
                None,
                &format!(
                    "the rig's clock reads {:.6} s, long before the run's time base {:.6} s: \
                     not waiting; this job's timestamps are earlier than the run's last ones",
                    now.as_secs_f64(),
                    base.as_secs_f64()
                ),
            )?,
            Some(base) => self.events.log(
                EventKind::Resumed,
                EventLevel::Info,
                None,
                &format!(
                    "the startup ended at {:.6} s, after the run's time base {:.6} s: the \
                     resumed samples begin {:.3} s later than an uninterrupted run's would",
                    now.as_secs_f64(),
                    base.as_secs_f64(),
                    (now.0 - base.0) as f64 * 1e-9
                ),
            )?,
        }
        if let Some(until) = until {
            tokio::time::sleep_until(until).await;
        }
        Ok(())
    }

    /// A store error kept by [`Job::log_or_keep`], as an error now.
    fn check_store(&mut self) -> Result<(), StoreError> {
        self.store_failed.take().map_or(Ok(()), Err)
    }

    /// Log an event; a store error is kept (the first one) for later instead of
    /// stopping what the job is doing, for code that must go on (retreat, the end).
    fn log_or_keep(
        &mut self,
        kind: EventKind,
        level: EventLevel,
        sample: Option<u64>,
        message: &str,
    ) {
        keep_log(
            &self.events,
            &mut self.store_failed,
            kind,
            level,
            sample,
            message,
        );
    }

    /// A store error that came back from an earlier submission, kept as for
    /// [`Job::log_or_keep`].
    fn keep_store_failure(&mut self) {
        if let Some(e) = self.store.take_failure() {
            self.store_failed.get_or_insert(e);
        }
    }
}
