//! The contact of a grasped object on one soft finger, in that finger's sensor frame
//! (its +x faces the object, z runs along the finger to its tip).
//!
//! The same law as the rod presses (`sim::contact`): the finger is cut into strips
//! along its axis; a strip at height `h` presses with `p = k(h)·δ^1.5` along the
//! surface normal, where the penetration `δ` is the object's half-width across the
//! fingers at that height (its profile: a chord, a taper, a lying rod's face) less half
//! the opening, plus how far the finger's surface there stands forward of its front at
//! the grasp height (the taper of the finger, and the curve of its section where the
//! contact sits off-centre across the finger), plus the object's shift towards this
//! finger. Friction from the approach opposes the slip of the pressing, as for the
//! rods. On top, the grasp's shear: the load the finger carries in friction (along z)
//! and the twist the object has turned against the fingers (along y), spread over the
//! strips in proportion to their normal force. The wrench is the sum of the strip
//! forces and their moments about the sensor origin, so a twist shows as a torque
//! about z from the shear itself: τz = Σ (x·f_y − y·f_x).

use super::super::SimError;
use super::super::contact::{ContactParams, FingerGeometry};
use super::object::GraspObject;
use crate::contact::{Contact, Strip};
use softtouch_schemas::Wrench;
use std::sync::Arc;

/// Strips along the whole finger.
pub(crate) const STRIPS: usize = 96;

/// Where the fingers and the object are.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Grip {
    /// Distance between the fingers' fronts at the grasp height, m.
    pub opening_m: f64,
    /// The object's shift along G's −x (towards finger 0), m.
    pub shift_m: f64,
    /// The object's turn about z relative to the gripper, rad.
    pub yaw_rad: f64,
}

/// One finger's contact.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FingerContact {
    /// Strips and the wrench on the finger.
    pub contact: Contact,
    /// Sum of the strips' normal forces, N.
    pub normal_n: f64,
    /// The object's half-width at the load's centre, m (the lever of a twist).
    pub radius_m: f64,
}

impl FingerContact {
    /// The squeeze: −F_x on the finger, N.
    pub(crate) fn squeeze_n(&self) -> f64 {
        -self.contact.wrench.force_n[0]
    }
}

