//! A simulated serial F/T controller: serves any [`ForceSensor`] over the ASCII
//! protocol on any byte transport (a pty, a serial port, an in-memory pipe).
//!
//! Commands end with CR; each is answered by its output (if any) and the `>` prompt.
//! `QS` streams records until any byte arrives. Unknown commands are answered with
//! `ERR` before the prompt.

use super::codec::{self, AsciiRecord};
use crate::error::DeviceError;
use crate::force::ForceSensor;
use softtouch_schemas::FtReading;
use std::future::Future;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

const DEVICE: &str = "ati-serial-peer";

fn link(e: impl std::fmt::Display) -> DeviceError {
    DeviceError::Link {
        device: DEVICE.into(),
        message: e.to_string(),
    }
}

fn counts(v: f64, per: f64) -> i32 {
    let c = (v * per).round();
    if c.is_nan() {
        0
    } else {
        c.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }
}

/// The record line for a reading.
#[must_use]
pub fn record_for(r: &FtReading, counts_per_force: f64, counts_per_torque: f64) -> AsciiRecord {
    let w = &r.wrench_in_sensor;
    AsciiRecord {
        error: if r.status.is_ok() {
            0
        } else {
            (r.status.0 >> 16).max(1)
        },
        counts: [
            counts(w.force_n[0], counts_per_force),
            counts(w.force_n[1], counts_per_force),
            counts(w.force_n[2], counts_per_force),
            counts(w.torque_nm[0], counts_per_torque),
            counts(w.torque_nm[1], counts_per_torque),
            counts(w.torque_nm[2], counts_per_torque),
        ],
    }
}

/// Serve `sensor` on `io` until `shutdown` completes or the transport closes.
/// Returns the number of records sent.
pub async fn serve<S, T, F>(
    mut sensor: S,
    mut io: T,
    counts_per_force: f64,
    counts_per_torque: f64,
    shutdown: F,
) -> Result<u64, DeviceError>
where
    S: ForceSensor,
    T: AsyncRead + AsyncWrite + Unpin + Send,
    F: Future<Output = ()> + Send,
{
    tokio::pin!(shutdown);
    let mut streaming = false;
    let mut line: Vec<u8> = Vec::new();
    let mut readings: Vec<FtReading> = Vec::new();
    let mut sent = 0u64;
    let mut chunk = [0u8; 256];
    loop {
        readings.clear();
        tokio::select! {
            biased;
            () = &mut shutdown => break,
            got = io.read(&mut chunk) => {
                let n = got.map_err(link)?;
                if n == 0 {
                    break;
                }
                if streaming {
                    // Any character stops the stream.
                    streaming = false;
                    sensor.stop().await?;
                    line.clear();
                    io.write_all(b"\r\n>").await.map_err(link)?;
                    continue;
                }
                for &b in chunk.get(..n).unwrap_or(&[]) {
                    if b != b'\r' {
                        if line.len() < 64 {
                            line.push(b);
                        }
                        continue;
                    }
                    let cmd = String::from_utf8_lossy(&line).trim().to_ascii_uppercase();
                    line.clear();
                    let reply: Vec<u8> = match cmd.as_str() {
                        "" | "CD A" | "CD R" | "SU" | "SZ" => b">".to_vec(),
                        "SB" => {
                            sensor.bias().await?;
                            b">".to_vec()
                        }
                        "QR" => {
                            sensor.start().await?;
                            let mut one = Vec::new();
                            sensor.read(&mut one).await?;
                            sensor.stop().await?;
                            let mut v = one
                                .last()
                                .map(|r| codec::format_record(&record_for(r, counts_per_force, counts_per_torque)))
                                .unwrap_or_default()
                                .into_bytes();
                            v.push(b'>');
                            v
                        }
                        "QS" => {
                            sensor.start().await?;
                            streaming = true;
                            Vec::new()
                        }
                        _ if cmd.starts_with("SA ") || cmd.starts_with("CB ") => b">".to_vec(),
                        _ => b"ERR\r\n>".to_vec(),
                    };
                    io.write_all(&reply).await.map_err(link)?;
                    if streaming {
                        break;
                    }
                }
                io.flush().await.map_err(link)?;
            }
            got = sensor.read(&mut readings), if streaming => {
                got?;
                let mut text = String::new();
                for r in &readings {
                    text.push_str(&codec::format_record(&record_for(r, counts_per_force, counts_per_torque)));
                }
                io.write_all(text.as_bytes()).await.map_err(link)?;
                io.flush().await.map_err(link)?;
                sent += readings.len() as u64;
            }
        }
    }
    let _ = sensor.stop().await;
    Ok(sent)
}
