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
use softtouch_schemas::config::{ConfigError, ConfigSource, parse_toml, to_toml};
use softtouch_schemas::{RigConfig, SceneSpec};
use std::path::PathBuf;

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
    /// Neither the request nor the scene names a rod.
    #[error("no rods to use")]
    NoRods,
    /// A stored run whose rod schedule is empty: the store is damaged.
    #[error("run {0} has no rod schedule")]
    NoRodSchedule(RunId),
}

impl PlanError {
    /// Whether the caller's input is at fault (a bad request, file or run id) rather
    /// than the store.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        match self {
            Self::Store(e) => matches!(e, StoreError::NoSuchRun(_)),
            Self::Config(_) | Self::UnknownRod { .. } | Self::ZeroBlock | Self::NoRods => true,
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
        let samples = request.samples;
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
            None => samples.div_ceil(rods.len() as u64).max(1),
        };
        let schedule = RodSchedule::new(rods, block).ok_or(PlanError::NoRods)?;
        let seed = request.seed.unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64)
        });
        let run_id = store.create_run(OwnedNewRun {
            seed,
            samples_planned: samples,
            rod_schedule: schedule.rods().to_vec(),
            rod_block: schedule.block(),
            scene_name: resolved.scene.name.clone(),
            medium: resolved.scene.medium,
            rig_toml: to_toml(&resolved.rig),
            scene_toml: to_toml(&resolved.scene),
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
        let record = store.run_record(run_id)?;
        let end = u64::try_from(record.samples_planned).unwrap_or(0);
        let missing = store.missing_indices(run_id, end)?;
        if record.status == RunStatus::Completed.as_str() && missing.is_empty() {
            return Ok(Resumed::AlreadyComplete);
        }
        let rig: RigConfig = parse_toml(
            &record.rig_toml,
            &ConfigSource::Stored(format!("run {run_id} rig")),
        )?;
        let scene: SceneSpec = parse_toml(
            &record.scene_toml,
            &ConfigSource::Stored(format!("run {run_id} scene")),
        )?;
        let rods: Vec<String> = record.rod_schedule.split(',').map(str::to_owned).collect();
        let schedule = RodSchedule::new(rods, u64::try_from(record.rod_block).unwrap_or(1))
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
        store.set_run_status(run_id, RunStatus::Running)?;
        let first = gaps.first().copied().unwrap_or(start);
        store.log_event(
            run_id,
            Some(first),
            None,
            EventLevel::Info,
            EventKind::Resumed.as_str(),
            &format!(
                "resumed at sample {start}, after {} missing earlier samples",
                gaps.len()
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
