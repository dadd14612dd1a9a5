//! `rigtwin diagnose` on sessions of the simulated rig whose hidden physics
//! (`[truth.variants]`) the model does not know, each log stripped of every trace of it
//! before the diagnosis sees it (tests/diagnose_support). Guards, on a short plan (1FU
//! impact-free at two levels and the low level again):
//! - the nominal rig: `no_significant_mismatch`, nothing accepted; the log with its hidden
//!   physics and the stripped log give the same diagnosis bit for bit;
//! - a wrong 1FU (frequency +1.0 %, damping x1.5): `linear_frequency` and `linear_damping`
//!   of 1FU accepted, within 0.5 % and 20 %, the validation error at least 3x lower; the
//!   written rig description replayed gives the "after" comparison;
//! - a lower and less damped 1FU (50.9 Hz, 0.0015): both refined by model runs and accepted,
//!   within 0.1 % and 5 %;
//! - a lower-tip accelerometer 5 % low (no redundant channel): `sensor_gain` of `lower_tip`
//!   named first, within 20 % (here 1 %);
//! - a platform accelerometer and the vibrometer off at once: both named, judged on their
//!   redundant partners;
//! - the vibrometer off beside a wrong 1FU: the two readings of the upper tip's sensors tie
//!   against the nominal model and the vibrometer is chosen against the corrected one;
//! - the linear case the other way round: the rig nominal (noise seed 1, the second null
//!   case), the model a wrong rig description given by `--config` (upper clamp layers 4x
//!   softer, 1FU damping 1.6x): `linear_frequency` and `linear_damping` of 1FU found within
//!   0.5 % and 20 % of the nominal rig's;
//! - bad input: not a log, a log cut before its first record window, a plan with a single
//!   level: a clear message of what cannot be diagnosed, no panic.

mod cli_support;
mod diagnose_support;

use std::path::Path;

use cli_support::{json, rigtwin, text};
use diagnose_support::{
    accepted, assert_null, assert_replay_gives_the_after_scores, diagnose, sim_session,
};
use serde_json::Value;

/// 1FU impact-free at 0.1e-5 l and 0.4e-5 l, then 0.1e-5 l again: the linear fit, its
/// validation and the amplitude dependence, in about 60 s of rig time.
const PLAN: &str = r#"
name = "diagnose-short"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 50
steps_per_period = 1000
steps = 7
direction = "up"
omega_start = 0.985
omega_end = 1.015

[[test]]
name = "1fu-low"
level = 0.1e-5

[[test]]
name = "1fu-high"
level = 0.4e-5

[[test]]
name = "1fu-low-again"
level = 0.1e-5
"#;

/// The diagnosis without what differs from run to run (wall time, paths).
fn comparable(mut d: Value) -> Value {
    d["wall_seconds"] = Value::Null;
    d["model"] = Value::Null;
    d["cost"]["model_wall_seconds"] = Value::Null;
    if let Some(stages) = d["cost"]["stages"].as_array_mut() {
        for s in stages {
            s["model_wall_seconds"] = Value::Null;
        }
    }
    d
}

/// Asserts that diagnosis `d` is a mismatch whose first accepted effect is the 1FU frequency,
/// within 0.5 % of `f_true`, with the 1FU damping within 20 % of `z_true` accepted too;
/// returns the two effects.
fn found_1fu(d: &Value, f_true: f64, z_true: f64) -> (&Value, &Value) {
    assert_eq!(d["verdict"], "mismatch");
    let f = accepted(d, "linear_frequency");
    assert_eq!(f.len(), 1, "{d:#}");
    assert_eq!(f[0]["rank"], 1);
    assert_eq!(f[0]["parameters"]["mode"], "1FU");
    let fit = f[0]["parameters"]["frequency_hz"].as_f64().unwrap();
    assert!((fit / f_true - 1.0).abs() < 0.005, "{fit} for {f_true}");
    let z = accepted(d, "linear_damping");
    assert_eq!(z.len(), 1, "{d:#}");
    assert_eq!(z[0]["parameters"]["mode"], "1FU");
    let zeta = z[0]["parameters"]["damping_ratio"].as_f64().unwrap();
    assert!((zeta / z_true - 1.0).abs() < 0.2, "{zeta} for {z_true}");
    (f[0], z[0])
}

