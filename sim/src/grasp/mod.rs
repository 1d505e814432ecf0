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
//!   x; it shifts until the two fingers' squeezes balance the push, so one finger is
//!   squeezed harder than the other.
//! - A squeeze on either finger above the crush limit crushes the object: it gives way
//!   and pushes back no more ([`HoldState::Crushed`]).
//! - Before [`SoftGraspHandle::start_lift`] the object rests on its support, which
//!   carries its weight. From then on the fingers must carry, in friction, the load
//!   `m·(g + a) − ρ·g·V + ½·ρ·C_d·A·v·|v|` (buoyancy and drag only when the scene lists
//!   `object_buoyancy` / `object_drag`) against `μ·(N₀ + N₁)`, the friction of the
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

mod object;
#[cfg(test)]
mod tests;
mod touch;

pub use object::GraspObject;

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

/// A trapezoidal lift of the gripper.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Lift {
    t0: TimestampNs,
    height_m: f64,
    speed_m_s: f64,
    accel_m_s2: f64,
}

impl Lift {
    /// Velocity (up) and acceleration (up) `tau_s` after the start.
    fn motion(&self, tau_s: f64) -> (f64, f64) {
        if tau_s < 0.0 {
            return (0.0, 0.0);
        }
        let a = self.accel_m_s2;
        // Triangle when the height is too short to reach the speed.
        let v_peak = self.speed_m_s.min((a * self.height_m).sqrt());
        let t_acc = v_peak / a;
        let cruise_m = self.height_m - v_peak * t_acc;
        let t_cruise = (cruise_m / v_peak).max(0.0);
        if tau_s < t_acc {
            (a * tau_s, a)
        } else if tau_s < t_acc + t_cruise {
            (v_peak, 0.0)
        } else if tau_s < 2.0 * t_acc + t_cruise {
            (v_peak - a * (tau_s - t_acc - t_cruise), -a)
        } else {
            (0.0, 0.0)
        }
    }
}

/// A scheduled turn of the object about z.
#[derive(Debug, Clone, Copy, PartialEq)]
struct YawMove {
    t0: TimestampNs,
    t1: TimestampNs,
    to_rad: f64,
}

/// The current's speed over time: mean plus three seeded sines.
#[derive(Debug, Clone, PartialEq)]
struct FlowSeries {
    flow: Flow,
    /// (angular frequency rad/s, phase rad, weight).
    waves: [(f64, f64, f64); 3],
}

impl FlowSeries {
    fn new(flow: Flow, seed: u64) -> Self {
        let mut rng = super::rng::stream(seed, "object-flow");
        let mut waves = [(0.0, 0.0, 0.0); 3];
        for w in &mut waves {
            let period = flow.period_s * rng.random_range(0.5..2.0);
            *w = (
                std::f64::consts::TAU / period,
                rng.random_range(0.0..std::f64::consts::TAU),
                rng.random_range(0.5..1.0),
            );
        }
        let total: f64 = waves.iter().map(|w| w.2).sum();
        for w in &mut waves {
            w.2 /= total;
        }
        Self { flow, waves }
    }

    /// Speed along G's +x at `t_s`, m/s.
    fn speed_m_s(&self, t_s: f64) -> f64 {
        let gust: f64 = self
            .waves
            .iter()
            .map(|(omega, phase, weight)| weight * (omega * t_s + phase).sin())
            .sum();
        self.flow.mean_m_s + self.flow.gust_m_s * gust
    }
}

/// A finger's contact and the grip and shear it was worked out for.
#[derive(Debug, Clone)]
struct ContactMemo {
    grip: Grip,
    shear_n: [f64; 2],
    /// Shared, not copied: the balance asks for it tens of times a frame.
    contact: Arc<FingerContact>,
}

