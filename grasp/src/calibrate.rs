//! End calibration of a parallel gripper: the usable count range of a Hand-E is
//! narrower than 0–255 and differs per gripper (docs/PROTOCOLS.md §2.x), so before a force
//! loop the fingers close fully and open fully with a low force, the reached positions
//! are read back, and the [`Stroke`] the stepper clamps to is derived from them.
//!
//! Each move re-sends its request within the keep-alive (the Hand-E faults with 0x09
//! after about 1 s without a command) and waits for the gPR echo before it trusts gPO.
//! A fault, a contact stop while closing (something between the fingers), a move that
//! does not finish in time or a travel too short to be a real stroke is a clear error;
//! whatever happens, the last request sent is the open end.

use std::time::Duration;

use softtouch_drivers::gripper::STROKE_MM;
use softtouch_drivers::{Clock, DeviceError, Gripper, GripperCommand, GripperStatus, ObjectStatus};

use crate::GraspError;
use crate::stepper::Stroke;

const DEVICE: &str = "gripper";

/// How the ends are found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationConfig {
    /// rSP of the calibration moves.
    pub speed: u8,
    /// rFR of the calibration moves: low, so an unexpected object is not crushed.
    pub force: u8,
    /// Longest time one end may take.
    pub move_timeout: Duration,
    /// Status polling period (the Hand-E allows 200 transactions per second).
    pub poll: Duration,
    /// Re-send the request after this long (below the Hand-E's 1 s watchdog).
    pub keep_alive: Duration,
    /// Counts kept free at each end, so the loop never rams the mechanical stop.
    pub margin_counts: u8,
    /// Least travel between the ends, counts; less means the fingers did not move.
    pub min_travel_counts: u8,
}

impl Default for CalibrationConfig {
    /// Half speed, a low force (rFR 20), 5 s per end, 10 ms polls, 200 ms keep-alive,
    /// 2 counts of margin, at least 50 counts of travel.
    fn default() -> Self {
        Self {
            speed: 128,
            force: 20,
            move_timeout: Duration::from_secs(5),
            poll: Duration::from_millis(10),
            keep_alive: Duration::from_millis(200),
            margin_counts: 2,
            min_travel_counts: 50,
        }
    }
}

impl CalibrationConfig {
    fn validate(&self) -> Result<(), GraspError> {
        let mut problems = Vec::new();
        if self.move_timeout.is_zero() {
            problems.push("move_timeout 0: expected a positive duration".to_owned());
        }
        if self.poll.is_zero() || self.poll >= self.move_timeout {
            problems.push(format!(
                "poll {:?}: expected more than 0 and less than move_timeout {:?}",
                self.poll, self.move_timeout
            ));
        }
        if self.keep_alive.is_zero() || self.keep_alive >= Duration::from_secs(1) {
            problems.push(format!(
                "keep_alive {:?}: expected more than 0 and less than 1 s",
                self.keep_alive
            ));
        }
        if u16::from(self.margin_counts) * 2 + u16::from(self.min_travel_counts) > 255 {
            problems.push(format!(
                "margin_counts {} and min_travel_counts {}: expected 2·margin + travel ≤ 255",
                self.margin_counts, self.min_travel_counts
            ));
        }
        if self.min_travel_counts == 0 {
            problems.push("min_travel_counts 0: expected at least 1".into());
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(GraspError::Config(problems.join("; ")))
        }
    }
}

/// What calibration found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EndCalibration {
    /// gPO when fully open (request 0).
    pub open_reached: u8,
    /// gPO when fully closed (request 255).
    pub closed_reached: u8,
    /// The stroke for the stepper: the reached ends less the margin, the full
    /// opening ([`STROKE_MM`]) spread over the reached counts.
    pub stroke: Stroke,
}

fn fault(message: String) -> GraspError {
    GraspError::Device(DeviceError::Fault {
        device: DEVICE.into(),
        code: None,
        message,
    })
}

