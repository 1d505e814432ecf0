//! The force/torque stream of a run and the label window of a sample.
//!
//! The sensor runs in its own task, appending every reading (stamped on the injected
//! clock) to a bounded ring. A sample takes the readings in a window around its
//! frame's time. Nothing is dropped silently: readings lost on the link are counted
//! by the driver (and show as sequence gaps, which reject a window); the ring holds
//! seconds of readings, far longer than any window waits.

use softtouch_drivers::{DeviceError, ForceGuard, ForceSensor, GuardTrip};
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{DurationNs, FtReading, TimestampNs, Wrench};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use tokio::sync::{Notify, mpsc, oneshot, watch};
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
    /// Tare requests, served by the reader task, which owns the sensor.
    bias: mpsc::Sender<oneshot::Sender<Result<(), DeviceError>>>,
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
        let (bias, mut bias_requests) = mpsc::channel::<oneshot::Sender<_>>(1);
        let task = {
            let ring = Arc::clone(&ring);
            let notify = Arc::clone(&notify);
            tokio::spawn(async move {
                let mut batch = Vec::new();
                loop {
                    tokio::select! {
                        biased;
                        _ = stopped.changed() => break,
                        // Cancels a pending read, which has then appended nothing.
                        Some(reply) = bias_requests.recv() => {
                            let _ = reply.send(sensor.bias().await);
                        }
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
            bias,
            task,
        })
    }

    /// Zero the sensor at its present load (tare): readings from now on are relative
    /// to it. Readings already in the ring keep the old zero.
    pub async fn bias(&self) -> Result<(), DeviceError> {
        let gone = || DeviceError::Link {
            device: "force/torque stream".into(),
            message: "the reader task has ended".into(),
        };
        let (reply, answer) = oneshot::channel();
        self.bias.send(reply).await.map_err(|_| gone())?;
        answer.await.map_err(|_| gone())?
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

    /// The approach guard: returns as soon as a reading arriving from now on trips
    /// `guard` ([`ForceGuard::check`]: NaN or ∞, force magnitude or any torque axis
    /// over its limit, a fault status), when no reading arrives for its stale limit,
    /// or when the sensor reports an error. Every reading of every packet is checked,
    /// not only the newest.
    pub async fn guard(&self, guard: &ForceGuard) -> GuardTrip {
        let mut seen = self.received();
        let mut last_reading = tokio::time::Instant::now();
        loop {
            let notified = self.notify.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            {
                let r = lock(&self.ring);
                if let Some(e) = &r.error {
                    return GuardTrip::SensorError(e.clone());
                }
                let new = r.received.saturating_sub(seen);
                if new > 0 {
                    last_reading = tokio::time::Instant::now();
                    // The newest `new` readings (all the ring holds, had it wrapped).
                    let skip = r
                        .readings
                        .len()
                        .saturating_sub(usize::try_from(new).unwrap_or(usize::MAX));
                    if let Err(trip) = guard.check_all(r.readings.iter().skip(skip)) {
                        return trip;
                    }
                    seen = r.received;
                }
            }
            tokio::select! {
                () = &mut notified => {}
                () = tokio::time::sleep_until(last_reading + guard.stale) => {
                    if self.received() == seen
                        && let Err(trip) = guard.check_silence(last_reading.elapsed())
                    {
                        return trip;
                    }
                }
            }
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

/// Whether `readings` cover the frame at `frame_t`: one at or before it and one at or
/// after it, each within `max_skew`. Otherwise the frame fell in a hole of the stream
/// (a stall with no lost sequence numbers, a host that stopped reading) or outside the
/// readings' time span (camera and sensor stamps on different time bases): the window
/// is not the force at the frame's moment.
#[must_use]
pub fn frame_covered(readings: &[FtReading], frame_t: TimestampNs, max_skew: DurationNs) -> bool {
    let before = readings
        .iter()
        .any(|r| r.t <= frame_t && frame_t.0 - r.t.0 <= max_skew.0);
    let after = readings
        .iter()
        .any(|r| r.t >= frame_t && r.t.0 - frame_t.0 <= max_skew.0);
    before && after
}

/// Mean, spread, skew and verdict of a window of readings.
#[must_use]
pub fn window_stats(
    readings: &[FtReading],
    frame_t: TimestampNs,
    rules: &WindowRules,
) -> WindowStats {
    let count = u32::try_from(readings.len()).unwrap_or(u32::MAX);
    // Mean and spread over the finite readings only, so that they stay finite (they
    // go to NOT NULL columns); a non-finite reading rejects the window below.
    let is_finite = |r: &&FtReading| r.wrench_in_sensor.to_array().iter().all(|v| v.is_finite());
    let non_finite = readings.iter().any(|r| !is_finite(&r));
    let n = readings.iter().filter(is_finite).count().max(1) as f64;
    let mut sum = [0.0; 6];
    for r in readings.iter().filter(is_finite) {
        for (s, v) in sum.iter_mut().zip(r.wrench_in_sensor.to_array()) {
            *s += v;
        }
    }
    let mean = sum.map(|s| s / n);
    let mut var = [0.0; 6];
    for r in readings.iter().filter(is_finite) {
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
    // Finite readings can still overflow the sums (values near f64::MAX).
    let finite = mean.iter().chain(&std).all(|v| v.is_finite());
    let (mean, std) = if finite {
        (mean, std)
    } else {
        ([0.0; 6], [0.0; 6])
    };
    let reject = if non_finite {
        Some(RejectReason::NonFinite)
    } else if count < rules.min_readings {
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
mod tests;
