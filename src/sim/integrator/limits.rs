//! Stability limits of the explicit modal (leapfrog) step for a ROM.
//!
//! The step of `eta'' + D eta' + A eta = f` with the damping averaged over the half steps is
//! stable for `w_max dt < 2`, `w_max^2` the largest eigenvalue of the stiffness the explicit
//! step sees (unit modal mass; the averaged damping does not move the bound):
//! - all pairs open: `A = Omega^2`, `w_max = max(Omega)`;
//! - all pairs closed and stuck with the explicit coupling (the gap held while the modal step
//!   is explicit): `A = Omega^2 + Phi_g^T K_gg Phi_g`, `K_gg = G_res^-1` (DESIGN.md NOTE in
//!   "The model" 4). The end-of-step coupling treats this part implicitly and needs only the
//!   open bound.
//!
// NOTE: rom/stability.rs (rom helper) computes the same bounds for `rom info`; once it is on
// main this module can delegate to it. The closed bound is computed here from G_res by a
// Cholesky factor `G_res = L L^T`: `Phi_g^T K_gg Phi_g = Z^T Z` with `Z = L^-1 Phi_g`, which
// does not rely on the stored K_gg being the exact inverse.

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Mat, Par, Side};

use crate::rom::Rom;
use crate::sim::error::SimError;

/// Highest circular frequencies seen by the explicit modal step, rad/s.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StabilityLimits {
    /// All pairs open: `max(Omega)`, rad/s.
    pub omega_open: f64,
    /// All pairs closed and stuck, explicit coupling: `sqrt(lambda_max(Omega^2 + Phi_g^T K_gg Phi_g))`, rad/s.
    pub omega_closed: f64,
    /// Reference circular frequency (the ROM's 1FU mode), rad/s.
    pub omega_ref: f64,
}

impl StabilityLimits {
    /// Largest stable step with all pairs open, s.
    pub fn dt_max_open(&self) -> f64 {
        2.0 / self.omega_open
    }

    /// Largest stable step with all pairs closed (explicit coupling), s.
    pub fn dt_max_closed(&self) -> f64 {
        2.0 / self.omega_closed
    }

    /// Minimum steps per reference (1FU) period with all pairs open.
    pub fn steps_per_period_open(&self) -> f64 {
        std::f64::consts::PI * self.omega_open / self.omega_ref
    }

    /// Minimum steps per reference (1FU) period with all pairs closed (explicit coupling).
    pub fn steps_per_period_closed(&self) -> f64 {
        std::f64::consts::PI * self.omega_closed / self.omega_ref
    }
}

/// Both limits of a ROM whose sizes were already checked (`phi_g` is `3C x m`, `g_res` is
/// `3C x 3C`). Fails when `G_res` is not positive definite.
pub fn stability_limits(rom: &Rom) -> Result<StabilityLimits, SimError> {
    let m = rom.n_modes();
    let nb = rom.g_res.nrows();
    let omega_open = rom.omega.iter().copied().fold(0.0, f64::max);
    let omega_ref = rom
        .omega
        .get(rom.meta.reference_mode)
        .copied()
        .unwrap_or(rom.omega[0]);
    if nb == 0 {
        return Ok(StabilityLimits {
            omega_open,
            omega_closed: omega_open,
            omega_ref,
        });
    }
    let g = Mat::<f64>::from_fn(nb, nb, |i, j| 0.5 * (rom.g_res[(i, j)] + rom.g_res[(j, i)]));
    let llt = g.llt(Side::Lower).map_err(|e| SimError::RomFlexibility {
        detail: format!("Cholesky factorisation of the {nb} x {nb} matrix failed ({e:?})"),
    })?;
    let mut z = rom.phi_g.clone();
    solve_lower_triangular_in_place(llt.L(), z.as_mut(), Par::Seq);
    let a = Mat::<f64>::from_fn(m, m, |i, j| {
        let mut s = 0.0;
        for r in 0..nb {
            s += z[(r, i)] * z[(r, j)];
        }
        if i == j {
            s + rom.omega[i] * rom.omega[i]
        } else {
            s
        }
    });
    let eig = a
        .self_adjoint_eigenvalues(Side::Lower)
        .map_err(|e| SimError::RomFlexibility {
            detail: format!("eigenvalues of Omega^2 + Phi_g^T K_gg Phi_g failed ({e:?})"),
        })?;
    let top = eig.iter().copied().fold(0.0, f64::max);
    Ok(StabilityLimits {
        omega_open,
        omega_closed: top.sqrt().max(omega_open),
        omega_ref,
    })
}
