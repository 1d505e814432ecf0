//! The simulated soft grasp behind the grasp library's narrow traits: its judge
//! ([`SimJudge`]), lift ([`SimLift`]), wrist ([`SimWrist`]) and the truth recorded
//! beside the estimate ([`SimTruth`], [`LoggedTruth`]; never fed to a loop). These
//! adapters live here so that `softtouch-grasp` names no simulator.

use std::sync::{Arc, Mutex};

use softtouch_drivers::{Clock, DeviceError};
use softtouch_grasp::{
    GraspError, Judge, Lift, LiftPlan, ObjectState, Observation, Projection, TrueForce, Verdict,
    Wrist, physics_verdict,
};
use softtouch_schemas::{ArmPose, TimestampNs};
use softtouch_sim::{HoldState, SimError, SoftGraspHandle};

/// The soft finger's sensor +x faces the object, so its push (−x) is the world's +y.
///
/// # Errors
/// Never in practice (the pose is a fixed rotation); the projection checks it.
pub fn projection() -> Result<Projection, GraspError> {
    Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
}

/// A runtime of its own on a paused clock, for one simulated grasp on this thread
/// (a trial, a calibration): the caller's runtime, and its database, keep real time.
///
/// # Errors
/// The runtime cannot be built.
pub(crate) fn paused_runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
}

pub(crate) fn sim_err(e: SimError) -> GraspError {
    GraspError::Config(format!("simulated grasp: {e}"))
}

/// The simulator's truth, recorded beside the estimate (never fed to the loop).
#[derive(Debug)]
pub struct SimTruth(pub SoftGraspHandle, pub Projection);

impl TrueForce for SimTruth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        self.0
            .true_wrench(t)
            .ok()
            .and_then(|w| self.1.grip_force_n(&w))
    }
}

/// The truth of a trial, whose verdict the physics gives with both fingers: each cycle
/// the loop's finger (0) as the trace records it, and the largest true grip force on
/// either finger so far in `peak_n` (each projected like the estimate): what a row's
/// `peak_true_n` and a cell's grip max report, since either finger can crush.
#[derive(Debug)]
pub struct BothFingersTruth {
    /// The grasp.
    pub handle: SoftGraspHandle,
    /// Each finger's projection onto the grip axis.
    pub projections: [Projection; 2],
    /// The largest true grip force on either finger at a cycle so far, N.
    pub peak_n: Arc<Mutex<Option<f64>>>,
}

impl TrueForce for BothFingersTruth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        let on = |k: usize| {
            self.handle
                .true_wrench_on(k, t)
                .ok()
                .and_then(|w| self.projections[k].grip_force_n(&w))
                .filter(|f| f.is_finite())
        };
        let (watched, other) = (on(0), on(1));
        let both = match (watched, other) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        if let (Some(f), Ok(mut peak)) = (both, self.peak_n.lock()) {
            *peak = Some(peak.map_or(f, |p| p.max(f)));
        }
        watched
    }
}

/// The simulator's truth at one cycle, as [`LoggedTruth`] records it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    /// When, on the devices' clock.
    pub t: TimestampNs,
    /// Mean true τz over the fingers read, N·m.
    pub torque_z_nm: f64,
    /// The wrist's yaw, rad.
    pub wrist_rad: f64,
}

/// The simulator's truth for the record (the loop never reads it): the mean of the
/// fingers the loop reads, projected like the estimate; τz and the wrist are logged.
#[derive(Debug)]
pub struct LoggedTruth {
    /// The grasp.
    pub handle: SoftGraspHandle,
    /// Each finger's projection onto the grip axis.
    pub projections: [Projection; 2],
    /// How many fingers the loop reads (1 or 2).
    pub fingers: usize,
    /// Every cycle's τz and wrist yaw.
    pub log: Arc<Mutex<Vec<TruthSample>>>,
}

impl TrueForce for LoggedTruth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        let (mut force, mut torque) = (0.0, 0.0);
        for k in 0..self.fingers {
            let w = self.handle.true_wrench_on(k, t).ok()?;
            force += self.projections[k].grip_force_n(&w)?;
            torque += w.torque_nm[2];
        }
        let n = self.fingers as f64;
        if let (Ok(wrist_rad), Ok(mut log)) = (self.handle.wrist_yaw(t), self.log.lock()) {
            log.push(TruthSample {
                t,
                torque_z_nm: torque / n,
                wrist_rad,
            });
        }
        Some(force / n)
    }
}

/// The first count at which the closing fingers touch the object (true force above
/// 0.02 N), and Λ_max from there to the first count whose true force exceeds `top_n`
/// (else the closed end), from the simulator's force-against-position curve; `None`
/// when the fingers never touch it.
///
/// # Errors
/// The simulator fails.
pub fn measure_stiffness(
    handle: &SoftGraspHandle,
    top_n: f64,
) -> Result<Option<(u8, f64)>, SimError> {
    let Some(touch) = handle.contact_count(0.02)? else {
        return Ok(None);
    };
    let counts: Vec<u8> = (touch..=255).collect();
    let curve = handle.grip_force_curve(&counts)?;
    let end = curve
        .iter()
        .find(|(_, f)| *f > top_n)
        .map_or(255, |(p, _)| *p);
    Ok(Some((touch, handle.max_stiffness_n_per_mm(touch, end)?)))
}

/// The simulator's judge: where the physics left the object after the hold.
#[derive(Debug, Clone)]
pub struct SimJudge(pub SoftGraspHandle);

impl Judge for SimJudge {
    async fn judge(&mut self, seen: &Observation) -> Result<Verdict, GraspError> {
        let state = match self.0.hold_state().map_err(sim_err)? {
            HoldState::Held => ObjectState::Held,
            HoldState::Crushed { .. } => ObjectState::Crushed,
            HoldState::Absent => ObjectState::Absent,
            HoldState::Slipped { .. } => ObjectState::Slipped,
            HoldState::Resting => ObjectState::Resting,
        };
        // Touched means gripped, by both fingers at once: the frames the loop saw show
        // one finger, and an object that moves may rest against either one alone.
        let seen = Observation {
            peak_true_n: Some(self.0.peak_grip_n().map_err(sim_err)?),
            ..*seen
        };
        Ok(physics_verdict(state, &seen))
    }
}

/// The simulator's lift: [`SoftGraspHandle::start_lift`] at the clock's present.
#[derive(Debug, Clone)]
pub struct SimLift {
    /// The grasp.
    pub handle: SoftGraspHandle,
    /// The clock the devices run on.
    pub clock: Arc<dyn Clock>,
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
            .map_err(|e| GraspError::Config(format!("simulated lift: {e}")))
    }
}

/// The simulated soft grasp's wrist: it turns the gripper at up to
/// [`softtouch_sim::WRIST_MAX_RAD_S`].
#[derive(Debug, Clone)]
pub struct SimWrist(pub SoftGraspHandle);

fn wrist_fault(e: &SimError) -> GraspError {
    GraspError::Device(DeviceError::Fault {
        device: "sim-wrist".into(),
        code: None,
        message: e.to_string(),
    })
}

impl Wrist for SimWrist {
    fn set_yaw_target(&mut self, yaw_rad: f64) -> Result<(), GraspError> {
        self.0
            .set_wrist_target(yaw_rad)
            .map_err(|e| wrist_fault(&e))
    }

    fn yaw_rad(&mut self) -> Result<f64, GraspError> {
        self.0.wrist_yaw_now().map_err(|e| wrist_fault(&e))
    }
}
