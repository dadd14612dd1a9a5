//! `strip_hidden_physics` (tests/diagnose_support), which writes the logs the `rigtwin diagnose`
//! proofs run on, on a session of the simulated rig (with the live twin) whose `[truth]` hides
//! every kind of physics in `[truth.variants]`. Guards:
//! - no trace of the hidden physics is left: "truth" (any case) is in no metadata record,
//!   attachment, topic or message of the copy, by rigtwin's reader and by the official Python
//!   `mcap` reader (skipped without it, unless `RIGTWIN_REQUIRE_MCAP_PY` is set);
//! - everything else is kept: the same channels and messages (sequence, log and publish times,
//!   payload), the metadata but the removed keys (the ones the report names), the same rig
//!   description but `[truth]`; replay gives the same summary and recording;
//! - a truncated file, an empty one, a missing one, one that is not MCAP or not rigtwin's is an
//!   error naming it, and nothing is written.

mod cli_support;
mod diagnose_support;
mod log_support;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use cli_support::{default_rig_with, rigtwin, text, write_plan};
use diagnose_support::strip_hidden_physics;
use log_support::mcap_python_or_skip;
use rigtwin::config::{RigConfig, TruthSpec};
use rigtwin::log::{read_session, Attachment, LogOptions, SessionLog, SessionRead};
use rigtwin::session::replay::replay;

/// The hidden physics: a `[truth]` key and every kind of `[truth.variants]`.
const HIDDEN: &str = r#"
[truth]
stability_margin = 0.5

[truth.variants]
modes = [{ mode = "1FU", frequency_hz = 50.9, damping_ratio = 0.004 }]
sensor_gains = [{ channel = "lower_tip", gain = 1.03 }]

[truth.variants.clamp_friction]
stiffness_fraction = 0.05
half_slip_tip_amplitude = 1.5e-4

[truth.variants.clearance]
offset = 2.0e-5

[truth.variants.wear]
coefficient = 2.5e-8

[truth.variants.tilt]
angle = 2.0e-3
"#;

/// Two short steps around 1FU.
const PLAN: &str = r#"
name = "strip"
[defaults]
level = 0.5e-5
clearance = 2.33e-3
steps = 2
settle_periods = 20
record_periods = 10
[[test]]
name = "near-1fu"
direction = "up"
omega_start = 0.99
omega_end = 1.01
"#;

/// Reads a file with the official Python `mcap` reader (CRCs checked): its metadata records,
/// its attachments as text, and how many messages it holds.
const PY_READ: &str = r#"
import json, sys
from mcap.reader import make_reader
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, validate_crcs=True)
    out = {
        "metadata": {m.name: dict(m.metadata) for m in reader.iter_metadata()},
        "attachments": {
            a.name: a.data.decode("utf-8", "replace") for a in reader.iter_attachments()
        },
        "messages": sum(1 for _ in reader.iter_messages()),
    }
print(json.dumps(out))
"#;

/// Whether `bytes` hold "truth" in any case.
fn has_truth(bytes: impl AsRef<[u8]>) -> bool {
    let bytes = bytes.as_ref();
    bytes.windows(5).any(|w| w.eq_ignore_ascii_case(b"truth"))
}

/// Where "truth" occurs in `s`: metadata records, attachments, channels and messages.
fn traces(s: &SessionRead) -> Vec<String> {
    let mut found = Vec::new();
    for (name, entries) in &s.metadata {
        if has_truth(name) {
            found.push(format!("metadata {name}"));
        }
        for (key, value) in entries {
            if has_truth(format!("{key} = {value}")) {
                found.push(format!("metadata {name}/{key}"));
            }
        }
    }
    for a in &s.attachments {
        if has_truth(&a.name) || has_truth(&a.data) {
            found.push(format!("attachment {}", a.name));
        }
    }
    for c in &s.channels {
        if has_truth(format!("{} {:?}", c.topic, c.metadata)) {
            found.push(format!("channel {}", c.topic));
        }
    }
    for m in s.messages.iter().filter(|m| has_truth(&m.data)) {
        found.push(format!("message {} #{}", m.topic, m.sequence));
    }
    found
}

