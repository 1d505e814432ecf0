//! The CLI's end-to-end tests: every file in this folder is a module of one test
//! binary, so the whole program is linked once, not once per file.
//!
//! One file's tests: `cargo test --release --test end_to_end -- collect::`.
//! The `#[ignore]`d tiers filter the same way (TESTING.md), for example the
//! franka-sim tier: `cargo test --release --test end_to_end -- --ignored
//! --test-threads=1 franka_sim::`.

mod common;
mod fcisim;
#[path = "../drivers/tests/common/pty.rs"]
mod pty;

mod cli;
mod collect;
mod dataset;
mod docs;
mod docs_walk;
mod faults;
mod franka_sim;
mod grasp;
mod grasp_rig_trials;
mod grasp_trials;
mod live;
mod postgres;
mod report;
mod resume;
mod train;
mod transfer;
