//! The per-step summary of a measured stepped sine, computed from the raw counts of the record
//! window. The live session and `rigtwin replay` call the same function on the same counts, so
//! a replay reproduces the live summary bit for bit.
//!
//! From the window: base acceleration = mean of the platform accelerometers; its fundamental /
//! Omega^2 is the measured base amplitude; base velocity by drift-free integration
//! ([`integrate_periodic`]); upper tip velocity relative to the base = vibrometer - base
//! velocity (or the integrated upper-tip acceleration without a vibrometer); lower tip
//! velocity = integral of (lower-tip acceleration - base acceleration); contact = contact
//! voltage below the threshold. The metrics are those of `rigtwin simulate`
//! ([`crate::signal::step_metrics`]), normalised by Omega times the target amplitude.

use crate::rig::channels::ChannelMap;
use crate::rig::DaqLayout;
use crate::signal::{
    demodulate, integrate_periodic, PeriodGrid, SignalError, StepMetrics, StepRecord,
};

/// What the session knew about a step when its record window ended (logged with the
/// `record_end` event, so replay needs nothing else).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StepInfo {
    /// Test name.
    pub test: String,
    /// Step index within the test.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// Omega, rad/s.
    pub omega: f64,
    /// Target fundamental base-displacement amplitude, m.
    pub base_amp_target: f64,
    /// Drive amplitude at the end of the record window, V.
    pub drive_amplitude: f64,
    /// Time from the frequency change to the start of the record window, s.
    pub settle_seconds: f64,
    /// Whether the settle criteria were met (false: recorded after the settle timeout).
    pub settled: bool,
    /// First sample of the record window (DAQ sample index).
    pub record_first_sample: u64,
    /// Samples in the record window.
    pub record_samples: usize,
    /// Contact-voltage threshold used, V.
    pub contact_threshold_v: f64,
    /// Which record window of the step this is (1 = the first; a window whose fundamental
    /// base amplitude misses `[control] record_tolerance` is recorded again).
    #[serde(default = "first_attempt")]
    pub record_attempt: u32,
}

fn first_attempt() -> u32 {
    1
}

impl StepInfo {
    /// One past the last sample of the record window (DAQ sample index).
    pub fn record_end_sample(&self) -> u64 {
        self.record_first_sample + self.record_samples as u64
    }

    /// Rig time of the end of the record window for samples `dt` s apart, s (the log time of
    /// the step's summary and comparisons).
    pub fn record_end_time(&self, dt: f64) -> f64 {
        self.record_end_sample() as f64 * dt
    }
}

/// One step of a measured stepped sine: the metric keys of `rigtwin simulate` plus the
/// control quantities.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StepSummary {
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The metrics of the record window.
    #[serde(flatten)]
    pub metrics: StepMetrics,
    /// Target fundamental base-displacement amplitude, m.
    pub base_amp_target: f64,
    /// Measured fundamental base-displacement amplitude over the record window, m.
    pub base_amp_measured: f64,
    /// Drive amplitude at the end of the record window, V.
    pub drive_amplitude: f64,
    /// Time from the frequency change to the start of the record window, s.
    pub settle_seconds: f64,
    /// Whether the settle criteria were met.
    pub settled: bool,
    /// Rig time of the first recorded sample, s.
    pub record_start_s: f64,
    /// Which record window of the step this is (1 = the first; see
    /// [`StepInfo::record_attempt`]).
    #[serde(default = "first_attempt")]
    pub record_attempt: u32,
}

/// Errors of a step summary.
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// A channel the summary needs is not in the layout.
    #[error("the DAQ layout has no {0} channel")]
    MissingChannel(&'static str),
    /// The window's counts do not match the layout.
    #[error("record window of step {step} of test {test}: {counts} counts for {channels} channels x {samples} samples")]
    Shape {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// Counts given.
        counts: usize,
        /// Channels in the layout.
        channels: usize,
        /// Samples expected.
        samples: usize,
    },
    /// The signal processing failed (e.g. a window shorter than a period).
    #[error("step {step} of test {test}: {source}")]
    Signal {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// What failed.
        source: SignalError,
    },
}

