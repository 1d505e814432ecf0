//! Checking a scene: every field against its range, the effects' parameters, the
//! objects' names and what a declared effect needs of them.

use super::*;

/// Why an object's or a rod's name cannot be used, if it cannot: the verbs take them
/// comma-separated (`--objects a,b`, `--rods a,b`) and print them in tables and CSV
/// files.
pub(crate) fn name_problem(name: &str) -> Option<String> {
    if name.contains(',') {
        return Some(format!(
            "`{name}` contains a comma: names are given comma-separated (--objects, --rods), so this one could never be chosen"
        ));
    }
    if let Some(ch) = name.chars().find(|ch| ch.is_control()) {
        return Some(format!(
            "{name:?} contains the control character {ch:?}: expected printable text"
        ));
    }
    if name.trim() != name {
        return Some(format!(
            "{name:?} starts or ends with white space: expected the name as typed"
        ));
    }
    None
}

/// The lightest fluid a scene may declare, kg/m³ (air is 1.2): a density of 0 would
/// declare an effect that does nothing.
const FLUID_DENSITY_MIN_KG_M3: f64 = 1.0;

impl Validate for SceneSpec {
    fn validate(&self, c: &mut Check) {
        if self.name.trim().is_empty() {
            c.fail("name", "expected a non-empty name");
        } else if let Some(ch) = self.name.chars().find(|ch| ch.is_control()) {
            c.fail(
                "name",
                format!("contains the control character {ch:?}: expected printable text"),
            );
        }
        c.range("poses.x_m", &self.poses.x_m, "m");
        c.range("poses.z_m", &self.poses.z_m, "m");
        c.range("poses.theta_rad", &self.poses.theta_rad, "rad");
        let pi = std::f64::consts::PI;
        if self.poses.theta_rad.is_valid()
            && !Range::new(-pi, pi).contains_range(&self.poses.theta_rad)
        {
            c.fail("poses.theta_rad", "expected a range inside [-π, π]");
        }
        if self.rods.is_empty() {
            c.fail("rods", "expected at least one rod ([[rods]] table)");
        }
        let mut names = HashSet::new();
        for (i, rod) in self.rods.iter().enumerate() {
            if rod.name.trim().is_empty() {
                c.fail(format!("rods[{i}].name"), "expected a non-empty name");
            } else if let Some(why) = name_problem(&rod.name) {
                // `--rods` takes them comma-separated, as `--objects` does objects.
                c.fail(format!("rods[{i}].name"), why);
            }
            if !names.insert(rod.name.as_str()) {
                c.fail(
                    format!("rods[{i}].name"),
                    format!("rod name `{}` is used twice", rod.name),
                );
            }
            c.within(&format!("rods[{i}].size_m"), rod.size_m, 1e-3, 0.05, "m");
            c.within(&format!("rods[{i}].aspect"), rod.aspect, 0.2, 5.0, "");
            if rod.shape != RodShape::Oval && (rod.aspect - 1.0).abs() > f64::EPSILON {
                c.fail(
                    format!("rods[{i}].aspect"),
                    "only an oval rod takes an aspect other than 1",
                );
            }
        }
        let mut object_names = HashSet::new();
        for (i, o) in self.objects.iter().enumerate() {
            let f = |name: &str| format!("objects[{i}].{name}");
            if o.name.trim().is_empty() {
                c.fail(f("name"), "expected a non-empty name");
            }
            if let Some(why) = name_problem(&o.name) {
                c.fail(f("name"), why);
            }
            if !object_names.insert(o.name.as_str()) {
                c.fail(f("name"), format!("object name `{}` is used twice", o.name));
            }
            match (&o.profile, o.size_m) {
                (None, Some(size)) => c.within(&f("size_m"), size, 1e-3, 0.05, "m"),
                (None, None) => c.fail(
                    f("size_m"),
                    "expected the face's extent along the finger, m, for an object lying across the finger (or a `profile` for a standing one)",
                ),
                (Some(_), Some(_)) => c.fail(
                    f("size_m"),
                    "a standing object (with a `profile`) takes no size_m: its section is width_m across and width_m × aspect deep",
                ),
                (Some(_), None) => {}
            }
            c.within(&f("aspect"), o.aspect, 0.2, 5.0, "");
            if o.shape != RodShape::Oval && (o.aspect - 1.0).abs() > f64::EPSILON {
                c.fail(
                    f("aspect"),
                    "only an oval face takes an aspect other than 1",
                );
            }
            // The Hand-E opens 50 mm.
            c.within(&f("width_m"), o.width_m, 1e-3, 0.049, "m");
            c.within(&f("contact_z_m"), o.contact_z_m, -0.05, 0.05, "m");
            c.within(&f("mass_kg"), o.mass_kg, 1e-4, 10.0, "kg");
            c.within(&f("friction"), o.friction, 0.0, 2.0, "");
            if let Some(wet) = o.wet_friction {
                c.within(&f("wet_friction"), wet, 0.0, 2.0, "");
            } else if self
                .effects
                .iter()
                .any(|e| matches!(e, Effect::WetContact {}))
            {
                c.fail(
                    f("wet_friction"),
                    "the scene declares wet_contact: expected this object's friction against the finger's silicone in water",
                );
            }
            if let Some(mu) = o.support_friction {
                c.within(&f("support_friction"), mu, 0.0, 2.0, "");
            }
            if let Some(surface) = &o.surface
                && (surface.trim().is_empty() || surface.chars().any(char::is_control))
            {
                c.fail(f("surface"), "expected a description in printable text");
            }
            if let Some(crush) = o.crush_force_n {
                c.positive(&f("crush_force_n"), crush, "N");
            }
            match o.profile {
                Some(ObjectProfile::Prism { height_m }) => {
                    c.within(&f("profile.height_m"), height_m, 0.005, 0.5, "m");
                }
                Some(ObjectProfile::Taper {
                    height_m,
                    top_width_m,
                }) => {
                    c.within(&f("profile.height_m"), height_m, 0.005, 0.5, "m");
                    c.within(&f("profile.top_width_m"), top_width_m, 1e-3, 0.049, "m");
                }
                Some(ObjectProfile::Sphere {}) if o.shape != RodShape::Circle => c.fail(
                    f("shape"),
                    "a sphere's section is a circle: expected shape = \"circle\"",
                ),
                Some(ObjectProfile::Sphere {}) | None => {}
            }
            if let Some(h) = o.grasp_height_m {
                match o.profile {
                    Some(p) => {
                        let top = p.height_m(o.width_m);
                        // At the tray itself the fingers would close on the tray.
                        c.within(&f("grasp_height_m"), h, 1e-3, top, "m");
                    }
                    None => c.fail(
                        f("grasp_height_m"),
                        "only a standing object (with a `profile`) takes a grasp height",
                    ),
                }
            }
            if let Some(g) = o.grasp_width_m {
                c.within(&f("grasp_width_m"), g, 0.0, 0.05, "m");
            }
            if let Some(v) = o.volume_m3 {
                c.within(&f("volume_m3"), v, 1e-9, 0.01, "m³");
            }
            if let Some(cd) = o.drag_coefficient {
                c.within(&f("drag_coefficient"), cd, 0.0, 10.0, "");
            }
            if let Some(a) = o.drag_area_m2 {
                c.within(&f("drag_area_m2"), a, 1e-8, 0.1, "m²");
            }
        }
        let mut kinds = HashSet::new();
        // A scene has one fluid: every effect that names its density names the same.
        let mut fluid: Option<(usize, &'static str, f64)> = None;
        for (i, e) in self.effects.iter().enumerate() {
            let at = format!("effects[{i}]");
            if !kinds.insert(e.kind()) {
                c.fail(
                    format!("{at}.kind"),
                    format!("effect `{}` is declared twice", e.kind()),
                );
            }
            e.validate(c, &at);
            let Some(rho) = e.fluid_density_kg_m3() else {
                continue;
            };
            match fluid {
                None => fluid = Some((i, e.kind(), rho)),
                Some((j, kind, first)) if rho.to_bits() != first.to_bits() => c.fail(
                    format!("{at}.fluid_density_kg_m3"),
                    format!(
                        "{rho} kg/m³, but effects[{j}] (`{kind}`) declares {first} kg/m³: a scene has one fluid, so every effect's fluid_density_kg_m3 must be the same"
                    ),
                ),
                Some(_) => {}
            }
        }
    }
}

impl Effect {
    fn validate(&self, c: &mut Check, at: &str) {
        let f = |name: &str| format!("{at}.{name}");
        match self {
            Self::Refraction { index } => c.within(&f("index"), *index, 1.0, 3.0, ""),
            Self::ColourAttenuation { per_m_rgb } => {
                for (i, v) in per_m_rgb.iter().enumerate() {
                    c.within(&f(&format!("per_m_rgb[{i}]")), *v, 0.0, 100.0, "1/m");
                }
            }
            Self::Turbidity { backscatter, .. } => {
                c.within(&f("backscatter"), *backscatter, 0.0, 1.0, "")
            }
            Self::Caustics {
                strength,
                period_px,
            } => {
                c.within(&f("strength"), *strength, 0.0, 1.0, "");
                c.within(&f("period_px"), *period_px, 2.0, 10_000.0, "px");
            }
            Self::Bubbles {
                per_frame,
                max_radius_px,
            } => {
                c.within(&f("per_frame"), *per_frame, 0.0, 1000.0, "");
                c.within(&f("max_radius_px"), *max_radius_px, 0.5, 200.0, "px");
            }
            Self::CameraNoise { sigma } => c.within(&f("sigma"), *sigma, 0.0, 255.0, ""),
            Self::Exposure { gain } => c.within(&f("gain"), *gain, 0.01, 100.0, ""),
            Self::BackgroundClutter { objects } => {
                if *objects > 10_000 {
                    c.fail(
                        f("objects"),
                        format!("expected at most 10000, found {objects}"),
                    );
                }
            }
            Self::FtNoise {
                force_sigma_n,
                torque_sigma_nm,
            } => {
                c.non_negative(&f("force_sigma_n"), *force_sigma_n, "N");
                c.non_negative(&f("torque_sigma_nm"), *torque_sigma_nm, "N·m");
            }
            Self::FtDrift {
                force_n_per_h,
                torque_nm_per_h,
            } => {
                c.within(&f("force_n_per_h"), *force_n_per_h, -1e3, 1e3, "N/h");
                c.within(&f("torque_nm_per_h"), *torque_nm_per_h, -1e2, 1e2, "N·m/h");
            }
            Self::BuoyancyOffset { force_n, torque_nm } => {
                for i in 0..3 {
                    c.within(&f(&format!("force_n[{i}]")), force_n[i], -100.0, 100.0, "N");
                    c.within(
                        &f(&format!("torque_nm[{i}]")),
                        torque_nm[i],
                        -10.0,
                        10.0,
                        "N·m",
                    );
                }
            }
            Self::FluidDrag {
                coefficient,
                flow_m_s,
            } => {
                c.non_negative(&f("coefficient"), *coefficient, "N·s²/m²");
                c.within(&f("flow_m_s"), *flow_m_s, -10.0, 10.0, "m/s");
            }
            Self::ObjectBuoyancy {
                fluid_density_kg_m3,
            }
            | Self::ObjectDrag {
                fluid_density_kg_m3,
            }
            | Self::ObjectAddedMass {
                fluid_density_kg_m3,
            } => c.within(
                &f("fluid_density_kg_m3"),
                *fluid_density_kg_m3,
                FLUID_DENSITY_MIN_KG_M3,
                20_000.0,
                "kg/m³",
            ),
            Self::ObjectFlow {
                fluid_density_kg_m3,
                mean_m_s,
                gust_m_s,
                period_s,
                spectrum,
            } => {
                c.within(
                    &f("fluid_density_kg_m3"),
                    *fluid_density_kg_m3,
                    FLUID_DENSITY_MIN_KG_M3,
                    20_000.0,
                    "kg/m³",
                );
                c.within(&f("mean_m_s"), *mean_m_s, -10.0, 10.0, "m/s");
                c.within(&f("gust_m_s"), *gust_m_s, 0.0, 10.0, "m/s");
                c.within(&f("period_s"), *period_s, 0.01, 1000.0, "s");
                if spectrum.as_ref().is_some_and(Vec::is_empty) {
                    c.fail(
                        f("spectrum"),
                        "expected at least one component (leave `spectrum` out for a steady current or gusts from gust_m_s/period_s)",
                    );
                }
                let spectrum = spectrum.as_deref().unwrap_or_default();
                if !spectrum.is_empty() && *gust_m_s != 0.0 {
                    c.fail(
                        f("spectrum"),
                        "expected the gusts either as gust_m_s/period_s or as a spectrum, not both",
                    );
                }
                if spectrum.len() > 64 {
                    c.fail(
                        f("spectrum"),
                        format!("expected at most 64 components, found {}", spectrum.len()),
                    );
                }
                for (i, g) in spectrum.iter().enumerate() {
                    c.within(
                        &f(&format!("spectrum[{i}].period_s")),
                        g.period_s,
                        0.01,
                        1000.0,
                        "s",
                    );
                    c.within(
                        &f(&format!("spectrum[{i}].amplitude_m_s")),
                        g.amplitude_m_s,
                        0.0,
                        10.0,
                        "m/s",
                    );
                }
            }
            Self::ObjectSupport { friction } => c.within(&f("friction"), *friction, 0.0, 2.0, ""),
            Self::WetContact {} => {}
            Self::FrameDrops { probability }
            | Self::FtPacketLoss { probability }
            | Self::ArmReflex { probability } => {
                c.within(&f("probability"), *probability, 0.0, 1.0, "")
            }
            Self::Latency { camera_ms, ft_ms } => {
                c.within(&f("camera_ms"), *camera_ms, 0.0, 10_000.0, "ms");
                c.within(&f("ft_ms"), *ft_ms, 0.0, 10_000.0, "ms");
            }
        }
    }
}
