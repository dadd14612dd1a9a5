//! `rigtwin run --foxglove ADDR`, the live view, seen by a Foxglove WebSocket client during a
//! short session on the simulated rig. Guards:
//! - a bare port binds 127.0.0.1 and the command prints where to connect;
//! - the server speaks the Foxglove WebSocket protocol: `serverInfo`, then `advertise` of the MCAP
//!   log's topics with the same schemas as the log (JSON Schemas, checked with Python's
//!   `jsonschema` when installed) and `/live/daq`, not the raw blocks;
//! - a subscribed client gets binary `messageData` frames whose JSON payloads are the session's
//!   records (control state, events, steps, the latched layout) with log time = rig time;
//! - `/live/daq` holds min/max/mean per channel in physical units, equal to the raw counts of the
//!   MCAP log times the channel scale, at about 200 points per rig second (10,240 Hz sampled);
//! - the server sends what is queued, then stops when the session ends (the connection closes,
//!   the command succeeds);
//! - with `--twin`, the twin's status and step comparisons are served with the log's schemas,
//!   and `/live/twin` holds its predicted channels decimated in `/live/daq`'s bins, equal to the
//!   logged `/twin/blocks`;
//! - a malformed or busy `--foxglove` address fails at once with an error naming the flag.

mod cli_support;
mod live_support;
mod log_support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::Message;

use cli_support::{rigtwin_command as rigtwin, text};
use live_support::wait_for_url;
use rigtwin::control::ControlState;
use rigtwin::log::read_session;
use rigtwin::rig::{DaqBlock, DaqLayout};

/// Two steps through the impact band at the high level (as in `rig_session_sim.rs`, shorter).
const PLAN: &str = r#"
name = "live-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 2
settle_periods = 60
record_periods = 30
steps_per_period = 1000

[[test]]
name = "high-down"
direction = "down"
omega_start = 1.01
omega_end = 0.99
"#;

/// The topics the live view serves.
const TOPICS: [&str; 6] = [
    "/daq/layout",
    "/control/state",
    "/session/events",
    "/rig/status",
    "/session/steps",
    "/live/daq",
];

/// The Foxglove WebSocket subprotocol the SDK's server (foxglove 0.30) speaks.
const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// An advertised channel.
#[derive(Clone, Debug)]
struct Advertised {
    id: u64,
    topic: String,
    encoding: String,
    schema_name: String,
    schema_encoding: String,
    schema: String,
}

/// What the client saw.
#[derive(Debug, Default)]
struct Seen {
    server_info: Option<serde_json::Value>,
    /// Text ops in arrival order.
    ops: Vec<String>,
    channels: BTreeMap<String, Advertised>,
    /// Per topic: (log time ns, payload, wall time of arrival).
    messages: BTreeMap<String, Vec<(u64, serde_json::Value, Instant)>>,
    closed_by_server: bool,
    negotiated: Option<String>,
}