/// The physical signals of a record window, as the summary uses them.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowSignals {
    /// Sample interval, s.
    pub dt: f64,
    /// Base acceleration (mean of the platform accelerometers), m/s^2.
    pub base_acceleration: Vec<f64>,
    /// Upper tip velocity relative to the base, m/s.
    pub upper: Vec<f64>,
    /// Lower tip velocity relative to the base, m/s.
    pub lower: Vec<f64>,
    /// Contact closed per sample.
    pub closed: Vec<bool>,
}

/// The physical signals of a record window from its counts (channel-major:
/// `counts[k * n + i]`, `n = info.record_samples`). See the module docs.
pub fn window_signals(
    layout: &DaqLayout,
    info: &StepInfo,
    counts: &[i32],
) -> Result<WindowSignals, SummaryError> {
    let n = info.record_samples;
    let nch = layout.channels.len();
    if counts.len() != n * nch {
        return Err(SummaryError::Shape {
            test: info.test.clone(),
            step: info.step,
            counts: counts.len(),
            channels: nch,
            samples: n,
        });
    }
    let sig = |source| SummaryError::Signal {
        test: info.test.clone(),
        step: info.step,
        source,
    };
    let values = |k: usize| -> Vec<f64> {
        let ch = &layout.channels[k];
        counts[k * n..(k + 1) * n]
            .iter()
            .map(|&c| ch.value(c))
            .collect()
    };
    let map = ChannelMap::of(layout);
    if map.platform.is_empty() {
        return Err(SummaryError::MissingChannel("platform acceleration"));
    }
    let a_base: Vec<f64> = (0..n)
        .map(|i| map.base_acceleration(counts, n, i))
        .collect();

    let dt = layout.dt();
    let grid = PeriodGrid::new(n, dt, info.omega).map_err(sig)?;
    let v_base = integrate_periodic(&a_base, dt, &grid).map_err(sig)?;
    let relative_velocity = |k: usize| -> Result<Vec<f64>, SummaryError> {
        let rel: Vec<f64> = values(k).iter().zip(&a_base).map(|(a, b)| a - b).collect();
        integrate_periodic(&rel, dt, &grid).map_err(sig)
    };
    let upper = match map.vibrometer {
        Some(k) => values(k).iter().zip(&v_base).map(|(v, b)| v - b).collect(),
        None => relative_velocity(
            map.upper_tip
                .ok_or(SummaryError::MissingChannel("upper_tip acceleration"))?,
        )?,
    };
    let k_lower = map
        .lower_tip
        .ok_or(SummaryError::MissingChannel("lower_tip acceleration"))?;
    let lower = relative_velocity(k_lower)?;
    let k_contact = map
        .contact_voltage
        .ok_or(SummaryError::MissingChannel("contact voltage"))?;
    let closed: Vec<bool> = values(k_contact)
        .iter()
        .map(|&v| v < info.contact_threshold_v)
        .collect();
    Ok(WindowSignals {
        dt,
        base_acceleration: a_base,
        upper,
        lower,
        closed,
    })
}

/// The step summary from the record window's counts (channel-major: `counts[k * n + i]`,
/// `n = info.record_samples`).
pub fn summarize(
    layout: &DaqLayout,
    info: &StepInfo,
    counts: &[i32],
) -> Result<StepSummary, SummaryError> {
    let w = window_signals(layout, info, counts)?;
    let sig = |source| SummaryError::Signal {
        test: info.test.clone(),
        step: info.step,
        source,
    };
    let omega = info.omega;
    let h = demodulate(&w.base_acceleration, w.dt, omega, 0.0).map_err(sig)?;
    let base_amp_measured = h.magnitude / (omega * omega);
    let metrics = StepRecord {
        dt: w.dt,
        omega,
        base_level: info.base_amp_target,
        tip_velocity_upper: &w.upper,
        tip_velocity_lower: &w.lower,
        contact_closed: &w.closed,
        normal_force: None,
    }
    .metrics()
    .map_err(sig)?;
    Ok(StepSummary {
        omega_ratio: info.omega_ratio,
        metrics,
        base_amp_target: info.base_amp_target,
        base_amp_measured,
        drive_amplitude: info.drive_amplitude,
        settle_seconds: info.settle_seconds,
        settled: info.settled,
        record_start_s: info.record_first_sample as f64 * w.dt,
        record_attempt: info.record_attempt,
    })
}
