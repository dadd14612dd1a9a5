//! Guards the figures of a diagnosis (`rigtwin::report::figures::diagnosis::draw_diagnosis`):
//! a synthetic diagnosis with every kind of data writes the mismatch maps (before and after),
//! the linear, clearance and sensor evidence and the before/after response, each as a PNG of
//! the default size and a well-formed SVG; missing evidence, non-finite values and
//! uncompared steps leave a figure out or a cell grey, never an error or a panic; an empty
//! diagnosis writes nothing. The figures of the full diagnosis and of a degenerate one are
//! kept in `$CARGO_TARGET_TMPDIR/report_diagnosis_figures*/` for inspection.

use std::path::{Path, PathBuf};

use rigtwin::config::PhysicsSpec;
use rigtwin::diagnose::clearance::TestClearance;
use rigtwin::diagnose::clearance::{ClearanceEvidence, ClearanceOptions, ClearanceTrend};
use rigtwin::diagnose::linear::Trend;
use rigtwin::diagnose::linear::{AmplitudeDependence, LinearEvidence, LinearOptions, ModeFit};
use rigtwin::diagnose::outcome::{
    BandSpread, BandStep, Diagnosis, DiagnosisCost, DiscretisationEvidence, DiscretisedStep,
    DiscretisedTwin, EffectResult, Regime, RegimeScores, SetError, StepScores, Verdict,
};
use rigtwin::diagnose::sensors::SensorOptions;
use rigtwin::diagnose::sensors::{ChannelSensitivity, SensitivityStatus, SensorEvidence};
use rigtwin::report::figures::diagnosis::draw_diagnosis;
use rigtwin::twin::FeatureComparison;

const MOTION: [&str; 5] = [
    "vibrometer",
    "upper_tip",
    "upper_mid",
    "lower_tip",
    "lower_mid",
];

/// Tests of the synthetic session: (name, base level / l).
const TESTS: [(&str, f64); 3] = [("low-up", 1e-5), ("mid-up", 2e-5), ("high-up", 4e-5)];

/// Steps per test and their Omega / omega_2.
fn omega(step: usize) -> f64 {
    0.90 + 0.01 * step as f64
}

/// A resonance of 1FU at `f0` (Omega / omega_2) with an impact cap at high level, scaled by
/// the channel's `gain`.
fn response(w: f64, f0: f64, level: f64, gain: f64) -> f64 {
    let lin = 1.0 / ((1.0 - (w / f0).powi(2)).powi(2) + 0.03f64.powi(2)).sqrt();
    gain * lin.min(3e-4 / level)
}

fn comparison(channel: &str, feature: &str, measured: f64, model: f64) -> FeatureComparison {
    let spread = 0.02 * measured.abs() + 0.01;
    FeatureComparison {
        channel: channel.into(),
        feature: feature.into(),
        measured,
        measured_spread: Some(spread),
        model,
        model_spread: Some(spread),
        score: (model - measured).abs() / (2.0f64.sqrt() * spread),
    }
}

/// The steps of every test, the model's 1FU at `f0` and its lower-tip gain `gain`.
fn scores(f0: f64, gain: f64) -> Vec<StepScores> {
    let mut out = Vec::new();
    for (ti, &(name, level)) in TESTS.iter().enumerate() {
        for step in 0..21 {
            let w = omega(step);
            let impacts = level > 1e-5 && (0.97..1.03).contains(&w);
            let mut features = Vec::new();
            for (c, channel) in MOTION.iter().enumerate() {
                let shape = 1.0 - 0.1 * c as f64;
                let measured = response(w, 0.99, level, shape * if c == 3 { 1.04 } else { 1.0 });
                let model = response(w, f0, level, shape * if c == 3 { gain } else { 1.0 });
                features.push(comparison(channel, "rms", measured, model));
                for (feature, k) in [("amp_p10", 1.2), ("amp_p50", 1.4), ("amp_p90", 1.6)] {
                    let spread = (k - 1.4) * if impacts { 2.0 } else { 0.1 };
                    features.push(comparison(
                        channel,
                        feature,
                        measured * (1.4 + spread),
                        model * (1.4 + 0.8 * spread),
                    ));
                }
            }
            let cf = if impacts { 0.05 } else { 0.0 };
            features.push(comparison("contact", "contact_fraction", cf, 0.8 * cf));
            features.push(comparison(
                "contact",
                "impacts_per_period",
                10.0 * cf,
                8.0 * cf,
            ));
            // The model missed one step of the first test: nothing compared there.
            if ti == 0 && step == 7 {
                features.clear();
            }
            // A non-finite value among the features: drawn around, not through.
            if ti == 1 && step == 4 {
                features[0].measured = f64::NAN;
                features[0].score = f64::NAN;
            }
            out.push(StepScores {
                test: name.into(),
                test_index: ti,
                step,
                omega_ratio: w,
                regime: match (impacts, level > 1e-5) {
                    (true, _) => Regime::Impacts,
                    (false, false) => Regime::ImpactFreeLow,
                    (false, true) => Regime::ImpactFreeHigh,
                },
                level,
                features,
            });
        }
    }
    out
}

