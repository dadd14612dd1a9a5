//! The implicit contact solver: augmented-Lagrangian fixed point
//! `lambda <- proj_C(lambda - eps .* (W lambda + c))` with projected Jacobi sweeps (the
//! reference method) or projected Gauss-Seidel sweeps, on the pairs not predicted open.
//!
//! One [`ContactSolver`] owns the constant Delassus matrix `W` (`G_res / dt` for a fixed time
//! step) and a workspace sized for all pairs, so a solve never allocates. Per solve:
//! 1. active-set prediction: pairs whose predicted normal gap (free gap plus predicted motion,
//!    given by the caller) exceeds [`ContactParameters::open_gap_margin`] get `lambda = 0` and
//!    leave the sweep;
//! 2. when the active set differs from the previous solve, the active rows and columns of `W`
//!    are gathered into a contiguous block and the step sizes `eps` are recomputed;
//! 3. sweeps from the warm start until the relative change of `lambda` drops below
//!    [`ContactParameters::tolerance`] or [`ContactParameters::max_iterations`] is reached;
//! 4. gap velocities `gamma = W lambda + c` for all pairs, the natural-map residual and the
//!    open/stick/slip state of every pair.
//!
//! Non-convergence and divergence are reported in [`SolveStats`], never by a panic; bad input
//! (sizes, non-finite numbers) is a [`ContactError`].

use super::kernels::{axpy, gauss_seidel_sweep, matvec};
use super::newton::{Newton, NewtonInput};
use super::projection::{project_pair, PairState};
use super::{check_vector, validate_matrix, ContactError, ContactProblem, ContactSolution};

/// How the pairs are swept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepMethod {
    /// All pairs updated from the previous iterate (the reference's projected Jacobi).
    #[default]
    Jacobi,
    /// Projected Jacobi with Nesterov momentum and adaptive restart (accelerated projected
    /// gradient, as in APGD solvers for cone complementarity): the same sweep, evaluated at an
    /// extrapolated point. Needs about the square root of Jacobi's sweeps on strongly coupled
    /// `W`; use a convergent step rule with relaxation <= 1.
    AcceleratedJacobi,
    /// Pairs updated in order, each from the latest values of the others.
    GaussSeidel,
}

/// How the augmented-Lagrangian step sizes `eps` (N per m/s) are chosen for the Jacobi sweep.
/// Every rule gives one `eps` for the normal component of a pair and one shared by its two
/// tangential components (a different `eps` for t1 and t2 would move the fixed points away
/// from Coulomb's law). `relaxation` (r) multiplies all of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepRule {
    /// DESIGN.md's rule: [`StepRule::Diagonal`] when the active block of `W` is diagonally
    /// dominant, [`StepRule::RowSum`] otherwise (always row sums for
    /// [`SweepMethod::AcceleratedJacobi`]).
    #[default]
    Auto,
    /// `eps = r / W_ii` (tangential: the larger of the two diagonal entries). Converges for
    /// diagonally dominant `W`; may diverge otherwise.
    Diagonal,
    /// `eps = r / sum_j |W_ij|`. Always convergent for r <= 1 (Gershgorin), slow when `W` is
    /// strongly coupled.
    RowSum,
    /// `eps = r / (W_ii rho)` with `rho` the largest eigenvalue of `D^-1/2 W D^-1/2`
    /// (`D` = the diagonal used by [`StepRule::Diagonal`]), estimated by power iteration once
    /// per active-set change. Convergent for r < 2 (up to the estimate) and much faster than
    /// row sums on strongly coupled `W`.
    Spectral,
}

