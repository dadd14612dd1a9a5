//! Synchronous demodulation of the fundamental harmonic over whole excitation periods: in batch
//! over a record ([`demodulate`]) and streaming, one result per completed period
//! ([`Demodulator`], for the amplitude controller: O(1) per sample, no allocation).
//!
//! With `t_k = t_0 + k dt` and `L` the length of the whole periods used,
//! `mean = (1/L) int x dt`, `cos = (2/L) int x cos(Omega t) dt`, `sin = (2/L) int x sin(Omega t) dt`,
//! integrated with the period quadrature of [`super::periods`] (sample-accurate fractional
//! period boundaries, exact for integer samples per period, `O((Omega dt)^4)` otherwise).
//! The DC offset and every other harmonic below the Nyquist frequency are orthogonal to the
//! fundamental over whole periods and drop out.

use super::error::{require_finite, SignalError};
use super::periods::{partial_weights, samples_per_period, snap, PeriodGrid};
use std::f64::consts::TAU;

/// Fundamental harmonic of a signal over whole periods:
/// `x(t) ~ mean + cos cos(Omega t) + sin sin(Omega t) = mean + magnitude cos(Omega t + phase)`.
/// The complex amplitude is `X = cos - i sin = magnitude e^{i phase}`, `x = Re(X e^{i Omega t})`.
/// Units of `mean`, `cos`, `sin`, `magnitude`: those of the signal; `phase` in rad, (-pi, pi].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Harmonic {
    /// Mean (DC) over the periods used.
    pub mean: f64,
    /// Coefficient of `cos(Omega t)`.
    pub cos: f64,
    /// Coefficient of `sin(Omega t)`.
    pub sin: f64,
    /// `sqrt(cos^2 + sin^2)`.
    pub magnitude: f64,
    /// `atan2(-sin, cos)`, rad.
    pub phase: f64,
}

impl Harmonic {
    /// From the integrals `[int x, int x cos, int x sin]` (in units of samples) over a span of
    /// `length` samples.
    fn from_integrals(i: [f64; 3], length: f64) -> Self {
        let cos = 2.0 * i[1] / length;
        let sin = 2.0 * i[2] / length;
        Harmonic {
            mean: i[0] / length,
            cos,
            sin,
            magnitude: cos.hypot(sin),
            phase: (-sin).atan2(cos),
        }
    }
}

/// Fundamental harmonic of `x` (sampled at `t_k = t0 + k dt`, `dt` in s) at `omega` (rad/s),
/// over all whole periods of the record counted from its first sample.
///
/// Errors: invalid `dt`, `omega` or `t0`, non-finite samples (channel "x"), fewer than 4
/// samples per period, less than one whole period.
pub fn demodulate(x: &[f64], dt: f64, omega: f64, t0: f64) -> Result<Harmonic, SignalError> {
    if x.is_empty() {
        return Err(SignalError::Empty { channel: "x" });
    }
    let grid = PeriodGrid::new(x.len(), dt, omega)?;
    require_t0(t0)?;
    require_finite("x", x)?;
    let phase0 = (omega * t0).rem_euclid(TAU);
    let step = omega * dt;
    let angle = |k: usize| phase0 + step * k as f64;
    let i0 = grid.integrate_window(|k| x[k]);
    let ic = grid.integrate_window(|k| x[k] * angle(k).cos());
    let is = grid.integrate_window(|k| x[k] * angle(k).sin());
    Ok(Harmonic::from_integrals(
        [i0, ic, is],
        grid.boundary(grid.periods()),
    ))
}

fn require_t0(t0: f64) -> Result<(), SignalError> {
    if t0.is_finite() {
        Ok(())
    } else {
        Err(SignalError::InvalidParameter {
            name: "t0 (s)",
            value: t0,
            expected: "finite",
        })
    }
}

