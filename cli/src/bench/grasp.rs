//! `softtouch bench grasp`: settling time, overshoot and steady-state error of the
//! force loop on the simulated soft grasp against K, δ, camera rate and model; a table,
//! `grasp-bench.csv` and `grasp-bench.png` (the true force over time for each K).

use std::io::Write;
use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;
use softtouch_grasp::GraspError;
use softtouch_sim::GraspObject;

use crate::{Failure, io_failure, open_existing};
use softtouch_collector::plot::{Series, SeriesStyle, XyChart, xy_chart};
use softtouch_lab::grasp::bench::{CSV_HEADER, Outcome, Point, Setup, csv_row, grid, run_point};
use softtouch_lab::grasp::settings;

/// Options of `bench grasp`.
#[derive(Debug, Args)]
pub struct BenchGraspArgs {
    /// Stored models, comma-separated: each is run over the whole grid.
    #[arg(long, value_delimiter = ',', required = true)]
    pub model: Vec<String>,
    /// Gains K as multiples of the measured stiffness Λ_max (Method S4: below 0.5 the
    /// loop may not settle).
    #[arg(long, value_delimiter = ',', default_value = "0.3,0.45,0.75,1.5,3")]
    pub gains: Vec<f64>,
    /// Tolerances δ, N.
    #[arg(long, value_delimiter = ',', default_value = "0.05,0.1,0.2")]
    pub tolerances: Vec<f64>,
    /// Camera rates, Hz (one control cycle per frame).
    #[arg(long, value_delimiter = ',', default_value = "30,60,120")]
    pub fps: Vec<f64>,
    /// Target force, N.
    #[arg(long, default_value_t = 1.6)]
    pub target: f64,
    /// How long the target is held per run, s.
    #[arg(long, default_value_t = 3.0)]
    pub hold_s: f64,
    /// Scene file (medium, effects, `[[objects]]`); default: the built-in scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Also run the baseline (K = 0.75 Λ, δ = 0.1 N, 120 Hz) on the wall clock and
    /// report the achieved cycle rate and late frames.
    #[arg(long)]
    pub wall_clock: bool,
    /// Folder for `grasp-bench.csv` and `grasp-bench.png`.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Seed of the simulated scene's effects.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Use stiffness calibrations their check refuses (as `grasp follow
    /// --accept-calibration`), saying each.
    #[arg(long)]
    pub accept_calibration: bool,
}

fn grasp_failure(e: GraspError) -> Failure {
    match e {
        GraspError::Config(_) | GraspError::UnreachableTarget { .. } => Failure::BadInput(e.into()),
        GraspError::Device(_)
        | GraspError::Estimate(_)
        | GraspError::EstimateStalled { .. }
        | GraspError::Interrupted(_) => Failure::Runtime(e.into()),
    }
}

fn check(args: &BenchGraspArgs) -> Result<(), Failure> {
    let bad = |m: String| Err(Failure::BadInput(anyhow!(m)));
    if args.model.iter().any(String::is_empty) {
        return bad("--model: expected stored model names, comma-separated".into());
    }
    for g in &args.gains {
        if !(g.is_finite() && *g > 0.0 && *g <= 100.0) {
            return bad(format!(
                "--gains {g}: expected multiples of Λ_max in (0, 100]"
            ));
        }
    }
    settings::TOLERANCE_N.check_all("--tolerances", &args.tolerances)?;
    settings::FPS_HZ.check_all("--fps", &args.fps)?;
    // Held under each tolerance of the grid: the widest leaves the least room.
    let widest = args.tolerances.iter().copied().fold(0.0, f64::max);
    settings::check_target_n("--target", args.target, widest)?;
    settings::duration_s(false).check("--hold-s", args.hold_s)?;
    Ok(())
}

