//! Stamps for RDT records from their sequence numbers rather than from when the host
//! read them: datagrams that queue in the socket while the host is busy arrive (are
//! read) together, yet were sampled a period apart.
//!
//! A record `u` (its sequence, unwrapped past 2^32) was sampled at `u·T + o`, with T
//! the sensor's period and `o` an offset the host does not know. Every datagram gives
//! an upper bound on `o`: it cannot arrive before its newest record was sampled, so
//! `o ≤ arrival − u·T`. The least-delayed datagram gives the tightest bound; the
//! smallest bound over the last few seconds is the offset used (so the estimate
//! follows a drift between the sensor's clock and the host's). Stamps never go
//! backwards.
//!
//! The period is the configured one, so it must be the sensor's: a bound that drifts
//! steadily says it is not. The least bound of the stream's first second against the
//! least of the latest window, over the records between them, is how far the period is
//! off ([`SequenceStamps::rate_error`]); the client refuses a stream more than a few
//! percent off rather than stamp it wrong (875 Hz taken for 1000 Hz runs 125 ms early
//! per second).

use std::collections::VecDeque;

/// How far back the smallest bound is taken, ns: long enough to contain some datagram
/// that was not delayed, short enough to follow clock drift (100 ppm is 0.2 ms here).
const WINDOW_NS: u64 = 2_000_000_000;

/// Sequence-based stamps for one stream.
#[derive(Debug, Clone, Default)]
pub(crate) struct SequenceStamps {
    period_ns: f64,
    /// The last record's raw sequence and its unwrapped value.
    last: Option<(u32, u64)>,
    /// `(arrival ns, bound ns, record)`, bounds increasing from front to back (the
    /// front is the window's smallest).
    bounds: VecDeque<(u64, f64, u64)>,
    last_stamp_ns: u64,
    /// The stream's first arrival, and its least bound over the first second with
    /// that bound's record.
    first: Option<(u64, f64, u64)>,
}

/// How long the stream must have run before its rate is judged, ns.
const RATE_AFTER_NS: u64 = 3_000_000_000;
/// How long the first bound is taken over, ns.
const FIRST_NS: u64 = 1_000_000_000;

impl SequenceStamps {
    /// A stream at `rate_hz` (a rate that is not positive and finite stamps every
    /// record with its datagram's arrival).
    pub(crate) fn new(rate_hz: f64) -> Self {
        Self {
            period_ns: if rate_hz.is_finite() && rate_hz > 0.0 {
                1e9 / rate_hz
            } else {
                0.0
            },
            ..Self::default()
        }
    }

    /// Forgets the stream (a new start restarts its sequence).
    pub(crate) fn reset(&mut self) {
        self.last = None;
        self.bounds.clear();
        self.first = None;
    }

    /// How far the sensor's period is from the configured one, as a fraction of the
    /// configured period (`rate_configured / rate_measured − 1`: 0.14 for a sensor at
    /// 875 Hz configured as 1000 Hz, −0.17 for one at 1200 Hz), once the stream has
    /// run [`RATE_AFTER_NS`]; `None` before, or without a rate.
    pub(crate) fn rate_error(&self) -> Option<f64> {
        let (t0, b0, u0) = self.first?;
        let &(_, b, u) = self.bounds.front()?;
        let &(newest, _, _) = self.bounds.back()?;
        if self.period_ns == 0.0 || newest.saturating_sub(t0) < RATE_AFTER_NS || u <= u0 {
            return None;
        }
        // bound = arrival − u·T grows by (T_true − T) per record.
        let per_record_ns = (b - b0) / (u - u0) as f64;
        Some(per_record_ns / self.period_ns)
    }

    /// The unwrapped sequence of `raw`, which follows the last one given (the caller
    /// drops records that go backwards).
    pub(crate) fn unwrap(&mut self, raw: u32) -> u64 {
        let u = match self.last {
            Some((last_raw, last_u)) => last_u + u64::from(raw.wrapping_sub(last_raw)),
            None => u64::from(raw),
        };
        self.last = Some((raw, u));
        u
    }

    /// Takes a datagram that arrived at `arrival_ns` with its newest record `newest`
    /// (unwrapped).
    pub(crate) fn arrived(&mut self, arrival_ns: u64, newest: u64) {
        if self.period_ns == 0.0 {
            return;
        }
        let bound = arrival_ns as f64 - newest as f64 * self.period_ns;
        match &mut self.first {
            None => self.first = Some((arrival_ns, bound, newest)),
            Some((t0, b0, u0)) => {
                if arrival_ns.saturating_sub(*t0) < FIRST_NS && bound < *b0 {
                    (*b0, *u0) = (bound, newest);
                }
            }
        }
        while self.bounds.back().is_some_and(|&(_, b, _)| b >= bound) {
            self.bounds.pop_back();
        }
        self.bounds.push_back((arrival_ns, bound, newest));
        while self
            .bounds
            .front()
            .is_some_and(|&(t, _, _)| t.saturating_add(WINDOW_NS) < arrival_ns)
        {
            self.bounds.pop_front();
        }
    }

