//! The shared world: the scene, the rod in place, the arm's motion in virtual time,
//! the object in the gripper. The arm writes its motion here; the sensor and the
//! camera read the contact it makes at the instants they sample.

use super::SimError;
use super::contact::{self, ContactParams, FingerGeometry, RodProfile};
use super::effects::Effects;
use super::gripper::SimObject;
use super::lattice::{Deformed, Lattice, LatticeParams};
use super::render::{FrameBuffers, Renderer};
use softtouch_schemas::{ArmPose, ContactPose, SceneSpec, TimestampNs, Wrench};
use std::sync::Arc;

/// Physical parameters of the simulated finger (all have sensible defaults).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimParams {
    /// Shape of the finger.
    pub finger: FingerGeometry,
    /// Skin stiffness, friction, and how `x` maps to penetration.
    pub contact: ContactParams,
    /// The internal lattice.
    pub lattice: LatticeParams,
}

/// The scene-independent model: finger, contact law, factorised lattice.
#[derive(Debug)]
pub(crate) struct Model {
    pub params: SimParams,
    pub lattice: Lattice,
}

impl Model {
    pub(crate) fn new(params: SimParams) -> Result<Self, SimError> {
        let lattice = Lattice::new(&params.finger, params.lattice)?;
        Ok(Self { params, lattice })
    }

    /// The default model, built once per process (the factorisation is the only
    /// costly part, and it depends on nothing but the defaults).
    pub(crate) fn shared_default() -> Result<Arc<Self>, SimError> {
        static DEFAULT: std::sync::OnceLock<Result<Arc<Model>, SimError>> =
            std::sync::OnceLock::new();
        DEFAULT
            .get_or_init(|| Model::new(SimParams::default()).map(Arc::new))
            .clone()
    }
}

/// One scene made ready to simulate: model, effects, rods, renderer.
#[derive(Debug, Clone)]
pub(crate) struct Scene {
    pub model: Arc<Model>,
    pub spec: SceneSpec,
    pub effects: Effects,
    pub renderer: Arc<Renderer>,
}

/// One look at the contact: the truth and the deformed lattice.
#[derive(Debug, Clone)]
pub(crate) struct Look {
    pub wrench: Wrench,
    pub deformed: Deformed,
}

impl Scene {
    pub(crate) fn new(spec: &SceneSpec, seed: u64, model: Arc<Model>) -> Self {
        let effects = Effects::from_scene(spec);
        let renderer = Arc::new(Renderer::new(&model.params.finger, &effects.image, seed));
        Self {
            model,
            spec: spec.clone(),
            effects,
            renderer,
        }
    }

    pub(crate) fn rod(&self, name: &str) -> Result<RodProfile, SimError> {
        let rod = self.spec.rod(name).ok_or_else(|| SimError::UnknownRod {
            name: name.to_owned(),
            known: self
                .spec
                .rods
                .iter()
                .map(|r| r.name.clone())
                .collect::<Vec<_>>()
                .join(", "),
        })?;
        RodProfile::new(rod)
    }

    pub(crate) fn wrench(&self, rod: &RodProfile, pose: &ContactPose) -> Result<Wrench, SimError> {
        let p = &self.model.params;
        Ok(contact::contact(&p.finger, &p.contact, rod, pose)?.wrench)
    }

    pub(crate) fn look(&self, rod: &RodProfile, pose: &ContactPose) -> Result<Look, SimError> {
        let p = &self.model.params;
        let c = contact::contact(&p.finger, &p.contact, rod, pose)?;
        let deformed = self.model.lattice.deform(&p.finger, &c)?;
        Ok(Look {
            wrench: c.wrench,
            deformed,
        })
    }

    pub(crate) fn render(&self, look: &Look, frame_index: u64, t_s: f64) -> Vec<u8> {
        self.render_into(look, frame_index, t_s, None)
    }

    /// [`Self::render`] into buffers made beforehand (the same bytes).
    pub(crate) fn render_into(
        &self,
        look: &Look,
        frame_index: u64,
        t_s: f64,
        buffers: Option<FrameBuffers>,
    ) -> Vec<u8> {
        self.renderer.render(
            &self.model.lattice,
            &look.deformed,
            frame_index,
            t_s,
            buffers,
        )
    }

    /// The renderer's background, to make [`FrameBuffers`] from.
    pub(crate) fn background(&self) -> std::sync::Arc<[u8]> {
        self.renderer.background()
    }
}

/// One straight move of the finger in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Segment {
    pub t0: TimestampNs,
    pub t1: TimestampNs,
    pub from: ArmPose,
    pub to: ArmPose,
}

/// How long motion history is kept behind the newest move, ns.
const HISTORY_NS: u64 = 30_000_000_000;

/// The shared state of a simulated rig.
#[derive(Debug)]
pub struct SimWorld {
    pub(crate) scene: Scene,
    pub(crate) rod_name: String,
    pub(crate) rod: RodProfile,
    pub(crate) base_from_rod: ArmPose,
    /// Pose before the oldest kept segment.
    pub(crate) initial: ArmPose,
    pub(crate) segments: Vec<Segment>,
    pub(crate) object: Option<SimObject>,
    cache: Option<(ContactPose, String, Wrench)>,
}

