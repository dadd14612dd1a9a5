//! Continuous wavelet transform with the analytic Morlet wavelet (reference section 4.2, the
//! time-frequency analysis of `u / (Omega l)`): magnitudes `|W(f, t)|` for a set of
//! frequencies, by FFT convolution (one forward FFT of the signal, one inverse FFT per
//! frequency).
//!
//! The analytic Morlet wavelet is defined in the frequency domain,
//! `psi_hat(w) = c exp(-(w - omega0)^2 / 2)` for `w > 0` and 0 otherwise (exactly analytic:
//! negative frequencies and DC are rejected; the usual admissibility correction
//! `exp(-omega0^2 / 2)` ~ 1.5e-8 at `omega0 = 6` is not needed). Scale `s` and frequency `f`
//! are related by the centre frequency, `s = omega0 / (2 pi f)`. Normalisations:
//! - [`WaveletNorm::L1`] (default): `W(s, t) = (1/s) int x(tau) psi*((tau - t)/s) dtau`,
//!   `c = 2`, so a tone `A cos(2 pi f t)` gives `|W| = A` at its own frequency: the scalogram
//!   reads as amplitude, comparable across frequencies and between rig and twin.
//! - [`WaveletNorm::L2`]: `W(s, t) = s^(-1/2) int x(tau) psi*((tau - t)/s) dtau`,
//!   `c = sqrt(2) pi^(1/4)` (unit-energy wavelet); `|W|^2` is an energy density, in units of
//!   the signal times sqrt(s).

use super::error::{require_finite, require_positive, SignalError};
use super::fft::{Complex, Fft, ZERO};
use std::f64::consts::{PI, TAU};

/// How the wavelet is normalised across scales (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WaveletNorm {
    /// Amplitude-preserving: a unit tone gives magnitude 1.
    #[default]
    L1,
    /// Energy-preserving (unit-energy wavelet at every scale).
    L2,
}

/// Parameters of the Morlet transform.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MorletParams {
    /// Non-dimensional centre frequency omega0 (default 6: about 6 oscillations within the
    /// Gaussian envelope, the usual time/frequency compromise).
    pub omega0: f64,
    /// Normalisation (default L1).
    pub norm: WaveletNorm,
}

impl Default for MorletParams {
    fn default() -> Self {
        MorletParams {
            omega0: 6.0,
            norm: WaveletNorm::L1,
        }
    }
}

/// Magnitudes of a wavelet transform, row-major `frequencies.len() x n_times`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scalogram {
    /// Analysis frequencies, Hz (as given).
    pub frequencies: Vec<f64>,
    /// Sample interval of the signal, s.
    pub dt: f64,
    /// Number of time samples per row (the signal length).
    pub n_times: usize,
    /// `|W(frequencies[i], k dt)|` at index `i * n_times + k`.
    pub magnitude: Vec<f64>,
}

impl Scalogram {
    /// Row `i`: `|W|` over time at `frequencies[i]`.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.magnitude[i * self.n_times..(i + 1) * self.n_times]
    }

    /// `|W(frequencies[i], k dt)|`.
    pub fn get(&self, i: usize, k: usize) -> f64 {
        self.magnitude[i * self.n_times + k]
    }

    /// Index of the frequency with the largest magnitude at time sample `k` (the ridge).
    pub fn ridge_at(&self, k: usize) -> usize {
        (0..self.frequencies.len())
            .max_by(|&a, &b| self.get(a, k).total_cmp(&self.get(b, k)))
            .unwrap_or(0)
    }
}

/// `count` frequencies from `f_min` to `f_max` (Hz, both included) with a constant ratio.
///
/// Errors: non-positive or non-finite bounds, `f_max < f_min`, `count == 0`.
pub fn log_spaced(f_min: f64, f_max: f64, count: usize) -> Result<Vec<f64>, SignalError> {
    require_positive("f_min (Hz)", f_min)?;
    require_positive("f_max (Hz)", f_max)?;
    if f_max < f_min {
        return Err(SignalError::InvalidParameter {
            name: "f_max (Hz)",
            value: f_max,
            expected: ">= f_min",
        });
    }
    if count == 0 {
        return Err(SignalError::InvalidParameter {
            name: "count",
            value: 0.0,
            expected: ">= 1",
        });
    }
    if count == 1 {
        return Ok(vec![f_min]);
    }
    let ratio = (f_max / f_min).ln() / (count - 1) as f64;
    let mut f: Vec<f64> = (0..count)
        .map(|i| f_min * (ratio * i as f64).exp())
        .collect();
    f[count - 1] = f_max;
    Ok(f)
}