fn trend(intercept: f64, slope: f64, se: f64) -> Trend {
    Trend {
        intercept,
        slope,
        slope_standard_error: se,
        significant: (slope / se).abs() > 3.0,
    }
}

fn linear() -> LinearEvidence {
    let mut fits = Vec::new();
    for (mode, f, amp) in [("1FU", 100.0, 2e-4), ("1FL", 92.0, 1.5e-4)] {
        for (ti, &(name, level)) in TESTS.iter().enumerate() {
            let a = amp * (level / 1e-5);
            fits.push(ModeFit {
                mode: mode.into(),
                test: name.into(),
                test_index: ti,
                level,
                base_amplitude_m: level * 0.3,
                steps: 8,
                omega_ratio_range: [0.95, 1.0],
                frequency_hz: f - 2000.0 * a,
                frequency_hz_standard_error: 0.05,
                frequency_ratio: (f - 2000.0 * a) / 100.0,
                damping_ratio: 0.002 + 2.0 * a,
                // A standard error the fit could not give: the marker without a bar.
                damping_ratio_standard_error: if ti == 1 { f64::NAN } else { 1e-4 },
                participation: [1.0, 0.0],
                residual_terms: [0.0, 0.0],
                peak_tip_amplitude_m: a,
                relative_residual: 0.01,
                transient_share: 0.02,
            });
        }
    }
    let dep = |mode: &str, f: f64| AmplitudeDependence {
        mode: mode.into(),
        tests: TESTS.iter().map(|t| t.0.to_string()).collect(),
        levels: 3,
        frequency_vs_amplitude: trend(f, -2000.0, 50.0),
        damping_vs_amplitude: trend(0.002, 2.0, 0.2),
        frequency_vs_session_order: None,
        damping_vs_session_order: None,
        clamp_friction_signature: true,
    };
    LinearEvidence {
        options: LinearOptions::default(),
        fits,
        skipped: Vec::new(),
        amplitude_dependence: vec![dep("1FU", 100.0), dep("1FL", 92.0)],
        amplitude_dependence_undecided: Vec::new(),
    }
}

fn clearance() -> ClearanceEvidence {
    let test = |ti: usize, c: Option<f64>| {
        let (name, level) = TESTS[ti];
        TestClearance {
            test: name.into(),
            test_index: ti,
            level,
            start_s: 100.0 * ti as f64,
            plan_clearance_m: 2.33e-3,
            clearance_m: c,
            clearance_l: c.map(|c| c / 0.3),
            uncertainty_m: c.map(|_| 5e-5),
            lower_bound_m: c.map(|c| c - 5e-5),
            upper_bound_m: c,
            lower_bound_omega_ratio: c.map(|_| 0.96),
            first_contact_omega_ratio: c.map(|_| 0.97),
            impact_free_windows: 7,
            onset_clearance_m: c.map(|c| 0.97 * c),
            onsets: if c.is_some() { 40 } else { 0 },
            onset_standard_error_m: c.map(|_| 1e-5),
            accumulated_contact_impulse_ns: None,
            note: String::new(),
        }
    };
    ClearanceEvidence {
        options: ClearanceOptions {
            beam_length: 0.3,
            contact_over_sensor: 1.0,
            static_offset: 0.0,
        },
        // The first test never touched: no estimate.
        tests: vec![test(0, None), test(1, Some(2.45e-3)), test(2, Some(2.5e-3))],
        trend: Some(ClearanceTrend {
            against: "session order".into(),
            intercept_m: 2.4e-3,
            slope_m: 5e-5,
            slope_standard_error_m: 1e-5,
            tests: 2,
        }),
    }
}

