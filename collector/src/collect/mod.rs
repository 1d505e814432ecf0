//! The collection job: sample contact poses, move the arm, pair a frame with a window
//! of force/torque readings, store each sample durably, and survive faults.
//!
//! One sample is a small state machine, `approach → settle → record → retreat`:
//! - **approach**: the target is checked against the workspace before it reaches the
//!   arm; the move races a force guard (contact force or torque over the rig's limit
//!   stops the arm and aborts the attempt);
//! - **settle**: wait the configured time;
//! - **record**: ask the camera for the first frame after settling, and take the
//!   force/torque readings in a window around that frame's time;
//! - **retreat**: back home, where the rod can be changed.
//!
//! Faults: an arm reflex is recovered automatically with backoff and the sample tried
//! again; a sensor fault, a bad window or a frame timeout retries the sample; when the
//! attempts run out the sample is stored as rejected with its reason. After too many
//! failed samples in a row the run stops safely (stop, retreat, flush, event, error).
//! Everything that goes wrong is an event in the store, a stop the arm refused included.
//!
//! # Layout
//! - this module: the job loop (rods, samples in order, failures in a row) and the
//!   safe stop at its end (stop, retreat, stream counts, the run's final status);
//! - `procedure`: one sample's state machine, its retries, and storing it;
//! - [`plan`]: what to collect, for a new run or the rest of a stored one;
//! - [`devices`]: the devices of a collection, built from the rig config;
//! - [`sampler`]: contact poses and the rod schedule;
//! - [`window`]: the force/torque stream and a sample's label window;
//! - [`rods`]: changing the rod (an operator, or the simulator);
//! - [`bench`]: what collection costs, and where its time goes.

pub mod bench;
pub mod devices;
pub mod plan;
mod procedure;
pub mod rods;
pub mod sampler;
pub mod window;

pub use devices::{CollectDevices, build_devices};
pub use plan::{CollectPlan, NewRunRequest, PlanError, Resumed};

use crate::store::{EventKind, EventLevel, RunId, RunStatus, StoreError, SyncStore};
use procedure::SampleEnd;
use rods::RodChanger;
use sampler::PoseSampler;
use softtouch_drivers::{Arm, Camera, Clock, DeviceError, TokioClock};
use softtouch_schemas::{ArmPose, SampleStatus};
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
}

/// Backoff before the `n`th recovery attempt (1-based): 0.5 s doubling, at most 8 s.
#[must_use]
pub fn recovery_backoff(n: u32) -> Duration {
    Duration::from_millis(500u64.saturating_mul(1 << n.saturating_sub(1).min(4)))
}

