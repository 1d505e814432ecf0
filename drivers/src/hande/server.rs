//! A simulated Hand-E: a tokio-modbus [`Service`] with the Hand-E register map,
//! backed by any [`Gripper`] (the simulator's `SimGripper`, a test model), served
//! over a serial port or pty ([`serve_serial`], tokio-modbus's RTU server) or any byte
//! transport ([`serve_rtu`]).
//!
//! It follows the manual: a rising edge on rACT activates (gSTA 1 then 3); rGTO with
//! rACT moves; a major fault ([`HandEService::inject_fault`]) stays until the next
//! rACT edge; requests for another slave id get no answer; registers outside the map
//! get an IllegalDataAddress exception, other function codes IllegalFunction.

use super::regs::{self, FaultClass, RawStatus};
use crate::error::DeviceError;
use crate::gripper::{Gripper, GripperCommand, ObjectStatus};
use std::borrow::Cow;
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio_modbus::server::Service;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Activation {
    Reset,
    Activating,
    Active,
}

#[derive(Debug)]
struct State {
    activation: Activation,
    action: u8,
    command: GripperCommand,
    fault: u8,
    requests: u64,
    /// Raise 0x09 after this long without a write while active (the real gripper's
    /// 1 s communication watchdog); `None`: no watchdog.
    watchdog: Option<std::time::Duration>,
    last_write: Option<tokio::time::Instant>,
    watchdog_faults: u64,
    /// How long the gripper takes to act on an rACT edge (a reset, or the start of an
    /// activation that clears a major fault); until then it reads as before the edge.
    edge_latency: Option<std::time::Duration>,
    /// Hold the next reply back this long (a gripper answering late once).
    next_reply_delay: Option<std::time::Duration>,
}

/// The register-level Hand-E over a [`Gripper`].
#[derive(Debug)]
pub struct HandEService<G> {
    gripper: Arc<tokio::sync::Mutex<G>>,
    state: Arc<Mutex<State>>,
    slave_id: u8,
}

impl<G> Clone for HandEService<G> {
    fn clone(&self) -> Self {
        Self {
            gripper: self.gripper.clone(),
            state: self.state.clone(),
            slave_id: self.slave_id,
        }
    }
}

type Reply = Result<Option<Response>, ExceptionCode>;

