//! The objects the soft fingers grasp: their width across the fingers along the
//! finger (the object's height), their horizontal section (which turns with the
//! object's yaw), mass, friction, crush limit and what a fluid needs (volume, drag
//! coefficient and area).
//!
//! Gripper frame G: the fingers close along x (finger 0 on the −x side, finger 1 on
//! the +x side), y runs across the fingers' faces, z runs along the fingers towards
//! their tips (down, for a grasp from above). Yaw is the object's turn about G's z.

use super::super::SimError;
use super::super::contact::RodProfile;
use super::touch::Grip;
use softtouch_drivers::gripper::STROKE_MM;
use softtouch_schemas::scene::{ObjectProfile, ObjectSpec};
use softtouch_schemas::{RodShape, RodSpec};

/// How far below the width at the grasp point the open-loop grasp closes by default, m.
const DEFAULT_SQUEEZE_M: f64 = 0.002;
/// Vertices within this of the support line share the contact (a flat face), m.
const FACE_TOLERANCE_M: f64 = 2e-4;

/// An object to grasp.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspObject {
    /// Name.
    pub name: String,
    /// Cross-section: of the face along the finger (lying objects, `profile` `None`) or
    /// the horizontal section (standing objects).
    pub shape: RodShape,
    /// Extent of the face along the finger, m (lying objects; a cylinder's diameter).
    pub size_m: f64,
    /// Depth over width of an oval face or section (1 otherwise).
    pub aspect: f64,
    /// Width across the fingers, m: at the grasp point (lying objects, prisms), at the
    /// bottom (tapers), the diameter (spheres).
    pub width_m: f64,
    /// Where along the finger the grasp point sits (contact pose z, m, in [−0.05, 0.05]).
    pub contact_z_m: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Friction coefficient against the finger (0 is allowed: nothing can be lifted).
    pub friction: f64,
    /// Squeeze on one finger that crushes it, N (`None`: rigid).
    pub crush_force_n: Option<f64>,
    /// How a standing object's section changes along its height; `None`: it lies
    /// across the finger.
    pub profile: Option<ObjectProfile>,
    /// Height of the grasp point above the support, m (standing objects).
    pub grasp_height_m: f64,
    /// Opening of the open-loop grasp, m (Figure 4e).
    pub grasp_width_m: f64,
    /// Volume of fluid it displaces, m³.
    pub volume_m3: f64,
    /// Drag coefficient C_d across the object (a current along the gripping
    /// direction; a lying object's lift).
    pub drag_coefficient: f64,
    /// Drag coefficient C_d along a standing object's axis (its lift, end-on); a
    /// lying object's is `drag_coefficient`.
    pub lift_drag_coefficient: f64,
    /// Area the fluid's drag acts on, m².
    pub drag_area_m2: f64,
    /// Area a current along the gripping direction (x) meets, m²: the object's
    /// outline seen along x (its side, for a standing object), not its top.
    pub flow_area_m2: f64,
    /// Friction coefficient against the finger's silicone in water, where known (the
    /// grasp uses it in place of `friction` when its scene declares `wet_contact`).
    pub wet_friction: Option<f64>,
    /// Where the grasp point sits from where the fingers meet it, m, in G (see
    /// [`GraspObject::placed`]).
    pub offset_m: [f64; 3],
    /// Friction coefficient against its support where it differs from the scene's
    /// `object_support` (a ball's rolling resistance).
    pub support_friction: Option<f64>,
    /// Added-mass coefficients `C_a` along G's x (the closing direction, a current)
    /// and z (the lift): the fluid an accelerating object carries is `C_a·ρ·V`.
    pub added_mass_xz: [f64; 2],
}

impl GraspObject {
    /// A rigid cylinder lying across the fingers (its axis along G's y), its round
    /// face along the finger: the grasp the rod presses stand for.
    #[must_use]
    pub fn cylinder(name: &str, diameter_m: f64) -> Self {
        let mut o = Self {
            name: name.to_owned(),
            shape: RodShape::Circle,
            size_m: diameter_m,
            aspect: 1.0,
            width_m: diameter_m,
            contact_z_m: 0.0,
            mass_kg: 0.05,
            friction: 0.5,
            crush_force_n: None,
            profile: None,
            grasp_height_m: 0.0,
            grasp_width_m: 0.0,
            volume_m3: 0.0,
            drag_coefficient: 0.0,
            lift_drag_coefficient: 0.0,
            drag_area_m2: 0.0,
            flow_area_m2: 0.0,
            wet_friction: None,
            offset_m: [0.0; 3],
            support_friction: None,
            added_mass_xz: [0.5; 2],
        };
        o.fill_defaults(None, None, None, None, None);
        o
    }

