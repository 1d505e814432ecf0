//! `softtouch grasp trials`: parses the flags into one
//! [`TrialsRequest`](softtouch_lab::grasp::trials::experiment::TrialsRequest) and hands
//! it to [`softtouch_lab::grasp::trials::experiment::run`], which runs the simulated or
//! rig session (new or resumed, one model or several) and prints its tables.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::setup::bad;
use crate::{Failure, open_existing};
use softtouch_lab::grasp::trials::TrialPlan;
use softtouch_lab::grasp::trials::experiment::{self, Terminal, TrialsRequest};
use softtouch_lab::grasp::trials::rig::Operator;
use softtouch_schemas::overrides::{Override, Sweep};

/// Options of `grasp trials`.
#[derive(Debug, Clone, Args)]
pub struct TrialsArgs {
    /// Stored model whose estimate closes the loop (and is recorded in open loop).
    #[arg(long, required_unless_present_any = ["resume", "models"])]
    pub model: Option<String>,
    /// Several stored models (comma-separated, e.g. three training seeds): the same
    /// trials (same plan, seed and perturbations) for each, one session each (its
    /// files under --out-dir/MODEL), then the spread of the success rates across them.
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["model", "resume", "rig"])]
    pub models: Vec<String>,
    /// Scene file, one per medium (repeat the flag); default: the built-in land and
    /// water scenes (`scenes/grasp.toml`, `scenes/grasp-water.toml`).
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Objects (`[[objects]]` names, comma-separated); default: every object of the
    /// first scene.
    #[arg(long, value_delimiter = ',')]
    pub objects: Vec<String>,
    /// Trials per object, mode, medium and σ.
    #[arg(long, default_value_t = 10)]
    pub trials: u32,
    /// σ of the grasp point's perturbation per axis, mm.
    #[arg(long, default_value_t = 5.0)]
    pub sigma_mm: f64,
    /// Run the trials at each of these σ, mm (comma-separated), and plot success
    /// against σ; replaces --sigma-mm.
    #[arg(long, value_delimiter = ',')]
    pub sweep_sigma: Vec<f64>,
    /// Set one value of every scene that has it for this session, validated as the
    /// file is (repeatable): `--set objects.bottle.wet_friction=0.2`,
    /// `--set effects.object_flow.mean_m_s=0.1`. Lists of tables are entered by an
    /// entry's name, kind or index. The session stores the scenes as set.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub set: Vec<Override>,
    /// Run the same trials (same perturbations) at each value of one scene value, and
    /// print, store and plot success against it: `--sweep
    /// objects.bottle.wet_friction=0.05,0.1,0.2`. `--sweep sigma_mm=0,2,5` sweeps the
    /// perturbation σ (as --sweep-sigma).
    #[arg(long, value_name = "PATH=V1,V2,…", conflicts_with = "sweep_sigma")]
    pub sweep: Option<Sweep>,
    /// Modes, comma-separated: open, closed.
    #[arg(long, value_delimiter = ',', default_value = "open,closed")]
    pub modes: Vec<String>,
    /// Seed of the perturbations and the simulated scenes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Continue a stored session (its settings are the stored ones, so the settings'
    /// flags are refused beside it; --out-dir may change).
    #[arg(
        long,
        conflicts_with_all = [
            "model", "scene", "objects", "trials", "sigma_mm", "sweep_sigma", "set", "sweep", "modes", "seed",
            "fps", "target_n", "tolerance", "confirm_s", "close_timeout_s", "lift_mm",
            "hold_s", "open_width_mm",
        ]
    )]
    pub resume: Option<i64>,
    /// Camera rate, Hz (one control cycle per frame).
    #[arg(long, default_value_t = 120.0)]
    pub fps: f64,
    /// Closed loop: the grip force F_ref, N.
    #[arg(long, default_value_t = 1.5)]
    pub target_n: f64,
    /// Closed loop: the tolerance δ, N.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Closed loop: how long |F_ref − F_est| ≤ δ must hold before the lift, s.
    #[arg(long, default_value_t = 0.25)]
    pub confirm_s: f64,
    /// Closed loop: how long the loop may take to confirm, s.
    #[arg(long, default_value_t = 4.0)]
    pub close_timeout_s: f64,
    /// How high the object is lifted, mm.
    #[arg(long, default_value_t = 50.0)]
    pub lift_mm: f64,
    /// How long it is held after the lift, s.
    #[arg(long, default_value_t = 2.0)]
    pub hold_s: f64,
    /// Open loop: close every object to this opening, mm, instead of its predefined
    /// gripping width.
    #[arg(long)]
    pub open_width_mm: Option<f64>,
    /// Rig file: run the trials on its real arm, Hand-E and finger camera at the grasp
    /// poses, widths, lifts and set-down places of its `[grasp]` section (the scene
    /// flags do not apply). With --resume: the rig of the stored session.
    #[arg(long, conflicts_with_all = ["scene", "open_width_mm", "lift_mm", "set", "sweep"])]
    pub rig: Option<PathBuf>,
    /// On a rig: take the rig judge's verdict without asking the operator (the
    /// operator still confirms each return of the object to its place).
    #[arg(long, requires = "rig")]
    pub no_confirm: bool,
    /// Use stiffness calibrations their check refuses (`softtouch grasp calibrate`),
    /// each refusal said in the session's header: for a model known to under-read (a
    /// land model in water before its image tare). The squeeze bound still limits
    /// every closed loop.
    #[arg(long, conflicts_with = "resume")]
    pub accept_calibration: bool,
    /// Read each water scene's frames through an image tare: at the session's start,
    /// rest frames of the finger camera (gripper open, nothing held) are matched to
    /// the rest frames of the model's dataset (scale, gain and offset per channel, a
    /// gain map; no water label). Stored with the session and said in its header:
    /// `grasp trials --model land-aug4 --scene scenes/grasp-water.toml --tare`.
    #[arg(long, conflicts_with_all = ["resume", "rig"])]
    pub tare: bool,
    /// Folder for `grasp-trials.csv`, `grasp-trials-rows.csv`, `grasp-trials.png`,
    /// with --sweep-sigma `grasp-trials-sigma.png`, and with --sweep
    /// `grasp-trials-sweep.csv` and `grasp-trials-sweep.png`.
    #[arg(long, default_value = "grasp-out")]
    pub out_dir: PathBuf,
}