impl<G: Gripper + 'static> HandEService<G> {
    /// Serve `gripper` as slave `slave_id`.
    pub fn new(gripper: G, slave_id: u8) -> Self {
        Self {
            gripper: Arc::new(tokio::sync::Mutex::new(gripper)),
            state: Arc::new(Mutex::new(State {
                activation: Activation::Reset,
                action: 0,
                command: GripperCommand {
                    position: 0,
                    speed: 0,
                    force: 0,
                },
                fault: 0,
                requests: 0,
                watchdog: None,
                last_write: None,
                watchdog_faults: 0,
                edge_latency: None,
                next_reply_delay: None,
            })),
            slave_id,
        }
    }

    /// Raise a fault code (gFLT), as the gripper would. A major one stays until the
    /// next rACT edge; others until the next valid command.
    pub fn inject_fault(&self, code: u8) {
        if let Ok(mut s) = self.state.lock() {
            s.fault = code;
        }
    }

    /// Arms the communication watchdog: while activated with rGTO set, a request that
    /// comes more than `after` since the last write raises fault 0x09 (a minor fault,
    /// cleared by the next valid command), as a real Hand-E does after 1 s without a
    /// command. Counted in [`Self::watchdog_faults`].
    #[must_use]
    pub fn with_watchdog(self, after: std::time::Duration) -> Self {
        if let Ok(mut s) = self.state.lock() {
            s.watchdog = Some(after);
        }
        self
    }

    /// Makes rACT edges take `after` to act on, as a real gripper's do: until then
    /// the status still shows the state (and the fault) from before the edge.
    #[must_use]
    pub fn with_edge_latency(self, after: std::time::Duration) -> Self {
        if let Ok(mut s) = self.state.lock() {
            s.edge_latency = Some(after);
        }
        self
    }

    /// Holds the reply to the next request back by `after` (the request is acted on
    /// at once), as a gripper does that answers late once: a client that timed out
    /// meanwhile finds the reply waiting when it sends its next request.
    pub fn delay_next_reply(&self, after: std::time::Duration) {
        if let Ok(mut s) = self.state.lock() {
            s.next_reply_delay = Some(after);
        }
    }

    /// How often the watchdog raised 0x09.
    #[must_use]
    pub fn watchdog_faults(&self) -> u64 {
        self.state.lock().map_or(0, |s| s.watchdog_faults)
    }

    /// Requests answered so far.
    #[must_use]
    pub fn requests(&self) -> u64 {
        self.state.lock().map_or(0, |s| s.requests)
    }

    async fn write(self, words: Vec<u16>) -> Result<(), ExceptionCode> {
        let (action, cmd) =
            regs::decode_output(&words).map_err(|_| ExceptionCode::IllegalDataValue)?;
        let (edge, latency) = {
            let mut s = self
                .state
                .lock()
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            s.last_write = Some(tokio::time::Instant::now());
            let was = s.action & regs::R_ACT != 0;
            let now = action & regs::R_ACT != 0;
            s.action = action;
            s.command = cmd;
            (
                match (was, now) {
                    (true, false) => Some(false),
                    (false, true) => Some(true),
                    _ => None,
                },
                s.edge_latency,
            )
        };
        match (edge, latency) {
            (Some(rising), Some(after)) => {
                // Acted on later; a command beside the edge is judged then too.
                let service = self.clone();
                tokio::spawn(async move {
                    tokio::time::sleep(after).await;
                    let _ = service.act(action, cmd, Some(rising)).await;
                });
                Ok(())
            }
            (edge, _) => self.act(action, cmd, edge).await,
        }
    }

    /// The gripper acting on an output write: `edge` is `Some(true)` for a rising rACT
    /// edge, `Some(false)` for a falling one.
    async fn act(
        self,
        action: u8,
        cmd: GripperCommand,
        edge: Option<bool>,
    ) -> Result<(), ExceptionCode> {
        let (rising, go) = {
            let mut s = self
                .state
                .lock()
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            let now = action & regs::R_ACT != 0;
            if !now {
                s.activation = Activation::Reset;
                // The falling edge arms the clearing of a major fault.
                if matches!(regs::fault_class(s.fault), FaultClass::Priority) {
                    s.fault = 0;
                }
            }
            let rising = edge == Some(true);
            if rising {
                s.fault = 0;
                s.activation = Activation::Activating;
            }
            let go = now && action & regs::R_GTO != 0;
            if go && s.activation != Activation::Active && !rising {
                s.fault = 0x05;
            }
            if !now && action & regs::R_GTO != 0 {
                s.fault = 0x07;
            }
            // A minor fault (0x08, 0x09) clears with the next valid command.
            if go
                && s.activation == Activation::Active
                && regs::fault_class(s.fault) == FaultClass::Minor
            {
                s.fault = 0;
            }
            (
                rising,
                go && s.activation == Activation::Active
                    && regs::fault_class(s.fault) == FaultClass::None,
            )
        };
        if rising {
            let gripper = self.gripper.clone();
            let state = self.state.clone();
            tokio::spawn(async move {
                let ok = gripper.lock().await.activate().await.is_ok();
                if let Ok(mut s) = state.lock()
                    && s.activation == Activation::Activating
                {
                    if ok {
                        s.activation = Activation::Active;
                    } else {
                        s.fault = 0x0D;
                    }
                }
            });
        }
        if go {
            let r = self.gripper.lock().await.command(cmd).await;
            if r.is_err() {
                self.inject_fault(0x0C);
            }
        }
        Ok(())
    }

    async fn read(self) -> Result<Vec<u16>, ExceptionCode> {
        let (activation, action, cmd, fault) = {
            let s = self
                .state
                .lock()
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            (s.activation, s.action, s.command, s.fault)
        };
        let mut raw = RawStatus {
            g_act: action & regs::R_ACT != 0,
            g_gto: action & regs::R_GTO != 0,
            g_sta: 0,
            g_obj: 0,
            g_flt: fault & 0x0F,
            k_flt: fault >> 4,
            g_pr: cmd.position,
            g_po: 0,
            g_cu: 0,
        };
        match activation {
            Activation::Reset => {}
            Activation::Activating => raw.g_sta = 1,
            Activation::Active => {
                let st = self
                    .gripper
                    .lock()
                    .await
                    .status()
                    .await
                    .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
                raw.g_sta = 3;
                raw.g_po = st.position;
                raw.g_pr = st.requested_position;
                raw.g_cu = u8::try_from(st.current_ma / 10).unwrap_or(u8::MAX);
                raw.g_obj = match st.object {
                    ObjectStatus::Moving => 0,
                    ObjectStatus::ContactOpening => 1,
                    ObjectStatus::ContactClosing => 2,
                    ObjectStatus::AtPosition => 3,
                };
                if !raw.g_gto {
                    raw.g_obj = 0;
                }
            }
        }
        Ok(raw.encode().to_vec())
    }

    fn block(addr: u16, cnt: u16, base: u16) -> Result<(), ExceptionCode> {
        if addr == base && cnt == regs::BLOCK_LEN {
            Ok(())
        } else {
            Err(ExceptionCode::IllegalDataAddress)
        }
    }

    async fn handle(self, req: SlaveRequest<'static>) -> Reply {
        if req.slave != self.slave_id {
            return Ok(None);
        }
        let delay = self
            .state
            .lock()
            .ok()
            .and_then(|mut s| s.next_reply_delay.take());
        let reply = self.clone().answer(req).await;
        if let Some(after) = delay {
            tokio::time::sleep(after).await;
        }
        reply
    }

    async fn answer(self, req: SlaveRequest<'static>) -> Reply {
        if let Ok(mut s) = self.state.lock() {
            s.requests += 1;
            let silent = match (s.watchdog, s.last_write) {
                (Some(after), Some(last)) => last.elapsed() > after,
                _ => false,
            };
            if silent
                && s.fault == 0
                && s.activation == Activation::Active
                && s.action & regs::R_GTO != 0
            {
                s.fault = 0x09;
                s.watchdog_faults += 1;
            }
        }
        match req.request {
            Request::ReadInputRegisters(a, n) => {
                Self::block(a, n, regs::INPUT_BASE)?;
                Ok(Some(Response::ReadInputRegisters(self.read().await?)))
            }
            Request::ReadHoldingRegisters(a, n) => {
                Self::block(a, n, regs::INPUT_BASE)?;
                Ok(Some(Response::ReadHoldingRegisters(self.read().await?)))
            }
            Request::WriteMultipleRegisters(a, words) => {
                let n = u16::try_from(words.len()).unwrap_or(u16::MAX);
                Self::block(a, n, regs::OUTPUT_BASE)?;
                self.write(words.into_owned()).await?;
                Ok(Some(Response::WriteMultipleRegisters(a, n)))
            }
            Request::ReadWriteMultipleRegisters(ra, rn, wa, words) => {
                let wn = u16::try_from(words.len()).unwrap_or(u16::MAX);
                Self::block(wa, wn, regs::OUTPUT_BASE)?;
                Self::block(ra, rn, regs::INPUT_BASE)?;
                self.clone().write(words.into_owned()).await?;
                Ok(Some(Response::ReadWriteMultipleRegisters(
                    self.read().await?,
                )))
            }
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }
}

