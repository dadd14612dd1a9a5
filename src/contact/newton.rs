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
//!   `Q lambda_t = Q gamma_t = 0` and `lambda_t = mu lambda_n t`). In the tangent plane
//!   `Q = s s^T` with `s` the unit vector normal to `t`, so the row splits into
//!   `t . lambda_t = mu lambda_n` (local) and `(1 - r) s . lambda_t + r eps_t s . gamma_t = 0`:
//!   a slipping pair has two unknowns, `lambda_n` and `b = s . lambda_t`, with
//!   `lambda_t = mu lambda_n t + b s`. A frictionless pair with a normal force has one
//!   (`lambda_t = 0`).
//!
//! Open and stick rows are linear, so with no slipping pair one Newton step solves the
//! linear complementarity piece exactly, and the iteration stops when the states repeat.
//! Each step is one dense linear system, solved in the cheaper of two equivalent forms:
//! - direct: the unknowns are the forces of the closed pairs (3 per sticking pair, 2 per
//!   slipping one), the matrix made of the closed rows and columns of `W`, LU-factorised;
//! - complement (Woodbury): with `K = W^-1` of all pairs (Cholesky, once per solver), every
//!   row whose gap velocity is not forced to zero is released: `W lambda + c = P z`, so
//!   `lambda = K (P z - c)` and the open / slip rows give `k = 3 (n - closed) + 2 slip`
//!   equations for `z` (`z` is the released gap velocity). Held contact closes most pairs, so
//!   `k` is small where `q` is large.
//!
//! `W` is read in place (rows of the full matrix by pair index), never gathered into an
//! active block, and gap velocities are updated from the columns of the nonzero forces only.
//!
//! The factorisation of the last fresh step is kept with its pattern (form, active pairs,
//! open/stick/slip state of each). A later step with the same pattern (in the same solve or a
//! later one) is a *chord* step: the current system is assembled (O(q^2)) but solved by defect
//! correction with the kept factors instead of a new LU (O(q^3)); only the slip directions
//! and ratios `r` differ, which is what the late iterations of a solve and a held contact that
//! keeps its states look like. A chord step must cut `||F||` at least in half; otherwise the
//! step is redone with a fresh factorisation (the safeguard), so the iteration is the Newton
//! iteration whenever the kept factors are not good enough. Like Siconos' `FC3D_NSN_AC`, the
//! step is damped by a backtracking line search on `||F||^2`; an attempt that does not
//! converge within the limit returns the iterate with the smallest residual and the caller
//! falls back to sweeps from it.

use std::mem::MaybeUninit;

use faer::dyn_stack::MemStack;
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::perm::PermRef;
use faer::{Mat, MatMut, MatRef, Par, Side};

use super::kernels::{axpy, matvec};
use super::projection::project_pair;

/// A chord step is kept when it brings `||F||^2` down to this fraction of its value before
/// the step (`||F||` halved); otherwise the step is redone with a fresh factorisation.
// NOTE: the fresh Newton step converges quadratically once the pattern is right, so a chord
// step that does not even halve the residual means the kept factors are stale (the slip
// directions moved too much); redoing it costs one O(q^2) assembly more than a plain Newton
// step, accepting it could cost several iterations.
const CHORD_DECREASE: f64 = 0.25;

/// Defect-correction passes of one chord step at most (each one O(q^2)).
const CHORD_PASSES: usize = 4;

/// State of an active pair at the current iterate (from the trial point `x`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Class {
    Open,
    Stick,
    /// Slipping: unit slip direction of the trial point and `r = mu x_n / |x_t|` (`t` zero
    /// and `r = 0` for a frictionless pair).
    Slip {
        t: [f64; 2],
        r: f64,
    },
}

