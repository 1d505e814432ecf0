//! One sample: `approach → settle → record → retreat`, with its retries, and storing
//! it (accepted or rejected).

use super::window::{WindowStats, frame_covered, window_bounds, window_stats};
use super::{CollectError, Job, recovery_backoff};
use crate::store::{EventKind, EventLevel};
use softtouch_drivers::{Clock as _, DeviceError, Frame};
use softtouch_drivers::{ForceGuard, GuardTrip};
use softtouch_schemas::rig::{SettleEnd, Tare, VisitOrder};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{
    ArmPose, ContactPose, DurationNs, FtReading, Sample, SampleStatus, TimestampNs, Wrench,
};
use std::time::Duration;

/// How a sample ended.
pub(super) enum SampleEnd {
    /// Stored, accepted or rejected.
    Stored(SampleStatus),
    /// A forced stop: not stored.
    Interrupted,
    /// The job cannot go on: stop safely.
    Fatal(String),
}

/// Why one attempt at a sample failed.
#[derive(Debug)]
pub(super) enum AttemptError {
    /// Reflex or other arm fault: recover and retry.
    ArmFault(DeviceError),
    /// The arm's link failed: stop safely.
    ArmLink(DeviceError),
    /// The force guard tripped during the approach; the arm was told to stop, which
    /// may have failed too.
    ForceLimit {
        reading: FtReading,
        stop_failed: Option<DeviceError>,
        /// How far the arm went from where it was measured at the trip to where it came
        /// to rest, m (`None`: an arm with no pose feed, or its state unread).
        stopped_after_m: Option<f64>,
    },
    /// The guard stopped the approach for the stream's sake (stale, failing or
    /// non-finite); the arm was told to stop, which may have failed too.
    Guard {
        trip: GuardTrip,
        stop_failed: Option<DeviceError>,
    },
    /// No frame came.
    FrameTimeout(DeviceError),
    /// The sensor failed while recording.
    Sensor(DeviceError),
    /// A target outside the workspace: never sent. A bug or a bad config.
    Unsafe(String),
    /// A forced stop (second Ctrl-C) interrupted the attempt.
    Interrupted,
}

impl AttemptError {
    /// What a failed move means for the attempt: a fault is recovered, a refused
    /// command is a bug or a bad config, anything else a lost link.
    pub(super) fn of_arm(e: DeviceError) -> Self {
        match e {
            e if e.is_fault() => Self::ArmFault(e),
            e @ DeviceError::InvalidCommand { .. } => Self::Unsafe(e.to_string()),
            e => Self::ArmLink(e),
        }
    }
}

/// A finished attempt: the pieces of a sample.
struct Taken {
    measured: Option<ContactPose>,
    frame: Frame,
    stats: WindowStats,
    window: Vec<FtReading>,
    start: TimestampNs,
    end: TimestampNs,
}

