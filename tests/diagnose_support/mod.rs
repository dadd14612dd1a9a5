//! Shared by the `rigtwin diagnose` proofs, which run on logs of the simulated rig from which
//! every trace of its hidden physics was stripped: [`strip_hidden_physics`] writes that copy.
//!
//! The traces a log of `rigtwin run --backend sim` carries (src/cli/run.rs,
//! src/session/run.rs):
//! - the `rig.toml` attachment: its `[truth]` table and sub-tables (the truth ROM, and in
//!   `[truth.variants]` the hidden physics), and its comments, which document `[truth]`;
//! - the `session` metadata record's `truth_variants` (the hidden physics, as JSON);
//! - the `rom` metadata record's `truth_config_hash` and `truth_modes` (the truth ROM).
//!
//! Metadata entries go by key: every key holding "truth" (any case), so that one added later
//! goes too. Everything else is copied as the library's reader reads it: the channels' schemas,
//! the channels (same ids, encodings and metadata), the messages (same channel, sequence, log
//! and publish times, payload, in file order), the other metadata entries and attachments
//! (attachment times are 0, as rigtwin writes them).

#![allow(dead_code)]

use std::path::Path;

use anyhow::{bail, Context};
use rigtwin::config::RigConfig;
use rigtwin::log::{read_session, write_atomically, SessionRead};

