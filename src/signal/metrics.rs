//! Per-step metrics of a stepped-sine step (reference section 4.2): RMS and per-period
//! zero-to-peak amplitudes of both tip velocities normalised by `Omega q`, contact fraction,
//! impacts per period and peak integrated normal force. The same function serves the virtual
//! stepped sine and recorded measurements: the input is a borrowed [`StepRecord`] view.
//!
//! The record window is every whole excitation period of the record, counted from its first
//! sample ([`PeriodGrid`]); samples after the last whole period are ignored.

use super::contact_activity::count_impacts;
use super::error::{require_finite, require_len, require_positive, SignalError};
use super::periods::{split, PeriodGrid};
use super::spectrum::{band_spectrum, SPECTRUM_BANDS};

/// Borrowed view of one recorded step: uniformly sampled channels of equal length plus the
/// excitation. Nothing is copied.
#[derive(Debug, Clone, Copy)]
pub struct StepRecord<'a> {
    /// Sample interval, s.
    pub dt: f64,
    /// Excitation frequency Omega, rad/s.
    pub omega: f64,
    /// Base displacement amplitude q (fundamental harmonic), m.
    pub base_level: f64,
    /// Upper beam tip velocity (vertical), m/s.
    pub tip_velocity_upper: &'a [f64],
    /// Lower beam tip velocity (vertical), m/s.
    pub tip_velocity_lower: &'a [f64],
    /// Per sample: true when at least one contact pair is closed.
    pub contact_closed: &'a [bool],
    /// Integrated normal contact force over the interface, N (>= 0 by the contact law);
    /// `None` for measurements (a rig has no force channel).
    pub normal_force: Option<&'a [f64]>,
}

/// Tuning of [`step_metrics`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct MetricsParams {
    /// Open gaps of at most this many samples between two closed samples are treated as
    /// closed (chatter is merged into one impact). Default 0: every open->closed transition
    /// counts, which is what the data says.
    pub impact_debounce: usize,
}

/// Metrics of one step. Velocities are normalised by `Omega q` (the reference's
/// `u_tip / (Omega q_base)`), so the linear response at resonance is the dynamic amplification.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
pub struct StepMetrics {
    /// RMS of the upper tip velocity over the window / (Omega q).
    pub rms_upper: f64,
    /// RMS of the lower tip velocity over the window / (Omega q).
    pub rms_lower: f64,
    /// Smallest per-period zero-to-peak amplitude of the upper tip velocity / (Omega q).
    pub amp_min_upper: f64,
    /// Mean per-period zero-to-peak amplitude of the upper tip velocity / (Omega q).
    pub amp_mean_upper: f64,
    /// Largest per-period zero-to-peak amplitude of the upper tip velocity / (Omega q).
    pub amp_max_upper: f64,
    /// Smallest per-period zero-to-peak amplitude of the lower tip velocity / (Omega q).
    pub amp_min_lower: f64,
    /// Mean per-period zero-to-peak amplitude of the lower tip velocity / (Omega q).
    pub amp_mean_lower: f64,
    /// Largest per-period zero-to-peak amplitude of the lower tip velocity / (Omega q).
    pub amp_max_lower: f64,
    /// Share of the window's time with at least one closed pair, in [0, 1].
    pub contact_fraction: f64,
    /// Open->closed transitions in the window divided by the number of periods.
    pub impacts_per_period: f64,
    /// Largest integrated normal contact force in the window, N; `None` without a force
    /// channel (measurements).
    pub peak_normal_force: Option<f64>,
    /// Number of whole excitation periods in the window.
    pub periods: usize,
    /// RMS of the upper tip velocity / (Omega q) in the half-harmonic bands `k Omega / 2`,
    /// k = 1 ..= 20 ([`super::spectrum`]); zeros in summaries written before it existed.
    #[serde(default)]
    pub spectrum_upper: [f64; SPECTRUM_BANDS],
}

/// Min, mean and max of the per-period amplitudes of one channel (same unit as the channel
/// unless normalised by the caller).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AmplitudeStats {
    /// Smallest per-period amplitude.
    pub min: f64,
    /// Mean per-period amplitude.
    pub mean: f64,
    /// Largest per-period amplitude.
    pub max: f64,
}

