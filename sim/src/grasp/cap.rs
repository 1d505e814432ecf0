//! What the physics allows a grip, from the scene alone: for an object and a lift, the
//! least squeeze per finger that carries it through the lift, and the squeeze that
//! crushes it ([`grip_window`]); and from those, the most of a scene's objects any
//! one grip force holds ([`GripCap`]): the closed loop's cap, whatever the model.
//!
//! The same load as the hold's physics ([`lift_load_n`]): weight and inertia, the
//! inertia of the fluid carried along, buoyancy and drag where the scene declares
//! them. The fingers hold it while the load is within μ times their two normal
//! forces; a squeeze along the grip axis is taken as each finger's normal force (a
//! contact tilted by a curved surface needs a little more).

use super::*;

/// The grip an object allows.
#[derive(Debug, Clone, PartialEq)]
pub struct GripWindow {
    /// The object's name.
    pub object: String,
    /// The friction coefficient of the grip (its wet one where the scene declares wet
    /// contact).
    pub friction: f64,
    /// The largest vertical load over the lift, N.
    pub peak_load_n: f64,
    /// The least squeeze per finger that holds it through the lift, N: the peak load
    /// over 2μ.
    pub holds_from_n: f64,
    /// The squeeze per finger that crushes it, N (`None`: rigid).
    pub crushes_above_n: Option<f64>,
}

impl GripWindow {
    /// Whether a squeeze of `force_n` per finger both holds it and leaves it whole.
    #[must_use]
    pub fn holds_at(&self, force_n: f64) -> bool {
        force_n >= self.holds_from_n && self.crushes_above_n.is_none_or(|c| force_n <= c)
    }
}

/// The window of `object` in `scene` for a trapezoidal lift of `height_m` at up to
/// `speed_m_s`, accelerating and braking at `accel_m_s2`.
///
/// # Errors
/// A lift the simulator would refuse (`start_lift`'s bounds), wet contact on an
/// object without a wet friction, an object whose friction is not positive, a load
/// that is not finite.
pub fn grip_window(
    scene: &SceneSpec,
    object: &GraspObject,
    height_m: f64,
    speed_m_s: f64,
    accel_m_s2: f64,
) -> Result<GripWindow, SimError> {
    // The lift the simulator would run, checked as `start_lift` checks it.
    let lift = Lift::checked(TimestampNs::ZERO, height_m, speed_m_s, accel_m_s2)?;
    let effects = Effects::from_scene(scene);
    let friction = grip_friction(&effects, object)?;
    if !(friction.is_finite() && friction >= 0.0) {
        return Err(SimError::InvalidParameter(format!(
            "object `{}`: friction {friction}: expected a number ≥ 0",
            object.name
        )));
    }
    // The load's extremes lie at the phases' ends: sampled at 0.5 ms over the lift.
    let duration_s = lift.duration_s();
    let steps = ((duration_s / 5e-4).ceil() as usize).clamp(2, 2_000_000);
    let mut peak_load_n = f64::NEG_INFINITY;
    for i in 0..=steps {
        let (v, a) = lift.motion(duration_s * i as f64 / steps as f64);
        peak_load_n = peak_load_n.max(lift_load_n(&effects, object, v, a).abs());
    }
    if !peak_load_n.is_finite() {
        return Err(SimError::InvalidParameter(format!(
            "object `{}`: the load on the lift is not finite",
            object.name
        )));
    }
    Ok(GripWindow {
        object: object.name.clone(),
        friction,
        peak_load_n,
        // No friction: no squeeze holds it (infinite, not a division's NaN at 0/0).
        holds_from_n: if friction > 0.0 {
            peak_load_n / (2.0 * friction)
        } else {
            f64::INFINITY
        },
        crushes_above_n: object.crush_force_n,
    })
}

/// The most of a scene's objects that any one grip force holds.
#[derive(Debug, Clone, PartialEq)]
pub struct GripCap {
    /// How many objects that force holds.
    pub held: usize,
    /// Of how many.
    pub of: usize,
    /// The least squeeze per finger that holds that many, N (`None`: no object).
    pub at_n: Option<f64>,
}

