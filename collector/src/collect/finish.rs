//! The end of every collection, however it ended: the safe stop (stop, retreat, stop
//! the stream, check completeness, record the end, release the lease, flush); and
//! every move that is not an approach: leaving the rod along the approach axis, travel
//! and homing, each guarded against a force that rises, and the elbow back to home's
//! joints.

use super::procedure::AttemptError;
use super::*;
use softtouch_drivers::ForceGuard;

impl Job<'_> {
    /// Whatever happened: stop the arm, retreat (unless a forced stop said stop where
    /// you are), stop the stream, check that a completed run is complete in the store,
    /// record how the run ended, give the lease back and flush. Every step is tried
    /// whatever the ones before it did; store errors turn the outcome into a safe stop
    /// that says so.
    pub(super) async fn finish(mut self, outcome: Outcome) -> (Outcome, Counters) {
        let mut outcome = outcome;
        let next_index = self.next_index;
        self.keep_store_failure();
        if let Err(e) = self.arm.stop().await {
            self.log_or_keep(
                EventKind::ArmStopFailed,
                EventLevel::Error,
                None,
                &format!("could not stop the arm at the end: {e}"),
            );
        }
        if *self.stop.borrow() >= 2 {
            self.log_or_keep(
                EventKind::Interrupted,
                EventLevel::Info,
                Some(next_index),
                "forced stop: the arm was stopped where it was and not sent home; \
                 the sample under way is not stored",
            );
        } else {
            let forced = forced_stop(self.stop.clone());
            let retreat = tokio::select! {
                r = self.go_home(None) => r.map_err(Some),
                () = forced => Err(None),
            };
            match retreat {
                Ok(()) => {}
                // The operator asked for it: an interruption, not a failure.
                Err(None) => {
                    let stopped = self.arm.stop().await;
                    self.log_or_keep(
                        EventKind::Interrupted,
                        EventLevel::Info,
                        None,
                        &format!(
                            "forced stop during the final retreat: the arm was stopped where it was \
                             and not sent home (arm stop {})",
                            match &stopped {
                                Ok(()) => "sent".to_owned(),
                                Err(e) => format!("failed: {e}"),
                            }
                        ),
                    );
                }
                Err(Some(e)) => {
                    let stopped = self.arm.stop().await;
                    self.log_or_keep(
                        EventKind::RetreatFailed,
                        EventLevel::Error,
                        None,
                        &format!(
                            "could not retreat home at the end: {e}; arm stop {}",
                            match &stopped {
                                Ok(()) => "sent".to_owned(),
                                Err(e) => format!("failed: {e}"),
                            }
                        ),
                    );
                }
            }
        }
        let received = self.ft.received();
        let ft_errors = self.ft.errors();
        let dropped = self.camera.dropped_frames();
        // Moves the stream out of the job: only its fields are used from here.
        let ft_result = self.ft.shutdown().await;
        let lost = ft_result.as_ref().map_or(0, |l| *l);
        let failed = &mut self.store_failed;
        keep_log(
            &self.events,
            failed,
            EventKind::StreamCounts,
            EventLevel::Info,
            None,
            &format!(
                "force/torque: {received} readings received, {lost} lost on the link, {ft_errors} read errors; \
                 camera: {dropped} frames dropped"
            ),
        );
        if self.counters.phases.samples > 0 {
            keep_log(
                &self.events,
                failed,
                EventKind::PhaseTimes,
                EventLevel::Info,
                None,
                self.counters.phases.table().trim_end(),
            );
        }
        if let Err(e) = ft_result {
            keep_log(
                &self.events,
                failed,
                EventKind::SensorStop,
                EventLevel::Warn,
                None,
                &e.to_string(),
            );
        }
        let store = self.store;
        let run_id = self.plan.run_id;
        // Completed means the store holds every planned index, whatever the job thinks.
        if outcome == Outcome::Completed {
            if let Some(e) = store.take_failure() {
                failed.get_or_insert(e);
            }
            match store.missing_indices(run_id, self.plan.end_index) {
                Ok(missing) if missing.is_empty() => {}
                Ok(missing) => {
                    outcome = Outcome::SafeStop {
                        reason: format!(
                            "{} planned samples are not in the database (first: {}); resume to take them",
                            missing.len(),
                            missing[0]
                        ),
                    };
                }
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        }
        if let Some(e) = store.take_failure() {
            failed.get_or_insert(e);
        }
        if let Some(e) = failed
            && !matches!(outcome, Outcome::SafeStop { .. })
        {
            outcome = Outcome::SafeStop {
                reason: format!("the store failed: {e}"),
            };
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
        // From here the store's answers are the last word: try each, keep the first error.
        let mut end_failed: Option<StoreError> = store.take_failure();
        let mut keep = |r: Result<(), StoreError>| {
            if let Err(e) = r {
                end_failed.get_or_insert(e);
            }
        };
        keep(self.events.log(kind, level, None, &message));
        keep(store.take_failure().map_or(Ok(()), Err));
        keep(store.set_run_status(run_id, status));
        if let Some(lease) = &self.plan.lease {
            keep(store.release_lease(run_id, lease));
        }
        let written = store.flush();
        let mut counters = self.counters;
        match written {
            Ok(w) => counters.already_present = w.already_present,
            Err(e) => keep(Err(e)),
        }
        if let Some(e) = end_failed {
            let reason = match outcome {
                Outcome::SafeStop { reason } => reason,
                Outcome::Completed | Outcome::Stopped => "the run ended".to_owned(),
            };
            outcome = Outcome::SafeStop {
                reason: format!("{reason}; and the store could not record the end: {e}"),
            };
        }
        (outcome, counters)
    }

    /// Leave the rod: straight back along the approach axis (the rod frame's x) to the
    /// retreat plane ([`Job::retreat_x_m`]), keeping z and θ, at the retreat speed up to
    /// the stand-off and the travel speed beyond, guarded
    /// ([`Job::leaving_guard`]). From the contact pose whose approach began
    /// (`near_rod`: the arm is on its approach line, wherever a trip, a fault or a stop
    /// left it); with none, from the measured pose, and only where it is nearer the rod
    /// than the retreat plane (a start after a crash). Nothing turns or travels before
    /// this has ended.
    pub(super) async fn leave_rod(&mut self, index: Option<u64>) -> Result<(), MoveFailed> {
        let w = &self.plan.rig.workspace;
        let from = match self.near_rod {
            Some(p) => p,
            None => {
                let s = self.arm.state().await.map_err(MoveFailed::Arm)?;
                let here = ContactPose::from_arm(&w.base_from_rod, &s.base_from_finger);
                // Near the rod: nearer than the retreat plane, within the workspace's
                // z and θ, with its retreat point in reach. Anywhere else (an arm left
                // elsewhere) it goes home as it is.
                let near = here.x_m > self.retreat_x_m() + LEAVE_FROM_M
                    && w.z_m.contains(here.z_m)
                    && w.theta_rad.contains(here.theta_rad)
                    && w.contains_arm(&self.retreat_pose(&here));
                if !near {
                    return Ok(());
                }
                here
            }
        };
        let clear = self.retreat_pose(&from);
        // Out of the contact at the retreat speed; from the approach's stand-off on at
        // the travel speed, where the arm is measured past it: one motion on an arm
        // that blends legs (two moves cost an FR3 a stop: 0.16 s a sample).
        let p = &self.plan.rig.procedure;
        let (retreat, travel) = (p.retreat_speed_m_s, p.travel_speed_m_s);
        let standoff = super::procedure::standoff_x_m(self.retreat_x_m(), &from, p);
        let legs = match (standoff, self.measured_x_m().await) {
            (Some(x_m), Some(here)) if here > x_m + LEAVE_FROM_M => {
                let at = ArmPose::from_contact(&w.base_from_rod, &ContactPose { x_m, ..from });
                vec![(at, retreat), (clear, travel)]
            }
            _ => vec![(clear, retreat)],
        };
        self.guarded_legs(&legs, index, "leaving the rod").await?;
        self.near_rod = None;
        Ok(())
    }

    /// The arm's measured x in the rod frame: its pose feed's latest, else its state
    /// (`None` where neither answers).
    async fn measured_x_m(&mut self) -> Option<f64> {
        let base_from_rod = self.plan.rig.workspace.base_from_rod;
        let fed = self
            .arm
            .pose_feed()
            .and_then(|f| f.borrow().map(|(_, p)| p));
        let pose = match fed {
            Some(p) => p,
            None => self.arm.state().await.ok()?.base_from_finger,
        };
        Some(ContactPose::from_arm(&base_from_rod, &pose).x_m)
    }

    /// Leave the rod ([`Job::leave_rod`]), then move home at the retreat speed,
    /// guarded, recovering from reflexes on the way (with backoff, logged). Store
    /// errors do not stop a retreat: they are kept for the sample loop.
    pub(super) async fn go_home(&mut self, index: Option<u64>) -> Result<(), MoveFailed> {
        self.leave_rod(index).await?;
        let home = self.home;
        self.go_to(&home, false, index).await
    }

    /// At home, the elbow back where the run first found it: every move is Cartesian and
    /// leaves the arm's redundancy to the robot, so over a night the elbow drifts
    /// toward a joint's limit. Where the arm has joints ([`Arm::joints_rad`]), log how
    /// far they drifted from home's (the largest, and which joint) and move back to
    /// them in joint space. Called at each block's end and after a recovery; a no-op on
    /// an arm without joints, or before home's joints are known.
    pub(super) async fn reset_elbow(
        &mut self,
        index: Option<u64>,
        at: &str,
    ) -> Result<(), MoveFailed> {
        let Some(home_q) = self.home_joints else {
            return Ok(());
        };
        let Some(q) = self.arm.joints_rad().await.map_err(MoveFailed::Arm)? else {
            return Ok(());
        };
        let (joint, drift_rad) = (0..7)
            .map(|j| (j + 1, (q[j] - home_q[j]).abs()))
            .fold((0, 0.0f64), |m, d| if d.1 > m.1 { d } else { m });
        let moved = drift_rad > ELBOW_RESET_FROM_RAD;
        self.log_or_keep(
            EventKind::Elbow,
            EventLevel::Info,
            index,
            &format!(
                "{at}: the joints drifted at most {drift_rad:.4} rad (joint {joint}) from home's{}",
                if moved {
                    "; moved back in joint space"
                } else {
                    ""
                }
            ),
        );
        if moved {
            // Guarded as every move near the rod is; a guard that cannot watch (the
            // stream down) leaves the move to run unguarded, as a retreat does.
            let guard = self.leaving_guard();
            let arm = &mut self.arm;
            let trip = tokio::select! {
                m = arm.move_joints(&home_q) => {
                    m.map_err(MoveFailed::Arm)?;
                    None
                }
                trip = self.ft.guard(&guard) => Some(trip),
            };
            match trip {
                None => {}
                Some(GuardTrip::OverLimit(reading)) => {
                    let stopped = self.arm.stop().await;
                    return Err(MoveFailed::Caught(format!(
                        "the force rose while moving the elbow back: {}; the arm was stopped{}",
                        reading.wrench_in_sensor,
                        stopped
                            .err()
                            .map_or(String::new(), |e| format!(" (its stop failed: {e})"))
                    )));
                }
                Some(trip) => {
                    self.log_or_keep(
                        EventKind::GuardStop,
                        EventLevel::Warn,
                        index,
                        &format!("moving the elbow back: the force guard cannot watch ({trip}); moving unguarded"),
                    );
                    self.arm
                        .move_joints(&home_q)
                        .await
                        .map_err(MoveFailed::Arm)?;
                }
            }
        }
        Ok(())
    }

    /// The arm's pose at the retreat point of contact pose `pose`: its z and θ on the
    /// retreat plane ([`super::procedure::retreat_x_m`]: the stand-off and a wrist
    /// turn's clearance short of the first touch, never beyond home's x).
    pub(super) fn retreat_pose(&self, pose: &ContactPose) -> ArmPose {
        let w = &self.plan.rig.workspace;
        ArmPose::from_contact(
            &w.base_from_rod,
            &ContactPose {
                x_m: self.retreat_x_m(),
                ..*pose
            },
        )
    }

    /// The retreat plane's x, rod frame.
    pub(super) fn retreat_x_m(&self) -> f64 {
        super::procedure::retreat_x_m(self.plan.rig.workspace.home.x_m, &self.plan.rig.procedure)
    }

    /// Move to `target` in the retreat plane (at the travel speed if `travel`, else the
    /// retreat speed), guarded as [`Job::guarded_move`] is. Only after the rod was left.
    pub(super) async fn go_to(
        &mut self,
        target: &ArmPose,
        travel: bool,
        index: Option<u64>,
    ) -> Result<(), MoveFailed> {
        let p = &self.plan.rig.procedure;
        let speed = if travel {
            p.travel_speed_m_s
        } else {
            p.retreat_speed_m_s
        };
        self.guarded_move(target, speed, index, "retreating").await
    }

    /// The force guard of a move that is not an approach (leaving the rod, travel in
    /// the retreat plane, homing): it trips on a force that rises, by a quarter of the
    /// rig's limit above the larger of the limit and the force when the move began.
    /// A finger that leaves a press over the limit (a guard trip) is not stopped by the
    /// force it left with; one that is caught, or hits something, is. Before the
    /// first tare (a start after a crash) the sensor's offset is what it began with.
    pub(super) fn leaving_guard(&self) -> ForceGuard {
        let l = &self.plan.rig.limits;
        let (force_n, torque_nm) = self.ft.latest().map_or((0.0, 0.0), |r| {
            let w = &r.wrench_in_sensor;
            let f = w.force_n.iter().map(|x| x * x).sum::<f64>().sqrt();
            let t = w.torque_nm.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            (f, t)
        });
        let finite = |x: f64| if x.is_finite() { x } else { 0.0 };
        ForceGuard {
            max_force_n: l.max_force_n.max(finite(force_n))
                + (LEAVE_RISE * l.max_force_n).max(LEAVE_RISE_FLOOR_N),
            max_torque_nm: l.max_torque_nm.max(finite(torque_nm))
                + (LEAVE_RISE * l.max_torque_nm).max(LEAVE_RISE_FLOOR_NM),
            stale: Duration::from_secs_f64(self.plan.rig.procedure.ft_stale_s),
        }
    }

    /// One move that is not an approach, raced against [`Job::leaving_guard`],
    /// recovering from reflexes on the way (with backoff, logged). A force that rises
    /// stops the arm: [`MoveFailed::Caught`]. A guard that cannot watch (the stream
    /// stalled, failed or sent non-finite readings) is logged and the move made
    /// unguarded: a run ending on a failed sensor still gets the arm clear.
    async fn guarded_move(
        &mut self,
        target: &ArmPose,
        speed_m_s: f64,
        index: Option<u64>,
        what: &str,
    ) -> Result<(), MoveFailed> {
        self.guarded_legs(&[(*target, speed_m_s)], index, what)
            .await
    }

    /// [`Job::guarded_move`] through `legs` (one motion where the arm blends them). A
    /// try after a fault goes straight to the last leg's end at the first leg's speed:
    /// the arm may be past an earlier leg's end already.
    async fn guarded_legs(
        &mut self,
        legs: &[(ArmPose, f64)],
        index: Option<u64>,
        what: &str,
    ) -> Result<(), MoveFailed> {
        let tries = self.plan.rig.procedure.max_attempts.max(1);
        let (Some(first), Some(last)) = (legs.first(), legs.last()) else {
            return Ok(());
        };
        let straight = [(last.0, first.1)];
        let mut watched = true;
        let mut n = 0;
        loop {
            n += 1;
            let legs = if n == 1 { legs } else { &straight[..] };
            let moved = if watched {
                let guard = self.leaving_guard();
                self.guarded(legs, &guard).await.map(drop)
            } else {
                self.arm
                    .move_through(legs)
                    .await
                    .map(drop)
                    .map_err(AttemptError::of_arm)
            };
            let e = match moved {
                Ok(()) => return Ok(()),
                Err(AttemptError::ForceLimit {
                    reading,
                    stop_failed,
                    ..
                }) => {
                    return Err(MoveFailed::Caught(format!(
                        "the force rose while {what}: {} over the guard's {:.2} N / {:.3} N·m; the arm was stopped{}",
                        reading.wrench_in_sensor,
                        self.leaving_guard().max_force_n,
                        self.leaving_guard().max_torque_nm,
                        stop_failed.map_or(String::new(), |e| format!(" (its stop failed: {e})"))
                    )));
                }
                Err(AttemptError::Guard { trip, .. }) => {
                    self.log_or_keep(
                        EventKind::GuardStop,
                        EventLevel::Warn,
                        index,
                        &format!("{what}: the force guard cannot watch ({trip}); moving unguarded"),
                    );
                    watched = false;
                    continue;
                }
                Err(AttemptError::ArmFault(e)) => e,
                Err(
                    AttemptError::ArmLink(e)
                    | AttemptError::FrameTimeout(e)
                    | AttemptError::Sensor(e),
                ) => {
                    return Err(MoveFailed::Arm(e));
                }
                Err(AttemptError::Unsafe(message)) => {
                    return Err(MoveFailed::Arm(DeviceError::InvalidCommand {
                        device: "arm".into(),
                        message,
                    }));
                }
                // Not met here: a forced stop races the whole retreat (`finish`).
                Err(AttemptError::Interrupted) => {
                    return Err(MoveFailed::Arm(DeviceError::InvalidCommand {
                        device: "arm".into(),
                        message: format!("{what}: interrupted"),
                    }));
                }
            };
            if n >= tries {
                return Err(MoveFailed::Arm(e));
            }
            self.counters.arm_faults += 1;
            self.log_or_keep(
                EventKind::ArmFault,
                EventLevel::Warn,
                index,
                &format!("{what}: {e}"),
            );
            tokio::time::sleep(recovery_backoff(n)).await;
            self.arm.recover().await.map_err(MoveFailed::Arm)?;
            self.log_or_keep(
                EventKind::ArmRecovered,
                EventLevel::Info,
                index,
                "automatic error recovery succeeded",
            );
        }
    }
}

/// Below this drift of every joint from home's the elbow is left where it is, rad.
const ELBOW_RESET_FROM_RAD: f64 = 1e-3;

/// How far nearer the rod than the retreat plane a measured pose must be for a start
/// or an end of a run to leave the rod first, m (the rest is a tracking error).
const LEAVE_FROM_M: f64 = 0.001;

/// How far a force must rise above the larger of the limit and its value at the start
/// of a move that is not an approach before the guard trips, as a share of the limit,
/// and at least [`LEAVE_RISE_FLOOR_N`] (and [`LEAVE_RISE_FLOOR_NM`]).
const LEAVE_RISE: f64 = 0.25;

/// The least rise that trips a move that is not an approach, N: above the sensor's
/// noise and the press still growing as a move begins (the arm, under impedance
/// control, comes to rest after its command does). Against franka-sim, stopped 16 mm
/// into the rod from 0.2 m/s under a 0.3 N limit, the force grew 0.08 N more as the
/// leave began; 0.075 N (a quarter of that limit) tripped it.
const LEAVE_RISE_FLOOR_N: f64 = 0.5;

/// The least torque rise that trips it, N·m.
const LEAVE_RISE_FLOOR_NM: f64 = 0.025;

/// Why a move clear of the rod (leaving it, travelling, homing) failed.
#[derive(Debug)]
pub(super) enum MoveFailed {
    /// The arm refused, faulted past its recoveries, or its link failed.
    Arm(DeviceError),
    /// The force guard stopped it: the finger was caught or hit something.
    Caught(String),
}

impl std::fmt::Display for MoveFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Arm(e) => write!(f, "{e}"),
            Self::Caught(m) => f.write_str(m),
        }
    }
}
