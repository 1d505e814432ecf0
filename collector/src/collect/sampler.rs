//! Contact poses and the rod schedule of a run.
//!
//! Pose `i` of a run is a pure function of `(seed, i)`: its own ChaCha stream, so a
//! resumed or replayed run takes exactly the same poses in any order.

use rand::SeedableRng as _;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution as _, Uniform};
use softtouch_schemas::scene::PoseRanges;
use softtouch_schemas::{ContactPose, Range};

/// Draws the contact pose of each sample (Method S1: uniform over the ranges).
#[derive(Debug, Clone)]
pub struct PoseSampler {
    seed: u64,
    ranges: PoseRanges,
}

impl PoseSampler {
    /// A sampler over `ranges` for a run seeded by `seed`.
    #[must_use]
    pub fn new(seed: u64, ranges: PoseRanges) -> Self {
        Self { seed, ranges }
    }

    /// Pose `index` of the run.
    #[must_use]
    pub fn pose(&self, index: u64) -> ContactPose {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(index);
        let mut draw = |r: &Range| match Uniform::new_inclusive(r.min, r.max) {
            Ok(u) => u.sample(&mut rng),
            // Only for a range validation would have refused (NaN, reversed); the
            // lower bound is then as good a pose as any and stays inside a valid box.
            Err(_) => r.min,
        };
        ContactPose {
            x_m: draw(&self.ranges.x_m),
            z_m: draw(&self.ranges.z_m),
            theta_rad: draw(&self.ranges.theta_rad),
        }
    }
}

/// Which rod each sample uses: the rods in turn, `block` samples each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RodSchedule {
    rods: Vec<String>,
    block: u64,
}

impl RodSchedule {
    /// A schedule; `None` if there is no rod or the block is zero.
    #[must_use]
    pub fn new(rods: Vec<String>, block: u64) -> Option<Self> {
        (!rods.is_empty() && block > 0).then_some(Self { rods, block })
    }

    /// The rod of sample `index`.
    #[must_use]
    pub fn rod_for(&self, index: u64) -> &str {
        let n = self.rods.len() as u64; // non-empty by construction
        let i = (index / self.block) % n;
        self.rods
            .get(usize::try_from(i).unwrap_or(0))
            .map_or("", String::as_str)
    }

    /// The rods, in order.
    #[must_use]
    pub fn rods(&self) -> &[String] {
        &self.rods
    }

    /// Samples per block.
    #[must_use]
    pub fn block(&self) -> u64 {
        self.block
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use softtouch_schemas::defaults;

    #[test]
    fn a_pose_depends_only_on_seed_and_index() {
        let s = PoseSampler::new(7, defaults::scene().poses);
        let forward: Vec<_> = (0..50).map(|i| s.pose(i)).collect();
        let backward: Vec<_> = (0..50).rev().map(|i| s.pose(i)).collect();
        assert!(forward.iter().eq(backward.iter().rev()));
        assert_ne!(s.pose(0), s.pose(1));
        assert_ne!(
            s.pose(0),
            PoseSampler::new(8, defaults::scene().poses).pose(0)
        );
    }

    #[test]
    fn a_degenerate_range_gives_its_single_value() {
        let mut ranges = defaults::scene().poses;
        ranges.z_m = Range::new(0.01, 0.01);
        assert!((PoseSampler::new(1, ranges).pose(3).z_m - 0.01).abs() < 1e-15);
    }

    #[test]
    fn rods_come_in_blocks_and_wrap_around() {
        let s =
            RodSchedule::new(vec!["a".into(), "b".into()], 3).unwrap_or_else(|| panic!("valid"));
        let rods: Vec<_> = (0..8).map(|i| s.rod_for(i)).collect();
        assert_eq!(rods, ["a", "a", "a", "b", "b", "b", "a", "a"]);
        assert!(RodSchedule::new(vec![], 3).is_none());
        assert!(RodSchedule::new(vec!["a".into()], 0).is_none());
    }

    proptest! {
        #[test]
        fn every_sampled_pose_lies_in_the_scene_ranges(seed in any::<u64>(), index in any::<u64>()) {
            let ranges = defaults::scene().poses;
            let p = PoseSampler::new(seed, ranges.clone()).pose(index);
            prop_assert!(ranges.x_m.contains(p.x_m) && ranges.z_m.contains(p.z_m) && ranges.theta_rad.contains(p.theta_rad));
        }
    }
}
