//! Algorithm 1 made ready on the simulated soft grasp, for the experiments of Figure 5
//! (`follow`, `disturb`, `twist`): the grasp of one object built, K = 0.75 Λ_max
//! unless given, with Λ_max and the first touch from the stiffness calibration on the
//! model's own estimate ([`super::calibration`]), and the fingers approached to four
//! counts before the touch. The model's estimate is the only force the loop sees; the
//! simulator's truth is logged beside it ([`LoggedTruth`]).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use softtouch_drivers::TokioClock;
use softtouch_grasp::{
    Controller, ControllerConfig, ExitAction, GainCheck, GraspError, Projection, check_gain,
    check_tolerance, one_count_force_n,
};
use softtouch_schemas::config::{ConfigSource, parse_toml};
use softtouch_schemas::{ArmPose, SceneSpec};
use softtouch_sim::{
    GraspObject, SimError, SoftFingerCamera, SoftGraspHandle, SoftGripper, soft_grasp,
};
use softtouch_trainer::Predictor;

use super::calibration::Calibrated;
use super::sim::{LoggedTruth, TruthSample};
use crate::models::ModelError;

// The grasp scene shipped in `scenes/grasp.toml`: the default for `disturb` and
// `twist` (its oval tube and cylinder).
use softtouch_schemas::defaults::GRASP_SCENE_TOML;

/// What can go wrong in a grasp experiment on the simulator.
#[derive(Debug, thiserror::Error)]
pub enum GraspRunError {
    /// A request that cannot work (an unknown object, a target the loop cannot
    /// hold); the message says what is expected.
    #[error("{0}")]
    Invalid(String),
    /// The loop's settings or devices.
    #[error(transparent)]
    Grasp(#[from] GraspError),
    /// The model cannot be loaded.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// An output that cannot be written.
    #[error("{0}")]
    Failed(String),
}

impl GraspRunError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Invalid(_) => true,
            Self::Grasp(GraspError::Config(_) | GraspError::UnreachableTarget { .. }) => true,
            Self::Model(e) => e.is_bad_input(),
            Self::Grasp(_) | Self::Sim(_) | Self::Failed(_) => false,
        }
    }
}

impl From<softtouch_trainer::TrainError> for GraspRunError {
    fn from(e: softtouch_trainer::TrainError) -> Self {
        Self::Model(e.into())
    }
}

fn invalid(m: String) -> GraspRunError {
    GraspRunError::Invalid(m)
}

/// The built-in grasp scene (`scenes/grasp.toml`).
///
/// # Errors
/// Never in a released build (the scene is checked by the tests).
pub fn grasp_scene() -> Result<SceneSpec, GraspRunError> {
    parse_toml(GRASP_SCENE_TOML, &ConfigSource::Embedded("grasp scene"))
        .map_err(|e| GraspRunError::Failed(format!("the embedded grasp scene: {e}")))
}

/// The scene's object `name`.
///
/// # Errors
/// The scene declares no such object (the message lists those it has).
pub fn named_object(scene: &SceneSpec, name: &str) -> Result<GraspObject, GraspRunError> {
    scene
        .object(name)
        .map(GraspObject::from_spec)
        .ok_or_else(|| {
            let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
            invalid(if names.is_empty() {
                format!(
                    "--object {name}: scene `{}` declares no objects ([[objects]]); \
                     pass a grasp scene, e.g. --scene scenes/grasp.toml",
                    scene.name
                )
            } else {
                format!(
                    "--object {name}: scene `{}` declares no such object (it has: {})",
                    scene.name,
                    names.join(", ")
                )
            })
        })
}

/// Finger 0's sensor +x faces the object, so its push (−x) is the world's +y, the
/// paper's gripping direction. Finger 1 is turned half a turn about z: its push is the
/// world's −y, which counts as squeezing for it.
///
/// # Errors
/// Never in practice (fixed rotations); the projection checks them.
pub fn projections() -> Result<[Projection; 2], GraspError> {
    let half_pi = std::f64::consts::FRAC_PI_2;
    Ok([
        Projection::along_world_y(ArmPose::from_translation_yaw([0.0; 3], -half_pi))?,
        Projection::new(
            ArmPose::from_translation_yaw([0.0; 3], half_pi),
            [0.0, -1.0, 0.0],
        )?,
    ])
}

/// The loop's settings shared by the experiments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    /// K, N/mm; `None`: 0.75 × the measured Λ_max.
    pub gain_n_per_mm: Option<f64>,
    /// δ, N.
    pub tolerance_n: f64,
    /// Camera rate, Hz (one cycle per frame).
    pub fps: f64,
    /// Sensorised fingers the loop reads (1 or 2).
    pub fingers: usize,
    /// Seed of the simulated scene's effects.
    pub seed: u64,
}