    /// A standing object with `profile`: its section is `shape`, `width_m` across the
    /// fingers and `width_m × aspect` deep, grasped at mid-height (a sphere at its
    /// centre), mass 50 g, friction 0.5.
    #[must_use]
    pub fn standing(
        name: &str,
        shape: RodShape,
        width_m: f64,
        aspect: f64,
        profile: ObjectProfile,
    ) -> Self {
        let mut o = Self {
            profile: Some(profile),
            shape,
            width_m,
            size_m: width_m,
            aspect,
            ..Self::cylinder(name, width_m)
        };
        o.fill_defaults(None, None, None, None, None);
        o
    }

    /// The object a scene declares (`[[objects]]`), defaults filled in.
    #[must_use]
    pub fn from_spec(spec: &ObjectSpec) -> Self {
        let mut o = Self {
            name: spec.name.clone(),
            shape: spec.shape,
            size_m: spec.size_m.unwrap_or(spec.width_m),
            aspect: spec.aspect,
            width_m: spec.width_m,
            contact_z_m: spec.contact_z_m,
            mass_kg: spec.mass_kg,
            friction: spec.friction,
            crush_force_n: spec.crush_force_n,
            profile: spec.profile,
            grasp_height_m: 0.0,
            grasp_width_m: 0.0,
            volume_m3: 0.0,
            drag_coefficient: 0.0,
            lift_drag_coefficient: 0.0,
            drag_area_m2: 0.0,
            flow_area_m2: 0.0,
            wet_friction: spec.wet_friction,
            offset_m: [0.0; 3],
            support_friction: spec.support_friction,
            added_mass_xz: [0.5; 2],
        };
        o.fill_defaults(
            spec.grasp_height_m,
            spec.grasp_width_m,
            spec.volume_m3,
            spec.drag_area_m2,
            spec.drag_coefficient,
        );
        o
    }

    /// Fills the derived quantities from the geometry where they are not given.
    fn fill_defaults(
        &mut self,
        grasp_height_m: Option<f64>,
        grasp_width_m: Option<f64>,
        volume_m3: Option<f64>,
        drag_area_m2: Option<f64>,
        drag_coefficient: Option<f64>,
    ) {
        self.grasp_height_m = grasp_height_m.unwrap_or(match self.profile {
            Some(p) => 0.5 * p.height_m(self.width_m),
            None => 0.0,
        });
        let at_grasp = 2.0
            * self
                .half_width_at(0.0, 0.0, 0)
                .map_or(self.width_m, |s| s.0);
        self.grasp_width_m = grasp_width_m.unwrap_or((at_grasp - DEFAULT_SQUEEZE_M).max(0.0));
        // Section area of a unit-width section (scaled by width² below).
        let unit_area = self.unit_section_area();
        let w = self.width_m;
        // The section's depth across y, over its width across x.
        let depth = self.section_aspect();
        // (volume, area seen from above: the lift's drag, area seen along x: a
        // current's along the gripping direction)
        let (volume, area, side) = match self.profile {
            // Lying: the face's section, as long as it is wide (along y).
            None => {
                let face = unit_area * self.size_m * self.size_m;
                (face * w, self.size_m * w, self.size_m * w)
            }
            Some(ObjectProfile::Prism { height_m }) => (
                unit_area * w * w * height_m,
                unit_area * w * w,
                depth * w * height_m,
            ),
            Some(ObjectProfile::Sphere {}) => {
                let r = 0.5 * w;
                let disc = std::f64::consts::PI * r * r;
                (4.0 / 3.0 * std::f64::consts::PI * r.powi(3), disc, disc)
            }
            Some(ObjectProfile::Taper {
                height_m,
                top_width_m,
            }) => {
                // A frustum of similar sections: area scales with width², its outline
                // from the side is a trapezoid.
                let k = top_width_m / w;
                let bottom = unit_area * w * w;
                (
                    bottom * height_m * (1.0 + k + k * k) / 3.0,
                    bottom * k.max(1.0).powi(2),
                    depth * 0.5 * (w + top_width_m) * height_m,
                )
            }
        };
        self.volume_m3 = volume_m3.unwrap_or(volume);
        self.drag_area_m2 = drag_area_m2.unwrap_or(area);
        self.flow_area_m2 = side;
        // Added mass of the spheroid of the object's length and volume, its axis
        // upright for a standing object (x is across it, z along it) and along y for a
        // lying one (x and z both across it).
        let length = match self.profile {
            Some(p) => p.height_m(self.width_m),
            None => w,
        };
        // A spheroid's volume is π/6·L·D² (a sphere's π/6·D³), not a cylinder's π/4·L·D².
        let diameter = (6.0 * self.volume_m3 / (std::f64::consts::PI * length)).sqrt();
        let (along, across) = spheroid_added_mass(length / diameter);
        self.added_mass_xz = match self.profile {
            Some(_) => [across, along],
            None => [across, across],
        };
        // A lying object meets the current and its lift across its length `w`; a
        // standing one meets the current across its height and its lift end-on.
        let [across, end_on] =
            default_drag_coefficients(self.shape, self.profile, length / self.size_m.max(1e-9));
        self.drag_coefficient = drag_coefficient.unwrap_or(across);
        self.lift_drag_coefficient = drag_coefficient.unwrap_or(match self.profile {
            Some(_) => end_on,
            None => across,
        });
    }