impl Job<'_> {
    fn forced(&self) -> bool {
        *self.stop.borrow() >= 2
    }

    /// Nanoseconds on the rig's clock since `t0`.
    fn since(&self, t0: TimestampNs) -> u64 {
        self.clock.now().0.saturating_sub(t0.0)
    }

    /// Take sample `index`, retrying as the procedure allows, and store it; its time
    /// is added to the run's [`PhaseTimes`](super::phases::PhaseTimes). The arm ends
    /// at the pose's retreat point in a planned order, or at home where `home_after`
    /// (the block's last sample: the rod is changed at home) or the order is index.
    pub(super) async fn sample(
        &mut self,
        index: u64,
        rod: &str,
        pose: ContactPose,
        home_after: bool,
    ) -> Result<SampleEnd, CollectError> {
        let t0 = self.clock.now();
        let before = self.counters.phases;
        let end = self.take_sample(index, rod, pose, home_after).await;
        if matches!(end, Ok(SampleEnd::Stored(_))) {
            self.counters.phases.samples += 1;
            self.counters.phases.total_ns += self.since(t0);
        } else {
            // Only stored samples count, each with all of its phases.
            self.counters.phases = before;
        }
        end
    }

    async fn take_sample(
        &mut self,
        index: u64,
        rod: &str,
        pose: ContactPose,
        home_after: bool,
    ) -> Result<SampleEnd, CollectError> {
        let max_attempts = self.plan.rig.procedure.max_attempts;
        let mut recoveries = 0u32;
        let mut last_reject = RejectReason::ArmFault;
        for attempt in 1..=max_attempts {
            if attempt > 1 {
                self.counters.retries += 1;
            }
            let result = self.attempt(pose).await;
            // End every attempt clear of the rod: first straight back along the
            // approach axis to the retreat plane (nothing turns or travels before),
            // then at its retreat point where the plan goes on from there, else at
            // home (a reflex is recovered below first). A block ends at home, so a
            // run resumed at the next block starts where the uninterrupted run was.
            if !matches!(
                result,
                Err(AttemptError::ArmLink(_)
                    | AttemptError::Interrupted
                    | AttemptError::ArmFault(_))
            ) {
                let t0 = self.clock.now();
                let planned = self.plan.rig.procedure.visit_order == VisitOrder::Planned;
                // From the pose whose approach began; an attempt that never began
                // one (refused, or stopped on its way to the retreat point) is clear.
                let mut back = self.leave_rod(Some(index)).await;
                let to = if planned && result.is_ok() && !home_after {
                    "its retreat point"
                } else {
                    if back.is_ok() {
                        back = self.go_home(Some(index)).await;
                    }
                    if back.is_ok() && home_after {
                        back = self.reset_elbow(Some(index), "block's end").await;
                    }
                    "home"
                };
                self.counters.phases.retreat_ns += self.since(t0);
                if let Err(e) = back {
                    return Ok(SampleEnd::Fatal(format!(
                        "cannot retreat to {to} after sample {index}: {e}"
                    )));
                }
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
                        self.events.log(
                            EventKind::WindowRejected(reason),
                            EventLevel::Warn,
                            Some(index),
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
                    self.events.log(
                        EventKind::ArmFault,
                        EventLevel::Warn,
                        Some(index),
                        &format!("attempt {attempt}: {e}"),
                    )?;
                    recoveries += 1;
                    tokio::time::sleep(recovery_backoff(recoveries)).await;
                    match self.arm.recover().await {
                        Ok(()) => self.events.log(
                            EventKind::ArmRecovered,
                            EventLevel::Info,
                            Some(index),
                            "automatic error recovery succeeded",
                        )?,
                        Err(e) => return Ok(SampleEnd::Fatal(format!("arm recovery failed: {e}"))),
                    }
                    // Out along the approach axis, then home, the elbow as at the start.
                    let back = match self.go_home(Some(index)).await {
                        Ok(()) => self.reset_elbow(Some(index), "after a recovery").await,
                        Err(e) => Err(e),
                    };
                    if let Err(e) = back {
                        return Ok(SampleEnd::Fatal(format!(
                            "cannot retreat home after a reflex: {e}"
                        )));
                    }
                }
                Err(AttemptError::ForceLimit {
                    reading,
                    stop_failed,
                    stopped_after_m,
                }) => {
                    self.events.log(
                        EventKind::ForceLimit,
                        EventLevel::Warn,
                        Some(index),
                        &format!(
                            "attempt {attempt}: approach aborted at {}{}",
                            reading.wrench_in_sensor,
                            stopped_after_m.map_or(String::new(), |m| format!(
                                "; the arm came to rest {:.2} mm from where it was at the trip",
                                m * 1000.0
                            ))
                        ),
                    )?;
                    if let Some(e) = stop_failed {
                        self.events.log(
                            EventKind::ArmStopFailed,
                            EventLevel::Error,
                            Some(index),
                            &format!(
                                "attempt {attempt}: could not stop the arm at the force limit: {e}"
                            ),
                        )?;
                    }
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
                Err(AttemptError::Guard { trip, stop_failed }) => {
                    last_reject = match trip {
                        GuardTrip::NonFinite(_) => RejectReason::NonFinite,
                        GuardTrip::Stale { .. } => RejectReason::StreamStalled,
                        GuardTrip::SensorError(_)
                        | GuardTrip::SensorFault(_)
                        | GuardTrip::OverLimit(_) => RejectReason::SensorFault,
                    };
                    self.events.log(
                        EventKind::GuardStop,
                        EventLevel::Warn,
                        Some(index),
                        &format!("attempt {attempt}: approach stopped: {trip}"),
                    )?;
                    if let Some(e) = stop_failed {
                        self.events.log(
                            EventKind::ArmStopFailed,
                            EventLevel::Error,
                            Some(index),
                            &format!("attempt {attempt}: could not stop the arm at the guard: {e}"),
                        )?;
                    }
                }
                Err(AttemptError::FrameTimeout(e)) => {
                    self.counters.frame_timeouts += 1;
                    last_reject = RejectReason::FrameTimeout;
                    self.events.log(
                        EventKind::FrameTimeout,
                        EventLevel::Warn,
                        Some(index),
                        &format!("attempt {attempt}: {e}"),
                    )?;
                }
                Err(AttemptError::Sensor(e)) => {
                    last_reject = RejectReason::SensorFault;
                    self.events.log(
                        EventKind::SensorFault,
                        EventLevel::Warn,
                        Some(index),
                        &format!("attempt {attempt}: {e}"),
                    )?;
                }
                Err(AttemptError::ArmLink(e)) => {
                    return Ok(SampleEnd::Fatal(format!("lost the arm: {e}")));
                }
                Err(AttemptError::Unsafe(msg)) => return Ok(SampleEnd::Fatal(msg)),
                Err(AttemptError::Interrupted) => {
                    if let Err(e) = self.arm.stop().await {
                        self.events.log(
                            EventKind::ArmStopFailed,
                            EventLevel::Error,
                            Some(index),
                            &format!("could not stop the arm at a forced stop: {e}"),
                        )?;
                    }
                    self.events.log(
                        EventKind::Interrupted,
                        EventLevel::Info,
                        Some(index),
                        "forced stop during the sample; not stored",
                    )?;
                    return Ok(SampleEnd::Interrupted);
                }
            }
        }
        self.events.log(
            EventKind::Rejected,
            EventLevel::Warn,
            Some(index),
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
        // Every sample is stored after its retreat: now is where the next one begins,
        // the run's time base for a resume (see `collect::clock_start`).
        self.store.submit_sample_at(
            self.plan.run_id,
            sample,
            frame,
            window,
            Some(self.clock.now()),
        )?;
        match status {
            SampleStatus::Ok => self.counters.ok += 1,
            SampleStatus::Rejected(_) => self.counters.rejected += 1,
        }
        Ok(SampleEnd::Stored(status))
    }

    /// The moves `legs` in turn, raced against the force guard `limits`; how long each
    /// took on the rig's clock. A trip stops the arm (the caller logs what happened).
    pub(super) async fn guarded(
        &mut self,
        legs: &[(ArmPose, f64)],
        limits: &ForceGuard,
    ) -> Result<Vec<u64>, AttemptError> {
        let clock = self.clock;
        let arm = &mut self.arm;
        let mut took = Vec::with_capacity(legs.len());
        let guard = self.ft.guard(limits);
        let feed = arm.pose_feed();
        // One motion where the arm blends the legs (a Franka: no stop between them).
        let moves = async {
            let mut t0 = clock.now();
            let (_, ends) = arm.move_through(legs).await?;
            for end in ends {
                took.push(end.0.saturating_sub(t0.0));
                t0 = t0.max(end);
            }
            Ok::<(), DeviceError>(())
        };
        let moved = tokio::select! {
            moved = moves => moved,
            trip = guard => {
                // Where the arm was at the trip (its latest measured pose), and where
                // it came to rest: the guard's stopping distance, said with the trip.
                let at_trip = feed.as_ref().and_then(|f| f.borrow().map(|(_, p)| p));
                let stop_failed = self.arm.stop().await.err();
                let stopped_after_m = match (at_trip, stop_failed.is_none()) {
                    (Some(at), true) => self
                        .arm
                        .state()
                        .await
                        .ok()
                        .map(|s| s.base_from_finger.distance_to(&at)),
                    _ => None,
                };
                return Err(match trip {
                    GuardTrip::OverLimit(reading) => AttemptError::ForceLimit {
                        reading,
                        stop_failed,
                        stopped_after_m,
                    },
                    trip => AttemptError::Guard { trip, stop_failed },
                });
            }
        };
        moved.map_err(AttemptError::of_arm)?;
        Ok(took)
    }

    /// One try: approach, settle, record. Leaves the arm wherever it ended.
    ///
    /// The approach runs along the straight line to the target, its last
    /// `procedure.slow_approach_m` at `slow_approach_speed_m_s`.
    async fn attempt(&mut self, pose: ContactPose) -> Result<Taken, AttemptError> {
        // The plan outlives the job's borrows: its settings stay usable across them.
        let plan = self.plan;
        let w = &plan.rig.workspace;
        let p = &plan.rig.procedure;
        let l = &plan.rig.limits;
        let target = ArmPose::from_contact(&w.base_from_rod, &pose);
        let clear = self.retreat_pose(&pose);
        // Every command is checked before it reaches the arm.
        if !pose.is_finite()
            || !w.contains_contact(&pose)
            || !w.contains_arm(&target)
            || !w.contains_arm(&clear)
        {
            return Err(AttemptError::Unsafe(format!(
                "pose {pose:?} (flange at {:?} m, its retreat point at {:?} m) lies outside the workspace; not sent",
                target.translation_m, clear.translation_m
            )));
        }
        if self.forced() {
            return Err(AttemptError::Interrupted);
        }

        let limits = ForceGuard {
            max_force_n: l.max_force_n,
            max_torque_nm: l.max_torque_nm,
            stale: Duration::from_secs_f64(p.ft_stale_s),
        };
        // Travel clear of the rod to this pose's retreat point (from the last one, a few
        // millimetres and a small turn away in a planned order; from home otherwise),
        // guarded as the approach is: a retreat point that is not clear of the rod
        // stops the arm. Every approach then runs along the approach axis alone.
        let took = self
            .guarded(&[(clear, p.travel_speed_m_s)], &limits)
            .await?;
        self.counters.phases.travel_ns += took.iter().sum::<u64>();

        // Zero the sensor clear of the rod (home, or the retreat point): the label then
        // carries neither the sensor's offset nor the drift from before this attempt.
        if p.tare_for(self.plan.scene.medium) == Tare::PerSample {
            let t0 = self.clock.now();
            self.ft.bias().await.map_err(AttemptError::Sensor)?;
            self.counters.phases.tare_ns += self.since(t0);
        }

        // approach, guarded; the last stretch slowly: a contact there trips the guard
        // at low speed.
        // From here the finger may touch the rod: whatever ends the attempt, the arm
        // leaves along the approach axis first (`leave_rod`).
        self.near_rod = Some(pose);
        // Free space first, at the travel speed, up to the stand-off short of the
        // finger's first touch; the contact is entered at the approach speed.
        let mut legs = Vec::with_capacity(3);
        // The retreat point lies on the retreat plane (`retreat_pose`).
        let from = match standoff_x_m(retreat_x_m(w.home.x_m, p), &pose, p) {
            Some(x_m) => {
                let standoff =
                    ArmPose::from_contact(&w.base_from_rod, &ContactPose { x_m, ..pose });
                legs.push((standoff, p.travel_speed_m_s));
                standoff
            }
            None => clear,
        };
        let free = legs.len();
        legs.extend(approach_legs(&from, &target, p));
        let took = self.guarded(&legs, &limits).await?;
        // The last leg is the slow one unless the slow end is off.
        let slow_last = p.slow_approach_m > 0.0;
        for (k, ns) in took.iter().enumerate() {
            if k < free {
                self.counters.phases.free_approach_ns += ns;
            } else if slow_last && k + 1 == took.len() {
                self.counters.phases.slow_approach_ns += ns;
            } else {
                self.counters.phases.approach_ns += ns;
            }
        }

        // settle: until the signal has settled (at most settle_s), or settle_s
        let t0 = self.clock.now();
        self.settle().await;
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
        self.counters.phases.settle_ns += self.since(t0);

        // record: the first frame after settling, and the readings around its time
        let t0 = self.clock.now();
        let timeout_ms = (p.frame_timeout_s * 1000.0).ceil() as u64;
        let frame = self
            .camera
            .frame_after(self.clock.now(), timeout_ms)
            .await
            .map_err(AttemptError::FrameTimeout)?;
        let (start, end) = window_bounds(frame.meta.t, DurationNs::from_secs_f64(p.ft_window_s));
        let deadline = self.clock.instant_at(end) + Duration::from_secs_f64(p.frame_timeout_s);
        let complete = self
            .ft
            .wait_until(end, deadline)
            .await
            .map_err(AttemptError::Sensor)?;
        let readings = self.ft.take_window(start, end);
        self.counters.phases.record_ns += self.since(t0);
        let mut stats = window_stats(&readings, frame.meta.t, &self.rules);
        // No reading reached the window's end in time: the stream stalled and the
        // window is cut short, whatever it holds.
        if !complete && stats.reject != Some(RejectReason::NonFinite) {
            stats.reject = Some(RejectReason::StreamStalled);
        }
        // A window that passes every other check must also hold readings close to
        // the frame on both sides: otherwise its mean is not the force in the image.
        let max_skew =
            DurationNs::from_secs_f64(p.max_skew_s_for(self.plan.rig.force_sensor.least_rate_hz()));
        if stats.reject.is_none() && !frame_covered(&readings, frame.meta.t, max_skew) {
            stats.reject = Some(RejectReason::ClockSkew);
        }
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

impl Job<'_> {
    /// Wait before recording: with `settle_end = "signal"`, until the signal has
    /// settled ([`super::settle::settled`], its noise read from the same readings) or
    /// `settle_s` has passed; otherwise `settle_s`.
    async fn settle(&mut self) {
        let p = &self.plan.rig.procedure;
        let bound = Duration::from_secs_f64(p.settle_s);
        if p.settle_end == SettleEnd::Fixed {
            tokio::time::sleep(bound).await;
            return;
        }
        let w_ns = DurationNs::from_secs_f64(p.ft_window_s);
        let started = tokio::time::Instant::now();
        let poll = Duration::from_secs_f64(super::settle::SETTLE_POLL_S);
        let two_windows = Duration::from_nanos(2 * w_ns.0);
        loop {
            let waited = started.elapsed();
            if waited >= bound {
                return;
            }
            if waited >= two_windows {
                // Every reading up to now first (the reader task may not have run yet
                // at this instant): the decision is the stream's, not the scheduler's,
                // and a resumed run settles as the uninterrupted one did.
                let now = self.clock.now();
                let deadline =
                    tokio::time::Instant::now() + Duration::from_secs_f64(p.frame_timeout_s);
                if !matches!(self.ft.wait_until(now, deadline).await, Ok(true)) {
                    // A stalled or failing stream: the record step says so; the
                    // settle waits out its bound as a fixed one would.
                    tokio::time::sleep(bound.saturating_sub(started.elapsed())).await;
                    return;
                }
                let mid = now.saturating_sub(w_ns);
                let earlier = self.ft.take_window(mid.saturating_sub(w_ns), mid);
                let later = self.ft.take_window(mid, now);
                if super::settle::settled(&earlier, &later) {
                    return;
                }
            }
            tokio::time::sleep(poll.min(bound - waited)).await;
        }
    }
}

/// The retreat plane's x (rod frame), where the arm waits and turns between samples:
/// `standoff_m` short of the finger model's first touch, and further out by what a
/// wrist turn needs to clear the rod ([`softtouch_sim::FingerGeometry::turn_clearance_m`],
/// 4 mm): −12.57 mm with the defaults. Never further out than home's x (which the rig
/// declares clear), and home's x where a setting is not finite or the model has no
/// first touch.
pub fn retreat_x_m(home_x_m: f64, p: &softtouch_schemas::rig::Procedure) -> f64 {
    let Some(touch) = softtouch_sim::ContactParams::default().first_touch_x_m() else {
        return home_x_m;
    };
    let x = touch - p.standoff_m - softtouch_sim::FingerGeometry::default().turn_clearance_m();
    if x.is_finite() && x > home_x_m {
        x
    } else {
        home_x_m
    }
}

/// Where an approach to `pose` from the retreat plane at `clear_x_m` stops crossing
/// free space fast: `standoff_m` short of the finger's first touch (the finger model's
/// [`softtouch_sim::ContactParams::first_touch_x_m`], the same for every rod and θ).
/// `None` (the whole approach at the approach speed) where that point is not between
/// the retreat plane and the pose, or a setting is not finite.
pub(super) fn standoff_x_m(
    clear_x_m: f64,
    pose: &ContactPose,
    p: &softtouch_schemas::rig::Procedure,
) -> Option<f64> {
    let touch = softtouch_sim::ContactParams::default().first_touch_x_m()?;
    let x = touch - p.standoff_m;
    (x.is_finite() && x > clear_x_m && x < pose.x_m).then_some(x)
}

/// The moves of an approach from `from` to `target`: the straight line, its last
/// `slow_approach_m` at the slow speed (one slow move when the whole path is shorter;
/// one move at the approach speed when the slow end is off).
fn approach_legs(
    from: &ArmPose,
    target: &ArmPose,
    p: &softtouch_schemas::rig::Procedure,
) -> Vec<(ArmPose, f64)> {
    let dist_m = from.distance_to(target);
    if p.slow_approach_m.is_nan() || p.slow_approach_m <= 0.0 {
        return vec![(*target, p.approach_speed_m_s)];
    }
    let mut legs = Vec::with_capacity(2);
    if dist_m.is_finite() && dist_m > p.slow_approach_m {
        legs.push((
            from.slerp(target, 1.0 - p.slow_approach_m / dist_m),
            p.approach_speed_m_s,
        ));
    }
    legs.push((*target, p.slow_approach_speed_m_s));
    legs
}

#[cfg(test)]
mod approach_tests;
