//! The evidence of every record window of a recording, computed once for all estimators: the
//! fundamental complex amplitude of every DAQ channel, of the base acceleration and of both
//! tips' velocities relative to the base, the relative tip displacement's extremes and the
//! contact state. The physical signals come from the session's own
//! [`crate::control::window_signals`] (base acceleration = mean of the platform
//! accelerometers, relative velocities by drift-free integration), so the diagnosis sees the
//! measurement exactly as the session summary does; sensor-gain corrections divide a
//! channel's sensitivity before anything is combined.

use rustfft::num_complex::Complex64;

use crate::control::{window_signals, EventKind, StepInfo};
use crate::rig::channels::platform_accelerometers;
use crate::rig::DaqLayout;
use crate::session::replay::{window_counts, Recording};
use crate::signal::{demodulate, integrate_periodic, Demodulator, Harmonic, PeriodGrid};

use super::error::EvidenceError;

/// A test of the session, as its `test_start` event announced it.
#[derive(Clone, Debug, PartialEq)]
pub struct TestRecord {
    /// Test name.
    pub name: String,
    /// Base level / l (the plan's target).
    pub level: f64,
    /// `up` or `down`.
    pub direction: String,
    /// The plan's clearance / l (what the model assumes, not a measurement).
    pub plan_clearance: f64,
}

/// What one record window shows.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowEvidence {
    /// Test name.
    pub test: String,
    /// Index of the test in [`SessionEvidence::tests`] (session order).
    pub test_index: usize,
    /// Step index within the test.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// Omega, rad/s.
    pub omega: f64,
    /// Target fundamental base-displacement amplitude, m.
    pub base_amp_target: f64,
    /// Rig time of the window's first sample, s.
    pub record_start_s: f64,
    /// Fundamental complex amplitude of every layout channel, physical units (layout order;
    /// `x = Re(X e^{i Omega t})`, t from the window's first sample).
    pub channels: Vec<Complex64>,
    /// Fundamental of the base acceleration, m/s^2.
    pub base_acceleration: Complex64,
    /// Fundamental of the upper tip's velocity relative to the base, m/s.
    pub upper_velocity: Complex64,
    /// Fundamental of the lower tip's velocity relative to the base, m/s.
    pub lower_velocity: Complex64,
    /// Fundamental of the base acceleration per whole period of the window, m/s^2.
    pub base_periods: Vec<Complex64>,
    /// Fundamental of the upper tip's relative velocity per whole period, m/s.
    pub upper_periods: Vec<Complex64>,
    /// Fundamental of the lower tip's relative velocity per whole period, m/s.
    pub lower_periods: Vec<Complex64>,
    /// Largest closing excursion over the window, m: `max(-(x_upper - x_lower))` of the tip
    /// displacements relative to the base (drift-free integrals of the relative velocities,
    /// zero mean over the window). The tips close the clearance when it reaches it.
    pub closing_peak: f64,
    /// The closing displacement `-(x_upper - x_lower)` (as in [`Self::closing_peak`]) at every
    /// contact onset of the window (a closed sample after an open one, contact-resistance
    /// channel), m, in time order: the tips' closing when the probes met. Empty without one.
    pub closing_at_onsets: Vec<f64>,
    /// Share of the window's samples with the contact closed (contact-resistance channel
    /// below the threshold), -.
    pub contact_fraction: f64,
}

impl WindowEvidence {
    /// Fundamental of the relative tip displacement upper - lower, m.
    pub fn relative_displacement(&self) -> Complex64 {
        (self.upper_velocity - self.lower_velocity) / Complex64::new(0.0, self.omega)
    }

    /// Whether the contact stayed open over the whole window.
    pub fn impact_free(&self) -> bool {
        self.contact_fraction == 0.0
    }
}

/// The evidence of a recording: its tests and the evidence of every complete record window,
/// in session order.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionEvidence {
    /// Layout channel names, in layout order (the order of [`WindowEvidence::channels`]).
    pub channel_names: Vec<String>,
    /// Indices of the platform accelerometers in the layout (the base), in layout order.
    pub platform: Vec<usize>,
    /// The tests, in session order.
    pub tests: Vec<TestRecord>,
    /// The complete record windows, in session order.
    pub windows: Vec<WindowEvidence>,
    /// Record windows whose counts are not in the recording (damaged or cut log), as
    /// `test step N` (1-based steps).
    pub incomplete: Vec<String>,
    /// The sensor-gain corrections applied (channel, true over nominal sensitivity).
    pub gain_corrections: Vec<(String, f64)>,
}

impl SessionEvidence {
    /// Index of the channel `name` in [`WindowEvidence::channels`].
    pub fn channel(&self, name: &str) -> Option<usize> {
        self.channel_names.iter().position(|n| n == name)
    }
}

fn phasor(h: &Harmonic) -> Complex64 {
    Complex64::new(h.cos, -h.sin)
}

/// The layout with every corrected channel's sensitivity divided out: a channel recording
/// `gain` times the physical value reads `count * scale / gain`.
fn corrected_layout(
    layout: &DaqLayout,
    gains: &[(String, f64)],
) -> Result<DaqLayout, EvidenceError> {
    let mut out = layout.clone();
    for (name, g) in gains {
        let k = layout
            .index(name)
            .ok_or_else(|| EvidenceError::UnknownChannel {
                channel: name.clone(),
            })?;
        if !(g.is_finite() && *g > 0.0) {
            return Err(EvidenceError::BadGain {
                channel: name.clone(),
                gain: *g,
            });
        }
        out.channels[k].scale /= g;
    }
    Ok(out)
}

