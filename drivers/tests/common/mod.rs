//! Test devices shared by the driver tests.
#![allow(dead_code, unreachable_pub)]

use async_trait::async_trait;
use softtouch_drivers::{DeviceError, ForceSensor};
use softtouch_schemas::{FtReading, FtStatus, TimestampNs, Wrench};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;
use tokio::time::Instant;

/// The wrench of reading `k` of a [`PatternSensor`] (before bias).
pub fn pattern(k: u64) -> Wrench {
    let s = (k % 1000) as f64;
    Wrench {
        force_n: [0.001 * s, -0.002 * s, 1.5],
        torque_nm: [0.0001 * s, 0.0, -0.05],
    }
}

fn minus(a: Wrench, b: Wrench) -> Wrench {
    Wrench {
        force_n: std::array::from_fn(|k| a.force_n[k] - b.force_n[k]),
        torque_nm: std::array::from_fn(|k| a.torque_nm[k] - b.torque_nm[k]),
    }
}

/// A sensor that produces [`pattern`] (less the reading at its last bias) at `rate_hz` on tokio's clock.
#[derive(Debug)]
pub struct PatternSensor {
    rate_hz: f64,
    start: Option<Instant>,
    next_k: u64,
    /// Status word of every `fault_every`-th reading.
    pub fault_every: Option<(u64, u32)>,
    /// Every `lose_every`-th reading is lost (counted, not delivered).
    pub lose_every: Option<u64>,
    lost: u64,
    /// Bias commands seen.
    pub biases: Arc<AtomicU32>,
    /// Ignore bias commands (count them, change nothing), as a sensor whose bias
    /// datagram was lost would.
    pub ignore_bias: bool,
    /// The reading a bias subtracts from every later one.
    offset: Wrench,
}

impl PatternSensor {
    pub fn new(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            start: None,
            next_k: 0,
            fault_every: None,
            lose_every: None,
            lost: 0,
            biases: Arc::new(AtomicU32::new(0)),
            ignore_bias: false,
            offset: Wrench::ZERO,
        }
    }
}

#[async_trait]
impl ForceSensor for PatternSensor {
    async fn start(&mut self) -> Result<(), DeviceError> {
        if self.start.is_none() {
            self.start = Some(Instant::now());
            self.next_k = 0;
        }
        Ok(())
    }

    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        let Some(start) = self.start else {
            return Err(DeviceError::InvalidCommand {
                device: "pattern".into(),
                message: "not started".into(),
            });
        };
        let at = |k: u64| start + Duration::from_secs_f64(k as f64 / self.rate_hz);
        tokio::time::sleep_until(at(self.next_k)).await;
        let due = ((start.elapsed().as_secs_f64() * self.rate_hz).floor() as u64 + 1)
            .min(self.next_k + 2000);
        let mut n = 0;
        for k in self.next_k..due.max(self.next_k + 1) {
            if self.lose_every.is_some_and(|e| k % e == e - 1) {
                self.lost += 1;
                continue;
            }
            let status = match self.fault_every {
                Some((e, word)) if k % e == e - 1 => FtStatus(word),
                _ => FtStatus::OK,
            };
            out.push(FtReading {
                t: TimestampNs(0),
                rdt_sequence: k as u32,
                ft_sequence: k as u32,
                status,
                wrench_in_sensor: minus(pattern(k), self.offset),
            });
            n += 1;
        }
        self.next_k = due.max(self.next_k + 1);
        Ok(n)
    }

    async fn bias(&mut self) -> Result<(), DeviceError> {
        self.biases.fetch_add(1, Ordering::SeqCst);
        if !self.ignore_bias {
            self.offset = pattern(self.next_k);
        }
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        self.start = None;
        Ok(())
    }

    fn lost_readings(&self) -> u64 {
        self.lost
    }
}

mod pty;
// Not every test binary opens a pty.
#[allow(unused_imports)]
pub use pty::pty_pair;
