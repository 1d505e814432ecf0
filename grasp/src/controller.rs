//! The force loop: one cycle per camera frame.
//!
//! Each cycle takes the next frame, runs the estimator on it (preprocessing and the
//! inference net), projects the wrench on the gripping direction (Method S3), reads
//! the gripper's measured position P_m, steps Algorithm 1 and sends the position
//! request rPR when it changed. Every cycle is recorded: t, P_m, P_ref, F_ref, F_est
//! and, where a [`TrueForce`] knows it (simulation, a reference sensor), F_true.
//! Nothing in the loop reads the truth; it is recorded beside the estimate only.
//!
//! Hand-E facts the loop respects (docs/PROTOCOLS.md §2, §2.x):
//! - **Keep-alive.** The gripper faults (0x09) after about 1 s without a command, so
//!   the current request is re-sent when [`ControllerConfig::keep_alive`] has passed.
//! - **Handshake.** After a request the loop waits for its echo in gPR before it steps
//!   again; when requests are sent back to back only the latest takes effect, and a
//!   P_m read before the echo belongs to the previous request.
//! - **Contact stops.** A contact-stopped Hand-E moves again only on an opposite
//!   command or a new rGTO edge, and toggling rGTO fast can fault it. The loop does not
//!   re-arm: it commands a grip force (rFR) whose current cap sits far above the
//!   newtons it regulates, and counts the cycles where the gripper reported a stop.
//! - **Stroke.** Requests never leave the calibrated stroke ([`crate::Stroke`]).
//! - **Safe exit.** Whatever ends a run (done, a device error, an unreachable target),
//!   the gripper is left as [`ExitAction`] says.

use std::sync::Arc;
use std::time::Duration;

use softtouch_drivers::{Camera, Clock, Gripper, GripperCommand, GripperStatus, ObjectStatus};
use softtouch_schemas::TimestampNs;

use crate::GraspError;
use crate::estimator::ForceEstimator;
use crate::projection::Projection;
use crate::squeeze::SqueezeBound;
use crate::stepper::{StepOutcome, Stepper, StepperConfig};
use crate::wrist::{Wrist, WristLoop};

/// How far from the request an arrival reported by the gripper (gOBJ = 3) may be,
/// counts (about 0.4 mm).
const ARRIVAL_SLACK_COUNTS: u8 = 2;
use softtouch_schemas::Wrench;

/// How often [`Controller::approach`] reads the gripper (the Hand-E allows 200 Hz).
const APPROACH_POLL: Duration = Duration::from_millis(10);

fn check_fault(status: &GripperStatus) -> Result<(), GraspError> {
    if status.fault == 0 {
        return Ok(());
    }
    Err(GraspError::Device(softtouch_drivers::DeviceError::Fault {
        device: "gripper".into(),
        code: Some(u32::from(status.fault)),
        message: format!(
            "the gripper reported a fault during the force loop: {}",
            softtouch_drivers::hande::regs::describe_fault(status.fault)
        ),
    }))
}

/// What the gripper does when a run ends, however it ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitAction {
    /// Hold the measured position (keep the object).
    Hold,
    /// Open to the calibrated open end (release the object).
    Open,
}

/// Settings of the loop.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Algorithm 1.
    pub stepper: StepperConfig,
    /// Method S3.
    pub projection: Projection,
    /// rSP for every request.
    pub speed: u8,
    /// rFR for every request. 0, the register's lowest: the grip force the Hand-E
    /// applies at a contact stop is then its least (about 20 N by the figures quoted,
    /// docs/PROTOCOLS.md §2.x), the hardware's own backstop under the squeeze bound;
    /// still far above the few newtons the loop regulates, so none trips a stop.
    pub force: u8,
    /// How long to wait for a frame before the run fails, ms. A cycle may wait this
    /// long on each of two cameras, so `keep_alive + 2 × frame_timeout_ms` stays under
    /// the Hand-E's 1 s watchdog.
    pub frame_timeout_ms: u64,
    /// Re-send the current request after this long without a command (< 1 s).
    pub keep_alive: Duration,
    /// What the gripper does at the end of a run.
    pub on_exit: ExitAction,
    /// The closing limit from the stiffness calibration ([`SqueezeBound`]); `None`
    /// only where no calibration exists (the end calibration, a bare test rig).
    pub squeeze: Option<SqueezeBound>,
}