fn sensors() -> SensorEvidence {
    let channel = |name: &str, status, gain: Option<f64>| ChannelSensitivity {
        channel: name.into(),
        status,
        gain,
        spread: gain.map(|_| 0.002),
        standard_error: gain.map(|_| 0.001),
        reason: String::new(),
    };
    SensorEvidence {
        windows: 40,
        options: SensorOptions::default(),
        platform_ratios: Vec::new(),
        upper_tip_over_vibrometer: None,
        channels: vec![
            channel("lower_tip", SensitivityStatus::Off, Some(1.04)),
            channel("lower_mid", SensitivityStatus::Nominal, Some(1.0)),
            channel("vibrometer", SensitivityStatus::Undecided, None),
        ],
    }
}

/// The impact band of `scores` with a spread `widen` times the pointwise one.
fn band(scores: &[StepScores], widen: f64) -> BandSpread {
    let steps: Vec<BandStep> = (scores.iter())
        .filter(|s| s.regime == Regime::Impacts)
        .filter_map(|s| {
            Some(BandStep {
                test: s.test.clone(),
                step: s.step,
                omega_ratio: s.omega_ratio,
                max_score: s.max_score()? / widen,
            })
        })
        .collect();
    let mut m: Vec<f64> = steps.iter().map(|s| s.max_score).collect();
    m.sort_by(f64::total_cmp);
    let median = m[m.len() / 2];
    BandSpread {
        members: 4,
        finer_modes: Some(74),
        scores: RegimeScores {
            regime: Regime::Impacts,
            steps: m.len(),
            steps_above: m.iter().filter(|&&v| v > 3.0).count(),
            median_max_score: median,
        },
        steps,
        beyond: median > 3.0,
    }
}

/// The discretisation stage's evidence on the tests with impacts of `scores`: the twin as
/// given scoring `coarse` times the scores, its step refined scoring them as they are, and a
/// refinement that could not run.
fn discretisation(scores: &[StepScores], coarse: f64) -> DiscretisationEvidence {
    let twin = |refined: Option<&str>, factor: f64, modes: usize, steps: f64| {
        let steps_of: Vec<DiscretisedStep> = (scores.iter())
            .filter(|s| s.regime == Regime::Impacts)
            .map(|s| DiscretisedStep {
                test: s.test.clone(),
                step: s.step,
                omega_ratio: s.omega_ratio,
                score: s.max_score().map(|v| factor * v),
                contact_measured: Some(0.02 * s.step as f64),
                contact_model: Some(0.02 * factor * s.step as f64),
            })
            .collect();
        DiscretisedTwin {
            refined: refined.map(str::to_string),
            modes,
            highest_mode_over_1fu: if modes == 8 { 17.1 } else { 178.0 },
            contact_pairs: 192,
            steps_per_sample: (steps / 200.0) as u32,
            steps_per_1fu_period: steps,
            error: Some(SetError {
                train: 2.0 * factor,
                validation: 2.2 * factor,
            }),
            failure: None,
            steps: steps_of,
        }
    };
    let failed = DiscretisedTwin {
        error: None,
        failure: Some("the step exceeds the ROM's stability limit".into()),
        steps: Vec::new(),
        ..twin(Some("the modal basis and the twin step"), 1.0, 40, 1000.0)
    };
    DiscretisationEvidence {
        train_tests: vec!["mid-up".into()],
        validation_tests: vec!["high-up".into()],
        given: twin(None, coarse, 8, 200.0),
        options: vec![twin(Some("the twin step"), 1.0, 8, 1000.0), failed],
    }
}

fn empty() -> Diagnosis {
    Diagnosis {
        verdict: Verdict::NoSignificantMismatch,
        threshold: 3.0,
        located: Vec::new(),
        scores_before: Vec::new(),
        scores_after: Vec::new(),
        regimes_before: Vec::new(),
        regimes_after: Vec::new(),
        band_before: None,
        band_after: None,
        effects: Vec::new(),
        undecided: Vec::new(),
        model_before: PhysicsSpec::default(),
        model_after: PhysicsSpec::default(),
        discretisation_after: None,
        discretisation: None,
        model: None,
        validation_tests: Vec::new(),
        validation_with_spread: None,
        sensors: None,
        linear: None,
        clearance: None,
        cost: DiagnosisCost::default(),
        wall_seconds: 0.0,
    }
}

