//! The scene spec: medium, rods, the contact poses to sample, and the declared effects.
//!
//! Only the effects a scene lists are simulated; medium `water` switches none on by
//! itself.

use crate::config::{Check, Validate};
use crate::geometry::Range;
use crate::rig::RigConfig;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::fmt;

mod check;
pub(crate) use check::name_problem;

/// A scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Short name, stored with every run.
    pub name: String,
    /// What surrounds the finger.
    pub medium: Medium,
    /// Ranges the contact poses are drawn from.
    pub poses: PoseRanges,
    /// Rods the finger is pressed on (at least one).
    pub rods: Vec<RodSpec>,
    /// Effects to simulate, with their parameters. Empty: an ideal scene.
    #[serde(default)]
    pub effects: Vec<Effect>,
    /// Objects for grasp trials (`[[objects]]`); optional, and left out of printed
    /// scenes without any so existing scenes print as before.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub objects: Vec<ObjectSpec>,
}

/// An object the gripper's soft fingers grasp.
///
/// Geometry in the gripper's terms: the fingers close along x (the gripping
/// direction), y runs across the fingers' faces and the fingers point down along z,
/// so an object's height runs along the finger. Without a `profile` the object lies
/// across the finger (a rod held crosswise, as in the rod presses): the face that meets
/// each finger is `shape`/`size_m`/`aspect` along the finger and `width_m` is its width
/// across the fingers. With a `profile` the object stands on a support with its height
/// along the finger: `shape` is its horizontal section (circle, oval with `aspect` =
/// depth across y over width, square, hexagon, triangle), `width_m` that section's width
/// across the fingers (a taper's bottom width, a sphere's diameter) and the profile how
/// the section changes with height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// Name, unique among the objects.
    pub name: String,
    /// Cross-section: of the face along the finger (lying objects) or the horizontal
    /// section (standing objects, with a `profile`).
    pub shape: RodShape,
    /// Extent of the face along the finger, m (a lying cylinder's diameter); only for
    /// objects without a `profile`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_m: Option<f64>,
    /// Depth over width of an oval section or face (1 for the others).
    #[serde(default = "one")]
    pub aspect: f64,
    /// Width across the fingers, m (below the 50 mm stroke): at the grasp height for a
    /// lying object or a prism, at the bottom for a taper, the diameter of a sphere.
    pub width_m: f64,
    /// Where along the finger the grasp point sits: the contact pose's z, m, in
    /// [−0.05, 0.05] (0: mid-finger).
    #[serde(default)]
    pub contact_z_m: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Friction coefficient against the finger's skin, dry.
    pub friction: f64,
    /// What its surface is (free text, with the source of its friction), for the
    /// reader: the simulator reads the numbers only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<String>,
    /// Friction coefficient against the finger's silicone in water; what the
    /// simulator uses where the scene declares `wet_contact` (then every object
    /// gives one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wet_friction: Option<f64>,
    /// Friction coefficient against its support, where it differs from the
    /// `object_support` effect's (a ball rolls: its rolling resistance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support_friction: Option<f64>,
    /// Squeeze on one finger that crushes it, N; absent for a rigid object.
    #[serde(default)]
    pub crush_force_n: Option<f64>,
    /// How the section changes along the height (standing objects); absent: the object
    /// lies across the finger.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<ObjectProfile>,
    /// Height of the predefined grasp point above the support, m (standing objects;
    /// default: mid-height, a sphere's centre).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp_height_m: Option<f64>,
    /// Opening the open-loop grasp closes the fingers to, m (the paper's Figure 4e;
    /// default: the width at the grasp point less 2 mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grasp_width_m: Option<f64>,
    /// Volume of fluid displaced, m³ (buoyancy; default: from the geometry).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volume_m3: Option<f64>,
    /// Drag coefficient C_d of the object in a fluid (default: by its section, from
    /// White's tables: a sphere 0.47, a circle or oval 1.2, a square 2.1, a triangle
    /// 2.0, a hexagon 1.0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drag_coefficient: Option<f64>,
    /// Area the fluid's drag acts on, m² (default: from the geometry).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drag_area_m2: Option<f64>,
}

