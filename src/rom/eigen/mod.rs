//! The sparse generalized eigen solver: lowest eigenpairs of `K phi = w^2 M phi` (K symmetric
//! positive definite, M symmetric positive semi-definite, both triangles stored) by shifted
//! block Lanczos with spectrum slicing.
//!
//! At a shift sigma the operator `S = (K - sigma M)^-1 M` is applied through a sparse LDL^T
//! factorisation; its eigenvalues `theta = 1 / (lambda - sigma)` make the eigenvalues nearest to
//! sigma the extreme ones, which block Lanczos (M-inner product, full reorthogonalisation, block
//! size >= the multiplicities expected) converges first. Each factorisation also yields, by
//! Sylvester's law of inertia, the exact number of eigenvalues below its shift (the negative
//! pivots of D). The solver keeps a verified bound: every eigenvalue below it has been found,
//! checked by such a count, so clustered or repeated eigenvalues cannot be missed silently.
//! When one Lanczos run at one shift is not enough (many modes wanted, basis full), the next
//! shift is placed beyond the converged range and the new run is deflated against the pairs
//! found nearby. Solving can resume with a larger target ([`EigenSolver::solve`] again): the
//! reduction first finds the lowest modes to identify 1FU, then extends to its cutoff.

use std::time::Instant;

use faer::reborrow::ReborrowMut;
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::sparse::SparseColMatRef;
use faer::{Accum, Mat, MatMut, MatRef};

use crate::rom::error::RomError;

mod dense;
mod factor;
mod lanczos;

pub use dense::symmetric_eigen;
use factor::{shift_hz, Factor, Shifted, SplitMix};
use lanczos::{LanczosRun, LANCZOS_PAR};

/// Acceptance of a Ritz pair by its explicitly computed residual `||S y - theta y||_M`,
/// relative to |theta|.
///
/// NOTE: this guards against gross failures (Ritz values far from an ill-placed shift); the
/// accuracy comes from the Lanczos tolerance. The explicit residual cannot go below the solve's
/// forward error, about eps cond(K - sigma M), which reaches 1e-9..1e-8 on fine solid meshes.
const EXPLICIT_TOLERANCE: f64 = 1e-7;

/// Pivot magnitude ratio (smallest / largest) of the factorisation of K below which K is
/// taken as singular.
const SINGULAR_PIVOT_RATIO: f64 = 1e-13;

/// Tuning of the eigen solver. The defaults suit FE models of 1e3-1e5 DOFs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EigenOptions {
    /// Lanczos block size: eigenvalue multiplicities up to this are resolved within one run
    /// (larger ones are still caught by the inertia counts). Default 4.
    pub block_size: usize,
    /// Largest Lanczos basis (columns) of one run at one shift; memory is about
    /// `n_dof x max_basis` doubles. Default 320.
    pub max_basis: usize,
    /// A Ritz pair converges when its Lanczos residual estimate `||S y - theta y||_M` is below
    /// `tolerance x |theta|`. Default 1e-12.
    pub tolerance: f64,
    /// Fresh Lanczos runs at one shift before giving up on missing eigenvalues. Default 4.
    pub max_restarts: usize,
    /// Seed of the random start blocks (the solver is deterministic for a given seed).
    pub seed: u64,
}

impl Default for EigenOptions {
    fn default() -> Self {
        EigenOptions {
            block_size: 4,
            max_basis: 320,
            tolerance: 1e-12,
            max_restarts: 4,
            seed: 0x5eed_2024,
        }
    }
}

/// Which eigenpairs are wanted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EigenTarget {
    /// The lowest `n` eigenpairs.
    Count(usize),
    /// Every eigenpair with circular frequency `w <= omega`, rad/s.
    BelowOmega(f64),
}

impl EigenTarget {
    fn describe(&self) -> String {
        match *self {
            EigenTarget::Count(n) => format!("wanted the lowest {n}"),
            EigenTarget::BelowOmega(w) => {
                format!(
                    "wanted all below {:.6e} Hz",
                    w / (2.0 * std::f64::consts::PI)
                )
            }
        }
    }
}

/// Progress report, sent after every convergence check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EigenProgress {
    /// Eigenpairs converged so far (verified and pending).
    pub converged: usize,
    /// Largest converged eigenfrequency, Hz.
    pub ritz_max_hz: f64,
    /// Number of modes wanted, when the target is a count.
    pub wanted: Option<usize>,
    /// Cutoff frequency, Hz, when the target is a frequency.
    pub target_hz: Option<f64>,
    /// Shifts (factorisations) used so far.
    pub shifts: usize,
}