/// Parameters of the contact solver. Defaults follow DESIGN.md "The model" step 4.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactParameters {
    /// Sweep method. Default: [`SweepMethod::Jacobi`].
    pub method: SweepMethod,
    /// Step-size rule of the Jacobi sweep. Default: [`StepRule::Auto`]. The Gauss-Seidel sweep
    /// always uses the pair's own 3x3 block (row sums of the block), which suffices there.
    pub step_rule: StepRule,
    /// Relaxation factor r multiplying every step size, -. Must lie in (0, 2). Default 1.0.
    pub relaxation: f64,
    /// Stop when `||lambda_new - lambda_old|| <= tolerance * ||lambda_new||` (2-norms over the
    /// active pairs), -. Default 1e-8.
    // NOTE: for Jacobi the change of one sweep is exactly the (eps-scaled) fixed-point
    // residual, but a slowly contracting iteration is farther from the solution than its last
    // step: on a coupled 192-pair patch the error was about 100x the tolerance (Siconos
    // cross-check: tolerance 1e-11 gave 1e-9 agreement). Gauss-Seidel and the accelerated
    // sweep are much closer to their tolerance.
    pub tolerance: f64,
    /// Sweep limit; reaching it is reported as [`SolveStatus::MaxIterations`]. Default 2000.
    pub max_iterations: usize,
    /// A pair whose predicted normal gap (m) is larger than this is predicted open and left out
    /// of the sweep, m. Default 0.0.
    pub open_gap_margin: f64,
    /// When the semismooth Newton solve (`newton.rs`) is used beside the sweeps. Default
    /// [`NewtonUse::Auto`].
    pub newton: NewtonUse,
    /// [`NewtonUse::Auto`]: a solve with at least this many active pairs is *large* and
    /// switches to Newton after [`ContactParameters::newton_after_sweeps_large`] sweeps, -.
    /// Default 48 (a quarter of the default rig's patch).
    // NOTE: 96 before the third pass of issue 16; with the few sweeps first (below) Newton is
    // cheaper than the sweeps from about 48 pairs on the touching probes' solves (captured
    // replay, `tests/contact_held_replay.rs`; BENCHMARKS.md "Held contact, third pass").
    pub newton_min_pairs: usize,
    /// [`NewtonUse::Auto`]: a solve below `newton_min_pairs` still sweeping after this many
    /// sweeps switches to Newton from the last sweep's iterate, -. Default 100 (impacts
    /// converge in about 30).
    pub newton_after_sweeps: usize,
    /// [`NewtonUse::Auto`]: the same for large solves, -; 0: Newton from the warm start.
    /// Default 3.
    // NOTE: the touching probes' large solves need hundreds to thousands of sweeps to
    // converge, but a handful of Gauss-Seidel sweeps (each O(m^2), a small fraction of one
    // LU) already finds most of the closed set. Newton from the warm start instead starts
    // from the previous step's forces, which after a bounce close far too many pairs (up to
    // all 192, a system of 557 unknowns, where the solution closes 20-60) or none, and then
    // shrinks the pattern by one LU per iteration. 3 sweeps first: 436 -> 273 LUs and 0.77 x
    // the time on the captured touching solves (BENCHMARKS.md "Held contact, third pass");
    // 2-8 do about the same, 40 is slower than none. The price of Newton in large solves: an impact with many
    // pairs is solved by Newton, equal to the sweeps' answer within the tolerance but not
    // bit for bit, so such vibro-impact trajectories differ from the sweeps-only ones after
    // it (chaotic sensitivity; the pinned demo outputs were rewritten for issue 16).
    pub newton_after_sweeps_large: usize,
    /// Iteration limit of one Newton attempt; an attempt that does not converge hands its
    /// best iterate back to the sweeps, which continue up to `max_iterations`. Default 30.
    pub newton_max_iterations: usize,
}

/// When the contact solve uses the semismooth Newton method (Alart–Curnier, `newton.rs`)
/// beside the projected sweeps. Both solve the same law to the same tolerance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NewtonUse {
    /// Sweeps only (the behaviour before issue 16).
    Never,
    /// Chosen per solve: sweeps first, then Newton from their iterate when they have not
    /// converged after [`ContactParameters::newton_after_sweeps_large`] sweeps (large active
    /// sets, [`ContactParameters::newton_min_pairs`]) or
    /// [`ContactParameters::newton_after_sweeps`] (small ones); sweeps finish a Newton attempt
    /// that fails.
    // NOTE: a Gauss-Seidel sweep costs O(m^2) and impacts converge in tens of them; a Newton
    // step costs a dense factorisation O(min(q, k)^3) (see `newton.rs`), which pays only when
    // many pairs are closed and the sweeps crawl (held contact: hundreds to thousands of
    // sweeps). BENCHMARKS.md (issue 16) has the measurements behind the defaults.
    #[default]
    Auto,
    /// Newton first for every solve with an active pair (sweeps only as the fallback).
    Always,
}

/// Which method produced the forces of a solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolvePath {
    /// Projected sweeps only (also: no active pair).
    #[default]
    Sweeps,
    /// Newton from the warm start.
    Newton,
    /// Sweeps first; Newton from their iterate finished the solve.
    SweepsThenNewton,
    /// A Newton attempt did not converge; the sweeps finished (or ran out) from its best
    /// iterate.
    NewtonFallback,
}

impl Default for ContactParameters {
    fn default() -> Self {
        ContactParameters {
            method: SweepMethod::Jacobi,
            step_rule: StepRule::Auto,
            relaxation: 1.0,
            tolerance: 1e-8,
            max_iterations: 2000,
            open_gap_margin: 0.0,
            newton: NewtonUse::Auto,
            newton_min_pairs: 48,
            newton_after_sweeps: 100,
            newton_after_sweeps_large: 3,
            newton_max_iterations: 30,
        }
    }
}

