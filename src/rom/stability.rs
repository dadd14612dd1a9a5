//! Stability limits of the explicit (leapfrog) modal step.
//!
//! The leapfrog step of `eta'' + A eta = f` is stable for `w_max dt < 2`, where `w_max^2` is
//! the largest eigenvalue of the stiffness the explicit step sees (mass is the identity):
//! - all pairs open: `A = Omega^2`, so `w_max = max(Omega)`;
//! - pairs closed (stuck, gap held at zero) with the coupling treated explicitly: the boundary
//!   adds `Phi_gc^T K_gg,c Phi_gc` with `K_gg,c = (G_res,cc)^-1` of the closed coordinates
//!   (all closed: `A = Omega^2 + Phi_g^T K_gg Phi_g`, the condensed `K_eta_eta`).
//!
//! The limits are given as circular frequencies and as steps per reference period
//! `2 pi / w_ref` (the 1FU period): `steps = pi w_max / w_ref`. The integrator rejects a step
//! beyond the limit it relies on with [`check_time_step`].

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Side};

use crate::rom::error::RomError;
use crate::rom::Rom;

/// Largest circular frequencies the explicit step sees, rad/s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilityLimits {
    /// All pairs open: the largest retained modal frequency, rad/s.
    pub omega_open: f64,
    /// All pairs closed: sqrt of the largest eigenvalue of `Omega^2 + Phi_g^T K_gg Phi_g`,
    /// rad/s.
    pub omega_closed: f64,
}

impl StabilityLimits {
    /// Largest stable step with all pairs open, s.
    pub fn dt_max_open(&self) -> f64 {
        max_stable_dt(self.omega_open)
    }

    /// Largest stable step with all pairs closed and the coupling explicit, s.
    pub fn dt_max_closed(&self) -> f64 {
        max_stable_dt(self.omega_closed)
    }
}

/// Largest stable leapfrog step for a highest circular frequency `omega` (rad/s): `2 / omega`, s.
pub fn max_stable_dt(omega: f64) -> f64 {
    2.0 / omega
}

/// Minimum number of steps per reference period `2 pi / omega_ref` for stability with the
/// highest circular frequency `omega_limit`: `pi omega_limit / omega_ref`.
pub fn steps_per_period(omega_limit: f64, omega_ref: f64) -> f64 {
    std::f64::consts::PI * omega_limit / omega_ref
}

/// The open limit: the largest modal frequency, rad/s (0 for no modes).
pub fn open_limit(omega: &[f64]) -> f64 {
    omega.iter().copied().fold(0.0, f64::max)
}

/// The closed limit with all pairs closed: sqrt of the largest eigenvalue of
/// `Omega^2 + Phi_g^T K_gg Phi_g`, rad/s.
pub fn closed_limit(
    omega: &[f64],
    phi_g: MatRef<'_, f64>,
    k_gg: MatRef<'_, f64>,
) -> Result<f64, RomError> {
    let m = omega.len();
    check_shapes(m, phi_g, k_gg.nrows(), k_gg.ncols())?;
    let par = faer::get_global_parallelism();
    let mut kp = Mat::<f64>::zeros(phi_g.nrows(), m);
    matmul(kp.as_mut(), Accum::Replace, k_gg, phi_g, 1.0, par);
    let mut a = Mat::<f64>::zeros(m, m);
    matmul(
        a.as_mut(),
        Accum::Replace,
        phi_g.transpose(),
        kp.as_ref(),
        1.0,
        par,
    );
    largest_with_diagonal(a, omega)
}

