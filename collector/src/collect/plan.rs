//! What to collect: a new run from configs and choices, or the rest of a stored run.
//!
//! Planning writes to the store (a new run's row; a resumed run's status and a
//! `resumed` event), so a plan always names a run that exists.

use super::sampler::RodSchedule;
use crate::configs;
use crate::store::{
    EventKind, EventLevel, LeaseHolder, LeaseTaken, OwnedNewRun, RunId, RunStatus, StoreError,
    SyncStore,
};
use softtouch_schemas::config::{Check, ConfigError, ConfigSource, parse_toml, to_toml};
use softtouch_schemas::{RigConfig, SceneSpec};
use std::path::{Path, PathBuf};

/// What to collect.
#[derive(Debug, Clone)]
pub struct CollectPlan {
    /// The run the samples belong to (already in the store).
    pub run_id: RunId,
    /// The run's seed.
    pub seed: u64,
    /// Index of the first sample to take (0, or where a resumed run left off).
    pub start_index: u64,
    /// One past the last index.
    pub end_index: u64,
    /// Indices below `start_index` missing from the store (a write that failed, a
    /// sample cut off by a forced stop), taken first.
    pub gaps: Vec<u64>,
    /// The run's lease, held by this job (`None`: a private run nobody else can see,
    /// as a benchmark's).
    pub lease: Option<LeaseHolder>,
    /// Rods in blocks.
    pub rods: RodSchedule,
    /// The rig.
    pub rig: RigConfig,
    /// The scene.
    pub scene: SceneSpec,
}

/// The choices for a new run; `None` and empty mean the defaults.
#[derive(Debug, Clone, Default)]
pub struct NewRunRequest {
    /// Rig config file (default: the embedded all-simulated rig).
    pub rig: Option<PathBuf>,
    /// Scene file (default: the embedded on-land scene).
    pub scene: Option<PathBuf>,
    /// Samples to take.
    pub samples: u64,
    /// Seed (default: from the clock).
    pub seed: Option<u64>,
    /// Rods in order (default: every rod of the scene).
    pub rods: Vec<String>,
    /// Samples per rod before the next (default: an equal share each).
    pub block: Option<u64>,
    /// Repeat this stored run's poses and rods (its seed, sample count and rod
    /// schedule), in this request's scene: paired deformations, e.g. land and water.
    /// `samples`, `seed`, `rods` and `block` must then be left unset.
    pub poses_from: Option<RunId>,
}

/// What resuming a run found.
#[derive(Debug, Clone)]
pub enum Resumed {
    /// Every planned sample is already stored: nothing to do, nothing changed.
    AlreadyComplete,
    /// The rest of the run, now marked running. (Boxed: the other variant is empty.)
    Plan(Box<CollectPlan>),
}

/// Why a plan could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The store failed, or has no such run.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A rig or scene (a file, or the copy stored with a run) is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A requested rod is not in the scene. (The messages name the CLI's flags: the
    /// requests come from them.)
    #[error("--rods: no rod `{rod}` in scene {scene} (it has: {available})")]
    UnknownRod {
        /// The rod asked for.
        rod: String,
        /// Where the scene came from.
        scene: String,
        /// The scene's rods, comma-separated.
        available: String,
    },
    /// A block of 0 samples per rod.
    #[error("--block: expected at least 1 sample per rod")]
    ZeroBlock,
    /// A new run of 0 samples (it would be stored as complete, holding nothing).
    #[error("--samples: expected at least 1 sample")]
    ZeroSamples,
    /// Neither the request nor the scene names a rod.
    #[error("no rods to use")]
    NoRods,
    /// A stored run whose rod schedule is empty: the store is damaged.
    #[error("run {0} has no rod schedule")]
    NoRodSchedule(RunId),
    /// `--poses-from`: the scene cannot repeat the source run's poses.
    #[error("--poses-from {from_run}: {why}")]
    Unpairable {
        /// The run whose poses were asked for.
        from_run: RunId,
        /// What differs.
        why: String,
    },
}

impl PlanError {
    /// Whether the caller's input is at fault (a bad request, file or run id) rather
    /// than the store.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        match self {
            Self::Store(e) => matches!(e, StoreError::NoSuchRun(_)),
            Self::Config(_)
            | Self::UnknownRod { .. }
            | Self::ZeroBlock
            | Self::ZeroSamples
            | Self::NoRods
            | Self::Unpairable { .. } => true,
            Self::NoRodSchedule(_) => false,
        }
    }
}

impl CollectPlan {
    /// Samples left to take.
    #[must_use]
    pub fn remaining(&self) -> u64 {
        self.gaps.len() as u64 + self.end_index.saturating_sub(self.start_index)
    }