/// Run `bench grasp`.
pub(super) async fn run(
    args: BenchGraspArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    check(&args)?;
    let resolved = softtouch_collector::configs::resolve(None, args.scene.as_deref())?;
    let scene = resolved.scene;
    let object = match (scene.objects.first(), scene.rods.first()) {
        (Some(o), _) => GraspObject::from_spec(o),
        (None, Some(rod)) => GraspObject {
            shape: rod.shape,
            aspect: rod.aspect,
            ..GraspObject::cylinder(&rod.name, rod.size_m)
        },
        (None, None) => {
            return Err(Failure::BadInput(anyhow!(
                "the scene has neither objects nor rods to grasp"
            )));
        }
    };
    let store = open_existing(db).await?;
    let mut models = Vec::new();
    for name in &args.model {
        let bytes = softtouch_lab::models::force_artifact(&store, name).await?;
        let predictor = softtouch_trainer::Predictor::from_bytes(&bytes)?;
        // Each model's own Λ_max on the object (at 120 Hz; the stiffness is the
        // contact's, not the camera's): the latest stored, else made now.
        let cal = softtouch_lab::grasp::calibration::calibration_for(
            &store,
            name,
            &bytes,
            &scene,
            &object,
            120.0,
            args.seed,
            softtouch_lab::grasp::calibration::top_for(args.target),
            args.accept_calibration,
            None,
        )
        .await?;
        if let Some(refusal) = &cal.accepted_against {
            writeln!(
                out,
                "warning: --accept-calibration: model `{name}` runs on a calibration its check refuses: {refusal}"
            )
            .map_err(io_failure)?;
        }
        models.push((name.clone(), bytes, predictor.header().config, cal));
    }
    store.close().await;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out.display())))?;
    let setup = Setup {
        scene,
        object,
        target_n: args.target,
        hold_s: args.hold_s,
        seed: args.seed,
    };
    let points = grid(&args.gains, &args.tolerances, &args.fps);
    let w = |e| io_failure(e);
    writeln!(
        out,
        "bench grasp: object `{}`, target {} N held {} s, {} runs per model on virtual time",
        setup.object.name,
        args.target,
        args.hold_s,
        points.len()
    )
    .map_err(w)?;
    for (name, _, _, cal) in &models {
        writeln!(
            out,
            "model `{name}`: calibration #{} ({}): first touch at count {}, Λ_max = {:.3} N/mm from its estimate{}",
            cal.row.calibration_id,
            if cal.fresh { "made now" } else { "stored" },
            cal.touch(),
            cal.lambda_max(),
            cal.row.true_lambda_max_n_per_mm.map_or_else(String::new, |t| format!(
                " (the simulator's true Λ_max: {t:.3} N/mm, a check only)"
            ))
        )
        .map_err(w)?;
    }
    writeln!(
        out,
        "{:<14} {:<12} {:<9} {:>6} {:>6} {:>5} {:>7} {:>9} {:>9} {:>10} {:>10} {:>12} {:>12}",
        "model",
        "shape",
        "varied",
        "K/Λ",
        "δ N",
        "fps",
        "Hz",
        "late/skip",
        "settle s",
        "overshoot",
        "ss err N",
        "true settle",
        "true ss N"
    )
    .map_err(w)?;
    let mut csv = format!("{CSV_HEADER}\n");
    let mut gain_traces: Vec<Series> = Vec::new();
    tokio::time::pause(); // virtual time for the simulated grasp
    for (i, (name, bytes, config, calibrated)) in models.iter().enumerate() {
        let shape = (config.preprocess.size_px, config.width, config.latent);
        for point in &points {
            let predictor = softtouch_trainer::Predictor::from_bytes(bytes)?;
            let o = run_point(&setup, predictor, *point, calibrated)
                .await
                .map_err(grasp_failure)?;
            print_row(out, name, shape, &o)?;
            csv.push_str(&csv_row(name, shape, "virtual", &o));
            csv.push('\n');
            if i == 0 && matches!(point.varied, "baseline" | "K") {
                gain_traces.push(Series {
                    label: format!("K = {:.2} Λ_max", point.gain_over_lambda),
                    points: o.true_trace.clone(),
                    style: SeriesStyle::Line,
                });
            }
        }
    }
    if args.wall_clock {
        tokio::time::resume();
        let (name, bytes, config, calibrated) = &models[0];
        let shape = (config.preprocess.size_px, config.width, config.latent);
        let point = Point {
            varied: "wall-clock",
            gain_over_lambda: 0.75,
            tolerance_n: 0.1,
            fps: 120.0,
        };
        let predictor = softtouch_trainer::Predictor::from_bytes(bytes)?;
        let o = run_point(&setup, predictor, point, calibrated)
            .await
            .map_err(grasp_failure)?;
        print_row(out, name, shape, &o)?;
        csv.push_str(&csv_row(name, shape, "wall", &o));
        csv.push('\n');
        writeln!(
            out,
            "wall clock at 120 Hz: {} cycles at {:.1} Hz, {} frames skipped, {} of {} handled later than one period (8.33 ms) after exposure (exposure → estimate median {:.2} ms, max {:.2} ms): {}",
            o.cycles,
            o.cycle_rate_hz,
            o.skipped_frames,
            o.late_frames,
            o.cycles,
            o.lateness_ms.0,
            o.lateness_ms.1,
            if o.skipped_frames == 0 && o.late_frames == 0 {
                "held 120 Hz"
            } else {
                "did NOT hold 120 Hz"
            }
        )
        .map_err(w)?;
    }
    let csv_path = args.out.join("grasp-bench.csv");
    std::fs::write(&csv_path, csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", csv_path.display())))?;
    gain_traces.push(Series {
        label: "target".into(),
        points: vec![(0.0, args.target), (args.hold_s, args.target)],
        style: SeriesStyle::Line,
    });
    let png = args.out.join("grasp-bench.png");
    xy_chart(
        &png,
        &XyChart {
            title: "True grip force over K (baseline δ and rate)",
            x_label: "time from the first cycle (s)",
            y_label: "true grip force (N)",
            series: &gain_traces,
        },
        (900, 500),
    )
    .map_err(|e| Failure::Runtime(e.into()))?;
    writeln!(out, "wrote {} and {}", csv_path.display(), png.display()).map_err(w)?;
    let scene_hash =
        softtouch_lab::grasp::calibration::scene_setup_hash(&setup.scene, 120.0, args.seed).ok();
    crate::results::Recorder::new("bench grasp")
        .model(&args.model[0])
        .setting("models", args.model.clone())
        .setting("object", setup.object.name.as_str())
        .setting("target_n", args.target)
        .setting("hold_s", args.hold_s)
        .setting("gains_over_lambda", args.gains.clone())
        .setting("tolerances_n", args.tolerances.clone())
        .setting("fps", args.fps.clone())
        .setting("wall_clock", args.wall_clock)
        .setting("seed", args.seed)
        .setting(
            "scene",
            args.scene.as_ref().map(|p| p.display().to_string()),
        )
        .scene_hash(scene_hash)
        .table(&csv_path)
        .store(
            db,
            format!(
                "{} runs over K, δ and rate for {} model(s) on `{}` at {} N",
                points.len(),
                models.len(),
                setup.object.name,
                args.target
            ),
            out,
        )
        .await
        .map(drop)
}

