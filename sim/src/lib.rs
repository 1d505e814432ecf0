//! The simulated scene and the simulated twin of every device, behind the drivers'
//! traits; it must not depend on a store, a model or the CLI (only the collector's
//! device building and experiments, and tests and benches, name it).
//!
//! # The finger and the contact
//!
//! Everything is in the **sensor frame**: origin at the force/torque sensor's
//! measuring centre, `z` along the finger from its base to its tip, `x` the finger's
//! depth, `y` its width. The finger ([`FingerGeometry`]) is a tapered body with an
//! elliptical cross-section (half-depth 12 → 4 mm, half-width 16 → 5 mm, 60 mm long,
//! base 12 mm above the sensor origin), so its sides lean towards the axis: the
//! "shrinking cross-section" of the paper's finger.
//!
//! The contact pose `(x, z, θ)` (the paper's `(x, 0, z, 0, 0, θ)`, rod frame) is read
//! as follows. The arm turns the finger by `θ` about the rod's axis and slides it
//! along that axis by `z`, then presses by `x` along the approach axis:
//!
//! - `θ` picks **which side of the finger** meets the rod: the rod touches the finger
//!   at azimuth `θ` about the finger's axis (direction `(cos θ, sin θ, 0)`), lying
//!   across that side (perpendicular to the finger axis). Everything depends on `θ`
//!   through `cos θ, sin θ`, so `θ = −π` and `θ = π` give the same contact.
//! - `z` picks **where along the finger** the rod's centre line sits: height
//!   `base + L·(0.5 + 0.4·z / 5 cm)`, i.e. 10 %…90 % of the finger over the paper's
//!   `z ∈ [−5, 5] cm` (clamped to 2 %…98 % beyond, so contacts at the tip stay
//!   defined).
//! - `x` sets **how deep** the rod presses: penetration `0.3 mm + 0.084·x`
//!   (0.3 … 4.5 mm over `x ∈ [0, 5] cm`). Below `x ≈ −3.6 mm` there is no contact
//!   (the rig's home pose `x = −3 cm` is free).
//!
//! The rod's cross-section sets the profile of the face that meets the finger: a
//! circle or an oval (width `size_m`, depth `aspect·size_m`), a square's flat face, a
//! triangle's or a hexagon's vertex (faces at 30° and 60° to the approach), with
//! corners rounded by 0.5 mm. The patch is cut into 48 strips along the finger axis;
//! each strip's penetration is the pressing depth minus the rod's gap profile plus the
//! taper of the finger's surface. A strip pushes with the Hertz-like law
//! `p = k(h)·δ^1.5` (the skin is softer towards the tip) along the surface normal,
//! plus regularised Coulomb friction `μ·N·tanh(slip / s₀)` opposing the surface's
//! slip along the rod. The sensor's wrench is the sum of strip forces and their
//! moments about the sensor origin. Over the default pose ranges forces stay within
//! about ±10 N and torques within about ±600 N·mm, and the wrench is a continuous
//! function of the pose (C¹ except where a patch edge leaves the finger's tip).
//!
//! # The lattice and the image
//!
//! The lattice ([`LatticeParams`]) is a linear-elastic truss of elliptical rings (16
//! nodes and a centre per layer, 10 layers, base clamped) with ring beams, spokes,
//! longitudinal beams and diagonals. Its stiffness is factorised once (dense
//! Cholesky); each contact distributes its strip forces onto the ring nodes around the
//! contact (Gaussian in angle, linear between layers) and solves for the node
//! displacements by back-substitution. The same strip forces make the wrench, so the
//! image carries the label: normal force bends the near side in, a torque about x or
//! y shows as the height of the load, a torque about z as a twist of the rings.
//!
//! A pinhole camera (f = 400 px) 22 mm under the finger's base looks along the finger
//! and renders 640×480 RGB: beams drawn far to near as anti-aliased thick lines in
//! the finger's orange ([`FINGER_RGB`]), lit by LEDs next to the camera (brightness
//! falls with distance), over a precomputed dim blue-grey background seen through
//! the translucent finger.
//!
//! # Effects
//!
//! Only the effects the scene lists are simulated ([`softtouch_schemas::Effect`]); the
//! medium alone switches nothing on. Image effects: refraction (focal length × index),
//! colour attenuation and turbidity (along the light path, per beam and once for the
//! background), caustics (a precomputed tile, shifted per frame), bubbles, exposure
//! (a lookup table), camera noise (a frame's worth of a precomputed Gaussian table, read
//! from a random offset per frame; one byte a level where σ allows), background clutter (drawn once into the background).
//! Force/torque: white noise, drift, buoyancy offset, packet loss, latency. Camera:
//! frame drops, latency. Arm: reflex faults. Gripper: fluid drag on the held object.
//!
//! # Devices
//!
//! [`SimRig::new`] builds [`SimArm`], [`SimForceSensor`], [`SimCamera`] and
//! [`SimGripper`] on one shared [`SimWorld`]; [`SimHandle`] changes the rod and puts
//! objects in the gripper. [`soft_grasp`] builds the Hand-E with soft, sensorised
//! fingers ([`SoftGripper`], [`SoftFingerCamera`]): an object's contact on the finger
//! goes through the same contact model, lattice and renderer as the rod presses;
//! [`SoftGraspArm`] carries that gripper between poses of a grasp rig (behind `Arm`:
//! down around the object, up with it, down to set it down). All of them wait on tokio's clock: run them on a paused
//! runtime (`start_paused`) and a night of collection takes minutes, and the same seed
//! gives the same bytes (every device and frame draws from its own ChaCha stream
//! derived from `(seed, stream name)`). Randomness is counter-based, never one
//! sequence per device: a force/torque reading draws from `(seed, "ft", k)` by its
//! grid index, a frame from its frame index, a move from its start time and target.
//! With a clock that continues a run's device time ([`TokioClock::starting_at`]) a
//! resumed run therefore reads, sees and moves exactly as an uninterrupted one.