/// The evidence of one record window.
fn window_evidence(
    layout: &DaqLayout,
    info: &StepInfo,
    counts: &[i32],
    test_index: usize,
) -> Result<WindowEvidence, EvidenceError> {
    let w = window_signals(layout, info, counts)?;
    let n = info.record_samples;
    let signal = |source| crate::control::summary::SummaryError::Signal {
        test: info.test.clone(),
        step: info.step,
        source,
    };
    let demod = |x: &[f64]| -> Result<Complex64, EvidenceError> {
        Ok(phasor(
            &demodulate(x, w.dt, info.omega, 0.0).map_err(signal)?,
        ))
    };
    let channels = layout
        .channels
        .iter()
        .enumerate()
        .map(|(k, ch)| {
            let x: Vec<f64> = counts[k * n..(k + 1) * n]
                .iter()
                .map(|&c| ch.value(c))
                .collect();
            demod(&x)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let per_period = |x: &[f64]| -> Result<Vec<Complex64>, EvidenceError> {
        let mut d = Demodulator::new(info.omega, w.dt, 0.0).map_err(signal)?;
        Ok(x.iter()
            .filter_map(|&v| d.push(v))
            .map(|p| phasor(&p.harmonic))
            .collect())
    };
    let grid = PeriodGrid::new(n, w.dt, info.omega).map_err(signal)?;
    let xu = integrate_periodic(&w.upper, w.dt, &grid).map_err(signal)?;
    let xl = integrate_periodic(&w.lower, w.dt, &grid).map_err(signal)?;
    // Over the whole periods only (the samples the integrals' line fit saw).
    let used = grid.used_samples();
    let closing_peak = xu[..used]
        .iter()
        .zip(&xl[..used])
        .map(|(u, l)| l - u)
        .fold(f64::NEG_INFINITY, f64::max);
    let closing_at_onsets = (1..used)
        .filter(|&i| w.closed[i] && !w.closed[i - 1])
        .map(|i| xl[i] - xu[i])
        .collect();
    let closed = w.closed.iter().filter(|&&c| c).count();
    Ok(WindowEvidence {
        test: info.test.clone(),
        test_index,
        step: info.step,
        omega_ratio: info.omega_ratio,
        omega: info.omega,
        base_amp_target: info.base_amp_target,
        record_start_s: info.record_first_sample as f64 * w.dt,
        channels,
        base_acceleration: demod(&w.base_acceleration)?,
        upper_velocity: demod(&w.upper)?,
        lower_velocity: demod(&w.lower)?,
        base_periods: per_period(&w.base_acceleration)?,
        upper_periods: per_period(&w.upper)?,
        lower_periods: per_period(&w.lower)?,
        closing_peak,
        closing_at_onsets,
        contact_fraction: closed as f64 / n as f64,
    })
}

/// The evidence of every record window of `rec`, with the sensor sensitivities `gains`
/// (channel, true over nominal) divided out (empty: as recorded).
///
/// Errors: no record window ([`EvidenceError::NoRecordWindows`]), none complete in the
/// blocks, an unknown channel or a bad gain in `gains`, a window whose signals cannot be
/// computed (a missing channel role, a window shorter than a period).
pub fn session_evidence(
    rec: &Recording,
    gains: &[(String, f64)],
) -> Result<SessionEvidence, EvidenceError> {
    let layout = corrected_layout(&rec.layout, gains)?;
    let mut tests: Vec<TestRecord> = Vec::new();
    let mut windows = Vec::new();
    let mut incomplete = Vec::new();
    let mut named = 0usize;
    for e in &rec.events {
        match &e.kind {
            EventKind::TestStart {
                test,
                level,
                direction,
                clearance,
            } => tests.push(TestRecord {
                name: test.clone(),
                level: *level,
                direction: direction.clone(),
                plan_clearance: *clearance,
            }),
            EventKind::RecordEnd { info } => {
                named += 1;
                let test_index = match tests.iter().rposition(|t| t.name == info.test) {
                    Some(i) => i,
                    None => {
                        // A log cut before the test_start event: the test is known by name.
                        tests.push(TestRecord {
                            name: info.test.clone(),
                            level: f64::NAN,
                            direction: String::new(),
                            plan_clearance: f64::NAN,
                        });
                        tests.len() - 1
                    }
                };
                match window_counts(rec, info) {
                    Some(counts) => {
                        windows.push(window_evidence(&layout, info, &counts, test_index)?)
                    }
                    None => incomplete.push(format!("{} step {}", info.test, info.step + 1)),
                }
            }
            _ => {}
        }
    }
    if named == 0 {
        return Err(EvidenceError::NoRecordWindows);
    }
    if windows.is_empty() {
        return Err(EvidenceError::NoCompleteWindows { windows: named });
    }
    Ok(SessionEvidence {
        channel_names: rec.layout.channels.iter().map(|c| c.name.clone()).collect(),
        platform: platform_accelerometers(&rec.layout)
            .into_iter()
            .map(|(k, _)| k)
            .collect(),
        tests,
        windows,
        incomplete,
        gain_corrections: gains.to_vec(),
    })
}
