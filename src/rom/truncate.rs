//! Truncation of a MacNeal ROM to its first modes (the modes convergence study).
//!
//! The static boundary flexibility is split as `G = Phi_g Omega^-2 Phi_g^T + G_res`, so a
//! ROM with fewer modes is the same ROM with the dropped modes moved into the residual
//! flexibility: `G_res' = G_res + sum_dropped phi_g,i phi_g,i^T / w_i^2`, and likewise the
//! residual part of the sensor rows, `c_lambda' = c_lambda + sum_dropped c_eta,i phi_g,i^T / w_i^2`.
//! This is exact: it equals the reduction of the parent model with the smaller mode set.

use faer::Mat;

use super::{ModeSelection, Rom, RomError, RomOutput};

impl Rom {
    /// This ROM with only its first `modes` modes (1 <= modes <= n_modes, and the 1FU
    /// reference mode must be kept). Exact, see the module docs.
    pub fn truncated(&self, modes: usize) -> Result<Rom, RomError> {
        let m = self.n_modes();
        if modes == 0 || modes > m || modes <= self.meta.reference_mode {
            return Err(RomError::InvalidSelection(format!(
                "cannot truncate a ROM of {m} modes to {modes}: keep between {} (the 1FU \
                 mode is number {}) and {m}",
                self.meta.reference_mode + 1,
                self.meta.reference_mode + 1
            )));
        }
        let nb = self.phi_g.nrows();
        let w2: Vec<f64> = self.omega.iter().map(|w| w * w).collect();
        let mut g_res = Mat::from_fn(nb, nb, |r, s| {
            let mut v = self.g_res[(r, s)];
            for (i, w2i) in w2.iter().enumerate().skip(modes) {
                v += self.phi_g[(r, i)] * self.phi_g[(s, i)] / w2i;
            }
            v
        });
        // Exactly symmetric.
        for r in 0..nb {
            for s in r + 1..nb {
                let v = 0.5 * (g_res[(r, s)] + g_res[(s, r)]);
                g_res[(r, s)] = v;
                g_res[(s, r)] = v;
            }
        }
        let k_gg = super::macneal::invert_spd(&g_res, modes)?;
        let outputs = self
            .outputs
            .iter()
            .map(|o| RomOutput {
                name: o.name.clone(),
                c_eta: o.c_eta[..modes].to_vec(),
                c_lambda: o
                    .c_lambda
                    .iter()
                    .enumerate()
                    .map(|(r, &c)| {
                        c + (modes..m)
                            .map(|i| o.c_eta[i] * self.phi_g[(r, i)] / w2[i])
                            .sum::<f64>()
                    })
                    .collect(),
            })
            .collect();
        let mut meta = self.meta.clone();
        meta.selection = ModeSelection::Count { count: modes };
        Ok(Rom {
            meta,
            omega: self.omega[..modes].to_vec(),
            damping_ratio: self.damping_ratio[..modes].to_vec(),
            labels: self.labels[..modes].to_vec(),
            phi_g: Mat::from_fn(nb, modes, |r, i| self.phi_g[(r, i)]),
            g_res,
            k_gg,
            beta: self.beta[..modes].to_vec(),
            pair_area: self.pair_area.clone(),
            pair_position: self.pair_position.clone(),
            clearance: self.clearance,
            friction: self.friction,
            outputs,
        })
    }
}
