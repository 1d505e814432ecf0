//! The force/torque stream of a run and the label window of a sample.
//!
//! The sensor runs in its own task, appending every reading (stamped on the injected
//! clock) to a bounded ring. A sample takes the readings in a window around its
//! frame's time. Nothing is dropped silently: readings lost on the link are counted
//! by the driver (and show as sequence gaps, which reject a window); the ring holds
//! seconds of readings, far longer than any window waits.

use softtouch_drivers::{DeviceError, ForceSensor};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{DurationNs, FtReading, TimestampNs, Wrench};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use tokio::sync::{Notify, watch};
use tokio::task::JoinHandle;

#[derive(Debug, Default)]
struct Ring {
    readings: VecDeque<FtReading>,
    capacity: usize,
    /// Readings received since the start.
    received: u64,
    /// The last error of the sensor, cleared by the next good read.
    error: Option<DeviceError>,
    errors: u64,
}

/// The sensor's stream, read by its own task.
pub struct FtStream {
    ring: Arc<Mutex<Ring>>,
    notify: Arc<Notify>,
    stop: watch::Sender<bool>,
    task: JoinHandle<Box<dyn ForceSensor>>,
}

impl std::fmt::Debug for FtStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FtStream")
            .field("ring", &self.ring)
            .finish_non_exhaustive()
    }
}

fn lock(ring: &Mutex<Ring>) -> MutexGuard<'_, Ring> {
    // A panic while holding this lock is a bug elsewhere; the data is plain and still usable.
    ring.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl FtStream {
    /// Start the sensor and its reader task; keep up to `capacity` readings.
    pub async fn spawn(
        mut sensor: Box<dyn ForceSensor>,
        capacity: usize,
    ) -> Result<Self, DeviceError> {
        sensor.start().await?;
        let ring = Arc::new(Mutex::new(Ring {
            capacity: capacity.max(1),
            ..Ring::default()
        }));
        let notify = Arc::new(Notify::new());
        let (stop, mut stopped) = watch::channel(false);
        let task = {
            let ring = Arc::clone(&ring);
            let notify = Arc::clone(&notify);
            tokio::spawn(async move {
                let mut batch = Vec::new();
                loop {
                    tokio::select! {
                        biased;
                        _ = stopped.changed() => break,
                        result = sensor.read(&mut batch) => {
                            let failed = result.is_err();
                            {
                                let mut r = lock(&ring);
                                match result {
                                    Ok(_) => {
                                        r.error = None;
                                        r.received += batch.len() as u64;
                                        for reading in batch.drain(..) {
                                            // The ring holds seconds of readings; older ones
                                            // are past any window still to be taken.
                                            if r.readings.len() == r.capacity {
                                                r.readings.pop_front();
                                            }
                                            r.readings.push_back(reading);
                                        }
                                    }
                                    Err(e) => {
                                        r.errors += 1;
                                        r.error = Some(e);
                                        batch.clear();
                                    }
                                }
                            }
                            notify.notify_waiters();
                            if failed {
                                // Do not spin on a dead link; the procedure sees the error.
                                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                            }
                        }
                    }
                }
                sensor
            })
        };
        Ok(Self {
            ring,
            notify,
            stop,
            task,
        })
    }

    /// Stop the reader task and the sensor; returns the readings the sensor's link lost.
    pub async fn shutdown(self) -> Result<u64, DeviceError> {
        let _ = self.stop.send(true);
        match self.task.await {
            Ok(mut sensor) => {
                let lost = sensor.lost_readings();
                sensor.stop().await.map(|()| lost)
            }
            Err(e) => Err(DeviceError::Link {
                device: "force/torque stream".into(),
                message: e.to_string(),
            }),
        }
    }

    /// The newest reading, if any.
    #[must_use]
    pub fn latest(&self) -> Option<FtReading> {
        lock(&self.ring).readings.back().copied()
    }

    /// Readings received since the start.
    #[must_use]
    pub fn received(&self) -> u64 {
        lock(&self.ring).received
    }

    /// Read errors so far.
    #[must_use]
    pub fn errors(&self) -> u64 {
        lock(&self.ring).errors
    }

    /// Wait until a reading at or after `t` has arrived, or until `deadline` (on the
    /// injected clock's tokio timeline). Returns the sensor's last error if it is failing.
    pub async fn wait_until(
        &self,
        t: TimestampNs,
        deadline: tokio::time::Instant,
    ) -> Result<bool, DeviceError> {
        loop {
            let notified = self.notify.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            {
                let r = lock(&self.ring);
                if r.readings.back().is_some_and(|x| x.t >= t) {
                    return Ok(true);
                }
                if let Some(e) = &r.error {
                    return Err(e.clone());
                }
            }
            tokio::select! {
                () = &mut notified => {}
                () = tokio::time::sleep_until(deadline) => return Ok(false),
            }
        }
    }

    /// Wait until a reading's force magnitude exceeds `max_force_n` or any torque
    /// exceeds `max_torque_nm`; returns that reading. Used as the approach guard.
    pub async fn wait_over_limit(&self, max_force_n: f64, max_torque_nm: f64) -> FtReading {
        loop {
            let notified = self.notify.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            if let Some(r) = self.latest()
                && (r.wrench_in_sensor.force_norm_n() > max_force_n
                    || r.wrench_in_sensor
                        .torque_nm
                        .iter()
                        .any(|t| t.abs() > max_torque_nm))
            {
                return r;
            }
            notified.await;
        }
    }

    /// The readings with `start <= t <= end`, oldest first.
    #[must_use]
    pub fn take_window(&self, start: TimestampNs, end: TimestampNs) -> Vec<FtReading> {
        let r = lock(&self.ring);
        r.readings
            .iter()
            .filter(|x| x.t >= start && x.t <= end)
            .copied()
            .collect()
    }
}

