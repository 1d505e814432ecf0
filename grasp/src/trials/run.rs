//! One trial on the devices: pre-grasp, the loop's close and hold, the lift, the verdict, its trace.

use super::*;

/// Lends a [`ForceEstimator`] to one trial's controller.
pub(super) struct Lent<'a, E>(&'a mut E);

impl<E: ForceEstimator> ForceEstimator for Lent<'_, E> {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        self.0.estimate(frame)
    }
}

pub(super) fn fmax(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.max(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

pub(super) fn elapsed_ns(clock: &dyn Clock, since: TimestampNs) -> u64 {
    clock.now().0.saturating_sub(since.0)
}

/// The devices of one trial.
#[derive(Debug)]
pub struct TrialDevices<'a, G, C, E, T, L, J> {
    /// The gripper.
    pub gripper: G,
    /// The finger camera the estimate reads.
    pub camera: C,
    /// The model (lent for the trial).
    pub estimator: &'a mut E,
    /// The force truth for the record, where one exists.
    pub truth: T,
    /// What raises the gripper.
    pub lift: L,
    /// What decides the outcome.
    pub judge: J,
    /// The clock the devices run on.
    pub clock: Arc<dyn Clock>,
}

/// Runs one trial: close (open or closed loop), lift, hold, judge. The gripper is left
/// holding its measured position on every path (the object stays where it is; putting
/// it down is the rig's business). A device error ends the trial as a device fault
/// (a timeout of the gripper as a timeout); an unreadable frame is an error.
///
/// # Errors
/// Bad settings, or the model could not read a frame.
pub async fn run_trial<G, C, E, T, L, J>(
    devices: TrialDevices<'_, G, C, E, T, L, J>,
    controller: ControllerConfig,
    config: &TrialConfig,
) -> Result<TrialResult, GraspError>
where
    G: Gripper,
    C: Camera,
    E: ForceEstimator,
    T: TrueForce,
    L: Lift,
    J: Judge,
{
    config.validate()?;
    if config.mode == Mode::Closed {
        controller.stepper.check_target(config.target_n)?;
    }
    let mut controller = controller;
    controller.on_exit = ExitAction::Hold;
    let TrialDevices {
        gripper,
        camera,
        estimator,
        truth,
        mut lift,
        mut judge,
        clock,
    } = devices;
    // The frames of the trial's moments, for its record.
    let camera = super::snapshots::SnapCamera::new(camera);
    let latest = camera.latest();
    let ctl = Controller::new(
        gripper,
        camera,
        Lent(estimator),
        truth,
        Arc::clone(&clock),
        controller.clone(),
    )?;
    let mut run = Run {
        clock: Arc::clone(&clock),
        trace: Vec::new(),
        lifted: false,
        confirmed_after_ns: None,
        last_status: None,
        commanded: match config.mode {
            Mode::Open => config.grasp_position,
            Mode::Closed => config.pregrasp_position,
        },
        latest,
        taken: Vec::new(),
        first_estimate_n: None,
        stalled_in_hold: None,
    };
    let outcome = match config.mode {
        Mode::Open => run.open_loop(ctl, &mut lift, &controller, config).await,
        Mode::Closed => run.closed_loop(ctl, &mut lift, config).await,
    };
    run.snap(Moment::End);
    let snapshots = run.thumbnails();
    let peak_estimate_n = run.trace.iter().fold(None, |m, r| fmax(m, r.estimate_n));
    let peak_true_n = run.trace.iter().fold(None, |m, r| fmax(m, r.true_n));
    let final_position = run.last_status.map_or(run.commanded, |s| s.position);
    let (verdict, detail) = match outcome {
        Ok(()) => {
            let last = run.trace.iter().rev().find_map(|r| r.estimate_n);
            let seen = Observation {
                mode: config.mode,
                lifted: run.lifted,
                last_status: run.last_status.unwrap_or(GripperStatus {
                    t: clock.now(),
                    activated: true,
                    object: ObjectStatus::AtPosition,
                    fault: 0,
                    requested_position: run.commanded,
                    position: final_position,
                    current_ma: 0,
                }),
                last_estimate_n: last,
                peak_estimate_n,
                peak_true_n,
            };
            let verdict = judge.judge(&seen).await?;
            match run.stalled_in_hold.take() {
                None => (verdict, None),
                // The loop gave up on an object it still holds: the loop's failure.
                Some(stall) if verdict == Verdict::Held => (
                    Verdict::Failed(FailReason::EstimateStalled),
                    Some(stall.to_string()),
                ),
                // The object went first (a slip, a crush) and the loop then closed on
                // the space it left: the physics' failure, the stall its detail.
                Some(stall) => (
                    verdict,
                    Some(format!(
                        "the loop stalled during the hold, after the object was lost: {stall}"
                    )),
                ),
            }
        }
        Err(GraspError::Device(DeviceError::Timeout { device, timeout_ms })) => (
            Verdict::Failed(FailReason::Timeout),
            Some(format!("{device} timed out after {timeout_ms} ms")),
        ),
        Err(GraspError::Device(e)) => (
            Verdict::Failed(FailReason::DeviceFault),
            Some(e.to_string()),
        ),
        Err(e @ GraspError::EstimateStalled { .. }) => (
            Verdict::Failed(FailReason::EstimateStalled),
            Some(e.to_string()),
        ),
        Err(e) => return Err(e),
    };
    Ok(TrialResult {
        verdict,
        detail,
        commanded_position: run.commanded,
        final_position,
        peak_estimate_n,
        peak_true_n,
        confirmed_after_ns: run.confirmed_after_ns,
        trace: run.trace,
        snapshots,
    })
}

/// The state of one trial while it runs.
pub(super) struct Run {
    pub(super) clock: Arc<dyn Clock>,
    pub(super) trace: Vec<TraceRow>,
    pub(super) lifted: bool,
    pub(super) confirmed_after_ns: Option<u64>,
    pub(super) last_status: Option<GripperStatus>,
    pub(super) commanded: u8,
    /// The newest frame the loop read ([`super::snapshots::SnapCamera`]).
    pub(super) latest: Arc<std::sync::Mutex<Option<Frame>>>,
    /// The frames of the moments seen so far.
    pub(super) taken: Vec<(Moment, Frame)>,
    /// The trial's first usable estimate, N (contact without a truth is 0.1 N above).
    pub(super) first_estimate_n: Option<f64>,
    /// The loop's stall after the lift began ([`GraspError::EstimateStalled`]): the
    /// judge then says whether the object was still held or lost first.
    pub(super) stalled_in_hold: Option<GraspError>,
}

impl Run {
    pub(super) fn record(&mut self, c: &crate::controller::Cycle) {
        self.push(TraceRow {
            t: c.t,
            estimate_n: c.estimate_n,
            true_n: c.true_n,
            measured_position: c.measured_position,
            position_request: c.position_request,
        });
        self.commanded = c.position_request;
    }

    /// A cycle into the trace, and the contact's frame on the first cycle with contact.
    pub(super) fn push(&mut self, row: TraceRow) {
        if self.first_estimate_n.is_none() {
            self.first_estimate_n = row.estimate_n;
        }
        let contact = match (row.true_n, row.estimate_n, self.first_estimate_n) {
            (Some(t), ..) => t > 0.05,
            (None, Some(e), Some(first)) => e > first + 0.1,
            _ => false,
        };
        self.trace.push(row);
        if contact {
            self.snap(Moment::Contact);
        }
    }

    /// Keeps the newest frame as `moment`'s, once.
    pub(super) fn snap(&mut self, moment: Moment) {
        if self.taken.iter().any(|(m, _)| *m == moment) {
            return;
        }
        let frame = self
            .latest
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        if let Some(frame) = frame {
            self.taken.push((moment, frame));
        }
    }

    /// The moments' frames as thumbnails (a frame that does not decode is left out:
    /// the record is an aid, never a reason to lose the trial).
    pub(super) fn thumbnails(&mut self) -> Vec<Snapshot> {
        std::mem::take(&mut self.taken)
            .into_iter()
            .filter_map(|(moment, frame)| {
                Some(Snapshot {
                    moment,
                    t: frame.meta.t,
                    png: super::snapshots::thumbnail_png(&frame).ok()?,
                })
            })
            .collect()
    }

    /// Close to the predefined width, lift, hold; watch the estimate all along.
    pub(super) async fn open_loop<G, C, E, T, L>(
        &mut self,
        mut ctl: Controller<G, C, E, T>,
        lift: &mut L,
        config: &ControllerConfig,
        trial: &TrialConfig,
    ) -> Result<(), GraspError>
    where
        G: Gripper,
        C: Camera,
        E: ForceEstimator,
        T: TrueForce,
        L: Lift,
    {
        let status = ctl
            .approach(trial.grasp_position, trial.move_timeout)
            .await?;
        self.last_status = Some(status);
        let (mut gripper, mut camera, mut estimator, mut truth) = ctl.into_parts();
        // What `approach` sent: the predefined width, clamped to the stroke.
        let grasp_position = config.stepper.stroke.clamp(i64::from(trial.grasp_position));
        let command = GripperCommand {
            position: grasp_position,
            speed: config.speed,
            force: config.force,
        };
        let mut next = self.clock.now();
        // The first cycle watches the closed fingers before the lift, so a grasp that
        // slips at lift-off (where the load is largest) is seen to have touched.
        let mut end: Option<u64> = None;
        let watched: Result<(), GraspError> = async {
            while end.is_none_or(|end| self.clock.now().0 < end) {
                let frame = camera
                    .latest_frame_after(next, config.frame_timeout_ms)
                    .await?;
                next = TimestampNs(frame.meta.t.0 + 1);
                let sat = config.stepper.saturation_n;
                let estimate_n = match estimator.estimate(&frame)? {
                    Some(w) if w.is_finite() && w.force_norm_n() >= sat => Some(sat),
                    Some(w) => config.projection.grip_force_n(&w),
                    None => None,
                };
                let true_n = truth.true_force_n(frame.meta.t);
                // One exchange a frame: the unchanged request (the keep-alive the
                // Hand-E needs at least every second) and the status read back.
                let status = gripper.command_and_status(command).await?;
                self.last_status = Some(status);
                if status.fault != 0 {
                    return Err(GraspError::Device(DeviceError::Fault {
                        device: "gripper".into(),
                        code: Some(u32::from(status.fault)),
                        message: format!(
                            "the gripper reported a fault while holding: {}",
                            softtouch_drivers::hande::regs::describe_fault(status.fault)
                        ),
                    }));
                }
                self.push(TraceRow {
                    t: frame.meta.t,
                    estimate_n,
                    true_n,
                    measured_position: status.position,
                    position_request: grasp_position,
                });
                if end.is_none() {
                    lift.start_lift(&trial.lift).await?;
                    self.lifted = true;
                    self.snap(Moment::Lifted);
                    end = Some(
                        self.clock.now().0
                            + (trial.lift.duration_s() * 1e9) as u64
                            + trial.hold.as_nanos() as u64,
                    );
                }
            }
            Ok(())
        }
        .await;
        if watched.is_err() {
            // Best effort: hold where the fingers are.
            if let Ok(s) = gripper.status().await {
                let _ = gripper
                    .command(GripperCommand {
                        position: s.position,
                        ..command
                    })
                    .await;
            }
        }
        watched
    }

    /// Algorithm 1 until |F_ref − F_est| ≤ δ for the confirmation time, then lift and
    /// hold with the loop still running.
    pub(super) async fn closed_loop<G, C, E, T, L>(
        &mut self,
        mut ctl: Controller<G, C, E, T>,
        lift: &mut L,
        trial: &TrialConfig,
    ) -> Result<(), GraspError>
    where
        G: Gripper,
        C: Camera,
        E: ForceEstimator,
        T: TrueForce,
        L: Lift,
    {
        let status = ctl
            .approach(trial.pregrasp_position, trial.move_timeout)
            .await?;
        self.last_status = Some(status);
        let tolerance_n = ctl.config().stepper.tolerance_n;
        // One frame through `follow` starts the loop on the camera's present frame
        // grid; it ends holding the measured (pre-grasp) position.
        for c in ctl
            .follow(&[(trial.target_n, Duration::from_nanos(1))])
            .await?
        {
            self.record(&c);
        }
        let close_start = self.clock.now();
        // The last `confirm` of estimates, oldest first, with their times.
        let mut window: std::collections::VecDeque<(TimestampNs, Option<f64>)> =
            std::collections::VecDeque::new();
        let confirm_ns = trial.confirm.as_nanos() as u64;
        let confirmed_at = loop {
            let c = ctl.cycle(trial.target_n).await?;
            self.record(&c);
            window.push_back((c.t, c.estimate_n));
            while window
                .get(1)
                .is_some_and(|(t, _)| c.t.0.saturating_sub(t.0) >= confirm_ns)
            {
                window.pop_front();
            }
            let spans = window
                .front()
                .is_some_and(|(t, _)| c.t.0.saturating_sub(t.0) >= confirm_ns);
            let estimates: Vec<Option<f64>> = window.iter().map(|(_, e)| *e).collect();
            if spans && super::confirmed(&estimates, trial.target_n, tolerance_n, trial.dither_n) {
                break c.t;
            }
            if elapsed_ns(self.clock.as_ref(), close_start) > trial.close_timeout.as_nanos() as u64
            {
                // Not confirmed: no lift; the judge says what became of the object.
                self.last_status = Some(self.status_of(&c));
                return Ok(());
            }
        };
        // On the trace's clock (its first cycle is 0), where the viewer, the CSV and the
        // frames' times all read it.
        let first = self.trace.first().map_or(confirmed_at.0, |r| r.t.0);
        self.confirmed_after_ns = Some(confirmed_at.0.saturating_sub(first));
        self.snap(Moment::Confirmed);
        lift.start_lift(&trial.lift).await?;
        self.lifted = true;
        self.snap(Moment::Lifted);
        let hold = Duration::from_secs_f64(trial.lift.duration_s()) + trial.hold;
        let end = self.clock.now().0 + hold.as_nanos() as u64;
        let mut last = None;
        while self.clock.now().0 < end {
            let c = match ctl.cycle(trial.target_n).await {
                Ok(c) => c,
                // The fingers hold where they stand (the controller's exit); what became
                // of the object is the judge's to say.
                Err(stall @ GraspError::EstimateStalled { .. }) => {
                    self.stalled_in_hold = Some(stall);
                    break;
                }
                Err(e) => return Err(e),
            };
            self.record(&c);
            last = Some(c);
        }
        if let Some(c) = last {
            self.last_status = Some(self.status_of(&c));
        }
        // The gripper keeps the loop's last request: it goes on holding.
        Ok(())
    }

    pub(super) fn status_of(&self, c: &crate::controller::Cycle) -> GripperStatus {
        GripperStatus {
            t: c.t,
            activated: true,
            object: c.object,
            fault: 0,
            requested_position: c.position_request,
            position: c.measured_position,
            current_ma: 0,
        }
    }
}
