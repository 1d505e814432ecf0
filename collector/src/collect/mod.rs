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
//! failed samples in a row the run stops safely (retreat, flush, event, error).
//! Everything that goes wrong is an event in the store.

pub mod bench;
pub mod rods;
pub mod sampler;
pub mod window;

use crate::store::{EventLevel, RunId, RunStatus, StoreError, SyncStore};
use rods::RodChanger;
use sampler::{PoseSampler, RodSchedule};
use softtouch_drivers::{Arm, Camera, Clock, DeviceError, Frame, TokioClock};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{
    ArmPose, ContactPose, DurationNs, FtReading, RigConfig, Sample, SampleStatus, SceneSpec,
    TimestampNs, Wrench,
};
use std::time::Duration;
use tokio::sync::watch;
use window::{FtStream, WindowRules, window_bounds, window_stats};

/// The devices a collection needs.
pub struct CollectDevices {
    /// The arm.
    pub arm: Box<dyn Arm>,
    /// The force/torque sensor.
    pub force_sensor: Box<dyn softtouch_drivers::ForceSensor>,
    /// The in-finger camera.
    pub camera: Box<dyn Camera>,
    /// Who changes the rod.
    pub rods: Box<dyn RodChanger>,
}

impl std::fmt::Debug for CollectDevices {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollectDevices").finish_non_exhaustive()
    }
}

/// What to collect.
#[derive(Debug, Clone)]
pub struct CollectPlan {
    /// The run the samples belong to (already in the store).
    pub run_id: RunId,
    /// The run's seed.
    pub seed: u64,
    /// Index of the first sample to take (0, or where a resumed run left off).
    pub start_index: u64,
    /// One past the last index.
    pub end_index: u64,
    /// Rods in blocks.
    pub rods: RodSchedule,
    /// The rig.
    pub rig: RigConfig,
    /// The scene.
    pub scene: SceneSpec,
}

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

/// Why one attempt at a sample failed.
#[derive(Debug)]
enum AttemptError {
    /// Reflex or other arm fault: recover and retry.
    ArmFault(DeviceError),
    /// The arm's link failed: stop safely.
    ArmLink(DeviceError),
    /// The force guard tripped during the approach.
    ForceLimit(FtReading),
    /// No frame came.
    FrameTimeout(DeviceError),
    /// The sensor failed while recording.
    Sensor(DeviceError),
    /// A target outside the workspace: never sent. A bug or a bad config.
    Unsafe(String),
    /// A forced stop (second Ctrl-C) interrupted the attempt.
    Interrupted,
}

/// A finished attempt: the pieces of a sample.
struct Taken {
    measured: Option<ContactPose>,
    frame: Frame,
    stats: window::WindowStats,
    window: Vec<FtReading>,
    start: TimestampNs,
    end: TimestampNs,
}

