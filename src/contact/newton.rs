//! The semismooth Newton solve of the contact problem on the Alart–Curnier function: the
//! method for held contact, where many pairs stay closed and the projected sweeps need
//! hundreds of passes over a strongly coupled Delassus block.
//!
//! With `x = lambda - eps .* gamma` (the trial point of the sweeps, same `eps`), the solutions
//! of the law are the zeros of `F(lambda) = lambda - proj_C(x)` ([`project_pair`], DESIGN.md
//! "The model" step 4). `F` is piecewise smooth; per pair and iterate:
//! - open (`x_n <= 0`): `F = lambda`, the Newton step sets `lambda_k = 0`;
//! - stick (`|x_t| <= mu x_n`): `F = eps .* gamma`, the step sets `gamma_k = 0`;
//! - slip: the step sets `gamma_n,k = 0` and the linearised tangential row
//!   `(I - r Q) lambda_t + r eps_t Q gamma_t - mu t lambda_n = 0` with `t = x_t / |x_t|`,
//!   `r = mu x_n / |x_t| < 1`, `Q = I - t t^T` (exact at a slipping solution, where
//!   `Q lambda_t = Q gamma_t = 0` and `lambda_t = mu lambda_n t`). A frictionless pair with
//!   a normal force is a slip pair with `r = 0`: `lambda_t = 0`.
//!
//! Open and stick rows are linear, so with no slipping pair one Newton step solves the
//! linear complementarity piece exactly, and the iteration stops when the states repeat.
//! Each step is one dense linear system, solved in the cheaper of two equivalent forms:
//! - direct: the unknowns are the forces of the closed pairs (`q = 3 closed`), the matrix the
//!   closed rows and columns of `W` (modified on slip rows), LU-factorised;
//! - complement (Woodbury): with `K = W^-1` of all pairs (Cholesky, once per solver), every
//!   row whose gap velocity is not forced to zero is released: `W lambda + c = P z`, so
//!   `lambda = K (P z - c)` and the open / slip rows give `k = 3 (n - closed) + 2 slip`
//!   equations for `z` (`z` is the released gap velocity). Held contact closes most pairs, so
//!   `k` is small where `q` is large.
//!
//! The factorisation is kept while the system is the same (same active pairs, same open/stick
//! states, no slipping pair), so a held contact that sticks costs one forward/back solve per
//! step. Like Siconos' `FC3D_NSN_AC`, the step is damped by a backtracking line search on
//! `||F||^2`; an attempt that does not converge within the limit returns the iterate with the smallest residual and the caller falls back
//! to sweeps from it.

use std::mem::MaybeUninit;

use faer::dyn_stack::MemStack;
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::perm::PermRef;
use faer::{Mat, MatMut, MatRef, Par, Side};

use super::kernels::{axpy, matvec};
use super::projection::project_pair;

/// Slipping pairs with `r = mu x_n / |x_t|` below this enter the direct system with their
/// normal force only, the tangential force fixed along the current slip direction.
// NOTE: the exact Alart–Curnier row `(I - r Q) lambda_t + r eps_t Q gamma_t - mu t lambda_n = 0`
// tends to `lambda_t = mu t lambda_n` as r -> 0; using that limit removes two unknowns per
// slipping pair (a 3x smaller system on a sliding patch) at the price of a fixed-point update
// of the slip direction. Measured on the touching-probes case (issue 16) with 0.5: the LU per
// iteration got cheaper but the iterations rose from 7 to 11 per solve and some attempts fell
// back to sweeps, no net gain; so it is off (0: every slipping pair keeps the exact rows).
const REDUCED_SLIP_R: f64 = 0.0;

/// Unknowns of closed pair `i` of the direct system (3, or 1 for a reduced slipping pair).
fn unknown_width(offset: &[usize], i: usize, q: usize) -> usize {
    offset.get(i + 1).copied().unwrap_or(q) - offset[i]
}

/// State of an active pair at the current iterate (from the trial point `x`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Class {
    Open,
    Stick,
    /// Slipping: unit slip direction of the trial point and `r = mu x_n / |x_t|`.
    Slip {
        t: [f64; 2],
        r: f64,
    },
}