fn full() -> Diagnosis {
    let effect = EffectResult {
        effect: "clamp_friction".into(),
        rank: 1,
        accepted: true,
        parameters: serde_json::json!({}),
        alternatives: Vec::new(),
        evidence: serde_json::json!({}),
        reason: "validated".into(),
        train_tests: vec!["low-up".into(), "mid-up".into()],
        validation_tests: vec!["high-up".into()],
        error_before: Some(SetError {
            train: 8.0,
            validation: 9.0,
        }),
        error_after: Some(SetError {
            train: 1.0,
            validation: 1.2,
        }),
    };
    // The tip-side edge's runs (3 mm from the centroid), its best at 0.016 rad.
    let angles: Vec<serde_json::Value> = [0.008, 0.012, 0.016, 0.02, 0.024]
        .iter()
        .map(|a: &f64| {
            serde_json::json!({
                "angle": a,
                "closing_m": 3e-3 * a.sin(),
                "train_error": 2.0 + 400.0 * (a - 0.016).abs() + 900.0 * (a - 0.02).max(0.0),
            })
        })
        .collect();
    let edge = |name: &str, axis: [f64; 2], angle: f64, extent: f64, error: f64| {
        serde_json::json!({
            "edge": name, "axis": axis, "angle": angle,
            "closing_m": extent * angle.abs().sin(), "train_error": error,
        })
    };
    let tilt = EffectResult {
        effect: "tilt".into(),
        rank: 2,
        accepted: false,
        parameters: serde_json::json!({"angle": -0.016, "axis": [0.0, 1.0]}),
        alternatives: vec!["clearance".into()],
        evidence: serde_json::json!({
            "edge": "clamp_side",
            "edge_closing_m": 3e-3 * 0.016f64.sin(),
            "runs_closing_m": 5.4e-5,
            "angles_tried": angles,
            "edges": [
                edge("tip_side", [0.0, 1.0], 0.016, 3e-3, 2.0),
                edge("clamp_side", [0.0, 1.0], -0.016, 3e-3, 1.9),
                edge("smaller_y_side", [1.0, 0.0], 0.0229, 2.1e-3, 2.3),
                edge("larger_y_side", [1.0, 0.0], -0.0229, 2.1e-3, 2.6),
            ],
            "other_edge": {"edge": "tip_side", "angle": 0.016, "train_error": 2.0, "told": false},
            "train_error_without_tilt": 16.9,
            "angle_spread": 0.002,
            "closing_spread_m": 6e-6,
            "floor_angles": [0.012, 0.016],
            "validation_contact_score_rms": {
                "model_before": 9.8, "with_tilt": 1.2, "with_clearance_offset": 4.1
            },
        }),
        reason: "the validation error falls 21 %".into(),
        train_tests: vec!["mid-up".into()],
        validation_tests: vec!["high-up".into()],
        error_before: Some(SetError {
            train: 16.9,
            validation: 1.92,
        }),
        error_after: Some(SetError {
            train: 2.0,
            validation: 1.52,
        }),
    };
    // The clearance offset's runs: a valley about +85 um, together and per train test.
    let valley = |o: f64| 1.2 + 0.0004 * (o - 85.0) * (o - 85.0);
    let together: Vec<serde_json::Value> = [-100.0, 0.0, 60.0, 85.0, 110.0, 200.0]
        .iter()
        .map(|o: &f64| serde_json::json!({"offset_m": o * 1e-6, "error": valley(*o)}))
        .collect();
    let alone = |shift: f64| {
        [-80.0, 20.0, 90.0, 150.0]
            .iter()
            .map(|o: &f64| serde_json::json!({"clearance_m": (699.0 + o) * 1e-6, "error": valley(o - shift) + 0.3}))
            .collect::<Vec<_>>()
    };
    let clearance_fit = EffectResult {
        effect: "clearance".into(),
        rank: 3,
        accepted: true,
        parameters: serde_json::json!({"offset": 85e-6}),
        alternatives: Vec::new(),
        evidence: serde_json::json!({
            "offset_m": 85e-6,
            "offset_by_tests_together": {"offset_m": 85e-6, "runs": together},
            "train_tests_one_by_one": [
                {"test": "low-up", "model_clearance_m": 699e-6, "runs": alone(10.0)},
                {"test": "high-up", "model_clearance_m": 699e-6, "runs": alone(-30.0)},
            ],
        }),
        reason: "validated where it was fitted".into(),
        train_tests: vec!["low-up".into(), "high-up".into()],
        validation_tests: vec!["mid-up".into()],
        error_before: Some(SetError {
            train: 12.6,
            validation: 2.73,
        }),
        error_after: Some(SetError {
            train: 1.24,
            validation: 0.875,
        }),
    };
    let (before, after) = (scores(1.01, 1.0), scores(0.991, 1.04));
    Diagnosis {
        verdict: Verdict::Mismatch,
        band_before: Some(band(&before, 1.5)),
        band_after: Some(band(&after, 4.0)),
        discretisation: Some(discretisation(&before, 2.5)),
        scores_before: before,
        scores_after: after,
        effects: vec![effect, tilt, clearance_fit],
        validation_tests: vec!["high-up".into()],
        sensors: Some(sensors()),
        linear: Some(linear()),
        clearance: Some(clearance()),
        ..empty()
    }
}