#[test]
fn the_nominal_rig_is_no_mismatch_and_the_hidden_physics_is_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let (log, stripped) = sim_session(
        dir.path(),
        "nominal",
        "[daq]\nnoise_seed = 2\n[truth.variants]\n",
        PLAN,
    );
    let d = diagnose(&log, dir.path(), "as-logged", &[]);
    assert_null(&d);
    assert!(d["scores_before"].as_array().unwrap().len() == 21);
    let figures: Vec<_> = std::fs::read_dir(dir.path().join("as-logged"))
        .unwrap()
        .collect();
    assert!(!figures.is_empty());
    // The same log without any trace of the hidden physics: the same diagnosis.
    let s = diagnose(&stripped, dir.path(), "stripped", &[]);
    assert_eq!(comparable(d), comparable(s));
}

#[test]
fn a_wrong_linear_1fu_is_found_fitted_validated_and_written_out() {
    let dir = tempfile::tempdir().unwrap();
    let (f_true, z_true) = (51.8, 0.0027);
    let truth = format!(
        "[truth.variants]\nmodes = [{{ mode = \"1FU\", frequency_hz = {f_true}, damping_ratio = {z_true} }}]\n"
    );
    let (_, stripped) = sim_session(dir.path(), "linear", &truth, PLAN);
    let fixed = dir.path().join("linear-fixed.toml");
    let d = diagnose(
        &stripped,
        dir.path(),
        "linear",
        &["--write-config", fixed.to_str().unwrap()],
    );
    let (f, z) = found_1fu(&d, f_true, z_true);
    let (b, a) = (
        f["error_before"]["validation"].as_f64().unwrap(),
        f["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "validation {b} -> {a}");
    assert!(
        z["error_after"]["validation"].as_f64().unwrap()
            < z["error_before"]["validation"].as_f64().unwrap()
    );

    // The written description, replayed, gives the "after" comparison of every step.
    assert_replay_gives_the_after_scores(&stripped, &fixed, dir.path(), &d);
}

/// The other way from the 1FU above: lower and less damped than the model's (50.9 Hz,
/// 0.0015 against 51.27 Hz, 0.00183), a resonance so sharp that the frequency-response fit's
/// residual bias (0.02 %) alone kept the damping from being accepted before the model-run
/// refinement (src/diagnose/modes.rs).
#[test]
fn an_underdamped_lower_1fu_is_found_by_model_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (f_true, z_true) = (50.9, 0.0015);
    let truth = format!(
        "[truth.variants]\nmodes = [{{ mode = \"1FU\", frequency_hz = {f_true}, damping_ratio = {z_true} }}]\n"
    );
    let (_, stripped) = sim_session(dir.path(), "underdamped", &truth, PLAN);
    let d = diagnose(&stripped, dir.path(), "underdamped", &[]);
    let (f, z) = found_1fu(&d, f_true, z_true);
    // Both fitted within 0.1 % and 5 % of the hidden values by the model runs.
    let fit = f["parameters"]["frequency_hz"].as_f64().unwrap();
    let zeta = z["parameters"]["damping_ratio"].as_f64().unwrap();
    assert!((fit / f_true - 1.0).abs() < 1e-3, "{fit}");
    assert!((zeta / z_true - 1.0).abs() < 0.05, "{zeta}");
    assert!(f["evidence"]["refined_by_model_runs"].is_object(), "{f:#}");
    let before = f["error_before"]["validation"].as_f64().unwrap();
    let after = z["error_after"]["validation"].as_f64().unwrap();
    assert!(before >= 3.0 * after, "validation {before} -> {after}");
}

#[test]
fn a_mis_calibrated_lower_tip_accelerometer_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let gain = 0.95;
    let truth = format!(
        "[truth.variants]\nsensor_gains = [{{ channel = \"lower_tip\", gain = {gain} }}]\n"
    );
    let (_, stripped) = sim_session(dir.path(), "gain", &truth, PLAN);
    let d = diagnose(&stripped, dir.path(), "gain", &[]);
    assert_eq!(d["verdict"], "mismatch");
    let g = accepted(&d, "sensor_gain");
    assert_eq!(g.len(), 1, "{d:#}");
    assert_eq!(g[0]["rank"], 1);
    assert_eq!(g[0]["parameters"]["channel"], "lower_tip");
    let fit = g[0]["parameters"]["gain"].as_f64().unwrap();
    assert!((fit / gain - 1.0).abs() < 0.01, "{fit} for {gain}");
}

