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

use crate::rig::channels::{ChannelMap, LOWER_MID, LOWER_TIP, UPPER_MID, UPPER_TIP, VIBROMETER};
use crate::rig::daq::ChannelKind;
use crate::rig::DaqLayout;
use crate::signal::{
    demodulate, integrate_periodic, noise_floor, window_features, Feature, FeatureWindow,
    NoiseFloor, PeriodGrid, SignalError, StepMetrics, StepRecord,
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
    /// `[control] record_tolerance` in force: the step's base amplitude was to be within this
    /// relative error of the target (`None` in logs written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record_tolerance: Option<f64>,
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
    /// The fundamental base amplitude of the kept window still misses `[control]
    /// record_tolerance` ([`StepInfo::record_tolerance`]): the step took every record window
    /// it may (`record_attempts`) and kept the last one. Written only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub base_amp_off_tolerance: bool,
    /// The compared features of every beam channel and the contact channel with their
    /// spread from sub-windows ([`crate::signal::features`]); empty in summaries written
    /// before they existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub features: Vec<Feature>,
    /// The white noise floor of every compared beam channel over the window
    /// ([`crate::signal::noise`]): the model's channels get the same noise before their
    /// features are compared. Empty for a window with contact (the estimate would measure the
    /// impacts' ringing, and the noise is negligible beside an impacting response's
    /// amplitudes) and in summaries written before it was measured.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub noise_floor: Vec<NoiseFloor>,
}

#[cfg(test)]
impl StepInfo {
    /// The first record window of a test `t`'s step 0 at `omega` (rad/s), base target
    /// `base_amp_target` (m), `record_samples` long from the session's first sample, settled,
    /// threshold 2.5 V, tolerance 1 %: the step of the synthetic windows the unit tests
    /// summarise.
    pub(crate) fn synthetic(omega: f64, base_amp_target: f64, record_samples: usize) -> StepInfo {
        StepInfo {
            test: "t".into(),
            step: 0,
            omega_ratio: 1.0,
            omega,
            base_amp_target,
            drive_amplitude: 0.1,
            settle_seconds: 1.0,
            settled: true,
            record_first_sample: 0,
            record_samples,
            contact_threshold_v: 2.5,
            record_attempt: 1,
            record_tolerance: Some(0.01),
        }
    }
}

