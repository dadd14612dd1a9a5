//! The twin against the measurement, step by step: the twin's predicted channels over each
//! record window go through the same metrics as the measured ones ([`crate::signal`]), and the
//! differences are reported ([`TwinComparison`], `tests[].steps[].twin` of a session summary).
//!
//! [`TwinWindows`] collects the twin's output samples and cuts the record windows out of them
//! (the live twin and the twin replay alike).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::control::summary::COMPARED_CHANNELS;
use crate::control::{StepInfo, StepSummary};
use crate::rig::channels::{
    LOWER_TIP as LOWER_TIP_CHANNEL, UPPER_MID as UPPER_MID_CHANNEL, UPPER_TIP as UPPER_TIP_CHANNEL,
    VIBROMETER,
};
use crate::signal::features::CONTACT_CHANNEL;
use crate::signal::{
    add_white_noise, ensemble_features, integrate_periodic, spectrum_distance_db, window_features,
    Feature, FeatureWindow, NoiseFloor, PeriodGrid, SignalError, StepMetrics, StepRecord,
};
// The lower and upper tip's indices in the twin's sensors (`TWIN_SENSORS`).
use crate::sim::driven::{LOWER_MID, LOWER_TIP, UPPER_MID, UPPER_TIP};

use super::observe::{Observation, TipObservation};
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
    /// Every compared feature of every channel the measurement has, with the measurement's
    /// and the model's spread and the score ([`FeatureComparison`]); empty in summaries
    /// written before they existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub features: Vec<FeatureComparison>,
    /// The largest score of `features` (`None` without features).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_score: Option<f64>,
    /// Runs of the model from perturbed initial states behind the model spread besides the
    /// twin's own run ([`TwinComparison::with_ensemble`]); 0: the model spread is that of the
    /// twin's own sub-windows.
    #[serde(default)]
    pub ensemble_members: usize,
    /// The measurement's noise floor laid on the model's channels before their features were
    /// taken ([`crate::signal::noise`]); empty when the measurement has none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub observation_noise: Vec<NoiseFloor>,
    /// Whether the model spreads carry the discretisation member's difference
    /// ([`TwinComparison::with_discretisation`], `[twin.discretisation]`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub discretisation_member: bool,
}

/// One compared feature of one channel: the measurement and the model, each with its spread
/// ([`crate::signal::features`]), and how far apart they are in units of the combined spread.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FeatureComparison {
    /// The channel (`vibrometer`, `upper_tip`, `upper_mid`, `lower_tip`, `lower_mid`,
    /// `contact`).
    pub channel: String,
    /// The feature (`rms`, `amp_p10`, `amp_p50`, `amp_p90`; `contact_fraction`,
    /// `impacts_per_period`).
    pub feature: String,
    /// The measured value (velocities normalised by `Omega q`), -.
    pub measured: f64,
    /// Its spread from the record window's sub-windows; `None` for a window too short.
    pub measured_spread: Option<f64>,
    /// The model's value (the twin as it ran).
    pub model: f64,
    /// Its spread: the twin's sub-windows, and the ensemble's scatter when there is one.
    pub model_spread: Option<f64>,
    /// `|model - measured| / sqrt(measured_spread^2 + model_spread^2 + tolerance^2)`, with
    /// the comparison's tolerance ([`ComparisonTolerance`]).
    pub score: f64,
}

pub use crate::config::twin::ComparisonTolerance;

/// The features of the measurement against the model's, matched by channel and feature
/// (a feature one side lacks is left out).
fn score(
    measured: &[Feature],
    model: &[Feature],
    tolerance: &ComparisonTolerance,
) -> Vec<FeatureComparison> {
    measured
        .iter()
        .filter_map(|m| {
            let x = model
                .iter()
                .find(|x| x.channel == m.channel && x.feature == m.feature)?;
            Some(FeatureComparison::scored(m, x, tolerance))
        })
        .collect()
}

impl FeatureComparison {
    /// The measured feature `m` against the model's `x` (the same channel and feature).
    fn scored(m: &Feature, x: &Feature, tolerance: &ComparisonTolerance) -> FeatureComparison {
        let t = tolerance.of(&m.feature, m.value, x.value);
        let var = m.spread.unwrap_or(0.0).powi(2) + x.spread.unwrap_or(0.0).powi(2) + t * t;
        let diff = (x.value - m.value).abs();
        let score = if var > 0.0 {
            diff / var.sqrt()
        } else if diff == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
        FeatureComparison {
            channel: m.channel.clone(),
            feature: m.feature.clone(),
            measured: m.value,
            measured_spread: m.spread,
            model: x.value,
            model_spread: x.spread,
            score,
        }
    }