/// What the setup measured and chose, and Method S4's verdicts on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setup {
    /// The first count at which the closing fingers touch the object (calibrated).
    pub touch: u8,
    /// Λ_max from the calibration on the model's estimate, N/mm.
    pub lambda_max: f64,
    /// The simulator's true Λ_max over the same range, N/mm: printed as a check of
    /// the estimate, never used.
    pub true_lambda_max: Option<f64>,
    /// The stored calibration used, and whether this run made it.
    pub calibration: (i64, bool),
    /// K, N/mm.
    pub gain: f64,
    /// Method S4 on K against Λ_max.
    pub gain_check: GainCheck,
    /// The force of one count at Λ_max, N: δ below half of it dithers.
    pub one_count_n: f64,
    /// Whether δ resolves one count.
    pub tolerance_ok: bool,
}

/// The loop on the simulated soft grasp.
pub type SimController = Controller<SoftGripper, SoftFingerCamera, Predictor, LoggedTruth>;

/// A loop made ready on the simulated soft grasp: approached to just before the
/// first touch.
#[derive(Debug)]
pub struct Prepared {
    /// The loop.
    pub controller: SimController,
    /// The simulated grasp (to turn the object, read the truth).
    pub handle: SoftGraspHandle,
    /// The devices' clock (virtual time).
    pub clock: TokioClock,
    /// The truth the loop logged (τz, wrist).
    pub truth_log: Arc<Mutex<Vec<TruthSample>>>,
    /// What was measured and chosen.
    pub setup: Setup,
}

/// Builds the soft grasp of `object`, takes Λ_max, the first touch and the squeeze
/// bound from `calibration`, configures Algorithm 1 and approaches to four counts
/// before the touch. `turns_object`: the run turns the object between the fingers
/// (disturb, twist), so the bound allows its width down to its narrowest side. Run on
/// a paused tokio clock.
///
/// # Errors
/// A target the loop cannot hold (checked before K is derived from the targets), a
/// Λ_max too small for a gain, the model, the simulator.
#[allow(clippy::too_many_arguments)] // the loop's settings, model, scene, object, targets, exit, calibration, and whether it turns the object
pub async fn prepare(
    settings: &LoopSettings,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: GraspObject,
    targets_n: &[f64],
    on_exit: ExitAction,
    calibration: &Calibrated,
    turns_object: bool,
) -> Result<Prepared, GraspRunError> {
    // The targets first: K is derived from them, so a bad target must not read as a
    // bad K (a flag the user never gave).
    for t in targets_n {
        super::settings::check_target_n("--targets", *t, settings.tolerance_n)
            .map_err(|e| invalid(e.to_string()))?;
    }
    // Λ is measured up to half again the largest target.
    let top_n = super::calibration::top_for(targets_n.iter().copied().fold(0.0, f64::max));
    let predictor = Predictor::from_bytes(model_bytes)?;
    let clock = TokioClock::new();
    let (gripper, camera, handle) =
        soft_grasp(scene, object.clone(), settings.fps, settings.seed, clock)
            .map_err(|e| invalid(format!("object `{}`: {e}", object.name)))?;
    let (touch, lambda_max) = (calibration.touch(), calibration.lambda_max());
    let gain = settings.gain_n_per_mm.unwrap_or(0.75 * lambda_max);
    if settings.gain_n_per_mm.is_none() && !(gain.is_finite() && gain > 0.0) {
        return Err(invalid(format!(
            "object `{}`: the calibrated stiffness (calibration #{}, from first touch up to {top_n:.3} N) is {lambda_max} N/mm, so K = 0.75 Λ_max is unusable; give --gain",
            object.name, calibration.row.calibration_id
        )));
    }
    let projections = projections()?;
    // An oval turned a quarter presents its depth (aspect × width) to the fingers.
    let allowance_mm = if turns_object {
        object.width_m * 1000.0 * (1.0 - object.aspect.min(1.0))
    } else {
        0.0
    };
    let mut config = ControllerConfig::new(projections[0])
        .with_squeeze(calibration.squeeze()?.with_allowance_mm(allowance_mm));
    config.stepper.gain_n_per_mm = gain;
    config.stepper.tolerance_n = settings.tolerance_n;
    config.on_exit = on_exit;
    // Every setting and target is checked before the fingers move.
    let checked: Vec<(f64, Duration)> = targets_n.iter().map(|t| (*t, Duration::ZERO)).collect();
    config.check(&checked)?;
    let setup = Setup {
        touch,
        lambda_max,
        true_lambda_max: calibration.row.true_lambda_max_n_per_mm,
        calibration: (calibration.row.calibration_id, calibration.fresh),
        gain,
        gain_check: check_gain(gain, lambda_max)?,
        one_count_n: one_count_force_n(lambda_max, &config.stepper.stroke),
        tolerance_ok: check_tolerance(settings.tolerance_n, lambda_max, &config.stepper.stroke),
    };
    let truth_log = Arc::new(Mutex::new(Vec::new()));
    let truth = LoggedTruth {
        handle: handle.clone(),
        projections,
        fingers: settings.fingers,
        log: Arc::clone(&truth_log),
    };
    let mut controller =
        Controller::new(gripper, camera, predictor, truth, Arc::new(clock), config)?;
    if settings.fingers == 2 {
        let second = handle.second_camera()?;
        controller = controller.with_second_finger(Box::new(second), projections[1]);
    }
    controller
        .approach(touch.saturating_sub(4), Duration::from_secs(5))
        .await?;
    Ok(Prepared {
        controller,
        handle,
        clock,
        truth_log,
        setup,
    })
}

