//! Guards the session log's crash promise: a process killed with SIGKILL while it logs leaves
//! a file that `read_session` reads without error, marked incomplete, with every message up to
//! the last flush the writer reported (sequence numbers contiguous from 0 on every channel)
//! and the session metadata.
//!
//! The test binary re-invokes itself: the `#[ignore]`d child test logs continuously (200 ms
//! flush interval) and prints a line after each flush it observes; the parent kills it after
//! several flushes.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use rigtwin::log::{read_session, LogOptions, SessionLog};
use serde::{Deserialize, Serialize};

const CHILD_ENV: &str = "RIGTWIN_SIGKILL_CHILD_LOG";
const CHILD_TEST: &str = "child_logs_until_killed";
/// Flushes the parent waits for before killing the child.
const FLUSHES_BEFORE_KILL: usize = 4;

#[derive(Serialize, Deserialize, schemars::JsonSchema)]
struct Block {
    seq: u64,
    counts: Vec<i32>,
}

#[derive(Serialize, Deserialize, schemars::JsonSchema)]
struct Event {
    block: u64,
}

/// The child: logs blocks (and an event every 10 blocks) until killed, at most 30 s.
#[test]
#[ignore = "child process of session_log_survives_sigkill"]
fn child_logs_until_killed() {
    let Some(path) = std::env::var_os(CHILD_ENV) else {
        return;
    };
    let options = LogOptions {
        flush_interval: Duration::from_millis(200),
        ..LogOptions::default()
    };
    let meta = vec![(
        "session".to_string(),
        [("kind".to_string(), "sigkill test".to_string())].into(),
    )];
    let (log, join) = SessionLog::create(Path::new(&path), options, meta, vec![]).unwrap();
    // As a session does once it starts: from here on the log is at its own name.
    log.publish().unwrap();
    let blocks = log.channel::<Block>("/rig/daq").unwrap();
    let events = log.channel::<Event>("/control/events").unwrap();
    let start = Instant::now();
    let mut seen_flushes = 0;
    let mut i = 0u64;
    while start.elapsed() < Duration::from_secs(30) {
        let block = Block {
            seq: i,
            counts: (0..256).map(|k| (k * 7 + i as i32) % 4000 - 2000).collect(),
        };
        log.log(&blocks, i * 1_000_000, &block).unwrap();
        if i % 10 == 0 {
            log.log(&events, i * 1_000_000, &Event { block: i })
                .unwrap();
        }
        i += 1;
        let progress = log.progress();
        if progress.flushes > seen_flushes {
            seen_flushes = progress.flushes;
            // The parent reads these lines from a pipe.
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "FLUSHED {}", progress.messages_flushed);
            let _ = out.flush();
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    join.close().unwrap();
}

#[test]
fn session_log_survives_sigkill() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.mcap");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", CHILD_TEST, "--ignored", "--nocapture"])
        .env(CHILD_ENV, &path)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start the child test process");
    let stdout = child.stdout.take().unwrap();
    let mut flushed = 0u64;
    let mut flushes = 0;
    let mut lines = Vec::new();
    // The pipe stays open until the child is dead: it keeps printing.
    let mut reader = BufReader::new(stdout);
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap() == 0 {
            break;
        }
        let line = line.trim_end().to_string();
        if let Some(n) = line.strip_prefix("FLUSHED ") {
            flushed = n.trim().parse().unwrap();
            flushes += 1;
            if flushes >= FLUSHES_BEFORE_KILL {
                break;
            }
        }
        lines.push(line);
    }
    // Half a flush interval later: the child is then usually inside a chunk.
    std::thread::sleep(Duration::from_millis(100));
    child.kill().unwrap();
    let status = child.wait().unwrap();
    drop(reader);
    assert!(
        flushes >= FLUSHES_BEFORE_KILL,
        "the child stopped after {flushes} flushes ({status}):\n{}",
        lines.join("\n")
    );
    assert!(flushed > 0);

    let s = read_session(&path).unwrap();
    assert!(
        !s.complete,
        "a killed writer cannot have written the footer"
    );
    let note = s.note.as_deref().unwrap();
    assert!(
        note.contains("ends early") || note.contains("did not close"),
        "{note}"
    );
    s.require_rigtwin().unwrap();
    assert_eq!(s.metadata("session").unwrap()["kind"], "sigkill test");
    assert!(s.valid_bytes <= s.file_bytes);

    let blocks = s.decode::<Block>("/rig/daq").unwrap();
    let events = s.decode::<Event>("/control/events").unwrap();
    for (i, (t, seq, b)) in blocks.iter().enumerate() {
        assert_eq!(
            (*seq, b.seq, *t),
            (i as u64, i as u64, i as u64 * 1_000_000)
        );
    }
    for (i, (_, seq, e)) in events.iter().enumerate() {
        assert_eq!((*seq, e.block), (i as u64, 10 * i as u64));
    }
    let total = (blocks.len() + events.len()) as u64;
    assert!(
        total >= flushed,
        "{total} messages recovered, the writer had flushed {flushed} ({note})"
    );
    eprintln!(
        "recovered {total} messages ({} blocks), {flushed} reported flushed; {note}",
        blocks.len()
    );
}