/// The shared state of the soft grasp.
#[derive(Debug)]
struct State {
    /// One scene per finger: the same model, each its own seeded renderer. Finger
    /// 1's is made when its camera is first asked for (its renderer's tables cost
    /// tens of milliseconds, and most grasps watch one finger).
    scenes: [Option<Scene>; 2],
    /// The scene finger 1's is made from, and its seed.
    second_spec: (SceneSpec, u64),
    model: Arc<Model>,
    effects: Effects,
    finger: FingerGeometry,
    contact: ContactParams,
    clock: TokioClock,
    period_ns: f64,
    /// The object's template.
    template: GraspObject,
    /// The object between the fingers, if still there.
    object: Option<GraspObject>,
    hold: HoldState,
    activated: bool,
    cmd: GripperCommand,
    opening_mm: f64,
    last_t: TimestampNs,
    status: ObjectStatus,
    lift: Option<Lift>,
    yaw_moves: Vec<YawMove>,
    flow: Option<FlowSeries>,
    /// The wrist's turn about z and where it is going, rad.
    wrist_rad: f64,
    wrist_target_rad: f64,
    /// The object's shift towards finger 0, m.
    shift_m: f64,
    /// The object's turn against the fingers at the last step, rad.
    rel_yaw_rad: f64,
    /// Each finger's stuck tangential displacement along its y, m.
    stick_m: [f64; 2],
    /// Each finger's shear (y, z in its frame), N.
    shear_n: [[f64; 2]; 2],
    /// Each finger's last contact and the grip and shear it was worked out for: the
    /// physics steps, the status and the camera ask for the same one many times while
    /// nothing moves (a steady hold).
    last_contact: RefCell<[Option<ContactMemo>; 2]>,
    /// Each finger's strips against the object at its last turn: the same for every
    /// contact until the object turns.
    strips: RefCell<[Option<Arc<Strips>>; 2]>,
    /// Each camera's last solved lattice and the contact it was solved for.
    last_deformed: [Option<(Contact, Deformed)>; 2],
}

impl State {
    /// Finger `k`'s scene (0 or 1), made on first use.
    fn scene(&mut self, k: usize) -> &Scene {
        let (spec, seed) = &self.second_spec;
        let model = &self.model;
        self.scenes[k.min(1)].get_or_insert_with(|| Scene::new(spec, *seed, Arc::clone(model)))
    }

    fn object_yaw_at(&self, t: TimestampNs) -> f64 {
        let mut yaw = 0.0;
        for m in &self.yaw_moves {
            if t <= m.t0 {
                break;
            }
            if t >= m.t1 || m.t1 <= m.t0 {
                yaw = m.to_rad;
            } else {
                let s = (t.0 - m.t0.0) as f64 / (m.t1.0 - m.t0.0) as f64;
                // Smoothstep: the turn starts and ends at rest.
                let s = s * s * (3.0 - 2.0 * s);
                yaw += (m.to_rad - yaw) * s;
                break;
            }
        }
        yaw
    }

    fn grip(&self, opening_mm: f64) -> Grip {
        Grip {
            opening_m: opening_mm / 1000.0,
            shift_m: self.shift_m,
            yaw_rad: self.rel_yaw_rad,
        }
    }

    /// Finger `k`'s contact at `opening_mm` with the present shift, turn and shear
    /// (`None`: no object).
    fn finger_at(&self, k: usize, opening_mm: f64) -> Result<Option<Arc<FingerContact>>, SimError> {
        let Some(obj) = &self.object else {
            return Ok(None);
        };
        let grip = self.grip(opening_mm);
        let shear = self.shear_n[k];
        // The same inputs bit for bit: the same contact.
        if let Some(m) = &self.last_contact.borrow()[k]
            && m.grip == grip
            && m.shear_n.map(f64::to_bits) == shear.map(f64::to_bits)
        {
            return Ok(Some(Arc::clone(&m.contact)));
        }
        let contact = Arc::new(contact_on(
            &self.strips_of(k, obj),
            &self.finger,
            &self.contact,
            obj,
            &grip,
            shear,
        )?);
        self.last_contact.borrow_mut()[k] = Some(ContactMemo {
            grip,
            shear_n: shear,
            contact: Arc::clone(&contact),
        });
        Ok(Some(contact))
    }