/// The default rig description with the upper beam's clamp layers 4x softer and the 1FU
/// damping ratio 0.0030 instead of 0.00183: a model whose 1FU sits 1.4 % low and is damped
/// 1.6x too much, as an analyst's first FE model might be.
fn wrong_rig_description(dir: &Path) -> std::path::PathBuf {
    let mut t = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/rig-config/two-beam.toml"
    ))
    .unwrap();
    for layer in ["upper_spacer", "upper_top"] {
        let start = t.find(&format!("[layers.{layer}]")).unwrap();
        let end = start + t[start..].find("\n\n").unwrap();
        let block = t[start..end]
            .replace("normal = 1.0e13", "normal = 2.5e12")
            .replace("tangential = 3.0e12", "tangential = 7.5e11");
        assert!(
            block.contains("2.5e12") && block.contains("7.5e11"),
            "{block}"
        );
        t.replace_range(start..end, &block);
    }
    let nominal = "{ label = \"1FU\", ratio = 0.00183 }";
    assert!(t.contains(nominal));
    t = t.replace(nominal, "{ label = \"1FU\", ratio = 0.00300 }");
    let p = dir.join("wrong.toml");
    std::fs::write(&p, t).unwrap();
    p
}

#[test]
fn a_nominal_session_against_a_wrong_rig_description_finds_its_1fu() {
    let dir = tempfile::tempdir().unwrap();
    // The nominal rig's 1FU and its damping ratio: the default rig's ROM.
    let rom = dir.path().join("nominal.rom");
    let info = dir.path().join("nominal-rom.json");
    let o = rigtwin(&["rom", "build", "--out", rom.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let o = rigtwin(&[
        "rom",
        "info",
        rom.to_str().unwrap(),
        "--json",
        info.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let info = json(&info);
    let f_true = info["f_1fu_hz"].as_f64().unwrap();
    let i = info["labels"]
        .as_array()
        .unwrap()
        .iter()
        .position(|l| l == "1FU")
        .unwrap();
    let z_true = info["damping_ratios"][i].as_f64().unwrap();

    // Noise seed 1 (the default): with its own description, the second null case.
    let (_, stripped) = sim_session(dir.path(), "nominal", "", PLAN);
    let d = diagnose(&stripped, dir.path(), "own", &[]);
    assert_null(&d);

    // The same recording against the wrong description.
    let wrong = wrong_rig_description(dir.path());
    let d = diagnose(
        &stripped,
        dir.path(),
        "wrong",
        &["--config", wrong.to_str().unwrap()],
    );
    let (f, z) = found_1fu(&d, f_true, z_true);
    for e in [f, z] {
        let (b, a) = (
            e["error_before"]["validation"].as_f64().unwrap(),
            e["error_after"]["validation"].as_f64().unwrap(),
        );
        assert!(b > a, "validation {b} -> {a}: {e:#}");
    }
}

#[test]
fn a_vibrometer_gain_beside_a_wrong_1fu_is_the_vibrometers() {
    // A vibrometer off beside a 1FU the model has wrong: against the nominal model the
    // upper beam's resonance misses in both of the upper tip's sensors, and the two readings
    // of their ratio (the accelerometer low or the vibrometer high) tie; against the model
    // with the 1FU corrected, the vibrometer's is the one (`gains::spot_gain_again`).
    let dir = tempfile::tempdir().unwrap();
    let (vibrometer, f_1fu) = (1.04, 50.8);
    let truth = format!(
        "[truth.variants]\nsensor_gains = [{{ channel = \"vibrometer\", gain = {vibrometer} }}]\n\
         modes = [{{ mode = \"1FU\", frequency_hz = {f_1fu} }}]\n"
    );
    let (_, stripped) = sim_session(dir.path(), "spot", &truth, PLAN);
    let d = diagnose(&stripped, dir.path(), "spot", &[]);
    assert_eq!(d["verdict"], "mismatch");
    let g = accepted(&d, "sensor_gain");
    assert_eq!(g.len(), 1, "{d:#}");
    assert_eq!(g[0]["parameters"]["channel"], "vibrometer", "{:#}", g[0]);
    let fit = g[0]["parameters"]["gain"].as_f64().unwrap();
    assert!(
        (fit / vibrometer - 1.0).abs() < 0.005,
        "{fit} for {vibrometer}"
    );
    // Chosen again against the corrected model, where the first pass tied.
    let again = &g[0]["evidence"]["chosen_again"]["errors"];
    let (v, u) = (
        again["train_error_vibrometer"].as_f64().unwrap(),
        again["train_error_upper_tip"].as_f64().unwrap(),
    );
    assert!(v + 0.3 < u, "vibrometer {v}, upper tip {u}: {:#}", g[0]);
    assert!(
        g[0]["alternatives"].as_array().unwrap().is_empty(),
        "{:#}",
        g[0]
    );
    let f = accepted(&d, "linear_frequency");
    assert_eq!(f.len(), 1, "{d:#}");
    let fit = f[0]["parameters"]["frequency_hz"].as_f64().unwrap();
    assert!((fit / f_1fu - 1.0).abs() < 0.005, "1FU {fit} for {f_1fu}");
}

#[test]
fn mis_calibrated_redundant_channels_are_named_and_judged_on_their_partners() {
    // Two redundant sensors off at once: a platform accelerometer (the base the model
    // consumes moves by a third of it) and the vibrometer (the upper-tip accelerometer sees
    // the same spot). Both are judged on their redundant partners over the validation tests.
    let dir = tempfile::tempdir().unwrap();
    let (platform, vibrometer) = (0.975, 1.035);
    let truth = format!(
        "[truth.variants]\nsensor_gains = [{{ channel = \"platform_3\", gain = {platform} }}, {{ channel = \"vibrometer\", gain = {vibrometer} }}]\n"
    );
    let (_, stripped) = sim_session(dir.path(), "redundant", &truth, PLAN);
    let d = diagnose(&stripped, dir.path(), "redundant", &[]);
    assert_eq!(d["verdict"], "mismatch");
    let g = accepted(&d, "sensor_gain");
    assert_eq!(g.len(), 2, "{d:#}");
    for (channel, hidden) in [("platform_3", platform), ("vibrometer", vibrometer)] {
        let e = g
            .iter()
            .find(|e| e["parameters"]["channel"] == channel)
            .unwrap_or_else(|| panic!("{channel} not named: {d:#}"));
        let fit = e["parameters"]["gain"].as_f64().unwrap();
        assert!(
            (fit / hidden - 1.0).abs() < 0.005,
            "{channel}: {fit} for {hidden}"
        );
        let (b, a) = (
            e["error_before"]["validation"].as_f64().unwrap(),
            e["error_after"]["validation"].as_f64().unwrap(),
        );
        assert!(b >= 3.0 * a, "{channel}: validation {b} -> {a}");
    }
    // Nothing else is blamed for what the sensors did.
    assert!(
        d["effects"]
            .as_array()
            .unwrap()
            .iter()
            .all(|e| e["accepted"] == false || e["effect"] == "sensor_gain"),
        "{d:#}"
    );
}

#[test]
fn what_cannot_be_diagnosed_is_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("d.json");
    let out = dir.path().join("fig");
    let run = |log: &Path| {
        rigtwin(&[
            "diagnose",
            log.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };
    // Not a log.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let o = run(&junk);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("junk.mcap") && !t.contains("panicked"), "{t}");

    // A plan with a single test at a single level: diagnosed, and says what it cannot decide
    // (the amplitude dependence needs two levels; a fit needs another test to validate on).
    let single = PLAN.split("[[test]]").next().unwrap().to_string()
        + "[[test]]\nname = \"1fu-only\"\nlevel = 0.1e-5\n";
    let (log, _) = sim_session(dir.path(), "single", "", &single);
    let d = diagnose(&log, dir.path(), "single", &[]);
    assert_eq!(d["verdict"], "no_significant_mismatch", "{d:#}");
    let undecided = |effect: &str| -> Vec<String> {
        d["undecided"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|u| u["effect"] == effect)
            .map(|u| u["reason"].as_str().unwrap().to_string())
            .collect()
    };
    let clamp = undecided("clamp_friction");
    assert!(
        clamp.iter().any(|r| r.contains("1 level(s) only")
            && r.starts_with("mode 1FU:")
            && !r.contains("1FU: mode")),
        "{d:#}"
    );
    assert!(
        undecided("linear_frequency")
            .iter()
            .any(|r| r.contains("1FU") && r.contains("validate")),
        "{d:#}"
    );

    // The same log cut before its first record window: nothing to diagnose.
    let bytes = std::fs::read(&log).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 20]).unwrap();
    let o = run(&cut);
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(t.contains("record window") || t.contains("cut.mcap"), "{t}");
}
