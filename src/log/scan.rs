//! Walks the records of an MCAP file, from the start, without needing the footer or summary:
//! the crash-recovery and salvage core of the reader. The file is held in memory
//! ([`Input::Memory`]) or read from disk record by record ([`Input::File`]: what is held at a
//! time is one record, i.e. one compressed chunk, and its records decompressed), with the same
//! walk and the same results.
//!
//! A file cut off anywhere (SIGKILL, disk full) ends in an incomplete record: the walk stops
//! there and reports everything before it plus a description of what was lost. Damage after
//! writing (bit flips, a bad sector) costs only the damaged records: a chunk that fails its
//! CRC or its decompression, or a record that does not parse, is skipped and described, and the
//! walk goes on with the next record (after a record whose length is damaged, with the next
//! chunk that passes its CRC), as the Python stream reader does. Damage after the data section
//! (the summary, the footer, the closing magic) loses nothing: the walk stops there with a
//! note. Only a file that is not MCAP at all is an error.
//!
//! Chunks are decompressed and checked here, not by the mcap crate, so that no length read
//! from the file is trusted: a chunk may claim at most [`MAX_CHUNK_BYTES`] uncompressed, is
//! decompressed to at most what it claims, checked against its CRC before a record in it is
//! parsed, and every record inside must end inside the chunk. Chunks are all or nothing.

use std::borrow::Cow;
use std::fs::File;
use std::io::Read;
use std::os::unix::fs::FileExt;
use std::path::Path;

use mcap::records::{op, Record};

use super::LogReadError;

/// Bytes of an opcode and a record length.
const RECORD_PREFIX: usize = 9;

/// The most a chunk may hold uncompressed, bytes: far above what the writer makes (its chunks
/// are flushed every second or at `LogOptions::chunk_size_bytes`); a larger claim is damage.
pub(super) const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// How the walk ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct ScanEnd {
    /// The data section is whole: it ended with its data-end record (the writer closed the
    /// file), whatever happened to the summary after it.
    pub(super) complete: bool,
    /// Bytes up to the end of the last record read (or of the closing magic).
    pub(super) valid_bytes: u64,
    /// What was lost at the end of the file, when not complete.
    pub(super) lost: Option<String>,
    /// Damaged regions that were skipped (and damage to the summary), in file order, for
    /// people.
    pub(super) damage: Vec<String>,
}

/// The bytes the walk reads.
pub(super) enum Input<'a> {
    /// A file already in memory.
    Memory(&'a [u8]),
    /// A file on disk, read a record at a time into `buf`.
    File {
        /// The open file.
        file: &'a File,
        /// Its path, for errors.
        path: &'a Path,
        /// Its length, bytes.
        len: usize,
        /// The bytes last read.
        buf: Vec<u8>,
    },
}

/// A read buffer larger than this (a damaged length) is released after use, bytes.
const KEEP_BUFFER_BYTES: usize = 64 << 20;

impl<'a> Input<'a> {
    /// A file on disk (its length as opened).
    pub(super) fn file(file: &'a File, path: &'a Path) -> Result<Input<'a>, LogReadError> {
        let io = |source| LogReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let len = file.metadata().map_err(io)?.len();
        let len = usize::try_from(len).map_err(|_| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "the file is larger than the address space",
            ))
        })?;
        Ok(Input::File {
            file,
            path,
            len,
            buf: Vec::new(),
        })
    }

    /// Length, bytes.
    pub(super) fn len(&self) -> usize {
        match self {
            Input::Memory(b) => b.len(),
            Input::File { len, .. } => *len,
        }
    }

    /// Bytes `from..to` (within the input).
    fn get(&mut self, from: usize, to: usize) -> Result<&[u8], LogReadError> {
        match self {
            Input::Memory(b) => Ok(&b[from..to]),
            Input::File {
                file, path, buf, ..
            } => {
                if buf.capacity() > KEEP_BUFFER_BYTES && to - from <= KEEP_BUFFER_BYTES {
                    *buf = Vec::new();
                }
                buf.clear();
                buf.resize(to - from, 0);
                file.read_exact_at(buf, from as u64)
                    .map_err(|source| LogReadError::Io {
                        path: path.to_path_buf(),
                        source,
                    })?;
                Ok(&buf[..])
            }
        }
    }

    /// Bytes `from..to` as an owned copy (for a few bytes).
    fn copy(&mut self, from: usize, to: usize) -> Result<Vec<u8>, LogReadError> {
        Ok(self.get(from, to)?.to_vec())
    }

    /// Whether bytes `from..` are all zero.
    fn zero_from(&mut self, from: usize) -> Result<bool, LogReadError> {
        const PIECE: usize = 1 << 20;
        let len = self.len();
        let mut at = from;
        while at < len {
            let to = (at + PIECE).min(len);
            if self.get(at, to)?.iter().any(|&b| b != 0) {
                return Ok(false);
            }
            at = to;
        }
        Ok(true)
    }
}

