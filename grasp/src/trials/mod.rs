//! Grasp success-rate trials (the paper's Figure 4): each trial perturbs the grasp
//! point, closes open loop (to the object's predefined width) or closed loop
//! (Algorithm 1 until |F_ref − F_est| ≤ δ for a confirmation time), lifts, holds, and
//! asks a [`Judge`] whether the object is still held.
//!
//! The protocol is generic over the devices ([`Gripper`], [`Camera`], a
//! [`ForceEstimator`]) plus two narrow traits: [`Lift`] raises the gripper (the
//! simulator's, in the collector; a real arm's is not written yet) and [`Judge`]
//! decides the outcome (where the object ended, through [`physics_verdict`], for the
//! simulator's judge in the collector; gOBJ, position and the estimate on a real rig
//! through [`RigJudge`], optionally confirmed or corrected by an operator through
//! [`OperatorJudge`]). Outcomes are never drawn at random: the physics, the rig or the
//! operator decides. No SQL, no files and no simulator here. `softtouch grasp trials`
//! runs the simulator only so far: a real rig also needs a [`Lift`] on its arm.
//!
//! Perturbations are a pure function of `(seed, object, trial)` ([`perturbation_m`]),
//! so any trial can be replayed alone; the same draws are scaled by σ, so a σ sweep
//! compares like with like.

mod judges;
pub use judges::{ObjectState, OperatorJudge, RigJudge, TOUCH_N, physics_verdict};

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use softtouch_drivers::{
    Camera, Clock, DeviceError, Frame, Gripper, GripperCommand, GripperStatus, ObjectStatus,
};
use softtouch_schemas::{TimestampNs, Wrench};

use crate::GraspError;
use crate::controller::{Controller, ControllerConfig, ExitAction, TrueForce};
use crate::estimator::ForceEstimator;

/// z of the two-sided 95 % normal interval.
pub const Z_95: f64 = 1.959_963_984_540_054;

/// The Wilson score interval `[lo, hi]` of a success rate of `successes` out of `n`
/// at normal quantile `z` (e.g. [`Z_95`]). With `n = 0` nothing is known: `[0, 1]`.
///
/// # Errors
/// `successes > n`, or `z` not finite and above 0.
pub fn wilson_interval(successes: u64, n: u64, z: f64) -> Result<[f64; 2], GraspError> {
    if successes > n {
        return Err(GraspError::Config(format!(
            "Wilson interval: {successes} successes out of {n} trials: expected at most {n}"
        )));
    }
    if !(z.is_finite() && z > 0.0) {
        return Err(GraspError::Config(format!(
            "Wilson interval: z = {z}: expected a finite value above 0"
        )));
    }
    if n == 0 {
        return Ok([0.0, 1.0]);
    }
    let nf = n as f64;
    let p = successes as f64 / nf;
    let z2 = z * z;
    let denom = 1.0 + z2 / nf;
    let centre = (p + z2 / (2.0 * nf)) / denom;
    let half = z / denom * (p * (1.0 - p) / nf + z2 / (4.0 * nf * nf)).sqrt();
    // Exact ends at 0 and n (the formula gives them up to rounding).
    let lo = if successes == 0 { 0.0 } else { centre - half };
    let hi = if successes == n { 1.0 } else { centre + half };
    Ok([lo.clamp(0.0, 1.0), hi.clamp(0.0, 1.0)])
}

/// How the fingers close.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Mode {
    /// To the object's predefined width, no force feedback.
    Open,
    /// Algorithm 1 on the learned estimate.
    Closed,
}

impl Mode {
    /// As stored and typed: `open`, `closed`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Open => "open",
            Self::Closed => "closed",
        }
    }

    /// Parses [`Self::as_str`].
    ///
    /// # Errors
    /// Anything else, with what is expected.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim() {
            "open" => Ok(Self::Open),
            "closed" => Ok(Self::Closed),
            other => Err(format!("unknown mode `{other}`: expected open or closed")),
        }
    }
}

/// Why a trial failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FailReason {
    /// The object slid out of the fingers during the lift or hold.
    Slip,
    /// A delicate object was squeezed past its limit.
    Crush,
    /// The fingers never held the object (closed on nothing, or landed on it).
    Miss,
    /// The closed loop never confirmed its force in time.
    Timeout,
    /// A device faulted or its link failed.
    DeviceFault,
}

