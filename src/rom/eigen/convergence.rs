//! Convergence of a Lanczos run for [`EigenSolver`]: periodic Ritz checks, the stopping rule
//! (every missing eigenvalue below the shift found, the target plausibly covered), explicit
//! residual checks of pairs far from the shift and the converged pairs with their residuals.

use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, Mat, MatRef};

use super::factor::Factor;
use super::lanczos::{LanczosRun, LANCZOS_PAR};
use super::{EigenProgress, EigenSolver, EigenTarget, Pair, RunResult, EXPLICIT_TOLERANCE};
use crate::rom::error::RomError;

impl EigenSolver<'_> {
    /// Drives `run` (id `id`) until it may stop or its basis is full; returns its converged
    /// pairs beyond the verified bound.
    pub(super) fn drive(
        &mut self,
        run: &mut LanczosRun,
        id: usize,
        f: &Factor,
        need_below: usize,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<RunResult, RomError> {
        let v = self.verified_lambda;
        let sigma = f.sigma;
        loop {
            if run.len() == 0 && run.is_full() {
                return Ok(RunResult {
                    pairs: Vec::new(),
                    estimates: Vec::new(),
                });
            }
            if !run.is_full() {
                self.stats.operator_columns += run.step(&self.shifted, f, self.m, &mut self.rng);
            }
            let k = run.len();
            if k < run.next_check && !run.is_full() {
                continue;
            }
            run.next_check = k + (k / 6).max(run.block());
            let ritz = run.ritz()?;
            let theta_max = ritz.theta.iter().fold(0.0f64, |a, t| a.max(t.abs()));
            let lam: Vec<f64> = ritz
                .theta
                .iter()
                .map(|&t| if t == 0.0 { f64::NAN } else { sigma + 1.0 / t })
                .collect();
            // NOTE: roundoff limits the attainable residual to about eps x theta_max; Ritz
            // values far from the shift (|theta| < 1e-6 theta_max) are left to a later shift.
            let conv: Vec<bool> = (0..k)
                .map(|i| {
                    ritz.theta[i] != 0.0
                        && ritz.est[i] <= self.options.tolerance * ritz.theta[i].abs()
                        && ritz.theta[i].abs() >= 1e-6 * theta_max
                })
                .collect();
            let new_conv = (0..k).filter(|&i| conv[i] && lam[i] > v).count();
            let own = self
                .pairs
                .iter()
                .filter(|p| p.run == id && p.lambda > v)
                .count();
            self.report(target, progress, new_conv.saturating_sub(own));
            if !(self.run_may_stop(target, f, id, need_below, &lam, &conv) || run.is_full()) {
                continue;
            }
            // Ritz vectors of the converged pairs beyond the verified bound, checked by an
            // explicit operator application.
            let sel: Vec<usize> = (0..k).filter(|&i| conv[i] && lam[i] > v).collect();
            let (vecs, mvecs) = run.vectors(ritz.y.as_ref(), &sel);
            // Pairs near the shift carry at most eps theta_max / |theta| < 1e-13 roundoff;
            // only those far from it are checked.
            let far: Vec<usize> = (0..sel.len())
                .filter(|&c| ritz.theta[sel[c]].abs() < 1e-3 * theta_max)
                .collect();
            let far_theta: Vec<f64> = far.iter().map(|&c| ritz.theta[sel[c]]).collect();
            let n = self.n_dof();
            let far_v = Mat::from_fn(n, far.len(), |r, c| vecs[(r, far[c])]);
            let far_mv = Mat::from_fn(n, far.len(), |r, c| mvecs[(r, far[c])]);
            let far_ok = self.explicit_check(f, far_v.as_ref(), far_mv.as_ref(), &far_theta);
            let mut ok = vec![true; sel.len()];
            for (i, &c) in far.iter().enumerate() {
                ok[c] = far_ok[i];
            }
            let mut conv2 = conv.clone();
            for (c, &i) in sel.iter().enumerate() {
                conv2[i] = ok[c];
            }
            if !(self.run_may_stop(target, f, id, need_below, &lam, &conv2) || run.is_full()) {
                continue;
            }
            let keep: Vec<usize> = (0..sel.len()).filter(|&c| ok[c]).collect();
            let v_keep = Mat::from_fn(n, keep.len(), |r, c| vecs[(r, keep[c])]);
            let mv_keep = Mat::from_fn(n, keep.len(), |r, c| mvecs[(r, keep[c])]);
            let l_keep: Vec<f64> = keep.iter().map(|&c| lam[sel[c]]).collect();
            let pairs = self.make_pairs(v_keep, mv_keep, &l_keep, id)?;
            let mut estimates: Vec<f64> = (0..k)
                .filter(|&i| !conv2[i] && lam[i] > sigma)
                .map(|i| lam[i])
                .collect();
            estimates.sort_by(f64::total_cmp);
            return Ok(RunResult { pairs, estimates });
        }
    }

    /// Whether a Lanczos run may stop: every missing eigenvalue below the shift converged,
    /// and the target looks reached (no unconverged Ritz value below the wanted range).
    pub(super) fn run_may_stop(
        &self,
        target: EigenTarget,
        f: &Factor,
        id: usize,
        need_below: usize,
        lam: &[f64],
        conv: &[bool],
    ) -> bool {
        let (sigma, v) = (f.sigma, self.verified_lambda);
        let k = lam.len();
        let below = (0..k)
            .filter(|&i| conv[i] && lam[i] < sigma && lam[i] > v)
            .count();
        if below < need_below {
            return false;
        }
        // Plausible coverage: up to the first unconverged Ritz value above v.
        let first_unconv = (0..k)
            .filter(|&i| !conv[i] && lam[i] > v)
            .map(|i| lam[i])
            .fold(f64::INFINITY, f64::min);
        // Known pairs in (lo, hi): stored ones (except this run's unverified ones, which its
        // converged Ritz pairs replace) and this run's converged ones.
        let known = |lo: f64, hi: f64| {
            self.pairs
                .iter()
                .filter(|p| !(p.run == id && p.lambda > v))
                .filter(|p| p.lambda > lo && p.lambda < hi)
                .count()
                + (0..k)
                    .filter(|&i| conv[i] && lam[i] > v.max(lo) && lam[i] < hi)
                    .count()
        };
        match target {
            EigenTarget::Count(c) => f.negative >= c || known(f64::NEG_INFINITY, first_unconv) > c,
            EigenTarget::BelowOmega(wc) => {
                let lc = wc * wc;
                sigma > lc || (first_unconv > lc && known(lc, first_unconv) > 0)
            }
        }
    }

    /// Explicit convergence check of Ritz vectors `y` (M-normalised columns, `my = M y`) with
    /// Ritz values `theta` of the operator of `f`.
    pub(super) fn explicit_check(
        &mut self,
        f: &Factor,
        y: MatRef<'_, f64>,
        my: MatRef<'_, f64>,
        theta: &[f64],
    ) -> Vec<bool> {
        let par = LANCZOS_PAR;
        let (n, s) = (y.nrows(), y.ncols());
        if s == 0 {
            return Vec::new();
        }
        let mut sy = my.to_owned();
        let mut mem = self.shifted.solve_scratch(s.min(64), par);
        let mut c = 0;
        while c < s {
            let w = 64.min(s - c);
            self.shifted
                .solve(f, sy.as_mut().subcols_mut(c, w), &mut mem, par);
            c += w;
        }
        self.stats.operator_columns += s;
        for c in 0..s {
            for i in 0..n {
                sy[(i, c)] -= theta[c] * y[(i, c)];
            }
        }
        let mut mr = Mat::<f64>::zeros(n, s);
        sparse_dense_matmul(mr.as_mut(), Accum::Replace, self.m, sy.as_ref(), 1.0, par);
        (0..s)
            .map(|c| {
                let r2: f64 = (0..n).map(|i| sy[(i, c)] * mr[(i, c)]).sum();
                r2.max(0.0).sqrt() <= EXPLICIT_TOLERANCE * theta[c].abs()
            })
            .collect()
    }

    /// Converged Ritz pairs (M-normalised) with their residuals.
    ///
    /// NOTE: the eigenvalue is the Ritz value `sigma + 1 / theta`, not the Rayleigh quotient
    /// `phi^T K phi`: the latter sums terms of size lambda_max |phi|^2 and loses about
    /// eps lambda_max / lambda relative accuracy (1e-8 for the lowest mode of a fine solid
    /// mesh), while theta comes from the smooth operator S.
    pub(super) fn make_pairs(
        &self,
        vecs: Mat<f64>,
        mvecs: Mat<f64>,
        lambda: &[f64],
        run: usize,
    ) -> Result<Vec<Pair>, RomError> {
        let par = LANCZOS_PAR;
        let (n, s) = (vecs.nrows(), vecs.ncols());
        let mut kv = Mat::<f64>::zeros(n, s);
        sparse_dense_matmul(kv.as_mut(), Accum::Replace, self.k, vecs.as_ref(), 1.0, par);
        let mut out = Vec::with_capacity(s);
        for j in 0..s {
            let vmv: f64 = (0..n).map(|i| vecs[(i, j)] * mvecs[(i, j)]).sum();
            let lambda = lambda[j];
            if vmv.is_nan() || vmv <= 0.0 || !lambda.is_finite() {
                return Err(RomError::NonFinite {
                    what: "a Ritz vector (zero mass or non-finite)".into(),
                });
            }
            let (mut r2, mut m2) = (0.0, 0.0);
            for i in 0..n {
                let r = kv[(i, j)] - lambda * mvecs[(i, j)];
                r2 += r * r;
                m2 += mvecs[(i, j)] * mvecs[(i, j)];
            }
            // The relative residual is scale invariant.
            let residual = r2.sqrt() / (lambda.abs() * m2.sqrt()).max(f64::MIN_POSITIVE);
            let scale = 1.0 / vmv.sqrt();
            out.push(Pair {
                lambda,
                vector: (0..n).map(|i| vecs[(i, j)] * scale).collect(),
                residual,
                run,
            });
        }
        Ok(out)
    }
}