fn out_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A PNG: the signature, the default 1600 x 1000 px in its header, a final IEND chunk and
/// more bytes than a blank image compresses to.
fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    let name = path.display();
    assert!(bytes.len() > 10_000, "{name}: only {} bytes", bytes.len());
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    assert_eq!(&bytes[12..16], b"IHDR", "{name}");
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    assert_eq!(
        (be(&bytes[16..20]), be(&bytes[20..24])),
        (1600, 1000),
        "{name}"
    );
    assert_eq!(&bytes[bytes.len() - 8..bytes.len() - 4], b"IEND", "{name}");
}

fn assert_svg(path: &Path, labels: &[&str]) {
    let svg = std::fs::read_to_string(path).unwrap();
    let name = path.display();
    assert!(svg.starts_with("<svg"), "{name}");
    assert!(svg.trim_end().ends_with("</svg>"), "{name}");
    assert!(!svg.contains("NaN"), "{name}: a non-finite coordinate");
    for l in labels {
        assert!(svg.contains(l), "{name}: no {l:?}");
    }
}

#[test]
fn a_diagnosis_draws_every_figure_as_png_and_svg() {
    let dir = out_dir("report_diagnosis_figures");
    let written = draw_diagnosis(&full(), &dir).unwrap();
    let figures: [(&str, &[&str]); 10] = [
        (
            "mismatch-map",
            &["Mismatch map", "upper_tip", "contact", "high-up"],
        ),
        ("mismatch-map-after", &["clamp_friction", "lower_mid"]),
        ("evidence-linear", &["1FU", "1FL", "ζ", "mid-up"]),
        (
            "evidence-clearance",
            &["clearance (mm)", "high-up", "plan clearance"],
        ),
        (
            "evidence-clearance-fit",
            &[
                "offset to the model",
                "together",
                "low-up alone",
                "fitted: 85 µm; validation 2.73",
                "0.875, accepted",
            ],
        ),
        ("evidence-sensors", &["lower_tip", "RMS measured"]),
        (
            "evidence-band",
            &["mid-up", "with the spread", "fixed model", "threshold"],
        ),
        (
            "evidence-tilt",
            &[
                "how much earlier than the mean gap",
                "the clamp side edge, not told from the others, -0.016 +- 0.002 rad about y",
                "the smaller y side edge",
                "rejected",
                "with the clearance offset",
                "the fitted edge closes 48 µm early (a flat face",
                "runs: 54 µm)",
            ],
        ),
        (
            "evidence-discretisation",
            &[
                "twin as given",
                "the twin step refined",
                "could not run",
                "high-up (validation)",
                "contact fraction",
            ],
        ),
        ("before-after", &["high-up", "model as given", "contact"]),
    ];
    let expected: Vec<PathBuf> = (figures.iter())
        .flat_map(|(f, _)| ["png", "svg"].map(|e| dir.join(format!("{f}.{e}"))))
        .collect();
    assert_eq!(written, expected);
    for (f, labels) in figures {
        assert_png(&dir.join(format!("{f}.png")));
        assert_svg(&dir.join(format!("{f}.svg")), labels);
    }
}

