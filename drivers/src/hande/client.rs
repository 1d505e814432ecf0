//! The Hand-E driver: a [`Gripper`] over Modbus RTU (tokio-modbus) on any transport.

use super::link::{FlushHandle, Flushable};
use super::regs::{self, FaultClass, RawStatus};
use crate::clock::Clock;
use crate::error::DeviceError;
use crate::gripper::{Gripper, GripperCommand, GripperStatus};
use async_trait::async_trait;
use softtouch_schemas::TimestampNs;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};

const DEVICE: &str = "hand-e";

/// Link settings and patience.
#[derive(Debug, Clone, PartialEq)]
pub struct HandEConfig {
    /// Modbus slave id (9 from the factory).
    pub slave_id: u8,
    /// Wait for one reply before [`DeviceError::Timeout`].
    pub reply_timeout: Duration,
    /// Least time between two transactions (the Hand-E takes at most 200 per second).
    pub min_interval: Duration,
    /// Longest activation.
    pub activation_timeout: Duration,
    /// Status polling period while activating.
    pub poll_interval: Duration,
}

impl Default for HandEConfig {
    fn default() -> Self {
        Self {
            slave_id: regs::DEFAULT_SLAVE,
            reply_timeout: Duration::from_millis(200),
            min_interval: Duration::from_millis(5),
            activation_timeout: Duration::from_secs(10),
            poll_interval: Duration::from_millis(20),
        }
    }
}

/// Counters of what the link did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HandEStats {
    /// Transactions started.
    pub transactions: u64,
    /// Exception replies.
    pub exceptions: u64,
    /// Replies that never came (or came corrupted and were discarded).
    pub timeouts: u64,
    /// Flushes of the port after a timeout or a mismatched reply.
    pub flushes: u64,
    /// Bytes those flushes dropped (late replies).
    pub flushed_bytes: u64,
}

/// A Robotiq Hand-E.
pub struct HandE {
    ctx: Context,
    clock: Arc<dyn Clock>,
    config: HandEConfig,
    last_transaction: Option<TimestampNs>,
    last_status: Option<RawStatus>,
    stats: HandEStats,
    flush: FlushHandle,
    /// A reply went missing or did not match: flush before the next request.
    flush_due: bool,
}

impl std::fmt::Debug for HandE {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HandE")
            .field("config", &self.config)
            .field("last_status", &self.last_status)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

fn link(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: e.to_string(),
    }
}

fn exception(e: ExceptionCode) -> DeviceError {
    DeviceError::Fault {
        device: DEVICE.into(),
        code: Some(u32::from(u8::from(e))),
        message: format!("exception reply: {e}"),
    }
}

fn fault(code: u8) -> DeviceError {
    let hint = if major(code) {
        "; activate again (rACT 0 then 1) to clear it"
    } else {
        ""
    };
    DeviceError::Fault {
        device: DEVICE.into(),
        code: Some(u32::from(code)),
        message: format!("{}{hint}", regs::describe_fault(code)),
    }
}

/// A fault that only a new activation edge clears (or one the manual does not list).
fn major(code: u8) -> bool {
    matches!(
        regs::fault_class(code),
        FaultClass::Major | FaultClass::Unknown
    )
}

impl HandE {
    /// An error once activation has taken longer than its limit: the last fault by
    /// name when there is one, else a timeout.
    fn check_activation_time(&self, start: TimestampNs, s: &RawStatus) -> Result<(), DeviceError> {
        let limit = u64::try_from(self.config.activation_timeout.as_nanos()).unwrap_or(u64::MAX);
        if self.clock.now().0.saturating_sub(start.0) <= limit {
            return Ok(());
        }
        let timeout_ms =
            u64::try_from(self.config.activation_timeout.as_millis()).unwrap_or(u64::MAX);
        if s.fault_byte() != 0 {
            return Err(DeviceError::Fault {
                device: DEVICE.into(),
                code: Some(u32::from(s.fault_byte())),
                message: format!(
                    "activation did not complete within {timeout_ms} ms (gSTA {}): {}",
                    s.g_sta,
                    regs::describe_fault(s.fault_byte())
                ),
            });
        }
        Err(DeviceError::Timeout {
            device: DEVICE.into(),
            timeout_ms,
        })
    }