/// Runs `PLAN` with the live twin on the default rig hiding `HIDDEN`; returns the log.
fn session(dir: &Path) -> PathBuf {
    let rig = default_rig_with(dir, HIDDEN);
    let plan = write_plan(dir, PLAN);
    let out = dir.join("session.mcap");
    let o = rigtwin(&[
        "run",
        rig.to_str().unwrap(),
        "--plan",
        &plan,
        "--twin",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    out
}

/// The rig description attached to `s`, parsed.
fn rig_config(s: &SessionRead) -> RigConfig {
    let a = s.attachment("rig.toml").expect("a rig.toml attachment");
    RigConfig::from_str(std::str::from_utf8(&a.data).unwrap(), "rig.toml").unwrap()
}

#[test]
fn a_stripped_log_keeps_no_trace_of_the_hidden_physics_and_replays_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let original = session(dir.path());
    let stripped = dir.path().join("stripped.mcap");
    let report = strip_hidden_physics(&original, &stripped).unwrap();
    let (before, after) = (
        read_session(&original).unwrap(),
        read_session(&stripped).unwrap(),
    );

    // The traces were there, and are gone.
    let mut tables = report.rig_toml_tables.clone();
    tables.sort();
    assert_eq!(
        tables,
        [
            "truth",
            "truth.variants",
            "truth.variants.clamp_friction",
            "truth.variants.clearance",
            "truth.variants.tilt",
            "truth.variants.wear"
        ]
    );
    let mut keys = report.metadata_keys.clone();
    keys.sort();
    assert_eq!(
        keys,
        [
            "rom/truth_config_hash",
            "rom/truth_modes",
            "session/truth_variants"
        ]
    );
    let found = traces(&before);
    assert!(
        found.contains(&"attachment rig.toml".to_string()),
        "{found:?}"
    );
    assert_eq!(traces(&after), Vec::<String>::new());

    // Everything else is kept.
    assert!(
        after.complete && after.damage.is_empty(),
        "{:?}",
        after.note
    );
    assert_eq!(
        (&after.profile, &after.library),
        (&before.profile, &before.library)
    );
    assert_eq!(after.channels, before.channels);
    assert!(before.channels.iter().any(|c| c.topic == "/twin/state"));
    assert_eq!(after.messages.len(), before.messages.len());
    assert!(
        after.messages == before.messages,
        "messages differ (channel, sequence, times or payload)"
    );
    let names = |s: &SessionRead| s.metadata.iter().map(|m| m.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&after), names(&before));
    let mut removed = Vec::new();
    for ((name, b), (_, a)) in before.metadata.iter().zip(&after.metadata) {
        for (key, value) in b {
            match a.get(key) {
                Some(kept) => assert_eq!(kept, value, "{name}/{key}"),
                None => removed.push(format!("{name}/{key}")),
            }
        }
        assert!(a.keys().all(|k| b.contains_key(k)), "{name}: {a:?}");
    }
    removed.sort();
    assert_eq!(removed, keys);
    let files = |s: &SessionRead| {
        s.attachments
            .iter()
            .map(|a| (a.name.clone(), a.media_type.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(files(&after), files(&before));
    for (a, b) in after.attachments.iter().zip(&before.attachments) {
        assert!(
            a.name == "rig.toml" || a.data == b.data,
            "{} changed",
            a.name
        );
    }
    // The rig description is the same but for `[truth]`: the same model (canonical hash).
    let (cfg_before, cfg_after) = (rig_config(&before), rig_config(&after));
    assert_eq!(cfg_after.canonical_hash(), cfg_before.canonical_hash());
    assert_ne!(cfg_before.truth, TruthSpec::default());
    let expected = RigConfig {
        truth: TruthSpec::default(),
        ..cfg_before
    };
    assert_eq!(cfg_after, expected);

    // Replay: the same summary and recording.
    let (r0, r1) = (replay(&original).unwrap(), replay(&stripped).unwrap());
    assert_eq!(r0.summary.steps().count(), 2);
    assert!(r1.complete && r1.matches_logged());
    assert_eq!(
        serde_json::to_string(&r1.summary).unwrap(),
        serde_json::to_string(&r0.summary).unwrap()
    );
    let (a, b) = (&r1.recording, &r0.recording);
    assert!(!b.blocks.is_empty() && !b.twin_states.is_empty());
    assert!(a.blocks == b.blocks, "recording blocks differ");
    assert!(a == b, "recording counts differ");
    assert_eq!(a.layout, b.layout);
    assert_eq!(a.events, b.events);
    assert_eq!(a.gaps, b.gaps);
    assert_eq!(a.twin_states, b.twin_states);

    // The official Python reader reads the copy and finds no trace either.
    let Some(python) = mcap_python_or_skip("python_reader_finds_no_trace") else {
        return;
    };
    let out = Command::new(&python)
        .args(["-c", PY_READ])
        .arg(&stripped)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let py: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(py["messages"], before.messages.len());
    let metadata: BTreeMap<String, BTreeMap<String, String>> =
        serde_json::from_value(py["metadata"].clone()).unwrap();
    assert_eq!(metadata.len(), before.metadata.len(), "{py:#}");
    for (name, entries) in &metadata {
        for (key, value) in entries {
            let entry = format!("{name}/{key} = {value}");
            assert!(!has_truth(&entry), "Python reader: {entry}");
        }
    }
    let attachments: BTreeMap<String, String> =
        serde_json::from_value(py["attachments"].clone()).unwrap();
    assert!(attachments["rig.toml"].contains("[rig]"), "{py:#}");
    for (name, data) in &attachments {
        assert!(
            !has_truth(name) && !has_truth(data),
            "Python reader: attachment {name}"
        );
    }
}

/// A one-channel rigtwin log at `path` with the default rig hiding `HIDDEN` attached.
fn small_log(dir: &Path, path: &Path) {
    #[derive(serde::Serialize, schemars::JsonSchema)]
    struct Tick {
        i: u64,
    }
    let rig = std::fs::read(default_rig_with(dir, HIDDEN)).unwrap();
    let session = BTreeMap::from([("truth_variants".to_string(), "{}".to_string())]);
    let (log, join) = SessionLog::create(
        path,
        LogOptions::default(),
        vec![("session".to_string(), session)],
        vec![Attachment {
            name: "rig.toml".into(),
            media_type: "application/toml".into(),
            data: rig,
        }],
    )
    .unwrap();
    let ticks = log.channel::<Tick>("/tick").unwrap();
    for i in 0..200 {
        log.log(&ticks, i * 1_000_000, &Tick { i }).unwrap();
    }
    drop(log);
    join.close().unwrap();
}

#[test]
fn a_truncated_or_foreign_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.mcap");
    small_log(dir.path(), &whole);
    let out = dir.path().join("out.mcap");
    let report = strip_hidden_physics(&whole, &out).unwrap();
    assert_eq!(report.metadata_keys, ["session/truth_variants"]);
    std::fs::remove_file(&out).unwrap();

    let bytes = std::fs::read(&whole).unwrap();
    let mut bad = Vec::new();
    for cut in [0, 5, 100, bytes.len() / 2, bytes.len() - 1] {
        let p = dir.path().join(format!("cut-{cut}.mcap"));
        std::fs::write(&p, &bytes[..cut]).unwrap();
        bad.push(p);
    }
    // The rig description `small_log` wrote: TOML, not MCAP.
    bad.push(dir.path().join("rig.toml"));
    let foreign = dir.path().join("foreign.mcap");
    mcap::Writer::new(std::fs::File::create(&foreign).unwrap())
        .unwrap()
        .finish()
        .unwrap();
    bad.push(foreign);
    bad.push(dir.path().join("missing.mcap"));

    for p in &bad {
        let err = strip_hidden_physics(p, &out).expect_err(&p.display().to_string());
        let message = format!("{err:#}");
        assert!(message.contains(&p.display().to_string()), "{message}");
        assert!(!out.exists(), "{message}: {} was written", out.display());
    }
}
