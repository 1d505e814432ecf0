//! What the experiment (never the loop) does with a soft grasp: the truth it reads, the lift, the object's turns, the wrist.

use super::*;

impl SoftGraspHandle {
    pub(super) fn lock(&self) -> Result<MutexGuard<'_, State>, SimError> {
        self.state
            .lock()
            .map_err(|_| SimError::Solver("simulation state poisoned by an earlier panic".into()))
    }

    /// The camera of the second finger (mirrored, its own seeded stream), on the same
    /// frame grid as the first.
    pub fn second_camera(&self) -> Result<SoftFingerCamera, SimError> {
        let s = self.lock()?;
        Ok(SoftFingerCamera {
            state: Arc::clone(&self.state),
            clock: s.clock,
            period_ns: s.period_ns,
            finger: 1,
        })
    }

    /// The true wrench on finger 0 (sensor frame, no sensor effects) at time `t`.
    pub fn true_wrench(&self, t: TimestampNs) -> Result<Wrench, SimError> {
        self.true_wrench_on(0, t)
    }

    /// The true wrench on finger `finger` (0 or 1; its own sensor frame) at time `t`.
    pub fn true_wrench_on(&self, finger: usize, t: TimestampNs) -> Result<Wrench, SimError> {
        if finger > 1 {
            return Err(SimError::InvalidParameter(format!(
                "finger {finger}: expected 0 or 1"
            )));
        }
        let mut s = self.lock()?;
        s.advance(t)?;
        s.wrench(finger)
    }

    /// Takes the object away (it was pulled out), or puts a fresh one back (resting).
    pub fn set_object(&self, present: bool) -> Result<(), SimError> {
        let mut s = self.lock()?;
        s.object = present.then(|| s.template.clone());
        s.last_contact = RefCell::default();
        s.strips = RefCell::default();
        s.hold = if present {
            HoldState::Resting
        } else {
            HoldState::Absent
        };
        s.lift = None;
        s.stick_m = [0.0; 2];
        s.shear_n = [[0.0; 2]; 2];
        s.shift_m = rest_shift_m(&s.effects, &s.template);
        s.slide_m_s = 0.0;
        s.peak_grip_n = 0.0;
        Ok(())
    }

    /// Puts a fresh object where the fingers meet it with the grasp point moved by
    /// `offset_m` ([`GraspObject::placed`]), resting on its support (an operator set
    /// it back in place and the arm came down around it); none when the fingers miss
    /// it. Returns whether it is between them.
    pub fn place_object(&self, offset_m: [f64; 3]) -> Result<bool, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        s.object = s.template.placed(offset_m);
        s.shift_m = s
            .object
            .as_ref()
            .map_or(0.0, |o| rest_shift_m(&s.effects, o));
        s.slide_m_s = 0.0;
        s.peak_grip_n = 0.0;
        s.last_contact = RefCell::default();
        s.strips = RefCell::default();
        s.hold = if s.object.is_some() {
            HoldState::Resting
        } else {
            HoldState::Absent
        };
        s.lift = None;
        s.stick_m = [0.0; 2];
        s.shear_n = [[0.0; 2]; 2];
        Ok(s.object.is_some())
    }

    /// The arm lowered a held object onto its support: it rests again, still between
    /// the fingers, and a later lift is a new one. An object that fell stays fallen.
    pub fn set_down(&self) -> Result<(), SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        if matches!(s.hold, HoldState::Held | HoldState::Resting) {
            s.hold = HoldState::Resting;
            s.lift = None;
        }
        Ok(())
    }

    /// Whether the object is between the fingers.
    pub fn has_object(&self) -> Result<bool, SimError> {
        Ok(self.lock()?.object.is_some())
    }

    /// Whether the grip crushed the object.
    pub fn crushed(&self) -> Result<bool, SimError> {
        Ok(matches!(self.lock()?.hold, HoldState::Crushed { .. }))
    }

    /// The opening between the fingers now, mm.
    pub fn opening_mm(&self) -> Result<f64, SimError> {
        Ok(self.lock()?.opening_mm)
    }

    /// The object the grasp was built with.
    pub fn object(&self) -> Result<GraspObject, SimError> {
        Ok(self.lock()?.template.clone())
    }

    /// Lift starts at `t`: the gripper rises `height_m`, accelerating at `accel_m_s2`
    /// up to `speed_m_s` (trapezoid). Before this the object rests on its support.
    pub fn start_lift(
        &self,
        t: TimestampNs,
        height_m: f64,
        speed_m_s: f64,
        accel_m_s2: f64,
    ) -> Result<(), SimError> {
        let lift = Lift::checked(t, height_m, speed_m_s, accel_m_s2)?;
        let mut s = self.lock()?;
        if s.lift.is_some() {
            return Err(SimError::InvalidParameter(
                "lift: already started (one lift per grasp)".into(),
            ));
        }
        if t < s.last_t {
            return Err(SimError::InvalidParameter(format!(
                "lift start {} ns lies before the simulation's present {} ns",
                t.0, s.last_t.0
            )));
        }
        s.lift = Some(lift);
        Ok(())
    }

    /// What the physics says happened so far (advanced to the clock's present).
    pub fn hold_state(&self) -> Result<HoldState, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(s.hold)
    }

    /// [`Self::hold_state`] after advancing the physics to `t`.
    pub fn hold_state_at(&self, t: TimestampNs) -> Result<HoldState, SimError> {
        let mut s = self.lock()?;
        s.advance(t)?;
        Ok(s.hold)
    }

    /// Turns the object about z (its axis along the finger) to `yaw_rad`, starting at
    /// `t0` and taking `duration_s` (smoothly, starting and ending at rest). Turns are
    /// scheduled in order and must not overlap.
    pub fn schedule_object_yaw(
        &self,
        t0: TimestampNs,
        yaw_rad: f64,
        duration_s: f64,
    ) -> Result<(), SimError> {
        if !(yaw_rad.is_finite() && yaw_rad.abs() <= 4.0 * std::f64::consts::PI) {
            return Err(SimError::InvalidParameter(format!(
                "object yaw {yaw_rad} rad: expected a finite value within ±4π"
            )));
        }
        if !(duration_s.is_finite() && (0.0..=600.0).contains(&duration_s)) {
            return Err(SimError::InvalidParameter(format!(
                "turn duration {duration_s} s: expected a value in [0, 600]"
            )));
        }
        let mut s = self.lock()?;
        if let Some(last) = s.yaw_moves.last()
            && t0 < last.t1
        {
            return Err(SimError::InvalidParameter(format!(
                "object turn at {} ns overlaps the previous one (ends at {} ns)",
                t0.0, last.t1.0
            )));
        }
        if t0 < s.last_t {
            return Err(SimError::InvalidParameter(format!(
                "object turn at {} ns lies before the simulation's present {} ns",
                t0.0, s.last_t.0
            )));
        }
        let t1 = TimestampNs(t0.0.saturating_add((duration_s * 1e9) as u64));
        s.yaw_moves.push(YawMove {
            t0,
            t1,
            to_rad: yaw_rad,
        });
        Ok(())
    }

    /// The object's yaw about z at `t`, rad (the schedule; world frame).
    pub fn object_yaw(&self, t: TimestampNs) -> Result<f64, SimError> {
        Ok(self.lock()?.object_yaw_at(t))
    }

    /// Asks the simulated wrist to turn the gripper about z to `yaw_rad`; it gets there
    /// at up to [`WRIST_MAX_RAD_S`].
    pub fn set_wrist_target(&self, yaw_rad: f64) -> Result<(), SimError> {
        if !(yaw_rad.is_finite() && yaw_rad.abs() <= 4.0 * std::f64::consts::PI) {
            return Err(SimError::InvalidParameter(format!(
                "wrist yaw {yaw_rad} rad: expected a finite value within ±4π"
            )));
        }
        self.lock()?.wrist_target_rad = yaw_rad;
        Ok(())
    }

    /// The wrist's yaw at `t`, rad.
    pub fn wrist_yaw(&self, t: TimestampNs) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        s.advance(t)?;
        Ok(s.wrist_rad)
    }

    /// The wrist's yaw now (the clock's present), rad.
    pub fn wrist_yaw_now(&self) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(s.wrist_rad)
    }

    /// The current's push on the object along the gripping direction (G's +x) at `t`,
    /// N (0 unless the scene lists `object_flow` and an object is held).
    pub fn flow_push_n(&self, t: TimestampNs) -> Result<f64, SimError> {
        let s = self.lock()?;
        let (Some(series), Some(obj)) = (&s.flow, &s.object) else {
            return Ok(0.0);
        };
        let u = series.speed_m_s(t.0 as f64 * 1e-9);
        Ok(series.side_drag(obj) * u * u.abs())
    }

    /// The largest squeeze both fingers have had on the object at once (the smaller of
    /// the two) since it was put in place, N, advanced to the clock's present: whether
    /// the fingers gripped it at all. The loop watches one finger, and an object that
    /// moves may rest against either one alone.
    pub fn peak_grip_n(&self) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(s.peak_grip_n)
    }

    /// The object's displacement along G's +x from where the fingers meet it, m, at
    /// the clock's present (0 without an object).
    pub fn object_x_m(&self) -> Result<f64, SimError> {
        let mut s = self.lock()?;
        let now = s.clock.now();
        s.advance(now)?;
        Ok(if s.object.is_some() { -s.shift_m } else { 0.0 })
    }

    /// The squeeze on one finger (−F_x in its sensor frame, N) at each gripper count
    /// in `counts`, from the contact physics with the object in place, centred and not
    /// turned: the curve the stiffness Λ = ∂F/∂P is measured on.
    pub fn grip_force_curve(&self, counts: &[u8]) -> Result<Vec<(u8, f64)>, SimError> {
        let s = self.lock()?;
        let grip = |p: u8| Grip {
            opening_m: opening_mm(p) / 1000.0,
            ..Grip::default()
        };
        counts
            .iter()
            .map(|&p| {
                let c = finger_contact(&s.finger, &s.contact, &s.template, 0, &grip(p), [0.0; 2])?;
                Ok((p, c.squeeze_n()))
            })
            .collect()
    }

    /// The largest stiffness Λ = ∂F/∂P over consecutive counts in `from..=to`, N per
    /// mm of closing, from [`Self::grip_force_curve`].
    pub fn max_stiffness_n_per_mm(&self, from: u8, to: u8) -> Result<f64, SimError> {
        let counts: Vec<u8> = (from.min(to)..=from.max(to)).collect();
        let curve = self.grip_force_curve(&counts)?;
        let mm_per_count = STROKE_MM / 255.0;
        Ok(curve
            .windows(2)
            .map(|w| (w[1].1 - w[0].1) / mm_per_count)
            .fold(0.0, f64::max))
    }

    /// The count at which the fingers first touch the object (force above `threshold_n`).
    pub fn contact_count(&self, threshold_n: f64) -> Result<Option<u8>, SimError> {
        let counts: Vec<u8> = (0..=255).collect();
        Ok(self
            .grip_force_curve(&counts)?
            .into_iter()
            .find(|(_, f)| *f > threshold_n)
            .map(|(p, _)| p))
    }
}
