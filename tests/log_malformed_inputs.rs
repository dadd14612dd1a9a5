//! Guards the session log reader against bad files: a missing file, an empty file, random
//! bytes, a text file, a PNG, a file cut inside the MCAP magic, an MCAP written by another tool
//! (no "rigtwin" metadata) and chunks with flipped bytes each give a clear error naming the file
//! and what is wrong, never a panic; a session cut at any byte offset reads without error,
//! incomplete, with a message count that only grows with the length kept.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use rigtwin::log::{read_session, Compression, LogOptions, LogReadError, SessionLog};
use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize, schemars::JsonSchema)]
struct Block {
    seq: u64,
    counts: Vec<i32>,
}

/// Writes a closed session with `n` blocks; returns its path.
fn write_session(dir: &Path, name: &str, compression: Compression, n: u64) -> PathBuf {
    let path = dir.join(name);
    let (log, join) = SessionLog::create(
        &path,
        LogOptions {
            compression,
            chunk_size_bytes: 2048,
            flush_interval: Duration::from_secs(10),
            ..LogOptions::default()
        },
        vec![(
            "session".to_string(),
            BTreeMap::from([("id".to_string(), "1".to_string())]),
        )],
        vec![],
    )
    .unwrap();
    let ch = log.channel::<Block>("/rig/daq").unwrap();
    for i in 0..n {
        let block = Block {
            seq: i,
            counts: (0..32).map(|k| (k * 31 + i as i32 * 17) % 1000).collect(),
        };
        log.log(&ch, i, &block).unwrap();
    }
    join.close().unwrap();
    path
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The error's message, checked to name the file.
fn error_text(path: &Path) -> String {
    let err = read_session(path).expect_err("a bad file must be an error");
    let text = err.to_string();
    assert!(text.contains(&*path.to_string_lossy()), "{text}");
    text
}

#[test]
fn missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("absent.mcap");
    let text = error_text(&path);
    assert!(text.contains("cannot read the file"), "{text}");
}

#[test]
fn empty_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "empty.mcap", b"");
    let text = error_text(&path);
    assert!(text.contains("empty"), "{text}");
}

#[test]
fn random_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let mut x = 0x2545_f491_4f6c_dd1d_u64;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    let path = write_file(dir.path(), "random.mcap", &bytes);
    let text = error_text(&path);
    assert!(text.contains("not an MCAP file"), "{text}");
}

#[test]
fn text_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "rig.toml", b"[rig]\nname = \"two beams\"\n");
    let text = error_text(&path);
    assert!(
        text.contains("not an MCAP file") && text.contains("text"),
        "{text}"
    );
}

#[test]
fn png_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend_from_slice(&[0, 0, 0, 13, b'I', b'H', b'D', b'R']);
    let path = write_file(dir.path(), "figure.png", &png);
    let text = error_text(&path);
    assert!(
        text.contains("not an MCAP file") && text.contains("PNG"),
        "{text}"
    );
}

#[test]
fn cut_inside_the_magic() {
    let dir = tempfile::tempdir().unwrap();
    let full = write_session(dir.path(), "full.mcap", Compression::Zstd, 10);
    let bytes = std::fs::read(full).unwrap();
    for n in 1..8 {
        let path = write_file(dir.path(), &format!("cut{n}.mcap"), &bytes[..n]);
        let err = read_session(&path).unwrap_err();
        assert!(
            matches!(err, LogReadError::TruncatedMagic { len, .. } if len == n),
            "{err}"
        );
        assert!(err.to_string().contains("inside the MCAP magic"), "{err}");
    }
}

#[test]
fn mcap_from_another_tool() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("foreign.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = mcap::WriteOptions::new()
            .library("other-tool/1.0")
            .create(file)
            .unwrap();
        let schema = w.add_schema("Point", "jsonschema", b"{}").unwrap();
        let ch = w
            .add_channel(schema, "/points", "json", &BTreeMap::new())
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, b"{\"x\":1}").unwrap();
        w.finish().unwrap();
    }
    // A valid MCAP reads fine ...
    let s = read_session(&path).unwrap();
    assert!(s.complete);
    assert_eq!(s.messages.len(), 1);
    // ... but is not a rigtwin session.
    let err = s.require_rigtwin().unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, LogReadError::NotRigtwin { .. }), "{text}");
    assert!(
        text.contains("foreign.mcap")
            && text.contains("\"rigtwin\" metadata")
            && text.contains("other-tool/1.0"),
        "{text}"
    );
}

/// Byte offset and length of the first chunk record's body.
fn first_chunk(bytes: &[u8]) -> (usize, usize) {
    let mut pos = 8;
    loop {
        let op = bytes[pos];
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        if op == 0x06 {
            return (pos + 9, len);
        }
        pos += 9 + len;
    }
}

#[test]
fn chunk_with_flipped_bytes() {
    let dir = tempfile::tempdir().unwrap();
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let name = format!("flipped-{compression:?}.mcap");
        let path = write_session(dir.path(), &name, compression, 200);
        let mut bytes = std::fs::read(&path).unwrap();
        let (body, len) = first_chunk(&bytes);
        // Past the chunk header, inside the compressed records.
        let at = body + len * 2 / 3;
        for b in &mut bytes[at..at + 4] {
            *b ^= 0x5a;
        }
        std::fs::write(&path, &bytes).unwrap();
        // Issue 17, case 8: the damaged chunk is skipped and described, the chunks before and
        // after it are read (the first chunk holds the first messages: the rest survive).
        let s = read_session(&path).unwrap();
        assert!(s.complete, "{compression:?}: {:?}", s.note);
        assert_eq!(s.damage.len(), 1, "{compression:?}: {:?}", s.damage);
        assert!(
            s.damage[0].contains("chunk") && s.damage[0].contains("damaged"),
            "{:?}",
            s.damage
        );
        let seqs: Vec<u32> = s.messages_on("/rig/daq").map(|m| m.sequence).collect();
        assert!(
            !seqs.is_empty() && seqs[0] > 0 && *seqs.last().unwrap() == 199,
            "{compression:?}: {seqs:?}"
        );
        assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1));
    }
}

#[test]
fn session_cut_at_any_offset_reads_what_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let full = write_session(dir.path(), "full.mcap", Compression::Zstd, 100);
    let bytes = std::fs::read(&full).unwrap();
    eprintln!("cutting a {} byte session at every offset", bytes.len());
    let all = read_session(&full).unwrap();
    assert!(all.complete);
    assert_eq!(all.messages.len(), 100);

    let mut last = 0;
    let mut step_count = 0;
    for n in 8..bytes.len() {
        let s = rigtwin::log::read_session_bytes(Path::new("cut.mcap"), &bytes[..n])
            .unwrap_or_else(|e| panic!("cut at {n} of {}: {e}", bytes.len()));
        assert!(!s.complete, "cut at {n} must be incomplete");
        assert!(s.note.is_some());
        assert!(
            s.messages.len() >= last,
            "cut at {n}: fewer messages than a shorter cut"
        );
        if s.messages.len() > last {
            step_count += 1;
        }
        last = s.messages.len();
        for (i, m) in s.messages.iter().enumerate() {
            assert_eq!(m.sequence as usize, i);
        }
    }
    assert_eq!(
        last, 100,
        "a file cut inside its summary keeps all messages"
    );
    assert!(step_count > 1, "several chunks expected");
}