impl ContactParameters {
    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<(), ContactError> {
        if !(self.relaxation > 0.0 && self.relaxation < 2.0) {
            return Err(ContactError::InvalidParameter {
                field: "relaxation",
                value: self.relaxation,
                expected: "a number in (0, 2)",
            });
        }
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(ContactError::InvalidParameter {
                field: "tolerance",
                value: self.tolerance,
                expected: "a finite number > 0",
            });
        }
        if self.max_iterations == 0 {
            return Err(ContactError::InvalidParameter {
                field: "max_iterations",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if self.newton_max_iterations == 0 {
            return Err(ContactError::InvalidParameter {
                field: "newton_max_iterations",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if !self.open_gap_margin.is_finite() {
            return Err(ContactError::InvalidParameter {
                field: "open_gap_margin",
                value: self.open_gap_margin,
                expected: "a finite length in m",
            });
        }
        Ok(())
    }
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolveStatus {
    /// The relative change dropped below the tolerance (or no pair was active).
    Converged,
    /// The sweep limit was reached first; the last iterate is returned.
    MaxIterations,
    /// The iterate became non-finite (step sizes too large for this `W`); the forces returned
    /// are zero and must not be used.
    Diverged,
}

/// What one solve did.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveStats {
    /// How the solve ended.
    pub status: SolveStatus,
    /// `status == Converged`.
    pub converged: bool,
    /// Sweeps done.
    pub iterations: usize,
    /// Newton iterations done (each one dense linear solve).
    pub newton_iterations: usize,
    /// LU factorisations of the Newton iterations (the others were chord steps on kept
    /// factors; see `newton.rs`).
    pub factorisations: usize,
    /// Which method produced the forces.
    pub path: SolvePath,
    /// Relative change of `lambda` in the last sweep, -. For the accelerated sweep: the
    /// change from the extrapolated point (its fixed-point residual).
    pub relative_change: f64,
    /// Natural-map residual `||lambda - proj_C(lambda - eps .* gamma)||_2` at the returned
    /// forces (N); zero exactly at a solution.
    pub residual: f64,
    /// `residual / max(||lambda||, ||eps .* c||)`, -.
    pub relative_residual: f64,
    /// Pairs in the sweep (not predicted open).
    pub active_pairs: usize,
    /// Pairs predicted open by the caller's gaps.
    pub predicted_open: usize,
    /// Pairs without normal force (predicted open or separating), stick and slip.
    pub open: usize,
    /// Pairs sticking.
    pub stick: usize,
    /// Pairs slipping.
    pub slip: usize,
    /// Whether the active set differed from the previous solve (W block regathered).
    pub active_set_changed: bool,
}

/// What the sweeps of one solve did.
struct SweepRun {
    status: SolveStatus,
    relative_change: f64,
}

/// Reusable contact solver: the Delassus matrix, friction coefficients, parameters and a
/// workspace for all pairs. `solve` does not allocate.
#[derive(Clone, Debug)]
pub struct ContactSolver {
    params: ContactParameters,
    n_pairs: usize,
    /// Full Delassus matrix, row-major `3n x 3n`.
    w: Vec<f64>,
    mu: Vec<f64>,
    /// Pairs in the sweep, ascending, and whether the gathered block below belongs to them.
    active: Vec<usize>,
    candidate: Vec<usize>,
    block_valid: bool,
    /// Whether `w_act` holds the active block. It is gathered only when the sweeps run (or the
    /// Jacobi step sizes need it): a Newton solve reads `W` in place.
    block_gathered: bool,
    /// Active block of W, row-major `m x m` with m = 3 * active.len() (capacity for all pairs).
    w_act: Vec<f64>,
    mu_act: Vec<f64>,
    /// Step size per active component, N per m/s.
    eps: Vec<f64>,
    /// Active forces, gap velocities, free gap velocities; scratch for the power iteration.
    lam: Vec<f64>,
    y: Vec<f64>,
    c_act: Vec<f64>,
    scratch: Vec<f64>,
    scratch2: Vec<f64>,
    /// Previous and extrapolated iterates of the accelerated sweep.
    prev: Vec<f64>,
    ext: Vec<f64>,
    states: Vec<PairState>,
    /// Workspace of the semismooth Newton solve.
    newton: Newton,
}

impl ContactSolver {
    /// A solver for `n = mu.len()` pairs with Delassus matrix `w` (row-major `3n x 3n`,
    /// symmetric positive definite, m/s/N) and friction coefficients `mu` (-). Checks the
    /// inputs (sizes, finiteness, symmetry, positive diagonal) and the parameters.
    pub fn new(
        w: &[f64],
        mu: &[f64],
        params: ContactParameters,
    ) -> Result<ContactSolver, ContactError> {
        validate_matrix(w, mu)?;
        params.validate()?;
        let n = mu.len();
        let dim = 3 * n;
        Ok(ContactSolver {
            params,
            n_pairs: n,
            w: w.to_vec(),
            mu: mu.to_vec(),
            active: Vec::with_capacity(n),
            candidate: Vec::with_capacity(n),
            block_valid: false,
            block_gathered: false,
            w_act: vec![0.0; dim * dim],
            mu_act: vec![0.0; n],
            eps: vec![0.0; dim],
            lam: vec![0.0; dim],
            y: vec![0.0; dim],
            c_act: vec![0.0; dim],
            scratch: vec![0.0; dim],
            scratch2: vec![0.0; dim],
            prev: vec![0.0; dim],
            ext: vec![0.0; dim],
            states: vec![PairState::Open; n],
            newton: Newton::new(n),
        })
    }

    /// Number of contact pairs.
    pub fn n_pairs(&self) -> usize {
        self.n_pairs
    }

    /// The parameters in use.
    pub fn parameters(&self) -> &ContactParameters {
        &self.params
    }

    /// Replaces the parameters (checked); step sizes are recomputed at the next solve.
    pub fn set_parameters(&mut self, params: ContactParameters) -> Result<(), ContactError> {
        params.validate()?;
        self.params = params;
        self.block_valid = false;
        self.newton.invalidate();
        Ok(())
    }

    /// Forgets what the last solves leave to the next: the active set with its block and step
    /// sizes, and the kept Newton factorisation. The next solve then gives the same bits as a
    /// new solver's (a chord step on kept factors agrees with a fresh factorisation only
    /// within the tolerance), so a run restarted from a saved state does not depend on what
    /// the solver solved before (e.g. the ensemble members a replay thread ran earlier).
    pub fn forget_history(&mut self) {
        self.block_valid = false;
        self.block_gathered = false;
        self.newton.invalidate();
    }

    /// State of every pair after the last solve (all open before the first).
    pub fn pair_states(&self) -> &[PairState] {
        &self.states
    }

    /// Pairs that were in the sweep of the last solve, ascending.
    pub fn active_pairs(&self) -> &[usize] {
        &self.active
    }

    /// The sub-problem on the active pairs of the last solve and its solution, for capture and
    /// cross-checks (allocates; not for the hot path).
    pub fn last_active_problem(&self, label: &str) -> (ContactProblem, ContactSolution) {
        let m = 3 * self.active.len();
        let dim = 3 * self.n_pairs;
        let w = if self.block_gathered {
            self.w_act[..m * m].to_vec()
        } else {
            let mut w = Vec::with_capacity(m * m);
            for &p in &self.active {
                for a in 0..3 {
                    let row = &self.w[(3 * p + a) * dim..(3 * p + a + 1) * dim];
                    for &q in &self.active {
                        w.extend_from_slice(&row[3 * q..3 * q + 3]);
                    }
                }
            }
            w
        };
        (
            ContactProblem {
                w,
                c: self.c_act[..m].to_vec(),
                mu: self.mu_act[..self.active.len()].to_vec(),
                label: label.to_string(),
            },
            ContactSolution {
                lambda: self.lam[..m].to_vec(),
                gamma: self.y[..m].to_vec(),
            },
        )
    }

    /// Solves one time step's contact problem.
    ///
    /// - `c`: gap velocity without contact forces, `3n`, m/s;
    /// - `predicted_gap_n`: predicted normal gap per pair, `n`, m (free gap plus predicted
    ///   motion); pairs above [`ContactParameters::open_gap_margin`] are left out. `None`: all
    ///   pairs take part;
    /// - `lambda`: in: warm start (e.g. the previous step's forces), `3n`, N; out: the forces
    ///   (zero on pairs predicted open);
    /// - `gamma`: out: gap velocities `W lambda + c` of all pairs, `3n`, m/s.
    ///
    /// Returns the statistics; a solve that did not converge still returns `Ok` with
    /// `converged == false`.
    ///
    /// The law is imposed on the gap velocity. For a pair that is still open at the start of
    /// the step (`g_n > 0`) but predicted to close, pass `c_n + g_n / dt` instead of `c_n`:
    /// the condition then reads `g_n + dt gamma_n >= 0` (contact at the end of the step)
    /// instead of stopping the pair at its current gap.
    pub fn solve(
        &mut self,
        c: &[f64],
        predicted_gap_n: Option<&[f64]>,
        lambda: &mut [f64],
        gamma: &mut [f64],
    ) -> Result<SolveStats, ContactError> {
        let n = self.n_pairs;
        let dim = 3 * n;
        check_vector("c", c, dim, n)?;
        check_vector("lambda (warm start)", lambda, dim, n)?;
        if gamma.len() != dim {
            return Err(ContactError::Dimension {
                what: "gamma",
                found: gamma.len(),
                expected: dim,
                n_pairs: n,
            });
        }
        if let Some(gaps) = predicted_gap_n {
            check_vector("predicted_gap_n", gaps, n, n)?;
        }

        // 1. Active-set prediction.
        self.candidate.clear();
        match predicted_gap_n {
            Some(gaps) => {
                let margin = self.params.open_gap_margin;
                self.candidate.extend((0..n).filter(|&k| gaps[k] <= margin));
            }
            None => self.candidate.extend(0..n),
        }
        let active_set_changed = !self.block_valid || self.candidate != self.active;
        if active_set_changed {
            std::mem::swap(&mut self.active, &mut self.candidate);
            for (slot, &p) in self.active.iter().enumerate() {
                self.mu_act[slot] = self.mu[p];
            }
            self.block_gathered = false;
            if self.params.method != SweepMethod::GaussSeidel {
                self.gather_block();
            }
            self.compute_step_sizes();
            self.block_valid = true;
        }
        let na = self.active.len();
        let m = 3 * na;

        // Warm start, projected onto the admissible set.
        for (slot, &p) in self.active.iter().enumerate() {
            let (start, _) = project_pair(
                self.mu[p],
                [lambda[3 * p], lambda[3 * p + 1], lambda[3 * p + 2]],
            );
            self.lam[3 * slot..3 * slot + 3].copy_from_slice(&start);
            self.c_act[3 * slot..3 * slot + 3].copy_from_slice(&c[3 * p..3 * p + 3]);
        }

        // 2. Sweeps and/or Newton (see `NewtonUse`).
        let mut status = SolveStatus::Converged;
        let mut iterations = 0;
        let mut relative_change = 0.0;
        let (mut newton_iterations, mut factorisations) = (0, 0);
        let mut path = SolvePath::Sweeps;
        if m > 0 {
            let newton = self.params.newton;
            let newton_first = match newton {
                NewtonUse::Never => false,
                NewtonUse::Always => true,
                NewtonUse::Auto => {
                    na >= self.params.newton_min_pairs && self.params.newton_after_sweeps_large == 0
                }
            };
            let mut newton_left = newton != NewtonUse::Never;
            let mut done = false;
            if newton_first {
                newton_left = false;
                let o = self.run_newton();
                newton_iterations += o.iterations;
                factorisations += o.factorisations;
                if o.converged {
                    relative_change = o.relative_change;
                    path = SolvePath::Newton;
                    done = true;
                } else {
                    path = SolvePath::NewtonFallback;
                }
            }
            if !done {
                let budget = if newton_left {
                    let after = if na >= self.params.newton_min_pairs {
                        self.params.newton_after_sweeps_large
                    } else {
                        self.params.newton_after_sweeps
                    };
                    after.min(self.params.max_iterations)
                } else {
                    self.params.max_iterations
                };
                let run = self.run_sweeps(m, budget, &mut iterations);
                status = run.status;
                relative_change = run.relative_change;
                if status == SolveStatus::MaxIterations && newton_left {
                    let o = self.run_newton();
                    newton_iterations += o.iterations;
                    factorisations += o.factorisations;
                    if o.converged {
                        status = SolveStatus::Converged;
                        relative_change = o.relative_change;
                        path = SolvePath::SweepsThenNewton;
                    } else {
                        path = SolvePath::NewtonFallback;
                        let run = self.run_sweeps(m, self.params.max_iterations, &mut iterations);
                        status = run.status;
                        relative_change = run.relative_change;
                    }
                }
            }
        }
        if status == SolveStatus::Diverged {
            self.lam[..m].fill(0.0);
        }

        // 3. Gap velocities, residual and states of the active pairs. Without a gathered block
        // (a Newton solve) the gap velocities of all pairs come first, from the rows of W of
        // the nonzero forces (step 4), and the active ones are read from them.
        let gathered = self.block_gathered;
        if gathered {
            matvec(
                &self.w_act[..m * m],
                &self.lam[..m],
                &self.c_act[..m],
                &mut self.y[..m],
            );
        } else {
            self.all_gap_velocities(c, lambda, gamma);
            for (slot, &p) in self.active.iter().enumerate() {
                self.y[3 * slot..3 * slot + 3].copy_from_slice(&gamma[3 * p..3 * p + 3]);
            }
        }
        let (mut res2, mut lam2, mut ec2) = (0.0, 0.0, 0.0);
        let (mut stick, mut slip) = (0, 0);
        self.states.fill(PairState::Open);
        for (slot, &p) in self.active.iter().enumerate() {
            let b = 3 * slot;
            let l = [self.lam[b], self.lam[b + 1], self.lam[b + 2]];
            let trial = [
                l[0] - self.eps[b] * self.y[b],
                l[1] - self.eps[b + 1] * self.y[b + 1],
                l[2] - self.eps[b + 2] * self.y[b + 2],
            ];
            let (proj, state) = project_pair(self.mu_act[slot], trial);
            for a in 0..3 {
                let r = l[a] - proj[a];
                res2 += r * r;
                lam2 += l[a] * l[a];
                let ec = self.eps[b + a] * self.c_act[b + a];
                ec2 += ec * ec;
            }
            self.states[p] = state;
            match state {
                PairState::Stick => stick += 1,
                PairState::Slip => slip += 1,
                PairState::Open => {}
            }
        }
        let residual = res2.sqrt();
        let scale = lam2.max(ec2).sqrt();
        let relative_residual = if residual == 0.0 {
            0.0
        } else {
            residual / scale
        };

        // 4. Outputs for all pairs (done in step 3 without a gathered block).
        if gathered {
            self.all_gap_velocities(c, lambda, gamma);
            for (slot, &p) in self.active.iter().enumerate() {
                gamma[3 * p..3 * p + 3].copy_from_slice(&self.y[3 * slot..3 * slot + 3]);
            }
        }

        Ok(SolveStats {
            status,
            converged: status == SolveStatus::Converged,
            iterations,
            newton_iterations,
            factorisations,
            path,
            relative_change,
            residual,
            relative_residual,
            active_pairs: na,
            predicted_open: n - na,
            open: n - stick - slip,
            stick,
            slip,
            active_set_changed,
        })
    }

    /// The forces of all pairs into `lambda` (zero outside the active set) and
    /// `gamma = c + W lambda` for all pairs, using the symmetry of W (row j is column j), so
    /// only the rows of nonzero forces are read.
    fn all_gap_velocities(&self, c: &[f64], lambda: &mut [f64], gamma: &mut [f64]) {
        let dim = 3 * self.n_pairs;
        lambda.fill(0.0);
        gamma.copy_from_slice(c);
        for (slot, &p) in self.active.iter().enumerate() {
            for a in 0..3 {
                let f = self.lam[3 * slot + a];
                lambda[3 * p + a] = f;
                if f != 0.0 {
                    let row = &self.w[(3 * p + a) * dim..(3 * p + a + 1) * dim];
                    axpy(f, row, gamma);
                }
            }
        }
    }

    /// Sweeps from the current iterate until converged or `*iterations` reaches `until`.
    fn run_sweeps(&mut self, m: usize, until: usize, iterations: &mut usize) -> SweepRun {
        // NOTE: with every pair active the block is W itself (the active pairs ascend), so the
        // Gauss-Seidel sweep reads W in place instead of copying it (held contact hands all
        // pairs to most large solves, which start with a few sweeps).
        let whole =
            self.active.len() == self.n_pairs && self.params.method == SweepMethod::GaussSeidel;
        if !self.block_gathered && !whole {
            self.gather_block();
        }
        let tol2 = self.params.tolerance * self.params.tolerance;
        let mut momentum = 1.0;
        self.ext[..m].copy_from_slice(&self.lam[..m]);
        let mut run = SweepRun {
            status: SolveStatus::MaxIterations,
            relative_change: 0.0,
        };
        while *iterations < until {
            *iterations += 1;
            let (d2, n2) = match self.params.method {
                SweepMethod::Jacobi => self.jacobi_sweep(m),
                SweepMethod::AcceleratedJacobi => self.accelerated_sweep(m, &mut momentum),
                SweepMethod::GaussSeidel => gauss_seidel_sweep(
                    if self.block_gathered {
                        &self.w_act[..m * m]
                    } else {
                        &self.w[..m * m]
                    },
                    &self.c_act[..m],
                    &self.eps[..m],
                    &self.mu_act[..m / 3],
                    &mut self.lam[..m],
                ),
            };
            if !(d2.is_finite() && n2.is_finite()) {
                run.status = SolveStatus::Diverged;
                run.relative_change = f64::NAN;
                break;
            }
            run.relative_change = if d2 == 0.0 { 0.0 } else { (d2 / n2).sqrt() };
            if d2 <= tol2 * n2 {
                run.status = SolveStatus::Converged;
                break;
            }
        }
        run
    }

    /// One Newton attempt from the current iterate (`lam` of the active pairs).
    fn run_newton(&mut self) -> super::newton::NewtonOutcome {
        let m = 3 * self.active.len();
        let input = NewtonInput {
            w: &self.w,
            active: &self.active,
            c_act: &self.c_act[..m],
            mu_act: &self.mu_act[..m / 3],
            eps: &self.eps[..m],
            tolerance: self.params.tolerance,
            max_iterations: self.params.newton_max_iterations,
        };
        self.newton.solve(&input, &mut self.lam, &mut self.y)
    }

    /// One projected Jacobi sweep: `y = W lambda + c` from the previous iterate, then every pair
    /// projected. Returns (||change||^2, ||lambda_new||^2).
    fn jacobi_sweep(&mut self, m: usize) -> (f64, f64) {
        matvec(
            &self.w_act[..m * m],
            &self.lam[..m],
            &self.c_act[..m],
            &mut self.y[..m],
        );
        let (mut d2, mut n2) = (0.0, 0.0);
        for (k, &mu) in self.mu_act[..m / 3].iter().enumerate() {
            let b = 3 * k;
            let trial = [
                self.lam[b] - self.eps[b] * self.y[b],
                self.lam[b + 1] - self.eps[b + 1] * self.y[b + 1],
                self.lam[b + 2] - self.eps[b + 2] * self.y[b + 2],
            ];
            let (p, _) = project_pair(mu, trial);
            for (l, &pa) in self.lam[b..b + 3].iter_mut().zip(&p) {
                let d = pa - *l;
                d2 += d * d;
                n2 += pa * pa;
                *l = pa;
            }
        }
        (d2, n2)
    }

    /// One accelerated projected Jacobi sweep: the projected step is taken from the
    /// extrapolated point `ext`, then `ext = lambda + beta (lambda - lambda_prev)` with
    /// Nesterov's `beta`, restarted (beta = 0, t = 1) when the step opposes the momentum.
    /// Returns (||lambda_new - ext||^2, ||lambda_new||^2).
    fn accelerated_sweep(&mut self, m: usize, t: &mut f64) -> (f64, f64) {
        matvec(
            &self.w_act[..m * m],
            &self.ext[..m],
            &self.c_act[..m],
            &mut self.y[..m],
        );
        let (mut d2, mut n2, mut restart) = (0.0, 0.0, 0.0);
        for (k, &mu) in self.mu_act[..m / 3].iter().enumerate() {
            let b = 3 * k;
            let trial = [
                self.ext[b] - self.eps[b] * self.y[b],
                self.ext[b + 1] - self.eps[b + 1] * self.y[b + 1],
                self.ext[b + 2] - self.eps[b + 2] * self.y[b + 2],
            ];
            let (p, _) = project_pair(mu, trial);
            for (a, &pa) in p.iter().enumerate() {
                let i = b + a;
                let step = pa - self.ext[i];
                d2 += step * step;
                n2 += pa * pa;
                // Gradient-mapping restart test (O'Donoghue & Candes): restart when
                // (ext - new) . (new - old) > 0, i.e. the step points against the momentum.
                restart -= step * (pa - self.lam[i]);
                self.prev[i] = self.lam[i];
                self.lam[i] = pa;
            }
        }
        if restart > 0.0 {
            *t = 1.0;
            self.ext[..m].copy_from_slice(&self.lam[..m]);
        } else {
            let t_next = 0.5 * (1.0 + (1.0 + 4.0 * *t * *t).sqrt());
            let beta = (*t - 1.0) / t_next;
            *t = t_next;
            for ((e, &l), &q) in self.ext[..m]
                .iter_mut()
                .zip(&self.lam[..m])
                .zip(&self.prev[..m])
            {
                *e = l + beta * (l - q);
            }
        }
        (d2, n2)
    }

    /// Copies the active rows and columns of W into the contiguous block `w_act`.
    fn gather_block(&mut self) {
        let dim = 3 * self.n_pairs;
        let m = 3 * self.active.len();
        for (ra, &p) in self.active.iter().enumerate() {
            for a in 0..3 {
                let src = &self.w[(3 * p + a) * dim..(3 * p + a + 1) * dim];
                let dst = &mut self.w_act[(3 * ra + a) * m..(3 * ra + a + 1) * m];
                for (cb, &q) in self.active.iter().enumerate() {
                    dst[3 * cb..3 * cb + 3].copy_from_slice(&src[3 * q..3 * q + 3]);
                }
            }
        }
        self.block_gathered = true;
    }

    /// Step sizes `eps` of the active components for the configured method and rule.
    fn compute_step_sizes(&mut self) {
        let m = 3 * self.active.len();
        let r = self.params.relaxation;
        let w = &self.w_act[..m * m];
        // Per component: the scale that eps divides, before sharing it within a pair's
        // tangential components.
        let scale = &mut self.scratch[..m];
        match self.params.method {
            SweepMethod::GaussSeidel => {
                // NOTE: a Gauss-Seidel update moves one pair with the others fixed, so only the
                // pair's own 3x3 block matters: its row sums bound the block's largest
                // eigenvalue and make each update a convergent projected step.
                // Read from the full W (the block may not be gathered): the same entries.
                let dim = 3 * self.n_pairs;
                for (i, s) in scale.iter_mut().enumerate() {
                    let p = self.active[i / 3];
                    let row = (3 * p + i % 3) * dim + 3 * p;
                    *s = self.w[row..row + 3].iter().map(|x| x.abs()).sum();
                }
            }
            SweepMethod::Jacobi | SweepMethod::AcceleratedJacobi => {
                // NOTE (DESIGN.md step 4): eps = r / W_ii converges when the active block is
                // diagonally dominant; a contact patch's G_res / dt is not (neighbouring nodes
                // are strongly coupled), and then the diagonal rule diverges. Row sums of |W|
                // bound the largest eigenvalue of D^-1 W by 1 (Gershgorin), which keeps the
                // Jacobi step a contraction at the price of many sweeps; the spectral rule
                // uses the actual largest eigenvalue instead.
                let mut dominant = true;
                for (i, s) in scale.iter_mut().enumerate() {
                    let row = &w[i * m..(i + 1) * m];
                    let diag = row[i];
                    let abs_sum: f64 = row.iter().map(|x| x.abs()).sum();
                    if abs_sum - diag >= diag {
                        dominant = false;
                    }
                    *s = match self.params.step_rule {
                        StepRule::RowSum => abs_sum,
                        _ => diag,
                    };
                }
                // The accelerated sweep is a gradient method: its step must stay below 1/L,
                // which the diagonal rule does not guarantee even for dominant W.
                let accelerated = self.params.method == SweepMethod::AcceleratedJacobi;
                if self.params.step_rule == StepRule::Auto && (!dominant || accelerated) {
                    for (i, s) in scale.iter_mut().enumerate() {
                        *s = w[i * m..(i + 1) * m].iter().map(|x| x.abs()).sum();
                    }
                }
            }
        }
        for k in 0..m / 3 {
            let t = scale[3 * k + 1].max(scale[3 * k + 2]);
            scale[3 * k + 1] = t;
            scale[3 * k + 2] = t;
        }
        let rho = if self.params.method != SweepMethod::GaussSeidel
            && self.params.step_rule == StepRule::Spectral
        {
            let inv_sqrt_d = &mut self.scratch2[..m];
            for (q, s) in inv_sqrt_d.iter_mut().zip(&self.scratch[..m]) {
                *q = 1.0 / s.sqrt();
            }
            let zero = &mut self.prev[..m];
            zero.fill(0.0);
            spectral_radius_scaled(w, inv_sqrt_d, zero, &mut self.y[..m], &mut self.lam[..m])
        } else {
            1.0
        };
        for (e, s) in self.eps[..m].iter_mut().zip(&self.scratch[..m]) {
            *e = r / (s * rho);
        }
    }
}

/// Largest eigenvalue of `D^-1/2 W D^-1/2`, given `inv_sqrt_d = D^-1/2` (m entries), estimated
/// by power iteration, with a small safety factor. `zero` is m zeros, `v` and `z` scratch of
/// length m.
fn spectral_radius_scaled(
    w: &[f64],
    inv_sqrt_d: &[f64],
    zero: &[f64],
    v: &mut [f64],
    z: &mut [f64],
) -> f64 {
    let m = inv_sqrt_d.len();
    // NOTE: the start vector D^1/2 * ones is close to the dominant eigenvector of a smooth,
    // positive flexibility kernel, so a few dozen iterations give the Rayleigh quotient to a
    // few per mille. The quotient never overestimates; 5 % margin (and r < 2) keeps the
    // Jacobi step a contraction even when the estimate is somewhat low.
    let norm = (m as f64).sqrt();
    for vi in v.iter_mut() {
        *vi = 1.0 / norm;
    }
    let mut rho = 0.0;
    for _ in 0..50 {
        // z = D^-1/2 W D^-1/2 v, with v scaled in place and restored.
        for (vi, q) in v.iter_mut().zip(inv_sqrt_d.iter()) {
            *vi *= q;
        }
        matvec(w, v, zero, z);
        for (zi, q) in z.iter_mut().zip(inv_sqrt_d.iter()) {
            *zi *= q;
        }
        for (vi, q) in v.iter_mut().zip(inv_sqrt_d.iter()) {
            *vi /= q;
        }
        let quotient: f64 = v.iter().zip(z.iter()).map(|(a, b)| a * b).sum();
        let zn = z.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(zn > 0.0 && zn.is_finite()) {
            break;
        }
        for (vi, zi) in v.iter_mut().zip(z.iter()) {
            *vi = zi / zn;
        }
        let done = (quotient - rho).abs() <= 1e-4 * quotient;
        rho = quotient;
        if done {
            break;
        }
    }
    1.05 * rho.max(f64::MIN_POSITIVE)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `W = S (I + a 1 1^T) S` with `S = diag(s)`: SPD, and `D^-1/2 W D^-1/2` for the diagonal
    /// rule has the known largest eigenvalue when the tangential diagonals of a pair agree.
    fn rank_one_coupled(n: usize, a: f64) -> Vec<f64> {
        let d = 3 * n;
        let s: Vec<f64> = (0..d).map(|i| 1.0 + (i / 3) as f64 * 0.1).collect();
        let mut w = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                w[i * d + j] = s[i] * s[j] * (a + if i == j { 1.0 } else { 0.0 });
            }
        }
        w
    }

    fn solver_with(w: &[f64], n: usize, method: SweepMethod, step_rule: StepRule) -> ContactSolver {
        let params = ContactParameters {
            method,
            step_rule,
            ..ContactParameters::default()
        };
        let mut s = ContactSolver::new(w, &vec![0.4; n], params).unwrap();
        let d = 3 * n;
        let (mut l, mut g) = (vec![0.0; d], vec![0.0; d]);
        s.solve(&vec![-1.0; d], None, &mut l, &mut g).unwrap();
        s
    }

    #[test]
    fn auto_rule_uses_the_diagonal_when_dominant_and_row_sums_otherwise() {
        let n = 3;
        let d = 3 * n;
        // a = 0.05: off-diagonal row sums 8 * 0.05 s_i s_j < (1.05) s_i^2: dominant.
        let w = rank_one_coupled(n, 0.05);
        let s = solver_with(&w, n, SweepMethod::Jacobi, StepRule::Auto);
        for k in 0..n {
            assert_eq!(s.eps[3 * k], 1.0 / w[3 * k * d + 3 * k]);
            let t = w[(3 * k + 1) * d + 3 * k + 1].max(w[(3 * k + 2) * d + 3 * k + 2]);
            assert_eq!(s.eps[3 * k + 1], 1.0 / t);
            assert_eq!(s.eps[3 * k + 2], 1.0 / t);
        }
        // a = 1: strongly coupled, row sums.
        let w = rank_one_coupled(n, 1.0);
        let s = solver_with(&w, n, SweepMethod::Jacobi, StepRule::Auto);
        let row_sum = |i: usize| w[i * d..(i + 1) * d].iter().map(|x| x.abs()).sum::<f64>();
        for k in 0..n {
            assert_eq!(s.eps[3 * k], 1.0 / row_sum(3 * k));
            let t = row_sum(3 * k + 1).max(row_sum(3 * k + 2));
            assert_eq!(s.eps[3 * k + 1], 1.0 / t);
        }
    }

    #[test]
    fn spectral_rule_estimates_the_largest_eigenvalue_from_above() {
        // With S constant within each pair, D^-1/2 W D^-1/2 = (I + a 1 1^T) / (1 + a), whose
        // largest eigenvalue is (1 + a d) / (1 + a).
        let n = 4;
        let d = 3 * n;
        let a = 0.5;
        let w = rank_one_coupled(n, a);
        let s = solver_with(&w, n, SweepMethod::Jacobi, StepRule::Spectral);
        let exact = (1.0 + a * d as f64) / (1.0 + a);
        for i in 0..d {
            let rho = 1.0 / (s.eps[i] * w[i * d + i]);
            assert!(rho >= exact && rho <= 1.06 * exact, "{rho} vs {exact}");
        }
    }

    #[test]
    fn parameters_are_checked() {
        let mut p = ContactParameters::default();
        assert!(p.validate().is_ok());
        p.tolerance = 0.0;
        assert!(p.validate().is_err());
        p = ContactParameters {
            max_iterations: 0,
            ..ContactParameters::default()
        };
        assert!(p.validate().is_err());
        p = ContactParameters {
            open_gap_margin: f64::NAN,
            ..ContactParameters::default()
        };
        assert!(p.validate().is_err());
    }

    #[test]
    fn parameters_read_from_toml_with_defaults() {
        let p: ContactParameters =
            toml::from_str("method = \"gauss_seidel\"\ntolerance = 1e-6\n").unwrap();
        assert_eq!(p.method, SweepMethod::GaussSeidel);
        assert_eq!(p.tolerance, 1e-6);
        assert_eq!(
            p.max_iterations,
            ContactParameters::default().max_iterations
        );
        assert!(toml::from_str::<ContactParameters>("tolerence = 1e-6").is_err());
    }

    #[test]
    fn no_active_pair_is_a_converged_solve_with_zero_sweeps() {
        let w = rank_one_coupled(2, 0.1);
        let mut s = ContactSolver::new(&w, &[0.4, 0.4], ContactParameters::default()).unwrap();
        let c = vec![-1.0; 6];
        let (mut l, mut g) = (vec![5.0; 6], vec![0.0; 6]);
        let stats = s.solve(&c, Some(&[1e-3, 2e-3]), &mut l, &mut g).unwrap();
        assert!(stats.converged);
        assert_eq!(
            (stats.iterations, stats.active_pairs, stats.open),
            (0, 0, 2)
        );
        assert_eq!(l, vec![0.0; 6]);
        assert_eq!(g, c);
    }
}
