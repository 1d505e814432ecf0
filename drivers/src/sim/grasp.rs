//! The simulated Hand-E with soft, sensorised fingers: an object between the fingers
//! presses on each finger through the same contact model, lattice and renderer as the
//! rod presses, and the in-finger camera shows that contact.
//!
//! The grasp is read as a rod press: the object's cross-section is the "rod", the
//! finger meets it on its `θ = 0` side (the sensor's +x faces the object), at height
//! `contact_z_m` (the contact pose's z), and each finger penetrates by half of
//! `width − opening`, which maps to the contact pose's x through the contact law's
//! penetration (`x = (p − p₀) / p′`). The fingers are symmetric, so one finger's
//! contact stands for both. The Hand-E's motor is far stronger than the few newtons
//! of the soft fingers: the fingers reach the requested opening unless the contact
//! force exceeds the grip-force cap (rFR), where they stop and report a contact
//! (gOBJ = 2), as the real gripper does.
//!
//! Nothing here hands the truth to the loop: [`SoftGraspHandle`] reads it for the
//! record, and [`SoftGraspHandle::grip_force_curve`] measures the contact stiffness
//! Λ = ∂F/∂P from the same physics.

use super::contact::ContactParams;
use super::gripper::{SPEED_MM_S, grip_force_n};
use super::{SceneSim, SimError};
use crate::camera::{Camera, Frame};
use crate::clock::{Clock, TokioClock};
use crate::error::DeviceError;
use crate::gripper::{
    Gripper, GripperCommand, GripperStatus, ObjectStatus, STROKE_MM, opening_mm,
    position_for_opening,
};
use async_trait::async_trait;
use softtouch_schemas::scene::ObjectSpec;
use softtouch_schemas::{
    ContactPose, FrameFormat, FrameMeta, RodShape, RodSpec, SceneSpec, TimestampNs, Wrench,
};
use std::sync::{Arc, Mutex, MutexGuard};

const GRIPPER: &str = "sim-soft-gripper";
const CAMERA: &str = "sim-soft-camera";

/// An object to grasp.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspObject {
    /// Name (the "rod" the contact model meets).
    pub name: String,
    /// Cross-section of the face that meets the finger.
    pub shape: RodShape,
    /// Extent of that face along the finger, m (diameter for a cylinder).
    pub size_m: f64,
    /// Depth over extent of the face (ovals; 1 otherwise).
    pub aspect: f64,
    /// Width across the fingers at the contact height, m.
    pub width_m: f64,
    /// Where along the finger the object sits (contact pose z, m, in [−0.05, 0.05]).
    pub contact_z_m: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Friction coefficient against the finger.
    pub friction: f64,
    /// Contact force that crushes it, N (`None`: rigid).
    pub crush_force_n: Option<f64>,
}

impl GraspObject {
    /// A rigid cylinder standing between the fingers, its axis across the finger.
    #[must_use]
    pub fn cylinder(name: &str, diameter_m: f64) -> Self {
        Self {
            name: name.to_owned(),
            shape: RodShape::Circle,
            size_m: diameter_m,
            aspect: 1.0,
            width_m: diameter_m,
            contact_z_m: 0.0,
            mass_kg: 0.05,
            friction: 0.5,
            crush_force_n: None,
        }
    }

    /// The object a scene declares (`[[objects]]`).
    #[must_use]
    pub fn from_spec(spec: &ObjectSpec) -> Self {
        Self {
            name: spec.name.clone(),
            shape: spec.shape,
            size_m: spec.size_m,
            aspect: spec.aspect,
            width_m: spec.width_m,
            contact_z_m: spec.contact_z_m,
            mass_kg: spec.mass_kg,
            friction: spec.friction,
            crush_force_n: spec.crush_force_n,
        }
    }

