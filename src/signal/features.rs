//! The compared features of a record window and their spread: what the twin's comparison with
//! the measurement puts side by side, for every beam channel the rig measures (the
//! vibrometer, the upper-tip accelerometer, both mid-beam accelerometers, the lower-tip
//! accelerometer) and the contact channel.
//!
//! Per channel (a relative velocity, normalised by `Omega q` like [`super::StepMetrics`]):
//! the RMS over the window (`rms`) and the distribution of the per-period zero-to-peak
//! amplitudes as its 10 %, 50 % and 90 % quantiles (`amp_p10`, `amp_p50`, `amp_p90`: a
//! period-1 response has one amplitude, a beating or chaotic one a spread of them, and the
//! quantiles compare the two distributions rather than single periods). For the contact
//! channel: the share of closed samples (`contact_fraction`) and the open->closed transitions
//! per period (`impacts_per_period`).
//!
//! **Spread.** The response in the impact band is non-periodic, so a window's feature is one
//! draw of a random quantity. [`window_features`] estimates how much it scatters from
//! sub-windows of at least [`SUB_WINDOW_PERIODS`] periods (long enough for the 1-2 Hz beat of
//! the two beams' free response): with `K >= 2` sub-windows of equal length and their values
//! `x_k`, the spread of the whole window's value is the standard error `s(x_k) / sqrt(K)`
//! (`s` the sample standard deviation), the scatter a repetition of the window would show if
//! the sub-windows are nearly independent. A window of fewer than `2 x` [`SUB_WINDOW_PERIODS`]
//! periods has no spread (`None`).
//!
//! The features are computed from per-period aggregates on the window's [`PeriodGrid`]
//! (period quadrature of the squared signal, the period's amplitude, its closed samples and
//! contact onsets), so every sub-window is a range of whole periods and the whole window is the
//! range of all of them.

use serde::{Deserialize, Serialize};

use super::error::{require_finite, require_len, require_positive, SignalError};
use super::metrics::period_amplitude;
use super::periods::PeriodGrid;

/// Shortest sub-window for the spread, in excitation periods (see the module docs).
pub const SUB_WINDOW_PERIODS: usize = 25;

/// The features of a beam channel, in [`window_features`]' order.
pub const CHANNEL_FEATURES: [&str; 4] = ["rms", "amp_p10", "amp_p50", "amp_p90"];

/// The name of the contact channel in a feature list.
pub const CONTACT_CHANNEL: &str = "contact";

/// The features of the contact channel, in [`window_features`]' order.
pub const CONTACT_FEATURES: [&str; 2] = ["contact_fraction", "impacts_per_period"];

/// The quantiles of the per-period amplitudes (`amp_p10`, `amp_p50`, `amp_p90`).
const AMPLITUDE_QUANTILES: [f64; 3] = [0.1, 0.5, 0.9];

/// One feature of one channel over a record window.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Feature {
    /// The channel (a beam channel's name, or `contact`).
    pub channel: String,
    /// The feature ([`CHANNEL_FEATURES`], [`CONTACT_FEATURES`]).
    pub feature: String,
    /// Its value over the whole window (velocities normalised by `Omega q`), -.
    pub value: f64,
    /// Its spread from sub-windows (module docs), same unit; `None` for a window of fewer than
    /// two sub-windows.
    pub spread: Option<f64>,
}

/// A record window as the features see it: relative velocities of named channels and the
/// contact flags, all of one length.
#[derive(Clone, Copy, Debug)]
pub struct FeatureWindow<'a> {
    /// Sample interval, s.
    pub dt: f64,
    /// Excitation frequency Omega, rad/s.
    pub omega: f64,
    /// Base displacement amplitude q (the target), m.
    pub base_level: f64,
    /// Beam channels: name and relative velocity, m/s.
    pub channels: &'a [(&'static str, &'a [f64])],
    /// Contact closed per sample.
    pub contact: &'a [bool],
}

