//! Spectrum slicing for [`EigenSolver`]: the run at sigma = 0 (started first, resumed while it
//! can grow), the placement and factorisation of further shifts (inertia checks in gaps of the
//! known spectrum, extension shifts beyond it, pulled back when too many eigenvalues are
//! missing below them), and the Lanczos runs at a shift until its inertia count is met.

use std::time::Instant;

use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::sparse::SparseColMatRef;
use faer::{Accum, Mat};

use super::factor::{shift_hz, Factor};
use super::lanczos::{LanczosRun, LANCZOS_PAR};
use super::{EigenProgress, EigenSolver, EigenTarget, RunResult, ShiftOutcome};
use crate::rom::error::RomError;

impl EigenSolver<'_> {
    /// Starts or resumes the run at sigma = 0; returns the number of new pairs.
    pub(super) fn run_at_zero(
        &mut self,
        f: &Factor,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<usize, RomError> {
        let (mut run, id) = match self.active.take() {
            Some(a) => a,
            None => {
                let id = self.stats.runs;
                self.stats.runs += 1;
                let (run, cols) = LanczosRun::start(
                    &self.shifted,
                    f,
                    self.m,
                    Mat::zeros(self.n_dof(), 0),
                    self.options.max_basis,
                    self.options.block_size,
                    &mut self.rng,
                );
                self.stats.operator_columns += cols;
                (run, id)
            }
        };
        let result = self.drive(&mut run, id, f, 0, target, progress)?;
        let before = self.pairs.len();
        self.merge(result, id);
        self.last_shift = 0.0;
        let new = self.pairs.len().saturating_sub(before);
        tracing::debug!(
            basis = run.len(),
            pairs = self.pairs.len(),
            "Lanczos run at zero"
        );
        if !run.is_full() {
            self.active = Some((run, id));
        }
        Ok(new)
    }

    /// Replaces the unverified pairs of run `id` by the run's current converged pairs.
    pub(super) fn merge(&mut self, result: RunResult, id: usize) {
        let v = self.verified_lambda;
        self.pairs.retain(|p| p.run != id || p.lambda <= v);
        for p in result.pairs {
            if p.lambda <= v {
                continue;
            }
            let at = self.pairs.partition_point(|q| q.lambda < p.lambda);
            self.pairs.insert(at, p);
        }
        self.estimates = result.estimates;
    }

    /// Chooses and factorises the next shift. Extension shifts are pulled back toward the
    /// converged range while their inertia count says that more eigenvalues are missing below
    /// them than one Lanczos run converges comfortably.
    pub(super) fn place_shift(
        &mut self,
        target: EigenTarget,
        cap: Option<f64>,
    ) -> Result<Factor, RomError> {
        let v = self.verified_lambda;
        let (mut sigma, extension) = self.next_shift(target);
        if let Some(c) = cap {
            sigma = sigma.min(v + 0.5 * (c - v));
        }
        let budget = (self.options.max_basis / 3).max(self.options.block_size);
        for _ in 0..8 {
            if sigma.partial_cmp(&v) != Some(std::cmp::Ordering::Greater)
                || (sigma - v) <= 1e-9 * sigma.abs()
            {
                return Err(self
                    .not_converged(target, format!("no progress beyond {:.6e} Hz", shift_hz(v))));
            }
            let f = self.factor_checked(sigma)?;
            let known = self.pairs.iter().filter(|p| p.lambda < f.sigma).count();
            let need = f.negative.saturating_sub(known);
            if !extension || need <= budget {
                return Ok(f);
            }
            let u = self
                .pairs
                .iter()
                .map(|p| p.lambda)
                .filter(|&l| l < f.sigma)
                .fold(v, f64::max);
            sigma = u + (f.sigma - u) * (budget as f64 / need as f64).clamp(0.1, 0.7);
        }
        self.factor_checked(sigma)
    }

    /// Lanczos runs at the shift of `f` until every eigenvalue between the verified bound and
    /// the shift is found (the count comes from the inertia of `f`) and the target looks
    /// reached or the basis is full.
    pub(super) fn runs_at_shift(
        &mut self,
        f: &Factor,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<ShiftOutcome, RomError> {
        let (sigma, negative) = (f.sigma, f.negative);
        let known_below = self.pairs.iter().filter(|p| p.lambda < sigma).count();
        if known_below > negative {
            return Err(self.not_converged(
                target,
                format!(
                    "inertia count {negative} below {:.6e} Hz is less than the {known_below} \
                     eigenpairs found there",
                    shift_hz(sigma)
                ),
            ));
        }
        let need = negative - known_below;
        let within = match target {
            EigenTarget::Count(c) => negative >= c,
            EigenTarget::BelowOmega(w) => sigma > w * w,
        };
        if need == 0 && within {
            return Ok(ShiftOutcome::Verified { sigma, negative });
        }
        // A run at another shift: the run at sigma = 0 can no longer be resumed.
        self.active = None;
        let mut found_below = 0usize;
        let mut runs = 0usize;
        loop {
            let v = self.verified_lambda;
            // Deflation: the known pairs near the shift.
            let window_lo = v - (sigma - v).max(0.0);
            let defl_idx: Vec<usize> = (0..self.pairs.len())
                .filter(|&i| self.pairs[i].lambda >= window_lo)
                .collect();
            let defl = Mat::<f64>::from_fn(self.n_dof(), defl_idx.len(), |i, j| {
                self.pairs[defl_idx[j]].vector[i]
            });
            let id = self.stats.runs;
            self.stats.runs += 1;
            runs += 1;
            let (mut run, cols) = LanczosRun::start(
                &self.shifted,
                f,
                self.m,
                defl,
                self.options.max_basis,
                self.options.block_size,
                &mut self.rng,
            );
            self.stats.operator_columns += cols;
            let result = self.drive(&mut run, id, f, need - found_below, target, progress)?;
            let new_below = result
                .pairs
                .iter()
                .filter(|p| p.lambda < sigma && p.lambda > v)
                .count();
            let new_total = result.pairs.len();
            found_below += new_below;
            self.merge(result, id);
            self.last_shift = sigma;
            tracing::debug!(
                shift_hz = shift_hz(sigma),
                need,
                found_below,
                new_total,
                basis = run.len(),
                "Lanczos run"
            );
            if found_below > need {
                return Err(self.not_converged(
                    target,
                    format!(
                        "more eigenpairs converged below {:.6e} Hz than its inertia count \
                         allows ({found_below} > {need})",
                        shift_hz(sigma)
                    ),
                ));
            }
            if found_below == need {
                return Ok(ShiftOutcome::Verified { sigma, negative });
            }
            // Missing eigenvalues below the shift: run again (deflated against what was found)
            // while that makes progress, otherwise try a shift nearer the verified bound.
            if runs > self.options.max_restarts || new_total == 0 {
                return Ok(ShiftOutcome::Incomplete { sigma });
            }
        }
    }

    pub(super) fn not_converged(&self, target: EigenTarget, detail: String) -> RomError {
        RomError::EigenNotConverged {
            found: self.verified_count,
            wanted: target.describe(),
            detail,
        }
    }

    pub(super) fn report(
        &self,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
        extra: usize,
    ) {
        let lmax = self.pairs.last().map_or(0.0, |p| p.lambda);
        progress(EigenProgress {
            converged: self.pairs.len() + extra,
            ritz_max_hz: shift_hz(lmax),
            wanted: match target {
                EigenTarget::Count(n) => Some(n),
                EigenTarget::BelowOmega(_) => None,
            },
            target_hz: match target {
                EigenTarget::Count(_) => None,
                EigenTarget::BelowOmega(w) => Some(w / (2.0 * std::f64::consts::PI)),
            },
            shifts: self.stats.factorisations,
        });
    }

    /// Factorises `K - sigma M`, nudging sigma upward when the factorisation fails or is
    /// inaccurate (sigma too close to an eigenvalue of a leading submatrix).
    pub(super) fn factor_checked(&mut self, sigma: f64) -> Result<Factor, RomError> {
        let mut sigma = sigma;
        let mut last_err = None;
        for _ in 0..4 {
            let t0 = Instant::now();
            let res = self.shifted.factor(self.k.val(), self.m.val(), sigma);
            self.stats.factorisations += 1;
            self.stats.factorisation_seconds += t0.elapsed().as_secs_f64();
            match res {
                Ok(f) => {
                    let err = self.backward_error(&f);
                    // NOTE: LDL^T without pivoting of the indefinite K - sigma M is stable as
                    // long as no pivot is tiny; a random solve's backward error detects the rare
                    // bad shift, which is then moved.
                    if err < 1e-10 {
                        return Ok(f);
                    }
                    last_err = Some(RomError::Factorisation {
                        shift_hz: shift_hz(sigma),
                        detail: format!("backward error {err:.2e} of a test solve"),
                    });
                }
                Err(e) => last_err = Some(e),
            }
            sigma *= 1.0 + 1e-3;
        }
        Err(last_err.unwrap_or(RomError::Factorisation {
            shift_hz: shift_hz(sigma),
            detail: "failed".into(),
        }))
    }

    /// Normwise backward error of a solve with `f` on a random right-hand side.
    pub(super) fn backward_error(&mut self, f: &Factor) -> f64 {
        let n = self.n_dof();
        let par = LANCZOS_PAR;
        let b = Mat::<f64>::from_fn(n, 1, |_, _| self.rng.next_f64());
        let mut x = b.clone();
        let mut mem = self.shifted.solve_scratch(1, par);
        self.shifted.solve(f, x.as_mut(), &mut mem, par);
        let mut r = b.clone();
        sparse_dense_matmul(r.as_mut(), Accum::Add, self.k, x.as_ref(), -1.0, par);
        sparse_dense_matmul(r.as_mut(), Accum::Add, self.m, x.as_ref(), f.sigma, par);
        let norm1 = |a: SparseColMatRef<'_, usize, f64>| {
            (0..a.ncols())
                .map(|j| a.val_of_col(j).iter().map(|v| v.abs()).sum::<f64>())
                .fold(0.0, f64::max)
        };
        let anorm = norm1(self.k) + f.sigma.abs() * norm1(self.m);
        let xn = x.col(0).iter().map(|v| v.abs()).sum::<f64>();
        let bn = b.col(0).iter().map(|v| v.abs()).sum::<f64>();
        let rn = r.col(0).iter().map(|v| v.abs()).sum::<f64>();
        rn / (anorm * xn + bn)
    }

    /// The next shift: an inertia check point in a gap above the wanted pairs when the known
    /// pairs reach the target, otherwise a point beyond the converged range.
    pub(super) fn next_shift(&self, target: EigenTarget) -> (f64, bool) {
        let lam: Vec<f64> = self.pairs.iter().map(|p| p.lambda).collect();
        let gap_ok = |a: f64, b: f64| b - a > 1e-6 * b.abs().max(f64::MIN_POSITIVE);
        match target {
            EigenTarget::Count(n) => {
                for j in n.max(1)..lam.len() {
                    if lam[j] > self.verified_lambda && gap_ok(lam[j - 1], lam[j]) {
                        let lo = lam[j - 1].max(self.verified_lambda);
                        return (0.5 * (lo + lam[j]), false);
                    }
                }
            }
            EigenTarget::BelowOmega(w) => {
                let lc = w * w;
                let j = lam.partition_point(|&l| l <= lc);
                if j < lam.len() {
                    let lo = lc.max(self.verified_lambda);
                    return (0.5 * (lo + lam[j]), false);
                }
            }
        }
        // Extend beyond the converged range: a shift in the widest relative gap among the
        // Ritz estimates around the q-th one above the converged range.
        // NOTE: a shift next to an eigenvalue makes the factorisation ill-conditioned and the
        // Ritz values far from it inaccurate; gaps keep it away from (estimated) eigenvalues.
        let u = lam.last().copied().unwrap_or(0.0).max(self.verified_lambda);
        let mut pts = vec![u];
        pts.extend(
            self.estimates
                .iter()
                .copied()
                .filter(|&e| e > u * (1.0 + 1e-8)),
        );
        if let EigenTarget::BelowOmega(w) = target {
            let lc = w * w;
            if lc > u && pts.last().is_some_and(|&l| l > lc) {
                let j = pts.partition_point(|&l| l <= lc);
                return (0.5 * (lc.max(pts[j - 1]) + pts[j]), true);
            }
        }
        let q = (self.options.max_basis / 8).max(self.options.block_size);
        let sigma = if pts.len() > 1 {
            let lo = (q / 2).max(1).min(pts.len() - 1);
            let hi = (2 * q).min(pts.len() - 1);
            let j = (lo..=hi)
                .max_by(|&a, &b| {
                    let ga = (pts[a] - pts[a - 1]) / pts[a];
                    let gb = (pts[b] - pts[b - 1]) / pts[b];
                    ga.total_cmp(&gb)
                })
                .unwrap_or(lo);
            0.5 * (pts[j - 1] + pts[j])
        } else {
            u + 0.5 * (u - self.last_shift).max(1e-3 * u.abs())
        };
        if sigma > u {
            (sigma, true)
        } else {
            (u * (1.0 + 1e-3) + f64::MIN_POSITIVE, true)
        }
    }
}
