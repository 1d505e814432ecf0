//! The arm's kinematics and the robot's joint limits: which robot ([`Robot`]), its
//! joint ranges, velocity limits (position-dependent on an FR3), acceleration and jerk
//! limits, and [`Kinematics`]: forward kinematics and the damped least-squares solve
//! with the end effector.

use super::*;

/// The robot model whose joint limits apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Robot {
    /// Franka Research 3 (FCI v10): position-dependent velocity limits.
    Fr3,
    /// Franka Emika Robot / Panda (FCI v5): constant velocity limits.
    Fer,
}

impl Robot {
    /// Its name in messages.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Fr3 => "FR3",
            Self::Fer => "Panda",
        }
    }

    /// Joint position limits `(lower, upper)`, rad (libfranka's, as franka-rs ports them).
    #[must_use]
    pub const fn position_limits(self) -> ([f64; 7], [f64; 7]) {
        match self {
            Self::Fr3 => franka::rate_limiting::JOINT_POSITION_LIMITS,
            Self::Fer => franka::rate_limiting::fer::JOINT_POSITION_LIMITS,
        }
    }

    /// Joint velocity limits `(lower, upper)` at `q`, rad/s.
    #[must_use]
    pub fn velocity_limits(self, q: &[f64; 7]) -> ([f64; 7], [f64; 7]) {
        match self {
            Self::Fr3 => (
                franka::compute_lower_limits_joint_velocity(q),
                franka::compute_upper_limits_joint_velocity(q),
            ),
            Self::Fer => (
                franka::rate_limiting::fer::MIN_JOINT_VELOCITY,
                franka::rate_limiting::fer::MAX_JOINT_VELOCITY,
            ),
        }
    }

    /// The robot an FCI version serves.
    #[must_use]
    pub const fn of(version: franka::FciVersion) -> Self {
        match version {
            franka::FciVersion::V10 => Self::Fr3,
            franka::FciVersion::V5 => Self::Fer,
        }
    }
}

/// The FR3's and Panda's "ready" joints (libfranka's examples): where `config check`
/// starts when no arm tells it where it is.
pub const READY_Q: [f64; 7] = [
    0.0,
    -std::f64::consts::FRAC_PI_4,
    0.0,
    -3.0 * std::f64::consts::FRAC_PI_4,
    0.0,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_4,
];

/// The arm's kinematics with its end effector: `F_T_EE` (flange to end effector,
/// column-major).
#[derive(Debug)]
pub struct Kinematics {
    model: franka::Model,
    f_t_ee: [f64; 16],
}

/// The identity transform, column-major (libfranka's layout).
pub const IDENTITY: [f64; 16] = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

impl Kinematics {
    /// The FER/FR3 kinematics with `f_t_ee` as the end effector.
    #[must_use]
    pub fn new(f_t_ee: [f64; 16]) -> Self {
        Self {
            model: franka::Model::native_fer(),
            f_t_ee,
        }
    }

    /// The same kinematics with `f_t_ee` as the end effector (the model is kept: it is
    /// parsed from a URDF).
    #[must_use]
    pub fn with_end_effector(self, f_t_ee: [f64; 16]) -> Self {
        Self { f_t_ee, ..self }
    }

    /// The end effector's pose at joints `q`.
    #[must_use]
    pub fn pose(&self, q: &[f64; 7]) -> ArmPose {
        ArmPose::from_matrix(&self.model.pose_q(
            franka::Frame::EndEffector,
            q,
            &self.f_t_ee,
            &IDENTITY,
        ))
    }

    fn jacobian(&self, q: &[f64; 7]) -> SMatrix<f64, 6, 7> {
        let j = self
            .model
            .zero_jacobian_q(franka::Frame::EndEffector, q, &self.f_t_ee, &IDENTITY);
        SMatrix::<f64, 6, 7>::from_column_slice(&j)
    }