/// The closed limit when only the boundary coordinates `closed` (indices into the 3C
/// coordinates, e.g. the three of each stuck pair) are held: sqrt of the largest eigenvalue of
/// `Omega^2 + Phi_gc^T (G_res,cc)^-1 Phi_gc`, rad/s.
pub fn closed_limit_subset(
    omega: &[f64],
    phi_g: MatRef<'_, f64>,
    g_res: MatRef<'_, f64>,
    closed: &[usize],
) -> Result<f64, RomError> {
    let m = omega.len();
    check_shapes(m, phi_g, g_res.nrows(), g_res.ncols())?;
    if let Some(&bad) = closed.iter().find(|&&c| c >= g_res.nrows()) {
        return Err(RomError::Dimension {
            what: format!("closed boundary coordinate {bad}"),
            expected: g_res.nrows(),
            found: bad + 1,
        });
    }
    if closed.is_empty() {
        return Ok(open_limit(omega));
    }
    let c = closed.len();
    let gcc = Mat::<f64>::from_fn(c, c, |i, j| {
        0.5 * (g_res[(closed[i], closed[j])] + g_res[(closed[j], closed[i])])
    });
    let llt = gcc
        .llt(Side::Lower)
        .map_err(|e| RomError::ResidualFlexibilityNotPositive {
            n_modes: m,
            n_boundary: c,
            detail: format!("closed sub-block: {e:?}"),
        })?;
    // Z = L^-1 Phi_gc, so Phi_gc^T G_cc^-1 Phi_gc = Z^T Z (better conditioned than forming
    // the inverse).
    let mut z = Mat::<f64>::from_fn(c, m, |i, j| phi_g[(closed[i], j)]);
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(
        llt.L(),
        z.as_mut(),
        faer::get_global_parallelism(),
    );
    let mut a = Mat::<f64>::zeros(m, m);
    matmul(
        a.as_mut(),
        Accum::Replace,
        z.transpose(),
        z.as_ref(),
        1.0,
        faer::get_global_parallelism(),
    );
    largest_with_diagonal(a, omega)
}

/// Both limits of a ROM.
pub fn stability_limits(rom: &Rom) -> Result<StabilityLimits, RomError> {
    Ok(StabilityLimits {
        omega_open: open_limit(&rom.omega),
        omega_closed: closed_limit(&rom.omega, rom.phi_g.as_ref(), rom.k_gg.as_ref())?,
    })
}

/// Rejects a leapfrog step `dt` (s) beyond the limit for the highest circular frequency
/// `omega_limit` (rad/s). `omega_ref` (rad/s) converts the limit into steps per reference
/// period for the message; `state` names the contact state the limit applies to
/// (e.g. "all pairs open").
pub fn check_time_step(
    dt: f64,
    omega_limit: f64,
    omega_ref: f64,
    state: &str,
) -> Result<(), RomError> {
    let dt_max = max_stable_dt(omega_limit);
    if dt.is_finite() && dt > 0.0 && dt < dt_max {
        Ok(())
    } else {
        Err(RomError::TimeStepTooLarge {
            dt,
            dt_max,
            state: state.to_string(),
            min_steps_per_period: steps_per_period(omega_limit, omega_ref),
        })
    }
}

fn check_shapes(
    m: usize,
    phi_g: MatRef<'_, f64>,
    rows: usize,
    cols: usize,
) -> Result<(), RomError> {
    if phi_g.ncols() != m {
        return Err(RomError::Dimension {
            what: "columns of Phi_g (one per mode)".into(),
            expected: m,
            found: phi_g.ncols(),
        });
    }
    for (what, found) in [
        ("rows of the boundary matrix", rows),
        ("columns of the boundary matrix", cols),
    ] {
        if found != phi_g.nrows() {
            return Err(RomError::Dimension {
                what: what.into(),
                expected: phi_g.nrows(),
                found,
            });
        }
    }
    Ok(())
}