impl ControllerConfig {
    /// Defaults for a projection: K = 4 N/mm, δ = 0.1 N, whole Hand-E scale, half speed,
    /// the lowest force register (0), 200 ms keep-alive, open on exit, no squeeze bound
    /// (set one from the calibration with [`Self::with_squeeze`]).
    pub fn new(projection: Projection) -> Self {
        Self {
            stepper: StepperConfig::default(),
            projection,
            speed: 128,
            force: 0,
            frame_timeout_ms: 300,
            keep_alive: Duration::from_millis(200),
            on_exit: ExitAction::Open,
            squeeze: None,
        }
    }

    /// The same settings with the closing limit `bound`.
    #[must_use]
    pub fn with_squeeze(mut self, bound: SqueezeBound) -> Self {
        self.squeeze = Some(bound);
        self
    }

    /// Checks the settings and every target before anything moves.
    ///
    /// # Errors
    /// A bad setting or an unreachable target, named.
    pub fn check(&self, targets: &[(f64, Duration)]) -> Result<(), GraspError> {
        self.validate()?;
        for (target_n, _) in targets {
            self.stepper.check_target(*target_n)?;
        }
        Ok(())
    }

    fn validate(&self) -> Result<(), GraspError> {
        self.stepper.validate()?;
        if let Some(bound) = &self.squeeze {
            bound.validate()?;
        }
        if self.keep_alive.is_zero() || self.keep_alive >= Duration::from_secs(1) {
            return Err(GraspError::Config(format!(
                "keep_alive {:?}: expected more than 0 and less than 1 s (the Hand-E faults after 1 s without a command)",
                self.keep_alive
            )));
        }
        if self.frame_timeout_ms == 0 {
            return Err(GraspError::Config(
                "frame_timeout_ms 0: expected at least 1 ms".into(),
            ));
        }
        // The longest a cycle can go without a command: the keep-alive's period, then
        // a wait on each of two cameras.
        let worst = self.keep_alive + Duration::from_millis(2 * self.frame_timeout_ms);
        if worst >= Duration::from_millis(900) {
            return Err(GraspError::Config(format!(
                "frame_timeout_ms {} with keep_alive {:?}: expected keep_alive + 2 × frame_timeout_ms under 0.9 s (the Hand-E faults after 1 s without a command)",
                self.frame_timeout_ms, self.keep_alive
            )));
        }
        Ok(())
    }
}

/// One control cycle, as recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cycle {
    /// When the frame was exposed, ns on the injected clock.
    pub t: TimestampNs,
    /// The camera's frame counter.
    pub frame_sequence: u64,
    /// Which target of [`Controller::follow`] this cycle held (0-based).
    pub hold: usize,
    /// F_ref, N.
    pub target_n: f64,
    /// F_est, N: the projected estimate (`None`: the model gave none or a NaN).
    pub estimate_n: Option<f64>,
    /// F_true, N, where known (recorded only, never used by the loop).
    pub true_n: Option<f64>,
    /// P_m, counts.
    pub measured_position: u8,
    /// P_ref, counts (what the gripper has been asked for after this cycle).
    pub position_request: u8,
    /// What the stepper did; `None` while the loop waited for the gPR echo.
    pub outcome: Option<StepOutcome>,
    /// gOBJ at this cycle.
    pub object: ObjectStatus,
    /// Each sensorised finger's projected estimate, N (finger 1: `None` with one
    /// finger). With two, F_est is their mean.
    pub finger_estimates_n: [Option<f64>; 2],
    /// With two fingers, the finger whose estimate alone made F_est because the other
    /// gave none (flagged); `None` when both (or the only one) did.
    pub single_finger: Option<usize>,
    /// The model's torque about the finger's axis, N·m (mean over the fingers that
    /// gave one), what the wrist loop works on.
    pub torque_z_nm: Option<f64>,
    /// The wrist target after this cycle, rad (only with a wrist loop).
    pub wrist_target_rad: Option<f64>,
}

/// The force truth, where one exists (the simulator, a reference force sensor).
pub trait TrueForce: Send {
    /// The true grip force at `t`, N, projected like the estimate.
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64>;
}

/// No truth (a real gripper without a reference sensor).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoTruth;

impl TrueForce for NoTruth {
    fn true_force_n(&mut self, _t: TimestampNs) -> Option<f64> {
        None
    }
}

