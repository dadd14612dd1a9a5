//! Band spectrum of a step's response and the log-spectral distance between two of them: how
//! the twin's spectrum differs from the measurement's, harmonics and the content between them
//! (modulation sidebands and subharmonics of an impacting response) alike.
//!
//! The bands are half-harmonic: band `k` (k = 1 ..= [`SPECTRUM_BANDS`]) is centred on
//! `k Omega / 2` and spans `((k - 1/2) Omega / 2, (k + 1/2) Omega / 2]`, so odd bands hold the
//! half-integer content (period doubling, beats near Omega / 2 away) and even bands the
//! harmonics `Omega, 2 Omega, ...` up to `10 Omega`. A band's value is the RMS of the signal's
//! content in it, from a Hann-windowed periodogram of the record's whole periods (zero-padded
//! to a power of two) and Parseval's relation; the values of all bands square-sum to the
//! signal's mean square in `(Omega / 4, 10.25 Omega]`.
//!
//! NOTE: the Hann window spreads a line over +-2 bins of width `2 pi / (N_pad dt)`, which is
//! far below the band width `Omega / 2` for any record of a few periods; leakage across band
//! edges is below -60 dB for records of 20 periods and more.

use super::error::{require_len, SignalError};
use super::fft::{Complex, Fft, ZERO};
use super::periods::PeriodGrid;

/// Number of half-harmonic bands: `Omega / 2` to `10 Omega`.
pub const SPECTRUM_BANDS: usize = 20;

/// Floor of [`spectrum_distance_db`], relative to the strongest band of the reference (the
/// measurement) in power: -60 dB. Bands below it in both spectra do not count as differences
/// (noise, quantisation, integration drift).
pub const SPECTRUM_FLOOR_DB: f64 = -60.0;

/// RMS of `x` in each half-harmonic band of the excitation `omega` (rad/s), over the whole
/// periods of `grid` (samples `dt` s apart). Same unit as `x`.
pub fn band_spectrum(
    x: &[f64],
    dt: f64,
    omega: f64,
    grid: &PeriodGrid,
) -> Result<[f64; SPECTRUM_BANDS], SignalError> {
    require_len("x", x.len(), "the period grid", grid.samples())?;
    let n = grid.used_samples();
    let mut bands = [0.0; SPECTRUM_BANDS];
    if n < 2 {
        return Ok(bands);
    }
    let m = n.next_power_of_two();
    // Periodic Hann window over the used samples; its mean square normalises the power.
    let w = |k: usize| 0.5 - 0.5 * (std::f64::consts::TAU * k as f64 / n as f64).cos();
    let mean = x[..n].iter().sum::<f64>() / n as f64;
    let mut buf = vec![ZERO; m];
    let mut w2 = 0.0;
    for (k, (b, &v)) in buf.iter_mut().zip(&x[..n]).enumerate() {
        let wk = w(k);
        w2 += wk * wk;
        *b = Complex::new(wk * (v - mean), 0.0);
    }
    Fft::new(m).forward(&mut buf);
    // Parseval: sum_j |X_j|^2 = m sum_k |x_w,k|^2, and mean(x^2) ~ sum_k |x_w,k|^2 / sum_k w_k^2.
    // One-sided: bins j and m - j carry the same power.
    let norm = 2.0 / (m as f64 * w2);
    let bin_omega = std::f64::consts::TAU / (m as f64 * dt);
    let half = omega / 2.0;
    let mut power = [0.0; SPECTRUM_BANDS];
    for (j, xj) in buf.iter().enumerate().take(m / 2).skip(1) {
        // Band index of bin j: round(omega_j / (Omega / 2)), bands 1 ..= SPECTRUM_BANDS.
        let b = (j as f64 * bin_omega / half).round();
        if b >= 1.0 && b <= SPECTRUM_BANDS as f64 {
            power[b as usize - 1] += (xj.re * xj.re + xj.im * xj.im) * norm;
        }
    }
    for (r, p) in bands.iter_mut().zip(power) {
        *r = p.sqrt();
    }
    Ok(bands)
}