impl StepSummary {
    /// The measured fundamental base amplitude's relative error against the target.
    pub fn base_amp_error(&self) -> f64 {
        self.base_amp_measured / self.base_amp_target - 1.0
    }
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
    /// The compared beam channels the layout has ([`COMPARED_CHANNELS`] order): relative
    /// velocities, m/s (the vibrometer's minus the base velocity; an accelerometer's
    /// acceleration minus the base's, integrated).
    pub beams: Vec<(&'static str, Vec<f64>)>,
}

/// The beam channels the twin comparison compares ([`crate::signal::features`]), in order:
/// the vibrometer and the upper-tip accelerometer (one spot, two sensors), the upper mid, the
/// lower tip and the lower mid.
pub const COMPARED_CHANNELS: [&str; 5] = [VIBROMETER, UPPER_TIP, UPPER_MID, LOWER_TIP, LOWER_MID];

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
    let mut beams = Vec::with_capacity(COMPARED_CHANNELS.len());
    for name in COMPARED_CHANNELS {
        let v = match name {
            VIBROMETER => match map.vibrometer {
                Some(k) => values(k).iter().zip(&v_base).map(|(v, b)| v - b).collect(),
                None => continue,
            },
            LOWER_TIP => lower.clone(),
            _ => match layout
                .index(name)
                .filter(|&k| layout.channels[k].kind == ChannelKind::BeamAcceleration)
            {
                Some(k) => relative_velocity(k)?,
                None => continue,
            },
        };
        beams.push((name, v));
    }
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
        beams,
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
    let channels: Vec<(&'static str, &[f64])> =
        w.beams.iter().map(|(n, v)| (*n, v.as_slice())).collect();
    let features = window_features(&FeatureWindow {
        dt: w.dt,
        omega,
        base_level: info.base_amp_target,
        channels: &channels,
        contact: &w.closed,
    })
    .map_err(sig)?;
    // With contact in the window the fourth difference measures the impacts' ringing, not
    // the sensors (crate::signal::noise): no floor, and none is needed beside the amplitudes
    // of an impacting response.
    let noise_floor = if w.closed.iter().any(|&c| c) {
        Vec::new()
    } else {
        channels
            .iter()
            .map(|(name, v)| NoiseFloor {
                channel: name.to_string(),
                rms: noise_floor(v),
            })
            .collect()
    };
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
        // NaN (a broken window) is never within tolerance, as in the procedure's gate.
        base_amp_off_tolerance: info.record_tolerance.is_some_and(|t| {
            let within = (base_amp_measured / info.base_amp_target - 1.0).abs() <= t;
            !within
        }),
        features,
        noise_floor,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::DaqSpec;
    use std::f64::consts::TAU;

    /// Excitation frequency of the synthetic window, Hz.
    const F: f64 = 50.0;

    /// A record window of 40 periods at [`F`] on the default channel map: the platform
    /// accelerometers carry the base acceleration, the vibrometer the upper tip's absolute
    /// velocity, the tip and mid accelerometers their absolute accelerations, the contact
    /// channel an open contact, the drive channels a sine. `gain` scales one channel's
    /// recording as a sensitivity error does.
    fn window(gain: Option<(&str, f64)>) -> (DaqLayout, StepInfo, Vec<i32>) {
        let layout = crate::rig::channels::layout(&DaqSpec::default());
        let dt = layout.dt();
        let w = TAU * F;
        let n = (40.0 / (F * dt)).round() as usize;
        let a_b = 2.0; // base acceleration amplitude, m/s^2
        let (v_up, v_lo) = (0.05, 0.03); // relative tip velocity amplitudes, m/s
        let signal = |name: &str, t: f64| -> f64 {
            let (s, c) = (w * t).sin_cos();
            let base_v = -a_b / w * c;
            match name {
                "vibrometer" => base_v + v_up * s,
                "upper_tip" | "upper_mid" => a_b * s + v_up * w * c,
                "lower_tip" | "lower_mid" => a_b * s + v_lo * w * (w * t + 0.3).cos(),
                "contact_voltage" => 5.0,
                "drive_voltage" | "drive_current" => 0.1 * s,
                _ => a_b * s, // the platform accelerometers
            }
        };
        let mut counts = Vec::with_capacity(n * layout.channels.len());
        for ch in &layout.channels {
            let g = gain.filter(|(c, _)| *c == ch.name).map_or(1.0, |x| x.1);
            counts.extend(
                (0..n).map(|i| (g * signal(&ch.name, i as f64 * dt) / ch.scale).round() as i32),
            );
        }
        let info = StepInfo::synthetic(w, a_b / (w * w), n);
        (layout, info, counts)
    }

    fn summary(gain: Option<(&str, f64)>) -> StepSummary {
        let (layout, info, counts) = window(gain);
        summarize(&layout, &info, &counts).unwrap()
    }

    /// Which channel feeds which metric (documented in rig-config/README.md, "Which channel
    /// feeds which metric"): a 3 % sensitivity error shows in the upper RMS through the
    /// vibrometer, in the lower RMS through the lower-tip accelerometer, in the base amplitude
    /// through each platform accelerometer; the upper-tip accelerometer (used only without a
    /// vibrometer) and the mid accelerometers change no metric, only their own compared
    /// features; the drive channels change nothing.
    #[test]
    fn each_metric_comes_from_its_channels() {
        let nominal = summary(None);
        assert!(!nominal.base_amp_off_tolerance, "{nominal:?}");
        for unused in ["drive_voltage", "drive_current"] {
            assert_eq!(summary(Some((unused, 1.03))), nominal, "{unused}");
        }
        let channels: Vec<&str> = nominal
            .features
            .iter()
            .map(|f| f.channel.as_str())
            .collect();
        for c in COMPARED_CHANNELS {
            assert!(channels.contains(&c), "{c} is compared: {channels:?}");
        }
        for compared_only in ["upper_tip", "upper_mid", "lower_mid"] {
            let s = summary(Some((compared_only, 1.03)));
            assert_eq!(s.metrics, nominal.metrics, "{compared_only}");
            assert_eq!(s.base_amp_measured, nominal.base_amp_measured);
            for (a, b) in s.features.iter().zip(&nominal.features) {
                if a.channel == compared_only {
                    // The channel records 1.03 a; its relative velocity grows by about 3 %.
                    let r = a.value / b.value;
                    assert!(
                        (1.025..1.035).contains(&r),
                        "{compared_only} {}: {r}",
                        a.feature
                    );
                } else {
                    assert_eq!(a, b, "{compared_only} changes {}", a.channel);
                }
            }
        }
        let vib = summary(Some(("vibrometer", 1.03)));
        assert!(
            vib.metrics.rms_upper > 1.01 * nominal.metrics.rms_upper,
            "{vib:?}"
        );
        assert_eq!(vib.metrics.rms_lower, nominal.metrics.rms_lower);
        assert_eq!(vib.base_amp_measured, nominal.base_amp_measured);
        let lower = summary(Some(("lower_tip", 1.03)));
        assert_ne!(lower.metrics.rms_lower, nominal.metrics.rms_lower);
        assert_eq!(lower.metrics.rms_upper, nominal.metrics.rms_upper);
        let platform = summary(Some(("platform_1", 1.03)));
        let e = platform.base_amp_measured / nominal.base_amp_measured - 1.0;
        assert!(
            (e - 0.01).abs() < 1e-3,
            "one of three platform accelerometers: {e}"
        );
        let all_platform = {
            let (layout, info, mut counts) = window(None);
            let n = info.record_samples;
            for (k, ch) in layout.channels.iter().enumerate() {
                if ch.name.starts_with("platform_") {
                    counts[k * n..(k + 1) * n]
                        .iter_mut()
                        .for_each(|c| *c = (f64::from(*c) * 1.03).round() as i32);
                }
            }
            summarize(&layout, &info, &counts).unwrap()
        };
        // 3 % off: past the record tolerance (1 %), flagged.
        assert!(all_platform.base_amp_off_tolerance, "{all_platform:?}");
        assert!((all_platform.base_amp_error() - 0.03).abs() < 1e-3);
    }
}