/// The loop over a gripper, a camera and an estimator.
#[derive(Debug)]
pub struct Controller<G, C, E, T = NoTruth> {
    gripper: G,
    camera: C,
    estimator: E,
    truth: T,
    clock: Arc<dyn Clock>,
    stepper: Stepper,
    config: ControllerConfig,
    /// The last request sent and when.
    sent: Option<(u8, TimestampNs)>,
    next_frame_t: TimestampNs,
    contact_stops: u64,
    activated: bool,
    hold: usize,
    /// A second sensorised finger: its camera and its own projection (its frame is
    /// the first one's mirror).
    second: Option<SecondFinger>,
    /// The wrist loop on τz, when the arm's wrist takes part.
    wrist: Option<(Box<dyn Wrist>, WristLoop)>,
    last_frame_t: Option<TimestampNs>,
    stop: Option<StopRequest>,
    /// This run's touch: the first measured count at which the estimate rose
    /// [`crate::squeeze::RUN_TOUCH_N`] over the calibrated no-contact level.
    run_touch: Option<u8>,
}

/// A stop request published by name (a signal's), checked once per cycle.
pub type StopRequest = tokio::sync::watch::Receiver<Option<&'static str>>;

/// The second sensorised finger: its camera and projection.
struct SecondFinger {
    camera: Box<dyn Camera>,
    projection: Projection,
}

impl std::fmt::Debug for SecondFinger {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SecondFinger")
            .field("projection", &self.projection)
            .finish_non_exhaustive()
    }
}

/// One finger's force estimate from its wrench: saturated wrenches report the
/// saturation limit (so the stepper holds), non-finite ones none.
fn finger_force_n(
    wrench: Option<&Wrench>,
    projection: &Projection,
    saturation_n: f64,
) -> Option<f64> {
    match wrench {
        Some(w) if w.is_finite() && w.force_norm_n() >= saturation_n => Some(saturation_n),
        Some(w) => projection.grip_force_n(w),
        None => None,
    }
}

/// F_est from the fingers' estimates: the mean of two, the one that is there if the
/// other is missing (flagged with its index), none if both are; a saturated finger
/// saturates the mean, so the loop holds.
#[must_use]
pub fn combine_fingers(
    estimates_n: [Option<f64>; 2],
    saturation_n: f64,
) -> (Option<f64>, Option<usize>) {
    match estimates_n {
        [Some(a), Some(b)] if a >= saturation_n || b >= saturation_n => (Some(saturation_n), None),
        [Some(a), Some(b)] => (Some(0.5 * (a + b)), None),
        [Some(a), None] => (Some(a), Some(0)),
        [None, Some(b)] => (Some(b), Some(1)),
        [None, None] => (None, None),
    }
}

impl<G: Gripper, C: Camera, E: ForceEstimator, T: TrueForce> Controller<G, C, E, T> {
    /// A controller; settings are checked here.
    pub fn new(
        gripper: G,
        camera: C,
        estimator: E,
        truth: T,
        clock: Arc<dyn Clock>,
        config: ControllerConfig,
    ) -> Result<Self, GraspError> {
        config.validate()?;
        Ok(Self {
            gripper,
            camera,
            estimator,
            truth,
            clock,
            stepper: Stepper::new(config.stepper)?,
            config,
            sent: None,
            next_frame_t: TimestampNs::ZERO,
            contact_stops: 0,
            activated: false,
            hold: 0,
            second: None,
            wrist: None,
            last_frame_t: None,
            stop: None,
            run_touch: None,
        })
    }

    /// Ends [`Self::follow`] at the next cycle once `stop` holds a request (Ctrl-C or
    /// SIGTERM on a rig): the gripper is then left as [`ExitAction`] says, and the
    /// error names the request. Checked between cycles, so no command is cut short.
    #[must_use]
    pub fn with_stop(mut self, stop: StopRequest) -> Self {
        self.stop = Some(stop);
        self
    }

    /// Adds a second sensorised finger: its camera (on the same frame grid as the
    /// first) and its projection. F_est becomes the mean of the two estimates.
    #[must_use]
    pub fn with_second_finger(mut self, camera: Box<dyn Camera>, projection: Projection) -> Self {
        self.second = Some(SecondFinger { camera, projection });
        self
    }

    /// Adds the wrist loop: each cycle turns `wrist` against the model's τz.
    #[must_use]
    pub fn with_wrist(mut self, wrist: Box<dyn Wrist>, wrist_loop: WristLoop) -> Self {
        self.wrist = Some((wrist, wrist_loop));
        self
    }

