//! The ATI serial F/T controller driver: a [`ForceSensor`] over any byte transport.

use super::codec::{self, AsciiRecord};
use crate::clock::Clock;
use crate::error::DeviceError;
use crate::force::ForceSensor;
use async_trait::async_trait;
use softtouch_schemas::{FtReading, FtStatus, TimestampNs, Wrench};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

const DEVICE: &str = "ati-serial";

/// Scaling and patience.
#[derive(Debug, Clone, PartialEq)]
pub struct AtiSerialConfig {
    /// Counts per N (the controller reports counts only).
    pub counts_per_force: f64,
    /// Counts per N·m.
    pub counts_per_torque: f64,
    /// How long to wait for a command's prompt.
    pub reply_timeout: Duration,
    /// How long [`ForceSensor::read`] waits for a record.
    pub read_timeout: Duration,
    /// Fixed delay from a record's sample instant to its arrival (serial transfer at
    /// the baud rate, the box's averaging): subtracted from every stamp.
    pub latency: Duration,
}

impl AtiSerialConfig {
    /// 500 ms reply timeout, 1 s read timeout, no latency correction.
    #[must_use]
    pub fn new(counts_per_force: f64, counts_per_torque: f64) -> Self {
        Self {
            counts_per_force,
            counts_per_torque,
            reply_timeout: Duration::from_millis(500),
            read_timeout: Duration::from_secs(1),
            latency: Duration::ZERO,
        }
    }
}

/// Counters of what the link did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AtiSerialStats {
    /// Records delivered.
    pub received: u64,
    /// Lines that were not records while streaming (each one a lost reading).
    pub garbled_lines: u64,
    /// Records whose error field was non-zero (delivered all the same).
    pub faulted: u64,
}

/// Status word of a record: 0 when the error field is 0, else bit 31 (fault) with
/// the error field in the low bits.
#[must_use]
pub fn status_of(error: u32) -> FtStatus {
    if error == 0 {
        FtStatus::OK
    } else {
        FtStatus(0x8000_0000 | (error & 0x7FFF_FFFF))
    }
}

enum Event {
    Line(Vec<u8>, TimestampNs),
    Prompt,
}

/// An ATI serial F/T controller on `T` (a serial port, a pty, an in-memory pipe).
#[derive(Debug)]
pub struct AtiSerial<T> {
    io: T,
    clock: Arc<dyn Clock>,
    config: AtiSerialConfig,
    buf: Vec<u8>,
    last_arrival: TimestampNs,
    streaming: bool,
    sequence: u32,
    stats: AtiSerialStats,
}

fn link(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: e.to_string(),
    }
}

fn protocol(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Protocol {
        device: DEVICE.into(),
        message: e.to_string(),
    }
}

