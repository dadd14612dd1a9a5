//! Guards the report figures: each figure function writes a non-empty PNG of the requested
//! pixel size from synthetic data (and an SVG holding its axis labels), overlays of several
//! sources are accepted, and empty, all-NaN or inconsistent data is an error naming the file
//! (with no file written). The figures are kept in `$CARGO_TARGET_TMPDIR/report_figures/`
//! for inspection.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use rigtwin::plan::Direction;
use rigtwin::report::{
    amplitude_range, contact_activity, convergence, rms_response, scalogram, time_histories, Beam,
    Convergence, ConvergenceKind, ConvergenceSignal, FigureOptions, FrequencyResponse, ReportError,
    ScalogramOptions, Source, TestCurve, TimeHistory, TimeWindow,
};
use rigtwin::signal::wavelet::{log_spaced, morlet_scalogram, MorletParams};

fn out_dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("report_figures");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert!(bytes.len() > 24, "{}: too short", path.display());
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    assert_eq!(&bytes[12..16], b"IHDR", "{}", path.display());
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    (be(&bytes[16..20]), be(&bytes[20..24]))
}

/// Checks a written PNG: non-trivial size on disk and the requested pixel size.
fn assert_png(path: &Path, opts: &FigureOptions) {
    let len = std::fs::metadata(path).unwrap().len();
    // A blank white PNG of this size compresses to a few kB; a drawn figure is larger.
    assert!(len > 10_000, "{}: only {len} bytes", path.display());
    assert_eq!(
        png_size(path),
        (opts.width, opts.height),
        "{}",
        path.display()
    );
}

fn assert_svg_has(path: &Path, labels: &[&str]) {
    let svg = std::fs::read_to_string(path).unwrap();
    assert!(svg.starts_with("<svg"), "{}", path.display());
    for l in labels {
        assert!(svg.contains(l), "{}: no {l:?}", path.display());
    }
}

/// A synthetic response: a linear resonance with an impact band that caps the RMS and
/// spreads the per-period amplitudes.
fn curve(name: &str, level: f64, direction: Direction, source: Source, shift: f64) -> TestCurve {
    let mut w: Vec<f64> = (0..41).map(|i| 0.94 + 0.003 * i as f64).collect();
    if direction == Direction::Down {
        w.reverse();
    }
    let lin = |x: f64, f0: f64| 1.0 / ((1.0 - (x / f0).powi(2)).powi(2) + 0.012f64.powi(2)).sqrt();
    // Stepping down holds the impacting branch to lower frequencies.
    let shift = shift
        - if direction == Direction::Down {
            0.006
        } else {
            0.0
        };
    let cap = 0.004 / level;
    let rms_upper: Vec<f64> = w.iter().map(|&x| lin(x, 1.0 + shift).min(cap)).collect();
    let rms_lower: Vec<f64> = w
        .iter()
        .zip(&rms_upper)
        .map(|(&x, &r)| 0.2 * lin(x, 0.918) + if r >= cap { 0.3 * cap } else { 0.0 })
        .collect();
    let spread: Vec<f64> = rms_upper
        .iter()
        .map(|&r| if r >= cap { 0.6 } else { 0.02 })
        .collect();
    let mean: Vec<f64> = rms_upper.iter().map(|r| r * 2f64.sqrt()).collect();
    TestCurve {
        name: name.into(),
        level,
        direction,
        source,
        amp_min_upper: mean
            .iter()
            .zip(&spread)
            .map(|(m, s)| m * (1.0 - s))
            .collect(),
        amp_max_upper: mean
            .iter()
            .zip(&spread)
            .map(|(m, s)| m * (1.0 + 2.0 * s))
            .collect(),
        amp_mean_upper: mean,
        omega_ratio: w,
        rms_upper,
        rms_lower,
        amp_min_lower: Vec::new(),
        amp_mean_lower: Vec::new(),
        amp_max_lower: Vec::new(),
    }
}

/// Four tests as in the reference's Table 2, simulated and measured, plus a twin curve with
/// a NaN step (skipped when drawn).
fn response() -> FrequencyResponse {
    let mut tests = Vec::new();
    for (source, shift) in [(Source::Simulation, 0.0), (Source::Measurement, 0.004)] {
        tests.push(curve("1-low-down", 2e-5, Direction::Down, source, shift));
        tests.push(curve("2-low-up", 2e-5, Direction::Up, source, shift));
        tests.push(curve("3-high-up", 6e-5, Direction::Up, source, shift));
        tests.push(curve("4-high-down", 6e-5, Direction::Down, source, shift));
    }
    let mut twin = curve("4-high-down", 6e-5, Direction::Down, Source::Twin, -0.003);
    twin.rms_upper[20] = f64::NAN;
    twin.amp_mean_upper[5] = f64::INFINITY;
    tests.push(twin);
    FrequencyResponse { tests }
}