// Numeric code indexes several parallel arrays by axis; iterators would hide that.
#![allow(clippy::needless_range_loop)]

mod arm;
mod camera;
mod contact;
mod effects;
mod force;
mod grasp;
mod gripper;
mod lattice;
mod render;
mod rng;
pub mod second_core;
mod world;

pub use arm::{MAX_ACCEL_M_S2, MAX_ROT_ACCEL_RAD_S2, MAX_ROT_SPEED_RAD_S, MAX_SPEED_M_S, SimArm};
pub use camera::SimCamera;
pub use contact::{ContactParams, FingerGeometry};
pub use force::{BUFFER_READINGS, COUNTS_PER_FORCE, COUNTS_PER_TORQUE, SimForceSensor};
pub use grasp::{
    GraspObject, SoftFingerCamera, SoftGrasp, SoftGraspArm, SoftGraspHandle, SoftGripper,
    check_scene_objects, default_drag_coefficient, default_drag_coefficients, soft_grasp,
    spheroid_added_mass,
};
pub use grasp::{GripCap, GripWindow, HoldState, WRIST_MAX_RAD_S, grip_window};
pub use gripper::{
    ACTIVATION, FORCE_N, G_M_S2, SPEED_MM_S, SimGripper, SimObject, grasp_holds, grip_force_n,
};
pub use lattice::LatticeParams;
pub use render::{FINGER_RGB, HEIGHT, WIDTH};
pub use world::{SimParams, SimWorld};

use image::RgbImage;
use softtouch_drivers::clock::TokioClock;
use softtouch_drivers::error::DeviceError;
use softtouch_drivers::{Arm, Camera, ForceSensor, Gripper};
use softtouch_schemas::rig::{ArmDevice, CameraDevice, ForceSensorDevice, GripperDevice};
use softtouch_schemas::{ArmPose, ContactPose, RigConfig, SceneSpec, TimestampNs, Wrench};
use std::sync::{Arc, Mutex, MutexGuard};
use world::{Model, Scene};

