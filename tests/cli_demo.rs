//! `rigtwin demo` end to end, as the README's first command runs it: the default ROM (from the
//! test cache shared with the other default-rig tests), the ROM summary, the demo plan's
//! virtual stepped sine with its JSON and figures, and the same plan on the simulated rig:
//! session log, summary (not aborted, impacts in the band, base amplitude within 1 %) and
//! figures from the recording; the live twin beside the session (issue 5's acceptance
//! figures: the twin, the rig description's own ROM at its own step, against the simulated
//! rig's finer truth with no hidden physics). The session summary and the virtual stepped
//! sine's results are pinned bit for bit (`tests/pinned/`).

mod cli_support;

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
    // The console says where the ROM came from (issue 18, item 4): a ROM from the cache is not
    // "built in N s".
    let reused = stdout.contains("ROM reused from");
    assert_eq!(stdout.contains("loaded from the cache"), reused, "{stdout}");
    assert_eq!(stdout.contains(", built in "), !reused, "{stdout}");
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
        for st in steps {
            cli_support::assert_base_amplitude_within(st, 0.01);
        }
        twin_follows_the_rig(t["name"].as_str().unwrap(), steps);
    }
    assert!(out_dir.path().join("session.mcap").is_file());
    // Bit for bit what the demo gave before the service layer was reshaped (issue 13).
    cli_support::assert_matches_pinned("demo-session.json", &session);
    cli_support::assert_matches_pinned(
        "demo-stepped-sine.json",
        &serde_json::json!({ "tests": sine["tests"] }),
    );
    for f in ["rms_response.png", "time_histories.png", "summary.json"] {
        assert!(
            out_dir.path().join("session-figures").join(f).exists(),
            "{f}"
        );
    }
}

/// The twin against the simulated rig over one test: the impact band's edges (first and last
/// step with contact) within 2 steps; the upper tip's RMS within 10 % outside the band (no
/// contact in either) and within 20 % inside it and in the first step past it (the edge steps
/// excepted, where the two may sit on different sides of the jump); contact fraction within
/// 0.1.
fn twin_follows_the_rig(test: &str, steps: &[serde_json::Value]) {
    let f = |st: &serde_json::Value, key: &str| st[key].as_f64().unwrap();
    let band = |contact: &dyn Fn(&serde_json::Value) -> f64| -> (usize, usize) {
        let idx: Vec<usize> = (0..steps.len())
            .filter(|&i| contact(&steps[i]) > 0.0)
            .collect();
        (*idx.first().unwrap(), *idx.last().unwrap())
    };
    let measured = band(&|st| f(st, "contact_fraction"));
    let twin = band(&|st| f(&st["twin"], "contact_fraction"));
    assert!(
        measured.0.abs_diff(twin.0) <= 2 && measured.1.abs_diff(twin.1) <= 2,
        "{test}: impact band steps {measured:?} measured, {twin:?} twin"
    );
    let edges = [measured.0, measured.1, twin.0, twin.1];
    // The first step past the band (in sweep order) starts from the band's vibro-impact state
    // and still carries its transient, whose size depends on when the last impact fell
    // (chaotic: a change of the contact solve's last bits moved it from 1 % to 12 % in the
    // high-down test at 0.96); it gets the band's tolerance.
    let after = [measured.1 + 1, twin.1 + 1];
    for (i, st) in steps.iter().enumerate() {
        let w = &st["twin"];
        let (e, cm, ct) = (
            f(w, "rms_error_upper"),
            f(st, "contact_fraction"),
            f(w, "contact_fraction"),
        );
        let at = st["omega_ratio"].as_f64().unwrap();
        assert!((ct - cm).abs() <= 0.1, "{test} {at}: contact {ct} vs {cm}");
        if cm == 0.0 && ct == 0.0 && !after.contains(&i) {
            assert!(
                e.abs() <= 0.10,
                "{test} {at}: outside the band, rms upper {e:+.3}"
            );
        } else if !edges.contains(&i) {
            assert!(
                e.abs() <= 0.20,
                "{test} {at}: in the band, rms upper {e:+.3}"
            );
        }
    }
}
