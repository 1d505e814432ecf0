//! The image tare of a grasp scene (issue 68): what a lab does at the start of a
//! water session with a model trained on land. With the gripper open and nothing
//! between the fingers, finger 0's camera gives its [`rest_frames`]; the tare that
//! maps them onto the rest frames of the runs the model learned from is fitted
//! ([`softtouch_trainer::fit_image_tare`]: scale about the principal point, gain and
//! offset per channel, a gain map), and every frame the calibrations and the trials
//! read goes through it ([`softtouch_trainer::Predictor::set_tare`]). No label
//! of the scene's medium is read.

use serde::{Deserialize, Serialize};
use softtouch_collector::collect::rest_frames;
use softtouch_drivers::{Clock as _, TokioClock};
use softtouch_schemas::SceneSpec;
use softtouch_sim::{GraspObject, soft_grasp};
use softtouch_trainer::{ImageTare, ModelArtifact, RestFrame, TareGains};

use super::soft::GraspRunError;
use crate::store::Store;
use crate::transfer::TransferError;

/// A scene's fitted tare, stored with the session that reads through it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneTare {
    /// The dataset whose runs' rest frames the scene's were fitted against (the
    /// model's).
    pub against: String,
    /// The correction.
    pub tare: ImageTare,
    /// RMS difference of the rest means on the finger, 0–255 units: as they came,
    /// and through the tare.
    pub rms_before: f64,
    pub rms_after: f64,
    /// Rest frames averaged: the dataset's, the scene's.
    pub land_frames: usize,
    pub scene_frames: usize,
}

impl SceneTare {
    /// One line for people.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "image tare from {} rest frames of the finger camera against {} of dataset `{}`: {}; rest RMS on the finger {:.1} → {:.1}",
            self.scene_frames,
            self.land_frames,
            self.against,
            self.tare.describe(),
            self.rms_before,
            self.rms_after
        )
    }
}

/// The [`rest_frames`] of finger 0's camera in `scene` with the gripper open and no
/// object between the fingers, on this thread with its own paused clock.
///
/// # Errors
/// A scene without objects, the simulator, a frame that does not decode.
pub fn sim_rest_frames(
    scene: &SceneSpec,
    fps: f64,
    seed: u64,
) -> Result<Vec<RestFrame>, GraspRunError> {
    let Some(spec) = scene.objects.first() else {
        return Err(GraspRunError::Invalid(format!(
            "scene `{}` has no object to set the fingers up for",
            scene.name
        )));
    };
    let object = GraspObject::from_spec(spec);
    let rt = super::sim::paused_runtime()
        .map_err(|e| GraspRunError::Failed(format!("cannot start a runtime: {e}")))?;
    rt.block_on(async {
        let clock = TokioClock::new();
        let (_gripper, mut camera, handle) = soft_grasp(scene, object, fps, seed, clock)?;
        handle.set_object(false)?;
        let frames = rest_frames(&mut camera, clock.now(), 1000)
            .await
            .map_err(|e| GraspRunError::Failed(format!("a rest frame: {e}")))?;
        frames
            .iter()
            .map(|frame| {
                let (width, height, rgb) = crate::models::decode_stored(
                    frame.meta.format.as_str(),
                    i64::from(frame.meta.width),
                    i64::from(frame.meta.height),
                    &frame.data,
                )
                .map_err(|why| GraspRunError::Failed(format!("a rest frame: {why}")))?;
                Ok(RestFrame { width, height, rgb })
            })
            .collect()
    })
}

