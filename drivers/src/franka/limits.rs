//! A move's limits: [`MotionLimits`] (a rig's share of the robot's, and the brake's),
//! the robot's Cartesian limits, and the path parameter's limits for one move.

use super::*;

/// Limits of a move (defaults: franka-rs target control's conservative ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Translational acceleration, m/s² (FCI allows 13; one FER refused 2.5).
    pub accel_m_s2: f64,
    /// Translational jerk, m/s³ (FCI allows 6500).
    pub jerk_m_s3: f64,
    /// Rotational velocity, rad/s (FCI allows 2.5).
    pub rot_speed_rad_s: f64,
    /// Rotational acceleration, rad/s² (FCI allows 25).
    pub rot_accel_rad_s2: f64,
    /// Rotational jerk, rad/s³ (FCI allows 12500).
    pub rot_jerk_rad_s3: f64,
    /// Translational deceleration when a move is aborted (the force guard's stop),
    /// m/s²: at least a move's own ([`MotionLimits::for_robot`]), so a brake always
    /// stops sooner than the move would.
    pub brake_accel_m_s2: f64,
    /// Translational jerk when a move is aborted, m/s³.
    pub brake_jerk_m_s3: f64,
    /// Translational speed a move is held to, m/s (a faster request is slowed).
    pub max_speed_m_s: f64,
    /// Test only, 1 on every rig: any other value plans every move's acceleration and
    /// jerk at this many times the robot's own Cartesian limits, skipping every limit
    /// and joint check. The franka-sim tier sets it to prove that its check of the
    /// commanded signal catches a broken plan.
    pub test_rate_scale: f64,
}

impl Default for MotionLimits {
    fn default() -> Self {
        Self {
            accel_m_s2: 0.5,
            jerk_m_s3: 20.0,
            rot_speed_rad_s: 0.5,
            rot_accel_rad_s2: 1.0,
            rot_jerk_rad_s3: 20.0,
            // What one FER accepted near the ready pose (docs/PROTOCOLS.md: 1.5 m/s² with
            // 200 m/s³ passed where 2.5 m/s² was refused): from the 0.05 m/s approach
            // it stops in about 41 ms and 1 mm, against 125 ms and 3 mm at the move's
            // own 0.5 m/s² and 20 m/s³.
            brake_accel_m_s2: 1.5,
            brake_jerk_m_s3: 200.0,
            max_speed_m_s: MAX_SPEED_M_S,
            test_rate_scale: 1.0,
        }
    }
}

/// A robot's Cartesian limits (libfranka's `rate_limiting.h`; franka-sim enforces the
/// same): `(velocity m/s, acceleration m/s², jerk m/s³, rotational velocity rad/s,
/// rotational acceleration rad/s², rotational jerk rad/s³)`.
#[must_use]
pub const fn cartesian_limits(robot: reach::Robot) -> [f64; 6] {
    match robot {
        reach::Robot::Fr3 => [3.0, 9.0, 4500.0, 2.5, 17.0, 8500.0],
        reach::Robot::Fer => [1.7, 13.0, 6500.0, 2.5, 25.0, 12500.0],
    }
}

impl MotionLimits {
    /// `margin` (in (0, 1]; anything else is taken as the default) of `robot`'s
    /// Cartesian limits. An abort brakes at least as hard as the move it stops: the
    /// harder of the move's own acceleration and jerk and the default brake's (1.5
    /// m/s², 200 m/s³: what one FER accepted), softened only where the joints need it
    /// (`run_path`). Its stopping distance at a rig's approach speeds is
    /// [`MotionLimits::stopping_distance_m`] (RIG.md gives the table).
    #[must_use]
    pub fn for_robot(robot: reach::Robot, margin: f64) -> Self {
        let m = if margin.is_finite() && margin > 0.0 && margin <= 1.0 {
            margin
        } else {
            softtouch_schemas::FRANKA_DEFAULT_MOTION_MARGIN
        };
        let [v, a, j, rv, ra, rj] = cartesian_limits(robot);
        let d = Self::default();
        Self {
            accel_m_s2: a * m,
            // Jerk within what one lost cycle leaves room for (reach::JERK_MARGIN).
            jerk_m_s3: j * m.min(reach::JERK_MARGIN),
            rot_speed_rad_s: rv * m,
            rot_accel_rad_s2: ra * m,
            rot_jerk_rad_s3: rj * m.min(reach::JERK_MARGIN),
            brake_accel_m_s2: d.brake_accel_m_s2.max(a * m),
            brake_jerk_m_s3: d.brake_jerk_m_s3.max(j * m.min(reach::JERK_MARGIN)),
            max_speed_m_s: (v * m).min(MAX_SPEED_M_S),
            test_rate_scale: 1.0,
        }
    }

    /// How far a straight move at `speed_m_s` (at its cruise: no acceleration) runs
    /// after an abort before it is at rest, m, braking at these limits.
    #[must_use]
    pub fn stopping_distance_m(&self, speed_m_s: f64) -> f64 {
        let b = Brake::new(
            0.0,
            speed_m_s,
            0.0,
            self.brake_accel_m_s2,
            self.brake_jerk_m_s3,
        );
        b.state_at(b.duration()).0
    }

    /// The limits an aborted move brakes with: the brake's translation, the move's
    /// rotation (no braking rotation has been measured on a Panda).
    #[must_use]
    pub const fn braking(&self) -> Self {
        Self {
            accel_m_s2: self.brake_accel_m_s2,
            jerk_m_s3: self.brake_jerk_m_s3,
            ..*self
        }
    }
}

/// The FCI's translational velocity limit used here (frankx's 1.7 m/s), m/s.
pub const MAX_SPEED_M_S: f64 = 1.7;

/// Limits of the path parameter s ∈ [0, 1] for a move of `dist_m` and `angle_rad`,
/// such that translation and rotation both stay within theirs.
#[must_use]
pub fn path_limits(
    dist_m: f64,
    angle_rad: f64,
    speed_m_s: f64,
    l: &MotionLimits,
) -> franka::OtgLimits {
    let per = |lin: f64, rot: f64| {
        let a = if dist_m > 1e-9 {
            lin / dist_m
        } else {
            f64::INFINITY
        };
        let b = if angle_rad > 1e-9 {
            rot / angle_rad
        } else {
            f64::INFINITY
        };
        let v = a.min(b);
        if v.is_finite() { v } else { 1e6 }
    };
    franka::OtgLimits {
        max_velocity: per(
            speed_m_s.min(l.max_speed_m_s).min(MAX_SPEED_M_S),
            l.rot_speed_rad_s,
        ),
        max_acceleration: per(l.accel_m_s2, l.rot_accel_rad_s2),
        max_jerk: per(l.jerk_m_s3, l.rot_jerk_rad_s3),
    }
}