/// Work counters and wall times of the solver.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EigenStats {
    /// Symbolic analysis and numeric factorisations, s.
    pub factorisation_seconds: f64,
    /// Everything else in [`EigenSolver::solve`] (Lanczos, Ritz vectors, residuals), s.
    pub solve_seconds: f64,
    /// Numeric factorisations (shifts).
    pub factorisations: usize,
    /// Columns the operator was applied to (one sparse forward/backward solve each).
    pub operator_columns: usize,
    /// Lanczos runs (including restarts).
    pub runs: usize,
}

/// Eigenpairs in ascending order.
#[derive(Clone, Debug)]
pub struct Modes {
    /// Eigenvalues `w^2`, rad^2/s^2, ascending.
    pub lambda: Vec<f64>,
    /// Eigenvectors as columns (n_dof x n_modes), M-orthonormal.
    pub vectors: Mat<f64>,
    /// Relative residuals `||K phi - w^2 M phi|| / (w^2 ||M phi||)`.
    pub residuals: Vec<f64>,
}

impl Modes {
    /// Number of eigenpairs.
    pub fn len(&self) -> usize {
        self.lambda.len()
    }

    /// True when there are no eigenpairs.
    pub fn is_empty(&self) -> bool {
        self.lambda.is_empty()
    }

    /// Circular frequencies `w = sqrt(lambda)`, rad/s.
    pub fn omega(&self) -> Vec<f64> {
        self.lambda.iter().map(|l| l.max(0.0).sqrt()).collect()
    }
}

/// Relative residuals `||K phi_i - lambda_i M phi_i|| / (lambda_i ||M phi_i||)` of the columns
/// of `vectors` (Euclidean norms).
pub fn relative_residuals(
    k: SparseColMatRef<'_, usize, f64>,
    m: SparseColMatRef<'_, usize, f64>,
    lambda: &[f64],
    vectors: MatRef<'_, f64>,
) -> Vec<f64> {
    let par = faer::get_global_parallelism();
    let (n, s) = (vectors.nrows(), vectors.ncols());
    let mut kv = Mat::<f64>::zeros(n, s);
    let mut mv = Mat::<f64>::zeros(n, s);
    sparse_dense_matmul(kv.as_mut(), Accum::Replace, k, vectors, 1.0, par);
    sparse_dense_matmul(mv.as_mut(), Accum::Replace, m, vectors, 1.0, par);
    (0..s)
        .map(|j| {
            let (mut r2, mut m2) = (0.0, 0.0);
            for i in 0..n {
                let r = kv[(i, j)] - lambda[j] * mv[(i, j)];
                r2 += r * r;
                m2 += mv[(i, j)] * mv[(i, j)];
            }
            r2.sqrt() / (lambda[j].abs() * m2.sqrt()).max(f64::MIN_POSITIVE)
        })
        .collect()
}

/// A converged eigenpair.
#[derive(Clone, Debug)]
struct Pair {
    lambda: f64,
    vector: Vec<f64>,
    residual: f64,
    /// The Lanczos run that found it.
    run: usize,
}

/// New converged pairs of a Lanczos run and its unconverged Ritz estimates above the shift.
struct RunResult {
    pairs: Vec<Pair>,
    estimates: Vec<f64>,
}

/// How the runs at one shift ended.
enum ShiftOutcome {
    /// Every eigenvalue below the shift is known.
    Verified { sigma: f64, negative: usize },
    /// Some eigenvalues below the shift were not found.
    Incomplete { sigma: f64 },
}

/// Shift-invert block Lanczos eigen solver with spectrum slicing and inertia checks; see the
/// module documentation.
pub struct EigenSolver<'a> {
    k: SparseColMatRef<'a, usize, f64>,
    m: SparseColMatRef<'a, usize, f64>,
    options: EigenOptions,
    shifted: Shifted,
    /// Factorisation of K itself (sigma = 0), kept for static solves.
    stat: Option<Factor>,
    /// Converged pairs, ascending.
    pairs: Vec<Pair>,
    /// Every eigenvalue below this bound is in `pairs` (checked by an inertia count).
    verified_lambda: f64,
    /// Number of eigenvalues below `verified_lambda`.
    verified_count: usize,
    /// Shift of the last Lanczos run.
    last_shift: f64,
    /// Unconverged Ritz estimates above the converged range of the last run.
    estimates: Vec<f64>,
    /// The first run (sigma = 0) with its id, while it can be resumed: no other run since.
    active: Option<(LanczosRun, usize)>,
    rng: SplitMix,
    stats: EigenStats,
}