impl Class {
    /// The part of the state that the system matrix depends on when nobody slips.
    fn key(self) -> u8 {
        match self {
            Class::Open => 0,
            Class::Stick => 1,
            Class::Slip { .. } => 2,
        }
    }
}

/// Which form of the Newton system is factorised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum System {
    Direct,
    Complement,
}

/// The data of one solve the Newton iteration reads.
pub(crate) struct NewtonInput<'a> {
    /// Full Delassus matrix, row-major `3n x 3n`.
    pub w: &'a [f64],
    /// Active pairs, ascending.
    pub active: &'a [usize],
    /// Active block of `W`, row-major `m x m`.
    pub w_act: &'a [f64],
    /// Free gap velocity, friction coefficients and step sizes of the active pairs.
    pub c_act: &'a [f64],
    pub mu_act: &'a [f64],
    pub eps: &'a [f64],
    /// Stop when `||lambda_new - lambda|| <= tolerance ||lambda_new||`.
    pub tolerance: f64,
    pub max_iterations: usize,
}

/// How a Newton attempt ended.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NewtonOutcome {
    pub converged: bool,
    pub iterations: usize,
    pub relative_change: f64,
    /// LU factorisations done (the rest of the iterations reused one).
    pub factorisations: usize,
}

/// Workspace of the Newton solve, sized for all pairs once (no allocation per solve, except
/// the one-time `W^-1` when the complement form is first used).
#[derive(Clone, Debug)]
pub(crate) struct Newton {
    n: usize,
    /// `W^-1`, row-major `3n x 3n`; empty until the complement form is first needed.
    k_inv: Vec<f64>,
    /// Whether computing `W^-1` failed (W numerically not positive definite): direct form only.
    k_failed: bool,
    class: Vec<Class>,
    /// Active slot of every pair (`usize::MAX`: not active).
    slot_of: Vec<usize>,
    /// Direct: active slots of the closed pairs; complement: released global components.
    unknowns: Vec<usize>,
    /// Direct: first unknown of each closed pair (in `unknowns` order); scratch row.
    offset: Vec<usize>,
    row_buf: Vec<f64>,
    /// Complement: position of a global component in `unknowns` (`usize::MAX`: not released).
    released_at: Vec<usize>,
    /// System matrix, column-major `q x q`, LU-factorised in place, and its right-hand side.
    mat: Vec<f64>,
    rhs: Vec<f64>,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    stack: Vec<MaybeUninit<u8>>,
    /// Complement: `-K c` over all components.
    lam0: Vec<f64>,
    lam_new: Vec<f64>,
    y_new: Vec<f64>,
    trial_l: Vec<f64>,
    trial_y: Vec<f64>,
    best: Vec<f64>,
    /// The factorisation in `mat`: its form, active pairs and states (valid only without slip).
    cached: Option<System>,
    cached_active: Vec<usize>,
    cached_keys: Vec<u8>,
}

impl Newton {
    /// A workspace for `n` pairs.
    pub(crate) fn new(n: usize) -> Newton {
        let d = 3 * n;
        let req =
            lu_factor::lu_in_place_scratch::<usize, f64>(d, d, Par::Seq, Default::default()).or(
                lu_solve::solve_in_place_scratch::<usize, f64>(d, 1, Par::Seq),
            );
        Newton {
            n,
            k_inv: Vec::new(),
            k_failed: false,
            class: vec![Class::Open; n],
            slot_of: vec![usize::MAX; n],
            unknowns: Vec::with_capacity(d),
            offset: Vec::with_capacity(n),
            row_buf: vec![0.0; d],
            released_at: vec![usize::MAX; d],
            mat: Vec::new(),
            rhs: vec![0.0; d],
            perm: vec![0; d],
            perm_inv: vec![0; d],
            stack: vec![MaybeUninit::uninit(); req.unaligned_bytes_required()],
            lam0: vec![0.0; d],
            lam_new: vec![0.0; d],
            y_new: vec![0.0; d],
            trial_l: vec![0.0; d],
            trial_y: vec![0.0; d],
            best: vec![0.0; d],
            cached: None,
            cached_active: Vec::with_capacity(n),
            cached_keys: Vec::with_capacity(n),
        }
    }

