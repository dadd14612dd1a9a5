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

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::matmul::matmul;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, supernodal::SupernodalLdltRef, LdltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::sparse::{SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Conj, Mat, MatMut, MatRef, Par, Side};

use crate::rom::error::RomError;

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
                format!("wanted all below {:.6e} Hz", w / (2.0 * std::f64::consts::PI))
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
}

/// A numeric LDL^T factorisation of `K - sigma M` with its inertia.
struct Factor {
    sigma: f64,
    values: Vec<f64>,
    negative: usize,
}

/// The union pattern of K and M (lower triangle), the value maps and the symbolic analysis,
/// shared by all shifts.
struct Shifted {
    a: SparseColMat<usize, f64>,
    k_pos: Vec<usize>,
    m_pos: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
}

const ABSENT: usize = usize::MAX;

/// Acceptance of a Ritz pair by its explicitly computed residual, relative to |theta|.
const EXPLICIT_TOLERANCE: f64 = 1e-9;

impl Shifted {
    fn new(
        k: SparseColMatRef<'_, usize, f64>,
        m: SparseColMatRef<'_, usize, f64>,
    ) -> Result<Self, RomError> {
        let n = k.nrows();
        let mut slot = vec![ABSENT; n];
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut k_pos = Vec::new();
        let mut m_pos = Vec::new();
        col_ptr.push(0usize);
        let mut col_rows: Vec<usize> = Vec::new();
        for j in 0..n {
            col_rows.clear();
            let start = row_idx.len();
            // Gather the rows i >= j of column j of K and M, then sort them.
            for (mat, is_k) in [(k, true), (m, false)] {
                let range = mat.col_range(j);
                for (off, &i) in mat.row_idx()[range.clone()].iter().enumerate() {
                    if i < j {
                        continue;
                    }
                    let pos = range.start + off;
                    if slot[i] == ABSENT {
                        slot[i] = col_rows.len();
                        col_rows.push(i);
                        k_pos.push(ABSENT);
                        m_pos.push(ABSENT);
                    }
                    let e = start + slot[i];
                    if is_k {
                        k_pos[e] = pos;
                    } else {
                        m_pos[e] = pos;
                    }
                }
            }
            // Sort the column by row index, carrying the value maps along.
            let mut order: Vec<usize> = (0..col_rows.len()).collect();
            order.sort_unstable_by_key(|&o| col_rows[o]);
            let kp: Vec<usize> = order.iter().map(|&o| k_pos[start + o]).collect();
            let mp: Vec<usize> = order.iter().map(|&o| m_pos[start + o]).collect();
            k_pos[start..].copy_from_slice(&kp);
            m_pos[start..].copy_from_slice(&mp);
            for &o in &order {
                row_idx.push(col_rows[o]);
            }
            for &i in &col_rows {
                slot[i] = ABSENT;
            }
            col_ptr.push(row_idx.len());
        }
        let nnz = row_idx.len();
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let a = SparseColMat::new(symbolic, vec![0.0; nnz]);
        let symbolic = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| RomError::Factorisation {
            shift_hz: 0.0,
            detail: format!("symbolic analysis: {e:?}"),
        })?;
        Ok(Shifted {
            a,
            k_pos,
            m_pos,
            symbolic,
        })
    }

    /// Sets the values of the lower triangle of `K - sigma M`.
    fn set_shift(&mut self, k: &[f64], m: &[f64], sigma: f64) {
        for (e, v) in self.a.val_mut().iter_mut().enumerate() {
            let kv = if self.k_pos[e] == ABSENT {
                0.0
            } else {
                k[self.k_pos[e]]
            };
            let mv = if self.m_pos[e] == ABSENT {
                0.0
            } else {
                m[self.m_pos[e]]
            };
            *v = kv - sigma * mv;
        }
    }

    /// Numeric LDL^T of `K - sigma M` and the signs of its pivots.
    fn factor(&mut self, k: &[f64], m: &[f64], sigma: f64) -> Result<Factor, RomError> {
        self.set_shift(k, m, sigma);
        let par = faer::get_global_parallelism();
        let fail = |detail: String| RomError::Factorisation {
            shift_hz: shift_hz(sigma),
            detail,
        };
        let mut values = vec![0.0; self.symbolic.len_val()];
        let req = self
            .symbolic
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default());
        let mut mem = MemBuffer::try_new(req).map_err(|_| fail("out of memory".into()))?;
        self.symbolic
            .factorize_numeric_ldlt(
                &mut values,
                self.a.as_ref(),
                Side::Lower,
                LdltRegularization::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| fail(format!("{e:?}")))?;
        let (mut negative, mut zero, mut non_finite) = (0usize, 0usize, false);
        let mut count = |d: f64| {
            if !d.is_finite() {
                non_finite = true;
            } else if d < 0.0 {
                negative += 1;
            } else if d == 0.0 {
                zero += 1;
            }
        };
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => {
                // NOTE: the simplicial factor stores each column's diagonal (D) first.
                let cp = s.col_ptr();
                for j in 0..s.nrows() {
                    count(values[cp[j]]);
                }
            }
            SymbolicCholeskyRaw::Supernodal(s) => {
                let f = SupernodalLdltRef::new(s, &values);
                for sn in 0..s.n_supernodes() {
                    let v = f.supernode(sn).val();
                    for c in 0..v.ncols() {
                        count(v[(c, c)]);
                    }
                }
            }
        }
        if non_finite {
            return Err(fail("non-finite pivot".into()));
        }
        if zero > 0 {
            return Err(fail(format!("{zero} zero pivots")));
        }
        Ok(Factor {
            sigma,
            values,
            negative,
        })
    }

    fn solve_scratch(&self, ncols: usize) -> MemBuffer {
        let par = faer::get_global_parallelism();
        MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, par))
    }

    /// `rhs <- (K - sigma M)^-1 rhs`.
    fn solve(&self, f: &Factor, rhs: MatMut<'_, f64>, mem: &mut MemBuffer) {
        let par = faer::get_global_parallelism();
        LdltRef::new(&self.symbolic, &f.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            par,
            MemStack::new(mem),
        );
    }
}