fn timeout(d: Duration) -> DeviceError {
    DeviceError::Timeout {
        device: DEVICE.into(),
        timeout_ms: u64::try_from(d.as_millis()).unwrap_or(u64::MAX),
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> AtiSerial<T> {
    /// Take the transport and set the controller to ASCII, resolved F/T output.
    pub async fn new(
        io: T,
        config: AtiSerialConfig,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DeviceError> {
        let valid = |v: f64| v.is_finite() && v > 0.0;
        if !valid(config.counts_per_force) || !valid(config.counts_per_torque) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "counts per force/torque must be positive".into(),
            });
        }
        let mut s = Self {
            io,
            clock,
            config,
            buf: Vec::with_capacity(256),
            last_arrival: TimestampNs(0),
            streaming: false,
            sequence: 0,
            stats: AtiSerialStats::default(),
        };
        // A controller left streaming stops on any character.
        s.io.write_all(b"\r").await.map_err(link)?;
        s.wait_prompt().await?;
        s.command(codec::ASCII_OUTPUT).await?;
        s.command(codec::RESOLVED_OUTPUT).await?;
        Ok(s)
    }

    /// What the link did so far.
    #[must_use]
    pub const fn stats(&self) -> AtiSerialStats {
        self.stats
    }

    /// Give the transport back.
    pub fn into_inner(self) -> T {
        self.io
    }

    async fn next_event(
        &mut self,
        deadline: Instant,
        wait: Duration,
    ) -> Result<Event, DeviceError> {
        loop {
            let skip = self
                .buf
                .iter()
                .take_while(|b| matches!(b, b'\r' | b'\n'))
                .count();
            self.buf.drain(..skip);
            if self.buf.first() == Some(&b'>') {
                self.buf.drain(..1);
                return Ok(Event::Prompt);
            }
            if let Some(pos) = self.buf.iter().position(|&b| b == b'\n' || b == b'\r') {
                let line: Vec<u8> = self.buf.drain(..=pos).take(pos).collect();
                return Ok(Event::Line(line, self.last_arrival));
            }
            if self.buf.len() > codec::MAX_LINE {
                let n = self.buf.len();
                self.buf.clear();
                return Err(protocol(format!("{n} bytes without an end of line")));
            }
            let mut chunk = [0u8; 256];
            let n = tokio::time::timeout_at(deadline, self.io.read(&mut chunk))
                .await
                .map_err(|_| timeout(wait))?
                .map_err(link)?;
            if n == 0 {
                return Err(link("the port closed"));
            }
            self.last_arrival = self.clock.now();
            self.buf.extend_from_slice(chunk.get(..n).unwrap_or(&[]));
        }
    }

    async fn wait_prompt(&mut self) -> Result<Vec<Vec<u8>>, DeviceError> {
        let wait = self.config.reply_timeout;
        let deadline = Instant::now() + wait;
        let mut lines = Vec::new();
        loop {
            match self.next_event(deadline, wait).await? {
                Event::Prompt => return Ok(lines),
                Event::Line(l, _) => {
                    if lines.len() < 64 {
                        lines.push(l);
                    }
                }
            }
        }
    }

    /// Send a command and wait for the prompt; the lines before it come back. A
    /// controller that answers with an error line refuses the command
    /// ([`DeviceError::Fault`]).
    pub async fn command(&mut self, command: &str) -> Result<Vec<Vec<u8>>, DeviceError> {
        if self.streaming {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!("{command:?} while streaming"),
            });
        }
        self.io
            .write_all(&codec::encode_command(command))
            .await
            .map_err(link)?;
        self.io.flush().await.map_err(link)?;
        let lines = self.wait_prompt().await?;
        for l in &lines {
            let text = String::from_utf8_lossy(l).to_ascii_uppercase();
            if text.contains("ERR") || text.contains("INVALID") {
                return Err(DeviceError::Fault {
                    device: DEVICE.into(),
                    code: None,
                    message: format!("{command:?} refused: {}", text.trim()),
                });
            }
        }
        Ok(lines)
    }

    fn reading(&mut self, r: AsciiRecord, t: TimestampNs) -> FtReading {
        self.sequence = self.sequence.wrapping_add(1);
        let status = status_of(r.error);
        if !status.is_ok() {
            self.stats.faulted += 1;
        }
        self.stats.received += 1;
        let c = r.counts;
        let latency_ns = u64::try_from(self.config.latency.as_nanos()).unwrap_or(u64::MAX);
        FtReading {
            t: TimestampNs(t.0.saturating_sub(latency_ns)),
            rdt_sequence: self.sequence,
            ft_sequence: self.sequence,
            status,
            wrench_in_sensor: Wrench {
                force_n: std::array::from_fn(|k| f64::from(c[k]) / self.config.counts_per_force),
                torque_nm: std::array::from_fn(|k| {
                    f64::from(c[k + 3]) / self.config.counts_per_torque
                }),
            },
        }
    }

    /// One record (`QR`), outside streaming.
    pub async fn query(&mut self) -> Result<FtReading, DeviceError> {
        let lines = self.command(codec::QUERY_RECORD).await?;
        let t = self.last_arrival;
        let rec = lines
            .iter()
            .find_map(|l| codec::parse_record(l).ok())
            .ok_or_else(|| protocol("QR: no record before the prompt"))?;
        Ok(self.reading(rec, t))
    }

    async fn stop_streaming(&mut self) -> Result<(), DeviceError> {
        self.io.write_all(b"\r").await.map_err(link)?;
        self.io.flush().await.map_err(link)?;
        self.streaming = false;
        // Records already on their way are discarded up to the prompt.
        self.wait_prompt().await.map(|_| ())
    }
}

#[async_trait]
impl<T: AsyncRead + AsyncWrite + Unpin + Send> ForceSensor for AtiSerial<T> {
    async fn start(&mut self) -> Result<(), DeviceError> {
        if self.streaming {
            return Ok(());
        }
        self.io
            .write_all(&codec::encode_command(codec::QUERY_STREAM))
            .await
            .map_err(link)?;
        self.io.flush().await.map_err(link)?;
        self.streaming = true;
        Ok(())
    }

    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        if !self.streaming {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "read before start".into(),
            });
        }
        let wait = self.config.read_timeout;
        let deadline = Instant::now() + wait;
        let mut appended = 0;
        loop {
            // After the first record, take only what is already buffered.
            let skip = self
                .buf
                .iter()
                .take_while(|b| matches!(b, b'\r' | b'\n'))
                .count();
            self.buf.drain(..skip);
            let has_line = self.buf.iter().any(|&b| b == b'\n' || b == b'\r');
            if appended > 0 && !has_line {
                return Ok(appended);
            }
            match self.next_event(deadline, wait).await? {
                Event::Prompt => {
                    self.streaming = false;
                    return Err(protocol("the controller left streaming (prompt received)"));
                }
                Event::Line(l, t) => match codec::parse_record(&l) {
                    Ok(r) => {
                        let reading = self.reading(r, t);
                        out.push(reading);
                        appended += 1;
                    }
                    Err(e) => {
                        self.stats.garbled_lines += 1;
                        self.sequence = self.sequence.wrapping_add(1);
                        // Readings already taken in this call are good: hand them
                        // out (the gap in their sequence shows the lost line); a
                        // caller drops a batch that comes with an error.
                        if appended > 0 {
                            tracing::debug!("ati serial: garbled record line: {e}");
                            return Ok(appended);
                        }
                        return Err(protocol(format!("garbled record line: {e}")));
                    }
                },
            }
        }
    }

    /// `SB`; while streaming, the stream is stopped, biased and started again.
    async fn bias(&mut self) -> Result<(), DeviceError> {
        let was = self.streaming;
        if was {
            self.stop_streaming().await?;
        }
        self.command(codec::SOFTWARE_BIAS).await?;
        if was {
            self.start().await?;
        }
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        if self.streaming {
            self.stop_streaming().await
        } else {
            Ok(())
        }
    }

    /// Garbled lines (a serial link has no sequence numbers to show other losses).
    fn lost_readings(&self) -> u64 {
        self.stats.garbled_lines
    }
}
