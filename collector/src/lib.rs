//! The softtouch collector: the store, config resolution and the `softtouch` CLI.
//!
//! # Layout
//! - [`store`]: SQLite through sqlx (runs, samples, frames, force/torque windows,
//!   events), one transaction per sample.
//! - [`collect`]: the collection job (pose sampler, per-sample procedure, force/torque
//!   stream and windows, faults and retries).
//! - [`configs`]: resolving the rig and scene from files or the embedded defaults.
//! - [`cli`]: the `softtouch` command line (clap), its verbs and exit codes.
//!
//! `src/main.rs` only parses arguments, sets up logging and calls [`cli::run`].

pub mod cli;
pub mod collect;
pub mod configs;
pub mod dataset;
pub mod models;
pub mod plot;
pub mod store;