    /// Finger `k`'s strips against `obj` (the object) at its present turn.
    fn strips_of(&self, k: usize, obj: &GraspObject) -> Arc<Strips> {
        if let Some(s) = &self.strips.borrow()[k]
            && s.are_for(k, self.rel_yaw_rad)
        {
            return Arc::clone(s);
        }
        let s = Arc::new(Strips::new(
            &self.finger,
            &self.contact,
            obj,
            k,
            self.rel_yaw_rad,
        ));
        self.strips.borrow_mut()[k] = Some(Arc::clone(&s));
        s
    }

    /// The larger squeeze of the two fingers at an opening, N.
    fn squeeze_at(&self, opening_mm: f64) -> Result<f64, SimError> {
        let mut most = 0.0_f64;
        for k in 0..2 {
            if let Some(c) = self.finger_at(k, opening_mm)? {
                most = most.max(c.squeeze_n());
            }
        }
        Ok(most)
    }

    /// The true wrench on finger `k` (its sensor frame) now.
    fn wrench(&self, k: usize) -> Result<Wrench, SimError> {
        Ok(self
            .finger_at(k, self.opening_mm)?
            .map_or(Wrench::ZERO, |c| c.contact.wrench))
    }

    /// Advances fingers and physics to `now` in steps of at most [`STEP_NS`].
    fn advance(&mut self, now: TimestampNs) -> Result<(), SimError> {
        while self.last_t < now {
            let t = TimestampNs(now.0.min(self.last_t.0.saturating_add(STEP_NS)));
            let dt_s = (t.0 - self.last_t.0) as f64 * 1e-9;
            self.last_t = t;
            self.move_fingers(dt_s)?;
            self.physics(t, dt_s)?;
        }
        Ok(())
    }

