//! The second core, for the two halves of one frame's work (the simulated camera's
//! drawing, the model's preprocessing and its larger convolutions), and for a grasp
//! frame's canvas while the caller works out the finger's lattice.
//!
//! A frame's half is a few hundred microseconds of work. Starting a thread for it
//! cost 85–140 µs on the 2-core VMs this runs on, and waking a sleeping pool worker
//! 40 µs: most of that is the idle core waking up. So the helper is one rayon worker
//! that, after a job, keeps polling for the next one for [`KEEP_WARM`] (a job then
//! starts within a few microseconds) and only then goes to sleep. During a grasp
//! trial, frames come every few milliseconds and the core stays awake; otherwise it
//! sleeps again within milliseconds.
//!
//! The helper pays only while its core is free. When other work holds the cores
//! (another process, more threads than cores), a half handed to it waits for the
//! scheduler, a time slice of milliseconds at every join: a grasp trial beside a
//! 2-core build ran about 30 ms a cycle instead of 1. So a half handed to a polling
//! helper that starts [`LATE_START`] or more later sends callers back to doing both
//! halves themselves for [`BACK_OFF`], after which the helper is tried again. (A
//! sleeping helper's start is not judged: waking it may take that long on a VM.)
//! None of this changes what the halves compute.
//!
//! # Against `rayon::join`
//! Measured here (`cargo bench -p softtouch-sim --bench second_core`, 2-core VM,
//! 2026-11-27): two halves of 100 µs joined from a thread outside any pool, as the
//! camera, the predictor and the grasp loop call it, take 175 µs with a 2 ms gap
//! between joins (a grasp trial's frame period) and 107 µs back to back; the same
//! through `rayon::join` on a 2-thread pool take 513 µs and 241 µs, slower than doing
//! both halves in turn (202 µs): from outside the pool rayon hands the whole join to a
//! worker and sleeps until it is done, so every join pays two wake-ups. Empty halves
//! cost 0.27 µs here against 12 µs (back to back) and 26 µs against 256 µs (2 ms
//! gap). So the helper stays. Beside other work its 5 ms of polling competes for a
//! core only until a late start sends the halves home ([`BACK_OFF`]): the last session
//! measured a closed water trial beside two busy loops at 4.3 ms a cycle with the back
//! off and 27.6 ms without.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// How long the helper keeps polling for work after its last job.
pub const KEEP_WARM: Duration = Duration::from_millis(5);

/// A half that starts this long after it was handed to the polling helper means the
/// helper's core is taken (a polling helper starts one within microseconds).
pub const LATE_START: Duration = Duration::from_millis(1);

/// How long callers do both halves themselves after a late start.
pub const BACK_OFF: Duration = Duration::from_millis(200);

/// The helper: a one-thread pool and whether its poller is running.
#[derive(Debug)]
pub struct SecondCore {
    pool: rayon::ThreadPool,
    keep_warm: Duration,
    /// A poller job is running (or about to) on the helper.
    warm: Arc<AtomicBool>,
    /// A caller's half is in flight: another caller does both of its halves itself
    /// (callers in parallel already keep the cores busy).
    busy: AtomicBool,
    /// See [`LATE_START`] and [`BACK_OFF`].
    late_start: Duration,
    back_off: Duration,
    /// Callers do both halves until this time, ns after `epoch` (0: no back-off).
    back_off_until_ns: AtomicU64,
    epoch: Instant,
}

/// The process's second core, or `None` on a one-core machine (or where no thread
/// can be started): callers then do both halves themselves.
pub fn second_core() -> Option<&'static SecondCore> {
    static HELPER: OnceLock<Option<SecondCore>> = OnceLock::new();
    HELPER
        .get_or_init(|| {
            let cores = std::thread::available_parallelism().map_or(1, usize::from);
            if cores < 2 {
                return None;
            }
            SecondCore::new(KEEP_WARM).ok()
        })
        .as_ref()
}