/// Connects to `url`, subscribes to every topic of `topics` as it is advertised, and reads
/// until the server closes the connection (or `deadline`).
async fn watch(url: &str, deadline: Duration, topics: &[&str]) -> Seen {
    let mut request = url.into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", SUBPROTOCOL.parse().unwrap());
    let (mut ws, response) = tokio_tungstenite::connect_async(request)
        .await
        .expect("connect to the live view");
    let mut seen = Seen {
        negotiated: response
            .headers()
            .get("Sec-WebSocket-Protocol")
            .map(|v| v.to_str().unwrap().to_string()),
        ..Seen::default()
    };
    let mut subscriptions: BTreeMap<u32, String> = BTreeMap::new();
    let end = tokio::time::Instant::now() + deadline;
    loop {
        let next = match tokio::time::timeout_at(end, ws.next()).await {
            Err(_) => panic!("the server did not close the connection within {deadline:?}"),
            Ok(None) => break,
            Ok(Some(m)) => m,
        };
        let msg = match next {
            Ok(m) => m,
            // The server may drop the TCP connection right after its close frame.
            Err(_) => break,
        };
        match msg {
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                let op = v["op"].as_str().unwrap_or("?").to_string();
                seen.ops.push(op.clone());
                match op.as_str() {
                    "serverInfo" => seen.server_info = Some(v),
                    "advertise" => {
                        let mut subscribe = Vec::new();
                        for c in v["channels"].as_array().unwrap() {
                            let a = Advertised {
                                id: c["id"].as_u64().unwrap(),
                                topic: c["topic"].as_str().unwrap().to_string(),
                                encoding: c["encoding"].as_str().unwrap().to_string(),
                                schema_name: c["schemaName"].as_str().unwrap().to_string(),
                                schema_encoding: c["schemaEncoding"]
                                    .as_str()
                                    .unwrap_or("")
                                    .to_string(),
                                schema: c["schema"].as_str().unwrap().to_string(),
                            };
                            if topics.contains(&a.topic.as_str()) {
                                let sub = subscriptions.len() as u32 + 1;
                                subscriptions.insert(sub, a.topic.clone());
                                subscribe.push(serde_json::json!({"id": sub, "channelId": a.id}));
                            }
                            seen.channels.insert(a.topic.clone(), a);
                        }
                        if !subscribe.is_empty() {
                            let m =
                                serde_json::json!({"op": "subscribe", "subscriptions": subscribe});
                            ws.send(Message::text(m.to_string())).await.unwrap();
                        }
                    }
                    _ => {}
                }
            }
            Message::Binary(b) => {
                // messageData: opcode 0x01, subscription id (u32 LE), log time (u64 LE, ns),
                // payload.
                assert!(b.len() >= 13, "short binary frame ({} bytes)", b.len());
                assert_eq!(b[0], 0x01, "binary opcode");
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let log_time = u64::from_le_bytes(b[5..13].try_into().unwrap());
                let topic = subscriptions
                    .get(&sub)
                    .unwrap_or_else(|| panic!("data for unknown subscription {sub}"));
                let payload: serde_json::Value = serde_json::from_slice(&b[13..])
                    .unwrap_or_else(|e| panic!("{topic}: payload is not JSON: {e}"));
                seen.messages.entry(topic.clone()).or_default().push((
                    log_time,
                    payload,
                    Instant::now(),
                ));
            }
            Message::Close(_) => {
                seen.closed_by_server = true;
                break;
            }
            _ => {}
        }
    }
    seen
}

fn ns(t: f64) -> u64 {
    (t * 1e9).round() as u64
}