/// The tare of `scene` for `model` (whose artifact is `model_bytes`): the scene's
/// rest frames ([`sim_rest_frames`]) against those of the dataset the model was
/// trained on, gain and offset fitted on the pixels the model keeps as the finger's.
///
/// # Errors
/// A model or dataset without rest frames (named), frames that cannot be compared,
/// the simulator, the store.
pub async fn fit_scene_tare(
    store: &Store,
    model: &str,
    model_bytes: &[u8],
    scene: &SceneSpec,
    fps: f64,
    seed: u64,
) -> Result<SceneTare, GraspRunError> {
    let info = store
        .model(model)
        .await
        .map_err(|e| GraspRunError::Failed(e.to_string()))?
        .ok_or_else(|| GraspRunError::Invalid(format!("no model `{model}`")))?;
    let land = crate::transfer::rest_frames(store, &info.dataset_name)
        .await
        .map_err(|e| match e {
            TransferError::NoRestFrames(_) => {
                GraspRunError::Invalid(format!("--tare: model `{model}`'s dataset: {e}"))
            }
            e => GraspRunError::Failed(e.to_string()),
        })?;
    // The header alone: no weights decoded, no colour table built.
    let preprocess = ModelArtifact::header_from_bytes(model_bytes)?
        .0
        .config
        .preprocess;
    let (scene2, scene_name) = (scene.clone(), scene.name.clone());
    let water = tokio::task::spawn_blocking(move || sim_rest_frames(&scene2, fps, seed))
        .await
        .map_err(|e| GraspRunError::Failed(format!("the rest frames' thread failed: {e}")))??;
    let keep = |r, g, b| preprocess.is_finger(r, g, b);
    let fit = softtouch_trainer::fit_image_tare(
        &land,
        &water,
        Some(&keep),
        TareGains::for_signal(preprocess.signal),
    )
    .map_err(|e| {
        GraspRunError::Invalid(format!(
            "--tare: scene `{scene_name}` against dataset `{}`: {e}",
            info.dataset_name
        ))
    })?;
    Ok(SceneTare {
        against: info.dataset_name,
        tare: fit.tare,
        rms_before: fit.rms_before,
        rms_after: fit.rms_after_map,
        land_frames: fit.land_frames,
        scene_frames: fit.water_frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The water grasp scene's finger camera, fitted against the land one's: the
    /// tare finds the flat port's magnification, 1.333, from rest frames alone.
    #[test]
    fn the_water_grasp_cameras_rest_frames_give_the_ports_magnification() {
        let scenes = crate::grasp::trials::load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        let land = sim_rest_frames(&scenes[0], 120.0, 3).unwrap_or_else(|e| panic!("{e}"));
        let water = sim_rest_frames(&scenes[1], 120.0, 3).unwrap_or_else(|e| panic!("{e}"));
        let n = softtouch_collector::collect::REST_FRAMES;
        assert_eq!((land.len(), water.len()), (n, n));
        let fit = softtouch_trainer::fit_image_tare(&land, &water, None, TareGains::PerChannel)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            (fit.tare.scale - 1.333).abs() < 0.01,
            "{}",
            fit.tare.describe()
        );
        assert!(fit.rms_after_map < fit.rms_before / 3.0, "{fit:?}");
        // The land scene against itself: no correction to speak of.
        let same = softtouch_trainer::fit_image_tare(&land, &land, None, TareGains::PerChannel)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            (same.tare.scale - 1.0).abs() < 0.005,
            "{}",
            same.tare.describe()
        );
    }

    #[test]
    fn a_scene_without_objects_is_named() {
        let mut scenes =
            crate::grasp::trials::load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        scenes[1].objects.clear();
        let err = sim_rest_frames(&scenes[1], 120.0, 3)
            .err()
            .map(|e| e.to_string());
        assert!(
            err.as_deref().is_some_and(|e| e.contains("has no object")),
            "{err:?}"
        );
    }

    #[test]
    fn a_tare_changes_the_setups_key_and_none_keeps_the_old_one() {
        use crate::grasp::calibration::{scene_setup_hash, tared_setup_hash};
        let scenes = crate::grasp::trials::load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        let plain = scene_setup_hash(&scenes[1], 120.0, 0).unwrap_or_else(|e| panic!("{e}"));
        let none = tared_setup_hash(&scenes[1], 120.0, 0, None).unwrap_or_else(|e| panic!("{e}"));
        let mut tare = ImageTare::identity(640, 480);
        let one =
            tared_setup_hash(&scenes[1], 120.0, 0, Some(&tare)).unwrap_or_else(|e| panic!("{e}"));
        tare.scale = 1.333;
        let other =
            tared_setup_hash(&scenes[1], 120.0, 0, Some(&tare)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(plain, none);
        assert_ne!(plain, one);
        assert_ne!(one, other);
    }
}
