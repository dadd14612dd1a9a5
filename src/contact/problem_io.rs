//! The rigtwin contact-problem exchange file (`.rtcp`): a sequence of frictional contact
//! problems, each optionally with rigtwin's solution, for the Siconos cross-check
//! (`tests/siconos/solve_fc3d.py`) and for capturing problems from simulations.
//!
//! A file is zero or more records back to back; a record for `n` pairs (`d = 3n`) is, all
//! integers unsigned 32-bit little-endian, all reals IEEE-754 binary64 little-endian:
//!
//! | field    | type            | meaning                                              |
//! |----------|-----------------|------------------------------------------------------|
//! | magic    | 4 bytes         | ASCII `RTCP`                                         |
//! | version  | u32             | 1                                                    |
//! | n        | u32             | number of contact pairs (at most [`MAX_PAIRS`])      |
//! | flags    | u32             | bit 0: a solution follows; other bits 0              |
//! | labellen | u32             | length of the label in bytes (at most 65536)         |
//! | label    | labellen bytes  | UTF-8 free text (where the problem comes from)       |
//! | W        | d*d f64         | Delassus matrix, row-major, m/s/N (Siconos `M`)      |
//! | c        | d f64           | free gap velocity, m/s (Siconos `q`)                 |
//! | mu       | n f64           | friction coefficient per pair (Siconos `mu`)         |
//! | lambda   | d f64           | only with flag bit 0: contact forces, N (`r`)        |
//! | gamma    | d f64           | only with flag bit 0: gap velocities, m/s (`u`)      |
//!
//! Per pair the components are ordered normal, t1, t2 (Siconos' local frame order), so the
//! problem is `u = M r + q`, `r in K = {||r_t|| <= mu r_n}` exactly as Siconos' fc3d reads it.

use std::io::{Read, Write};

use super::{ContactError, ContactProblem, ContactSolution};

/// Largest number of pairs a record may declare (W then takes 302 MB).
pub const MAX_PAIRS: usize = 2048;
const MAGIC: &[u8; 4] = b"RTCP";
const VERSION: u32 = 1;
const MAX_LABEL: usize = 65536;
const FLAG_SOLUTION: u32 = 1;

/// One record of an exchange file.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactRecord {
    /// The problem.
    pub problem: ContactProblem,
    /// rigtwin's solution, when it was written with the problem.
    pub solution: Option<ContactSolution>,
}

/// Why an exchange file could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ContactIoError {
    /// The underlying reader or writer failed.
    #[error("contact problem file: I/O error at record {record}: {source}")]
    Io {
        /// Record index (0-based).
        record: usize,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The data ended inside a record.
    #[error(
        "contact problem file: record {record} is truncated at byte {offset} (reading {what})"
    )]
    Truncated {
        /// Record index (0-based).
        record: usize,
        /// Byte offset in the file where data was missing.
        offset: u64,
        /// Which field was being read.
        what: &'static str,
    },
    /// A header field is invalid.
    #[error("contact problem file: record {record} at byte {offset}: {what}")]
    BadHeader {
        /// Record index (0-based).
        record: usize,
        /// Byte offset of the record start.
        offset: u64,
        /// What is wrong and what was expected.
        what: String,
    },
    /// The problem (on write) or the stored problem (on read) is not valid.
    #[error("contact problem file: record {record}: {source}")]
    Invalid {
        /// Record index (0-based).
        record: usize,
        /// What is wrong with the problem.
        #[source]
        source: ContactError,
    },
}