/// Calls `visit(offset, record)` for every readable record, chunk contents in place of the
/// chunk (`offset` is then the chunk's). Skips damaged records (listed in
/// [`ScanEnd::damage`]); stops at the first incomplete record.
pub(super) fn scan<E: From<LogReadError>>(
    path: &Path,
    input: &mut Input<'_>,
    mut visit: impl FnMut(u64, Record<'static>) -> Result<(), E>,
) -> Result<ScanEnd, E> {
    let magic = mcap::MAGIC;
    let len = input.len();
    if len == 0 {
        return Err(LogReadError::Empty {
            path: path.to_path_buf(),
        }
        .into());
    }
    let head = input.copy(0, len.min(magic.len()))?;
    if !head.starts_with(magic) {
        if len < magic.len() && magic.starts_with(&head) {
            return Err(LogReadError::TruncatedMagic {
                path: path.to_path_buf(),
                len,
            }
            .into());
        }
        return Err(LogReadError::NotMcap {
            path: path.to_path_buf(),
            found: describe_start(&head),
        }
        .into());
    }
    // A file that ends with the magic was closed; a record running past its end is damage,
    // not a cut.
    let looks_closed = len >= 2 * magic.len() && input.copy(len - magic.len(), len)? == magic;
    let mut damage: Vec<String> = Vec::new();
    let mut pos = magic.len();
    let mut data_end = false;
    let mut footer_seen = false;
    let end = |complete: bool, valid: usize, lost: Option<String>, damage: Vec<String>| ScanEnd {
        complete,
        valid_bytes: valid as u64,
        lost,
        damage,
    };
    loop {
        if footer_seen {
            // What follows the footer (its length, and the bytes when few).
            let rest_len = len - pos;
            let rest = input.copy(pos, pos + rest_len.min(magic.len() + 1))?;
            if rest != magic && magic.starts_with(&rest) {
                return Ok(end(
                    false,
                    pos,
                    Some(format!(
                        "the file ends early: {} bytes after byte offset {pos} were lost (the \
                         closing magic is cut off); everything before is intact",
                        len - pos
                    )),
                    damage,
                ));
            }
            if rest != magic {
                damage.push(format!(
                    "byte offset {pos}: {rest_len} bytes after the footer where the closing \
                     magic belongs (ignored)"
                ));
            }
            return Ok(end(true, len, None, damage));
        }
        if pos == len {
            if data_end {
                return Ok(end(
                    false,
                    len,
                    Some(format!(
                        "the file ends at byte offset {len} inside its summary, before the \
                         footer: the data are whole"
                    )),
                    damage,
                ));
            }
            let after = if pos == magic.len() {
                "right after the MCAP magic"
            } else {
                "after a complete record"
            };
            return Ok(end(
                false,
                len,
                Some(format!(
                    "the file ends at byte offset {len} {after}, without footer: the writer \
                     did not close it; messages after its last flush were lost"
                )),
                damage,
            ));
        }
        let lost = |pos: usize, what: &str| {
            Some(format!(
                "the file ends early: {} bytes after byte offset {pos} were lost ({what}); \
                 everything before is intact",
                len - pos
            ))
        };
        if data_end {
            // The summary: everything in it is also in the data section; damage to it costs
            // nothing, so the walk reads what parses and stops at the first problem.
            match next_record(input, pos)? {
                Ok((record_end, Record::Footer(f))) => {
                    footer_seen = true;
                    visit(pos as u64, Record::Footer(f))?;
                    pos = record_end;
                }
                Ok((record_end, record)) => {
                    visit(pos as u64, record.into_owned())?;
                    pos = record_end;
                }
                Err(reason) if looks_closed => {
                    // Damaged, not cut: the writer closed the file.
                    damage.push(format!(
                        "byte offset {pos}: the summary section is damaged ({reason}); ignored \
                         from there on (the data are whole)"
                    ));
                    return Ok(end(true, len, None, damage));
                }
                Err(reason) => {
                    return Ok(end(
                        false,
                        pos,
                        Some(format!(
                            "the file ends inside its summary, before the footer ({reason}): \
                             the data are whole"
                        )),
                        damage,
                    ));
                }
            }
            continue;
        }
        if len - pos < RECORD_PREFIX {
            return Ok(end(
                false,
                pos,
                lost(pos, "a record's opcode and length"),
                damage,
            ));
        }
        let prefix = input.copy(pos, pos + RECORD_PREFIX)?;
        let opcode = prefix[0];
        if opcode == 0 && input.zero_from(pos)? {
            return Ok(end(false, pos, lost(pos, "a zero-filled tail"), damage));
        }
        let length = u64::from_le_bytes(prefix[1..RECORD_PREFIX].try_into().expect("8 bytes"));
        let fits = usize::try_from(length)
            .ok()
            .and_then(|l| l.checked_add(pos + RECORD_PREFIX))
            .is_some_and(|e| e <= len);
        if !fits && !looks_closed {
            let what = if opcode == op::CHUNK {
                "an unfinished chunk".to_string()
            } else {
                format!("a record with opcode {opcode:#04x} cut off")
            };
            return Ok(end(false, pos, lost(pos, &what), damage));
        }
        let parsed = if fits {
            next_record(input, pos)?
        } else {
            Err(format!("its length {length} runs past the end of the file"))
        };
        match parsed {
            Ok((record_end, record)) if known(opcode) => {
                match record {
                    Record::Chunk { header, data } => match read_chunk(&header, &data) {
                        Ok(records) => {
                            for r in records {
                                visit(pos as u64, r)?;
                            }
                        }
                        Err(reason) => damage.push(format!(
                            "byte offset {pos}: a chunk of {} bytes is damaged ({reason}); its \
                             messages are lost",
                            record_end - pos
                        )),
                    },
                    Record::DataEnd(_) => {
                        data_end = true;
                        visit(pos as u64, record.into_owned())?;
                    }
                    Record::Footer(_) => {
                        // A footer without data end: the writer closed the file.
                        data_end = true;
                        footer_seen = true;
                        visit(pos as u64, record.into_owned())?;
                    }
                    other => visit(pos as u64, other.into_owned())?,
                }
                pos = record_end;
            }
            other => {
                // A record that does not parse, an opcode the writer never writes, or a length
                // past the end: skip to the next chunk that passes its CRC.
                let reason = match other {
                    Err(reason) => reason,
                    Ok(_) => format!("unknown opcode {opcode:#04x}"),
                };
                let summary = summary_start(input)?.filter(|&s| s > pos);
                match resync(input, pos + 1, summary.unwrap_or(len))? {
                    Some(next) => {
                        damage.push(format!(
                            "byte offset {pos}: a damaged record ({reason}); {} bytes up to the \
                             next intact chunk at byte offset {next} skipped",
                            next - pos
                        ));
                        pos = next;
                    }
                    None if summary.is_some() => {
                        let next = summary.expect("some");
                        damage.push(format!(
                            "byte offset {pos}: a damaged record ({reason}); {} bytes up to the \
                             summary section at byte offset {next} (named by the footer) skipped",
                            next - pos
                        ));
                        pos = next;
                        data_end = true;
                    }
                    None => {
                        damage.push(format!(
                            "byte offset {pos}: a damaged record ({reason}); no intact chunk \
                             after it: the last {} bytes of the file are unreadable",
                            len - pos
                        ));
                        return Ok(end(
                            false,
                            pos,
                            Some(format!(
                                "the file is damaged from byte offset {pos} on ({} bytes \
                                 unreadable, {reason}); everything before is intact",
                                len - pos
                            )),
                            damage,
                        ));
                    }
                }
            }
        }
    }
}

/// Whether the MCAP specification defines `opcode` (the writer writes no other).
fn known(opcode: u8) -> bool {
    (op::HEADER..=op::DATA_END).contains(&opcode)
}

/// The record at `pos` and the offset after it, or what is wrong with it (the outer error:
/// the file could not be read).
#[allow(clippy::type_complexity)]
fn next_record<'i>(
    input: &'i mut Input<'_>,
    pos: usize,
) -> Result<Result<(usize, Record<'i>), String>, LogReadError> {
    let len = input.len();
    if len.saturating_sub(pos) < RECORD_PREFIX {
        return Ok(Err("a record's opcode and length are cut off".into()));
    }
    let prefix = input.copy(pos, pos + RECORD_PREFIX)?;
    let length = u64::from_le_bytes(prefix[1..RECORD_PREFIX].try_into().expect("8 bytes"));
    let Some(end) = usize::try_from(length)
        .ok()
        .and_then(|l| l.checked_add(pos + RECORD_PREFIX))
        .filter(|&e| e <= len)
    else {
        return Ok(Err(format!(
            "its length {length} runs past the end of the file"
        )));
    };
    let body = input.get(pos + RECORD_PREFIX, end)?;
    Ok(mcap::parse_record(prefix[0], body)
        .map(|record| (end, record))
        .map_err(|e| format!("opcode {:#04x}: {e}", prefix[0])))
}

