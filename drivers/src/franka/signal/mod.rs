//! The driver's commanded signal judged on the robot's 1 ms clock: what it asked for,
//! not what a busy host let through.
//!
//! The robot judges a Cartesian pose stream by differencing it at 1 kHz, in Cartesian
//! space and in joint space through its inverse kinematics, and aborts a motion whose
//! velocity, acceleration or jerk breaks a limit. A lost cycle is extrapolated there,
//! so on a starved host the robot can read a jerk the driver never commanded. This
//! takes the commands the driver sent, each keyed by the state it answered (the
//! robot's clock), differences only runs of consecutive cycles (so no lost cycle is in
//! any difference), and holds each derivative against the robot's limits. The same
//! commands give the same verdict on a quiet host and a busy one.

use super::cartesian_limits;
use super::reach::{self, Kinematics, Robot};
use nalgebra::Vector3;
use softtouch_schemas::ArmPose;

/// The robot's control period, s.
pub const CYCLE_S: f64 = 0.001;

/// One command the driver sent.
#[derive(Debug, Clone, PartialEq)]
pub struct Commanded {
    /// The id of the robot state it answered: the robot's 1 ms clock.
    pub message_id: u64,
    /// The commanded end-effector pose (`O_T_EE_c`).
    pub pose: ArmPose,
    /// The measured joints when it arrived: the seed of the first joint solve of a run
    /// of consecutive cycles (`None`: the ready pose).
    pub q_measured: Option<[f64; 7]>,
    /// A joint-space motion's command: its joints (`q_c`), judged as they are; `pose`
    /// is then ignored and taken as their forward kinematics.
    pub q_commanded: Option<[f64; 7]>,
}

/// The largest value of one quantity over the signal, against its limit.
#[derive(Debug, Clone, PartialEq)]
pub struct Peak {
    /// What it is, with its unit ("translational jerk, m/s³", "joint 2 acceleration,
    /// rad/s²").
    pub what: String,
    /// Its largest magnitude (NaN when a value was not finite).
    pub value: f64,
    /// The robot's limit (for a joint's velocity: the limit at its position then, so
    /// `value / limit` is the share used).
    pub limit: f64,
    /// The command where it was largest.
    pub message_id: u64,
}

impl Peak {
    /// The share of its limit used (NaN is over).
    #[must_use]
    pub fn share(&self) -> f64 {
        self.value / self.limit
    }

    /// Whether it breaks its limit (or is not finite).
    #[must_use]
    pub fn over(&self) -> bool {
        self.value.is_nan() || self.value > self.limit
    }
}

/// What [`judge`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Commands judged.
    pub commands: usize,
    /// Runs of consecutive cycles (a gap: a cycle the driver did not answer).
    pub runs: usize,
    /// Each quantity's peak: Cartesian velocity, acceleration and jerk (translational
    /// and rotational), then each joint's.
    pub peaks: Vec<Peak>,
    /// Commanded poses whose joints could not be solved (out of reach, a singularity),
    /// by message id.
    pub unsolved: Vec<u64>,
}

impl Verdict {
    /// The peaks over their limits.
    #[must_use]
    pub fn over(&self) -> Vec<&Peak> {
        self.peaks.iter().filter(|p| p.over()).collect()
    }

    /// Whether every quantity is within its limit and every pose was solved.
    #[must_use]
    pub fn holds(&self) -> bool {
        self.unsolved.is_empty() && self.over().is_empty()
    }