/// Sends `position` and waits until the gripper echoes it and stops (at the position
/// or on a contact), re-sending within the keep-alive.
///
/// # Errors
/// A fault, a link error, or no stop within `config.move_timeout`.
pub async fn move_to_end<G: Gripper + ?Sized>(
    gripper: &mut G,
    clock: &dyn Clock,
    config: &CalibrationConfig,
    position: u8,
) -> Result<GripperStatus, GraspError> {
    let cmd = GripperCommand {
        position,
        speed: config.speed,
        force: config.force,
    };
    let start = clock.now();
    gripper.command(cmd).await?;
    let mut sent = start;
    let mut first_position = None;
    loop {
        tokio::time::sleep(config.poll).await;
        let status = gripper.status().await?;
        if status.fault != 0 {
            return Err(GraspError::Device(DeviceError::Fault {
                device: DEVICE.into(),
                code: Some(u32::from(status.fault)),
                message: format!(
                    "calibration: the gripper faulted while moving to count {position}"
                ),
            }));
        }
        let first = *first_position.get_or_insert(status.position);
        if status.requested_position == position && status.object != ObjectStatus::Moving {
            return Ok(status);
        }
        let now = clock.now();
        let elapsed = Duration::from_nanos(now.0.saturating_sub(start.0));
        if elapsed > config.move_timeout {
            return Err(fault(format!(
                "calibration: the gripper did not reach count {position} within {:?} (it went from count {first} to {}, echo gPR = {}, gOBJ = {:?}); check that it is powered, activated and free to move",
                config.move_timeout, status.position, status.requested_position, status.object
            )));
        }
        if Duration::from_nanos(now.0.saturating_sub(sent.0)) >= config.keep_alive {
            gripper.command(cmd).await?;
            sent = now;
        }
    }
}

/// Activates the gripper, closes it fully and opens it fully with a low force, and
/// derives the usable [`Stroke`]. Nothing may be between the fingers. The gripper
/// ends at its open end on success; on an error the last request is the open end too.
pub async fn calibrate_ends<G: Gripper + ?Sized>(
    gripper: &mut G,
    clock: &dyn Clock,
    config: &CalibrationConfig,
) -> Result<EndCalibration, GraspError> {
    config.validate()?;
    let result = calibrate_inner(gripper, clock, config).await;
    if result.is_err() {
        // Leave the fingers opening; the calibration's error is the one to report.
        let _ = gripper
            .command(GripperCommand {
                position: 0,
                speed: config.speed,
                force: config.force,
            })
            .await;
    }
    result
}

async fn calibrate_inner<G: Gripper + ?Sized>(
    gripper: &mut G,
    clock: &dyn Clock,
    config: &CalibrationConfig,
) -> Result<EndCalibration, GraspError> {
    gripper.activate().await?;
    let closed = move_to_end(gripper, clock, config, 255).await?;
    if closed.object == ObjectStatus::ContactClosing {
        return Err(fault(format!(
            "calibration: the fingers stopped on contact at count {} while closing; remove any object from between the fingers",
            closed.position
        )));
    }
    let open = move_to_end(gripper, clock, config, 0).await?;
    if open.object == ObjectStatus::ContactOpening {
        return Err(fault(format!(
            "calibration: the fingers stopped on contact at count {} while opening; clear the space around the fingers",
            open.position
        )));
    }
    derive_stroke(open.position, closed.position, config)
}