/// The fundamental over one completed period, from [`Demodulator::push`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PeriodHarmonic {
    /// Index of the period since the demodulator started (0-based).
    pub period: u64,
    /// Time at which the period ended, s (same clock as `t0`).
    pub end_time: f64,
    /// The fundamental over this period.
    pub harmonic: Harmonic,
    /// Non-finite samples that entered this period (replaced by 0). A controller must not act
    /// on a period with invalid samples.
    pub invalid_samples: u32,
}

/// Streaming synchronous demodulator: feed samples one at a time, get the fundamental of each
/// completed excitation period. O(1) per sample, no allocation, no clock.
///
/// Period `p` spans `[t0 + p T, t0 + (p + 1) T)`, `T = 2 pi / Omega`; its result is returned by
/// the `push` of the last sample at or before its end (no look-ahead). Summed over periods the
/// results equal [`demodulate`] over the same samples.
#[derive(Debug, Clone)]
pub struct Demodulator {
    t0: f64,
    dt: f64,
    omega: f64,
    samples_per_period: f64,
    /// Omega dt, rad per sample.
    step: f64,
    /// Omega t0 mod 2 pi.
    phase0: f64,
    /// Index of the next sample.
    k: u64,
    period: u64,
    /// Boundary (fractional sample position, snapped) where the current period ends.
    next: f64,
    /// Integrals [x, x cos, x sin] of the current period so far (units of samples).
    acc: [f64; 3],
    /// Integrands of the last three samples, newest first.
    history: [[f64; 3]; 3],
    invalid: u32,
}

impl Demodulator {
    /// Demodulator at `omega` (rad/s) for samples at `t_k = t0 + k dt` (s).
    ///
    /// Errors: invalid `dt`, `omega`, `t0`, or fewer than 4 samples per period.
    pub fn new(omega: f64, dt: f64, t0: f64) -> Result<Self, SignalError> {
        let spp = samples_per_period(dt, omega)?;
        require_t0(t0)?;
        Ok(Demodulator {
            t0,
            dt,
            omega,
            samples_per_period: spp,
            step: omega * dt,
            phase0: (omega * t0).rem_euclid(TAU),
            k: 0,
            period: 0,
            next: snap(spp),
            acc: [0.0; 3],
            history: [[0.0; 3]; 3],
            invalid: 0,
        })
    }

    /// Excitation frequency, rad/s.
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Samples per period, `2 pi / (Omega dt)`.
    pub fn samples_per_period(&self) -> f64 {
        self.samples_per_period
    }

    /// Number of samples pushed so far.
    pub fn samples(&self) -> u64 {
        self.k
    }