/// The record at `pos` of `bytes` (a chunk's records) and the offset after it, or what is
/// wrong.
fn record_in(bytes: &[u8], pos: usize) -> Result<(usize, Record<'_>), String> {
    let rest = &bytes[pos..];
    if rest.len() < RECORD_PREFIX {
        return Err("a record's opcode and length are cut off".into());
    }
    let length = u64::from_le_bytes(rest[1..RECORD_PREFIX].try_into().expect("8 bytes"));
    let end = usize::try_from(length)
        .ok()
        .and_then(|l| l.checked_add(pos + RECORD_PREFIX))
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| format!("its length {length} runs past the end of the file"))?;
    let record = mcap::parse_record(rest[0], &bytes[pos + RECORD_PREFIX..end])
        .map_err(|e| format!("opcode {:#04x}: {e}", rest[0]))?;
    Ok((end, record))
}

/// Where the summary section starts, as the footer at the end of a closed file says (`None`
/// without an intact footer, or without a summary).
pub(super) fn summary_start(input: &mut Input<'_>) -> Result<Option<usize>, LogReadError> {
    // Footer: opcode, length 20, summary start, summary offset start, summary CRC.
    const FOOTER: usize = RECORD_PREFIX + 20;
    let magic = mcap::MAGIC;
    let len = input.len();
    let Some(at) = len.checked_sub(magic.len() + FOOTER) else {
        return Ok(None);
    };
    if at < magic.len() || input.copy(len - magic.len(), len)? != magic {
        return Ok(None);
    }
    Ok(match next_record(input, at)? {
        Ok((_, Record::Footer(f))) => usize::try_from(f.summary_start)
            .ok()
            .filter(|&s| s >= magic.len() && s < at),
        _ => None,
    })
}

