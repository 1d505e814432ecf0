//! The simulated Hand-E with two soft, sensorised fingers: an object between the
//! fingers presses on each finger through the same contact law, lattice and renderer
//! as the rod presses, and each finger's camera shows its own contact.
//!
//! # Geometry
//!
//! Gripper frame G: the fingers close along x (finger 0 on the −x side, finger 1
//! mirrored on the +x side, each finger's sensor +x facing the object), y across the
//! fingers' faces, z along the fingers to their tips (down, for a grasp from above).
//! The object's width across the fingers along the finger comes from its profile
//! ([`GraspObject`]: a lying rod's face, a prism, a sphere's chord, a taper), its
//! section turns with its yaw (an oval tube turned about its axis gets wider or
//! narrower and its contact moves across the finger, which changes the contact's θ
//! and so the image), and the opening is the distance between the fingers' fronts at
//! the grasp height ([`touch`]). The Hand-E's motor is far stronger than the few
//! newtons of the soft fingers: the fingers reach the requested opening unless the
//! squeeze exceeds the grip-force cap (rFR), where they stop and report a contact
//! (gOBJ = 2), as the real gripper does.
//!
//! # Physics of the hold (per step of at most 2 ms on the injected clock)
//!
//! - A current (`object_flow`, only when the scene lists it) pushes the object along
//!   x with ½·ρ·C_d·A·u·|u| on the outline it meets (its side, `flow_area_m2`); u is
//!   the mean plus gusts (three seeded sines, or the scene's declared spectrum).
//!   Held, it shifts until the two fingers' squeezes balance the push, so one finger
//!   is squeezed harder than the other.
//! - On its support (`object_support`, only when the scene lists it) the object
//!   stays where it was put until the forces along x exceed what the support's
//!   friction holds, `μ·(m·g − ρ·g·V)`; beyond, it slides (implicit Euler of
//!   `m_eff·dv/dt` with the fingers' squeezes, the current's drag at the relative
//!   speed and the sliding friction). So the first finger to touch pushes it until
//!   the other meets it, a current drifts what the support cannot hold, and a
//!   neutrally buoyant object sways with the gusts. Absent, the support is
//!   frictionless and the object is still until both fingers grip it (and then
//!   centred). Lifted, the support lets go.
//! - Added mass (`object_added_mass`): `m_eff = m + C_a·ρ·V`, with `C_a` of the
//!   object's equivalent spheroid ([`spheroid_added_mass`]), across it on the
//!   support and along it on the lift.
//! - Wet contact (`wet_contact`, only when the scene lists it): the object grips the
//!   silicone with its `wet_friction` in place of its dry `friction`, in the hold and
//!   the twist alike.
//! - A squeeze on either finger above the crush limit crushes the object: it gives way
//!   and pushes back no more ([`HoldState::Crushed`]).
//! - Before [`SoftGraspHandle::start_lift`] the object rests on its support, which
//!   carries its weight. From then on the fingers must carry, in friction, the load
//!   `m·(g + a) + m_a·a − ρ·g·V + ½·ρ·C_d·A·v·|v|` (added mass, buoyancy and drag only
//!   when the scene lists `object_added_mass` / `object_buoyancy` / `object_drag`) against `μ·(N₀ + N₁)`, the friction of the
//!   true normal forces on both fingers. A load beyond it is a slip: the object falls
//!   ([`HoldState::Slipped`]) and the cameras show no contact. The load the fingers
//!   carry shows on each as a shear along z.
//! - A turn of the object against the fingers (its yaw, scheduled by
//!   [`SoftGraspHandle::schedule_object_yaw`], less the wrist's) drags each contact
//!   across the finger: an elastic stick (tangential stiffness growing with the
//!   normal force as N^⅓, Mindlin) up to the friction left beside the load, sliding
//!   beyond. That shear along y is what makes the torque about z.
//!
//! Nothing here hands the truth to the loop: [`SoftGraspHandle`] reads it for the
//! record, and [`SoftGraspHandle::grip_force_curve`] measures the contact stiffness
//! Λ = ∂F/∂P from the same physics.

mod cap;
mod object;
#[cfg(test)]
mod tests;
mod touch;

pub use cap::{GripCap, GripWindow, grip_window};

pub use object::{
    GraspObject, default_drag_coefficient, default_drag_coefficients, spheroid_added_mass,
};

