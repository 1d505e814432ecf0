//! Judges of a trial's outcome: where the object ended ([`physics_verdict`], for a
//! judge that can see it, as the simulator can), the rig's own reading of gOBJ,
//! position and estimate ([`RigJudge`]), and an operator confirming or correcting
//! another judge ([`OperatorJudge`]).

use super::{FailReason, Judge, Mode, Observation, Verdict};
use crate::GraspError;
use softtouch_drivers::ObjectStatus;

/// Below this true force the fingers never touched the object, N.
pub const TOUCH_N: f64 = 0.02;

/// Where the object is after the hold, as something that can see it reports it (a
/// simulator's physics; a camera watching the rig).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectState {
    /// Lifted with the fingers and still between them.
    Held,
    /// Squeezed past what it survives.
    Crushed,
    /// Not between the fingers at all.
    Absent,
    /// Lifted, then slid out of the grip.
    Slipped,
    /// Still where it stood: never lifted.
    Resting,
}

/// The verdict on a trial from where the object ended ([`ObjectState`]) and what the
/// trial saw: an object the fingers never touched (true force at most [`TOUCH_N`]) is
/// a miss, whatever else happened (a closed loop that closed on nothing never confirms
/// either, but what failed is the reach, not the loop); one touched and never lifted is
/// a timeout of the loop. A closed loop that lifted (it confirmed its force) with the
/// object between the fingers but never touched is a false confirmation: the
/// estimate read a grip that was not there.
#[must_use]
pub fn physics_verdict(state: ObjectState, seen: &Observation) -> Verdict {
    let touched = seen.peak_true_n.is_some_and(|f| f > TOUCH_N);
    let confirmed_on_nothing = seen.mode == Mode::Closed && seen.lifted && !touched;
    match state {
        ObjectState::Held => Verdict::Held,
        ObjectState::Crushed => Verdict::Failed(FailReason::Crush),
        ObjectState::Absent => Verdict::Failed(FailReason::Miss),
        ObjectState::Slipped | ObjectState::Resting if confirmed_on_nothing => {
            Verdict::Failed(FailReason::FalseConfirm)
        }
        ObjectState::Slipped if !touched => Verdict::Failed(FailReason::Miss),
        ObjectState::Slipped => Verdict::Failed(FailReason::Slip),
        ObjectState::Resting if !touched => Verdict::Failed(FailReason::Miss),
        // Touched, never lifted: the loop did not confirm its force.
        ObjectState::Resting => Verdict::Failed(FailReason::Timeout),
    }
}

/// A real rig's judge: the object is held when, after the lift, the fingers stopped
/// short of the closed end and either the estimate still shows at least
/// `min_force_n` or the gripper reports contact while closing (gOBJ = 2: stopped by
/// an object) and the finger agrees that it touches something (an estimate of at
/// least [`GOBJ_CONFIRM_FRACTION`] of `min_force_n`): a gOBJ left over from an earlier
/// move, or stuck (users of other Hand-E drivers report both), is not a grip. The position is checked whatever gOBJ says: the manual warns that it
/// is precise only to a few mm and that thin objects may never set it, and soft
/// fingers stepped by position reach their request (gOBJ = 3) while they hold. A
/// grasp that never saw `min_force_n` is a miss, one that lost it a slip. A crush
/// cannot be seen this way: [`OperatorJudge`] asks someone who watched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigJudge {
    /// Least estimated grip force of a held object, N.
    pub min_force_n: f64,
    /// The calibrated closed end, counts (fingers there hold nothing).
    pub closed_count: u8,
    /// How far from the closed end still counts as closed, counts.
    pub closed_margin: u8,
}

/// The share of [`RigJudge::min_force_n`] the finger's estimate must show before the
/// judge believes gOBJ's contact report.
pub const GOBJ_CONFIRM_FRACTION: f64 = 0.25;