impl<G: Gripper + 'static> Service for HandEService<G> {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Pin<Box<dyn Future<Output = Reply> + Send>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        Box::pin(self.clone().handle(req))
    }
}

fn link(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Link {
        device: "hand-e-server".into(),
        message: e.to_string(),
    }
}

/// Serve on a serial port (or a pty opened as one) with tokio-modbus's RTU server,
/// until `shutdown` completes.
pub async fn serve_serial<G, F>(
    service: HandEService<G>,
    port: tokio_serial::SerialStream,
    shutdown: F,
) -> Result<(), DeviceError>
where
    G: Gripper + 'static,
    F: Future<Output = ()> + Send + Sync + 'static,
{
    tokio_modbus::server::rtu::Server::new(port)
        .serve_until(service, shutdown)
        .await
        .map(|_| ())
        .map_err(link)
}

/// The length of the request frame starting at `b[0]`, when enough bytes are there to
/// tell; `Err` for a function code this server cannot frame.
fn frame_len(b: &[u8]) -> Result<Option<usize>, u8> {
    let Some(&fc) = b.get(1) else { return Ok(None) };
    Ok(match fc {
        0x03 | 0x04 => Some(8),
        0x10 => b.get(6).map(|&n| 9 + usize::from(n)),
        0x17 => b.get(10).map(|&n| 13 + usize::from(n)),
        other => return Err(other),
    })
}