    /// Area of the section at width 1 (depth `aspect`).
    fn unit_section_area(&self) -> f64 {
        let a = self.section_aspect();
        match self.shape {
            RodShape::Circle | RodShape::Oval => std::f64::consts::PI / 4.0 * a,
            RodShape::Square => a,
            // Across-flats 1: side 1/√3.
            RodShape::Hexagon => 3.0_f64.sqrt() / 2.0,
            // Height 1: side 2/√3.
            RodShape::Triangle => 1.0 / 3.0_f64.sqrt(),
        }
    }

    fn section_aspect(&self) -> f64 {
        if self.shape == RodShape::Oval {
            self.aspect
        } else {
            1.0
        }
    }

    /// Refuses an object lighter than the fluid it displaces (`fluid_density_kg_m3`,
    /// where the scene declares `object_buoyancy`): the simulator stands objects on the
    /// tray and does not model one floating up from it.
    ///
    /// # Errors
    /// The object floats: its mass, volume and density against the fluid's.
    pub fn sinks_in(&self, fluid_density_kg_m3: Option<f64>) -> Result<(), SimError> {
        let Some(rho) = fluid_density_kg_m3 else {
            return Ok(());
        };
        let displaced_kg = rho * self.volume_m3;
        // Neutrally buoyant (to rounding) rests on the tray with no weight: modelled.
        if displaced_kg <= self.mass_kg * (1.0 + 1e-9) {
            return Ok(());
        }
        Err(SimError::InvalidParameter(format!(
            "object `{}`: {:.1} g in {:.1} cm³ ({:.0} kg/m³) floats in this scene's fluid ({rho} kg/m³: buoyancy {:.3} N against a weight of {:.3} N); the simulator stands objects on the tray and does not model a floating one: declare the mass it has in the fluid (soaked, or weighted down) in its mass_kg",
            self.name,
            self.mass_kg * 1e3,
            self.volume_m3 * 1e6,
            self.mass_kg / self.volume_m3,
            displaced_kg * crate::G_M_S2,
            self.mass_kg * crate::G_M_S2,
        )))
    }