impl Class {
    /// The part of the state that the structure of the system depends on.
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
    /// LU factorisations done (the other iterations were chord steps on kept factors).
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
    /// Direct: first unknown of each closed pair (in `unknowns` order) and the force
    /// directions of its unknowns (`lambda_pair = sum_j x_j basis[j]`).
    offset: Vec<usize>,
    basis: Vec<[[f64; 3]; 3]>,
    /// Complement: position of a global component in `unknowns` (`usize::MAX`: not released).
    released_at: Vec<usize>,
    /// The current system `A` (row-major `q x q`, i.e. `A^T` column-major), its right-hand
    /// side, the unknowns at the current iterate and the solution.
    a_cur: Vec<f64>,
    rhs: Vec<f64>,
    x0: Vec<f64>,
    x: Vec<f64>,
    defect: Vec<f64>,
    zeros: Vec<f64>,
    /// Direct: the number of unknowns of the assembled system.
    q_direct: usize,
    /// LU factors of a system like `a_cur` (same layout) and its permutation.
    lu: Vec<f64>,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    stack: Vec<MaybeUninit<u8>>,
    /// `W lambda` over all components (scratch of the gap-velocity update).
    w_lambda: Vec<f64>,
    /// A combination of a pair's rows of W over all components (scratch of the assembly).
    row_comb: Vec<f64>,
    /// Complement: `-K c` over all components.
    lam0: Vec<f64>,
    lam_new: Vec<f64>,
    y_new: Vec<f64>,
    trial_l: Vec<f64>,
    trial_y: Vec<f64>,
    best: Vec<f64>,
    /// The pattern of the factors in `lu`: form, size, active pairs and states.
    cached: Option<(System, usize)>,
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
            basis: Vec::with_capacity(n),
            released_at: vec![usize::MAX; d],
            a_cur: Vec::new(),
            rhs: vec![0.0; d],
            x0: vec![0.0; d],
            x: vec![0.0; d],
            defect: vec![0.0; d],
            zeros: vec![0.0; d],
            q_direct: 0,
            lu: Vec::new(),
            perm: vec![0; d],
            perm_inv: vec![0; d],
            stack: vec![MaybeUninit::uninit(); req.unaligned_bytes_required()],
            w_lambda: vec![0.0; d],
            row_comb: vec![0.0; d],
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
        // NOTE: the matrix buffers are sized at the first Newton solve, not in `new`: most
        // solvers (open flight, impacts) never need them.
        if self.lu.is_empty() {
            let d = 3 * self.n;
            self.lu = vec![0.0; d * d];
            self.a_cur = vec![0.0; d * d];
        }
        self.slot_of.fill(usize::MAX);
        for (slot, &p) in inp.active.iter().enumerate() {
            self.slot_of[p] = slot;
        }
        gap_velocities(inp, &lam[..m], &mut self.w_lambda, &mut y[..m]);
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
            let (closed, slipping, frictionless) = self.classify(inp, lam, y);
            let q = 3 * closed - slipping - frictionless;
            let k = 3 * (self.n - closed) + 2 * slipping;
            let complement = k < q && self.ensure_inverse(inp.w);
            let (system, size) = if complement {
                if !lam0_ready {
                    self.form_lam0(inp);
                    lam0_ready = true;
                }
                self.assemble_complement(inp, y);
                (System::Complement, k)
            } else {
                self.assemble_direct(inp, lam, q);
                (System::Direct, q)
            };
            // A chord step on the kept factors when the pattern repeats, kept if it at least
            // halves ||F|| (see CHORD_DECREASE) or is converged (a step below the tolerance:
            // the current forces solve the current system; the residual may then be at its
            // round-off and not halve); a fresh factorisation otherwise.
            let mut step = None;
            if self.same_pattern(system, size, inp.active) && self.chord(size) {
                self.map_solution(system, inp);
                let change = relative_step(&lam[..m], &self.lam_new[..m]);
                let r = merit(inp, &self.lam_new[..m], &self.y_new[..m]);
                let converged = change.0 <= inp.tolerance * inp.tolerance * change.1;
                if r <= CHORD_DECREASE * res || converged {
                    step = Some(change);
                }
            }
            let (d2, n2) = match step {
                Some(change) => change,
                None => {
                    out.factorisations += 1;
                    if !self.factor_and_solve(size) {
                        break;
                    }
                    self.remember(system, size, inp.active);
                    self.map_solution(system, inp);
                    relative_step(&lam[..m], &self.lam_new[..m])
                }
            };
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
    /// pairs, of slipping ones, and of closed frictionless ones (counted as slipping too).
    fn classify(&mut self, inp: &NewtonInput<'_>, lam: &[f64], y: &[f64]) -> (usize, usize, usize) {
        let (mut closed, mut slipping, mut frictionless) = (0, 0, 0);
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
                    frictionless += 1;
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
        (closed, slipping, frictionless)
    }

