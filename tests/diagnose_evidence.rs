//! The identification stage of `rigtwin diagnose` (`rigtwin::diagnose`) on sessions of the
//! simulated rig with physics hidden in `[truth.variants]`; the estimators see only the
//! recording (DAQ counts, layout, events), never the rig description. Guards:
//! - sensor sensitivities from the redundant channels: a mis-calibrated platform
//!   accelerometer is named (2 of 3 agree) with its gain within 1 %; a vibrometer or upper-tip
//!   gain gives their ratio within 1 % and says it cannot tell which; the nominal rig gives
//!   gains of 1 within their spread;
//! - the linear 1FU frequency within 0.5 % and damping within 20 % of the hidden values, from
//!   the impact-free steps;
//! - the clamp's friction: frequency falling and damping rising with the level, where the
//!   nominal rig shows neither;
//! - the clearance per test within 20 % of the hidden one, bracketed by the first contact;
//! - what cannot be estimated is a typed error: no record windows, a single level, no
//!   impact-free step.

mod cli_support;

use std::path::{Path, PathBuf};

use cli_support::{default_rig_with, rigtwin, text};
use rigtwin::diagnose::clearance::{clearance_per_test, ClearanceOptions};
use rigtwin::diagnose::linear::{amplitude_dependence, linear_modes, LinearOptions};
use rigtwin::diagnose::sensors::{sensor_sensitivities, SensitivityStatus, SensorOptions};
use rigtwin::diagnose::EvidenceError;
use rigtwin::session::replay::{replay, Recording};

/// Beam length of the default rig, m.
const L: f64 = 0.3;

