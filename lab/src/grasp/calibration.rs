//! The stiffness calibration the grasp verbs take their gain and pre-grasp opening
//! from: the fingers close on the object one count at a time and the model's own
//! estimate gives Λ(P) ([`softtouch_grasp::stiffness`]), on the simulated soft grasp
//! here exactly as on a rig. The latest stored calibration matching the setup, the
//! model's artifact and the object is reused; with none, one is made and stored.
//!
//! The simulator's true Λ_max over the same range is measured beside it and stored for
//! comparison only: no loop, gain or opening ever reads it.

use std::sync::Arc;

use softtouch_collector::dataset::export::sha256_hex;
use softtouch_drivers::gripper::{STROKE_MM, position_for_opening};
use softtouch_drivers::{Clock, TokioClock};
use softtouch_grasp::{
    GraspError, StiffnessCalibration, StiffnessConfig, Stroke, calibrate_stiffness,
};
use softtouch_schemas::SceneSpec;
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::Predictor;

use super::sim::{measure_stiffness, projection, sim_err};
use super::soft::GraspRunError;
use crate::store::{GraspCalibrationRow, Store};

/// The calibration a verb runs with.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibrated {
    /// As stored.
    pub row: GraspCalibrationRow,
    /// Made by this run (else reused).
    pub fresh: bool,
}

impl Calibrated {
    /// Λ_max, N/mm.
    #[must_use]
    pub const fn lambda_max(&self) -> f64 {
        self.row.lambda_max_n_per_mm
    }

    /// First touch, counts.
    #[must_use]
    pub const fn touch(&self) -> u8 {
        self.row.touch_count
    }
}

/// What a simulated setup is: the scene (with its objects and effects), the camera
/// rate and the seed of its effects. Its fingerprint keys the stored calibrations.
///
/// # Errors
/// The scene does not serialise (never for a parsed one).
pub fn scene_setup_hash(scene: &SceneSpec, fps: f64, seed: u64) -> Result<String, GraspRunError> {
    let json = serde_json::to_string(&(scene, fps.to_bits(), seed))
        .map_err(|e| GraspRunError::Failed(format!("cannot fingerprint the scene: {e}")))?;
    Ok(sha256_hex(json.as_bytes()))
}

/// What a rig's calibration depends on: its gripper and its finger cameras (the rest
/// of the rig file, the arm, the grasp poses, may change without making a stiffness
/// calibration stale). Its fingerprint keys the rig's stored calibrations.
///
/// # Errors
/// The rig does not serialise (never for a parsed one).
pub fn rig_setup_hash(rig: &softtouch_schemas::RigConfig) -> Result<String, GraspRunError> {
    let json = serde_json::to_string(&(&rig.gripper, &rig.camera, &rig.second_camera))
        .map_err(|e| GraspRunError::Failed(format!("cannot fingerprint the rig: {e}")))?;
    Ok(sha256_hex(json.as_bytes()))
}

/// The closing for `object`: from 10 mm wider than it (the scene says how wide it
/// is) up to `top_n`.
#[must_use]
pub fn config_for(object: &GraspObject, top_n: f64) -> StiffnessConfig {
    StiffnessConfig {
        start_count: position_for_opening(object.width_m * 1000.0 + 10.0),
        top_n,
        ..StiffnessConfig::default()
    }
}

/// The top of a closing for loops up to `largest_target_n`: half again the largest
/// target, and never under the paper's 3 N × 1.5 (a calibration then serves every
/// verb's defaults).
#[must_use]
pub fn top_for(largest_target_n: f64) -> f64 {
    (1.5 * largest_target_n).max(4.5)
}

/// Calibrates on a fresh simulated grasp of `object`, on this thread with its own
/// paused clock (so a caller's runtime, and its database, keep real time). The
/// predictor is handed back whatever happens.
pub fn calibrate_on_sim(
    scene: &SceneSpec,
    object: &GraspObject,
    fps: f64,
    seed: u64,
    top_n: f64,
    mut predictor: Predictor,
) -> (
    Predictor,
    Result<(StiffnessCalibration, Option<f64>), GraspRunError>,
) {
    let rt = match crate::grasp::sim::paused_runtime() {
        Ok(rt) => rt,
        Err(e) => {
            return (
                predictor,
                Err(GraspRunError::Failed(format!(
                    "cannot start the calibration's runtime: {e}"
                ))),
            );
        }
    };
    let result = rt.block_on(async {
        let clock = TokioClock::new();
        let (mut gripper, mut camera, handle) = soft_grasp(scene, object.clone(), fps, seed, clock)
            .map_err(|e| GraspRunError::Invalid(format!("object `{}`: {e}", object.name)))?;
        let config = config_for(object, top_n);
        let shared: Arc<dyn Clock> = Arc::new(clock);
        let cal = calibrate_stiffness(
            &mut gripper,
            &mut camera,
            &mut predictor,
            &projection()?,
            &Stroke::default(),
            shared.as_ref(),
            &config,
        )
        .await
        .map_err(|e| match e {
            GraspError::Config(m) => {
                GraspRunError::Invalid(format!("calibrating on `{}`: {m}", object.name))
            }
            e => GraspRunError::Grasp(e),
        })?;
        // The truth over the same range, for comparison only.
        let truth = measure_stiffness(&handle, top_n)
            .map_err(sim_err)?
            .map(|(_, lambda)| lambda);
        Ok((cal, truth))
    });
    (predictor, result)
}

