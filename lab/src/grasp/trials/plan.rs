//! A session's plan: its settings as stored with it ([`TrialPlan`], [`RigPlan`]),
//! checked, and every trial it plans ([`planned`]).

use super::*;

/// A session's settings, stored as JSON with it (the field names are that JSON's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialPlan {
    /// Objects (`[[objects]]` names); empty: every object of the first scene.
    pub objects: Vec<String>,
    /// Modes: `open`, `closed`.
    pub modes: Vec<String>,
    /// Trials per object, mode, medium and σ.
    pub trials: u32,
    /// σ of the perturbation per axis, mm; more than one is a sweep.
    pub sigmas_mm: Vec<f64>,
    /// Camera rate, Hz (one control cycle per frame).
    pub fps: f64,
    /// Closed loop: the grip force F_ref, N.
    pub target_n: f64,
    /// Closed loop: the tolerance δ, N.
    pub tolerance_n: f64,
    /// K as a multiple of the measured Λ_max.
    pub gain_over_lambda: f64,
    /// Closed loop: how long |F_ref − F_est| ≤ δ must hold before the lift, s.
    pub confirm_s: f64,
    /// Closed loop: how long the loop may take to confirm, s.
    pub close_timeout_s: f64,
    /// How high the object is lifted, mm.
    pub lift_mm: f64,
    /// The lift's speed, m/s.
    pub lift_speed_m_s: f64,
    /// The lift's acceleration, m/s².
    pub lift_accel_m_s2: f64,
    /// How long it is held after the lift, s.
    pub hold_s: f64,
    /// Open loop: every object closed to this opening, mm, instead of its own width.
    pub open_width_mm: Option<f64>,
    /// The pre-grasp opening's margin, mm: with `pregrasp_from_touch`, this much short
    /// of the calibrated first touch; else this much wider than the grasp width.
    pub pregrasp_margin_mm: f64,
    /// The closed loop starts from the stiffness calibration's first touch less the
    /// margin (every session started by this build); `false` in sessions stored
    /// before, which keep the grasp width plus the margin, so a resume runs as the
    /// session began.
    #[serde(default)]
    pub pregrasp_from_touch: bool,
    /// Use stiffness calibrations their check refuses (`--accept-calibration`); each
    /// refusal is said in the session's header. Absent in sessions stored before.
    #[serde(default)]
    pub accept_calibration: bool,
    /// A rig's session: what its rig file chose (absent: a simulated session).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<RigPlan>,
    /// A scene value swept (`--sweep PATH=V1,V2,…`): the session's scenes are the base
    /// scenes at each value in turn (absent: no sweep).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep: Option<SceneSweep>,
    /// The scene values the session set (`--set PATH=VALUE`, as typed): shown beside
    /// its results, which they changed. Absent: none (or a session stored before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sets: Vec<String>,
    /// Read each water scene's frames through an image tare fitted at the session's
    /// start (`--tare`, [`crate::grasp::tare`]). Absent: no tare.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub tare: bool,
    /// The tare fitted for each scene (by index; `None`: read as it comes), stored so
    /// that a resume reads through the same one. Empty without `tare`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scene_tares: Vec<Option<crate::grasp::tare::SceneTare>>,
}

/// What a rig session runs on, stored with it: the fingerprint of the rig's gripper
/// and finger cameras (its calibrations' key), and the grasp section and workspace of
/// its rig file, so that a resume runs the same poses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigPlan {
    /// [`crate::grasp::calibration::rig_setup_hash`] of the rig.
    pub setup_hash: String,
    /// The rig file's `[grasp]`.
    pub grasp: softtouch_schemas::rig::GraspSetup,
    /// The rig file's `[workspace]`.
    pub workspace: softtouch_schemas::rig::WorkspaceBounds,
}

impl Default for TrialPlan {
    /// The paper's protocol: 10 trials, σ = 5 mm, both modes, 120 Hz, 1.5 N ± 0.1 N
    /// confirmed for 0.25 s within 4 s, K = 0.75 Λ_max, a 50 mm lift held 2 s.
    fn default() -> Self {
        Self {
            objects: Vec::new(),
            modes: vec!["open".into(), "closed".into()],
            trials: 10,
            sigmas_mm: vec![PAPER_SIGMA_MM],
            fps: 120.0,
            target_n: 1.5,
            tolerance_n: 0.1,
            gain_over_lambda: 0.75,
            confirm_s: 0.25,
            close_timeout_s: 4.0,
            lift_mm: 50.0,
            lift_speed_m_s: 0.1,
            lift_accel_m_s2: 2.0,
            hold_s: 2.0,
            open_width_mm: None,
            pregrasp_margin_mm: 6.0,
            pregrasp_from_touch: true,
            accept_calibration: false,
            rig: None,
            sweep: None,
            sets: Vec::new(),
            tare: false,
            scene_tares: Vec::new(),
        }
    }
}

