use super::*;
use softtouch_schemas::FtStatus;
use std::time::Duration;

fn reading(i: u32, f: f64) -> FtReading {
    FtReading {
        t: TimestampNs(u64::from(i) * 1_000_000),
        rdt_sequence: i,
        ft_sequence: i,
        status: FtStatus::OK,
        wrench_in_sensor: Wrench::from_array([f, 0.0, 0.0, 0.0, 0.0, 0.0]),
    }
}

const RULES: WindowRules = WindowRules {
    min_readings: 3,
    range: [10.0, 10.0, 10.0, 1.0, 1.0, 1.0],
};

#[test]
fn a_clean_window_gives_mean_std_and_skew() {
    let w: Vec<_> = (0..4).map(|i| reading(i, f64::from(i))).collect();
    let s = window_stats(&w, TimestampNs(1_400_000), &RULES);
    assert_eq!(s.reject, None);
    assert!((s.mean.force_n[0] - 1.5).abs() < 1e-12);
    assert!((s.std.force_n[0] - 1.25f64.sqrt()).abs() < 1e-12);
    assert_eq!(s.skew_ns, 400_000);
    assert_eq!(s.count, 4);
}

#[test]
fn each_defect_of_a_window_has_its_reason() {
    let ok: Vec<_> = (0..4).map(|i| reading(i, 1.0)).collect();
    assert_eq!(
        window_stats(&ok[..2], TimestampNs(0), &RULES).reject,
        Some(RejectReason::ShortWindow)
    );
    assert_eq!(
        window_stats(&[], TimestampNs(0), &RULES).reject,
        Some(RejectReason::ShortWindow)
    );
    let mut gap = ok.clone();
    gap.remove(1);
    assert_eq!(
        window_stats(&gap, TimestampNs(0), &RULES).reject,
        Some(RejectReason::MissingReadings)
    );
    let mut fault = ok.clone();
    fault[2].status = FtStatus(0x0010_0000);
    assert_eq!(
        window_stats(&fault, TimestampNs(0), &RULES).reject,
        Some(RejectReason::SensorFault)
    );
    let mut warn = ok.clone();
    warn[2].status = FtStatus::MONITOR_LATCHED;
    assert_eq!(
        window_stats(&warn, TimestampNs(0), &RULES).reject,
        None,
        "a warning is not a fault"
    );
    let mut sat = ok.clone();
    sat[3].wrench_in_sensor.torque_nm[2] = -1.0;
    assert_eq!(
        window_stats(&sat, TimestampNs(0), &RULES).reject,
        Some(RejectReason::Saturated)
    );
    let mut nan = ok.clone();
    nan[0].wrench_in_sensor.force_n[1] = f64::NAN;
    let s = window_stats(&nan, TimestampNs(0), &RULES);
    assert_eq!(s.reject, Some(RejectReason::NonFinite));
    assert!(
        s.mean
            .to_array()
            .iter()
            .chain(&s.std.to_array())
            .all(|v| v.is_finite()),
        "a rejected window still has storable statistics: {s:?}"
    );
    assert!(
        (s.mean.force_n[0] - 1.0).abs() < 1e-12,
        "over the finite readings"
    );
    let mut inf = ok;
    inf[3].wrench_in_sensor.torque_nm[0] = f64::NEG_INFINITY;
    assert_eq!(
        window_stats(&inf, TimestampNs(0), &RULES).reject,
        Some(RejectReason::NonFinite)
    );
    let huge: Vec<_> = (0..4).map(|i| reading(i, f64::MAX)).collect();
    let s = window_stats(
        &huge,
        TimestampNs(0),
        &WindowRules {
            min_readings: 1,
            range: [f64::INFINITY; 6],
        },
    );
    assert_eq!(
        s.reject,
        Some(RejectReason::SensorFault),
        "the sums overflow"
    );
    assert!(s.mean.to_array().iter().all(|v| v.is_finite()));
}

#[test]
fn sequence_numbers_may_wrap_inside_a_window() {
    let w: Vec<_> = [u32::MAX - 1, u32::MAX, 0, 1]
        .iter()
        .enumerate()
        .map(|(k, &seq)| FtReading {
            rdt_sequence: seq,
            ..reading(u32::try_from(k).unwrap_or(0), 1.0)
        })
        .collect();
    assert_eq!(window_stats(&w, TimestampNs(0), &RULES).reject, None);
}

#[test]
fn a_constant_window_has_zero_spread_not_nan() {
    let w: Vec<_> = (0..5).map(|i| reading(i, 1e300)).collect();
    let s = window_stats(
        &w,
        TimestampNs(0),
        &WindowRules {
            min_readings: 1,
            range: [f64::INFINITY; 6],
        },
    );
    assert!(s.std.to_array().iter().all(|v| v.is_finite()));
}

#[test]
fn window_bounds_saturate_at_the_epoch() {
    assert_eq!(
        window_bounds(TimestampNs(10), DurationNs(100)),
        (TimestampNs(0), TimestampNs(60))
    );
}

