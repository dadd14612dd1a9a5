//! The precomputed model: everything that depends on the ROM and the time step only
//! ([`Model`]: the ROM's matrices in row-major order, the damped leapfrog coefficients, the
//! Delassus matrix handed to the contact solver, the open-prediction data, the sensor rows),
//! and the buffers every step reuses ([`Workspace`]; sized once, the hot loop does not
//! allocate).

use crate::contact::{ContactParameters, ContactSolver, PairState};
use crate::rom::Rom;

use super::super::error::SimError;
use super::kernels::dot;
use super::parameters::{Coupling, IntegratorParameters};
use super::predict::Predictor;

/// Everything that depends on the ROM and the time step only.
#[derive(Clone, Debug)]
pub(crate) struct Model {
    pub(crate) m: usize,
    pub(crate) n_pairs: usize,
    pub(crate) n_out: usize,
    pub(crate) dt: f64,
    pub(crate) coupling: Coupling,
    pub(crate) kappa: f64,
    pub(crate) report_gaps: bool,
    pub(crate) clearance: f64,
    /// Per-pair normal gap offsets added to the clearance (`C`), m; `None`: none (the
    /// default, the scalar code path).
    pub(crate) gap_offset: Option<Vec<f64>>,
    /// The smallest offset and the largest magnitude of `gap_offset`, m (zero without).
    pub(crate) gap_offset_range: (f64, f64),
    /// Omega^2, D = 2 zeta w, beta, per mode.
    pub(crate) omega2: Vec<f64>,
    pub(crate) damping: Vec<f64>,
    pub(crate) beta: Vec<f64>,
    /// `1/a` and `b` of the damped leapfrog step (depend on dt).
    pub(crate) inv_a: Vec<f64>,
    pub(crate) b: Vec<f64>,
    /// Phi_g row-major `3C x m`.
    pub(crate) phi_g: Vec<f64>,
    /// G_res row-major `3C x 3C`, exactly symmetric.
    pub(crate) g_res: Vec<f64>,
    pub(crate) predictor: Predictor,
    /// Sensor rows: `c_eta` row-major `n_out x m`, `c_lambda` row-major `n_out x 3C`.
    pub(crate) c_eta: Vec<f64>,
    pub(crate) c_lambda: Vec<f64>,
    pub(crate) friction: f64,
}

impl Model {
    /// The precomputation for a checked ROM with `m` modes and `n` pairs at time step `dt`
    /// (s): row-major copies of `Phi_g` and the exactly symmetric `G_res`, the prediction
    /// data, the sensor rows and the per-mode `Omega^2`, `D`, `beta`. The leapfrog
    /// coefficients are set by [`Model::set_dt`].
    pub(super) fn new(
        rom: &Rom,
        params: &IntegratorParameters,
        (m, n): (usize, usize),
        dt: f64,
    ) -> Model {
        let nb = 3 * n;
        let phi_g: Vec<f64> = (0..nb)
            .flat_map(|r| (0..m).map(move |i| (r, i)))
            .map(|(r, i)| rom.phi_g[(r, i)])
            .collect();
        let g_res: Vec<f64> = (0..nb)
            .flat_map(|r| (0..nb).map(move |s| (r, s)))
            .map(|(r, s)| 0.5 * (rom.g_res[(r, s)] + rom.g_res[(s, r)]))
            .collect();
        let phi_n: Vec<f64> = (0..n)
            .flat_map(|k| phi_g[3 * k * m..(3 * k + 1) * m].to_vec())
            .collect();
        let predictor = Predictor::new(phi_n, &rom.omega, n);
        let n_out = rom.outputs.len();
        let c_eta: Vec<f64> = rom
            .outputs
            .iter()
            .flat_map(|o| o.c_eta.iter().copied())
            .collect();
        let c_lambda: Vec<f64> = rom
            .outputs
            .iter()
            .flat_map(|o| o.c_lambda.iter().copied())
            .collect();
        let damping: Vec<f64> = rom
            .omega
            .iter()
            .zip(&rom.damping_ratio)
            .map(|(w, z)| 2.0 * z * w)
            .collect();

        Model {
            m,
            n_pairs: n,
            n_out,
            dt,
            coupling: params.coupling,
            kappa: params.open_margin_steps,
            report_gaps: params.report_gaps,
            clearance: rom.clearance,
            gap_offset: None,
            gap_offset_range: (0.0, 0.0),
            omega2: rom.omega.iter().map(|w| w * w).collect(),
            damping,
            beta: rom.beta.clone(),
            inv_a: vec![0.0; m],
            b: vec![0.0; m],
            phi_g,
            g_res,
            predictor,
            c_eta,
            c_lambda,
            friction: rom.friction,
        }
    }