fn be_words(b: &[u8]) -> Vec<u16> {
    b.chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect()
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    b.get(at..at + 2)
        .map_or(0, |c| u16::from_be_bytes([c[0], c[1]]))
}

fn parse_request(f: &[u8]) -> Option<SlaveRequest<'static>> {
    let slave = *f.first()?;
    let request = match *f.get(1)? {
        0x03 => Request::ReadHoldingRegisters(u16_at(f, 2), u16_at(f, 4)),
        0x04 => Request::ReadInputRegisters(u16_at(f, 2), u16_at(f, 4)),
        0x10 => Request::WriteMultipleRegisters(
            u16_at(f, 2),
            Cow::Owned(be_words(f.get(7..f.len() - 2)?)),
        ),
        0x17 => Request::ReadWriteMultipleRegisters(
            u16_at(f, 2),
            u16_at(f, 4),
            u16_at(f, 6),
            Cow::Owned(be_words(f.get(11..f.len() - 2)?)),
        ),
        _ => return None,
    };
    Some(SlaveRequest { slave, request })
}

fn encode_reply(slave: u8, fc: u8, reply: &Reply) -> Option<Vec<u8>> {
    let mut out = vec![slave];
    match reply {
        Ok(None) => return None,
        Err(e) => {
            out.push(fc | 0x80);
            out.push(u8::from(*e));
        }
        Ok(Some(
            Response::ReadInputRegisters(w)
            | Response::ReadHoldingRegisters(w)
            | Response::ReadWriteMultipleRegisters(w),
        )) => {
            out.push(fc);
            out.push(u8::try_from(w.len() * 2).unwrap_or(u8::MAX));
            for x in w {
                out.extend_from_slice(&x.to_be_bytes());
            }
        }
        Ok(Some(Response::WriteMultipleRegisters(a, n))) => {
            out.push(fc);
            out.extend_from_slice(&a.to_be_bytes());
            out.extend_from_slice(&n.to_be_bytes());
        }
        Ok(Some(_)) => {
            out.push(fc | 0x80);
            out.push(u8::from(ExceptionCode::ServerDeviceFailure));
        }
    }
    let crc = regs::crc16(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Some(out)
}

/// Serve Modbus RTU on any byte transport (an in-memory pipe in tests) until
/// `shutdown` completes or the transport closes. Frames with a bad CRC are ignored,
/// as a slave on a bus does.
pub async fn serve_rtu<G, T, F>(
    service: HandEService<G>,
    mut io: T,
    shutdown: F,
) -> Result<(), DeviceError>
where
    G: Gripper + 'static,
    T: AsyncRead + AsyncWrite + Unpin + Send,
    F: Future<Output = ()> + Send,
{
    tokio::pin!(shutdown);
    let mut buf: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 256];
    loop {
        tokio::select! {
            biased;
            () = &mut shutdown => return Ok(()),
            got = io.read(&mut chunk) => {
                let n = got.map_err(link)?;
                if n == 0 {
                    return Ok(());
                }
                buf.extend_from_slice(chunk.get(..n).unwrap_or(&[]));
            }
        }
        loop {
            let len = match frame_len(&buf) {
                Ok(Some(len)) if buf.len() >= len => len,
                Ok(_) if buf.len() < 300 => break,
                Ok(_) => {
                    buf.clear();
                    break;
                }
                Err(fc) => {
                    // Unframeable: answer IllegalFunction if it addressed us, drop the rest.
                    let slave = buf.first().copied().unwrap_or(0);
                    buf.clear();
                    if slave == service.slave_id
                        && let Some(out) =
                            encode_reply(slave, fc, &Err(ExceptionCode::IllegalFunction))
                    {
                        io.write_all(&out).await.map_err(link)?;
                    }
                    break;
                }
            };
            let frame: Vec<u8> = buf.drain(..len).collect();
            let body = frame.get(..len - 2).unwrap_or(&[]);
            let crc = u16::from_le_bytes([frame[len - 2], frame[len - 1]]);
            if regs::crc16(body) != crc {
                buf.clear();
                break;
            }
            let Some(req) = parse_request(&frame) else {
                continue;
            };
            let (slave, fc) = (frame[0], frame[1]);
            let reply = service.call(req).await;
            if let Some(out) = encode_reply(slave, fc, &reply) {
                io.write_all(&out).await.map_err(link)?;
                io.flush().await.map_err(link)?;
            }
        }
    }
}