/// The features of every channel of `w` (its channels in order, [`CHANNEL_FEATURES`] each,
/// then the contact channel's [`CONTACT_FEATURES`]) over the whole periods of the window, each
/// with its spread from sub-windows (module docs).
///
/// Errors: non-positive or non-finite `dt`, `omega`, `base_level`; channels of unequal length
/// or with non-finite samples; less than one whole period.
pub fn window_features(w: &FeatureWindow<'_>) -> Result<Vec<Feature>, SignalError> {
    require_positive("base_level (m)", w.base_level)?;
    let n = w.contact.len();
    for (name, x) in w.channels {
        require_len(name, x.len(), "contact", n)?;
        require_finite(name, x)?;
    }
    let grid = PeriodGrid::new(n, w.dt, w.omega)?;
    let periods = grid.periods();
    let scale = 1.0 / (w.omega * w.base_level);
    let k = periods / SUB_WINDOW_PERIODS;
    // Sub-window i: periods [i P / K, (i + 1) P / K).
    let ranges: Vec<std::ops::Range<usize>> = (0..k.max(1))
        .map(|i| i * periods / k.max(1)..(i + 1) * periods / k.max(1))
        .collect();
    let mut out = Vec::with_capacity(w.channels.len() * CHANNEL_FEATURES.len() + 2);
    let mut push = |channel: &str, feature: &str, of: &dyn Fn(std::ops::Range<usize>) -> f64| {
        let value = of(0..periods);
        let spread = (k >= 2).then(|| {
            let xs: Vec<f64> = ranges.iter().map(|r| of(r.clone())).collect();
            standard_error(&xs)
        });
        out.push(Feature {
            channel: channel.to_string(),
            feature: feature.to_string(),
            value,
            spread,
        });
    };
    for (name, x) in w.channels {
        let mean_square: Vec<f64> = (0..periods)
            .map(|p| grid.integrate_period(p, |i| x[i] * x[i]))
            .collect();
        let length: Vec<f64> = (0..periods)
            .map(|p| grid.boundary(p + 1) - grid.boundary(p))
            .collect();
        let amplitude: Vec<f64> = (0..periods)
            .map(|p| period_amplitude(x, &grid, p).unwrap_or(f64::NAN))
            .collect();
        push(name, CHANNEL_FEATURES[0], &|r| {
            let s: f64 = mean_square[r.clone()].iter().sum();
            let l: f64 = length[r].iter().sum();
            (s / l).max(0.0).sqrt() * scale
        });
        for (q, feature) in AMPLITUDE_QUANTILES.iter().zip(&CHANNEL_FEATURES[1..]) {
            push(name, feature, &|r| quantile(&amplitude[r], *q) * scale);
        }
    }
    let closed: Vec<(usize, usize)> = (0..periods)
        .map(|p| {
            let m = grid.members(p);
            let count = w.contact[m.clone()].iter().filter(|&&c| c).count();
            (count, m.len())
        })
        .collect();
    // An onset: a closed sample after an open one (the first sample of the window has no
    // predecessor and starts none), counted in the period of the closed sample.
    let onsets: Vec<usize> = (0..periods)
        .map(|p| {
            grid.members(p)
                .filter(|&i| i > 0 && w.contact[i] && !w.contact[i - 1])
                .count()
        })
        .collect();
    push(CONTACT_CHANNEL, CONTACT_FEATURES[0], &|r| {
        let (c, m) = closed[r]
            .iter()
            .fold((0, 0), |(c, m), &(a, b)| (c + a, m + b));
        c as f64 / m.max(1) as f64
    });
    push(CONTACT_CHANNEL, CONTACT_FEATURES[1], &|r| {
        let len = r.len().max(1);
        onsets[r].iter().sum::<usize>() as f64 / len as f64
    });
    Ok(out)
}

/// The features of an ensemble of model runs over one window: each feature's value is the
/// first run's (the twin as it ran), its spread the larger of that run's sub-window spread
/// and the sample standard deviation across the runs (the scatter of a whole-window value
/// between runs that differ only in their initial state). `runs` are [`window_features`] of
/// the same channels; `None` when `runs` is empty or their features do not line up.
pub fn ensemble_features(runs: &[Vec<Feature>]) -> Option<Vec<Feature>> {
    let first = runs.first()?;
    if runs.iter().any(|r| {
        r.len() != first.len()
            || r.iter()
                .zip(first)
                .any(|(a, b)| a.channel != b.channel || a.feature != b.feature)
    }) {
        return None;
    }
    Some(
        first
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let across = (runs.len() >= 2).then(|| {
                    let xs: Vec<f64> = runs.iter().map(|r| r[i].value).collect();
                    sample_std(&xs)
                });
                let spread = match (f.spread, across) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    (a, b) => a.or(b),
                };
                Feature {
                    spread,
                    ..f.clone()
                }
            })
            .collect(),
    )
}

/// The `q` quantile (0..=1) of `x` by linear interpolation between order statistics (NaN for
/// an empty or non-finite `x`).
pub fn quantile(x: &[f64], q: f64) -> f64 {
    if x.is_empty() || x.iter().any(|v| !v.is_finite()) {
        return f64::NAN;
    }
    let mut s = x.to_vec();
    s.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let (lo, t) = (pos.floor() as usize, pos.fract());
    if lo + 1 < s.len() {
        s[lo] + t * (s[lo + 1] - s[lo])
    } else {
        s[lo]
    }
}

