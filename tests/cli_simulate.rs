//! `rigtwin simulate` end to end on the coarse fixture rig (sim-fixtures/small-rig.toml; its ROM
//! is built into a temporary cache): a two-test plan writes the JSON the issue names and the
//! figures; the convergence studies write their JSON and figure; bad plans and flags fail
//! with an error naming the key.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_rigtwin"))
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sim-fixtures/small-rig.toml")
}

fn rigtwin(cache: &Path, args: &[&str]) -> std::process::Output {
    Command::new(bin())
        .env("RIGTWIN_CACHE", cache)
        .args(args)
        .output()
        .expect("run rigtwin")
}

const PLAN: &str = r#"
name = "cli test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 3
settle_periods = 4
record_periods = 3
[[test]]
name = "down"
direction = "down"
omega_start = 1.02
omega_end = 0.98
[[test]]
name = "up"
direction = "up"
omega_start = 0.98
omega_end = 1.02
"#;

#[test]
fn simulate_writes_results_and_figures_and_rejects_bad_plans() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let json = dir.path().join("out/results.json");
    let figs = dir.path().join("figs");
    let out = rigtwin(
        &cache,
        &[
            "simulate",
            "--config",
            fixture().to_str().unwrap(),
            "--plan",
            plan.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--figures",
            figs.to_str().unwrap(),
            "--quiet",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["steps_per_second"].as_f64().unwrap() > 0.0);
    assert!(v["wall_seconds"].as_f64().unwrap() > 0.0);
    let tests = v["tests"].as_array().unwrap();
    assert_eq!(tests.len(), 2);
    for t in tests {
        let steps = t["steps"].as_array().unwrap();
        assert_eq!(steps.len(), 3);
        for s in steps {
            for key in [
                "omega_ratio",
                "rms_upper",
                "rms_lower",
                "amp_min_upper",
                "amp_mean_upper",
                "amp_max_upper",
                "contact_fraction",
                "impacts_per_period",
                "solver_failures",
            ] {
                assert!(s[key].is_number(), "step lacks {key}: {s}");
            }
            assert!(s["rms_upper"].as_f64().unwrap() > 0.0);
        }
        // Each test ran 3 x (4 + 3) periods at 1000 steps per period.
        assert_eq!(t["time_steps"].as_u64(), Some(21_000));
    }
    assert_eq!(tests[0]["steps"][0]["omega_ratio"].as_f64(), Some(1.02));
    assert_eq!(tests[1]["steps"][0]["omega_ratio"].as_f64(), Some(0.98));
    for f in [
        "rms_response.png",
        "amplitude_upper.png",
        "amplitude_lower.png",
        "time_histories.png",
        "time_histories_zoom.png",
        "scalogram_down.png",
        "scalogram_up.png",
    ] {
        let meta = std::fs::metadata(figs.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(meta.len() > 10_000, "{f} is only {} bytes", meta.len());
    }

    // Bad plans: each error names the key.
    let cases = [
        ("steps_per_period = 100", "steps_per_period"),
        ("setle_periods = 4", "setle_periods"),
        ("settle_periods = 0", "settle_periods"),
        ("level = -1e-5", "level"),
        ("omega_end = 12.0", "omega_end"),
    ];
    for (line, key) in cases {
        let bad = PLAN.replacen(
            "[[test]]\nname = \"down\"",
            &format!("[[test]]\nname = \"down\"\n{line}"),
            1,
        );
        assert_ne!(bad, PLAN);
        // omega_end appears in the test already: replace instead of adding a duplicate key.
        let bad = if key == "omega_end" {
            PLAN.replacen("omega_end = 0.98", "omega_end = 12.0", 1)
        } else {
            bad
        };
        std::fs::write(&plan, &bad).unwrap();
        let out = rigtwin(
            &cache,
            &[
                "simulate",
                "--config",
                fixture().to_str().unwrap(),
                "--plan",
                plan.to_str().unwrap(),
                "--quiet",
            ],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{line}: accepted");
        assert!(
            err.contains(key),
            "{line}: error does not name {key}: {err}"
        );
        assert!(!err.contains("panicked"), "{line}: {err}");
    }

    // `[model]` values the ROM decides on (a mode label, the beams' 1F modes) are checked
    // against it before anything runs, the error naming the file and the key.
    let fixture_text = std::fs::read_to_string(fixture()).unwrap();
    for (extra, key) in [
        (
            "[model]\nmodes = [{ mode = \"9XZ\", damping_ratio = 0.01 }]\n",
            "model.modes[0].mode",
        ),
        (
            "[model]\nmodes = [{ mode = \"1FU\", frequency_hz = 1.0e6 }]\n",
            "model.modes[0].frequency_hz",
        ),
    ] {
        let rig = dir.path().join("bad-model.toml");
        std::fs::write(&rig, format!("{fixture_text}\n{extra}")).unwrap();
        std::fs::write(&plan, PLAN).unwrap();
        let out = rigtwin(
            &cache,
            &[
                "simulate",
                "--config",
                rig.to_str().unwrap(),
                "--plan",
                plan.to_str().unwrap(),
                "--quiet",
            ],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra}: accepted");
        assert!(
            err.contains("bad-model.toml") && err.contains(key),
            "{extra}: error does not name the file and {key}: {err}"
        );
    }
}

#[test]
fn convergence_studies_write_json_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let fx = fixture();
    let fx = fx.to_str().unwrap();
    let dir_s = dir.path().to_str().unwrap().to_string();
    for (kind, extra) in [
        ("dt", vec!["--steps", "1000,2000,4000"]),
        ("modes", vec!["--modes", "5,10,20,40"]),
    ] {
        let json = dir.path().join(format!("{kind}.json"));
        let json_s = json.to_str().unwrap().to_string();
        let mut args = vec![
            "simulate",
            "convergence",
            "--config",
            fx,
            "--kind",
            kind,
            "--periods",
            "2",
            "--json",
            &json_s,
            "--figures",
            &dir_s,
            "--quiet",
        ];
        args.extend(extra.iter());
        let out = rigtwin(&cache, &args);
        assert!(
            out.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let runs = v["runs"].as_array().unwrap();
        assert_eq!(runs.len(), if kind == "dt" { 3 } else { 4 });
        assert_eq!(runs.last().unwrap()["error"].as_f64(), Some(0.0));
        for r in &runs[..runs.len() - 1] {
            let e = r["error"].as_f64().unwrap();
            assert!(e > 0.0 && e.is_finite(), "{kind}: {r}");
        }
        assert!(dir.path().join(format!("convergence_{kind}.png")).exists());
    }
    // A mode count above the ROM's is an error naming it.
    let out = rigtwin(
        &cache,
        &[
            "simulate",
            "convergence",
            "--config",
            fixture().to_str().unwrap(),
            "--kind",
            "modes",
            "--modes",
            "5,4000",
            "--json",
            dir.path().join("x.json").to_str().unwrap(),
            "--quiet",
        ],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("4000"));
}