    /// Moves the fingers for `dt_s` at the commanded speed; stops on a squeeze that
    /// exceeds the grip-force cap.
    fn move_fingers(&mut self, dt_s: f64) -> Result<(), SimError> {
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
        if closing && self.squeeze_at(next)? > cap_n {
            // Find where the cap is reached (force grows with closing) and stop there.
            let (mut lo, mut hi) = (next, self.opening_mm);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if self.squeeze_at(mid)? > cap_n {
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
        Ok(())
    }

    /// The object's shift that balances a push along G's +x, m: the squeeze on finger
    /// 0 less that on finger 1 equals −push.
    fn balance_shift(&mut self, push_n: f64) -> Result<f64, SimError> {
        let last_m = self.shift_m;
        self.shift_m = 0.0;
        let Some(obj) = &self.object else {
            return Ok(0.0);
        };
        // Only the shift changes in here: each finger's squeeze is worked out along it
        // (the same bits as its whole contact, at a fraction of the cost).
        let squeezes = [0, 1].map(|k| {
            SqueezeAlongShift::new(
                self.strips_of(k, obj),
                &self.contact,
                obj,
                &self.grip(self.opening_mm),
                self.shear_n[k],
            )
        });
        let [Ok(along_0), Ok(along_1)] = squeezes else {
            // The whole contact says what is not finite.
            self.finger_at(0, self.opening_mm)?;
            self.finger_at(1, self.opening_mm)?;
            return Ok(0.0);
        };
        // The normal force and squeeze of finger `k` at `shift`: where they are not
        // finite, the whole contact's error.
        let at = |s: &mut Self, k: usize, shift: f64| -> Result<(f64, f64), SimError> {
            let along = if k == 0 { &along_0 } else { &along_1 };
            match along.at(shift) {
                Some(v) => Ok(v),
                None => {
                    s.shift_m = shift;
                    Ok(s.finger_at(k, s.opening_mm)?
                        .map_or((0.0, 0.0), |c| (c.normal_n, c.squeeze_n())))
                }
            }
        };
        // Not gripped by both fingers: the support keeps it where it is.
        for k in 0..2 {
            if at(self, k, 0.0)?.0 <= 0.0 {
                self.shift_m = 0.0;
                return Ok(0.0);
            }
        }
        // Squeeze on finger 0 less that on finger 1 plus the push: grows with the shift.
        let imbalance = |s: &mut Self, shift: f64| -> Result<f64, SimError> {
            let a = at(s, 0, shift)?.1;
            let b = at(s, 1, shift)?.1;
            Ok(a - b + push_n)
        };
        let reach = 0.25 * self.object.as_ref().map_or(0.0, GraspObject::max_width_m);
        // Bracket the balance around the last step's shift first (a step changes the
        // push and the grip a little), widening to the whole reach: about half the
        // contacts of bracketing the whole reach every step.
        let mut half_m = if last_m.is_finite() && last_m.abs() < reach {
            WARM_BRACKET_M
        } else {
            2.0 * reach
        };
        let (mut lo, mut hi, mut f_lo, mut f_hi);
        let mut tries = 0;
        loop {
            tries += 1;
            lo = (last_m - half_m).max(-reach);
            hi = (last_m + half_m).min(reach);
            if !lo.is_finite() || !hi.is_finite() || lo >= hi {
                (lo, hi) = (-reach, reach);
            }
            (f_lo, f_hi) = (imbalance(self, lo)?, imbalance(self, hi)?);
            let whole = lo <= -reach && hi >= reach;
            // The push beats the squeeze anywhere within reach: the object sits at
            // the end.
            if lo <= -reach && f_lo >= 0.0 {
                return Ok(lo);
            }
            if hi >= reach && f_hi <= 0.0 {
                return Ok(hi);
            }
            // (A reach that is not a number never becomes whole: the tries end it.)
            if (f_lo < 0.0 && f_hi > 0.0) || whole || tries >= 16 {
                break;
            }
            half_m *= 8.0;
        }
        // Illinois false position: the imbalance grows smoothly with the shift, so a
        // few steps reach 0.1 µN (30 bisections cost 60 contacts a step).
        let mut last_side = 0;
        let mut x = 0.0;
        for _ in 0..60 {
            x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
            if !x.is_finite() {
                x = 0.5 * (lo + hi);
            }
            let f = imbalance(self, x)?;
            if f.abs() <= 1e-7 || hi - lo <= 1e-12 {
                break;
            }
            if f > 0.0 {
                (hi, f_hi) = (x, f);
                if last_side == 1 {
                    f_lo *= 0.5;
                }
                last_side = 1;
            } else {
                (lo, f_lo) = (x, f);
                if last_side == -1 {
                    f_hi *= 0.5;
                }
                last_side = -1;
            }
        }
        Ok(x)
    }

    /// One step of the hold's physics at `t`.
    fn physics(&mut self, t: TimestampNs, dt_s: f64) -> Result<(), SimError> {
        // The wrist turns towards its target at its top speed.
        let turn = (self.wrist_target_rad - self.wrist_rad)
            .clamp(-WRIST_MAX_RAD_S * dt_s, WRIST_MAX_RAD_S * dt_s);
        self.wrist_rad += turn;
        let rel_yaw = self.object_yaw_at(t) - self.wrist_rad;
        let d_yaw = rel_yaw - self.rel_yaw_rad;
        self.rel_yaw_rad = rel_yaw;
        let Some(obj) = self.object.clone() else {
            self.shear_n = [[0.0; 2]; 2];
            self.stick_m = [0.0; 2];
            self.shift_m = 0.0;
            return Ok(());
        };
        let t_s = t.0 as f64 * 1e-9;
        if let Some(series) = &self.flow {
            let u = series.speed_m_s(t_s);
            let push_n = 0.5
                * series.flow.density_kg_m3
                * obj.drag_coefficient
                * obj.drag_area_m2
                * u
                * u.abs();
            self.shift_m = self.balance_shift(push_n)?;
        }
        let mut contacts = Vec::with_capacity(2);
        for k in 0..2 {
            contacts.push(self.finger_at(k, self.opening_mm)?);
        }
        let normal = |k: usize| contacts[k].as_ref().map_or(0.0, |c| c.normal_n);
        let squeeze = |k: usize| contacts[k].as_ref().map_or(0.0, |c| c.squeeze_n());
        if let Some(limit) = obj.crush_force_n
            && squeeze(0).max(squeeze(1)) > limit
        {
            return self.lose(HoldState::Crushed { t });
        }
        let total_n = normal(0) + normal(1);
        let capacity_n = obj.friction * total_n;
        let mut load_n = [0.0; 2];
        if let Some(lift) = self.lift
            && t >= lift.t0
        {
            let (v, a) = lift.motion((t.0 - lift.t0.0) as f64 * 1e-9);
            let buoyancy_n = self
                .effects
                .object_buoyancy_kg_m3
                .map_or(0.0, |rho| rho * G_M_S2 * obj.volume_m3);
            // Drag opposes the motion: a rising object is pulled down.
            let drag_n = self.effects.object_drag_kg_m3.map_or(0.0, |rho| {
                0.5 * rho * obj.drag_coefficient * obj.drag_area_m2 * v * v.abs()
            });
            let load = obj.mass_kg * (G_M_S2 + a) - buoyancy_n + drag_n;
            if load.is_nan() || load.abs() > capacity_n {
                return self.lose(HoldState::Slipped { t });
            }
            self.hold = HoldState::Held;
            for k in 0..2 {
                load_n[k] = load * normal(k) / total_n.max(f64::MIN_POSITIVE);
            }
        }
        // The twist: an elastic stick up to the friction the load leaves, then sliding.
        for k in 0..2 {
            let n = normal(k);
            let radius = contacts[k].as_ref().map_or(0.0, |c| c.radius_m);
            if n <= 0.0 {
                self.stick_m[k] = 0.0;
                self.shear_n[k] = [0.0; 2];
                continue;
            }
            let stiffness = SHEAR_STIFFNESS_N_PER_M * n.cbrt();
            let room_n = ((obj.friction * n).powi(2) - load_n[k].powi(2))
                .max(0.0)
                .sqrt();
            let limit_m = room_n / stiffness;
            self.stick_m[k] = (self.stick_m[k] + radius * d_yaw).clamp(-limit_m, limit_m);
            // The object's surface drags each finger along its own −y for a positive turn.
            self.shear_n[k] = [-stiffness * self.stick_m[k], load_n[k]];
        }
        Ok(())
    }

    /// The object is gone (slipped or crushed): it pushes back no more.
    fn lose(&mut self, how: HoldState) -> Result<(), SimError> {
        self.object = None;
        self.last_contact = RefCell::default();
        self.strips = RefCell::default();
        self.hold = how;
        self.shear_n = [[0.0; 2]; 2];
        self.stick_m = [0.0; 2];
        self.shift_m = 0.0;
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
    let second_spec = (spec, seed ^ 0x5eed_f1a6_e201_0001);
    let flow = effects.object_flow.map(|f| FlowSeries::new(f, seed));
    let period_ns = 1e9 / fps;
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
        shift_m: 0.0,
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

impl SoftGraspHandle {
    fn lock(&self) -> Result<MutexGuard<'_, State>, SimError> {
        self.state
            .lock()
            .map_err(|_| SimError::Solver("simulation state poisoned by an earlier panic".into()))
    }

    /// The camera of the second finger (mirrored, its own seeded stream), on the same
    /// frame grid as the first.
    pub fn second_camera(&self) -> Result<SoftFingerCamera, SimError> {
        let s = self.lock()?;
        Ok(SoftFingerCamera {
            state: Arc::clone(&self.state),
            clock: s.clock,
            period_ns: s.period_ns,
            finger: 1,
        })
    }

    /// The true wrench on finger 0 (sensor frame, no sensor effects) at time `t`.
    pub fn true_wrench(&self, t: TimestampNs) -> Result<Wrench, SimError> {
        self.true_wrench_on(0, t)
    }

    /// The true wrench on finger `finger` (0 or 1; its own sensor frame) at time `t`.
    pub fn true_wrench_on(&self, finger: usize, t: TimestampNs) -> Result<Wrench, SimError> {
        if finger > 1 {
            return Err(SimError::InvalidParameter(format!(
                "finger {finger}: expected 0 or 1"
            )));
        }
        let mut s = self.lock()?;
        s.advance(t)?;
        s.wrench(finger)
    }

    /// Takes the object away (it was pulled out), or puts a fresh one back (resting).
    pub fn set_object(&self, present: bool) -> Result<(), SimError> {
        let mut s = self.lock()?;
        s.object = present.then(|| s.template.clone());
        s.last_contact = RefCell::default();
        s.strips = RefCell::default();
        s.hold = if present {
            HoldState::Resting
        } else {
            HoldState::Absent
        };
        s.lift = None;
        s.stick_m = [0.0; 2];
        s.shear_n = [[0.0; 2]; 2];
        Ok(())
    }

    /// Whether the object is between the fingers.
    pub fn has_object(&self) -> Result<bool, SimError> {
        Ok(self.lock()?.object.is_some())
    }

    /// Whether the grip crushed the object.
    pub fn crushed(&self) -> Result<bool, SimError> {
        Ok(matches!(self.lock()?.hold, HoldState::Crushed { .. }))
    }

    /// The opening between the fingers now, mm.
    pub fn opening_mm(&self) -> Result<f64, SimError> {
        Ok(self.lock()?.opening_mm)
    }

    /// The object the grasp was built with.
    pub fn object(&self) -> Result<GraspObject, SimError> {
        Ok(self.lock()?.template.clone())
    }

    /// Lift starts at `t`: the gripper rises `height_m`, accelerating at `accel_m_s2`
    /// up to `speed_m_s` (trapezoid). Before this the object rests on its support.
    pub fn start_lift(
        &self,
        t: TimestampNs,
        height_m: f64,
        speed_m_s: f64,
        accel_m_s2: f64,
    ) -> Result<(), SimError> {
        for (field, v, hi) in [
            ("height_m", height_m, 2.0),
            ("speed_m_s", speed_m_s, 5.0),
            ("accel_m_s2", accel_m_s2, 100.0),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= hi) {
                return Err(SimError::InvalidParameter(format!(
                    "lift {field} = {v}: expected a value in (0, {hi}]"
                )));
            }
        }
        let mut s = self.lock()?;
        if s.lift.is_some() {
            return Err(SimError::InvalidParameter(
                "lift: already started (one lift per grasp)".into(),
            ));
        }
        if t < s.last_t {
            return Err(SimError::InvalidParameter(format!(
                "lift start {} ns lies before the simulation's present {} ns",
                t.0, s.last_t.0
            )));
        }
        s.lift = Some(Lift {
            t0: t,
            height_m,
            speed_m_s,
            accel_m_s2,
        });
        Ok(())
    }

    /// What the physics says happened so far (advanced to the clock's present).
    pub fn hold_state(&self) -> Result<HoldState, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(s.hold)
    }

    /// [`Self::hold_state`] after advancing the physics to `t`.
    pub fn hold_state_at(&self, t: TimestampNs) -> Result<HoldState, SimError> {
        let mut s = self.lock()?;
        s.advance(t)?;
        Ok(s.hold)
    }

    /// Turns the object about z (its axis along the finger) to `yaw_rad`, starting at
    /// `t0` and taking `duration_s` (smoothly, starting and ending at rest). Turns are
    /// scheduled in order and must not overlap.
    pub fn schedule_object_yaw(
        &self,
        t0: TimestampNs,
        yaw_rad: f64,
        duration_s: f64,
    ) -> Result<(), SimError> {
        if !(yaw_rad.is_finite() && yaw_rad.abs() <= 4.0 * std::f64::consts::PI) {
            return Err(SimError::InvalidParameter(format!(
                "object yaw {yaw_rad} rad: expected a finite value within ±4π"
            )));
        }
        if !(duration_s.is_finite() && (0.0..=600.0).contains(&duration_s)) {
            return Err(SimError::InvalidParameter(format!(
                "turn duration {duration_s} s: expected a value in [0, 600]"
            )));
        }
        let mut s = self.lock()?;
        if let Some(last) = s.yaw_moves.last()
            && t0 < last.t1
        {
            return Err(SimError::InvalidParameter(format!(
                "object turn at {} ns overlaps the previous one (ends at {} ns)",
                t0.0, last.t1.0
            )));
        }
        if t0 < s.last_t {
            return Err(SimError::InvalidParameter(format!(
                "object turn at {} ns lies before the simulation's present {} ns",
                t0.0, s.last_t.0
            )));
        }
        let t1 = TimestampNs(t0.0.saturating_add((duration_s * 1e9) as u64));
        s.yaw_moves.push(YawMove {
            t0,
            t1,
            to_rad: yaw_rad,
        });
        Ok(())
    }

    /// The object's yaw about z at `t`, rad (the schedule; world frame).
    pub fn object_yaw(&self, t: TimestampNs) -> Result<f64, SimError> {
        Ok(self.lock()?.object_yaw_at(t))
    }

    /// Asks the simulated wrist to turn the gripper about z to `yaw_rad`; it gets there
    /// at up to [`WRIST_MAX_RAD_S`].
    pub fn set_wrist_target(&self, yaw_rad: f64) -> Result<(), SimError> {
        if !(yaw_rad.is_finite() && yaw_rad.abs() <= 4.0 * std::f64::consts::PI) {
            return Err(SimError::InvalidParameter(format!(
                "wrist yaw {yaw_rad} rad: expected a finite value within ±4π"
            )));
        }
        self.lock()?.wrist_target_rad = yaw_rad;
        Ok(())
    }

    /// The wrist's yaw at `t`, rad.
    pub fn wrist_yaw(&self, t: TimestampNs) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        s.advance(t)?;
        Ok(s.wrist_rad)
    }

