//! Sensor noise as the comparison sees it: the white noise floor of a measured channel,
//! estimated from the record window itself ([`noise_floor`]), and the same noise laid on the
//! model's channel ([`add_white_noise`]) so that features that noise biases are compared
//! like with like.
//!
//! Why it matters: a per-period zero-to-peak amplitude is the extreme of the period's
//! samples, and white noise raises it by about 1.3 standard deviations of the noise at 200
//! samples per period (the extremes pick the positive and negative excursions). The RMS is
//! biased only to second order. A vibrometer reads velocity with white noise, so at a low
//! level, or on the beam that is off its resonance, its amplitude quantiles sit several
//! percent above a noiseless model's while every RMS agrees: without the noise on the
//! model's side, a long record window (small spreads) scores that as a mismatch of the
//! model. The accelerometers' noise is integrated into velocity (weighted by 1 / omega), so
//! their floor here is small; it is estimated and applied all the same.
//!
//! **Estimator.** White noise of RMS `s` gives the fourth difference
//! `d_i = x_i - 4 x_{i+1} + 6 x_{i+2} - 4 x_{i+3} + x_{i+4}` the variance `70 s^2`, while a
//! signal sampled `N` times per period of its highest content is attenuated by
//! `(2 sin(pi / N))^4`: 1e-5 at 50 Hz and 10 kHz, 0.09 for a mode at 900 Hz. The estimate is
//! the median absolute fourth difference scaled to a standard deviation (`1.4826 MAD /
//! sqrt(70)`), robust to the few samples around an impact.
//!
// NOTE: in a window with impacts the fourth difference measures the ringing of the higher
// modes, not the sensor: on the simulated rig the estimate rises 10x on the vibrometer and
// 1000x on the accelerometers in the impact band. The step summary therefore gives no floor
// for a window with contact (`crate::control::StepSummary::noise_floor`); there the noise is
// negligible beside the response's amplitudes.
//
// NOTE: the estimator sees the noise near the Nyquist frequency, so it measures noise added
// after the anti-alias filter (the ADC's, the conditioning's; the simulated rig's DAQ adds its
// noise there). A sensor noise shaped by the anti-alias filter is under-estimated, and the
// model's amplitudes then stay below the measured ones by the difference: the comparison
// errs towards reporting a mismatch, never towards hiding one.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// The white noise floor of one measured channel over a record window.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct NoiseFloor {
    /// The channel (a compared beam channel's name).
    pub channel: String,
    /// RMS of the white noise on the channel's relative velocity, m/s.
    pub rms: f64,
}

/// Standard normal deviates by the Box-Muller transform (both deviates of a pair used), from a
/// seeded ChaCha8 generator: the same seed gives the same deviates on every machine.
#[derive(Clone, Debug)]
pub struct Gaussian {
    rng: ChaCha8Rng,
    spare: Option<f64>,
}

impl Gaussian {
    /// The generator seeded with `seed`.
    pub fn new(seed: u64) -> Gaussian {
        Gaussian {
            rng: ChaCha8Rng::seed_from_u64(seed),
            spare: None,
        }
    }

