//! Grasp success-rate trials (the paper's Figure 4): each trial perturbs the grasp
//! point, closes open loop (to the object's predefined width) or closed loop
//! (Algorithm 1 until |F_ref − F_est| ≤ δ for a confirmation time), lifts, holds, and
//! asks a [`Judge`] whether the object is still held.
//!
//! The protocol is generic over the devices ([`Gripper`], [`Camera`], a
//! [`ForceEstimator`]) plus two narrow traits: [`Lift`] raises the gripper (the
//! simulator's, in the lab crate; a real arm's through [`ArmLift`]) and [`Judge`]
//! decides the outcome (where the object ended, through [`physics_verdict`], for the
//! simulator's judge in the collector; gOBJ, position and the estimate on a real rig
//! through [`RigJudge`], optionally confirmed or corrected by an operator through
//! [`OperatorJudge`]). Outcomes are never drawn at random: the physics, the rig or the
//! operator decides. No SQL, no files and no simulator here. On a rig the operator
//! answers through [`OperatorInput`], which keeps the Hand-E alive while it waits.
//!
//! Perturbations are a pure function of `(seed, object, trial)` ([`perturbation_m`]),
//! so any trial can be replayed alone; the same draws are scaled by σ, so a σ sweep
//! compares like with like.

mod arm;
mod judges;
mod operator;
pub use arm::{ArmLift, SharedArm};
pub use judges::{
    GOBJ_CONFIRM_FRACTION, ObjectState, OperatorJudge, RigJudge, TOUCH_N, physics_verdict,
};
pub use operator::{KEEP_ALIVE, OperatorInput, operator_verdict, verdict_name};

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

mod run;
pub use run::*;
mod snapshots;
pub use snapshots::{Moment, SNAPSHOT_WIDTH_PX, SnapCamera, Snapshot, thumbnail_png};

/// McNemar's exact test of paired outcomes: the two-sided p-value that `b` pairs
/// going one way (e.g. open held, closed failed) and `c` the other are as likely as
/// a fair coin's split of `b + c` (the binomial test at ½; pairs that agree carry no
/// information). 1 when `b + c = 0`.
///
/// Summed in log space, so any count gives a finite p in [0, 1]. (Written here rather
/// than taken from `statrs`: it is one binomial tail, and `statrs` would bring
/// `nalgebra`'s build into every crate that judges a trial.)
#[must_use]
pub fn mcnemar_exact_p(b: u64, c: u64) -> f64 {
    let n = b + c;
    if n == 0 {
        return 1.0;
    }
    let k = b.min(c);
    // ln C(n, i) · 2^-n for i = 0..=k, accumulated with log-sum-exp.
    let ln_half_n = -(n as f64) * std::f64::consts::LN_2;
    let mut ln_c = 0.0_f64;
    let mut terms = Vec::with_capacity(k as usize + 1);
    for i in 0..=k {
        if i > 0 {
            ln_c += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        terms.push(ln_c + ln_half_n);
    }
    let top = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let tail = top.exp() * terms.iter().map(|t| (t - top).exp()).sum::<f64>();
    (2.0 * tail).min(1.0)
}

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
    /// The closed loop reached its squeeze bound with the estimate below the target
    /// ([`crate::GraspError::EstimateStalled`]): it stopped there instead of closing on.
    EstimateStalled,
    /// The closed loop confirmed its force on an estimate the fingers never felt (the
    /// true force stayed at most [`TOUCH_N`]) and lifted without the object: the
    /// estimate failed, not the reach (a `miss` is a grasp that never met the object).
    FalseConfirm,
    /// The perturbed grasp pose lay outside the workspace: nothing moved. Stored and
    /// shown, never counted as a trial of the success rate.
    Refused,
}

impl FailReason {
    /// Every reason, in the order tables list them.
    pub const ALL: [Self; 8] = [
        Self::Slip,
        Self::Crush,
        Self::Miss,
        Self::Timeout,
        Self::DeviceFault,
        Self::EstimateStalled,
        Self::FalseConfirm,
        Self::Refused,
    ];