    /// This comparison with another run's model value `model` in its place, both spreads
    /// kept: another draw of the same model scored against this comparison's spreads (an
    /// ensemble's scatter is the model's, not one run's).
    pub fn with_model_value(
        &self,
        model: f64,
        tolerance: &ComparisonTolerance,
    ) -> FeatureComparison {
        let feature = |value, spread| Feature {
            channel: self.channel.clone(),
            feature: self.feature.clone(),
            value,
            spread,
        };
        FeatureComparison::scored(
            &feature(self.measured, self.measured_spread),
            &feature(model, self.model_spread),
            tolerance,
        )
    }
}

/// The seed of the noise laid on the model's channel `channel` over the record window of
/// `info`: the window's place in the session and the channel, nothing of the run.
fn observation_seed(info: &StepInfo, channel: &str) -> u64 {
    let k = COMPARED_CHANNELS
        .iter()
        .position(|c| *c == channel)
        .unwrap_or(COMPARED_CHANNELS.len()) as u64;
    info.record_first_sample
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(k + 1)
}

/// The largest score (NaN scores, from broken windows, count as the largest).
fn max_score(features: &[FeatureComparison]) -> Option<f64> {
    features.iter().map(|f| f.score).reduce(|a, b| {
        if a.is_nan() || b.is_nan() {
            f64::NAN
        } else {
            a.max(b)
        }
    })
}

impl TwinComparison {
    /// The comparison with the model spread of an ensemble: `members` are the features of
    /// runs of the model over the same window from perturbed initial states
    /// ([`TwinWindows::features`]); each feature's model spread becomes the larger of the
    /// twin's own sub-window spread and the scatter across the twin and the members
    /// ([`crate::signal::ensemble_features`]), and the scores are recomputed with the floor
    /// `tolerance`. Members whose
    /// features do not line up with the comparison's are an error of the caller: the
    /// comparison is returned unchanged.
    pub fn with_ensemble(
        mut self,
        members: &[Vec<Feature>],
        tolerance: &ComparisonTolerance,
    ) -> TwinComparison {
        let own: Vec<Feature> = self
            .features
            .iter()
            .map(|f| Feature {
                channel: f.channel.clone(),
                feature: f.feature.clone(),
                value: f.model,
                spread: f.model_spread,
            })
            .collect();
        let measured: Vec<Feature> = self
            .features
            .iter()
            .map(|f| Feature {
                channel: f.channel.clone(),
                feature: f.feature.clone(),
                value: f.measured,
                spread: f.measured_spread,
            })
            .collect();
        let runs: Vec<Vec<Feature>> = std::iter::once(own)
            .chain(members.iter().cloned())
            .collect();
        let Some(model) = ensemble_features(&runs) else {
            return self;
        };
        self.features = score(&measured, &model, tolerance);
        self.max_score = max_score(&self.features);
        self.ensemble_members = members.len();
        self
    }

    /// A comparison of the features `measured` and `model` alone (every other field zero):
    /// for tests of the scores.
    #[cfg(test)]
    pub(crate) fn synthetic(
        measured: &[Feature],
        model: &[Feature],
        tolerance: &ComparisonTolerance,
    ) -> TwinComparison {
        let features = score(measured, model, tolerance);
        TwinComparison {
            metrics: StepMetrics::default(),
            rms_error_upper: 0.0,
            rms_error_lower: 0.0,
            contact_fraction_error: 0.0,
            impacts_per_period_error: 0.0,
            spectrum_distance_db: None,
            max_score: max_score(&features),
            features,
            ensemble_members: 0,
            observation_noise: Vec::new(),
            discretisation_member: false,
        }
    }

    /// The comparison with the discretisation member's features `member` (a finer model's run
    /// over the same window, `[twin.discretisation]`): each feature's model spread gains
    /// `|model - member|` in quadrature, and the scores are recomputed with the floor
    /// `tolerance`. A feature the member lacks keeps its spread.
    pub fn with_discretisation(
        mut self,
        member: &[Feature],
        tolerance: &ComparisonTolerance,
    ) -> TwinComparison {
        let (mut measured, mut model) = (Vec::new(), Vec::new());
        for f in &self.features {
            let d = member
                .iter()
                .find(|m| m.channel == f.channel && m.feature == f.feature)
                .map_or(0.0, |m| (m.value - f.model).abs());
            measured.push(Feature {
                channel: f.channel.clone(),
                feature: f.feature.clone(),
                value: f.measured,
                spread: f.measured_spread,
            });
            model.push(Feature {
                channel: f.channel.clone(),
                feature: f.feature.clone(),
                value: f.model,
                spread: Some(f.model_spread.unwrap_or(0.0).hypot(d)),
            });
        }
        self.features = score(&measured, &model, tolerance);
        self.max_score = max_score(&self.features);
        self.discretisation_member = true;
        self
    }
}