    /// Talk Modbus RTU over `transport` (a serial port from [`super::open_port`], a pty,
    /// an in-memory pipe).
    pub fn new<T>(transport: T, config: HandEConfig, clock: Arc<dyn Clock>) -> Self
    where
        T: AsyncRead + AsyncWrite + Unpin + Send + std::fmt::Debug + 'static,
    {
        let flush = FlushHandle::default();
        let ctx = tokio_modbus::client::rtu::attach_slave(
            Flushable::new(transport, flush.clone()),
            Slave(config.slave_id),
        );
        Self {
            ctx,
            clock,
            config,
            last_transaction: None,
            last_status: None,
            stats: HandEStats::default(),
            flush,
            flush_due: false,
        }
    }

    /// What the link did so far.
    #[must_use]
    pub fn stats(&self) -> HandEStats {
        HandEStats {
            flushed_bytes: self.flush.dropped_bytes(),
            ..self.stats
        }
    }

    /// After a lost or mismatched reply: wait one reply timeout for a late reply to
    /// arrive, then have it dropped before the next request goes out. A reply later
    /// than twice the timeout is not caught; its request's function code then
    /// usually differs and the mismatch flushes again.
    async fn flush_if_due(&mut self) {
        if self.flush_due {
            self.flush_due = false;
            tokio::time::sleep(self.config.reply_timeout).await;
            self.flush.request();
            self.stats.flushes += 1;
        }
    }

    /// Wait out the 200-per-second limit, on the injected clock.
    async fn pace(&mut self) {
        if let Some(last) = self.last_transaction {
            let next = last.0.saturating_add(
                u64::try_from(self.config.min_interval.as_nanos()).unwrap_or(u64::MAX),
            );
            let now = self.clock.now().0;
            if next > now {
                tokio::time::sleep(Duration::from_nanos(next - now)).await;
            }
        }
        self.last_transaction = Some(self.clock.now());
        self.stats.transactions += 1;
    }

    async fn transact<R, F>(&mut self, call: F) -> Result<R, DeviceError>
    where
        F: for<'a> FnOnce(
            &'a mut Context,
        ) -> std::pin::Pin<
            Box<dyn std::future::Future<Output = tokio_modbus::Result<R>> + Send + 'a>,
        >,
    {
        self.flush_if_due().await;
        self.pace().await;
        let wait = self.config.reply_timeout;
        match tokio::time::timeout(wait, call(&mut self.ctx)).await {
            Err(_) => {
                self.stats.timeouts += 1;
                self.flush_due = true;
                Err(DeviceError::Timeout {
                    device: DEVICE.into(),
                    timeout_ms: u64::try_from(wait.as_millis()).unwrap_or(u64::MAX),
                })
            }
            Ok(Err(tokio_modbus::Error::Transport(e))) => Err(link(e)),
            Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                // A reply for another request (a late one): what follows is suspect too.
                self.flush_due = true;
                Err(DeviceError::Protocol {
                    device: DEVICE.into(),
                    message: e.to_string(),
                })
            }
            Ok(Ok(Err(e))) => {
                self.stats.exceptions += 1;
                Err(exception(e))
            }
            Ok(Ok(Ok(v))) => Ok(v),
        }
    }

    /// Read the three input registers.
    pub async fn read_raw_status(&mut self) -> Result<RawStatus, DeviceError> {
        let words = self
            .transact(|c| Box::pin(c.read_input_registers(regs::INPUT_BASE, regs::BLOCK_LEN)))
            .await?;
        let s = regs::decode_status(&words).map_err(|m| DeviceError::Protocol {
            device: DEVICE.into(),
            message: m,
        })?;
        self.last_status = Some(s);
        Ok(s)
    }

    /// Write the three output registers and read the three input registers in one
    /// transaction (function 23: the Hand-E writes first, then answers the read).
    pub async fn write_output_read_status(
        &mut self,
        action: u8,
        cmd: GripperCommand,
    ) -> Result<RawStatus, DeviceError> {
        let words = regs::encode_output(action, cmd);
        let read = self
            .transact(move |c| {
                Box::pin(async move {
                    c.read_write_multiple_registers(
                        regs::INPUT_BASE,
                        regs::BLOCK_LEN,
                        regs::OUTPUT_BASE,
                        &words,
                    )
                    .await
                })
            })
            .await?;
        let s = regs::decode_status(&read).map_err(|m| DeviceError::Protocol {
            device: DEVICE.into(),
            message: m,
        })?;
        self.last_status = Some(s);
        Ok(s)
    }

    /// The last status read refuses a move: a major fault, or no activation.
    fn refuse_move(&self) -> Result<(), DeviceError> {
        if let Some(s) = self.last_status {
            if major(s.fault_byte()) {
                return Err(fault(s.fault_byte()));
            }
            if !s.active() {
                return Err(DeviceError::InvalidCommand {
                    device: DEVICE.into(),
                    message: "not activated".into(),
                });
            }
        }
        Ok(())
    }

    fn decoded(&self, s: &RawStatus) -> GripperStatus {
        GripperStatus {
            t: self.clock.now(),
            activated: s.active(),
            object: s.object(),
            fault: s.fault_byte(),
            requested_position: s.g_pr,
            position: s.g_po,
            current_ma: u32::from(s.g_cu) * 10,
        }
    }

    /// Write the three output registers.
    pub async fn write_output(
        &mut self,
        action: u8,
        cmd: GripperCommand,
    ) -> Result<(), DeviceError> {
        let words = regs::encode_output(action, cmd);
        self.transact(move |c| {
            Box::pin(async move { c.write_multiple_registers(regs::OUTPUT_BASE, &words).await })
        })
        .await
    }
}

