//! The ASCII side of the ATI serial F/T controller (manual 9610-05-1001), as pure
//! functions: commands, and record lines `err, Fx, Fy, Fz, Tx, Ty, Tz` (counts).
//! The parser takes any bytes and never panics.

/// The longest record line accepted (a record is under 60 characters).
pub const MAX_LINE: usize = 128;

/// ASCII output (`CD A`).
pub const ASCII_OUTPUT: &str = "CD A";
/// Resolved force/torque output (`CD R`).
pub const RESOLVED_OUTPUT: &str = "CD R";
/// One record (`QR`).
pub const QUERY_RECORD: &str = "QR";
/// Stream records until any character arrives (`QS`).
pub const QUERY_STREAM: &str = "QS";
/// Push the current load on the bias stack (`SB`).
pub const SOFTWARE_BIAS: &str = "SB";
/// Pop the bias stack (`SU`).
pub const BIAS_POP: &str = "SU";
/// Clear the bias stack (`SZ`).
pub const BIAS_CLEAR: &str = "SZ";

/// A command as sent: the text and a carriage return.
#[must_use]
pub fn encode_command(command: &str) -> Vec<u8> {
    let mut v = command.as_bytes().to_vec();
    v.push(b'\r');
    v
}

/// One ASCII record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AsciiRecord {
    /// The controller's error field (0 = OK).
    pub error: u32,
    /// `Fx Fy Fz Tx Ty Tz` in counts.
    pub counts: [i32; 6],
}

/// What was wrong with a line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    /// Not seven fields.
    #[error("expected 7 fields (err, Fx..Tz), found {0}")]
    FieldCount(usize),
    /// A field is not an integer in range.
    #[error("field {index} is not an integer: {text:?}")]
    NotANumber {
        /// Which field (0 = error field).
        index: usize,
        /// Its text (at most 16 characters).
        text: String,
    },
    /// Longer than [`MAX_LINE`].
    #[error("line of {0} bytes is too long")]
    TooLong(usize),
    /// Bytes that are not ASCII text.
    #[error("line is not ASCII")]
    NotAscii,
}

/// Parse a record line (without or with its CR LF). Fields are separated by commas
/// and/or blanks.
pub fn parse_record(line: &[u8]) -> Result<AsciiRecord, LineError> {
    if line.len() > MAX_LINE {
        return Err(LineError::TooLong(line.len()));
    }
    let text = std::str::from_utf8(line).map_err(|_| LineError::NotAscii)?;
    if !text.is_ascii() {
        return Err(LineError::NotAscii);
    }
    let fields: Vec<&str> = text
        .split(|c: char| c == ',' || c.is_ascii_whitespace())
        .filter(|f| !f.is_empty())
        .collect();
    if fields.len() != 7 {
        return Err(LineError::FieldCount(fields.len()));
    }
    let bad = |index: usize, f: &str| LineError::NotANumber {
        index,
        text: f.chars().take(16).collect(),
    };
    let error: u32 = fields[0].parse().map_err(|_| bad(0, fields[0]))?;
    let mut counts = [0i32; 6];
    for (i, f) in fields[1..].iter().enumerate() {
        counts[i] = f.parse().map_err(|_| bad(i + 1, f))?;
    }
    Ok(AsciiRecord { error, counts })
}

/// A record line as the controller writes it, with CR LF.
#[must_use]
pub fn format_record(r: &AsciiRecord) -> String {
    let c = r.counts;
    format!(
        "{},{},{},{},{},{},{}\r\n",
        r.error, c[0], c[1], c[2], c[3], c[4], c[5]
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_accept_blanks() {
        let r = AsciiRecord {
            error: 0,
            counts: [1, -2, 3, -40000, 5, 6],
        };
        assert_eq!(parse_record(format_record(&r).as_bytes()), Ok(r));
        assert_eq!(parse_record(b"  0   1  -2 3 -40000,5 ,6\r"), Ok(r));
        assert_eq!(parse_record(b"1,2,3"), Err(LineError::FieldCount(3)));
        assert!(matches!(
            parse_record(b"0,1,2,3,4,5,x"),
            Err(LineError::NotANumber { index: 6, .. })
        ));
        assert!(matches!(
            parse_record(b"-1,1,2,3,4,5,6"),
            Err(LineError::NotANumber { index: 0, .. })
        ));
        assert_eq!(parse_record(&[0xFF, b'1']), Err(LineError::NotAscii));
        assert!(matches!(
            parse_record(&[b'1'; 200]),
            Err(LineError::TooLong(200))
        ));
    }
}
