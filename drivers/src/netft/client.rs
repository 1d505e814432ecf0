//! The Net F/T RDT client: a [`ForceSensor`] over UDP.

use super::codec::{self, Calibration, Command, RawRecord};
use crate::clock::Clock;
use crate::error::DeviceError;
use crate::force::ForceSensor;
use async_trait::async_trait;
use softtouch_schemas::{FtReading, FtStatus, TimestampNs, Wrench};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, UdpSocket};

const DEVICE: &str = "net-ft";

/// Real-time (one record per datagram) or buffered (several per datagram) streaming.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamMode {
    /// Command `0x0002`.
    RealTime,
    /// Command `0x0003`.
    Buffered,
}

/// Where the counts-per-unit come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Scaling {
    /// Given (rig config): counts per N and counts per N·m.
    Given {
        /// Counts per newton.
        counts_per_force: f64,
        /// Counts per newton-metre.
        counts_per_torque: f64,
    },
    /// Read with the TCP calibration request from this address (port 49151 on a sensor).
    CalibrationRequest(SocketAddr),
    /// Read from `http://ADDR/netftapi2.xml`.
    Http(SocketAddr),
}

/// How to reach the sensor and how patient to be.
#[derive(Debug, Clone, PartialEq)]
pub struct NetFtConfig {
    /// The sensor's RDT address (port 49152 on a sensor).
    pub rdt_addr: SocketAddr,
    /// Counts per unit.
    pub scaling: Scaling,
    /// Real-time or buffered.
    pub mode: StreamMode,
    /// The sensor's output rate, Hz: records of a buffered datagram are back-dated by
    /// one period each from the datagram's arrival.
    pub rate_hz: f64,
    /// Start commands sent before giving up (the first record confirms the start).
    pub start_attempts: u32,
    /// How long to wait for the first record after each start command, and for the
    /// calibration reply.
    pub reply_timeout: Duration,
    /// How long [`ForceSensor::read`] waits for a datagram before a timeout error.
    pub read_timeout: Duration,
    /// Silence after which a read sends the start command again (a sensor that
    /// rebooted, or that another client stopped, streams only when asked anew), and
    /// again after each further silence this long, until `read_timeout`.
    pub restart_after: Duration,
    /// Fixed delay from a record's sample instant to the datagram's arrival (the
    /// sensor's filter and the network): subtracted from every stamp, so readings
    /// share the frames' time base.
    pub latency: Duration,
    /// A bias is confirmed when the mean of [`BIAS_CONFIRM_READINGS`] consecutive
    /// readings after it lies within this force (N) and torque (N·m) of zero. RDT
    /// acknowledges nothing: a lost bias datagram would otherwise leave the old offset
    /// in every label.
    pub bias_tolerance: (f64, f64),
    /// Bias commands sent before giving up (each waits `reply_timeout` for zero).
    pub bias_attempts: u32,
}

/// Readings averaged to confirm a bias.
pub const BIAS_CONFIRM_READINGS: usize = 5;

impl NetFtConfig {
    /// Defaults for a sensor at `rdt_addr`, calibration read over TCP at port 49151 of
    /// the same host: real-time mode, 10 start attempts, 100 ms reply timeout, 1 s read
    /// timeout, a restart after 100 ms of silence (or 10 periods, if longer), no latency
    /// correction.
    #[must_use]
    pub fn new(rdt_addr: SocketAddr, rate_hz: f64) -> Self {
        let cal = SocketAddr::new(rdt_addr.ip(), codec::CALIBRATION_PORT);
        Self {
            rdt_addr,
            scaling: Scaling::CalibrationRequest(cal),
            mode: StreamMode::RealTime,
            rate_hz,
            start_attempts: 10,
            reply_timeout: Duration::from_millis(100),
            read_timeout: Duration::from_secs(1),
            restart_after: restart_after(rate_hz),
            latency: Duration::ZERO,
            bias_tolerance: (0.1, 0.002),
            bias_attempts: 3,
        }
    }
}

