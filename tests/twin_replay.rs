//! `rigtwin replay --twin`: the twin re-run on a recorded session's base motion. Guards:
//! - every step gets the twin's metrics and its errors against the measurement
//!   (`tests[].steps[].twin`), the twin following the measurement closely outside the
//!   impact band (same model as the simulated rig's structure, fewer modes);
//! - the same recording and model give the same bits; a changed model changes them;
//! - a bad model argument is a clear error.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const PLAN: &str = r#"
name = "twin-replay-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 3
settle_periods = 60
record_periods = 30
steps_per_period = 1000

[[test]]
name = "high-down"
direction = "down"
omega_start = 1.08
omega_end = 1.00
"#;

fn cache() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rom-cache")
}

fn rigtwin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rigtwin"))
        .env("RIGTWIN_CACHE", cache())
        .args(args)
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn replay_with_the_twin_compares_every_step_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let mcap = dir.path().join("session.mcap");
    let o = rigtwin(&[
        "run",
        "--plan",
        plan.to_str().unwrap(),
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));

    let replay = |name: &str, extra: &[&str]| -> PathBuf {
        let out = dir.path().join(name);
        let mut args = vec![
            "replay",
            mcap.to_str().unwrap(),
            "--twin",
            "--json",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = rigtwin(&args);
        assert!(o.status.success(), "{}", text(&o));
        assert!(text(&o).contains("3 steps compared"), "{}", text(&o));
        out
    };
    let a = replay("a.json", &[]);
    let b = replay("b.json", &[]);
    assert_eq!(
        std::fs::read_to_string(&a).unwrap(),
        std::fs::read_to_string(&b).unwrap(),
        "the same recording and model give the same bits"
    );
    let s = json(&a);
    let steps = s["tests"][0]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 3);
    for st in steps {
        let w = &st["twin"];
        for key in [
            "rms_upper",
            "rms_lower",
            "amp_min_upper",
            "amp_mean_upper",
            "amp_max_upper",
            "contact_fraction",
            "impacts_per_period",
            "rms_error_upper",
            "rms_error_lower",
            "contact_fraction_error",
        ] {
            assert!(w[key].as_f64().is_some(), "{key} missing in {w}");
        }
    }
    // 1.08 and 1.04 omega_2 are outside the impact band: the twin (the rig's own model, fewer
    // modes, driven by the measured base acceleration) follows the upper tip within 2 %.
    for st in &steps[..2] {
        assert_eq!(st["contact_fraction"], 0.0, "{st}");
        let e = st["twin"]["rms_error_upper"].as_f64().unwrap();
        assert!(e.abs() < 0.02, "{e} at {}", st["omega_ratio"]);
    }

    // A changed model (the twin's time step) changes the twin's output.
    let cfg = dir.path().join("rig.toml");
    let mut t = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/rig-config/two-beam.toml"
    ))
    .unwrap();
    t.push_str("\n[twin]\nsteps_per_reference_period = 2000\n");
    std::fs::write(&cfg, t).unwrap();
    let c = replay("c.json", &["--config", cfg.to_str().unwrap()]);
    let sc = json(&c);
    assert_ne!(
        s["tests"][0]["steps"][0]["twin"], sc["tests"][0]["steps"][0]["twin"],
        "another model gives other numbers"
    );
    // The measurement part is the same.
    assert_eq!(
        s["tests"][0]["steps"][0]["rms_upper"],
        sc["tests"][0]["steps"][0]["rms_upper"]
    );

    // Bad model arguments.
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--rom",
        "/nonexistent/twin.rom",
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("--rom /nonexistent/twin.rom"),
        "{}",
        text(&o)
    );
    let o = rigtwin(&["replay", mcap.to_str().unwrap(), "--rom", "x.rom"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--twin"), "{}", text(&o));
}
