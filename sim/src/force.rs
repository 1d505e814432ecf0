//! The simulated force/torque sensor: a Net F/T-like stream on a fixed grid of
//! sample instants, quantised to counts, with the scene's noise, drift, offset,
//! packet loss and latency.
//!
//! Every reading is a pure function of the seed, its grid index `k` and the arm's
//! motion: its noise and its packet-loss draw come from the counter-based stream of its
//! packet `(seed, "ft", k / batch)` at the reading's place in the packet, drift is a function of its device time, packets are whole blocks
//! of the grid (`k / batch`), and the equilibrium contact within a packet is
//! interpolated between the last readings of this packet and the one before, whichever
//! packet was read first. So when and how often the stream is read, and where it was
//! started, change nothing: a resumed run whose clock continues the run's time reads
//! exactly the values an uninterrupted one does.

use super::effects::FtEffects;
use super::world::{SimWorld, relaxed};
use super::{lock, rng};
use async_trait::async_trait;
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use softtouch_drivers::clock::{Clock, TokioClock};
use softtouch_drivers::error::DeviceError;
use softtouch_drivers::force::ForceSensor;
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
    /// Readings per packet: packet `m` holds readings `m·batch … (m+1)·batch − 1`.
    batch: u64,
    /// The contact wrench at the last reading of the last packet read (its index).
    prev_contact: Option<(u64, Wrench)>,
    lost: u64,
    seed: u64,
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
            seed,
            drift_dir,
            bias: Wrench::ZERO,
        }
    }

    fn sample_time(&self, k: u64) -> TimestampNs {
        TimestampNs((k as f64 * self.period_ns).round() as u64)
    }

    /// When reading `k` reaches the host.
    fn arrival(&self, k: u64) -> u64 {
        self.sample_time(k).0.saturating_add(self.latency_ns)
    }

    /// The index of the last reading of the packet holding reading `k`.
    fn packet_end(&self, k: u64) -> u64 {
        (k / self.batch)
            .saturating_add(1)
            .saturating_mul(self.batch)
            - 1
    }

    /// The last reading of the last whole packet that has arrived by `now`, if it is
    /// at or after `from`'s packet.
    fn last_arrived(&self, from: u64, now: TimestampNs) -> Option<u64> {
        let first = self.packet_end(from);
        if self.arrival(first) > now.0 {
            return None;
        }
        // The newest reading due by now (the grid is rounded to whole ns: fix up).
        let mut due = ((now.0.saturating_sub(self.latency_ns)) as f64 / self.period_ns) as u64;
        due = due.max(first);
        while self.arrival(due + 1) <= now.0 {
            due += 1;
        }
        while due > first && self.arrival(due) > now.0 {
            due -= 1;
        }
        // Back to the end of a whole packet.
        let whole = (due + 1) / self.batch * self.batch;
        Some(whole.saturating_sub(1).max(first))
    }

    /// The random draws of one reading, in a fixed order from its packet's stream:
    /// whether it is lost, then its noise (standard normals).
    fn draws(&self, g: &mut rand_chacha::ChaCha8Rng) -> (bool, [f64; 6]) {
        let lost = self
            .effects
            .packet_loss
            .is_some_and(|p| g.random_bool(p.clamp(0.0, 1.0)));
        let mut z = [0.0; 6];
        if self.effects.noise.is_some() {
            for v in &mut z {
                *v = StandardNormal.sample(g);
            }
        }
        (lost, z)
    }

    /// One reading: contact, load, saturation, noise, loss, quantisation. `None`: lost.
    fn reading(&self, k: u64, contact: &Wrench, draws: (bool, [f64; 6])) -> Option<FtReading> {
        let t = self.sample_time(k);
        let (lost, z) = draws;
        if lost {
            return None;
        }
        let mut v = self.load(contact, t).to_array();
        let mut status = FtStatus::OK;
        for i in 0..6 {
            if v[i].abs() >= self.range[i] {
                status = FtStatus::SATURATED;
                v[i] = v[i].clamp(-self.range[i], self.range[i]);
            }
        }
        if let Some((fs, ts)) = self.effects.noise {
            for (i, x) in v.iter_mut().enumerate() {
                *x += z[i] * if i < 3 { fs } else { ts };
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
        Some(FtReading {
            t: TimestampNs(t.0 + self.latency_ns),
            rdt_sequence: k as u32,
            ft_sequence: k as u32,
            status,
            wrench_in_sensor: Wrench::from_array(w),
        })
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
        loop {
            let now = self.clock.now();
            // A packet is delivered when its last reading is due.
            let Some(last_k) = self.last_arrived(self.next_k, now) else {
                let due = self.arrival(self.packet_end(self.next_k));
                tokio::time::sleep_until(self.clock.instant_at(TimestampNs(due))).await;
                continue;
            };
            if last_k - self.next_k + 1 > BUFFER_READINGS {
                let skip = last_k + 1 - BUFFER_READINGS - self.next_k;
                self.lost += skip;
                self.next_k += skip;
            }
            let mut appended = 0;
            let mut world = lock(&self.world)?;
            let mut k = self.next_k;
            while k <= last_k {
                let end_k = self.packet_end(k);
                // The equilibrium contact is evaluated once per packet, at its last
                // reading, and interpolated linearly from the previous packet's last
                // reading: the motion is smooth on a packet's scale (≤ 20 ms), and the
                // contact model is the costly part. The previous one is remembered, or
                // evaluated (the same value: it is a function of the motion and `t`).
                // The relaxation, which jumps when a move ends, is exact per reading.
                let end = world
                    .equilibrium_at(self.sample_time(end_k))
                    .map_err(Self::fault)?;
                let start = match end_k.checked_sub(self.batch) {
                    None => None,
                    Some(k0) => Some(match self.prev_contact {
                        Some((pk, w)) if pk == k0 => (k0, w),
                        _ => (
                            k0,
                            world
                                .equilibrium_at(self.sample_time(k0))
                                .map_err(Self::fault)?,
                        ),
                    }),
                };
                // One counter-based stream per packet of the grid, drawn in reading
                // order; readings of the packet before `k` (a stream started or skipped
                // mid-packet) have their draws skipped, so each reading's draws are the
                // same however the packet was read.
                let mut g = rng::indexed(self.seed, "ft", end_k / self.batch);
                for _ in (end_k + 1 - self.batch)..k {
                    self.draws(&mut g);
                }
                for kk in k..=end_k {
                    let t = self.sample_time(kk);
                    let equilibrium = match start {
                        _ if kk == end_k => end,
                        Some((k0, w0)) => {
                            let f = (kk - k0) as f64 / (end_k - k0) as f64;
                            let (a, b) = (w0.to_array(), end.to_array());
                            Wrench::from_array(std::array::from_fn(|i| a[i] + f * (b[i] - a[i])))
                        }
                        // The very first packet of the grid has no packet before it.
                        None => world.equilibrium_at(t).map_err(Self::fault)?,
                    };
                    let contact = relaxed(&equilibrium, world.relaxation_at(t));
                    let draws = self.draws(&mut g);
                    match self.reading(kk, &contact, draws) {
                        Some(r) => {
                            out.push(r);
                            appended += 1;
                        }
                        None => self.lost += 1,
                    }
                }
                self.prev_contact = Some((end_k, end));
                k = end_k + 1;
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
