//! A stop request, as the verbs that move devices hear it: the first Ctrl-C, SIGTERM or
//! SIGHUP published by name on a watch channel (the CLI's signal watch sends it), which
//! a session's loop checks once per cycle before ending through its own safe exit.

use tokio::sync::watch;

/// The first stop request's name (`None` until one arrives).
pub type StopRequest = watch::Receiver<Option<&'static str>>;

/// Resolves with the name of the first stop request; never, if none can arrive.
pub async fn requested(mut rx: StopRequest) -> &'static str {
    loop {
        if let Some(name) = *rx.borrow_and_update() {
            return name;
        }
        if rx.changed().await.is_err() {
            return std::future::pending().await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn a_request_is_seen_by_every_receiver_and_a_closed_channel_never_fires() {
        let (tx, rx) = watch::channel(None);
        let waiting = tokio::spawn(requested(rx.clone()));
        tx.send(Some("SIGTERM")).expect("open");
        assert_eq!(waiting.await.expect("joins"), "SIGTERM");
        // Seen later too.
        assert_eq!(requested(rx).await, "SIGTERM");
        let (tx, rx) = watch::channel::<Option<&'static str>>(None);
        drop(tx);
        let never = tokio::time::timeout(std::time::Duration::from_secs(3600), requested(rx));
        assert!(never.await.is_err());
    }
}