#[async_trait]
impl Gripper for HandE {
    /// Activation, idempotent and patient with a real gripper's timing:
    /// - already active without a major fault: nothing is written (a reset would open
    ///   the fingers and drop what they hold);
    /// - else rACT 0, a wait until the gripper shows the reset (gSTA 0), then rACT 1 (a
    ///   rising edge, which also clears a major fault) and a poll until gSTA = 3;
    /// - a major fault read before the gripper shows the activation under way (gSTA 1
    ///   or 3) is the old one, not cleared yet, and is waited out; one read after is
    ///   returned, by name. A timeout names the last status's fault.
    async fn activate(&mut self) -> Result<(), DeviceError> {
        let first = self.read_raw_status().await?;
        if first.active() && !major(first.fault_byte()) {
            return Ok(());
        }
        let zero = GripperCommand {
            position: 0,
            speed: 0,
            force: 0,
        };
        let start = self.clock.now();
        self.write_output(0, zero).await?;
        loop {
            let s = self.read_raw_status().await?;
            if s.g_sta == 0 {
                break;
            }
            self.check_activation_time(start, &s)?;
            tokio::time::sleep(self.config.poll_interval).await;
        }
        self.write_output(regs::R_ACT, zero).await?;
        let mut under_way = false;
        loop {
            let s = self.read_raw_status().await?;
            under_way |= s.g_sta != 0;
            if under_way && major(s.fault_byte()) {
                return Err(fault(s.fault_byte()));
            }
            if s.active() {
                return Ok(());
            }
            self.check_activation_time(start, &s)?;
            tokio::time::sleep(self.config.poll_interval).await;
        }
    }

    /// rACT | rGTO with the move. Refused without sending when the last status read
    /// showed a major fault or no activation.
    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        self.refuse_move()?;
        self.write_output(regs::R_ACT | regs::R_GTO, cmd).await
    }

    /// The decoded status; a fault is reported in `fault`, not as an error (the
    /// caller decides; [`Gripper::command`] refuses on a major one).
    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        let s = self.read_raw_status().await?;
        Ok(self.decoded(&s))
    }

    /// The move and the status read back in one function-23 transaction: half the
    /// link time of a write and a read (with an FTDI adapter's default 16 ms latency
    /// timer, the difference between about 25 and 50 exchanges a second). Refused as
    /// [`Gripper::command`] is.
    async fn command_and_status(
        &mut self,
        cmd: GripperCommand,
    ) -> Result<GripperStatus, DeviceError> {
        self.refuse_move()?;
        let s = self
            .write_output_read_status(regs::R_ACT | regs::R_GTO, cmd)
            .await?;
        Ok(self.decoded(&s))
    }
}
