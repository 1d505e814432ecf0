//! The operator of a rig's trials: lines typed at a terminal (or a scripted file), read
//! off the loop's thread, and questions asked while the Hand-E is kept alive (a
//! command every [`KEEP_ALIVE`], under its 1 s watchdog) and the arm stands still.

use std::io::Write;
use std::time::Duration;

use softtouch_drivers::{DeviceError, Gripper, GripperCommand};

use super::{FailReason, Verdict};
use crate::GraspError;

/// How often the gripper hears its hold command while a question waits.
pub const KEEP_ALIVE: Duration = Duration::from_millis(200);

/// The operator's answers, one a line.
#[derive(Debug)]
pub struct OperatorInput {
    lines: tokio::sync::mpsc::Receiver<String>,
}

impl OperatorInput {
    /// Reads `input` on a thread of its own (a blocking terminal never stalls the
    /// loop); the channel closes when the input ends or fails, or a line is not UTF-8.
    #[must_use]
    pub fn from_reader<R: std::io::BufRead + Send + 'static>(mut input: R) -> Self {
        let (tx, lines) = tokio::sync::mpsc::channel(16);
        std::thread::spawn(move || {
            loop {
                let mut line = String::new();
                match input.read_line(&mut line) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {
                        if tx.blocking_send(line).is_err() {
                            break;
                        }
                    }
                }
            }
        });
        Self { lines }
    }

    /// The next line, or `None` once the input has closed.
    pub async fn next_line(&mut self) -> Option<String> {
        self.lines.recv().await
    }

    /// Asks `question` on `out` and waits for a line, sending `hold` to the gripper
    /// every [`KEEP_ALIVE`] meanwhile.
    ///
    /// # Errors
    /// [`GraspError::Interrupted`] when the input closes (nobody answers), a gripper
    /// that fails or faults, an output that cannot be written.
    pub async fn ask<G: Gripper + ?Sized>(
        &mut self,
        question: &str,
        out: &mut (dyn Write + Send),
        gripper: &mut G,
        hold: GripperCommand,
    ) -> Result<String, GraspError> {
        let gone =
            |e: std::io::Error| GraspError::Interrupted(format!("the operator's output ({e})"));
        write!(out, "{question} ")
            .and_then(|()| out.flush())
            .map_err(gone)?;
        let mut tick = tokio::time::interval(KEEP_ALIVE);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                line = self.lines.recv() => {
                    return line.ok_or_else(|| GraspError::Interrupted(
                        "the operator's input closing before an answer".into(),
                    ));
                }
                _ = tick.tick() => {
                    let status = gripper.command_and_status(hold).await?;
                    if status.fault != 0 {
                        return Err(GraspError::Device(DeviceError::Fault {
                            device: "gripper".into(),
                            code: Some(u32::from(status.fault)),
                            message: format!(
                                "the gripper faulted while waiting for the operator: {}",
                                softtouch_drivers::hande::regs::describe_fault(status.fault)
                            ),
                        }));
                    }
                }
            }
        }
    }

    /// Asks the operator to confirm or correct `machine` (the rig judge's verdict),
    /// again until the answer reads ([`operator_verdict`]), keeping the gripper alive.
    ///
    /// # Errors
    /// As [`Self::ask`].
    pub async fn confirm<G: Gripper + ?Sized>(
        &mut self,
        machine: Verdict,
        out: &mut (dyn Write + Send),
        gripper: &mut G,
        hold: GripperCommand,
    ) -> Result<Verdict, GraspError> {
        let said = verdict_name(machine);
        let question = format!(
            "the judge says {said}; held? [y, n, slip, crush, miss, timeout, device_fault; Enter keeps {said}]"
        );
        loop {
            let line = self.ask(&question, out, gripper, hold).await?;
            match operator_verdict(machine, &line) {
                Some(v) => return Ok(v),
                None => writeln!(
                    out,
                    "`{}`: expected y, n, a failure reason or an empty line",
                    line.trim()
                )
                .map_err(|e| GraspError::Interrupted(format!("the operator's output ({e})")))?,
            }
        }
    }
}

/// `held` or the failure reason's name.
#[must_use]
pub const fn verdict_name(v: Verdict) -> &'static str {
    match v {
        Verdict::Held => "held",
        Verdict::Failed(reason) => reason.as_str(),
    }
}

/// What an operator's `answer` makes of the judge's `machine` verdict: an empty line
/// keeps it, `y` is held, `n` is not held (the judge's reason, or slip where it saw
/// the object held), a reason by name is that reason; anything else is `None` (ask
/// again).
#[must_use]
pub fn operator_verdict(machine: Verdict, answer: &str) -> Option<Verdict> {
    match answer.trim().to_ascii_lowercase().as_str() {
        "" => Some(machine),
        "y" | "yes" | "held" => Some(Verdict::Held),
        "n" | "no" => Some(match machine {
            Verdict::Held => Verdict::Failed(FailReason::Slip),
            failed => failed,
        }),
        other => FailReason::parse(other).ok().map(Verdict::Failed),
    }
}