impl FailReason {
    /// Every reason, in the order tables list them.
    pub const ALL: [Self; 5] = [
        Self::Slip,
        Self::Crush,
        Self::Miss,
        Self::Timeout,
        Self::DeviceFault,
    ];

    /// As stored: `slip`, `crush`, `miss`, `timeout`, `device_fault`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Slip => "slip",
            Self::Crush => "crush",
            Self::Miss => "miss",
            Self::Timeout => "timeout",
            Self::DeviceFault => "device_fault",
        }
    }

    /// Parses [`Self::as_str`].
    ///
    /// # Errors
    /// Anything else, with what is expected.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|r| r.as_str() == s)
            .ok_or_else(|| {
                format!("unknown failure reason `{s}`: expected slip, crush, miss, timeout or device_fault")
            })
    }
}

/// The outcome of a trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Verdict {
    /// Still held after the lift and the hold.
    Held,
    /// Not held, and why.
    Failed(FailReason),
}

impl Verdict {
    /// Whether the object was held.
    #[must_use]
    pub const fn success(self) -> bool {
        matches!(self, Self::Held)
    }

    /// The failure reason, if any.
    #[must_use]
    pub const fn reason(self) -> Option<FailReason> {
        match self {
            Self::Held => None,
            Self::Failed(r) => Some(r),
        }
    }
}

/// FNV-1a, 64 bit: a stable hash of an object's name.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// SplitMix64 finaliser.
const fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A seed that depends only on `(seed, object, trial)`: the perturbation's stream, and
/// the simulator's, so both modes and every medium see the same trial.
#[must_use]
pub fn trial_seed(seed: u64, object: &str, trial: u64) -> u64 {
    mix(mix(seed) ^ mix(fnv1a(object.as_bytes())).rotate_left(21) ^ mix(trial ^ 0x7f4a_7c15))
}

/// The grasp point's offset of trial `trial` of `object`, m, per axis N(0, σ²) (x along
/// the gripping direction, y across the fingers, z along the finger). A pure function
/// of `(seed, object, trial)`; σ only scales the same standard-normal draws.
#[must_use]
pub fn perturbation_m(seed: u64, object: &str, trial: u64, sigma_m: f64) -> [f64; 3] {
    let mut rng = ChaCha8Rng::seed_from_u64(trial_seed(seed, object, trial));
    let sigma = if sigma_m.is_finite() {
        sigma_m.max(0.0)
    } else {
        0.0
    };
    let mut out = [0.0; 3];
    for v in &mut out {
        let z: f64 = StandardNormal.sample(&mut rng);
        *v = sigma * z;
    }
    out
}

/// A trapezoidal lift of the gripper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftPlan {
    /// How high, m.
    pub height_m: f64,
    /// Top speed, m/s.
    pub speed_m_s: f64,
    /// Acceleration and deceleration, m/s².
    pub accel_m_s2: f64,
}

impl LiftPlan {
    /// Checks the numbers.
    ///
    /// # Errors
    /// A value not finite and above 0.
    pub fn validate(&self) -> Result<(), GraspError> {
        for (field, v) in [
            ("lift height_m", self.height_m),
            ("lift speed_m_s", self.speed_m_s),
            ("lift accel_m_s2", self.accel_m_s2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GraspError::Config(format!(
                    "{field} = {v}: expected a finite value above 0"
                )));
            }
        }
        Ok(())
    }

    /// How long the lift takes, s (a triangle when the height is too short to reach
    /// the top speed).
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        let (h, v, a) = (self.height_m, self.speed_m_s, self.accel_m_s2);
        if h * a <= v * v {
            2.0 * (h / a).sqrt()
        } else {
            h / v + v / a
        }
    }
}

/// Raises the gripper with the object (the simulator's handle; a real arm).
pub trait Lift: Send {
    /// Starts the lift now; it runs on while the caller goes on cycling.
    fn start_lift(
        &mut self,
        plan: &LiftPlan,
    ) -> impl Future<Output = Result<(), GraspError>> + Send;
}

/// What a trial saw, for the [`Judge`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The mode.
    pub mode: Mode,
    /// Whether the lift was started (closed loop: only after the force was confirmed).
    pub lifted: bool,
    /// The gripper's last status.
    pub last_status: GripperStatus,
    /// The last usable estimate, N.
    pub last_estimate_n: Option<f64>,
    /// The largest usable estimate, N.
    pub peak_estimate_n: Option<f64>,
    /// The largest true force, N, where a truth is known (simulation).
    pub peak_true_n: Option<f64>,
}

