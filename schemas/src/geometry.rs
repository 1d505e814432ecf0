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

    /// The same pose with a unit quaternion; a degenerate one (near zero or not
    /// finite) becomes the identity rather than spreading NaN.
    #[must_use]
    pub fn normalised(&self) -> Self {
        Self {
            translation_m: self.translation_m,
            rotation_wxyz: quat_normalize(self.rotation_wxyz),
        }
    }

    /// The rotation as a row-major 3×3 matrix: `r[row][col]`.
    #[must_use]
    pub fn rotation_matrix(&self) -> [[f64; 3]; 3] {
        let [w, x, y, z] = quat_normalize(self.rotation_wxyz);
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// The homogeneous 4×4 transform, column-major (element `(row, col)` at
    /// `col * 4 + row`): the layout libfranka uses for `O_T_EE`.
    #[must_use]
    pub fn to_matrix(&self) -> [f64; 16] {
        let r = self.rotation_matrix();
        let t = self.translation_m;
        [
            r[0][0], r[1][0], r[2][0], 0.0, r[0][1], r[1][1], r[2][1], 0.0, r[0][2], r[1][2],
            r[2][2], 0.0, t[0], t[1], t[2], 1.0,
        ]
    }

    /// The pose of a column-major homogeneous 4×4 transform (the inverse of
    /// [`ArmPose::to_matrix`]). The rotation block is assumed orthonormal; the bottom
    /// row is ignored.
    #[must_use]
    pub fn from_matrix(m: &[f64; 16]) -> Self {
        let r = |row: usize, col: usize| m[col * 4 + row];
        let trace = r(0, 0) + r(1, 1) + r(2, 2);
        // Shepperd's method: divide by the largest of the four candidates, so a
        // rotation near 180° (trace ≈ −1) stays accurate.
        let q = if trace > 0.0 {
            let s = (trace + 1.0).sqrt() * 2.0;
            [
                0.25 * s,
                (r(2, 1) - r(1, 2)) / s,
                (r(0, 2) - r(2, 0)) / s,
                (r(1, 0) - r(0, 1)) / s,
            ]
        } else if r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2) {
            let s = (1.0 + r(0, 0) - r(1, 1) - r(2, 2)).sqrt() * 2.0;
            [
                (r(2, 1) - r(1, 2)) / s,
                0.25 * s,
                (r(0, 1) + r(1, 0)) / s,
                (r(0, 2) + r(2, 0)) / s,
            ]
        } else if r(1, 1) > r(2, 2) {
            let s = (1.0 + r(1, 1) - r(0, 0) - r(2, 2)).sqrt() * 2.0;
            [
                (r(0, 2) - r(2, 0)) / s,
                (r(0, 1) + r(1, 0)) / s,
                0.25 * s,
                (r(1, 2) + r(2, 1)) / s,
            ]
        } else {
            let s = (1.0 + r(2, 2) - r(0, 0) - r(1, 1)).sqrt() * 2.0;
            [
                (r(1, 0) - r(0, 1)) / s,
                (r(0, 2) + r(2, 0)) / s,
                (r(1, 2) + r(2, 1)) / s,
                0.25 * s,
            ]
        };
        Self {
            translation_m: [m[12], m[13], m[14]],
            rotation_wxyz: quat_normalize(q),
        }
    }

    /// The pose a fraction `s` ∈ [0, 1] of the way to `other`: translation along the
    /// straight line, rotation by spherical interpolation the short way round (a
    /// Cartesian straight-line move at constant angular rate).
    #[must_use]
    pub fn slerp(&self, other: &ArmPose, s: f64) -> Self {
        Self {
            translation_m: std::array::from_fn(|i| {
                self.translation_m[i] + s * (other.translation_m[i] - self.translation_m[i])
            }),
            rotation_wxyz: quat_slerp(self.rotation_wxyz, other.rotation_wxyz, s),
        }
    }

    /// The straight-line distance between this position and `other`'s, m.
    #[must_use]
    pub fn distance_to(&self, other: &ArmPose) -> f64 {
        (0..3)
            .map(|i| (other.translation_m[i] - self.translation_m[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The angle of the rotation taking this orientation to `other`'s, rad in
    /// `[0, π]` (`q` and `−q` are the same orientation).
    #[must_use]
    pub fn angle_to(&self, other: &ArmPose) -> f64 {
        let (a, b) = (
            quat_normalize(self.rotation_wxyz),
            quat_normalize(other.rotation_wxyz),
        );
        let dot = quat_dot(a, b).abs().min(1.0);
        2.0 * dot.acos()
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

/// `a × b`.
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
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

fn quat_dot(a: [f64; 4], b: [f64; 4]) -> f64 {
    a.iter().zip(&b).map(|(x, y)| x * y).sum()
}

/// Spherical interpolation from `a` to `b` at `s`, the short way round. Nearly equal
/// quaternions fall back to a normalised lerp, where `sin θ` would divide by ~0.
fn quat_slerp(a: [f64; 4], b: [f64; 4], s: f64) -> [f64; 4] {
    let (a, mut b) = (quat_normalize(a), quat_normalize(b));
    let mut dot = quat_dot(a, b);
    if dot < 0.0 {
        b = b.map(|v| -v);
        dot = -dot;
    }
    if dot > 0.9995 {
        return quat_normalize(std::array::from_fn(|i| a[i] + s * (b[i] - a[i])));
    }
    let theta = dot.clamp(-1.0, 1.0).acos();
    let (wa, wb) = (
        ((1.0 - s) * theta).sin() / theta.sin(),
        (s * theta).sin() / theta.sin(),
    );
    quat_normalize(std::array::from_fn(|i| wa * a[i] + wb * b[i]))
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
    fn distance_is_the_translation_apart_whatever_the_rotation() {
        let a = ArmPose::from_translation_yaw([1.0, 2.0, 3.0], 0.3);
        let b = ArmPose::from_translation_yaw([4.0, 6.0, 3.0], -1.0);
        assert!((a.distance_to(&b) - 5.0).abs() < 1e-12);
        assert!((b.distance_to(&a) - 5.0).abs() < 1e-12);
        assert_eq!(a.distance_to(&a).to_bits(), 0.0f64.to_bits());
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

    fn pose(t: [f64; 3], q: [f64; 4]) -> ArmPose {
        ArmPose {
            translation_m: t,
            rotation_wxyz: q,
        }
        .normalised()
    }

    /// Same translation and orientation (`q` or `−q`), compared by component:
    /// `acos` near 1 would turn rounding into an angle of ~1e-8.
    fn same_pose(a: &ArmPose, b: &ArmPose) -> bool {
        let (qa, qb) = (a.normalised().rotation_wxyz, b.normalised().rotation_wxyz);
        let sign = if quat_dot(qa, qb) < 0.0 { -1.0 } else { 1.0 };
        (0..4).all(|i| close(qa[i], sign * qb[i]))
            && (0..3).all(|i| close(a.translation_m[i], b.translation_m[i]))
    }

    /// `m · [v, 1]` for a column-major 4×4.
    fn apply(m: &[f64; 16], v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|row| (0..3).map(|c| m[c * 4 + row] * v[c]).sum::<f64>() + m[12 + row])
    }

    #[test]
    fn the_identity_is_the_identity_matrix_and_back() {
        let m = ArmPose::IDENTITY.to_matrix();
        for (k, v) in m.iter().enumerate() {
            let expect = if k % 5 == 0 { 1.0 } else { 0.0 };
            assert!(close(*v, expect), "{m:?}");
        }
        assert_eq!(ArmPose::from_matrix(&m), ArmPose::IDENTITY);
    }

    #[test]
    fn poses_and_matrices_convert_both_ways() {
        let p = pose([0.4, -0.1, 0.3], [0.3, 0.8, -0.2, 0.4]);
        let back = ArmPose::from_matrix(&p.to_matrix());
        assert!(same_pose(&p, &back), "{p:?} vs {back:?}");
        // Half turns (trace −1) take each of the non-trace branches.
        for q in [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, 0.6, 0.8, 0.0],
        ] {
            let p = pose([0.0; 3], q);
            let back = ArmPose::from_matrix(&p.to_matrix());
            assert!(same_pose(&p, &back), "{q:?}: {back:?}");
        }
    }

    #[test]
    fn the_matrix_moves_points_like_the_pose() {
        let p = pose([0.4, -0.1, 0.3], [0.3, 0.8, -0.2, 0.4]);
        let v = [0.02, -0.5, 1.5];
        let by_pose = p.rotate(v);
        let by_matrix = apply(&p.to_matrix(), v);
        for i in 0..3 {
            assert!(close(by_matrix[i], by_pose[i] + p.translation_m[i]));
        }
    }

    #[test]
    fn slerp_ends_at_its_ends_and_halves_the_angle() {
        let a = pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        let b = pose([0.2, -0.4, 0.6], [0.0, 0.0, 0.0, 1.0]);
        assert!(same_pose(&a.slerp(&b, 0.0), &a));
        assert!(same_pose(&a.slerp(&b, 1.0), &b));
        let mid = a.slerp(&b, 0.5);
        assert!(close(a.angle_to(&mid), std::f64::consts::FRAC_PI_2));
        assert!(close(mid.angle_to(&b), std::f64::consts::FRAC_PI_2));
        assert!(same_pose(
            &mid,
            &pose([0.1, -0.2, 0.3], [1.0, 0.0, 0.0, 1.0])
        ));
    }

    #[test]
    fn slerp_takes_the_short_way_round() {
        let a = ArmPose::from_translation_yaw([0.0; 3], 170f64.to_radians());
        let b = ArmPose::from_translation_yaw([0.0; 3], -170f64.to_radians());
        assert!(close(a.angle_to(&b), 20f64.to_radians()));
        let mid = a.slerp(&b, 0.5);
        assert!(close(mid.yaw_rad().abs(), std::f64::consts::PI), "{mid:?}");
    }

    #[test]
    fn antipodal_quaternions_are_one_orientation() {
        let q = [0.3, 0.8, -0.2, 0.4];
        let a = pose([0.0; 3], q);
        let b = pose([0.0; 3], q.map(|v| -v));
        // Rounding near `acos(1)` leaves up to ~3e-8 rad.
        assert!(a.angle_to(&b).abs() < 1e-7);
        for s in [0.0, 0.5, 1.0] {
            let p = a.slerp(&b, s);
            assert!(p.is_valid() && same_pose(&p, &a), "{s}: {p:?}");
        }
    }

    #[test]
    fn near_identical_poses_give_finite_results() {
        let a = ArmPose::from_translation_yaw([0.1, 0.2, 0.3], 0.7);
        let b = ArmPose::from_translation_yaw([0.1, 0.2, 0.3 + 1e-12], 0.7 + 1e-10);
        let angle = a.angle_to(&b);
        assert!(angle.is_finite() && angle < 1e-6, "{angle}");
        assert!(a.angle_to(&a).is_finite());
        for s in [0.0, 1e-9, 0.5, 1.0] {
            let p = a.slerp(&b, s);
            assert!(p.is_valid() && same_pose(&p, &a), "{s}: {p:?}");
        }
        let zero = pose([0.0; 3], [0.0; 4]);
        assert!(zero.angle_to(&ArmPose::IDENTITY).abs() < 1e-12);
        assert_eq!(zero.rotation_wxyz, [1.0, 0.0, 0.0, 0.0]);
    }

    proptest! {
        #[test]
        fn any_pose_survives_the_matrix_and_slerp_is_uniform(
            q in proptest::array::uniform4(-1.0..1.0f64), t in proptest::array::uniform3(-1.0..1.0f64),
            q2 in proptest::array::uniform4(-1.0..1.0f64), s in 0.0..1.0f64,
        ) {
            prop_assume!(q.iter().map(|v| v * v).sum::<f64>() > 1e-3);
            prop_assume!(q2.iter().map(|v| v * v).sum::<f64>() > 1e-3);
            let a = pose(t, q);
            prop_assert!(same_pose(&a, &ArmPose::from_matrix(&a.to_matrix())));
            let b = pose([0.0; 3], q2);
            let total = a.angle_to(&b);
            let p = a.slerp(&b, s);
            prop_assert!((a.angle_to(&p) - s * total).abs() < 1e-5, "{} vs {}", a.angle_to(&p), s * total);
            prop_assert!((p.angle_to(&b) - (1.0 - s) * total).abs() < 1e-5);
        }
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