/// Runs `here` on the calling thread (so it need not be `Send`) and `there` on the
/// second core when there is one and it is free, else both here; returns when both
/// are done. A panic in either is resumed here.
pub fn join(here: impl FnOnce(), there: impl FnOnce() + Send) {
    match second_core() {
        Some(core) => core.join(here, there),
        None => {
            here();
            there();
        }
    }
}

impl SecondCore {
    /// A helper thread that polls for work for `keep_warm` after each job, with the
    /// default [`LATE_START`] and [`BACK_OFF`].
    pub fn new(keep_warm: Duration) -> Result<Self, rayon::ThreadPoolBuildError> {
        Self::with_back_off(keep_warm, LATE_START, BACK_OFF)
    }

    /// [`Self::new`], with callers doing both halves for `back_off` after a half
    /// started `late_start` or more after it was handed over.
    pub fn with_back_off(
        keep_warm: Duration,
        late_start: Duration,
        back_off: Duration,
    ) -> Result<Self, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .thread_name(|_| "second-core".into())
            .build()?;
        Ok(Self {
            pool,
            keep_warm,
            warm: Arc::new(AtomicBool::new(false)),
            busy: AtomicBool::new(false),
            late_start,
            back_off,
            back_off_until_ns: AtomicU64::new(0),
            epoch: Instant::now(),
        })
    }

    /// See [`join`].
    pub fn join(&self, here: impl FnOnce(), there: impl FnOnce() + Send) {
        if self.backing_off() || self.busy.swap(true, Ordering::Acquire) {
            here();
            there();
            return;
        }
        // Clear `busy` even when a half panics (the scope resumes the panic).
        let _free = Free(&self.busy);
        let polling = self.warm.swap(true, Ordering::AcqRel);
        if !polling {
            self.pool
                .spawn(poll_for_work(Arc::clone(&self.warm), self.keep_warm));
        }
        let handed = Instant::now();
        let start_ns = AtomicU64::new(0);
        self.pool.in_place_scope(|s| {
            s.spawn(|_| {
                start_ns.store(nanos(handed.elapsed()), Ordering::Relaxed);
                there();
            });
            here();
        });
        if polling && start_ns.load(Ordering::Relaxed) >= nanos(self.late_start) {
            let until = nanos(self.epoch.elapsed().saturating_add(self.back_off));
            self.back_off_until_ns
                .store(until.max(1), Ordering::Relaxed);
        }
    }

    /// Whether callers do both halves themselves now (see [`BACK_OFF`]).
    fn backing_off(&self) -> bool {
        let until = self.back_off_until_ns.load(Ordering::Relaxed);
        until != 0 && nanos(self.epoch.elapsed()) < until
    }
}

/// A duration in whole nanoseconds, saturating (584 years).
fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// Clears its flag when dropped.
struct Free<'a>(&'a AtomicBool);

