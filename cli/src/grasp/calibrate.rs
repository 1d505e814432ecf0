//! `softtouch grasp calibrate`: the stiffness of an object as the finger's own estimate
//! sees it (Λ(P) and Λ_max by Theil–Sen, the first touch), on the simulated soft grasp
//! or on a rig's Hand-E; stored, so that the grasp verbs take K = 0.75 Λ_max and their
//! pre-grasp opening from it.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use clap::Args;
use softtouch_collector::dataset::export::sha256_hex;
use softtouch_lab::grasp::calibration::{calibrate_sim_row, to_row, top_for};
use softtouch_lab::grasp::follow::object_for;
use softtouch_trainer::Predictor;

use super::setup::{bad, grasp_failure};
use crate::{Failure, io_failure, open_existing};

/// Options of `grasp calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Stored model whose estimate is calibrated.
    #[arg(long)]
    pub model: String,
    /// The reference object (a `[[objects]]` name of the scene; on a rig, its name for
    /// the record, matched by `grasp follow --rig … --object`).
    #[arg(long)]
    pub object: Option<String>,
    /// Scene file (simulated grasp); default: the built-in grasp scene
    /// (`scenes/grasp.toml`), its first object unless --object names another. Beside
    /// --rig: the scene's object of --object's name declares the width and crush
    /// force the calibration is checked against (else the rig's `[grasp]` object).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Rig file with a real Hand-E and finger camera: the ends are calibrated first
    /// (nothing between the fingers), then you place the object and press Enter.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Store the calibration even when its check refuses it, printing the refusal
    /// (the verbs that use it then need `--accept-calibration` too).
    #[arg(long)]
    pub accept_calibration: bool,
    /// The largest target the loop will hold, N: the closing goes up to 1.5 × it (at
    /// least 4.5 N).
    #[arg(long, default_value_t = 3.0)]
    pub target: f64,
    /// Camera rate of the simulated grasp, Hz.
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// Seed of the simulated scene's effects.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Run `grasp calibrate`.
pub(super) async fn run(
    args: CalibrateArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    softtouch_lab::grasp::settings::FPS_HZ.check("--fps", args.fps)?;
    // The loop's own tolerance δ (the default the verbs run with).
    let tolerance_n = softtouch_grasp::StepperConfig::default().tolerance_n;
    softtouch_lab::grasp::settings::check_target_n("--target", args.target, tolerance_n)?;
    let top_n = top_for(args.target);
    let store = open_existing(db).await?;
    let bytes = softtouch_lab::models::force_artifact(&store, &args.model).await?;
    let model_sha256 = sha256_hex(&bytes);
    let w = io_failure;
    let (row, ends) = if let Some(rig_path) = &args.rig {
        let object = args
            .object
            .clone()
            .ok_or_else(|| bad("--object: expected the reference object's name on a rig".into()))?;
        // The rig alone: a grasp uses none of a collection scene's poses.
        let rig = softtouch_collector::configs::rig(Some(rig_path))?.0;
        let setup_hash = softtouch_lab::grasp::calibration::rig_setup_hash(&rig)?;
        let predictor = Predictor::from_bytes(&bytes)?;
        let projection = softtouch_lab::grasp::soft::projections().map_err(grasp_failure)?[0];
        writeln!(
            out,
            "rig {}: calibrating the gripper's ends: nothing may be between the fingers",
            rig_path.display()
        )
        .map_err(w)?;
        out.flush().map_err(w)?;
        let prompt = format!(
            "place `{object}` between the open fingers, then press Enter (an empty input stops)"
        );
        let ready = async move {
            eprintln!("{prompt}");
            tokio::task::spawn_blocking(|| {
                let mut line = String::new();
                match std::io::stdin().lock().read_line(&mut line) {
                    Ok(0) | Err(_) => Err("no answer: the input closed".to_owned()),
                    Ok(_) => Ok(()),
                }
            })
            .await
            .map_err(|e| e.to_string())?
        };
        let (ends, cal) = softtouch_lab::grasp::devices::stiffness_on_rig(
            &rig, predictor, projection, top_n, ready,
        )
        .await
        .map_err(|e| match e {
            softtouch_lab::grasp::devices::RigFollowError::Open(e) => {
                Failure::Runtime(anyhow::anyhow!("{e}"))
            }
            softtouch_lab::grasp::devices::RigFollowError::Grasp(e) => grasp_failure(e),
        })?;
        let mut row = to_row(
            &cal,
            ("rig", &setup_hash),
            (&args.model, &model_sha256),
            &object,
            None,
        )?;
        row.mm_per_count = ends.stroke.mm_per_count;
        // What the rig knows: the object's declared opening where the rig's grasp
        // trials declare it (no crush force there: taken as rigid), and the finger's
        // press in the model's training samples.
        let press = softtouch_lab::grasp::calibration::training_press(&store, &args.model).await?;
        let evidence = match args.scene.as_deref() {
            Some(path) => {
                let scene = softtouch_collector::configs::scene(Some(path))?.0;
                let declared = object_for(&scene, Some(&object))?;
                softtouch_lab::grasp::calibration::Evidence {
                    press,
                    ..softtouch_lab::grasp::calibration::Evidence::of_object(&declared)
                }
            }
            None => softtouch_lab::grasp::calibration::Evidence {
                object: object.clone(),
                open_width_mm: rig
                    .grasp
                    .as_ref()
                    .and_then(|g| g.objects.iter().find(|o| o.name == object))
                    .map(|o| o.open_width_mm),
                crush_force_n: None,
                press,
            },
        };
        accept_or_refuse(
            softtouch_lab::grasp::calibration::check_calibration(&row, top_n, &evidence),
            args.accept_calibration,
        )?;
        (row, Some(ends))
    } else {
        // The grasp scene unless told otherwise, as every grasp verb: its objects are
        // the ones `follow`, `disturb`, `twist` and `trials` hold.
        let scene = match args.scene.as_deref() {
            None => softtouch_lab::grasp::soft::grasp_scene()?,
            Some(path) => softtouch_collector::configs::resolve(None, Some(path))?.scene,
        };
        let object = object_for(&scene, args.object.as_deref())?;
        let row = calibrate_sim_row(
            &args.model,
            &bytes,
            &scene,
            &object,
            args.fps,
            args.seed,
            top_n,
            None,
        )
        .await?;
        let evidence =
            softtouch_lab::grasp::calibration::sim_evidence(&store, &args.model, &object).await?;
        accept_or_refuse(
            softtouch_lab::grasp::calibration::check_calibration(&row, top_n, &evidence),
            args.accept_calibration,
        )?;
        (row, None)
    };
    let id = store
        .insert_grasp_calibration(&row)
        .await
        .map_err(|e| Failure::Runtime(anyhow::anyhow!("{e}")))?;
    store.close().await;
    if let Some(e) = ends {
        writeln!(
            out,
            "ends: counts {}–{} at {:.4} mm per count",
            e.stroke.open_count, e.stroke.closed_count, e.stroke.mm_per_count
        )
        .map_err(w)?;
    }
    writeln!(
        out,
        "calibration #{id}: `{}` with model `{}`: first touch at count {} (no-contact estimate {:.3} N); Λ_max = {:.3} N/mm (IQR of its window's slopes {:.3}–{:.3}) over {} counts, closing ended: {}",
        row.object,
        row.model,
        row.touch_count,
        row.baseline_n,
        row.lambda_max_n_per_mm,
        row.lambda_iqr_n_per_mm.0,
        row.lambda_iqr_n_per_mm.1,
        row.counts_spanned,
        row.ended
    )
    .map_err(w)?;
    if let Some(t) = row.true_lambda_max_n_per_mm {
        writeln!(
            out,
            "the simulator's true Λ_max over the same range: {t:.3} N/mm ({:+.1} %; a check of the estimate, never used by a loop)",
            (row.lambda_max_n_per_mm / t - 1.0) * 100.0
        )
        .map_err(w)?;
    }
    writeln!(
        out,
        "K = 0.75 Λ_max = {:.3} N/mm; one count is {:.3} N at Λ_max",
        0.75 * row.lambda_max_n_per_mm,
        row.lambda_max_n_per_mm * row.mm_per_count
    )
    .map_err(w)?;
    // Λ(P) every few windows, for a look.
    let curve: Vec<(u8, f64)> = serde_json::from_str(&row.lambda_json).unwrap_or_default();
    let step = (curve.len() / 8).max(1);
    let shown: Vec<String> = curve
        .iter()
        .step_by(step)
        .map(|(p, l)| format!("{p}: {l:.2}"))
        .collect();
    writeln!(out, "Λ(P) N/mm by count: {}", shown.join(", ")).map_err(w)?;
    Ok(())
}

/// A check's refusal: an error, or with `--accept-calibration` a warning on stderr.
fn accept_or_refuse(
    checked: Result<(), softtouch_lab::grasp::soft::GraspRunError>,
    accept: bool,
) -> Result<(), softtouch_lab::grasp::soft::GraspRunError> {
    if let Some(refusal) = softtouch_lab::grasp::calibration::accepted(checked, accept)? {
        eprintln!("warning: --accept-calibration: stored against its check: {refusal}");
    }
    Ok(())
}