use super::SimError;
use super::contact::{Contact, ContactParams, FingerGeometry};
use super::effects::{Effects, Flow};
use super::gripper::{G_M_S2, SPEED_MM_S, grip_force_n};
use super::lattice::Deformed;
use super::render::FrameBuffers;
use super::world::{Look, Model, Scene};
use async_trait::async_trait;
use rand::RngExt;
use softtouch_drivers::camera::{Camera, Frame};
use softtouch_drivers::clock::{Clock, TokioClock};
use softtouch_drivers::error::DeviceError;
use softtouch_drivers::gripper::{
    Gripper, GripperCommand, GripperStatus, ObjectStatus, STROKE_MM, opening_mm,
    position_for_opening,
};
use softtouch_schemas::{FrameFormat, FrameMeta, SceneSpec, TimestampNs, Wrench};
use std::cell::RefCell;
use std::sync::{Arc, Mutex, MutexGuard};
use touch::{FingerContact, Grip, SqueezeAlongShift, Strips, contact_on, finger_contact};

mod arm;
mod devices;
mod handle;
pub use arm::SoftGraspArm;
mod lift;
use lift::*;
mod state;
use state::*;

const GRIPPER: &str = "sim-soft-gripper";
const CAMERA: &str = "sim-soft-camera";
/// Longest physics step, ns.
const STEP_NS: u64 = 2_000_000;
/// Tangential stiffness of a finger's contact at 1 N of normal force, N/m.
const SHEAR_STIFFNESS_N_PER_M: f64 = 600.0;
/// Half width of the first bracket of the object's balance around the last step's
/// shift, m (widened eightfold until it holds the balance).
const WARM_BRACKET_M: f64 = 1e-5;
/// Fastest the simulated wrist turns, rad/s (a Panda's last joint: 2.61 rad/s).
pub const WRIST_MAX_RAD_S: f64 = 2.5;

/// What the physics says happened to the object so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HoldState {
    /// Not lifted yet (resting on its support).
    Resting,
    /// Lifted and held.
    Held,
    /// Friction could not carry the load; it fell at `t`.
    Slipped {
        /// When it slipped.
        t: TimestampNs,
    },
    /// The squeeze exceeded its crush limit at `t`.
    Crushed {
        /// When it gave way.
        t: TimestampNs,
    },
    /// No object between the fingers (never placed, missed, or removed).
    Absent,
}

/// The gripper of a soft grasp, behind the [`Gripper`] trait.
#[derive(Debug)]
pub struct SoftGripper {
    state: Arc<Mutex<State>>,
    clock: TokioClock,
}

/// One finger's camera of a soft grasp, behind the [`Camera`] trait: raw RGB8 640×480
/// frames on the grid `t_k = k / fps`, rendered from that finger's contact at the
/// exposure time.
#[derive(Debug)]
pub struct SoftFingerCamera {
    state: Arc<Mutex<State>>,
    clock: TokioClock,
    period_ns: f64,
    finger: usize,
}

impl SoftFingerCamera {
    /// What the finger looks like at `exposed`: the sim advanced to it, the finger's
    /// contact and its lattice (solved once per contact).
    fn look_at(&self, s: &mut State, exposed: TimestampNs) -> Result<Look, DeviceError> {
        s.advance(exposed).map_err(|e| device_fault(CAMERA, &e))?;
        let contact = s
            .finger_at(self.finger, s.opening_mm)
            .map_err(|e| device_fault(CAMERA, &e))?;
        Ok(match contact {
            Some(c) => {
                let cached = s.last_deformed[self.finger]
                    .as_ref()
                    .filter(|(solved_for, _)| *solved_for == c.contact)
                    .map(|(_, d)| d.clone());
                let deformed = match cached {
                    Some(d) => d,
                    None => {
                        let finger = s.finger;
                        let d = s
                            .scene(self.finger)
                            .model
                            .lattice
                            .deform(&finger, &c.contact)
                            .map_err(|e| device_fault(CAMERA, &e))?;
                        s.last_deformed[self.finger] = Some((c.contact.clone(), d.clone()));
                        d
                    }
                };
                Look {
                    wrench: c.contact.wrench,
                    deformed,
                }
            }
            None => Look {
                wrench: Wrench::ZERO,
                deformed: Deformed {
                    nodes: s.scene(self.finger).model.lattice.rest.clone(),
                },
            },
        })
    }
}

/// Truth and scene changes for a soft grasp (never used by the loop itself).
#[derive(Debug, Clone)]
pub struct SoftGraspHandle {
    state: Arc<Mutex<State>>,
}

/// A soft grasp: its gripper, finger 0's camera and a handle on it (finger 1's camera
/// from [`SoftGraspHandle::second_camera`]).
pub type SoftGrasp = (SoftGripper, SoftFingerCamera, SoftGraspHandle);

/// Where `obj` rests when put down, as a shift towards finger 0, m: where its offset
/// puts it on a support with friction; in the middle on a frictionless one (the
/// first finger slides it there).
fn rest_shift_m(effects: &Effects, obj: &GraspObject) -> f64 {
    if effects.support_friction.is_some() {
        -obj.offset_m[0]
    } else {
        0.0
    }
}