/// The stroke from the reached ends (pure; the checks of [`calibrate_ends`]).
pub fn derive_stroke(
    open_reached: u8,
    closed_reached: u8,
    config: &CalibrationConfig,
) -> Result<EndCalibration, GraspError> {
    let travel = i32::from(closed_reached) - i32::from(open_reached);
    if travel < i32::from(config.min_travel_counts) {
        return Err(fault(format!(
            "calibration: the fingers travelled from count {open_reached} (open) to {closed_reached} (closed), expected at least {} counts; the gripper did not move",
            config.min_travel_counts
        )));
    }
    let stroke = Stroke {
        open_count: open_reached.saturating_add(config.margin_counts),
        closed_count: closed_reached.saturating_sub(config.margin_counts),
        mm_per_count: STROKE_MM / f64::from(travel),
    };
    let problems = stroke.problems();
    if !problems.is_empty() {
        return Err(GraspError::Config(problems.join("; ")));
    }
    Ok(EndCalibration {
        open_reached,
        closed_reached,
        stroke,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use async_trait::async_trait;
    use softtouch_drivers::TokioClock;
    use softtouch_schemas::TimestampNs;

    /// A gripper whose fingers reach only `lo..=hi`, move `counts_per_poll` per status
    /// read, optionally stuck, faulting, or stopped by an object at `object_at`.
    #[derive(Debug)]
    struct Model {
        lo: u8,
        hi: u8,
        pos: u8,
        req: u8,
        stuck: bool,
        fault_after: Option<u32>,
        object_at: Option<u8>,
        reads: u32,
        commands: Vec<GripperCommand>,
    }

    impl Model {
        fn new(lo: u8, hi: u8) -> Self {
            Self {
                lo,
                hi,
                pos: 100,
                req: 100,
                stuck: false,
                fault_after: None,
                object_at: None,
                reads: 0,
                commands: Vec::new(),
            }
        }
    }

    #[async_trait]
    impl Gripper for Model {
        async fn activate(&mut self) -> Result<(), DeviceError> {
            Ok(())
        }
        async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
            self.req = cmd.position;
            self.commands.push(cmd);
            Ok(())
        }
        async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
            self.reads += 1;
            let target = self.req.clamp(self.lo, self.hi);
            let stop = self
                .object_at
                .filter(|&o| self.req > self.pos && o <= target);
            let goal = stop.unwrap_or(target);
            if !self.stuck {
                let step = 20i32;
                let d = (i32::from(goal) - i32::from(self.pos)).clamp(-step, step);
                self.pos = (i32::from(self.pos) + d) as u8;
            }
            let object = if self.stuck || self.pos != goal {
                ObjectStatus::Moving
            } else if stop.is_some() {
                ObjectStatus::ContactClosing
            } else {
                ObjectStatus::AtPosition
            };
            Ok(GripperStatus {
                t: TimestampNs::ZERO,
                activated: true,
                object,
                fault: match self.fault_after {
                    Some(n) if self.reads > n => 0x0B,
                    _ => 0,
                },
                requested_position: self.req,
                position: self.pos,
                current_ma: 0,
            })
        }
    }

    fn rt() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .start_paused(true)
            .build()
            .expect("runtime")
    }

    fn run(g: &mut Model) -> Result<EndCalibration, GraspError> {
        rt().block_on(async {
            let clock = TokioClock::new();
            calibrate_ends(g, &clock, &CalibrationConfig::default()).await
        })
    }

    #[test]
    fn the_reached_ends_give_the_stroke_and_the_gripper_ends_open() {
        let mut g = Model::new(6, 229);
        let c = run(&mut g).expect("calibrates");
        assert_eq!((c.open_reached, c.closed_reached), (6, 229));
        assert_eq!((c.stroke.open_count, c.stroke.closed_count), (8, 227));
        assert!((c.stroke.mm_per_count - 50.0 / 223.0).abs() < 1e-12);
        assert_eq!(g.commands.last().map(|c| c.position), Some(0));
        assert!(g.commands.iter().all(|c| c.force == 20));
    }

    #[test]
    fn a_stuck_gripper_a_fault_or_an_object_is_a_clear_error_and_it_is_told_to_open() {
        let mut stuck = Model::new(0, 255);
        stuck.stuck = true;
        let e = run(&mut stuck).expect_err("stuck").to_string();
        assert!(e.contains("did not reach count 255"), "{e}");
        assert_eq!(stuck.commands.last().map(|c| c.position), Some(0));
        // Keep-alive: the request was re-sent while waiting (5 s at 200 ms).
        assert!(stuck.commands.len() >= 20, "{}", stuck.commands.len());

        let mut faulty = Model::new(0, 255);
        faulty.fault_after = Some(3);
        let e = run(&mut faulty).expect_err("fault").to_string();
        assert!(e.contains("0xB") && e.contains("faulted"), "{e}");

        let mut blocked = Model::new(0, 255);
        blocked.object_at = Some(150);
        let e = run(&mut blocked).expect_err("object").to_string();
        assert!(e.contains("remove any object"), "{e}");
        assert_eq!(blocked.commands.last().map(|c| c.position), Some(0));
    }

    #[test]
    fn a_short_travel_or_bad_settings_are_refused() {
        let c = CalibrationConfig::default();
        let e = derive_stroke(100, 120, &c).expect_err("short").to_string();
        assert!(e.contains("did not move"), "{e}");
        let e = derive_stroke(200, 10, &c)
            .expect_err("reversed")
            .to_string();
        assert!(e.contains("did not move"), "{e}");
        let bad = CalibrationConfig {
            keep_alive: Duration::from_secs(2),
            min_travel_counts: 0,
            ..c
        };
        let e = rt()
            .block_on(async {
                calibrate_ends(&mut Model::new(0, 255), &TokioClock::new(), &bad).await
            })
            .expect_err("bad")
            .to_string();
        assert!(
            e.contains("keep_alive") && e.contains("min_travel_counts"),
            "{e}"
        );
    }
}