    /// Forgets the kept factorisation (e.g. after a parameter change).
    pub(crate) fn invalidate(&mut self) {
        self.cached = None;
    }

    /// Newton iterations from `lam` (the active forces, admissible), with `y` scratch for the
    /// gap velocities. On return `lam` holds the last iterate if converged, else the iterate
    /// with the smallest residual seen.
    pub(crate) fn solve(
        &mut self,
        inp: &NewtonInput<'_>,
        lam: &mut [f64],
        y: &mut [f64],
    ) -> NewtonOutcome {
        let na = inp.active.len();
        let m = 3 * na;
        // NOTE: the matrix buffer is sized at the first Newton solve, not in `new`: most
        // solvers (open flight, impacts) never need it.
        if self.mat.is_empty() {
            let d = 3 * self.n;
            self.mat = vec![0.0; d * d];
        }
        self.slot_of.fill(usize::MAX);
        for (slot, &p) in inp.active.iter().enumerate() {
            self.slot_of[p] = slot;
        }
        matvec(&inp.w_act[..m * m], &lam[..m], &inp.c_act[..m], &mut y[..m]);
        let mut lam0_ready = false;
        let mut res = merit(inp, lam, y);
        let mut best_res = res;
        self.best[..m].copy_from_slice(&lam[..m]);
        let mut out = NewtonOutcome {
            converged: false,
            iterations: 0,
            relative_change: f64::NAN,
            factorisations: 0,
        };
        while out.iterations < inp.max_iterations && res.is_finite() {
            if res == 0.0 {
                out.converged = true;
                out.relative_change = 0.0;
                return out;
            }
            out.iterations += 1;
            let (closed, slipping) = self.classify(inp, lam, y);
            let q = 3 * closed;
            let k = 3 * (self.n - closed) + 2 * slipping;
            let complement = k < q && self.ensure_inverse(inp.w);
            let system = if complement {
                System::Complement
            } else {
                System::Direct
            };
            let reuse = slipping == 0 && self.same_system(system, inp.active);
            let ok = if complement {
                if !lam0_ready {
                    self.form_lam0(inp);
                    lam0_ready = true;
                }
                self.complement_step(inp, reuse)
            } else {
                self.direct_step(inp, reuse)
            };
            if !reuse {
                out.factorisations += 1;
                self.remember(system, inp.active, slipping == 0);
            }
            if !ok {
                break;
            }
            let (mut d2, mut n2) = (0.0, 0.0);
            for (l, &ln) in lam[..m].iter().zip(&self.lam_new[..m]) {
                d2 += (ln - l) * (ln - l);
                n2 += ln * ln;
            }
            if !(d2.is_finite() && n2.is_finite()) {
                break;
            }
            out.relative_change = if d2 == 0.0 { 0.0 } else { (d2 / n2).sqrt() };
            if d2 <= inp.tolerance * inp.tolerance * n2 {
                lam[..m].copy_from_slice(&self.lam_new[..m]);
                out.converged = true;
                // NOTE: the converged iterate satisfies the law up to the round-off of the
                // linear solve; the projection makes it admissible exactly, as the sweeps'
                // iterates are.
                for (k, &mu) in inp.mu_act[..na].iter().enumerate() {
                    let b = 3 * k;
                    let (p, _) = project_pair(mu, [lam[b], lam[b + 1], lam[b + 2]]);
                    lam[b..b + 3].copy_from_slice(&p);
                }
                return out;
            }
            // Backtracking (Armijo) on the merit ||F||^2 along the Newton direction. The gap
            // velocity is affine in lambda, so a trial point costs O(m), no product with W.
            // NOTE: without it the iteration can cycle between state patterns on strongly
            // coupled patches (seen on held contact: 30 iterations without convergence).
            let mut alpha = 1.0;
            loop {
                for i in 0..m {
                    self.trial_l[i] = lam[i] + alpha * (self.lam_new[i] - lam[i]);
                    self.trial_y[i] = y[i] + alpha * (self.y_new[i] - y[i]);
                }
                let r = merit(inp, &self.trial_l[..m], &self.trial_y[..m]);
                if r <= (1.0 - 1e-4 * alpha) * res || alpha < 1.0 / 64.0 {
                    res = r;
                    break;
                }
                alpha *= 0.5;
            }
            lam[..m].copy_from_slice(&self.trial_l[..m]);
            y[..m].copy_from_slice(&self.trial_y[..m]);
            if res < best_res {
                best_res = res;
                self.best[..m].copy_from_slice(&lam[..m]);
            }
        }
        if best_res.is_finite() {
            lam[..m].copy_from_slice(&self.best[..m]);
        }
        self.cached = None;
        out
    }

