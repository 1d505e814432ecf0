//! Departures from the rod in the commanded pose stream: from every pose nearer the
//! rod than the retreat plane, how the finger leaves. It should leave straight back
//! along the approach axis (the rod frame's x) and turn nothing until the retreat
//! plane; what a twist or a drag along the rod would show is the largest turn and the
//! largest angle off that axis, in the first [`WATCHED_M`] of the way and all the way
//! to the plane.

use softtouch_schemas::{ArmPose, ContactPose};

/// The first stretch of a departure the issue asks about, m.
pub(crate) const WATCHED_M: f64 = 0.004;

/// The side angle is measured once the finger has moved this far from where the
/// departure began (below it a direction is rounding), m.
const SIDE_FROM_M: f64 = 0.0002;

/// One departure.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Departure {
    /// Where it began (the rod frame).
    pub(crate) from: ContactPose,
    /// Its first pose's index in the stream.
    pub(crate) start_index: usize,
    /// Largest turn from the starting orientation in the first [`WATCHED_M`], rad.
    pub(crate) turn_rad: f64,
    /// Largest angle between the way travelled and the approach axis (backwards) in
    /// the first [`WATCHED_M`], degrees.
    pub(crate) side_deg: f64,
    /// The same two all the way to the retreat plane.
    pub(crate) turn_to_plane_rad: f64,
    pub(crate) side_to_plane_deg: f64,
    /// Whether the stream reached the retreat plane (else it ended, or turned back
    /// toward the rod, first).
    pub(crate) reached_plane: bool,
}

/// Every departure in `poses` (commanded finger poses in the base frame, in order):
/// each starts where the finger, beyond `near_x_m` along the approach axis (within
/// reach of the rod: the scene's poses begin at x = 0) and along the rod within `z_m`
/// (the scene's poses, with a margin), first moves away from it, and runs until the
/// retreat plane `plane_x_m`. The arm's first move home from wherever the
/// robot stood is not one (franka-sim's ready pose is 25 mm out and 60-130 mm down).
///
/// `restarts` (ascending indices into `poses`) are the first commands of motions: a
/// motion starts where the robot reports its last command to be (after an abort, where
/// its reflex stopped it off the last command by its tracking error), so a jump to a
/// motion's first command is not a way the driver sent; the departure is measured
/// again from there.
pub(crate) fn departures(
    poses: &[ArmPose],
    restarts: &[usize],
    base_from_rod: &ArmPose,
    plane_x_m: f64,
    near_x_m: f64,
    z_m: (f64, f64),
) -> Vec<Departure> {
    let rod_from_base = base_from_rod.inverse();
    let in_rod: Vec<ArmPose> = poses.iter().map(|p| rod_from_base.compose(p)).collect();
    let x = |k: usize| in_rod[k].translation_m[0];
    let mut out = Vec::new();
    let mut k = 0;
    while k + 1 < in_rod.len() {
        let z = in_rod[k].translation_m[2];
        if !(x(k) > near_x_m && x(k + 1) < x(k) - 1e-12 && z_m.0 <= z && z <= z_m.1) {
            k += 1;
            continue;
        }
        let mut start = in_rod[k];
        let mut d = Departure {
            from: ContactPose::from_arm(base_from_rod, &poses[k]),
            start_index: k,
            turn_rad: 0.0,
            side_deg: 0.0,
            turn_to_plane_rad: 0.0,
            side_to_plane_deg: 0.0,
            reached_plane: false,
        };
        let mut j = k + 1;
        while j < in_rod.len() {
            let p = &in_rod[j];
            if restarts.binary_search(&j).is_ok() {
                start = *p;
            }
            let way: Vec<f64> = (0..3)
                .map(|i| p.translation_m[i] - start.translation_m[i])
                .collect();
            let dist = way.iter().map(|v| v * v).sum::<f64>().sqrt();
            let turn = start.angle_to(p);
            let side = if dist >= SIDE_FROM_M {
                // The angle to −x (back along the approach axis).
                (-way[0] / dist).clamp(-1.0, 1.0).acos().to_degrees()
            } else {
                0.0
            };
            if dist <= WATCHED_M {
                d.turn_rad = d.turn_rad.max(turn);
                d.side_deg = d.side_deg.max(side);
            }
            d.turn_to_plane_rad = d.turn_to_plane_rad.max(turn);
            d.side_to_plane_deg = d.side_to_plane_deg.max(side);
            if x(j) <= plane_x_m + 1e-6 {
                d.reached_plane = true;
                break;
            }
            // Back toward the rod before the plane: the departure is over.
            if x(j) > x(j - 1) + 1e-12 {
                break;
            }
            j += 1;
        }
        out.push(d);
        k = j.max(k + 1);
    }
    out
}

