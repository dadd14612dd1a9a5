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

mod convergence;
mod dense;
mod factor;
mod lanczos;
mod slicing;

pub use dense::symmetric_eigen;
use factor::{Factor, Shifted, SplitMix};
use lanczos::LanczosRun;

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
}

#[cfg(test)]
mod tests;
