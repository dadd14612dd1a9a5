//! Helpers of the live-view tests: the URL a `run --foxglove` prints, and the check of served
//! schemas and payloads with Python's `jsonschema` (`check_jsonschema.py`). Test crates that use
//! it also declare `mod log_support;`.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Command;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Waits for the line with the live view's URL on the child's stdout; returns the URL and the
/// channel of the following lines.
pub fn wait_for_url(child: &mut std::process::Child) -> (String, mpsc::Receiver<String>) {
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let end = Instant::now() + Duration::from_secs(600);
    loop {
        let line = rx
            .recv_timeout(end.saturating_duration_since(Instant::now()))
            .expect("the command printed no live-view URL");
        if let Some(i) = line.find("connect to ws://") {
            let url = line[i + "connect to ".len()..]
                .split_whitespace()
                .next()
                .unwrap()
                .to_string();
            return (url, rx);
        }
    }
}

/// Validates every topic's advertised schema (JSON text) and its received payloads with
/// Python's `jsonschema` (skipped when it is not installed, unless
/// RIGTWIN_REQUIRE_JSONSCHEMA_PY is set). `topics`: topic -> (schema, payloads).
pub fn check_with_jsonschema(
    dir: &Path,
    topics: &BTreeMap<String, (String, Vec<serde_json::Value>)>,
) {
    let python = super::log_support::python();
    let available = Command::new(&python)
        .args(["-c", "import jsonschema"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !available {
        if std::env::var_os("RIGTWIN_REQUIRE_JSONSCHEMA_PY").is_some() {
            panic!("RIGTWIN_REQUIRE_JSONSCHEMA_PY is set but `{python}` cannot import jsonschema");
        }
        eprintln!("SKIPPED the jsonschema check: `{python} -m pip install jsonschema` to run it");
        return;
    }
    let mut input = serde_json::Map::new();
    for (topic, (schema, messages)) in topics {
        input.insert(
            topic.clone(),
            serde_json::json!({"schema": schema, "messages": messages}),
        );
    }
    let path = dir.join("live.json");
    std::fs::write(&path, serde_json::Value::Object(input).to_string()).unwrap();
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/live_support/check_jsonschema.py");
    let o = Command::new(&python)
        .arg(script)
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for (topic, r) in report.as_object().unwrap() {
        assert!(
            r["schema_error"].is_null(),
            "{topic}: {}",
            r["schema_error"]
        );
        assert!(
            r["invalid"].as_array().unwrap().is_empty(),
            "{topic}: {}",
            r["invalid"]
        );
        assert!(r["checked"].as_u64().unwrap() > 0, "{topic}");
    }
}