/// What can go wrong building or evaluating the simulation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The scene has no rod of that name.
    #[error("unknown rod `{name}`; the scene has: {known}")]
    UnknownRod {
        /// The name asked for.
        name: String,
        /// The names the scene has.
        known: String,
    },
    /// A pose with NaN or infinite coordinates.
    #[error("contact pose is not finite: x = {x_m} m, z = {z_m} m, θ = {theta_rad} rad")]
    NonFinitePose {
        /// x, m.
        x_m: f64,
        /// z, m.
        z_m: f64,
        /// θ, rad.
        theta_rad: f64,
    },
    /// The lattice or contact solve failed (singular stiffness, non-finite result).
    #[error("simulation solve failed: {0}")]
    Solver(String),
    /// A parameter of the model is out of its domain.
    #[error("invalid simulation parameter: {0}")]
    InvalidParameter(String),
    /// The rig config names a real driver where a simulated one is needed.
    #[error("rig device `{device}` uses driver `{driver}`; the simulated rig needs driver `sim`")]
    NotSimulated {
        /// Which device.
        device: &'static str,
        /// Its driver.
        driver: &'static str,
    },
    /// PNG encoding failed.
    #[error("PNG encoding failed: {0}")]
    Encode(String),
}

/// Lock the world; a poisoned lock (a panic elsewhere) is reported, not propagated.
pub(crate) fn lock(world: &Mutex<SimWorld>) -> Result<MutexGuard<'_, SimWorld>, DeviceError> {
    world.lock().map_err(|_| DeviceError::Fault {
        device: "sim".into(),
        code: None,
        message: "simulation state poisoned by an earlier panic".into(),
    })
}

/// One look at a scene: the frame and the noise-free wrench that made it.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// 640×480 RGB.
    pub image: RgbImage,
    /// The true contact wrench in the sensor frame (no sensor effects).
    pub wrench_in_sensor: Wrench,
}

/// Render one contact of `rod_name` at `pose` in `scene` (frame 0, time 0; seeded
/// effects use `seed`). A pure function: same inputs, same bytes.
pub fn render_contact(
    scene: &SceneSpec,
    rod_name: &str,
    pose: &ContactPose,
    seed: u64,
) -> Result<Rendered, SimError> {
    SceneSim::new(scene, seed)?.render(rod_name, pose, 0, 0.0)
}

/// A scene made ready for repeated looks (the renderer's tables and the factorised
/// lattice are built once): what [`render_contact`] uses, for callers that render
/// many contacts.
#[derive(Debug, Clone)]
pub struct SceneSim {
    scene: Scene,
}

impl SceneSim {
    /// Prepare `scene` with the default finger.
    pub fn new(scene: &SceneSpec, seed: u64) -> Result<Self, SimError> {
        Ok(Self {
            scene: Scene::new(scene, seed, Model::shared_default()?),
        })
    }

    /// Prepare `scene` with other finger parameters.
    pub fn with_params(scene: &SceneSpec, seed: u64, params: SimParams) -> Result<Self, SimError> {
        Ok(Self {
            scene: Scene::new(scene, seed, Arc::new(Model::new(params)?)),
        })
    }

    /// The noise-free contact wrench in the sensor frame.
    pub fn wrench(&self, rod_name: &str, pose: &ContactPose) -> Result<Wrench, SimError> {
        self.scene.wrench(&self.scene.rod(rod_name)?, pose)
    }

    /// Deformed lattice node positions (sensor frame, m) for a contact.
    pub fn lattice_nodes(
        &self,
        rod_name: &str,
        pose: &ContactPose,
    ) -> Result<Vec<[f64; 3]>, SimError> {
        Ok(self
            .scene
            .look(&self.scene.rod(rod_name)?, pose)?
            .deformed
            .nodes)
    }

    /// Render frame `frame_index` exposed at `t_s` seconds with the contact.
    pub fn render(
        &self,
        rod_name: &str,
        pose: &ContactPose,
        frame_index: u64,
        t_s: f64,
    ) -> Result<Rendered, SimError> {
        let look = self.scene.look(&self.scene.rod(rod_name)?, pose)?;
        let data = self.scene.render(&look, frame_index, t_s);
        let image = RgbImage::from_raw(WIDTH, HEIGHT, data)
            .ok_or_else(|| SimError::Solver("rendered buffer has the wrong size".into()))?;
        Ok(Rendered {
            image,
            wrench_in_sensor: look.wrench,
        })
    }