impl GripCap {
    /// The best of `windows` over every grip force.
    #[must_use]
    pub fn of(windows: &[GripWindow]) -> Self {
        // The count only rises where some object starts to hold.
        let (held, at_n) = windows
            .iter()
            .map(|w| w.holds_from_n)
            .filter(|f| f.is_finite())
            .map(|f| (windows.iter().filter(|w| w.holds_at(f)).count(), f))
            .fold((0, None), |(best, at), (n, f)| {
                if n > best || (n == best && at.is_some_and(|a: f64| f < a)) {
                    (n, Some(f))
                } else {
                    (best, at)
                }
            });
        Self {
            held,
            of: windows.len(),
            at_n,
        }
    }

    /// The share held, 0–1 (0 with no object).
    #[must_use]
    pub fn rate(&self) -> f64 {
        if self.of == 0 {
            0.0
        } else {
            self.held as f64 / self.of as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(name: &str, from: f64, crush: Option<f64>) -> GripWindow {
        GripWindow {
            object: name.into(),
            friction: 0.5,
            peak_load_n: from,
            holds_from_n: from,
            crushes_above_n: crush,
        }
    }

    #[test]
    fn the_cap_is_the_most_objects_one_force_holds() {
        // A heavy slippery one needs 3.2 N, a delicate one crushes above 2.5 N.
        let w = [
            window("bottle", 3.2, None),
            window("cake", 0.4, Some(2.5)),
            window("ball", 0.5, None),
        ];
        let cap = GripCap::of(&w);
        assert_eq!((cap.held, cap.of, cap.at_n), (2, 3, Some(0.5)));
        assert!((cap.rate() - 2.0 / 3.0).abs() < 1e-12);
        // Room for both: all three.
        let w = [window("bottle", 2.0, None), window("cake", 0.4, Some(2.5))];
        assert_eq!(GripCap::of(&w).held, 2);
        // Nothing, and an object no force holds.
        assert!(GripCap::of(&[]).rate().abs() < f64::EPSILON);
        let never = [window("x", f64::INFINITY, None)];
        assert_eq!(GripCap::of(&never).held, 0);
    }

    #[test]
    fn bad_lifts_and_frictions_are_named() {
        let scenes = [softtouch_schemas::defaults::GRASP_SCENE_TOML];
        let scene: SceneSpec = softtouch_schemas::config::parse_toml(
            scenes[0],
            &softtouch_schemas::config::ConfigSource::Embedded("grasp"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let object = GraspObject::from_spec(&scene.objects[0]);
        for (h, v, a) in [(0.0, 0.1, 2.0), (0.05, f64::NAN, 2.0), (0.05, 0.1, -1.0)] {
            assert!(
                grip_window(&scene, &object, h, v, a).is_err(),
                "{h} {v} {a}"
            );
        }
        let mut slick = object.clone();
        slick.friction = -0.1;
        let err = grip_window(&scene, &slick, 0.05, 0.1, 2.0)
            .err()
            .map(|e| e.to_string());
        assert!(
            err.as_deref().is_some_and(|e| e.contains("friction -0.1")),
            "{err:?}"
        );
        // No friction at all (a swept value): nothing holds it, and that is an answer.
        slick.friction = 0.0;
        let w = grip_window(&scene, &slick, 0.05, 0.1, 2.0).unwrap_or_else(|e| panic!("{e}"));
        assert!(w.holds_from_n.is_infinite() && !w.holds_at(100.0), "{w:?}");
        let w = grip_window(&scene, &object, 0.05, 0.1, 2.0).unwrap_or_else(|e| panic!("{e}"));
        // On land: weight and the lift's 2 m/s² over 2μ.
        let expected = object.mass_kg * (G_M_S2 + 2.0) / (2.0 * object.friction);
        assert!((w.holds_from_n - expected).abs() < 1e-9, "{w:?}");
    }
}