    fn validate(&self) -> Result<(), SimError> {
        let positive = [
            ("size_m", self.size_m),
            ("aspect", self.aspect),
            ("width_m", self.width_m),
            ("mass_kg", self.mass_kg),
            ("friction", self.friction),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimError::InvalidParameter(format!(
                    "object `{}`: {field} = {v}: expected a finite value above 0",
                    self.name
                )));
            }
        }
        if self.width_m * 1000.0 >= STROKE_MM {
            return Err(SimError::InvalidParameter(format!(
                "object `{}`: width_m = {}: expected less than the stroke, {} m",
                self.name,
                self.width_m,
                STROKE_MM / 1000.0
            )));
        }
        if !(self.contact_z_m.is_finite() && self.contact_z_m.abs() <= 0.05) {
            return Err(SimError::InvalidParameter(format!(
                "object `{}`: contact_z_m = {}: expected a value in [−0.05, 0.05] m",
                self.name, self.contact_z_m
            )));
        }
        if let Some(c) = self.crush_force_n
            && !(c.is_finite() && c > 0.0)
        {
            return Err(SimError::InvalidParameter(format!(
                "object `{}`: crush_force_n = {c}: expected a finite value above 0",
                self.name
            )));
        }
        Ok(())
    }

    fn rod(&self) -> RodSpec {
        RodSpec {
            name: self.name.clone(),
            shape: self.shape,
            size_m: self.size_m,
            aspect: if self.shape == RodShape::Oval {
                self.aspect
            } else {
                1.0
            },
        }
    }
}

/// The shared state of the soft grasp.
#[derive(Debug)]
struct State {
    sim: SceneSim,
    contact: ContactParams,
    /// The object's template (its rod lives in `sim`'s scene).
    template: GraspObject,
    /// The object between the fingers, if still there.
    object: Option<GraspObject>,
    crushed: bool,
    activated: bool,
    cmd: GripperCommand,
    opening_mm: f64,
    last_t: TimestampNs,
    status: ObjectStatus,
}

impl State {
    /// The contact pose of one finger at an opening (far away without an object).
    fn pose(&self, opening_mm: f64) -> ContactPose {
        let o = &self.template;
        let x_m = match &self.object {
            Some(obj) => {
                let penetration_m = (obj.width_m - opening_mm / 1000.0) / 2.0;
                (penetration_m - self.contact.penetration_at_zero_m)
                    / self.contact.penetration_per_m
            }
            // Well clear of any contact (the rig's home pose x = −3 cm is free).
            None => -0.05,
        };
        ContactPose {
            x_m,
            z_m: o.contact_z_m,
            theta_rad: 0.0,
        }
    }

    /// The true wrench on one finger (sensor frame) at an opening.
    fn wrench_at_opening(&self, opening_mm: f64) -> Result<Wrench, SimError> {
        self.sim.wrench(&self.template.name, &self.pose(opening_mm))
    }

    /// Moves the fingers to `now` at the commanded speed; stops on a contact whose
    /// force exceeds the grip-force cap, and crushes a fragile object.
    fn advance(&mut self, now: TimestampNs) -> Result<(), SimError> {
        let dt_s = now.0.saturating_sub(self.last_t.0) as f64 * 1e-9;
        self.last_t = self.last_t.max(now);
        if !self.activated {
            return Ok(());
        }
        let target = opening_mm(self.cmd.position);
        let speed =
            SPEED_MM_S[0] + (SPEED_MM_S[1] - SPEED_MM_S[0]) * f64::from(self.cmd.speed) / 255.0;
        let step = speed * dt_s;
        let closing = target < self.opening_mm;
        let next = if closing {
            (self.opening_mm - step).max(target)
        } else {
            (self.opening_mm + step).min(target)
        };
        let cap_n = grip_force_n(self.cmd.force);
        let squeeze_n = -self.wrench_at_opening(next)?.force_n[0];
        if closing && squeeze_n > cap_n {
            // Find where the cap is reached (force grows with closing) and stop there.
            let (mut lo, mut hi) = (next, self.opening_mm);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if -self.wrench_at_opening(mid)?.force_n[0] > cap_n {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            self.opening_mm = hi;
            self.status = ObjectStatus::ContactClosing;
        } else {
            self.opening_mm = next;
            self.status = if (self.opening_mm - target).abs() < 1e-9 {
                ObjectStatus::AtPosition
            } else {
                ObjectStatus::Moving
            };
        }
        let force_n = -self.wrench_at_opening(self.opening_mm)?.force_n[0];
        if let Some(obj) = &self.object
            && obj.crush_force_n.is_some_and(|c| force_n > c)
        {
            // Crushed: it gives way and no longer pushes back.
            self.object = None;
            self.crushed = true;
        }
        Ok(())
    }
}

fn lock_state(state: &Mutex<State>) -> Result<MutexGuard<'_, State>, DeviceError> {
    state.lock().map_err(|_| DeviceError::Fault {
        device: "sim".into(),
        code: None,
        message: "simulation state poisoned by an earlier panic".into(),
    })
}