/// Zero-to-peak amplitude of `x` in period `p` of `grid`: half the peak-to-peak,
/// `(max - min) / 2` over the period's samples. `None` when `p` is not a whole period of the
/// grid or `x` is shorter than the grid's record.
///
/// NOTE: half the peak-to-peak, not `max |x|`, so that a mean offset (sensor bias, a drifting
/// integrated velocity) does not enter the amplitude; for a sine both agree. The extremes are
/// the sampled ones (no interpolation between samples: impacts make the velocity kink and a
/// parabolic refinement would overshoot there); for a sine this underestimates by at most
/// `1 - cos(pi / S)`, 5e-6 at S = 1000 samples per period.
pub fn period_amplitude(x: &[f64], grid: &PeriodGrid, p: usize) -> Option<f64> {
    if p >= grid.periods() {
        return None;
    }
    let (lo, hi) = x
        .get(grid.members(p))?
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    Some(0.5 * (hi - lo))
}

/// Min, mean and max over the whole periods of `grid` of [`period_amplitude`]; no allocation.
/// A non-finite sample makes the result non-finite.
///
/// Errors: `x` does not have `grid.samples()` samples.
pub fn amplitude_stats(x: &[f64], grid: &PeriodGrid) -> Result<AmplitudeStats, SignalError> {
    require_len("x", x.len(), "the period grid", grid.samples())?;
    let (mut min, mut max, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for p in 0..grid.periods() {
        let a = period_amplitude(x, grid, p).unwrap_or(f64::NAN);
        min = min.min(a);
        max = max.max(a);
        sum += a;
    }
    Ok(AmplitudeStats {
        min,
        mean: sum / grid.periods() as f64,
        max,
    })
}

/// RMS of `x` over the whole periods of `grid` (period quadrature of [`PeriodGrid`]).
///
/// Errors: `x` does not have `grid.samples()` samples.
pub fn rms(x: &[f64], grid: &PeriodGrid) -> Result<f64, SignalError> {
    require_len("x", x.len(), "the period grid", grid.samples())?;
    Ok(grid.mean_over_window(|k| x[k] * x[k]).max(0.0).sqrt())
}

impl StepRecord<'_> {
    /// Checks the view: positive finite `dt`, `omega`, `base_level`; equal non-zero lengths;
    /// finite samples; at least one whole period. Returns the period grid.
    pub fn validate(&self) -> Result<PeriodGrid, SignalError> {
        require_positive("dt (s)", self.dt)?;
        require_positive("omega (rad/s)", self.omega)?;
        require_positive("base_level (m)", self.base_level)?;
        let n = self.tip_velocity_upper.len();
        if n == 0 {
            return Err(SignalError::Empty {
                channel: "tip_velocity_upper",
            });
        }
        let reference = "tip_velocity_upper";
        require_len(
            "tip_velocity_lower",
            self.tip_velocity_lower.len(),
            reference,
            n,
        )?;
        require_len("contact_closed", self.contact_closed.len(), reference, n)?;
        if let Some(f) = self.normal_force {
            require_len("normal_force", f.len(), reference, n)?;
            require_finite("normal_force", f)?;
        }
        require_finite("tip_velocity_upper", self.tip_velocity_upper)?;
        require_finite("tip_velocity_lower", self.tip_velocity_lower)?;
        PeriodGrid::new(n, self.dt, self.omega)
    }

    /// [`step_metrics`] with default parameters.
    pub fn metrics(&self) -> Result<StepMetrics, SignalError> {
        step_metrics(self, &MetricsParams::default())
    }
}