/// A value in `(0, hi]`, with its kind and unit for the message.
pub(super) const fn above_zero(what: &'static str, hi: f64, unit: &'static str) -> Setting {
    Setting {
        what,
        lo: 0.0,
        lo_inclusive: false,
        hi,
        unit,
    }
}

impl TrialPlan {
    /// The tare fitted for scene `index`, if any.
    #[must_use]
    pub fn scene_tare(&self, index: usize) -> Option<&crate::grasp::tare::SceneTare> {
        self.scene_tares.get(index).and_then(Option::as_ref)
    }

    /// The image tare scene `index`'s frames are read through, if any.
    #[must_use]
    pub fn tare_of(&self, index: usize) -> Option<&softtouch_trainer::ImageTare> {
        self.scene_tare(index).map(|t| &t.tare)
    }

    /// The plan checked (each setting in its range, named by its flag) and
    /// normalised: each mode and object once, in the order first given (a repeated
    /// object would run its trials twice, the second time as already stored).
    ///
    /// # Errors
    /// The first setting out of range.
    pub fn checked(mut self) -> Result<Self, TrialsError> {
        settings::FPS_HZ.check("--fps", self.fps)?;
        settings::TOLERANCE_N.check("--tolerance", self.tolerance_n)?;
        settings::check_target_n("--target-n", self.target_n, self.tolerance_n)?;
        above_zero("a value", 60.0, "s").check("--confirm-s", self.confirm_s)?;
        above_zero("a value", 600.0, "s").check("--close-timeout-s", self.close_timeout_s)?;
        above_zero("a value", 500.0, "mm").check("--lift-mm", self.lift_mm)?;
        settings::duration_s(false).check("--hold-s", self.hold_s)?;
        if self.trials == 0 || self.trials > 10_000 {
            return Err(invalid(format!(
                "--trials {}: expected 1 to 10000 trials per object and mode",
                self.trials
            )));
        }
        for s in &self.sigmas_mm {
            if !(s.is_finite() && (0.0..=50.0).contains(s)) {
                return Err(invalid(format!(
                    "σ {s} mm (--sigma-mm / --sweep-sigma): expected a value in [0, 50] mm"
                )));
            }
        }
        let mut modes = Vec::new();
        for m in &self.modes {
            let mode = Mode::parse(m).map_err(|e| invalid(format!("--modes: {e}")))?;
            if !modes.contains(&mode.as_str().to_owned()) {
                modes.push(mode.as_str().to_owned());
            }
        }
        if modes.is_empty() {
            return Err(invalid("--modes: expected open, closed or both".into()));
        }
        self.modes = modes;
        if let Some(w) = self.open_width_mm {
            above_zero("a value", STROKE_MM, "mm").check("--open-width-mm", w)?;
        }
        let mut objects: Vec<String> = Vec::new();
        for o in &self.objects {
            if !objects.contains(o) {
                objects.push(o.clone());
            }
        }
        self.objects = objects;
        Ok(self)
    }

    /// The modes, parsed.
    ///
    /// # Errors
    /// A stored mode that is not one (a damaged session).
    pub fn parsed_modes(&self) -> Result<Vec<Mode>, TrialsError> {
        self.modes
            .iter()
            .map(|m| Mode::parse(m).map_err(|e| TrialsError::Failed(format!("stored plan: {e}"))))
            .collect()
    }

    pub(crate) fn lift(&self) -> LiftPlan {
        LiftPlan {
            height_m: self.lift_mm / 1000.0,
            speed_m_s: self.lift_speed_m_s,
            accel_m_s2: self.lift_accel_m_s2,
        }
    }
}

/// One planned trial.
#[derive(Debug, Clone)]
pub struct Planned {
    /// Its key in the store.
    pub key: GraspTrialKey,
    /// Open or closed loop.
    pub mode: Mode,
    /// σ of the perturbation per axis, m.
    pub sigma_m: f64,
}

/// Every trial of the plan over `scenes` scenes, in the order they run.
#[must_use]
pub fn planned(plan: &TrialPlan, scenes: usize, modes: &[Mode]) -> Vec<Planned> {
    let mut out = Vec::new();
    for (si, sigma) in plan.sigmas_mm.iter().enumerate() {
        for scene_index in 0..scenes {
            for object in &plan.objects {
                for mode in modes {
                    for trial in 0..plan.trials {
                        out.push(Planned {
                            key: GraspTrialKey {
                                sigma_index: si as u32,
                                scene_index: scene_index as u32,
                                object: object.clone(),
                                mode: mode.as_str().to_owned(),
                                trial,
                            },
                            mode: *mode,
                            sigma_m: sigma / 1000.0,
                        });
                    }
                }
            }
        }
    }
    out
}