impl<'a> EigenSolver<'a> {
    /// Checks the matrices, runs the symbolic analysis and factorises K (sigma = 0), which also
    /// proves K positive definite.
    pub fn new(
        k: SparseColMatRef<'a, usize, f64>,
        m: SparseColMatRef<'a, usize, f64>,
        options: EigenOptions,
    ) -> Result<Self, RomError> {
        let n = k.nrows();
        for (what, found) in [
            ("stiffness matrix columns", k.ncols()),
            ("mass matrix rows", m.nrows()),
            ("mass matrix columns", m.ncols()),
        ] {
            if found != n {
                return Err(RomError::Dimension {
                    what: what.into(),
                    expected: n,
                    found,
                });
            }
        }
        if n == 0 {
            return Err(RomError::EmptyModel("no free DOFs".into()));
        }
        if k.val().iter().any(|v| !v.is_finite()) {
            return Err(RomError::NonFinite {
                what: "stiffness matrix".into(),
            });
        }
        if m.val().iter().any(|v| !v.is_finite()) {
            return Err(RomError::NonFinite {
                what: "mass matrix".into(),
            });
        }
        let block = options.block_size.max(1);
        let options = EigenOptions {
            block_size: block,
            max_basis: options.max_basis.max(2 * block),
            ..options
        };
        let t0 = Instant::now();
        let mut shifted = Shifted::new(k, m)?;
        let f = match shifted.factor(k.val(), m.val(), 0.0) {
            Ok(f) => f,
            Err(RomError::Factorisation { detail, .. })
                if detail.contains("zero pivot") || detail.contains("ZeroPivot") =>
            {
                return Err(RomError::StiffnessNotPositiveDefinite {
                    negative: 0,
                    zero: 1,
                })
            }
            Err(e) => return Err(e),
        };
        // NOTE: a rigid-body motion (an unclamped part) leaves a pivot at roundoff level,
        // about eps times the largest; a clamped model's smallest pivot is 1 / cond(K), far
        // above that even for stiff interface layers.
        if f.negative > 0 || f.pivot_ratio < SINGULAR_PIVOT_RATIO {
            return Err(RomError::StiffnessNotPositiveDefinite {
                negative: f.negative,
                zero: usize::from(f.pivot_ratio < SINGULAR_PIVOT_RATIO),
            });
        }
        let stats = EigenStats {
            factorisations: 1,
            factorisation_seconds: t0.elapsed().as_secs_f64(),
            ..EigenStats::default()
        };
        Ok(EigenSolver {
            k,
            m,
            options,
            shifted,
            stat: Some(f),
            pairs: Vec::new(),
            verified_lambda: 0.0,
            verified_count: 0,
            last_shift: 0.0,
            estimates: Vec::new(),
            active: None,
            rng: SplitMix(options.seed),
            stats,
        })
    }

    /// Work counters and timings so far.
    pub fn stats(&self) -> EigenStats {
        self.stats
    }

    /// Number of DOFs.
    pub fn n_dof(&self) -> usize {
        self.k.nrows()
    }

    /// Number of eigenpairs found and verified by an inertia count.
    pub fn verified_count(&self) -> usize {
        self.verified_count
    }

    /// Frees the Lanczos basis kept for resuming (about `2 n_dof max_basis` doubles); later
    /// solves start new runs.
    pub fn release_workspace(&mut self) {
        self.active = None;
    }

    /// `rhs <- K^-1 rhs` with the factorisation of K (static solves).
    pub fn static_solve(&self, mut rhs: MatMut<'_, f64>) -> Result<(), RomError> {
        let Some(f) = self.stat.as_ref() else {
            return Err(RomError::Factorisation {
                shift_hz: 0.0,
                detail: "no factorisation of K".into(),
            });
        };
        if rhs.nrows() != self.n_dof() {
            return Err(RomError::Dimension {
                what: "right-hand side of a static solve".into(),
                expected: self.n_dof(),
                found: rhs.nrows(),
            });
        }
        // Chunks of columns bound the solver scratch memory.
        const CHUNK: usize = 64;
        let par = faer::get_global_parallelism();
        let mut mem = self
            .shifted
            .solve_scratch(CHUNK.min(rhs.ncols()).max(1), par);
        let mut c = 0;
        while c < rhs.ncols() {
            let w = CHUNK.min(rhs.ncols() - c);
            self.shifted
                .solve(f, rhs.rb_mut().subcols_mut(c, w), &mut mem, par);
            c += w;
        }
        Ok(())
    }