    /// When record `u` was sampled, ns on the host's clock; `arrival_ns` is its
    /// datagram's arrival (the stamp never lies after it).
    pub(crate) fn stamp(&mut self, u: u64, arrival_ns: u64) -> u64 {
        let at = match self.bounds.front() {
            Some(&(_, offset, _)) if self.period_ns > 0.0 => {
                let t = u as f64 * self.period_ns + offset;
                if t.is_finite() && t > 0.0 {
                    (t.round() as u64).min(arrival_ns)
                } else {
                    arrival_ns
                }
            }
            _ => arrival_ns,
        };
        let at = at.max(self.last_stamp_ns);
        self.last_stamp_ns = at;
        at
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn queued_datagrams_are_stamped_a_period_apart_not_when_read() {
        let mut s = SequenceStamps::new(1000.0);
        // Records 1..=3 on time, then 4..=8 queued and read together at 10 ms.
        let mut stamps = Vec::new();
        for (seq, arrival) in [(1, MS), (2, 2 * MS), (3, 3 * MS)]
            .into_iter()
            .chain((4..=8).map(|q| (q, 10 * MS)))
        {
            let u = s.unwrap(seq);
            s.arrived(arrival, u);
            stamps.push(s.stamp(u, arrival));
        }
        assert_eq!(
            stamps,
            [1, 2, 3, 4, 5, 6, 7, 8].map(|k| k * MS),
            "sampled 1 ms apart"
        );
    }

    #[test]
    fn the_offset_follows_the_least_delayed_datagram_and_stamps_never_go_back() {
        let mut s = SequenceStamps::new(1000.0);
        // The first datagram was late by 5 ms; the next ones are on time.
        let u = s.unwrap(1);
        s.arrived(6 * MS, u);
        let first = s.stamp(u, 6 * MS);
        assert_eq!(first, 6 * MS);
        let u = s.unwrap(2);
        s.arrived(2 * MS + 1, u);
        // The better bound says record 2 was sampled at 2 ms; the stamp stays at the
        // previous one rather than going back.
        assert_eq!(s.stamp(u, 2 * MS + 1), 6 * MS);
        let u = s.unwrap(10);
        s.arrived(10 * MS + 1, u);
        assert_eq!(s.stamp(u, 10 * MS + 1), 10 * MS + 1);
    }

    #[test]
    fn sequences_unwrap_past_two_to_the_32_and_a_reset_starts_over() {
        let mut s = SequenceStamps::new(7000.0);
        assert_eq!(s.unwrap(u32::MAX - 1), u64::from(u32::MAX - 1));
        assert_eq!(s.unwrap(u32::MAX), u64::from(u32::MAX));
        assert_eq!(s.unwrap(1), (1u64 << 32) + 1);
        s.reset();
        assert_eq!(s.unwrap(1), 1);
    }

    /// A stream of `rate_hz` records a second, one per datagram, each late by up to
    /// 3 ms (a host busy now and then), read by stamps configured for 1000 Hz.
    fn stream(rate_hz: f64, seconds: f64) -> SequenceStamps {
        let mut s = SequenceStamps::new(1000.0);
        let n = (rate_hz * seconds) as u64;
        for k in 1..=n {
            let sampled = k as f64 * 1e9 / rate_hz;
            let late = ((k * 7919) % 3000) as f64 * 1000.0;
            let u = s.unwrap(u32::try_from(k).unwrap_or(u32::MAX));
            s.arrived((sampled + late) as u64 + 5 * MS, u);
        }
        s
    }

    #[test]
    fn a_stream_at_another_rate_than_configured_shows_in_its_drifting_bound() {
        assert_eq!(stream(1000.0, 2.0).rate_error(), None, "too early to judge");
        let right = stream(1000.0, 4.0).rate_error().expect("judged");
        assert!(right.abs() < 0.005, "{right}");
        // 875 Hz read as 1000 Hz: the period is 1/875 s, 14 % longer.
        let slow = stream(875.0, 4.0).rate_error().expect("judged");
        assert!((slow - (1000.0 / 875.0 - 1.0)).abs() < 0.005, "{slow}");
        let fast = stream(1200.0, 4.0).rate_error().expect("judged");
        assert!((fast - (1000.0 / 1200.0 - 1.0)).abs() < 0.005, "{fast}");
        // 100 ppm of clock drift is no rate error.
        let drift = stream(1000.1, 4.0).rate_error().expect("judged");
        assert!(drift.abs() < 0.001, "{drift}");
        let mut s = stream(875.0, 4.0);
        s.reset();
        assert_eq!(s.rate_error(), None, "a new stream is judged anew");
        assert_eq!(SequenceStamps::new(0.0).rate_error(), None);
    }

    #[test]
    fn without_a_rate_a_record_is_stamped_on_arrival() {
        let mut s = SequenceStamps::new(0.0);
        let u = s.unwrap(5);
        s.arrived(42, u);
        assert_eq!(s.stamp(u, 42), 42);
        let mut nan = SequenceStamps::new(f64::NAN);
        let u = nan.unwrap(5);
        nan.arrived(7, u);
        assert_eq!(nan.stamp(u, 7), 7);
    }
}
