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
    CalibrationEnd, GraspError, SqueezeBound, StiffnessCalibration, StiffnessConfig, Stroke,
    calibrate_stiffness,
};
use softtouch_schemas::SceneSpec;
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::{ImageTare, Predictor};

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
    /// The check's refusal, where the caller accepted the calibration against it
    /// (`--accept-calibration`): said beside every result it is used for.
    pub accepted_against: Option<String>,
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

    /// The closing limit of every force loop run on this calibration.
    ///
    /// # Errors
    /// A stored closing that does not parse (a damaged row), named.
    pub fn squeeze(&self) -> Result<SqueezeBound, GraspRunError> {
        squeeze_of_row(&self.row)
    }
}

/// The closing limit ([`SqueezeBound`]) of a stored calibration: its touch, its
/// no-contact level, its closing and Λ_max.
///
/// # Errors
/// `points_json` does not parse, named with the calibration's id.
pub fn squeeze_of_row(row: &GraspCalibrationRow) -> Result<SqueezeBound, GraspRunError> {
    let points: Vec<(u8, u8, Option<f64>)> =
        serde_json::from_str(&row.points_json).map_err(|e| {
            GraspRunError::Failed(format!(
                "calibration #{}: field points_json does not parse ({e}); expected [[request, measured, estimate or null], …]; recalibrate",
                row.calibration_id
            ))
        })?;
    let measured: Vec<(u8, Option<f64>)> = points.iter().map(|p| (p.1, p.2)).collect();
    Ok(SqueezeBound::from_points(
        row.touch_count,
        row.baseline_n,
        &measured,
        row.lambda_max_n_per_mm,
        row.mm_per_count,
    ))
}

/// What a simulated setup is: the scene (with its objects and effects), the camera
/// rate and the seed of its effects. Its fingerprint keys the stored calibrations.
///
/// # Errors
/// The scene does not serialise (never for a parsed one).
pub fn scene_setup_hash(scene: &SceneSpec, fps: f64, seed: u64) -> Result<String, GraspRunError> {
    tared_setup_hash(scene, fps, seed, None)
}