    /// Sets the time step: the damped leapfrog coefficients and the Delassus matrix, and
    /// returns a contact solver for it.
    pub(super) fn set_dt(
        &mut self,
        dt: f64,
        contact: &ContactParameters,
    ) -> Result<ContactSolver, SimError> {
        let (m, nb) = (self.m, 3 * self.n_pairs);
        self.dt = dt;
        for i in 0..m {
            let a = 1.0 / dt + 0.5 * self.damping[i];
            self.inv_a[i] = 1.0 / a;
            self.b[i] = 1.0 / dt - 0.5 * self.damping[i];
        }
        // Delassus matrix, row-major 3C x 3C. Explicit: W = G_res / dt. End of step:
        // W' = G_res / dt + Phi_g diag(1/a) Phi_g^T, built from the upper triangle and mirrored
        // so that it is exactly symmetric.
        let mut w = vec![0.0; nb * nb];
        let mut scaled = vec![0.0; m];
        for r in 0..nb {
            let row_r = &self.phi_g[r * m..(r + 1) * m];
            for ((s, &p), &ia) in scaled.iter_mut().zip(row_r).zip(&self.inv_a) {
                *s = p * ia;
            }
            for s in r..nb {
                let mut v = self.g_res[r * nb + s] / dt;
                if self.coupling == Coupling::EndOfStep {
                    v += dot(&scaled, &self.phi_g[s * m..(s + 1) * m]);
                }
                w[r * nb + s] = v;
                w[s * nb + r] = v;
            }
        }
        let mut params = contact.clone();
        params.open_gap_margin = 0.0;
        let mu = vec![self.friction; self.n_pairs];
        Ok(ContactSolver::new(&w, &mu, params)?)
    }
}

/// Buffers reused by every step (sized once; the hot loop does not allocate).
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    pub(crate) vf: Vec<f64>,
    pub(crate) x_p: Vec<f64>,
    pub(crate) x_q: Vec<f64>,
    pub(crate) v_c: Vec<f64>,
    pub(crate) f_c: Vec<f64>,
    pub(crate) v_new: Vec<f64>,
    pub(crate) eta_next: Vec<f64>,
    pub(crate) cand: Vec<usize>,
    pub(crate) p_cand: Vec<f64>,
    pub(crate) closed_new: Vec<usize>,
    pub(crate) c_full: Vec<f64>,
    pub(crate) mask: Vec<f64>,
    pub(crate) lambda: Vec<f64>,
    pub(crate) lambda_dirty: bool,
    pub(crate) gamma: Vec<f64>,
    pub(crate) g_lambda_new: Vec<f64>,
    pub(crate) gap_n: Vec<f64>,
    pub(crate) pair_states: Vec<PairState>,
    pub(crate) states_dirty: bool,
    pub(crate) disp: Vec<f64>,
    pub(crate) vel: Vec<f64>,
}

impl Workspace {
    /// Buffers for `m` modes, `n` pairs and `n_out` sensors.
    pub(super) fn new(m: usize, n: usize, n_out: usize) -> Workspace {
        let nb = 3 * n;
        Workspace {
            vf: vec![0.0; m],
            x_p: vec![0.0; m],
            x_q: vec![0.0; m],
            v_c: vec![0.0; m],
            f_c: vec![0.0; m],
            v_new: vec![0.0; m],
            eta_next: vec![0.0; m],
            cand: Vec::with_capacity(n),
            p_cand: Vec::with_capacity(n),
            closed_new: Vec::with_capacity(n),
            c_full: vec![0.0; nb],
            mask: vec![1.0; n],
            lambda: vec![0.0; nb],
            lambda_dirty: false,
            gamma: vec![0.0; nb],
            g_lambda_new: vec![0.0; nb],
            gap_n: vec![0.0; n],
            pair_states: vec![PairState::Open; n],
            states_dirty: false,
            disp: vec![0.0; n_out],
            vel: vec![0.0; n_out],
        }
    }
}