/// 100 ms, or ten periods of a slow stream.
/// How far the stream's period may be from the configured one before the stream is
/// refused, as a fraction ([`super::stamp::SequenceStamps::rate_error`]).
pub const RATE_REFUSED: f64 = 0.05;

/// The highest `rdt_sequence` taken as the first record of a new stream. RDT numbers
/// the records of each start request from 1; a few may be lost before the first
/// arrives (a second at 1 kHz is allowed for). A late record of the previous stream
/// can be taken only if that stream was this short, and then holds the new one back
/// by at most this many records.
pub const NEW_STREAM_MAX_FIRST_SEQUENCE: u32 = 1000;

fn restart_after(rate_hz: f64) -> Duration {
    let periods = if rate_hz.is_finite() && rate_hz > 0.0 {
        10.0 / rate_hz
    } else {
        0.0
    };
    Duration::from_secs_f64(periods.clamp(0.1, 10.0))
}

/// Counters of what the link did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NetFtStats {
    /// Records delivered.
    pub received: u64,
    /// Records known lost (gaps in `rdt_sequence`, wrap at 2^32 included).
    pub lost: u64,
    /// Records dropped because their `rdt_sequence` went backwards (stale or duplicated).
    pub out_of_order: u64,
    /// Datagrams rejected as not following the protocol.
    pub bad_datagrams: u64,
    /// Records whose status word reported a fault (delivered all the same).
    pub faulted: u64,
    /// Records whose status word reported a warning only.
    pub warnings: u64,
    /// Start commands sent (more than one when a start was lost).
    pub start_commands: u64,
    /// Streams restarted after a silence (a start command sent again mid-stream).
    pub restarts: u64,
    /// Bias commands sent (more than one per bias when the readings did not go to zero).
    pub bias_commands: u64,
}

/// A Net F/T over RDT. Implements [`ForceSensor`].
#[derive(Debug)]
pub struct NetFtClient {
    socket: UdpSocket,
    config: NetFtConfig,
    clock: Arc<dyn Clock>,
    counts_per_force: f64,
    counts_per_torque: f64,
    streaming: bool,
    last_sequence: Option<u32>,
    /// Whether a stream has been asked for on this socket before: then its datagrams
    /// may still arrive after a new start (a new socket receives none of them).
    streamed_before: bool,
    /// Until the new stream's first record: take only one that starts a stream
    /// ([`NEW_STREAM_MAX_FIRST_SEQUENCE`]); set by a restart and by a start on a
    /// socket that streamed before.
    new_stream_only: bool,
    stamps: super::stamp::SequenceStamps,
    latched_status: FtStatus,
    stats: NetFtStats,
    buf: Vec<u8>,
    records: Vec<RawRecord>,
    /// Length of the confirming datagram `start` left in `buf`, and when it came.
    pending: Option<usize>,
    pending_t: TimestampNs,
    /// Readings a bias's confirmation read, handed out by the next `read`.
    held: Vec<FtReading>,
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

fn mean_wrench(readings: &[FtReading]) -> Wrench {
    let n = readings.len().max(1) as f64;
    let sum = |f: &dyn Fn(&Wrench) -> f64| {
        readings.iter().map(|r| f(&r.wrench_in_sensor)).sum::<f64>() / n
    };
    Wrench {
        force_n: std::array::from_fn(|k| sum(&|w| w.force_n[k])),
        torque_nm: std::array::from_fn(|k| sum(&|w| w.torque_nm[k])),
    }
}

/// Read the calibration with the TCP request (port 49151 on a sensor).
pub async fn read_calibration(
    addr: SocketAddr,
    wait: Duration,
) -> Result<Calibration, DeviceError> {
    let exchange = async {
        let mut s = TcpStream::connect(addr).await.map_err(link)?;
        s.write_all(&codec::encode_calibration_request())
            .await
            .map_err(link)?;
        let mut reply = [0u8; codec::CALIBRATION_REPLY_LEN];
        s.read_exact(&mut reply).await.map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                protocol("calibration reply truncated")
            } else {
                link(e)
            }
        })?;
        codec::decode_calibration_reply(&reply).map_err(protocol)
    };
    tokio::time::timeout(wait, exchange)
        .await
        .map_err(|_| timeout(wait))?
}

