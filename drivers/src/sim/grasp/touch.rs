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
use crate::sim::contact::{Contact, Strip};
use softtouch_schemas::Wrench;

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
    let centre = finger.contact_height(obj.contact_z_m);
    let (front, _, _, _) = finger.semi_axes(centre);
    let towards = if k == 0 { 1.0 } else { -1.0 };
    // Finger 1 is turned half a turn about z: its y is G's −y.
    let y_sign = if k == 0 { 1.0 } else { -1.0 };
    let dq = finger.length_m / STRIPS as f64;
    let facing = obj.facing(grip.yaw_rad, k);
    let mut strips = Vec::with_capacity(STRIPS);
    let mut normals = Vec::with_capacity(STRIPS);
    let mut normal_n = 0.0;
    let (mut wy, mut wx, mut wr) = (0.0, 0.0, 0.0);
    for j in 0..STRIPS {
        let h = finger.base_height_m + (j as f64 + 0.5) * dq;
        let q = h - centre - obj.offset_m[2];
        let mut fn_mag = 0.0;
        let mut point = [finger.semi_axes(h).0, 0.0, h];
        let mut n = [1.0, 0.0, 0.0];
        if let Some((r, y_g)) = facing.half_width_at(obj, q) {
            let y = y_sign * (y_g + obj.offset_m[1]);
            if let Some((x, normal)) = surface(finger, h, y) {
                point = [x, y, h];
                n = normal;
                let pen = r - 0.5 * grip.opening_m + towards * grip.shift_m - front + x;
                if pen > 0.0 {
                    let s = finger.frac(h);
                    let stiffness = params.stiffness * (1.0 + (params.tip_softening - 1.0) * s);
                    fn_mag = stiffness * dq * pen.powf(1.5);
                    wr += fn_mag * r;
                }
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
        // Pressing: the finger moves along +x; friction opposes the tangential slip.
        let an = n[0];
        let slip = [1.0 - an * n[0], -an * n[1], -an * n[2]];
        let slip_mag = (slip[0] * slip[0] + slip[1] * slip[1] + slip[2] * slip[2]).sqrt();
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