/// Statistics of a window and whether it makes a label.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowStats {
    /// Mean wrench.
    pub mean: Wrench,
    /// Per-axis population standard deviation.
    pub std: Wrench,
    /// Readings in the window.
    pub count: u32,
    /// Frame time minus the nearest reading's time, ns.
    pub skew_ns: i64,
    /// `None` if the window is a good label, else why not.
    pub reject: Option<RejectReason>,
}

/// What a window must satisfy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowRules {
    /// Fewest readings.
    pub min_readings: u32,
    /// Sensor range per axis (SI); a reading at it is saturated.
    pub range: [f64; 6],
}

/// The window `[frame_t − w/2, frame_t + w/2]`.
#[must_use]
pub fn window_bounds(frame_t: TimestampNs, window: DurationNs) -> (TimestampNs, TimestampNs) {
    let half = DurationNs(window.0 / 2);
    (frame_t.saturating_sub(half), frame_t.saturating_add(half))
}

/// Mean, spread, skew and verdict of a window of readings.
#[must_use]
pub fn window_stats(
    readings: &[FtReading],
    frame_t: TimestampNs,
    rules: &WindowRules,
) -> WindowStats {
    let count = u32::try_from(readings.len()).unwrap_or(u32::MAX);
    let n = readings.len().max(1) as f64;
    let mut sum = [0.0; 6];
    for r in readings {
        for (s, v) in sum.iter_mut().zip(r.wrench_in_sensor.to_array()) {
            *s += v;
        }
    }
    let mean = sum.map(|s| s / n);
    let mut var = [0.0; 6];
    for r in readings {
        for ((acc, v), m) in var.iter_mut().zip(r.wrench_in_sensor.to_array()).zip(mean) {
            *acc += (v - m) * (v - m);
        }
    }
    let std = var.map(|v| (v / n).max(0.0).sqrt());
    let skew_ns = readings
        .iter()
        .map(|r| frame_t.signed_since(r.t))
        .min_by_key(|d| d.unsigned_abs())
        .unwrap_or(0);

    let gaps = readings
        .windows(2)
        .any(|w| w[1].rdt_sequence.wrapping_sub(w[0].rdt_sequence) != 1);
    let fault = readings
        .iter()
        .any(|r| r.status.is_fault() && r.status != softtouch_schemas::FtStatus::SATURATED);
    let saturated = readings.iter().any(|r| {
        r.status == softtouch_schemas::FtStatus::SATURATED
            || r.wrench_in_sensor
                .to_array()
                .iter()
                .zip(rules.range)
                .any(|(v, lim)| v.abs() >= lim)
    });
    let finite = mean.iter().chain(&std).all(|v| v.is_finite());
    let reject = if count < rules.min_readings {
        Some(RejectReason::ShortWindow)
    } else if gaps {
        Some(RejectReason::MissingReadings)
    } else if saturated {
        Some(RejectReason::Saturated)
    } else if fault || !finite {
        Some(RejectReason::SensorFault)
    } else {
        None
    };
    WindowStats {
        mean: Wrench::from_array(mean),
        std: Wrench::from_array(std),
        count,
        skew_ns,
        reject,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_schemas::FtStatus;

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
        let mut nan = ok;
        nan[0].wrench_in_sensor.force_n[1] = f64::NAN;
        assert_eq!(
            window_stats(&nan, TimestampNs(0), &RULES).reject,
            Some(RejectReason::SensorFault)
        );
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
}