    /// The next deviate.
    #[allow(clippy::should_implement_trait)]
    #[inline]
    pub fn next(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        // u1 in (0, 1] so that ln(u1) is finite.
        let u1 = 1.0 - self.rng.gen::<f64>();
        let u2 = self.rng.gen::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

/// Variance of the fourth difference of unit white noise: `1 + 16 + 36 + 16 + 1`.
const FOURTH_DIFFERENCE_VARIANCE: f64 = 70.0;

/// Standard deviation over median absolute deviation of a normal distribution.
const MAD_TO_STD: f64 = 1.482_602_218_505_602;

/// The RMS of the white noise on `x` (module docs): 0 for fewer than 5 samples; NaN if `x`
/// holds a non-finite sample.
pub fn noise_floor(x: &[f64]) -> f64 {
    if x.len() < 5 {
        return 0.0;
    }
    let mut d: Vec<f64> = x
        .windows(5)
        .map(|w| (w[0] - 4.0 * w[1] + 6.0 * w[2] - 4.0 * w[3] + w[4]).abs())
        .collect();
    if d.iter().any(|v| !v.is_finite()) {
        return f64::NAN;
    }
    let mid = d.len() / 2;
    let (_, median, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    MAD_TO_STD * *median / FOURTH_DIFFERENCE_VARIANCE.sqrt()
}

/// Adds white noise of RMS `rms` from a generator seeded with `seed` to every sample of `x`
/// (nothing for `rms <= 0` or a non-finite `rms`).
pub fn add_white_noise(x: &mut [f64], rms: f64, seed: u64) {
    if !(rms > 0.0 && rms.is_finite()) {
        return;
    }
    let mut g = Gaussian::new(seed);
    for v in x {
        *v += rms * g.next();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// `periods` periods of a sine of amplitude `a` at `spp` samples per period, plus white
    /// noise of RMS `s`.
    fn sine(a: f64, spp: usize, periods: usize, s: f64, seed: u64) -> Vec<f64> {
        let mut x: Vec<f64> = (0..spp * periods)
            .map(|i| a * (TAU * i as f64 / spp as f64 + 0.3).sin())
            .collect();
        add_white_noise(&mut x, s, seed);
        x
    }

    #[test]
    fn the_floor_of_a_noisy_sine_is_its_noise() {
        for (a, s) in [(1.0, 0.01), (1.0, 0.05), (100.0, 0.02)] {
            let x = sine(a, 218, 100, s, 7);
            let est = noise_floor(&x);
            // 21,800 samples: the MAD's standard error is about 1 %.
            assert!((est / s - 1.0).abs() < 0.04, "{est} for {s} on {a}");
        }
        // A noiseless sine at 218 samples per period: the fourth difference is 1e-5 of it.
        let quiet = noise_floor(&sine(1.0, 218, 10, 0.0, 1));
        assert!(quiet < 1e-5, "{quiet}");
    }

    #[test]
    fn impacts_barely_move_the_floor() {
        // Velocity jumps (an impact's) in 2 periods of 3, one sample wide, 100x the noise.
        let s = 0.01;
        let mut x = sine(1.0, 218, 90, s, 3);
        for p in (0..90).filter(|p| p % 3 != 0) {
            for v in &mut x[p * 218 + 50..] {
                *v += if p % 2 == 0 { 1.0 } else { -1.0 };
            }
        }
        let est = noise_floor(&x);
        assert!((est / s - 1.0).abs() < 0.06, "{est}");
    }

    #[test]
    fn the_noise_raises_the_peaks_as_on_the_rig() {
        // What the module docs say: the half peak-to-peak per period of a sine with noise
        // 1 % of its amplitude at 218 samples a period is about 1.3 % above the amplitude.
        let x = sine(1.0, 218, 200, 0.01, 11);
        let mean: f64 = x
            .chunks(218)
            .map(|c| {
                let (lo, hi) = c
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                        (l.min(v), h.max(v))
                    });
                0.5 * (hi - lo)
            })
            .sum::<f64>()
            / 200.0;
        assert!((1.008..1.02).contains(&mean), "{mean}");
    }

    #[test]
    fn short_or_broken_records() {
        assert_eq!(noise_floor(&[1.0, 2.0, 3.0, 4.0]), 0.0);
        assert!(noise_floor(&[0.0, 1.0, f64::NAN, 0.0, 1.0, 2.0]).is_nan());
        let mut x = vec![1.0; 8];
        add_white_noise(&mut x, 0.0, 1);
        add_white_noise(&mut x, f64::NAN, 1);
        assert_eq!(x, vec![1.0; 8]);
    }

    #[test]
    fn the_same_seed_gives_the_same_noise() {
        let (mut a, mut b, mut c) = (vec![0.0; 64], vec![0.0; 64], vec![0.0; 64]);
        add_white_noise(&mut a, 1.0, 5);
        add_white_noise(&mut b, 1.0, 5);
        add_white_noise(&mut c, 1.0, 6);
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