/// Sample standard deviation (n - 1); 0 for fewer than two values.
fn sample_std(x: &[f64]) -> f64 {
    if x.len() < 2 {
        return 0.0;
    }
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// Standard error of the mean of `x`: `s(x) / sqrt(len)`.
pub(crate) fn standard_error(x: &[f64]) -> f64 {
    sample_std(x) / (x.len() as f64).sqrt()
}

/// Whether every spread is known: a finite, positive number.
pub(crate) fn spreads_known(spreads: &[f64]) -> bool {
    spreads.iter().all(|s| s.is_finite() && *s > 0.0)
}

/// The 99.9 % point of chi-squared with `n` (>= 1) degrees of freedom: exact to the table's
/// digits up to 6, the Wilson-Hilferty approximation above (NaN for 0).
pub(crate) fn chi2_999(n: usize) -> f64 {
    const TABLE: [f64; 6] = [10.828, 13.816, 16.266, 18.467, 20.515, 22.458];
    match n {
        0 => f64::NAN,
        1..=6 => TABLE[n - 1],
        _ => {
            let v = 2.0 / (9.0 * n as f64);
            n as f64 * (1.0 - v + 3.090 * v.sqrt()).powi(3)
        }
    }
}

/// What [`held_out_confirms`] found: the largest |z| against the fitted model, the
/// chi-squared against the null one and its 99.9 % point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HeldOut {
    pub worst: f64,
    pub chi2: f64,
    pub limit: f64,
}

/// Whether held-out estimates confirm a fitted model against a null one: `to_fit` and
/// `to_null` are their residuals from each, in units of their own spreads (one per estimate).
/// They confirm it when every residual from the fit is within 3 and together they reject the
/// null beyond the 99.9 % point of chi-squared. None without estimates or where they do not.
pub(crate) fn held_out_confirms(to_fit: &[f64], to_null: &[f64]) -> Option<HeldOut> {
    if to_fit.is_empty() || to_fit.len() != to_null.len() {
        return None;
    }
    let worst = to_fit.iter().fold(0.0_f64, |m, z| m.max(z.abs()));
    let chi2: f64 = to_null.iter().map(|z| z * z).sum();
    let limit = chi2_999(to_null.len());
    (worst <= 3.0 && chi2 > limit).then_some(HeldOut { worst, chi2, limit })
}