    /// How many sensorised fingers the loop reads.
    pub fn fingers(&self) -> usize {
        if self.second.is_some() { 2 } else { 1 }
    }

    /// Settings.
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// Cycles in which the gripper reported a contact stop while the loop closed.
    pub fn contact_stops(&self) -> u64 {
        self.contact_stops
    }

    /// The devices back (for a caller that goes on using them).
    pub fn into_parts(self) -> (G, C, E, T) {
        (self.gripper, self.camera, self.estimator, self.truth)
    }

    /// Holds each `(target, duration)` in turn, from wherever the fingers are, and
    /// returns every cycle. Targets are checked before anything moves. The gripper is
    /// left as [`ControllerConfig::on_exit`] says on every path out.
    pub async fn follow(&mut self, targets: &[(f64, Duration)]) -> Result<Vec<Cycle>, GraspError> {
        let (cycles, result, exit) = self.follow_and_exit(targets).await?;
        result?;
        exit?;
        Ok(cycles)
    }

    /// [`Self::follow`], but a stop request ([`Self::with_stop`]) ends it cleanly: the
    /// gripper is left as [`ControllerConfig::on_exit`] says and the cycles run so far
    /// come back with the request's name, for a summary of what ran.
    ///
    /// # Errors
    /// As [`Self::follow`], but never [`GraspError::Interrupted`].
    pub async fn follow_until_stopped(
        &mut self,
        targets: &[(f64, Duration)],
    ) -> Result<(Vec<Cycle>, Option<&'static str>), GraspError> {
        let (cycles, result, exit) = self.follow_and_exit(targets).await?;
        let stopped = match result {
            Ok(()) => None,
            Err(GraspError::Interrupted(_)) => self.stop.as_ref().and_then(|s| *s.borrow()),
            Err(e) => return Err(e),
        };
        exit?;
        Ok((cycles, stopped))
    }

    /// The targets checked (nothing moves on a bad one), the loop run, and the exit
    /// action taken whatever the loop did: the cycles, the loop's outcome and the
    /// exit's, for the caller to rank.
    async fn follow_and_exit(
        &mut self,
        targets: &[(f64, Duration)],
    ) -> Result<(Vec<Cycle>, Result<(), GraspError>, Result<(), GraspError>), GraspError> {
        for (target_n, _) in targets {
            self.config.stepper.check_target(*target_n)?;
        }
        let mut cycles = Vec::new();
        let result = self.follow_inner(targets, &mut cycles).await;
        let exit = self.exit().await;
        Ok((cycles, result, exit))
    }

    /// Moves the fingers to `position` (clamped to the stroke) without force control,
    /// the pre-grasp before [`Self::follow`], and waits until the gripper echoes the
    /// request and reports arrival or a contact stop. Re-sends within the keep-alive;
    /// fails after `timeout` (then the gripper is left as [`ExitAction`] says).
    pub async fn approach(
        &mut self,
        position: u8,
        timeout: Duration,
    ) -> Result<GripperStatus, GraspError> {
        let result = self.approach_inner(position, timeout).await;
        if result.is_err() {
            // The move's error is the one to report; the exit is best effort.
            let _ = self.exit().await;
        }
        result
    }

    async fn approach_inner(
        &mut self,
        position: u8,
        timeout: Duration,
    ) -> Result<GripperStatus, GraspError> {
        self.activate().await?;
        let position = self.config.stepper.stroke.clamp(i64::from(position));
        let start = self.clock.now();
        self.send(position, start).await?;
        loop {
            tokio::time::sleep(APPROACH_POLL).await;
            let status = self.gripper.status().await?;
            check_fault(&status)?;
            let echoed = status.requested_position == position;
            let stopped = matches!(
                status.object,
                ObjectStatus::ContactClosing | ObjectStatus::ContactOpening
            );
            // A real Hand-E may settle a count or two short of the request and report
            // gOBJ = 3 (at position); take that as arrival too.
            let arrived = status.position == position
                || (status.object == ObjectStatus::AtPosition
                    && status.position.abs_diff(position) <= ARRIVAL_SLACK_COUNTS);
            if echoed && (arrived || stopped) {
                return Ok(status);
            }
            let now = self.clock.now();
            if now.0.saturating_sub(start.0) > timeout.as_nanos() as u64 {
                return Err(GraspError::Device(
                    softtouch_drivers::DeviceError::Timeout {
                        device: "gripper".into(),
                        timeout_ms: timeout.as_millis() as u64,
                    },
                ));
            }
            if self.sent.is_none_or(|(_, t)| {
                now.0.saturating_sub(t.0) >= self.config.keep_alive.as_nanos() as u64
            }) {
                self.send(position, now).await?;
            }
        }
    }