impl RigJudge {
    /// Whether gOBJ's report of a contact while closing is confirmed by the finger.
    #[must_use]
    pub fn contact_confirmed(&self, object: ObjectStatus, estimate_n: Option<f64>) -> bool {
        object == ObjectStatus::ContactClosing
            && estimate_n
                .is_some_and(|f| f.is_finite() && f >= GOBJ_CONFIRM_FRACTION * self.min_force_n)
    }
}

impl Judge for RigJudge {
    async fn judge(&mut self, seen: &Observation) -> Result<Verdict, GraspError> {
        let at_closed_end =
            seen.last_status.position >= self.closed_count.saturating_sub(self.closed_margin);
        let ever = seen.peak_estimate_n.is_some_and(|f| f >= self.min_force_n);
        let now = seen.last_estimate_n.is_some_and(|f| f >= self.min_force_n)
            || self.contact_confirmed(seen.last_status.object, seen.last_estimate_n);
        Ok(if !ever {
            Verdict::Failed(FailReason::Miss)
        } else if !seen.lifted {
            Verdict::Failed(FailReason::Timeout)
        } else if at_closed_end || !now {
            Verdict::Failed(FailReason::Slip)
        } else {
            Verdict::Held
        })
    }
}

/// An operator's word on every trial, after another judge's (a real rig cannot see a
/// crush, and a lab may want eyes on every outcome): the judge's verdict is shown and
/// the operator answers `y` (held), `n` (not held: the judge's reason, or slip where
/// it saw the object held), a reason by name (`slip`, `crush`, `miss`, `timeout`,
/// `device_fault`), or an empty line to keep the judge's verdict. Anything else is
/// asked again. An input that closes or fails stops the trials
/// ([`GraspError::Interrupted`]): no outcome is stored that nobody gave.
#[derive(Debug)]
pub struct OperatorJudge<J, R, W> {
    /// The judge whose verdict is confirmed.
    pub judge: J,
    /// The operator's answers, one a line (stdin's lock, say).
    pub input: R,
    /// Where the questions go.
    pub output: W,
}