/// Log-spectral distance of `candidate` from `reference` (two [`band_spectrum`]s), dB: the
/// RMS over the bands of `20 log10((a_k + f) / (r_k + f))`, with the floor `f` at
/// [`SPECTRUM_FLOOR_DB`] below the reference's strongest band. 0 for equal spectra; a
/// candidate twice the reference in every band gives 6.02 dB. `NaN` when the reference is
/// all zero or either spectrum is not finite.
pub fn spectrum_distance_db(
    candidate: &[f64; SPECTRUM_BANDS],
    reference: &[f64; SPECTRUM_BANDS],
) -> f64 {
    let peak = reference.iter().copied().fold(0.0, f64::max);
    if peak <= 0.0 || !peak.is_finite() {
        return f64::NAN;
    }
    let floor = peak * 10f64.powf(SPECTRUM_FLOOR_DB / 20.0);
    let sum: f64 = candidate
        .iter()
        .zip(reference)
        .map(|(&a, &r)| {
            let d = 20.0 * ((a + floor) / (r + floor)).log10();
            d * d
        })
        .sum();
    (sum / SPECTRUM_BANDS as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn grid_for(n: usize, dt: f64, omega: f64) -> PeriodGrid {
        PeriodGrid::new(n, dt, omega).unwrap()
    }

    #[test]
    fn tones_land_in_their_bands_with_their_rms() {
        // 55 Hz excitation sampled at 10240 Hz (not a whole number of samples per period),
        // 60 periods: a fundamental, a third harmonic and a subharmonic at Omega / 2.
        let omega = TAU * 55.0;
        let dt = 1.0 / 10240.0;
        let n = (60.0 * 10240.0 / 55.0) as usize + 7;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                0.3 + 2.0 * (omega * t).sin()
                    + 0.5 * (3.0 * omega * t + 1.0).cos()
                    + 0.1 * (0.5 * omega * t).sin()
            })
            .collect();
        let s = band_spectrum(&x, dt, omega, &grid_for(n, dt, omega)).unwrap();
        let rms = |a: f64| a / 2f64.sqrt();
        // Band k is centred on k Omega / 2: Omega / 2 in band 1, Omega in 2, 3 Omega in 6.
        assert!((s[0] / rms(0.1) - 1.0).abs() < 1e-3, "{s:?}");
        assert!((s[1] / rms(2.0) - 1.0).abs() < 1e-3, "{s:?}");
        assert!((s[5] / rms(0.5) - 1.0).abs() < 1e-3, "{s:?}");
        // Everything else (the offset included) is leakage, 60 dB down at the least.
        for (k, v) in s.iter().enumerate() {
            if ![0, 1, 5].contains(&k) {
                assert!(*v < 2e-3 * rms(2.0), "band {}: {v}", k + 1);
            }
        }
    }

    #[test]
    fn distance_is_zero_for_equal_spectra_and_6_db_for_double() {
        let mut r = [0.0; SPECTRUM_BANDS];
        for (k, v) in r.iter_mut().enumerate() {
            *v = 1.0 / (1.0 + k as f64);
        }
        assert_eq!(spectrum_distance_db(&r, &r), 0.0);
        let double = r.map(|v| 2.0 * v);
        let d = spectrum_distance_db(&double, &r);
        // The floor (1e-3 of the strongest band) pulls each band's ratio a little below 2.
        let floor = 1e-3;
        let expected = (r
            .iter()
            .map(|v| (20.0 * ((2.0 * v + floor) / (v + floor)).log10()).powi(2))
            .sum::<f64>()
            / SPECTRUM_BANDS as f64)
            .sqrt();
        assert!((d - expected).abs() < 1e-12, "{d} {expected}");
        assert!((d - 20.0 * 2f64.log10()).abs() < 0.1, "{d}");
        // A band missing in the candidate counts as much as the floor allows, not infinitely.
        let mut missing = r;
        missing[1] = 0.0;
        let d = spectrum_distance_db(&missing, &r);
        let worst = 20.0 * ((r[1] + floor) / floor).log10();
        assert!(
            (d - worst / (SPECTRUM_BANDS as f64).sqrt()).abs() < 1e-9,
            "{d}"
        );
        assert!(spectrum_distance_db(&r, &[0.0; SPECTRUM_BANDS]).is_nan());
    }

    #[test]
    fn a_short_record_is_checked_against_the_grid() {
        let g = grid_for(100, 0.01, TAU);
        assert!(band_spectrum(&[0.0; 99], 0.01, TAU, &g).is_err());
    }
}
