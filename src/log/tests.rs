//! Unit tests of the session log: writer and reader round trip, sequence numbers, the
//! backlog path (with a stalled writer thread), idle flushing, reserved names and misuse.

use std::collections::BTreeMap;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::task::Command;
use super::*;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
struct Block {
    seq: u64,
    counts: Vec<i32>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
struct Event {
    what: String,
}

fn options() -> LogOptions {
    LogOptions {
        flush_interval: Duration::from_millis(50),
        ..LogOptions::default()
    }
}

#[test]
fn round_trip_keeps_messages_metadata_and_attachments() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.mcap");
        let meta = vec![(
            "session".to_string(),
            BTreeMap::from([("id".to_string(), "42".to_string())]),
        )];
        let att = vec![Attachment {
            name: "rig.toml".into(),
            media_type: "application/toml".into(),
            data: b"[rig]\n".to_vec(),
        }];
        let (log, join) = SessionLog::create(
            &path,
            LogOptions {
                compression,
                chunk_size_bytes: 256,
                ..options()
            },
            meta,
            att,
        )
        .unwrap();
        let blocks = log.channel::<Block>("/daq").unwrap();
        let events = log.channel::<Event>("/events").unwrap();
        for i in 0..100u64 {
            let block = Block {
                seq: i,
                counts: vec![i as i32; 8],
            };
            log.log(&blocks, i * 1000, &block).unwrap();
            if i % 10 == 0 {
                let e = Event {
                    what: format!("step {i}"),
                };
                log.log(&events, i * 1000, &e).unwrap();
            }
        }
        let stats = join.close().unwrap();
        assert_eq!(stats.messages_per_topic["/daq"], 100);
        assert_eq!(stats.messages_per_topic["/events"], 10);
        assert_eq!(stats.backlog_drops, 0);
        assert_eq!(stats.bytes_written, std::fs::metadata(&path).unwrap().len());

        let s = read_session(&path).unwrap();
        assert!(s.complete, "{compression:?}: {:?}", s.note);
        assert_eq!(s.note, None);
        assert_eq!(s.require_rigtwin().unwrap().format_version, FORMAT_VERSION);
        assert_eq!(s.metadata("session").unwrap()["id"], "42");
        assert_eq!(s.attachment("rig.toml").unwrap().data, b"[rig]\n");
        let daq = s.decode::<Block>("/daq").unwrap();
        assert_eq!(daq.len(), 100);
        for (i, (t, seq, b)) in daq.iter().enumerate() {
            assert_eq!((*t, *seq, b.seq), (i as u64 * 1000, i as u64, i as u64));
        }
        let ch = s.channel("/daq").unwrap();
        assert_eq!(ch.message_encoding, "json");
        let schema = ch.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("Block", "jsonschema")
        );
        let schema: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(schema["properties"]["counts"]["type"], "array");
        assert_eq!(s.decode::<Event>("/events").unwrap()[1].2.what, "step 10");
    }
}

#[test]
fn full_queue_reports_backlog_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let (log, join) = SessionLog::create(
        &path,
        LogOptions {
            queue_capacity: 2,
            ..options()
        },
        vec![],
        vec![],
    )
    .unwrap();
    let ch = log.channel::<Event>("/events").unwrap();
    // Stall the writer thread (it has taken the stall command off the queue).
    let (entered_tx, entered_rx) = mpsc::sync_channel(1);
    let (release_tx, release_rx) = mpsc::channel();
    log.send_for_test(Command::Stall {
        entered: entered_tx,
        release: release_rx,
    });
    entered_rx.recv().unwrap();

    let e = Event { what: "x".into() };
    log.log(&ch, 0, &e).unwrap();
    log.log(&ch, 1, &e).unwrap();
    let start = Instant::now();
    let err = log.log(&ch, 2, &e).unwrap_err();
    assert!(start.elapsed() < Duration::from_millis(100), "log() waited");
    assert!(
        matches!(err, LogError::Backlog { capacity: 2, .. }),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.contains("s.mcap") && text.contains("/events"),
        "{text}"
    );
    assert_eq!(log.progress().backlog_drops, 1);
    assert_eq!(ch.raw().backlog_drops(), 1);

    release_tx.send(()).unwrap();
    let start = Instant::now();
    while log.progress().messages_written < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "writer did not resume"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    log.log(&ch, 3, &e).unwrap();
    let stats = join.close().unwrap();
    assert_eq!(stats.backlog_drops, 1);
    assert_eq!(stats.drops_per_topic["/events"], 1);
    assert_eq!(stats.messages_per_topic["/events"], 3);
    // The dropped message left a gap in the sequence.
    let s = read_session(&path).unwrap();
    let seqs: Vec<u64> = s
        .decode::<Event>("/events")
        .unwrap()
        .iter()
        .map(|m| m.1)
        .collect();
    assert_eq!(seqs, [0, 1, 3]);
}