/// Appends one problem (and optionally its solution) as a record to `out`. The problem is
/// validated first; the solution must have `3n` forces and gap velocities.
pub fn write_problem<W: Write>(
    out: &mut W,
    problem: &ContactProblem,
    solution: Option<&ContactSolution>,
) -> Result<(), ContactIoError> {
    let invalid = |source| ContactIoError::Invalid { record: 0, source };
    problem.validate().map_err(invalid)?;
    let n = problem.n_pairs();
    if n > MAX_PAIRS {
        return Err(ContactIoError::BadHeader {
            record: 0,
            offset: 0,
            what: format!("{n} pairs exceed the format limit of {MAX_PAIRS}"),
        });
    }
    if let Some(s) = solution {
        super::check_vector("solution lambda", &s.lambda, 3 * n, n).map_err(invalid)?;
        super::check_vector("solution gamma", &s.gamma, 3 * n, n).map_err(invalid)?;
    }
    let label = problem.label.as_bytes();
    if label.len() > MAX_LABEL {
        return Err(ContactIoError::BadHeader {
            record: 0,
            offset: 0,
            what: format!("label of {} bytes exceeds {MAX_LABEL}", label.len()),
        });
    }
    let mut buf = Vec::with_capacity(20 + label.len() + 8 * (problem.w.len() + 12 * n));
    buf.extend_from_slice(MAGIC);
    for v in [
        VERSION,
        n as u32,
        if solution.is_some() { FLAG_SOLUTION } else { 0 },
        label.len() as u32,
    ] {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    buf.extend_from_slice(label);
    let mut reals = |v: &[f64]| {
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    };
    reals(&problem.w);
    reals(&problem.c);
    reals(&problem.mu);
    if let Some(s) = solution {
        reals(&s.lambda);
        reals(&s.gamma);
    }
    out.write_all(&buf)
        .map_err(|source| ContactIoError::Io { record: 0, source })
}

/// Reads all records of an exchange file (until the end of the data). Every problem is
/// validated as [`ContactProblem::validate`] does.
pub fn read_problems<R: Read>(input: &mut R) -> Result<Vec<ContactRecord>, ContactIoError> {
    let mut reader = Counting {
        inner: input,
        offset: 0,
    };
    let mut records = Vec::new();
    loop {
        let record = records.len();
        let start = reader.offset;
        let mut magic = [0u8; 4];
        match reader.read_full(&mut magic, record)? {
            0 => return Ok(records),
            4 => {}
            _ => {
                return Err(ContactIoError::Truncated {
                    record,
                    offset: reader.offset,
                    what: "magic",
                })
            }
        }
        let bad = |what: String| ContactIoError::BadHeader {
            record,
            offset: start,
            what,
        };
        if &magic != MAGIC {
            return Err(bad(format!(
                "magic {magic:?} is not \"RTCP\" (not a rigtwin contact problem file?)"
            )));
        }
        let version = reader.u32(record, "version")?;
        if version != VERSION {
            return Err(bad(format!(
                "version {version} is not supported (expected {VERSION})"
            )));
        }
        let n = reader.u32(record, "pair count")? as usize;
        if n > MAX_PAIRS {
            return Err(bad(format!(
                "{n} pairs exceed the format limit of {MAX_PAIRS}"
            )));
        }
        let flags = reader.u32(record, "flags")?;
        if flags & !FLAG_SOLUTION != 0 {
            return Err(bad(format!(
                "unknown flag bits {flags:#x} (only bit 0 is defined)"
            )));
        }
        let label_len = reader.u32(record, "label length")? as usize;
        if label_len > MAX_LABEL {
            return Err(bad(format!("label length {label_len} exceeds {MAX_LABEL}")));
        }
        let mut label = vec![0u8; label_len];
        if reader.read_full(&mut label, record)? != label_len {
            return Err(ContactIoError::Truncated {
                record,
                offset: reader.offset,
                what: "label",
            });
        }
        let label =
            String::from_utf8(label).map_err(|e| bad(format!("label is not UTF-8: {e}")))?;
        let d = 3 * n;
        let w = reader.reals(d * d, record, "W")?;
        let c = reader.reals(d, record, "c")?;
        let mu = reader.reals(n, record, "mu")?;
        let solution = if flags & FLAG_SOLUTION != 0 {
            Some(ContactSolution {
                lambda: reader.reals(d, record, "lambda")?,
                gamma: reader.reals(d, record, "gamma")?,
            })
        } else {
            None
        };
        let problem = ContactProblem { w, c, mu, label };
        problem
            .validate()
            .map_err(|source| ContactIoError::Invalid { record, source })?;
        records.push(ContactRecord { problem, solution });
    }
}

/// A reader that counts bytes for error messages.
struct Counting<'a, R: Read> {
    inner: &'a mut R,
    offset: u64,
}