/// The stored form of a calibration.
///
/// # Errors
/// Never in practice (numbers and counts serialise).
pub fn to_row(
    cal: &StiffnessCalibration,
    setup: (&str, &str),
    model: (&str, &str),
    object: &str,
    true_lambda_max: Option<f64>,
) -> Result<GraspCalibrationRow, GraspRunError> {
    let failed =
        |e: serde_json::Error| GraspRunError::Failed(format!("cannot write a calibration: {e}"));
    let points: Vec<(u8, u8, Option<f64>)> = cal
        .points
        .iter()
        .map(|p| {
            (
                p.request,
                p.measured,
                p.estimate_n.filter(|f| f.is_finite()),
            )
        })
        .collect();
    Ok(GraspCalibrationRow {
        calibration_id: 0,
        created_at: String::new(),
        setup_kind: setup.0.to_owned(),
        setup_hash: setup.1.to_owned(),
        model: model.0.to_owned(),
        model_sha256: model.1.to_owned(),
        object: object.to_owned(),
        touch_count: cal.touch_count,
        lambda_max_n_per_mm: cal.lambda_max_n_per_mm,
        lambda_iqr_n_per_mm: cal.lambda_max_iqr,
        counts_spanned: cal.counts_spanned,
        baseline_n: cal.baseline_n,
        mm_per_count: STROKE_MM / 255.0,
        ended: cal.ended.name().to_owned(),
        points_json: serde_json::to_string(&points).map_err(failed)?,
        lambda_json: serde_json::to_string(&cal.lambda_curve).map_err(failed)?,
        true_lambda_max_n_per_mm: true_lambda_max,
    })
}

/// A new calibration of `object` on the simulator (on a blocking thread, its own paused
/// clock), as a row ready to store: keyed by the scene's fingerprint and the model's
/// artifact, with the simulator's true Λ_max beside it.
///
/// # Errors
/// The model, or a calibration that finds no touch.
pub async fn calibrate_sim_row(
    model: &str,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: &GraspObject,
    fps: f64,
    seed: u64,
    top_n: f64,
) -> Result<GraspCalibrationRow, GraspRunError> {
    let setup_hash = scene_setup_hash(scene, fps, seed)?;
    let predictor = Predictor::from_bytes(model_bytes)?;
    let (scene2, object2) = (scene.clone(), object.clone());
    let (_, made) = tokio::task::spawn_blocking(move || {
        calibrate_on_sim(&scene2, &object2, fps, seed, top_n, predictor)
    })
    .await
    .map_err(|e| GraspRunError::Failed(format!("the calibration's thread failed: {e}")))?;
    let (cal, truth) = made?;
    to_row(
        &cal,
        ("scene", &setup_hash),
        (model, &sha256_hex(model_bytes)),
        &object.name,
        truth,
    )
}

/// The latest stored calibration of `object` with this model on this simulated setup,
/// else a new one made on the simulator (on a blocking thread) and stored.
///
/// # Errors
/// The store, the model, or a calibration that finds no touch.
#[allow(clippy::too_many_arguments)] // what identifies a calibration, and what makes one
pub async fn calibration_for(
    store: &Store,
    model: &str,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: &GraspObject,
    fps: f64,
    seed: u64,
    top_n: f64,
) -> Result<Calibrated, GraspRunError> {
    let model_sha256 = sha256_hex(model_bytes);
    let setup_hash = scene_setup_hash(scene, fps, seed)?;
    let stored = store
        .latest_grasp_calibration(&setup_hash, &model_sha256, &object.name)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?;
    if let Some(row) = stored {
        return Ok(Calibrated { row, fresh: false });
    }
    let mut row = calibrate_sim_row(model, model_bytes, scene, object, fps, seed, top_n).await?;
    row.calibration_id = store
        .insert_grasp_calibration(&row)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?;
    Ok(Calibrated { row, fresh: true })
}