/// Decides whether the object is still held after the lift and the hold.
pub trait Judge: Send {
    /// The verdict on what the trial saw.
    fn judge(
        &mut self,
        seen: &Observation,
    ) -> impl Future<Output = Result<Verdict, GraspError>> + Send;
}

/// A trial's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialConfig {
    /// Open or closed loop.
    pub mode: Mode,
    /// Open loop: the predefined width's position, counts.
    pub grasp_position: u8,
    /// Closed loop: where the fingers wait before the loop closes them, counts.
    pub pregrasp_position: u8,
    /// Closed loop: F_ref, N.
    pub target_n: f64,
    /// Closed loop: how long |F_ref − F_est| ≤ δ must hold before the lift.
    pub confirm: Duration,
    /// Closed loop: how long the loop may take to confirm.
    pub close_timeout: Duration,
    /// How long a pre-grasp or open-loop move may take.
    pub move_timeout: Duration,
    /// The lift.
    pub lift: LiftPlan,
    /// How long the object is held after the lift ends.
    pub hold: Duration,
}

impl TrialConfig {
    fn validate(&self) -> Result<(), GraspError> {
        self.lift.validate()?;
        if !(self.target_n.is_finite() && self.target_n > 0.0) {
            return Err(GraspError::Config(format!(
                "target_n = {}: expected a finite force above 0 N",
                self.target_n
            )));
        }
        for (field, d) in [
            ("close_timeout", self.close_timeout),
            ("move_timeout", self.move_timeout),
        ] {
            if d.is_zero() {
                return Err(GraspError::Config(format!(
                    "{field} 0 s: expected a time above 0"
                )));
            }
        }
        Ok(())
    }
}

/// One control (closed loop) or observation (open loop) cycle of a trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRow {
    /// When the frame was exposed, ns on the devices' clock.
    pub t: TimestampNs,
    /// F_est, N (`None`: no usable estimate).
    pub estimate_n: Option<f64>,
    /// F_true, N, where known.
    pub true_n: Option<f64>,
    /// P_m, counts.
    pub measured_position: u8,
    /// P_ref, counts.
    pub position_request: u8,
}

/// What a trial did.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    /// Held, or why not.
    pub verdict: Verdict,
    /// A device's message when the verdict is a device fault.
    pub detail: Option<String>,
    /// The last position requested, counts (open loop: the predefined width's).
    pub commanded_position: u8,
    /// The measured position at the end, counts.
    pub final_position: u8,
    /// The largest usable estimate, N.
    pub peak_estimate_n: Option<f64>,
    /// The largest true force, N (simulation).
    pub peak_true_n: Option<f64>,
    /// When the closed loop confirmed its force (ns after the trial's start).
    pub confirmed_after_ns: Option<u64>,
    /// Every cycle.
    pub trace: Vec<TraceRow>,
}

/// Lends a [`ForceEstimator`] to one trial's controller.
struct Lent<'a, E>(&'a mut E);

impl<E: ForceEstimator> ForceEstimator for Lent<'_, E> {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        self.0.estimate(frame)
    }
}

fn fmax(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.max(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

fn elapsed_ns(clock: &dyn Clock, since: TimestampNs) -> u64 {
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
    let ctl = Controller::new(
        gripper,
        camera,
        Lent(estimator),
        truth,
        Arc::clone(&clock),
        controller,
    )?;
    let mut run = Run {
        clock: Arc::clone(&clock),
        start: clock.now(),
        trace: Vec::new(),
        lifted: false,
        confirmed_after_ns: None,
        last_status: None,
        commanded: match config.mode {
            Mode::Open => config.grasp_position,
            Mode::Closed => config.pregrasp_position,
        },
    };
    let outcome = match config.mode {
        Mode::Open => run.open_loop(ctl, &mut lift, &controller, config).await,
        Mode::Closed => run.closed_loop(ctl, &mut lift, config).await,
    };
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
            (judge.judge(&seen).await?, None)
        }
        Err(GraspError::Device(DeviceError::Timeout { device, timeout_ms })) => (
            Verdict::Failed(FailReason::Timeout),
            Some(format!("{device} timed out after {timeout_ms} ms")),
        ),
        Err(GraspError::Device(e)) => (
            Verdict::Failed(FailReason::DeviceFault),
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
    })
}