impl Drop for Free<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// The poller: runs the jobs callers inject as they come, until none came for
/// `keep_warm`, then clears `warm`. Correctness never depends on it: a job injected
/// while no poller runs is run by the pool's worker when it wakes.
fn poll_for_work(warm: Arc<AtomicBool>, keep_warm: Duration) -> impl FnOnce() + Send + 'static {
    move || {
        let mut last_job = Instant::now();
        let mut spins = 0u32;
        loop {
            if matches!(rayon::yield_now(), Some(rayon::Yield::Executed)) {
                last_job = Instant::now();
                continue;
            }
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            // Reading the clock costs tens of nanoseconds: not on every spin.
            if spins.is_multiple_of(64) && last_job.elapsed() >= keep_warm {
                warm.store(false, Ordering::Release);
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_halves_run_and_write_their_own_data() {
        let mut data = vec![0u32; 1000];
        for round in 1..=50u32 {
            let (a, b) = data.split_at_mut(400);
            join(
                || a.iter_mut().for_each(|v| *v += round),
                || b.iter_mut().for_each(|v| *v += 2 * round),
            );
        }
        let total: u32 = (1..=50).sum();
        assert!(data[..400].iter().all(|v| *v == total));
        assert!(data[400..].iter().all(|v| *v == 2 * total));
    }

    #[test]
    fn callers_on_many_threads_all_finish() {
        // The helper takes one caller's half at a time; the others do both halves.
        let sums: Vec<u64> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4u64)
                .map(|t| {
                    s.spawn(move || {
                        let mut total = 0u64;
                        for i in 0..200u64 {
                            let (mut x, mut y) = (0u64, 0u64);
                            join(|| x = t + i, || y = 2 * (t + i));
                            total += x + y;
                        }
                        total
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap_or(0)).collect()
        });
        for (t, sum) in sums.iter().enumerate() {
            let want: u64 = (0..200u64).map(|i| 3 * (t as u64 + i)).sum();
            assert_eq!(*sum, want, "thread {t}");
        }
    }

    #[test]
    fn a_panic_in_the_far_half_reaches_the_caller_and_the_helper_stays_usable() {
        let caught = std::panic::catch_unwind(|| join(|| (), || panic!("far half")));
        assert!(caught.is_err());
        let mut ran = false;
        join(|| (), || ran = true);
        assert!(ran);
    }

    /// The thread each half ran on, for `joins` joins on `core`.
    fn where_halves_ran(core: &SecondCore, joins: usize) -> Vec<(bool, bool)> {
        let caller = std::thread::current().id();
        (0..joins)
            .map(|_| {
                let (mut here, mut there) = (None, None);
                core.join(
                    || here = Some(std::thread::current().id()),
                    || there = Some(std::thread::current().id()),
                );
                (here == Some(caller), there == Some(caller))
            })
            .collect()
    }

    #[test]
    fn a_late_start_sends_the_halves_back_to_the_caller_for_the_back_off() {
        // Every start on a polling helper counts as late: the first join (which
        // wakes the helper, and is not judged) and the next use it, then the
        // (hour-long) back-off does both halves on the caller.
        let sent_back = |ran: &[(bool, bool)]| {
            let first = ran.iter().position(|r| *r == (true, true));
            first.is_some_and(|i| i >= 1 && ran[i..].iter().all(|r| *r == (true, true)))
        };
        let taken = SecondCore::with_back_off(KEEP_WARM, Duration::ZERO, Duration::from_secs(3600))
            .expect("a thread");
        let ran = where_halves_ran(&taken, 10);
        assert!(ran.iter().all(|r| r.0), "{ran:?}");
        assert!(sent_back(&ran), "{ran:?}");
        // A back-off of zero tries the helper again at once.
        let retried =
            SecondCore::with_back_off(KEEP_WARM, Duration::ZERO, Duration::ZERO).expect("a thread");
        assert!(
            where_halves_ran(&retried, 5)
                .iter()
                .all(|r| *r == (true, false))
        );
        // No start is an hour late: every far half runs on the helper.
        let free = SecondCore::with_back_off(KEEP_WARM, Duration::from_secs(3600), Duration::MAX)
            .expect("a thread");
        assert!(
            where_halves_ran(&free, 20)
                .iter()
                .all(|r| *r == (true, false))
        );
        // An unrepresentable back-off end saturates instead of wrapping into the past.
        let forever =
            SecondCore::with_back_off(KEEP_WARM, Duration::ZERO, Duration::MAX).expect("a thread");
        let ran = where_halves_ran(&forever, 10);
        assert!(sent_back(&ran), "{ran:?}");
    }

    #[test]
    fn with_no_keep_warm_the_poller_stops_at_once_and_every_join_still_runs() {
        let core = SecondCore::new(Duration::ZERO).expect("a thread");
        let mut x = 0;
        for _ in 0..100 {
            core.join(|| (), || x += 1);
        }
        assert_eq!(x, 100);
    }
}