/// Elliptical section of the finger at height `h`: the x of its surface at lateral `y`
/// and the normal there; `None` off the finger's face (|y| ≥ half-width).
fn surface(finger: &FingerGeometry, h: f64, y: f64) -> Option<(f64, [f64; 3])> {
    let (a, b, da, db) = finger.semi_axes(h);
    if y.abs() >= b {
        return None;
    }
    let x = a * (1.0 - (y / b).powi(2)).sqrt();
    let n = [
        x / (a * a),
        y / (b * b),
        -(x * x) * da / (a * a * a) - (y * y) * db / (b * b * b),
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    Some((x, [n[0] / len, n[1] / len, n[2] / len]))
}

/// What the strips of finger `k` press with against `obj` turned by `yaw_rad`, apart
/// from the opening, the object's shift and the shear: the part of [`finger_contact`]
/// that changes only when the object turns (a balance moves only the shift, a
/// closing only the opening).
pub(crate) struct Strips {
    /// The finger and the turn they were worked out for.
    k: usize,
    yaw_rad: f64,
    /// The finger's front at the grasp height, m.
    front: f64,
    /// +1 for finger 0, −1 for finger 1: the sign of a shift towards this finger.
    towards: f64,
    /// Each strip's height, m, and what faces it (`None`: nothing).
    strips: Vec<(f64, Option<Facing>)>,
}

/// An object's face against one strip.
#[derive(Debug, Clone, Copy)]
struct Facing {
    /// The object's half-width across the fingers there, m.
    r: f64,
    /// The finger's surface point that touches (x, y), m, and its normal.
    x: f64,
    y: f64,
    normal: [f64; 3],
    /// The strip's stiffness × length: the press is this × penetration^1.5.
    k_dq: f64,
}

impl Strips {
    pub(crate) fn new(
        finger: &FingerGeometry,
        params: &ContactParams,
        obj: &GraspObject,
        k: usize,
        yaw_rad: f64,
    ) -> Self {
        let centre = finger.contact_height(obj.contact_z_m);
        let (front, _, _, _) = finger.semi_axes(centre);
        // Finger 1 is turned half a turn about z: its y is G's −y.
        let y_sign = if k == 0 { 1.0 } else { -1.0 };
        let dq = finger.length_m / STRIPS as f64;
        let facing = obj.facing(yaw_rad, k);
        let strips = (0..STRIPS)
            .map(|j| {
                let h = finger.base_height_m + (j as f64 + 0.5) * dq;
                let q = h - centre - obj.offset_m[2];
                let face = facing.half_width_at(obj, q).and_then(|(r, y_g)| {
                    let y = y_sign * (y_g + obj.offset_m[1]);
                    let (x, normal) = surface(finger, h, y)?;
                    let s = finger.frac(h);
                    let stiffness = params.stiffness * (1.0 + (params.tip_softening - 1.0) * s);
                    Some(Facing {
                        r,
                        x,
                        y,
                        normal,
                        k_dq: stiffness * dq,
                    })
                });
                (h, face)
            })
            .collect();
        Self {
            k,
            yaw_rad,
            front,
            towards: if k == 0 { 1.0 } else { -1.0 },
            strips,
        }
    }

    /// Whether these are finger `k`'s strips against the object turned by `yaw_rad`
    /// (the same bits).
    pub(crate) fn are_for(&self, k: usize, yaw_rad: f64) -> bool {
        self.k == k && self.turned_as(yaw_rad)
    }

    /// A facing strip's normal force at an opening and shift, N: `k·δ^1.5` for a
    /// penetration `δ` > 0, else 0.
    fn press_n(&self, f: &Facing, opening_m: f64, shift_m: f64) -> f64 {
        let pen = f.r - 0.5 * opening_m + self.towards * shift_m - self.front + f.x;
        if pen > 0.0 {
            f.k_dq * pen.powf(1.5)
        } else {
            0.0
        }
    }

    /// Whether these were worked out for the turn `yaw_rad` (the same bits).
    fn turned_as(&self, yaw_rad: f64) -> bool {
        self.yaw_rad.to_bits() == yaw_rad.to_bits()
    }
}

/// The slip of pressing along the normal `n` (the finger moves along +x; friction
/// opposes the tangential slip) and its magnitude.
fn slip_of(n: [f64; 3]) -> ([f64; 3], f64) {
    let an = n[0];
    let slip = [1.0 - an * n[0], -an * n[1], -an * n[2]];
    let slip_mag = (slip[0] * slip[0] + slip[1] * slip[1] + slip[2] * slip[2]).sqrt();
    (slip, slip_mag)
}

fn check_finite(grip: &Grip, shear_n: [f64; 2]) -> Result<(), SimError> {
    let values = [
        grip.opening_m,
        grip.shift_m,
        grip.yaw_rad,
        shear_n[0],
        shear_n[1],
    ];
    if values.iter().any(|v| !v.is_finite()) {
        return Err(SimError::InvalidParameter(format!(
            "grasp state is not finite: {grip:?}, shear {shear_n:?} N"
        )));
    }
    Ok(())
}

/// The contact of `obj` on finger `k` (0 or 1) at `grip`, with `shear_n` = (along y,
/// along z) in the finger's frame, N, spread over the loaded strips.
pub(crate) fn finger_contact(
    finger: &FingerGeometry,
    params: &ContactParams,
    obj: &GraspObject,
    k: usize,
    grip: &Grip,
    shear_n: [f64; 2],
) -> Result<FingerContact, SimError> {
    let along = Strips::new(finger, params, obj, k, grip.yaw_rad);
    contact_on(&along, finger, params, obj, grip, shear_n)
}

/// [`finger_contact`] on strips already worked out for the finger and `grip`'s turn.
pub(crate) fn contact_on(
    along: &Strips,
    finger: &FingerGeometry,
    params: &ContactParams,
    obj: &GraspObject,
    grip: &Grip,
    shear_n: [f64; 2],
) -> Result<FingerContact, SimError> {
    check_finite(grip, shear_n)?;
    debug_assert!(along.turned_as(grip.yaw_rad), "strips for another turn");
    let mut strips = Vec::with_capacity(STRIPS);
    let mut normals = Vec::with_capacity(STRIPS);
    let mut normal_n = 0.0;
    let (mut wy, mut wx, mut wr) = (0.0, 0.0, 0.0);
    for &(h, face) in &along.strips {
        let mut fn_mag = 0.0;
        let mut point = [finger.semi_axes(h).0, 0.0, h];
        let mut n = [1.0, 0.0, 0.0];
        if let Some(f) = face {
            point = [f.x, f.y, h];
            n = f.normal;
            fn_mag = along.press_n(&f, grip.opening_m, grip.shift_m);
            if fn_mag > 0.0 {
                wr += fn_mag * f.r;
            }
        }
        normal_n += fn_mag;
        wy += fn_mag * point[1];
        wx += fn_mag * point[0];
        normals.push((fn_mag, n));
        strips.push(Strip {
            h,
            point,
            force: [0.0; 3],
        });
    }
    let mut force = [0.0; 3];
    let mut torque = [0.0; 3];
    for (strip, (fn_mag, n)) in strips.iter_mut().zip(normals) {
        if fn_mag <= 0.0 {
            continue;
        }
        let (slip, slip_mag) = slip_of(n);
        let fric = if slip_mag > 1e-12 {
            obj.friction * fn_mag * (slip_mag / params.friction_slip).tanh() / slip_mag
        } else {
            0.0
        };
        let share = fn_mag / normal_n;
        let f = [
            -fn_mag * n[0] - fric * slip[0],
            -fn_mag * n[1] - fric * slip[1] + share * shear_n[0],
            -fn_mag * n[2] - fric * slip[2] + share * shear_n[1],
        ];
        let p = strip.point;
        let t = [
            p[1] * f[2] - p[2] * f[1],
            p[2] * f[0] - p[0] * f[2],
            p[0] * f[1] - p[1] * f[0],
        ];
        for i in 0..3 {
            force[i] += f[i];
            torque[i] += t[i];
        }
        strip.force = f;
    }
    let wrench = Wrench {
        force_n: force,
        torque_nm: torque,
    };
    if !wrench.is_finite() {
        return Err(SimError::Solver(format!(
            "grasp contact produced a non-finite wrench at {grip:?}"
        )));
    }
    let (azimuth, radius_m) = if normal_n > 0.0 {
        (wy.atan2(wx), wr / normal_n)
    } else {
        (0.0, 0.0)
    };
    Ok(FingerContact {
        contact: Contact {
            azimuth,
            strips,
            wrench,
        },
        normal_n,
        radius_m,
    })
}

/// Finger `k`'s squeeze against the object's shift, at a fixed opening, turn and
/// shear: what a balance asks for at each of its iterations. The same arithmetic as
/// [`finger_contact`], term for term and in the same order, so the same bits, for
/// the x component only (the shear and the moments do not enter it).
#[derive(Debug)]
pub(crate) struct SqueezeAlongShift {
    opening_m: f64,
    along: Arc<Strips>,
    /// The object's friction coefficient.
    friction: f64,
    /// Per facing strip: tanh(slip/slip₀), the slip's magnitude and its x (1 − n_x²).
    slips: Vec<(f64, f64, f64)>,
}

impl std::fmt::Debug for Strips {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Strips")
            .field("front", &self.front)
            .field("towards", &self.towards)
            .field(
                "facing",
                &self.strips.iter().filter(|s| s.1.is_some()).count(),
            )
            .finish()
    }
}