/// The twin's output samples from `first` on, to cut record windows from.
#[derive(Debug)]
pub struct TwinWindows {
    /// How the step summary sees the upper and lower tip (sensor sensitivities).
    observe: [TipObservation; 2],
    /// How the comparison sees each compared beam channel ([`COMPARED_CHANNELS`] order).
    beams: [TipObservation; 5],
    /// The scores' floor.
    tolerance: ComparisonTolerance,
    first: u64,
    base: VecDeque<f64>,
    upper: VecDeque<f64>,
    lower: VecDeque<f64>,
    /// The twin's beam sensors ([`super::TWIN_SENSORS`]) for the channels not in `upper` and
    /// `lower`: the lower mid and the upper mid.
    lower_mid: VecDeque<f64>,
    upper_mid: VecDeque<f64>,
    contact: VecDeque<bool>,
    normal: VecDeque<f64>,
    /// Sample ranges `[from, to)` the twin did not see (input gaps).
    gaps: Vec<(u64, u64)>,
}

impl Default for TwinWindows {
    /// Windows for nominal sensors.
    fn default() -> Self {
        TwinWindows::new(
            &Observation::nominal(&crate::config::ContactCircuitSpec::default(), 0.0),
            ComparisonTolerance::default(),
        )
    }
}

impl TwinWindows {
    /// Windows whose channels the step summary and the comparison see through the sensor
    /// sensitivities of `o` (see [`super::observe`]), scored with the floor `tolerance`.
    pub fn new(o: &Observation, tolerance: ComparisonTolerance) -> TwinWindows {
        TwinWindows {
            observe: [o.upper, o.lower],
            beams: o.beams,
            tolerance,
            first: 0,
            base: VecDeque::new(),
            upper: VecDeque::new(),
            lower: VecDeque::new(),
            lower_mid: VecDeque::new(),
            upper_mid: VecDeque::new(),
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
                self.lower_mid.extend(std::iter::repeat_n(f64::NAN, pad));
                self.upper_mid.extend(std::iter::repeat_n(f64::NAN, pad));
                self.contact.extend(std::iter::repeat_n(false, pad));
                self.normal.extend(std::iter::repeat_n(f64::NAN, pad));
            }
        }
        self.base.extend(&b.base_acceleration);
        self.upper.extend(b.sensor(UPPER_TIP));
        self.lower.extend(b.sensor(LOWER_TIP));
        self.lower_mid.extend(b.sensor(LOWER_MID));
        self.upper_mid.extend(b.sensor(UPPER_MID));
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
        self.lower_mid.drain(..n);
        self.upper_mid.drain(..n);
        self.contact.drain(..n);
        self.normal.drain(..n);
        self.first += n as u64;
        self.gaps.retain(|&(_, to)| to > self.first);
    }

    /// The twin's observed channels over the record window of `info` (samples `dt` s apart),
    /// with the measurement's white noise `noise` laid on them: `None` while the window is
    /// not complete, or when the twin missed samples of it (an input gap).
    fn window(
        &self,
        info: &StepInfo,
        dt: f64,
        noise: &[NoiseFloor],
    ) -> Option<Result<Window, SignalError>> {
        let (from, to) = (info.record_first_sample, info.record_end_sample());
        if from < self.first || to > self.end() {
            return None;
        }
        if self.gaps.iter().any(|&(a, b)| a < to && b > from) {
            return None;
        }
        let range = (from - self.first) as usize..(to - self.first) as usize;
        let take = |x: &VecDeque<f64>| -> Vec<f64> { x.range(range.clone()).copied().collect() };
        let mut upper = take(&self.upper);
        let mut lower = take(&self.lower);
        let sensor = |name: &str| match name {
            VIBROMETER | UPPER_TIP_CHANNEL => &self.upper,
            UPPER_MID_CHANNEL => &self.upper_mid,
            LOWER_TIP_CHANNEL => &self.lower,
            _ => &self.lower_mid,
        };
        let mut beams: Vec<(&'static str, Vec<f64>)> = COMPARED_CHANNELS
            .iter()
            .map(|&name| (name, take(sensor(name))))
            .collect();
        let identity = self.observe.iter().all(TipObservation::is_identity)
            && self.beams.iter().all(TipObservation::is_identity);
        if !identity {
            let base = take(&self.base);
            let v_base = match PeriodGrid::new(base.len(), dt, info.omega)
                .and_then(|grid| integrate_periodic(&base, dt, &grid))
            {
                Ok(v) => v,
                Err(e) => return Some(Err(e)),
            };
            let apply = |o: &TipObservation, v: &mut Vec<f64>| {
                for (x, vb) in v.iter_mut().zip(&v_base) {
                    *x = o.gain * *x + o.base_weight * vb;
                }
            };
            apply(&self.observe[0], &mut upper);
            apply(&self.observe[1], &mut lower);
            for (o, (_, v)) in self.beams.iter().zip(beams.iter_mut()) {
                apply(o, v);
            }
        }
        // The measurement's noise on each channel, from a seed of the window and the channel:
        // every run of the model over this window (ensemble members, fits) gets the same
        // realisation. The tip series behind the metrics get their sensor's: the upper tip is
        // read by the vibrometer where there is one.
        let floor = |name: &str| noise.iter().find(|f| f.channel == name).map(|f| f.rms);
        let seed = |name: &str| observation_seed(info, name);
        for (name, v) in beams.iter_mut() {
            if let Some(rms) = floor(name) {
                add_white_noise(v, rms, seed(name));
            }
        }
        let upper_sensor = [VIBROMETER, UPPER_TIP_CHANNEL]
            .into_iter()
            .find(|n| floor(n).is_some());
        if let Some(name) = upper_sensor {
            add_white_noise(&mut upper, floor(name).unwrap_or(0.0), seed(name));
        }
        if let Some(rms) = floor(LOWER_TIP_CHANNEL) {
            add_white_noise(&mut lower, rms, seed(LOWER_TIP_CHANNEL));
        }
        Some(Ok(Window {
            upper,
            lower,
            beams,
            contact: self.contact.range(range.clone()).copied().collect(),
            normal: self.normal.range(range).copied().collect(),
        }))
    }

    /// The twin's compared features over the record window of `info` (samples `dt` s apart),
    /// with the spreads of its own sub-windows, for the channels `channels` (the measurement's):
    /// `None` as for [`TwinWindows::compare`]. An ensemble member's contribution to the
    /// comparison's model spread ([`TwinComparison::with_ensemble`]).
    pub fn features(
        &self,
        info: &StepInfo,
        dt: f64,
        channels: &[&str],
        noise: &[NoiseFloor],
    ) -> Option<Result<Vec<Feature>, SignalError>> {
        Some(
            self.window(info, dt, noise)?
                .and_then(|w| w.features(info, dt, channels)),
        )
    }

    /// The twin over the record window of `info` (samples `dt` s apart), against `measured`:
    /// `None` while the window is not complete, or when the twin missed samples of it (an
    /// input gap).
    pub fn compare(
        &self,
        info: &StepInfo,
        measured: &StepSummary,
        dt: f64,
    ) -> Option<Result<TwinComparison, SignalError>> {
        let w = match self.window(info, dt, &measured.noise_floor)? {
            Ok(w) => w,
            Err(e) => return Some(Err(e)),
        };
        let metrics = StepRecord {
            dt,
            omega: info.omega,
            base_level: info.base_amp_target,
            tip_velocity_upper: &w.upper,
            tip_velocity_lower: &w.lower,
            contact_closed: &w.contact,
            normal_force: Some(&w.normal),
        }
        .metrics();
        let channels = measured_channels(&measured.features);
        let features = w.features(info, dt, &channels);
        Some(metrics.and_then(|m| {
            let mut c = compare(m, &measured.metrics);
            c.features = score(&measured.features, &features?, &self.tolerance);
            c.max_score = max_score(&c.features);
            c.observation_noise = measured.noise_floor.clone();
            Ok(c)
        }))
    }
}

/// The twin's observed channels over one record window.
struct Window {
    upper: Vec<f64>,
    lower: Vec<f64>,
    beams: Vec<(&'static str, Vec<f64>)>,
    contact: Vec<bool>,
    normal: Vec<f64>,
}

impl Window {
    fn features(
        &self,
        info: &StepInfo,
        dt: f64,
        channels: &[&str],
    ) -> Result<Vec<Feature>, SignalError> {
        let beams: Vec<(&'static str, &[f64])> = self
            .beams
            .iter()
            .filter(|(n, _)| channels.contains(n))
            .map(|(n, v)| (*n, v.as_slice()))
            .collect();
        window_features(&FeatureWindow {
            dt,
            omega: info.omega,
            base_level: info.base_amp_target,
            channels: &beams,
            contact: &self.contact,
        })
    }
}

/// The beam channels of a measurement's features, in order.
fn measured_channels(features: &[Feature]) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for f in features {
        if f.channel != CONTACT_CHANNEL && !out.contains(&f.channel.as_str()) {
            out.push(&f.channel);
        }
    }
    out
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
        features: Vec::new(),
        max_score: None,
        ensemble_members: 0,
        observation_noise: Vec::new(),
        discretisation_member: false,
    }
}