    async fn activate(&mut self) -> Result<(), GraspError> {
        if !self.activated {
            self.gripper.activate().await?;
            self.activated = true;
        }
        Ok(())
    }

    async fn follow_inner(
        &mut self,
        targets: &[(f64, Duration)],
        cycles: &mut Vec<Cycle>,
    ) -> Result<(), GraspError> {
        self.activate().await?;
        self.next_frame_t = self.clock.now();
        for (hold, (target_n, duration)) in targets.iter().enumerate() {
            self.hold = hold;
            let end = TimestampNs(
                self.clock
                    .now()
                    .0
                    .saturating_add(duration.as_nanos() as u64),
            );
            while self.clock.now() < end {
                if let Some(name) = self.stop.as_ref().and_then(|s| *s.borrow()) {
                    return Err(GraspError::Interrupted(name.to_string()));
                }
                cycles.push(self.cycle(*target_n).await?);
            }
        }
        Ok(())
    }

    /// One cycle: frame → estimate → projection → step → request.
    pub async fn cycle(&mut self, target_n: f64) -> Result<Cycle, GraspError> {
        // The newest frame, never a queued older one: the loop acts on what the
        // finger feels now, even when it runs slower than the camera.
        let frame = self
            .camera
            .latest_frame_after(self.next_frame_t, self.config.frame_timeout_ms)
            .await?;
        self.next_frame_t = TimestampNs(frame.meta.t.0 + 1);
        let saturation_n = self.config.stepper.saturation_n;
        let first = self.estimator.estimate(&frame)?;
        let mut wrenches = vec![first];
        let mut finger_estimates_n = [
            finger_force_n(first.as_ref(), &self.config.projection, saturation_n),
            None,
        ];
        if let Some(SecondFinger { camera, projection }) = &mut self.second {
            // The same exposure on the second finger's grid.
            let other = camera
                .frame_after(frame.meta.t, self.config.frame_timeout_ms)
                .await?;
            let w = self.estimator.estimate(&other)?;
            finger_estimates_n[1] = finger_force_n(w.as_ref(), projection, saturation_n);
            wrenches.push(w);
        }
        let (estimate_n, single_finger) = if self.second.is_some() {
            combine_fingers(finger_estimates_n, saturation_n)
        } else {
            (finger_estimates_n[0], None)
        };
        // τz only from fingers whose estimate is usable: a NaN or saturated wrench
        // never turns the wrist either.
        let torques: Vec<f64> = wrenches
            .iter()
            .zip(finger_estimates_n)
            .filter(|(_, f)| f.is_some_and(|f| f.is_finite() && f < saturation_n))
            .filter_map(|(w, _)| w.as_ref().map(|w| w.torque_nm[2]))
            .filter(|t| t.is_finite())
            .collect();
        let torque_z_nm =
            (!torques.is_empty()).then(|| torques.iter().sum::<f64>() / torques.len() as f64);
        let dt_s = self
            .last_frame_t
            .map_or(0.0, |t0| frame.meta.t.0.saturating_sub(t0.0) as f64 * 1e-9);
        self.last_frame_t = Some(frame.meta.t);
        let wrist_target_rad = match &mut self.wrist {
            Some((wrist, wrist_loop)) => {
                if let Some(target) = wrist_loop.step(torque_z_nm, dt_s) {
                    wrist.set_yaw_target(target)?;
                }
                Some(wrist_loop.target_rad())
            }
            None => None,
        };
        let true_n = self.truth.true_force_n(frame.meta.t);
        let status = self.gripper.status().await?;
        check_fault(&status)?;
        let now = self.clock.now();
        let echoed = self
            .sent
            .is_none_or(|(p, _)| status.requested_position == p);
        let (position_request, outcome) = if echoed {
            let step = self.stepper.step(status.position, target_n, estimate_n);
            match self.squeezed(&step, &status, target_n, estimate_n) {
                Err(stalled) => {
                    // Hold where the fingers stand: the bound is the furthest they go.
                    let hold = status.position.min(step.position_request);
                    self.send(hold, now).await?;
                    return Err(stalled);
                }
                Ok(step) => (step.position_request, Some(step.outcome)),
            }
        } else {
            let pending = self.sent.map_or(status.position, |(p, _)| p);
            (pending, None)
        };
        if matches!(status.object, ObjectStatus::ContactClosing)
            && position_request > status.position
        {
            self.contact_stops += 1;
        }
        let stale = self.sent.is_none_or(|(_, t)| {
            now.0.saturating_sub(t.0) >= self.config.keep_alive.as_nanos() as u64
        });
        let changed = self.sent.is_none_or(|(p, _)| p != position_request);
        if changed || stale {
            if outcome.is_some_and(StepOutcome::is_flagged) {
                // The stepper's hold is the measured position itself, even outside the
                // stroke: clamping it would move the fingers on an unusable estimate.
                self.send_unclamped(position_request, now).await?;
            } else {
                self.send(position_request, now).await?;
            }
        }
        Ok(Cycle {
            t: frame.meta.t,
            frame_sequence: frame.meta.sequence,
            hold: self.hold,
            target_n,
            estimate_n,
            true_n,
            measured_position: status.position,
            position_request,
            outcome,
            object: status.object,
            finger_estimates_n,
            single_finger,
            torque_z_nm,
            wrist_target_rad,
        })
    }