impl<R: Read> Counting<'_, R> {
    /// Reads until `buf` is full or the data ends; returns the bytes read.
    fn read_full(&mut self, buf: &mut [u8], record: usize) -> Result<usize, ContactIoError> {
        let mut filled = 0;
        while filled < buf.len() {
            match self.inner.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(k) => filled += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(source) => return Err(ContactIoError::Io { record, source }),
            }
        }
        self.offset += filled as u64;
        Ok(filled)
    }

    fn u32(&mut self, record: usize, what: &'static str) -> Result<u32, ContactIoError> {
        let mut b = [0u8; 4];
        if self.read_full(&mut b, record)? != 4 {
            return Err(ContactIoError::Truncated {
                record,
                offset: self.offset,
                what,
            });
        }
        Ok(u32::from_le_bytes(b))
    }

    fn reals(
        &mut self,
        count: usize,
        record: usize,
        what: &'static str,
    ) -> Result<Vec<f64>, ContactIoError> {
        let mut v = Vec::with_capacity(count);
        let mut chunk = [0u8; 8 * 512];
        while v.len() < count {
            let k = (count - v.len()).min(512);
            let bytes = &mut chunk[..8 * k];
            if self.read_full(bytes, record)? != 8 * k {
                return Err(ContactIoError::Truncated {
                    record,
                    offset: self.offset,
                    what,
                });
            }
            v.extend(bytes.chunks_exact(8).map(|b| {
                let mut a = [0u8; 8];
                a.copy_from_slice(b);
                f64::from_le_bytes(a)
            }));
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(n: usize, label: &str) -> ContactProblem {
        let d = 3 * n;
        let mut w = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                w[i * d + j] = if i == j {
                    4.0 + i as f64
                } else {
                    0.5 / (1.0 + (i + j) as f64)
                };
            }
        }
        ContactProblem {
            w,
            c: (0..d).map(|i| (i as f64).sin()).collect(),
            mu: (0..n).map(|k| 0.1 * k as f64).collect(),
            label: label.to_string(),
        }
    }

    #[test]
    fn records_round_trip_bit_for_bit() {
        let p1 = sample(2, "first");
        let p2 = sample(3, "zweite \u{00e9}tape");
        let s2 = ContactSolution {
            lambda: (0..9).map(|i| i as f64 * 1.5e-3).collect(),
            gamma: (0..9).map(|i| -(i as f64) * 2.0e7).collect(),
        };
        let mut buf = Vec::new();
        write_problem(&mut buf, &p1, None).unwrap();
        write_problem(&mut buf, &p2, Some(&s2)).unwrap();
        let records = read_problems(&mut buf.as_slice()).unwrap();
        assert_eq!(records.len(), 2);
        assert_eq!(records[0].problem, p1);
        assert_eq!(records[0].solution, None);
        assert_eq!(records[1].problem, p2);
        assert_eq!(records[1].solution.as_ref(), Some(&s2));
    }

    #[test]
    fn empty_input_has_no_records() {
        assert!(read_problems(&mut [].as_slice()).unwrap().is_empty());
    }

    #[test]
    fn truncated_record_names_the_field() {
        let mut buf = Vec::new();
        write_problem(&mut buf, &sample(2, ""), None).unwrap();
        buf.truncate(buf.len() - 3);
        let err = read_problems(&mut buf.as_slice()).unwrap_err();
        assert!(
            matches!(
                err,
                ContactIoError::Truncated {
                    record: 0,
                    what: "mu",
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn foreign_data_is_rejected_by_the_magic() {
        let err = read_problems(&mut b"PK\x03\x04 not ours".as_slice()).unwrap_err();
        assert!(err.to_string().contains("RTCP"), "{err}");
    }

    #[test]
    fn invalid_problem_is_not_written() {
        let mut p = sample(2, "");
        p.c[4] = f64::NAN;
        let mut buf = Vec::new();
        let err = write_problem(&mut buf, &p, None).unwrap_err();
        assert!(err.to_string().contains("c[4]"), "{err}");
        assert!(buf.is_empty());
    }
}
