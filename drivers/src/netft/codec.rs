//! The Net F/T wire formats, as pure functions: RDT requests and records (UDP 49152)
//! and the calibration request and reply (TCP 49151). Every decoder takes any bytes
//! and returns an error for bytes that do not follow the protocol; none panics.
//!
//! All fields are big-endian (docs/PROTOCOLS.md §1.1).

/// UDP port of the RDT stream.
pub const RDT_PORT: u16 = 49152;
/// TCP port of the calibration request (`READCALINFO`).
pub const CALIBRATION_PORT: u16 = 49151;
/// The header of every request and of the calibration reply.
pub const HEADER: u16 = 0x1234;
/// Bytes in one RDT request.
pub const REQUEST_LEN: usize = 8;
/// Bytes in one RDT record.
pub const RECORD_LEN: usize = 36;
/// Bytes in the calibration request.
pub const CALIBRATION_REQUEST_LEN: usize = 20;
/// Bytes in the calibration reply.
pub const CALIBRATION_REPLY_LEN: usize = 24;
/// Most records a datagram may carry (the RDT buffer holds at most 40 on a Net F/T;
/// more is accepted up to this bound so a generous peer still decodes).
pub const MAX_RECORDS_PER_DATAGRAM: usize = 1000;

/// RDT command codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `0x0000`: stop streaming.
    Stop,
    /// `0x0002`: real-time streaming, one record per datagram.
    RealTime,
    /// `0x0003`: buffered streaming, several records per datagram.
    Buffered,
    /// `0x0004`: multi-unit synchronised streaming.
    MultiUnit,
    /// `0x0041`: reset the threshold latch.
    ResetLatch,
    /// `0x0042`: software bias (tare).
    Bias,
}

impl Command {
    /// The code on the wire.
    #[must_use]
    pub const fn code(self) -> u16 {
        match self {
            Self::Stop => 0x0000,
            Self::RealTime => 0x0002,
            Self::Buffered => 0x0003,
            Self::MultiUnit => 0x0004,
            Self::ResetLatch => 0x0041,
            Self::Bias => 0x0042,
        }
    }

    /// The command for a code (extended RDT's high bit is ignored).
    #[must_use]
    pub const fn from_code(code: u16) -> Option<Self> {
        match code & 0x7FFF {
            0x0000 => Some(Self::Stop),
            0x0002 => Some(Self::RealTime),
            0x0003 => Some(Self::Buffered),
            0x0004 => Some(Self::MultiUnit),
            0x0041 => Some(Self::ResetLatch),
            0x0042 => Some(Self::Bias),
            _ => None,
        }
    }
}

/// An RDT request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request {
    /// What to do.
    pub command: Command,
    /// Records to send; 0 streams until stopped.
    pub sample_count: u32,
}

/// One RDT record, in counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RawRecord {
    /// Transport sequence: 1 for the first record of each request, wrapping at 2^32.
    pub rdt_sequence: u32,
    /// The sensor's internal sample counter since power-up.
    pub ft_sequence: u32,
    /// Status word (0 = OK).
    pub status: u32,
    /// `Fx Fy Fz Tx Ty Tz` in counts.
    pub counts: [i32; 6],
}

/// The calibration reply (`READCALINFO`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Calibration {
    /// Force unit code (2 = N).
    pub force_unit: u8,
    /// Torque unit code (3 = N·m, 4 = N·mm).
    pub torque_unit: u8,
    /// Counts per force unit.
    pub counts_per_force: u32,
    /// Counts per torque unit.
    pub counts_per_torque: u32,
    /// Scaling factors of the six axes (analog output; unused here).
    pub scale: [u16; 6],
}

impl Calibration {
    /// A calibration in N and N·m with the given counts per unit.
    #[must_use]
    pub const fn si(counts_per_force: u32, counts_per_torque: u32) -> Self {
        Self {
            force_unit: 2,
            torque_unit: 3,
            counts_per_force,
            counts_per_torque,
            scale: [1; 6],
        }
    }

