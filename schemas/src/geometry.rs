//! Poses: the contact pose the collector samples and the arm's full rigid pose.

use serde::{Deserialize, Serialize};

/// A closed interval `[min, max]`, written `[min, max]` in TOML.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "[f64; 2]", into = "[f64; 2]")]
pub struct Range {
    /// Lower bound (inclusive).
    pub min: f64,
    /// Upper bound (inclusive).
    pub max: f64,
}

impl From<[f64; 2]> for Range {
    fn from([min, max]: [f64; 2]) -> Self {
        Self { min, max }
    }
}

impl From<Range> for [f64; 2] {
    fn from(r: Range) -> Self {
        [r.min, r.max]
    }
}

impl Range {
    /// A range from its bounds.
    #[must_use]
    pub const fn new(min: f64, max: f64) -> Self {
        Self { min, max }
    }

    /// Both bounds finite and `min <= max`.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.min.is_finite() && self.max.is_finite() && self.min <= self.max
    }

    /// `v` lies inside the closed interval (NaN never does).
    #[must_use]
    pub fn contains(&self, v: f64) -> bool {
        v >= self.min && v <= self.max
    }

    /// `other` lies entirely inside this range.
    #[must_use]
    pub fn contains_range(&self, other: &Range) -> bool {
        self.contains(other.min) && self.contains(other.max)
    }

    /// `max − min`.
    #[must_use]
    pub fn span(&self) -> f64 {
        self.max - self.min
    }
}

/// Where the finger touches the rod, in the rod frame: the paper's `(x, 0, z, 0, 0, θ)`.
///
/// `x_m` is the offset along the finger's approach axis, `z_m` along the rod's axis
/// (the paper's text calls it y), `theta_rad` the rotation about the rod's axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactPose {
    /// Offset along the approach axis, metres.
    pub x_m: f64,
    /// Offset along the rod's axis, metres.
    pub z_m: f64,
    /// Rotation about the rod's axis, radians in `[−π, π]`.
    pub theta_rad: f64,
}

impl ContactPose {
    /// The contact pose a measured finger pose corresponds to: the inverse of
    /// [`ArmPose::from_contact`]. The offset across the approach axis (y in the rod
    /// frame) and any tilt are not part of a contact pose and are dropped.
    #[must_use]
    pub fn from_arm(base_from_rod: &ArmPose, base_from_finger: &ArmPose) -> Self {
        let rod_from_finger = base_from_rod.inverse().compose(base_from_finger);
        Self {
            x_m: rod_from_finger.translation_m[0],
            z_m: rod_from_finger.translation_m[2],
            theta_rad: rod_from_finger.yaw_rad(),
        }
    }

    /// All three coordinates are finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.x_m.is_finite() && self.z_m.is_finite() && self.theta_rad.is_finite()
    }
}

/// A rigid pose: translation in metres and a unit quaternion `[w, x, y, z]`.
///
/// Used as `base_from_flange` (the arm's end effector in its base frame) and
/// `base_from_rod` (where the rod stands in the arm's base frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ArmPose {
    /// Translation, metres.
    pub translation_m: [f64; 3],
    /// Unit quaternion `[w, x, y, z]`.
    pub rotation_wxyz: [f64; 4],
}

impl Default for ArmPose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl ArmPose {
    /// No translation, no rotation.
    pub const IDENTITY: Self = Self {
        translation_m: [0.0; 3],
        rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
    };

    /// A pose from a translation and a rotation of `yaw_rad` about the z axis.
    #[must_use]
    pub fn from_translation_yaw(translation_m: [f64; 3], yaw_rad: f64) -> Self {
        let (s, c) = (yaw_rad * 0.5).sin_cos();
        Self {
            translation_m,
            rotation_wxyz: [c, 0.0, 0.0, s],
        }
    }

    /// The pose of the finger for a contact pose, given where the rod stands:
    /// `base_from_finger = base_from_rod · Trans(x, 0, z) · RotZ(θ)`.
    #[must_use]
    pub fn from_contact(base_from_rod: &ArmPose, contact: &ContactPose) -> Self {
        let rod_from_finger =
            Self::from_translation_yaw([contact.x_m, 0.0, contact.z_m], contact.theta_rad);
        base_from_rod.compose(&rod_from_finger)
    }

    /// The inverse pose: `other_from_self` for `self = self_from_other`.
    #[must_use]
    pub fn inverse(&self) -> Self {
        let [w, x, y, z] = quat_normalize(self.rotation_wxyz);
        let inv = Self {
            translation_m: [0.0; 3],
            rotation_wxyz: [w, -x, -y, -z],
        };
        let t = inv.rotate(self.translation_m);
        Self {
            translation_m: [-t[0], -t[1], -t[2]],
            rotation_wxyz: inv.rotation_wxyz,
        }
    }