fn device_fault(device: &str, e: &SimError) -> DeviceError {
    DeviceError::Fault {
        device: device.into(),
        code: None,
        message: e.to_string(),
    }
}

/// The gripper of a soft grasp, behind the [`Gripper`] trait.
#[derive(Debug)]
pub struct SoftGripper {
    state: Arc<Mutex<State>>,
    clock: TokioClock,
}

/// The in-finger camera of a soft grasp, behind the [`Camera`] trait: raw RGB8
/// 640×480 frames on the grid `t_k = k / fps`, rendered from the grasp's contact at
/// the exposure time.
#[derive(Debug)]
pub struct SoftFingerCamera {
    state: Arc<Mutex<State>>,
    clock: TokioClock,
    period_ns: f64,
}

/// Truth and scene changes for a soft grasp (never used by the loop itself).
#[derive(Debug, Clone)]
pub struct SoftGraspHandle {
    state: Arc<Mutex<State>>,
}

/// A soft grasp: its gripper, its camera and a handle on it.
pub type SoftGrasp = (SoftGripper, SoftFingerCamera, SoftGraspHandle);

/// Builds a soft grasp of `object` in `scene` (its medium and effects; its rods are
/// replaced by the object), the camera at `fps`, seeded by `seed`, on `clock`. The
/// object starts between the open fingers.
pub fn soft_grasp(
    scene: &SceneSpec,
    object: GraspObject,
    fps: f64,
    seed: u64,
    clock: TokioClock,
) -> Result<SoftGrasp, SimError> {
    object.validate()?;
    if !(fps.is_finite() && (1.0..=1000.0).contains(&fps)) {
        return Err(SimError::InvalidParameter(format!(
            "fps = {fps}: expected a value in [1, 1000]"
        )));
    }
    let mut spec = scene.clone();
    spec.rods = vec![object.rod()];
    let sim = SceneSim::new(&spec, seed)?;
    let state = Arc::new(Mutex::new(State {
        sim,
        contact: ContactParams::default(),
        object: Some(object.clone()),
        template: object,
        crushed: false,
        activated: false,
        cmd: GripperCommand {
            position: 0,
            speed: 0,
            force: 0,
        },
        opening_mm: STROKE_MM,
        last_t: TimestampNs::ZERO,
        status: ObjectStatus::AtPosition,
    }));
    Ok((
        SoftGripper {
            state: Arc::clone(&state),
            clock,
        },
        SoftFingerCamera {
            state: Arc::clone(&state),
            clock,
            period_ns: 1e9 / fps,
        },
        SoftGraspHandle { state },
    ))
}