    pub(crate) fn validate(&self) -> Result<(), SimError> {
        let bad = |field: &str, v: f64, expected: &str| {
            Err(SimError::InvalidParameter(format!(
                "object `{}`: {field} = {v}: expected {expected}",
                self.name
            )))
        };
        let positive = [
            ("size_m", self.size_m),
            ("aspect", self.aspect),
            ("width_m", self.width_m),
            ("mass_kg", self.mass_kg),
            ("volume_m3", self.volume_m3),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, v, "a finite value above 0");
            }
        }
        for (field, v) in [
            ("friction", self.friction),
            ("drag_coefficient", self.drag_coefficient),
            ("lift_drag_coefficient", self.lift_drag_coefficient),
            ("drag_area_m2", self.drag_area_m2),
            ("flow_area_m2", self.flow_area_m2),
            ("grasp_width_m", self.grasp_width_m),
            ("wet_friction", self.wet_friction.unwrap_or(0.0)),
            ("support_friction", self.support_friction.unwrap_or(0.0)),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, v, "a finite value ≥ 0");
            }
        }
        if self.max_width_m() * 1000.0 >= STROKE_MM {
            return bad(
                "width_m",
                self.max_width_m(),
                &format!("less than the stroke, {} m", STROKE_MM / 1000.0),
            );
        }
        if !(self.contact_z_m.is_finite() && self.contact_z_m.abs() <= 0.05) {
            return bad(
                "contact_z_m",
                self.contact_z_m,
                "a value in [−0.05, 0.05] m",
            );
        }
        if let Some(c) = self.crush_force_n
            && !(c.is_finite() && c > 0.0)
        {
            return bad("crush_force_n", c, "a finite value above 0");
        }
        if self.offset_m.iter().any(|v| !v.is_finite()) {
            return Err(SimError::InvalidParameter(format!(
                "object `{}`: offset_m = {:?}: expected finite values",
                self.name, self.offset_m
            )));
        }
        if let Some(p) = self.profile {
            let h = p.height_m(self.width_m);
            if !(h.is_finite() && h > 0.0) {
                return bad("profile.height_m", h, "a finite value above 0");
            }
            if !(self.grasp_height_m.is_finite() && (0.0..=h).contains(&self.grasp_height_m)) {
                return bad(
                    "grasp_height_m",
                    self.grasp_height_m,
                    &format!("a height in [0, {h}] m"),
                );
            }
            if let ObjectProfile::Taper { top_width_m, .. } = p
                && !(top_width_m.is_finite() && top_width_m > 0.0)
            {
                return bad("profile.top_width_m", top_width_m, "a finite value above 0");
            }
        }
        RodProfile::new(&self.face_rod()).map(|_| ())
    }

    /// The widest width across the fingers, m.
    #[must_use]
    pub fn max_width_m(&self) -> f64 {
        let section = self.max_section_extent();
        match self.profile {
            None => self.width_m,
            Some(p) => p.max_width_m(self.width_m) * section,
        }
    }

    /// The largest extent of a unit-width section in any direction (it may turn).
    fn max_section_extent(&self) -> f64 {
        let a = self.section_aspect();
        match self.shape {
            RodShape::Circle | RodShape::Oval => a.max(1.0),
            RodShape::Square => (1.0 + a * a).sqrt(),
            RodShape::Hexagon => 2.0 / 3.0_f64.sqrt(),
            RodShape::Triangle => 1.0,
        }
    }

    /// The face of a lying object as a rod (the rod presses' gap profile).
    pub(crate) fn face_rod(&self) -> RodSpec {
        RodSpec {
            name: self.name.clone(),
            shape: self.shape,
            size_m: self.size_m,
            aspect: self.section_aspect(),
        }
    }

    /// Height of the object, m (a lying object: the extent of its face).
    #[must_use]
    pub fn height_m(&self) -> f64 {
        self.profile
            .map_or(self.size_m, |p| p.height_m(self.width_m))
    }

    /// Width of a standing object's section across the fingers at height `u` above
    /// the support (yaw 0), m; `None` above or below it.
    fn width_at_height(&self, u: f64) -> Option<f64> {
        let p = self.profile?;
        let h = p.height_m(self.width_m);
        if !(0.0..=h).contains(&u) {
            return None;
        }
        Some(match p {
            ObjectProfile::Prism { .. } => self.width_m,
            ObjectProfile::Sphere {} => {
                let r = 0.5 * self.width_m;
                2.0 * (r * r - (u - r) * (u - r)).max(0.0).sqrt()
            }
            ObjectProfile::Taper { top_width_m, .. } => {
                self.width_m + (top_width_m - self.width_m) * u / h
            }
        })
    }

    /// The object's surface facing finger `finger` (0: on G's −x side, 1: on +x) at
    /// offset `q` along the finger from the grasp point (towards the tip), the object
    /// turned by `yaw_rad` about z: `(half-width across the fingers, y of the contact
    /// line in G)`, m, before the placement offset. `None` where there is no material.
    /// A lying object's face is the rod presses' gap profile (its flanks slope away
    /// steeply beyond its extent, so the half-width there is small or negative).
    pub(crate) fn half_width_at(&self, q: f64, yaw_rad: f64, finger: usize) -> Option<(f64, f64)> {
        self.facing(yaw_rad, finger).half_width_at(self, q)
    }

    /// What of the object faces finger `finger` when it is turned by `yaw_rad`: the
    /// part of [`Self::half_width_at`] that does not change along the finger, worked
    /// out once per contact instead of once per strip.
    pub(crate) fn facing(&self, yaw_rad: f64, finger: usize) -> Facing {
        match self.profile {
            None => Facing::Lying(RodProfile::new(&self.face_rod()).ok()),
            Some(_) => Facing::Standing(self.section_support(yaw_rad, finger)),
        }
    }

    /// Support of the unit-width section turned by `yaw_rad`, towards finger `finger`:
    /// `(half-width, y of the contact point in G)` per unit width.
    fn section_support(&self, yaw_rad: f64, finger: usize) -> (f64, f64) {
        let (s, c) = yaw_rad.sin_cos();
        let sign = if finger == 0 { -1.0 } else { 1.0 };
        // The direction towards the finger, in the object's own frame: R(−yaw)·(±1, 0).
        let d = [sign * c, -sign * s];
        let to_g = |p: [f64; 2]| s * p[0] + c * p[1];
        let a = self.section_aspect();
        match self.shape {
            RodShape::Circle | RodShape::Oval => {
                let (ax, by) = (0.5, 0.5 * a);
                let h = (ax * ax * d[0] * d[0] + by * by * d[1] * d[1]).sqrt();
                let p = [ax * ax * d[0] / h, by * by * d[1] / h];
                (h, to_g(p))
            }
            shape => {
                let verts = unit_polygon(shape, a);
                let h = verts
                    .iter()
                    .map(|v| v[0] * d[0] + v[1] * d[1])
                    .fold(f64::NEG_INFINITY, f64::max);
                // A face flat against the finger: its middle carries the contact.
                let tol = FACE_TOLERANCE_M / self.width_m.max(1e-6);
                let near: Vec<&[f64; 2]> = verts
                    .iter()
                    .filter(|v| v[0] * d[0] + v[1] * d[1] >= h - tol)
                    .collect();
                let n = near.len() as f64;
                let mid = [
                    near.iter().map(|v| v[0]).sum::<f64>() / n,
                    near.iter().map(|v| v[1]).sum::<f64>() / n,
                ];
                (h, to_g(mid))
            }
        }
    }

    /// The object as the fingers meet it when the grasp point is moved by `offset_m`
    /// (x: along the gripping direction, y: across the fingers, z: along the finger
    /// towards its tip), m. `None`: the fingers miss it — an open finger lands on it
    /// (`|x|` beyond the room the open stroke leaves), or the closed fingers would not
    /// touch it at all (off the fingers' faces across, above or below them along z).
    /// Inside the stroke, on a frictionless support (the scene lists no
    /// `object_support`), an x offset changes nothing once gripped: the first finger to
    /// touch slides the object to the middle. On a support with friction the object
    /// starts where the offset puts it and the physics moves it.
    #[must_use]
    pub fn placed(&self, offset_m: [f64; 3]) -> Option<GraspObject> {
        if offset_m.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut o = self.clone();
        for i in 0..3 {
            o.offset_m[i] += offset_m[i];
        }
        // The fully open fingers come down around the object moved by x: a finger that
        // already presses it there lands on it. The finger's own section over its
        // length decides, with the object as it stands (yaw 0), so only what the
        // fingers' faces pass counts (a bottle's wide base below the tips does not).
        let open = Grip {
            opening_m: STROKE_MM / 1000.0,
            // Grip's shift is along G's −x, towards finger 0.
            shift_m: -o.offset_m[0],
            yaw_rad: 0.0,
        };
        if (0..2).any(|k| o.touches_at(k, &open)) {
            return None;
        }
        let closed = Grip::default();
        (0..2).any(|k| o.touches_at(k, &closed)).then_some(o)
    }

    /// Whether finger `k` (the default finger) presses the object at `grip`.
    fn touches_at(&self, k: usize, grip: &Grip) -> bool {
        let finger = super::super::FingerGeometry::default();
        super::touch::reaches_finger(&finger, self, k, grip)
    }
}