    /// States of the active pairs at `(lam, y)`; returns the number of closed (stick or slip)
    /// pairs and of slipping ones.
    fn classify(&mut self, inp: &NewtonInput<'_>, lam: &[f64], y: &[f64]) -> (usize, usize) {
        let (mut closed, mut slipping) = (0, 0);
        for (slot, &mu) in inp.mu_act[..inp.active.len()].iter().enumerate() {
            let b = 3 * slot;
            let x = [
                lam[b] - inp.eps[b] * y[b],
                lam[b + 1] - inp.eps[b + 1] * y[b + 1],
                lam[b + 2] - inp.eps[b + 2] * y[b + 2],
            ];
            // A NaN trial point counts as open (the merit is NaN and the attempt stops).
            let class = if x[0].is_nan() || x[0] <= 0.0 {
                Class::Open
            } else {
                let nt = x[1].hypot(x[2]);
                let radius = mu * x[0];
                if mu > 0.0 && nt <= radius {
                    Class::Stick
                } else if mu > 0.0 {
                    Class::Slip {
                        t: [x[1] / nt, x[2] / nt],
                        r: radius / nt,
                    }
                } else {
                    Class::Slip {
                        t: [0.0, 0.0],
                        r: 0.0,
                    }
                }
            };
            match class {
                Class::Open => {}
                Class::Stick => closed += 1,
                Class::Slip { .. } => {
                    closed += 1;
                    slipping += 1;
                }
            }
            self.class[slot] = class;
        }
        (closed, slipping)
    }

    /// Whether the kept factorisation is the one of `system` for the current states.
    fn same_system(&self, system: System, active: &[usize]) -> bool {
        self.cached == Some(system)
            && self.cached_active == active
            && self.cached_keys.len() == active.len()
            && self
                .cached_keys
                .iter()
                .zip(&self.class)
                .all(|(&k, c)| k == c.key())
    }

    fn remember(&mut self, system: System, active: &[usize], reusable: bool) {
        if !reusable {
            self.cached = None;
            return;
        }
        self.cached = Some(system);
        self.cached_active.clear();
        self.cached_active.extend_from_slice(active);
        self.cached_keys.clear();
        let na = active.len();
        self.cached_keys
            .extend(self.class[..na].iter().map(|c| c.key()));
    }

    /// `K = W^-1` for the complement form, computed once (Cholesky); false if W is not
    /// numerically positive definite.
    fn ensure_inverse(&mut self, w: &[f64]) -> bool {
        if !self.k_inv.is_empty() {
            return true;
        }
        if self.k_failed {
            return false;
        }
        let d = 3 * self.n;
        let wm = Mat::<f64>::from_fn(d, d, |i, j| w[i * d + j]);
        // NOTE: one-time allocation and O((3n)^3) work (about 20 ms for 192 pairs), on the
        // first solve that needs it; W is constant for the solver's life.
        match wm.llt(Side::Lower) {
            Ok(llt) => {
                use faer::linalg::solvers::DenseSolveCore;
                let inv = llt.inverse();
                self.k_inv = vec![0.0; d * d];
                for i in 0..d {
                    for j in 0..d {
                        // Exactly symmetric (the inverse is formed from one triangle).
                        self.k_inv[i * d + j] = if j >= i { inv[(i, j)] } else { inv[(j, i)] };
                    }
                }
                true
            }
            Err(_) => {
                self.k_failed = true;
                false
            }
        }
    }