    /// The stages of one sample, separately (for benchmarks): contact only.
    #[doc(hidden)]
    pub fn stage_contact(&self, rod_name: &str, pose: &ContactPose) -> Result<Wrench, SimError> {
        self.wrench(rod_name, pose)
    }

    /// Contact + lattice solve, returning the number of nodes (benchmarks).
    #[doc(hidden)]
    pub fn stage_deform(&self, rod_name: &str, pose: &ContactPose) -> Result<usize, SimError> {
        Ok(self
            .scene
            .look(&self.scene.rod(rod_name)?, pose)?
            .deformed
            .nodes
            .len())
    }

    /// Draw a precomputed look without the per-frame effects (benchmarks, tests).
    #[doc(hidden)]
    pub fn stage_draw(&self, rod_name: &str, pose: &ContactPose) -> Result<Vec<u8>, SimError> {
        let look = self.scene.look(&self.scene.rod(rod_name)?, pose)?;
        let r = &self.scene.renderer;
        let mut img = r.background_copy();
        r.draw_lattice(&mut img, &self.scene.model.lattice, &look.deformed);
        Ok(img)
    }

    /// Apply the declared per-frame image effects to a raw frame (benchmarks).
    #[doc(hidden)]
    pub fn stage_effects(&self, img: &mut [u8], frame_index: u64, t_s: f64) {
        self.scene.renderer.apply_effects(img, frame_index, t_s);
    }
}

/// PNG-encode a frame with fast compression (what the store keeps).
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>, SimError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let mut out = Vec::with_capacity(image.as_raw().len() / 4);
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| SimError::Encode(e.to_string()))?;
    Ok(out)
}

/// A handle on the shared world: change the rod between blocks, place objects in the
/// gripper, read the truth.
#[derive(Debug, Clone)]
pub struct SimHandle {
    world: Arc<Mutex<SimWorld>>,
}

impl SimHandle {
    fn lock(&self) -> Result<MutexGuard<'_, SimWorld>, SimError> {
        self.world
            .lock()
            .map_err(|_| SimError::Solver("simulation state poisoned by an earlier panic".into()))
    }

    /// Where a real arm measured the finger at `t` (base frame): the simulated
    /// sensor and camera then see the finger there from `t` on, as they see the
    /// simulated arm's moves. A measurement older than the newest one kept is ignored.
    pub fn follow_arm(&self, t: TimestampNs, base_from_finger: ArmPose) -> Result<(), SimError> {
        if !base_from_finger.is_valid() {
            return Ok(());
        }
        let mut w = self.lock()?;
        if w.segments.last().is_some_and(|s| s.t1 > t) {
            return Ok(());
        }
        let from = w.pose_at(t);
        w.push_segment(world::Segment {
            t0: t,
            t1: t,
            from,
            to: base_from_finger.normalised(),
        });
        Ok(())
    }

    /// Put rod `name` (from the scene) in place.
    pub fn set_rod(&self, name: &str) -> Result<(), SimError> {
        self.lock()?.set_rod(name)
    }

    /// The rod in place.
    pub fn rod(&self) -> Result<String, SimError> {
        Ok(self.lock()?.rod_name.clone())
    }

    /// Put an object between the gripper's fingers (or take it away).
    pub fn set_gripper_object(&self, object: Option<SimObject>) -> Result<(), SimError> {
        self.lock()?.object = object;
        Ok(())
    }

    /// The object between the fingers, if it has not slipped out.
    pub fn gripper_object(&self) -> Result<Option<SimObject>, SimError> {
        Ok(self.lock()?.object)
    }

    /// The true contact wrench (sensor frame) with the finger at `base_from_finger`.
    pub fn true_wrench(&self, base_from_finger: &ArmPose) -> Result<Wrench, SimError> {
        self.lock()?.wrench_for(base_from_finger)
    }
}