/// The drag coefficient C_d of an infinitely long body of `shape`'s section, a face
/// towards the flow, in the subcritical range a grasp's currents and lifts reach (a
/// 30 mm object at 0.01–0.3 m/s in water: Re ≈ 300–9 000): F. M. White, *Fluid
/// Mechanics* (7th ed., 2011), Table 7.2 (two-dimensional bodies, Re ≥ 10⁴: a circle
/// 1.2, a square 2.1, an equilateral triangle 2.0, a hexagon 1.0); an oval is taken as
/// its circle. A sphere's is Table 7.3's 0.47. What an object of finite length sees is
/// [`default_drag_coefficients`].
#[must_use]
pub fn default_drag_coefficient(shape: RodShape, profile: Option<ObjectProfile>) -> f64 {
    if matches!(profile, Some(ObjectProfile::Sphere {})) {
        return 0.47;
    }
    match shape {
        RodShape::Circle | RodShape::Oval => 1.2,
        RodShape::Square => 2.1,
        RodShape::Triangle => 2.0,
        RodShape::Hexagon => 1.0,
    }
}

/// White (2011) Table 7.3, three-dimensional bodies, Re ≥ 10⁴: a short circular
/// cylinder crosswise, `(L/D, C_d)` (∞: 1.2, the two-dimensional value).
const CROSSWISE_L_D: [(f64, f64); 8] = [
    (1.0, 0.64),
    (2.0, 0.68),
    (3.0, 0.72),
    (5.0, 0.74),
    (10.0, 0.82),
    (20.0, 0.91),
    (40.0, 0.98),
    (1e6, 1.2),
];