    /// `lam0 = -K c` over all components, `c` zero outside the active rows.
    fn form_lam0(&mut self, inp: &NewtonInput<'_>) {
        let d = 3 * self.n;
        self.lam0.fill(0.0);
        for (slot, &p) in inp.active.iter().enumerate() {
            for a in 0..3 {
                let f = -inp.c_act[3 * slot + a];
                if f != 0.0 {
                    let row = &self.k_inv[(3 * p + a) * d..(3 * p + a + 1) * d];
                    axpy(f, row, &mut self.lam0);
                }
            }
        }
    }

    /// One Newton step in the direct form (unknowns: forces of the closed pairs; a slipping
    /// pair below [`REDUCED_SLIP_R`] contributes only its normal force, see the NOTE there).
    fn direct_step(&mut self, inp: &NewtonInput<'_>, reuse: bool) -> bool {
        let na = inp.active.len();
        let m = 3 * na;
        self.unknowns.clear();
        self.offset.clear();
        let mut q = 0;
        for s in 0..na {
            let width = match self.class[s] {
                Class::Open => continue,
                Class::Stick => 3,
                Class::Slip { r, .. } => {
                    if r < REDUCED_SLIP_R {
                        1
                    } else {
                        3
                    }
                }
            };
            self.unknowns.push(s);
            self.offset.push(q);
            q += width;
        }
        let w = inp.w_act;
        let c = inp.c_act;
        // NOTE: the matrix is written row by row into a column-major buffer of its transpose
        // (contiguous writes); the LU is of A^T and the solve uses the transposed solve.
        for (i, &p) in self.unknowns.iter().enumerate() {
            let class = self.class[p];
            let width = unknown_width(&self.offset, i, q);
            for a in 0..width {
                let row = self.offset[i] + a;
                let slip_row = match class {
                    Class::Slip { t, r } if a > 0 => Some((t, r)),
                    _ => None,
                };
                match slip_row {
                    None => {
                        self.rhs[row] = -c[3 * p + a];
                        if !reuse {
                            self.row_buf[..m]
                                .copy_from_slice(&w[(3 * p + a) * m..(3 * p + a + 1) * m]);
                            fill_row(
                                &mut self.mat[row * q..(row + 1) * q],
                                &self.row_buf,
                                &self.unknowns,
                                &self.offset,
                                &self.class,
                                inp.mu_act,
                            );
                        }
                    }
                    Some((t, r)) => {
                        let al = a - 1;
                        let qm = [
                            [1.0 - t[0] * t[0], -t[0] * t[1]],
                            [-t[1] * t[0], 1.0 - t[1] * t[1]],
                        ];
                        let re = r * inp.eps[3 * p + 1];
                        let (g0, g1) = (re * qm[al][0], re * qm[al][1]);
                        self.rhs[row] = -(g0 * c[3 * p + 1] + g1 * c[3 * p + 2]);
                        let r1 = &w[(3 * p + 1) * m..(3 * p + 2) * m];
                        let r2 = &w[(3 * p + 2) * m..(3 * p + 3) * m];
                        for ((v, &x1), &x2) in self.row_buf[..m].iter_mut().zip(r1).zip(r2) {
                            *v = g0 * x1 + g1 * x2;
                        }
                        fill_row(
                            &mut self.mat[row * q..(row + 1) * q],
                            &self.row_buf,
                            &self.unknowns,
                            &self.offset,
                            &self.class,
                            inp.mu_act,
                        );
                        let own = self.offset[i];
                        self.mat[row * q + own] -= inp.mu_act[p] * t[al];
                        for (be, &qb) in qm[al].iter().enumerate() {
                            let ident = if al == be { 1.0 } else { 0.0 };
                            self.mat[row * q + own + 1 + be] += ident - r * qb;
                        }
                    }
                }
            }
        }
        if q > 0 && !self.factor_and_solve(q, reuse) {
            return false;
        }
        self.lam_new[..m].fill(0.0);
        for (i, &p) in self.unknowns.iter().enumerate() {
            let o = self.offset[i];
            if unknown_width(&self.offset, i, q) == 3 {
                self.lam_new[3 * p..3 * p + 3].copy_from_slice(&self.rhs[o..o + 3]);
            } else {
                let (ln, mu) = (self.rhs[o], inp.mu_act[p]);
                let t = match self.class[p] {
                    Class::Slip { t, .. } => t,
                    _ => [0.0, 0.0],
                };
                self.lam_new[3 * p..3 * p + 3].copy_from_slice(&[
                    ln,
                    mu * ln * t[0],
                    mu * ln * t[1],
                ]);
            }
        }
        matvec(
            &w[..m * m],
            &self.lam_new[..m],
            &c[..m],
            &mut self.y_new[..m],
        );
        true
    }

