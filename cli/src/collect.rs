//! `softtouch collect` and `softtouch status`.

use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::Args;
use softtouch_collector::collect::{
    CollectPlan, NewRunRequest, Outcome, PlanError, Resumed, abandon, build_run_devices, collect,
};
use softtouch_store::SyncStore;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `softtouch collect`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:
  softtouch collect --samples 200 --seed 1          # simulated rig, on-land scene
  softtouch collect --scene scenes/water.toml --samples 30000
  softtouch collect --rig lab-rig.toml --scene rods.toml --rods circle-10 --samples 5000
  softtouch collect --scene scenes/water.toml --poses-from 1   # run 1's poses, underwater
  softtouch collect --resume 3                      # continue run 3 where it stopped
  softtouch collect --resume 3 --rig lab-rig.toml   # ... with the F/T box on a new port

Ctrl-C, SIGTERM or SIGHUP finishes the current sample, retreats and exits 0 (resume later
with --resume); a second one stops the arm at once, wherever it is. A run being collected
is leased to its process: a second `collect --resume` of it is refused while that process
lives. A log is written beside the database (DB.log).")]
pub struct CollectArgs {
    /// Rig config (default: the embedded all-simulated rig). With --resume: the run's
    /// rig with devices reached elsewhere (addresses, ports, device paths may differ
    /// from the stored rig, nothing else); default the stored rig.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Scene (default: the embedded on-land scene).
    #[arg(long, conflicts_with = "resume")]
    pub scene: Option<PathBuf>,
    /// Samples to take (at least 1).
    #[arg(
        long,
        required_unless_present_any = ["resume", "poses_from"],
        conflicts_with_all = ["resume", "poses_from"],
        // `-1` is a value to refuse by this flag's name, not an unknown flag.
        allow_negative_numbers = true,
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub samples: Option<u64>,
    /// Seed of the pose sampler and the simulation (default: from the clock; printed
    /// and stored with the run).
    #[arg(long, conflicts_with_all = ["resume", "poses_from"])]
    pub seed: Option<u64>,
    /// Rods to use, in order, comma-separated (default: every rod of the scene).
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["resume", "poses_from"])]
    pub rods: Vec<String>,
    /// Samples per rod before changing to the next (default: an equal share each).
    #[arg(long, conflicts_with_all = ["resume", "poses_from"])]
    pub block: Option<u64>,
    /// Repeat run RUN's poses and rods (its seed, sample count and rod schedule) in
    /// this scene: the finger meets the same deformations, e.g. on land and underwater.
    /// The scene must have the same pose ranges and rods; the finished run is checked
    /// against RUN pose by pose.
    #[arg(long, value_name = "RUN", conflicts_with = "resume")]
    pub poses_from: Option<i64>,
    /// Continue run RUN at its next sample, with its stored seed, rig and scene (the
    /// database must exist).
    #[arg(long, value_name = "RUN")]
    pub resume: Option<i64>,
}

/// The new run `args` ask for.
fn new_run_request(args: &CollectArgs) -> NewRunRequest {
    NewRunRequest {
        rig: args.rig.clone(),
        scene: args.scene.clone(),
        samples: args.samples.unwrap_or(0),
        seed: args.seed,
        rods: args.rods.clone(),
        block: args.block,
        poses_from: args.poses_from,
    }
}

/// A planning error as a CLI failure: the exit code says whose fault it is.
fn plan_failure(e: PlanError) -> Failure {
    match e {
        // Unwrapped so the message and class are what these errors give everywhere.
        PlanError::Store(e) => e.into(),
        PlanError::Config(e) => e.into(),
        e if e.is_bad_input() => Failure::BadInput(e.into()),
        e => Failure::Runtime(e.into()),
    }
}