/// Run the collection `plan` on `devices`, storing into `store`. Returns how it ended;
/// the run's status in the store says the same.
pub async fn collect(
    store: &SyncStore,
    plan: &CollectPlan,
    devices: CollectDevices,
    clock: TokioClock,
    stop: StopSignal,
    progress: &mut dyn Progress,
) -> Result<(Outcome, Counters), CollectError> {
    let rate_hz = match &plan.rig.force_sensor {
        softtouch_schemas::ForceSensorDevice::Sim { rate_hz }
        | softtouch_schemas::ForceSensorDevice::NetFt { rate_hz, .. } => *rate_hz,
        softtouch_schemas::ForceSensorDevice::AtiSerial { .. } => 7000.0,
    };
    // Hold 4 s of readings: far more than any window, bounded whatever happens.
    let capacity = (rate_hz * 4.0).ceil().max(1024.0) as usize;
    let ft = FtStream::spawn(devices.force_sensor, capacity).await?;
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
        stop,
    };
    // A store error ends the job at once: nothing more could be recorded, not even
    // the safe stop.
    let (outcome, next_index) = job.run_samples(devices.rods, progress).await?;
    job.finish(outcome, next_index).await
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
        let max_failures = plan.rig.procedure.max_consecutive_failures;
        let mut consecutive_failures = 0u32;
        let mut current_rod: Option<&str> = None;
        let mut index = plan.start_index;
        if let Err(e) = self.go_home(None).await {
            let reason = format!("cannot move the arm home before starting: {e}");
            return Ok((Outcome::SafeStop { reason }, index));
        }
        while index < plan.end_index {
            if *self.stop.borrow() > 0 {
                return Ok((Outcome::Stopped, index));
            }
            let rod = plan.rods.rod_for(index);
            if current_rod != Some(rod) {
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
            match self.sample(index, rod, sampler.pose(index)).await? {
                SampleEnd::Stored(SampleStatus::Ok) => consecutive_failures = 0,
                SampleEnd::Stored(SampleStatus::Rejected(_)) => consecutive_failures += 1,
                SampleEnd::Interrupted => return Ok((Outcome::Stopped, index)),
                SampleEnd::Fatal(reason) => return Ok((Outcome::SafeStop { reason }, index)),
            }
            progress.sample_done(index, &self.counters);
            index += 1;
            if consecutive_failures >= max_failures {
                let reason = format!(
                    "{consecutive_failures} samples in a row failed (limit procedure.max_consecutive_failures = {max_failures})"
                );
                return Ok((Outcome::SafeStop { reason }, index));
            }
        }
        Ok((Outcome::Completed, index))
    }

    /// Whatever happened: stop the arm, retreat, stop the sensor, record how the run
    /// ended and flush.
    async fn finish(
        mut self,
        outcome: Outcome,
        next_index: u64,
    ) -> Result<(Outcome, Counters), CollectError> {
        let events = self.events;
        if let Err(e) = self.arm.stop().await {
            events.log(
                EventKind::ArmStopFailed,
                EventLevel::Error,
                None,
                &format!("could not stop the arm at the end: {e}"),
            )?;
        }
        if let Err(e) = self.go_home(None).await {
            events.log(
                EventKind::RetreatFailed,
                EventLevel::Error,
                None,
                &format!("could not retreat home at the end: {e}"),
            )?;
        }
        let received = self.ft.received();
        let ft_errors = self.ft.errors();
        let ft_result = self.ft.shutdown().await;
        let lost = ft_result.as_ref().map_or(0, |l| *l);
        let dropped = self.camera.dropped_frames();
        events.log(
            EventKind::StreamCounts,
            EventLevel::Info,
            None,
            &format!(
                "force/torque: {received} readings received, {lost} lost on the link, {ft_errors} read errors; \
                 camera: {dropped} frames dropped"
            ),
        )?;
        if let Err(e) = ft_result {
            events.log(
                EventKind::SensorStop,
                EventLevel::Warn,
                None,
                &e.to_string(),
            )?;
        }
        let (status, level, kind, message) = match &outcome {
            Outcome::Completed => (
                RunStatus::Completed,
                EventLevel::Info,
                EventKind::Completed,
                "all planned samples stored".to_owned(),
            ),
            Outcome::Stopped => (
                RunStatus::Stopped,
                EventLevel::Info,
                EventKind::Stopped,
                format!("stopped by the operator before sample {next_index}"),
            ),
            Outcome::SafeStop { reason } => (
                RunStatus::Failed,
                EventLevel::Error,
                EventKind::SafeStop,
                reason.clone(),
            ),
        };
        events.log(kind, level, None, &message)?;
        let store = self.store;
        store.set_run_status(self.plan.run_id, status)?;
        let written = store.flush()?;
        let mut counters = self.counters;
        counters.already_present = written.already_present;
        Ok((outcome, counters))
    }

    /// Move home, recovering from reflexes on the way (with backoff, logged).
    async fn go_home(&mut self, index: Option<u64>) -> Result<(), CollectError> {
        let speed = self.plan.rig.procedure.retreat_speed_m_s;
        let tries = self.plan.rig.procedure.max_attempts.max(1);
        let mut n = 0;
        loop {
            n += 1;
            match self.arm.move_to(&self.home, speed).await {
                Ok(_) => return Ok(()),
                Err(e) if e.is_fault() && n < tries => {
                    self.counters.arm_faults += 1;
                    self.events.log(
                        EventKind::ArmFault,
                        EventLevel::Warn,
                        index,
                        &format!("retreating: {e}"),
                    )?;
                    tokio::time::sleep(recovery_backoff(n)).await;
                    self.arm.recover().await?;
                    self.events.log(
                        EventKind::ArmRecovered,
                        EventLevel::Info,
                        index,
                        "automatic error recovery succeeded",
                    )?;
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
}