struct Job<'a> {
    store: &'a SyncStore,
    plan: &'a CollectPlan,
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
    let mut rods = devices.rods;
    let sampler = PoseSampler::new(plan.seed, plan.scene.poses.clone());
    let max_failures = plan.rig.procedure.max_consecutive_failures;
    let mut consecutive_failures = 0u32;
    let mut current_rod: Option<String> = None;
    let run = plan.run_id;

    let mut outcome = Outcome::Completed;
    if let Err(e) = job.go_home(None).await {
        outcome = Outcome::SafeStop {
            reason: format!("cannot move the arm home before starting: {e}"),
        };
    }
    let mut index = plan.start_index;
    while outcome == Outcome::Completed && index < plan.end_index {
        if *job.stop.borrow() > 0 {
            outcome = Outcome::Stopped;
            break;
        }
        let rod = plan.rods.rod_for(index);
        if current_rod.as_deref() != Some(rod) {
            if let Err(e) = rods.change_rod(rod).await {
                outcome = Outcome::SafeStop {
                    reason: format!("cannot change to rod `{rod}`: {e}"),
                };
                break;
            }
            store.log_event(
                run,
                Some(index),
                Some(job.clock.now()),
                EventLevel::Info,
                "rod_change",
                &format!("rod `{rod}` in place"),
            )?;
            progress.note(&format!("rod `{rod}` in place"));
            current_rod = Some(rod.to_owned());
        }
        let pose = sampler.pose(index);
        match job.sample(index, rod, pose).await? {
            SampleEnd::Stored(SampleStatus::Ok) => consecutive_failures = 0,
            SampleEnd::Stored(SampleStatus::Rejected(_)) => consecutive_failures += 1,
            SampleEnd::Interrupted => {
                outcome = Outcome::Stopped;
                break;
            }
            SampleEnd::Fatal(reason) => {
                outcome = Outcome::SafeStop { reason };
                break;
            }
        }
        progress.sample_done(index, &job.counters);
        if consecutive_failures >= max_failures {
            outcome = Outcome::SafeStop {
                reason: format!(
                    "{consecutive_failures} samples in a row failed (limit procedure.max_consecutive_failures = {max_failures})"
                ),
            };
        }
        index += 1;
    }

    // Whatever happened: stop the arm, retreat, flush, record.
    let _ = job.arm.stop().await;
    if let Err(e) = job.go_home(None).await {
        store.log_event(
            run,
            None,
            Some(job.clock.now()),
            EventLevel::Error,
            "retreat_failed",
            &format!("could not retreat home at the end: {e}"),
        )?;
    }
    let received = job.ft.received();
    let ft_errors = job.ft.errors();
    let ft_result = job.ft.shutdown().await;
    let lost = ft_result.as_ref().map_or(0, |l| *l);
    let dropped = job.camera.dropped_frames();
    store
        .log_event(
            run,
            None,
            Some(job.clock.now()),
            EventLevel::Info,
            "stream_counts",
            &format!(
                "force/torque: {received} readings received, {lost} lost on the link, {ft_errors} read errors; \
                 camera: {dropped} frames dropped"
            ),
        )
        ?;
    if let Err(e) = ft_result {
        store.log_event(
            run,
            None,
            Some(job.clock.now()),
            EventLevel::Warn,
            "sensor_stop",
            &e.to_string(),
        )?;
    }
    let (status, level, kind, message) = match &outcome {
        Outcome::Completed => (
            RunStatus::Completed,
            EventLevel::Info,
            "completed",
            "all planned samples stored".to_owned(),
        ),
        Outcome::Stopped => (
            RunStatus::Stopped,
            EventLevel::Info,
            "stopped",
            format!("stopped by the operator before sample {index}"),
        ),
        Outcome::SafeStop { reason } => (
            RunStatus::Failed,
            EventLevel::Error,
            "safe_stop",
            reason.clone(),
        ),
    };
    store.log_event(run, None, Some(job.clock.now()), level, kind, &message)?;
    store.set_run_status(run, status)?;
    let written = store.flush()?;
    job.counters.already_present = written.already_present;
    Ok((outcome, job.counters))
}

enum SampleEnd {
    Stored(SampleStatus),
    Interrupted,
    Fatal(String),
}