    /// One Newton step in the complement form (unknowns: released gap velocities, all pairs).
    fn complement_step(&mut self, inp: &NewtonInput<'_>, reuse: bool) -> bool {
        let n = self.n;
        let d = 3 * n;
        let m = 3 * inp.active.len();
        self.unknowns.clear();
        self.released_at.fill(usize::MAX);
        for g in 0..n {
            let slot = self.slot_of[g];
            let class = if slot == usize::MAX {
                Class::Open
            } else {
                self.class[slot]
            };
            let first = match class {
                Class::Open => 0,
                Class::Slip { .. } => 1,
                Class::Stick => 3,
            };
            for a in first..3 {
                self.released_at[3 * g + a] = self.unknowns.len();
                self.unknowns.push(3 * g + a);
            }
        }
        let k = self.unknowns.len();
        let kinv = &self.k_inv;
        // Constraint rows, in the order of the released components (an open pair's three
        // rows, a slipping pair's two tangential rows).
        let mut row = 0;
        while row < k {
            let comp = self.unknowns[row];
            let g = comp / 3;
            let slot = self.slot_of[g];
            let class = if slot == usize::MAX {
                Class::Open
            } else {
                self.class[slot]
            };
            match class {
                Class::Open => {
                    self.rhs[row] = -self.lam0[comp];
                    if !reuse {
                        let krow = &kinv[comp * d..(comp + 1) * d];
                        for (j, &cj) in self.unknowns.iter().enumerate() {
                            self.mat[row * k + j] = krow[cj];
                        }
                    }
                    row += 1;
                }
                Class::Slip { t, r } => {
                    let mu = inp.mu_act[slot];
                    let qm = [
                        [1.0 - t[0] * t[0], -t[0] * t[1]],
                        [-t[1] * t[0], 1.0 - t[1] * t[1]],
                    ];
                    let re = r * inp.eps[3 * slot + 1];
                    let kn = &kinv[3 * g * d..(3 * g + 1) * d];
                    let k1 = &kinv[(3 * g + 1) * d..(3 * g + 2) * d];
                    let k2 = &kinv[(3 * g + 2) * d..(3 * g + 3) * d];
                    for al in 0..2 {
                        // (I - r Q) rows
                        let a0 = if al == 0 { 1.0 } else { 0.0 } - r * qm[al][0];
                        let a1 = if al == 1 { 1.0 } else { 0.0 } - r * qm[al][1];
                        let tn = mu * t[al];
                        let rr = row + al;
                        self.rhs[rr] = -(a0 * self.lam0[3 * g + 1] + a1 * self.lam0[3 * g + 2])
                            + tn * self.lam0[3 * g];
                        for (j, &cj) in self.unknowns.iter().enumerate() {
                            self.mat[rr * k + j] = a0 * k1[cj] + a1 * k2[cj] - tn * kn[cj];
                        }
                        self.mat[rr * k + row] += re * qm[al][0];
                        self.mat[rr * k + row + 1] += re * qm[al][1];
                    }
                    row += 2;
                }
                Class::Stick => unreachable!("stick components are not released"),
            }
        }
        if k > 0 && !self.factor_and_solve(k, reuse) {
            return false;
        }
        let kinv = &self.k_inv;
        // lambda = lam0 + K P z on the closed active pairs; open ones are exactly zero.
        // gamma = z on the released components, zero on the others.
        for (slot, &g) in inp.active.iter().enumerate() {
            let b = 3 * slot;
            if self.class[slot] == Class::Open {
                self.lam_new[b..b + 3].fill(0.0);
            } else {
                for a in 0..3 {
                    let comp = 3 * g + a;
                    let krow = &kinv[comp * d..(comp + 1) * d];
                    let mut v = self.lam0[comp];
                    for (&cj, &z) in self.unknowns.iter().zip(&self.rhs[..k]) {
                        v += krow[cj] * z;
                    }
                    self.lam_new[b + a] = v;
                }
            }
            for a in 0..3 {
                let at = self.released_at[3 * g + a];
                self.y_new[b + a] = if at == usize::MAX { 0.0 } else { self.rhs[at] };
            }
        }
        debug_assert!(m <= self.lam_new.len());
        true
    }