/// Read counts per N and per N·m from `http://ADDR/netftapi2.xml`.
pub async fn read_netftapi2(addr: SocketAddr, wait: Duration) -> Result<(f64, f64), DeviceError> {
    let exchange = async {
        let mut s = TcpStream::connect(addr).await.map_err(link)?;
        let req = format!(
            "GET /netftapi2.xml HTTP/1.0\r\nHost: {}\r\nConnection: close\r\n\r\n",
            addr.ip()
        );
        s.write_all(req.as_bytes()).await.map_err(link)?;
        let mut body = Vec::new();
        // A sensor's page is a few kB; refuse anything absurd.
        (&mut s)
            .take(1 << 20)
            .read_to_end(&mut body)
            .await
            .map_err(link)?;
        let text = String::from_utf8_lossy(&body);
        if !text.starts_with("HTTP/1.") || !text.lines().next().is_some_and(|l| l.contains(" 200"))
        {
            return Err(protocol(format!(
                "netftapi2.xml: unexpected HTTP answer {:?}",
                text.lines().next().unwrap_or("")
            )));
        }
        codec::parse_netftapi2(&text).map_err(protocol)
    };
    tokio::time::timeout(wait, exchange)
        .await
        .map_err(|_| timeout(wait))?
}

impl NetFtClient {
    /// Bind a local UDP port, connect it to the sensor and resolve the scaling
    /// (reading the calibration from the sensor when the config does not give it).
    pub async fn connect(config: NetFtConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        let (counts_per_force, counts_per_torque) = match &config.scaling {
            Scaling::Given {
                counts_per_force,
                counts_per_torque,
            } => (*counts_per_force, *counts_per_torque),
            Scaling::CalibrationRequest(addr) => read_calibration(*addr, config.reply_timeout)
                .await?
                .counts_per_si()
                .map_err(protocol)?,
            Scaling::Http(addr) => read_netftapi2(*addr, config.reply_timeout).await?,
        };
        let valid = |v: f64| v.is_finite() && v > 0.0;
        if !valid(counts_per_force) || !valid(counts_per_torque) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!(
                    "counts per force/torque must be positive, got {counts_per_force} / {counts_per_torque}"
                ),
            });
        }
        let local: SocketAddr = if config.rdt_addr.is_ipv4() {
            ([0, 0, 0, 0], 0).into()
        } else {
            (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
        };
        let socket = UdpSocket::bind(local).await.map_err(link)?;
        // Connected: the kernel drops datagrams from anyone but the sensor.
        socket.connect(config.rdt_addr).await.map_err(link)?;
        let stamps = super::stamp::SequenceStamps::new(config.rate_hz);
        Ok(Self {
            socket,
            config,
            clock,
            counts_per_force,
            counts_per_torque,
            streaming: false,
            last_sequence: None,
            streamed_before: false,
            new_stream_only: false,
            stamps,
            latched_status: FtStatus::OK,
            stats: NetFtStats::default(),
            buf: vec![0u8; 65_536],
            records: Vec::new(),
            pending: None,
            pending_t: TimestampNs(0),
            held: Vec::new(),
        })
    }

    /// The local address the stream arrives on.
    pub fn local_addr(&self) -> Result<SocketAddr, DeviceError> {
        self.socket.local_addr().map_err(link)
    }

    /// Counts per N and per N·m in use.
    #[must_use]
    pub const fn scaling(&self) -> (f64, f64) {
        (self.counts_per_force, self.counts_per_torque)
    }

    /// What the link did so far.
    #[must_use]
    pub const fn stats(&self) -> NetFtStats {
        self.stats
    }

    /// The first non-OK status word seen since the last [`Self::clear_latched_status`]
    /// (the reference driver latches any non-zero status the same way).
    #[must_use]
    pub const fn latched_status(&self) -> FtStatus {
        self.latched_status
    }

    /// Forget the latched status.
    pub fn clear_latched_status(&mut self) {
        self.latched_status = FtStatus::OK;
    }

    /// Send one RDT command.
    pub async fn send_command(
        &self,
        command: Command,
        sample_count: u32,
    ) -> Result<(), DeviceError> {
        self.socket
            .send(&codec::encode_request(command, sample_count))
            .await
            .map_err(link)
            .map(|_| ())
    }

    /// Drain datagrams already queued (after a stop, before a start).
    fn drain(&mut self) {
        while self.socket.try_recv(&mut self.buf).is_ok() {}
    }

    /// Turn one datagram's records into readings appended to `out`, each stamped
    /// from its sequence ([`super::stamp`]) given the datagram's arrival at `t`.
    fn accept_datagram(
        &mut self,
        len: usize,
        t: TimestampNs,
        out: &mut Vec<FtReading>,
    ) -> Result<usize, DeviceError> {
        let latency_ns = u64::try_from(self.config.latency.as_nanos()).unwrap_or(u64::MAX);
        self.records.clear();
        let bytes = self.buf.get(..len).unwrap_or(&[]);
        if let Err(e) = codec::decode_records(bytes, &mut self.records) {
            self.stats.bad_datagrams += 1;
            return Err(protocol(e));
        }
        // The records that follow the stream, with their unwrapped sequence.
        let mut accepted: Vec<(usize, u64)> = Vec::with_capacity(self.records.len());
        for (i, r) in self.records.iter().enumerate() {
            // A (re)started stream counts from 1: until its first record, anything
            // further on is a late datagram of the stream before, which would
            // otherwise become the baseline and hold back every new record as old
            // for as long as the old stream had run.
            if self.last_sequence.is_none()
                && self.new_stream_only
                && r.rdt_sequence > NEW_STREAM_MAX_FIRST_SEQUENCE
            {
                self.stats.out_of_order += 1;
                continue;
            }
            if let Some(last) = self.last_sequence {
                let ahead = r.rdt_sequence.wrapping_sub(last);
                if ahead == 0 || ahead >= 1 << 31 {
                    self.stats.out_of_order += 1;
                    continue;
                }
                self.stats.lost += u64::from(ahead - 1);
            }
            self.last_sequence = Some(r.rdt_sequence);
            accepted.push((i, self.stamps.unwrap(r.rdt_sequence)));
        }
        if let Some(&(_, newest)) = accepted.last() {
            self.stamps.arrived(t.0, newest);
        }
        for &(i, u) in &accepted {
            let r = self.records[i];
            let status = FtStatus(r.status);
            if status.is_fault() {
                self.stats.faulted += 1;
            } else if status.is_warning() {
                self.stats.warnings += 1;
            }
            if !status.is_ok() && self.latched_status.is_ok() {
                self.latched_status = status;
            }
            let sampled = self.stamps.stamp(u, t.0);
            let c = r.counts;
            out.push(FtReading {
                t: TimestampNs(sampled.saturating_sub(latency_ns)),
                rdt_sequence: r.rdt_sequence,
                ft_sequence: r.ft_sequence,
                status,
                wrench_in_sensor: Wrench {
                    force_n: std::array::from_fn(|k| f64::from(c[k]) / self.counts_per_force),
                    torque_nm: std::array::from_fn(|k| {
                        f64::from(c[k + 3]) / self.counts_per_torque
                    }),
                },
            });
        }
        self.stats.received += accepted.len() as u64;
        Ok(accepted.len())
    }

    async fn recv_within(&mut self, wait: Duration) -> Result<Option<usize>, DeviceError> {
        match tokio::time::timeout(wait, self.socket.recv(&mut self.buf)).await {
            Err(_) => Ok(None),
            Ok(Ok(len)) => Ok(Some(len)),
            Ok(Err(e)) => Err(link(e)),
        }
    }

    /// Sends the bias up to `bias_attempts` times until the readings after it come
    /// to zero; every reading read is appended to `kept`. `Ok(Ok(()))`: confirmed;
    /// `Ok(Err(mean))`: not, with the last offset seen (`None`: too few readings).
    async fn confirm_bias(
        &mut self,
        tol_n: f64,
        tol_nm: f64,
        kept: &mut Vec<FtReading>,
    ) -> Result<Result<(), Option<Wrench>>, DeviceError> {
        let mut last_mean = None;
        for _ in 0..self.config.bias_attempts.max(1) {
            self.send_command(Command::Bias, 0).await?;
            self.stats.bias_commands += 1;
            let mut since: Vec<FtReading> = Vec::new();
            let deadline = tokio::time::Instant::now() + self.config.reply_timeout;
            loop {
                let mut got = Vec::new();
                match tokio::time::timeout_at(deadline, ForceSensor::read(self, &mut got)).await {
                    Err(_) => break,
                    Ok(r) => {
                        r?;
                    }
                }
                since.extend_from_slice(&got);
                kept.append(&mut got);
                let Some(tail) = since.len().checked_sub(BIAS_CONFIRM_READINGS) else {
                    continue;
                };
                let mean = mean_wrench(since.get(tail..).unwrap_or(&[]));
                if mean.force_norm_n() <= tol_n && mean.torque_nm.iter().all(|t| t.abs() <= tol_nm)
                {
                    return Ok(Ok(()));
                }
                last_mean = Some(mean);
            }
        }
        Ok(Err(last_mean))
    }

    fn start_command(&self) -> Command {
        match self.config.mode {
            StreamMode::RealTime => Command::RealTime,
            StreamMode::Buffered => Command::Buffered,
        }
    }
}

