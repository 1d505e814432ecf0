//! The experiments a lab runs on a collected dataset and a trained model, and the
//! report that shows them: settings in, rows and runs out, each with its own error.
//! It must not depend on the command line (`softtouch-cli`, no clap) and names no
//! simulator outside the grasp adapters (`grasp::sim`) and its tests.
//!
//! # Layout
//! - [`models`]: the bridge to the trainer: a dataset's splits as training examples,
//!   trained models stored with their metrics.
//! - [`experiments`]: Table 1, the latent sweep and the model benchmark: grids, rows,
//!   CSV and plots, shared by the verbs and reports.
//! - [`grasp`]: the grasp experiments (settings in, rows out, their own errors):
//!   Figure 5's `follow`, `disturb`, `twist` on the loop `soft` makes ready, Figure 4's
//!   `trials`, `bench`; the simulated soft grasp behind the grasp library's traits
//!   (`sim`), a real Hand-E and finger cameras (`devices`), one validation per setting
//!   (`settings`).
//! - [`transfer`]: land to water: a dataset's test split alone, and the water test
//!   samples paired with land samples of the same pose (`collect --poses-from`).
//! - [`finetune`], [`latent`]: the fine-tuning curve and the latent figures.
//! - [`live`]: `softtouch live`'s session, the estimate beside the sensor during a
//!   scripted press.
//! - [`rig_check`]: `rig check`'s device checks, a typed result per device.
//! - [`report`]: `softtouch report`, one self-contained HTML page (inline SVG, maud
//!   templates) of runs, datasets, models and sweeps, read from a read-only database.

pub mod bench_train;
pub mod experiments;
pub mod finetune;
pub mod grasp;
pub mod host;
pub mod latent;
pub mod live;
pub mod models;
pub mod report;
pub mod rig_check;
/// The store crate, so that paths read `crate::store` as in the collector.
pub use softtouch_store as store;
pub mod transfer;
