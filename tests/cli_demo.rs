//! `rigtwin demo` end to end, as the README's first command runs it: the default ROM (from the
//! test cache shared with the other default-rig tests), the ROM summary, the demo plan's
//! virtual stepped sine with its JSON and figures, and the same plan on the simulated rig:
//! session log, summary (not aborted, impacts in the band) and figures from the recording.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn demo_reports_the_rom_and_runs_the_demo_plan() {
    let out_dir = tempfile::tempdir().unwrap();
    let cache = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rom-cache");
    let out = Command::new(env!("CARGO_BIN_EXE_rigtwin"))
        .env("RIGTWIN_CACHE", &cache)
        .args(["demo", "--quiet", "--out"])
        .arg(out_dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{stdout}");
    let info: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.path().join("rom-info.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(info["n_contact_pairs"].as_u64(), Some(192));
    let sine: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.path().join("stepped-sine.json")).unwrap(),
    )
    .unwrap();
    let tests = sine["tests"].as_array().unwrap();
    assert_eq!(tests.len(), 2);
    for t in tests {
        assert_eq!(t["steps"].as_array().unwrap().len(), 13);
        assert!(t["steps"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["impacts_per_period"].as_f64().unwrap() > 0.0));
    }
    for f in [
        "rms_response.png",
        "contact_activity.png",
        "scalogram_high-up.png",
    ] {
        assert!(out_dir.path().join("figures").join(f).exists(), "{f}");
    }
    let session: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.path().join("session.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(session["aborted"], false);
    let tests = session["tests"].as_array().unwrap();
    assert_eq!(tests.len(), 2);
    for t in tests {
        let steps = t["steps"].as_array().unwrap();
        assert_eq!(steps.len(), 13);
        assert!(steps
            .iter()
            .any(|s| s["impacts_per_period"].as_f64().unwrap() > 0.0));
    }
    assert!(out_dir.path().join("session.mcap").is_file());
    for f in ["rms_response.png", "time_histories.png", "summary.json"] {
        assert!(
            out_dir.path().join("session-figures").join(f).exists(),
            "{f}"
        );
    }
}
