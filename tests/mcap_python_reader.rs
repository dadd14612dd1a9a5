//! Guards that rigtwin's session logs are standard MCAP that a reader not written here reads
//! as intended: the official Python `mcap` reader (PyPI `mcap`, CRC validation on) must find
//! every channel with message encoding "json" and a "jsonschema" schema named after the Rust
//! type, the message counts per topic, per-channel sequence numbers contiguous from 0, JSON
//! payloads, the metadata records (with the writer's "rigtwin" record) and the attachments.
//! Checked for each chunk compression.
//!
//! Without python3 or its `mcap` module the test says why and passes, unless
//! `RIGTWIN_REQUIRE_MCAP_PY` is set (CI), when it fails.

mod log_support;

use log_support::{mcap_python_or_skip, read_with_python};
use std::collections::BTreeMap;

use rigtwin::log::{Attachment, Compression, LogOptions, SessionLog};
use serde::Serialize;

/// A DAQ-block-like message.
#[derive(Serialize, schemars::JsonSchema)]
struct TestBlock {
    seq: u64,
    time: f64,
    counts: Vec<i32>,
}

/// An event message with an enum.
#[derive(Serialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum TestEvent {
    StepStarted { frequency_hz: f64 },
    Abort { cause: String },
}

/// A control-state-like message.
#[derive(Serialize, schemars::JsonSchema)]
struct TestControl {
    amplitude_v: f64,
    settled: bool,
}

#[test]
fn official_python_reader_reads_session_logs() {
    let Some(python) = mcap_python_or_skip("official_python_reader_reads_session_logs") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let path = dir.path().join(format!("{compression:?}.mcap"));
        let rig_toml = b"[rig]\nname = \"two beams\"\n".to_vec();
        let (log, join) = SessionLog::create(
            &path,
            LogOptions {
                compression,
                // Small chunks: several chunks per file.
                chunk_size_bytes: 4096,
                ..LogOptions::default()
            },
            vec![
                (
                    "session".to_string(),
                    BTreeMap::from([("backend".to_string(), "sim".to_string())]),
                ),
                (
                    "rom".to_string(),
                    BTreeMap::from([("sha256".to_string(), "ab12".to_string())]),
                ),
            ],
            vec![Attachment {
                name: "rig.toml".into(),
                media_type: "application/toml".into(),
                data: rig_toml.clone(),
            }],
        )
        .unwrap();
        let daq = log.channel::<TestBlock>("/rig/daq").unwrap();
        let events = log.channel::<TestEvent>("/control/events").unwrap();
        let control = log.channel::<TestControl>("/control/state").unwrap();
        let _unused = log.channel::<TestControl>("/twin/unused").unwrap();
        let n = 500u64;
        for i in 0..n {
            let t = i * 1_000_000;
            let block = TestBlock {
                seq: i,
                time: i as f64 * 1e-3,
                counts: (0..64).map(|k| (k * i as i32) % 2048 - 1024).collect(),
            };
            log.log(&daq, t, &block).unwrap();
            if i % 5 == 0 {
                let state = TestControl {
                    amplitude_v: 0.01 * i as f64,
                    settled: i % 2 == 0,
                };
                log.log(&control, t, &state).unwrap();
            }
            if i % 100 == 0 {
                let event = if i == 400 {
                    TestEvent::Abort {
                        cause: "contact duty".into(),
                    }
                } else {
                    TestEvent::StepStarted {
                        frequency_hz: 100.0 + i as f64,
                    }
                };
                log.log(&events, t, &event).unwrap();
            }
        }
        let stats = join.close().unwrap();
        assert_eq!(stats.messages_per_topic["/rig/daq"], n);

        let py = read_with_python(&python, &path);
        let ctx = format!("{compression:?}: {py:#}");
        let channels = py["channels"].as_object().unwrap();
        assert_eq!(channels.len(), 4, "{ctx}");
        for (topic, schema_name) in [
            ("/rig/daq", "TestBlock"),
            ("/control/events", "TestEvent"),
            ("/control/state", "TestControl"),
            ("/twin/unused", "TestControl"),
        ] {
            let ch = &channels[topic];
            assert_eq!(ch["message_encoding"], "json", "{topic} {ctx}");
            assert_eq!(ch["schema_name"], schema_name, "{topic} {ctx}");
            assert_eq!(ch["schema_encoding"], "jsonschema", "{topic} {ctx}");
            assert_eq!(ch["schema_is_object"], true, "{topic} {ctx}");
        }
        let expected_counts = serde_json::json!({
            "/rig/daq": n, "/control/state": n / 5, "/control/events": n / 100
        });
        assert_eq!(py["counts"], expected_counts, "{ctx}");
        for topic in ["/rig/daq", "/control/state", "/control/events"] {
            assert_eq!(
                py["sequences_contiguous_from_0"][topic], true,
                "{topic} {ctx}"
            );
            assert_eq!(py["log_times_sorted"][topic], true, "{topic} {ctx}");
        }
        assert_eq!(py["payload_errors"], serde_json::json!([]), "{ctx}");
        assert_eq!(py["first_payloads"]["/rig/daq"]["seq"], 0, "{ctx}");
        assert_eq!(
            py["first_payloads"]["/rig/daq"]["counts"]
                .as_array()
                .unwrap()
                .len(),
            64,
            "{ctx}"
        );
        assert_eq!(
            py["first_payloads"]["/control/events"]["kind"], "step_started",
            "{ctx}"
        );
        let metadata = py["metadata"].as_object().unwrap();
        let mut names: Vec<&str> = metadata.keys().map(String::as_str).collect();
        names.sort_unstable();
        assert_eq!(names, ["rigtwin", "rom", "session"], "{ctx}");
        assert_eq!(
            metadata["rigtwin"]["crate_version"],
            env!("CARGO_PKG_VERSION"),
            "{ctx}"
        );
        assert_eq!(
            metadata["rigtwin"]["format_version"],
            rigtwin::log::FORMAT_VERSION.to_string(),
            "{ctx}"
        );
        assert_eq!(metadata["session"]["backend"], "sim", "{ctx}");
        assert_eq!(
            py["attachments"]["rig.toml"],
            serde_json::json!({"media_type": "application/toml", "size": rig_toml.len()}),
            "{ctx}"
        );
        let total = n + n / 5 + n / 100;
        assert_eq!(py["statistics"]["message_count"], total, "{ctx}");
        assert_eq!(py["statistics"]["channel_count"], 4, "{ctx}");
        assert!(
            py["statistics"]["chunk_count"].as_u64().unwrap() > 1,
            "{ctx}"
        );
        assert!(
            py["library"].as_str().unwrap().starts_with("rigtwin/"),
            "{ctx}"
        );
    }
}
