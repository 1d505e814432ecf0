//! The hold's physics state, stepped on the injected clock: the fingers, the object, its lift and turns, the flow.

use super::*;

/// The fluid `obj` carries along as it accelerates along G's x (`axis` 0) or z (1),
/// kg (0 unless the scene lists `object_added_mass`).
pub(super) fn added_mass_kg(effects: &Effects, obj: &GraspObject, axis: usize) -> f64 {
    effects.object_added_mass_kg_m3.map_or(0.0, |rho| {
        rho * obj.added_mass_xz[axis.min(1)] * obj.volume_m3
    })
}

/// The vertical load the fingers' friction must carry while `obj` rises at `v_m_s`
/// with acceleration `a_m_s2` (both up), N: its weight and inertia, the inertia of
/// the fluid it carries along, less what the fluid buoys, plus the drag that opposes
/// a rising object (each only where the scene declares it).
pub(super) fn lift_load_n(effects: &Effects, obj: &GraspObject, v_m_s: f64, a_m_s2: f64) -> f64 {
    let drag_n = effects.object_drag_kg_m3.map_or(0.0, |rho| {
        0.5 * rho * obj.lift_drag_coefficient * obj.drag_area_m2 * v_m_s * v_m_s.abs()
    });
    obj.mass_kg * (G_M_S2 + a_m_s2) + added_mass_kg(effects, obj, 1) * a_m_s2
        - buoyancy_n(effects, obj)
        + drag_n
}

/// What the fluid carries of `obj`'s weight, N (0 unless the scene lists
/// `object_buoyancy`).
pub(super) fn buoyancy_n(effects: &Effects, obj: &GraspObject) -> f64 {
    effects
        .object_buoyancy_kg_m3
        .map_or(0.0, |rho| rho * G_M_S2 * obj.volume_m3)
}

/// A scheduled turn of the object about z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct YawMove {
    pub(super) t0: TimestampNs,
    pub(super) t1: TimestampNs,
    pub(super) to_rad: f64,
}

/// The current's speed over time: the mean plus the gusts, either three seeded sines
/// around the declared period or the declared spectrum with seeded phases.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct FlowSeries {
    pub(super) flow: Flow,
    /// (angular frequency rad/s, phase rad, weight): times `gust_m_s` for the three
    /// seeded sines, or each component's amplitude in m/s for a spectrum.
    pub(super) waves: Vec<(f64, f64, f64)>,
}

impl FlowSeries {
    pub(super) fn new(flow: Flow, seed: u64) -> Self {
        let mut rng = crate::rng::stream(seed, "object-flow");
        if !flow.spectrum.is_empty() {
            let waves = flow
                .spectrum
                .iter()
                .map(|&(period_s, amplitude_m_s)| {
                    (
                        std::f64::consts::TAU / period_s,
                        rng.random_range(0.0..std::f64::consts::TAU),
                        amplitude_m_s,
                    )
                })
                .collect();
            return Self { flow, waves };
        }
        let mut waves = vec![(0.0, 0.0, 0.0); 3];
        for w in &mut waves {
            let period = flow.period_s * rng.random_range(0.5..2.0);
            *w = (
                std::f64::consts::TAU / period,
                rng.random_range(0.0..std::f64::consts::TAU),
                rng.random_range(0.5..1.0),
            );
        }
        let total: f64 = waves.iter().map(|w| w.2).sum();
        for w in &mut waves {
            w.2 /= total;
        }
        Self { flow, waves }
    }

    /// `½·ρ·C_d·A` of `obj` on the outline the current meets (its side, not its top),
    /// N·s²/m²: the push is this × u·|u|.
    pub(super) fn side_drag(&self, obj: &GraspObject) -> f64 {
        0.5 * self.flow.density_kg_m3 * obj.drag_coefficient * obj.flow_area_m2
    }

    /// The current's own acceleration along G's +x at `t_s`, m/s²: the time derivative
    /// of [`FlowSeries::speed_m_s`] (the gusts'; a steady current has none).
    pub(super) fn accel_m_s2(&self, t_s: f64) -> f64 {
        let d: f64 = self
            .waves
            .iter()
            .map(|(omega, phase, weight)| weight * omega * (omega * t_s + phase).cos())
            .sum();
        if self.flow.spectrum.is_empty() {
            self.flow.gust_m_s * d
        } else {
            d
        }
    }