/// Writes `text` to `path`.
///
/// # Errors
/// The file cannot be written.
pub fn write_text(path: &std::path::Path, text: &str) -> Result<(), GraspRunError> {
    std::fs::write(path, text)
        .map_err(|e| GraspRunError::Failed(format!("cannot write {}: {e}", path.display())))
}

/// The grip at its firmest over `cycles`, in words for a run's one-line summary: the
/// largest true force where the simulator gives one, else (a rig) how far past the
/// calibrated first touch the fingers closed (`touch`: its count and mm per count).
#[must_use]
pub fn grip_words(cycles: &[softtouch_grasp::Cycle], touch: (u8, f64)) -> String {
    let peak = cycles
        .iter()
        .filter_map(|c| c.true_n)
        .filter(|f| f.is_finite())
        .reduce(f64::max);
    let deepest = cycles.iter().map(|c| c.measured_position).max();
    match (peak, deepest) {
        (Some(p), _) => format!("peak true {p:.2} N"),
        (None, Some(c)) => format!(
            "closed {:.2} mm past the touch",
            softtouch_grasp::squeeze::past_touch_mm(c, touch.0, touch.1)
        ),
        (None, None) => "no cycle ran".to_owned(),
    }
}

/// Seconds of a timestamp.
#[must_use]
pub fn t_s(t: softtouch_schemas::TimestampNs) -> f64 {
    t.0 as f64 * 1e-9
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cycle(hold: usize, true_n: Option<f64>, measured_position: u8) -> softtouch_grasp::Cycle {
        softtouch_grasp::Cycle {
            t: softtouch_schemas::TimestampNs(0),
            frame_sequence: 0,
            hold,
            target_n: 1.0,
            estimate_n: Some(1.0),
            true_n,
            measured_position,
            position_request: measured_position,
            outcome: None,
            object: softtouch_drivers::ObjectStatus::Moving,
            finger_estimates_n: [Some(1.0), None],
            single_finger: None,
            torque_z_nm: None,
            wrist_target_rad: None,
        }
    }

    /// The grip in words: the truth's peak (a NaN skipped), else the deepest closing
    /// past the touch (0 short of it), else that nothing ran.
    #[test]
    fn the_grip_is_the_true_peak_else_the_closing_past_the_touch() {
        let mm = 0.2;
        let sim = [
            cycle(0, Some(1.5), 120),
            cycle(0, Some(f64::NAN), 125),
            cycle(0, Some(2.25), 110),
        ];
        assert_eq!(grip_words(&sim, (100, mm)), "peak true 2.25 N");
        let rig = [
            cycle(0, None, 104),
            cycle(0, None, 112),
            cycle(0, None, 108),
        ];
        assert_eq!(grip_words(&rig, (100, mm)), "closed 2.40 mm past the touch");
        let short = [cycle(0, None, 90)];
        assert_eq!(
            grip_words(&short, (100, mm)),
            "closed 0.00 mm past the touch"
        );
        assert_eq!(grip_words(&[], (100, mm)), "no cycle ran");
        // follow's rows: per hold, the same two numbers.
        let all = [
            cycle(0, Some(1.0), 105),
            cycle(1, None, 130),
            cycle(1, None, 140),
        ];
        let rows = super::super::follow::follow_rows(&all, &[1.0, 2.0], 0.1, (100, mm));
        assert_eq!(rows[0].peak_true_n, Some(1.0));
        assert!((rows[0].past_touch_mm.expect("hold 0") - 1.0).abs() < 1e-12);
        assert_eq!(rows[1].peak_true_n, None);
        assert!((rows[1].past_touch_mm.expect("hold 1") - 8.0).abs() < 1e-12);
    }

    #[test]
    fn an_unknown_object_is_named_with_the_scenes_objects_or_told_there_are_none() {
        let grasp = grasp_scene().expect("the embedded grasp scene");
        let e = named_object(&grasp, "vase")
            .expect_err("no vase")
            .to_string();
        let first = &grasp.objects[0].name;
        assert!(
            e.contains("declares no such object (it has: ") && e.contains(first.as_str()),
            "{e}"
        );
        // A collection scene has rods, no objects: no empty list, and what to pass.
        let rods_only = softtouch_schemas::defaults::scene();
        let e = named_object(&rods_only, "cylinder")
            .expect_err("no objects")
            .to_string();
        assert!(e.contains("declares no objects ([[objects]])"), "{e}");
        assert!(e.contains("--scene scenes/grasp.toml"), "{e}");
        assert!(!e.contains("it has: )"), "{e}");
    }
}