impl<J: Judge, R: std::io::BufRead + Send, W: std::io::Write + Send> Judge
    for OperatorJudge<J, R, W>
{
    async fn judge(&mut self, seen: &Observation) -> Result<Verdict, GraspError> {
        let machine = self.judge.judge(seen).await?;
        let said = super::operator::verdict_name(machine);
        let gone =
            |e: std::io::Error| GraspError::Interrupted(format!("the operator's input ({e})"));
        loop {
            write!(
                self.output,
                "the judge says {said}; held? [y, n, slip, crush, miss, timeout, device_fault; Enter keeps {said}] "
            )
            .and_then(|()| self.output.flush())
            .map_err(gone)?;
            let mut line = String::new();
            if self.input.read_line(&mut line).map_err(gone)? == 0 {
                return Err(GraspError::Interrupted(
                    "the operator's input closing before an answer".into(),
                ));
            }
            let verdict = super::operator::operator_verdict(machine, &line);
            match verdict {
                Some(v) => return Ok(v),
                None => writeln!(
                    self.output,
                    "`{}`: expected y, n, a failure reason or an empty line",
                    line.trim()
                )
                .map_err(gone)?,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_drivers::GripperStatus;
    use softtouch_schemas::TimestampNs;

    fn seen(lifted: bool, position: u8, last: Option<f64>, peak: Option<f64>) -> Observation {
        Observation {
            mode: Mode::Closed,
            lifted,
            last_status: GripperStatus {
                t: TimestampNs::ZERO,
                activated: true,
                object: ObjectStatus::AtPosition,
                fault: 0,
                requested_position: position,
                position,
                current_ma: 0,
            },
            last_estimate_n: last,
            peak_estimate_n: peak,
            peak_true_n: None,
        }
    }

    /// The rig judge the tests use: 0.3 N, closed end at 250 counts, 3 counts' margin.
    const RIG_JUDGE: RigJudge = RigJudge {
        min_force_n: 0.3,
        closed_count: 250,
        closed_margin: 3,
    };

    #[test]
    fn an_object_never_touched_is_a_miss_in_either_mode() {
        for mode in [Mode::Open, Mode::Closed] {
            let mut untouched = seen(false, 250, None, None);
            untouched.mode = mode;
            untouched.peak_true_n = Some(0.0);
            assert_eq!(
                physics_verdict(ObjectState::Resting, &untouched),
                Verdict::Failed(FailReason::Miss),
                "{mode:?}"
            );
            let mut touched = untouched;
            touched.peak_true_n = Some(1.0);
            let expected = Verdict::Failed(FailReason::Timeout);
            assert_eq!(physics_verdict(ObjectState::Resting, &touched), expected);
        }
    }

    /// A closed loop that confirmed on a phantom estimate (it lifted while the true
    /// force never passed the touch threshold) failed by its estimate, not its reach;
    /// an open loop lifts whatever it feels, and an object not between the fingers is
    /// still a miss.
    #[test]
    fn a_closed_loop_that_lifts_on_a_force_it_never_felt_is_a_false_confirmation() {
        for state in [ObjectState::Resting, ObjectState::Slipped] {
            let mut phantom = seen(true, 200, Some(1.5), Some(1.5));
            phantom.mode = Mode::Closed;
            phantom.peak_true_n = Some(0.01);
            assert_eq!(
                physics_verdict(state, &phantom),
                Verdict::Failed(FailReason::FalseConfirm),
                "{state:?}"
            );
            let mut open = phantom;
            open.mode = Mode::Open;
            assert_eq!(
                physics_verdict(state, &open),
                Verdict::Failed(FailReason::Miss)
            );
            let mut felt = phantom;
            felt.peak_true_n = Some(0.5);
            assert_ne!(
                physics_verdict(state, &felt),
                Verdict::Failed(FailReason::FalseConfirm)
            );
        }
        let mut phantom = seen(true, 200, Some(1.5), Some(1.5));
        phantom.mode = Mode::Closed;
        assert_eq!(
            physics_verdict(ObjectState::Absent, &phantom),
            Verdict::Failed(FailReason::Miss)
        );
        assert_eq!(
            FailReason::parse("false_confirm"),
            Ok(FailReason::FalseConfirm)
        );
    }

    #[tokio::test]
    async fn the_rig_judge_reads_position_and_estimate() {
        let mut j = RIG_JUDGE;
        let held = j.judge(&seen(true, 150, Some(1.0), Some(1.2))).await.ok();
        assert_eq!(held, Some(Verdict::Held));
        let slip = j.judge(&seen(true, 249, Some(1.0), Some(1.2))).await.ok();
        assert_eq!(slip, Some(Verdict::Failed(FailReason::Slip)));
        let lost = j.judge(&seen(true, 150, Some(0.1), Some(1.2))).await.ok();
        assert_eq!(lost, Some(Verdict::Failed(FailReason::Slip)));
        let miss = j.judge(&seen(true, 250, None, None)).await.ok();
        assert_eq!(miss, Some(Verdict::Failed(FailReason::Miss)));
        let timeout = j.judge(&seen(false, 150, Some(1.0), Some(1.0))).await.ok();
        assert_eq!(timeout, Some(Verdict::Failed(FailReason::Timeout)));
    }

    #[tokio::test]
    async fn the_rig_judge_takes_a_contact_stop_for_a_grip_but_not_at_the_closed_end() {
        let mut j = RIG_JUDGE;
        // The estimate fell under the least force, but gOBJ = 2: an object stops them.
        let mut low = seen(true, 150, Some(0.1), Some(1.2));
        low.last_status.object = ObjectStatus::ContactClosing;
        assert_eq!(j.judge(&low).await.ok(), Some(Verdict::Held));
        // The same report at the closed end is not believed (gOBJ is coarse).
        let mut closed = seen(true, 249, Some(0.1), Some(1.2));
        closed.last_status.object = ObjectStatus::ContactClosing;
        assert_eq!(
            j.judge(&closed).await.ok(),
            Some(Verdict::Failed(FailReason::Slip))
        );
        // gOBJ = 2 while the finger feels nothing (0.05 N, under a quarter of 0.3 N): a
        // stale or stuck report, not a grip.
        let mut stuck = seen(true, 150, Some(0.05), Some(1.2));
        stuck.last_status.object = ObjectStatus::ContactClosing;
        assert_eq!(
            j.judge(&stuck).await.ok(),
            Some(Verdict::Failed(FailReason::Slip))
        );
        let mut nan = seen(true, 150, Some(f64::NAN), Some(1.2));
        nan.last_status.object = ObjectStatus::ContactClosing;
        assert_eq!(
            j.judge(&nan).await.ok(),
            Some(Verdict::Failed(FailReason::Slip))
        );
        // A contact report never makes a grasp that never felt the force a hold.
        let mut never = seen(true, 150, None, None);
        never.last_status.object = ObjectStatus::ContactClosing;
        assert_eq!(
            j.judge(&never).await.ok(),
            Some(Verdict::Failed(FailReason::Miss))
        );
    }

    async fn operator(
        answers: &[u8],
        judged: Observation,
    ) -> (Result<Verdict, GraspError>, String) {
        let mut j = OperatorJudge {
            judge: RIG_JUDGE,
            input: std::io::Cursor::new(answers.to_vec()),
            output: Vec::new(),
        };
        let verdict = j.judge(&judged).await;
        (verdict, String::from_utf8_lossy(&j.output).into_owned())
    }

    #[tokio::test]
    async fn the_operator_confirms_overrides_or_names_the_reason() {
        let held = || seen(true, 150, Some(1.0), Some(1.2));
        let slipped = || seen(true, 249, Some(1.0), Some(1.2));
        let cases = [
            ("\n", held(), Verdict::Held),
            ("y\n", slipped(), Verdict::Held),
            ("n\n", held(), Verdict::Failed(FailReason::Slip)),
            ("N\n", slipped(), Verdict::Failed(FailReason::Slip)),
            ("crush\n", held(), Verdict::Failed(FailReason::Crush)),
            (" Miss \r\n", held(), Verdict::Failed(FailReason::Miss)),
            ("\n", slipped(), Verdict::Failed(FailReason::Slip)),
        ];
        for (answers, judged, expected) in cases {
            let (verdict, asked) = operator(answers.as_bytes(), judged).await;
            assert_eq!(verdict.ok(), Some(expected), "answers {answers:?}");
            assert!(asked.contains("the judge says"), "{asked}");
        }
    }

    #[tokio::test]
    async fn the_operator_is_asked_again_and_a_closed_input_stops_the_trials() {
        let (verdict, asked) = operator(
            "maybe\n\u{1F600}\ncrush\n".as_bytes(),
            seen(true, 150, Some(1.0), Some(1.2)),
        )
        .await;
        assert_eq!(verdict.ok(), Some(Verdict::Failed(FailReason::Crush)));
        assert!(asked.contains("`maybe`: expected y, n"), "{asked}");
        assert_eq!(asked.matches("the judge says held").count(), 3, "{asked}");
        for answers in ["", "maybe\n", "maybe"] {
            let (verdict, _) =
                operator(answers.as_bytes(), seen(true, 150, Some(1.0), Some(1.2))).await;
            assert!(
                matches!(verdict, Err(GraspError::Interrupted(_))),
                "answers {answers:?}: {verdict:?}"
            );
        }
        // Bytes that are not UTF-8 are an unreadable input, not a panic.
        let (verdict, _) =
            operator(&[0xff, 0xfe, b'\n'], seen(true, 150, Some(1.0), Some(1.2))).await;
        assert!(
            matches!(verdict, Err(GraspError::Interrupted(_))),
            "{verdict:?}"
        );
    }
}