    /// The inertia force of an accelerating current on `obj` per m/s² of its
    /// acceleration, kg (Morison et al. 1950, "The force exerted by surface waves on
    /// piles", Petroleum Transactions 189:149-154; Newman 1977, *Marine Hydrodynamics*,
    /// ch. 4): `ρ·V·(1 + C_a)`, the pressure gradient that accelerates the water
    /// (Froude–Krylov, `ρ·V`) and the water the object's presence makes accelerate
    /// with it (`C_a·ρ·V`, across the
    /// object: `C_a` of its equivalent spheroid, as the added mass uses). Part of the
    /// declared current, whether or not the scene lists `object_added_mass` (which is
    /// the object's own acceleration in still water).
    pub(super) fn inertia_kg(&self, obj: &GraspObject) -> f64 {
        self.flow.density_kg_m3 * obj.volume_m3 * (1.0 + obj.added_mass_xz[0])
    }

    /// Speed along G's +x at `t_s`, m/s.
    pub(super) fn speed_m_s(&self, t_s: f64) -> f64 {
        let gust: f64 = self
            .waves
            .iter()
            .map(|(omega, phase, weight)| weight * (omega * t_s + phase).sin())
            .sum();
        if !self.flow.spectrum.is_empty() {
            return self.flow.mean_m_s + gust;
        }
        self.flow.mean_m_s + self.flow.gust_m_s * gust
    }
}

/// A finger's contact and the grip and shear it was worked out for.
#[derive(Debug, Clone)]
pub(super) struct ContactMemo {
    pub(super) grip: Grip,
    pub(super) shear_n: [f64; 2],
    /// Shared, not copied: the balance asks for it tens of times a frame.
    pub(super) contact: Arc<FingerContact>,
}

/// The shared state of the soft grasp.
#[derive(Debug)]
pub(super) struct State {
    /// One scene per finger: the same model, each its own seeded renderer. Finger
    /// 1's is made when its camera is first asked for (its renderer's tables cost
    /// tens of milliseconds, and most grasps watch one finger).
    pub(super) scenes: [Option<Scene>; 2],
    /// The scene finger 1's is made from, and its seed.
    pub(super) second_spec: (SceneSpec, u64),
    pub(super) model: Arc<Model>,
    pub(super) effects: Effects,
    pub(super) finger: FingerGeometry,
    pub(super) contact: ContactParams,
    pub(super) clock: TokioClock,
    pub(super) period_ns: f64,
    /// The object's template.
    pub(super) template: GraspObject,
    /// The object between the fingers, if still there.
    pub(super) object: Option<GraspObject>,
    pub(super) hold: HoldState,
    pub(super) activated: bool,
    pub(super) cmd: GripperCommand,
    pub(super) opening_mm: f64,
    pub(super) last_t: TimestampNs,
    pub(super) status: ObjectStatus,
    pub(super) lift: Option<Lift>,
    pub(super) yaw_moves: Vec<YawMove>,
    pub(super) flow: Option<FlowSeries>,
    /// The wrist's turn about z and where it is going, rad.
    pub(super) wrist_rad: f64,
    pub(super) wrist_target_rad: f64,
    /// The object's shift towards finger 0, m.
    pub(super) shift_m: f64,
    /// The shift's rate on the support, m/s (`Effect::ObjectSupport`; 0 otherwise).
    pub(super) slide_m_s: f64,
    /// The largest squeeze both fingers had on the object at once (the smaller of the
    /// two) since it was put in place, N: whether the fingers ever gripped it, which
    /// the watched finger alone cannot say (an object on a tray or in a current may
    /// rest against one finger only).
    pub(super) peak_grip_n: f64,
    /// The object's turn against the fingers at the last step, rad.
    pub(super) rel_yaw_rad: f64,
    /// Each finger's stuck tangential displacement along its y, m.
    pub(super) stick_m: [f64; 2],
    /// Each finger's shear (y, z in its frame), N.
    pub(super) shear_n: [[f64; 2]; 2],
    /// Each finger's last contact and the grip and shear it was worked out for: the
    /// physics steps, the status and the camera ask for the same one many times while
    /// nothing moves (a steady hold).
    pub(super) last_contact: RefCell<[Option<ContactMemo>; 2]>,
    /// Each finger's strips against the object at its last turn: the same for every
    /// contact until the object turns.
    pub(super) strips: RefCell<[Option<Arc<Strips>>; 2]>,
    /// Each camera's last solved lattice and the contact it was solved for.
    pub(super) last_deformed: [Option<(Contact, Deformed)>; 2],
}