    /// A table, a peak a line, the largest share first.
    #[must_use]
    pub fn table(&self) -> String {
        let mut peaks: Vec<&Peak> = self.peaks.iter().collect();
        peaks.sort_by(|a, b| b.share().total_cmp(&a.share()));
        let mut s = format!(
            "{} commands in {} runs of consecutive cycles{}\n",
            self.commands,
            self.runs,
            if self.unsolved.is_empty() {
                String::new()
            } else {
                format!(
                    "; {} poses with no joint solution (first at message {})",
                    self.unsolved.len(),
                    self.unsolved[0]
                )
            }
        );
        for p in peaks {
            s.push_str(&format!(
                "  {:<40} {:>12.4} of {:>10.4} ({:>5.1} %) at message {}{}\n",
                p.what,
                p.value,
                p.limit,
                p.share() * 100.0,
                p.message_id,
                if p.over() { "  OVER" } else { "" }
            ));
        }
        s
    }
}

/// Keeps the largest magnitude of one quantity.
struct Max {
    what: String,
    limit: f64,
    value: f64,
    share: f64,
    message_id: u64,
}

impl Max {
    fn new(what: String, limit: f64) -> Self {
        Self {
            what,
            limit,
            value: 0.0,
            share: 0.0,
            message_id: 0,
        }
    }

    /// `value` against `limit` (a position-dependent one: the largest share is kept).
    fn see(&mut self, value: f64, limit: f64, message_id: u64) {
        // A limit of zero (a joint at the end of its range) is over at any speed.
        let share = if limit > 0.0 {
            value / limit
        } else if value > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
        if share.is_nan() {
            if !self.share.is_nan() {
                (self.value, self.limit, self.share, self.message_id) =
                    (f64::NAN, limit, f64::NAN, message_id);
            }
            return;
        }
        if !self.share.is_nan() && share > self.share {
            (self.value, self.limit, self.share, self.message_id) =
                (value, limit, share, message_id);
        }
    }

    fn peak(self) -> Peak {
        Peak {
            what: self.what,
            value: self.value,
            limit: self.limit,
            message_id: self.message_id,
        }
    }
}

/// Backward differences of a run of samples on the 1 ms clock: (first, second, third)
/// derivative at each index where they exist.
fn differences<const N: usize>(x: &[[f64; N]]) -> [Vec<[f64; N]>; 3] {
    let diff = |v: &[[f64; N]]| -> Vec<[f64; N]> {
        v.windows(2)
            .map(|w| std::array::from_fn(|i| (w[1][i] - w[0][i]) / CYCLE_S))
            .collect()
    };
    let d1 = diff(x);
    let d2 = diff(&d1);
    let d3 = diff(&d2);
    [d1, d2, d3]
}

fn norm(v: &[f64; 3]) -> f64 {
    Vector3::from(*v).norm()
}

/// Joints of `pose` from `seed`, converged to machine precision: differenced three
/// times at 1 ms, a solve good to 1e-5 rad would read as 10⁴ rad/s³ of jerk.
fn solve_exact(kin: &Kinematics, pose: &ArmPose, seed: &[f64; 7]) -> Option<[f64; 7]> {
    let q = kin.solve(pose, seed)?;
    Some(kin.refine(pose, &q, 1e-13))
}

