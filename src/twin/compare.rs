//! The twin against the measurement, step by step: the twin's predicted channels over each
//! record window go through the same metrics as the measured ones ([`crate::signal`]), and the
//! differences are reported ([`TwinComparison`], `tests[].steps[].twin` of a session summary).
//!
//! [`TwinWindows`] collects the twin's output samples and cuts the record windows out of them
//! (the live twin and the twin replay alike).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::control::{StepInfo, StepSummary};
use crate::signal::{
    integrate_periodic, spectrum_distance_db, PeriodGrid, SignalError, StepMetrics, StepRecord,
};
// The lower and upper tip's indices in the twin's sensors (`TWIN_SENSORS`).
use crate::sim::driven::{LOWER_TIP, UPPER_TIP};

use super::observe::TipObservation;
use super::TwinBlock;

/// The twin over one record window, against the measurement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinComparison {
    /// The twin's metrics over the window (the measurement's keys).
    #[serde(flatten)]
    pub metrics: StepMetrics,
    /// `rms_upper(twin) / rms_upper(measured) - 1`, -.
    pub rms_error_upper: f64,
    /// `rms_lower(twin) / rms_lower(measured) - 1`, -.
    pub rms_error_lower: f64,
    /// `contact_fraction(twin) - contact_fraction(measured)`, -.
    pub contact_fraction_error: f64,
    /// `impacts_per_period(twin) - impacts_per_period(measured)`, -.
    pub impacts_per_period_error: f64,
    /// Log-spectral distance of the twin's upper-tip band spectrum from the measurement's,
    /// dB ([`crate::signal::spectrum_distance_db`]: RMS over the half-harmonic bands up to
    /// 10 Omega of the level difference, floor 60 dB below the measurement's strongest band);
    /// `None` when the measurement's spectrum is empty (a summary written before spectra
    /// were measured).
    #[serde(default)]
    pub spectrum_distance_db: Option<f64>,
}

/// The twin's output samples from `first` on, to cut record windows from.
#[derive(Debug)]
pub struct TwinWindows {
    /// How the step summary sees the upper and lower tip (sensor sensitivities).
    observe: [TipObservation; 2],
    first: u64,
    base: VecDeque<f64>,
    upper: VecDeque<f64>,
    lower: VecDeque<f64>,
    contact: VecDeque<bool>,
    normal: VecDeque<f64>,
    /// Sample ranges `[from, to)` the twin did not see (input gaps).
    gaps: Vec<(u64, u64)>,
}

impl Default for TwinWindows {
    /// Windows for nominal sensors.
    fn default() -> Self {
        TwinWindows::new(TipObservation::IDENTITY, TipObservation::IDENTITY)
    }
}

impl TwinWindows {
    /// Windows whose upper and lower tip velocities the step summary sees through `upper` and
    /// `lower` (see [`super::observe`]).
    pub fn new(upper: TipObservation, lower: TipObservation) -> TwinWindows {
        TwinWindows {
            observe: [upper, lower],
            first: 0,
            base: VecDeque::new(),
            upper: VecDeque::new(),
            lower: VecDeque::new(),
            contact: VecDeque::new(),
            normal: VecDeque::new(),
            gaps: Vec::new(),
        }
    }

    /// Appends a twin output block (blocks in sample order).
    pub fn push(&mut self, b: &TwinBlock) {
        if let Some(g) = &b.gap {
            self.gaps.push((g.from_sample, g.from_sample + g.samples));
        }
        if self.upper.is_empty() {
            self.first = b.first_sample;
        } else {
            let end = self.first + self.upper.len() as u64;
            if b.first_sample > end {
                // Samples the twin never produced: pad so indices stay aligned, and mark them.
                self.gaps.push((end, b.first_sample));
                let pad = (b.first_sample - end) as usize;
                self.base.extend(std::iter::repeat_n(f64::NAN, pad));
                self.upper.extend(std::iter::repeat_n(f64::NAN, pad));
                self.lower.extend(std::iter::repeat_n(f64::NAN, pad));
                self.contact.extend(std::iter::repeat_n(false, pad));
                self.normal.extend(std::iter::repeat_n(f64::NAN, pad));
            }
        }
        self.base.extend(&b.base_acceleration);
        self.upper.extend(b.sensor(UPPER_TIP));
        self.lower.extend(b.sensor(LOWER_TIP));
        self.contact.extend(&b.contact);
        self.normal.extend(&b.normal_force);
    }

    /// One past the last sample held.
    pub fn end(&self) -> u64 {
        self.first + self.upper.len() as u64
    }

