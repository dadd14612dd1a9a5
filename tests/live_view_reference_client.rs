//! The live view seen by the Foxglove WebSocket protocol's reference client, `FoxgloveClient`
//! of the npm package `@foxglove/ws-protocol` under node (the client the open-source viewers
//! are built on), during `rigtwin run --twin --foxglove` on the simulated rig. Guards:
//! - the published subprotocol `foxglove.websocket.v1` is accepted (not HTTP 400);
//! - every topic is advertised with the schema the live view declares for the session's DAQ
//!   layout ([`rigtwin::session::live::topic_schemas`], what the shipped Foxglove layout is
//!   checked against), and the client, subscribed to every topic, receives messages on each;
//! - every payload is valid against its advertised schema (Python's `jsonschema`);
//! - the connection is closed by the server when the session ends.
//!
//! Needs node and `tests/live_support/node/node_modules` (`npm install` there, as `.ci/run`
//! does); skipped without them unless RIGTWIN_REQUIRE_NODE is set.

mod cli_support;
mod live_support;
mod log_support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use cli_support::rigtwin_command as rigtwin;
use live_support::wait_for_url;
use rigtwin::config::RigConfig;
use rigtwin::rig::channels::layout;
use rigtwin::session::live::{topic_schemas, LiveOptions, PUBLISHED_SUBPROTOCOL};

/// One step at omega_2 at the high level (impacts, so the contact channels move).
const PLAN: &str = r#"
name = "reference-client"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 1
settle_periods = 60
record_periods = 30
steps_per_period = 1000

[[test]]
name = "dwell"
direction = "down"
omega_start = 1.0
omega_end = 1.0
"#;

/// The reference client's folder, when node and the client are installed; `None` (skip)
/// otherwise, unless RIGTWIN_REQUIRE_NODE is set, when it panics.
fn reference_client() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/live_support/node");
    let node = Command::new("node").arg("--version").output();
    let why = match node {
        Ok(o) if o.status.success() => {
            if dir.join("node_modules/@foxglove/ws-protocol").is_dir()
                && dir.join("node_modules/ws").is_dir()
            {
                return Some(dir);
            }
            format!(
                "the reference client is not installed: `npm install` in {}",
                dir.display()
            )
        }
        _ => "node is not installed".to_string(),
    };
    if std::env::var_os("RIGTWIN_REQUIRE_NODE").is_some() {
        panic!("RIGTWIN_REQUIRE_NODE is set but {why}");
    }
    eprintln!("SKIPPED: {why}");
    None
}

#[test]
fn the_reference_client_receives_every_topic_over_the_published_subprotocol() {
    let Some(client_dir) = reference_client() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let mut child = rigtwin()
        .args(["run", "--plan", plan.to_str().unwrap(), "--quiet", "--twin"])
        .arg("--out")
        .arg(dir.path().join("session.mcap"))
        .args(["--foxglove", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (url, lines) = wait_for_url(&mut child);
    let seen_path = dir.path().join("seen.json");
    let node = Command::new("node")
        .current_dir(&client_dir)
        .arg("reference_client.mjs")
        .arg(&url)
        .arg(&seen_path)
        .arg("900")
        .output()
        .unwrap();
    let output = child.wait_with_output().unwrap();
    let rest: Vec<String> = lines.try_iter().collect();
    let out = format!(
        "{}\n{}\nnode: {}{}",
        rest.join("\n"),
        String::from_utf8_lossy(&output.stderr),
        String::from_utf8_lossy(&node.stdout),
        String::from_utf8_lossy(&node.stderr)
    );
    assert!(output.status.success(), "{out}");
    assert!(node.status.success(), "{out}");
    let seen: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&seen_path).unwrap()).unwrap();

    assert_eq!(seen["subprotocol"], PUBLISHED_SUBPROTOCOL, "{out}");
    assert_eq!(seen["errors"], serde_json::json!([]), "{out}");
    assert_eq!(seen["closed"], true);
    assert!(seen["serverInfo"]["name"]
        .as_str()
        .unwrap()
        .starts_with("rigtwin"));

    // Every topic the live view declares, advertised with its declared schema.
    let declared = topic_schemas(
        &layout(&RigConfig::default_rig().daq),
        &LiveOptions::default(),
    );
    let channels = seen["channels"].as_object().unwrap();
    let advertised: BTreeSet<&str> = channels.keys().map(String::as_str).collect();
    let expected: BTreeSet<&str> = declared.iter().map(|t| t.topic).collect();
    assert_eq!(advertised, expected, "advertised topics");
    let mut topics = BTreeMap::new();
    for t in &declared {
        let c = &channels[t.topic];
        assert_eq!(c["encoding"], "json", "{}", t.topic);
        assert_eq!(c["schemaEncoding"], "jsonschema", "{}", t.topic);
        assert_eq!(c["schemaName"], t.schema_name.as_str(), "{}", t.topic);
        let schema = c["schema"].as_str().unwrap();
        assert_eq!(
            schema.as_bytes(),
            t.schema.as_slice(),
            "{}: the advertised schema is the declared one",
            t.topic
        );
        let payloads: Vec<serde_json::Value> = seen["messages"][t.topic]
            .as_array()
            .unwrap_or_else(|| panic!("nothing received on {}", t.topic))
            .iter()
            .map(|m| m["payload"].clone())
            .collect();
        assert!(!payloads.is_empty(), "nothing received on {}", t.topic);
        topics.insert(t.topic.to_string(), (schema.to_string(), payloads));
    }
    println!(
        "reference client: {} topics, {} messages",
        topics.len(),
        topics.values().map(|t| t.1.len()).sum::<usize>()
    );
    live_support::check_with_jsonschema(dir.path(), &topics);
}
