//! The brake after an abort: from the path parameter's state to rest within the move's
//! acceleration and jerk limits.

/// Braking after an abort: from the path parameter's state `(s, v, a)` to rest within
/// the move's acceleration and jerk limits, as three constant-jerk pieces (the
/// time-optimal transfer to zero velocity that franka-rs's OTG also plans). Freezing
/// the setpoint instead would ask for an instant stop, which a Panda answers with a
/// reflex (`cartesian_motion_generator_velocity_discontinuity`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Brake {
    /// `(jerk, duration)` of each piece.
    pieces: [(f64, f64); 3],
    start: (f64, f64, f64),
    pub(super) elapsed: f64,
}

impl Brake {
    /// A brake from position `s`, velocity `v` and acceleration `a` (per second) under
    /// `a_max` and `j_max` (> 0; anything else is taken as 1e6, i.e. unconstrained).
    #[must_use]
    pub fn new(s: f64, v: f64, a: f64, a_max: f64, j_max: f64) -> Self {
        let limit = |x: f64| if x.is_finite() && x > 0.0 { x } else { 1e6 };
        let (a_max, j_max) = (limit(a_max), limit(j_max));
        let v = if v.is_finite() { v } else { 0.0 };
        let a = if a.is_finite() {
            a.clamp(-a_max, a_max)
        } else {
            0.0
        };
        // Brake in the direction that also cancels what the acceleration alone would
        // add by ramping to zero (a|a| / 2j); in that frame the transfer decelerates.
        let dv = -v;
        let sign = 1.0f64.copysign(dv - a * a.abs() / (2.0 * j_max));
        let (dv, a0) = (sign * dv, sign * a);
        let a_peak = (j_max * dv + 0.5 * a0 * a0).max(0.0).sqrt().min(a_max);
        let t1 = ((a_peak - a0) / j_max).max(0.0);
        let t3 = a_peak / j_max;
        let t2 = if a_peak > 0.0 {
            ((dv - (2.0 * a_peak * a_peak - a0 * a0) / (2.0 * j_max)) / a_peak).max(0.0)
        } else {
            0.0
        };
        Self {
            pieces: [(sign * j_max, t1), (0.0, t2), (-sign * j_max, t3)],
            start: (s, v, a),
            elapsed: 0.0,
        }
    }

    /// Whether it stays at or before path position `end` (the move's target) all the
    /// way to rest. A brake that would pass the target and come back is not one: cut
    /// off at the target it would ask for a jump in velocity (a jerk spike on the
    /// wire); the move's own plan stops there within its limits instead.
    #[must_use]
    pub fn stops_before(&self, end: f64) -> bool {
        let end = end + 1e-12;
        // The furthest point is where the velocity crosses zero, inside a piece or at
        // its end: each piece's velocity is a quadratic, so its roots are checked with
        // the ends.
        let (mut s, mut v, mut a) = self.start;
        if s.is_nan() || s > end {
            return false;
        }
        for &(jerk, duration) in &self.pieces {
            let at = |t: f64| s + v * t + a * t * t / 2.0 + jerk * t * t * t / 6.0;
            let mut times = vec![duration];
            // v + a t + jerk t²/2 = 0
            if jerk.abs() > 0.0 {
                let disc = a * a - 2.0 * jerk * v;
                if disc >= 0.0 {
                    let r = disc.sqrt();
                    times.extend([(-a + r) / jerk, (-a - r) / jerk]);
                }
            } else if a.abs() > 0.0 {
                times.push(-v / a);
            }
            if times.iter().any(|&t| {
                t.is_finite() && (0.0..=duration).contains(&t) && (at(t).is_nan() || at(t) > end)
            }) {
                return false;
            }
            (s, v, a) = (
                at(duration),
                v + a * duration + jerk * duration * duration / 2.0,
                a + jerk * duration,
            );
        }
        true
    }

    /// How long braking takes, s.
    #[must_use]
    pub fn duration(&self) -> f64 {
        self.pieces.iter().map(|p| p.1).sum()
    }

    /// Whether the path is at rest.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.elapsed >= self.duration()
    }

    /// `(s, v, a)` at `t` seconds after the abort (at rest after the last piece).
    #[must_use]
    pub fn state_at(&self, t: f64) -> (f64, f64, f64) {
        let (mut p, mut v, mut a) = self.start;
        let mut left = t.max(0.0);
        for &(jerk, duration) in &self.pieces {
            let dt = left.min(duration);
            p += v * dt + a * dt * dt / 2.0 + jerk * dt * dt * dt / 6.0;
            v += a * dt + jerk * dt * dt / 2.0;
            a += jerk * dt;
            left -= dt;
        }
        if t >= self.duration() {
            // The pieces end at rest up to rounding: do not creep on it.
            (v, a) = (0.0, 0.0);
        }
        (p, v, a)
    }

    /// Advance by `dt` seconds (ignored unless finite and positive); the new position.
    pub fn step(&mut self, dt: f64) -> f64 {
        if dt.is_finite() && dt > 0.0 {
            self.elapsed += dt;
        }
        self.state_at(self.elapsed).0
    }
}