pub async fn run_collect(
    args: CollectArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if args.resume.is_some() && db.file().is_some_and(|path| !path.exists()) {
        // A mistyped --db would otherwise become a new, empty database.
        return Err(Failure::BadInput(anyhow!(
            "--resume: no database at {} (check --db; only a new run creates one)",
            db.display()
        )));
    }
    // A new run's request is checked before anything is said or the database opened:
    // a refused one leaves no new, empty database (nor its log) behind.
    if args.resume.is_none() {
        if let Some(source) = args.poses_from
            && db.file().is_some_and(|path| !path.exists())
        {
            return Err(Failure::BadInput(anyhow!(
                "--poses-from {source}: no database at {} (check --db)",
                db.display()
            )));
        }
        CollectPlan::check_new_run(&new_run_request(&args)).map_err(plan_failure)?;
    }
    // The disk a run takes is said, and checked, before anything is written. A request
    // the plan below refuses (a bad scene, a missing --poses-from run) is left to it.
    if args.resume.is_none()
        && let Ok(resolved) =
            softtouch_collector::configs::resolve(args.rig.as_deref(), args.scene.as_deref())
    {
        let samples = match args.poses_from {
            Some(source) => planned_samples(db, source).await?,
            None => args.samples.unwrap_or(0),
        };
        if samples > 0 {
            check_disk(db, &resolved.scene, samples, out).await?;
        }
    }
    let store = SyncStore::open(db)?;
    let plan = if let Some(run_id) = args.resume {
        match CollectPlan::resume_with_rig(&store, run_id, args.rig.as_deref())
            .map_err(plan_failure)?
        {
            Resumed::AlreadyComplete => {
                writeln!(out, "run {run_id} is already complete").map_err(io_failure)?;
                return Ok(());
            }
            Resumed::Plan(plan) => *plan,
        }
    } else {
        CollectPlan::new_run(&store, &new_run_request(&args)).map_err(plan_failure)?
    };

    let run_id = plan.run_id;
    if args.resume.is_some()
        && let Err(e) = check_disk(db, &plan.scene, plan.remaining(), out).await
    {
        store.close();
        return Err(e);
    }
    // A resumed run's clock continues the run's device time.
    let (devices, clock) = match build_run_devices(&store, &plan).await {
        Ok(built) => built,
        Err(e) => {
            // No empty `running` run is left behind: the run says why it never started.
            let reason = abandon(&store, &plan, &format!("cannot set up the rig: {e}"));
            store.close();
            return Err(Failure::Runtime(anyhow!("{reason}").context(format!(
                "run {run_id}: failed before collecting (fix the cause, then --resume {run_id})"
            ))));
        }
    };
    writeln!(
        out,
        "run {run_id}: samples {}..{} of scene `{}` ({}), seed {}",
        plan.start_index, plan.end_index, plan.scene.name, plan.scene.medium, plan.seed
    )
    .map_err(io_failure)?;

    let (stop_tx, stop_rx) = tokio::sync::watch::channel(0u32);
    let signals = tokio::spawn(super::signals::count_stop_signals(stop_tx, "sample"));
    let mut progress = softtouch_collector::progress::collection_progress(plan.remaining());
    let started = Instant::now();
    let (outcome, counters) =
        collect(&store, &plan, devices, clock, stop_rx, progress.as_mut()).await;
    signals.abort();
    drop(progress);
    // Through the writer's own runtime: this one's clock may be paused (simulated rig).
    let paired = match outcome {
        Outcome::Completed => check_pairing(&store, run_id),
        _ => Ok(None),
    };
    store.close();
    let wall = started.elapsed().as_secs_f64();
    let summary = format!(
        "run {run_id}: {} ok, {} rejected, {} already present, {} retries, {} arm faults, {} frame timeouts in {wall:.1} s wall, {:.1} s on the rig's clock",
        counters.ok,
        counters.rejected,
        counters.already_present,
        counters.retries,
        counters.arm_faults,
        counters.frame_timeouts,
        softtouch_drivers::Clock::now(&clock).as_secs_f64()
    );
    // Where the time went, as stored with the run's events (`phase_times`).
    if counters.phases.samples > 0 {
        write!(out, "{}", counters.phases.table()).map_err(io_failure)?;
    }
    match outcome {
        Outcome::Completed => {
            writeln!(out, "{summary}; complete").map_err(io_failure)?;
            if let Some((source, pairs)) = paired? {
                writeln!(
                    out,
                    "run {run_id} pairs with run {source}: {pairs} samples in both, every rod and pose the same"
                )
                .map_err(io_failure)?;
            }
            Ok(())
        }
        Outcome::Stopped => {
            writeln!(out, "{summary}; stopped (resume with --resume {run_id})").map_err(io_failure)
        }
        Outcome::SafeStop { reason } => Err(Failure::Runtime(anyhow!("{reason}").context(
            format!("{summary}; safe stop (fix the cause, then --resume {run_id})"),
        ))),
    }
}

/// What the database at `db` holds, for the disk estimate of a run of `scene` (nothing
/// when there is no database yet).
async fn footprint(
    db: &softtouch_store::DbTarget,
    scene: &softtouch_schemas::SceneSpec,
) -> Result<softtouch_collector::collect::disk::Footprint, Failure> {
    if let Some(path) = db.file()
        && softtouch_store::sqlite_file::inspect(path)?
            != softtouch_store::sqlite_file::DbFile::Sqlite
    {
        return Ok(softtouch_collector::collect::disk::Footprint::default());
    }
    let store = softtouch_store::Store::open_existing(db).await?;
    let held = async {
        Ok::<_, softtouch_store::StoreError>(softtouch_collector::collect::disk::Footprint {
            samples: store.stored_samples().await?,
            total_bytes: store.database_bytes().await?,
            frames: store.frame_bytes(None).await?,
            scene_frames: store.frame_bytes(Some(&scene.name)).await?,
        })
    }
    .await;
    store.close().await;
    Ok(held?)
}

