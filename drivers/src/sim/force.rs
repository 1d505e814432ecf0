//! The simulated force/torque sensor: a Net F/T-like stream on a fixed grid of
//! sample instants, quantised to counts, with the scene's noise, drift, offset,
//! packet loss and latency.

use super::effects::FtEffects;
use super::world::SimWorld;
use super::{lock, rng};
use crate::clock::{Clock, TokioClock};
use crate::error::DeviceError;
use crate::force::ForceSensor;
use async_trait::async_trait;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use softtouch_schemas::{FtReading, FtStatus, TimestampNs, Wrench};
use std::sync::{Arc, Mutex};

/// Counts per newton (a Net F/T's usual metric calibration).
pub const COUNTS_PER_FORCE: f64 = 1_000_000.0;
/// Counts per newton-metre.
pub const COUNTS_PER_TORQUE: f64 = 1_000_000.0;
/// Readings the host's receive buffer holds; older unread ones are lost.
pub const BUFFER_READINGS: u64 = 4096;
/// Readings arrive in packets spanning up to this long, as a Net F/T in buffered mode
/// sends several records per datagram: one wake-up per packet instead of per reading.
pub(crate) const PACKET_NS: f64 = 20_000_000.0;
/// Most records per packet (a Net F/T's RDT buffer holds up to 40).
pub(crate) const PACKET_MAX_READINGS: u64 = 40;
const DEVICE: &str = "sim-ft";

/// The simulated sensor.
#[derive(Debug)]
pub struct SimForceSensor {
    world: Arc<Mutex<SimWorld>>,
    clock: TokioClock,
    period_ns: f64,
    latency_ns: u64,
    effects: FtEffects,
    range: [f64; 6],
    started: bool,
    next_k: u64,
    /// Readings per packet.
    batch: u64,
    /// The contact wrench at the last reading of the previous packet (its index).
    prev_contact: Option<(u64, Wrench)>,
    lost: u64,
    rng: ChaCha8Rng,
    drift_dir: [f64; 6],
    bias: Wrench,
}

impl SimForceSensor {
    pub(crate) fn new(
        world: Arc<Mutex<SimWorld>>,
        clock: TokioClock,
        rate_hz: f64,
        range: [f64; 6],
        effects: FtEffects,
        seed: u64,
    ) -> Self {
        let mut g = rng::stream(seed, "ft-drift-direction");
        let drift_dir = std::array::from_fn(
            |_| if g.random_bool(0.5) { 1.0 } else { -1.0 } * g.random_range(0.5..1.0),
        );
        let latency_ns = effects
            .latency_ms
            .map_or(0, |ms| (ms * 1e6).round().max(0.0) as u64);
        let period_ns = 1e9 / rate_hz.clamp(1.0, 7000.0);
        Self {
            world,
            clock,
            period_ns,
            batch: ((PACKET_NS / period_ns).floor() as u64).clamp(1, PACKET_MAX_READINGS),
            prev_contact: None,
            latency_ns,
            effects,
            range,
            started: false,
            next_k: 0,
            lost: 0,
            rng: rng::stream(seed, "ft"),
            drift_dir,
            bias: Wrench::ZERO,
        }
    }

    fn sample_time(&self, k: u64) -> TimestampNs {
        TimestampNs((k as f64 * self.period_ns).round() as u64)
    }

    /// Load on the sensor before noise: contact + offset + drift at `t`.
    fn load(&self, contact: &Wrench, t: TimestampNs) -> Wrench {
        let mut v = contact.to_array();
        if let Some((f, tq)) = self.effects.offset {
            for i in 0..3 {
                v[i] += f[i];
                v[i + 3] += tq[i];
            }
        }
        if let Some((fr, tr)) = self.effects.drift_per_h {
            let hours = t.as_secs_f64() / 3600.0;
            for i in 0..6 {
                v[i] += if i < 3 { fr } else { tr } * hours * self.drift_dir[i];
            }
        }
        Wrench::from_array(v)
    }

    fn fault(e: impl std::fmt::Display) -> DeviceError {
        DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: e.to_string(),
        }
    }
}

fn quantise(v: f64, counts_per_unit: f64) -> f64 {
    let counts = (v * counts_per_unit)
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX));
    counts / counts_per_unit
}