    /// Whether `target` is met by verified pairs.
    fn satisfied(&self, target: EigenTarget) -> bool {
        match target {
            EigenTarget::Count(n) => self.verified_count >= n.min(self.n_dof()),
            EigenTarget::BelowOmega(w) => {
                self.verified_lambda > w * w || self.verified_count >= self.n_dof()
            }
        }
    }

    /// Finds eigenpairs until `target` is met (all wanted pairs converged and verified by an
    /// inertia count). Can be called again with a larger target; the work done is kept and the
    /// first Lanczos run is resumed while that is the cheapest way forward.
    pub fn solve(
        &mut self,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<(), RomError> {
        let t_start = Instant::now();
        let fact_before = self.stats.factorisation_seconds;
        let result = self.solve_inner(target, progress);
        let spent = t_start.elapsed().as_secs_f64();
        self.stats.solve_seconds += spent - (self.stats.factorisation_seconds - fact_before);
        result
    }

    fn solve_inner(
        &mut self,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<(), RomError> {
        let mut guard = 0usize;
        // Upper bound for the next shift after a shift whose missing eigenvalues could not all
        // be converged (the next one is placed nearer the verified bound).
        let mut cap: Option<f64> = None;
        while !self.satisfied(target) {
            guard += 1;
            if guard > 1000 {
                return Err(self.not_converged(target, "too many shifts".into()));
            }
            let resume = self.stats.runs > 0
                && cap.is_none()
                && self.active.as_ref().is_some_and(|(r, _)| !r.is_full())
                && self.next_shift(target).1;
            if self.stats.runs == 0 || resume {
                // The run at sigma = 0 with the factorisation of K: started first, resumed
                // while it can grow and the target lies beyond the known pairs.
                let f = self
                    .stat
                    .take()
                    .ok_or_else(|| self.not_converged(target, "no factorisation of K".into()))?;
                let result = self.run_at_zero(&f, target, progress);
                self.stat = Some(f);
                let new = result?;
                if new == 0 && self.active.is_none() {
                    // Nothing more from this run; the next pass places a shift.
                    continue;
                }
                self.report(target, progress, 0);
                continue;
            }
            let f = self.place_shift(target, cap)?;
            match self.runs_at_shift(&f, target, progress)? {
                ShiftOutcome::Verified { sigma, negative } => {
                    self.verified_lambda = sigma;
                    self.verified_count = negative;
                    cap = None;
                }
                ShiftOutcome::Incomplete { sigma } => cap = Some(sigma),
            }
            self.report(target, progress, 0);
        }
        self.report(target, progress, 0);
        Ok(())
    }

    /// Starts or resumes the run at sigma = 0; returns the number of new pairs.
    fn run_at_zero(
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
    fn merge(&mut self, result: RunResult, id: usize) {
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
    fn place_shift(&mut self, target: EigenTarget, cap: Option<f64>) -> Result<Factor, RomError> {
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
    fn runs_at_shift(
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

    fn not_converged(&self, target: EigenTarget, detail: String) -> RomError {
        RomError::EigenNotConverged {
            found: self.verified_count,
            wanted: target.describe(),
            detail,
        }
    }

    fn report(&self, target: EigenTarget, progress: &mut dyn FnMut(EigenProgress), extra: usize) {
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
    fn factor_checked(&mut self, sigma: f64) -> Result<Factor, RomError> {
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
    fn backward_error(&mut self, f: &Factor) -> f64 {
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
    fn next_shift(&self, target: EigenTarget) -> (f64, bool) {
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

    /// The selected verified eigenpairs (ascending) for `target`.
    pub fn modes(&self, target: EigenTarget) -> Modes {
        let verified = &self.pairs[..self.verified_count.min(self.pairs.len())];
        let take = match target {
            EigenTarget::Count(n) => n.min(verified.len()),
            EigenTarget::BelowOmega(w) => verified.partition_point(|p| p.lambda <= w * w),
        };
        let n = self.n_dof();
        let sel = &verified[..take];
        Modes {
            lambda: sel.iter().map(|p| p.lambda).collect(),
            vectors: Mat::from_fn(n, take, |i, j| sel[j].vector[i]),
            residuals: sel.iter().map(|p| p.residual).collect(),
        }
    }

    /// Drives `run` (id `id`) until it may stop or its basis is full; returns its converged
    /// pairs beyond the verified bound.
    fn drive(
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
    fn run_may_stop(
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
    fn explicit_check(
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
    fn make_pairs(
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

#[cfg(test)]
mod tests;