/// The samples a `--poses-from` run will take: its source's plan (0 when the source is
/// not there: the plan says so).
async fn planned_samples(db: &softtouch_store::DbTarget, source: i64) -> Result<u64, Failure> {
    if db.file().is_some_and(|path| !path.is_file()) {
        return Ok(0);
    }
    let store = softtouch_store::Store::open_existing(db).await?;
    let record = store.run_record(source).await;
    store.close().await;
    Ok(record.map_or(0, |r| u64::try_from(r.samples_planned).unwrap_or(0)))
}

/// Says what the run will take on disk and refuses one that would not fit (on a
/// server, says it: its disk is its administrator's to watch).
async fn check_disk(
    db: &softtouch_store::DbTarget,
    scene: &softtouch_schemas::SceneSpec,
    samples: u64,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    use softtouch_collector::collect::disk;
    let held = footprint(db, scene).await?;
    let per_sample = disk::sample_bytes(&held, scene).map_err(|e| Failure::Runtime(anyhow!(e)))?;
    let disk = disk::DiskPlan::new(db.file(), per_sample, samples)?;
    if !disk.fits() {
        return Err(Failure::Runtime(anyhow!(
            "not enough disk for {samples} samples beside {}: {}; free some space, collect fewer (--samples) or use a database elsewhere (--db)",
            db.display(),
            disk.describe()
        )));
    }
    writeln!(out, "disk: {}", disk.describe()).map_err(io_failure)
}

/// A run made with `--poses-from` is checked against its source pose by pose once it
/// is complete (and after a completed resume): `(source, pairs)`, or `None` for a run
/// with poses of its own.
fn check_pairing(store: &SyncStore, run_id: i64) -> Result<Option<(i64, u64)>, Failure> {
    let Some(source) = store.run_record(run_id)?.poses_from else {
        return Ok(None);
    };
    Ok(Some((source, store.check_paired_poses(run_id, source)?)))
}

pub async fn run_status(
    db: &softtouch_store::DbTarget,
    run: Option<i64>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let runs = store.runs().await?;
    let stored = store.stored_samples().await?;
    let human = softtouch_collector::collect::disk::human_bytes;
    let (total, parts) = match db.file() {
        Some(path) => {
            let size = softtouch_store::sqlite_file::db_size(path);
            (
                size.total(),
                format!(
                    " ({} file + {} write-ahead log)",
                    human(size.file_bytes),
                    human(size.wal_bytes)
                ),
            )
        }
        None => (store.database_bytes().await?, " on the server".to_owned()),
    };
    let mut text = format!(
        "database {}: {}{parts}, {stored} samples{}\n",
        db.display(),
        human(total),
        softtouch_collector::collect::disk::bytes_per_sample(total, stored)
            .map_or_else(String::new, |b| format!(", {} a sample", human(b)))
    );
    let mut any = false;
    for r in runs.iter().filter(|r| run.is_none_or(|id| id == r.run_id)) {
        any = true;
        let done = r.ok + r.rejected;
        let per_h = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |v| format!("{v:.0}"));
        let rate = format!(
            "ok samples/h: {} run clock (first frame to last), {} wall clock (start to last update)",
            per_h(r.ok_per_run_clock_hour()),
            per_h(r.ok_per_wall_hour())
        );
        text.push_str(&format!(
            "run {} [{}] scene {} ({}): {done}/{} samples, {} ok, {} rejected, {} retries, {} faults; {rate}; updated {}\n",
            r.run_id, r.status, r.scene_name, r.medium, r.samples_planned, r.ok, r.rejected, r.retried, r.faults, r.updated_at
        ));
        if run.is_some() {
            // JSON, so that every name reads back exactly (commas, quotes, blanks). A
            // damaged schedule is shown as such: the rest of the status still helps.
            match store.run_record(r.run_id).await {
                Ok(record) => text.push_str(&format!(
                    "    rods {}, {} samples each{}\n",
                    serde_json::to_string(&record.rod_schedule).unwrap_or_default(),
                    record.rod_block,
                    record
                        .poses_from
                        .map_or_else(String::new, |s| format!("; poses and rods of run {s}"))
                )),
                Err(e @ softtouch_store::StoreError::Damaged { .. }) => {
                    text.push_str(&format!("    rods: {e}\n"));
                }
                Err(e) => return Err(e.into()),
            }
        }
        let limit = if run.is_some() { 20 } else { 3 };
        for e in store.events(r.run_id, limit).await? {
            let at = e
                .sample_index
                .map(|i| format!(" sample {i}"))
                .unwrap_or_default();
            text.push_str(&format!(
                "    {} {:<5} {}{at}: {}\n",
                e.created_at, e.level, e.kind, e.message
            ));
        }
    }
    store.close().await;
    if let Some(id) = run
        && !any
    {
        return Err(Failure::BadInput(anyhow!(
            "no run {id} in {}",
            db.display()
        )));
    }
    if !any {
        text = format!("no runs in {}\n", db.display());
    }
    out.write_all(text.as_bytes()).map_err(io_failure)
}