#[test]
fn a_foxglove_client_sees_the_session_live_decimated_and_the_server_stops_at_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let mcap = dir.path().join("session.mcap");
    let summary = dir.path().join("summary.json");
    let mut child = rigtwin()
        .args(["run", "--plan", plan.to_str().unwrap(), "--quiet", "--out"])
        .arg(&mcap)
        .arg("--json")
        .arg(&summary)
        // A bare port: binds 127.0.0.1; 0 picks a free port.
        .args(["--foxglove", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (url, lines) = wait_for_url(&mut child);
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");
    assert!(!url.ends_with(":0"), "{url}: the chosen port is printed");

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let t_connect = Instant::now();
    let seen = runtime.block_on(watch(&url, Duration::from_secs(900), &TOPICS));
    let output = child.wait_with_output().unwrap();
    let rest: Vec<String> = lines.try_iter().collect();
    let out = format!(
        "{}\n{}",
        rest.join("\n"),
        String::from_utf8_lossy(&output.stderr)
    );
    println!("{out}");
    assert!(output.status.success(), "{out}");
    assert!(
        rest.iter().any(|l| l.starts_with("live view: stopped")),
        "{out}"
    );

    // The protocol.
    assert_eq!(seen.negotiated.as_deref(), Some(SUBPROTOCOL));
    assert_eq!(seen.ops.first().map(String::as_str), Some("serverInfo"));
    let info = seen.server_info.as_ref().unwrap();
    assert!(
        info["name"].as_str().unwrap().starts_with("rigtwin"),
        "{info}"
    );
    assert!(seen.closed_by_server, "the server closes the connection");
    let topics: BTreeSet<&str> = seen.channels.keys().map(String::as_str).collect();
    assert_eq!(
        topics,
        TOPICS.iter().copied().collect(),
        "advertised topics"
    );

    // Same names and schemas as the MCAP log, JSON over JSON Schema.
    let log = read_session(&mcap).unwrap();
    assert!(log.complete);
    for (topic, a) in &seen.channels {
        assert_eq!(a.encoding, "json", "{topic}");
        assert_eq!(a.schema_encoding, "jsonschema", "{topic}");
        let schema: serde_json::Value = serde_json::from_str(&a.schema)
            .unwrap_or_else(|e| panic!("{topic}: schema is not JSON: {e}"));
        assert!(
            schema.is_object() && schema["properties"].is_object(),
            "{topic}"
        );
        if topic != "/live/daq" {
            let logged = log.channel(topic).unwrap().schema.clone().unwrap();
            assert_eq!(a.schema_name, logged.name, "{topic}");
            assert_eq!(a.schema.as_bytes(), logged.data.as_slice(), "{topic}");
        }
    }
    assert_eq!(seen.channels["/live/daq"].schema_name, "LiveDaqPoint");
    assert!(
        log.channel("/live/daq").is_none(),
        "the live topic is not logged"
    );

    // Every subscribed topic delivered, log time = rig time.
    let got = |t: &str| seen.messages.get(t).map_or(&[][..], Vec::as_slice);
    for t in TOPICS {
        assert!(!got(t).is_empty(), "nothing received on {t}");
    }
    let layout: DaqLayout = serde_json::from_value(got("/daq/layout")[0].1.clone()).unwrap();
    assert_eq!(got("/daq/layout")[0].0, 0);
    for (t, v, _) in got("/control/state") {
        let c: ControlState = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(*t, ns(c.time));
    }
    let events: Vec<&str> = got("/session/events")
        .iter()
        .map(|(_, v, _)| v["event"].as_str().unwrap())
        .collect();
    assert_eq!(events.first(), Some(&"session_start"), "{events:?}");
    assert_eq!(
        events.last(),
        Some(&"session_end"),
        "{events:?}: queued records go out before the stop"
    );
    assert_eq!(got("/session/steps").len(), 2);
    for (_, v, _) in got("/session/steps") {
        assert!(v["summary"]["omega_ratio"].is_f64(), "{v}");
    }

    // The decimated DAQ.
    let points = got("/live/daq");
    let bin = (layout.sample_rate / 200.0).round() as u64;
    let blocks: Vec<DaqBlock> = log
        .decode::<DaqBlock>("/daq/blocks")
        .unwrap()
        .into_iter()
        .map(|x| x.2)
        .collect();
    let samples_logged: u64 = blocks.iter().map(|b| b.len as u64).sum();
    let counts = |k: usize, s: u64| -> i32 {
        let b = &blocks[(s / layout.block_size as u64) as usize];
        assert_eq!(b.first_sample, s - s % layout.block_size as u64);
        b.channel(k)[(s - b.first_sample) as usize]
    };
    let mut previous: Option<u64> = None;
    for (t, p, _) in points {
        let first = p["first_sample"].as_u64().unwrap();
        let n = p["samples"].as_u64().unwrap();
        assert_eq!(*t, ns(p["time"].as_f64().unwrap()), "{p}");
        assert_eq!(
            p["time"].as_f64().unwrap(),
            first as f64 / layout.sample_rate
        );
        assert_eq!(first % bin, 0, "bins aligned to the sample index: {p}");
        if let Some(prev) = previous {
            assert_eq!(first, prev + bin, "consecutive bins: {p}");
        }
        previous = Some(first);
        assert!(n == bin || first + n == samples_logged, "{p}");
        for (k, ch) in layout.channels.iter().enumerate() {
            let v = &p[ch.name.as_str()];
            let (lo, hi, mean) = (
                v["min"].as_f64().unwrap(),
                v["max"].as_f64().unwrap(),
                v["mean"].as_f64().unwrap(),
            );
            assert!(lo <= mean && mean <= hi, "{}: {v}", ch.name);
            // Physical units: the raw counts of the log times the scale.
            let raw: Vec<i32> = (first..first + n).map(|s| counts(k, s)).collect();
            assert_eq!(
                lo,
                f64::from(*raw.iter().min().unwrap()) * ch.scale,
                "{}",
                ch.name
            );
            assert_eq!(
                hi,
                f64::from(*raw.iter().max().unwrap()) * ch.scale,
                "{}",
                ch.name
            );
        }
    }
    let (t0, t1) = (
        points[0].1["time"].as_f64().unwrap(),
        points.last().unwrap().1["time"].as_f64().unwrap(),
    );
    let rate = (points.len() - 1) as f64 / (t1 - t0);
    let wall = points.last().unwrap().2 - points[0].2;
    let wall_rate = points.len() as f64 / wall.as_secs_f64();
    let all: usize = seen.messages.values().map(Vec::len).sum();
    println!(
        "live view: {} points over {:.2} s of rig time = {rate:.1} per rig second \
         (sampling {} Hz); {} messages in all; {wall_rate:.0} points per wall second \
         ({:.1} s after connecting)",
        points.len(),
        t1 - t0,
        layout.sample_rate,
        all,
        t_connect.elapsed().as_secs_f64()
    );
    assert!(
        (rate - layout.sample_rate / bin as f64).abs() < 1e-6 * rate,
        "{rate} points per rig second"
    );
    assert!(rate < layout.sample_rate / 40.0, "decimated: {rate}");
    assert!(
        points.len() as f64 > 0.5 * samples_logged as f64 / bin as f64,
        "{} points for {samples_logged} samples: most of the session is seen",
        points.len()
    );

    // The oracle: Python's jsonschema checks every schema and validates every payload.
    check_with_jsonschema(dir.path(), &seen);
}

#[test]
fn a_foxglove_client_sees_the_live_twin_beside_the_measurement() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    // One step at omega_2 (a dwell), in the impact band.
    let one_step = PLAN
        .replace("steps = 2", "steps = 1")
        .replace("omega_start = 1.01", "omega_start = 1.0")
        .replace("omega_end = 0.99", "omega_end = 1.0");
    std::fs::write(&plan, one_step).unwrap();
    let mcap = dir.path().join("session.mcap");
    let mut child = rigtwin()
        .args(["run", "--plan", plan.to_str().unwrap(), "--quiet", "--twin"])
        .arg("--out")
        .arg(&mcap)
        .args(["--foxglove", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (url, lines) = wait_for_url(&mut child);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let twin_topics = ["/twin/status", "/twin/steps", "/live/twin"];
    let wanted: Vec<&str> = TOPICS.iter().chain(&twin_topics).copied().collect();
    let seen = runtime.block_on(watch(&url, Duration::from_secs(900), &wanted));
    let output = child.wait_with_output().unwrap();
    let rest: Vec<String> = lines.try_iter().collect();
    let out = format!(
        "{}\n{}",
        rest.join("\n"),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(output.status.success(), "{out}");

    let log = read_session(&mcap).unwrap();
    for topic in ["/twin/status", "/twin/steps"] {
        let a = &seen.channels[topic];
        let logged = log.channel(topic).unwrap().schema.clone().unwrap();
        assert_eq!(a.schema_name, logged.name, "{topic}");
        assert_eq!(a.schema.as_bytes(), logged.data.as_slice(), "{topic}");
    }
    assert_eq!(seen.channels["/live/twin"].schema_name, "LiveTwinPoint");
    let got = |t: &str| seen.messages.get(t).map_or(&[][..], Vec::as_slice);
    assert_eq!(got("/twin/steps").len(), 1, "{out}");
    assert!(got("/twin/steps")[0].1["twin"]["rms_error_upper"].is_f64());
    assert!(!got("/twin/status").is_empty());

    // /live/twin: the logged predictions (single precision) decimated in /live/daq's bins.
    let layout: DaqLayout = serde_json::from_value(got("/daq/layout")[0].1.clone()).unwrap();
    let bin = (layout.sample_rate / 200.0).round() as u64;
    let blocks: Vec<rigtwin::twin::TwinSamples> = log
        .decode::<rigtwin::twin::TwinSamples>(rigtwin::session::topics::TOPIC_TWIN_BLOCKS)
        .unwrap()
        .into_iter()
        .map(|x| x.2)
        .collect();
    let upper = |s: u64| -> f64 {
        let b = &blocks[(s / layout.block_size as u64) as usize];
        assert_eq!(b.first_sample, s - s % layout.block_size as u64);
        f64::from(b.upper_tip[(s - b.first_sample) as usize])
    };
    let daq_bins: BTreeSet<u64> = got("/live/daq")
        .iter()
        .map(|(_, p, _)| p["first_sample"].as_u64().unwrap())
        .collect();
    let points = got("/live/twin");
    assert!(points.len() > 100, "{} twin points", points.len());
    let mut contact_seen = false;
    for (t, p, _) in points {
        let first = p["first_sample"].as_u64().unwrap();
        let n = p["samples"].as_u64().unwrap();
        assert_eq!(*t, ns(p["time"].as_f64().unwrap()), "{p}");
        assert_eq!(first % bin, 0, "{p}");
        let raw: Vec<f64> = (first..first + n).map(upper).collect();
        let lo = raw.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = raw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (plo, phi) = (
            p["upper_tip"]["min"].as_f64().unwrap(),
            p["upper_tip"]["max"].as_f64().unwrap(),
        );
        // The view decimates the twin's f64 output, the log holds it in f32.
        let tol = 1e-6 * hi.abs().max(lo.abs()).max(1e-9);
        assert!(
            (plo - lo).abs() <= tol && (phi - hi).abs() <= tol,
            "{p} vs {lo} {hi}"
        );
        let c = p["contact"]["mean"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&c), "{p}");
        contact_seen |= c > 0.0;
    }
    assert!(
        contact_seen,
        "the twin predicts impacts at omega_2 in this plan"
    );
    // Same bins as /live/daq (each topic's first points may predate the subscription: the
    // session starts as the URL is printed, and the twin lags the DAQ).
    let shared = points
        .iter()
        .filter(|(_, p, _)| daq_bins.contains(&p["first_sample"].as_u64().unwrap()))
        .count();
    assert!(
        shared > points.len() / 2,
        "{shared} of {} twin bins are /live/daq bins",
        points.len()
    );
    check_with_jsonschema(dir.path(), &seen);
}

/// Validates the advertised schemas and the received payloads with Python's `jsonschema`
/// (skipped when it is not installed, unless RIGTWIN_REQUIRE_JSONSCHEMA_PY is set).
fn check_with_jsonschema(dir: &Path, seen: &Seen) {
    let topics = seen
        .channels
        .iter()
        .map(|(topic, a)| {
            let messages: Vec<serde_json::Value> = seen
                .messages
                .get(topic)
                .map(|m| m.iter().map(|x| x.1.clone()).collect())
                .unwrap_or_default();
            (topic.clone(), (a.schema.clone(), messages))
        })
        .collect();
    live_support::check_with_jsonschema(dir, &topics);
}

#[test]
fn a_bad_or_busy_foxglove_address_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let mcap = dir.path().join("x.mcap");
    let run = |addr: &str| {
        rigtwin()
            .args(["run", "--plan", plan.to_str().unwrap(), "--quiet", "--out"])
            .arg(&mcap)
            .args(["--foxglove", addr])
            .output()
            .unwrap()
    };
    for bad in ["localhost", "127.0.0.1:99999", "example.org:8765"] {
        let o = run(bad);
        assert!(!o.status.success(), "{bad}");
        let t = text(&o);
        assert!(t.contains("--foxglove") && t.contains(bad), "{t}");
        assert!(t.contains("expected PORT"), "{t}");
    }
    // A port in use: fails before anything else happens (no ROM, no log file).
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = busy.local_addr().unwrap().to_string();
    let t0 = Instant::now();
    let o = run(&addr);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains(&format!("--foxglove {addr}")), "{t}");
    assert!(
        t.contains("cannot listen on") && t.contains("choose another port"),
        "{t}"
    );
    assert!(!t.contains("panicked"), "{t}");
    assert!(
        !mcap.exists(),
        "no session log for a session that did not start"
    );
    println!(
        "busy port: failed in {:.2} s: {t}",
        t0.elapsed().as_secs_f64()
    );
}
