//! The finger, the rod, and the contact between them.
//!
//! See the module docs of [`crate`] for the geometric reading of `(x, z, θ)`.
//! Everything here is in the sensor frame, metres and newtons.

use super::SimError;
use softtouch_schemas::{ContactPose, RodShape, RodSpec, Wrench};

/// Strips the contact patch is cut into along the finger's axis.
pub(crate) const STRIPS: usize = 48;

/// Shape of the finger: a tapered body with an elliptical cross-section, from its base
/// (on the sensor) to its tip, and where the contact pose puts the rod on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerGeometry {
    /// Height of the finger's base above the sensor origin, m.
    pub base_height_m: f64,
    /// Length of the finger from base to tip, m.
    pub length_m: f64,
    /// Half-depth (along the sensor's x) at the base and at the tip, m.
    pub half_depth_m: [f64; 2],
    /// Half-width (along the sensor's y) at the base and at the tip, m.
    pub half_width_m: [f64; 2],
}

impl Default for FingerGeometry {
    fn default() -> Self {
        Self {
            base_height_m: 0.012,
            length_m: 0.060,
            half_depth_m: [0.012, 0.004],
            half_width_m: [0.016, 0.005],
        }
    }
}

/// Material of the contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParams {
    /// Penetration at `x = 0` (a light touch), m.
    pub penetration_at_zero_m: f64,
    /// Extra penetration per metre of `x`.
    pub penetration_per_m: f64,
    /// Stiffness of the skin at the base, N per m of strip per m^1.5 of penetration
    /// (pressure ∝ penetration^1.5, Hertz-like); it falls linearly to
    /// `tip_softening` times this at the tip.
    pub stiffness: f64,
    /// Stiffness at the tip over stiffness at the base.
    pub tip_softening: f64,
    /// Coulomb friction coefficient between skin and rod.
    pub friction: f64,
    /// Tangential slip (fraction of the approach) at which friction is fully developed
    /// (regularised Coulomb: friction = μ·N·tanh(slip / this)).
    pub friction_slip: f64,
    /// Stress relaxation of the silicone: right after the finger stops pressing, the
    /// contact wrench is `1 + this` times its equilibrium value, decaying
    /// exponentially (a standard linear solid under a step strain).
    pub relaxation_ratio: f64,
    /// Time constant of that decay, s.
    pub relaxation_time_s: f64,
}

impl ContactParams {
    /// The `x` of the finger's first touch of a rod, m: where the penetration
    /// (`penetration_at_zero_m + penetration_per_m · x`) reaches zero. The law holds
    /// for every rod section and θ, so one stand-off serves every pose. `None` where
    /// the penetration does not grow with `x`.
    #[must_use]
    pub fn first_touch_x_m(&self) -> Option<f64> {
        let x = -self.penetration_at_zero_m / self.penetration_per_m;
        (self.penetration_per_m > 0.0 && x.is_finite()).then_some(x)
    }
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            penetration_at_zero_m: 0.0003,
            penetration_per_m: 0.084,
            stiffness: 3.4e6,
            tip_softening: 0.85,
            friction: 0.4,
            friction_slip: 0.05,
            relaxation_ratio: 0.12,
            relaxation_time_s: 0.06,
        }
    }
}

/// One strip of the contact patch: where it presses and with what force on the finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Strip {
    /// Height along the finger (sensor z), m.
    pub h: f64,
    /// Point on the finger's surface, sensor frame, m.
    pub point: [f64; 3],
    /// Force on the finger, N.
    pub force: [f64; 3],
}

/// The contact: where, how hard, and the wrench it puts on the sensor.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Contact {
    /// Azimuth of the pressed side about the finger axis, rad.
    pub azimuth: f64,
    /// Loaded strips (force may be zero).
    pub strips: Vec<Strip>,
    /// Sum of the strip forces and their moments about the sensor origin.
    pub wrench: Wrench,
}

/// The face of a rod's cross-section that meets the finger, as a gap profile: how far
/// the rod's surface stands back from its front line at offset `q` along the finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RodProfile {
    shape: RodShape,
    /// Half-extent along the finger axis, m.
    half_extent: f64,
    /// Depth of the section (towards the finger), half, m (ovals, circles).
    half_depth: f64,
}

/// Rounding radius of polygon corners, m (keeps the gap profile smooth).
const CORNER_M: f64 = 0.0005;
/// Slope of the rod's flank beyond its extent (continuity, not physics of note).
const FLANK_SLOPE: f64 = 5.0;

