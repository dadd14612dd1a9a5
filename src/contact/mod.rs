//! Implicit frictional contact: the admissible set and its projection ([`projection`]), the
//! augmented-Lagrangian solver with projected Jacobi (accelerated Jacobi, Gauss-Seidel) sweeps
//! ([`solver`]) on dense kernels with a fixed evaluation order (`kernels`), the semismooth
//! Newton solve on the Alart–Curnier function for large, held contact (`newton`, chosen per
//! solve by [`NewtonUse`], reported in [`SolveStats::path`]), and the exchange
//! file for contact problems ([`problem_io`]) used by the Siconos cross-check
//! (`tests/siconos/solve_fc3d.py`) and to capture problems from simulations
//! ([`ContactSolver::last_active_problem`] + [`write_problem`]).
//!
//! The problem (DESIGN.md "The model" step 4, reference section 3.3.2): for the contact pairs
//! of one time step find the forces `lambda` (3 per pair: normal, t1, t2; N) with
//! `gamma = W lambda + c` and `-gamma in N_C(lambda)`, `C_k = R+ x Disk(mu_k lambda_n,k)`.
//! `W` (m/s per N) is the dense symmetric positive definite Delassus matrix (`G_res / dt`),
//! `c` (m/s) the gap velocity without contact forces, `gamma` (m/s) the gap velocity.
//! Ordering everywhere: pair-major, `[n, t1, t2]` per pair, so component `3k + a` is pair `k`.
//!
//! This is the same problem as Siconos' `FrictionContactProblem` (dimension 3):
//! `u = M r + q`, `r in K = {||r_t|| <= mu r_n}`, with `M = W`, `q = c`, `r = lambda`, `u = gamma`.

mod kernels;
mod newton;
pub mod problem_io;
pub mod projection;
pub mod solver;

pub use problem_io::{read_problems, write_problem, ContactIoError, ContactRecord};
pub use projection::{project_pair, PairState};
pub use solver::{
    ContactParameters, ContactSolver, NewtonUse, SolvePath, SolveStats, SolveStatus, StepRule,
    SweepMethod,
};

/// Why a contact problem or solver input was rejected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ContactError {
    /// A vector or matrix has the wrong size for the number of pairs.
    #[error("contact problem: {what} has {found} entries, expected {expected} for {n_pairs} contact pairs")]
    Dimension {
        /// Which input ("W", "c", "mu", "lambda", ...).
        what: &'static str,
        /// Entries found.
        found: usize,
        /// Entries expected.
        expected: usize,
        /// Number of contact pairs of the problem.
        n_pairs: usize,
    },
    /// An input entry is NaN or infinite.
    #[error("contact problem: {what}[{index}] = {value} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Flat index of the entry (row-major for W).
        index: usize,
        /// The value found.
        value: f64,
    },
    /// W is not symmetric within the tolerance.
    #[error(
        "contact problem: Delassus matrix W is not symmetric: W[{row},{col}] = {upper} but \
         W[{col},{row}] = {lower} (tolerance {tolerance:e}); symmetrise it where it is built"
    )]
    NotSymmetric {
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
        /// `W[row, col]`.
        upper: f64,
        /// `W[col, row]`.
        lower: f64,
        /// Absolute tolerance that was applied.
        tolerance: f64,
    },
    /// A diagonal entry of W is not positive, so W cannot be positive definite.
    #[error("contact problem: Delassus matrix W[{index},{index}] = {value} must be positive (W is symmetric positive definite)")]
    NonPositiveDiagonal {
        /// Row (= column) of the entry.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// A friction coefficient is negative or not finite.
    #[error("contact problem: friction coefficient mu[{pair}] = {value} must be finite and >= 0")]
    InvalidFriction {
        /// Pair index.
        pair: usize,
        /// The value found.
        value: f64,
    },
    /// A solver parameter is out of range.
    #[error("contact parameters: {field} = {value} is invalid, expected {expected}")]
    InvalidParameter {
        /// Field of [`ContactParameters`].
        field: &'static str,
        /// The value found.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
}

/// One frictional contact problem `gamma = W lambda + c`, `-gamma in N_C(lambda)`: what the
/// solver solves in one time step, what the exchange file stores and what Siconos is given.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactProblem {
    /// Delassus matrix, row-major, `3n x 3n` for `n` pairs, symmetric positive definite, m/s/N.
    pub w: Vec<f64>,
    /// Gap velocity without contact forces, `3n`, m/s (Siconos `q`).
    pub c: Vec<f64>,
    /// Friction coefficient per pair, `n`, -.
    pub mu: Vec<f64>,
    /// Free text saying where the problem comes from (e.g. "run X, step 12345"), may be empty.
    pub label: String,
}

impl ContactProblem {
    /// Number of contact pairs.
    pub fn n_pairs(&self) -> usize {
        self.mu.len()
    }