/// The same table's flat-faced cylinder end-on (along its axis), `(L/D, C_d)`.
const END_ON_L_D: [(f64, f64); 5] = [
    (0.5, 1.15),
    (1.0, 0.90),
    (2.0, 0.85),
    (4.0, 0.87),
    (8.0, 0.99),
];

/// Piecewise linear in ln(L/D) through `table`, held at its ends.
fn by_slenderness(table: &[(f64, f64)], l_over_d: f64) -> f64 {
    let x = l_over_d.clamp(table[0].0, table[table.len() - 1].0);
    for w in table.windows(2) {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if x <= x1 {
            let t = (x.ln() - x0.ln()) / (x1.ln() - x0.ln());
            return y0 + t * (y1 - y0);
        }
    }
    table[table.len() - 1].1
}

/// The drag coefficients `[across, end-on]` of an object with no `drag_coefficient` of
/// its own, `l_over_d` its length along its axis over its width (a standing object's
/// height, a lying one's length across the fingers): a short body lets the flow pass
/// round its ends, so it sees far less than the two-dimensional value. Across: the
/// section's two-dimensional value ([`default_drag_coefficient`]) times the short
/// circular cylinder's share of its own (White 2011, Table 7.3: 0.64, 0.68, 0.72, 0.74
/// of 1.2 at L/D 1, 2, 3, 5; Hoerner, *Fluid-Dynamic Drag* (1965), reduces every
/// prism's drag for its finite length alike); a square at L/D 1 so comes to 1.12 against
/// the table's cube, 1.07. End-on (a standing object's lift): the flat-faced cylinder
/// (1.15, 0.90, 0.85, 0.87, 0.99 at L/D 0.5, 1, 2, 4, 8). A sphere: 0.47 either way. A
/// slenderness that is not finite and positive is taken as 1.
#[must_use]
pub fn default_drag_coefficients(
    shape: RodShape,
    profile: Option<ObjectProfile>,
    l_over_d: f64,
) -> [f64; 2] {
    if matches!(profile, Some(ObjectProfile::Sphere {})) {
        return [0.47; 2];
    }
    let l_over_d = if l_over_d.is_finite() && l_over_d > 0.0 {
        l_over_d
    } else {
        1.0
    };
    let share = by_slenderness(&CROSSWISE_L_D, l_over_d) / 1.2;
    [
        default_drag_coefficient(shape, profile) * share,
        by_slenderness(&END_ON_L_D, l_over_d),
    ]
}