/// Judges `commands` (any order; a repeated message id keeps its first) against
/// `robot`'s Cartesian limits and, through `kin`, its joint limits.
#[must_use]
pub fn judge(commands: &[Commanded], robot: Robot, kin: &Kinematics) -> Verdict {
    // A joint command's pose is where its joints put the end effector.
    let owned: Vec<Commanded> = commands
        .iter()
        .map(|c| Commanded {
            pose: c.q_commanded.map_or(c.pose, |q| kin.pose(&q)),
            ..*c
        })
        .collect();
    let mut sorted: Vec<&Commanded> = owned.iter().collect();
    sorted.sort_by_key(|c| c.message_id);
    sorted.dedup_by_key(|c| c.message_id);
    let [v, a, j, rv, ra, rj] = cartesian_limits(robot);
    let cart = [
        ("translational velocity, m/s", v),
        ("translational acceleration, m/s²", a),
        ("translational jerk, m/s³", j),
        ("rotational velocity, rad/s", rv),
        ("rotational acceleration, rad/s²", ra),
        ("rotational jerk, rad/s³", rj),
    ];
    let mut cart_max: Vec<Max> = cart
        .iter()
        .map(|(what, limit)| Max::new((*what).into(), *limit))
        .collect();
    let (qa, qj) = reach::joint_rate_limits(robot);
    let (_, ready_v) = robot.velocity_limits(&reach::READY_Q);
    let mut joint_max: Vec<[Max; 3]> = (0..7)
        .map(|i| {
            [
                Max::new(format!("joint {} velocity, rad/s", i + 1), ready_v[i]),
                Max::new(format!("joint {} acceleration, rad/s²", i + 1), qa[i]),
                Max::new(format!("joint {} jerk, rad/s³", i + 1), qj[i]),
            ]
        })
        .collect();
    let mut unsolved = Vec::new();
    let mut runs = 0;
    let mut start = 0;
    while start < sorted.len() {
        let mut end = start + 1;
        while end < sorted.len() && sorted[end].message_id == sorted[end - 1].message_id + 1 {
            end += 1;
        }
        runs += 1;
        let run = &sorted[start..end];
        start = end;
        let ids: Vec<u64> = run.iter().map(|c| c.message_id).collect();
        // Cartesian: translation, and the rotation between consecutive poses.
        let p: Vec<[f64; 3]> = run.iter().map(|c| c.pose.translation_m).collect();
        let [dp, ddp, dddp] = differences(&p);
        for (k, d) in [dp, ddp, dddp].iter().enumerate() {
            let offset = k + 1;
            for (i, x) in d.iter().enumerate() {
                cart_max[k].see(norm(x), cart[k].1, ids[i + offset]);
            }
        }
        let w: Vec<[f64; 3]> = run
            .windows(2)
            .map(|c| {
                let r = reach::rotation_error(&c[1].pose, &c[0].pose) / CYCLE_S;
                [r[0], r[1], r[2]]
            })
            .collect();
        let [dw, ddw, _] = differences(&w);
        for (k, d) in [&w, &dw, &ddw].iter().enumerate() {
            let offset = k + 1;
            for (i, x) in d.iter().enumerate() {
                cart_max[3 + k].see(norm(x), cart[3 + k].1, ids[i + offset]);
            }
        }
        // Joints, each pose solved from the last (the first from the measured joints).
        let mut q: Vec<[f64; 7]> = Vec::with_capacity(run.len());
        let mut seed = run[0].q_measured.unwrap_or(reach::READY_Q);
        let mut solved = true;
        for c in run {
            let solved_q = c.q_commanded.or_else(|| solve_exact(kin, &c.pose, &seed));
            match solved_q {
                Some(x) => {
                    q.push(x);
                    seed = x;
                }
                None => {
                    unsolved.push(c.message_id);
                    solved = false;
                    break;
                }
            }
        }
        if !solved {
            continue;
        }
        let [dq, ddq, dddq] = differences(&q);
        for (i, x) in dq.iter().enumerate() {
            let at = &q[i + 1];
            let (lo, hi) = robot.velocity_limits(at);
            for (n, m) in joint_max.iter_mut().enumerate() {
                let limit = if x[n] < 0.0 { -lo[n] } else { hi[n] };
                m[0].see(x[n].abs(), limit, ids[i + 1]);
            }
        }
        for (k, d) in [ddq, dddq].iter().enumerate() {
            for (i, x) in d.iter().enumerate() {
                for (n, m) in joint_max.iter_mut().enumerate() {
                    let limit = m[k + 1].limit;
                    m[k + 1].see(x[n].abs(), limit, ids[i + k + 2]);
                }
            }
        }
    }
    let mut peaks: Vec<Peak> = cart_max.into_iter().map(Max::peak).collect();
    for m in joint_max {
        peaks.extend(m.into_iter().map(Max::peak));
    }
    Verdict {
        commands: sorted.len(),
        runs,
        peaks,
        unsolved,
    }
}

#[cfg(test)]
mod tests;