    /// `self · other`: apply `other`, then `self`.
    #[must_use]
    pub fn compose(&self, other: &ArmPose) -> Self {
        let t = self.rotate(other.translation_m);
        Self {
            translation_m: [
                t[0] + self.translation_m[0],
                t[1] + self.translation_m[1],
                t[2] + self.translation_m[2],
            ],
            rotation_wxyz: quat_normalize(quat_mul(self.rotation_wxyz, other.rotation_wxyz)),
        }
    }

    /// Rotate a vector by this pose's rotation.
    #[must_use]
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let [w, x, y, z] = quat_normalize(self.rotation_wxyz);
        // v' = v + 2w(q×v) + 2 q×(q×v), q = (x, y, z)
        let q = [x, y, z];
        let c1 = cross(q, v);
        let c2 = cross(q, c1);
        [
            v[0] + 2.0 * (w * c1[0] + c2[0]),
            v[1] + 2.0 * (w * c1[1] + c2[1]),
            v[2] + 2.0 * (w * c1[2] + c2[2]),
        ]
    }

    /// Rotation about z (yaw) in radians, in `(−π, π]`.
    #[must_use]
    pub fn yaw_rad(&self) -> f64 {
        let [w, x, y, z] = quat_normalize(self.rotation_wxyz);
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }

    /// All components finite and the quaternion not degenerate.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        let n2: f64 = self.rotation_wxyz.iter().map(|c| c * c).sum();
        self.translation_m
            .iter()
            .chain(&self.rotation_wxyz)
            .all(|v| v.is_finite())
            && n2 > 1e-12
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// Normalise; a degenerate (near-zero or non-finite) quaternion becomes the identity
/// rather than spreading NaN.
fn quat_normalize(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if !n.is_finite() || n < 1e-12 {
        return [1.0, 0.0, 0.0, 0.0];
    }
    [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are the point of these tests
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn a_degenerate_quaternion_rotates_like_the_identity() {
        let p = ArmPose {
            translation_m: [0.0; 3],
            rotation_wxyz: [0.0; 4],
        };
        assert_eq!(p.rotate([1.0, 2.0, 3.0]), [1.0, 2.0, 3.0]);
        assert!(!p.is_valid());
    }

    #[test]
    fn range_rejects_nan_and_reversed_bounds() {
        assert!(!Range::new(f64::NAN, 1.0).is_valid());
        assert!(!Range::new(1.0, 0.0).is_valid());
        assert!(Range::new(0.0, 0.0).is_valid());
        assert!(!Range::new(0.0, 1.0).contains(f64::NAN));
    }

    proptest! {
        #[test]
        fn contact_pose_maps_to_the_arm_with_its_yaw_and_offset(
            x in 0.0..0.05f64, z in -0.05..0.05f64, theta in -std::f64::consts::PI..std::f64::consts::PI,
            rod_yaw in -3.0..3.0f64,
        ) {
            let rod = ArmPose::from_translation_yaw([0.5, 0.1, 0.3], rod_yaw);
            let p = ArmPose::from_contact(&rod, &ContactPose { x_m: x, z_m: z, theta_rad: theta });
            let expect_yaw = (rod_yaw + theta + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
            let dyaw = (p.yaw_rad() - expect_yaw).abs();
            prop_assert!(dyaw < 1e-9 || (dyaw - 2.0 * std::f64::consts::PI).abs() < 1e-9);
            prop_assert!(close(p.translation_m[2], 0.3 + z));
            let dx = p.translation_m[0] - 0.5;
            let dy = p.translation_m[1] - 0.1;
            prop_assert!(close((dx * dx + dy * dy).sqrt(), x));
        }

        #[test]
        fn a_contact_pose_survives_the_trip_through_the_arm_frame(
            x in -0.05..0.05f64, z in -0.05..0.05f64, theta in -3.1..3.1f64,
            rod_yaw in -3.0..3.0f64, rx in -1.0..1.0f64,
        ) {
            let rod = ArmPose::from_translation_yaw([rx, 0.1, 0.3], rod_yaw);
            let c = ContactPose { x_m: x, z_m: z, theta_rad: theta };
            let back = ContactPose::from_arm(&rod, &ArmPose::from_contact(&rod, &c));
            prop_assert!(close(back.x_m, x) && close(back.z_m, z) && close(back.theta_rad, theta), "{back:?}");
        }
    }
}
