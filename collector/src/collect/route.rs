//! The order a rod's block of samples is visited in, and where the arm waits between
//! two samples.
//!
//! Pose `i` stays a pure function of `(seed, i)` ([`PoseSampler`]); only the order in
//! which a block's poses are taken is planned. A block is a rod's run of indices
//! ([`RodSchedule`]). The plan sorts the block's poses into bands of θ and sweeps z
//! back and forth within each band, so consecutive samples differ by a small turn of
//! the wrist and a few millimetres of z, where index order asks for turns of up to a
//! full turn (at a Panda's 0.5 rad/s, seconds a sample). The plan is a pure function
//! of the seed, the scene's pose ranges and the block; its fingerprint is stored with
//! the run (a `visit_plan` event), and a resumed run visits what it lacks in the same
//! order.
//!
//! Between samples the arm waits at the *retreat point* of the pose just taken: the
//! same z and θ with x at home's (which the rig declares clear of the rod), so a
//! sample's travel is out along x, across to the next retreat point, and in.

use super::sampler::{PoseSampler, RodSchedule};
use sha2::{Digest as _, Sha256};
use softtouch_schemas::ContactPose;
use softtouch_schemas::rig::VisitOrder;
use softtouch_schemas::scene::PoseRanges;
use std::collections::BTreeSet;
use std::ops::Range;

/// The speed and turn rate the plan weighs a move's z against its θ with (the travel
/// at the default speed and an FR3's default rotation): only the bands' width depends
/// on them, never a pose.
const PLAN_SPEED_M_S: f64 = 0.5;
const PLAN_TURN_RAD_S: f64 = 0.75;

/// The planned order of the indices `block` (a rod's block), sampled by `sampler`.
///
/// Bands of θ as wide as balances a band's mean turn (a third of its width) against
/// its mean step in z (the z range over the band's share of the samples):
/// `√(n · Δθ · v / (3 · Δz · ω))` bands of `n` samples. Within a band z rises, in the
/// next it falls; ties go by θ, then index. A permutation of `block`, the same for the same
/// seed, ranges and block.
#[must_use]
pub fn plan_block(sampler: &PoseSampler, ranges: &PoseRanges, block: Range<u64>) -> Vec<u64> {
    let n = block.end.saturating_sub(block.start);
    if n <= 1 {
        return block.collect();
    }
    let theta_span = ranges.theta_rad.max - ranges.theta_rad.min;
    let z_span = ranges.z_m.max - ranges.z_m.min;
    let bands = if !(theta_span.is_finite() && theta_span > 0.0) {
        1
    } else if !(z_span.is_finite() && z_span > 0.0) {
        n
    } else {
        let b = (n as f64 * theta_span * PLAN_SPEED_M_S / (3.0 * z_span * PLAN_TURN_RAD_S))
            .sqrt()
            .round();
        (b as u64).clamp(1, n)
    };
    let band_of = |p: &ContactPose| -> u64 {
        if bands == 1 {
            return 0;
        }
        let u = (p.theta_rad - ranges.theta_rad.min) / theta_span;
        // NaN (never from a valid range) lands in band 0.
        ((u * bands as f64).floor().max(0.0) as u64).min(bands - 1)
    };
    let mut keyed: Vec<(u64, f64, f64, u64)> = block
        .map(|i| {
            let p = sampler.pose(i);
            let band = band_of(&p);
            // z rises in even bands and falls in odd ones.
            let z = if band % 2 == 0 { p.z_m } else { -p.z_m };
            (band, z, p.theta_rad, i)
        })
        .collect();
    // Equal z (a single-valued range) goes by θ, then by index.
    keyed.sort_by(|a, b| {
        a.0.cmp(&b.0)
            .then(a.1.total_cmp(&b.1))
            .then(a.2.total_cmp(&b.2))
            .then(a.3.cmp(&b.3))
    });
    keyed.into_iter().map(|k| k.3).collect()
}

/// The indices of `block` in the order `order` visits them.
#[must_use]
pub fn block_order(
    order: VisitOrder,
    sampler: &PoseSampler,
    ranges: &PoseRanges,
    block: Range<u64>,
) -> Vec<u64> {
    match order {
        VisitOrder::Planned => plan_block(sampler, ranges, block),
        VisitOrder::Index => block.collect(),
    }
}

/// One rod's block of a run, as visited.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockVisit {
    /// The block's indices (a rod's share of the run).
    pub block: Range<u64>,
    /// The whole block in visiting order (what the fingerprint covers).
    pub order: Vec<u64>,
    /// The indices of it still to take, in that order.
    pub todo: Vec<u64>,
}