/// The schema and channel records of the summary section of a closed file (read up to the
/// first record that does not parse; none without an intact footer), in order.
pub(super) fn summary_channels(
    input: &mut Input<'_>,
) -> Result<Vec<Record<'static>>, LogReadError> {
    let mut out = Vec::new();
    let Some(mut pos) = summary_start(input)? else {
        return Ok(out);
    };
    loop {
        match next_record(input, pos)? {
            Ok((_, Record::Footer(_))) | Err(_) => return Ok(out),
            Ok((end, record)) => {
                if matches!(record, Record::Schema { .. } | Record::Channel(_)) {
                    out.push(record.into_owned());
                }
                pos = end;
            }
        }
    }
}

/// The offset of the first chunk in `from..until` that parses and passes its CRC.
fn resync(input: &mut Input<'_>, from: usize, until: usize) -> Result<Option<usize>, LogReadError> {
    const PIECE: usize = 1 << 16;
    let stop = until.min(input.len().saturating_sub(RECORD_PREFIX));
    let mut at = from;
    while at < stop {
        let to = (at + PIECE).min(stop);
        let piece = input.copy(at, to)?;
        for (i, _) in piece.iter().enumerate().filter(|(_, &b)| b == op::CHUNK) {
            let p = at + i;
            if let Ok((_, Record::Chunk { header, data })) = next_record(input, p)? {
                if read_chunk(&header, &data).is_ok() {
                    return Ok(Some(p));
                }
            }
        }
        at = to;
    }
    Ok(None)
}

