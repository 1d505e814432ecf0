//! Stop requests for verbs that move real devices (`live`, `grasp follow --rig`): the
//! first Ctrl-C, SIGTERM or SIGHUP is published by name on a watch channel, which the
//! loops check once per cycle before ending through their own safe exit (the gripper
//! opens, the arm stops). Cooperative, so no device transaction is cut in half.
//! `collect` counts them instead ([`count_stop_signals`]): the first finishes the
//! sample, a second stops the arm at once.

use tokio::sync::watch;

pub(crate) use softtouch_collector::stop::StopRequest;

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

/// How long the first stop request waits for others sent with it: rounds of a step.
#[cfg(unix)]
const GATHER_ROUNDS: u32 = 25;
#[cfg(unix)]
const GATHER_STEP: std::time::Duration = std::time::Duration::from_millis(2);

/// Count stop requests into `stop` (1: finish the `unit` in hand, a sample or a trial;
/// 2: stop at once): Ctrl-C (SIGINT), and on Unix SIGTERM and SIGHUP alike (a service
/// manager, a closed terminal). Ends if no handler can be installed.
pub(crate) async fn count_stop_signals(stop: tokio::sync::watch::Sender<u32>, unit: &'static str) {
    #[cfg(unix)]
    let (mut term, mut hup) = {
        use tokio::signal::unix::{SignalKind, signal};
        match (
            signal(SignalKind::terminate()),
            signal(SignalKind::hangup()),
        ) {
            (Ok(t), Ok(h)) => (t, h),
            (Err(e), _) | (_, Err(e)) => {
                eprintln!("warning: cannot watch SIGTERM/SIGHUP ({e}); only Ctrl-C stops the run");
                return ctrl_c_only(stop).await;
            }
        }
    };
    let mut requests = 0;
    loop {
        #[cfg(unix)]
        let name = tokio::select! {
            r = tokio::signal::ctrl_c() => match r { Ok(()) => "Ctrl-C", Err(_) => break },
            Some(()) = term.recv() => "SIGTERM",
            Some(()) = hup.recv() => "SIGHUP",
            else => break,
        };
        #[cfg(not(unix))]
        let name = match tokio::signal::ctrl_c().await {
            Ok(()) => "Ctrl-C",
            Err(_) => break,
        };
        let mut names = vec![name];
        // Signals that came together count together, so the loop never acts on the
        // first while the second is already here (a stopped shell's HUP and TERM). Sent
        // together, they can still reach their handlers apart (another thread takes
        // one; on a busy machine it runs milliseconds later): gather for a moment of
        // real time before acting. The wait is on the blocking pool, so a paused
        // (simulated) clock does not move meanwhile.
        #[cfg(unix)]
        if requests == 0 {
            for _ in 0..GATHER_ROUNDS {
                // Lets the driver hand over what has reached the handlers.
                tokio::task::yield_now().await;
                names.extend(
                    [
                        already_here(&mut term, "SIGTERM"),
                        already_here(&mut hup, "SIGHUP"),
                    ]
                    .into_iter()
                    .flatten(),
                );
                if names.len() > 1 {
                    break;
                }
                let _ = tokio::task::spawn_blocking(|| std::thread::sleep(GATHER_STEP)).await;
            }
        }
        for name in names {
            requests += 1;
            if requests == 1 {
                eprintln!("\n{name}: stopping after this {unit} (again to stop the arm at once)");
            } else {
                eprintln!("\n{name}: stopping the arm now");
            }
        }
        if stop.send(requests).is_err() {
            break;
        }
    }
}

/// `name` if a notification of `signal` is already waiting (taken), without waiting.
#[cfg(unix)]
fn already_here(
    signal: &mut tokio::signal::unix::Signal,
    name: &'static str,
) -> Option<&'static str> {
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    match signal.poll_recv(&mut cx) {
        std::task::Poll::Ready(Some(())) => Some(name),
        _ => None,
    }
}

#[cfg(unix)]
async fn ctrl_c_only(stop: tokio::sync::watch::Sender<u32>) {
    let mut requests = 0;
    while tokio::signal::ctrl_c().await.is_ok() {
        requests += 1;
        if stop.send(requests).is_err() {
            break;
        }
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
