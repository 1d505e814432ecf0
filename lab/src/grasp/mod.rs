//! Grasping experiments on a soft-finger Hand-E, as a library the verbs call.
//!
//! - [`sim`]: the simulated soft grasp behind the grasp library's traits (judge, lift,
//!   wrist, the recorded truth) and the simulator's measured stiffness.
//! - [`calibration`]: the stiffness calibration from the model's own estimate that
//!   every verb takes K = 0.75 Λ_max and its pre-grasp opening from (stored, reused
//!   when the setup, model and object match).
//! - [`devices`]: a real Hand-E and the finger cameras from the rig config, end
//!   calibration, force following on a rig.
//! - [`settings`]: each setting's one validation (rate, δ, durations, fingers), shared
//!   by every verb that takes it.
//! - [`soft`]: Algorithm 1 made ready on the simulated soft grasp (Λ_max measured, K
//!   chosen, the fingers approached), shared by [`follow`], [`disturb`] and [`twist`],
//!   Figure 5's force following, disturbance and twist.
//! - [`trials`]: the success-rate trials of Figure 4: sessions, trials run and stored
//!   one at a time, the table with Wilson intervals, its CSVs and charts; on the
//!   simulated soft grasp, and on a lab's rig ([`trials::rig`]: the arm at the rig
//!   file's grasp poses, the operator in the loop, a safe exit on every path).
//! - [`bench`](mod@bench): `softtouch bench grasp`, the force loop measured over K, δ, camera rate
//!   and model on the simulated soft grasp.
//!
//! Nothing here parses arguments; the verbs under `cli/` do, and print.

pub mod bench;
pub mod calibration;
pub mod devices;
pub mod disturb;
pub mod follow;
pub mod settings;
pub mod sim;
pub mod soft;
pub mod tare;
pub mod trials;
pub mod twist;