/// A modulated time history at Omega = omega_2 (55 Hz) with impacts every few periods.
fn history(source: Source, phase: f64) -> TimeHistory {
    let f = 55.0;
    let dt = 1.0 / (f * 200.0);
    let n = 200 * 40;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let env = |t: f64| 1.0 + 0.6 * (TAU * f / 7.0 * t + phase).sin();
    let upper: Vec<f64> = t
        .iter()
        .map(|&t| 0.01 * env(t) * (TAU * f * t).sin() + 0.002 * (TAU * 6.0 * f * t).sin())
        .collect();
    let lower: Vec<f64> = t
        .iter()
        .map(|&t| 0.003 * (TAU * f * t + 0.4).sin())
        .collect();
    let closed: Vec<bool> = t
        .iter()
        .map(|&t| env(t) > 1.3 && (TAU * f * t).sin() > 0.93)
        .collect();
    let normal: Vec<f64> = closed
        .iter()
        .zip(&t)
        .map(|(&c, &t)| if c { 200.0 * env(t) } else { 0.0 })
        .collect();
    let tangential = normal.iter().map(|n| 0.3 * n).collect();
    TimeHistory {
        name: "3-high-up".into(),
        source,
        omega_ratio: 1.0,
        t,
        upper,
        lower,
        contact_closed: closed,
        normal_force: if source == Source::Measurement {
            Vec::new()
        } else {
            normal
        },
        tangential_force: if source == Source::Measurement {
            Vec::new()
        } else {
            tangential
        },
    }
}

fn small() -> FigureOptions {
    FigureOptions {
        width: 900,
        height: 600,
    }
}

#[test]
fn rms_response_draws_both_beams_levels_and_sources() {
    let opts = FigureOptions::default();
    let png = out_dir().join("rms_response.png");
    rms_response(&response(), &png, &opts).unwrap();
    assert_png(&png, &opts);
    let svg = out_dir().join("rms_response.svg");
    rms_response(&response(), &svg, &small()).unwrap();
    assert_svg_has(
        &svg,
        &[
            "Ω / ω₂ (-)",
            "u_rms / (Ω q_base) (-)",
            "upper beam",
            "lower beam",
            "3-high-up (up, measurement)",
            "4-high-down (down, twin)",
        ],
    );
}