impl BlockVisit {
    /// The order's fingerprint: the first 16 hex digits of the SHA-256 of its indices
    /// (little-endian u64s).
    #[must_use]
    pub fn fingerprint(&self) -> String {
        let mut h = Sha256::new();
        for i in &self.order {
            h.update(i.to_le_bytes());
        }
        h.finalize()
            .iter()
            .take(8)
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// The index visited before `index` in the whole block's order (`None`: `index`
    /// comes first, or is not in the block).
    #[must_use]
    pub fn before(&self, index: u64) -> Option<u64> {
        let at = self.order.iter().position(|&i| i == index)?;
        at.checked_sub(1).map(|k| self.order[k])
    }
}

/// The blocks of `wanted` (indices below `end` of a run whose rods follow `rods`), in
/// block order, each with its indices in `order`'s order: a new run's whole plan, or
/// what a resumed run lacks in the order the uninterrupted run would have taken it.
#[must_use]
pub fn visits(
    order: VisitOrder,
    sampler: &PoseSampler,
    ranges: &PoseRanges,
    rods: &RodSchedule,
    end: u64,
    wanted: impl IntoIterator<Item = u64>,
) -> Vec<BlockVisit> {
    let wanted: BTreeSet<u64> = wanted.into_iter().filter(|&i| i < end).collect();
    let size = rods.block().max(1);
    let mut out: Vec<BlockVisit> = Vec::new();
    let mut next = wanted.first().copied();
    while let Some(first) = next {
        let start = first - first % size;
        let block = start..start.saturating_add(size).min(end);
        let order = block_order(order, sampler, ranges, block.clone());
        let todo = order
            .iter()
            .copied()
            .filter(|i| wanted.contains(i))
            .collect();
        next = wanted.range(block.end..).next().copied();
        out.push(BlockVisit { block, order, todo });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use softtouch_schemas::defaults;

    fn sampler(seed: u64) -> (PoseSampler, PoseRanges) {
        let ranges = defaults::scene().poses;
        (PoseSampler::new(seed, ranges.clone()), ranges)
    }

    /// The largest wrist turn and z step between consecutive poses of `order`.
    fn steps(s: &PoseSampler, order: &[u64]) -> (f64, f64) {
        let poses: Vec<_> = order.iter().map(|&i| s.pose(i)).collect();
        poses.windows(2).fold((0.0f64, 0.0f64), |(t, z), w| {
            (
                t.max((w[1].theta_rad - w[0].theta_rad).abs()),
                z.max((w[1].z_m - w[0].z_m).abs()),
            )
        })
    }

    #[test]
    fn a_plan_turns_the_wrist_far_less_than_index_order() {
        let (s, r) = sampler(11);
        let planned = plan_block(&s, &r, 0..1000);
        let index: Vec<u64> = (0..1000).collect();
        let mean_turn = |o: &[u64]| {
            o.windows(2)
                .map(|w| (s.pose(w[1]).theta_rad - s.pose(w[0]).theta_rad).abs())
                .sum::<f64>()
                / (o.len() - 1) as f64
        };
        // Index order: a third of the 2π range a step on average; planned: a
        // fraction of a band's width (2π / 118 bands).
        assert!(mean_turn(&index) > 1.5, "{}", mean_turn(&index));
        assert!(mean_turn(&planned) < 0.06, "{}", mean_turn(&planned));
        // No step turns more than two bands' width.
        let (turn, z) = steps(&s, &planned);
        assert!(turn < 2.0 * std::f64::consts::TAU / 118.0, "{turn}");
        assert!(z <= 0.1 + 1e-12, "{z}");
    }

    #[test]
    fn degenerate_ranges_and_tiny_blocks_still_give_a_permutation() {
        let (s, mut r) = sampler(3);
        assert_eq!(plan_block(&s, &r, 5..5), Vec::<u64>::new());
        assert_eq!(plan_block(&s, &r, 5..6), vec![5]);
        r.theta_rad = softtouch_schemas::Range::new(0.2, 0.2);
        let s1 = PoseSampler::new(3, r.clone());
        let mut o = plan_block(&s1, &r, 0..50);
        o.sort_unstable();
        assert_eq!(o, (0..50).collect::<Vec<_>>());
        r = defaults::scene().poses;
        r.z_m = softtouch_schemas::Range::new(0.01, 0.01);
        let s2 = PoseSampler::new(3, r.clone());
        let o = plan_block(&s2, &r, 0..50);
        // One pose per band: sorted by θ.
        let thetas: Vec<f64> = o.iter().map(|&i| s2.pose(i).theta_rad).collect();
        assert!(thetas.windows(2).all(|w| w[0] <= w[1]), "{thetas:?}");
    }

    #[test]
    fn a_resumed_run_takes_what_it_lacks_in_the_plans_order() {
        let (s, r) = sampler(5);
        let rods =
            RodSchedule::new(vec!["a".into(), "b".into()], 40).unwrap_or_else(|| panic!("valid"));
        let all = visits(VisitOrder::Planned, &s, &r, &rods, 100, 0..100);
        assert_eq!(
            all.iter().map(|v| v.block.clone()).collect::<Vec<_>>(),
            vec![0..40, 40..80, 80..100]
        );
        // Killed after 25 samples of the second block, with one write lost in the first.
        let taken: BTreeSet<u64> = all[0]
            .order
            .iter()
            .copied()
            .filter(|&i| i != 7)
            .chain(all[1].order[..25].iter().copied())
            .collect();
        let rest = visits(
            VisitOrder::Planned,
            &s,
            &r,
            &rods,
            100,
            (0..100).filter(|i| !taken.contains(i)),
        );
        assert_eq!(rest[0].todo, vec![7]);
        assert_eq!(rest[1].todo, all[1].order[25..].to_vec());
        assert_eq!(rest[1].before(rest[1].todo[0]), Some(all[1].order[24]));
        assert_eq!(rest[2].todo, all[2].order);
        assert_eq!(rest[1].fingerprint(), all[1].fingerprint());
        // Index order is plain.
        let plain = visits(VisitOrder::Index, &s, &r, &rods, 100, [3, 1, 50]);
        assert_eq!(plain[0].todo, vec![1, 3]);
        assert_eq!(plain[1].todo, vec![50]);
        assert_eq!(plain[1].before(50), Some(49));
        assert_eq!(plain[1].before(40), None);
    }

    proptest! {
        #[test]
        fn a_plan_is_a_deterministic_permutation_of_its_block(
            seed in any::<u64>(), start in 0u64..1_000_000, n in 0u64..300,
        ) {
            let (s, r) = sampler(seed);
            let o = plan_block(&s, &r, start..start + n);
            prop_assert_eq!(&o, &plan_block(&s, &r, start..start + n));
            let mut sorted = o.clone();
            sorted.sort_unstable();
            prop_assert_eq!(sorted, (start..start + n).collect::<Vec<_>>());
        }
    }
}