fn shift_hz(sigma: f64) -> f64 {
    sigma.signum() * sigma.abs().sqrt() / (2.0 * std::f64::consts::PI)
}

/// Deterministic pseudo-random numbers for start blocks (SplitMix64).
#[derive(Clone, Debug)]
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        // Uniform in [-1, 1).
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// Outcome of one Lanczos run at one shift.
struct Run {
    /// New converged pairs (not yet merged).
    pairs: Vec<Pair>,
    /// Unconverged Ritz estimates of eigenvalues above the shift, ascending.
    estimates: Vec<f64>,
    /// The basis reached its maximum size (or the space was exhausted).
    full: bool,
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
        let options = EigenOptions {
            block_size: options.block_size.max(1),
            max_basis: options.max_basis.max(2 * options.block_size.max(1)),
            ..options
        };
        let t0 = Instant::now();
        let shifted = Shifted::new(k, m)?;
        let mut solver = EigenSolver {
            k,
            m,
            options,
            shifted,
            stat: None,
            pairs: Vec::new(),
            verified_lambda: f64::NEG_INFINITY,
            verified_count: 0,
            last_shift: 0.0,
            estimates: Vec::new(),
            rng: SplitMix(options.seed),
            stats: EigenStats::default(),
        };
        let f = match solver.shifted.factor(k.val(), m.val(), 0.0) {
            Ok(f) => f,
            Err(RomError::Factorisation { detail, .. }) if detail.contains("zero pivot") => {
                return Err(RomError::StiffnessNotPositiveDefinite {
                    negative: 0,
                    zero: 1,
                })
            }
            Err(e) => return Err(e),
        };
        solver.stats.factorisations += 1;
        solver.stats.factorisation_seconds += t0.elapsed().as_secs_f64();
        if f.negative > 0 {
            return Err(RomError::StiffnessNotPositiveDefinite {
                negative: f.negative,
                zero: 0,
            });
        }
        solver.verified_lambda = 0.0;
        solver.verified_count = 0;
        solver.stat = Some(f);
        Ok(solver)
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
        let mut mem = self.shifted.solve_scratch(CHUNK.min(rhs.ncols()).max(1));
        let mut c = 0;
        while c < rhs.ncols() {
            let w = CHUNK.min(rhs.ncols() - c);
            self.shifted
                .solve(f, rhs.rb_mut().subcols_mut(c, w), &mut mem);
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
    /// inertia count). Can be called again with a larger target; the work done is kept.
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
            let first = self.stats.runs == 0;
            // The first run uses the factorisation of K itself (taken out of `self` for the
            // run and put back afterwards).
            let factor = if first {
                self.stat
                    .take()
                    .ok_or_else(|| self.not_converged(target, "no factorisation of K".into()))?
            } else {
                self.place_shift(target, cap)?
            };
            let outcome = self.runs_at_shift(&factor, target, progress);
            if first {
                self.stat = Some(factor);
            }
            match outcome? {
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
                return Err(self.not_converged(
                    target,
                    format!("no progress beyond {:.6e} Hz", shift_hz(v)),
                ));
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
        let mut found_below = 0usize;
        let mut runs = 0usize;
        loop {
            let run = self.lanczos(f, need - found_below, target, progress)?;
            self.stats.runs += 1;
            runs += 1;
            if std::env::var("EIG_DEBUG").is_ok() {
                eprintln!("run sigma={sigma:.4e} v={:.4e} need={need} found_below={found_below} new={:?} est={:?} full={}", self.verified_lambda, run.pairs.iter().map(|p| p.lambda).collect::<Vec<_>>(), &run.estimates[..run.estimates.len().min(6)], run.full);
            }
            let v = self.verified_lambda;
            let new_below = run
                .pairs
                .iter()
                .filter(|p| p.lambda < sigma && p.lambda > v)
                .count();
            found_below += new_below;
            let new_total = run.pairs.len();
            for p in run.pairs {
                if p.lambda <= v {
                    continue;
                }
                let at = self.pairs.partition_point(|q| q.lambda < p.lambda);
                self.pairs.insert(at, p);
            }
            self.estimates = run.estimates;
            self.last_shift = sigma;
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
            if runs > self.options.max_restarts || (new_below == 0 && new_total == 0) {
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
        let par = faer::get_global_parallelism();
        let b = Mat::<f64>::from_fn(n, 1, |_, _| self.rng.next_f64());
        let mut x = b.clone();
        let mut mem = self.shifted.solve_scratch(1);
        self.shifted.solve(f, x.as_mut(), &mut mem);
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

    /// One block Lanczos run at the shift of `f`.
    fn lanczos(
        &mut self,
        f: &Factor,
        need_below: usize,
        target: EigenTarget,
        progress: &mut dyn FnMut(EigenProgress),
    ) -> Result<Run, RomError> {
        let par = faer::get_global_parallelism();
        let n = self.n_dof();
        let p = self.options.block_size.min(n);
        let sigma = f.sigma;
        let v = self.verified_lambda;

        // Deflation: pairs near the shift that are already known.
        let window_lo = if v.is_finite() && sigma > v {
            v - (sigma - v)
        } else {
            f64::NEG_INFINITY
        };
        let defl_idx: Vec<usize> = (0..self.pairs.len())
            .filter(|&i| self.pairs[i].lambda >= window_lo)
            .collect();
        let d = defl_idx.len();
        let defl = Mat::<f64>::from_fn(n, d, |i, j| self.pairs[defl_idx[j]].vector[i]);
        let room = n.saturating_sub(d);
        let kmax = (self.options.max_basis.min(room) / p) * p;
        if kmax == 0 {
            return Ok(Run {
                pairs: Vec::new(),
                estimates: Vec::new(),
                full: true,
            });
        }

        let mut q = Mat::<f64>::zeros(n, kmax + p);
        let mut t = Mat::<f64>::zeros(kmax + p, kmax + p);
        let mut w = Mat::<f64>::zeros(n, p);
        let mut mw = Mat::<f64>::zeros(n, p);
        let mut mem = self.shifted.solve_scratch(p);

        // Start block: S applied to random vectors (keeps the basis in the range of S, free of
        // components with infinite eigenvalues when M is singular).
        for j in 0..p {
            for i in 0..n {
                w[(i, j)] = self.rng.next_f64();
            }
        }
        sparse_dense_matmul(mw.as_mut(), Accum::Replace, self.m, w.as_ref(), 1.0, par);
        w.copy_from(&mw);
        self.shifted.solve(f, w.as_mut(), &mut mem);
        self.stats.operator_columns += p;
        let mut scale = 0.0f64;
        for _ in 0..2 {
            project_out(self.m, w.as_mut(), q.subcols(0, 0), defl.as_ref(), mw.as_mut(), par);
        }
        let r0 = orthonormalize_block(
            self.m,
            w.as_mut(),
            q.subcols(0, 0),
            defl.as_ref(),
            1.0,
            &mut self.rng,
        );
        if r0.is_none() {
            return Ok(Run {
                pairs: Vec::new(),
                estimates: Vec::new(),
                full: true,
            });
        }
        q.subcols_mut(0, p).copy_from(&w);

        let mut next_check = p;
        let mut j = 0usize;
        loop {
            let c0 = j * p;
            let c1 = c0 + p;
            // W = S Q_j, A_j = Q_j^T M S Q_j.
            sparse_dense_matmul(mw.as_mut(), Accum::Replace, self.m, q.subcols(c0, p), 1.0, par);
            w.copy_from(&mw);
            self.shifted.solve(f, w.as_mut(), &mut mem);
            self.stats.operator_columns += p;
            let mut aj = Mat::<f64>::zeros(p, p);
            matmul(aj.as_mut(), Accum::Replace, mw.transpose(), w.as_ref(), 1.0, par);
            for a in 0..p {
                for b in 0..a {
                    let s = 0.5 * (aj[(a, b)] + aj[(b, a)]);
                    aj[(a, b)] = s;
                    aj[(b, a)] = s;
                }
                scale = scale.max(aj[(a, a)].abs());
            }
            t.submatrix_mut(c0, c0, p, p).copy_from(&aj);
            // Three-term recurrence, then full reorthogonalisation (twice is enough).
            matmul(w.as_mut(), Accum::Add, q.subcols(c0, p), aj.as_ref(), -1.0, par);
            if j > 0 {
                let bj = t.submatrix(c0, c0 - p, p, p).to_owned();
                matmul(w.as_mut(), Accum::Add, q.subcols(c0 - p, p), bj.transpose(), -1.0, par);
            }
            for _ in 0..2 {
                project_out(self.m, w.as_mut(), q.subcols(0, c1), defl.as_ref(), mw.as_mut(), par);
            }
            let full = c1 >= kmax;
            let b = if full {
                None
            } else {
                orthonormalize_block(
                    self.m,
                    w.as_mut(),
                    q.subcols(0, c1),
                    defl.as_ref(),
                    scale,
                    &mut self.rng,
                )
            };
            let exhausted = !full && b.is_none();
            // The residual block for the convergence estimates: W = Q_{j+1} B_{j+1}.
            let bnext = match &b {
                Some(b) => b.clone(),
                None => {
                    // Basis full: estimates from the unnormalised residual block's M-norms.
                    m_gram_cholesky_like(self.m, w.as_ref(), par)
                }
            };
            if let Some(b) = &b {
                q.subcols_mut(c1, p).copy_from(&w);
                t.submatrix_mut(c1, c0, p, p).copy_from(b);
                t.submatrix_mut(c0, c1, p, p).copy_from(b.transpose());
            }
            let k = c1;
            if k >= next_check || full || exhausted {
                next_check = k + (k / 6).max(p);
                let tk = t.submatrix(0, 0, k, k).to_owned();
                let eig = tk.self_adjoint_eigen(Side::Lower).map_err(|e| RomError::Dense {
                    what: "Lanczos projected matrix".into(),
                    detail: format!("{e:?}"),
                })?;
                let theta: Vec<f64> = eig.S().column_vector().iter().copied().collect();
                let y = eig.U();
                let theta_max = theta.iter().fold(0.0f64, |a, t| a.max(t.abs()));
                let mut conv = vec![false; k];
                let mut lam = vec![f64::NAN; k];
                for i in 0..k {
                    if theta[i] == 0.0 {
                        continue;
                    }
                    lam[i] = sigma + 1.0 / theta[i];
                    let mut est2 = 0.0;
                    for r in 0..p {
                        let mut s = 0.0;
                        for c in 0..p {
                            s += bnext[(r, c)] * y[(c0 + c, i)];
                        }
                        est2 += s * s;
                    }
                    // NOTE: roundoff limits the attainable residual to about eps x theta_max;
                    // Ritz values far from the shift (|theta| < 1e-6 theta_max) are left to a
                    // later shift instead of being trusted.
                    conv[i] = est2.sqrt() <= self.options.tolerance * theta[i].abs()
                        && theta[i].abs() >= 1e-6 * theta_max;
                }
                let new_conv = (0..k).filter(|&i| conv[i] && lam[i] > v).count();
                self.report(target, progress, new_conv);
                if self.run_may_stop(target, f, need_below, &lam, &conv) || full || exhausted {
                    // Ritz vectors of the converged pairs beyond the verified bound, checked by
                    // an explicit operator application: ||S y - theta y||_M <= tol_x |theta|.
                    let sel: Vec<usize> = (0..k).filter(|&i| conv[i] && lam[i] > v).collect();
                    let mut ys = Mat::<f64>::zeros(k, sel.len());
                    for (c, &i) in sel.iter().enumerate() {
                        for r in 0..k {
                            ys[(r, c)] = y[(r, i)];
                        }
                    }
                    let mut vecs = Mat::<f64>::zeros(n, sel.len());
                    matmul(vecs.as_mut(), Accum::Replace, q.subcols(0, k), ys.as_ref(), 1.0, par);
                    let sel_theta: Vec<f64> = sel.iter().map(|&i| theta[i]).collect();
                    let ok = self.explicit_check(f, vecs.as_ref(), &sel_theta);
                    let mut conv2 = conv.clone();
                    for (c, &i) in sel.iter().enumerate() {
                        conv2[i] = ok[c];
                    }
                    if !(self.run_may_stop(target, f, need_below, &lam, &conv2) || full || exhausted)
                    {
                        // Some estimates were optimistic: keep iterating.
                        next_check = k + p;
                        j += 1;
                        continue;
                    }
                    let keep: Vec<usize> = (0..sel.len()).filter(|&c| ok[c]).collect();
                    let vecs = Mat::from_fn(n, keep.len(), |r, c| vecs[(r, keep[c])]);
                    let pairs = self.make_pairs(vecs)?;
                    let mut estimates: Vec<f64> = (0..k)
                        .filter(|&i| !conv2[i] && lam[i] > sigma)
                        .map(|i| lam[i])
                        .collect();
                    estimates.sort_by(f64::total_cmp);
                    return Ok(Run {
                        pairs,
                        estimates,
                        full: full || exhausted,
                    });
                }
            }
            j += 1;
        }
    }

    /// Whether a Lanczos run may stop: every missing eigenvalue below the shift converged,
    /// and the target looks reached (no unconverged Ritz value below the wanted range).
    fn run_may_stop(
        &self,
        target: EigenTarget,
        f: &Factor,
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
        let known = |lo: f64, hi: f64| {
            self.pairs
                .iter()
                .filter(|p| p.lambda > lo && p.lambda < hi)
                .count()
                + (0..k)
                    .filter(|&i| conv[i] && lam[i] > v.max(lo) && lam[i] < hi)
                    .count()
        };
        match target {
            EigenTarget::Count(c) => {
                f.negative >= c || known(f64::NEG_INFINITY, first_unconv) > c
            }
            EigenTarget::BelowOmega(wc) => {
                let lc = wc * wc;
                sigma > lc || (first_unconv > lc && known(lc, first_unconv) > 0)
            }
        }
    }

    /// Explicit convergence check of Ritz vectors `y` (M-normalised columns) with Ritz values
    /// `theta` of the operator of `f`.
    fn explicit_check(&mut self, f: &Factor, y: MatRef<'_, f64>, theta: &[f64]) -> Vec<bool> {
        let par = faer::get_global_parallelism();
        let (n, s) = (y.nrows(), y.ncols());
        if s == 0 {
            return Vec::new();
        }
        let mut my = Mat::<f64>::zeros(n, s);
        sparse_dense_matmul(my.as_mut(), Accum::Replace, self.m, y, 1.0, par);
        let mut sy = my.clone();
        let mut mem = self.shifted.solve_scratch(s);
        self.shifted.solve(f, sy.as_mut(), &mut mem);
        self.stats.operator_columns += s;
        for c in 0..s {
            for i in 0..n {
                sy[(i, c)] -= theta[c] * y[(i, c)];
            }
        }
        sparse_dense_matmul(my.as_mut(), Accum::Replace, self.m, sy.as_ref(), 1.0, par);
        (0..s)
            .map(|c| {
                let r2: f64 = (0..n).map(|i| sy[(i, c)] * my[(i, c)]).sum();
                r2.max(0.0).sqrt() <= EXPLICIT_TOLERANCE * theta[c].abs()
            })
            .collect()
    }

    /// Rayleigh quotients and residuals of converged Ritz vectors.
    fn make_pairs(&self, vecs: Mat<f64>) -> Result<Vec<Pair>, RomError> {
        let par = faer::get_global_parallelism();
        let (n, s) = (vecs.nrows(), vecs.ncols());
        let mut kv = Mat::<f64>::zeros(n, s);
        let mut mv = Mat::<f64>::zeros(n, s);
        sparse_dense_matmul(kv.as_mut(), Accum::Replace, self.k, vecs.as_ref(), 1.0, par);
        sparse_dense_matmul(mv.as_mut(), Accum::Replace, self.m, vecs.as_ref(), 1.0, par);
        let mut out = Vec::with_capacity(s);
        for j in 0..s {
            let (mut vkv, mut vmv) = (0.0, 0.0);
            for i in 0..n {
                vkv += vecs[(i, j)] * kv[(i, j)];
                vmv += vecs[(i, j)] * mv[(i, j)];
            }
            if !(vmv > 0.0) || !vkv.is_finite() {
                return Err(RomError::NonFinite {
                    what: "a Ritz vector (zero mass or non-finite)".into(),
                });
            }
            let lambda = vkv / vmv;
            let scale = 1.0 / vmv.sqrt();
            let (mut r2, mut m2) = (0.0, 0.0);
            for i in 0..n {
                let r = kv[(i, j)] - lambda * mv[(i, j)];
                r2 += r * r;
                m2 += mv[(i, j)] * mv[(i, j)];
            }
            let residual = r2.sqrt() / (lambda.abs() * m2.sqrt()).max(f64::MIN_POSITIVE);
            out.push(Pair {
                lambda,
                vector: (0..n).map(|i| vecs[(i, j)] * scale).collect(),
                residual,
            });
        }
        Ok(out)
    }
}

/// `w <- w - B (B^T M w)` for the M-orthonormal bases `b1` and `b2` (one pass).
fn project_out(
    m: SparseColMatRef<'_, usize, f64>,
    mut w: MatMut<'_, f64>,
    b1: MatRef<'_, f64>,
    b2: MatRef<'_, f64>,
    mut mw: MatMut<'_, f64>,
    par: Par,
) {
    if b1.ncols() + b2.ncols() == 0 {
        return;
    }
    sparse_dense_matmul(mw.rb_mut(), Accum::Replace, m, w.rb(), 1.0, par);
    for b in [b1, b2] {
        if b.ncols() == 0 {
            continue;
        }
        let mut c = Mat::<f64>::zeros(b.ncols(), w.ncols());
        matmul(c.as_mut(), Accum::Replace, b.transpose(), mw.rb(), 1.0, par);
        matmul(w.rb_mut(), Accum::Add, b, c.as_ref(), -1.0, par);
    }
}

/// M-norm of a vector given M times it.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Orthonormalises the columns of `w` among themselves in the M-inner product (modified
/// Gram-Schmidt, twice), `w <- Q`, and returns the upper-triangular `R` with `W = Q R`.
/// A column that vanishes (relative to `scale`) is replaced by a random vector orthogonal to
/// `prev`, `defl` and the previous columns, with a zero row in R. Returns None when the
/// space is exhausted.
fn orthonormalize_block(
    m: SparseColMatRef<'_, usize, f64>,
    mut w: MatMut<'_, f64>,
    prev: MatRef<'_, f64>,
    defl: MatRef<'_, f64>,
    scale: f64,
    rng: &mut SplitMix,
) -> Option<Mat<f64>> {
    let par = faer::get_global_parallelism();
    let (n, p) = (w.nrows(), w.ncols());
    let mut r = Mat::<f64>::zeros(p, p);
    let mut mx = Mat::<f64>::zeros(n, 1);
    let mut mcol = Mat::<f64>::zeros(n, 1);
    for c in 0..p {
        let mut random_tries = 0;
        let mut is_random = false;
        loop {
            // Two MGS passes against the previous columns of the block.
            for _ in 0..2 {
                sparse_dense_matmul(mx.as_mut(), Accum::Replace, m, w.rb().subcols(c, 1), 1.0, par);
                for c2 in 0..c {
                    let h = dot(
                        w.rb().col(c2).try_as_col_major().unwrap().as_slice(),
                        mx.col(0).try_as_col_major().unwrap().as_slice(),
                    );
                    if !is_random {
                        r[(c2, c)] += h;
                    }
                    for i in 0..n {
                        let v = w[(i, c2)];
                        w[(i, c)] -= h * v;
                    }
                }
            }
            sparse_dense_matmul(mx.as_mut(), Accum::Replace, m, w.rb().subcols(c, 1), 1.0, par);
            let nrm = dot(
                w.rb().col(c).try_as_col_major().unwrap().as_slice(),
                mx.col(0).try_as_col_major().unwrap().as_slice(),
            )
            .max(0.0)
            .sqrt();
            // NOTE: a column is dependent when the reorthogonalised residual is at roundoff
            // level relative to the operator norm; it is replaced by a fresh random direction
            // (the Krylov space became invariant, the run continues in new directions).
            let threshold = if is_random { 1e-6 } else { 1e-13 * scale.max(f64::MIN_POSITIVE) };
            if nrm > threshold && nrm.is_finite() {
                if !is_random {
                    r[(c, c)] = nrm;
                }
                for i in 0..n {
                    w[(i, c)] /= nrm;
                }
                break;
            }
            random_tries += 1;
            if random_tries > 3 {
                return None;
            }
            is_random = true;
            for i in 0..n {
                w[(i, c)] = rng.next_f64();
            }
            // Random directions are projected off the whole basis (twice), then normalised
            // in the MGS loop above.
            let mut wc = Mat::<f64>::from_fn(n, 1, |i, _| w[(i, c)]);
            for _ in 0..2 {
                project_out(m, wc.as_mut(), prev, defl, mcol.as_mut(), par);
            }
            let scale_rand = {
                sparse_dense_matmul(mcol.as_mut(), Accum::Replace, m, wc.as_ref(), 1.0, par);
                dot(
                    wc.col(0).try_as_col_major().unwrap().as_slice(),
                    mcol.col(0).try_as_col_major().unwrap().as_slice(),
                )
                .max(0.0)
                .sqrt()
            };
            if !(scale_rand > 0.0) {
                return None;
            }
            for i in 0..n {
                w[(i, c)] = wc[(i, 0)] / scale_rand;
            }
        }
    }
    Some(r)
}

/// For a residual block W that is not normalised (basis full), an upper-triangular factor
/// `R` with `R^T R = W^T M W`, used only for the residual estimates.
fn m_gram_cholesky_like(m: SparseColMatRef<'_, usize, f64>, w: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let (n, p) = (w.nrows(), w.ncols());
    let mut mw = Mat::<f64>::zeros(n, p);
    sparse_dense_matmul(mw.as_mut(), Accum::Replace, m, w, 1.0, par);
    let mut g = Mat::<f64>::zeros(p, p);
    matmul(g.as_mut(), Accum::Replace, w.transpose(), mw.as_ref(), 1.0, par);
    // Eigen-based square root (robust to rank deficiency): R = diag(sqrt(s)) U^T.
    match g.self_adjoint_eigen(Side::Lower) {
        Ok(e) => {
            let s = e.S().column_vector();
            let u = e.U();
            Mat::from_fn(p, p, |i, j| s[i].max(0.0).sqrt() * u[(j, i)])
        }
        Err(_) => Mat::from_fn(p, p, |i, j| if i == j { f64::INFINITY } else { 0.0 }),
    }
}

#[cfg(test)]
mod tests;