/// Computes the [`StepMetrics`] of a step over all its whole excitation periods.
///
/// Errors: see [`StepRecord::validate`].
pub fn step_metrics(
    record: &StepRecord<'_>,
    params: &MetricsParams,
) -> Result<StepMetrics, SignalError> {
    let grid = record.validate()?;
    let scale = 1.0 / (record.omega * record.base_level);
    let upper = record.tip_velocity_upper;
    let lower = record.tip_velocity_lower;
    let au = amplitude_stats(upper, &grid)?;
    let al = amplitude_stats(lower, &grid)?;

    // Contact time: sample k stands for [k, k+1); the sample cut by the window end counts with
    // the fraction inside. Flags are not smooth, so no boundary correction here.
    let end = grid.boundary(grid.periods());
    let (k_end, theta) = split(end);
    let closed = record.contact_closed;
    let mut contact = closed[..k_end].iter().filter(|&&c| c).count() as f64;
    if theta > 0.0 && closed[k_end] {
        contact += theta;
    }
    let used = grid.used_samples();
    let impacts = count_impacts(&closed[..used], params.impact_debounce);
    let peak_normal_force = record
        .normal_force
        .map(|f| f[..used].iter().copied().fold(f64::NEG_INFINITY, f64::max));

    Ok(StepMetrics {
        rms_upper: rms(upper, &grid)? * scale,
        rms_lower: rms(lower, &grid)? * scale,
        amp_min_upper: au.min * scale,
        amp_mean_upper: au.mean * scale,
        amp_max_upper: au.max * scale,
        amp_min_lower: al.min * scale,
        amp_mean_lower: al.mean * scale,
        amp_max_lower: al.max * scale,
        contact_fraction: contact / end,
        impacts_per_period: impacts as f64 / grid.periods() as f64,
        peak_normal_force,
        periods: grid.periods(),
        spectrum_upper: band_spectrum(upper, record.dt, record.omega, &grid)?.map(|v| v * scale),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{SQRT_2, TAU};

    struct Owned {
        dt: f64,
        omega: f64,
        q: f64,
        up: Vec<f64>,
        lo: Vec<f64>,
        closed: Vec<bool>,
        force: Vec<f64>,
    }

    impl Owned {
        fn view(&self) -> StepRecord<'_> {
            StepRecord {
                dt: self.dt,
                omega: self.omega,
                base_level: self.q,
                tip_velocity_upper: &self.up,
                tip_velocity_lower: &self.lo,
                contact_closed: &self.closed,
                normal_force: Some(&self.force),
            }
        }
    }

    /// `periods` periods at `spp` samples per period of `up(t)`, `lo(t)`, no contact.
    fn record(spp: f64, periods: f64, up: impl Fn(f64) -> f64, lo: impl Fn(f64) -> f64) -> Owned {
        let f_hz = 55.0;
        let omega = TAU * f_hz;
        let dt = 1.0 / (spp * f_hz);
        let n = (spp * periods).round() as usize;
        let t = |k: usize| k as f64 * dt;
        Owned {
            dt,
            omega,
            q: 2e-5 * 0.3,
            up: (0..n).map(|k| up(t(k))).collect(),
            lo: (0..n).map(|k| lo(t(k))).collect(),
            closed: vec![false; n],
            force: vec![0.0; n],
        }
    }

    #[test]
    fn pure_sine_gives_exact_rms_and_constant_amplitude() {
        let omega = TAU * 55.0;
        let (a, b) = (0.8, 0.05);
        let r = record(
            1000.0,
            10.0,
            |t| a * (omega * t).sin(),
            |t| b * (omega * t).sin(),
        );
        let m = r.view().metrics().unwrap();
        let s = omega * r.q;
        assert_eq!(m.periods, 10);
        assert!((m.rms_upper - a / SQRT_2 / s).abs() < 1e-12 * a / s);
        assert!((m.rms_lower - b / SQRT_2 / s).abs() < 1e-12 * b / s);
        for v in [m.amp_min_upper, m.amp_mean_upper, m.amp_max_upper] {
            assert!((v - a / s).abs() < 1e-12 * a / s, "{v} vs {}", a / s);
        }
        for v in [m.amp_min_lower, m.amp_mean_lower, m.amp_max_lower] {
            assert!((v - b / s).abs() < 1e-12 * b / s);
        }
        assert_eq!(m.contact_fraction, 0.0);
        assert_eq!(m.impacts_per_period, 0.0);
        assert_eq!(m.peak_normal_force, Some(0.0));
    }

    #[test]
    fn rms_with_offset_harmonics_and_fractional_periods() {
        // u = c + a sin + h cos(6 Omega t + 1): rms^2 = c^2 + a^2/2 + h^2/2. Sampled at a rate
        // that is not a multiple of the excitation, with a partial period at the end.
        let omega = TAU * 55.0;
        let (c, a, h) = (0.1, 0.8, 0.2);
        let u = |t: f64| c + a * (omega * t).sin() + h * (6.0 * omega * t + 1.0).cos();
        let r = record(987.654, 7.6, u, u);
        let m = r.view().metrics().unwrap();
        assert_eq!(m.periods, 7);
        let expected = (c * c + a * a / 2.0 + h * h / 2.0).sqrt() / (omega * r.q);
        let rel = (m.rms_upper - expected).abs() / expected;
        assert!(rel < 1e-10, "relative rms error {rel:e}");
    }

    #[test]
    fn period_wise_amplitude_steps_give_exact_min_mean_max() {
        // u = A_p sin(Omega t) in period p: the per-period amplitudes are exactly A_p.
        let omega = TAU * 55.0;
        let amps = [1.0, 0.4, 2.5, 1.7, 0.9, 3.1, 1.2];
        let a_of = |t: f64| amps[((t * 55.0 + 1e-9).floor() as usize).min(amps.len() - 1)];
        let r = record(
            1000.0,
            amps.len() as f64,
            |t| a_of(t) * (omega * t).sin(),
            |t| -0.5 * a_of(t) * (omega * t).sin(),
        );
        let m = r.view().metrics().unwrap();
        let s = omega * r.q;
        let mean = amps.iter().sum::<f64>() / amps.len() as f64;
        assert!((m.amp_min_upper * s - 0.4).abs() < 1e-12);
        assert!((m.amp_max_upper * s - 3.1).abs() < 1e-12);
        assert!((m.amp_mean_upper * s - mean).abs() < 1e-12);
        assert!((m.amp_min_lower * s - 0.2).abs() < 1e-12);
        assert!((m.amp_max_lower * s - 1.55).abs() < 1e-12);
        assert!((m.amp_mean_lower * s - 0.5 * mean).abs() < 1e-12);
    }

    #[test]
    fn amplitude_modulated_signal_gives_envelope_extremes() {
        // Envelope 1 + 0.5 cos(Omega t / 64) over one envelope period (64 excitation periods):
        // per-period amplitudes follow the envelope from 1.5 down to 0.5; within one period
        // near the extremes the envelope changes by less than 2e-3.
        let omega = TAU * 55.0;
        let env = |t: f64| 1.0 + 0.5 * (omega * t / 64.0).cos();
        let r = record(
            1000.0,
            64.0,
            |t| env(t) * (omega * t).sin(),
            |t| 0.3 * env(t) * (omega * t).sin(),
        );
        let m = r.view().metrics().unwrap();
        let s = omega * r.q;
        assert!(
            (m.amp_max_upper * s - 1.5).abs() < 2e-3,
            "{}",
            m.amp_max_upper * s
        );
        assert!(
            (m.amp_min_upper * s - 0.5).abs() < 2e-3,
            "{}",
            m.amp_min_upper * s
        );
        assert!((m.amp_mean_upper * s - 1.0).abs() < 2e-3);
        assert!((m.amp_max_lower / m.amp_max_upper - 0.3).abs() < 1e-12);
        // The RMS of a modulated sine: sqrt(mean(env^2) / 2) = sqrt((1 + 0.125) / 2).
        assert!((m.rms_upper * s - (1.125f64 / 2.0).sqrt()).abs() < 1e-3);
    }

    #[test]
    fn contact_counts_fraction_and_peak_force() {
        // 4 periods of 100 samples; contact closed for samples 10..20 in each period, plus a
        // chatter pair 25, 27 in period 1 (gap of 1 sample).
        let omega = TAU * 55.0;
        let mut r = record(100.0, 4.0, |t| (omega * t).sin(), |_| 0.0);
        for p in 0..4 {
            for k in 10..20 {
                r.closed[p * 100 + k] = true;
                r.force[p * 100 + k] = (p + 1) as f64;
            }
        }
        r.closed[125] = true;
        r.closed[127] = true;
        let m = r.view().metrics().unwrap();
        assert_eq!(m.periods, 4);
        assert_eq!(m.impacts_per_period, 6.0 / 4.0);
        assert!((m.contact_fraction - 42.0 / 400.0).abs() < 1e-15);
        assert_eq!(m.peak_normal_force, Some(4.0));
        // Debounce 1 merges 125/127 into one impact; debounce 5 also merges it with 10..20.
        let m1 = step_metrics(&r.view(), &MetricsParams { impact_debounce: 1 }).unwrap();
        assert_eq!(m1.impacts_per_period, 5.0 / 4.0);
        let m5 = step_metrics(&r.view(), &MetricsParams { impact_debounce: 5 }).unwrap();
        assert_eq!(m5.impacts_per_period, 4.0 / 4.0);
    }

    #[test]
    fn samples_after_the_last_whole_period_are_ignored() {
        let omega = TAU * 55.0;
        let mut r = record(100.0, 3.5, |t| (omega * t).sin(), |_| 0.0);
        for k in 310..330 {
            r.closed[k] = true;
            r.force[k] = 9.0;
        }
        r.up[320] = 50.0;
        let m = r.view().metrics().unwrap();
        assert_eq!(m.periods, 3);
        assert_eq!(m.contact_fraction, 0.0);
        assert_eq!(m.impacts_per_period, 0.0);
        assert_eq!(m.peak_normal_force, Some(0.0));
        assert!((m.amp_max_upper * omega * r.q - 1.0).abs() < 1e-12);
    }

    #[test]
    fn contact_fraction_counts_the_cut_sample_by_its_share() {
        // 2.5 samples past 2 periods... use 10.25 samples per period, all closed.
        let omega = TAU * 55.0;
        let mut r = record(10.25, 3.0, |t| (omega * t).sin(), |_| 0.0);
        r.closed.iter_mut().for_each(|c| *c = true);
        let m = r.view().metrics().unwrap();
        assert_eq!(m.periods, 3);
        assert!((m.contact_fraction - 1.0).abs() < 1e-12);
        assert_eq!(m.impacts_per_period, 0.0);
    }

    #[test]
    fn bad_records_are_rejected_naming_the_problem() {
        let omega = TAU * 55.0;
        let r = record(100.0, 2.0, |t| (omega * t).sin(), |_| 0.0);

        let mut v = r.view();
        v.omega = 0.0;
        let e = v.metrics().unwrap_err();
        assert!(
            matches!(e, SignalError::InvalidParameter { name, .. } if name.starts_with("omega"))
        );

        let mut v = r.view();
        v.base_level = -1.0;
        assert!(matches!(
            v.metrics(),
            Err(SignalError::InvalidParameter { .. })
        ));

        let short = &r.up[..99];
        let mut v = r.view();
        v.tip_velocity_upper = short;
        let e = v.metrics().unwrap_err();
        assert!(
            matches!(
                e,
                SignalError::LengthMismatch {
                    channel: "tip_velocity_lower",
                    len: 200,
                    expected: 99,
                    ..
                }
            ),
            "{e}"
        );

        let mut v = r.view();
        let (up, lo, c, f) = (&r.up[..99], &r.lo[..99], &r.closed[..99], &r.force[..99]);
        v.tip_velocity_upper = up;
        v.tip_velocity_lower = lo;
        v.contact_closed = c;
        v.normal_force = Some(f);
        assert!(matches!(v.metrics(), Err(SignalError::TooShort { .. })));

        let mut v = r.view();
        v.tip_velocity_upper = &[];
        v.tip_velocity_lower = &[];
        v.contact_closed = &[];
        v.normal_force = Some(&[]);
        assert!(matches!(v.metrics(), Err(SignalError::Empty { .. })));

        let mut bad = r.lo.clone();
        bad[137] = f64::NAN;
        let mut v = r.view();
        v.tip_velocity_lower = &bad;
        let e = v.metrics().unwrap_err();
        assert!(matches!(
            e,
            SignalError::NonFinite {
                channel: "tip_velocity_lower",
                index: 137,
                ..
            }
        ));
        assert!(e.to_string().contains("tip_velocity_lower"));
        assert!(e.to_string().contains("137"));
    }

    #[test]
    fn helpers_check_lengths_and_period_indices() {
        let grid = PeriodGrid::new(300, 0.01, TAU).unwrap();
        let x = vec![1.0; 300];
        assert_eq!(period_amplitude(&x, &grid, 2), Some(0.0));
        assert_eq!(period_amplitude(&x, &grid, 3), None);
        assert_eq!(period_amplitude(&x[..250], &grid, 2), None);
        assert!(matches!(
            amplitude_stats(&x[..250], &grid),
            Err(SignalError::LengthMismatch {
                channel: "x",
                len: 250,
                expected: 300,
                ..
            })
        ));
        assert!(rms(&x[..10], &grid).is_err());
        assert_eq!(rms(&x, &grid).unwrap(), 1.0);
    }

    #[test]
    fn metrics_round_trip_through_json_with_the_agreed_field_names() {
        let omega = TAU * 55.0;
        let r = record(100.0, 2.0, |t| (omega * t).sin(), |_| 0.0);
        let m = r.view().metrics().unwrap();
        let json = serde_json::to_value(m).unwrap();
        for key in [
            "rms_upper",
            "rms_lower",
            "amp_min_upper",
            "amp_mean_upper",
            "amp_max_upper",
            "amp_min_lower",
            "amp_mean_lower",
            "amp_max_lower",
            "contact_fraction",
            "impacts_per_period",
            "peak_normal_force",
            "periods",
            "spectrum_upper",
        ] {
            assert!(json.get(key).is_some(), "missing {key}");
        }
        let back: StepMetrics = serde_json::from_value(json).unwrap();
        assert_eq!(back, m);
    }
}
