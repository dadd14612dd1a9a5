//! Drift-free integration of a measured signal over a record of whole excitation periods
//! (acceleration -> velocity -> displacement), for records that sample a steady response.
//!
//! Integrating a measured acceleration accumulates its offset (sensor bias, a DC drift of
//! the conditioning) into a ramp, and the unknown initial velocity into a constant. Over whole
//! periods of a steady vibration the acceleration has zero mean and so does the velocity:
//! [`integrate_periodic`] removes the whole-period mean of the input, integrates by the
//! trapezoidal rule and removes the whole-period mean of the result. Every harmonic of the
//! excitation passes unchanged in amplitude (the trapezoidal rule's gain error at `Omega dt`
//! is `(Omega dt)^2 / 12`: 1e-4 at 100 samples per period); the bias and the constant of
//! integration drop out exactly.

use super::error::{require_finite, require_len, require_positive, SignalError};
use super::periods::PeriodGrid;

/// `y(t) = int x dt` over the record (sample interval `dt`, s) with the whole-period means of
/// `x` and `y` removed (module docs). Same length as `x`; `grid` must describe `x` (same
/// sample count).
///
/// Errors: a grid of another length, non-finite samples (channel "x"), a bad `dt`.
pub fn integrate_periodic(x: &[f64], dt: f64, grid: &PeriodGrid) -> Result<Vec<f64>, SignalError> {
    require_len("x", x.len(), "period grid", grid.samples())?;
    require_positive("dt (s)", dt)?;
    require_finite("x", x)?;
    let mean_x = grid.mean_over_window(|k| x[k]);
    let mut y = Vec::with_capacity(x.len());
    let mut acc = 0.0;
    y.push(0.0);
    for w in x.windows(2) {
        acc += 0.5 * dt * ((w[0] - mean_x) + (w[1] - mean_x));
        y.push(acc);
    }
    let mean_y = grid.mean_over_window(|k| y[k]);
    for v in &mut y {
        *v -= mean_y;
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn sine_acceleration_with_bias_gives_the_velocity_without_drift() {
        // 10240 Hz, 51.3 Hz: a fractional number of samples per period, as on the rig.
        let (fs, f) = (10240.0, 51.3);
        let dt = 1.0 / fs;
        let w = TAU * f;
        let n = (20.0 * fs / f) as usize + 37;
        let a: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                3.0 * (w * t + 0.4).cos() + 0.8 * (3.0 * w * t).sin() + 0.25
            })
            .collect();
        let grid = PeriodGrid::new(n, dt, w).unwrap();
        let v = integrate_periodic(&a, dt, &grid).unwrap();
        let used = grid.used_samples();
        let mut err: f64 = 0.0;
        for (k, &vk) in v.iter().enumerate().take(used) {
            let t = k as f64 * dt;
            let exact = 3.0 / w * (w * t + 0.4).sin() - 0.8 / (3.0 * w) * (3.0 * w * t).cos();
            err = err.max((vk - exact).abs());
        }
        // Bias gone, constant gone: the error is the trapezoidal rule's, ~(Omega dt)^2 / 12
        // of the amplitude plus the period quadrature's.
        assert!(err < 2e-3 * 3.0 / w, "max error {err:e}");
    }

    #[test]
    fn wrong_length_and_non_finite_input_are_errors() {
        let grid = PeriodGrid::new(100, 0.01, TAU).unwrap();
        assert!(integrate_periodic(&[0.0; 99], 0.01, &grid).is_err());
        let mut x = vec![0.0; 100];
        x[3] = f64::NAN;
        assert!(integrate_periodic(&x, 0.01, &grid).is_err());
    }
}
