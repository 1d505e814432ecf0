//! The clock every reading is stamped with.

use softtouch_schemas::TimestampNs;
use std::fmt::Debug;

/// Monotonic time, injected into every driver.
pub trait Clock: Send + Sync + Debug {
    /// Now, in nanoseconds since this clock's epoch.
    fn now(&self) -> TimestampNs;
}

/// Time from tokio's clock, relative to the moment the clock was made.
///
/// On a rig this is the host's monotonic clock. In simulation the runtime is started
/// paused (`tokio::time::pause`, `start_paused`): time then stands still while code
/// runs and jumps to the next timer when every task waits, so a night of simulated
/// collection takes as long as its computation, and the same seed gives the same bytes.
#[derive(Debug, Clone, Copy)]
pub struct TokioClock {
    epoch: tokio::time::Instant,
}

impl TokioClock {
    /// A clock whose epoch is now. Must be called inside a tokio runtime.
    #[must_use]
    pub fn new() -> Self {
        Self {
            epoch: tokio::time::Instant::now(),
        }
    }

    /// The tokio instant at a timestamp of this clock (for `sleep_until`).
    #[must_use]
    pub fn instant_at(&self, t: TimestampNs) -> tokio::time::Instant {
        self.epoch + std::time::Duration::from_nanos(t.0)
    }
}

impl Default for TokioClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for TokioClock {
    fn now(&self) -> TimestampNs {
        let ns = self.epoch.elapsed().as_nanos();
        TimestampNs(u64::try_from(ns).unwrap_or(u64::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test(start_paused = true)]
    async fn paused_time_advances_only_by_sleeping() {
        let clock = TokioClock::new();
        assert_eq!(clock.now(), TimestampNs(0));
        tokio::time::sleep(Duration::from_millis(1500)).await;
        assert_eq!(clock.now(), TimestampNs(1_500_000_000));
        tokio::time::sleep_until(clock.instant_at(TimestampNs(2_000_000_000))).await;
        assert_eq!(clock.now(), TimestampNs(2_000_000_000));
    }
}
