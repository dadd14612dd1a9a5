//! The twin against the measurement, step by step: the twin's predicted channels over each
//! record window go through the same metrics as the measured ones ([`crate::signal`]), and the
//! differences are reported ([`TwinComparison`], `tests[].steps[].twin` of a session summary).
//!
//! [`TwinWindows`] collects the twin's output samples and cuts the record windows out of them;
//! [`replay_twin`] runs the twin over a recorded session (deterministic: the same recording
//! and model give the same bits).
//!
//! Clearance schedule: a test's clearance applies from the first DAQ block that starts at or
//! after the sample of its `test_start` event — in the live session the event is logged
//! after the block that ended the previous test, and the simulated rig changes its clearance
//! from the next block, so live and replay cut at the same place.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::control::{EventKind, SessionSummary, StepInfo, StepSummary};
use crate::log::replay::Recording;
use crate::rom::Rom;
use crate::signal::{spectrum_distance_db, StepMetrics, StepRecord};

use super::{Twin, TwinBlock, TwinError, TwinSpec};

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

/// Index of the lower and upper tip in the twin's sensors ([`super::TWIN_SENSORS`]).
const LOWER_TIP: usize = 0;
const UPPER_TIP: usize = crate::rig::sim::truth::UPPER_TIP;

/// The twin's output samples from `first` on, to cut record windows from.
#[derive(Debug, Default)]
pub struct TwinWindows {
    first: u64,
    upper: VecDeque<f64>,
    lower: VecDeque<f64>,
    contact: VecDeque<bool>,
    normal: VecDeque<f64>,
    /// Sample ranges `[from, to)` the twin did not see (input gaps).
    gaps: Vec<(u64, u64)>,
}

impl TwinWindows {
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
                self.upper.extend(std::iter::repeat_n(f64::NAN, pad));
                self.lower.extend(std::iter::repeat_n(f64::NAN, pad));
                self.contact.extend(std::iter::repeat_n(false, pad));
                self.normal.extend(std::iter::repeat_n(f64::NAN, pad));
            }
        }
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
        let (from, to) = (
            info.record_first_sample,
            info.record_first_sample + info.record_samples as u64,
        );
        if from < self.first || to > self.end() {
            return None;
        }
        if self.gaps.iter().any(|&(a, b)| a < to && b > from) {
            return None;
        }
        let range = (from - self.first) as usize..(to - self.first) as usize;
        let upper: Vec<f64> = self.upper.range(range.clone()).copied().collect();
        let lower: Vec<f64> = self.lower.range(range.clone()).copied().collect();
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
            let end = info.record_first_sample + info.record_samples as u64;
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

/// What a twin replay did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwinReplayStats {
    /// Blocks the twin ran through.
    pub blocks: u64,
    /// Steps compared.
    pub steps_compared: usize,
    /// Contact-solver failures over the session.
    pub solver_failures: u64,
    /// Twin seconds of computation per second of rig time, -.
    pub wall_per_rig_second: f64,
}

/// Where a twin replay's output goes besides the summary (e.g. a copy of the session log,
/// [`super::TwinLogCopy`]). `()` keeps nothing.
pub trait TwinSink {
    /// The twin's prediction for one block, in block order.
    fn block(&mut self, block: &TwinBlock) -> Result<(), TwinError>;
    /// A step's comparison as its record window completes (`None`: the twin missed part of
    /// the window).
    fn step(&mut self, info: &StepInfo, twin: Option<&TwinComparison>) -> Result<(), TwinError>;
}

impl TwinSink for () {
    fn block(&mut self, _: &TwinBlock) -> Result<(), TwinError> {
        Ok(())
    }
    fn step(&mut self, _: &StepInfo, _: Option<&TwinComparison>) -> Result<(), TwinError> {
        Ok(())
    }
}

/// Runs the twin (ROM `rom`, settings `spec`, beam length `beam_length` m for the plan's
/// clearances) over the recording `rec` and writes each step's comparison into `summary`
/// (`tests[].steps[].twin`, in the order of the recording's record windows; `summary` is the
/// replayed summary of the same recording). Every output block and comparison also goes to
/// `sink`.
pub fn replay_twin(
    rec: &Recording,
    summary: &mut SessionSummary,
    rom: &Rom,
    spec: &TwinSpec,
    beam_length: f64,
    sink: &mut dyn TwinSink,
) -> Result<TwinReplayStats, TwinError> {
    let wall = std::time::Instant::now();
    let mut clearances: VecDeque<(u64, f64)> = VecDeque::new();
    let mut infos: Vec<StepInfo> = Vec::new();
    for e in &rec.events {
        match &e.kind {
            EventKind::TestStart { clearance, .. } => {
                clearances.push_back((e.sample, clearance * beam_length))
            }
            EventKind::RecordEnd { info } => infos.push(info.clone()),
            _ => {}
        }
    }
    let first_clearance = clearances.front().map_or(0.0, |c| c.1);
    let mut twin = Twin::new(rom, spec, &rec.layout, first_clearance)?;
    let dt = rec.layout.dt();
    // The measured step summaries are in record-window order.
    let mut pending: VecDeque<(StepInfo, StepSummary)> =
        infos.into_iter().zip(summary.steps().cloned()).collect();
    let mut results: Vec<Option<TwinComparison>> = Vec::new();
    let mut out = TwinWindows::default();
    let mut stats = TwinReplayStats::default();
    let take = |done: Vec<Completed>,
                results: &mut Vec<Option<TwinComparison>>,
                sink: &mut dyn TwinSink|
     -> Result<(), TwinError> {
        for (info, c) in done {
            let c = match c {
                Some(Ok(c)) => Some(c),
                Some(Err(e)) => {
                    return Err(TwinError::Metrics(format!(
                        "metrics of step {} of test {}: {e}",
                        info.step, info.test
                    )))
                }
                None => None,
            };
            sink.step(&info, c.as_ref())?;
            results.push(c);
        }
        Ok(())
    };
    for b in &rec.blocks {
        while let Some(&(sample, c)) = clearances.front() {
            if sample > b.first_sample {
                break;
            }
            twin.set_clearance(c)?;
            clearances.pop_front();
        }
        let tb = twin.push_block(b)?;
        stats.blocks += 1;
        stats.solver_failures += tb
            .solver_failures
            .iter()
            .map(|&f| u64::from(f))
            .sum::<u64>();
        sink.block(&tb)?;
        out.push(&tb);
        take(out.complete(&mut pending, dt, false), &mut results, sink)?;
    }
    take(out.complete(&mut pending, dt, true), &mut results, sink)?;
    stats.steps_compared = summary.attach_twin(results);
    let rig = rec
        .blocks
        .last()
        .map_or(0.0, |b| b.time + b.len as f64 / rec.layout.sample_rate);
    stats.wall_per_rig_second = wall.elapsed().as_secs_f64() / rig.max(f64::MIN_POSITIVE);
    Ok(stats)
}