    /// Counts per newton and counts per newton-metre, converting the sensor's units.
    pub fn counts_per_si(&self) -> Result<(f64, f64), CodecError> {
        let n_per_unit = force_unit_in_newtons(self.force_unit).ok_or(CodecError::UnknownUnit {
            force: true,
            code: self.force_unit,
        })?;
        let nm_per_unit =
            torque_unit_in_newton_metres(self.torque_unit).ok_or(CodecError::UnknownUnit {
                force: false,
                code: self.torque_unit,
            })?;
        if self.counts_per_force == 0 || self.counts_per_torque == 0 {
            return Err(CodecError::ZeroCounts);
        }
        Ok((
            f64::from(self.counts_per_force) / n_per_unit,
            f64::from(self.counts_per_torque) / nm_per_unit,
        ))
    }
}

/// Newtons in one ATI force unit (1 lbf, 2 N, 3 klbf, 4 kN, 5 kgf, 6 gf).
#[must_use]
pub fn force_unit_in_newtons(code: u8) -> Option<f64> {
    Some(match code {
        1 => 4.448_221_615_260_5,
        2 => 1.0,
        3 => 4_448.221_615_260_5,
        4 => 1_000.0,
        5 => 9.806_65,
        6 => 0.009_806_65,
        _ => return None,
    })
}

/// Newton-metres in one ATI torque unit (1 lbf·in, 2 lbf·ft, 3 N·m, 4 N·mm, 5 kgf·cm,
/// 6 kN·m).
#[must_use]
pub fn torque_unit_in_newton_metres(code: u8) -> Option<f64> {
    Some(match code {
        1 => 0.112_984_829_027_616_7,
        2 => 1.355_817_948_331_400_4,
        3 => 1.0,
        4 => 0.001,
        5 => 0.098_066_5,
        6 => 1_000.0,
        _ => return None,
    })
}

/// What was wrong with the bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    /// Fewer bytes than the message needs.
    #[error("truncated: {len} bytes, expected {expected}")]
    Truncated {
        /// Bytes received.
        len: usize,
        /// Bytes expected.
        expected: usize,
    },
    /// More bytes than the message may have.
    #[error("oversized: {len} bytes, at most {max}")]
    Oversized {
        /// Bytes received.
        len: usize,
        /// The most allowed.
        max: usize,
    },
    /// A datagram that is not a whole number of records.
    #[error("{len} bytes is not a whole number of {RECORD_LEN}-byte records")]
    PartialRecord {
        /// Bytes received.
        len: usize,
    },
    /// The header is not `0x1234`.
    #[error("wrong header 0x{0:04X}, expected 0x1234")]
    WrongHeader(u16),
    /// An unknown command code.
    #[error("unknown command 0x{0:04X}")]
    UnknownCommand(u16),
    /// The calibration request does not start with 1.
    #[error("calibration request starts with {0}, expected 1")]
    NotCalibrationRequest(u8),
    /// A unit code this driver does not know.
    #[error("unknown {} unit code {code}", if *force { "force" } else { "torque" })]
    UnknownUnit {
        /// Force (true) or torque.
        force: bool,
        /// The code.
        code: u8,
    },
    /// Counts per unit of zero cannot scale anything.
    #[error("counts per unit is zero")]
    ZeroCounts,
}

fn be_u16(b: &[u8], at: usize) -> u16 {
    match b.get(at..at + 2) {
        Some(&[x, y]) => u16::from_be_bytes([x, y]),
        _ => 0,
    }
}

fn be_u32(b: &[u8], at: usize) -> u32 {
    match b.get(at..at + 4) {
        Some(&[a, c, d, e]) => u32::from_be_bytes([a, c, d, e]),
        _ => 0,
    }
}

/// The 8-byte request for `command` with `sample_count` (0 = until stopped).
#[must_use]
pub fn encode_request(command: Command, sample_count: u32) -> [u8; REQUEST_LEN] {
    let mut out = [0u8; REQUEST_LEN];
    out[0..2].copy_from_slice(&HEADER.to_be_bytes());
    out[2..4].copy_from_slice(&command.code().to_be_bytes());
    out[4..8].copy_from_slice(&sample_count.to_be_bytes());
    out
}

