//! Grasp trials on the simulated soft grasp: the protocol of `trials/` run end to
//! end, the physics deciding through [`physics_verdict`].
#![allow(clippy::float_cmp)]

use softtouch_drivers::gripper::position_for_opening;
use softtouch_drivers::{Clock, Frame, TokioClock};
use softtouch_grasp::{
    ControllerConfig, FailReason, ForceEstimator, GraspError, Judge, Lift, LiftPlan, Mode, Moment,
    ObjectState, Observation, Projection, SNAPSHOT_WIDTH_PX, SqueezeBound, TrialConfig,
    TrialDevices, TrialResult, TrueForce, Verdict, physics_verdict, run_trial,
};
use softtouch_schemas::scene::ObjectProfile;
use softtouch_schemas::{ArmPose, RodShape, TimestampNs, Wrench};
use softtouch_sim::{GraspObject, HoldState, SoftGraspHandle, soft_grasp};
use std::sync::Arc;
use std::time::Duration;

/// The simulator's judge, as the collector's: the physics' hold state.
struct SimJudge(SoftGraspHandle);

impl Judge for SimJudge {
    async fn judge(&mut self, seen: &Observation) -> Result<Verdict, GraspError> {
        let state = match self
            .0
            .hold_state()
            .map_err(|e| GraspError::Config(e.to_string()))?
        {
            HoldState::Held => ObjectState::Held,
            HoldState::Crushed { .. } => ObjectState::Crushed,
            HoldState::Absent => ObjectState::Absent,
            HoldState::Slipped { .. } => ObjectState::Slipped,
            HoldState::Resting => ObjectState::Resting,
        };
        Ok(physics_verdict(state, seen))
    }
}

/// The simulator's lift at the clock's present.
struct SimLift {
    handle: SoftGraspHandle,
    clock: Arc<dyn Clock>,
}

impl Lift for SimLift {
    async fn start_lift(&mut self, plan: &LiftPlan) -> Result<(), GraspError> {
        self.handle
            .start_lift(
                self.clock.now(),
                plan.height_m,
                plan.speed_m_s,
                plan.accel_m_s2,
            )
            .map_err(|e| GraspError::Config(e.to_string()))
    }
}

/// A stand-in for the model: the simulator's true wrench on finger 0 at the
/// frame's time (what a perfect model would read).
struct Perfect(SoftGraspHandle);

impl ForceEstimator for Perfect {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        self.0
            .true_wrench(frame.meta.t)
            .map(Some)
            .map_err(|e| GraspError::Estimate(e.to_string()))
    }
}

struct Truth(SoftGraspHandle, Projection);

impl TrueForce for Truth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        self.0
            .true_wrench(t)
            .ok()
            .and_then(|w| self.1.grip_force_n(&w))
    }
}

fn projection() -> Projection {
    Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
    .unwrap_or_else(|e| panic!("{e}"))
}

fn cylinder() -> GraspObject {
    GraspObject::standing(
        "cylinder",
        RodShape::Circle,
        0.03,
        1.0,
        ObjectProfile::Prism { height_m: 0.05 },
    )
}

async fn trial(
    object: GraspObject,
    mode: Mode,
    grasp_opening_mm: f64,
    target_n: f64,
) -> TrialResult {
    trial_bounded(object, mode, grasp_opening_mm, target_n, false).await
}

/// [`trial`], with `bounded`: the loop's squeeze bound from the true closing (1.5 ×
/// the squeeze the target needs past the touch, plus 2 counts).
async fn trial_bounded(
    object: GraspObject,
    mode: Mode,
    grasp_opening_mm: f64,
    target_n: f64,
    bounded: bool,
) -> TrialResult {
    let scene = softtouch_schemas::defaults::scene();
    let clock = TokioClock::new();
    let (gripper, camera, handle) =
        soft_grasp(&scene, object, 30.0, 1, clock).unwrap_or_else(|e| panic!("{e}"));
    let touch = handle.contact_count(0.02).ok().flatten().unwrap_or(0);
    let lambda = handle.max_stiffness_n_per_mm(touch, 255).unwrap_or(1.0);
    let mut config = ControllerConfig::new(projection());
    config.stepper.gain_n_per_mm = 0.75 * lambda.max(0.1);
    if bounded {
        let counts: Vec<u8> = (touch..=touch.saturating_add(40)).collect();
        let closing: Vec<(u8, Option<f64>)> = handle
            .grip_force_curve(&counts)
            .unwrap_or_else(|e| panic!("{e}"))
            .into_iter()
            .map(|(p, f)| (p, Some(f)))
            .collect();
        let mut bound = SqueezeBound::from_points(
            touch,
            0.0,
            &closing,
            lambda,
            config.stepper.stroke.mm_per_count,
        );
        // Tight, so that a loop closing on nothing meets it within the short hold.
        (bound.factor, bound.floor_counts) = (1.5, 2);
        config.squeeze = Some(bound);
    }
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut estimator = Perfect(handle.clone());
    let devices = TrialDevices {
        gripper,
        camera,
        estimator: &mut estimator,
        truth: Truth(handle.clone(), config.projection),
        lift: SimLift {
            handle: handle.clone(),
            clock: Arc::clone(&shared),
        },
        judge: SimJudge(handle.clone()),
        clock: shared,
    };
    let trial = TrialConfig {
        mode,
        grasp_position: position_for_opening(grasp_opening_mm),
        pregrasp_position: touch.saturating_sub(6),
        target_n,
        confirm: Duration::from_millis(200),
        dither_n: 0.0,
        close_timeout: Duration::from_secs(3),
        move_timeout: Duration::from_secs(3),
        lift: LiftPlan {
            height_m: 0.05,
            speed_m_s: 0.1,
            accel_m_s2: 2.0,
        },
        hold: Duration::from_millis(500),
    };
    run_trial(devices, config, &trial)
        .await
        .unwrap_or_else(|e| panic!("{e}"))
}

