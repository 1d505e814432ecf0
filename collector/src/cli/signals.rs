//! Stop requests for verbs that move real devices (`live`, `grasp follow --rig`): the
//! first Ctrl-C, SIGTERM or SIGHUP is published by name on a watch channel, which the
//! loops check once per cycle before ending through their own safe exit (the gripper
//! opens, the arm stops). Cooperative, so no device transaction is cut in half.

use tokio::sync::watch;

pub(crate) use crate::stop::StopRequest;

/// Watches the signals until dropped.
#[derive(Debug)]
pub(crate) struct SignalWatch {
    rx: StopRequest,
    task: tokio::task::JoinHandle<()>,
}

impl SignalWatch {
    /// Starts watching (needs a tokio runtime).
    pub(crate) fn start() -> Self {
        let (tx, rx) = watch::channel(None);
        let task = tokio::spawn(async move {
            let name = first_signal().await;
            let _ = tx.send(Some(name));
            eprintln!("\n{name}: stopping safely (the gripper opens, the arm stops)");
            // Keep the sender, so receivers see the request rather than a closed channel.
            std::future::pending::<()>().await;
        });
        Self { rx, task }
    }

    /// A receiver for a loop.
    pub(crate) fn request(&self) -> StopRequest {
        self.rx.clone()
    }
}

impl Drop for SignalWatch {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn first_signal() -> &'static str {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match (
            signal(SignalKind::terminate()),
            signal(SignalKind::hangup()),
        ) {
            (Ok(mut term), Ok(mut hup)) => {
                return tokio::select! {
                    r = tokio::signal::ctrl_c() => match r {
                        Ok(()) => "Ctrl-C",
                        Err(_) => std::future::pending().await,
                    },
                    Some(()) = term.recv() => "SIGTERM",
                    Some(()) = hup.recv() => "SIGHUP",
                };
            }
            (Err(e), _) | (_, Err(e)) => {
                eprintln!("warning: cannot watch SIGTERM/SIGHUP ({e}); only Ctrl-C stops safely");
            }
        }
    }
    match tokio::signal::ctrl_c().await {
        Ok(()) => "Ctrl-C",
        Err(_) => std::future::pending().await,
    }
}