/// The table the note quotes: one row per departure, and the largest of each column.
pub(crate) fn table(ds: &[Departure]) -> String {
    let mut s = String::from(
        "departure  from x mm  z mm  θ rad   turn ≤4 mm rad  side ≤4 mm °  turn to plane rad  side to plane °\n",
    );
    for (i, d) in ds.iter().enumerate() {
        s.push_str(&format!(
            "{:>9}  {:>9.2}  {:>4.1}  {:>5.2}   {:>14.2e}  {:>12.3}  {:>17.2e}  {:>15.3}{}\n",
            i + 1,
            d.from.x_m * 1000.0,
            d.from.z_m * 1000.0,
            d.from.theta_rad,
            d.turn_rad,
            d.side_deg,
            d.turn_to_plane_rad,
            d.side_to_plane_deg,
            if d.reached_plane {
                ""
            } else {
                "  (plane not reached)"
            }
        ));
    }
    let most = |f: fn(&Departure) -> f64| ds.iter().map(f).fold(0.0f64, f64::max);
    s.push_str(&format!(
        "largest: turn {:.2e} rad and {:.3}° off the axis in the first 4 mm; {:.2e} rad and {:.3}° to the plane\n",
        most(|d| d.turn_rad),
        most(|d| d.side_deg),
        most(|d| d.turn_to_plane_rad),
        most(|d| d.side_to_plane_deg)
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const Z: (f64, f64) = (-0.06, 0.06);
    const NEAR: f64 = -0.005;

    fn rod() -> ArmPose {
        crate::fcisim::base_from_rod()
    }

    fn at(x_m: f64, z_m: f64, theta_rad: f64) -> ArmPose {
        ArmPose::from_contact(
            &rod(),
            &ContactPose {
                x_m,
                z_m,
                theta_rad,
            },
        )
    }

    /// 1 mm steps between two contact poses.
    fn line(a: (f64, f64, f64), b: (f64, f64, f64), steps: usize) -> Vec<ArmPose> {
        (0..=steps)
            .map(|i| {
                let t = i as f64 / steps as f64;
                at(
                    a.0 + (b.0 - a.0) * t,
                    a.1 + (b.1 - a.1) * t,
                    a.2 + (b.2 - a.2) * t,
                )
            })
            .collect()
    }

    #[test]
    fn a_straight_departure_reads_zero_and_a_dragged_one_its_angles() {
        // In along x, out along x: nothing.
        let mut poses = line((-0.03, 0.01, 0.2), (0.002, 0.01, 0.2), 64);
        poses.extend(line((0.002, 0.01, 0.2), (-0.03, 0.01, 0.2), 64));
        let ds = departures(&poses, &[], &rod(), -0.03, NEAR, Z);
        assert_eq!(ds.len(), 1, "{ds:?}");
        assert!(ds[0].reached_plane);
        assert!(ds[0].turn_rad < 1e-9 && ds[0].side_deg < 1e-4, "{ds:?}");
        // Home in one move from the pressed pose: x, z and θ together.
        let mut poses = line((-0.03, 0.01, 0.2), (0.002, 0.01, 0.2), 64);
        poses.extend(line((0.002, 0.01, 0.2), (-0.03, 0.0, 0.0), 64));
        let ds = departures(&poses, &[], &rod(), -0.03, NEAR, Z);
        assert_eq!(ds.len(), 1, "{ds:?}");
        // 10 mm of z over 32 mm of x: 17° off the axis; 0.2 rad turned over the whole
        // way, 4/33.5 of it in the first 4 mm.
        assert!(
            (ds[0].side_deg - (10.0f64 / 32.0).atan().to_degrees()).abs() < 0.1,
            "{ds:?}"
        );
        assert!((ds[0].turn_to_plane_rad - 0.2).abs() < 1e-6, "{ds:?}");
        assert!(ds[0].turn_rad > 0.015 && ds[0].turn_rad < 0.03, "{ds:?}");
        assert!(table(&ds).contains("largest"));
    }

    #[test]
    fn a_jump_to_where_the_robot_stood_after_an_abort_is_not_a_drag() {
        // In to 50 mm, out 2 mm, an abort; the retry starts from the robot's pose 0.5 mm
        // along the rod and goes straight out from there.
        let mut poses = line((-0.03, 0.01, 0.2), (0.05, 0.01, 0.2), 80);
        poses.extend(line((0.05, 0.01, 0.2), (0.048, 0.01, 0.2), 2));
        let restart = poses.len();
        poses.extend(line((0.048, 0.0105, 0.2), (-0.03, 0.0105, 0.2), 78));
        let ds = departures(&poses, &[], &rod(), -0.03, NEAR, Z);
        assert_eq!(ds.len(), 1, "{ds:?}");
        assert!(ds[0].side_deg > 2.0, "the jump reads as a drag: {ds:?}");
        let ds = departures(&poses, &[restart], &rod(), -0.03, NEAR, Z);
        assert_eq!(ds.len(), 1, "{ds:?}");
        assert!(ds[0].reached_plane && ds[0].side_deg < 1e-3, "{ds:?}");
    }

    #[test]
    fn nothing_near_the_rod_an_empty_stream_and_a_turn_back_are_no_departures() {
        assert!(departures(&[], &[], &rod(), -0.03, NEAR, Z).is_empty());
        // Travel in the retreat plane is not a departure.
        let poses = line((-0.03, 0.0, 0.0), (-0.03, 0.02, 0.3), 20);
        assert!(departures(&poses, &[], &rod(), -0.03, NEAR, Z).is_empty());
        // Out 2 mm and back in: one departure that never reached the plane.
        let mut poses = line((-0.03, 0.0, 0.0), (0.002, 0.0, 0.0), 32);
        poses.extend(line((0.002, 0.0, 0.0), (0.0, 0.0, 0.0), 2));
        poses.extend(line((0.0, 0.0, 0.0), (0.003, 0.0, 0.0), 3));
        let ds = departures(&poses, &[], &rod(), -0.03, NEAR, Z);
        assert_eq!(ds.len(), 1, "{ds:?}");
        assert!(!ds[0].reached_plane);
        // Far down the rod (the robot's ready pose) is not near it.
        let mut poses = line((-0.018, -0.13, 0.0), (-0.03, 0.0, 0.0), 20);
        poses.insert(0, at(-0.018, -0.13, 0.0));
        assert!(departures(&poses, &[], &rod(), -0.03, NEAR, Z).is_empty());
        // A constant stream: nothing.
        assert!(departures(&vec![at(0.0, 0.0, 0.0); 10], &[], &rod(), -0.03, NEAR, Z).is_empty());
    }
}