/// The state of one trial while it runs.
struct Run {
    clock: Arc<dyn Clock>,
    start: TimestampNs,
    trace: Vec<TraceRow>,
    lifted: bool,
    confirmed_after_ns: Option<u64>,
    last_status: Option<GripperStatus>,
    commanded: u8,
}

impl Run {
    fn record(&mut self, c: &crate::controller::Cycle) {
        self.trace.push(TraceRow {
            t: c.t,
            estimate_n: c.estimate_n,
            true_n: c.true_n,
            measured_position: c.measured_position,
            position_request: c.position_request,
        });
        self.commanded = c.position_request;
    }

    /// Close to the predefined width, lift, hold; watch the estimate all along.
    async fn open_loop<G, C, E, T, L>(
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
        let keep_alive_ns = config.keep_alive.as_nanos() as u64;
        let mut sent = self.clock.now();
        let mut next = self.clock.now();
        // The first cycle watches the closed fingers before the lift, so a grasp that
        // slips at lift-off (where the load is largest) is seen to have touched.
        let mut end: Option<u64> = None;
        let watched: Result<(), GraspError> = async {
            while end.is_none_or(|end| self.clock.now().0 < end) {
                let frame = camera.frame_after(next, config.frame_timeout_ms).await?;
                next = TimestampNs(frame.meta.t.0 + 1);
                let sat = config.stepper.saturation_n;
                let estimate_n = match estimator.estimate(&frame)? {
                    Some(w) if w.is_finite() && w.force_norm_n() >= sat => Some(sat),
                    Some(w) => config.projection.grip_force_n(&w),
                    None => None,
                };
                let true_n = truth.true_force_n(frame.meta.t);
                let status = gripper.status().await?;
                self.last_status = Some(status);
                if status.fault != 0 {
                    return Err(GraspError::Device(DeviceError::Fault {
                        device: "gripper".into(),
                        code: Some(u32::from(status.fault)),
                        message: "the gripper reported a fault while holding".into(),
                    }));
                }
                // Keep-alive: the Hand-E faults after about 1 s without a command.
                if elapsed_ns(self.clock.as_ref(), sent) >= keep_alive_ns {
                    gripper.command(command).await?;
                    sent = self.clock.now();
                }
                self.trace.push(TraceRow {
                    t: frame.meta.t,
                    estimate_n,
                    true_n,
                    measured_position: status.position,
                    position_request: grasp_position,
                });
                if end.is_none() {
                    lift.start_lift(&trial.lift).await?;
                    self.lifted = true;
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
    async fn closed_loop<G, C, E, T, L>(
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
        let mut within_since: Option<TimestampNs> = None;
        loop {
            let c = ctl.cycle(trial.target_n).await?;
            self.record(&c);
            let within = c
                .estimate_n
                .is_some_and(|f| (trial.target_n - f).abs() <= tolerance_n);
            if within {
                let since = *within_since.get_or_insert(c.t);
                if c.t.0.saturating_sub(since.0) >= trial.confirm.as_nanos() as u64 {
                    break;
                }
            } else {
                within_since = None;
            }
            if elapsed_ns(self.clock.as_ref(), close_start) > trial.close_timeout.as_nanos() as u64
            {
                // Not confirmed: no lift; the judge says what became of the object.
                self.last_status = Some(self.status_of(&c));
                return Ok(());
            }
        }
        self.confirmed_after_ns = Some(elapsed_ns(self.clock.as_ref(), self.start));
        lift.start_lift(&trial.lift).await?;
        self.lifted = true;
        let hold = Duration::from_secs_f64(trial.lift.duration_s()) + trial.hold;
        let end = self.clock.now().0 + hold.as_nanos() as u64;
        let mut last = None;
        while self.clock.now().0 < end {
            let c = ctl.cycle(trial.target_n).await?;
            self.record(&c);
            last = Some(c);
        }
        if let Some(c) = last {
            self.last_status = Some(self.status_of(&c));
        }
        // The gripper keeps the loop's last request: it goes on holding.
        Ok(())
    }

    fn status_of(&self, c: &crate::controller::Cycle) -> GripperStatus {
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

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are the point of some checks
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn wilson_intervals_match_known_values() {
        assert_eq!(wilson_interval(0, 0, Z_95).ok(), Some([0.0, 1.0]));
        // All failures: [0, z²/(n+z²)]; all successes: its mirror.
        let [lo, hi] = wilson_interval(0, 10, Z_95).unwrap_or_default();
        assert_eq!(lo, 0.0);
        assert!(close(hi, 0.2775, 1e-4), "{hi}");
        let [lo, hi] = wilson_interval(10, 10, Z_95).unwrap_or_default();
        assert!(close(lo, 0.7225, 1e-4), "{lo}");
        assert_eq!(hi, 1.0);
        // Newcombe (1998), Statistics in Medicine 17:857, Table I, method 3.
        for (k, n, lo_want, hi_want) in [
            (81, 263, 0.2553, 0.3662),
            (15, 148, 0.0624, 0.1605),
            (0, 20, 0.0, 0.1611),
            (1, 29, 0.0061, 0.1718),
        ] {
            let [lo, hi] = wilson_interval(k, n, Z_95).unwrap_or_default();
            assert!(
                close(lo, lo_want, 1e-4) && close(hi, hi_want, 1e-4),
                "{k}/{n}: {lo} {hi}"
            );
        }
        assert!(wilson_interval(11, 10, Z_95).is_err());
        assert!(wilson_interval(1, 10, f64::NAN).is_err());
        assert!(wilson_interval(1, 10, 0.0).is_err());
        // Huge counts stay finite and inside [0, 1].
        let [lo, hi] = wilson_interval(u64::MAX / 2, u64::MAX, Z_95).unwrap_or_default();
        assert!(lo.is_finite() && hi.is_finite() && lo <= 0.5 && hi >= 0.5);
    }

    #[test]
    fn perturbations_are_a_function_of_seed_object_and_trial() {
        let a = perturbation_m(7, "cake", 3, 0.005);
        assert_eq!(a, perturbation_m(7, "cake", 3, 0.005));
        assert_ne!(a, perturbation_m(7, "cake", 4, 0.005));
        assert_ne!(a, perturbation_m(7, "ball", 3, 0.005));
        assert_ne!(a, perturbation_m(8, "cake", 3, 0.005));
        // σ scales the same draws; σ = 0 (or garbage) is no perturbation.
        let b = perturbation_m(7, "cake", 3, 0.010);
        for i in 0..3 {
            assert!(close(b[i], 2.0 * a[i], 1e-15));
        }
        assert_eq!(perturbation_m(7, "cake", 3, 0.0), [0.0; 3]);
        assert_eq!(perturbation_m(7, "cake", 3, f64::NAN), [0.0; 3]);
        // Over many trials each axis has about the asked σ.
        let n = 4000;
        let sd: Vec<f64> = (0..3)
            .map(|axis| {
                let v: Vec<f64> = (0..n)
                    .map(|t| perturbation_m(1, "x", t, 0.005)[axis])
                    .collect();
                (v.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt()
            })
            .collect();
        assert!(sd.iter().all(|s| close(*s, 0.005, 0.0003)), "{sd:?}");
    }

    #[test]
    fn names_parse_back_and_bad_ones_say_what_is_expected() {
        for m in [Mode::Open, Mode::Closed] {
            assert_eq!(Mode::parse(m.as_str()), Ok(m));
        }
        for r in FailReason::ALL {
            assert_eq!(FailReason::parse(r.as_str()), Ok(r));
        }
        assert!(Mode::parse("half").is_err_and(|e| e.contains("open or closed")));
        assert!(FailReason::parse("").is_err_and(|e| e.contains("slip")));
    }

    #[test]
    fn lift_durations_are_trapezoids_or_triangles() {
        let long = LiftPlan {
            height_m: 0.05,
            speed_m_s: 0.1,
            accel_m_s2: 1.0,
        };
        assert!(close(long.duration_s(), 0.6, 1e-12));
        let short = LiftPlan {
            height_m: 0.001,
            speed_m_s: 1.0,
            accel_m_s2: 1.0,
        };
        assert!(close(short.duration_s(), 2.0 * 0.001_f64.sqrt(), 1e-12));
        assert!(
            LiftPlan {
                height_m: 0.0,
                ..long
            }
            .validate()
            .is_err()
        );
        assert!(
            LiftPlan {
                accel_m_s2: f64::INFINITY,
                ..long
            }
            .validate()
            .is_err()
        );
    }
}