/// Decode a request (the sensor's side). Extended requests (high bit set, with an
/// address appended) are accepted and their destination ignored.
pub fn decode_request(bytes: &[u8]) -> Result<Request, CodecError> {
    if bytes.len() < REQUEST_LEN {
        return Err(CodecError::Truncated {
            len: bytes.len(),
            expected: REQUEST_LEN,
        });
    }
    let max = REQUEST_LEN + 8;
    if bytes.len() > max {
        return Err(CodecError::Oversized {
            len: bytes.len(),
            max,
        });
    }
    let header = be_u16(bytes, 0);
    if header != HEADER {
        return Err(CodecError::WrongHeader(header));
    }
    let code = be_u16(bytes, 2);
    let command = Command::from_code(code).ok_or(CodecError::UnknownCommand(code))?;
    Ok(Request {
        command,
        sample_count: be_u32(bytes, 4),
    })
}

/// The 36 bytes of a record.
#[must_use]
pub fn encode_record(r: &RawRecord) -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    out[0..4].copy_from_slice(&r.rdt_sequence.to_be_bytes());
    out[4..8].copy_from_slice(&r.ft_sequence.to_be_bytes());
    out[8..12].copy_from_slice(&r.status.to_be_bytes());
    for (i, c) in r.counts.iter().enumerate() {
        out[12 + 4 * i..16 + 4 * i].copy_from_slice(&c.to_be_bytes());
    }
    out
}

/// Decode one 36-byte record.
pub fn decode_record(bytes: &[u8]) -> Result<RawRecord, CodecError> {
    if bytes.len() < RECORD_LEN {
        return Err(CodecError::Truncated {
            len: bytes.len(),
            expected: RECORD_LEN,
        });
    }
    if bytes.len() > RECORD_LEN {
        return Err(CodecError::Oversized {
            len: bytes.len(),
            max: RECORD_LEN,
        });
    }
    Ok(RawRecord {
        rdt_sequence: be_u32(bytes, 0),
        ft_sequence: be_u32(bytes, 4),
        status: be_u32(bytes, 8),
        counts: std::array::from_fn(|i| be_u32(bytes, 12 + 4 * i) as i32),
    })
}

/// Decode a datagram of one (real-time) or several (buffered) records, appending them
/// to `out`. Nothing is appended unless the whole datagram is valid.
pub fn decode_records(datagram: &[u8], out: &mut Vec<RawRecord>) -> Result<usize, CodecError> {
    let len = datagram.len();
    if len < RECORD_LEN {
        return Err(CodecError::Truncated {
            len,
            expected: RECORD_LEN,
        });
    }
    let max = RECORD_LEN * MAX_RECORDS_PER_DATAGRAM;
    if len > max {
        return Err(CodecError::Oversized { len, max });
    }
    if !len.is_multiple_of(RECORD_LEN) {
        return Err(CodecError::PartialRecord { len });
    }
    let n = len / RECORD_LEN;
    out.reserve(n);
    for chunk in datagram.chunks_exact(RECORD_LEN) {
        out.push(decode_record(chunk)?);
    }
    Ok(n)
}

/// The 20-byte calibration request (first byte 1, the rest zero).
#[must_use]
pub fn encode_calibration_request() -> [u8; CALIBRATION_REQUEST_LEN] {
    let mut out = [0u8; CALIBRATION_REQUEST_LEN];
    out[0] = 1;
    out
}

/// Check a calibration request (the sensor's side).
pub fn decode_calibration_request(bytes: &[u8]) -> Result<(), CodecError> {
    if bytes.len() < CALIBRATION_REQUEST_LEN {
        return Err(CodecError::Truncated {
            len: bytes.len(),
            expected: CALIBRATION_REQUEST_LEN,
        });
    }
    if bytes.len() > CALIBRATION_REQUEST_LEN {
        return Err(CodecError::Oversized {
            len: bytes.len(),
            max: CALIBRATION_REQUEST_LEN,
        });
    }
    match bytes.first() {
        Some(1) => Ok(()),
        other => Err(CodecError::NotCalibrationRequest(
            other.copied().unwrap_or(0),
        )),
    }
}