/// Runs `plan` on the simulated rig described by the default rig plus `truth` (TOML appended:
/// the hidden physics) in a folder of `dir`; returns the recording.
fn session(dir: &Path, name: &str, truth: &str, plan: &str) -> Recording {
    let sub = dir.join(name);
    std::fs::create_dir_all(&sub).unwrap();
    let rig = default_rig_with(&sub, truth);
    let plan_path = sub.join("plan.toml");
    std::fs::write(&plan_path, plan).unwrap();
    let mcap: PathBuf = sub.join("session.mcap");
    let o = rigtwin(&[
        "run",
        rig.to_str().unwrap(),
        "--plan",
        plan_path.to_str().unwrap(),
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    replay(&mcap).unwrap().recording
}

/// A few impact-free steps around 1FU: enough signal on every motion channel.
const SHORT_PLAN: &str = r#"
name = "gains"
[defaults]
level = 0.3e-5
clearance = 2.33e-3
steps = 4
settle_periods = 30
record_periods = 20
steps_per_period = 1000
[[test]]
name = "near-1fu"
direction = "up"
omega_start = 0.99
omega_end = 1.01
"#;

#[test]
fn sensor_gains_are_found_from_redundant_channels() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SensorOptions::default();

    // Nominal: every decided gain is 1 within its spread (and within 0.2 %).
    let rec = session(dir.path(), "nominal", "", SHORT_PLAN);
    let ev = sensor_sensitivities(&rec, &opts).unwrap();
    for c in &ev.channels {
        match c.channel.as_str() {
            "lower_tip" | "lower_mid" | "upper_mid" => {
                assert_eq!(c.status, SensitivityStatus::Undecided, "{c:?}");
                assert!(c.reason.contains("no redundant channel"), "{c:?}");
            }
            _ => {
                assert_eq!(c.status, SensitivityStatus::Nominal, "{c:?}");
                let (g, spread) = (c.gain.unwrap(), c.spread.unwrap());
                assert!((g - 1.0).abs() <= spread.max(0.002), "{c:?}");
            }
        }
    }

    // A platform accelerometer off: the two others agree and name it.
    for (channel, gain) in [("platform_2", 1.03), ("platform_3", 0.96)] {
        let truth = format!(
            "[truth.variants]\nsensor_gains = [{{ channel = \"{channel}\", gain = {gain} }}]\n"
        );
        let rec = session(dir.path(), channel, &truth, SHORT_PLAN);
        let ev = sensor_sensitivities(&rec, &opts).unwrap();
        for c in ev
            .channels
            .iter()
            .filter(|c| c.channel.starts_with("platform_"))
        {
            if c.channel == channel {
                assert_eq!(c.status, SensitivityStatus::Off, "{c:?}");
                let g = c.gain.unwrap();
                assert!((g / gain - 1.0).abs() < 0.01, "{channel}: {g} for {gain}");
            } else {
                assert_eq!(c.status, SensitivityStatus::Nominal, "{c:?}");
                assert!((c.gain.unwrap() - 1.0).abs() < 0.002, "{c:?}");
            }
        }
    }

    // The vibrometer or the upper-tip accelerometer off: their ratio, undecided which.
    for (channel, gain) in [("vibrometer", 0.95), ("upper_tip", 1.02)] {
        let truth = format!(
            "[truth.variants]\nsensor_gains = [{{ channel = \"{channel}\", gain = {gain} }}]\n"
        );
        let rec = session(dir.path(), channel, &truth, SHORT_PLAN);
        let ev = sensor_sensitivities(&rec, &opts).unwrap();
        let r = ev.upper_tip_over_vibrometer.as_ref().unwrap();
        let expected = if channel == "upper_tip" {
            gain
        } else {
            1.0 / gain
        };
        assert!(
            (r.ratio / expected - 1.0).abs() < 0.01,
            "{channel}: ratio {} for {expected}",
            r.ratio
        );
        for name in ["upper_tip", "vibrometer"] {
            let c = ev.channel(name).unwrap();
            assert_eq!(c.status, SensitivityStatus::Undecided, "{c:?}");
            assert!(c.reason.contains("no third channel"), "{c:?}");
        }
        // The platform channels are untouched.
        for c in ev
            .channels
            .iter()
            .filter(|c| c.channel.starts_with("platform_"))
        {
            assert_eq!(c.status, SensitivityStatus::Nominal, "{c:?}");
        }
    }
}

/// Impact-free steps over 1FU (+-1.5 % of the ROM's) at two levels, settled 100 periods.
const TWO_LEVELS: &str = r#"
name = "two-levels"
[defaults]
clearance = 2.33e-3
steps = 11
settle_periods = 100
record_periods = 50
steps_per_period = 1000
direction = "up"
omega_start = 0.985
omega_end = 1.015
[[test]]
name = "1fu-low"
level = 0.1e-5
[[test]]
name = "1fu-high"
level = 0.4e-5
"#;

#[test]
fn linear_1fu_frequency_and_damping_are_found_on_the_impact_free_steps() {
    let dir = tempfile::tempdir().unwrap();
    let opts = LinearOptions::default();
    for (i, (f, zeta)) in [(50.90, 0.0030), (51.55, 0.0013)].into_iter().enumerate() {
        let truth = format!(
            "[truth.variants]\nmodes = [{{ mode = \"1FU\", frequency_hz = {f}, damping_ratio = {zeta} }}]\n"
        );
        let rec = session(dir.path(), &format!("modes{i}"), &truth, TWO_LEVELS);
        let ev = linear_modes(&rec, &opts).unwrap();
        let fits: Vec<_> = ev.fits_of("1FU").collect();
        assert_eq!(fits.len(), 2, "{ev:#?}");
        for fit in fits {
            println!(
                "hidden {f} Hz, {zeta}: {} {:.4} +- {:.4} Hz, {:.5} +- {:.5}",
                fit.test,
                fit.frequency_hz,
                fit.frequency_hz_standard_error,
                fit.damping_ratio,
                fit.damping_ratio_standard_error
            );
            assert!((fit.frequency_hz / f - 1.0).abs() < 0.005, "{fit:?}");
            assert!((fit.damping_ratio / zeta - 1.0).abs() < 0.2, "{fit:?}");
        }
        // The lower tip has no resonance inside the 1FU band: said, not fitted.
        assert!(ev.skipped.iter().any(|s| s.mode == "1FL"), "{ev:#?}");
        // A linear rig: no amplitude dependence.
        let a = &ev.amplitude_dependence[0];
        assert!(!a.clamp_friction_signature, "{a:#?}");
    }
}

#[test]
fn clamp_friction_lowers_the_frequency_and_raises_the_damping_with_the_level() {
    let dir = tempfile::tempdir().unwrap();
    let opts = LinearOptions::default();
    for (i, (fraction, half_slip)) in [(0.05, 3.0e-4), (0.03, 1.5e-4)].into_iter().enumerate() {
        let truth = format!(
            "[truth.variants.clamp_friction]\nstiffness_fraction = {fraction}\n\
             half_slip_tip_amplitude = {half_slip}\nbeams = [\"upper\"]\n"
        );
        let rec = session(dir.path(), &format!("clamp{i}"), &truth, TWO_LEVELS);
        let ev = linear_modes(&rec, &opts).unwrap();
        let a = ev
            .amplitude_dependence
            .iter()
            .find(|a| a.mode == "1FU")
            .unwrap_or_else(|| panic!("{ev:#?}"));
        let fits: Vec<_> = ev.fits_of("1FU").collect();
        println!(
            "clamp {fraction}, {half_slip} m: f {:.3} -> {:.3} Hz, zeta {:.5} -> {:.5}",
            fits[0].frequency_hz,
            fits[1].frequency_hz,
            fits[0].damping_ratio,
            fits[1].damping_ratio
        );
        assert!(a.clamp_friction_signature, "{a:#?}");
        assert!(fits[1].frequency_hz < fits[0].frequency_hz, "{fits:#?}");
        assert!(fits[1].damping_ratio > fits[0].damping_ratio, "{fits:#?}");
    }
}

/// Stepping down into the impact band at 2e-5 l: impact-free steps above the band, then the
/// first contact.
const INTO_THE_BAND: &str = r#"
name = "into-the-band"
[defaults]
level = 2.0e-5
clearance = 2.33e-3
settle_periods = 40
record_periods = 30
steps_per_period = 1000
[[test]]
name = "low-down"
direction = "down"
steps = 11
omega_start = 1.05
omega_end = 1.0
"#;

#[test]
fn the_clearance_of_a_test_is_bracketed_by_its_first_contact() {
    let dir = tempfile::tempdir().unwrap();
    let opts = ClearanceOptions {
        beam_length: L,
        ..ClearanceOptions::of_rig(&rigtwin::config::RigConfig::default_rig())
    };
    let plan = 2.33e-3 * L;
    for (i, offset) in [1.5e-4, -1.0e-4].into_iter().enumerate() {
        let truth = format!("[truth.variants.clearance]\noffset = {offset}\n");
        let rec = session(dir.path(), &format!("clearance{i}"), &truth, INTO_THE_BAND);
        let ev = clearance_per_test(&rec, &opts).unwrap();
        let t = &ev.tests[0];
        let hidden = plan + offset;
        let c = t.clearance_m.unwrap_or_else(|| panic!("{t:#?}"));
        println!(
            "hidden {hidden:.4e} m: {c:.4e} +- {:.2e} m ([{:.4e}, {:.4e}], first contact at {:?})",
            t.uncertainty_m.unwrap(),
            t.lower_bound_m.unwrap(),
            t.upper_bound_m.unwrap(),
            t.first_contact_omega_ratio
        );
        assert!((c / hidden - 1.0).abs() < 0.2, "{t:#?}");
        // The second estimate, at the contact onsets: within 10 % (about 5 % in the
        // measurements of BENCHMARKS.md, "Wear on six probes, and the clearance at the contact
        // onsets").
        let o = t.onset_clearance_m.unwrap_or_else(|| panic!("{t:#?}"));
        println!("  at {} contact onsets: {o:.4e} m", t.onsets);
        assert!(t.onsets > 0 && (o / hidden - 1.0).abs() < 0.1, "{t:#?}");
        assert!((t.clearance_l.unwrap() - c / L).abs() < 1e-12);
        assert_eq!(t.plan_clearance_m, plan);
    }
}

#[test]
fn what_cannot_be_estimated_is_a_typed_error() {
    let dir = tempfile::tempdir().unwrap();
    let rec = session(dir.path(), "short", "", SHORT_PLAN);

    // No record windows.
    let mut none = rec.clone();
    none.events
        .retain(|e| !matches!(e.kind, rigtwin::control::EventKind::RecordEnd { .. }));
    assert!(matches!(
        sensor_sensitivities(&none, &SensorOptions::default()),
        Err(EvidenceError::NoRecordWindows)
    ));
    assert!(matches!(
        linear_modes(&none, &LinearOptions::default()),
        Err(EvidenceError::NoRecordWindows)
    ));
    let copts = ClearanceOptions {
        beam_length: L,
        contact_over_sensor: 1.0,
        static_offset: 0.0,
    };
    let e = clearance_per_test(&none, &copts).unwrap_err();
    assert!(e.to_string().contains("no record window"), "{e}");

    // A single level: the amplitude dependence cannot be told.
    let plan = SHORT_PLAN
        .replace("steps = 4", "steps = 7")
        .replace("0.99", "0.985")
        .replace("1.01", "1.015");
    let rec = session(dir.path(), "single", "", &plan);
    let lin = linear_modes(&rec, &LinearOptions::default()).unwrap();
    assert!(lin.amplitude_dependence.is_empty(), "{lin:#?}");
    assert!(lin.amplitude_dependence_undecided[0]
        .reason
        .contains("two or more levels"));
    let fits: Vec<_> = lin.fits.clone();
    let e = amplitude_dependence(&fits, &LinearOptions::default()).unwrap_err();
    assert!(matches!(e, EvidenceError::SingleLevel { .. }), "{e}");

    // No impact-free step: nothing linear to fit.
    let mut ev = rigtwin::diagnose::session_evidence(&rec, &[]).unwrap();
    for w in &mut ev.windows {
        w.contact_fraction = 0.5;
    }
    let e = rigtwin::diagnose::linear::linear_modes_of(&ev, &LinearOptions::default()).unwrap_err();
    assert!(matches!(e, EvidenceError::NoImpactFreeSteps { .. }), "{e}");

    // A bad gain correction names the channel.
    let e = rigtwin::diagnose::session_evidence(&rec, &[("nowhere".into(), 1.0)]).unwrap_err();
    assert!(e.to_string().contains("\"nowhere\""), "{e}");
}
