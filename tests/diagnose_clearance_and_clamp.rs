//! `rigtwin diagnose` on effects that need the impact band and two levels, on stripped logs of
//! the simulated rig (tests/diagnose_support). Guards:
//! - a clearance larger than the plan's (hidden offset +1e-4 m, +14 %), on the plan of 1FU and
//!   1FL at two levels, 1FU low again and 2e-5 l down and up through the band
//!   ([`LONG_PLAN`]): `clearance` accepted, the offset within 20 %, the validation error (the
//!   other impact test) at least 3x lower. On the shorter [`PLAN`] the offset is found as
//!   well, but the up-sweep that validates it lands on another attractor at its last steps
//!   in the model and the rig alike and does not improve beyond the null spread
//!   (BENCHMARKS.md, "Diagnosis"): validation of a clearance on one impact test is fragile;
//! - a clearance smaller than the plan's (hidden offset -7e-5 m, -10 %), on two up-sweeps
//!   through the first contact at 3e-5 l and 2e-5 l in 0.005 omega_2 steps, 100 periods
//!   recorded ([`SMALL_CLEARANCE_PLAN`]): `clearance` accepted, the offset within 20 %, the
//!   validation error (the other up-sweep) at least 3x lower, nothing else accepted (a tilt
//!   is its equal alternative). A smaller clearance lowers the amplitude at which the probes
//!   graze, by about its share, in every contact step (upper-tip RMS 13 % lower for -10 %),
//!   and makes the first contact harder; on [`LONG_PLAN`]'s 0.01 omega_2 steps and 50
//!   recorded periods the first
//!   contact falls on the same step for offsets 0 to -17 % and one or two contact steps
//!   carry the amplitude, within the twin's spread there (BENCHMARKS.md, "A smaller
//!   clearance");
//! - a clearance larger than the plan's (+8e-5 m, +11 %) on four sweeps through the first
//!   contact at two levels ([`FOUR_BAND_PLAN`]), two of them training one offset together:
//!   `clearance` accepted, the offset within 20 %, the validation error at least 3x lower
//!   (fitted one by one, the two tests' offsets averaged +145 um);
//! - a clearance smaller than the plan's (-8e-5 m) where one test brackets it and the other
//!   touches from its first step ([`ONE_BRACKET_PLAN`]): fitted on the one, validated on
//!   the other, accepted, the offset within 20 %, the validation error at least 2x lower (a
//!   test in contact throughout moves less with the clearance than one that crosses the
//!   first contact);
//! - a lower mid-beam gain (0.96) beside a clearance +1e-4 m larger on [`LONG_PLAN`]: both
//!   named, the gain judged on the validation tests without contact, at least 3x lower;
//! - two effects at once, a lower-tip gain (0.96) and friction in the upper clamp (Iwan,
//!   stiffness share 0.2, half-slip tip amplitude 3e-4 m): both named and accepted; the gain
//!   within 1 %, the clamp's stiffness share per slip amplitude (what amplitudes below full
//!   slip identify) within 20 %, each lowering the validation error at least 3x;
//! - friction in the lower clamp strong enough that 1FL's resonance leaves the band of the
//!   higher level (stiffness share 0.15, half-slip tip amplitude 2e-4 m, on [`LIN5_PLAN`]):
//!   the resonance estimator sees one level, the clamp is fitted by model runs on the higher
//!   level's test and validated on the lower level's: named first, on the lower beam, its
//!   stiffness share per slip amplitude within 20 %, the validation error at least 3x lower;
//! - a clamp whose joint slips at the lowest level already (stiffness share 0.3, half-slip
//!   tip amplitude 1e-4 m on both beams; 0.2 and 8e-5 m on the upper one), on [`LIN5_PLAN`]:
//!   the one level's resonance is the joint's microslip against the model's linear values,
//!   the joint is fitted in place of a linear correction (one joint on both beams where the
//!   other beam's resonance left its band at every level): named first, on the hidden
//!   beams, the share per slip amplitude within 20 %, the validation 3x lower, no linear
//!   correction accepted.

mod cli_support;
mod diagnose_support;

use diagnose_support::{accepted, diagnose, sim_session, validation_with_spread};

/// 1FU 0.98-1.02 and 1FL 0.90-0.94 omega_2 at 0.1e-5 l, then at 0.4e-5 / 0.3e-5 l, 1FU low
/// again (9 steps), then 2e-5 l down 1.02 -> 0.97 and up (6 steps): about 210 s of rig time.
const LONG_PLAN: &str = r#"
name = "diagnose-long"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 50
steps_per_period = 1000
steps = 9
direction = "up"

