//! One motion through legs along one straight line, each at up to its own speed: an
//! approach crosses free space fast, enters the contact at the approach speed and
//! ends slow, without stopping between legs (each Franka motion has its own start and
//! stop, which dominate short moves: a 21 mm leg took 0.39 s against franka-sim).
//!
//! The path parameter `s ∈ [0, 1]` runs along the line; leg `k` ends at `s = end_k`
//! and is driven at up to `speed_k` (both in path units). Everything is franka-rs's
//! jerk-limited [`franka::Otg`], re-planned every cycle:
//! - in leg `k` the generator's velocity limit is `speed_k` and its target the nearest
//!   point where it must be slow: for each later boundary `end_j` whose next leg is
//!   slower than `speed_k`, `end_j + d(speed_{j+1})`, where `d(v)` is the shortest
//!   distance in which the generator stops from `v` (its last two segments: at the
//!   full deceleration `a`, then jerk `j` back to zero, `a³/(6j²)` for the jerk ramp).
//!   Braking towards that point, it is at `speed_{j+1}` at or before `end_j`;
//! - the next leg begins when the position reaches `end_k`, or earlier when the
//!   generator, braking, is already down to the next leg's speed. Only then is the
//!   limit changed, so a lowered limit never cuts the velocity (which would step the
//!   acceleration) and a raised one never asks for more than the limits allow.
//!
//! So a slower leg is never entered faster than its speed, every command stays within
//! the move's acceleration and jerk, and the motion ends at rest at `s = 1`.

use franka::{Otg, OtgLimits};

/// Shortest distance (path units) in which the generator stops from `v` while braking
/// at up to `a` with jerk `j`: on its final jerk ramp where `v ≤ a²/(2j)`, else at `−a`
/// and then the ramp.
fn stopping_distance(v: f64, a: f64, j: f64) -> f64 {
    let ramp_v = a * a / (2.0 * j);
    if v <= ramp_v {
        let a_c = (2.0 * j * v.max(0.0)).sqrt();
        a_c.powi(3) / (6.0 * j * j)
    } else {
        let t = (v - ramp_v) / a;
        v * t - a * t * t / 2.0 + a.powi(3) / (6.0 * j * j)
    }
}

/// The generator of one blended motion; see the module docs.
#[derive(Debug, Clone)]
pub struct Blend {
    otg: Otg,
    /// `(end, speed)` per leg, path units; ends increasing, the last at 1.
    legs: Vec<(f64, f64)>,
    leg: usize,
}

impl Blend {
    /// A generator at rest at `s = 0` for `legs` (`(end, speed)` in path units, ends
    /// strictly increasing within `(0, 1]`, the last 1; speeds positive and finite),
    /// accelerating and jerking at most as `limits` say (their velocity is ignored).
    /// `None` for legs that do not form such a path.
    #[must_use]
    pub fn new(legs: Vec<(f64, f64)>, limits: OtgLimits) -> Option<Self> {
        let ends_ok = legs.windows(2).all(|w| w[0].0 < w[1].0)
            && legs.first().is_some_and(|l| l.0 > 0.0)
            && legs.last().is_some_and(|l| (l.0 - 1.0).abs() < 1e-12);
        let speeds_ok = legs.iter().all(|l| l.1.is_finite() && l.1 > 0.0);
        if !(ends_ok && speeds_ok) {
            return None;
        }
        let otg = Otg::new(
            0.0,
            OtgLimits {
                max_velocity: legs[0].1,
                ..limits
            },
        )
        .ok()?;
        let mut b = Self { otg, legs, leg: 0 };
        let target = b.target_of(0);
        b.otg.set_target(target).ok()?;
        Some(b)
    }

    /// Where leg `k` aims: the nearest point it must be slow by, else the path's end.
    fn target_of(&self, k: usize) -> f64 {
        let l = self.otg.limits();
        let speed = self.legs[k].1;
        let mut target = 1.0f64;
        for w in self.legs[k..].windows(2) {
            let (end, next_speed) = (w[0].0, w[1].1);
            if next_speed < speed {
                let d = stopping_distance(next_speed, l.max_acceleration, l.max_jerk);
                target = target.min(end + d);
            }
        }
        target
    }

