//! The little CSV this module needs: RFC 4180 fields (quotes, doubled quotes, CRLF),
//! with the line and column of every field so that errors can point at them, and
//! number formatting that reads back to the same bits.

/// One record of a CSV file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Record {
    /// 1-based line where the record starts.
    pub(crate) line: usize,
    /// The fields, unquoted.
    pub(crate) fields: Vec<String>,
}

/// A CSV syntax error: 1-based line and column (field number).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct SyntaxError {
    pub(crate) line: usize,
    pub(crate) column: usize,
    pub(crate) message: String,
}

/// Parse a whole CSV text. Blank lines are skipped; a UTF-8 byte-order mark is ignored.
pub(crate) fn parse(text: &str) -> Result<Vec<Record>, SyntaxError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut records = Vec::new();
    let mut chars = text.chars().peekable();
    let mut line = 1usize;
    while chars.peek().is_some() {
        let start_line = line;
        let mut fields = Vec::new();
        let mut field = String::new();
        let mut quoted = false;
        let mut was_quoted = false;
        loop {
            let Some(c) = chars.next() else {
                if quoted {
                    return Err(SyntaxError {
                        line: start_line,
                        column: fields.len() + 1,
                        message: "unterminated quoted field".into(),
                    });
                }
                fields.push(std::mem::take(&mut field));
                break;
            };
            if quoted {
                match c {
                    '"' if chars.peek() == Some(&'"') => {
                        chars.next();
                        field.push('"');
                    }
                    '"' => quoted = false,
                    '\n' => {
                        line += 1;
                        field.push(c);
                    }
                    _ => field.push(c),
                }
                continue;
            }
            match c {
                ',' => {
                    fields.push(std::mem::take(&mut field));
                    was_quoted = false;
                }
                '"' if field.is_empty() && !was_quoted => {
                    quoted = true;
                    was_quoted = true;
                }
                '"' => {
                    return Err(SyntaxError {
                        line,
                        column: fields.len() + 1,
                        message: "a quote inside an unquoted field".into(),
                    });
                }
                '\r' if chars.peek() == Some(&'\n') => {}
                '\n' => {
                    line += 1;
                    fields.push(std::mem::take(&mut field));
                    break;
                }
                _ if was_quoted => {
                    return Err(SyntaxError {
                        line,
                        column: fields.len() + 1,
                        message: "text after a closing quote".into(),
                    });
                }
                _ => field.push(c),
            }
        }
        let blank = fields.len() == 1 && fields.first().is_some_and(String::is_empty);
        if !blank {
            records.push(Record {
                line: start_line,
                fields,
            });
        }
    }
    Ok(records)
}