/// Added-mass coefficients `(along its axis, across it)` of a spheroid whose length
/// along its axis over its diameter is `ratio`, in potential flow, as fractions of the
/// displaced fluid's mass: Lamb, *Hydrodynamics* (6th ed., 1932) §373; Newman, *Marine
/// Hydrodynamics* (1977) §4.15. A sphere's are both ½; a 2:1 prolate spheroid's
/// 0.210 and 0.704. With `α₀ + 2β₀ = 2`, `C_a = α₀/(2 − α₀)` along the axis and
/// `β₀/(2 − β₀)` across it. A ratio that is not finite and positive gives a sphere's.
#[must_use]
pub fn spheroid_added_mass(ratio: f64) -> (f64, f64) {
    if !(ratio.is_finite() && ratio > 0.0) {
        return (0.5, 0.5);
    }
    // A needle or a disc a million to one is as far as the closed forms stay finite.
    let ratio = ratio.clamp(1e-6, 1e6);
    // Eccentricity of the meridian ellipse; near a sphere the closed forms cancel.
    let e2 = if ratio >= 1.0 {
        1.0 - 1.0 / (ratio * ratio)
    } else {
        1.0 - ratio * ratio
    };
    if e2 < 1e-6 {
        return (0.5, 0.5);
    }
    let e = e2.sqrt();
    let (alpha, beta) = if ratio >= 1.0 {
        // Prolate: the axis is the long one.
        let log = ((1.0 + e) / (1.0 - e)).ln();
        let alpha = 2.0 * (1.0 - e2) / (e2 * e) * (0.5 * log - e);
        (alpha, 0.5 * (2.0 - alpha))
    } else {
        // Oblate: the axis is the short one.
        let alpha = 2.0 / e2 * (1.0 - (1.0 - e2).sqrt() / e * e.asin());
        (alpha, 0.5 * (2.0 - alpha))
    };
    let k = |c: f64| c / (2.0 - c).max(f64::MIN_POSITIVE);
    (k(alpha), k(beta))
}

/// The side of an object facing one finger ([`GraspObject::facing`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Facing {
    /// A lying object's face: the rod presses' gap profile (`None`: not a valid rod).
    Lying(Option<RodProfile>),
    /// A standing object's section: (half-width, y of the contact) per unit width.
    Standing((f64, f64)),
}

impl Facing {
    /// [`GraspObject::half_width_at`] at offset `q` along the finger, m.
    pub(crate) fn half_width_at(&self, obj: &GraspObject, q: f64) -> Option<(f64, f64)> {
        match self {
            Self::Lying(rod) => Some((0.5 * obj.width_m - rod.as_ref()?.gap(q), 0.0)),
            Self::Standing((h, y)) => {
                let width = obj.width_at_height(obj.grasp_height_m - q)?;
                if width <= 0.0 {
                    return None;
                }
                Some((h * width, y * width))
            }
        }
    }
}

/// Vertices of a unit-width polygonal section (width 1 along x at yaw 0, depth
/// `aspect` along y for a box), centred on its centroid.
fn unit_polygon(shape: RodShape, aspect: f64) -> Vec<[f64; 2]> {
    match shape {
        RodShape::Square => vec![
            [0.5, 0.5 * aspect],
            [-0.5, 0.5 * aspect],
            [-0.5, -0.5 * aspect],
            [0.5, -0.5 * aspect],
        ],
        RodShape::Hexagon => {
            // Across-flats 1 along x: vertices at 30° + k·60°, circumradius 1/√3.
            let r = 1.0 / 3.0_f64.sqrt();
            (0..6)
                .map(|k| {
                    let a = std::f64::consts::PI / 6.0 + k as f64 * std::f64::consts::PI / 3.0;
                    [r * a.cos(), r * a.sin()]
                })
                .collect()
        }
        RodShape::Triangle => {
            // Height 1 along x, a vertex towards +x.
            let side = 2.0 / 3.0_f64.sqrt();
            vec![
                [2.0 / 3.0, 0.0],
                [-1.0 / 3.0, 0.5 * side],
                [-1.0 / 3.0, -0.5 * side],
            ]
        }
        RodShape::Circle | RodShape::Oval => Vec::new(),
    }
}
