//! Grasp success-rate trials (the paper's Figure 4) on the simulated soft-finger
//! Hand-E, open loop against closed loop, per object and medium, each trial stored as
//! it ends (one transaction) so a session resumes where it stopped.
//!
//! A session's plan ([`TrialPlan`]) is its objects, modes, trial count, σ list and loop
//! settings, stored as JSON with the session beside its model (name and artifact
//! sha256), scenes (one per medium) and seed; trial `i` of an object is a pure function
//! of `(seed, object, i)` and σ, so it replays alone. [`start_session`] or
//! [`resume_session`], then [`run_trials`]; [`table::summarise`] gives the stored rows
//! per object, mode, medium and σ with Wilson 95 % intervals, and
//! [`table::write_outputs`] the CSVs and charts; [`experiment::run`] carries out a
//! whole `grasp trials` request, printing [`text`]'s tables. Nothing here parses
//! arguments.

pub mod experiment;
pub mod rig;
mod run;
pub mod table;
pub mod text;

pub use run::{RunEnd, TrialDone, TrialTiming, pack_trace, run_trials};

use serde::{Deserialize, Serialize};
use softtouch_drivers::gripper::STROKE_MM;
use softtouch_grasp::{GraspError, LiftPlan, Mode};
use softtouch_schemas::config::{ConfigSource, parse_toml};
use softtouch_schemas::overrides::{self, Override, Sweep};
use softtouch_schemas::{ConfigError, Medium, SceneSpec};
use softtouch_sim::GraspObject;

use super::settings::{self, Setting, SettingError};
use crate::models::ModelError;
use crate::store::{GraspTrialKey, Store, StoreError};
use softtouch_collector::dataset::export::sha256_hex;

/// The built-in scenes: on land and underwater, five objects each.
use softtouch_schemas::defaults::{
    GRASP_SCENE_TOML as LAND_TOML, GRASP_WATER_SCENE_TOML as WATER_TOML,
};

/// The grasp-point perturbation σ of the paper's success rates, mm (Figure 4): its
/// rates are shown beside this σ's rows only.
pub const PAPER_SIGMA_MM: f64 = 5.0;

/// The paper's overall success rates (Figure 4, σ = [`PAPER_SIGMA_MM`]): (medium, mode)
/// → rate.
#[must_use]
pub fn paper_rate(medium: Medium, mode: Mode) -> f64 {
    match (medium, mode) {
        (Medium::Air, Mode::Open) => 0.44,
        (Medium::Air, Mode::Closed) => 1.0,
        (Medium::Water, Mode::Open) => 0.30,
        (Medium::Water, Mode::Closed) => 0.90,
    }
}

/// A σ as the charts label it: the paper's is marked, `σ 5 mm (paper)`.
#[must_use]
pub fn sigma_label(sigma_mm: f64) -> String {
    if (sigma_mm - PAPER_SIGMA_MM).abs() < 1e-9 {
        format!("σ {sigma_mm} mm (paper)")
    } else {
        format!("σ {sigma_mm} mm")
    }
}

/// A medium as the tables name it.
#[must_use]
pub fn medium_name(m: Medium) -> &'static str {
    match m {
        Medium::Air => "land",
        Medium::Water => "water",
    }
}