#[async_trait]
impl ForceSensor for SimForceSensor {
    async fn start(&mut self) -> Result<(), DeviceError> {
        if !self.started {
            let now = self.clock.now().0 as f64;
            self.next_k = (now / self.period_ns).ceil() as u64;
            self.started = true;
        }
        Ok(())
    }

    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        if !self.started {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "read before start".into(),
            });
        }
        let mut appended = 0;
        loop {
            let now = self.clock.now();
            // The packet is delivered when its last reading is due.
            let first_delivery = self.sample_time(self.next_k + self.batch - 1).0 + self.latency_ns;
            if first_delivery > now.0 {
                if appended > 0 {
                    return Ok(appended);
                }
                tokio::time::sleep_until(self.clock.instant_at(TimestampNs(first_delivery))).await;
                continue;
            }
            // Readings delivered by now: k with t_k + latency ≤ now.
            let last_k = ((now.0 - self.latency_ns) as f64 / self.period_ns).floor() as u64;
            let mut last_k = last_k.max(self.next_k);
            while self.sample_time(last_k).0 + self.latency_ns > now.0 && last_k > self.next_k {
                last_k -= 1;
            }
            if last_k - self.next_k + 1 > BUFFER_READINGS {
                let skip = last_k + 1 - BUFFER_READINGS - self.next_k;
                self.lost += skip;
                self.next_k += skip;
            }
            let mut world = lock(&self.world)?;
            // The contact is evaluated once per packet, at its last reading, and
            // interpolated linearly from the previous packet's: the motion is smooth on
            // a packet's scale (≤ 20 ms), and the contact model is the costly part.
            let end = world
                .wrench_at(self.sample_time(last_k))
                .map_err(Self::fault)?;
            let start = match self.prev_contact {
                Some((k, w)) if k + 1 == self.next_k => Some((k, w)),
                _ => None,
            };
            self.prev_contact = Some((last_k, end));
            for k in self.next_k..=last_k {
                let t = self.sample_time(k);
                if let Some(p) = self.effects.packet_loss
                    && self.rng.random_bool(p.clamp(0.0, 1.0))
                {
                    self.lost += 1;
                    continue;
                }
                let contact = match start {
                    _ if k == last_k => end,
                    Some((k0, w0)) => {
                        let f = (k - k0) as f64 / (last_k - k0) as f64;
                        let (a, b) = (w0.to_array(), end.to_array());
                        Wrench::from_array(std::array::from_fn(|i| a[i] + f * (b[i] - a[i])))
                    }
                    None => world.wrench_at(t).map_err(Self::fault)?,
                };
                let mut v = self.load(&contact, t).to_array();
                let mut status = FtStatus::OK;
                for i in 0..6 {
                    if v[i].abs() >= self.range[i] {
                        status = FtStatus::SATURATED;
                        v[i] = v[i].clamp(-self.range[i], self.range[i]);
                    }
                }
                if let Some((fs, ts)) = self.effects.noise {
                    for (i, x) in v.iter_mut().enumerate() {
                        let z: f64 = StandardNormal.sample(&mut self.rng);
                        *x += z * if i < 3 { fs } else { ts };
                    }
                }
                let b = self.bias.to_array();
                let w: [f64; 6] = std::array::from_fn(|i| {
                    quantise(
                        v[i] - b[i],
                        if i < 3 {
                            COUNTS_PER_FORCE
                        } else {
                            COUNTS_PER_TORQUE
                        },
                    )
                });
                out.push(FtReading {
                    t: TimestampNs(t.0 + self.latency_ns),
                    rdt_sequence: k as u32,
                    ft_sequence: k as u32,
                    status,
                    wrench_in_sensor: Wrench::from_array(w),
                });
                appended += 1;
            }
            drop(world);
            self.next_k = last_k + 1;
            if appended > 0 {
                return Ok(appended);
            }
        }
    }

    /// Zero at the present load: the contact (none at home), the buoyancy offset and
    /// the drift accumulated until now; later readings carry only the drift since.
    /// Noise-free, as a sensor's tare over its low-pass filter is to within its
    /// resolution.
    async fn bias(&mut self) -> Result<(), DeviceError> {
        let now = self.clock.now();
        let contact = lock(&self.world)?.wrench_at(now).map_err(Self::fault)?;
        self.bias = self.load(&contact, now);
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        self.started = false;
        Ok(())
    }

    fn lost_readings(&self) -> u64 {
        self.lost
    }
}
