//! Grasp success-rate trials (the paper's Figure 4) on the simulated soft-finger
//! Hand-E, open loop against closed loop, per object and medium, each trial stored as
//! it ends (one transaction) so a session resumes where it stopped.
//!
//! A session's plan ([`TrialPlan`]) is its objects, modes, trial count, σ list and loop
//! settings, stored as JSON with the session beside its model (name and artifact
//! sha256), scenes (one per medium) and seed; trial `i` of an object is a pure function
//! of `(seed, object, i)` and σ, so it replays alone. [`start_session`] or
//! [`resume_session`], then [`run_trials`]; [`table::summarise`] gives the stored rows
//! per object, mode, medium and σ with Wilson 95 % intervals, and
//! [`table::write_outputs`] the CSVs and charts; [`experiment::run`] carries out a
//! whole `grasp trials` request, printing [`text`]'s tables. Nothing here parses
//! arguments.

pub mod cap;
pub mod experiment;
pub mod rig;
mod run;
pub mod table;
pub mod text;

pub use run::{RunEnd, TrialDone, TrialTiming, pack_trace, run_trials};

use serde::{Deserialize, Serialize};
use softtouch_drivers::gripper::STROKE_MM;
use softtouch_grasp::{GraspError, LiftPlan, Mode};
use softtouch_schemas::config::{ConfigSource, parse_toml};
use softtouch_schemas::overrides::{self, Override, Sweep};
use softtouch_schemas::{ConfigError, Medium, SceneSpec};
use softtouch_sim::GraspObject;

use super::settings::{self, Setting, SettingError};
use crate::models::ModelError;
use crate::store::{GraspTrialKey, Store, StoreError};
use softtouch_collector::dataset::export::sha256_hex;

/// The built-in scenes: on land and underwater, five objects each.
use softtouch_schemas::defaults::{
    GRASP_SCENE_TOML as LAND_TOML, GRASP_WATER_SCENE_TOML as WATER_TOML,
};

mod plan;
mod scenes;
mod session;

pub use plan::*;
pub use scenes::*;
pub use session::*;
/// The grasp-point perturbation σ of the paper's success rates, mm (Figure 4): its
/// rates are shown beside this σ's rows only.
pub const PAPER_SIGMA_MM: f64 = 5.0;

/// The paper's overall success rates (Figure 4, σ = [`PAPER_SIGMA_MM`]): (medium, mode)
/// → rate.
#[must_use]
pub fn paper_rate(medium: Medium, mode: Mode) -> f64 {
    match (medium, mode) {
        (Medium::Air, Mode::Open) => 0.44,
        (Medium::Air, Mode::Closed) => 1.0,
        (Medium::Water, Mode::Open) => 0.30,
        (Medium::Water, Mode::Closed) => 0.90,
    }
}

/// A σ as the charts label it: the paper's is marked, `σ 5 mm (paper)`.
#[must_use]
pub fn sigma_label(sigma_mm: f64) -> String {
    if (sigma_mm - PAPER_SIGMA_MM).abs() < 1e-9 {
        format!("σ {sigma_mm} mm (paper)")
    } else {
        format!("σ {sigma_mm} mm")
    }
}

/// A medium as the tables name it.
#[must_use]
pub fn medium_name(m: Medium) -> &'static str {
    match m {
        Medium::Air => "land",
        Medium::Water => "water",
    }
}

/// What can go wrong in a trial session.
#[derive(Debug, thiserror::Error)]
pub enum TrialsError {
    /// The request cannot work (an unknown object, a session that is not there, a
    /// model changed under its name); the message says what is expected.
    #[error("{0}")]
    Invalid(String),
    /// A setting outside its range.
    #[error(transparent)]
    Setting(#[from] SettingError),
    /// A scene file that does not read.
    #[error(transparent)]
    Scene(#[from] ConfigError),
    /// The model could not be found or loaded.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The database failed (boxed: a store error is several times larger than the
    /// other variants).
    #[error(transparent)]
    Store(Box<StoreError>),
    /// The loop or the simulated grasp failed.
    #[error(transparent)]
    Grasp(#[from] GraspError),
    /// Something failed while running (a stored session that does not read back, a
    /// trial's thread, an output file).
    #[error("{0}")]
    Failed(String),
    /// A second stop request ended the run at once; the trial in hand is not stored.
    #[error("stopped at once by a second stop request; the trial in hand was not stored")]
    Interrupted,
}

impl TrialsError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Invalid(_) | Self::Setting(_) | Self::Scene(_) => true,
            Self::Model(e) => e.is_bad_input(),
            Self::Store(e) if matches!(**e, StoreError::NoSuchRun(_)) => true,
            Self::Grasp(GraspError::Config(_) | GraspError::UnreachableTarget { .. }) => true,
            Self::Store(_) | Self::Grasp(_) | Self::Failed(_) | Self::Interrupted => false,
        }
    }
}

impl From<StoreError> for TrialsError {
    fn from(e: StoreError) -> Self {
        Self::Store(Box::new(e))
    }
}

pub(crate) fn invalid(m: String) -> TrialsError {
    TrialsError::Invalid(m)
}

impl From<crate::grasp::soft::GraspRunError> for TrialsError {
    fn from(e: crate::grasp::soft::GraspRunError) -> Self {
        use crate::grasp::soft::GraspRunError as E;
        match e {
            E::Invalid(m) => Self::Invalid(m),
            E::Grasp(e) => Self::Grasp(e),
            E::Model(e) => Self::Model(e),
            e => Self::Failed(e.to_string()),
        }
    }
}

impl From<softtouch_trainer::TrainError> for TrialsError {
    fn from(e: softtouch_trainer::TrainError) -> Self {
        Self::Model(e.into())
    }
}

#[cfg(test)]
mod tests;