/// What can go wrong in a trial session.
#[derive(Debug, thiserror::Error)]
pub enum TrialsError {
    /// The request cannot work (an unknown object, a session that is not there, a
    /// model changed under its name); the message says what is expected.
    #[error("{0}")]
    Invalid(String),
    /// A setting outside its range.
    #[error(transparent)]
    Setting(#[from] SettingError),
    /// A scene file that does not read.
    #[error(transparent)]
    Scene(#[from] ConfigError),
    /// The model could not be found or loaded.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The database failed (boxed: a store error is several times larger than the
    /// other variants).
    #[error(transparent)]
    Store(Box<StoreError>),
    /// The loop or the simulated grasp failed.
    #[error(transparent)]
    Grasp(#[from] GraspError),
    /// Something failed while running (a stored session that does not read back, a
    /// trial's thread, an output file).
    #[error("{0}")]
    Failed(String),
    /// A second stop request ended the run at once; the trial in hand is not stored.
    #[error("stopped at once by a second stop request; the trial in hand was not stored")]
    Interrupted,
}

impl TrialsError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Invalid(_) | Self::Setting(_) | Self::Scene(_) => true,
            Self::Model(e) => e.is_bad_input(),
            Self::Store(e) if matches!(**e, StoreError::NoSuchRun(_)) => true,
            Self::Grasp(GraspError::Config(_) | GraspError::UnreachableTarget { .. }) => true,
            Self::Store(_) | Self::Grasp(_) | Self::Failed(_) | Self::Interrupted => false,
        }
    }
}

impl From<StoreError> for TrialsError {
    fn from(e: StoreError) -> Self {
        Self::Store(Box::new(e))
    }
}

pub(crate) fn invalid(m: String) -> TrialsError {
    TrialsError::Invalid(m)
}

impl From<softtouch_trainer::TrainError> for TrialsError {
    fn from(e: softtouch_trainer::TrainError) -> Self {
        Self::Model(e.into())
    }
}

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
    /// A rig's session: what its rig file chose (absent: a simulated session).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<RigPlan>,
    /// A scene value swept (`--sweep PATH=V1,V2,…`): the session's scenes are the base
    /// scenes at each value in turn (absent: no sweep).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep: Option<SceneSweep>,
}

/// A scene value swept over a session, stored with its plan: the session's scenes are
/// the base scenes (one per medium), `per_value` of them, at each value in turn, so
/// scene `i` has value `i / per_value`. Every value runs the same trials: the
/// perturbations and the scenes' seeds depend on the seed, the object and the trial,
/// never on the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSweep {
    /// Dotted path of the value (`objects.bottle.wet_friction`).
    pub path: String,
    /// The values as typed.
    pub values: Vec<String>,
    /// Base scenes per value.
    pub per_value: u32,
    /// The value the scenes ship with, where they all have one and agree (marked on
    /// the charts; the paper gives no value for a scene's physics).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shipped: Option<String>,
}

impl SceneSweep {
    /// Value `i` as the charts label it: `0.05 (shipped)` for the scenes' own value.
    #[must_use]
    pub fn value_label(&self, i: usize) -> String {
        let v = self.values.get(i).map_or("?", String::as_str);
        if self.shipped.as_deref() == Some(v) {
            format!("{v} (shipped)")
        } else {
            v.to_owned()
        }
    }

    /// The swept value of scene `scene_index`.
    #[must_use]
    pub fn value_of(&self, scene_index: u32) -> Option<&str> {
        let i = scene_index.checked_div(self.per_value)? as usize;
        self.values.get(i).map(String::as_str)
    }

    /// Which value scene `scene_index` has.
    #[must_use]
    pub fn value_index(&self, scene_index: u32) -> Option<usize> {
        let i = scene_index.checked_div(self.per_value)? as usize;
        (i < self.values.len()).then_some(i)
    }
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
            rig: None,
            sweep: None,
        }
    }
}

/// A value in `(0, hi]`, with its kind and unit for the message.
const fn above_zero(what: &'static str, hi: f64, unit: &'static str) -> Setting {
    Setting {
        what,
        lo: 0.0,
        lo_inclusive: false,
        hi,
        unit,
    }
}

