//! What `grasp follow`, `disturb` and `twist` share: the loop's flags, their one
//! check, the scene and model they load, the setup they print, and their failures.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::anyhow;
use clap::Args;
use softtouch_grasp::Cycle;
use softtouch_grasp::{GainCheck, GraspError};

use crate::{Failure, io_failure, open_existing};
use softtouch_lab::grasp::settings;
use softtouch_lab::grasp::soft::{GraspRunError, LoopSettings, Setup, grasp_scene};

/// Options every grasp experiment shares.
#[derive(Debug, Args)]
pub struct LoopArgs {
    /// Stored model whose estimate closes the loop.
    #[arg(long)]
    pub model: String,
    /// Scene file (medium, effects, `[[objects]]`); default: the built-in grasp scene
    /// (`scenes/grasp.toml`).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Gain K, N/mm; default: 0.75 × Λ_max from the latest stiffness calibration of
    /// this model on this object and setup (`softtouch grasp calibrate`; made and
    /// stored first when there is none).
    #[arg(long)]
    pub gain: Option<f64>,
    /// Tolerance δ, N.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Camera rate, Hz (one control cycle per frame).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// Sensorised fingers the loop reads: 1, or 2 (the second mirrors the first; the
    /// estimate is the mean of both, or the one left when the other gives none).
    #[arg(long, default_value_t = 1)]
    pub fingers: u8,
    /// Folder for the CSV and the PNG.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
    /// Seed of the simulated scene's effects.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Use a stiffness calibration its check refuses (`softtouch grasp calibrate`:
    /// the touch far from the object's width, an estimate that did not follow the
    /// closing): the refusal is printed and stored with the result, and the squeeze
    /// bound still limits the loop. For a model known to under-read (a land model in
    /// water) or an object the check does not know.
    #[arg(long)]
    pub accept_calibration: bool,
}

/// What a grasp experiment stores: the model and the shared flags (each verb adds
/// its own settings, hashes and tables).
pub(super) fn loop_recorder(verb: &'static str, c: &LoopArgs) -> crate::results::Recorder {
    crate::results::Recorder::new(verb)
        .model(&c.model)
        .setting("gain_flag_n_per_mm", c.gain)
        .setting("tolerance_n", c.tolerance)
        .setting("fps", c.fps)
        .setting("fingers", c.fingers)
        .setting("seed", c.seed)
        .setting("scene", c.scene.as_ref().map(|p| p.display().to_string()))
        .setting("accept_calibration", c.accept_calibration)
}

/// The simulated scene's fingerprint as a result records it.
pub(super) fn scene_hash(scene: &softtouch_schemas::SceneSpec, c: &LoopArgs) -> Option<String> {
    softtouch_lab::grasp::calibration::scene_setup_hash(scene, c.fps, c.seed).ok()
}

pub(super) fn grasp_failure(e: GraspError) -> Failure {
    GraspRunError::Grasp(e).into()
}

pub(super) fn bad(m: String) -> Failure {
    Failure::BadInput(anyhow!(m))
}

/// The shared flags, checked: one validation per setting for every verb.
pub(super) fn loop_settings(c: &LoopArgs) -> Result<LoopSettings, Failure> {
    settings::FPS_HZ.check("--fps", c.fps)?;
    settings::TOLERANCE_N.check("--tolerance", c.tolerance)?;
    let fingers = settings::check_fingers(c.fingers)?;
    Ok(LoopSettings {
        gain_n_per_mm: c.gain,
        tolerance_n: c.tolerance,
        fps: c.fps,
        fingers,
        seed: c.seed,
    })
}

pub(super) fn check_duration(flag: &str, v: f64, zero_allowed: bool) -> Result<(), Failure> {
    settings::duration_s(zero_allowed).check(flag, v)?;
    Ok(())
}