impl SoftGraspHandle {
    fn lock(&self) -> Result<MutexGuard<'_, State>, SimError> {
        self.state
            .lock()
            .map_err(|_| SimError::Solver("simulation state poisoned by an earlier panic".into()))
    }

    /// The true wrench on one finger (sensor frame, no sensor effects) at time `t`.
    pub fn true_wrench(&self, t: TimestampNs) -> Result<Wrench, SimError> {
        let mut s = self.lock()?;
        s.advance(t)?;
        s.wrench_at_opening(s.opening_mm)
    }

    /// Takes the object away (it slipped out or was pulled), or puts it back.
    pub fn set_object(&self, present: bool) -> Result<(), SimError> {
        let mut s = self.lock()?;
        s.object = present.then(|| s.template.clone());
        Ok(())
    }

    /// Whether the object is between the fingers.
    pub fn has_object(&self) -> Result<bool, SimError> {
        Ok(self.lock()?.object.is_some())
    }

    /// Whether the grip crushed the object.
    pub fn crushed(&self) -> Result<bool, SimError> {
        Ok(self.lock()?.crushed)
    }

    /// The opening between the fingers now, mm.
    pub fn opening_mm(&self) -> Result<f64, SimError> {
        Ok(self.lock()?.opening_mm)
    }

    /// The squeeze on one finger (−F_x in its sensor frame, N) at each gripper count
    /// in `counts`, from the contact physics with the object in place: the curve the
    /// stiffness Λ = ∂F/∂P is measured on.
    pub fn grip_force_curve(&self, counts: &[u8]) -> Result<Vec<(u8, f64)>, SimError> {
        let mut s = self.lock()?;
        let present = s.object.is_some();
        s.object = Some(s.template.clone());
        let out = counts
            .iter()
            .map(|&p| Ok((p, -s.wrench_at_opening(opening_mm(p))?.force_n[0])))
            .collect::<Result<Vec<_>, SimError>>();
        if !present {
            s.object = None;
        }
        out
    }

    /// The largest stiffness Λ = ∂F/∂P over consecutive counts in `from..=to`, N per
    /// mm of closing, from [`Self::grip_force_curve`].
    pub fn max_stiffness_n_per_mm(&self, from: u8, to: u8) -> Result<f64, SimError> {
        let counts: Vec<u8> = (from.min(to)..=from.max(to)).collect();
        let curve = self.grip_force_curve(&counts)?;
        let mm_per_count = STROKE_MM / 255.0;
        Ok(curve
            .windows(2)
            .map(|w| (w[1].1 - w[0].1) / mm_per_count)
            .fold(0.0, f64::max))
    }

    /// The count at which the fingers first touch the object (force above `threshold_n`).
    pub fn contact_count(&self, threshold_n: f64) -> Result<Option<u8>, SimError> {
        let counts: Vec<u8> = (0..=255).collect();
        Ok(self
            .grip_force_curve(&counts)?
            .into_iter()
            .find(|(_, f)| *f > threshold_n)
            .map(|(p, _)| p))
    }
}

#[async_trait]
impl Gripper for SoftGripper {
    async fn activate(&mut self) -> Result<(), DeviceError> {
        let activated = lock_state(&self.state)?.activated;
        if !activated {
            tokio::time::sleep(super::gripper::ACTIVATION).await;
            let now = self.clock.now();
            let mut s = lock_state(&self.state)?;
            s.last_t = now;
            s.activated = true;
        }
        Ok(())
    }

    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        let now = self.clock.now();
        let mut s = lock_state(&self.state)?;
        if !s.activated {
            return Err(DeviceError::InvalidCommand {
                device: GRIPPER.into(),
                message: "not activated".into(),
            });
        }
        s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
        s.cmd = cmd;
        Ok(())
    }

    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        let now = self.clock.now();
        let mut s = lock_state(&self.state)?;
        s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
        let current_ma = match s.status {
            ObjectStatus::ContactClosing | ObjectStatus::ContactOpening => {
                (100.0 + 500.0 * f64::from(s.cmd.force) / 255.0) as u32
            }
            ObjectStatus::Moving => 150,
            ObjectStatus::AtPosition => 0,
        };
        Ok(GripperStatus {
            t: now,
            activated: s.activated,
            object: s.status,
            fault: 0,
            requested_position: s.cmd.position,
            position: position_for_opening(s.opening_mm),
            current_ma,
        })
    }
}

#[async_trait]
impl Camera for SoftFingerCamera {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        let k = (t.0 as f64 / self.period_ns).ceil() as u64;
        let exposed = TimestampNs((k as f64 * self.period_ns).round() as u64);
        if exposed.0.saturating_sub(t.0) > timeout_ms.saturating_mul(1_000_000) {
            tokio::time::sleep_until(self.clock.instant_at(TimestampNs(
                t.0.saturating_add(timeout_ms.saturating_mul(1_000_000)),
            )))
            .await;
            return Err(DeviceError::Timeout {
                device: CAMERA.into(),
                timeout_ms,
            });
        }
        tokio::time::sleep_until(self.clock.instant_at(exposed)).await;
        let mut s = lock_state(&self.state)?;
        s.advance(exposed).map_err(|e| device_fault(CAMERA, &e))?;
        let pose = s.pose(s.opening_mm);
        let rendered = s
            .sim
            .render(&s.template.name, &pose, k, exposed.0 as f64 * 1e-9)
            .map_err(|e| device_fault(CAMERA, &e))?;
        Ok(Frame {
            meta: FrameMeta {
                t: exposed,
                sequence: k,
                width: rendered.image.width(),
                height: rendered.image.height(),
                format: FrameFormat::Rgb8,
            },
            data: rendered.image.into_raw(),
        })
    }

    fn dropped_frames(&self) -> u64 {
        0
    }
}