impl TrialPlan {
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

/// The scenes of `paths` (one per medium), or the built-in land and water scenes, with
/// each of `sets` applied to every scene that has its path's parent (the land scene's
/// objects and the water scene's alike; an effect only where it is declared), each
/// scene then checked as its file is.
///
/// # Errors
/// A scene file that does not read or validate, a set whose path is in no scene, a
/// value the scene refuses.
pub fn load_scenes(
    paths: &[std::path::PathBuf],
    sets: &[Override],
) -> Result<Vec<SceneSpec>, TrialsError> {
    let read: Vec<(SceneSpec, ConfigSource)> = if paths.is_empty() {
        [
            ("built-in land scene", LAND_TOML),
            ("built-in water scene", WATER_TOML),
        ]
        .iter()
        .map(|(name, text)| {
            let source = ConfigSource::Embedded(name);
            parse_toml::<SceneSpec>(text, &source)
                .map(|s| (s, source))
                .map_err(|e| TrialsError::Failed(e.to_string()))
        })
        .collect::<Result<_, _>>()?
    } else {
        paths
            .iter()
            .map(|p| {
                let r = softtouch_collector::configs::resolve(None, Some(p))?;
                Ok((r.scene, r.scene_source))
            })
            .collect::<Result<_, TrialsError>>()?
    };
    let mut scenes = Vec::with_capacity(read.len());
    for (mut scene, source) in read {
        let here: Vec<Override> = sets
            .iter()
            .filter(|o| overrides::applies_to(&scene, &o.path))
            .cloned()
            .collect();
        if !here.is_empty() {
            scene = overrides::apply(&scene, &here, &source)?;
        }
        scenes.push(scene);
    }
    for o in sets {
        in_some_scene(&scenes, &o.path, &format!("--set {o}"))?;
    }
    Ok(scenes)
}

/// Refuses a path that no scene has (its parent table), naming the scenes.
fn in_some_scene(scenes: &[SceneSpec], path: &str, flag: &str) -> Result<(), TrialsError> {
    if scenes.iter().any(|s| overrides::applies_to(s, path)) {
        return Ok(());
    }
    // The first scene's own words on where the path went astray.
    let why = scenes
        .first()
        .and_then(|s| overrides::astray(s, path))
        .unwrap_or_default();
    Err(invalid(format!(
        "{flag}: no scene has `{path}` (scenes: {}){}",
        scenes
            .iter()
            .map(|s| format!("`{}`", s.name))
            .collect::<Vec<_>>()
            .join(", "),
        if why.is_empty() {
            String::new()
        } else {
            format!("; {why}")
        }
    )))
}

/// The base scenes (one per medium) at each of `sweep`'s values in turn, and the
/// sweep as the plan stores it. A base scene without the path's parent (the land scene
/// for a water effect) runs unchanged at every value: the same trials again.
///
/// # Errors
/// A path in no scene, a value a scene refuses (named with the value).
pub fn swept_scenes(
    base: &[SceneSpec],
    sweep: &Sweep,
) -> Result<(Vec<SceneSpec>, SceneSweep), TrialsError> {
    in_some_scene(base, &sweep.path, &format!("--sweep {}", sweep.path))?;
    let mut out = Vec::with_capacity(base.len() * sweep.values.len());
    for i in 0..sweep.values.len() {
        let Some(o) = sweep.at(i) else { continue };
        for scene in base {
            out.push(if overrides::applies_to(scene, &o.path) {
                overrides::apply(
                    scene,
                    std::slice::from_ref(&o),
                    &ConfigSource::Embedded("scene"),
                )
                .map_err(|e| {
                    invalid(format!(
                        "--sweep {}: scene `{}` at {}: {e}",
                        sweep.path,
                        scene.name,
                        overrides::shown(&o.value)
                    ))
                })?
            } else {
                scene.clone()
            });
        }
    }
    let per_value =
        u32::try_from(base.len()).map_err(|_| invalid("--scene: too many scenes".into()))?;
    // The value the scenes ship with, where those that have the path agree on one.
    let mut shipped: Vec<String> = base
        .iter()
        .filter_map(|s| overrides::value_at(s, &sweep.path))
        .map(|v| overrides::shown(&v))
        .collect();
    shipped.dedup();
    Ok((
        out,
        SceneSweep {
            path: sweep.path.clone(),
            values: sweep.values.iter().map(overrides::shown).collect(),
            per_value,
            shipped: match shipped.as_slice() {
                [one] => Some(one.clone()),
                _ => None,
            },
        },
    ))
}

/// The objects of the plan in every scene, checked: known, and inside the stroke.
pub fn objects_of(
    plan: &TrialPlan,
    scenes: &[SceneSpec],
) -> Result<Vec<Vec<GraspObject>>, TrialsError> {
    scenes
        .iter()
        .map(|scene| {
            let known: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
            if known.is_empty() {
                return Err(invalid(format!(
                    "scene `{}` declares no [[objects]]: expected the objects to grasp",
                    scene.name
                )));
            }
            plan.objects
                .iter()
                .map(|name| {
                    let spec = scene.object(name).ok_or_else(|| {
                        invalid(format!(
                            "--objects: scene `{}` declares no object `{name}` (it has: {})",
                            scene.name,
                            known.join(", ")
                        ))
                    })?;
                    let object = GraspObject::from_spec(spec);
                    let widest_mm = object.max_width_m() * 1000.0;
                    let grasp_mm = plan
                        .open_width_mm
                        .unwrap_or(object.grasp_width_m * 1000.0);
                    if widest_mm >= STROKE_MM || grasp_mm >= STROKE_MM {
                        return Err(invalid(format!(
                            "object `{name}` of scene `{}` is {widest_mm:.1} mm at its widest (open-loop width {grasp_mm:.1} mm): outside the Hand-E's {STROKE_MM} mm stroke; objects inside it: {}",
                            scene.name,
                            scene
                                .objects
                                .iter()
                                .filter(|o| GraspObject::from_spec(o).max_width_m() * 1000.0 < STROKE_MM)
                                .map(|o| o.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )));
                    }
                    Ok(object)
                })
                .collect()
        })
        .collect()
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

/// A session ready to run: its stored identity, settings and model.
#[derive(Debug)]
pub struct Session {
    /// Its id in the store.
    pub id: i64,
    /// The model's name.
    pub model: String,
    /// The sha256 of the model's artifact.
    pub model_sha256: String,
    /// Seed of the perturbations and the simulated scenes.
    pub seed: u64,
    /// Its settings.
    pub plan: TrialPlan,
    /// One scene per medium.
    pub scenes: Vec<SceneSpec>,
    /// The model's artifact.
    model_bytes: Vec<u8>,
    /// Each (scene index, object)'s stiffness calibration, made or found before any
    /// trial ran, and the δ the closed loop uses on it.
    pub calibrations: std::collections::HashMap<(u32, String), run::ObjectSetup>,
}

impl Session {
    /// One line per calibrated object: the calibration used, Λ_max from the model's
    /// estimate beside the simulator's truth, K, and δ (and why it was widened).
    #[must_use]
    pub fn setup_lines(&self) -> Vec<String> {
        let mut keys: Vec<&(u32, String)> = self.calibrations.keys().collect();
        keys.sort();
        let keys_in_order = keys.clone();
        keys.into_iter()
            .filter_map(|k| {
                let o = self.calibrations.get(k)?;
                let medium = self
                    .scenes
                    .get(k.0 as usize)
                    .map_or("?", |s| medium_name(s.medium));
                let c = &o.calibration;
                let gain = self.plan.gain_over_lambda * c.lambda_max().max(0.05);
                // Method S4 on the calibrated Λ_max, said with the calibration's number.
                let s4 = match softtouch_grasp::check_gain(gain, c.lambda_max()) {
                    Ok(softtouch_grasp::GainCheck::Converges { contraction_at_max }) => {
                        format!("S4: K > Λ_max/2, the error × {contraction_at_max:.2} a step at Λ_max")
                    }
                    Ok(softtouch_grasp::GainCheck::MayNotConverge { amplification }) => format!(
                        "warning (S4, calibration #{}): K ≤ Λ_max/2, the loop may oscillate (× {amplification:.2} a step)",
                        c.row.calibration_id
                    ),
                    Ok(softtouch_grasp::GainCheck::NoStiffness) | Err(_) => format!(
                        "warning (S4, calibration #{}): no usable stiffness",
                        c.row.calibration_id
                    ),
                };
                // Two objects that meet the fingers alike (the same width across the
                // grasp axis at the same height: a round and an oval tube at yaw 0)
                // close alike, count for count; said, so no one looks for a bug.
                let twin = keys_in_order
                    .iter()
                    .take_while(|j| **j != k)
                    .filter(|j| j.0 == k.0)
                    .find_map(|j| {
                        let other = &self.calibrations.get(*j)?.calibration.row;
                        (other.points_json == c.row.points_json).then(|| {
                            format!(
                                "; the same closing as `{}`'s, count for count: the fingers meet the same section across the grasp axis (its depth does not enter a closing)",
                                j.1
                            )
                        })
                    })
                    .unwrap_or_default();
                let dither = if o.tolerance_n < o.count_n / 2.0 {
                    "; δ is under half a count: the loop dithers by one count around F_ref, which the confirmation accepts when its mean is within δ"
                } else {
                    ""
                };
                Some(format!(
                    "`{}` ({medium}): calibration #{} ({}): first touch at count {}, Λ_max = {:.3} N/mm from the model's estimate{}; K = {:.3} N/mm, δ = {} N{}; {s4}{dither}{twin}",
                    k.1,
                    c.row.calibration_id,
                    if c.fresh { "made now" } else { "stored" },
                    c.touch(),
                    c.lambda_max(),
                    c.row.true_lambda_max_n_per_mm.map_or_else(String::new, |t| format!(
                        " (true {t:.3}, a check only)"
                    )),
                    gain,
                    o.tolerance_n,
                    if o.tolerance_n > self.plan.tolerance_n {
                        format!(
                            " (widened from {} N: one count is {:.3} N here, and a loop dithering by one count confirms only within a quarter of it)",
                            self.plan.tolerance_n, o.count_n
                        )
                    } else {
                        String::new()
                    }
                ))
            })
            .collect()
    }
}

/// A new session of `plan` (checked) with `model` on `scenes`, stored before any
/// trial runs. With no objects in the plan, every object of the first scene.
///
/// # Errors
/// Bad settings or objects, an unknown model, the store.
pub async fn start_session(
    store: &Store,
    model: &str,
    seed: u64,
    plan: TrialPlan,
    scenes: Vec<SceneSpec>,
) -> Result<Session, TrialsError> {
    let mut plan = plan.checked()?;
    if plan.objects.is_empty() {
        plan.objects = scenes
            .first()
            .map(|s| s.objects.iter().map(|o| o.name.clone()).collect())
            .unwrap_or_default();
    }
    let objects = objects_of(&plan, &scenes)?; // checked before anything is stored
    // The model must exist before a session names it.
    let model_bytes = crate::models::force_artifact(store, model).await?;
    // Every object calibrated (or its stored calibration found) before the session is
    // stored: an object the fingers never touch leaves no empty session.
    let pairs = (0..scenes.len()).flat_map(|si| {
        plan.objects
            .iter()
            .map(move |o| (u32::try_from(si).unwrap_or(u32::MAX), o.clone()))
    });
    let pairs: Vec<(u32, String)> = pairs.collect();
    let calibrations = run::calibrate_all(
        store,
        model,
        &model_bytes,
        seed,
        &plan,
        &scenes,
        &objects,
        pairs,
    )
    .await?;
    let model_sha256 = sha256_hex(&model_bytes);
    let config_json = serde_json::to_string(&plan)
        .map_err(|e| TrialsError::Failed(format!("cannot encode the settings: {e}")))?;
    let scenes_json = serde_json::to_string(&scenes)
        .map_err(|e| TrialsError::Failed(format!("cannot encode the scenes: {e}")))?;
    let id = store
        .create_grasp_session(model, &model_sha256, seed, &scenes_json, &config_json)
        .await?;
    Ok(Session {
        id,
        model: model.to_owned(),
        model_sha256,
        seed,
        plan,
        scenes,
        model_bytes,
        calibrations,
    })
}

/// Stored session `id` and its settings, for a resume on the simulator or a rig:
/// `model`, when given, must be the session's.
///
/// # Errors
/// No such session, another model, stored settings that do not read back, the store.
pub(crate) async fn stored_session(
    store: &Store,
    id: i64,
    model: Option<&str>,
) -> Result<(crate::store::GraspSessionRow, TrialPlan), TrialsError> {
    let s = store.grasp_session(id).await?.ok_or_else(|| {
        invalid(format!(
            "--resume {id}: no grasp session {id} in {}",
            store.target().display()
        ))
    })?;
    if let Some(m) = model
        && m != s.model
    {
        return Err(invalid(format!(
            "--model {m}: session {id} runs model `{}` (leave --model out to resume it)",
            s.model
        )));
    }
    let plan: TrialPlan = serde_json::from_str(&s.config_json).map_err(|e| {
        TrialsError::Failed(format!(
            "grasp session {id}: stored settings do not read back: {e}"
        ))
    })?;
    Ok((s, plan))
}

/// The artifact of a stored session's model and its sha256, refused if the model
/// changed under its name since the session started.
///
/// # Errors
/// A changed or missing model, the store.
pub(crate) async fn unchanged_model(
    store: &Store,
    s: &crate::store::GraspSessionRow,
) -> Result<(Vec<u8>, String), TrialsError> {
    let model_bytes = crate::models::force_artifact(store, &s.model).await?;
    let now = sha256_hex(&model_bytes);
    if let Some(then) = &s.model_sha256
        && *then != now
    {
        return Err(invalid(format!(
            "--resume {}: model `{}` has changed since the session started (sha256 {} then, {} now); start a new session",
            s.session_id,
            s.model,
            &then[..then.len().min(12)],
            &now[..12]
        )));
    }
    Ok((model_bytes, now))
}

/// Stored session `id`, on its stored settings. `model`, when given, must be the
/// session's; the model must not have changed under its name since.
///
/// # Errors
/// No such session, another model, a changed model, stored settings that do not
/// read back, the store.
pub async fn resume_session(
    store: &Store,
    id: i64,
    model: Option<&str>,
) -> Result<Session, TrialsError> {
    let (s, plan) = stored_session(store, id, model).await?;
    if plan.rig.is_some() {
        return Err(invalid(format!(
            "--resume {id}: session {id} ran on a rig: resume it with --rig FILE --resume {id}"
        )));
    }
    let scenes: Vec<SceneSpec> = serde_json::from_str(&s.scenes_json).map_err(|e| {
        TrialsError::Failed(format!(
            "grasp session {id}: stored scenes do not read back: {e}"
        ))
    })?;
    let (model_bytes, now) = unchanged_model(store, &s).await?;
    let objects = objects_of(&plan, &scenes)?;
    let pairs: Vec<(u32, String)> = (0..scenes.len())
        .flat_map(|si| {
            plan.objects
                .iter()
                .map(move |o| (u32::try_from(si).unwrap_or(u32::MAX), o.clone()))
        })
        .collect();
    let calibrations = run::calibrate_all(
        store,
        &s.model,
        &model_bytes,
        s.seed,
        &plan,
        &scenes,
        &objects,
        pairs,
    )
    .await?;
    Ok(Session {
        id,
        model: s.model,
        model_sha256: now,
        seed: s.seed,
        plan,
        scenes,
        model_bytes,
        calibrations,
    })
}

/// What is planned and stored of a session.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Every trial of the plan.
    pub planned: Vec<Planned>,
    /// Those not stored yet, in the order they run.
    pub todo: Vec<Planned>,
}

impl Session {
    /// The plan's trials and those still to run.
    ///
    /// # Errors
    /// A damaged stored plan, the store.
    pub async fn progress(&self, store: &Store) -> Result<Progress, TrialsError> {
        let modes = self.plan.parsed_modes()?;
        let planned = planned(&self.plan, self.scenes.len(), &modes);
        let done = store.grasp_trial_keys(self.id).await?;
        let todo = planned
            .iter()
            .filter(|p| !done.contains(&p.key))
            .cloned()
            .collect();
        Ok(Progress { planned, todo })
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact stored and published values
mod tests {
    use super::*;

    #[test]
    fn a_sweep_marks_the_value_the_scenes_ship_with_and_sigma_the_papers() {
        let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        let sweep: Sweep = "objects.bottle.wet_friction=0.05,0.2"
            .parse()
            .unwrap_or_else(|e| panic!("{e}"));
        // Only the water scene has the value (land has no wet friction): it is the one.
        let (_, stored) = swept_scenes(&scenes, &sweep).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(stored.shipped.as_deref(), Some("0.05"));
        assert_eq!(stored.value_label(0), "0.05 (shipped)");
        assert_eq!(stored.value_label(1), "0.2");
        assert_eq!(stored.value_label(7), "?");
        // Scenes that disagree have no one shipped value to mark.
        let both: Sweep = "objects.bottle.friction=0.3,0.9"
            .parse()
            .unwrap_or_else(|e| panic!("{e}"));
        let mut differing = scenes.clone();
        differing[1]
            .objects
            .iter_mut()
            .for_each(|o| o.friction += 0.01);
        let (_, stored) = swept_scenes(&differing, &both).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(stored.shipped, None);
        // A session stored before the mark existed reads back without one.
        let old: SceneSweep =
            serde_json::from_str(r#"{"path":"a.b","values":["1"],"per_value":1}"#)
                .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(old.shipped, None);
        assert_eq!(sigma_label(PAPER_SIGMA_MM), "σ 5 mm (paper)");
        assert_eq!(sigma_label(2.0), "σ 2 mm");
    }

    #[test]
    fn the_built_in_scenes_load_with_objects_inside_the_stroke() {
        let scenes = load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scenes.len(), 2);
        assert_eq!(scenes[0].medium, Medium::Air);
        assert_eq!(scenes[1].medium, Medium::Water);
        let mut plan = TrialPlan {
            modes: vec!["open".into(), "closed".into(), "open".into()],
            ..TrialPlan::default()
        }
        .checked()
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(plan.modes, ["open", "closed"]);
        plan.objects = scenes[0].objects.iter().map(|o| o.name.clone()).collect();
        assert_eq!(plan.objects.len(), 5);
        let objects = objects_of(&plan, &scenes).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(objects[1].len(), 5);
        // The full table: 2 σ-free media × 5 objects × 2 modes × 10 trials.
        assert_eq!(planned(&plan, 2, &[Mode::Open, Mode::Closed]).len(), 200);
        plan.objects.push("vase".into());
        let err = objects_of(&plan, &scenes).err().map(|e| e.to_string());
        assert!(err.is_some_and(|e| e.contains("vase") && e.contains("cylinder")));
    }

    #[test]
    fn objects_that_close_alike_are_said_to() {
        let setup = |object: &str, points: &str| run::ObjectSetup {
            calibration: crate::grasp::calibration::Calibrated {
                row: crate::store::GraspCalibrationRow {
                    calibration_id: 1,
                    created_at: String::new(),
                    setup_kind: "scene".into(),
                    setup_hash: String::new(),
                    model: "m".into(),
                    model_sha256: String::new(),
                    object: object.into(),
                    touch_count: 100,
                    lambda_max_n_per_mm: 1.0,
                    lambda_iqr_n_per_mm: (0.9, 1.1),
                    counts_spanned: 10,
                    baseline_n: 0.0,
                    mm_per_count: 0.2,
                    ended: "top".into(),
                    points_json: points.into(),
                    lambda_json: "[]".into(),
                    true_lambda_max_n_per_mm: None,
                },
                fresh: true,
            },
            count_n: 0.2,
            tolerance_n: 0.1,
        };
        let mut calibrations = std::collections::HashMap::new();
        for (scene, object, points) in [
            (0, "cylinder", "[[100,100,0.5]]"),
            (0, "oval-tube", "[[100,100,0.5]]"),
            (0, "ball", "[[100,100,0.7]]"),
            // Another medium's scene is never compared with the first's.
            (1, "cylinder", "[[100,100,0.6]]"),
            (1, "oval-tube", "[[100,100,0.5]]"),
        ] {
            calibrations.insert((scene, object.to_owned()), setup(object, points));
        }
        let session = Session {
            id: 1,
            model: "m".into(),
            model_sha256: String::new(),
            seed: 0,
            plan: TrialPlan::default(),
            scenes: load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}")),
            model_bytes: Vec::new(),
            calibrations,
        };
        let lines = session.setup_lines();
        let line = |prefix: &str| {
            lines
                .iter()
                .find(|l| l.starts_with(prefix))
                .cloned()
                .unwrap_or_else(|| panic!("no `{prefix}` in {lines:?}"))
        };
        let twin = "the same closing as `cylinder`'s, count for count";
        assert!(line("`oval-tube` (land)").contains(twin), "{lines:?}");
        assert!(!line("`oval-tube` (water)").contains(twin), "{lines:?}");
        assert!(
            !line("`ball` (land)").contains("the same closing"),
            "{lines:?}"
        );
        assert!(
            !line("`cylinder` (land)").contains("the same closing"),
            "{lines:?}"
        );
    }

    #[test]
    fn settings_out_of_range_name_their_flag() {
        for (plan, flag) in [
            (
                TrialPlan {
                    tolerance_n: 0.0,
                    ..TrialPlan::default()
                },
                "--tolerance 0",
            ),
            (
                TrialPlan {
                    fps: 0.5,
                    ..TrialPlan::default()
                },
                "--fps 0.5",
            ),
            (
                TrialPlan {
                    trials: 0,
                    ..TrialPlan::default()
                },
                "--trials 0",
            ),
            (
                TrialPlan {
                    modes: vec![],
                    ..TrialPlan::default()
                },
                "--modes",
            ),
            (
                TrialPlan {
                    sigmas_mm: vec![f64::NAN],
                    ..TrialPlan::default()
                },
                "σ NaN",
            ),
            (
                TrialPlan {
                    hold_s: 1e308,
                    ..TrialPlan::default()
                },
                "--hold-s 1e308",
            ),
        ] {
            let e = plan.checked().expect_err(flag);
            assert!(e.is_bad_input(), "{e}");
            assert!(e.to_string().starts_with(flag), "{e}");
        }
    }

    #[test]
    fn a_session_stored_before_the_calibrated_pregrasp_keeps_its_own_on_resume() {
        let mut json = serde_json::to_value(TrialPlan::default()).expect("encodes");
        assert_eq!(
            json["pregrasp_from_touch"], true,
            "new sessions start from the touch"
        );
        json.as_object_mut()
            .expect("an object")
            .remove("pregrasp_from_touch");
        let old: TrialPlan = serde_json::from_value(json).expect("an older session reads");
        assert!(
            !old.pregrasp_from_touch,
            "it keeps the grasp width plus the margin"
        );
        assert!(old.rig.is_none());
    }

    #[test]
    fn the_paper_figures_are_the_published_ones() {
        assert_eq!(paper_rate(Medium::Air, Mode::Open), 0.44);
        assert_eq!(paper_rate(Medium::Water, Mode::Closed), 0.90);
        assert_eq!(table::csv_field("a,b"), "\"a,b\"");
    }
}
