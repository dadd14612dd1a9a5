//! The figures of a stepped sine: the virtual stepped sine's (`rigtwin simulate`, the demo)
//! from its results, and the building blocks a recorded session's figures share with it
//! ([`time_figures`], [`scalogram_of`]): time histories and contact activity (whole records and
//! a zoom on five periods holding an impact cluster, [`zoom_window`]), RMS response, amplitude
//! ranges and Morlet scalograms.

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

/// Excitation periods the zoomed time figures show.
pub const ZOOM_PERIODS: f64 = 5.0;

/// The window of the zoomed time figures (time histories and contact activity alike):
/// [`ZOOM_PERIODS`] excitation periods of length `period` (s) within the records' common span
/// that hold the most contact onsets (impacts) of all `histories`, the latest such window on a
/// tie, as the reference zooms into the late span of its record where the impact cluster is.
/// Candidates start every half period back from the end. Records with contact but no onset
/// (held from the start) count closed samples instead. Without contact: the last periods.
pub fn zoom_window(histories: &[TimeHistory], period: f64) -> TimeWindow {
    let end = histories
        .iter()
        .filter_map(|h| h.t.last().copied())
        .fold(f64::INFINITY, f64::min);
    let first = histories
        .iter()
        .filter_map(|h| h.t.first().copied())
        .fold(f64::NEG_INFINITY, f64::max)
        .max(0.0);
    let width = ZOOM_PERIODS * period;
    let last = TimeWindow {
        start: (end - width).max(first),
        end,
    };
    if !(end.is_finite() && width > 0.0 && width.is_finite()) {
        return last;
    }
    let mut onsets = Vec::new();
    let mut closed = Vec::new();
    for h in histories {
        for (i, (&c, &t)) in h.contact_closed.iter().zip(&h.t).enumerate() {
            if c {
                closed.push(t);
                if i > 0 && !h.contact_closed[i - 1] {
                    onsets.push(t);
                }
            }
        }
    }
    let mut events = if onsets.is_empty() { closed } else { onsets };
    if events.is_empty() {
        return last;
    }
    events.sort_by(f64::total_cmp);
    let count = |w: &TimeWindow| {
        events.partition_point(|&t| t <= w.end) - events.partition_point(|&t| t < w.start)
    };
    let (mut best, mut best_count) = (last, count(&last));
    let mut k = 1.0;
    loop {
        let e = end - 0.5 * period * k;
        let w = TimeWindow {
            start: e - width,
            end: e,
        };
        if w.start < first {
            break;
        }
        let n = count(&w);
        if n > best_count {
            (best, best_count) = (w, n);
        }
        k += 1.0;
    }
    best
}

/// Time histories and contact activity (whole records and the zoom of [`zoom_window`], the same
/// window for both) of `histories`, `period` the excitation period, s; returns the files
/// written.
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
    let zoom = zoom_window(histories, period);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of `periods` periods of 1 s at 100 samples per period, closed on `contact`.
    fn record(periods: usize, contact: impl Fn(f64) -> bool) -> TimeHistory {
        let t: Vec<f64> = (0..periods * 100).map(|i| i as f64 * 0.01).collect();
        TimeHistory {
            name: "r".into(),
            source: Source::Simulation,
            omega_ratio: 1.0,
            upper: vec![0.0; t.len()],
            lower: Vec::new(),
            contact_closed: t.iter().map(|&x| contact(x)).collect(),
            normal_force: Vec::new(),
            tangential_force: Vec::new(),
            t,
        }
    }

    /// Contact onsets of `h` inside `w`.
    fn onsets_in(h: &TimeHistory, w: &TimeWindow) -> usize {
        (1..h.t.len())
            .filter(|&i| h.contact_closed[i] && !h.contact_closed[i - 1] && w.contains(h.t[i]))
            .count()
    }

    #[test]
    fn the_zoom_holds_the_impact_cluster_wherever_it_is() {
        // A cluster of impacts (one per period, 0.05 s long) in periods 30..38 of a 100-period
        // record, nothing at its end: the zoom moves onto the cluster.
        let h = record(100, |t| (30.0..38.0).contains(&t) && t.fract() < 0.05);
        let w = zoom_window(std::slice::from_ref(&h), 1.0);
        assert!((w.end - w.start - ZOOM_PERIODS).abs() < 1e-9, "{w:?}");
        assert_eq!(onsets_in(&h, &w), 5, "{w:?}");
        assert!(w.start >= 30.0 - 1e-9 && w.end <= 38.0 + 1.0, "{w:?}");
        // Two equal clusters: the later one (the late span, as the reference zooms).
        let h = record(100, |t| {
            ((10.0..20.0).contains(&t) || (70.0..80.0).contains(&t)) && t.fract() < 0.05
        });
        let w = zoom_window(std::slice::from_ref(&h), 1.0);
        assert!(w.start >= 70.0 - 1e-9, "{w:?}");
        assert_eq!(onsets_in(&h, &w), 5);
        // A single impact anywhere is inside the window.
        for at in [0.5, 42.3, 99.2] {
            let h = record(100, |t| (at..at + 0.03).contains(&t));
            let w = zoom_window(std::slice::from_ref(&h), 1.0);
            let closed =
                h.t.iter()
                    .zip(&h.contact_closed)
                    .any(|(&t, &c)| c && w.contains(t));
            assert!(closed, "impact at {at}: {w:?}");
        }
        // Contact held from the first sample (no onset) still counts.
        let h = record(50, |t| t < 2.0);
        let w = zoom_window(std::slice::from_ref(&h), 1.0);
        assert!(w.start < 2.0, "{w:?}");
    }

    #[test]
    fn without_contact_the_zoom_is_the_last_periods() {
        let h = record(20, |_| false);
        let w = zoom_window(&[h], 1.0);
        assert!(
            (w.end - 19.99).abs() < 1e-9 && (w.start - 14.99).abs() < 1e-9,
            "{w:?}"
        );
    }
}