    /// The wrist's yaw now (the clock's present), rad.
    pub fn wrist_yaw_now(&self) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(s.wrist_rad)
    }

    /// The current's push on the object along the gripping direction (G's +x) at `t`,
    /// N (0 unless the scene lists `object_flow` and an object is held).
    pub fn flow_push_n(&self, t: TimestampNs) -> Result<f64, SimError> {
        let s = self.lock()?;
        let (Some(series), Some(obj)) = (&s.flow, &s.object) else {
            return Ok(0.0);
        };
        let u = series.speed_m_s(t.0 as f64 * 1e-9);
        Ok(0.5 * series.flow.density_kg_m3 * obj.drag_coefficient * obj.drag_area_m2 * u * u.abs())
    }

    /// The squeeze on one finger (−F_x in its sensor frame, N) at each gripper count
    /// in `counts`, from the contact physics with the object in place, centred and not
    /// turned: the curve the stiffness Λ = ∂F/∂P is measured on.
    pub fn grip_force_curve(&self, counts: &[u8]) -> Result<Vec<(u8, f64)>, SimError> {
        let s = self.lock()?;
        let grip = |p: u8| Grip {
            opening_m: opening_mm(p) / 1000.0,
            ..Grip::default()
        };
        counts
            .iter()
            .map(|&p| {
                let c = finger_contact(&s.finger, &s.contact, &s.template, 0, &grip(p), [0.0; 2])?;
                Ok((p, c.squeeze_n()))
            })
            .collect()
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
            s.advance(now).map_err(|e| device_fault(GRIPPER, &e))?;
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
        // The frame's buffers on the second core while this one works out the
        // finger's contact and lattice.
        let background = s.scene(self.finger).background();
        let mut buffers = None;
        let mut look = None;
        crate::second_core::join(
            || look = Some(self.look_at(&mut s, exposed)),
            || buffers = Some(FrameBuffers::new(&background)),
        );
        let look = match look {
            Some(look) => look?,
            None => self.look_at(&mut s, exposed)?,
        };
        let scene = s.scene(self.finger);
        let data = scene.render_into(&look, k, exposed.0 as f64 * 1e-9, buffers);
        Ok(Frame {
            meta: FrameMeta {
                t: exposed,
                sequence: k,
                width: super::WIDTH,
                height: super::HEIGHT,
                format: FrameFormat::Rgb8,
            },
            data,
        })
    }

    fn dropped_frames(&self) -> u64 {
        0
    }
}