fn print_row(
    out: &mut dyn Write,
    name: &str,
    shape: (usize, usize, usize),
    o: &Outcome,
) -> Result<(), Failure> {
    let opt = |v: Option<f64>| v.map_or_else(|| "never".to_owned(), |s| format!("{s:.3}"));
    let e = o.estimate;
    let t = o.truth;
    writeln!(
        out,
        "{:<14} {:<12} {:<9} {:>6.2} {:>6.2} {:>5.0} {:>7.1} {:>9} {:>9} {:>10} {:>10} {:>12} {:>12}",
        name,
        format!("{}px/w{}/z{}", shape.0, shape.1, shape.2),
        o.point.varied,
        o.point.gain_over_lambda,
        o.point.tolerance_n,
        o.point.fps,
        o.cycle_rate_hz,
        format!("{}/{}", o.late_frames, o.skipped_frames),
        opt(e.and_then(|m| m.settling_time_s)),
        e.map_or_else(|| "-".into(), |m| format!("{:.3}", m.overshoot_n)),
        e.map_or_else(|| "-".into(), |m| format!("{:+.3}", m.steady_state_error_n)),
        opt(t.and_then(|m| m.settling_time_s)),
        t.map_or_else(|| "-".into(), |m| format!("{:+.3}", m.steady_state_error_n)),
    )
    .map_err(io_failure)
}