/// Half-width of the cone of influence at `frequency` (Hz), s: the e-folding time
/// `sqrt(2) s` of the wavelet's response to an edge. Closer than this to either end of the
/// record, the magnitudes are affected by the (zero-padded) edges.
pub fn cone_of_influence(frequency: f64, omega0: f64) -> f64 {
    std::f64::consts::SQRT_2 * omega0 / (TAU * frequency)
}

// NOTE: the Gaussian is cut where exp(-d^2 / 2) < 2e-16 relative to its peak.
const GAUSS_CUT: f64 = 8.5;
// NOTE: zero padding covers +-6 scales of the widest wavelet (its envelope exp(-t^2/(2 s^2))
// is 1.5e-8 there), so the circular convolution does not wrap the record onto itself. It is
// capped at the record length: where the wavelet is longer than the record, every time lies
// inside the cone of influence anyway.
const SUPPORT_SCALES: f64 = 6.0;

/// Morlet transform magnitudes of `x` (sampled at `dt`, s) at `frequencies` (Hz).
///
/// The signal's mean is removed first (it is outside every analysis band; removing it keeps
/// the zero padding from adding an edge step). Cost: one FFT and one inverse FFT per
/// frequency of size `M = next_pow2(n + padding)`; memory `frequencies.len() * n` magnitudes.
///
/// Errors: empty or non-finite `x` (channel "x"), invalid `dt` or `omega0`, a frequency outside
/// `(0, 1 / (2 dt)]`.
pub fn morlet_scalogram(
    x: &[f64],
    dt: f64,
    frequencies: &[f64],
    params: &MorletParams,
) -> Result<Scalogram, SignalError> {
    require_positive("dt (s)", dt)?;
    require_positive("omega0", params.omega0)?;
    if x.is_empty() {
        return Err(SignalError::Empty { channel: "x" });
    }
    require_finite("x", x)?;
    let nyquist = 0.5 / dt;
    for (index, &f) in frequencies.iter().enumerate() {
        if !(f.is_finite() && f > 0.0 && f <= nyquist) {
            return Err(SignalError::FrequencyOutOfRange {
                index,
                value: f,
                nyquist,
            });
        }
    }
    let n = x.len();
    let omega0 = params.omega0;
    let mut out = Scalogram {
        frequencies: frequencies.to_vec(),
        dt,
        n_times: n,
        magnitude: vec![0.0; frequencies.len() * n],
    };
    let Some(f_min) = frequencies.iter().copied().reduce(f64::min) else {
        return Ok(out);
    };
    let s_max = omega0 / (TAU * f_min);
    let pad = (SUPPORT_SCALES * s_max / dt).ceil().min(n as f64) as usize;
    let m = (n + pad).next_power_of_two();
    let mut fft = Fft::new(m);

    let mean = x.iter().sum::<f64>() / n as f64;
    let mut spectrum = vec![ZERO; m];
    for (s, &v) in spectrum.iter_mut().zip(x) {
        *s = Complex::new(v - mean, 0.0);
    }
    fft.forward(&mut spectrum);

    let d_omega = TAU / (m as f64 * dt);
    let mut buf = vec![ZERO; m];
    for (i, &f) in frequencies.iter().enumerate() {
        let s = omega0 / (TAU * f);
        let amp = match params.norm {
            WaveletNorm::L1 => 2.0,
            WaveletNorm::L2 => (2.0 * s).sqrt() * PI.powf(0.25),
        };
        // Bins with |s w_j - omega0| <= GAUSS_CUT, positive frequencies only (j = m/2 is the
        // Nyquist bin, reached only for f near Nyquist).
        let j_lo = (((omega0 - GAUSS_CUT) / (s * d_omega)).ceil().max(1.0)) as usize;
        let j_hi = (((omega0 + GAUSS_CUT) / (s * d_omega)).floor() as usize).min(m / 2);
        buf.iter_mut().for_each(|b| *b = ZERO);
        for j in j_lo..=j_hi {
            let d = s * j as f64 * d_omega - omega0;
            buf[j] = spectrum[j].scale(amp * (-0.5 * d * d).exp());
        }
        fft.inverse(&mut buf);
        let row = &mut out.magnitude[i * n..(i + 1) * n];
        for (r, b) in row.iter_mut().zip(&buf) {
            *r = b.norm();
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_spacing_has_exact_ends_and_constant_ratio() {
        let f = log_spaced(10.0, 1000.0, 21).unwrap();
        assert_eq!(f.len(), 21);
        assert_eq!(f[0], 10.0);
        assert_eq!(f[20], 1000.0);
        for w in f.windows(2) {
            assert!((w[1] / w[0] - 10f64.powf(0.1)).abs() < 1e-12);
        }
        assert_eq!(log_spaced(5.0, 9.0, 1).unwrap(), vec![5.0]);
        assert!(log_spaced(0.0, 9.0, 3).is_err());
        assert!(log_spaced(10.0, 9.0, 3).is_err());
        assert!(log_spaced(1.0, 9.0, 0).is_err());
    }

    /// Samples away from both edges by 5 cones of influence of `f_low` (the edge response
    /// decays as exp(-(t / coi)^2), e^-25 there).
    fn interior(n: usize, dt: f64, f_low: f64) -> std::ops::Range<usize> {
        let edge = (5.0 * cone_of_influence(f_low, 6.0) / dt).ceil() as usize;
        edge..n - edge
    }

    #[test]
    fn a_tone_peaks_at_its_frequency_with_unit_gain_in_l1() {
        let (fs, f0, amp) = (2_000.0, 55.0, 0.7);
        let dt = 1.0 / fs;
        let n = 4_000;
        let x: Vec<f64> = (0..n)
            .map(|k| 0.25 + amp * (TAU * f0 * k as f64 * dt + 0.3).cos())
            .collect();
        let mut freqs = log_spaced(20.0, 400.0, 50).unwrap();
        freqs.push(f0);
        let sc = morlet_scalogram(&x, dt, &freqs, &MorletParams::default()).unwrap();
        let nearest = (0..freqs.len())
            .min_by(|&a, &b| {
                (f0 / freqs[a] - 1.0)
                    .abs()
                    .total_cmp(&(f0 / freqs[b] - 1.0).abs())
            })
            .unwrap();
        assert_eq!(freqs[nearest], f0);
        let mut worst: f64 = 0.0;
        for k in interior(n, dt, 20.0) {
            assert_eq!(sc.ridge_at(k), nearest, "time sample {k}");
            worst = worst.max((sc.get(freqs.len() - 1, k) - amp).abs());
        }
        assert!(worst < 1e-9 * amp, "L1 gain error {worst:e}");
    }

    #[test]
    fn l2_normalisation_scales_with_the_square_root_of_scale() {
        let (fs, f0) = (1_000.0, 40.0);
        let dt = 1.0 / fs;
        let n = 3_000;
        let x: Vec<f64> = (0..n).map(|k| (TAU * f0 * k as f64 * dt).sin()).collect();
        let p = MorletParams {
            norm: WaveletNorm::L2,
            ..Default::default()
        };
        let sc = morlet_scalogram(&x, dt, &[f0], &p).unwrap();
        // |W| = (1/2) sqrt(s) sqrt(2) pi^(1/4) for a unit tone at its own scale.
        let s = 6.0 / (TAU * f0);
        let expected = 0.5 * (2.0 * s).sqrt() * PI.powf(0.25);
        for k in interior(n, dt, f0) {
            assert!(
                (sc.get(0, k) - expected).abs() < 1e-9 * expected,
                "{k}: {} vs {expected}",
                sc.get(0, k)
            );
        }
    }

    #[test]
    fn the_ridge_of_a_chirp_follows_the_instantaneous_frequency() {
        // Linear chirp 20 -> 100 Hz over 4 s.
        let (fs, f_a, rate) = (2_000.0, 20.0, 20.0);
        let dt = 1.0 / fs;
        let n = 8_000;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                (TAU * (f_a * t + 0.5 * rate * t * t)).sin()
            })
            .collect();
        let freqs = log_spaced(10.0, 200.0, 80).unwrap();
        let step = freqs[1] / freqs[0] - 1.0; // 3.9 % spacing
        let sc = morlet_scalogram(&x, dt, &freqs, &MorletParams::default()).unwrap();
        let mut worst: f64 = 0.0;
        for k in (1_000..7_000).step_by(50) {
            let f_inst = f_a + rate * k as f64 * dt;
            let f_ridge = freqs[sc.ridge_at(k)];
            worst = worst.max((f_ridge / f_inst - 1.0).abs());
        }
        assert!(
            worst <= 0.6 * step,
            "ridge off by {worst:.4} (spacing {step:.4})"
        );
    }

    #[test]
    fn rejects_bad_inputs() {
        let x = vec![0.0; 100];
        let p = MorletParams::default();
        assert!(matches!(
            morlet_scalogram(&x, 1e-3, &[10.0, 600.0], &p),
            Err(SignalError::FrequencyOutOfRange { index: 1, .. })
        ));
        assert!(matches!(
            morlet_scalogram(&[], 1e-3, &[10.0], &p),
            Err(SignalError::Empty { .. })
        ));
        let mut bad = x.clone();
        bad[7] = f64::INFINITY;
        assert!(matches!(
            morlet_scalogram(&bad, 1e-3, &[10.0], &p),
            Err(SignalError::NonFinite {
                channel: "x",
                index: 7,
                ..
            })
        ));
        assert!(morlet_scalogram(&x, 0.0, &[10.0], &p).is_err());
        let empty = morlet_scalogram(&x, 1e-3, &[], &p).unwrap();
        assert!(empty.magnitude.is_empty());
    }
}