    /// The step held to the squeeze bound: a request past it stops at it, and fingers
    /// that stand at it (within the arrival slack) while the estimate is still below
    /// the target by more than δ end the loop with [`GraspError::EstimateStalled`].
    fn squeezed(
        &mut self,
        step: &crate::stepper::Step,
        status: &GripperStatus,
        target_n: f64,
        estimate_n: Option<f64>,
    ) -> Result<crate::stepper::Step, GraspError> {
        let Some(bound) = &self.config.squeeze else {
            return Ok(*step);
        };
        if step.outcome.is_flagged() {
            return Ok(*step);
        }
        if self.run_touch.is_none()
            && estimate_n.is_some_and(|f| f - bound.baseline_n >= crate::squeeze::RUN_TOUCH_N)
        {
            self.run_touch = Some(status.position);
        }
        let limit = bound.limit_from(target_n, self.run_touch);
        let below = estimate_n.is_none_or(|f| f < target_n - self.config.stepper.tolerance_n);
        // At the bound: asked for it, and there (or stopped within the arrival slack).
        let asked = self.sent.is_some_and(|(p, _)| p >= limit);
        let there = status.position >= limit
            || (status.object != ObjectStatus::Moving
                && status.position.saturating_add(ARRIVAL_SLACK_COUNTS) >= limit);
        if below && asked && there {
            return Err(GraspError::EstimateStalled {
                target_n,
                estimate_n,
                limit_count: limit,
                touch_count: bound.anchor_count(self.run_touch),
                limit_mm: f64::from(limit.saturating_sub(bound.anchor_count(self.run_touch)))
                    * bound.mm_per_count,
                factor: bound.factor,
            });
        }
        if step.position_request > limit {
            return Ok(crate::stepper::Step {
                position_request: limit,
                outcome: StepOutcome::ClampedSqueeze,
            });
        }
        Ok(*step)
    }

    async fn send(&mut self, position: u8, now: TimestampNs) -> Result<(), GraspError> {
        let position = self.config.stepper.stroke.clamp(i64::from(position));
        self.send_unclamped(position, now).await
    }

    async fn send_unclamped(&mut self, position: u8, now: TimestampNs) -> Result<(), GraspError> {
        self.gripper
            .command(GripperCommand {
                position,
                speed: self.config.speed,
                force: self.config.force,
            })
            .await?;
        self.sent = Some((position, now));
        Ok(())
    }

    /// Leaves the gripper as configured.
    async fn exit(&mut self) -> Result<(), GraspError> {
        let position = match self.config.on_exit {
            ExitAction::Open => self.config.stepper.stroke.open_count,
            ExitAction::Hold => match self.gripper.status().await {
                Ok(s) => self.config.stepper.stroke.clamp(i64::from(s.position)),
                // Cannot read where it is: opening is the safe default.
                Err(_) => self.config.stepper.stroke.open_count,
            },
        };
        let now = self.clock.now();
        self.send(position, now).await
    }
}