    /// Feeds the next sample; returns the fundamental of the period that this sample completes.
    /// A non-finite sample is replaced by 0 and counted in
    /// [`PeriodHarmonic::invalid_samples`].
    pub fn push(&mut self, x: f64) -> Option<PeriodHarmonic> {
        let k = self.k as f64;
        // Position within the current period from the unsnapped start, so the phase reference
        // stays Omega t exactly (the start differs from p S by at most the snap tolerance).
        let rel = k - self.period as f64 * self.samples_per_period;
        let (s, c) = (self.phase0 + self.step * rel).sin_cos();
        let bad = !x.is_finite();
        let x = if bad { 0.0 } else { x };
        let f = [x, x * c, x * s];
        self.invalid = self.invalid.saturating_add(u32::from(bad));

        let mut out = None;
        if self.next <= k + 1.0 {
            // The period ends inside this sample's interval: theta in (0, 1] of it belongs to
            // the current period (with the boundary corrections), the rest to the next.
            let w = partial_weights(self.next - k);
            let h = &self.history;
            let mut before = [0.0; 3];
            for (i, b) in before.iter_mut().enumerate() {
                *b = w[0] * f[i] + w[1] * h[0][i] + w[2] * h[1][i] + w[3] * h[2][i];
            }
            let start = snap(self.period as f64 * self.samples_per_period);
            let mut total = self.acc;
            for (t, b) in total.iter_mut().zip(before) {
                *t += b;
            }
            out = Some(PeriodHarmonic {
                period: self.period,
                end_time: self.t0 + self.next * self.dt,
                harmonic: Harmonic::from_integrals(total, self.next - start),
                invalid_samples: self.invalid,
            });
            for (a, (fi, b)) in self.acc.iter_mut().zip(f.iter().zip(before)) {
                *a = fi - b;
            }
            self.invalid = u32::from(bad);
            self.period += 1;
            self.next = snap((self.period + 1) as f64 * self.samples_per_period);
        } else {
            for (a, fi) in self.acc.iter_mut().zip(f) {
                *a += fi;
            }
        }
        self.history = [f, self.history[0], self.history[1]];
        self.k += 1;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// DC + fundamental + harmonics, as a function of time.
    fn signal(omega: f64, mean: f64, a: f64, b: f64) -> impl Fn(f64) -> f64 {
        move |t: f64| {
            let w = omega * t;
            mean + a * w.cos()
                + b * w.sin()
                + 0.3 * (2.0 * w + 1.0).cos()
                + 0.2 * (3.0 * w).sin()
                + 0.1 * (6.0 * w + 0.5).cos()
        }
    }

    fn sampled(x: impl Fn(f64) -> f64, t0: f64, dt: f64, n: usize) -> Vec<f64> {
        (0..n).map(|k| x(t0 + k as f64 * dt)).collect()
    }

    fn check(h: &Harmonic, mean: f64, a: f64, b: f64, tol: f64) {
        assert!((h.mean - mean).abs() < tol, "mean {} vs {mean}", h.mean);
        assert!((h.cos - a).abs() < tol, "cos {} vs {a}", h.cos);
        assert!((h.sin - b).abs() < tol, "sin {} vs {b}", h.sin);
        assert!((h.magnitude - a.hypot(b)).abs() < tol);
        assert!((h.phase - (-b).atan2(a)).abs() < tol / a.hypot(b));
    }

    #[test]
    fn fundamental_with_dc_and_harmonics_integer_samples_per_period() {
        let omega = TAU * 55.0;
        let dt = 1.0 / (1000.0 * 55.0);
        let x = sampled(signal(omega, 0.7, 1.3, -0.4), 0.0, dt, 8000);
        let h = demodulate(&x, dt, omega, 0.0).unwrap();
        check(&h, 0.7, 1.3, -0.4, 1e-12);
    }

    #[test]
    fn fundamental_with_fractional_samples_per_period_and_time_offset() {
        // A fixed-rate DAQ: 55 Hz sampled at 55 010.37 Hz (1000.1885 samples per period)
        // and at 19 327 Hz (351.4 per period), the record ending inside a period.
        for (fs, n) in [(55_010.37, 7_777), (19_327.0, 2_700)] {
            let omega = TAU * 55.0;
            let dt = 1.0 / fs;
            let t0 = 12.345_678;
            let x = sampled(signal(omega, -0.2, 0.9, 0.6), t0, dt, n);
            let h = demodulate(&x, dt, omega, t0).unwrap();
            check(&h, -0.2, 0.9, 0.6, 1e-9);
        }
    }

    #[test]
    fn streaming_periods_are_accurate_and_sum_to_the_batch_result() {
        let omega = TAU * 55.0;
        let dt = 1.0 / 55_010.37;
        let t0 = 0.5;
        let x = sampled(signal(omega, 0.1, -0.5, 1.1), t0, dt, 10_500);
        let mut d = Demodulator::new(omega, dt, t0).unwrap();
        let periods: Vec<PeriodHarmonic> = x.iter().filter_map(|&v| d.push(v)).collect();
        let batch = demodulate(&x, dt, omega, t0).unwrap();
        assert_eq!(periods.len(), 10);
        let (mut sc, mut ss) = (0.0, 0.0);
        for (p, r) in periods.iter().enumerate() {
            assert_eq!(r.period, p as u64);
            assert_eq!(r.invalid_samples, 0);
            check(&r.harmonic, 0.1, -0.5, 1.1, 1e-9);
            let t_end = t0 + (p + 1) as f64 * TAU / omega;
            assert!((r.end_time - t_end).abs() < 1e-12);
            sc += r.harmonic.cos;
            ss += r.harmonic.sin;
        }
        assert!((sc / 10.0 - batch.cos).abs() < 1e-13);
        assert!((ss / 10.0 - batch.sin).abs() < 1e-13);
    }

    #[test]
    fn streaming_result_arrives_with_the_last_sample_of_the_period() {
        let omega = TAU;
        let dt = 1e-2; // 100 samples per period
        let mut d = Demodulator::new(omega, dt, 0.0).unwrap();
        for k in 0..300 {
            let r = d.push((omega * k as f64 * dt).sin());
            assert_eq!(r.is_some(), k % 100 == 99, "sample {k}");
            if let Some(r) = r {
                check(&r.harmonic, 0.0, 0.0, 1.0, 1e-13);
            }
        }
    }

    #[test]
    fn noise_gives_the_statistically_expected_scatter() {
        // White noise of std sigma over N samples of whole periods gives cos/sin estimates with
        // std sigma sqrt(2 / N). Check the scatter over 400 records.
        let omega = TAU * 10.0;
        let dt = 1.0 / 1_234.5; // 123.45 samples per period
        let n = 1_300; // 10 whole periods, 1234 or 1235 samples used
        let sigma = 0.05;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
        let clean = sampled(signal(omega, 0.3, 1.0, 0.5), 0.0, dt, n);
        let trials = 400;
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..trials {
            let x: Vec<f64> = clean
                .iter()
                .map(|&v| {
                    // Box-Muller.
                    let (u1, u2): (f64, f64) = (rng.gen_range(1e-300..1.0), rng.gen());
                    v + sigma * (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
                })
                .collect();
            let e = demodulate(&x, dt, omega, 0.0).unwrap().cos - 1.0;
            s1 += e;
            s2 += e * e;
        }
        let mean = s1 / trials as f64;
        let std = (s2 / trials as f64 - mean * mean).sqrt();
        let expected = sigma * (2.0 / 1234.5f64).sqrt();
        // The sample std of 400 draws is within ~7 % (1 sigma) of the truth; allow 25 %.
        assert!(
            (std / expected - 1.0).abs() < 0.25,
            "std {std:e}, expected {expected:e}"
        );
        assert!(mean.abs() < 4.0 * expected / (trials as f64).sqrt());
    }

    #[test]
    fn invalid_samples_are_reported() {
        let omega = TAU;
        let dt = 1e-2;
        let mut x = sampled(|t| (omega * t).sin(), 0.0, dt, 200);
        x[150] = f64::NAN;
        assert!(matches!(
            demodulate(&x, dt, omega, 0.0),
            Err(SignalError::NonFinite {
                channel: "x",
                index: 150,
                ..
            })
        ));
        let mut d = Demodulator::new(omega, dt, 0.0).unwrap();
        let r: Vec<PeriodHarmonic> = x.iter().filter_map(|&v| d.push(v)).collect();
        assert_eq!(r[0].invalid_samples, 0);
        assert_eq!(r[1].invalid_samples, 1);
        assert!(r[1].harmonic.magnitude.is_finite());
    }

    #[test]
    fn rejects_bad_parameters() {
        assert!(Demodulator::new(-1.0, 1e-3, 0.0).is_err());
        assert!(Demodulator::new(1.0, 0.0, 0.0).is_err());
        assert!(Demodulator::new(1.0, 1e-3, f64::INFINITY).is_err());
        assert!(matches!(
            Demodulator::new(TAU * 400.0, 1e-3, 0.0),
            Err(SignalError::TooCoarse { .. })
        ));
        assert!(matches!(
            demodulate(&[0.0; 50], 1e-2, TAU, 0.0),
            Err(SignalError::TooShort { .. })
        ));
    }
}
