//! The clock every reading is stamped with.

use softtouch_schemas::TimestampNs;
use std::fmt::Debug;

/// Monotonic time, injected into every driver.
pub trait Clock: Send + Sync + Debug {
    /// Now, in nanoseconds since this clock's epoch.
    fn now(&self) -> TimestampNs;
}

/// Time from tokio's clock: `start` plus the time since the clock was made.
///
/// A run's device time continues across a resume: the resumed job's clock starts where
/// the run's time left off ([`TokioClock::starting_at`]), so the sensor's and the
/// camera's sample grids, the drift and every timestamp carry on as if the run had not
/// stopped. On a rig this is the host's monotonic clock. In simulation the runtime is started
/// paused (`tokio::time::pause`, `start_paused`): time then stands still while code
/// runs and jumps to the next timer when every task waits, so a night of simulated
/// collection takes as long as its computation, and the same seed gives the same bytes.
#[derive(Debug, Clone, Copy)]
pub struct TokioClock {
    /// The tokio instant at which this clock read `start`.
    made: tokio::time::Instant,
    /// What the clock read when it was made.
    start: TimestampNs,
}

impl TokioClock {
    /// A clock that reads 0 now. Must be called inside a tokio runtime.
    #[must_use]
    pub fn new() -> Self {
        Self::starting_at(TimestampNs::ZERO)
    }

    /// A clock that reads `start` now (a resumed run's clock). Must be called inside a
    /// tokio runtime. An offset, not an earlier epoch: a monotonic instant hours
    /// before now may not exist on a host booted minutes ago.
    #[must_use]
    pub fn starting_at(start: TimestampNs) -> Self {
        Self {
            made: tokio::time::Instant::now(),
            start,
        }
    }

    /// The tokio instant to `sleep_until` for timestamp `t` of this clock: a sleep
    /// until it ends at `t` rounded up to this clock's next whole millisecond (a time
    /// before the clock's start: at once).
    ///
    /// Why not `t` itself: tokio's timer counts whole milliseconds from its runtime's
    /// start and rounds a deadline up to the end of its millisecond, and on a paused
    /// clock a sleep ends exactly on that tick. A runtime paused some real time after
    /// it was built puts this clock's epoch a fraction of a millisecond off that grid,
    /// so the tick a sleep until `t` ends on would depend on that fraction, and virtual
    /// time on the real time the process took to start (two runs of a seed would
    /// diverge). Asking for 999 999 ns before the whole millisecond at or after `t`
    /// ends the sleep on that millisecond whatever the fraction: virtual time is a
    /// function of the run alone. On a running clock the wake-up is at most that
    /// fraction (< 1 ms) before `t`, as tokio's rounding allows anyway.
    #[must_use]
    pub fn instant_at(&self, t: TimestampNs) -> tokio::time::Instant {
        const MS: u64 = 1_000_000;
        let whole_ms =
            t.0.saturating_sub(self.start.0)
                .div_ceil(MS)
                .saturating_mul(MS);
        // Beyond what an instant holds (centuries): as far as tokio's timer goes.
        let at = self
            .made
            .checked_add(std::time::Duration::from_nanos(whole_ms))
            .unwrap_or_else(|| self.made + std::time::Duration::from_secs(86_400 * 365 * 30));
        at.checked_sub(std::time::Duration::from_nanos(MS - 1))
            .unwrap_or(at)
    }
}

impl Default for TokioClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for TokioClock {
    fn now(&self) -> TimestampNs {
        let ns = u64::try_from(self.made.elapsed().as_nanos()).unwrap_or(u64::MAX);
        TimestampNs(self.start.0.saturating_add(ns))
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

    /// Sleeps end on the clock's whole milliseconds, the same ones whatever real time
    /// passed between building the runtime and pausing it (that phase moved them).
    #[test]
    fn sleeps_end_on_the_same_virtual_times_whatever_the_runtime_phase() {
        let landings = |real_us: u64, paused_from_start: bool| {
            let mut b = tokio::runtime::Builder::new_current_thread();
            b.enable_all().start_paused(paused_from_start);
            let rt = b.build().expect("runtime");
            rt.block_on(async {
                if !paused_from_start {
                    std::thread::sleep(Duration::from_micros(real_us));
                    tokio::time::pause();
                }
                let clock = TokioClock::starting_at(TimestampNs(7_000_000_000));
                let mut ends = Vec::new();
                for dt_ns in [
                    0, 1_000_000, 2_500_000, 2_999_999, 5_000_001, 7_400_000, 0, 1,
                ] {
                    let t = TimestampNs(clock.now().0 + dt_ns);
                    tokio::time::sleep_until(clock.instant_at(t)).await;
                    ends.push(clock.now().0 - t.0);
                }
                ends
            })
        };
        let expect = vec![0, 0, 500_000, 1, 999_999, 600_000, 0, 999_999];
        assert_eq!(landings(0, true), expect);
        for real_us in [0, 1, 300, 700, 999, 1_500] {
            assert_eq!(landings(real_us, false), expect, "paused {real_us} µs late");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_clock_started_later_continues_from_its_start() {
        let start = TimestampNs(3_600_000_000_000);
        let clock = TokioClock::starting_at(start);
        assert_eq!(clock.now(), start);
        tokio::time::sleep(Duration::from_millis(250)).await;
        assert_eq!(clock.now(), TimestampNs(3_600_250_000_000));
        tokio::time::sleep_until(clock.instant_at(TimestampNs(3_601_000_000_000))).await;
        assert_eq!(clock.now(), TimestampNs(3_601_000_000_000));
        // Before the start: already past, no wait.
        let before = clock.now();
        tokio::time::sleep_until(clock.instant_at(TimestampNs(5))).await;
        assert_eq!(clock.now(), before);
        // Saturates instead of wrapping at the end of time.
        let end = TokioClock::starting_at(TimestampNs(u64::MAX - 1));
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert_eq!(end.now(), TimestampNs(u64::MAX));
    }
}