/// How a standing object's section changes along its height (the finger's z).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ObjectProfile {
    /// The same section all the way up: a cylinder, an oval tube, a box.
    Prism {
        /// Height, m.
        height_m: f64,
    },
    /// A ball of diameter `width_m`: the fingers meet its chord at each height. (A
    /// struct variant, so that an unknown key beside `kind` is refused as for the
    /// others: serde lets an internally tagged unit variant ignore them.)
    Sphere {},
    /// The section scales linearly from `width_m` at the bottom to `top_width_m` at the
    /// top: a tapered bottle.
    Taper {
        /// Height, m.
        height_m: f64,
        /// Width across the fingers at the top, m.
        top_width_m: f64,
    },
}

impl ObjectProfile {
    /// The object's height, m (a sphere's is its diameter `width_m`).
    #[must_use]
    pub fn height_m(&self, width_m: f64) -> f64 {
        match *self {
            Self::Prism { height_m } | Self::Taper { height_m, .. } => height_m,
            Self::Sphere {} => width_m,
        }
    }

    /// The widest width across the fingers over the height, m.
    #[must_use]
    pub fn max_width_m(&self, width_m: f64) -> f64 {
        match *self {
            Self::Prism { .. } | Self::Sphere {} => width_m,
            Self::Taper { top_width_m, .. } => width_m.max(top_width_m),
        }
    }
}

/// What surrounds the finger.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Medium {
    /// On land.
    Air,
    /// Underwater.
    Water,
}

impl Medium {
    /// Name as stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Air => "air",
            Self::Water => "water",
        }
    }
}

impl fmt::Display for Medium {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Medium {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "air" => Ok(Self::Air),
            "water" => Ok(Self::Water),
            other => Err(format!("unknown medium `{other}`, expected air or water")),
        }
    }
}

/// Ranges of the contact pose `(x, z, θ)`; uniform draws (Method S1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseRanges {
    /// Along the approach axis, m (paper: [0, 0.05]).
    pub x_m: Range,
    /// Along the rod axis, m (paper: [−0.05, 0.05]).
    pub z_m: Range,
    /// About the rod axis, rad (paper: [−π, π]).
    pub theta_rad: Range,
}

/// Cross-section of a rod.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RodShape {
    /// Round.
    Circle,
    /// Square.
    Square,
    /// Equilateral triangle.
    Triangle,
    /// Regular hexagon.
    Hexagon,
    /// Ellipse; `aspect` sets height over width.
    Oval,
}

/// One rod.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RodSpec {
    /// Name, unique in the scene, stored with every sample.
    pub name: String,
    /// Cross-section.
    pub shape: RodShape,
    /// Width of the cross-section across the approach axis, m (diameter, side, or
    /// across-flats).
    pub size_m: f64,
    /// Height over width of the cross-section (ovals; 1 for the others).
    #[serde(default = "one")]
    pub aspect: f64,
}

fn one() -> f64 {
    1.0
}

