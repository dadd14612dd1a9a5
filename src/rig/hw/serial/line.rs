//! The line codec shared by both serial protocols: `BODY*CCCC\n`, where BODY is 1..=120
//! printable ASCII characters without `*` and CCCC the CRC-16/CCITT-FALSE of BODY in four
//! upper-case hex digits; a `\r` before the `\n` is ignored. [`LineReader`] splits a byte
//! stream into checked bodies; a partial line is a state ("need more bytes"), not an error.

use crate::rig::hw::crc::crc16_ccitt;

/// Longest body, bytes.
pub const MAX_BODY: usize = 120;

/// Why a line was rejected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    /// A byte outside printable ASCII.
    #[error("byte {pos} = {byte:#04x}: not printable ASCII")]
    BadByte {
        /// Position in the line.
        pos: usize,
        /// The byte.
        byte: u8,
    },
    /// No `*CCCC` at the end.
    #[error("no checksum (`*` and four hex digits) at the end of {line:?}")]
    NoChecksum {
        /// The line, lossy.
        line: String,
    },
    /// Checksum mismatch.
    #[error("checksum {got} of {body:?}, expected {expected:04X}")]
    BadChecksum {
        /// The body.
        body: String,
        /// What the line says.
        got: String,
        /// What the body gives.
        expected: u16,
    },
    /// More than MAX_BODY + 5 bytes without a newline (discarded up to the next one).
    #[error("line longer than {max} bytes without a newline")]
    Overlong {
        /// The limit.
        max: usize,
    },
    /// Empty body.
    #[error("empty line")]
    Empty,
}

impl LineError {
    /// Whether the error is a checksum mismatch (counted apart from garbage).
    pub fn is_checksum(&self) -> bool {
        matches!(self, LineError::BadChecksum { .. })
    }
}

/// Frames a body; `Err` when the body itself is not allowed.
pub fn encode_line(body: &str) -> Result<String, LineError> {
    check_body(body.as_bytes())?;
    Ok(format!("{body}*{:04X}\n", crc16_ccitt(body.as_bytes())))
}

fn check_body(b: &[u8]) -> Result<(), LineError> {
    if b.is_empty() {
        return Err(LineError::Empty);
    }
    if b.len() > MAX_BODY {
        return Err(LineError::Overlong { max: MAX_BODY });
    }
    if let Some((pos, &byte)) = b
        .iter()
        .enumerate()
        .find(|(_, &c)| !(0x20..=0x7E).contains(&c) || c == b'*')
    {
        return Err(LineError::BadByte { pos, byte });
    }
    Ok(())
}

/// Checks one line (without its `\n`) and returns its body.
pub fn decode_line(line: &[u8]) -> Result<String, LineError> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let Some(star) = line.iter().rposition(|&c| c == b'*') else {
        if let Some((pos, &byte)) = line
            .iter()
            .enumerate()
            .find(|(_, &c)| !(0x20..=0x7E).contains(&c))
        {
            return Err(LineError::BadByte { pos, byte });
        }
        return Err(LineError::NoChecksum {
            line: String::from_utf8_lossy(line).into_owned(),
        });
    };
    let (body, ck) = (&line[..star], &line[star + 1..]);
    check_body(body)?;
    let body = String::from_utf8_lossy(body).into_owned();
    let ck_ok = ck.len() == 4
        && ck
            .iter()
            .all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(c));
    if !ck_ok {
        return Err(LineError::NoChecksum {
            line: String::from_utf8_lossy(line).into_owned(),
        });
    }
    let ck = String::from_utf8_lossy(ck).into_owned();
    let expected = crc16_ccitt(body.as_bytes());
    if u16::from_str_radix(&ck, 16).ok() != Some(expected) {
        return Err(LineError::BadChecksum {
            body,
            got: ck,
            expected,
        });
    }
    Ok(body)
}

/// Splits a byte stream into lines and checks them.
#[derive(Debug, Default)]
pub struct LineReader {
    buf: Vec<u8>,
    discarding: bool,
}

impl LineReader {
    /// A reader with nothing buffered.
    pub fn new() -> LineReader {
        LineReader::default()
    }

    /// Adds bytes; returns every complete line's result in order.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Result<String, LineError>> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'\n' {
                if self.discarding {
                    self.discarding = false;
                } else if !self.buf.is_empty() && self.buf != b"\r" {
                    out.push(decode_line(&self.buf));
                }
                self.buf.clear();
            } else if !self.discarding {
                self.buf.push(b);
                if self.buf.len() > MAX_BODY + 6 {
                    out.push(Err(LineError::Overlong { max: MAX_BODY + 6 }));
                    self.buf.clear();
                    self.discarding = true;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn lines_round_trip_and_errors_say_where() {
        let l = encode_line("12 OK STATUS EN=1").unwrap();
        assert!(l.ends_with('\n'));
        let mut r = LineReader::new();
        let got = r.push(l.replace('\n', "\r\n").as_bytes());
        assert_eq!(got, vec![Ok("12 OK STATUS EN=1".to_string())]);
        // Split delivery.
        assert!(r.push(&l.as_bytes()[..5]).is_empty());
        assert_eq!(
            r.push(&l.as_bytes()[5..]),
            vec![Ok("12 OK STATUS EN=1".to_string())]
        );
        let bad = l.replace("EN=1", "EN=0");
        assert!(matches!(
            r.push(bad.as_bytes())[0],
            Err(LineError::BadChecksum { .. })
        ));
        assert_eq!(
            r.push(b"ab\x01c*0000\n")[0],
            Err(LineError::BadByte { pos: 2, byte: 1 })
        );
        assert!(matches!(
            r.push(b"hello\n")[0],
            Err(LineError::NoChecksum { .. })
        ));
        let long = vec![b'x'; 500];
        let got = r.push(&long);
        assert_eq!(got, vec![Err(LineError::Overlong { max: MAX_BODY + 6 })]);
        // The rest of the long line is dropped, the next line reads.
        let got = r.push(format!("yyy\n{l}").as_bytes());
        assert_eq!(got, vec![Ok("12 OK STATUS EN=1".to_string())]);
        assert!(encode_line("a*b").is_err() && encode_line("").is_err());
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(chunks in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..200), 0..8)) {
            let mut r = LineReader::new();
            for c in chunks {
                for line in r.push(&c).into_iter().flatten() {
                    prop_assert!(line.len() <= MAX_BODY);
                }
            }
        }

        #[test]
        fn every_valid_body_round_trips(body in "[ -)+-~]{1,120}") {
            let l = encode_line(&body).unwrap();
            prop_assert_eq!(LineReader::new().push(l.as_bytes()), vec![Ok(body)]);
        }
    }
}