    /// Drops the samples before `sample`.
    pub fn trim(&mut self, sample: u64) {
        let n = (sample.saturating_sub(self.first) as usize).min(self.upper.len());
        self.base.drain(..n);
        self.upper.drain(..n);
        self.lower.drain(..n);
        self.contact.drain(..n);
        self.normal.drain(..n);
        self.first += n as u64;
        self.gaps.retain(|&(_, to)| to > self.first);
    }

    /// The twin over the record window of `info` (samples `dt` s apart), against `measured`:
    /// `None` while the window is not complete, or when the twin missed samples of it (an
    /// input gap).
    pub fn compare(
        &self,
        info: &StepInfo,
        measured: &StepSummary,
        dt: f64,
    ) -> Option<Result<TwinComparison, crate::signal::SignalError>> {
        let (from, to) = (info.record_first_sample, info.record_end_sample());
        if from < self.first || to > self.end() {
            return None;
        }
        if self.gaps.iter().any(|&(a, b)| a < to && b > from) {
            return None;
        }
        let range = (from - self.first) as usize..(to - self.first) as usize;
        let mut upper: Vec<f64> = self.upper.range(range.clone()).copied().collect();
        let mut lower: Vec<f64> = self.lower.range(range.clone()).copied().collect();
        if !self.observe.iter().all(TipObservation::is_identity) {
            let base: Vec<f64> = self.base.range(range.clone()).copied().collect();
            if let Err(e) = observe_tips(
                &self.observe,
                &base,
                dt,
                info.omega,
                [&mut upper, &mut lower],
            ) {
                return Some(Err(e));
            }
        }
        let contact: Vec<bool> = self.contact.range(range.clone()).copied().collect();
        let normal: Vec<f64> = self.normal.range(range).copied().collect();
        let metrics = StepRecord {
            dt,
            omega: info.omega,
            base_level: info.base_amp_target,
            tip_velocity_upper: &upper,
            tip_velocity_lower: &lower,
            contact_closed: &contact,
            normal_force: Some(&normal),
        }
        .metrics();
        Some(metrics.map(|m| compare(m, &measured.metrics)))
    }
}

/// A completed record window: the step, and the twin over it (`None`: the twin missed part
/// of the window; `Err`: its metrics failed).
pub type Completed = (
    StepInfo,
    Option<Result<TwinComparison, crate::signal::SignalError>>,
);

impl TwinWindows {
    /// Takes the windows at the front of `pending` (record windows in order, with the
    /// measurement's summary) that the output covers — all of them when `all` — and compares
    /// each; then drops the output no longer needed: everything before the next pending window,
    /// or, with none pending, all but the last 30 s (the twin may run ahead of the session's
    /// record-window events; no record window is that long).
    pub fn complete(
        &mut self,
        pending: &mut VecDeque<(StepInfo, StepSummary)>,
        dt: f64,
        all: bool,
    ) -> Vec<Completed> {
        let mut done = Vec::new();
        while let Some((info, _)) = pending.front() {
            let end = info.record_end_sample();
            if !all && end > self.end() {
                break;
            }
            let (info, measured) = pending.pop_front().expect("front");
            let c = self.compare(&info, &measured, dt);
            done.push((info, c));
            self.trim(end);
        }
        let keep = match pending.front() {
            Some((info, _)) => info.record_first_sample,
            None => self.end().saturating_sub((30.0 / dt) as u64),
        };
        self.trim(keep);
        done
    }
}

/// Applies the tip observations to the window's relative velocities, with the base velocity
/// integrated from `base` (m/s^2) over whole periods like the step summary does.
fn observe_tips(
    observe: &[TipObservation; 2],
    base: &[f64],
    dt: f64,
    omega: f64,
    tips: [&mut Vec<f64>; 2],
) -> Result<(), SignalError> {
    let grid = PeriodGrid::new(base.len(), dt, omega)?;
    let v_base = integrate_periodic(base, dt, &grid)?;
    for (o, v) in observe.iter().zip(tips) {
        for (x, vb) in v.iter_mut().zip(&v_base) {
            *x = o.gain * *x + o.base_weight * vb;
        }
    }
    Ok(())
}

fn compare(twin: StepMetrics, measured: &StepMetrics) -> TwinComparison {
    TwinComparison {
        rms_error_upper: twin.rms_upper / measured.rms_upper - 1.0,
        rms_error_lower: twin.rms_lower / measured.rms_lower - 1.0,
        contact_fraction_error: twin.contact_fraction - measured.contact_fraction,
        impacts_per_period_error: twin.impacts_per_period - measured.impacts_per_period,
        spectrum_distance_db: Some(spectrum_distance_db(
            &twin.spectrum_upper,
            &measured.spectrum_upper,
        ))
        .filter(|d| d.is_finite()),
        metrics: twin,
    }
}
