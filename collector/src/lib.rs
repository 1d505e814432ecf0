//! The library a lab's verbs call (collection, datasets, experiments, the report) and
//! the `softtouch` CLI; the one crate that names both real and simulated devices.
//!
//! # Layout
//! - [`store`]: the store crate (`softtouch-store`, the only one with SQL), re-exported
//!   so its paths read `crate::store`.
//! - [`collect`]: the collection job (planning a new or resumed run, building the
//!   devices, pose sampler, per-sample procedure, force/torque stream and windows,
//!   faults and retries, the collection benchmark).
//! - [`dataset`]: named datasets over runs (filters, seeded splits), statistics,
//!   export to files Python reads, import of an export or the paper's layout.
//! - [`models`]: the bridge to the trainer: a dataset's splits as training examples,
//!   trained models stored with their metrics.
//! - [`experiments`]: Table 1, the latent sweep and the model benchmark: grids, rows,
//!   CSV and plots, shared by the verbs and reports.
//! - [`devices`]: a rig of boxed devices from the rig config, each real or simulated;
//!   the one place that names both.
//! - [`grasp`]: the grasp experiments as a library (settings in, rows out, their own
//!   errors): Figure 5's `follow`, `disturb`, `twist` on the loop `soft` makes ready,
//!   Figure 4's `trials`, `bench`; the simulated soft grasp behind the grasp
//!   library's traits (`sim`), a real Hand-E and finger cameras (`devices`), one
//!   validation per setting (`settings`).
//! - [`transfer`]: land to water: a dataset's test split alone, and the water test
//!   samples paired with land samples of the same pose (`collect --poses-from`).
//! - [`configs`]: resolving the rig and scene from files or the embedded defaults.
//! - [`plot`]: PNG histograms, x–y, bar and two-panel charts (plotters).
//! - [`finetune`], [`latent`]: the fine-tuning curve and the latent figures.
//! - [`live`]: `softtouch live`'s session, the estimate beside the sensor during a
//!   scripted press.
//! - [`rig_check`]: `rig check`'s device checks, a typed result per device.
//! - [`report`]: `softtouch report`, one self-contained HTML page (inline SVG, maud
//!   templates) of runs, datasets, models and sweeps, read from a read-only database.
//! - `progress`: the progress bar and the per-epoch training lines.
//! - [`stop`]: a stop request as a session's loop hears it (the CLI's signal watch
//!   sends it).
//! - [`synthetic`]: synthetic samples and windows (`bench ingest`, tests, examples).
//! - `testing` (the `testing` feature, on in tests and examples): test fixtures;
//!   `store_tests` runs the store's round trips on them.
//! - [`cli`]: the `softtouch` command line (clap): one file per verb group, each only
//!   parsing, calling the library and printing; exit codes.
//!
//! `src/main.rs` only parses arguments, sets up logging and calls [`cli::run`].

pub mod cli;
pub mod collect;
pub mod configs;
pub mod dataset;
pub mod devices;
pub mod experiments;
pub mod finetune;
pub mod grasp;
pub mod latent;
pub mod live;
pub mod models;
pub mod plot;
pub(crate) mod progress;
pub mod report;
pub mod rig_check;
/// The store is its own crate; `crate::store` keeps its paths.
pub use softtouch_store as store;
pub mod stop;
#[cfg(test)]
mod store_tests;
pub mod synthetic;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod transfer;
