//! The figures of a stepped sine: the virtual stepped sine's (`rigtwin simulate`, the demo)
//! from its results, and the building blocks a recorded session's figures share with it
//! ([`time_figures`], [`scalogram_of`]): time histories and contact activity (whole records and
//! a zoom on the last five periods), RMS response, amplitude ranges and Morlet scalograms.

use std::path::{Path, PathBuf};

use crate::sim::stepped::{StepTrace, TestResult};

use super::{
    Beam, FigureOptions, FrequencyResponse, ReportError, ScalogramOptions, Source, TestCurve,
    TimeHistory, TimeWindow,
};

/// The frequency-response curve of a simulated test.
fn curve(r: &TestResult) -> TestCurve {
    let steps: Vec<(f64, &crate::signal::StepMetrics)> = r
        .steps
        .iter()
        .map(|s| (s.omega_ratio, &s.metrics))
        .collect();
    TestCurve::from_steps(
        &r.spec.name,
        r.spec.level,
        r.spec.direction,
        Source::Simulation,
        &steps,
    )
}

/// A trace as a time history u/(Omega l), time from the start of the record window.
fn history(name: &str, tr: &StepTrace, l: f64) -> TimeHistory {
    let s = 1.0 / (tr.omega * l);
    let t0 = tr.time.first().copied().unwrap_or(0.0);
    TimeHistory {
        name: name.into(),
        source: Source::Simulation,
        omega_ratio: tr.omega_ratio,
        t: tr.time.iter().map(|t| t - t0).collect(),
        upper: tr.velocity_upper.iter().map(|v| v * s).collect(),
        lower: tr.velocity_lower.iter().map(|v| v * s).collect(),
        contact_closed: tr.any_closed.clone(),
        normal_force: tr.normal_force.clone(),
        tangential_force: tr.tangential_force.clone(),
    }
}

/// Time histories and contact activity (whole records and a zoom on their last five
/// excitation periods of length `period`, s) of `histories`; returns the files written.
pub fn time_figures(
    histories: &[TimeHistory],
    period: f64,
    dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    let fig = FigureOptions::default();
    let mut written = Vec::new();
    if histories.is_empty() {
        return Ok(written);
    }
    // Zoom: the last five excitation periods of the shortest record.
    let end = histories
        .iter()
        .filter_map(|h| h.t.last().copied())
        .fold(f64::INFINITY, f64::min);
    let zoom = TimeWindow {
        start: (end - 5.0 * period).max(0.0),
        end,
    };
    for (file, window) in [
        ("time_histories.png", None),
        ("time_histories_zoom.png", Some(zoom)),
    ] {
        let p = dir.join(file);
        crate::report::time_histories(histories, window, &p, &fig)?;
        written.push(p);
    }
    for (file, window) in [
        ("contact_activity.png", None),
        ("contact_activity_zoom.png", Some(zoom)),
    ] {
        let p = dir.join(file);
        match crate::report::contact_activity(histories, window, &p, &fig) {
            Ok(()) => written.push(p),
            // No contact in any record: nothing to draw, which is a result, not an error.
            Err(crate::report::ReportError::NothingToPlot { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(written)
}

/// The figures of a stepped sine; returns the files written.
pub fn stepped_sine_figures(
    results: &[TestResult],
    beam_length: f64,
    dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    let fig = FigureOptions::default();
    let mut written = Vec::new();
    let data = FrequencyResponse {
        tests: results
            .iter()
            .filter(|r| !r.steps.is_empty())
            .map(curve)
            .collect(),
    };
    let p = dir.join("rms_response.png");
    crate::report::rms_response(&data, &p, &fig)?;
    written.push(p);
    for (beam, file) in [
        (Beam::Upper, "amplitude_upper.png"),
        (Beam::Lower, "amplitude_lower.png"),
    ] {
        let p = dir.join(file);
        crate::report::amplitude_range(&data, beam, &p, &fig)?;
        written.push(p);
    }
    let l = beam_length;
    let histories: Vec<TimeHistory> = results
        .iter()
        .filter_map(|r| r.trace.as_ref().map(|tr| history(&r.spec.name, tr, l)))
        .collect();
    let period = results
        .iter()
        .filter_map(|r| r.trace.as_ref())
        .map(|t| 2.0 * std::f64::consts::PI / t.omega)
        .fold(0.0, f64::max);
    written.extend(time_figures(&histories, period, dir)?);
    for r in results {
        let Some(tr) = &r.trace else { continue };
        let p = dir.join(format!("scalogram_{}.png", sanitize(&r.spec.name)));
        scalogram_figure(tr, l, &r.spec.name, &p)?;
        written.push(p);
    }
    Ok(written)
}

/// A test name as a file-name part: ASCII letters, digits and `-` kept, anything else `_`.
pub fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Morlet scalogram of the upper tip velocity u/(Omega l) over the trace (decimated to about
/// 100 samples per excitation period; analysis frequencies 0.2 to 12 x the excitation).
fn scalogram_figure(tr: &StepTrace, l: f64, name: &str, out: &Path) -> Result<(), ReportError> {
    let label = format!(
        "simulation, {name}, upper beam, Omega/omega_2 = {:.3}",
        tr.omega_ratio
    );
    scalogram_of(&tr.velocity_upper, tr.dt, tr.omega, l, &label, out)
}

/// Morlet scalogram of a velocity `v` (m/s, sampled every `dt` s) as u/(Omega l) (decimated
/// to about 100 samples per excitation period; analysis frequencies 0.2 to 12 x the
/// excitation; log10 colour scale over 4 decades).
pub fn scalogram_of(
    v: &[f64],
    dt: f64,
    omega: f64,
    l: f64,
    label: &str,
    out: &Path,
) -> Result<(), ReportError> {
    let f_exc = omega / (2.0 * std::f64::consts::PI);
    let per_period = (2.0 * std::f64::consts::PI / omega / dt).round().max(1.0);
    let decim = ((per_period / 100.0).floor() as usize).max(1);
    let s = 1.0 / (omega * l);
    let x: Vec<f64> = v.iter().step_by(decim).map(|v| v * s).collect();
    let dt = dt * decim as f64;
    let signal = |source| ReportError::Signal {
        path: out.to_path_buf(),
        source,
    };
    let freqs = crate::signal::log_spaced(0.2 * f_exc, 12.0 * f_exc, 120).map_err(signal)?;
    let sc =
        crate::signal::morlet_scalogram(&x, dt, &freqs, &Default::default()).map_err(signal)?;
    crate::report::scalogram(
        &sc,
        f_exc,
        &ScalogramOptions {
            t0: 0.0,
            decades: 4.0,
            label: label.to_string(),
        },
        out,
        &FigureOptions::default(),
    )?;
    Ok(())
}