/// Append one field, quoted if it must be.
pub(crate) fn push_field(out: &mut String, value: &str) {
    if value.contains([',', '"', '\n', '\r']) {
        out.push('"');
        out.push_str(&value.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(value);
    }
}

/// A number as text that parses back to the same `f64` (Rust's shortest round-trip
/// form, never an exponent).
pub(crate) fn number(v: f64) -> String {
    format!("{v}")
}

/// A torque in N·m as N·mm text, by moving the decimal point of its shortest
/// round-trip form three places: exact, no floating-point multiplication, so the
/// text reads `23.17884`, never `23.178839999999997`, and
/// [`nmm_text_to_nm`] gives back the very same `f64`.
pub(crate) fn nm_to_nmm_text(nm: f64) -> String {
    let text = number(nm);
    if !nm.is_finite() {
        return text;
    }
    let (sign, digits) = match text.strip_prefix('-') {
        Some(rest) => ("-", rest),
        None => ("", text.as_str()),
    };
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    let mut frac = frac.to_owned();
    while frac.len() < 3 {
        frac.push('0');
    }
    let (moved, rest) = frac.split_at(3);
    let int = format!("{int}{moved}");
    let int = int.trim_start_matches('0');
    let int = if int.is_empty() { "0" } else { int };
    let rest = rest.trim_end_matches('0');
    if rest.is_empty() {
        format!("{sign}{int}")
    } else {
        format!("{sign}{int}.{rest}")
    }
}

/// N·m from N·mm text, exactly: the decimal number divided by 1000 before rounding to
/// `f64` (by moving the exponent), so `nmm_text_to_nm(&nm_to_nmm_text(x)) == x`.
/// `None` if the text is not a number.
pub(crate) fn nmm_text_to_nm(text: &str) -> Option<f64> {
    let t = text.trim();
    t.parse::<f64>().ok()?;
    let shifted = match t.find(['e', 'E']) {
        Some(at) => {
            let exponent: i64 = t[at + 1..].parse().ok()?;
            format!("{}e{}", &t[..at], exponent - 3)
        }
        None => format!("{t}e-3"),
    };
    shifted.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn fields(text: &str) -> Vec<Vec<String>> {
        parse(text)
            .unwrap_or_else(|e| panic!("{e:?}"))
            .into_iter()
            .map(|r| r.fields)
            .collect()
    }

    #[test]
    fn quoted_fields_crlf_and_blank_lines() {
        assert_eq!(
            fields("a,\"b,c\",\"d\"\"e\"\r\n\n1,2,3\n"),
            vec![vec!["a", "b,c", "d\"e"], vec!["1", "2", "3"]]
        );
        let records = parse("x\n\n\"multi\nline\",y\nz\n").unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(
            records.iter().map(|r| r.line).collect::<Vec<_>>(),
            [1, 3, 5]
        );
        assert_eq!(fields("a,,b\n"), vec![vec!["a", "", "b"]]);
    }

    #[test]
    fn syntax_errors_name_line_and_column() {
        let err = parse("a,b\nc,\"d\n").err();
        assert_eq!(err.map(|e| (e.line, e.column)), Some((2, 2)));
        let err = parse("a,b\nc,d\"e\n").err();
        assert_eq!(err.map(|e| (e.line, e.column)), Some((2, 2)));
        let err = parse("a,\"b\"c\n").err();
        assert_eq!(err.map(|e| (e.line, e.column)), Some((1, 2)));
    }

    #[test]
    fn torques_print_short_and_exact() {
        for (nm, text) in [
            (0.023_178_84, "23.17884"),
            (-0.25, "-250"),
            (0.0, "0"),
            (-0.0, "-0"),
            (1.0, "1000"),
            (123.5, "123500"),
            (1e-9, "0.000001"),
            (0.000_1, "0.1"),
        ] {
            assert_eq!(nm_to_nmm_text(nm), text);
            assert_eq!(
                nmm_text_to_nm(text).map(f64::to_bits),
                Some(nm.to_bits()),
                "{text}"
            );
        }
        assert_eq!(nmm_text_to_nm("1.5E+2"), Some(0.15));
        assert_eq!(nmm_text_to_nm("2e-3"), Some(0.000_002));
        assert_eq!(nmm_text_to_nm("abc"), None);
    }

    #[test]
    fn fields_that_need_quotes_get_them() {
        let mut s = String::new();
        push_field(&mut s, "rod, \"big\"");
        assert_eq!(s, "\"rod, \"\"big\"\"\"");
        assert_eq!(fields(&s), vec![vec!["rod, \"big\""]]);
    }

    proptest! {
        #[test]
        fn torque_text_imports_back_to_the_same_bits(nm in any::<f64>()) {
            prop_assume!(nm.is_finite());
            let text = nm_to_nmm_text(nm);
            prop_assert_eq!(nmm_text_to_nm(&text).map(f64::to_bits), Some(nm.to_bits()), "{}", text);
            let value: f64 = text.parse().unwrap_or(f64::NAN);
            if nm.abs() < 1e300 {
                prop_assert!((value - nm * 1000.0).abs() <= 1e-12 * (1.0 + value.abs()));
            }
        }

        #[test]
        fn numbers_print_back_to_the_same_bits(v in any::<f64>()) {
            prop_assume!(v.is_finite());
            let back: f64 = number(v).parse().unwrap_or_else(|e| panic!("{e}"));
            prop_assert_eq!(back.to_bits(), v.to_bits());
        }
    }
}