/// The 24-byte calibration reply.
#[must_use]
pub fn encode_calibration_reply(c: &Calibration) -> [u8; CALIBRATION_REPLY_LEN] {
    let mut out = [0u8; CALIBRATION_REPLY_LEN];
    out[0..2].copy_from_slice(&HEADER.to_be_bytes());
    out[2] = c.force_unit;
    out[3] = c.torque_unit;
    out[4..8].copy_from_slice(&c.counts_per_force.to_be_bytes());
    out[8..12].copy_from_slice(&c.counts_per_torque.to_be_bytes());
    for (i, s) in c.scale.iter().enumerate() {
        out[12 + 2 * i..14 + 2 * i].copy_from_slice(&s.to_be_bytes());
    }
    out
}

/// Decode the 24-byte calibration reply.
pub fn decode_calibration_reply(bytes: &[u8]) -> Result<Calibration, CodecError> {
    if bytes.len() < CALIBRATION_REPLY_LEN {
        return Err(CodecError::Truncated {
            len: bytes.len(),
            expected: CALIBRATION_REPLY_LEN,
        });
    }
    if bytes.len() > CALIBRATION_REPLY_LEN {
        return Err(CodecError::Oversized {
            len: bytes.len(),
            max: CALIBRATION_REPLY_LEN,
        });
    }
    let header = be_u16(bytes, 0);
    if header != HEADER {
        return Err(CodecError::WrongHeader(header));
    }
    Ok(Calibration {
        force_unit: bytes[2],
        torque_unit: bytes[3],
        counts_per_force: be_u32(bytes, 4),
        counts_per_torque: be_u32(bytes, 8),
        scale: std::array::from_fn(|i| be_u16(bytes, 12 + 2 * i)),
    })
}

