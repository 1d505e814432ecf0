//! The scene's declared effects, parsed once into typed options. An effect the scene
//! does not list is `None` here and every stage skips it with one branch.

use softtouch_schemas::{Effect, SceneSpec};

/// Image effects.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct ImageEffects {
    pub refraction_index: Option<f64>,
    pub attenuation_per_m: Option<[f64; 3]>,
    pub turbidity: Option<(f64, [u8; 3])>,
    pub caustics: Option<(f64, f64)>,
    pub bubbles: Option<(f64, f64)>,
    pub noise_sigma: Option<f64>,
    pub exposure_gain: Option<f64>,
    pub clutter_objects: Option<u32>,
}

/// Force/torque effects.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct FtEffects {
    pub noise: Option<(f64, f64)>,
    pub drift_per_h: Option<(f64, f64)>,
    pub offset: Option<([f64; 3], [f64; 3])>,
    pub packet_loss: Option<f64>,
    pub latency_ms: Option<f64>,
}

/// Everything the scene declares.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Effects {
    pub image: ImageEffects,
    pub ft: FtEffects,
    pub frame_drop_probability: Option<f64>,
    pub camera_latency_ms: Option<f64>,
    pub arm_reflex_probability: Option<f64>,
    pub fluid_drag: Option<(f64, f64)>,
    /// Buoyancy on a grasped object: the fluid's density, kg/m³.
    pub object_buoyancy_kg_m3: Option<f64>,
    /// Drag on a lifted object: the fluid's density, kg/m³.
    pub object_drag_kg_m3: Option<f64>,
    /// A current on a grasped object.
    pub object_flow: Option<Flow>,
    /// Objects grip with their wet friction (`Effect::WetContact`).
    pub wet_contact: bool,
    /// The support's friction under a resting object (`Effect::ObjectSupport`).
    pub support_friction: Option<f64>,
    /// Added mass of an accelerating object: the fluid's density, kg/m³.
    pub object_added_mass_kg_m3: Option<f64>,
}

/// A current along the gripping direction (`Effect::ObjectFlow`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Flow {
    pub density_kg_m3: f64,
    pub mean_m_s: f64,
    pub gust_m_s: f64,
    pub period_s: f64,
    /// Declared gust components: (period s, amplitude m/s).
    pub spectrum: Vec<(f64, f64)>,
}

impl Effects {
    pub(crate) fn from_scene(scene: &SceneSpec) -> Self {
        let mut e = Self::default();
        for effect in &scene.effects {
            match *effect {
                Effect::Refraction { index } => e.image.refraction_index = Some(index),
                Effect::ColourAttenuation { per_m_rgb } => {
                    e.image.attenuation_per_m = Some(per_m_rgb)
                }
                Effect::Turbidity {
                    backscatter,
                    colour_rgb,
                } => e.image.turbidity = Some((backscatter, colour_rgb)),
                Effect::Caustics {
                    strength,
                    period_px,
                } => e.image.caustics = Some((strength, period_px)),
                Effect::Bubbles {
                    per_frame,
                    max_radius_px,
                } => e.image.bubbles = Some((per_frame, max_radius_px)),
                Effect::CameraNoise { sigma } => e.image.noise_sigma = Some(sigma),
                Effect::Exposure { gain } => e.image.exposure_gain = Some(gain),
                Effect::BackgroundClutter { objects } => e.image.clutter_objects = Some(objects),
                Effect::FtNoise {
                    force_sigma_n,
                    torque_sigma_nm,
                } => e.ft.noise = Some((force_sigma_n, torque_sigma_nm)),
                Effect::FtDrift {
                    force_n_per_h,
                    torque_nm_per_h,
                } => {
                    e.ft.drift_per_h = Some((force_n_per_h, torque_nm_per_h));
                }
                Effect::BuoyancyOffset { force_n, torque_nm } => {
                    e.ft.offset = Some((force_n, torque_nm))
                }
                Effect::FluidDrag {
                    coefficient,
                    flow_m_s,
                } => e.fluid_drag = Some((coefficient, flow_m_s)),
                Effect::FrameDrops { probability } => e.frame_drop_probability = Some(probability),
                Effect::FtPacketLoss { probability } => e.ft.packet_loss = Some(probability),
                Effect::Latency { camera_ms, ft_ms } => {
                    e.camera_latency_ms = Some(camera_ms);
                    e.ft.latency_ms = Some(ft_ms);
                }
                Effect::ArmReflex { probability } => e.arm_reflex_probability = Some(probability),
                Effect::ObjectBuoyancy {
                    fluid_density_kg_m3,
                } => e.object_buoyancy_kg_m3 = Some(fluid_density_kg_m3),
                Effect::ObjectDrag {
                    fluid_density_kg_m3,
                } => e.object_drag_kg_m3 = Some(fluid_density_kg_m3),
                Effect::WetContact {} => e.wet_contact = true,
                Effect::ObjectFlow {
                    fluid_density_kg_m3,
                    mean_m_s,
                    gust_m_s,
                    period_s,
                    ref spectrum,
                } => {
                    e.object_flow = Some(Flow {
                        density_kg_m3: fluid_density_kg_m3,
                        mean_m_s,
                        gust_m_s,
                        period_s,
                        spectrum: spectrum
                            .iter()
                            .flatten()
                            .map(|g| (g.period_s, g.amplitude_m_s))
                            .collect(),
                    });
                }
                Effect::ObjectSupport { friction } => e.support_friction = Some(friction),
                Effect::ObjectAddedMass {
                    fluid_density_kg_m3,
                } => e.object_added_mass_kg_m3 = Some(fluid_density_kg_m3),
            }
        }
        e
    }
}