impl TrialsArgs {
    /// The σ of the session: --sweep-sigma, --sweep sigma_mm=…, or --sigma-mm.
    fn sigmas_mm(&self) -> Result<Vec<f64>, Failure> {
        match &self.sweep {
            Some(s) if s.path == "sigma_mm" => s
                .values
                .iter()
                .map(|v| {
                    v.as_float()
                        .or_else(|| v.as_integer().map(|i| i as f64))
                        .ok_or_else(|| {
                            bad(format!(
                                "--sweep sigma_mm: `{}` is not a number of mm",
                                softtouch_schemas::overrides::shown(v)
                            ))
                        })
                })
                .collect(),
            _ if !self.sweep_sigma.is_empty() => Ok(self.sweep_sigma.clone()),
            _ => Ok(vec![self.sigma_mm]),
        }
    }

    /// The request the flags make (its settings are checked when a session starts).
    fn request(self) -> Result<TrialsRequest, Failure> {
        let plan = TrialPlan {
            objects: self.objects.clone(),
            modes: self.modes.clone(),
            trials: self.trials,
            sigmas_mm: self.sigmas_mm()?,
            fps: self.fps,
            target_n: self.target_n,
            tolerance_n: self.tolerance,
            confirm_s: self.confirm_s,
            close_timeout_s: self.close_timeout_s,
            lift_mm: self.lift_mm,
            hold_s: self.hold_s,
            open_width_mm: self.open_width_mm,
            accept_calibration: self.accept_calibration,
            tare: self.tare,
            ..TrialPlan::default()
        };
        Ok(TrialsRequest {
            model: self.model,
            models: self.models,
            resume: self.resume,
            plan,
            seed: self.seed,
            scenes: self.scene,
            sets: self.set,
            // σ is the plan's own list; any other path is a scene value.
            sweep: self.sweep.filter(|s| s.path != "sigma_mm"),
            rig: self.rig,
            out_dir: self.out_dir,
        })
    }
}

/// The operator at this terminal: answers on stdin, questions on stderr.
pub(super) fn terminal_operator(confirm_verdicts: bool) -> Operator {
    Operator {
        input: softtouch_grasp::OperatorInput::from_reader(std::io::BufReader::new(
            std::io::stdin(),
        )),
        output: Box::new(std::io::stderr()),
        confirm_verdicts,
    }
}

/// Run `grasp trials`.
pub(super) async fn run(
    args: TrialsArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let operator = terminal_operator(!args.no_confirm);
    let request = args.request()?;
    let store = open_existing(db).await?;
    // The first Ctrl-C, SIGTERM or SIGHUP finishes the trial in hand (or the session's
    // start and calibrations, then none) and ends with the summary of what ran (exit
    // 0); a second stops at once. Watched from the moment the store is open, before
    // anything is stored, so that no signal kills the verb with the database open.
    let (stop_tx, stop) = tokio::sync::watch::channel(0u32);
    let signals = tokio::spawn(crate::signals::count_stop_signals(stop_tx, "trial"));
    let mut terminal = Terminal {
        out,
        stop,
        operator,
    };
    let ran = experiment::run(&request, &store, &mut terminal).await;
    signals.abort();
    // Closed (the log checkpointed into the file) on every path.
    store.close().await;
    Ok(ran?)
}