    /// The indices to take, in order: the gaps, then `start_index..end_index`.
    pub fn indices(&self) -> impl Iterator<Item = u64> + '_ {
        self.gaps
            .iter()
            .copied()
            .chain(self.start_index..self.end_index)
    }

    /// Resolve the configs, check the request against the scene and create the run.
    ///
    /// # Errors
    /// A bad config or request, checked before the run is created; or the store.
    pub fn new_run(store: &SyncStore, request: &NewRunRequest) -> Result<Self, PlanError> {
        let resolved = configs::resolve(request.rig.as_deref(), request.scene.as_deref())?;
        if let Some(source) = request.poses_from {
            return Self::paired_run(store, request, resolved, source);
        }
        let (rods, block) = Self::schedule_of(request, &resolved)?;
        let schedule = RodSchedule::new(rods, block).ok_or(PlanError::NoRods)?;
        let seed = request.seed.unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64)
        });
        Self::create(store, resolved, seed, request.samples, schedule, None)
    }

    /// What [`CollectPlan::new_run`] checks before it needs the store (the configs, the
    /// rods, the block), so that a refused request creates no database. A request
    /// repeating another run's poses needs that run: it is checked by `new_run`.
    ///
    /// # Errors
    /// As `new_run`'s own checks.
    pub fn check_new_run(request: &NewRunRequest) -> Result<(), PlanError> {
        let resolved = configs::resolve(request.rig.as_deref(), request.scene.as_deref())?;
        if request.poses_from.is_none() {
            let (rods, block) = Self::schedule_of(request, &resolved)?;
            RodSchedule::new(rods, block).ok_or(PlanError::NoRods)?;
        }
        Ok(())
    }

    /// The rods (the request's, each in the scene, or all of the scene's) and the block.
    fn schedule_of(
        request: &NewRunRequest,
        resolved: &configs::Resolved,
    ) -> Result<(Vec<String>, u64), PlanError> {
        let samples = request.samples;
        if samples == 0 {
            return Err(PlanError::ZeroSamples);
        }
        let scene_rods = || resolved.scene.rods.iter().map(|r| r.name.as_str());
        let rods: Vec<String> = if request.rods.is_empty() {
            scene_rods().map(str::to_owned).collect()
        } else {
            if let Some(rod) = request
                .rods
                .iter()
                .find(|r| resolved.scene.rod(r).is_none())
            {
                return Err(PlanError::UnknownRod {
                    rod: rod.clone(),
                    scene: resolved.scene_source.to_string(),
                    available: scene_rods().collect::<Vec<_>>().join(", "),
                });
            }
            request.rods.clone()
        };
        let block = match request.block {
            Some(0) => return Err(PlanError::ZeroBlock),
            Some(b) => b,
            None => samples.div_ceil(rods.len().max(1) as u64).max(1),
        };
        Ok((rods, block))
    }

    /// A new run repeating run `source`'s poses and rods in the request's scene. Pose
    /// `i` is a pure function of the seed and the scene's pose ranges, so the same
    /// seed and ranges give the same poses; the rods must be the same shapes.
    fn paired_run(
        store: &SyncStore,
        request: &NewRunRequest,
        resolved: configs::Resolved,
        source: RunId,
    ) -> Result<Self, PlanError> {
        let unpairable = |why: String| PlanError::Unpairable {
            from_run: source,
            why,
        };
        if request.seed.is_some() || !request.rods.is_empty() || request.block.is_some() {
            return Err(unpairable(
                "the seed, rods and block come from that run: leave --seed, --rods and --block out"
                    .into(),
            ));
        }
        let record = store.run_record(source)?;
        let source_scene: SceneSpec = parse_toml(
            &record.scene_toml,
            &ConfigSource::Stored(format!("run {source} scene")),
        )?;
        if resolved.scene.poses != source_scene.poses {
            return Err(unpairable(format!(
                "scene {} samples poses over {:?}, run {source}'s scene over {:?}: expected the same ranges",
                resolved.scene_source, resolved.scene.poses, source_scene.poses
            )));
        }
        for name in &record.rod_schedule {
            let theirs = source_scene.rod(name);
            match resolved.scene.rod(name) {
                Some(ours) if Some(ours) == theirs => {}
                Some(ours) => {
                    return Err(unpairable(format!(
                        "rod `{name}` is {ours:?} in scene {}, {theirs:?} in run {source}'s scene: expected the same rod",
                        resolved.scene_source
                    )));
                }
                None => {
                    return Err(unpairable(format!(
                        "scene {} has no rod `{name}`, which run {source} used",
                        resolved.scene_source
                    )));
                }
            }
        }
        let samples = u64::try_from(record.samples_planned).unwrap_or(0);
        if request.samples != 0 && request.samples != samples {
            return Err(unpairable(format!(
                "it planned {samples} samples, not {}: leave --samples out",
                request.samples
            )));
        }
        let schedule = RodSchedule::new(
            record.rod_schedule.clone(),
            u64::try_from(record.rod_block).unwrap_or(1),
        )
        .ok_or(PlanError::NoRodSchedule(source))?;
        Self::create(
            store,
            resolved,
            record.seed_u64(),
            samples,
            schedule,
            Some(source),
        )
    }

    fn create(
        store: &SyncStore,
        resolved: configs::Resolved,
        seed: u64,
        samples: u64,
        schedule: RodSchedule,
        poses_from: Option<RunId>,
    ) -> Result<Self, PlanError> {
        let run_id = store.create_run(OwnedNewRun {
            seed,
            samples_planned: samples,
            rod_schedule: schedule.rods().to_vec(),
            rod_block: schedule.block(),
            scene_name: resolved.scene.name.clone(),
            medium: resolved.scene.medium,
            rig_toml: to_toml(&resolved.rig),
            scene_toml: to_toml(&resolved.scene),
            poses_from,
        })?;
        // Nobody else knows the run yet: the lease is free.
        let lease = LeaseHolder::this_process();
        store.acquire_lease(run_id, &lease)?;
        Ok(Self {
            run_id,
            seed,
            start_index: 0,
            end_index: samples,
            gaps: Vec::new(),
            lease: Some(lease),
            rods: schedule,
            rig: resolved.rig,
            scene: resolved.scene,
        })
    }

    /// The rest of stored run `run_id`, with its stored seed, rig, scene and rods:
    /// every index below the planned count that the store lacks. Takes the run's lease
    /// (refused while another live process holds it; a stale one is taken over, with
    /// an event), marks the run running and logs a `resumed` event.
    ///
    /// # Errors
    /// No such run, a run leased by another process, a stored config that no longer
    /// parses, or the store.
    pub fn resume(store: &SyncStore, run_id: RunId) -> Result<Resumed, PlanError> {
        Self::resume_with_rig(store, run_id, None)
    }

    /// [`CollectPlan::resume`] on the rig in file `rig_file` (`None`: the run's stored rig).
    /// The file may differ from the stored rig only where a device is reached
    /// ([`CONNECTION_FIELDS`]: a moved serial port, a new address); it then becomes the
    /// run's stored rig, and the `resumed` event names what changed. Either way the
    /// run's scene is checked against the rig again, as for a new run.
    ///
    /// # Errors
    /// As [`CollectPlan::resume`]; a rig file that does not load, or that differs from
    /// the stored rig in any other field (the error names the field).
    pub fn resume_with_rig(
        store: &SyncStore,
        run_id: RunId,
        rig_file: Option<&Path>,
    ) -> Result<Resumed, PlanError> {
        let record = store.run_record(run_id)?;
        let end = u64::try_from(record.samples_planned).unwrap_or(0);
        let missing = store.missing_indices(run_id, end)?;
        if record.status == RunStatus::Completed.as_str() && missing.is_empty() {
            return Ok(Resumed::AlreadyComplete);
        }
        let stored_rig: RigConfig = parse_toml(
            &record.rig_toml,
            &ConfigSource::Stored(format!("run {run_id} rig")),
        )?;
        let scene: SceneSpec = parse_toml(
            &record.scene_toml,
            &ConfigSource::Stored(format!("run {run_id} scene")),
        )?;
        let (rig, rig_source, changed) = match rig_file {
            None => (
                stored_rig,
                ConfigSource::Stored(format!("run {run_id} rig")),
                Vec::new(),
            ),
            Some(path) => {
                let (rig, source) = configs::rig(Some(path))?;
                let changed = connection_changes(&stored_rig, &rig, run_id, &source)?;
                (rig, source, changed)
            }
        };
        // The checks may have grown since the run began: a scene the rig cannot take
        // is refused before the arm moves, as for a new run.
        let mut check = Check::default();
        scene.validate_against(&rig, &mut check);
        check.finish(&ConfigSource::Stored(format!(
            "run {run_id} scene, on rig {rig_source}"
        )))?;
        let schedule = RodSchedule::new(
            record.rod_schedule.clone(),
            u64::try_from(record.rod_block).unwrap_or(1),
        )
        .ok_or(PlanError::NoRodSchedule(run_id))?;
        let start = store.next_index(run_id)?.min(end);
        let gaps: Vec<u64> = missing.into_iter().filter(|&i| i < start).collect();
        let lease = LeaseHolder::this_process();
        // No rig clock yet: these events have no rig time.
        if let LeaseTaken::TakenOver { previous, why } = store.acquire_lease(run_id, &lease)? {
            store.log_event(
                run_id,
                None,
                None,
                EventLevel::Warn,
                EventKind::LeaseTakenOver.as_str(),
                &format!(
                    "took the lease over from {previous}: {why}; now process {} on host `{}`",
                    lease.pid, lease.host
                ),
            )?;
        }
        // Only the lease holder changes the run.
        if !changed.is_empty() {
            store.set_run_rig(run_id, &to_toml(&rig))?;
        }
        store.set_run_status(run_id, RunStatus::Running)?;
        let first = gaps.first().copied().unwrap_or(start);
        store.log_event(
            run_id,
            Some(first),
            None,
            EventLevel::Info,
            EventKind::Resumed.as_str(),
            &format!(
                "resumed at sample {start}, after {} missing earlier samples{}",
                gaps.len(),
                if changed.is_empty() {
                    String::new()
                } else {
                    format!("; rig {rig_source}: {}", changed.join(", "))
                }
            ),
        )?;
        Ok(Resumed::Plan(Box::new(Self {
            run_id,
            seed: record.seed_u64(),
            start_index: start,
            end_index: end,
            gaps,
            lease: Some(lease),
            rods: schedule,
            rig,
            scene,
        })))
    }
}

