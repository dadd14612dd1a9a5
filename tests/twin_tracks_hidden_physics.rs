//! Issue 14, "What must hold", first point, for the effects seen without contact: a session of
//! the simulated rig with one effect hidden in `[truth.variants]`, and a twin that declares the
//! same physics with the same parameters in `[model]`, tracks the rig as closely as the
//! nominal twin tracks the nominal rig — per step, in the comparison's scores (every compared
//! channel and feature against the measurement's and the model's spread) — while the nominal
//! twin on the same recording does not. Two parameter values per effect: the linear 1FU
//! frequency and damping, the clamp's friction (Iwan element on the upper beam), and sensor
//! sensitivities (the lower tip, and a mid-beam accelerometer, which the comparison now
//! compares too).
//!
//! The steps sit around 1FU at a level where nothing touches (the contact effects — clearance,
//! wear, tilt — act in the impact band, where the nominal twin's own scores are those of
//! BENCHMARKS.md, "The comparison's spread").

mod cli_support;
mod twin_support;

use std::path::Path;

use twin_support::{hidden_and_declared, max_scores, on_every_core, Case};

/// Three steps through 1FU at a level far from contact; 50 recorded periods give the
/// measurement two sub-windows, hence a spread.
const PLAN: &str = r#"
name = "track"
[defaults]
level = 0.3e-5
clearance = 2.33e-3
steps = 3
settle_periods = 60
record_periods = 50
steps_per_period = 1000
[[test]]
name = "near-1fu"
direction = "up"
omega_start = 0.99
omega_end = 1.01
"#;

/// Runs the plan on the rig `extra` describes (appended to the default rig) with the live
/// twin, then replays the twin of the default (nominal) rig on the same recording; returns
/// the live twin's and the nominal twin's per-step largest scores.
fn session(dir: &Path, name: &str, extra: &str) -> (Vec<f64>, Vec<f64>) {
    let case = Case::new(dir, name, "", extra);
    let live = case.record(PLAN, true).unwrap();
    let nominal = case.replay(&case.nominal, "nominal-twin");
    (max_scores(&live), max_scores(&nominal))
}

#[test]
fn a_twin_with_the_hidden_physics_tracks_the_rig_and_the_nominal_twin_does_not() {
    let dir = tempfile::tempdir().unwrap();
    let (null, _) = session(dir.path(), "null", "");
    println!("null case: {null:.2?}");
    // The nominal twin on the nominal rig off the impact band (BENCHMARKS.md: median 0.06).
    assert!(null.iter().all(|&s| s < 1.0), "null case {null:?}");

    let cases: [(&str, &str); 8] = [
        (
            "1FU 50.9 Hz",
            "[{t}]\nmodes = [{ mode = \"1FU\", frequency_hz = 50.9 }]\n",
        ),
        (
            "1FU 51.6 Hz, damping 0.004",
            "[{t}]\nmodes = [{ mode = \"1FU\", frequency_hz = 51.6, damping_ratio = 0.004 }]\n",
        ),
        (
            "clamp friction 0.05, 1.5e-4 m",
            "[{t}.clamp_friction]\nstiffness_fraction = 0.05\nhalf_slip_tip_amplitude = 1.5e-4\n\
             beams = [\"upper\"]\n",
        ),
        (
            "clamp friction 0.08, 1e-4 m, both beams",
            "[{t}.clamp_friction]\nstiffness_fraction = 0.08\nhalf_slip_tip_amplitude = 1.0e-4\n\
             beams = [\"upper\", \"lower\"]\n",
        ),
        (
            "lower-tip gain 0.96",
            "[{t}]\nsensor_gains = [{ channel = \"lower_tip\", gain = 0.96 }]\n",
        ),
        (
            "lower-tip gain 1.05",
            "[{t}]\nsensor_gains = [{ channel = \"lower_tip\", gain = 1.05 }]\n",
        ),
        (
            "upper-mid gain 1.04",
            "[{t}]\nsensor_gains = [{ channel = \"upper_mid\", gain = 1.04 }]\n",
        ),
        (
            "upper-mid gain 0.95",
            "[{t}]\nsensor_gains = [{ channel = \"upper_mid\", gain = 0.95 }]\n",
        ),
    ];
    let runs = on_every_core(&cases, |i, &(_, physics)| {
        session(
            dir.path(),
            &format!("case{i}"),
            &hidden_and_declared(physics),
        )
    });
    for ((name, _), (matched, nominal)) in cases.iter().zip(&runs) {
        println!("{name}: twin with the physics {matched:.2?}, nominal twin {nominal:.2?}");
        for (k, (&m, &n)) in matched.iter().zip(&null).enumerate() {
            // As close as the null case, per step: within its score plus one spread.
            assert!(
                m <= n + 1.0,
                "{name}: step {k}: {m} against the null case's {n}"
            );
        }
        // The nominal twin misses somewhere by more than the threshold of a mismatch (3:
        // rig-config/README.md), and by far more than the twin with the physics. (A 4 %
        // sensitivity error is 4 tolerances of 1 %: a score of about 3.5.)
        let worst = nominal.iter().copied().fold(0.0, f64::max);
        let matched_worst = matched.iter().copied().fold(0.0, f64::max);
        assert!(
            worst > 3.0 && worst > 3.0 * matched_worst,
            "{name}: the nominal twin should not track the rig: {nominal:?} (with the physics \
             {matched:?})"
        );
    }
}