/// Decompresses a chunk (to at most the size it claims), checks its size and CRC, then parses
/// its records; its records, or what is wrong.
fn read_chunk(
    header: &mcap::records::ChunkHeader,
    data: &[u8],
) -> Result<Vec<Record<'static>>, String> {
    let size = header.uncompressed_size;
    if size > MAX_CHUNK_BYTES {
        return Err(format!(
            "it claims {size} bytes uncompressed, more than the {MAX_CHUNK_BYTES} a chunk may \
             hold"
        ));
    }
    let raw: Cow<'_, [u8]> = match header.compression.as_str() {
        "" => Cow::Borrowed(data),
        "zstd" => Cow::Owned(decompress(
            zstd::stream::read::Decoder::new(data).map_err(|e| format!("zstd: {e}"))?,
            size,
        )?),
        "lz4" => Cow::Owned(decompress(
            lz4::Decoder::new(data).map_err(|e| format!("lz4: {e}"))?,
            size,
        )?),
        other => return Err(format!("unknown compression {other:?}")),
    };
    if raw.len() as u64 != size {
        return Err(format!(
            "it holds {} bytes uncompressed, its header says {size}",
            raw.len()
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&raw);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "CRC {crc:#010x} where {:#010x} was written",
                header.uncompressed_crc
            ));
        }
    }
    let mut records = Vec::new();
    let mut pos = 0;
    while pos < raw.len() {
        let (end, record) =
            record_in(&raw, pos).map_err(|e| format!("a record inside at {pos}: {e}"))?;
        records.push(record.into_owned());
        pos = end;
    }
    Ok(records)
}

/// Reads a decompressor to its end, at most `size + 1` bytes (one more tells a chunk that
/// holds more than it claims).
fn decompress(reader: impl Read, size: u64) -> Result<Vec<u8>, String> {
    // NOTE: the capacity is not taken from the file: a damaged size must not allocate.
    let mut out = Vec::with_capacity(usize::try_from(size).map_or(0, |s| s.min(1 << 24)));
    reader
        .take(size + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("it does not decompress: {e}"))?;
    Ok(out)
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
        let end = scan::<LogReadError>(
            Path::new("x.mcap"),
            &mut Input::Memory(mcap::MAGIC),
            |_, _| Ok(()),
        )
        .unwrap();
        assert!(!end.complete);
        assert_eq!(end.valid_bytes, 8);
    }

    #[test]
    fn prefix_of_magic_is_reported_as_cut_magic() {
        let err = scan::<LogReadError>(
            Path::new("x.mcap"),
            &mut Input::Memory(&mcap::MAGIC[..5]),
            |_, _| Ok(()),
        )
        .unwrap_err();
        assert!(
            matches!(err, LogReadError::TruncatedMagic { len: 5, .. }),
            "{err}"
        );
    }
}