/// sqrt of the largest eigenvalue of `diag(omega^2) + a` (a symmetric), rad/s.
fn largest_with_diagonal(mut a: Mat<f64>, omega: &[f64]) -> Result<f64, RomError> {
    let m = omega.len();
    if m == 0 {
        return Ok(0.0);
    }
    for i in 0..m {
        a[(i, i)] += omega[i] * omega[i];
        for j in 0..i {
            let s = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = s;
            a[(j, i)] = s;
        }
    }
    let ev = a
        .self_adjoint_eigenvalues(Side::Lower)
        .map_err(|e| RomError::Dense {
            what: "closed-contact modal stiffness".into(),
            detail: format!("{e:?}"),
        })?;
    let top = ev.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return Err(RomError::NonFinite {
            what: "closed-contact modal stiffness".into(),
        });
    }
    Ok(top.max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit mass on a spring k1 to ground, with a massless spring k2 whose free end is the
    /// contact (g = its end displacement, Phi_g = 1, G_res = 1 / k2): open w^2 = k1, closed
    /// (end held) w^2 = k1 + k2.
    #[test]
    fn single_dof_open_and_closed() {
        let (k1, k2) = (4.0f64, 12.0f64);
        let omega = [k1.sqrt()];
        let phi_g = Mat::<f64>::from_fn(1, 1, |_, _| 1.0);
        let k_gg = Mat::<f64>::from_fn(1, 1, |_, _| k2);
        let closed = closed_limit(&omega, phi_g.as_ref(), k_gg.as_ref()).unwrap();
        assert!((closed - (k1 + k2).sqrt()).abs() < 1e-12);
        let g_res = Mat::<f64>::from_fn(1, 1, |_, _| 1.0 / k2);
        let sub = closed_limit_subset(&omega, phi_g.as_ref(), g_res.as_ref(), &[0]).unwrap();
        assert!((sub - (k1 + k2).sqrt()).abs() < 1e-12);
        assert_eq!(open_limit(&omega), 2.0);
        // steps per period of the mode itself: pi.
        assert!((steps_per_period(2.0, 2.0) - std::f64::consts::PI).abs() < 1e-15);
    }

    /// Two modes coupled through one boundary coordinate: closed matrix
    /// [[w1^2 + k a^2, k a b], [k a b, w2^2 + k b^2]] with known eigenvalues.
    #[test]
    fn two_dof_closed_limit() {
        let (w1, w2, k, a, b) = (1.0f64, 3.0f64, 5.0f64, 0.6f64, -0.8f64);
        let omega = [w1, w2];
        let phi_g = Mat::<f64>::from_fn(1, 2, |_, j| if j == 0 { a } else { b });
        let k_gg = Mat::<f64>::from_fn(1, 1, |_, _| k);
        let (p, q, r) = (w1 * w1 + k * a * a, w2 * w2 + k * b * b, k * a * b);
        let top = 0.5 * (p + q) + (0.25 * (p - q) * (p - q) + r * r).sqrt();
        let closed = closed_limit(&omega, phi_g.as_ref(), k_gg.as_ref()).unwrap();
        assert!(
            (closed - top.sqrt()).abs() < 1e-12,
            "{closed} vs {}",
            top.sqrt()
        );
        let limits = StabilityLimits {
            omega_open: open_limit(&omega),
            omega_closed: closed,
        };
        assert_eq!(limits.omega_open, 3.0);
        assert!(limits.dt_max_closed() < limits.dt_max_open());
        // No closed coordinates: the open limit.
        let g_res = Mat::<f64>::from_fn(1, 1, |_, _| 1.0 / k);
        assert_eq!(
            closed_limit_subset(&omega, phi_g.as_ref(), g_res.as_ref(), &[]).unwrap(),
            3.0
        );
    }

    #[test]
    fn time_step_check() {
        let w = 100.0;
        assert!(check_time_step(0.0199, w, 1.0, "all pairs open").is_ok());
        let err = check_time_step(0.0201, w, 1.0, "all pairs open").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("all pairs open") && text.contains("2.000000e-2"),
            "{text}"
        );
        assert!(check_time_step(f64::NAN, w, 1.0, "x").is_err());
        assert!(check_time_step(-1.0, w, 1.0, "x").is_err());
    }
}