[[test]]
name = "1fu-low"
level = 0.1e-5
omega_start = 0.98
omega_end = 1.02

[[test]]
name = "1fl-low"
level = 0.1e-5
omega_start = 0.90
omega_end = 0.94

[[test]]
name = "1fu-high"
level = 0.4e-5
omega_start = 0.98
omega_end = 1.02

[[test]]
name = "1fl-high"
level = 0.3e-5
omega_start = 0.90
omega_end = 0.94

[[test]]
name = "1fu-low-again"
level = 0.1e-5
omega_start = 0.98
omega_end = 1.02

[[test]]
name = "band-down"
level = 2e-5
direction = "down"
omega_start = 1.02
omega_end = 0.97
steps = 6

[[test]]
name = "band-up"
level = 2e-5
omega_start = 0.97
omega_end = 1.02
steps = 6
"#;

/// Up through the first contact at 3e-5 l (0.975 -> 1.01 omega_2) and at 2e-5 l (0.98 ->
/// 1.015), in 0.005 steps (8 each), settle 60 + record 100 periods; the second test settles
/// 300 (the lower beam's free 1FL transient after the first test's contact decays over about
/// 115 periods: after 150 it still touched in the first window, or made the nominal model's
/// first impact-free windows score above 3): about 90 s of rig time.
const SMALL_CLEARANCE_PLAN: &str = r#"
name = "diagnose-small-clearance"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 100
steps_per_period = 1000
direction = "up"

[[test]]
name = "band-up-higher"
level = 3e-5
omega_start = 0.975
omega_end = 1.01
steps = 8

[[test]]
name = "band-up"
level = 2e-5
settle_periods = 300
omega_start = 0.98
omega_end = 1.015
steps = 8
"#;

/// Up through the first contact at 3e-5 l and 2e-5 l, then down through it at 2e-5 l and 3e-5
/// l, in 0.005 omega_2 steps (8 each), settle 60 (300 after a level change) + record 100
/// periods: three tests bracket the clearance (the last one touches from its first step), so
/// two train it together: about 180 s of rig time.
const FOUR_BAND_PLAN: &str = r#"
name = "diagnose-four-bands"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 100
steps_per_period = 1000

[[test]]
name = "band-up-higher"
level = 3e-5
direction = "up"
omega_start = 0.975
omega_end = 1.01
steps = 8

[[test]]
name = "band-up"
level = 2e-5
settle_periods = 300
direction = "up"
omega_start = 0.98
omega_end = 1.015
steps = 8

[[test]]
name = "band-down"
level = 2e-5
direction = "down"
omega_start = 1.015
omega_end = 0.98
steps = 8

[[test]]
name = "band-down-higher"
level = 3e-5
settle_periods = 300
direction = "down"
omega_start = 1.01
omega_end = 0.975
steps = 8
"#;

/// Up through the first contact at 2e-5 l (0.98 -> 1.015 omega_2, 8 steps), then at 3e-5 l
/// from inside the band (0.995 -> 1.015, 5 steps), settle 60 (300 after the level change) +
/// record 100 periods: one test brackets the clearance, the other touches from its first
/// step: about 70 s of rig time.
const ONE_BRACKET_PLAN: &str = r#"
name = "diagnose-one-bracket"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 100
steps_per_period = 1000
direction = "up"

[[test]]
name = "band-up"
level = 2e-5
omega_start = 0.98
omega_end = 1.015
steps = 8

[[test]]
name = "band-in-higher"
level = 3e-5
settle_periods = 300
omega_start = 0.995
omega_end = 1.015
steps = 5
"#;

/// About 90 s of rig time.
const PLAN: &str = r#"
name = "diagnose-contact"
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
name = "band-down"
level = 2e-5
direction = "down"
omega_start = 1.02
omega_end = 0.97
steps = 6

[[test]]
name = "band-up"
level = 2e-5
omega_start = 0.97
omega_end = 1.02
steps = 6
"#;

/// 1FU and 1FL at 0.1e-5 l, at 0.4e-5 / 0.3e-5 l, 1FU low again, 7 steps each, impact free:
/// about 150 s of rig time.
const LIN5_PLAN: &str = r#"
name = "diagnose-lin5"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 50
steps_per_period = 1000
steps = 7
direction = "up"