/// A declared effect and its parameters. The simulator applies exactly these.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Effect {
    /// Apparent magnification through water at a flat port (Snell's law).
    Refraction {
        /// Refractive index of the medium outside the camera (water ≈ 1.333).
        index: f64,
    },
    /// Wavelength-dependent colour attenuation over the light path.
    ColourAttenuation {
        /// Attenuation per metre for R, G, B (water: red fades first).
        per_m_rgb: [f64; 3],
    },
    /// Turbidity: backscatter veiling light.
    Turbidity {
        /// Fraction of veiling light in [0, 1].
        backscatter: f64,
        /// Colour of the veiling light, RGB 0–255.
        colour_rgb: [u8; 3],
    },
    /// Moving caustic light patterns.
    Caustics {
        /// Peak added brightness in [0, 1].
        strength: f64,
        /// Spatial period of the pattern, px.
        period_px: f64,
    },
    /// Bubbles or particles drifting through the view.
    Bubbles {
        /// Mean count per frame.
        per_frame: f64,
        /// Largest radius, px.
        max_radius_px: f64,
    },
    /// Sensor noise, Gaussian per pixel and channel.
    CameraNoise {
        /// Standard deviation in 0–255 intensity units.
        sigma: f64,
    },
    /// Exposure gain (1 = nominal).
    Exposure {
        /// Multiplier on pixel intensities.
        gain: f64,
    },
    /// Objects in the background seen through the finger.
    BackgroundClutter {
        /// How many shapes.
        objects: u32,
    },
    /// White noise on each force/torque reading.
    FtNoise {
        /// Standard deviation per force axis, N.
        force_sigma_n: f64,
        /// Standard deviation per torque axis, N·m.
        torque_sigma_nm: f64,
    },
    /// Slow drift of the force/torque zero.
    FtDrift {
        /// Force drift rate, N per hour.
        force_n_per_h: f64,
        /// Torque drift rate, N·m per hour.
        torque_nm_per_h: f64,
    },
    /// Constant offset from buoyancy and pressure on the finger.
    BuoyancyOffset {
        /// Force offset in the sensor frame, N.
        force_n: [f64; 3],
        /// Torque offset in the sensor frame, N·m.
        torque_nm: [f64; 3],
    },
    /// Fluid drag on a held object while the gripper moves or the fluid flows.
    FluidDrag {
        /// Drag coefficient times area times density / 2, N·s²/m².
        coefficient: f64,
        /// Flow speed of the fluid, m/s.
        flow_m_s: f64,
    },
    /// Buoyancy on a grasped object: the fluid carries ρ·g·V of its weight.
    ObjectBuoyancy {
        /// Density of the fluid, kg/m³ (water ≈ 1000).
        fluid_density_kg_m3: f64,
    },
    /// Drag on a grasped object while it is lifted: ½·ρ·C_d·A·v², against the motion.
    ObjectDrag {
        /// Density of the fluid, kg/m³.
        fluid_density_kg_m3: f64,
    },
    /// A current pushing on a grasped object along the gripping direction:
    /// ½·ρ·C_d·A·u·|u| with a seeded, time-varying speed u(t) = mean + gust·(a sum of
    /// three seeded sines around `period_s`), so the squeeze on the fingers changes.
    ///
    /// The gusts are declared either as `gust_m_s` around `period_s` (three seeded
    /// sines of periods 0.5–2× `period_s`, weights summing to 1) or as a `spectrum`:
    /// each component a sine of its own period and amplitude with a seeded phase. A
    /// scene with neither has a steady current.
    ObjectFlow {
        /// Density of the fluid, kg/m³.
        fluid_density_kg_m3: f64,
        /// Mean flow speed along the gripping direction, m/s.
        mean_m_s: f64,
        /// Amplitude of the gusts, m/s (0: none, or see `spectrum`).
        #[serde(default)]
        gust_m_s: f64,
        /// Typical period of the gusts, s.
        #[serde(default = "one")]
        period_s: f64,
        /// The gusts as components (in place of `gust_m_s`/`period_s`); absent, none.
        /// An empty list is refused: no lab means it.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        spectrum: Option<Vec<GustComponent>>,
    },
    /// The object rests on a support (the floor, a tray): its weight less buoyancy
    /// presses it down and the support's friction holds it, so a finger that touches
    /// first pushes it along the closing direction and a current may drift it. Absent,
    /// the support is frictionless and the object is still until both fingers grip it.
    ObjectSupport {
        /// Friction coefficient of the object on the support (one for every object).
        friction: f64,
    },
    /// Added mass: an object accelerating in a fluid carries some of the fluid with
    /// it, `C_a·ρ·V` more inertia (on the lift, and along the closing direction),
    /// `C_a` from the object's equivalent spheroid.
    ObjectAddedMass {
        /// Density of the fluid, kg/m³.
        fluid_density_kg_m3: f64,
    },
    /// Wet contact: each object grips the finger's silicone with its `wet_friction`
    /// (measured in water against a silicone like the finger's) instead of its dry
    /// `friction`. Declared per object, because water lubricates a hydrophilic surface
    /// against silicone and barely a hydrophobic one.
    WetContact {},
    /// Camera frames lost.
    FrameDrops {
        /// Probability each frame is dropped.
        probability: f64,
    },
    /// Force/torque datagrams lost.
    FtPacketLoss {
        /// Probability each reading is lost.
        probability: f64,
    },
    /// Delivery latency of the streams.
    Latency {
        /// Camera latency, ms.
        camera_ms: f64,
        /// Force/torque latency, ms.
        ft_ms: f64,
    },
    /// Reflex faults of the arm.
    ArmReflex {
        /// Probability that a move ends in a reflex fault.
        probability: f64,
    },
}