    /// Whether the kept factors are of a system with the current pattern.
    fn same_pattern(&self, system: System, size: usize, active: &[usize]) -> bool {
        self.cached == Some((system, size))
            && self.cached_active == active
            && self.cached_keys.len() == active.len()
            && self
                .cached_keys
                .iter()
                .zip(&self.class)
                .all(|(&k, c)| k == c.key())
    }

    fn remember(&mut self, system: System, size: usize, active: &[usize]) {
        self.cached = Some((system, size));
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

    /// The direct system (`q` unknowns: the forces of the closed pairs in their bases) into
    /// `a_cur`, `rhs`, and the unknowns at the current forces `lam` into `x0`.
    fn assemble_direct(&mut self, inp: &NewtonInput<'_>, lam: &[f64], q: usize) {
        let na = inp.active.len();
        let d = 3 * self.n;
        self.unknowns.clear();
        self.offset.clear();
        self.basis.clear();
        let mut o = 0;
        for s in 0..na {
            let b = 3 * s;
            let (width, basis, x0) = match self.class[s] {
                Class::Open => continue,
                Class::Stick => (
                    3,
                    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                    [lam[b], lam[b + 1], lam[b + 2]],
                ),
                Class::Slip { t, .. } if inp.mu_act[s] > 0.0 => {
                    let mu = inp.mu_act[s];
                    (
                        2,
                        [[1.0, mu * t[0], mu * t[1]], [0.0, -t[1], t[0]], [0.0; 3]],
                        [lam[b], -t[1] * lam[b + 1] + t[0] * lam[b + 2], 0.0],
                    )
                }
                Class::Slip { .. } => {
                    (1, [[1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]], [lam[b], 0.0, 0.0])
                }
            };
            self.unknowns.push(s);
            self.offset.push(o);
            self.basis.push(basis);
            self.x0[o..o + width].copy_from_slice(&x0[..width]);
            o += width;
        }
        debug_assert_eq!(o, q);
        self.q_direct = q;
        let c = inp.c_act;
        let w = inp.w;
        for (i, &s) in self.unknowns.iter().enumerate() {
            let p = inp.active[s];
            let oi = self.offset[i];
            let width = unknown_width(&self.offset, i, q);
            for a in 0..width {
                let row = oi + a;
                // The row as a combination `alpha` of the pair's three rows of W, the
                // right-hand side, and an extra term on the pair's own unknown.
                let (alpha, rhs, own) = match self.class[s] {
                    Class::Slip { t, r } if a == 1 => {
                        let re = r * inp.eps[3 * s + 1];
                        let (s0, s1) = (-t[1], t[0]);
                        (
                            [0.0, re * s0, re * s1],
                            -re * (s0 * c[3 * s + 1] + s1 * c[3 * s + 2]),
                            Some(1.0 - r),
                        )
                    }
                    _ => {
                        let mut e = [0.0; 3];
                        e[a] = 1.0;
                        (e, -c[3 * s + a], None)
                    }
                };
                self.rhs[row] = rhs;
                // The row of W combined once over all components (a plain row of W unless
                // this is a slipping pair's `s` row), then read at the unknowns' pairs.
                let src: &[f64] = if own.is_some() {
                    self.row_comb.fill(0.0);
                    for (al, r) in alpha.iter().zip(0..3) {
                        if *al != 0.0 {
                            axpy(
                                *al,
                                &w[(3 * p + r) * d..(3 * p + r + 1) * d],
                                &mut self.row_comb,
                            );
                        }
                    }
                    &self.row_comb
                } else {
                    &w[(3 * p + a) * d..(3 * p + a + 1) * d]
                };
                let out = &mut self.a_cur[row * q..(row + 1) * q];
                for (j, &sj) in self.unknowns.iter().enumerate() {
                    let pj = 3 * inp.active[sj];
                    let v = [src[pj], src[pj + 1], src[pj + 2]];
                    let oj = self.offset[j];
                    // Width 3: a sticking pair (identity basis); 1: frictionless ([1, 0, 0]).
                    match unknown_width(&self.offset, j, q) {
                        3 => out[oj..oj + 3].copy_from_slice(&v),
                        1 => out[oj] = v[0],
                        wj => {
                            for (col, bas) in out[oj..oj + wj].iter_mut().zip(&self.basis[j]) {
                                *col = bas[0] * v[0] + bas[1] * v[1] + bas[2] * v[2];
                            }
                        }
                    }
                }
                if let Some(own) = own {
                    out[oi + 1] += own;
                }
            }
        }
    }

    /// The complement system (unknowns: released gap velocities, all pairs) into `a_cur`,
    /// `rhs`, and the released gap velocities at the current iterate into `x0` (`y` on the
    /// active pairs, `W lambda` on the others, whose `c` the form takes as zero).
    fn assemble_complement(&mut self, inp: &NewtonInput<'_>, y: &[f64]) {
        let n = self.n;
        let d = 3 * n;
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
                self.x0[self.unknowns.len()] = if slot == usize::MAX {
                    self.w_lambda[3 * g + a]
                } else {
                    y[3 * slot + a]
                };
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
                    let krow = &kinv[comp * d..(comp + 1) * d];
                    for (j, &cj) in self.unknowns.iter().enumerate() {
                        self.a_cur[row * k + j] = krow[cj];
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
                            self.a_cur[rr * k + j] = a0 * k1[cj] + a1 * k2[cj] - tn * kn[cj];
                        }
                        self.a_cur[rr * k + row] += re * qm[al][0];
                        self.a_cur[rr * k + row + 1] += re * qm[al][1];
                    }
                    row += 2;
                }
                Class::Stick => unreachable!("stick components are not released"),
            }
        }
    }

    /// The forces `lam_new` and gap velocities `y_new` of the active pairs from the solution
    /// `x` of the system.
    fn map_solution(&mut self, system: System, inp: &NewtonInput<'_>) {
        let m = 3 * inp.active.len();
        match system {
            System::Direct => {
                let q = self.q_direct;
                self.lam_new[..m].fill(0.0);
                for (i, &s) in self.unknowns.iter().enumerate() {
                    let o = self.offset[i];
                    let width = unknown_width(&self.offset, i, q);
                    let mut l = [0.0; 3];
                    for (xj, bas) in self.x[o..o + width].iter().zip(&self.basis[i]) {
                        l[0] += xj * bas[0];
                        l[1] += xj * bas[1];
                        l[2] += xj * bas[2];
                    }
                    self.lam_new[3 * s..3 * s + 3].copy_from_slice(&l);
                }
                gap_velocities(
                    inp,
                    &self.lam_new[..m],
                    &mut self.w_lambda,
                    &mut self.y_new[..m],
                );
            }
            System::Complement => {
                let d = 3 * self.n;
                let k = self.unknowns.len();
                let kinv = &self.k_inv;
                // lambda = lam0 + K P z on the closed active pairs; open ones are exactly
                // zero. gamma = z on the released components, zero on the others.
                for (slot, &g) in inp.active.iter().enumerate() {
                    let b = 3 * slot;
                    if self.class[slot] == Class::Open {
                        self.lam_new[b..b + 3].fill(0.0);
                    } else {
                        for a in 0..3 {
                            let comp = 3 * g + a;
                            let krow = &kinv[comp * d..(comp + 1) * d];
                            let mut v = self.lam0[comp];
                            for (&cj, &z) in self.unknowns.iter().zip(&self.x[..k]) {
                                v += krow[cj] * z;
                            }
                            self.lam_new[b + a] = v;
                        }
                    }
                    for a in 0..3 {
                        let at = self.released_at[3 * g + a];
                        self.y_new[b + a] = if at == usize::MAX { 0.0 } else { self.x[at] };
                    }
                }
            }
        }
    }

    /// LU-factorises the current system (`a_cur`, `size x size`) into `lu` and solves it for
    /// `x`. False if the solution is not finite (singular system).
    fn factor_and_solve(&mut self, size: usize) -> bool {
        if size == 0 {
            return true;
        }
        self.lu[..size * size].copy_from_slice(&self.a_cur[..size * size]);
        let stack = MemStack::new(&mut self.stack);
        let a = MatMut::from_column_major_slice_mut(&mut self.lu[..size * size], size, size);
        lu_factor::lu_in_place(
            a,
            &mut self.perm[..size],
            &mut self.perm_inv[..size],
            Par::Seq,
            stack,
            Default::default(),
        );
        self.x[..size].copy_from_slice(&self.rhs[..size]);
        self.lu_solve(size);
        self.x[..size].iter().all(|v| v.is_finite())
    }

    /// Solves `A x = x` in place with the kept factors (`lu` holds the LU of `A^T`,
    /// column-major, i.e. of `A` row-major: the transposed solve).
    fn lu_solve_in(&mut self, size: usize, which: Buffer) {
        let stack = MemStack::new(&mut self.stack);
        let lu = MatRef::from_column_major_slice(&self.lu[..size * size], size, size);
        let perm = PermRef::new_checked(&self.perm[..size], &self.perm_inv[..size], size);
        let v = match which {
            Buffer::X => &mut self.x[..size],
            Buffer::Defect => &mut self.defect[..size],
        };
        let rhs = MatMut::from_column_major_slice_mut(v, size, 1);
        lu_solve::solve_transpose_in_place(lu, lu, perm, rhs, Par::Seq, stack);
    }

    fn lu_solve(&mut self, size: usize) {
        self.lu_solve_in(size, Buffer::X);
    }

    /// A chord step: the solution `x` of the current system by defect correction from `x0`
    /// with the kept factors (`x <- x + LU^-1 (rhs - A x)`, at most [`CHORD_PASSES`] times,
    /// until the correction is below 1e-3 of the step or at the round-off of `x`). False if
    /// the corrections do not shrink (the kept factors are too far from the current system)
    /// or are not finite.
    fn chord(&mut self, size: usize) -> bool {
        if size == 0 {
            return true;
        }
        self.x[..size].copy_from_slice(&self.x0[..size]);
        let mut last = f64::INFINITY;
        for _ in 0..CHORD_PASSES {
            // defect = rhs - A x
            matvec(
                &self.a_cur[..size * size],
                &self.x[..size],
                &self.zeros[..size],
                &mut self.defect[..size],
            );
            for (dv, &r) in self.defect[..size].iter_mut().zip(&self.rhs[..size]) {
                *dv = r - *dv;
            }
            self.lu_solve_in(size, Buffer::Defect);
            let (mut d2, mut s2, mut x2) = (0.0, 0.0, 0.0);
            for ((xi, &di), &x0i) in self.x[..size]
                .iter_mut()
                .zip(&self.defect[..size])
                .zip(&self.x0[..size])
            {
                *xi += di;
                d2 += di * di;
                s2 += (*xi - x0i) * (*xi - x0i);
                x2 += *xi * *xi;
            }
            if !(d2.is_finite() && s2.is_finite()) {
                return false;
            }
            // A correction at the round-off of x: solved as well as the factors can.
            if d2 <= 1e-28 * x2 {
                break;
            }
            if d2 > 0.25 * last {
                return false;
            }
            last = d2;
            if d2 <= 1e-6 * s2 {
                break;
            }
        }
        true
    }
}

