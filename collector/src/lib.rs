//! The collection job and the datasets it feeds, with what they share with the lab's
//! experiments (rig and scene configs, devices, plots, progress, stop requests); the
//! one crate that names both real and simulated devices. It must not depend on the
//! experiments (`softtouch-lab`) or the command line (`softtouch-cli`).
//!
//! # Layout
//! - [`store`]: the store crate (`softtouch-store`, the only one with SQL), re-exported
//!   so its paths read `crate::store`.
//! - [`collect`]: the collection job (planning a new or resumed run, building the
//!   devices, pose sampler, per-sample procedure, force/torque stream and windows,
//!   faults and retries, the collection benchmark).
//! - [`dataset`]: named datasets over runs (filters, seeded splits), statistics,
//!   export to files Python reads, import of an export or the paper's layout.
//! - [`devices`]: a rig of boxed devices from the rig config, each real or simulated;
//!   the one place that names both.
//! - [`configs`]: resolving the rig and scene from files or the embedded defaults.
//! - [`plot`]: charts drawn once for a PNG and for the report's SVG (plotters):
//!   histograms, x–y, bar and two-panel charts, their ticks and bounds.
//! - [`progress`]: the progress bar and the per-epoch training lines.
//! - [`stop`]: a stop request as a session's loop hears it (the CLI's signal watch
//!   sends it).
//! - [`synthetic`]: synthetic samples and windows (`bench ingest`, tests, examples).
//! - `testing` (the `testing` feature, on in tests and examples): test fixtures;
//!   `store_tests` runs the store's round trips on them.

pub mod collect;
pub mod configs;
pub mod dataset;
pub mod devices;
pub mod plot;
pub mod progress;
/// The store is its own crate; `crate::store` keeps its paths.
pub use softtouch_store as store;
pub mod stop;
#[cfg(test)]
mod store_tests;
pub mod synthetic;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