/// One component of a current's gusts: `amplitude_m_s · sin(2π·t / period_s + φ)`,
/// the phase φ drawn from the scene's seed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GustComponent {
    /// Period, s.
    pub period_s: f64,
    /// Amplitude, m/s.
    pub amplitude_m_s: f64,
}

impl Effect {
    /// The effect's `kind` as written in the scene file.
    #[must_use]
    pub const fn kind(&self) -> &'static str {
        match self {
            Self::Refraction { .. } => "refraction",
            Self::ColourAttenuation { .. } => "colour_attenuation",
            Self::Turbidity { .. } => "turbidity",
            Self::Caustics { .. } => "caustics",
            Self::Bubbles { .. } => "bubbles",
            Self::CameraNoise { .. } => "camera_noise",
            Self::Exposure { .. } => "exposure",
            Self::BackgroundClutter { .. } => "background_clutter",
            Self::FtNoise { .. } => "ft_noise",
            Self::FtDrift { .. } => "ft_drift",
            Self::BuoyancyOffset { .. } => "buoyancy_offset",
            Self::FluidDrag { .. } => "fluid_drag",
            Self::ObjectBuoyancy { .. } => "object_buoyancy",
            Self::ObjectDrag { .. } => "object_drag",
            Self::ObjectFlow { .. } => "object_flow",
            Self::ObjectSupport { .. } => "object_support",
            Self::ObjectAddedMass { .. } => "object_added_mass",
            Self::WetContact {} => "wet_contact",
            Self::FrameDrops { .. } => "frame_drops",
            Self::FtPacketLoss { .. } => "ft_packet_loss",
            Self::Latency { .. } => "latency",
            Self::ArmReflex { .. } => "arm_reflex",
        }
    }
}

impl Effect {
    /// The density of the fluid an effect acts through, kg/m³, where it names one.
    #[must_use]
    pub const fn fluid_density_kg_m3(&self) -> Option<f64> {
        match self {
            Self::ObjectBuoyancy {
                fluid_density_kg_m3,
            }
            | Self::ObjectDrag {
                fluid_density_kg_m3,
            }
            | Self::ObjectAddedMass {
                fluid_density_kg_m3,
            }
            | Self::ObjectFlow {
                fluid_density_kg_m3,
                ..
            } => Some(*fluid_density_kg_m3),
            _ => None,
        }
    }
}

impl SceneSpec {
    /// The first declared effect of the given kind, if any.
    #[must_use]
    pub fn effect(&self, kind: &str) -> Option<&Effect> {
        self.effects.iter().find(|e| e.kind() == kind)
    }

    /// The rod with this name.
    #[must_use]
    pub fn rod(&self, name: &str) -> Option<&RodSpec> {
        self.rods.iter().find(|r| r.name == name)
    }

    /// The grasp object with this name.
    #[must_use]
    pub fn object(&self, name: &str) -> Option<&ObjectSpec> {
        self.objects.iter().find(|o| o.name == name)
    }

    /// Checks that need the rig too: the pose ranges must lie inside its workspace.
    pub fn validate_against(&self, rig: &RigConfig, c: &mut Check) {
        let w = &rig.workspace;
        for (field, scene, bound) in [
            ("poses.x_m", &self.poses.x_m, &w.x_m),
            ("poses.z_m", &self.poses.z_m, &w.z_m),
            ("poses.theta_rad", &self.poses.theta_rad, &w.theta_rad),
        ] {
            if !bound.contains_range(scene) {
                c.fail(
                    field,
                    format!(
                        "range [{}, {}] lies outside the rig's workspace [{}, {}]",
                        scene.min, scene.max, bound.min, bound.max
                    ),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests;