/// Which workspace vector a kept-factor solve works on.
#[derive(Clone, Copy)]
enum Buffer {
    X,
    Defect,
}

/// Unknowns of closed pair `i` of the direct system.
fn unknown_width(offset: &[usize], i: usize, q: usize) -> usize {
    offset.get(i + 1).copied().unwrap_or(q) - offset[i]
}

/// Gap velocities `y = W lambda + c` of the active pairs from the columns of `W` of the
/// nonzero forces (rows, by symmetry), with `W lambda` over all components left in `w_lambda`.
fn gap_velocities(inp: &NewtonInput<'_>, lam: &[f64], w_lambda: &mut [f64], y: &mut [f64]) {
    let d = w_lambda.len();
    w_lambda.fill(0.0);
    for (slot, &p) in inp.active.iter().enumerate() {
        for a in 0..3 {
            let f = lam[3 * slot + a];
            if f != 0.0 {
                axpy(f, &inp.w[(3 * p + a) * d..(3 * p + a + 1) * d], w_lambda);
            }
        }
    }
    for (slot, &p) in inp.active.iter().enumerate() {
        for a in 0..3 {
            y[3 * slot + a] = inp.c_act[3 * slot + a] + w_lambda[3 * p + a];
        }
    }
}

/// `(||lambda_new - lambda||^2, ||lambda_new||^2)`.
fn relative_step(lam: &[f64], lam_new: &[f64]) -> (f64, f64) {
    let (mut d2, mut n2) = (0.0, 0.0);
    for (l, &ln) in lam.iter().zip(lam_new) {
        d2 += (ln - l) * (ln - l);
        n2 += ln * ln;
    }
    (d2, n2)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `W`, `c`, `mu`, `eps` and the active pairs of a test problem.
    type Problem = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<usize>);

    /// A held contact on `n` pairs with an SPD, coupled `W` (3n x 3n) whose even pairs stick
    /// at the solution `lambda* = (1 + k/10, 0, 0)` and odd ones separate (`c = -W lambda*`,
    /// plus an opening velocity on the odd pairs): the direct form (`q = k`). Also the step
    /// sizes of the Gauss-Seidel rule and the active set of all pairs.
    fn sticking(n: usize) -> Problem {
        let d = 3 * n;
        let mut w = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                let dist = (i as f64 - j as f64).abs();
                w[i * d + j] = 0.5 / (1.0 + dist) + if i == j { 1.0 } else { 0.0 };
            }
        }
        let target: Vec<f64> = (0..d)
            .map(|i| {
                if i % 3 == 0 && (i / 3) % 2 == 0 {
                    1.0 + (i / 3) as f64 * 0.1
                } else {
                    0.0
                }
            })
            .collect();
        let c: Vec<f64> = (0..d)
            .map(|i| {
                let open = if i % 3 == 0 && (i / 3) % 2 == 1 {
                    1.0
                } else {
                    0.0
                };
                open - (0..d).map(|j| w[i * d + j] * target[j]).sum::<f64>()
            })
            .collect();
        let mut eps = vec![0.0; d];
        for i in 0..d {
            let b = 3 * (i / 3);
            eps[i] = 1.0
                / w[i * d + b..i * d + b + 3]
                    .iter()
                    .map(|x| x.abs())
                    .sum::<f64>();
        }
        for k in 0..n {
            let t = eps[3 * k + 1].min(eps[3 * k + 2]);
            eps[3 * k + 1] = t;
            eps[3 * k + 2] = t;
        }
        (w, c, vec![0.4; n], eps, (0..n).collect())
    }

    #[test]
    fn stale_kept_factors_are_rejected_and_the_step_redone_fresh() {
        let n = 10;
        let d = 3 * n;
        let (w, c, mu, eps, active) = sticking(n);
        let inp = NewtonInput {
            w: &w,
            active: &active,
            c_act: &c,
            mu_act: &mu,
            eps: &eps,
            tolerance: 1e-12,
            max_iterations: 30,
        };
        let mut newton = Newton::new(n);
        let (mut lam, mut y) = (vec![0.0; d], vec![0.0; d]);
        let first = newton.solve(&inp, &mut lam, &mut y);
        assert!(first.converged && first.factorisations >= 1, "{first:?}");
        let solution = lam.clone();

        // The same problem from a perturbed start: the states repeat, so the kept factors
        // serve as chord steps and no LU is needed.
        let start: Vec<f64> = solution.iter().map(|x| x * 1.01).collect();
        let mut good = newton.clone();
        let mut l = start.clone();
        let o = good.solve(&inp, &mut l, &mut y);
        assert!(o.converged && o.factorisations == 0, "{o:?}");
        for (a, b) in l.iter().zip(&solution) {
            assert!((a - b).abs() <= 1e-10 * b.abs().max(1.0), "{a} vs {b}");
        }

        // Stale factors with the same pattern (the kept LU replaced by the identity): the
        // chord step does not halve the residual, so the safeguard refactorises, and the answer
        // is the same.
        let mut stale = newton.clone();
        let q = match stale.cached {
            Some((System::Direct, q)) => q,
            other => panic!("expected kept direct factors, found {other:?}"),
        };
        assert_eq!(q, 3 * n / 2);
        stale.lu[..q * q].fill(0.0);
        for i in 0..q {
            stale.lu[i * q + i] = 1.0;
            stale.perm[i] = i;
            stale.perm_inv[i] = i;
        }
        let mut l = start;
        let o = stale.solve(&inp, &mut l, &mut y);
        assert!(
            o.converged && o.factorisations >= 1,
            "safeguard not taken: {o:?}"
        );
        for (a, b) in l.iter().zip(&solution) {
            assert!((a - b).abs() <= 1e-10 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn a_slipping_pair_has_two_unknowns_and_frictionless_one() {
        // Two pairs pushed closed and driven sideways: both slip; the direct system has two
        // unknowns per pair with friction and one without.
        let n = 2;
        let d = 3 * n;
        let mut w = vec![0.0; d * d];
        for i in 0..d {
            w[i * d + i] = 1.0;
        }
        w[1] = 0.2;
        w[d] = 0.2;
        let c = vec![-1.0, 5.0, 1.0, -1.0, -3.0, 2.0];
        for (mu, width) in [(0.4, 2), (0.0, 1)] {
            let mu_act = vec![mu; n];
            let eps = vec![1.0; d];
            let active = [0, 1];
            let inp = NewtonInput {
                w: &w,
                active: &active,
                c_act: &c,
                mu_act: &mu_act,
                eps: &eps,
                tolerance: 1e-12,
                max_iterations: 30,
            };
            let mut newton = Newton::new(n);
            let (mut lam, mut y) = (vec![0.0; d], vec![0.0; d]);
            let o = newton.solve(&inp, &mut lam, &mut y);
            assert!(o.converged, "{o:?}");
            assert_eq!(newton.q_direct, width * n, "mu {mu}");
            // On the rim of the friction disk (or without tangential force).
            for k in 0..n {
                let lt = lam[3 * k + 1].hypot(lam[3 * k + 2]);
                assert!(lam[3 * k] > 0.0);
                assert!(
                    (lt - mu * lam[3 * k]).abs() <= 1e-10,
                    "pair {k}: {lt} vs {}",
                    mu * lam[3 * k]
                );
            }
        }
    }
}