    /// Joints that put the end effector at `target`, found from `seed` (the nearest
    /// solution it converges to), or `None` when none is found within 0.1 mm and
    /// 0.001 rad (out of reach, or a singularity on the way).
    #[must_use]
    pub fn solve(&self, target: &ArmPose, seed: &[f64; 7]) -> Option<[f64; 7]> {
        if !target.is_valid() || seed.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let want = target.normalised();
        let mut q = *seed;
        for _ in 0..200 {
            let (e, dp, dr) = self.pose_error(&want, &q);
            if dp < 1e-5 && dr < 1e-5 {
                return Some(q);
            }

            let j = self.jacobian(&q);
            // Damped least squares: steady near singularities, exact away from them.
            let damping = 1e-4;
            let jjt: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * damping;
            let y = jjt.lu().solve(&e)?;
            let mut dq = j.transpose() * y;
            // Small steps: the nearest solution, not a jump to another branch.
            let step = dq.amax();
            if step > 0.2 {
                dq *= 0.2 / step;
            }
            for (qi, d) in q.iter_mut().zip(dq.iter()) {
                *qi += d;
            }
            if q.iter().any(|v| !v.is_finite()) {
                return None;
            }
        }
        let at = self.pose(&q);
        (at.distance_to(&want) < 1e-4 && at.angle_to(&want) < 1e-3).then_some(q)
    }

    /// The error from the end effector at `q` to `want` (normalised): the stacked
    /// translation (m) and rotation vector (rad), and the norm of each.
    fn pose_error(&self, want: &ArmPose, q: &[f64; 7]) -> (Vector6<f64>, f64, f64) {
        let at = self.pose(q);
        let dp = Vector3::from(want.translation_m) - Vector3::from(at.translation_m);
        let dr = rotation_error(want, &at);
        let e = Vector6::new(dp[0], dp[1], dp[2], dr[0], dr[1], dr[2]);
        (e, dp.norm(), dr.norm())
    }

    /// `q` (near a solution for `target`) refined by Gauss-Newton steps, with no
    /// damping and the least joint motion, until the pose error is below `tol` (m and
    /// rad) or 20 steps pass: joints differenced at 1 kHz need them exact, where
    /// [`Kinematics::solve`] stops at 1e-5.
    #[must_use]
    pub fn refine(&self, target: &ArmPose, q: &[f64; 7], tol: f64) -> [f64; 7] {
        let want = target.normalised();
        let mut q = *q;
        for _ in 0..20 {
            let (e, dp, dr) = self.pose_error(&want, &q);
            if dp < tol && dr < tol {
                break;
            }
            let j = self.jacobian(&q);
            let jjt: Matrix6<f64> = j * j.transpose();
            let Some(y) = jjt.lu().solve(&e) else { break };
            let dq = j.transpose() * y;
            let next: [f64; 7] = std::array::from_fn(|i| q[i] + dq[i]);
            if next.iter().any(|v| !v.is_finite()) {
                break;
            }
            q = next;
        }
        q
    }
}

/// The rotation vector (axis × angle, base frame) that turns `at` into `want`: from
/// the quaternion `want · at⁻¹`, finite at zero angle (where a matrix's `acos` is not).
pub fn rotation_error(want: &ArmPose, at: &ArmPose) -> Vector3<f64> {
    let [w1, x1, y1, z1] = want.rotation_wxyz;
    let [w2, x2, y2, z2] = at.normalised().rotation_wxyz;
    // want · conj(at)
    let (x2, y2, z2) = (-x2, -y2, -z2);
    let mut w = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2;
    let mut v = Vector3::new(
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    );
    // The short way round.
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let s = v.norm();
    if s < 1e-12 {
        return 2.0 * v;
    }
    v * (2.0 * s.atan2(w) / s)
}

/// Joint acceleration and jerk limits `(rad/s², rad/s³)` of `robot` (libfranka's, as
/// franka-rs ports them: the FR3's uniform, the Panda's per joint).
#[must_use]
pub const fn joint_rate_limits(robot: Robot) -> ([f64; 7], [f64; 7]) {
    match robot {
        Robot::Fr3 => (
            franka::rate_limiting::MAX_JOINT_ACCELERATION,
            franka::rate_limiting::MAX_JOINT_JERK,
        ),
        Robot::Fer => (
            franka::rate_limiting::fer::MAX_JOINT_ACCELERATION,
            franka::rate_limiting::fer::MAX_JOINT_JERK,
        ),
    }
}