/// The scene of `--scene`, else the built-in grasp scene (every grasp verb, and
/// `grasp calibrate`, default to it: one calibration serves them all).
pub(super) fn scene_for(c: &LoopArgs) -> Result<softtouch_schemas::SceneSpec, Failure> {
    match c.scene.as_deref() {
        None => Ok(grasp_scene()?),
        Some(path) => Ok(softtouch_collector::configs::resolve(None, Some(path))?.scene),
    }
}

/// The stored model's bytes and the calibration of `object` it runs with (the latest
/// stored, else one made now on the simulator and stored); then tokio's clock is
/// paused, for the simulated gripper and cameras (the database is used first: its
/// pool's timeouts need real time).
pub(super) async fn load_model_calibrate_and_pause(
    c: &LoopArgs,
    db: &softtouch_store::DbTarget,
    scene: &softtouch_schemas::SceneSpec,
    object: &softtouch_sim::GraspObject,
    largest_target_n: f64,
) -> Result<(Vec<u8>, softtouch_lab::grasp::calibration::Calibrated), Failure> {
    let store = open_existing(db).await?;
    let bytes = softtouch_lab::models::force_artifact(&store, &c.model).await?;
    let calibrated = softtouch_lab::grasp::calibration::calibration_for(
        &store,
        &c.model,
        &bytes,
        scene,
        object,
        c.fps,
        c.seed,
        softtouch_lab::grasp::calibration::top_for(largest_target_n),
        c.accept_calibration,
        None,
    )
    .await?;
    store.close().await;
    if let Some(refusal) = &calibrated.accepted_against {
        eprintln!("warning: --accept-calibration: using it against its check: {refusal}");
    }
    tokio::time::pause();
    Ok((bytes, calibrated))
}

/// What the setup measured and chose, and Method S4's warnings, each said once with
/// its remedy.
pub(super) fn print_setup(
    object: &str,
    s: &Setup,
    l: &LoopSettings,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let w = io_failure;
    let (id, fresh) = s.calibration;
    writeln!(
        out,
        "object `{object}`: calibration #{id} ({}): first touch at count {}, Λ_max = {:.3} N/mm from the model's estimate{}; K = {:.3} N/mm, δ = {} N, {} Hz, {} finger(s)",
        if fresh { "made now" } else { "stored" },
        s.touch,
        s.lambda_max,
        s.true_lambda_max.map_or_else(String::new, |t| format!(
            " (the simulator's true Λ_max: {t:.3} N/mm, a check only)"
        )),
        s.gain,
        l.tolerance_n,
        l.fps,
        l.fingers
    )
    .map_err(w)?;
    match s.gain_check {
        GainCheck::MayNotConverge { amplification } => writeln!(
            out,
            "warning: K ≤ Λ_max/2 (Method S4): the loop may oscillate (|1 − Λ/K| = {amplification:.2}); leave --gain out for 0.75 Λ_max"
        )
        .map_err(w)?,
        GainCheck::NoStiffness => {
            writeln!(out, "warning: Λ = 0: the force does not follow position").map_err(w)?;
        }
        GainCheck::Converges { .. } => {}
    }
    if !s.tolerance_ok {
        writeln!(
            out,
            "warning: δ = {} N is below half the force of one count ({:.3} N at Λ_max): expect dithering; --tolerance {:.3} or more avoids it",
            l.tolerance_n,
            s.one_count_n,
            (s.one_count_n / 2.0 * 1000.0).ceil() / 1000.0
        )
        .map_err(w)?;
    }
    Ok(())
}

pub(super) fn create_out_dir(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", dir.display())))
}

/// A line when a stop request ended the loop early: what follows is what ran.
pub(super) fn print_stopped(
    stopped: Option<&'static str>,
    cycles: &[Cycle],
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if let Some(name) = stopped {
        let ran_s = match (cycles.first(), cycles.last()) {
            (Some(a), Some(b)) => b.t.0.saturating_sub(a.t.0) as f64 * 1e-9,
            _ => 0.0,
        };
        writeln!(
            out,
            "stopped by {name} after {} cycles ({ran_s:.2} s); the fingers are open; below is what ran",
            cycles.len()
        )
        .map_err(io_failure)?;
    }
    Ok(())
}