impl State {
    /// Finger `k`'s scene (0 or 1), made on first use.
    pub(super) fn scene(&mut self, k: usize) -> &Scene {
        let (spec, seed) = &self.second_spec;
        let model = &self.model;
        self.scenes[k.min(1)].get_or_insert_with(|| Scene::new(spec, *seed, Arc::clone(model)))
    }

    pub(super) fn object_yaw_at(&self, t: TimestampNs) -> f64 {
        let mut yaw = 0.0;
        for m in &self.yaw_moves {
            if t <= m.t0 {
                break;
            }
            if t >= m.t1 || m.t1 <= m.t0 {
                yaw = m.to_rad;
            } else {
                let s = (t.0 - m.t0.0) as f64 / (m.t1.0 - m.t0.0) as f64;
                // Smoothstep: the turn starts and ends at rest.
                let s = s * s * (3.0 - 2.0 * s);
                yaw += (m.to_rad - yaw) * s;
                break;
            }
        }
        yaw
    }

    pub(super) fn grip(&self, opening_mm: f64) -> Grip {
        Grip {
            opening_m: opening_mm / 1000.0,
            shift_m: self.shift_m,
            yaw_rad: self.rel_yaw_rad,
        }
    }

    /// Finger `k`'s contact at `opening_mm` with the present shift, turn and shear
    /// (`None`: no object).
    pub(super) fn finger_at(
        &self,
        k: usize,
        opening_mm: f64,
    ) -> Result<Option<Arc<FingerContact>>, SimError> {
        let Some(obj) = &self.object else {
            return Ok(None);
        };
        let grip = self.grip(opening_mm);
        let shear = self.shear_n[k];
        // The same inputs bit for bit: the same contact.
        if let Some(m) = &self.last_contact.borrow()[k]
            && m.grip == grip
            && m.shear_n.map(f64::to_bits) == shear.map(f64::to_bits)
        {
            return Ok(Some(Arc::clone(&m.contact)));
        }
        let contact = Arc::new(contact_on(
            &self.strips_of(k, obj),
            &self.finger,
            &self.contact,
            obj,
            &grip,
            shear,
        )?);
        self.last_contact.borrow_mut()[k] = Some(ContactMemo {
            grip,
            shear_n: shear,
            contact: Arc::clone(&contact),
        });
        Ok(Some(contact))
    }

    /// Finger `k`'s strips against `obj` (the object) at its present turn.
    pub(super) fn strips_of(&self, k: usize, obj: &GraspObject) -> Arc<Strips> {
        if let Some(s) = &self.strips.borrow()[k]
            && s.are_for(k, self.rel_yaw_rad)
        {
            return Arc::clone(s);
        }
        let s = Arc::new(Strips::new(
            &self.finger,
            &self.contact,
            obj,
            k,
            self.rel_yaw_rad,
        ));
        self.strips.borrow_mut()[k] = Some(Arc::clone(&s));
        s
    }

    /// The larger squeeze of the two fingers at an opening, N.
    pub(super) fn squeeze_at(&self, opening_mm: f64) -> Result<f64, SimError> {
        let mut most = 0.0_f64;
        for k in 0..2 {
            if let Some(c) = self.finger_at(k, opening_mm)? {
                most = most.max(c.squeeze_n());
            }
        }
        Ok(most)
    }

    /// The true wrench on finger `k` (its sensor frame) now.
    pub(super) fn wrench(&self, k: usize) -> Result<Wrench, SimError> {
        Ok(self
            .finger_at(k, self.opening_mm)?
            .map_or(Wrench::ZERO, |c| c.contact.wrench))
    }

    /// Advances fingers and physics to `now` in steps of at most [`STEP_NS`].
    pub(super) fn advance(&mut self, now: TimestampNs) -> Result<(), SimError> {
        while self.last_t < now {
            let t = TimestampNs(now.0.min(self.last_t.0.saturating_add(STEP_NS)));
            let dt_s = (t.0 - self.last_t.0) as f64 * 1e-9;
            self.last_t = t;
            self.move_fingers(dt_s)?;
            self.physics(t, dt_s)?;
        }
        Ok(())
    }