impl SimWorld {
    pub(crate) fn new(
        scene: Scene,
        base_from_rod: ArmPose,
        start: ArmPose,
    ) -> Result<Self, SimError> {
        let first = scene
            .spec
            .rods
            .first()
            .ok_or_else(|| SimError::UnknownRod {
                name: String::new(),
                known: "(the scene has no rods)".into(),
            })?;
        let rod_name = first.name.clone();
        let rod = scene.rod(&rod_name)?;
        Ok(Self {
            scene,
            rod_name,
            rod,
            base_from_rod,
            initial: start,
            segments: Vec::new(),
            object: None,
            cache: None,
        })
    }

    pub(crate) fn set_rod(&mut self, name: &str) -> Result<(), SimError> {
        self.rod = self.scene.rod(name)?;
        self.rod_name = name.to_owned();
        self.cache = None;
        Ok(())
    }

    /// Record a move; drop history older than [`HISTORY_NS`] before it.
    pub(crate) fn push_segment(&mut self, seg: Segment) {
        let horizon = seg.t0.0.saturating_sub(HISTORY_NS);
        while let Some(first) = self.segments.first() {
            if first.t1.0 < horizon && self.segments.len() > 1 {
                self.initial = first.to;
                self.segments.remove(0);
            } else {
                break;
            }
        }
        self.segments.push(seg);
    }

    /// Cut the motion short at `t` (stop or reflex): the last segment ends there.
    pub(crate) fn truncate_motion(&mut self, t: TimestampNs) {
        let pose = self.pose_at(t);
        if let Some(last) = self.segments.last_mut()
            && t < last.t1
        {
            last.t1 = t.max(last.t0);
            last.to = pose;
        }
    }

    /// The latest segment that started by `t` (searched from the newest, where the
    /// sensor and camera almost always look).
    fn segment_at(&self, t: TimestampNs) -> Option<&Segment> {
        self.segments.iter().rev().find(|seg| seg.t0 <= t)
    }

    /// Where the finger is at `t`: in the latest segment that started by `t`.
    pub(crate) fn pose_at(&self, t: TimestampNs) -> ArmPose {
        let Some(seg) = self.segment_at(t) else {
            return self.initial;
        };
        if t >= seg.t1 || seg.t1 <= seg.t0 {
            seg.to
        } else {
            let s = (t.0 - seg.t0.0) as f64 / (seg.t1.0 - seg.t0.0) as f64;
            super::arm::interpolate(&seg.from, &seg.to, super::arm::profile(s))
        }
    }

    /// The contact pose (rod frame) of a finger pose.
    pub(crate) fn contact_pose(&self, base_from_finger: &ArmPose) -> ContactPose {
        super::arm::contact_from_arm(&self.base_from_rod, base_from_finger)
    }

    /// The true contact wrench in the sensor frame with the finger at `pose`.
    pub(crate) fn wrench_for(&mut self, pose: &ArmPose) -> Result<Wrench, SimError> {
        let c = self.contact_pose(pose);
        if let Some((p, rod, w)) = &self.cache
            && *p == c
            && *rod == self.rod_name
        {
            return Ok(*w);
        }
        let w = self.scene.wrench(&self.rod, &c)?;
        self.cache = Some((c, self.rod_name.clone(), w));
        Ok(w)
    }

    /// The contact wrench at `t`: the equilibrium wrench of the pose
    /// ([`SimWorld::equilibrium_at`]) raised by the silicone's stress relaxation
    /// ([`SimWorld::relaxation_at`]).
    pub(crate) fn wrench_at(&mut self, t: TimestampNs) -> Result<Wrench, SimError> {
        let equilibrium = self.equilibrium_at(t)?;
        Ok(relaxed(&equilibrium, self.relaxation_at(t)))
    }

    /// The equilibrium contact wrench of the finger's pose at `t`: continuous in `t`
    /// (the motion is), so it may be interpolated between nearby instants.
    pub(crate) fn equilibrium_at(&mut self, t: TimestampNs) -> Result<Wrench, SimError> {
        let pose = self.pose_at(t);
        self.wrench_for(&pose)
    }

    /// The factor (≥ 1) by which the stress relaxation raises the equilibrium wrench at
    /// `t`: `1 + r·exp(−Δt/τ)` once the move under way at `t` has ended; `None` while
    /// moving (or without relaxation).
    /// It jumps when a move ends, so it is evaluated per reading, never interpolated. A
    /// function of the motion and `t` alone: a move commanded after `t` does not change
    /// it, however late a reader asks (a delayed packet, a resumed run's first packet).
    pub(crate) fn relaxation_at(&self, t: TimestampNs) -> Option<f64> {
        let p = &self.scene.model.params.contact;
        let arrived = self.segment_at(t).map(|s| s.t1).filter(|t1| *t1 <= t);
        match arrived {
            Some(t1) if p.relaxation_ratio > 0.0 && p.relaxation_time_s > 0.0 => {
                let since_s = (t.0 - t1.0) as f64 * 1e-9;
                Some(1.0 + p.relaxation_ratio * (-since_s / p.relaxation_time_s).exp())
            }
            _ => None,
        }
    }
}

/// `w` raised by a relaxation factor (unchanged without one).
pub(crate) fn relaxed(w: &Wrench, factor: Option<f64>) -> Wrench {
    match factor {
        Some(f) => Wrench::from_array(w.to_array().map(|v| v * f)),
        None => *w,
    }
}
