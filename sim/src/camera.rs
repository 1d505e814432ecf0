//! The simulated in-finger camera: frames on a fixed grid `t_k = k / fps`, rendered
//! only when a caller asks for one (rendering is the expensive part).

use super::render::{HEIGHT, WIDTH};
use super::world::SimWorld;
use super::{lock, rng};
use async_trait::async_trait;
use rand::RngExt;
use softtouch_drivers::camera::{Camera, Frame};
use softtouch_drivers::clock::TokioClock;
use softtouch_drivers::error::DeviceError;
use softtouch_schemas::{FrameFormat, FrameMeta, TimestampNs};
use std::sync::{Arc, Mutex};

const DEVICE: &str = "sim-camera";

/// The simulated camera.
#[derive(Debug)]
pub struct SimCamera {
    world: Arc<Mutex<SimWorld>>,
    clock: TokioClock,
    period_ns: f64,
    latency_ns: u64,
    drop_probability: Option<f64>,
    seed: u64,
    dropped: u64,
    /// Frames below this index have been counted as dropped already.
    counted_through: u64,
    rendered: u64,
}

impl SimCamera {
    pub(crate) fn new(
        world: Arc<Mutex<SimWorld>>,
        clock: TokioClock,
        fps: f64,
        seed: u64,
    ) -> Result<Self, DeviceError> {
        let (latency_ms, drop_probability) = {
            let w = lock(&world)?;
            (
                w.scene.effects.camera_latency_ms,
                w.scene.effects.frame_drop_probability,
            )
        };
        Ok(Self {
            world,
            clock,
            period_ns: 1e9 / fps.clamp(1.0, 1000.0),
            latency_ns: latency_ms.map_or(0, |ms| (ms * 1e6).round().max(0.0) as u64),
            drop_probability,
            seed,
            dropped: 0,
            counted_through: 0,
            rendered: 0,
        })
    }

    /// Exposure time of frame `k`.
    pub fn frame_time(&self, k: u64) -> TimestampNs {
        TimestampNs((k as f64 * self.period_ns).round() as u64)
    }

    /// Frames rendered so far (only the ones callers asked for).
    pub fn rendered_frames(&self) -> u64 {
        self.rendered
    }

    fn is_dropped(&self, k: u64) -> bool {
        self.drop_probability.is_some_and(|p| {
            rng::indexed(self.seed, "frame-drops", k).random_bool(p.clamp(0.0, 1.0))
        })
    }
}

#[async_trait]
impl Camera for SimCamera {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        let deadline = TimestampNs(t.0.saturating_add(timeout_ms.saturating_mul(1_000_000)));
        let mut k = (t.0 as f64 / self.period_ns).ceil() as u64;
        while k > 0 && self.frame_time(k - 1) >= t {
            k -= 1;
        }
        while self.frame_time(k) < t {
            k += 1;
        }
        loop {
            let exposed = self.frame_time(k);
            let delivered = TimestampNs(exposed.0.saturating_add(self.latency_ns));
            if delivered > deadline {
                tokio::time::sleep_until(self.clock.instant_at(deadline)).await;
                return Err(DeviceError::Timeout {
                    device: DEVICE.into(),
                    timeout_ms,
                });
            }
            if self.is_dropped(k) {
                if k >= self.counted_through {
                    self.dropped += 1;
                    self.counted_through = k + 1;
                }
                k += 1;
                continue;
            }
            tokio::time::sleep_until(self.clock.instant_at(delivered)).await;
            let data = {
                let w = lock(&self.world)?;
                let pose = w.pose_at(exposed);
                let contact = w.contact_pose(&pose);
                let look = w
                    .scene
                    .look(&w.rod, &contact)
                    .map_err(|e| DeviceError::Fault {
                        device: DEVICE.into(),
                        code: None,
                        message: e.to_string(),
                    })?;
                w.scene.render(&look, k, exposed.as_secs_f64())
            };
            self.rendered += 1;
            self.counted_through = self.counted_through.max(k + 1);
            return Ok(Frame {
                meta: FrameMeta {
                    t: exposed,
                    sequence: k,
                    width: WIDTH,
                    height: HEIGHT,
                    format: FrameFormat::Rgb8,
                },
                data,
            });
        }
    }

    fn dropped_frames(&self) -> u64 {
        self.dropped
    }
}