impl RodProfile {
    pub(crate) fn new(rod: &RodSpec) -> Result<Self, SimError> {
        if !(rod.size_m.is_finite()
            && rod.size_m > 0.0
            && rod.aspect.is_finite()
            && rod.aspect > 0.0)
        {
            return Err(SimError::InvalidParameter(format!(
                "rod `{}`: size_m {} and aspect {} must be finite and positive",
                rod.name, rod.size_m, rod.aspect
            )));
        }
        let half = rod.size_m * 0.5;
        let aspect = if rod.shape == RodShape::Oval {
            rod.aspect
        } else {
            1.0
        };
        Ok(Self {
            shape: rod.shape,
            half_extent: half,
            half_depth: half * aspect,
        })
    }

    /// Half-extent of the face along the finger axis, m.
    pub(crate) fn half_extent(&self) -> f64 {
        self.half_extent
    }

    /// Gap `g(q) ≥ 0` of the rod's face at offset `q` from its centre line.
    pub(crate) fn gap(&self, q: f64) -> f64 {
        let aq = q.abs();
        let e = self.half_extent;
        let inside = aq.min(e);
        let g = match self.shape {
            RodShape::Circle | RodShape::Oval => {
                let r = (inside / e).min(1.0);
                self.half_depth * (1.0 - (1.0 - r * r).max(0.0).sqrt())
            }
            RodShape::Square => {
                // Flat face of width `size`, corners rounded.
                let flat = (e - CORNER_M).max(0.0);
                let d = (inside - flat).max(0.0);
                let rc = CORNER_M.min(e);
                rc - (rc * rc - d * d).max(0.0).sqrt()
            }
            RodShape::Triangle => {
                // A vertex towards the finger; faces at 30° to the approach.
                let lin = inside * 3f64.sqrt();
                (lin * lin + CORNER_M * CORNER_M).sqrt() - CORNER_M
            }
            RodShape::Hexagon => {
                // A vertex towards the finger (across-flats along the finger axis);
                // faces at 60° to the approach.
                let lin = inside / 3f64.sqrt();
                (lin * lin + CORNER_M * CORNER_M).sqrt() - CORNER_M
            }
        };
        g + FLANK_SLOPE * (aq - e).max(0.0)
    }
}

impl FingerGeometry {
    pub(crate) fn validate(&self) -> Result<(), SimError> {
        let all = [
            self.base_height_m,
            self.length_m,
            self.half_depth_m[0],
            self.half_depth_m[1],
            self.half_width_m[0],
            self.half_width_m[1],
        ];
        if all.iter().all(|v| v.is_finite() && *v > 0.0) {
            Ok(())
        } else {
            Err(SimError::InvalidParameter(format!(
                "finger geometry must be finite and positive: {self:?}"
            )))
        }
    }

    /// How much nearer the rod the finger's surface can come when the wrist turns it,
    /// m. The contact law reads `x` from the side facing the rod; a turn about the
    /// finger's axis brings another radius of its elliptical cross-section to face
    /// the rod, longer by at most the difference of half-depth and half-width (largest
    /// at an end of the taper: 4 mm at the default finger's base). A retreat plane this
    /// far out beyond the stand-off lets any turn between retreat points clear the rod.
    #[must_use]
    pub fn turn_clearance_m(&self) -> f64 {
        let at = |k: usize| (self.half_depth_m[k] - self.half_width_m[k]).abs();
        at(0).max(at(1))
    }

    /// Height of the finger's tip above the sensor origin, m.
    pub(crate) fn tip_height(&self) -> f64 {
        self.base_height_m + self.length_m
    }

    /// Position along the finger (0 base, 1 tip) of a height, clamped.
    pub(crate) fn frac(&self, h: f64) -> f64 {
        ((h - self.base_height_m) / self.length_m).clamp(0.0, 1.0)
    }

    /// Semi-axes `(A along x, B along y)` of the cross-section at height `h`, and
    /// their derivatives with respect to `h` (zero outside the finger).
    pub(crate) fn semi_axes(&self, h: f64) -> (f64, f64, f64, f64) {
        let s = self.frac(h);
        let a = self.half_depth_m[0] + (self.half_depth_m[1] - self.half_depth_m[0]) * s;
        let b = self.half_width_m[0] + (self.half_width_m[1] - self.half_width_m[0]) * s;
        let inside = h > self.base_height_m && h < self.tip_height();
        let (da, db) = if inside {
            (
                (self.half_depth_m[1] - self.half_depth_m[0]) / self.length_m,
                (self.half_width_m[1] - self.half_width_m[0]) / self.length_m,
            )
        } else {
            (0.0, 0.0)
        };
        (a, b, da, db)
    }