#[async_trait]
impl ForceSensor for NetFtClient {
    /// Send the start command and wait for the first record; a lost command is sent
    /// again, up to `start_attempts` times. The first records are kept for `read`.
    async fn start(&mut self) -> Result<(), DeviceError> {
        if self.streaming {
            return Ok(());
        }
        self.drain();
        self.last_sequence = None;
        self.new_stream_only = self.streamed_before;
        self.streamed_before = true;
        self.stamps.reset();
        let command = self.start_command();
        let attempts = self.config.start_attempts.max(1);
        for _ in 0..attempts {
            self.send_command(command, 0).await?;
            self.stats.start_commands += 1;
            let deadline = tokio::time::Instant::now() + self.config.reply_timeout;
            loop {
                let left = deadline.saturating_duration_since(tokio::time::Instant::now());
                match self.recv_within(left).await {
                    Ok(Some(len)) => {
                        // Only a valid datagram confirms the start; stray bytes do not.
                        if codec::decode_records(
                            self.buf.get(..len).unwrap_or(&[]),
                            &mut Vec::new(),
                        )
                        .is_ok()
                        {
                            // Keep its records: put them back for the next read.
                            self.pending = Some(len);
                            self.pending_t = self.clock.now();
                            self.streaming = true;
                            return Ok(());
                        }
                        self.stats.bad_datagrams += 1;
                    }
                    Ok(None) => break,
                    // ICMP "port unreachable" on a connected socket: the sensor is not
                    // there (yet); count it as a lost start.
                    Err(DeviceError::Link { .. }) if left > Duration::ZERO => {
                        tokio::time::sleep(left).await;
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
        }
        Err(DeviceError::Timeout {
            device: DEVICE.into(),
            timeout_ms: u64::try_from((self.config.reply_timeout * attempts).as_millis())
                .unwrap_or(u64::MAX),
        })
    }

    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        if !self.streaming {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "read before start".into(),
            });
        }
        // Stamps come from the sequence at the configured period: a sensor streaming
        // at another rate would have every stamp drift (and its window pair with the
        // wrong frame), so the stream is refused once its rate shows.
        if let Some(off) = self.stamps.rate_error()
            && off.abs() > RATE_REFUSED
        {
            let configured = self.config.rate_hz;
            return Err(DeviceError::Protocol {
                device: DEVICE.into(),
                message: format!(
                    "the sensor streams at {:.0} Hz, the rig says force_sensor.rate_hz = {configured}: readings are stamped from their sequence at the configured period, so set rate_hz to the sensor's RDT output rate (its web page)",
                    configured / (1.0 + off)
                ),
            });
        }
        // A malformed datagram is counted (`bad_datagrams`) and skipped: it must not
        // discard the good readings of the same read. Only a read that brings nothing
        // but malformed datagrams until its timeout reports the protocol error.
        let mut appended = self.held.len();
        out.append(&mut self.held);
        let mut malformed = None;
        if let Some(len) = self.pending.take() {
            let t = self.pending_t;
            match self.accept_datagram(len, t, out) {
                Ok(n) => appended += n,
                Err(e) => malformed = Some(e),
            }
        }
        let deadline = tokio::time::Instant::now() + self.config.read_timeout;
        while appended == 0 {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                return Err(malformed.unwrap_or_else(|| timeout(self.config.read_timeout)));
            }
            match self
                .recv_within(left.min(self.config.restart_after))
                .await?
            {
                None if left <= self.config.restart_after => {
                    return Err(malformed.unwrap_or_else(|| timeout(self.config.read_timeout)));
                }
                None => {
                    // Silence: ask for the stream anew. Its records start a new
                    // sequence, so the old one is no baseline for gaps.
                    self.send_command(self.start_command(), 0).await?;
                    self.stats.start_commands += 1;
                    self.stats.restarts += 1;
                    self.last_sequence = None;
                    self.new_stream_only = true;
                    self.stamps.reset();
                }
                Some(len) => {
                    let t = self.clock.now();
                    match self.accept_datagram(len, t, out) {
                        Ok(n) => appended += n,
                        Err(e) => malformed = Some(e),
                    }
                }
            }
        }
        // Everything else already received, without waiting.
        loop {
            match self.socket.try_recv(&mut self.buf) {
                Ok(len) => {
                    let t = self.clock.now();
                    // Counted in `bad_datagrams` when malformed.
                    if let Ok(n) = self.accept_datagram(len, t, out) {
                        appended += n;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                // The readings already decoded stand; the next read reports the link.
                Err(_) if appended > 0 => break,
                Err(e) => return Err(link(e)),
            }
        }
        Ok(appended)
    }

    /// Sends the bias and, while streaming, confirms it: the readings must come to
    /// zero (the mean of [`BIAS_CONFIRM_READINGS`] in a row within
    /// `bias_tolerance`) within `reply_timeout`, or the bias is sent again, up to
    /// `bias_attempts` times; then an error names the offset that stayed. The
    /// readings read meanwhile are handed out by the next `read`. Not streaming,
    /// there is nothing to confirm it against: it is sent once.
    async fn bias(&mut self) -> Result<(), DeviceError> {
        if !self.streaming {
            self.stats.bias_commands += 1;
            return self.send_command(Command::Bias, 0).await;
        }
        let (tol_n, tol_nm) = self.config.bias_tolerance;
        // Kept aside while confirming, so that `read` below returns only new ones.
        let mut kept = std::mem::take(&mut self.held);
        let confirmed = self.confirm_bias(tol_n, tol_nm, &mut kept).await;
        kept.append(&mut self.held);
        self.held = kept;
        let last_mean = match confirmed {
            Ok(Ok(())) => return Ok(()),
            Ok(Err(mean)) => mean,
            Err(DeviceError::Timeout { .. }) => None,
            Err(e) => return Err(e),
        };
        Err(DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: format!(
                "bias not confirmed after {} command(s): {}",
                self.config.bias_attempts.max(1),
                last_mean.map_or_else(
                    || "no readings arrived".to_owned(),
                    |m| format!(
                        "the readings stayed at {m} (expected within {tol_n} N and {tol_nm} N·m of zero; is the sensor being touched, or the bias datagram dropped?)"
                    )
                )
            ),
        })
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        self.send_command(Command::Stop, 0).await?;
        self.streaming = false;
        self.pending = None;
        self.held.clear();
        self.drain();
        Ok(())
    }

    fn lost_readings(&self) -> u64 {
        self.stats.lost
    }
}