/// Counts per N and per N·m from the sensor's `netftapi2.xml` (elements `cfgcpf`,
/// `cfgcpt`, and the unit strings `scfgfu`, `scfgtu`).
pub fn parse_netftapi2(xml: &str) -> Result<(f64, f64), String> {
    fn element<'a>(xml: &'a str, name: &str) -> Option<&'a str> {
        let open = format!("<{name}>");
        let close = format!("</{name}>");
        let start = xml.find(&open)? + open.len();
        let end = start + xml.get(start..)?.find(&close)?;
        xml.get(start..end).map(str::trim)
    }
    let number = |name: &str| -> Result<f64, String> {
        let s = element(xml, name).ok_or_else(|| format!("netftapi2.xml has no <{name}>"))?;
        let v: f64 = s
            .parse()
            .map_err(|_| format!("<{name}> is not a number: {s:?}"))?;
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(format!("<{name}> must be positive, found {v}"))
        }
    };
    let cpf = number("cfgcpf")?;
    let cpt = number("cfgcpt")?;
    let fu = element(xml, "scfgfu").unwrap_or("N");
    let tu = element(xml, "scfgtu").unwrap_or("Nm");
    let n_per = match fu {
        "N" => 1.0,
        "kN" => 1000.0,
        "lbf" => 4.448_221_615_260_5,
        "klbf" => 4_448.221_615_260_5,
        "kgf" => 9.806_65,
        "gf" => 0.009_806_65,
        other => return Err(format!("unknown force unit {other:?}")),
    };
    let nm_per = match tu {
        "Nm" | "N-m" | "N·m" => 1.0,
        "Nmm" | "N-mm" | "N·mm" => 0.001,
        "kNm" | "kN-m" => 1000.0,
        "lbf-in" | "lbfin" => 0.112_984_829_027_616_7,
        "lbf-ft" | "lbfft" => 1.355_817_948_331_400_4,
        "kgf-cm" | "kgfcm" => 0.098_066_5,
        other => return Err(format!("unknown torque unit {other:?}")),
    };
    Ok((cpf / n_per, cpt / nm_per))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_round_trips_and_writes_the_count_once() {
        let b = encode_request(Command::Buffered, 0x0102_0304);
        assert_eq!(b, [0x12, 0x34, 0x00, 0x03, 0x01, 0x02, 0x03, 0x04]);
        assert_eq!(
            decode_request(&b),
            Ok(Request {
                command: Command::Buffered,
                sample_count: 0x0102_0304
            })
        );
    }

    #[test]
    fn record_round_trips() {
        let r = RawRecord {
            rdt_sequence: u32::MAX,
            ft_sequence: 7,
            status: 0x8001_0000,
            counts: [1, -1, i32::MIN, i32::MAX, 0, 123_456],
        };
        assert_eq!(decode_record(&encode_record(&r)), Ok(r));
        let mut two = encode_record(&r).to_vec();
        two.extend_from_slice(&encode_record(&RawRecord::default()));
        let mut out = Vec::new();
        assert_eq!(decode_records(&two, &mut out), Ok(2));
        assert_eq!(out[0], r);
    }

    #[test]
    fn bad_datagrams_are_errors() {
        let mut out = Vec::new();
        assert!(matches!(
            decode_records(&[0; 35], &mut out),
            Err(CodecError::Truncated { .. })
        ));
        assert!(matches!(
            decode_records(&[0; 37], &mut out),
            Err(CodecError::PartialRecord { .. })
        ));
        assert!(matches!(
            decode_records(
                &vec![0; RECORD_LEN * (MAX_RECORDS_PER_DATAGRAM + 1)],
                &mut out
            ),
            Err(CodecError::Oversized { .. })
        ));
        assert!(out.is_empty());
        assert_eq!(
            decode_request(&[0x43, 0x21, 0, 2, 0, 0, 0, 0]),
            Err(CodecError::WrongHeader(0x4321))
        );
        assert_eq!(
            decode_request(&[0x12, 0x34, 0, 9, 0, 0, 0, 0]),
            Err(CodecError::UnknownCommand(9))
        );
    }

    #[test]
    fn calibration_reply_round_trips_and_converts_units() {
        let c = Calibration {
            force_unit: 2,
            torque_unit: 4,
            counts_per_force: 1_000_000,
            counts_per_torque: 1000,
            scale: [1, 2, 3, 4, 5, 6],
        };
        let b = encode_calibration_reply(&c);
        assert_eq!(decode_calibration_reply(&b), Ok(c));
        let (cpf, cpt) = c.counts_per_si().expect("SI units");
        assert!((cpf - 1e6).abs() < 1e-9 && (cpt - 1e6).abs() < 1e-6);
        let mut bad = b;
        bad[0] = 0;
        assert!(matches!(
            decode_calibration_reply(&bad),
            Err(CodecError::WrongHeader(_))
        ));
        assert!(
            Calibration {
                torque_unit: 99,
                ..c
            }
            .counts_per_si()
            .is_err()
        );
        assert!(
            Calibration {
                counts_per_force: 0,
                ..c
            }
            .counts_per_si()
            .is_err()
        );
        assert_eq!(
            decode_calibration_request(&encode_calibration_request()),
            Ok(())
        );
    }

    #[test]
    fn netftapi2_xml_gives_counts_per_si_unit() {
        let xml = "<netft><cfgcpf>1000000</cfgcpf><cfgcpt>1000</cfgcpt>\
                   <scfgfu>N</scfgfu><scfgtu>Nmm</scfgtu></netft>";
        let (cpf, cpt) = parse_netftapi2(xml).expect("valid page");
        assert!((cpf - 1e6).abs() < 1e-9 && (cpt - 1e6).abs() < 1e-6);
        assert!(parse_netftapi2("<netft></netft>").is_err());
        assert!(parse_netftapi2("<cfgcpf>x</cfgcpf><cfgcpt>1</cfgcpt>").is_err());
    }
}