[[test]]
name = "1fu-low"
level = 0.1e-5
omega_start = 0.985
omega_end = 1.015

[[test]]
name = "1fl-low"
level = 0.1e-5
omega_start = 0.905
omega_end = 0.935

[[test]]
name = "1fu-high"
level = 0.4e-5
omega_start = 0.985
omega_end = 1.015

[[test]]
name = "1fl-high"
level = 0.3e-5
omega_start = 0.905
omega_end = 0.935

[[test]]
name = "1fu-low-again"
level = 0.1e-5
omega_start = 0.985
omega_end = 1.015
"#;

/// The accepted clamp friction's stiffness share per slip amplitude (what the sessions
/// identify below full slip) is within 20 % of `share / slip`, on `beams`; its share within
/// 20 % of `share`, or else inside the shares it names as not told apart; the validation
/// error falls at least 3x.
fn assert_clamp(c: &serde_json::Value, share: f64, slip: f64, beams: serde_json::Value) {
    let p = &c["parameters"];
    println!("clamp_friction for share {share}, half-slip {slip} m: {p}");
    assert_eq!(p["beams"], beams, "{c:#}");
    let ratio =
        p["stiffness_fraction"].as_f64().unwrap() / p["half_slip_tip_amplitude"].as_f64().unwrap();
    let hidden = share / slip;
    assert!(
        (ratio / hidden - 1.0).abs() < 0.2,
        "stiffness share per slip amplitude {ratio} /m for {hidden} /m"
    );
    // The share itself within 20 %, or the session says it cannot tell it: the shares named
    // as not told apart (and as the alternative) hold the hidden one.
    let fitted = p["stiffness_fraction"].as_f64().unwrap();
    if (fitted / share - 1.0).abs() >= 0.2 {
        let apart: Vec<f64> = (c["evidence"]["shares_not_told_apart"].as_array())
            .unwrap_or_else(|| panic!("share {fitted} for {share}, no range named: {c:#}"))
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert!(
            apart[0] <= share * 1.05 && share <= apart[1] * 1.05,
            "share {fitted} for {share}, the shares not told apart {apart:?}: {c:#}"
        );
        let named = (c["alternatives"].as_array().unwrap().iter())
            .any(|a| a.as_str().unwrap().contains("stiffness_fraction from"));
        assert!(named, "{c:#}");
    }
    let (b, a) = (
        c["error_before"]["validation"].as_f64().unwrap(),
        c["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "{}: validation {b} -> {a}", c["effect"]);
}

#[test]
fn clamp_friction_past_the_band_is_fitted_by_model_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (share, slip) = (0.15, 2.0e-4);
    let truth = format!(
        "[truth.variants.clamp_friction]\nstiffness_fraction = {share}\n\
         half_slip_tip_amplitude = {slip}\nbeams = [\"lower\"]\n"
    );
    let (_, log) = sim_session(dir.path(), "lower", &truth, LIN5_PLAN);
    let d = diagnose(&log, dir.path(), "lower", &[]);
    assert_eq!(d["verdict"], "mismatch", "{d:#}");
    let c = accepted(&d, "clamp_friction");
    assert_eq!(c.len(), 1, "{d:#}");
    assert_eq!(c[0]["rank"], 1, "{d:#}");
    // Fitted from the one level's microslip, or by the grid of runs on the higher level.
    let ev = &c[0]["evidence"];
    assert!(
        ev["mode"] == "1FL" || ev["modes"] == serde_json::json!(["1FL"]),
        "{d:#}"
    );
    assert_clamp(c[0], share, slip, serde_json::json!(["lower"]));
    // The shares the runs cannot tell apart bracket the fitted one; where they span more than
    // 20 % of it, the other shares are named as the alternative.
    let (ev, p) = (&c[0]["evidence"], &c[0]["parameters"]);
    let sf = p["stiffness_fraction"].as_f64().unwrap();
    let apart: Vec<f64> = (ev["shares_not_told_apart"].as_array().unwrap().iter())
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(apart[0] <= sf && sf <= apart[1], "{ev}");
    let wide = apart[0] < 0.8 * sf || apart[1] > 1.2 * sf;
    let named = (c[0]["alternatives"].as_array().unwrap().iter())
        .any(|a| a.as_str().unwrap().contains("stiffness_fraction from"));
    assert_eq!(wide, named, "{:#}", c[0]);
}

fn clearance_is_found(offset: f64, plan: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let truth = format!("[truth.variants.clearance]\noffset = {offset}\n");
    let (_, log) = sim_session(dir.path(), "clearance", &truth, plan);
    let d = diagnose(&log, dir.path(), "clearance", &[]);
    assert_eq!(d["verdict"], "mismatch", "{d:#}");
    let c = accepted(&d, "clearance");
    assert_eq!(c.len(), 1, "{d:#}");
    assert_eq!(c[0]["rank"], 1, "{d:#}");
    let fit = c[0]["parameters"]["offset"].as_f64().unwrap();
    assert!(
        (fit / offset - 1.0).abs() < 0.2,
        "offset {fit} for {offset}"
    );
    let (b, a) = (
        c[0]["error_before"]["validation"].as_f64().unwrap(),
        c[0]["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "validation {b} -> {a}");
    // Where both bands ran with the comparison's spread, those are its errors (accepted
    // alone), and the judge's pointwise ones are kept as evidence.
    if let Some(spread) = validation_with_spread(&d) {
        assert_eq!(spread, (b, a), "{d:#}");
        assert!(
            c[0]["evidence"]["pointwise"]["error_after"].is_object(),
            "{d:#}"
        );
    }
    // Every run of the fit is in the evidence, each train test's against its clearance in the
    // model, and drawn against the offset.
    for t in c[0]["evidence"]["train_tests_one_by_one"]
        .as_array()
        .unwrap()
    {
        assert!(t["runs"].as_array().unwrap().len() >= 9, "{t}");
        assert!(t["model_clearance_m"].is_f64(), "{t}");
    }
    for ext in ["png", "svg"] {
        let f = (dir.path().join("clearance")).join(format!("evidence-clearance-fit.{ext}"));
        assert!(f.is_file(), "no {}", f.display());
    }
    // A smaller clearance closes the face early, as a tilt would: the tilt is fitted, and its
    // landscape (the train error against the angle, through the face as given) drawn.
    if offset < 0.0 {
        let tilt = (d["effects"].as_array().unwrap().iter())
            .find(|e| e["effect"] == "tilt")
            .unwrap_or_else(|| panic!("no tilt tried: {d:#}"));
        let ev = &tilt["evidence"];
        assert!(ev["angles_tried"].as_array().unwrap().len() >= 9, "{ev}");
        assert!(ev["train_error_without_tilt"].is_f64(), "{ev}");
        // Every edge was tried: along the beams on both sides, across them; each other edge
        // about the tip side's closing.
        let edges = ev["edges"].as_array().unwrap();
        let names: Vec<&str> = edges.iter().map(|e| e["edge"].as_str().unwrap()).collect();
        assert_eq!(
            names,
            ["tip_side", "clamp_side", "smaller_y_side", "larger_y_side"],
            "{ev}"
        );
        let closings: Vec<f64> = edges
            .iter()
            .map(|e| e["closing_m"].as_f64().unwrap())
            .collect();
        assert!(
            (closings.iter()).all(|c| (0.84..1.16).contains(&(c / closings[0]))),
            "{ev}"
        );
        assert_eq!(
            ev["edge_points"].as_array().unwrap().len(),
            1 + 3 * 3,
            "{ev}"
        );
        // The edge taken is the fitted one; the other named is another edge.
        let taken = ev["edge"].as_str().unwrap();
        let at = edges.iter().find(|e| e["edge"] == taken).unwrap();
        assert_eq!(at["angle"], tilt["parameters"]["angle"], "{ev}");
        assert_eq!(at["axis"], tilt["parameters"]["axis"], "{ev}");
        assert_ne!(ev["other_edge"]["edge"].as_str().unwrap(), taken, "{ev}");
        assert!(ev["other_edge"]["told"].is_boolean(), "{ev}");
        for ext in ["png", "svg"] {
            let f = dir
                .path()
                .join("clearance")
                .join(format!("evidence-tilt.{ext}"));
            assert!(f.is_file(), "no {}", f.display());
        }
    }
    // Nothing else is taken for it.
    assert_eq!(
        d["effects"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["accepted"] == true)
            .count(),
        1,
        "{d:#}"
    );
    d
}

#[test]
fn a_larger_clearance_is_found_by_model_runs_and_validated() {
    clearance_is_found(1.0e-4, LONG_PLAN);
}

#[test]
fn a_smaller_clearance_is_found_by_model_runs_and_validated() {
    clearance_is_found(-7.0e-5, SMALL_CLEARANCE_PLAN);
}

#[test]
fn a_clearance_is_fitted_on_its_train_tests_together() {
    // 2026-11-29: one by one, band-up-higher and band-down fitted 784 and 904 um (hidden 779
    // um): a mean offset of +145 um for +80, rejected on band-up (2.73 -> 2.14 where it was
    // fitted). Together: +85 um, 2.73 -> 0.875.
    let d = clearance_is_found(8.0e-5, FOUR_BAND_PLAN);
    let c = accepted(&d, "clearance");
    assert_eq!(
        c[0]["train_tests"],
        serde_json::json!(["band-up-higher", "band-down"])
    );
    let ev = &c[0]["evidence"];
    assert_eq!(
        ev["offset_by_tests_together"]["offset_m"], ev["offset_m"],
        "{ev:#}"
    );
    assert_eq!(
        ev["train_tests_one_by_one"].as_array().unwrap().len(),
        2,
        "{ev:#}"
    );
    // Each train test weighs by its own valley's spread: inverse variances, their mean 1.
    let weights = ev["offset_by_tests_together"]["weights"]
        .as_array()
        .unwrap();
    let spreads: Vec<f64> = (ev["train_tests_one_by_one"].as_array().unwrap().iter())
        .map(|t| t["spread_m"].as_f64().unwrap())
        .collect();
    assert_eq!(weights.len(), 2, "{ev:#}");
    let w: Vec<f64> = weights
        .iter()
        .map(|w| w["weight"].as_f64().unwrap())
        .collect();
    assert!((w[0] + w[1] - 2.0).abs() < 1e-9, "{ev:#}");
    assert!(
        (w[0] / w[1] - (spreads[1] / spreads[0]).powi(2)).abs() < 1e-6 * w[0] / w[1],
        "{ev:#}"
    );
}

#[test]
fn a_clearance_with_one_bracket_is_validated_on_a_test_in_contact_from_its_start() {
    // 2026-11-29: band-up fits 630 um (hidden 619 um), band-in-higher validates: 2.31 -> 1.02
    // with the comparison's spread (2.2x on the whole test at the twin's step). The build
    // before 096ae2b left the clearance undecided: two brackets were needed.
    let dir = tempfile::tempdir().unwrap();
    let offset = -8.0e-5;
    let truth = format!("[truth.variants.clearance]\noffset = {offset}\n");
    let (_, log) = sim_session(dir.path(), "one-bracket", &truth, ONE_BRACKET_PLAN);
    let d = diagnose(&log, dir.path(), "one-bracket", &[]);
    assert_eq!(d["verdict"], "mismatch", "{d:#}");
    let c = accepted(&d, "clearance");
    assert_eq!(c.len(), 1, "{d:#}");
    assert_eq!(c[0]["train_tests"], serde_json::json!(["band-up"]));
    assert_eq!(
        c[0]["validation_tests"],
        serde_json::json!(["band-in-higher"])
    );
    let fit = c[0]["parameters"]["offset"].as_f64().unwrap();
    assert!(
        (fit / offset - 1.0).abs() < 0.2,
        "offset {fit} for {offset}"
    );
    let (b, a) = (
        c[0]["error_before"]["validation"].as_f64().unwrap(),
        c[0]["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 2.0 * a, "validation {b} -> {a}");
}

#[test]
fn a_beam_gain_beside_a_larger_clearance_is_judged_where_no_contact_moves_it() {
    // A lower mid-beam accelerometer 4 % low and a clearance 1e-4 m larger than planned. The
    // band tests' impact-free steps beside their contact move with the clearance, which the
    // gain stage does not know yet, so the gain is judged on the validation tests without
    // measured contact (2026-11-29: 1.74 -> 0.18 on 1fl-low and 1fl-high; with band-down
    // among them, as before, 2.34 -> 1.56).
    let dir = tempfile::tempdir().unwrap();
    let (gain, offset) = (0.96, 1.0e-4);
    let truth = format!(
        "[truth.variants]\nsensor_gains = [{{ channel = \"lower_mid\", gain = {gain} }}]\n\
         [truth.variants.clearance]\noffset = {offset}\n"
    );
    let (_, log) = sim_session(dir.path(), "gain-clearance", &truth, LONG_PLAN);
    let d = diagnose(&log, dir.path(), "gain-clearance", &[]);
    assert_eq!(d["verdict"], "mismatch");
    let g = accepted(&d, "sensor_gain");
    assert_eq!(g.len(), 1, "{d:#}");
    assert_eq!(g[0]["parameters"]["channel"], "lower_mid", "{:#}", g[0]);
    let fit = g[0]["parameters"]["gain"].as_f64().unwrap();
    assert!((fit / gain - 1.0).abs() < 0.01, "gain {fit} for {gain}");
    let validation = g[0]["validation_tests"].as_array().unwrap();
    assert!(
        validation
            .iter()
            .all(|t| !t.as_str().unwrap().starts_with("band")),
        "{:#}",
        g[0]
    );
    let (b, a) = (
        g[0]["error_before"]["validation"].as_f64().unwrap(),
        g[0]["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "sensor_gain: validation {b} -> {a}");
    let c = accepted(&d, "clearance");
    assert_eq!(c.len(), 1, "{d:#}");
    let found = c[0]["parameters"]["offset"].as_f64().unwrap();
    assert!(
        (found / offset - 1.0).abs() < 0.2,
        "offset {found} for {offset}"
    );
}

#[test]
fn a_sensor_gain_and_clamp_friction_at_once_are_both_named() {
    let dir = tempfile::tempdir().unwrap();
    let (gain, share, slip) = (0.96, 0.2, 3.0e-4);
    let truth = format!(
        "[truth.variants]\nsensor_gains = [{{ channel = \"lower_tip\", gain = {gain} }}]\n\
         [truth.variants.clamp_friction]\nstiffness_fraction = {share}\n\
         half_slip_tip_amplitude = {slip}\nbeams = [\"upper\"]\n"
    );
    let (_, log) = sim_session(dir.path(), "both", &truth, PLAN);
    let d = diagnose(&log, dir.path(), "both", &[]);
    assert_eq!(d["verdict"], "mismatch");
    let g = accepted(&d, "sensor_gain");
    assert_eq!(g.len(), 1, "{d:#}");
    assert_eq!(g[0]["parameters"]["channel"], "lower_tip");
    let fit = g[0]["parameters"]["gain"].as_f64().unwrap();
    // Refined by model runs that observe the gain (its first measured/model ratio carries
    // the base's share off the beam's resonance).
    assert!((fit / gain - 1.0).abs() < 0.003, "gain {fit} for {gain}");
    let (b, a) = (
        g[0]["error_before"]["validation"].as_f64().unwrap(),
        g[0]["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "sensor_gain: validation {b} -> {a}");
    let c = accepted(&d, "clamp_friction");
    assert_eq!(c.len(), 1, "{d:#}");
    assert_clamp(c[0], share, slip, serde_json::json!(["upper"]));
}

/// A clamp whose joint already slips at the lowest level (half-slip tip amplitude a few
/// times the low tests' 3e-5 m), strong enough that the higher level's resonance leaves the
/// band: the one level's resonance is softer and more damped than the model's, as the
/// joint's microslip gives, and the joint is fitted in place of a linear correction. Named
/// first, on `beams` (one joint when on both), its stiffness share per slip amplitude within
/// 20 %, the validation error at least 3x lower; no linear correction of its mode accepted.
fn clamp_slipping_at_the_lowest_level(tag: &str, share: f64, slip: f64, beams: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let list = beams.iter().map(|b| format!("\"{b}\"")).collect::<Vec<_>>();
    let truth = format!(
        "[truth.variants.clamp_friction]\nstiffness_fraction = {share}\n\
         half_slip_tip_amplitude = {slip}\nbeams = [{}]\n",
        list.join(", ")
    );
    let (_, log) = sim_session(dir.path(), tag, &truth, LIN5_PLAN);
    let d = diagnose(&log, dir.path(), tag, &[]);
    assert_eq!(d["verdict"], "mismatch", "{d:#}");
    let c = accepted(&d, "clamp_friction");
    assert_eq!(c.len(), 1, "{d:#}");
    assert_eq!(c[0]["rank"], 1, "{d:#}");
    assert_clamp(c[0], share, slip, serde_json::json!(beams));
    for linear in ["linear_frequency", "linear_damping"] {
        assert!(accepted(&d, linear).is_empty(), "{d:#}");
    }
}

#[test]
fn a_clamp_slipping_at_the_lowest_level_on_both_beams_is_one_joint() {
    clamp_slipping_at_the_lowest_level("slipping-both", 0.3, 1.0e-4, &["upper", "lower"]);
}

#[test]
fn a_clamp_slipping_at_the_lowest_level_is_no_linear_correction() {
    clamp_slipping_at_the_lowest_level("slipping-upper", 0.2, 8.0e-5, &["upper"]);
}