#[test]
fn an_empty_diagnosis_draws_nothing() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        draw_diagnosis(&empty(), dir.path()).unwrap(),
        Vec::<PathBuf>::new()
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn missing_data_leaves_figures_out() {
    let dir = tempfile::tempdir().unwrap();
    // Scores before only, evidence without anything to show, a threshold that is not finite.
    let mut d = full();
    d.scores_after.clear();
    d.threshold = f64::NAN;
    d.sensors = None;
    d.band_before = None;
    if let Some(l) = &mut d.linear {
        l.fits
            .iter_mut()
            .for_each(|f| f.peak_tip_amplitude_m = f64::NAN);
    }
    if let Some(c) = &mut d.clearance {
        c.tests.iter_mut().for_each(|t| t.clearance_m = None);
    }
    d.effects[1].evidence = serde_json::json!({});
    // Clearance runs without an error or an offset, a test without its model clearance.
    d.effects[2].evidence = serde_json::json!({
        "offset_m": 85e-6,
        "offset_by_tests_together": {"runs": [{"offset_m": null, "error": 1.0}, {"offset_m": 1e-5}]},
        "train_tests_one_by_one": [{"test": "low-up", "runs": [{"clearance_m": 7e-4, "error": 1.0}]}],
    });
    if let Some(e) = &mut d.discretisation {
        for t in std::iter::once(&mut e.given).chain(&mut e.options) {
            t.steps.iter_mut().for_each(|s| {
                s.score = None;
                s.contact_measured = Some(f64::NAN);
            });
        }
    }
    let names: Vec<String> = (draw_diagnosis(&d, dir.path()).unwrap().iter())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "mismatch-map.png",
            "mismatch-map.svg",
            "evidence-sensors.png",
            "evidence-sensors.svg"
        ]
    );
    // Steps with nothing finite: no figure at all.
    let mut d = full();
    for s in d.scores_before.iter_mut().chain(&mut d.scores_after) {
        s.omega_ratio = f64::NAN;
        s.features.iter_mut().for_each(|f| f.score = f64::NAN);
    }
    for b in d.band_before.iter_mut().chain(&mut d.band_after) {
        b.steps.iter_mut().for_each(|s| s.omega_ratio = f64::NAN);
    }
    d.linear = None;
    d.clearance = None;
    d.effects[1].evidence = serde_json::json!({
        "angles_tried": [
            {"angle": f64::NAN, "closing_m": 1e-5, "train_error": 1.0},
            {"angle": 0.01, "closing_m": -1.0, "train_error": -2.0},
        ],
        "edges": [{"edge": "clamp_side", "closing_m": 3e-5, "train_error": 0.0}],
        "train_error_without_tilt": null,
    });
    d.effects[2].evidence = serde_json::json!({});
    if let Some(e) = &mut d.discretisation {
        for t in std::iter::once(&mut e.given).chain(&mut e.options) {
            t.steps.iter_mut().for_each(|s| {
                s.omega_ratio = f64::NAN;
                s.contact_model = None;
            });
        }
    }
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        draw_diagnosis(&d, dir.path()).unwrap(),
        Vec::<PathBuf>::new()
    );
}

#[test]
fn single_and_extreme_values_draw() {
    // One step with an infinite score (and one band step, one step per discretisation), one
    // fit per mode, one clearance against contact impulse, a threshold below 1: degenerate
    // ranges are widened, nothing panics.
    let mut d = full();
    d.threshold = 0.5;
    d.scores_before.truncate(1);
    d.scores_before[0].features[0].score = f64::INFINITY;
    d.scores_after.truncate(1);
    if let Some(b) = &mut d.band_before {
        b.steps.truncate(1);
        b.steps[0].max_score = f64::INFINITY;
    }
    d.band_after = None;
    d.validation_tests = vec!["low-up".into()];
    if let Some(l) = &mut d.linear {
        l.fits.retain(|f| f.test_index == 2);
        l.amplitude_dependence.clear();
    }
    if let Some(c) = &mut d.clearance {
        c.tests.retain(|t| t.test_index == 2);
        c.tests[0].accumulated_contact_impulse_ns = Some(12.5);
    }
    if let Some(e) = &mut d.discretisation {
        for t in std::iter::once(&mut e.given).chain(&mut e.options) {
            t.steps.truncate(1);
            if let Some(s) = t.steps.first_mut() {
                s.score = Some(4.0);
                (s.contact_measured, s.contact_model) = (Some(0.0), Some(0.0));
            }
        }
    }
    // One joint run, at the fitted offset, and no test alone.
    d.effects[2].evidence = serde_json::json!({
        "offset_m": 85e-6,
        "offset_by_tests_together": {"runs": [{"offset_m": 85e-6, "error": 1.2}]},
    });
    let dir = out_dir("report_diagnosis_figures_degenerate");
    let written = draw_diagnosis(&d, &dir).unwrap();
    assert_eq!(written.len(), 20, "{written:?}");
    for p in written.iter().filter(|p| p.extension().unwrap() == "png") {
        assert_png(p);
    }
    let svg = dir.join("evidence-clearance.svg");
    assert_svg(
        &svg,
        &["normal contact impulse accumulated before the test (N s)"],
    );
}
