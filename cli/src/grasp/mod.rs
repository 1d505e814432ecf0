//! `softtouch grasp follow|disturb|twist|trials|calibrate`: the grasp experiments of
//! Figures 4 and 5 on the simulated Hand-E with soft fingers (and on a rig), closed by a
//! stored model's estimate. One file per verb, each checking its flags, calling its
//! experiment in [`softtouch_lab::grasp`] and printing its table (the experiment writes
//! the CSV and the chart); `setup.rs` holds the loop's options and steps they share.

use std::io::Write;

use clap::Subcommand;

use crate::Failure;

mod calibrate;
mod disturb;
mod follow;
mod setup;
mod trials;
mod twist;

pub use calibrate::CalibrateArgs;
pub use disturb::DisturbArgs;
pub use follow::FollowArgs;
pub use setup::LoopArgs;
pub use trials::TrialsArgs;
pub use twist::TwistArgs;

/// The grasp experiments.
#[derive(Debug, Subcommand)]
pub enum GraspCommand {
    /// Hold each target force in turn on the simulated soft-finger Hand-E, the model's
    /// estimate closing the loop (Algorithm 1); prints rise time, settling time,
    /// overshoot, steady-state and RMS error per target; writes a CSV and a PNG.
    #[command(
        after_help = "Example:\n  softtouch grasp follow --model land-v1-svae --targets 0.4,1.6,3\n  softtouch grasp follow --model land-v1-svae --scene scenes/grasp.toml --object ball --fingers 2\n  softtouch grasp follow --model land-v1-svae --rig lab.toml --object bottle --targets 0.4,1.6   # a real Hand-E, K from its calibration"
    )]
    Follow(FollowArgs),
    /// Hold 0.4 N on land or 1.6 N in water (the scene's medium) on an oval tube while
    /// the simulator turns it about its axis by 45°, then 60°, then −90°; prints per
    /// turn the peak deviation, the recovery time to within δ and the RMS error;
    /// writes `grasp-disturb.csv` and `grasp-disturb.png`.
    #[command(
        after_help = "Example:\n  softtouch grasp disturb --model land-v1-svae\n  softtouch grasp disturb --model water-v1-svae --scene scenes/grasp-water.toml --fingers 2"
    )]
    Disturb(DisturbArgs),
    /// Hold a grip force on a cylinder that the simulator turns about the fingers'
    /// axis, and hold the torque τz ≈ 0 by turning the wrist on the model's τz
    /// estimate; runs with and without the wrist loop and prints the τz RMS of both;
    /// writes `grasp-twist.csv` and `grasp-twist.png`.
    #[command(
        after_help = "Example:\n  softtouch grasp twist --model land-v1-svae\n  softtouch grasp twist --model land-v1-svae --turn-deg 30 --wrist-gain 1000\n  softtouch grasp twist --model land-v1-svae --rig lab.toml --object bottle --duration-s 15   # the real wrist"
    )]
    Twist(TwistArgs),
    /// Grasp success-rate trials (Figure 4): per object, mode (open, closed) and medium
    /// (one scene each; default land and water), `--trials` grasps with the grasp point
    /// perturbed by N(0, σ²) per axis, lift and hold; the physics decides held, slip,
    /// crush, miss or timeout. Each trial is stored as it ends; `--resume SESSION`
    /// continues. Prints success rates with Wilson 95 % intervals beside the paper's;
    /// writes `grasp-trials.csv`, `grasp-trials-rows.csv` and `grasp-trials.png`.
    /// With `--rig FILE` the trials run on the rig's Franka, Hand-E and finger camera
    /// at the grasp poses of its `[grasp]` section, K from each object's stored
    /// `grasp calibrate --rig`; the rig judges (gOBJ, position, estimate) and the
    /// operator confirms each verdict and each return of the object to its place.
    #[command(after_help = "Example:
  softtouch grasp trials --model land-v1-svae --trials 10 --sigma-mm 5 --modes open,closed
  softtouch grasp trials --model land-v1-svae --rig lab.toml --objects bottle,ball --trials 10
  softtouch grasp trials --rig lab.toml --resume 4
  softtouch grasp trials --model land-v1-svae --objects cake,ball --scene scenes/grasp.toml
  softtouch grasp trials --resume 3
  softtouch grasp trials --model land-v1-svae --sweep-sigma 0,2,5,8,12 --trials 5")]
    Trials(TrialsArgs),
    /// Calibrate an object's stiffness from the model's own estimate: close on it one
    /// count at a time, fit Λ(P) = ΔF_est/ΔP (Theil–Sen over 7-count windows), report
    /// the first touch and Λ_max with its spread, and store it. `follow`, `disturb`,
    /// `twist`, `trials` and `bench grasp` take K = 0.75 Λ_max and the pre-grasp
    /// opening from the latest matching calibration (making one when none matches);
    /// on the simulator the true Λ_max is printed beside it as a check.
    #[command(after_help = "Example:
  softtouch grasp calibrate --model land-v1-svae --scene scenes/grasp.toml --object bottle
  softtouch grasp calibrate --model land-v1-svae --rig lab.toml --object bottle   # a real Hand-E")]
    Calibrate(CalibrateArgs),
}

/// Run a grasp verb.
pub async fn run(
    cmd: GraspCommand,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    match cmd {
        GraspCommand::Follow(args) => follow::run(args, db, out).await,
        GraspCommand::Disturb(args) => disturb::run(args, db, out).await,
        GraspCommand::Twist(args) => twist::run(args, db, out).await,
        GraspCommand::Trials(args) => trials::run(args, db, out).await,
        GraspCommand::Calibrate(args) => calibrate::run(args, db, out).await,
    }
}