    /// Moves the fingers for `dt_s` at the commanded speed; stops on a squeeze that
    /// exceeds the grip-force cap.
    pub(super) fn move_fingers(&mut self, dt_s: f64) -> Result<(), SimError> {
        if !self.activated {
            return Ok(());
        }
        let target = opening_mm(self.cmd.position);
        let speed =
            SPEED_MM_S[0] + (SPEED_MM_S[1] - SPEED_MM_S[0]) * f64::from(self.cmd.speed) / 255.0;
        let step = speed * dt_s;
        let closing = target < self.opening_mm;
        let next = if closing {
            (self.opening_mm - step).max(target)
        } else {
            (self.opening_mm + step).min(target)
        };
        let cap_n = grip_force_n(self.cmd.force);
        if closing && self.squeeze_at(next)? > cap_n {
            // Find where the cap is reached (force grows with closing) and stop there.
            let (mut lo, mut hi) = (next, self.opening_mm);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if self.squeeze_at(mid)? > cap_n {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            self.opening_mm = hi;
            self.status = ObjectStatus::ContactClosing;
        } else {
            self.opening_mm = next;
            self.status = if (self.opening_mm - target).abs() < 1e-9 {
                ObjectStatus::AtPosition
            } else {
                ObjectStatus::Moving
            };
        }
        Ok(())
    }

    /// The fluid `obj` carries along as it accelerates along G's x (`axis` 0) or z
    /// (1), kg (0 unless the scene lists `object_added_mass`).
    fn added_mass_kg(&self, obj: &GraspObject, axis: usize) -> f64 {
        added_mass_kg(&self.effects, obj, axis)
    }

    /// Each finger's squeeze along the object's shift at the present opening, turn and
    /// shear (the same bits as its whole contact, at a fraction of the cost); `None`
    /// where it is not finite and the whole contact raised no error either.
    fn squeezes_along(
        &self,
        obj: &GraspObject,
    ) -> Result<Option<[SqueezeAlongShift; 2]>, SimError> {
        let squeezes = [0, 1].map(|k| {
            SqueezeAlongShift::new(
                self.strips_of(k, obj),
                &self.contact,
                obj,
                &self.grip(self.opening_mm),
                self.shear_n[k],
            )
        });
        let [Ok(along_0), Ok(along_1)] = squeezes else {
            // The whole contact says what is not finite.
            self.finger_at(0, self.opening_mm)?;
            self.finger_at(1, self.opening_mm)?;
            return Ok(None);
        };
        Ok(Some([along_0, along_1]))
    }

    /// The normal force and squeeze of finger `k` at `shift` (N): where they are not
    /// finite, the whole contact's error.
    fn probe(
        &mut self,
        along: &[SqueezeAlongShift; 2],
        k: usize,
        shift: f64,
    ) -> Result<(f64, f64), SimError> {
        match along[k.min(1)].at(shift) {
            Some(v) => Ok(v),
            None => {
                self.shift_m = shift;
                Ok(self
                    .finger_at(k, self.opening_mm)?
                    .map_or((0.0, 0.0), |c| (c.normal_n, c.squeeze_n())))
            }
        }
    }

    /// One step of an object resting on a support with friction coefficient `mu`,
    /// along the closing direction (`Effect::ObjectSupport`): implicit Euler of
    /// `m_eff·dv/dt = F_fingers + F_current + F_friction`, where the friction holds
    /// the object up to `μ·(m·g − ρ·g·V)` and opposes its sliding beyond. So a finger
    /// that touches first pushes the object ahead of it until the other finger meets
    /// it, a current drifts an object its friction cannot hold, and one the fluid
    /// carries (neutrally buoyant) sways with the gusts. Implicit, because the soft
    /// fingers are stiff against a light object at the 2 ms step.
    pub(super) fn slide_on_support(
        &mut self,
        mu: f64,
        u_m_s: f64,
        du_dt_m_s2: f64,
        dt_s: f64,
    ) -> Result<(), SimError> {
        let Some(obj) = self.object.clone() else {
            return Ok(());
        };
        let (s0, w0) = (self.shift_m, self.slide_m_s);
        let mu = obj.support_friction.unwrap_or(mu);
        let hold_n = mu * (obj.mass_kg * G_M_S2 - buoyancy_n(&self.effects, &obj)).max(0.0);
        let mass_kg = obj.mass_kg + self.added_mass_kg(&obj, 0);
        let drag = self.flow.as_ref().map_or(0.0, |f| f.side_drag(&obj));
        // The accelerating current's inertia force along +x (Morison).
        let inertia_n = self
            .flow
            .as_ref()
            .map_or(0.0, |f| f.inertia_kg(&obj) * du_dt_m_s2);
        let Some(along) = self.squeezes_along(&obj)? else {
            return Ok(());
        };
        // The shift grows towards finger 0 (G's −x): the object's velocity along +x is
        // −w, the current meets it at u + w. H(s) is the inertia less the forces
        // along +shift; the step lands where H equals the friction, which only grows
        // with s (finger 0 presses harder, finger 1 less, the drag grows).
        let h = |st: &mut Self, s1: f64| -> Result<f64, SimError> {
            let w1 = (s1 - s0) / dt_s;
            let a = st.probe(&along, 0, s1)?.1;
            let b = st.probe(&along, 1, s1)?.1;
            let rel = u_m_s + w1;
            Ok(mass_kg * (w1 - w0) / dt_s + a - b + drag * rel * rel.abs() + inertia_n)
        };
        let h0 = h(self, s0)?;
        if !h0.is_finite() {
            return Err(SimError::InvalidParameter(format!(
                "object `{}` on its support: the forces along the closing direction are not finite ({h0})",
                obj.name
            )));
        }
        if h0.abs() <= hold_n {
            // The friction holds it.
            self.shift_m = s0;
            self.slide_m_s = 0.0;
            return Ok(());
        }
        // It slides towards growing s where H < −friction, and the friction opposes it.
        let dir = if h0 < 0.0 { 1.0 } else { -1.0 };
        let target = -dir * hold_n;
        let f = |st: &mut Self, s1: f64| -> Result<f64, SimError> { Ok(h(st, s1)? - target) };
        let (mut lo, mut f_lo) = (s0, h0 - target);
        let mut step = (2.0 * w0.abs() * dt_s).max(1e-7);
        let (mut hi, mut f_hi);
        let mut tries = 0;
        loop {
            hi = s0 + dir * step;
            f_hi = f(self, hi)?;
            tries += 1;
            if f_hi * dir >= 0.0 || tries >= 64 {
                break;
            }
            (lo, f_lo) = (hi, f_hi);
            step *= 2.0;
        }
        if f_hi * dir < 0.0 {
            return Err(SimError::InvalidParameter(format!(
                "object `{}` on its support: no balance within {step} m",
                obj.name
            )));
        }
        // H only grows with s: the bracket's lower end is where f is below 0.
        let (left, right) = if dir > 0.0 {
            ((lo, f_lo), (hi, f_hi))
        } else {
            ((hi, f_hi), (lo, f_lo))
        };
        let x = self.illinois(left, right, f)?;
        self.shift_m = x;
        self.slide_m_s = (x - s0) / dt_s;
        // Pushed or drifted beyond the open stroke: out of the fingers' reach.
        if x.abs() * 1000.0 > STROKE_MM {
            return self.lose(HoldState::Absent);
        }
        Ok(())
    }

    /// The object's shift that balances a push along G's +x, m: the squeeze on finger
    /// 0 less that on finger 1 equals −push.
    pub(super) fn balance_shift(&mut self, push_n: f64) -> Result<f64, SimError> {
        let last_m = self.shift_m;
        self.shift_m = 0.0;
        let Some(obj) = &self.object else {
            return Ok(0.0);
        };
        let obj = obj.clone();
        let Some(along) = self.squeezes_along(&obj)? else {
            return Ok(0.0);
        };
        let at = |s: &mut Self, k: usize, shift: f64| s.probe(&along, k, shift);
        // Not gripped by both fingers: the support keeps it where it is.
        for k in 0..2 {
            if at(self, k, 0.0)?.0 <= 0.0 {
                self.shift_m = 0.0;
                return Ok(0.0);
            }
        }
        // Squeeze on finger 0 less that on finger 1 plus the push: grows with the shift.
        let imbalance = |s: &mut Self, shift: f64| -> Result<f64, SimError> {
            let a = at(s, 0, shift)?.1;
            let b = at(s, 1, shift)?.1;
            Ok(a - b + push_n)
        };
        let reach = 0.25 * self.object.as_ref().map_or(0.0, GraspObject::max_width_m);
        // Bracket the balance around the last step's shift first (a step changes the
        // push and the grip a little), widening to the whole reach: about half the
        // contacts of bracketing the whole reach every step.
        let mut half_m = if last_m.is_finite() && last_m.abs() < reach {
            WARM_BRACKET_M
        } else {
            2.0 * reach
        };
        let (mut lo, mut hi, mut f_lo, mut f_hi);
        let mut tries = 0;
        loop {
            tries += 1;
            lo = (last_m - half_m).max(-reach);
            hi = (last_m + half_m).min(reach);
            if !lo.is_finite() || !hi.is_finite() || lo >= hi {
                (lo, hi) = (-reach, reach);
            }
            (f_lo, f_hi) = (imbalance(self, lo)?, imbalance(self, hi)?);
            let whole = lo <= -reach && hi >= reach;
            // The push beats the squeeze anywhere within reach: the object sits at
            // the end.
            if lo <= -reach && f_lo >= 0.0 {
                return Ok(lo);
            }
            if hi >= reach && f_hi <= 0.0 {
                return Ok(hi);
            }
            // (A reach that is not a number never becomes whole: the tries end it.)
            if (f_lo < 0.0 && f_hi > 0.0) || whole || tries >= 16 {
                break;
            }
            half_m *= 8.0;
        }
        self.illinois((lo, f_lo), (hi, f_hi), imbalance)
    }

    /// Illinois false position for the root of `f` between `lo` (where it is below 0)
    /// and `hi` (above), `f` growing smoothly: a few steps reach 0.1 µN, where 30
    /// bisections would cost 60 contacts. At most 60 steps, or a bracket of 1 pm.
    fn illinois(
        &mut self,
        (mut lo, mut f_lo): (f64, f64),
        (mut hi, mut f_hi): (f64, f64),
        f: impl Fn(&mut Self, f64) -> Result<f64, SimError>,
    ) -> Result<f64, SimError> {
        let mut last_side = 0;
        let mut x = 0.0;
        for _ in 0..60 {
            x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
            if !x.is_finite() {
                x = 0.5 * (lo + hi);
            }
            let fx = f(self, x)?;
            if fx.abs() <= 1e-7 || hi - lo <= 1e-12 {
                break;
            }
            if fx > 0.0 {
                (hi, f_hi) = (x, fx);
                if last_side == 1 {
                    f_lo *= 0.5;
                }
                last_side = 1;
            } else {
                (lo, f_lo) = (x, fx);
                if last_side == -1 {
                    f_hi *= 0.5;
                }
                last_side = -1;
            }
        }
        Ok(x)
    }

    /// One step of the hold's physics at `t`.
    pub(super) fn physics(&mut self, t: TimestampNs, dt_s: f64) -> Result<(), SimError> {
        // The wrist turns towards its target at its top speed.
        let turn = (self.wrist_target_rad - self.wrist_rad)
            .clamp(-WRIST_MAX_RAD_S * dt_s, WRIST_MAX_RAD_S * dt_s);
        self.wrist_rad += turn;
        let rel_yaw = self.object_yaw_at(t) - self.wrist_rad;
        let d_yaw = rel_yaw - self.rel_yaw_rad;
        self.rel_yaw_rad = rel_yaw;
        let Some(obj) = self.object.clone() else {
            self.shear_n = [[0.0; 2]; 2];
            self.stick_m = [0.0; 2];
            self.shift_m = 0.0;
            return Ok(());
        };
        let t_s = t.0 as f64 * 1e-9;
        let u = self.flow.as_ref().map_or(0.0, |f| f.speed_m_s(t_s));
        let du_dt = self.flow.as_ref().map_or(0.0, |f| f.accel_m_s2(t_s));
        // A current that is not a number has no physical outcome: an error, never a
        // shift solved to the end of the reach.
        if !(u.is_finite() && du_dt.is_finite()) {
            return Err(SimError::InvalidParameter(format!(
                "object `{}`: the current at {t_s:.3} s is not finite ({u} m/s, {du_dt} m/s²)",
                obj.name
            )));
        }
        let lifted = self.lift.is_some_and(|l| t >= l.t0);
        match self.effects.support_friction {
            // On its support: friction and inertia decide where it goes.
            Some(mu) if !lifted => {
                self.slide_on_support(mu, u, du_dt, dt_s)?;
                if self.object.is_none() {
                    return Ok(());
                }
            }
            _ if self.flow.is_some() || self.effects.support_friction.is_some() => {
                self.slide_m_s = 0.0;
                // On the outline the current meets: the object's side, not its top;
                // and its inertia force as it gusts (Morison).
                let push_n = self.flow.as_ref().map_or(0.0, |f| {
                    f.side_drag(&obj) * u * u.abs() + f.inertia_kg(&obj) * du_dt
                });
                self.shift_m = self.balance_shift(push_n)?;
            }
            _ => {}
        }
        let mut contacts = Vec::with_capacity(2);
        for k in 0..2 {
            contacts.push(self.finger_at(k, self.opening_mm)?);
        }
        let normal = |k: usize| contacts[k].as_ref().map_or(0.0, |c| c.normal_n);
        let squeeze = |k: usize| contacts[k].as_ref().map_or(0.0, |c| c.squeeze_n());
        self.peak_grip_n = self.peak_grip_n.max(squeeze(0).min(squeeze(1)));
        if let Some(limit) = obj.crush_force_n
            && squeeze(0).max(squeeze(1)) > limit
        {
            return self.lose(HoldState::Crushed { t });
        }
        let total_n = normal(0) + normal(1);
        let capacity_n = obj.friction * total_n;
        let mut load_n = [0.0; 2];
        if let Some(lift) = self.lift
            && t >= lift.t0
        {
            let (v, a) = lift.motion((t.0 - lift.t0.0) as f64 * 1e-9);
            let load = lift_load_n(&self.effects, &obj, v, a);
            // A load or a grip that is not a number is a fault of the inputs, not a
            // slip (nor a hold: NaN compares false).
            if !(load.is_finite() && capacity_n.is_finite()) {
                return Err(SimError::InvalidParameter(format!(
                    "object `{}` on the lift: the load ({load} N) or the friction's capacity ({capacity_n} N) is not finite",
                    obj.name
                )));
            }
            if load.abs() > capacity_n {
                return self.lose(HoldState::Slipped { t });
            }
            self.hold = HoldState::Held;
            for k in 0..2 {
                load_n[k] = load * normal(k) / total_n.max(f64::MIN_POSITIVE);
            }
        }
        // The twist: an elastic stick up to the friction the load leaves, then sliding.
        for k in 0..2 {
            let n = normal(k);
            let radius = contacts[k].as_ref().map_or(0.0, |c| c.radius_m);
            if n <= 0.0 {
                self.stick_m[k] = 0.0;
                self.shear_n[k] = [0.0; 2];
                continue;
            }
            let stiffness = SHEAR_STIFFNESS_N_PER_M * n.cbrt();
            let room_n = ((obj.friction * n).powi(2) - load_n[k].powi(2))
                .max(0.0)
                .sqrt();
            let limit_m = room_n / stiffness;
            self.stick_m[k] = (self.stick_m[k] + radius * d_yaw).clamp(-limit_m, limit_m);
            // The object's surface drags each finger along its own −y for a positive turn.
            self.shear_n[k] = [-stiffness * self.stick_m[k], load_n[k]];
        }
        Ok(())
    }

    /// The object is gone (slipped or crushed): it pushes back no more.
    pub(super) fn lose(&mut self, how: HoldState) -> Result<(), SimError> {
        self.object = None;
        self.last_contact = RefCell::default();
        self.strips = RefCell::default();
        self.hold = how;
        self.shear_n = [[0.0; 2]; 2];
        self.stick_m = [0.0; 2];
        self.shift_m = 0.0;
        self.slide_m_s = 0.0;
        Ok(())
    }
}

pub(super) fn lock_state(state: &Mutex<State>) -> Result<MutexGuard<'_, State>, DeviceError> {
    state.lock().map_err(|_| DeviceError::Fault {
        device: "sim".into(),
        code: None,
        message: "simulation state poisoned by an earlier panic".into(),
    })
}

pub(super) fn device_fault(device: &str, e: &SimError) -> DeviceError {
    DeviceError::Fault {
        device: device.into(),
        code: None,
        message: e.to_string(),
    }
}