    /// Height of the contact's centre for the pose's `z`: `z ∈ [−5, 5] cm` spans
    /// 10 %…90 % of the finger, clamped to 2 %…98 % beyond.
    pub(crate) fn contact_height(&self, z_m: f64) -> f64 {
        let s = (0.5 + 0.4 * z_m / 0.05).clamp(0.02, 0.98);
        self.base_height_m + s * self.length_m
    }
}

/// Radius of the ellipse `(a, b)` in direction `(c, s) = (cos φ, sin φ)`.
fn polar_radius(a: f64, b: f64, c: f64, s: f64) -> f64 {
    a * b / ((b * c).powi(2) + (a * s).powi(2)).sqrt()
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > 0.0 && n.is_finite() {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        [0.0; 3]
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The contact of `rod` on the finger at `pose`.
pub(crate) fn contact(
    finger: &FingerGeometry,
    params: &ContactParams,
    rod: &RodProfile,
    pose: &ContactPose,
) -> Result<Contact, SimError> {
    if !pose.is_finite() {
        return Err(SimError::NonFinitePose {
            x_m: pose.x_m,
            z_m: pose.z_m,
            theta_rad: pose.theta_rad,
        });
    }
    let depth = params.penetration_at_zero_m + params.penetration_per_m * pose.x_m;
    let centre = finger.contact_height(pose.z_m);
    let azimuth = pose.theta_rad;
    let (s_az, c_az) = azimuth.sin_cos();
    let approach = [c_az, s_az, 0.0];
    let (a0, b0, _, _) = finger.semi_axes(centre);
    let rho0 = polar_radius(a0, b0, c_az, s_az);

    // The patch spans the rod's face plus a margin for its flanks.
    let half_span = rod.half_extent() + depth.max(0.0) / FLANK_SLOPE + 0.0005;
    let dq = 2.0 * half_span / STRIPS as f64;
    let mut strips = Vec::with_capacity(STRIPS);
    let mut force = [0.0; 3];
    let mut torque = [0.0; 3];
    for j in 0..STRIPS {
        let q = -half_span + (j as f64 + 0.5) * dq;
        // The part of the strip on the finger (strips crossing the base or the tip
        // count in part, so the wrench does not jump as they cross).
        let lo = (centre + q - 0.5 * dq).max(finger.base_height_m);
        let hi = (centre + q + 0.5 * dq).min(finger.tip_height());
        if hi <= lo {
            continue;
        }
        let coverage = (hi - lo) / dq;
        let h = 0.5 * (lo + hi);
        let q = h - centre;
        let (a, b, da, db) = finger.semi_axes(h);
        let rho = polar_radius(a, b, c_az, s_az);
        let pen = depth - rod.gap(q) + (rho - rho0);
        let point = [rho * c_az, rho * s_az, h];
        let mut f = [0.0; 3];
        if pen > 0.0 {
            let s = finger.frac(h);
            let k = params.stiffness * (1.0 + (params.tip_softening - 1.0) * s);
            let fn_mag = k * dq * coverage * pen.powf(1.5);
            // Outward normal of x²/A² + y²/B² = 1 with A, B functions of h.
            let (x, y) = (point[0], point[1]);
            let n = normalize([
                x / (a * a),
                y / (b * b),
                -(x * x) * da / (a * a * a) - (y * y) * db / (b * b * b),
            ]);
            // The finger moves towards the rod along `approach`; its surface slips
            // along the tangential part of that motion and friction opposes it.
            let an = dot(approach, n);
            let slip = [
                approach[0] - an * n[0],
                approach[1] - an * n[1],
                approach[2] - an * n[2],
            ];
            let slip_mag = dot(slip, slip).sqrt();
            let fric = if slip_mag > 1e-12 {
                params.friction * fn_mag * (slip_mag / params.friction_slip).tanh() / slip_mag
            } else {
                0.0
            };
            for i in 0..3 {
                f[i] = -fn_mag * n[i] - fric * slip[i];
            }
        }
        let t = cross(point, f);
        for i in 0..3 {
            force[i] += f[i];
            torque[i] += t[i];
        }
        strips.push(Strip { h, point, force: f });
    }
    let wrench = Wrench {
        force_n: force,
        torque_nm: torque,
    };
    if !wrench.is_finite() {
        return Err(SimError::Solver(format!(
            "contact produced a non-finite wrench at {pose:?}"
        )));
    }
    Ok(Contact {
        azimuth,
        strips,
        wrench,
    })
}