/// Inverse-variance weights `1 / spread^2` of estimates with the given spreads, or `None`
/// where a spread is missing ([`spreads_known`]): the caller then weighs them equally.
pub(crate) fn inverse_variance_weights(spreads: &[f64]) -> Option<Vec<f64>> {
    spreads_known(spreads).then(|| spreads.iter().map(|s| 1.0 / (s * s)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{SQRT_2, TAU};

    const F: f64 = 50.0;

    fn window_of(
        periods: f64,
        spp: f64,
        x: impl Fn(f64) -> f64,
        closed: impl Fn(f64) -> bool,
    ) -> (f64, Vec<f64>, Vec<bool>) {
        let dt = 1.0 / (spp * F);
        let n = (periods * spp).round() as usize;
        let t = |k: usize| k as f64 * dt;
        (
            dt,
            (0..n).map(|k| x(t(k))).collect(),
            (0..n).map(|k| closed(t(k))).collect(),
        )
    }

    fn get<'a>(f: &'a [Feature], channel: &str, feature: &str) -> &'a Feature {
        f.iter()
            .find(|x| x.channel == channel && x.feature == feature)
            .unwrap()
    }

    #[test]
    fn a_steady_sine_has_exact_features_and_no_spread() {
        let w = TAU * F;
        let (a, q) = (0.3, 1e-5);
        let (dt, x, c) = window_of(100.0, 204.8, |t| a * (w * t).sin(), |_| false);
        let f = window_features(&FeatureWindow {
            dt,
            omega: w,
            base_level: q,
            channels: &[("lower_tip", &x)],
            contact: &c,
        })
        .unwrap();
        assert_eq!(f.len(), 6);
        let s = w * q;
        let rms = get(&f, "lower_tip", "rms");
        assert!((rms.value - a / SQRT_2 / s).abs() < 1e-9 * a / s, "{rms:?}");
        // Four sub-windows of 25 periods, all alike: the spread is round-off.
        assert!(rms.spread.unwrap() < 1e-9 * rms.value, "{rms:?}");
        for feature in ["amp_p10", "amp_p50", "amp_p90"] {
            let v = get(&f, "lower_tip", feature).value;
            // Sampled extremes: within 1 - cos(pi / S) of the amplitude.
            assert!((v - a / s).abs() < 2e-4 * a / s, "{feature} {v}");
        }
        assert_eq!(get(&f, "contact", "contact_fraction").value, 0.0);
        assert_eq!(get(&f, "contact", "impacts_per_period").value, 0.0);
    }

    #[test]
    fn a_beat_spreads_the_amplitudes_and_the_sub_windows() {
        // A 1 Hz beat (50 periods of 50 Hz) over 100 periods: amplitudes from a(1 - m) to
        // a(1 + m); the sub-windows of 25 periods (half a beat) see different RMS values.
        let w = TAU * F;
        let (a, m, q) = (0.3, 0.5, 1e-5);
        let env = |t: f64| a * (1.0 + m * (TAU * 1.0 * t).sin());
        let (dt, x, c) = window_of(
            100.0,
            200.0,
            |t| env(t) * (w * t).sin(),
            |t| (w * t).sin() > 0.99,
        );
        let f = window_features(&FeatureWindow {
            dt,
            omega: w,
            base_level: q,
            channels: &[("upper_tip", &x)],
            contact: &c,
        })
        .unwrap();
        let s = w * q;
        let p10 = get(&f, "upper_tip", "amp_p10").value * s;
        let p90 = get(&f, "upper_tip", "amp_p90").value * s;
        assert!(
            p10 < a * (1.0 - 0.5 * m) && p90 > a * (1.0 + 0.5 * m),
            "{p10} {p90}"
        );
        let rms = get(&f, "upper_tip", "rms");
        assert!(rms.spread.unwrap() > 0.05 * rms.value, "{rms:?}");
        // One contact onset per period (the sine's crest), closed ~4.5 % of the time.
        let ipp = get(&f, "contact", "impacts_per_period");
        assert!((ipp.value - 1.0).abs() < 0.02, "{ipp:?}");
        let cf = get(&f, "contact", "contact_fraction").value;
        let expected = (0.99f64).acos() / std::f64::consts::PI;
        assert!((cf - expected).abs() < 0.01, "{cf} vs {expected}");
    }

    #[test]
    fn short_windows_have_no_spread_and_bad_input_is_refused() {
        let w = TAU * F;
        let (dt, x, c) = window_of(40.0, 200.0, |t| (w * t).sin(), |_| false);
        let win = FeatureWindow {
            dt,
            omega: w,
            base_level: 1e-5,
            channels: &[("lower_mid", &x)],
            contact: &c,
        };
        assert!(window_features(&win)
            .unwrap()
            .iter()
            .all(|f| f.spread.is_none()));
        let short = &x[..10];
        let err = window_features(&FeatureWindow {
            channels: &[("lower_mid", short)],
            ..win
        })
        .unwrap_err();
        assert!(err.to_string().contains("lower_mid"), "{err}");
        let mut bad = x.clone();
        bad[7] = f64::NAN;
        let err = window_features(&FeatureWindow {
            channels: &[("lower_mid", &bad)],
            ..win
        })
        .unwrap_err();
        assert!(err.to_string().contains("lower_mid"), "{err}");
    }

    #[test]
    fn an_ensemble_takes_the_first_run_and_the_larger_spread() {
        let f = |v: f64, s: Option<f64>| Feature {
            channel: "lower_tip".into(),
            feature: "rms".into(),
            value: v,
            spread: s,
        };
        let e = ensemble_features(&[vec![f(1.0, Some(0.01))], vec![f(1.2, None)]]).unwrap();
        assert_eq!(e[0].value, 1.0);
        // s(1.0, 1.2) = 0.1414
        assert!((e[0].spread.unwrap() - 0.2f64.sqrt() / 10f64.sqrt() * 1.0).abs() < 1e-12);
        let e = ensemble_features(&[vec![f(1.0, Some(0.01))]]).unwrap();
        assert_eq!(e[0].spread, Some(0.01));
        assert!(ensemble_features(&[]).is_none());
        let other = Feature {
            feature: "amp_p10".into(),
            ..f(1.0, None)
        };
        assert!(ensemble_features(&[vec![f(1.0, None)], vec![other]]).is_none());
        assert_eq!(quantile(&[3.0, 1.0, 2.0], 0.5), 2.0);
        assert_eq!(quantile(&[1.0, 2.0], 0.25), 1.25);
        assert!(quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn inverse_variance_weights_need_every_spread() {
        assert_eq!(inverse_variance_weights(&[1.0, 0.5]), Some(vec![1.0, 4.0]));
        assert_eq!(inverse_variance_weights(&[1.0, 0.0]), None);
        assert_eq!(inverse_variance_weights(&[f64::NAN, 1.0]), None);
        assert_eq!(inverse_variance_weights(&[]), Some(vec![]));
        assert!(spreads_known(&[2e-5, 1e-6]));
        assert!(!spreads_known(&[2e-5, f64::INFINITY]));
        assert!(!spreads_known(&[-1e-6]));
    }
}
