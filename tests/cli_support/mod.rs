//! Helpers shared by the tests that run the `rigtwin` binary on the default rig: the ROM
//! cache they share, running the binary, its output as text, JSON files, plan files.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The ROM cache shared by the default-rig tests (built once per target directory).
pub fn cache() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rom-cache")
}

/// The `rigtwin` binary with the shared ROM cache.
pub fn rigtwin_command() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rigtwin"));
    c.env("RIGTWIN_CACHE", cache());
    c
}

/// Runs `rigtwin args...` to completion.
pub fn rigtwin(args: &[&str]) -> Output {
    rigtwin_command().args(args).output().unwrap()
}

/// Stdout and stderr of a run, for assertion messages.
pub fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A JSON file.
pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Writes `text` as `dir/plan.toml`; returns its path.
pub fn write_plan(dir: &Path, text: &str) -> String {
    let p = dir.join("plan.toml");
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// The embedded default rig description with `extra` TOML appended, written to `dir/rig.toml`.
pub fn default_rig_with(dir: &Path, extra: &str) -> PathBuf {
    let mut t = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/rig-config/two-beam.toml"
    ))
    .unwrap();
    t.push('\n');
    t.push_str(extra);
    let p = dir.join("rig.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// Asserts that a step of a session summary (`tests[].steps[]`) held the fundamental base
/// displacement within `tolerance` (relative) of its target.
pub fn assert_base_amplitude_within(step: &serde_json::Value, tolerance: f64) {
    let (q, target) = (
        step["base_amp_measured"].as_f64().unwrap(),
        step["base_amp_target"].as_f64().unwrap(),
    );
    assert!(
        (q / target - 1.0).abs() <= tolerance,
        "base amplitude {q:e} vs target {target:e} ({:+.4} %) at {}",
        100.0 * (q / target - 1.0),
        step["omega_ratio"]
    );
}

/// Waits (up to 120 s) until the session log `path` written by `child` holds `bytes`: a few
/// flushes of DAQ data, so a kill lands mid-test. Fails if the session ends first.
pub fn wait_for_log_growth(child: &mut std::process::Child, path: &Path, bytes: u64) {
    let t0 = std::time::Instant::now();
    while std::fs::metadata(path).map_or(0, |m| m.len()) < bytes {
        assert!(
            t0.elapsed().as_secs() < 120,
            "the session log does not grow"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the session ended before the kill"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Compares `value` with the pinned output `tests/pinned/NAME` (JSON, compared as values: every
/// number bit for bit). `RIGTWIN_WRITE_PINS=1` rewrites the file instead: only for a change
/// meant to change the numbers, said so in its commit. On a difference the new output is
/// written to the temporary folder and named in the panic.
pub fn assert_matches_pinned(name: &str, value: &serde_json::Value) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/pinned")
        .join(name);
    if std::env::var_os("RIGTWIN_WRITE_PINS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, serde_json::to_string_pretty(value).unwrap() + "\n").unwrap();
        return;
    }
    if &json(&path) != value {
        let got = std::env::temp_dir().join(format!("{name}.got.json"));
        std::fs::write(&got, serde_json::to_string_pretty(value).unwrap()).unwrap();
        panic!(
            "{name} differs from the pinned output tests/pinned/{name} (this run's output: {})",
            got.display()
        );
    }
}
