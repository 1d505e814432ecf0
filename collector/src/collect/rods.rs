//! Changing the rod between blocks of a run.
//!
//! On a real rig an operator swaps the rod; the simulated rig swaps it itself. Both sit
//! behind [`RodChanger`], so the collection loop does not know which it has.

use async_trait::async_trait;
use softtouch_drivers::DeviceError;
use softtouch_sim::SimHandle;
use std::io::{BufRead as _, IsTerminal as _, Write as _};

/// Puts a rod in place (the arm is at home when this is called).
#[async_trait]
pub trait RodChanger: Send {
    /// Make `rod` the rod the finger will touch.
    async fn change_rod(&mut self, rod: &str) -> Result<(), DeviceError>;
}

#[async_trait]
impl RodChanger for SimHandle {
    async fn change_rod(&mut self, rod: &str) -> Result<(), DeviceError> {
        self.set_rod(rod).map_err(|e| DeviceError::InvalidCommand {
            device: "sim rod".into(),
            message: e.to_string(),
        })
    }
}

/// Asks the operator on the terminal to change the rod, and waits for Enter.
#[derive(Debug, Default)]
pub struct TerminalOperator {
    current: Option<String>,
}

#[async_trait]
impl RodChanger for TerminalOperator {
    async fn change_rod(&mut self, rod: &str) -> Result<(), DeviceError> {
        if self.current.as_deref() == Some(rod) {
            return Ok(());
        }
        if self.current.is_none() {
            // The first rod is whatever the operator mounted before starting.
            self.current = Some(rod.to_owned());
            return Ok(());
        }
        if !std::io::stdin().is_terminal() {
            return Err(DeviceError::InvalidCommand {
                device: "operator".into(),
                message: format!(
                    "the schedule needs rod `{rod}` now but nobody is at a terminal to change it; \
                     run one rod per run when unattended"
                ),
            });
        }
        let rod_owned = rod.to_owned();
        // A detached thread, not `spawn_blocking`: a forced stop drops this future, and
        // the runtime would otherwise wait for the blocked read before the process exits.
        let (reply, answer) = tokio::sync::oneshot::channel();
        std::thread::Builder::new()
            .name("rod-prompt".into())
            .spawn(move || {
                let mut err = std::io::stderr().lock();
                let _ = writeln!(
                    err,
                    "\n>>> Mount rod `{rod_owned}`, then press Enter (the arm is at home)."
                );
                let mut line = String::new();
                let _ = reply.send(std::io::stdin().lock().read_line(&mut line));
            })
            .map_err(|e| DeviceError::Link {
                device: "operator".into(),
                message: e.to_string(),
            })?;
        match answer.await {
            Ok(Ok(_)) => {
                self.current = Some(rod.to_owned());
                Ok(())
            }
            Ok(Err(e)) => Err(DeviceError::Link {
                device: "operator".into(),
                message: e.to_string(),
            }),
            Err(e) => Err(DeviceError::Link {
                device: "operator".into(),
                message: e.to_string(),
            }),
        }
    }
}