/// A folder `name` for what the tests of one test binary share (a session recorded once per
/// process), in cargo's folder for integration tests' files, made afresh by each process:
/// `cargo test` runs a binary's tests in one, `cargo nextest` each in its own.
pub fn process_dir(name: &str) -> std::path::PathBuf {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The plan file `name` of the repository's `rig-config/plans/`.
pub fn repo_plan(name: &str) -> String {
    std::fs::read_to_string(format!(
        "{}/rig-config/plans/{name}",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

/// The rig description attachment.
const RIG_ATTACHMENT: &str = "rig.toml";

/// The rig description's table of the simulated rig's truth model.
const TRUTH_TABLE: &str = "truth";

/// What [`strip_hidden_physics`] removed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StripReport {
    /// The tables removed from the `rig.toml` attachment, dotted (`truth`, `truth.variants`,
    /// `truth.variants.wear`, ...); empty when it had no `[truth]` table. The attachment is
    /// re-serialised either way, without its comments.
    pub rig_toml_tables: Vec<String>,
    /// The metadata entries removed, as `record/key` (`session/truth_variants`, ...).
    pub metadata_keys: Vec<String>,
}

/// Writes the session log `src` to `dst` without the traces of the hidden physics (see the
/// module documentation) and says what it removed. `src` must be a complete, undamaged rigtwin
/// session log; `dst` is written through a temporary file (it may be `src`).
pub fn strip_hidden_physics(src: &Path, dst: &Path) -> anyhow::Result<StripReport> {
    let session = read_session(src)?;
    session.require_rigtwin()?;
    if !session.complete || !session.damage.is_empty() {
        let what: Vec<&str> = session
            .note
            .iter()
            .chain(&session.damage)
            .map(String::as_str)
            .collect();
        bail!(
            "session log {}: incomplete or damaged ({}); only a whole log can be stripped",
            src.display(),
            what.join("; ")
        );
    }
    let mut report = StripReport::default();
    let bytes = write_stripped(&session, &mut report)
        .with_context(|| format!("stripping session log {}", src.display()))?;
    write_atomically(dst, &bytes).with_context(|| format!("writing {}", dst.display()))?;
    Ok(report)
}

/// The stripped copy of `session` as MCAP bytes; what was removed goes into `report`.
fn write_stripped(session: &SessionRead, report: &mut StripReport) -> anyhow::Result<Vec<u8>> {
    let mut w = mcap::WriteOptions::new()
        .profile(session.profile.as_str())
        .library(session.library.as_str())
        .create(std::io::Cursor::new(Vec::new()))?;
    for (name, entries) in &session.metadata {
        let mut metadata = entries.clone();
        metadata.retain(|key, _| {
            let hidden = key.to_ascii_lowercase().contains(TRUTH_TABLE);
            if hidden {
                report.metadata_keys.push(format!("{name}/{key}"));
            }
            !hidden
        });
        let name = name.clone();
        w.write_metadata(&mcap::records::Metadata { name, metadata })?;
    }
    for a in &session.attachments {
        let data = if a.name == RIG_ATTACHMENT {
            let text = std::str::from_utf8(&a.data).context("rig.toml is not UTF-8")?;
            let (stripped, tables) = without_truth(text)?;
            report.rig_toml_tables = tables;
            stripped.into_bytes()
        } else {
            a.data.clone()
        };
        w.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: a.name.clone(),
            media_type: a.media_type.clone(),
            data: data.into(),
        })?;
    }
    for c in &session.channels {
        let schema_id = match &c.schema {
            Some(s) => w.add_schema(&s.name, &s.encoding, &s.data)?,
            None => 0,
        };
        w.add_channel_with_id(c.id, schema_id, &c.topic, &c.message_encoding, &c.metadata)?;
    }
    for m in &session.messages {
        let header = mcap::records::MessageHeader {
            channel_id: m.channel_id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &m.data)?;
    }
    w.finish()?;
    Ok(w.into_inner().into_inner())
}

/// The rig description `text` without its `[truth]` table, and the dotted names of the tables
/// removed. Checked: the result is a valid rig description with the same model (canonical
/// hash) as `text`.
fn without_truth(text: &str) -> anyhow::Result<(String, Vec<String>)> {
    let before = RigConfig::from_str(text, RIG_ATTACHMENT)?;
    let mut table: toml::Table = toml::from_str(text)?;
    let mut tables = Vec::new();
    if let Some(truth) = table.remove(TRUTH_TABLE) {
        table_names(TRUTH_TABLE, &truth, &mut tables);
    }
    let stripped = toml::to_string(&table)?;
    let after = RigConfig::from_str(&stripped, "rig.toml (stripped)")?;
    if after.canonical_hash() != before.canonical_hash() {
        bail!("rig.toml without [truth] describes another model (canonical hash changed)");
    }
    Ok((stripped, tables))
}

/// Pushes `name` and the dotted names of the tables inside `value`, if it is a table.
fn table_names(name: &str, value: &toml::Value, out: &mut Vec<String>) {
    if let toml::Value::Table(t) = value {
        out.push(name.to_string());
        for (key, inner) in t {
            table_names(&format!("{name}.{key}"), inner, out);
        }
    }
}

/// Runs `plan` (plan TOML) on the simulated rig described by the default rig plus `extra`
/// (TOML appended: the hidden physics) in the folder `dir/name`; returns the session log and
/// its copy without the hidden physics ([`strip_hidden_physics`]).
pub fn sim_session(
    dir: &Path,
    name: &str,
    extra: &str,
    plan: &str,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let sub = dir.join(name);
    std::fs::create_dir_all(&sub).unwrap();
    let rig = crate::cli_support::default_rig_with(&sub, extra);
    let plan_path = sub.join("plan.toml");
    std::fs::write(&plan_path, plan).unwrap();
    let log = sub.join("session.mcap");
    let o = crate::cli_support::rigtwin(&[
        "run",
        rig.to_str().unwrap(),
        "--plan",
        plan_path.to_str().unwrap(),
        "--quiet",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", crate::cli_support::text(&o));
    let stripped = sub.join("stripped.mcap");
    strip_hidden_physics(&log, &stripped).unwrap();
    (log, stripped)
}

/// `rigtwin diagnose LOG --json dir/TAG.json --out dir/TAG --jobs 2 ARGS...`: asserts it
/// succeeds and shows its stages and verdict, each clearance fit once; returns the diagnosis.
pub fn diagnose(log: &Path, dir: &Path, tag: &str, args: &[&str]) -> serde_json::Value {
    let json = dir.join(format!("{tag}.json"));
    let out = dir.join(tag);
    let mut all = vec![
        "diagnose",
        log.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "2",
    ];
    all.extend(args);
    let o = crate::cli_support::rigtwin(&all);
    let t = crate::cli_support::text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("== locate") && t.contains("verdict:"), "{t}");
    // A clearance fit several stages share is shown once, where it was run.
    let fits: Vec<&str> = t
        .lines()
        .filter(|l| l.contains("by model runs (bracket"))
        .collect();
    for (k, l) in fits.iter().enumerate() {
        assert!(!fits[..k].contains(l), "shown twice: {l}\n{t}");
    }
    serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
}

/// The accepted effects of kind `effect` in diagnosis `d`.
pub fn accepted<'a>(d: &'a serde_json::Value, effect: &str) -> Vec<&'a serde_json::Value> {
    d["effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["effect"] == effect && e["accepted"] == true)
        .collect()
}

/// The validation error of diagnosis `d` with the comparison's spread: (the model as given,
/// the fixed model), or None where the band was not run with the spread for both.
pub fn validation_with_spread(d: &serde_json::Value) -> Option<(f64, f64)> {
    let v = &d["validation_with_spread"];
    Some((v["before"].as_f64()?, v["after"].as_f64()?))
}

/// Asserts the null verdict of diagnosis `d`: `no_significant_mismatch`, nothing accepted
/// (so no validation error with the spread either).
pub fn assert_null(d: &serde_json::Value) {
    assert_eq!(d["verdict"], "no_significant_mismatch", "{d:#}");
    assert!(d["validation_with_spread"].is_null(), "{d:#}");
    let accepted: Vec<&serde_json::Value> = d["effects"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["accepted"] == true)
        .collect();
    assert!(
        accepted.is_empty(),
        "accepted on a nominal session: {accepted:#?}"
    );
}

/// Asserts that the rig description `fixed` (written by `diagnose --write-config`), replayed
/// over `log` with the twin alone (`rigtwin replay LOG --twin --config FIXED --ensemble 0`,
/// its summary in `dir`), gives diagnosis `d`'s "after" comparison of every step.
pub fn assert_replay_gives_the_after_scores(
    log: &Path,
    fixed: &Path,
    dir: &Path,
    d: &serde_json::Value,
) {
    let replayed = dir.join(format!(
        "{}-replayed.json",
        fixed.file_stem().unwrap().to_str().unwrap()
    ));
    let o = crate::cli_support::rigtwin(&[
        "replay",
        log.to_str().unwrap(),
        "--twin",
        "--config",
        fixed.to_str().unwrap(),
        "--ensemble",
        "0",
        "--json",
        replayed.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", crate::cli_support::text(&o));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&replayed).unwrap()).unwrap();
    let replayed_steps: Vec<&serde_json::Value> = r["tests"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|t| t["steps"].as_array().unwrap())
        .collect();
    let after = d["scores_after"].as_array().unwrap();
    assert_eq!(after.len(), replayed_steps.len());
    for (a, s) in after.iter().zip(replayed_steps) {
        assert_eq!(a["features"], s["twin"]["features"]);
    }
}