    /// Checks sizes, finiteness, symmetry of W, positive diagonal and friction coefficients.
    pub fn validate(&self) -> Result<(), ContactError> {
        validate_matrix(&self.w, &self.mu)?;
        check_vector("c", &self.c, 3 * self.n_pairs(), self.n_pairs())
    }

    /// The sub-problem on the given pairs (indices into this problem, in the given order).
    /// Out-of-range indices are an error.
    pub fn restrict(&self, pairs: &[usize]) -> Result<ContactProblem, ContactError> {
        let n = self.n_pairs();
        let dim = 3 * n;
        if let Some(&bad) = pairs.iter().find(|&&p| p >= n) {
            return Err(ContactError::Dimension {
                what: "restrict: pair index",
                found: bad,
                expected: n,
                n_pairs: n,
            });
        }
        let m = 3 * pairs.len();
        let mut w = Vec::with_capacity(m * m);
        let mut c = Vec::with_capacity(m);
        for &p in pairs {
            for a in 0..3 {
                let row = 3 * p + a;
                for &q in pairs {
                    w.extend_from_slice(&self.w[row * dim + 3 * q..row * dim + 3 * q + 3]);
                }
                c.push(self.c[row]);
            }
        }
        Ok(ContactProblem {
            w,
            c,
            mu: pairs.iter().map(|&p| self.mu[p]).collect(),
            label: self.label.clone(),
        })
    }
}

/// A solution of a [`ContactProblem`]: forces and gap velocities, both `3n`, pair-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSolution {
    /// Contact forces, N.
    pub lambda: Vec<f64>,
    /// Gap velocities `W lambda + c`, m/s.
    pub gamma: Vec<f64>,
}

/// Solves one problem from scratch (or from `warm_start`, `3n` forces in N) with a fresh
/// solver. Convenient for tests, captures and cross-checks; a simulation keeps one
/// [`ContactSolver`] instead, which does not allocate per solve.
pub fn solve_problem(
    problem: &ContactProblem,
    params: &ContactParameters,
    warm_start: Option<&[f64]>,
) -> Result<(ContactSolution, SolveStats), ContactError> {
    problem.validate()?;
    let mut solver = ContactSolver::new(&problem.w, &problem.mu, params.clone())?;
    let dim = problem.c.len();
    let mut lambda = vec![0.0; dim];
    if let Some(start) = warm_start {
        check_vector("warm start lambda", start, dim, problem.n_pairs())?;
        lambda.copy_from_slice(start);
    }
    let mut gamma = vec![0.0; dim];
    let stats = solver.solve(&problem.c, None, &mut lambda, &mut gamma)?;
    Ok((ContactSolution { lambda, gamma }, stats))
}

/// Checks a `3n x 3n` row-major W and `n` friction coefficients.
pub(crate) fn validate_matrix(w: &[f64], mu: &[f64]) -> Result<(), ContactError> {
    let n = mu.len();
    let dim = 3 * n;
    if w.len() != dim * dim {
        return Err(ContactError::Dimension {
            what: "W",
            found: w.len(),
            expected: dim * dim,
            n_pairs: n,
        });
    }
    for (pair, &value) in mu.iter().enumerate() {
        if !(value.is_finite() && value >= 0.0) {
            return Err(ContactError::InvalidFriction { pair, value });
        }
    }
    let mut scale = 0.0f64;
    for (index, &value) in w.iter().enumerate() {
        if !value.is_finite() {
            return Err(ContactError::NonFinite {
                what: "W",
                index,
                value,
            });
        }
        scale = scale.max(value.abs());
    }
    for index in 0..dim {
        let value = w[index * dim + index];
        if value <= 0.0 {
            return Err(ContactError::NonPositiveDiagonal { index, value });
        }
    }
    // NOTE: the solver reads rows of W as columns (symmetry), so an asymmetric W would give
    // inconsistent gap velocities. 1e-10 relative to the largest entry admits round-off from
    // building G_res but not a genuinely non-symmetric matrix.
    let tolerance = 1e-10 * scale;
    for row in 0..dim {
        for col in row + 1..dim {
            let upper = w[row * dim + col];
            let lower = w[col * dim + row];
            if (upper - lower).abs() > tolerance {
                return Err(ContactError::NotSymmetric {
                    row,
                    col,
                    upper,
                    lower,
                    tolerance,
                });
            }
        }
    }
    Ok(())
}

/// Checks the length and finiteness of a per-component or per-pair vector.
pub(crate) fn check_vector(
    what: &'static str,
    v: &[f64],
    expected: usize,
    n_pairs: usize,
) -> Result<(), ContactError> {
    if v.len() != expected {
        return Err(ContactError::Dimension {
            what,
            found: v.len(),
            expected,
            n_pairs,
        });
    }
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(ContactError::NonFinite {
            what,
            index,
            value: v[index],
        }),
        None => Ok(()),
    }
}
