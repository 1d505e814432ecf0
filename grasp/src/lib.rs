//! The grasp library: Algorithm 1, the force loop and the trial protocol over narrow
//! device traits; it must name no simulator and know no SQL (the collector adapts both).
//!
//! Grasping with the learned touch: the finger's own force estimate closes the loop on
//! a parallel gripper (the paper's Results "Tactile Sensorimotor Grasping
//! Adaptability", Algorithm 1, Methods S3 and S4).
//!
//! # Layout
//! - [`projection`]: Method S3, the predicted wrench rotated from the finger-base frame
//!   to the world frame and projected on the gripping direction.
//! - [`stepper`]: Algorithm 1 as a pure stepper on gripper counts (gain K, tolerance
//!   δ, clamped to the calibrated stroke; NaN or saturated estimates hold), and the
//!   Method S4 checks on K and δ for a measured stiffness Λ.
//! - [`squeeze`]: the closing limit of every force loop, from the stiffness
//!   calibration and the target; an estimate that does not rise stops the loop there.
//! - [`estimator`]: camera frame → wrench, implemented for the trained
//!   [`softtouch_trainer::Predictor`].
//! - [`controller`]: one cycle per camera frame (frame → preprocess → inference →
//!   projection → position request) behind the drivers' [`softtouch_drivers::Gripper`]
//!   and [`softtouch_drivers::Camera`] traits and the injected clock, recording every
//!   cycle; keep-alive, the gPR echo handshake and a safe exit on every path.
//! - [`calibrate`]: end calibration (close and open fully with a low force, read the
//!   reached counts, derive the [`Stroke`]).
//! - [`stiffness`]: Λ(P) and Λ_max from the finger's own estimate while the fingers
//!   close on a reference object one count at a time (Theil–Sen), for K = 0.75 Λ_max.
//! - [`wrist`]: the second, narrow loop that holds τz ≈ 0 by turning the wrist
//!   ([`Wrist`], [`WristLoop`]; on a rig [`ArmWrist`], the flange turned through the
//!   drivers' [`softtouch_drivers::Arm`]).
//! - [`trials`]: the success-rate trials of Figure 4 (perturbed grasp point, open or
//!   closed loop, lift, hold, a judge's verdict) and the Wilson interval; on a rig the
//!   arm lifts through [`ArmLift`] and the operator answers through [`OperatorInput`]
//!   (the Hand-E kept alive while a question waits).
//! - [`metrics`]: rise time, settling time, overshoot, steady-state and RMS error of a
//!   held target.
//!
//! No SQL and no files: callers hand devices and a predictor in and take the trace out.

pub mod calibrate;
pub mod controller;
pub mod estimator;
pub mod metrics;
pub mod projection;
pub mod squeeze;
pub mod stepper;
pub mod stiffness;
pub mod trials;
pub mod wrist;

pub use calibrate::{CalibrationConfig, EndCalibration, calibrate_ends, move_to_end};
pub use controller::{
    Controller, ControllerConfig, Cycle, ExitAction, NoTruth, StopRequest, TrueForce,
    combine_fingers,
};
pub use estimator::ForceEstimator;
pub use metrics::{HoldMetrics, hold_metrics};
pub use projection::Projection;
pub use squeeze::{
    RUN_TOUCH_N, SQUEEZE_FACTOR, SQUEEZE_FLOOR_COUNTS, SqueezeBound, TOUCH_SEARCH_MM,
};
pub use stepper::{
    GainCheck, Step, StepOutcome, Stepper, StepperConfig, Stroke, check_gain, check_tolerance,
    one_count_force_n,
};
pub use stiffness::{
    CalibrationEnd, CalibrationPoint, StiffnessCalibration, StiffnessConfig, calibrate_stiffness,
    theil_sen_slope,
};
pub use trials::{
    ArmLift, FailReason, Judge, KEEP_ALIVE, Lift, LiftPlan, Mode, Moment, ObjectState, Observation,
    OperatorInput, OperatorJudge, RigJudge, SNAPSHOT_WIDTH_PX, SharedArm, SnapCamera, Snapshot,
    TOUCH_N, TraceRow, TrialConfig, TrialDevices, TrialResult, Verdict, Z_95, confirmed,
    mcnemar_exact_p, operator_verdict, perturbation_m, physics_verdict, run_trial, thumbnail_png,
    trial_seed, wilson_interval,
};
pub use wrist::{ArmWrist, Wrist, WristConfig, WristLoop, turned};

use softtouch_drivers::DeviceError;

/// Everything that can go wrong in a grasp.
#[derive(Debug, thiserror::Error)]
pub enum GraspError {
    /// Settings that cannot work (the message names the field and what it expects).
    #[error("invalid grasp settings: {0}")]
    Config(String),
    /// A target force the finger cannot reach.
    #[error(
        "target {target_n} N is unreachable: expected a force in ({lo}, {hi}) N ({why})",
        lo = reachable_n[0],
        hi = reachable_n[1]
    )]
    UnreachableTarget {
        /// The target asked for, N.
        target_n: f64,
        /// The open interval of reachable targets, N.
        reachable_n: [f64; 2],
        /// Why the limits are where they are.
        why: &'static str,
    },
    /// A device refused, faulted or its link failed.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The model could not read a frame.
    #[error("force estimate: {0}")]
    Estimate(String),
    /// The fingers reached the closing limit of [`SqueezeBound`] with the estimate
    /// still below the target: the estimate does not follow the force (a weak model,
    /// a bad frame) and closing further could crush. The loop stops there.
    #[error(
        "estimate stalled: the fingers stand at count {limit_count} ({limit_mm:.2} mm past the touch at {touch_count}, {factor} × the squeeze the calibration needed for {target_n} N) and the estimate reads {estimate}; the loop stopped instead of closing further (check the model and the lighting, or recalibrate)",
        estimate = estimate_n.map_or_else(|| "nothing".to_owned(), |f| format!("{f:.3} N"))
    )]
    EstimateStalled {
        /// The target, N.
        target_n: f64,
        /// The last estimate, N.
        estimate_n: Option<f64>,
        /// The limit reached, counts.
        limit_count: u8,
        /// The touch the limit was measured from (this run's, else the calibrated),
        /// counts.
        touch_count: u8,
        /// The limit's squeeze past the touch, mm.
        limit_mm: f64,
        /// The bound's factor.
        factor: f64,
    },
    /// A stop request (a signal, named) ended the loop; the gripper was left as the
    /// controller's exit action says.
    #[error("stopped by {0}")]
    Interrupted(String),
}