/// Checks every object a scene declares as [`soft_grasp`] would on its own: each
/// valid, and none lighter than the fluid where the scene declares `object_buoyancy`
/// (what `config check` reports before any run).
///
/// # Errors
/// The first object refused, by name.
pub fn check_scene_objects(scene: &SceneSpec) -> Result<(), SimError> {
    let rho = scene.effects.iter().find_map(|e| match e {
        softtouch_schemas::Effect::ObjectBuoyancy {
            fluid_density_kg_m3,
        } => Some(*fluid_density_kg_m3),
        _ => None,
    });
    for spec in &scene.objects {
        let object = GraspObject::from_spec(spec);
        object.validate()?;
        object.sinks_in(rho)?;
    }
    Ok(())
}

/// The friction `object` grips with in the scene whose effects are `effects`: its wet
/// one where the scene declares wet contact (and only then), else its dry one.
///
/// # Errors
/// Wet contact on an object that declares no wet friction.
pub(super) fn grip_friction(effects: &Effects, object: &GraspObject) -> Result<f64, SimError> {
    if effects.wet_contact {
        object.wet_friction.ok_or_else(|| {
            SimError::InvalidParameter(format!(
                "object `{}`: the scene declares wet_contact but the object has no wet_friction",
                object.name
            ))
        })
    } else {
        Ok(object.friction)
    }
}

/// Builds a soft grasp of `object` in `scene` (its medium and effects), the cameras at
/// `fps`, seeded by `seed`, on `clock`. The object starts between the open fingers,
/// resting on its support.
pub fn soft_grasp(
    scene: &SceneSpec,
    object: GraspObject,
    fps: f64,
    seed: u64,
    clock: TokioClock,
) -> Result<SoftGrasp, SimError> {
    // The scene as a file is checked (a scene built in code, or with values set from
    // the command line, too): a gust period of 0 divides, a NaN current has no physics.
    let mut check = softtouch_schemas::config::Check::default();
    softtouch_schemas::config::Validate::validate(scene, &mut check);
    if let Some(p) = check.problems().first() {
        return Err(SimError::InvalidParameter(format!(
            "scene `{}`: field `{}`: {}",
            scene.name, p.field, p.message
        )));
    }
    object.validate()?;
    if !(fps.is_finite() && (1.0..=1000.0).contains(&fps)) {
        return Err(SimError::InvalidParameter(format!(
            "fps = {fps}: expected a value in [1, 1000]"
        )));
    }
    let model = Model::shared_default()?;
    let mut spec = scene.clone();
    spec.rods = vec![object.face_rod()];
    // Finger 1's camera draws its own seeded streams.
    let first = Scene::new(&spec, seed, Arc::clone(&model));
    let effects = first.effects.clone();
    object.sinks_in(effects.object_buoyancy_kg_m3)?;
    let mut object = object;
    object.friction = grip_friction(&effects, &object)?;
    let second_spec = (spec, seed ^ 0x5eed_f1a6_e201_0001);
    let flow = effects
        .object_flow
        .clone()
        .map(|f| FlowSeries::new(f, seed));
    let period_ns = 1e9 / fps;
    let shift_m = rest_shift_m(&effects, &object);
    let state = Arc::new(Mutex::new(State {
        finger: model.params.finger,
        contact: model.params.contact,
        scenes: [Some(first), None],
        second_spec,
        model: Arc::clone(&model),
        effects,
        clock,
        period_ns,
        object: Some(object.clone()),
        template: object,
        hold: HoldState::Resting,
        activated: false,
        cmd: GripperCommand {
            position: 0,
            speed: 0,
            force: 0,
        },
        opening_mm: STROKE_MM,
        last_t: TimestampNs::ZERO,
        status: ObjectStatus::AtPosition,
        lift: None,
        yaw_moves: Vec::new(),
        flow,
        wrist_rad: 0.0,
        wrist_target_rad: 0.0,
        shift_m,
        slide_m_s: 0.0,
        peak_grip_n: 0.0,
        rel_yaw_rad: 0.0,
        stick_m: [0.0; 2],
        shear_n: [[0.0; 2]; 2],
        last_contact: RefCell::default(),
        strips: RefCell::default(),
        last_deformed: [None, None],
    }));
    Ok((
        SoftGripper {
            state: Arc::clone(&state),
            clock,
        },
        SoftFingerCamera {
            state: Arc::clone(&state),
            clock,
            period_ns,
            finger: 0,
        },
        SoftGraspHandle { state },
    ))
}