impl Job<'_> {
    fn forced(&self) -> bool {
        *self.stop.borrow() >= 2
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
                    self.store.log_event(
                        self.plan.run_id,
                        index,
                        Some(self.clock.now()),
                        EventLevel::Warn,
                        "arm_fault",
                        &format!("retreating: {e}"),
                    )?;
                    tokio::time::sleep(recovery_backoff(n)).await;
                    self.arm.recover().await?;
                    self.store.log_event(
                        self.plan.run_id,
                        index,
                        Some(self.clock.now()),
                        EventLevel::Info,
                        "arm_recovered",
                        "automatic error recovery succeeded",
                    )?;
                }
                Err(e) => return Err(e.into()),
            }
        }
    }

    fn event(
        &self,
        index: u64,
        level: EventLevel,
        kind: &str,
        message: &str,
    ) -> Result<(), StoreError> {
        self.store.log_event(
            self.plan.run_id,
            Some(index),
            Some(self.clock.now()),
            level,
            kind,
            message,
        )
    }

    /// Take sample `index`, retrying as the procedure allows, and store it.
    async fn sample(
        &mut self,
        index: u64,
        rod: &str,
        pose: ContactPose,
    ) -> Result<SampleEnd, CollectError> {
        let max_attempts = self.plan.rig.procedure.max_attempts;
        let mut recoveries = 0u32;
        let mut last_reject = RejectReason::ArmFault;
        for attempt in 1..=max_attempts {
            if attempt > 1 {
                self.counters.retries += 1;
            }
            let result = self.attempt(pose).await;
            // Always end an attempt at home, whatever happened.
            // (A reflex is recovered below first.)
            if !matches!(
                result,
                Err(AttemptError::ArmLink(_)
                    | AttemptError::Interrupted
                    | AttemptError::ArmFault(_))
            ) && let Err(e) = self.go_home(Some(index)).await
            {
                return Ok(SampleEnd::Fatal(format!(
                    "cannot retreat home after sample {index}: {e}"
                )));
            }
            match result {
                Ok(taken) => match taken.stats.reject {
                    None => {
                        return self.store_sample(
                            index,
                            rod,
                            pose,
                            attempt,
                            SampleStatus::Ok,
                            Some(taken),
                        );
                    }
                    Some(reason) => {
                        self.counters.bad_windows += 1;
                        last_reject = reason;
                        // A saturated window comes back the same at the same pose.
                        let retry = reason != RejectReason::Saturated && attempt < max_attempts;
                        self.event(
                            index,
                            EventLevel::Warn,
                            reason.as_str(),
                            &format!(
                                "attempt {attempt}: window rejected ({reason}: {} readings){}",
                                taken.stats.count,
                                if retry { ", retrying" } else { "" }
                            ),
                        )?;
                        if !retry {
                            return self.store_sample(
                                index,
                                rod,
                                pose,
                                attempt,
                                SampleStatus::Rejected(reason),
                                Some(taken),
                            );
                        }
                    }
                },
                Err(AttemptError::ArmFault(e)) => {
                    self.counters.arm_faults += 1;
                    last_reject = RejectReason::ArmFault;
                    self.event(
                        index,
                        EventLevel::Warn,
                        "arm_fault",
                        &format!("attempt {attempt}: {e}"),
                    )?;
                    recoveries += 1;
                    tokio::time::sleep(recovery_backoff(recoveries)).await;
                    match self.arm.recover().await {
                        Ok(()) => self.event(
                            index,
                            EventLevel::Info,
                            "arm_recovered",
                            "automatic error recovery succeeded",
                        )?,
                        Err(e) => return Ok(SampleEnd::Fatal(format!("arm recovery failed: {e}"))),
                    }
                    if let Err(e) = self.go_home(Some(index)).await {
                        return Ok(SampleEnd::Fatal(format!(
                            "cannot retreat home after a reflex: {e}"
                        )));
                    }
                }
                Err(AttemptError::ForceLimit(r)) => {
                    self.event(
                        index,
                        EventLevel::Warn,
                        "force_limit",
                        &format!(
                            "attempt {attempt}: approach aborted at {}",
                            r.wrench_in_sensor
                        ),
                    )?;
                    // The same pose would press as hard again: reject at once.
                    return self.store_sample(
                        index,
                        rod,
                        pose,
                        attempt,
                        SampleStatus::Rejected(RejectReason::ForceLimit),
                        None,
                    );
                }
                Err(AttemptError::FrameTimeout(e)) => {
                    self.counters.frame_timeouts += 1;
                    last_reject = RejectReason::FrameTimeout;
                    self.event(
                        index,
                        EventLevel::Warn,
                        "frame_timeout",
                        &format!("attempt {attempt}: {e}"),
                    )?;
                }
                Err(AttemptError::Sensor(e)) => {
                    last_reject = RejectReason::SensorFault;
                    self.event(
                        index,
                        EventLevel::Warn,
                        "sensor_fault",
                        &format!("attempt {attempt}: {e}"),
                    )?;
                }
                Err(AttemptError::ArmLink(e)) => {
                    return Ok(SampleEnd::Fatal(format!("lost the arm: {e}")));
                }
                Err(AttemptError::Unsafe(msg)) => return Ok(SampleEnd::Fatal(msg)),
                Err(AttemptError::Interrupted) => {
                    let _ = self.arm.stop().await;
                    self.event(
                        index,
                        EventLevel::Info,
                        "interrupted",
                        "forced stop during the sample; not stored",
                    )?;
                    return Ok(SampleEnd::Interrupted);
                }
            }
        }
        self.event(
            index,
            EventLevel::Warn,
            "rejected",
            &format!("gave up after {max_attempts} attempts ({last_reject})"),
        )?;
        self.store_sample(
            index,
            rod,
            pose,
            max_attempts,
            SampleStatus::Rejected(last_reject),
            None,
        )
    }

    fn store_sample(
        &mut self,
        index: u64,
        rod: &str,
        pose: ContactPose,
        attempts: u32,
        status: SampleStatus,
        taken: Option<Taken>,
    ) -> Result<SampleEnd, CollectError> {
        let (measured, stats, frame, window, start, end) = match taken {
            Some(t) => (
                t.measured,
                Some(t.stats),
                Some(t.frame),
                t.window,
                t.start,
                t.end,
            ),
            None => (
                None,
                None,
                None,
                Vec::new(),
                TimestampNs::ZERO,
                TimestampNs::ZERO,
            ),
        };
        let sample = Sample {
            index,
            rod: rod.to_owned(),
            medium: self.plan.scene.medium,
            commanded: pose,
            measured,
            wrench_mean_in_sensor: stats.as_ref().map_or(Wrench::ZERO, |s| s.mean),
            wrench_std_in_sensor: stats.as_ref().map_or(Wrench::ZERO, |s| s.std),
            reading_count: stats.as_ref().map_or(0, |s| s.count),
            frame_t: frame.as_ref().map_or(TimestampNs::ZERO, |f| f.meta.t),
            window_start: start,
            window_end: end,
            sync_skew_ns: stats.as_ref().map_or(0, |s| s.skew_ns),
            status,
            attempts,
        };
        self.store
            .submit_sample(self.plan.run_id, sample, frame, window)?;
        match status {
            SampleStatus::Ok => self.counters.ok += 1,
            SampleStatus::Rejected(_) => self.counters.rejected += 1,
        }
        Ok(SampleEnd::Stored(status))
    }

    /// One try: approach, settle, record. Leaves the arm wherever it ended.
    async fn attempt(&mut self, pose: ContactPose) -> Result<Taken, AttemptError> {
        let w = &self.plan.rig.workspace;
        let p = &self.plan.rig.procedure;
        let l = &self.plan.rig.limits;
        let target = ArmPose::from_contact(&w.base_from_rod, &pose);
        // Every command is checked before it reaches the arm.
        if !pose.is_finite() || !w.contains_contact(&pose) || !w.contains_arm(&target) {
            return Err(AttemptError::Unsafe(format!(
                "pose {pose:?} (flange at {:?} m) lies outside the workspace; not sent",
                target.translation_m
            )));
        }
        if self.forced() {
            return Err(AttemptError::Interrupted);
        }

        // approach, guarded
        let guard = self.ft.wait_over_limit(l.max_force_n, l.max_torque_nm);
        let moved = tokio::select! {
            moved = self.arm.move_to(&target, p.approach_speed_m_s) => moved,
            tripped = guard => {
                let _ = self.arm.stop().await;
                return Err(AttemptError::ForceLimit(tripped));
            }
        };
        match moved {
            Ok(_) => {}
            Err(e) if e.is_fault() => return Err(AttemptError::ArmFault(e)),
            Err(e @ DeviceError::InvalidCommand { .. }) => {
                return Err(AttemptError::Unsafe(e.to_string()));
            }
            Err(e) => return Err(AttemptError::ArmLink(e)),
        }

        // settle
        tokio::time::sleep(Duration::from_secs_f64(p.settle_s)).await;
        if self.forced() {
            return Err(AttemptError::Interrupted);
        }
        let measured = match self.arm.state().await {
            Ok(s) if s.faulted => {
                return Err(AttemptError::ArmFault(DeviceError::Fault {
                    device: "arm".into(),
                    code: None,
                    message: "faulted while settling".into(),
                }));
            }
            Ok(s) => Some(ContactPose::from_arm(&w.base_from_rod, &s.base_from_finger)),
            Err(e) if e.is_fault() => return Err(AttemptError::ArmFault(e)),
            Err(e) => return Err(AttemptError::ArmLink(e)),
        };

        // record: the first frame after settling, and the readings around its time
        let timeout_ms = (p.frame_timeout_s * 1000.0).ceil() as u64;
        let frame = self
            .camera
            .frame_after(self.clock.now(), timeout_ms)
            .await
            .map_err(AttemptError::FrameTimeout)?;
        let (start, end) = window_bounds(frame.meta.t, DurationNs::from_secs_f64(p.ft_window_s));
        let deadline = self.clock.instant_at(end) + Duration::from_secs_f64(p.frame_timeout_s);
        match self.ft.wait_until(end, deadline).await {
            Ok(_) => {}
            Err(e) => return Err(AttemptError::Sensor(e)),
        }
        let readings = self.ft.take_window(start, end);
        let stats = window_stats(&readings, frame.meta.t, &self.rules);
        Ok(Taken {
            measured,
            frame,
            stats,
            window: readings,
            start,
            end,
        })
    }
}
