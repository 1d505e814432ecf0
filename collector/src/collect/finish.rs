//! The end of every collection, however it ended: the safe stop (stop, retreat, stop
//! the stream, check completeness, record the end, release the lease, flush) and the
//! retreat home.

use super::*;

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

    /// Move home at the retreat speed, recovering from reflexes on the way (with
    /// backoff, logged). Store errors do not stop a retreat: they are kept for the
    /// sample loop.
    pub(super) async fn go_home(&mut self, index: Option<u64>) -> Result<(), DeviceError> {
        let home = self.home;
        self.go_to(&home, false, index).await
    }

    /// The arm's pose at the retreat point of contact pose `pose`: its z and θ, home's
    /// x (which the rig declares clear of the rod).
    pub(super) fn retreat_pose(&self, pose: &ContactPose) -> ArmPose {
        let w = &self.plan.rig.workspace;
        ArmPose::from_contact(
            &w.base_from_rod,
            &ContactPose {
                x_m: w.home.x_m,
                ..*pose
            },
        )
    }

    /// Move to `target` clear of the rod (at the travel speed if `travel`, else the
    /// retreat speed), recovering from reflexes on the way as [`Job::go_home`] does.
    pub(super) async fn go_to(
        &mut self,
        target: &ArmPose,
        travel: bool,
        index: Option<u64>,
    ) -> Result<(), DeviceError> {
        let p = &self.plan.rig.procedure;
        let speed = if travel {
            p.travel_speed_m_s
        } else {
            p.retreat_speed_m_s
        };
        let tries = p.max_attempts.max(1);
        let mut n = 0;
        loop {
            n += 1;
            match self.arm.move_to(target, speed).await {
                Ok(_) => return Ok(()),
                Err(e) if e.is_fault() && n < tries => {
                    self.counters.arm_faults += 1;
                    self.log_or_keep(
                        EventKind::ArmFault,
                        EventLevel::Warn,
                        index,
                        &format!("retreating: {e}"),
                    );
                    tokio::time::sleep(recovery_backoff(n)).await;
                    self.arm.recover().await?;
                    self.log_or_keep(
                        EventKind::ArmRecovered,
                        EventLevel::Info,
                        index,
                        "automatic error recovery succeeded",
                    );
                }
                Err(e) => return Err(e),
            }
        }
    }
}