#[tokio::test(start_paused = true)]
async fn a_closed_loop_grasp_holds_and_an_open_width_that_misses_is_a_miss() {
    let held = trial(cylinder(), Mode::Closed, 28.0, 1.5).await;
    assert_eq!(held.verdict, Verdict::Held, "{held:?}");
    assert!(held.confirmed_after_ns.is_some());
    assert!(held.peak_true_n.is_some_and(|f| f > 1.0));
    // The finger's frames at each moment, in the order they happened, each a
    // thumbnail of a frame the loop read.
    let moments: Vec<Moment> = held.snapshots.iter().map(|s| s.moment).collect();
    assert_eq!(
        moments,
        [
            Moment::Contact,
            Moment::Confirmed,
            Moment::Lifted,
            Moment::End
        ]
    );
    assert!(held.snapshots.windows(2).all(|w| w[0].t <= w[1].t));
    let trace_times: Vec<TimestampNs> = held.trace.iter().map(|r| r.t).collect();
    for s in &held.snapshots {
        assert!(
            trace_times.contains(&s.t),
            "{:?} at a cycle's frame",
            s.moment
        );
        let img = image::load_from_memory(&s.png).unwrap_or_else(|e| panic!("{e}"));
        assert!(img.width() <= SNAPSHOT_WIDTH_PX && img.width() > 0);
    }
    // Contact: the first cycle with a true force above 0.05 N.
    let first_touch = held
        .trace
        .iter()
        .find(|r| r.true_n.is_some_and(|f| f > 0.05))
        .map(|r| r.t);
    assert_eq!(Some(held.snapshots[0].t), first_touch);
    // The confirmation time is on the trace's clock (its first cycle is 0), at the
    // confirming cycle's frame: the viewer's marker, its title, the CSV and the
    // confirmed frame's caption are one number.
    let confirmed = held
        .snapshots
        .iter()
        .find(|s| s.moment == Moment::Confirmed)
        .expect("a confirmed frame");
    assert_eq!(
        held.confirmed_after_ns,
        Some(confirmed.t.0 - held.trace[0].t.0),
        "{held:?}"
    );
    let wide = trial(cylinder(), Mode::Open, 45.0, 1.5).await;
    assert_eq!(
        wide.verdict,
        Verdict::Failed(FailReason::Miss),
        "{:?}",
        wide.verdict
    );
    assert!(!wide.trace.is_empty());
    // An open loop that missed: lifted and ended, never confirmed (and never touched).
    let moments: Vec<Moment> = wide.snapshots.iter().map(|s| s.moment).collect();
    assert_eq!(moments, [Moment::Lifted, Moment::End]);
    let tight = trial(cylinder(), Mode::Open, 28.0, 1.5).await;
    assert!(tight.peak_true_n.is_some_and(|f| f > 0.02));
    // The same trial again gives the same record.
    assert_eq!(trial(cylinder(), Mode::Closed, 28.0, 1.5).await, held);
}

#[tokio::test(start_paused = true)]
async fn a_delicate_object_squeezed_past_its_limit_is_crushed() {
    let mut cake = cylinder();
    cake.name = "cake".into();
    cake.crush_force_n = Some(1.0);
    let r = trial(cake, Mode::Closed, 28.0, 2.0).await;
    assert_eq!(
        r.verdict,
        Verdict::Failed(FailReason::Crush),
        "{:?}",
        r.verdict
    );
}

/// An object too heavy for its friction slips on the lift; the loop, reading a
/// perfect estimate, then closes on the space it left until its squeeze bound stops
/// it. The trial is the physics' failure, a slip, with the stall as its detail: the
/// estimate did not stall, the object was gone.
#[tokio::test(start_paused = true)]
async fn a_loop_that_stalls_after_the_object_slipped_is_a_slip() {
    let mut heavy = cylinder();
    heavy.name = "heavy".into();
    heavy.friction = 0.05;
    heavy.mass_kg = 0.2;
    let r = trial_bounded(heavy, Mode::Closed, 28.0, 1.5, true).await;
    assert!(
        r.confirmed_after_ns.is_some(),
        "{:?} {:?} {:?}",
        r.verdict,
        r.detail,
        r.peak_true_n
    );
    assert_eq!(
        r.verdict,
        Verdict::Failed(FailReason::Slip),
        "{:?}",
        r.detail
    );
    assert!(
        r.detail.as_deref().is_some_and(
            |d| d.contains("after the object was lost") && d.contains("estimate stalled")
        ),
        "{:?}",
        r.detail
    );
    // The same object held by the same bounded loop at the same target, light enough
    // for its friction: held, no stall.
    let mut light = cylinder();
    light.friction = 0.6;
    light.mass_kg = 0.02;
    let r = trial_bounded(light, Mode::Closed, 28.0, 1.5, true).await;
    assert_eq!(r.verdict, Verdict::Held, "{:?}", r.detail);
}