#[test]
fn idle_writer_flushes_within_the_interval() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    log.publish().unwrap();
    let ch = log.channel::<Event>("/events").unwrap();
    log.log(&ch, 5, &Event { what: "a".into() }).unwrap();
    // No further messages: the flush must come from the timeout.
    let start = Instant::now();
    while log.progress().messages_flushed < 1 {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "no flush while idle"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let s = read_session(&path).unwrap();
    assert!(!s.complete);
    assert!(
        s.note.as_deref().unwrap().contains("did not close"),
        "{:?}",
        s.note
    );
    assert_eq!(s.decode::<Event>("/events").unwrap().len(), 1);
    join.close().unwrap();
    assert!(read_session(&path).unwrap().complete);
}

#[test]
fn dropping_every_handle_finishes_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    let ch = log.channel::<Event>("/events").unwrap();
    let other = log.clone();
    std::thread::spawn(move || other.log(&ch, 1, &Event { what: "t".into() }).unwrap())
        .join()
        .unwrap();
    drop(log);
    let stats = join.close().unwrap();
    assert_eq!(stats.messages_per_topic["/events"], 1);
    assert!(read_session(&path).unwrap().complete);
}

/// Issue 17, case 3: until published (a session publishes when it starts) the log is written
/// under a temporary name; a log dropped unpublished leaves an existing file of its name as it
/// was and nothing else behind, a closed one replaces it.
#[test]
fn an_unpublished_log_leaves_the_existing_file_alone() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    std::fs::write(&path, b"the previous session").unwrap();
    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    let ch = log.channel::<Event>("/events").unwrap();
    log.log(&ch, 5, &Event { what: "a".into() }).unwrap();
    assert_ne!(log.current_path(), path);
    assert!(log.current_path().exists());
    drop((log, join));
    assert_eq!(std::fs::read(&path).unwrap(), b"the previous session");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    drop(log);
    join.close().unwrap();
    assert!(read_session(&path).unwrap().complete);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn logging_after_close_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    let ch = log.channel::<Event>("/events").unwrap();
    join.close().unwrap();
    let err = log
        .log(
            &ch,
            0,
            &Event {
                what: "late".into(),
            },
        )
        .unwrap_err();
    assert!(matches!(err, LogError::Closed { .. }), "{err}");
    assert!(log.channel::<Block>("/daq").is_err());
}

#[test]
fn misuse_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    let err = SessionLog::create(
        &path,
        options(),
        vec![(RIGTWIN_METADATA.to_string(), BTreeMap::new())],
        vec![],
    )
    .err()
    .unwrap();
    assert!(matches!(err, LogError::ReservedMetadata { .. }), "{err}");

    let (log, join) = SessionLog::create(&path, options(), vec![], vec![]).unwrap();
    let a = log.channel::<Event>("/t").unwrap();
    let again = log.channel::<Event>("/t").unwrap();
    log.log(&a, 0, &Event { what: "1".into() }).unwrap();
    log.log(&again, 0, &Event { what: "2".into() }).unwrap();
    let err = log.channel::<Block>("/t").unwrap_err();
    assert!(matches!(err, LogError::TopicConflict { .. }), "{err}");

    let other_path = dir.path().join("other.mcap");
    let (other, other_join) = SessionLog::create(&other_path, options(), vec![], vec![]).unwrap();
    let err = other.log(&a, 0, &Event { what: "x".into() }).unwrap_err();
    assert!(matches!(err, LogError::ForeignChannel { .. }), "{err}");
    other_join.close().unwrap();

    join.close().unwrap();
    let s = read_session(&path).unwrap();
    let seqs: Vec<u64> = s
        .decode::<Event>("/t")
        .unwrap()
        .iter()
        .map(|m| m.1)
        .collect();
    assert_eq!(seqs, [0, 1], "copies of a channel share its sequence");
    let err = s.decode::<Event>("/nope").unwrap_err();
    assert!(
        err.to_string().contains("\"/nope\"") && err.to_string().contains("/t"),
        "{err}"
    );
    let err = s.decode::<Block>("/t").unwrap_err();
    let text = err.to_string();
    assert!(text.contains("topic /t, message 0 (sequence 0)"), "{text}");
}

#[test]
fn bad_options_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    for (options, what) in [
        (
            LogOptions {
                flush_interval: Duration::ZERO,
                ..options()
            },
            "flush_interval",
        ),
        (
            LogOptions {
                queue_capacity: 0,
                ..options()
            },
            "queue_capacity",
        ),
        (
            LogOptions {
                chunk_size_bytes: 0,
                ..options()
            },
            "chunk_size_bytes",
        ),
    ] {
        let err = SessionLog::create(&path, options, vec![], vec![])
            .err()
            .unwrap();
        assert!(matches!(err, LogError::Options { .. }), "{err}");
        assert!(err.to_string().contains(what), "{err}");
    }
    assert!(!path.exists(), "no file for bad options");
}

#[test]
fn missing_directory_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/dir/s.mcap");
    let err = SessionLog::create(&path, options(), vec![], vec![])
        .err()
        .unwrap();
    assert!(err.to_string().contains("no/such/dir/s.mcap"), "{err}");
}
