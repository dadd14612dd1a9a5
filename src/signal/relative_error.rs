//! The relative RMS error of a signal against a reference (reference section 4.3, the time-step
//! and mode-count convergence studies):
//! `eps_RMS = sqrt(sum_k |u_k - u_ref,k|^2 / sum_k |u_ref,k|^2)`.
//!
//! NOTE (different sample intervals): both signals start at `t = 0`. They are compared on the
//! coarser of the two grids (`dt_c = max(dt, dt_ref)`) over the time both cover; the finer
//! signal is linearly interpolated onto it. When the ratio of the intervals is an integer (the
//! usual refinement study: 1000 vs 128 000 steps per period) the coarse times coincide with
//! fine samples and no interpolation happens, so the error is that of the samples themselves.
//! Interpolating the coarse signal onto the fine grid instead would charge the interpolation
//! error to the signal being judged.

use super::error::{require_finite, require_positive, SignalError};

// NOTE: sample ratios and positions within this of an integer are treated as integers.
const INTEGER_TOL: f64 = 1e-9;

/// `eps_RMS` of `u` (sampled at `dt`, s) against `u_ref` (sampled at `dt_ref`, s), both from
/// `t = 0`, on the coarser grid over the common time span (module docs). Dimensionless.
///
/// Errors: empty or non-finite channels ("u", "u_ref"), invalid intervals, a reference that is
/// zero over the compared span.
pub fn relative_rms_error(
    u: &[f64],
    dt: f64,
    u_ref: &[f64],
    dt_ref: f64,
) -> Result<f64, SignalError> {
    require_positive("dt (s)", dt)?;
    require_positive("dt_ref (s)", dt_ref)?;
    if u.is_empty() {
        return Err(SignalError::Empty { channel: "u" });
    }
    if u_ref.is_empty() {
        return Err(SignalError::Empty { channel: "u_ref" });
    }
    require_finite("u", u)?;
    require_finite("u_ref", u_ref)?;

    let u_is_coarse = dt >= dt_ref;
    let (coarse, dt_c, fine, dt_f) = if u_is_coarse {
        (u, dt, u_ref, dt_ref)
    } else {
        (u_ref, dt_ref, u, dt)
    };
    let span = ((coarse.len() - 1) as f64 * dt_c).min((fine.len() - 1) as f64 * dt_f);
    let count = (((span / dt_c) * (1.0 + INTEGER_TOL)).floor() as usize + 1).min(coarse.len());
    let ratio = dt_c / dt_f;
    let int_ratio = ratio.round();
    let integer = (ratio - int_ratio).abs() <= INTEGER_TOL * ratio;
    let fine_at = |m: usize| -> f64 {
        if integer {
            return fine[(m * int_ratio as usize).min(fine.len() - 1)];
        }
        let pos = m as f64 * ratio;
        let i = pos.floor();
        let frac = pos - i;
        let i = i as usize;
        if i + 1 >= fine.len() || frac <= INTEGER_TOL {
            fine[i.min(fine.len() - 1)]
        } else if frac >= 1.0 - INTEGER_TOL {
            fine[i + 1]
        } else {
            fine[i] + frac * (fine[i + 1] - fine[i])
        }
    };

    let (mut num, mut den) = (0.0, 0.0);
    for (m, &c) in coarse[..count].iter().enumerate() {
        let f = fine_at(m);
        let (v, r) = if u_is_coarse { (c, f) } else { (f, c) };
        num += (v - r) * (v - r);
        den += r * r;
    }
    if den == 0.0 {
        return Err(SignalError::ZeroReference {
            channel: "u_ref",
            samples: count,
        });
    }
    Ok((num / den).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn same_grid_gives_the_plain_formula() {
        let r = [1.0, -2.0, 3.0, 0.5];
        let u = [1.1, -2.0, 2.8, 0.5];
        let expected = ((0.01 + 0.04) / (1.0f64 + 4.0 + 9.0 + 0.25)).sqrt();
        let e = relative_rms_error(&u, 0.1, &r, 0.1).unwrap();
        assert!((e - expected).abs() < 1e-15);
        assert_eq!(relative_rms_error(&r, 0.1, &r, 0.1).unwrap(), 0.0);
        // Extra samples beyond the common span are ignored.
        let longer = [1.1, -2.0, 2.8, 0.5, 100.0];
        assert_eq!(relative_rms_error(&longer, 0.1, &r, 0.1).unwrap(), e);
    }

    #[test]
    fn integer_refinement_picks_coinciding_samples() {
        // Reference at 128x finer steps: the coarse times are reference samples, so a coarse
        // signal equal to the sampled function has zero error whatever the function.
        let f = |t: f64| (TAU * 3.0 * t).sin() + (TAU * 40.0 * t).cos();
        let dt = 1e-3;
        let dt_ref = dt / 128.0;
        let u: Vec<f64> = (0..1001).map(|k| f(k as f64 * dt)).collect();
        let r: Vec<f64> = (0..128_001).map(|k| f(k as f64 * dt_ref)).collect();
        assert!(relative_rms_error(&u, dt, &r, dt_ref).unwrap() < 1e-14);
        // Either argument may be the finer one.
        assert!(relative_rms_error(&r, dt_ref, &u, dt).unwrap() < 1e-14);
    }

    #[test]
    fn non_integer_ratio_interpolates_the_finer_signal_linearly() {
        // A linear function is interpolated exactly; a known offset gives a known error.
        let dt = 0.3;
        let dt_ref = 0.07;
        let u: Vec<f64> = (0..20).map(|k| 2.0 + 0.5 * k as f64 * dt).collect();
        let r: Vec<f64> = (0..90).map(|k| 2.0 + 0.5 * k as f64 * dt_ref).collect();
        assert!(relative_rms_error(&u, dt, &r, dt_ref).unwrap() < 1e-14);
        // Common span: min(19 * 0.3, 89 * 0.07) = 5.7 s -> 20 coarse samples.
        let shifted: Vec<f64> = u.iter().map(|v| v + 0.1).collect();
        let den: f64 = (0..20).map(|k| (2.0 + 0.15 * k as f64).powi(2)).sum();
        let expected = (20.0 * 0.01 / den).sqrt();
        let e = relative_rms_error(&shifted, dt, &r, dt_ref).unwrap();
        assert!((e - expected).abs() < 1e-12, "{e} vs {expected}");
    }

    #[test]
    fn rejects_bad_inputs() {
        assert!(matches!(
            relative_rms_error(&[1.0], 0.1, &[0.0, 0.0], 0.1),
            Err(SignalError::ZeroReference { .. })
        ));
        assert!(matches!(
            relative_rms_error(&[1.0, f64::NAN], 0.1, &[1.0, 1.0], 0.1),
            Err(SignalError::NonFinite {
                channel: "u",
                index: 1,
                ..
            })
        ));
        assert!(matches!(
            relative_rms_error(&[], 0.1, &[1.0], 0.1),
            Err(SignalError::Empty { channel: "u" })
        ));
        assert!(relative_rms_error(&[1.0], -0.1, &[1.0], 0.1).is_err());
    }
}