#[test]
fn amplitude_range_draws_one_panel_per_level() {
    let opts = FigureOptions {
        width: 1400,
        height: 700,
    };
    let png = out_dir().join("amplitude_range_upper.png");
    amplitude_range(&response(), Beam::Upper, &png, &opts).unwrap();
    assert_png(&png, &opts);
    // A small figure keeps its layout (fonts scale with the size).
    let small_png = out_dir().join("amplitude_range_upper_small.png");
    amplitude_range(&response(), Beam::Upper, &small_png, &small()).unwrap();
    assert_png(&small_png, &small());
    let svg = out_dir().join("amplitude_range_upper.svg");
    amplitude_range(&response(), Beam::Upper, &svg, &small()).unwrap();
    assert_svg_has(
        &svg,
        &[
            "tip velocity amplitude / (Ω q_base) (-)",
            "q_base = 2.00e-5 l",
            "q_base = 6.00e-5 l",
        ],
    );
    // The synthetic lower beam has no amplitudes.
    let err =
        amplitude_range(&response(), Beam::Lower, &out_dir().join("x.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::NothingToPlot { .. }), "{err}");
    assert!(err.to_string().contains("lower beam"), "{err}");
}

#[test]
fn time_histories_overlay_sources_and_zoom() {
    let h = vec![
        history(Source::Measurement, 0.0),
        history(Source::Simulation, 0.5),
    ];
    let opts = FigureOptions::default();
    let png = out_dir().join("time_histories.png");
    time_histories(&h, None, &png, &opts).unwrap();
    assert_png(&png, &opts);
    let zoom = out_dir().join("time_histories_zoom.png");
    let w = TimeWindow {
        start: 0.3,
        end: 0.45,
    };
    time_histories(&h, Some(w), &zoom, &opts).unwrap();
    assert_png(&zoom, &opts);
    let svg = out_dir().join("time_histories.svg");
    time_histories(&h, None, &svg, &small()).unwrap();
    assert_svg_has(
        &svg,
        &[
            "t (s)",
            "u / (Ω l) (-)",
            "Ω / ω₂ = 1.000",
            "upper beam tip",
            "lower beam tip",
        ],
    );
    // A window with no sample is nothing to plot.
    let empty = TimeWindow {
        start: 10.0,
        end: 11.0,
    };
    let err = time_histories(&h, Some(empty), &out_dir().join("none.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::NothingToPlot { .. }), "{err}");
}

#[test]
fn contact_activity_draws_lanes_and_normalised_forces() {
    let h = vec![
        history(Source::Measurement, 0.0),
        history(Source::Simulation, 0.5),
    ];
    let opts = FigureOptions::default();
    let png = out_dir().join("contact_activity.png");
    contact_activity(&h, None, &png, &opts).unwrap();
    assert_png(&png, &opts);
    let zoom = out_dir().join("contact_activity_zoom.png");
    let w = TimeWindow {
        start: 0.5,
        end: 0.7,
    };
    contact_activity(&h, Some(w), &zoom, &opts).unwrap();
    assert_png(&zoom, &opts);
    let svg = out_dir().join("contact_activity.svg");
    contact_activity(&h, None, &svg, &small()).unwrap();
    assert_svg_has(
        &svg,
        &[
            "contact closed",
            "F_n / max|F_n| (-)",
            "F_t / max|F_t| (-)",
            "t (s)",
        ],
    );
    // Velocities alone are not contact activity.
    let mut bare = history(Source::Measurement, 0.0);
    bare.contact_closed.clear();
    let err = contact_activity(&[bare], None, &out_dir().join("bare.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::NothingToPlot { .. }), "{err}");
}

#[test]
fn scalogram_draws_a_log_colour_map_with_a_bar() {
    let h = history(Source::Simulation, 0.0);
    let dt = h.t[1] - h.t[0];
    let f_exc = 55.0;
    let freqs = log_spaced(0.3 * f_exc, 8.0 * f_exc, 90).unwrap();
    let s = morlet_scalogram(&h.upper, dt, &freqs, &MorletParams::default()).unwrap();
    let opts = FigureOptions {
        width: 1400,
        height: 800,
    };
    let sopts = ScalogramOptions {
        label: "simulation, upper beam".into(),
        ..ScalogramOptions::default()
    };
    let png = out_dir().join("scalogram.png");
    scalogram(&s, f_exc, &sopts, &png, &opts).unwrap();
    assert_png(&png, &opts);
    let svg = out_dir().join("scalogram.svg");
    scalogram(&s, f_exc, &sopts, &svg, &small()).unwrap();
    assert_svg_has(&svg, &["f / f_exc (-)", "t (s)", "log10 |W| (-)"]);
    // An all-zero transform has no logarithm.
    let mut zero = s.clone();
    zero.magnitude.iter_mut().for_each(|m| *m = 0.0);
    let err = scalogram(&zero, f_exc, &sopts, &out_dir().join("z.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::NothingToPlot { .. }), "{err}");
    let mut short = s.clone();
    short.magnitude.pop();
    let err = scalogram(&short, f_exc, &sopts, &out_dir().join("z.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::InvalidData { .. }), "{err}");
}

fn study(kind: ConvergenceKind) -> Convergence {
    let (x, reference): (Vec<f64>, f64) = match kind {
        ConvergenceKind::Dt => (
            vec![500.0, 1000.0, 2000.0, 4000.0, 8000.0, 16000.0, 128000.0],
            128000.0,
        ),
        ConvergenceKind::Modes => (vec![20.0, 40.0, 80.0, 120.0, 200.0, 800.0], 800.0),
    };
    let error: Vec<f64> = x
        .iter()
        .map(|&v| {
            if v == reference {
                0.0
            } else {
                0.3 * (x[0] / v).powi(2)
            }
        })
        .collect();
    let f = 55.0;
    let signals = x
        .iter()
        .zip(&error)
        .map(|(&v, &e)| {
            let t: Vec<f64> = (0..2000).map(|k| k as f64 * 5.0 / (f * 2000.0)).collect();
            let u = t
                .iter()
                .map(|&t| 0.01 * (1.0 + e) * (TAU * f * t + e).sin())
                .collect();
            ConvergenceSignal { x: v, t, u }
        })
        .collect();
    Convergence {
        kind,
        x,
        error,
        reference: Some(reference),
        signals,
    }
}

#[test]
fn convergence_draws_log_log_error_and_signals() {
    let opts = FigureOptions {
        width: 1400,
        height: 700,
    };
    for (kind, name) in [
        (ConvergenceKind::Dt, "dt"),
        (ConvergenceKind::Modes, "modes"),
    ] {
        let png = out_dir().join(format!("convergence_{name}.png"));
        convergence(&study(kind), &png, &opts).unwrap();
        assert_png(&png, &opts);
        let svg = out_dir().join(format!("convergence_{name}.svg"));
        convergence(&study(kind), &svg, &small()).unwrap();
        assert_svg_has(&svg, &["ε_RMS (-)", kind.axis_label(), "(reference)"]);
    }
    // Error panel alone.
    let mut bare = study(ConvergenceKind::Dt);
    bare.signals.clear();
    let png = out_dir().join("convergence_error_only.png");
    convergence(&bare, &png, &opts).unwrap();
    assert_png(&png, &opts);
    // Only the reference (error 0) is nothing to plot on log axes.
    bare.x = vec![128000.0];
    bare.error = vec![0.0];
    let err = convergence(&bare, &out_dir().join("c.png"), &opts).unwrap_err();
    assert!(matches!(err, ReportError::NothingToPlot { .. }), "{err}");
}

#[test]
fn empty_or_inconsistent_data_is_an_error_naming_the_file_and_writes_nothing() {
    let opts = small();
    let path = out_dir().join("must_not_exist.png");
    let _ = std::fs::remove_file(&path);
    let check = |r: Result<(), ReportError>, what: &str| {
        let err = r.expect_err(what);
        assert!(
            err.to_string().contains("must_not_exist.png"),
            "{what}: {err}"
        );
        assert!(!path.exists(), "{what}: a file was written");
        err
    };
    let e = check(
        rms_response(&FrequencyResponse::default(), &path, &opts),
        "empty response",
    );
    assert!(matches!(e, ReportError::NothingToPlot { .. }));
    let mut nan = response();
    for c in &mut nan.tests {
        c.rms_upper.iter_mut().for_each(|v| *v = f64::NAN);
        c.rms_lower.iter_mut().for_each(|v| *v = f64::NAN);
    }
    let e = check(rms_response(&nan, &path, &opts), "all-NaN response");
    assert!(matches!(e, ReportError::NothingToPlot { .. }));
    let mut short = response();
    short.tests[2].rms_lower.pop();
    let e = check(rms_response(&short, &path, &opts), "short vector");
    assert!(e.to_string().contains("rms_lower"), "{e}");
    assert!(e.to_string().contains("3-high-up"), "{e}");
    let e = check(time_histories(&[], None, &path, &opts), "no histories");
    assert!(matches!(e, ReportError::NothingToPlot { .. }));
    let mut h = history(Source::Simulation, 0.0);
    h.upper.pop();
    let e = check(time_histories(&[h], None, &path, &opts), "short upper");
    assert!(e.to_string().contains("`upper`"), "{e}");
    let e = check(contact_activity(&[], None, &path, &opts), "no contact");
    assert!(matches!(e, ReportError::NothingToPlot { .. }));
    let mut c = study(ConvergenceKind::Modes);
    c.error.pop();
    let e = check(convergence(&c, &path, &opts), "short error");
    assert!(matches!(e, ReportError::InvalidData { .. }));
    // Unsupported format and size.
    let jpg = out_dir().join("figure.jpg");
    let err = rms_response(&response(), &jpg, &opts).unwrap_err();
    assert!(
        matches!(err, ReportError::UnsupportedFormat { .. }),
        "{err}"
    );
    let tiny = FigureOptions {
        width: 10,
        height: 10,
    };
    let err = rms_response(&response(), &path, &tiny).unwrap_err();
    assert!(matches!(err, ReportError::InvalidSize { .. }), "{err}");
}

/// Vectors equal to within serde_json's float parsing (not bit-exact without its
/// `float_roundtrip` feature).
fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= 1e-14 * x.abs().max(1.0))
}

#[test]
fn data_round_trips_through_json() {
    let r = response();
    let json = serde_json::to_string(&r).unwrap();
    assert!(json.contains("\"source\":\"twin\"") && json.contains("\"direction\":\"down\""));
    let c = curve("a", 2e-5, Direction::Up, Source::Measurement, 0.0);
    let back: FrequencyResponse = serde_json::from_str(
        &serde_json::to_string(&FrequencyResponse {
            tests: vec![c.clone()],
        })
        .unwrap(),
    )
    .unwrap();
    let b = &back.tests[0];
    assert_eq!(
        (&b.name, b.level, b.direction, b.source),
        (&c.name, c.level, c.direction, c.source)
    );
    assert!(close(&b.omega_ratio, &c.omega_ratio));
    assert!(close(&b.rms_upper, &c.rms_upper) && close(&b.rms_lower, &c.rms_lower));
    assert!(close(&b.amp_max_upper, &c.amp_max_upper) && b.amp_max_lower.is_empty());
    let s = study(ConvergenceKind::Dt);
    let back: Convergence = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!((back.kind, back.reference), (s.kind, s.reference));
    assert!(close(&back.x, &s.x) && close(&back.error, &s.error));
    assert_eq!(back.signals.len(), s.signals.len());
    // Optional vectors may be left out of hand-written JSON.
    let minimal = r#"{"tests":[{"name":"m","level":6e-5,"direction":"up","source":"measurement",
        "omega_ratio":[1.0],"rms_upper":[2.0],"rms_lower":[]}]}"#;
    let m: FrequencyResponse = serde_json::from_str(minimal).unwrap();
    assert!(m.tests[0].amp_mean_upper.is_empty());
}