    /// Advance one cycle of `dt` seconds: the next leg first where this one is done,
    /// then the generator. Returns the new position.
    pub fn step(&mut self, dt: f64) -> f64 {
        while self.leg + 1 < self.legs.len() {
            let (end, speed) = self.legs[self.leg];
            let next_speed = self.legs[self.leg + 1].1;
            let braked = next_speed < speed
                && self.otg.velocity() <= next_speed
                && self.otg.acceleration() < 0.0;
            if !(self.otg.position() >= end || braked) {
                break;
            }
            self.leg += 1;
            let limits = OtgLimits {
                max_velocity: next_speed,
                ..self.otg.limits()
            };
            // Valid by construction: a positive finite speed, a target within [0, 1].
            let _ = self.otg.set_limits(limits);
            let target = self.target_of(self.leg);
            let _ = self.otg.set_target(target);
        }
        self.otg.step(dt)
    }

    /// The generator's state (position, velocity, acceleration; path units).
    #[must_use]
    pub fn otg(&self) -> &Otg {
        &self.otg
    }

    /// The leg the generator is in (0-based).
    #[must_use]
    pub fn leg(&self) -> usize {
        self.leg
    }

    /// At rest at the path's end.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.otg.position() >= 1.0 - 1e-9 && self.otg.velocity().abs() < 1e-9
    }

    /// The legs' ends, path units.
    pub fn ends(&self) -> impl Iterator<Item = f64> + '_ {
        self.legs.iter().map(|l| l.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An FR3 approach at its rig's limits: 21 mm at 0.5 m/s, 6 mm at 0.05 m/s, the last
    /// 3 mm at 0.02 m/s (30 mm in all; path units are metres / 0.03).
    fn approach() -> (Vec<(f64, f64)>, OtgLimits) {
        let d = 0.03;
        let legs = vec![(0.021 / d, 0.5 / d), (0.027 / d, 0.05 / d), (1.0, 0.02 / d)];
        let limits = OtgLimits {
            max_velocity: 1.0,
            max_acceleration: 2.7 / d,
            max_jerk: 1350.0 / d,
        };
        (legs, limits)
    }

    /// Run to rest at 1 kHz; per cycle `(s, v, a)` as commanded.
    fn run(mut b: Blend) -> Vec<(f64, f64, f64)> {
        let mut out = vec![(0.0, 0.0, 0.0)];
        let mut prev = 0.0;
        let mut v_prev = 0.0;
        while !b.finished() {
            let s = b.step(1e-3);
            let v = (s - prev) / 1e-3;
            out.push((s, v, (v - v_prev) / 1e-3));
            (prev, v_prev) = (s, v);
            assert!(out.len() < 100_000, "never ends");
        }
        out
    }

    #[test]
    fn a_slower_leg_is_never_entered_faster_than_its_speed() {
        let (legs, limits) = approach();
        let b = Blend::new(legs.clone(), limits).expect("a path");
        let cycles = run(b);
        let (last, _, _) = *cycles.last().expect("cycles");
        assert!((last - 1.0).abs() < 1e-9);
        for w in cycles.windows(2) {
            let (s, v, a) = w[1];
            // Never backs up, never passes the end.
            assert!(s >= w[0].0 - 1e-12 && s <= 1.0 + 1e-9, "{w:?}");
            // Within the leg's speed (a mean over the cycle), the acceleration, and the
            // jerk (a difference of two means: twice the cycle's jerk at most).
            let leg = legs
                .iter()
                .position(|l| w[0].0 < l.0)
                .unwrap_or(legs.len() - 1);
            let speed = legs[..=leg].iter().map(|l| l.1).fold(0.0, f64::max);
            assert!(v <= speed * (1.0 + 1e-9), "{v} in leg {leg}");
            assert!(a.abs() <= limits.max_acceleration * 1.001, "{a}");
            assert!(
                (a - w[0].2).abs() <= 2.0 * limits.max_jerk * 1e-3 * 1.001 + 1e-6,
                "jerk at {s}: {} -> {a}",
                w[0].2
            );
            // Past a boundary into a slower leg: at most that leg's speed.
            for k in 0..legs.len() - 1 {
                if w[0].0 >= legs[k].0 && legs[k + 1].1 < legs[k].1 {
                    let slowest_after = legs[k + 1..=leg.max(k + 1)]
                        .iter()
                        .map(|l| l.1)
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        v <= legs[k + 1].1.max(slowest_after) * (1.0 + 1e-6),
                        "{v} past boundary {k} at {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn one_blended_motion_is_faster_than_its_legs_one_by_one() {
        let (legs, limits) = approach();
        let blended = run(Blend::new(legs.clone(), limits).expect("a path")).len();
        // The same legs as three motions, each from rest to rest.
        let mut apart = 0;
        let mut from = 0.0;
        for (end, speed) in &legs {
            let mut otg = Otg::new(
                from,
                OtgLimits {
                    max_velocity: *speed,
                    ..limits
                },
            )
            .expect("otg");
            otg.set_target(*end).expect("target");
            // The generator snaps to rest exactly at its target.
            while otg.position().to_bits() != end.to_bits() || otg.velocity() != 0.0 {
                otg.step(1e-3);
                apart += 1;
            }
            from = *end;
        }
        // Less than the legs apart, even with nothing counted for each motion's start.
        eprintln!("the FR3 approach: blended {blended} cycles, leg by leg {apart}");
        assert!(blended < apart, "blended {blended} cycles, apart {apart}");
    }

    #[test]
    fn rising_speeds_and_a_single_leg_run_to_rest_at_the_end() {
        // A leave: 10 mm out of the contact at 0.1 m/s, then 30 mm at 0.5 m/s.
        let d = 0.04;
        let limits = OtgLimits {
            max_velocity: 1.0,
            max_acceleration: 2.7 / d,
            max_jerk: 1350.0 / d,
        };
        let legs = vec![(0.01 / d, 0.1 / d), (1.0, 0.5 / d)];
        let cycles = run(Blend::new(legs, limits).expect("a path"));
        let at_boundary = cycles.iter().find(|c| c.0 >= 0.25).expect("crossed");
        assert!(at_boundary.1 <= 0.1 / d * 1.001, "{at_boundary:?}");
        assert!(cycles.iter().any(|c| c.1 > 0.2 / d), "never sped up");
        let one = run(Blend::new(vec![(1.0, 0.5 / d)], limits).expect("a path"));
        assert!((one.last().expect("cycles").0 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn legs_that_do_not_form_a_path_are_refused() {
        let (_, limits) = approach();
        for legs in [
            vec![],
            vec![(0.5, 1.0)],
            vec![(0.5, 1.0), (0.4, 1.0), (1.0, 1.0)],
            vec![(0.0, 1.0), (1.0, 1.0)],
            vec![(0.5, f64::NAN), (1.0, 1.0)],
            vec![(0.5, 1.0), (1.0, 0.0)],
            vec![(f64::NAN, 1.0), (1.0, 1.0)],
        ] {
            assert!(Blend::new(legs.clone(), limits).is_none(), "{legs:?}");
        }
    }

    #[test]
    fn the_stopping_distance_is_the_generators_own() {
        // From cruise at v, the generator's own stop (target far enough ahead) covers
        // at least the shortest distance, which starts at full deceleration.
        for v in [0.001, 0.01, 0.1, 1.0, 10.0] {
            let (a, j) = (2.0, 50.0);
            let d = stopping_distance(v, a, j);
            assert!(d.is_finite() && d >= 0.0);
            let mut otg = Otg::new(
                0.0,
                OtgLimits {
                    max_velocity: v,
                    max_acceleration: a,
                    max_jerk: j,
                },
            )
            .expect("otg");
            otg.set_state(0.0, v, 0.0).expect("state");
            otg.set_target(0.0).expect("target");
            // Stopping "at 0" from v means overshooting by the stopping distance.
            let mut peak = 0.0f64;
            for _ in 0..200_000 {
                peak = peak.max(otg.step(1e-4));
                if otg.velocity() <= 0.0 {
                    break;
                }
            }
            assert!(peak >= d * 0.999, "v {v}: stopped in {peak}, shortest {d}");
        }
        assert!(stopping_distance(0.0, 1.0, 1.0).abs() < 1e-15);
    }
}
