//! A simulated Net F/T: serves any [`ForceSensor`] over real RDT (UDP) and the TCP
//! calibration request, so the client (or any RDT program) can be run against it.
//!
//! Readings the served sensor reports lost ([`ForceSensor::lost_readings`]) show up on
//! the wire as gaps in `rdt_sequence`, the way a real sensor's lost datagrams would.

use super::codec::{self, Calibration, Command, RawRecord};
use crate::error::DeviceError;
use crate::force::ForceSensor;
use softtouch_schemas::FtReading;
use std::future::Future;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, UdpSocket};

const DEVICE: &str = "net-ft-server";

/// Where to listen and what to claim.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerConfig {
    /// UDP address for RDT (49152 on a sensor; port 0 picks a free one).
    pub rdt_bind: SocketAddr,
    /// TCP address for the calibration request (49151 on a sensor), or none.
    pub calibration_bind: Option<SocketAddr>,
    /// The calibration reported, and used to turn wrenches into counts.
    pub calibration: Calibration,
    /// Records per datagram in buffered mode (a Net F/T's RDT buffer size).
    pub records_per_datagram: usize,
}

impl ServerConfig {
    /// RDT at `rdt_bind`, calibration on TCP one port below it (49151 for 49152; port 0
    /// for port 0), N and N·m at 1 000 000 counts per unit, 10 records per buffered
    /// datagram.
    #[must_use]
    pub fn at(rdt_bind: SocketAddr) -> Self {
        let cal_port = rdt_bind.port().saturating_sub(1);
        Self {
            rdt_bind,
            calibration_bind: Some(SocketAddr::new(rdt_bind.ip(), cal_port)),
            calibration: Calibration::si(1_000_000, 1_000_000),
            records_per_datagram: 10,
        }
    }
}

/// What the server did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServerStats {
    /// Valid RDT requests received.
    pub commands: u64,
    /// Requests that were not valid RDT.
    pub bad_requests: u64,
    /// Datagrams sent.
    pub datagrams_sent: u64,
    /// Records sent.
    pub records_sent: u64,
    /// Readings the served sensor lost (sent as sequence gaps).
    pub records_lost: u64,
}

/// A bound server; [`NetFtServer::run`] serves it.
#[derive(Debug)]
pub struct NetFtServer<S> {
    sensor: S,
    udp: UdpSocket,
    tcp: Option<TcpListener>,
    config: ServerConfig,
    counts_per_si: (f64, f64),
}

fn link(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: e.to_string(),
    }
}

fn to_counts(v: f64, counts_per_unit: f64) -> i32 {
    let c = (v * counts_per_unit).round();
    if c.is_nan() {
        0
    } else {
        c.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }
}

/// Serve `sensor` until `shutdown` completes: bind, then [`NetFtServer::run`].
pub async fn serve<S, F>(
    sensor: S,
    config: ServerConfig,
    shutdown: F,
) -> Result<ServerStats, DeviceError>
where
    S: ForceSensor,
    F: Future<Output = ()> + Send,
{
    NetFtServer::bind(sensor, config).await?.run(shutdown).await
}

struct Stream {
    client: SocketAddr,
    buffered: bool,
    next_sequence: u32,
    remaining: Option<u32>,
}

impl<S: ForceSensor> NetFtServer<S> {
    /// Bind the sockets.
    pub async fn bind(sensor: S, config: ServerConfig) -> Result<Self, DeviceError> {
        let counts_per_si =
            config
                .calibration
                .counts_per_si()
                .map_err(|e| DeviceError::InvalidCommand {
                    device: DEVICE.into(),
                    message: e.to_string(),
                })?;
        let udp = UdpSocket::bind(config.rdt_bind).await.map_err(link)?;
        let tcp = match config.calibration_bind {
            Some(a) => Some(TcpListener::bind(a).await.map_err(link)?),
            None => None,
        };
        Ok(Self {
            sensor,
            udp,
            tcp,
            config,
            counts_per_si,
        })
    }

    /// The bound RDT address.
    pub fn rdt_addr(&self) -> Result<SocketAddr, DeviceError> {
        self.udp.local_addr().map_err(link)
    }

    /// The bound calibration address.
    pub fn calibration_addr(&self) -> Result<Option<SocketAddr>, DeviceError> {
        self.tcp
            .as_ref()
            .map(|t| t.local_addr().map_err(link))
            .transpose()
    }

    fn record(&self, r: &FtReading, rdt_sequence: u32) -> RawRecord {
        let (cpf, cpt) = self.counts_per_si;
        let w = &r.wrench_in_sensor;
        RawRecord {
            rdt_sequence,
            ft_sequence: r.ft_sequence,
            status: r.status.0,
            counts: [
                to_counts(w.force_n[0], cpf),
                to_counts(w.force_n[1], cpf),
                to_counts(w.force_n[2], cpf),
                to_counts(w.torque_nm[0], cpt),
                to_counts(w.torque_nm[1], cpt),
                to_counts(w.torque_nm[2], cpt),
            ],
        }
    }