/// A complete simulated rig on one shared world.
#[derive(Debug)]
pub struct SimRig {
    /// The arm.
    pub arm: SimArm,
    /// The force/torque sensor.
    pub force_sensor: SimForceSensor,
    /// The in-finger camera.
    pub camera: SimCamera,
    /// The gripper.
    pub gripper: SimGripper,
    /// Rod changes, gripper objects, truth.
    pub handle: SimHandle,
}

/// The devices of a [`SimRig`], boxed behind the device traits.
pub type BoxedRig = (
    Box<dyn Arm>,
    Box<dyn ForceSensor>,
    Box<dyn Camera>,
    Box<dyn Gripper>,
    SimHandle,
);

impl SimRig {
    /// Build the rig for `rig` (every device must use driver `sim`) and `scene`,
    /// seeded by `seed`, on `clock` (start the runtime paused for virtual time). The
    /// arm starts at the workspace's home pose; the first rod of the scene is in place.
    pub fn new(
        rig: &RigConfig,
        scene: &SceneSpec,
        seed: u64,
        clock: TokioClock,
    ) -> Result<Self, SimError> {
        Self::with_params(rig, scene, seed, clock, None)
    }

    /// [`SimRig::new`] with other finger parameters (`None`: defaults).
    pub fn with_params(
        rig: &RigConfig,
        scene: &SceneSpec,
        seed: u64,
        clock: TokioClock,
        params: Option<SimParams>,
    ) -> Result<Self, SimError> {
        let ArmDevice::Sim { reflex_force_n } = rig.arm else {
            return Err(SimError::NotSimulated {
                device: "arm",
                driver: "franka",
            });
        };
        let rate_hz = match rig.force_sensor {
            ForceSensorDevice::Sim { rate_hz } => rate_hz,
            ForceSensorDevice::NetFt { .. } => {
                return Err(SimError::NotSimulated {
                    device: "force_sensor",
                    driver: "net-ft",
                });
            }
            ForceSensorDevice::AtiSerial { .. } => {
                return Err(SimError::NotSimulated {
                    device: "force_sensor",
                    driver: "ati-serial",
                });
            }
        };
        let CameraDevice::Sim { fps } = rig.camera else {
            return Err(SimError::NotSimulated {
                device: "camera",
                driver: "v4l",
            });
        };
        let GripperDevice::Sim {} = rig.gripper else {
            return Err(SimError::NotSimulated {
                device: "gripper",
                driver: "hand-e",
            });
        };
        for (what, v) in [
            ("reflex_force_n", reflex_force_n),
            ("rate_hz", rate_hz),
            ("fps", fps),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimError::InvalidParameter(format!(
                    "{what} must be finite and positive, found {v}"
                )));
            }
        }
        let model = match params {
            None => Model::shared_default()?,
            Some(p) => Arc::new(Model::new(p)?),
        };
        let w = &rig.workspace;
        let home = ArmPose::from_contact(&w.base_from_rod, &w.home);
        let world = SimWorld::new(Scene::new(scene, seed, model), w.base_from_rod, home)?;
        let ft_effects = world.scene.effects.ft.clone();
        let world = Arc::new(Mutex::new(world));
        let range = rig.limits.sensor_range();
        let camera = SimCamera::new(Arc::clone(&world), clock, fps, seed)
            .map_err(|e| SimError::InvalidParameter(e.to_string()))?;
        Ok(Self {
            arm: SimArm::new(Arc::clone(&world), clock, reflex_force_n, seed),
            force_sensor: SimForceSensor::new(
                Arc::clone(&world),
                clock,
                rate_hz,
                range,
                ft_effects,
                seed,
            ),
            camera,
            gripper: SimGripper::new(Arc::clone(&world), clock),
            handle: SimHandle { world },
        })
    }

    /// The devices boxed behind their traits, for code that takes any rig.
    #[must_use]
    pub fn into_boxed(self) -> BoxedRig {
        (
            Box::new(self.arm),
            Box::new(self.force_sensor),
            Box::new(self.camera),
            Box::new(self.gripper),
            self.handle,
        )
    }
}

#[cfg(test)]
mod tests;