/// Fields of a rig that only say where a device is reached (dotted paths; a field
/// absent from a device's driver is skipped). A resume may change these and nothing
/// else: every other field shapes the samples (geometry, limits, timings, calibration,
/// latencies) or is a different device (`driver`).
pub const CONNECTION_FIELDS: [&str; 8] = [
    "arm.address",
    "force_sensor.address",
    "force_sensor.port",
    "force_sensor.baud",
    "camera.device",
    "second_camera.device",
    "gripper.port",
    "gripper.slave_id",
];

/// What `new` changes of `stored`'s connection fields (`field: old -> new`), or the
/// first other field that differs, as a config error naming `new`'s file.
fn connection_changes(
    stored: &RigConfig,
    new: &RigConfig,
    run_id: RunId,
    source: &ConfigSource,
) -> Result<Vec<String>, ConfigError> {
    let as_json = |rig: &RigConfig| serde_json::to_value(rig).unwrap_or(serde_json::Value::Null);
    let (mut old_v, mut new_v) = (as_json(stored), as_json(new));
    let mut changed = Vec::new();
    for field in CONNECTION_FIELDS {
        let (table, key) = field.split_once('.').unwrap_or((field, ""));
        let take = |v: &mut serde_json::Value| {
            v.get_mut(table)
                .and_then(serde_json::Value::as_object_mut)
                .and_then(|t| t.remove(key))
        };
        match (take(&mut old_v), take(&mut new_v)) {
            (Some(a), Some(b)) if a != b => changed.push(format!("{field}: {a} -> {b}")),
            _ => {}
        }
    }
    let mut check = Check::default();
    if let Some((field, old, new)) = first_difference("", &old_v, &new_v) {
        check.fail(
            field,
            format!(
                "differs from run {run_id}'s stored rig (stored {old}, here {new}); a resumed run keeps its rig except where a device is reached ({})",
                CONNECTION_FIELDS.join(", ")
            ),
        );
    }
    check.finish(source)?;
    Ok(changed)
}

/// The first path at which `a` and `b` differ, with both values (`absent` where one
/// has no such field).
fn first_difference(
    path: &str,
    a: &serde_json::Value,
    b: &serde_json::Value,
) -> Option<(String, String, String)> {
    use serde_json::Value;
    let join = |key: &str| {
        if path.is_empty() {
            key.to_owned()
        } else {
            format!("{path}.{key}")
        }
    };
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            // A different driver is a different device: say so before its fields.
            keys.sort_by_key(|k| (k.as_str() != "driver", k.as_str()));
            keys.dedup();
            keys.into_iter().find_map(|k| match (x.get(k), y.get(k)) {
                (Some(p), Some(q)) => first_difference(&join(k), p, q),
                (p, q) => {
                    let show =
                        |v: Option<&Value>| v.map_or_else(|| "absent".to_owned(), Value::to_string);
                    Some((join(k), show(p), show(q)))
                }
            })
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (p, q))| first_difference(&format!("{path}[{i}]"), p, q)),
        _ if a == b => None,
        _ => Some((path.to_owned(), a.to_string(), b.to_string())),
    }
}