    /// As stored: `slip`, `crush`, `miss`, `timeout`, `device_fault`,
    /// `estimate_stalled`, `false_confirm`, `refused`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Slip => "slip",
            Self::Crush => "crush",
            Self::Miss => "miss",
            Self::Timeout => "timeout",
            Self::DeviceFault => "device_fault",
            Self::EstimateStalled => "estimate_stalled",
            Self::FalseConfirm => "false_confirm",
            Self::Refused => "refused",
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
                format!("unknown failure reason `{s}`: expected slip, crush, miss, timeout, device_fault, estimate_stalled, false_confirm or refused")
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

impl<L: Lift> Lift for &mut L {
    fn start_lift(
        &mut self,
        plan: &LiftPlan,
    ) -> impl Future<Output = Result<(), GraspError>> + Send {
        (**self).start_lift(plan)
    }
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

impl<J: Judge> Judge for &mut J {
    fn judge(
        &mut self,
        seen: &Observation,
    ) -> impl Future<Output = Result<Verdict, GraspError>> + Send {
        (**self).judge(seen)
    }
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
    /// Closed loop: how long the force must be confirmed before the lift: over this
    /// window the mean of F_est lies within δ of F_ref and every F_est within
    /// δ + `dither_n` ([`confirmed`]).
    pub confirm: Duration,
    /// Closed loop: the force of one count at the calibrated Λ_max, N (Method S4). A
    /// loop whose δ is below half of it dithers by a count around F_ref for ever; the
    /// confirmation accepts that dither when its mean is within δ. 0: every estimate
    /// within δ.
    pub dither_n: f64,
    /// Closed loop: how long the loop may take to confirm.
    pub close_timeout: Duration,
    /// How long a pre-grasp or open-loop move may take.
    pub move_timeout: Duration,
    /// The lift.
    pub lift: LiftPlan,
    /// How long the object is held after the lift ends.
    pub hold: Duration,
}

/// Whether a closed loop's force is confirmed over `window` (the estimates of the
/// last `confirm`, oldest first): every estimate usable and within δ + `dither_n` of
/// F_ref, and their mean within δ. With `dither_n` = 0 this is "every estimate
/// within δ"; with one count's force it also confirms a loop dithering one count
/// around a target between two counts, which no δ below half a count's force
/// otherwise lets through (a feasible target that would time out).
#[must_use]
pub fn confirmed(window: &[Option<f64>], target_n: f64, tolerance_n: f64, dither_n: f64) -> bool {
    let slack = tolerance_n + dither_n.max(0.0);
    let mut sum = 0.0;
    for e in window {
        match e {
            Some(f) if f.is_finite() && (target_n - f).abs() <= slack => sum += f,
            _ => return false,
        }
    }
    !window.is_empty() && (target_n - sum / window.len() as f64).abs() <= tolerance_n
}

impl TrialConfig {
    fn validate(&self) -> Result<(), GraspError> {
        self.lift.validate()?;
        if !(self.dither_n.is_finite() && self.dither_n >= 0.0) {
            return Err(GraspError::Config(format!(
                "dither_n = {}: expected a force of at least 0 N",
                self.dither_n
            )));
        }
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

#[cfg(test)]
mod confirm_tests {
    use super::confirmed;

    #[test]
    fn a_one_count_dither_around_the_target_confirms_only_with_its_allowance() {
        // One count is 0.23 N; δ = 0.1 N: the loop alternates 1.38 and 1.61 N around 1.5.
        let dither: Vec<Option<f64>> = (0..30)
            .map(|i| Some(if i % 2 == 0 { 1.38 } else { 1.61 }))
            .collect();
        assert!(
            !confirmed(&dither, 1.5, 0.1, 0.0),
            "the old rule never confirms it"
        );
        assert!(confirmed(&dither, 1.5, 0.1, 0.23));
        // Held a count off: the mean is outside δ.
        let off: Vec<Option<f64>> = vec![Some(1.38); 30];
        assert!(!confirmed(&off, 1.5, 0.1, 0.23));
        // A swing beyond one count, a missing or NaN estimate, an empty window.
        let mut swing = dither.clone();
        swing[7] = Some(2.0);
        assert!(!confirmed(&swing, 1.5, 0.1, 0.23));
        let mut hole = dither.clone();
        hole[3] = None;
        assert!(!confirmed(&hole, 1.5, 0.1, 0.23));
        hole[3] = Some(f64::NAN);
        assert!(!confirmed(&hole, 1.5, 0.1, 0.23));
        assert!(!confirmed(&[], 1.5, 0.1, 0.23));
        // Without a dither allowance: every estimate within δ.
        assert!(confirmed(&[Some(1.45), Some(1.58)], 1.5, 0.1, 0.0));
        assert!(!confirmed(&[Some(1.45), Some(1.61)], 1.5, 0.1, 0.0));
        // A negative allowance counts as none.
        assert!(!confirmed(&dither, 1.5, 0.1, -1.0));
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
    /// When the closed loop confirmed its force: ns after the trial's first cycle (the
    /// trace's and the frames' time origin), at the frame of the confirming cycle.
    pub confirmed_after_ns: Option<u64>,
    /// Every cycle.
    pub trace: Vec<TraceRow>,
    /// The finger's frames at contact, confirmation, lift and end (those that
    /// happened), as thumbnails.
    pub snapshots: Vec<Snapshot>,
}

impl TrialResult {
    /// The furthest the fingers closed in the trial, counts (`None`: no cycle ran).
    #[must_use]
    pub fn deepest_position(&self) -> Option<u8> {
        self.trace.iter().map(|r| r.measured_position).max()
    }
}

#[cfg(test)]
mod tests;