/// [`scene_setup_hash`] of a setup whose frames the model reads through `tare`: a
/// calibration made through one tare is not one made through another, or none
/// (`None` gives [`scene_setup_hash`]'s value, so calibrations stored before tares
/// keep their key).
///
/// # Errors
/// The scene does not serialise (never for a parsed one).
pub fn tared_setup_hash(
    scene: &SceneSpec,
    fps: f64,
    seed: u64,
    tare: Option<&ImageTare>,
) -> Result<String, GraspRunError> {
    let json = match tare {
        None => serde_json::to_string(&(scene, fps.to_bits(), seed)),
        Some(t) => serde_json::to_string(&(scene, fps.to_bits(), seed, t)),
    }
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

/// How far the opening at the calibrated first touch may lie from the object's
/// declared width, mm (the declared width is the open-loop opening plus 2 mm, each
/// finger pressed in 1 mm: scenes/grasp.toml). Wide enough for a current that pushes
/// a standing object against one finger first (the water bottle touches 6.8 mm early);
/// a touch read from noise at the open end lies 20 mm and more away.
pub const TOUCH_SLACK_MM: f64 = 8.0;

/// Training samples read for the press stiffness (a Theil–Sen fit is quadratic).
pub const PRESS_SAMPLES: i64 = 1500;

/// What the rig knows without the model, which a calibration must agree with.
#[derive(Debug, Clone, PartialEq)]
pub struct Evidence {
    /// The object's name.
    pub object: String,
    /// Its declared open-loop opening, mm (the scene's `grasp_width_m`, a rig's
    /// `open_width_mm`); `None`: not declared, not checked.
    pub open_width_mm: Option<f64>,
    /// The squeeze that crushes it, N (`None`: rigid). A rigid object cannot end the
    /// closing at the closed end or on a contact stop before the estimate reaches the
    /// top; a crushable one that gave way must have been read at least half way to
    /// its crush force first.
    pub crush_force_n: Option<f64>,
    /// The finger's press stiffness from the model's training samples: label force
    /// over commanded press, N/mm, and the samples it came from.
    pub press: Option<(f64, usize)>,
}

/// The finger's press stiffness from its training samples `(commanded x m, |F| N)`:
/// the Theil–Sen slope in N per mm of commanded press, with the sample count. The
/// arm and the mount yield too, so the finger itself is at least this stiff. `None`
/// under 20 samples or with no slope.
#[must_use]
pub fn press_stiffness(samples: &[(f64, f64)]) -> Option<(f64, usize)> {
    if samples.len() < 20 {
        return None;
    }
    let mm: Vec<(f64, f64)> = samples.iter().map(|(x, f)| (x * 1000.0, *f)).collect();
    softtouch_grasp::theil_sen_slope(&mm)
        .map(|(k, _)| k.abs())
        .filter(|k| k.is_finite() && *k > 0.0)
        .map(|k| (k, samples.len()))
}

/// The least Λ_max a calibration may report on a finger of press stiffness `k`,
/// N/mm of opening. Each finger takes half the closing, and the finger is at least
/// `k` stiff (the commanded press overstates its indentation), so a rigid object
/// gives at least k/2. An object that declares a crush force may give way itself:
/// its floor is a quarter of that, k/8.
#[must_use]
pub fn lambda_floor(press_n_per_mm: f64, rigid: bool) -> f64 {
    if rigid {
        press_n_per_mm / 2.0
    } else {
        press_n_per_mm / 8.0
    }
}

/// Checks a calibration against what the rig knows before it is stored or reused: the
/// touch within [`TOUCH_SLACK_MM`] of the object's declared width; a closing that the
/// fingers ended (closed end, contact stop) only after the estimate read the largest
/// target it serves (a rigid object) or half the crush force (one that gave way); and
/// Λ_max above [`lambda_floor`] from the finger's press in the model's training
/// samples.
///
/// # Errors
/// [`GraspRunError::Invalid`] naming every disagreement with its numbers and what to
/// do.
pub fn check_calibration(
    cal: &GraspCalibrationRow,
    top_n: f64,
    evidence: &Evidence,
) -> Result<(), GraspRunError> {
    let mm_per_count = cal.mm_per_count;
    let mut wrong = Vec::new();
    let touch_mm = STROKE_MM - f64::from(cal.touch_count) * mm_per_count;
    if let Some(open) = evidence.open_width_mm {
        let declared = open + 2.0;
        if (touch_mm - declared).abs() > TOUCH_SLACK_MM || !touch_mm.is_finite() {
            wrong.push(format!(
                "the first touch came at an opening of {touch_mm:.1} mm (count {}) where the object is declared {declared:.1} mm wide (open-loop opening {open} mm + 2 mm); expected within {TOUCH_SLACK_MM} mm",
                cal.touch_count
            ));
        }
    }
    let fingers_ended = [CalibrationEnd::ClosedEnd, CalibrationEnd::ContactStop]
        .iter()
        .any(|e| e.name() == cal.ended);
    // The estimate's largest rise above its no-contact level over the closing.
    let peak = squeeze_of_row(cal)
        .map(|b| {
            b.rise_n
                .iter()
                .map(|r| r.1)
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .unwrap_or(f64::NAN);
    // The largest target the closing serves (its top is 1.5 × that).
    let served_n = top_n / 1.5;
    match evidence.crush_force_n {
        None if fingers_ended && (peak.is_nan() || peak < served_n) => wrong.push(format!(
            "the closing ended at {} {:.1} mm past the touch with the estimate at most {peak:.3} N above its no-contact level, on an object declared rigid (no crush_force_n): expected the estimate to reach at least {served_n:.2} N (the largest target a closing to {top_n} N serves) before the fingers stopped",
            cal.ended,
            f64::from(cal.counts_spanned) * mm_per_count
        )),
        // It gave way: the estimate must have seen the squeeze that crushed it.
        Some(crush) if fingers_ended && (peak.is_nan() || peak < 0.5 * crush) => {
            wrong.push(format!(
                "the object gave way ({} {:.1} mm past the touch) while the estimate rose at most {peak:.3} N; expected at least half its crush_force_n {crush} N",
                cal.ended,
                f64::from(cal.counts_spanned) * mm_per_count
            ));
        }
        _ => {}
    }
    let lambda = cal.lambda_max_n_per_mm;
    match evidence.press {
        Some((k, n)) => {
            let floor = lambda_floor(k, evidence.crush_force_n.is_none());
            if !(lambda.is_finite() && lambda >= floor) {
                wrong.push(format!(
                    "Λ_max {lambda:.3} N/mm lies under {floor:.3} N/mm, the floor from the finger's press in its {n} training samples ({k:.3} N per mm pressed: a grasp of a rigid object gives at least half that per mm of opening, of one that declares a crush force an eighth)"
                ));
            }
        }
        None if !(lambda.is_finite() && lambda > 0.0) => {
            wrong.push(format!(
                "Λ_max {lambda} N/mm: expected a positive stiffness"
            ));
        }
        None => {}
    }
    if wrong.is_empty() {
        return Ok(());
    }
    Err(GraspRunError::Invalid(format!(
        "calibration of `{}` refused, nothing stored: {}. The estimate does not follow the force the way the rig measures it: train the model longer or on more samples, check the finger's lighting and that the model is this finger's, then calibrate again",
        evidence.object,
        wrong.join("; ")
    )))
}

/// A check's verdict under `--accept-calibration`: passed (`None`), refused (the
/// error), or refused and accepted all the same (`Some` of the refusal, for the
/// caller to say).
///
/// # Errors
/// The check's refusal when `accept` is false.
pub fn accepted(
    checked: Result<(), GraspRunError>,
    accept: bool,
) -> Result<Option<String>, GraspRunError> {
    match checked {
        Ok(()) => Ok(None),
        Err(e) if accept => Ok(Some(e.to_string())),
        Err(e) => Err(e),
    }
}

/// The evidence for a simulated object: its declared open-loop opening and crush
/// force, and the press of `model`'s training samples in `store`.
///
/// # Errors
/// The store.
pub async fn sim_evidence(
    store: &Store,
    model: &str,
    object: &GraspObject,
) -> Result<Evidence, GraspRunError> {
    Ok(Evidence {
        press: training_press(store, model).await?,
        ..Evidence::of_object(object)
    })
}

impl Evidence {
    /// What a scene's object declares: its open-loop opening and its crush force (no
    /// press: [`training_press`] adds it).
    #[must_use]
    pub fn of_object(object: &GraspObject) -> Self {
        Self {
            object: object.name.clone(),
            open_width_mm: Some(object.grasp_width_m * 1000.0),
            crush_force_n: object.crush_force_n,
            press: None,
        }
    }
}

/// The finger's press stiffness from `model`'s training samples ([`press_stiffness`]).
///
/// # Errors
/// The store.
pub async fn training_press(
    store: &Store,
    model: &str,
) -> Result<Option<(f64, usize)>, GraspRunError> {
    let samples = store
        .training_press(model, PRESS_SAMPLES)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?;
    Ok(press_stiffness(&samples))
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
/// clock), as a row ready to store: keyed by the scene's fingerprint (with `tare`, the
/// image tare the model reads the frames through) and the model's artifact, with the
/// simulator's true Λ_max beside it.
///
/// # Errors
/// The model, or a calibration that finds no touch.
#[allow(clippy::too_many_arguments)] // what identifies a calibration, and what makes one
pub async fn calibrate_sim_row(
    model: &str,
    model_bytes: &[u8],
    scene: &SceneSpec,
    object: &GraspObject,
    fps: f64,
    seed: u64,
    top_n: f64,
    tare: Option<&ImageTare>,
) -> Result<GraspCalibrationRow, GraspRunError> {
    let setup_hash = tared_setup_hash(scene, fps, seed, tare)?;
    let mut predictor = Predictor::from_bytes(model_bytes)?;
    predictor.set_tare(tare.cloned());
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
/// else a new one made on the simulator (on a blocking thread) and stored; either is
/// first held to [`check_calibration`]: a refused one is neither stored nor used,
/// unless `accept` (`--accept-calibration`), which keeps the refusal in
/// [`Calibrated::accepted_against`] for the caller to say. With `tare`, the model
/// reads every frame through it, and the calibration is that setup's.
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
    accept: bool,
    tare: Option<&ImageTare>,
) -> Result<Calibrated, GraspRunError> {
    let model_sha256 = sha256_hex(model_bytes);
    let setup_hash = tared_setup_hash(scene, fps, seed, tare)?;
    let stored = store
        .latest_grasp_calibration(&setup_hash, &model_sha256, &object.name)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?;
    let evidence = sim_evidence(store, model, object).await?;
    let checked =
        |row: &GraspCalibrationRow| accepted(check_calibration(row, top_n, &evidence), accept);
    if let Some(row) = stored {
        // One stored before the check existed is held to it too.
        let accepted_against = checked(&row).map_err(|e| {
            GraspRunError::Invalid(format!("stored calibration #{}: {e}", row.calibration_id))
        })?;
        return Ok(Calibrated {
            row,
            fresh: false,
            accepted_against,
        });
    }
    let mut row =
        calibrate_sim_row(model, model_bytes, scene, object, fps, seed, top_n, tare).await?;
    let accepted_against = checked(&row)?;
    row.calibration_id = store
        .insert_grasp_calibration(&row)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?;
    Ok(Calibrated {
        row,
        fresh: true,
        accepted_against,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(touch_count: u8, lambda: f64, ended: &str) -> GraspCalibrationRow {
        GraspCalibrationRow {
            calibration_id: 0,
            created_at: String::new(),
            setup_kind: "scene".into(),
            setup_hash: String::new(),
            model: "m".into(),
            model_sha256: String::new(),
            object: "cylinder".into(),
            touch_count,
            lambda_max_n_per_mm: lambda,
            lambda_iqr_n_per_mm: (lambda, lambda),
            counts_spanned: 20,
            baseline_n: 0.0,
            mm_per_count: STROKE_MM / 255.0,
            ended: ended.into(),
            points_json: "[]".into(),
            lambda_json: "[]".into(),
            true_lambda_max_n_per_mm: None,
        }
    }

    fn cylinder() -> Evidence {
        Evidence {
            object: "cylinder".into(),
            open_width_mm: Some(28.0),
            crush_force_n: None,
            press: Some((0.14, 1050)),
        }
    }

    #[test]
    fn a_good_calibration_passes() {
        // The cylinder with a 12-epoch model: touch at 97 (31.0 mm), Λ_max 1.8 N/mm.
        check_calibration(&row(97, 1.801, "reached_top"), 4.5, &cylinder()).expect("passes");
    }

    #[test]
    fn a_weak_calibration_is_refused_with_its_numbers_and_what_to_do() {
        // The issue's: Λ_max 0.022 N/mm.
        let e = check_calibration(&row(97, 0.022, "reached_top"), 4.5, &cylinder())
            .expect_err("refused")
            .to_string();
        assert!(e.contains("Λ_max 0.022 N/mm lies under 0.070 N/mm"), "{e}");
        assert!(e.contains("1050 training samples"), "{e}");
        assert!(e.contains("train the model longer"), "{e}");
        assert!(e.contains("nothing stored"), "{e}");
        // NaN and negative stiffness, with and without a press to compare.
        for lambda in [f64::NAN, -1.0, 0.0] {
            assert!(check_calibration(&row(97, lambda, "reached_top"), 4.5, &cylinder()).is_err());
            let bare = Evidence {
                press: None,
                ..cylinder()
            };
            assert!(check_calibration(&row(97, lambda, "reached_top"), 4.5, &bare).is_err());
        }
    }

    #[test]
    fn a_touch_away_from_the_declared_width_and_a_closing_the_estimate_did_not_end_are_refused() {
        // Count 170 is an opening of 16.7 mm on a 30 mm object; count 3 (49.4 mm) is a
        // touch read from noise at the open end.
        let e = check_calibration(&row(170, 1.8, "reached_top"), 4.5, &cylinder())
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("opening of 16.7 mm (count 170)") && e.contains("30.0 mm wide"),
            "{e}"
        );
        assert!(check_calibration(&row(3, 1.8, "reached_top"), 4.5, &cylinder()).is_err());
        check_calibration(&row(140, 1.8, "reached_top"), 4.5, &cylinder()).expect("within 8 mm");
        for ended in ["closed_end", "contact_stop"] {
            let mut r = row(97, 1.8, ended);
            r.points_json = "[[97,97,0.0],[110,110,1.0],[120,120,2.9]]".into();
            let e = check_calibration(&r, 4.5, &cylinder())
                .expect_err("refused")
                .to_string();
            assert!(
                e.contains(ended) && e.contains("at most 2.900 N") && e.contains("declared rigid"),
                "{e}"
            );
            // One that read the largest target it serves (3 N) first passes: the loop's
            // range is covered (a land model in water stops at 3.7 N on a contact stop).
            r.points_json = "[[97,97,0.0],[110,110,1.0],[120,120,3.7]]".into();
            check_calibration(&r, 4.5, &cylinder()).expect("covers 3 N");
        }
        // A crushable object may end at the closed end (it gave way) once the estimate
        // saw half its crush force, with the lower floor.
        let cake = Evidence {
            object: "cake".into(),
            crush_force_n: Some(2.5),
            ..cylinder()
        };
        let mut gave_way = row(97, 0.9, "closed_end");
        gave_way.points_json = "[[97,97,0.0],[110,110,1.4],[120,120,2.4],[130,130,0.2]]".into();
        check_calibration(&gave_way, 4.5, &cake).expect("a cake may give way");
        // The weak model's cake: Λ_max 0.052 N/mm, the estimate never past 0.3 N.
        let mut unseen = row(107, 0.052, "closed_end");
        unseen.points_json = "[[107,107,0.0],[200,200,0.3],[254,254,0.25]]".into();
        let e = check_calibration(&unseen, 4.5, &cake)
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("rose at most 0.300 N") && e.contains("crush_force_n 2.5 N"),
            "{e}"
        );
    }

    #[test]
    fn the_press_stiffness_needs_samples_and_a_slope() {
        assert_eq!(press_stiffness(&[]), None);
        let few: Vec<(f64, f64)> = (0..10).map(|i| (f64::from(i) * 1e-3, 1.0)).collect();
        assert_eq!(press_stiffness(&few), None);
        // 0.2 N per mm pressed, pressing along −x: the magnitude.
        let line: Vec<(f64, f64)> = (0..40)
            .map(|i| (-f64::from(i) * 1e-3, 0.2 * f64::from(i)))
            .collect();
        let (k, n) = press_stiffness(&line).expect("a slope");
        assert!((k - 0.2).abs() < 1e-9, "{k}");
        assert_eq!(n, 40);
        // A constant force: no stiffness to compare with.
        let flat: Vec<(f64, f64)> = (0..40).map(|i| (f64::from(i) * 1e-3, 1.0)).collect();
        assert_eq!(press_stiffness(&flat), None);
    }

    #[test]
    fn a_stored_closing_gives_its_bound_and_a_damaged_one_is_named() {
        let mut r = row(100, 0.1 / (STROKE_MM / 255.0), "reached_top");
        r.points_json = "[[100,100,0.0],[105,105,0.5],[110,110,1.0]]".into();
        let b = squeeze_of_row(&r).expect("parses");
        assert_eq!(b.limit_count(1.0), 100 + 30 + 3);
        r.points_json = "[[100,100".into();
        r.calibration_id = 12;
        let e = squeeze_of_row(&r).expect_err("damaged").to_string();
        assert!(
            e.contains("calibration #12") && e.contains("points_json"),
            "{e}"
        );
    }
}
