//! Walks the records of an MCAP file held in memory, from the start, without needing the
//! footer or summary: the crash-recovery core of the reader.
//!
//! A file cut off anywhere (SIGKILL, disk full) ends in an incomplete record: the walk stops
//! there and reports everything before it plus a description of what was lost. Damage that a
//! crash cannot cause (bad magic, a chunk failing its CRC or decompression, a record that does
//! not parse) is an error. Chunks are all or nothing: their records are handed on only once
//! the whole chunk has decompressed and passed its CRC.

use std::path::Path;

use mcap::records::{op, Record};

use super::LogReadError;

/// Bytes of an opcode and a record length.
const RECORD_PREFIX: usize = 9;

/// How the walk ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct ScanEnd {
    /// The footer and the closing magic were read.
    pub(super) complete: bool,
    /// Bytes up to the end of the last complete record (or of the closing magic).
    pub(super) valid_bytes: u64,
    /// What was lost, when not complete.
    pub(super) lost: Option<String>,
}

/// Calls `visit(offset, record)` for every record, chunk contents in place of the chunk
/// (`offset` is then the chunk's). Stops at the first incomplete record.
pub(super) fn scan(
    path: &Path,
    bytes: &[u8],
    mut visit: impl FnMut(u64, Record<'static>) -> Result<(), LogReadError>,
) -> Result<ScanEnd, LogReadError> {
    let magic = mcap::MAGIC;
    let len = bytes.len();
    if len == 0 {
        return Err(LogReadError::Empty {
            path: path.to_path_buf(),
        });
    }
    if !bytes.starts_with(magic) {
        if len < magic.len() && magic.starts_with(bytes) {
            return Err(LogReadError::TruncatedMagic {
                path: path.to_path_buf(),
                len,
            });
        }
        return Err(LogReadError::NotMcap {
            path: path.to_path_buf(),
            found: describe_start(bytes),
        });
    }
    // A file that ends with the magic was closed; a record running past its end is damage,
    // not a cut.
    let looks_closed = len >= 2 * magic.len() && bytes.ends_with(magic);
    let truncated = |pos: usize, what: String| ScanEnd {
        complete: false,
        valid_bytes: pos as u64,
        lost: Some(format!(
            "the file ends early: {} bytes after byte offset {pos} were lost ({what}); \
             everything before is intact",
            len - pos
        )),
    };
    let corrupt = |pos: usize, opcode: u8, reason: String| LogReadError::CorruptRecord {
        path: path.to_path_buf(),
        offset: pos as u64,
        opcode,
        reason,
    };

    let mut pos = magic.len();
    let mut footer_seen = false;
    loop {
        let rest = &bytes[pos..];
        if footer_seen {
            return if rest == magic {
                Ok(ScanEnd {
                    complete: true,
                    valid_bytes: len as u64,
                    lost: None,
                })
            } else if magic.starts_with(rest) {
                Ok(truncated(pos, "the closing magic is cut off".into()))
            } else {
                Err(corrupt(
                    pos,
                    rest[0],
                    format!(
                        "{} bytes after the footer where the closing magic belongs",
                        rest.len()
                    ),
                ))
            };
        }
        if rest.is_empty() {
            let after = if pos == magic.len() {
                "right after the MCAP magic"
            } else {
                "after a complete record"
            };
            return Ok(ScanEnd {
                complete: false,
                valid_bytes: len as u64,
                lost: Some(format!(
                    "the file ends at byte offset {len} {after}, without footer: the writer \
                     did not close it; messages after its last flush were lost"
                )),
            });
        }
        if rest.len() < RECORD_PREFIX {
            return Ok(truncated(pos, "a record's opcode and length".into()));
        }
        let opcode = rest[0];
        let mut length = [0u8; 8];
        length.copy_from_slice(&rest[1..RECORD_PREFIX]);
        let length = u64::from_le_bytes(length);
        if opcode == 0 && rest.iter().all(|&b| b == 0) {
            return Ok(truncated(pos, "a zero-filled tail".into()));
        }
        let end = usize::try_from(length)
            .ok()
            .and_then(|l| l.checked_add(pos + RECORD_PREFIX))
            .filter(|&end| end <= len);
        let Some(end) = end else {
            if looks_closed {
                return Err(corrupt(
                    pos,
                    opcode,
                    format!("record length {length} runs past the end of the file"),
                ));
            }
            let what = if opcode == op::CHUNK {
                "an unfinished chunk".to_string()
            } else {
                format!("a record with opcode {opcode:#04x} cut off")
            };
            return Ok(truncated(pos, what));
        };
        let body = &bytes[pos + RECORD_PREFIX..end];
        let record = mcap::parse_record(opcode, body)
            .map_err(|e| corrupt(pos, opcode, format!("cannot parse it: {e}")))?;
        match record {
            Record::Chunk { header, data } => {
                let inner = read_chunk(header, &data).map_err(|e| LogReadError::CorruptChunk {
                    path: path.to_path_buf(),
                    offset: pos as u64,
                    reason: e.to_string(),
                })?;
                for record in inner {
                    visit(pos as u64, record)?;
                }
            }
            Record::Footer(_) => {
                footer_seen = true;
                visit(pos as u64, record.into_owned())?;
            }
            other => visit(pos as u64, other.into_owned())?,
        }
        pos = end;
    }
}

/// Decompresses a chunk and checks its CRC; its records, or the first problem.
fn read_chunk(
    header: mcap::records::ChunkHeader,
    data: &[u8],
) -> Result<Vec<Record<'static>>, mcap::McapError> {
    // NOTE: the CRC is checked at the end of the chunk, so nothing is handed on before.
    mcap::read::ChunkReader::new(header, data)?
        .map(|r| r.map(Record::into_owned))
        .collect()
}

/// The first bytes of a file, in hex and, when printable, as text.
fn describe_start(bytes: &[u8]) -> String {
    let head = &bytes[..bytes.len().min(8)];
    let hex: Vec<String> = head.iter().map(|b| format!("{b:02X}")).collect();
    let kind = if bytes.starts_with(b"\x89PNG") {
        " (a PNG image)".to_string()
    } else if head
        .iter()
        .all(|b| b.is_ascii_graphic() || b.is_ascii_whitespace())
    {
        format!(" (text {:?})", String::from_utf8_lossy(head))
    } else {
        String::new()
    };
    format!("{}{kind}", hex.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn describes_text_and_png() {
        assert_eq!(
            describe_start(b"[rig]\nname"),
            "5B 72 69 67 5D 0A 6E 61 (text \"[rig]\\nna\")"
        );
        assert!(describe_start(b"\x89PNG\r\n\x1a\n....").contains("PNG"));
        assert_eq!(describe_start(&[0, 1, 2]), "00 01 02");
    }

    #[test]
    fn magic_alone_is_an_incomplete_empty_session() {
        let end = scan(Path::new("x.mcap"), mcap::MAGIC, |_, _| Ok(())).unwrap();
        assert!(!end.complete);
        assert_eq!(end.valid_bytes, 8);
    }

    #[test]
    fn prefix_of_magic_is_reported_as_cut_magic() {
        let err = scan(Path::new("x.mcap"), &mcap::MAGIC[..5], |_, _| Ok(())).unwrap_err();
        assert!(
            matches!(err, LogReadError::TruncatedMagic { len: 5, .. }),
            "{err}"
        );
    }
}