/// A sensor that delivers the given packets 10 ms apart, then nothing.
struct Packets(std::collections::VecDeque<Vec<FtReading>>);

#[async_trait::async_trait]
impl ForceSensor for Packets {
    async fn start(&mut self) -> Result<(), DeviceError> {
        Ok(())
    }
    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        tokio::time::sleep(Duration::from_millis(10)).await;
        match self.0.pop_front() {
            Some(p) => {
                out.extend_from_slice(&p);
                Ok(p.len())
            }
            None => std::future::pending().await,
        }
    }
    async fn bias(&mut self) -> Result<(), DeviceError> {
        Ok(())
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        Ok(())
    }
    fn lost_readings(&self) -> u64 {
        0
    }
}

/// The guard's verdict on `packets`, on virtual time.
fn guard_on(packets: Vec<Vec<FtReading>>) -> (GuardTrip, Duration) {
    crate::testing::block_on(async {
        tokio::time::pause();
        let t0 = tokio::time::Instant::now();
        let stream = FtStream::spawn(Box::new(Packets(packets.into())), 64)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let trip = stream
            .guard(&ForceGuard {
                max_force_n: 15.0,
                max_torque_nm: 0.8,
                stale: Duration::from_millis(100),
            })
            .await;
        let after = t0.elapsed();
        let _ = stream.shutdown().await;
        (trip, after)
    })
}

#[test]
fn the_guard_sees_a_spike_in_the_middle_of_a_packet() {
    let mut spiked: Vec<_> = (0..5).map(|i| reading(i, 1.0)).collect();
    spiked[2].wrench_in_sensor.force_n[2] = 30.0;
    let expected = spiked[2];
    let (trip, _) = guard_on(vec![(10..15).map(|i| reading(i, 1.0)).collect(), spiked]);
    assert_eq!(
        trip,
        GuardTrip::OverLimit(expected),
        "not the packet's newest"
    );
}

#[test]
fn the_guard_trips_on_nan_and_on_a_stale_stream() {
    let mut nan: Vec<_> = (0..5).map(|i| reading(i, 1.0)).collect();
    nan[1].wrench_in_sensor.torque_nm[1] = f64::NAN;
    let (trip, _) = guard_on(vec![nan]);
    assert!(
        matches!(trip, GuardTrip::NonFinite(r) if r.rdt_sequence == 1),
        "{trip:?}"
    );

    let (trip, after) = guard_on(vec![(0..5).map(|i| reading(i, 1.0)).collect()]);
    assert_eq!(
        trip,
        GuardTrip::Stale {
            silent: Duration::from_millis(100)
        }
    );
    // The last packet came at 10 ms; stale 100 ms after it.
    assert!(after >= Duration::from_millis(110), "{after:?}");
}

#[test]
fn a_frame_is_covered_only_by_readings_close_on_both_sides() {
    // Readings every 1 ms at 0..=9 ms.
    let w: Vec<_> = (0..10).map(|i| reading(i, 1.0)).collect();
    let skew = DurationNs(1_000_000);
    // Between two readings, or on one: covered.
    assert!(frame_covered(&w, TimestampNs(4_500_000), skew));
    assert!(frame_covered(&w, TimestampNs(4_000_000), DurationNs(0)));
    // Half a period from each neighbour needs a limit of at least half a period.
    assert!(!frame_covered(
        &w,
        TimestampNs(4_500_000),
        DurationNs(400_000)
    ));
    // Past the newest reading or before the oldest: one side is missing.
    assert!(!frame_covered(&w, TimestampNs(9_500_000), skew));
    assert!(!frame_covered(&w[5..], TimestampNs(4_900_000), skew));
    // A hole in the stream around the frame (sequence numbers intact, as when the
    // host stalled): no reading within the limit before the frame.
    let mut hole = w.clone();
    hole.retain(|r| !(3..=6).contains(&r.rdt_sequence));
    assert!(!frame_covered(&hole, TimestampNs(6_500_000), skew));
    // The nearest reading before it is at 2 ms, 4.5 ms away.
    assert!(!frame_covered(
        &hole,
        TimestampNs(6_500_000),
        DurationNs(4_499_999)
    ));
    assert!(frame_covered(
        &hole,
        TimestampNs(6_500_000),
        DurationNs(4_500_000)
    ));
    // No readings at all, and extreme stamps, neither panic nor count as covered.
    assert!(!frame_covered(&[], TimestampNs(0), skew));
    assert!(!frame_covered(
        &w,
        TimestampNs(u64::MAX),
        DurationNs(u64::MAX - 1)
    ));
    assert!(!frame_covered(
        &w,
        TimestampNs(u64::MAX),
        DurationNs(u64::MAX)
    ));
}

#[test]
fn the_clock_skew_reason_has_a_stored_name_that_reads_back() {
    assert_eq!(RejectReason::ClockSkew.as_str(), "clock_skew");
    assert_eq!("clock_skew".parse(), Ok(RejectReason::ClockSkew));
}