    /// LU-factorises `mat` (the transpose of the system matrix `A`, `q x q`, column-major,
    /// i.e. `A` row-major) unless `reuse`, then solves `A x = rhs` in place. False if the solution is not finite (singular system).
    fn factor_and_solve(&mut self, q: usize, reuse: bool) -> bool {
        let stack = MemStack::new(&mut self.stack);
        if !reuse {
            let a = MatMut::from_column_major_slice_mut(&mut self.mat[..q * q], q, q);
            lu_factor::lu_in_place(
                a,
                &mut self.perm[..q],
                &mut self.perm_inv[..q],
                Par::Seq,
                stack,
                Default::default(),
            );
        }
        let lu = MatRef::from_column_major_slice(&self.mat[..q * q], q, q);
        let perm = PermRef::new_checked(&self.perm[..q], &self.perm_inv[..q], q);
        let rhs = MatMut::from_column_major_slice_mut(&mut self.rhs[..q], q, 1);
        lu_solve::solve_transpose_in_place(lu, lu, perm, rhs, Par::Seq, stack);
        self.rhs[..q].iter().all(|x| x.is_finite())
    }
}

/// `||F(lambda)||^2 = ||lambda - proj_C(lambda - eps .* gamma)||^2` over the active pairs.
fn merit(inp: &NewtonInput<'_>, lam: &[f64], y: &[f64]) -> f64 {
    let mut res2 = 0.0;
    for (slot, &mu) in inp.mu_act[..inp.active.len()].iter().enumerate() {
        let b = 3 * slot;
        let x = [
            lam[b] - inp.eps[b] * y[b],
            lam[b + 1] - inp.eps[b + 1] * y[b + 1],
            lam[b + 2] - inp.eps[b + 2] * y[b + 2],
        ];
        let (p, _) = project_pair(mu, x);
        for a in 0..3 {
            res2 += (lam[b + a] - p[a]) * (lam[b + a] - p[a]);
        }
    }
    res2
}

/// Writes one row of the direct system (`out`, q entries) from a row `v` over the active
/// components: a full pair takes its three entries, a reduced slipping pair the combination
/// along its force direction `(1, mu t)`.
fn fill_row(
    out: &mut [f64],
    v: &[f64],
    unknowns: &[usize],
    offset: &[usize],
    class: &[Class],
    mu_act: &[f64],
) {
    let q = out.len();
    for (i, &s) in unknowns.iter().enumerate() {
        let o = offset[i];
        let b = 3 * s;
        if unknown_width(offset, i, q) == 3 {
            out[o..o + 3].copy_from_slice(&v[b..b + 3]);
        } else {
            let t = match class[s] {
                Class::Slip { t, .. } => t,
                _ => [0.0, 0.0],
            };
            out[o] = v[b] + mu_act[s] * (t[0] * v[b + 1] + t[1] * v[b + 2]);
        }
    }
}