    /// Serve until `shutdown` completes (or the sensor fails), then stop the sensor.
    pub async fn run<F>(mut self, shutdown: F) -> Result<ServerStats, DeviceError>
    where
        F: Future<Output = ()> + Send,
    {
        let calibration = self.tcp.take().map(|listener| {
            let reply = codec::encode_calibration_reply(&self.config.calibration);
            tokio::spawn(serve_calibration(listener, reply))
        });
        let result = self.serve_rdt(shutdown).await;
        if let Some(task) = calibration {
            task.abort();
        }
        let stopped = self.sensor.stop().await;
        let stats = result?;
        stopped.map(|()| stats)
    }

    async fn serve_rdt<F>(&mut self, shutdown: F) -> Result<ServerStats, DeviceError>
    where
        F: Future<Output = ()> + Send,
    {
        tokio::pin!(shutdown);
        let mut stats = ServerStats::default();
        let mut stream: Option<Stream> = None;
        let mut request = [0u8; 64];
        let mut readings: Vec<FtReading> = Vec::new();
        let mut datagram: Vec<u8> = Vec::new();
        loop {
            readings.clear();
            let lost_before = self.sensor.lost_readings();
            let streaming = stream.is_some();
            tokio::select! {
                biased;
                () = &mut shutdown => return Ok(stats),
                got = self.udp.recv_from(&mut request) => {
                    let (len, from) = match got {
                        Ok(x) => x,
                        // An ICMP error from a client that went away: keep serving.
                        Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused
                            || e.kind() == std::io::ErrorKind::ConnectionReset => continue,
                        Err(e) => return Err(link(e)),
                    };
                    let Ok(req) = codec::decode_request(request.get(..len).unwrap_or(&[])) else {
                        stats.bad_requests += 1;
                        continue;
                    };
                    stats.commands += 1;
                    match req.command {
                        Command::RealTime | Command::Buffered | Command::MultiUnit => {
                            self.sensor.start().await?;
                            // The newest command wins; a second client steals the stream.
                            stream = Some(Stream {
                                client: from,
                                buffered: req.command == Command::Buffered,
                                next_sequence: 1,
                                remaining: (req.sample_count > 0).then_some(req.sample_count),
                            });
                        }
                        Command::Stop => {
                            stream = None;
                            self.sensor.stop().await?;
                        }
                        Command::Bias => self.sensor.bias().await?,
                        Command::ResetLatch => {}
                    }
                }
                got = self.sensor.read(&mut readings), if streaming => {
                    got?;
                    let Some(s) = stream.as_mut() else { continue };
                    let lost = self.sensor.lost_readings().saturating_sub(lost_before);
                    stats.records_lost += lost;
                    s.next_sequence = s.next_sequence.wrapping_add(u32::try_from(lost).unwrap_or(u32::MAX));
                    let mut take = readings.len();
                    if let Some(rem) = s.remaining {
                        take = take.min(usize::try_from(rem).unwrap_or(usize::MAX));
                    }
                    let per = if s.buffered { self.config.records_per_datagram.max(1) } else { 1 };
                    for chunk in readings.get(..take).unwrap_or(&[]).chunks(per) {
                        datagram.clear();
                        for r in chunk {
                            let rec = self.record(r, s.next_sequence);
                            s.next_sequence = s.next_sequence.wrapping_add(1);
                            datagram.extend_from_slice(&codec::encode_record(&rec));
                        }
                        match self.udp.send_to(&datagram, s.client).await {
                            Ok(_) => {
                                stats.datagrams_sent += 1;
                                stats.records_sent += chunk.len() as u64;
                            }
                            // UDP: a full buffer or a vanished client loses the datagram,
                            // as on a real sensor.
                            Err(e) if matches!(e.kind(), std::io::ErrorKind::ConnectionRefused
                                | std::io::ErrorKind::WouldBlock) => {}
                            Err(e) => return Err(link(e)),
                        }
                    }
                    if let Some(rem) = s.remaining.as_mut() {
                        *rem = rem.saturating_sub(u32::try_from(take).unwrap_or(u32::MAX));
                        if *rem == 0 {
                            stream = None;
                        }
                    }
                }
            }
        }
    }
}

async fn serve_calibration(listener: TcpListener, reply: [u8; codec::CALIBRATION_REPLY_LEN]) {
    loop {
        let Ok((mut conn, _)) = listener.accept().await else {
            continue;
        };
        tokio::spawn(async move {
            let mut req = [0u8; codec::CALIBRATION_REQUEST_LEN];
            let read =
                tokio::time::timeout(Duration::from_secs(2), conn.read_exact(&mut req)).await;
            if matches!(read, Ok(Ok(_))) && codec::decode_calibration_request(&req).is_ok() {
                let _ = conn.write_all(&reply).await;
            }
        });
    }
}