impl SqueezeAlongShift {
    /// On `along`, the finger's strips at `grip`'s turn, at `grip`'s opening (its
    /// shift is not used); errors as [`finger_contact`] would on a state that is not
    /// finite.
    pub(crate) fn new(
        along: Arc<Strips>,
        params: &ContactParams,
        obj: &GraspObject,
        grip: &Grip,
        shear_n: [f64; 2],
    ) -> Result<Self, SimError> {
        check_finite(grip, shear_n)?;
        debug_assert!(along.turned_as(grip.yaw_rad), "strips for another turn");
        let slips = along
            .strips
            .iter()
            .filter_map(|s| s.1)
            .map(|f| {
                let (slip, slip_mag) = slip_of(f.normal);
                let tanh = (slip_mag / params.friction_slip).tanh();
                (tanh, slip_mag, slip[0])
            })
            .collect();
        Ok(Self {
            opening_m: grip.opening_m,
            along,
            friction: obj.friction,
            slips,
        })
    }

    /// The normal force and the squeeze (−F_x) at `shift_m`, N; `None` where they
    /// are not finite ([`finger_contact`] says why).
    pub(crate) fn at(&self, shift_m: f64) -> Option<(f64, f64)> {
        let mut normal_n = 0.0;
        let mut force_x = 0.0;
        let faces = self.along.strips.iter().filter_map(|s| s.1.as_ref());
        for (f, &(tanh, slip_mag, slip_x)) in faces.zip(&self.slips) {
            let fn_mag = self.along.press_n(f, self.opening_m, shift_m);
            normal_n += fn_mag;
            if fn_mag <= 0.0 {
                continue;
            }
            let fric = if slip_mag > 1e-12 {
                self.friction * fn_mag * tanh / slip_mag
            } else {
                0.0
            };
            force_x += -fn_mag * f.normal[0] - fric * slip_x;
        }
        (normal_n.is_finite() && force_x.is_finite() && shift_m.is_finite())
            .then_some((normal_n, -force_x))
    }
}

/// Whether finger `k` presses `obj` at `grip` (no shear).
pub(crate) fn reaches_finger(
    finger: &FingerGeometry,
    obj: &GraspObject,
    k: usize,
    grip: &Grip,
) -> bool {
    finger_contact(finger, &ContactParams::default(), obj, k, grip, [0.0; 2])
        .is_ok_and(|c| c.normal_n > 0.0)
}
