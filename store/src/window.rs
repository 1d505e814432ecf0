//! Packing of a force/torque window into a blob.
//!
//! Encoding `ftw1`, per reading, little-endian: `u64 t_ns, u32 rdt_sequence,
//! u32 ft_sequence, u32 status, f64 × 6` (Fx Fy Fz in N, Tx Ty Tz in N·m): 68 bytes.

use softtouch_schemas::{FtReading, FtStatus, TimestampNs, Wrench};

/// Name of the encoding, stored beside each blob.
pub const WINDOW_ENCODING: &str = "ftw1";
const RECORD: usize = 68;

/// Pack readings.
#[must_use]
pub fn encode_window(readings: &[FtReading]) -> Vec<u8> {
    let mut out = Vec::with_capacity(readings.len() * RECORD);
    for r in readings {
        out.extend_from_slice(&r.t.0.to_le_bytes());
        out.extend_from_slice(&r.rdt_sequence.to_le_bytes());
        out.extend_from_slice(&r.ft_sequence.to_le_bytes());
        out.extend_from_slice(&r.status.0.to_le_bytes());
        for v in r.wrench_in_sensor.to_array() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Unpack readings; `None` if the blob is not a whole number of records.
#[must_use]
pub fn decode_window(blob: &[u8]) -> Option<Vec<FtReading>> {
    if !blob.len().is_multiple_of(RECORD) {
        return None;
    }
    let u32_at = |b: &[u8], at: usize| {
        b.get(at..at + 4)
            .and_then(|s| s.try_into().ok())
            .map(u32::from_le_bytes)
    };
    let u64_at = |b: &[u8], at: usize| {
        b.get(at..at + 8)
            .and_then(|s| s.try_into().ok())
            .map(u64::from_le_bytes)
    };
    blob.chunks_exact(RECORD)
        .map(|rec| {
            let mut w = [0.0; 6];
            for (i, v) in w.iter_mut().enumerate() {
                *v = f64::from_bits(u64_at(rec, 20 + 8 * i)?);
            }
            Some(FtReading {
                t: TimestampNs(u64_at(rec, 0)?),
                rdt_sequence: u32_at(rec, 8)?,
                ft_sequence: u32_at(rec, 12)?,
                status: FtStatus(u32_at(rec, 16)?),
                wrench_in_sensor: Wrench::from_array(w),
            })
        })
        .collect()
}
