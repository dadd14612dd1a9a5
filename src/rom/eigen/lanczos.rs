//! One block Lanczos run for `S = (K - sigma M)^-1 M` in the M-inner product, with full
//! reorthogonalisation against its basis and a deflation set (pairs already known), kept as a
//! state that can be stepped, inspected (Ritz pairs) and resumed.
//!
//! The basis Q and M Q are both stored, so the reorthogonalisation (classical Gram-Schmidt,
//! twice) needs no sparse product; each step costs one block solve and two block products
//! with M (the Gram matrices of a CholQR2 orthonormalisation).

use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::sparse::SparseColMatRef;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};

use crate::rom::eigen::dense::symmetric_eigen;
use crate::rom::eigen::factor::{Factor, Shifted, SplitMix};
use crate::rom::error::RomError;

/// Ritz values and vectors (in basis coordinates) of the projected matrix, with the Lanczos
/// residual estimates `||S y - theta y||_M`.
pub(crate) struct Ritz {
    pub(crate) theta: Vec<f64>,
    pub(crate) y: Mat<f64>,
    pub(crate) est: Vec<f64>,
}

/// State of a block Lanczos run at one shift.
pub(crate) struct LanczosRun {
    p: usize,
    kmax: usize,
    /// Basis columns the operator has been applied to (a multiple of p).
    k: usize,
    q: Mat<f64>,
    mq: Mat<f64>,
    t: Mat<f64>,
    defl: Mat<f64>,
    mdefl: Mat<f64>,
    /// Residual block factor: the last step's remainder is `Q_next bnext`.
    bnext: Mat<f64>,
    /// Largest |theta| seen (scale for rank decisions).
    scale: f64,
    full: bool,
    /// Basis size at which the next convergence check is due.
    pub(crate) next_check: usize,
}

/// Parallelism of the Lanczos kernels.
///
/// NOTE: a step works on a few columns; thread synchronisation in faer's parallel triangular
/// solves and sparse products cost more than it gained (the reference rig's eigen solve was
/// 1.5x slower with two threads on a loaded 2-core machine), so the run is sequential. The
/// factorisations and the many-column static solves use the global setting.
pub(crate) const LANCZOS_PAR: Par = Par::Seq;

fn mmul(dst: MatMut<'_, f64>, m: SparseColMatRef<'_, usize, f64>, x: MatRef<'_, f64>, par: Par) {
    sparse_dense_matmul(dst, Accum::Replace, m, x, 1.0, par);
}

impl LanczosRun {
    /// Starts a run at the shift of `f`, deflated against the M-orthonormal columns of `defl`,
    /// from `S` applied to a random block. Returns the run and the operator columns used.
    pub(crate) fn start(
        shifted: &Shifted,
        f: &Factor,
        m: SparseColMatRef<'_, usize, f64>,
        defl: Mat<f64>,
        max_basis: usize,
        block: usize,
        rng: &mut SplitMix,
    ) -> (Self, usize) {
        let par = LANCZOS_PAR;
        let n = m.nrows();
        let p = block.min(n).max(1);
        let d = defl.ncols();
        let kmax = (max_basis.min(n.saturating_sub(d)) / p) * p;
        let mut mdefl = Mat::<f64>::zeros(n, d);
        mmul(mdefl.as_mut(), m, defl.as_ref(), par);
        let mut run = LanczosRun {
            p,
            kmax,
            k: 0,
            q: Mat::zeros(n, kmax + p),
            mq: Mat::zeros(n, kmax + p),
            t: Mat::zeros(kmax + p, kmax + p),
            defl,
            mdefl,
            bnext: Mat::zeros(p, p),
            scale: 0.0,
            full: kmax == 0,
            next_check: p,
        };
        if run.full {
            return (run, 0);
        }
        // S applied to random vectors keeps the basis in the range of S (no components with
        // infinite eigenvalues when M is singular).
        let mut w = Mat::<f64>::from_fn(n, p, |_, _| rng.next_f64());
        let mut mw = Mat::<f64>::zeros(n, p);
        mmul(mw.as_mut(), m, w.as_ref(), par);
        w.copy_from(&mw);
        let mut mem = shifted.solve_scratch(p, par);
        shifted.solve(f, w.as_mut(), &mut mem, par);
        run.reorthogonalise(w.as_mut(), 0);
        match run.orthonormalise(m, w, 0, rng) {
            Some((qn, mqn, _)) => {
                run.q.subcols_mut(0, p).copy_from(&qn);
                run.mq.subcols_mut(0, p).copy_from(&mqn);
            }
            None => run.full = true,
        }
        (run, p)
    }

    /// True when the basis cannot grow any more.
    pub(crate) fn is_full(&self) -> bool {
        self.full
    }

    /// Basis size (columns the operator has been applied to).
    pub(crate) fn len(&self) -> usize {
        self.k
    }

    /// Block size.
    pub(crate) fn block(&self) -> usize {
        self.p
    }

    /// One block step; returns the operator columns used.
    pub(crate) fn step(
        &mut self,
        shifted: &Shifted,
        f: &Factor,
        m: SparseColMatRef<'_, usize, f64>,
        rng: &mut SplitMix,
    ) -> usize {
        if self.full {
            return 0;
        }
        let par = LANCZOS_PAR;
        let p = self.p;
        let c0 = self.k;
        // W = S Q_j and A_j = Q_j^T M S Q_j.
        let mut w = self.mq.subcols(c0, p).to_owned();
        let mut mem = shifted.solve_scratch(p, par);
        shifted.solve(f, w.as_mut(), &mut mem, par);
        let mut a = Mat::<f64>::zeros(p, p);
        matmul(
            a.as_mut(),
            Accum::Replace,
            self.mq.subcols(c0, p).transpose(),
            w.as_ref(),
            1.0,
            par,
        );
        for i in 0..p {
            for j in 0..i {
                let s = 0.5 * (a[(i, j)] + a[(j, i)]);
                a[(i, j)] = s;
                a[(j, i)] = s;
            }
            self.scale = self.scale.max(a[(i, i)].abs());
        }
        self.t.submatrix_mut(c0, c0, p, p).copy_from(&a);
        // Three-term recurrence, then full reorthogonalisation.
        matmul(
            w.as_mut(),
            Accum::Add,
            self.q.subcols(c0, p),
            a.as_ref(),
            -1.0,
            par,
        );
        if c0 >= p {
            let b = self.t.submatrix(c0, c0 - p, p, p).to_owned();
            matmul(
                w.as_mut(),
                Accum::Add,
                self.q.subcols(c0 - p, p),
                b.transpose(),
                -1.0,
                par,
            );
        }
        self.reorthogonalise(w.as_mut(), c0 + p);
        self.k = c0 + p;
        if self.k >= self.kmax {
            self.full = true;
            self.bnext = gram_root(m, w.as_ref(), par);
            return p;
        }
        match self.orthonormalise(m, w.clone(), self.k, rng) {
            Some((qn, mqn, b)) => {
                let k = self.k;
                self.q.subcols_mut(k, p).copy_from(&qn);
                self.mq.subcols_mut(k, p).copy_from(&mqn);
                self.t.submatrix_mut(k, c0, p, p).copy_from(&b);
                self.t.submatrix_mut(c0, k, p, p).copy_from(b.transpose());
                self.bnext = b;
            }
            None => {
                // The space is exhausted: the remainder is at roundoff level.
                self.full = true;
                self.bnext = gram_root(m, w.as_ref(), par);
            }
        }
        p
    }

    /// `w <- w - Q (MQ^T w) - D (MD^T w)` twice, with the first `cols` basis columns.
    fn reorthogonalise(&self, mut w: MatMut<'_, f64>, cols: usize) {
        let par = LANCZOS_PAR;
        let p = w.ncols();
        for _ in 0..2 {
            if cols > 0 {
                let mut c = Mat::<f64>::zeros(cols, p);
                matmul(
                    c.as_mut(),
                    Accum::Replace,
                    self.mq.subcols(0, cols).transpose(),
                    w.rb(),
                    1.0,
                    par,
                );
                matmul(
                    w.rb_mut(),
                    Accum::Add,
                    self.q.subcols(0, cols),
                    c.as_ref(),
                    -1.0,
                    par,
                );
            }
            if self.defl.ncols() > 0 {
                let mut c = Mat::<f64>::zeros(self.defl.ncols(), p);
                matmul(
                    c.as_mut(),
                    Accum::Replace,
                    self.mdefl.transpose(),
                    w.rb(),
                    1.0,
                    par,
                );
                matmul(
                    w.rb_mut(),
                    Accum::Add,
                    self.defl.as_ref(),
                    c.as_ref(),
                    -1.0,
                    par,
                );
            }
        }
    }

    /// M-orthonormalises the block `w` (already orthogonal to the basis and the deflation set):
    /// returns (Q, M Q, R) with `W = Q R`, R upper triangular. CholQR2 when the block is well
    /// conditioned, otherwise modified Gram-Schmidt with dependent columns replaced by random
    /// directions (zero rows of R). None when the space is exhausted.
    fn orthonormalise(
        &self,
        m: SparseColMatRef<'_, usize, f64>,
        w: Mat<f64>,
        cols: usize,
        rng: &mut SplitMix,
    ) -> Option<(Mat<f64>, Mat<f64>, Mat<f64>)> {
        let par = LANCZOS_PAR;
        let (n, p) = (w.nrows(), w.ncols());
        let mut mw = Mat::<f64>::zeros(n, p);
        mmul(mw.as_mut(), m, w.as_ref(), par);
        if let Some(l1) = chol_gram(w.as_ref(), mw.as_ref(), self.scale) {
            let w1 = right_solve_lt(w.as_ref(), l1.as_ref());
            let mut mw1 = Mat::<f64>::zeros(n, p);
            mmul(mw1.as_mut(), m, w1.as_ref(), par);
            if let Some(l2) = chol_gram(w1.as_ref(), mw1.as_ref(), 0.0) {
                let qn = right_solve_lt(w1.as_ref(), l2.as_ref());
                let mqn = right_solve_lt(mw1.as_ref(), l2.as_ref());
                // R = L2^T L1^T.
                let mut r = Mat::<f64>::zeros(p, p);
                matmul(
                    r.as_mut(),
                    Accum::Replace,
                    l2.transpose(),
                    l1.transpose(),
                    1.0,
                    par,
                );
                return Some((qn, mqn, r));
            }
        }
        let mut w = w;
        let r = mgs_block(
            m,
            w.as_mut(),
            self.q.subcols(0, cols),
            self.mq.subcols(0, cols),
            self.defl.as_ref(),
            self.mdefl.as_ref(),
            self.scale,
            rng,
        )?;
        let mut mq = Mat::<f64>::zeros(n, p);
        mmul(mq.as_mut(), m, w.as_ref(), par);
        Some((w, mq, r))
    }

    /// Ritz pairs of the current basis with their residual estimates.
    pub(crate) fn ritz(&self) -> Result<Ritz, RomError> {
        let k = self.k;
        let tk = self.t.submatrix(0, 0, k, k).to_owned();
        let (theta, y) = symmetric_eigen(tk.as_ref(), "Lanczos projected matrix")?;
        let p = self.p;
        let est = (0..k)
            .map(|i| {
                let mut e2 = 0.0;
                for r in 0..p {
                    let s: f64 = (0..p).map(|c| self.bnext[(r, c)] * y[(k - p + c, i)]).sum();
                    e2 += s * s;
                }
                e2.sqrt()
            })
            .collect();
        Ok(Ritz { theta, y, est })
    }

    /// Ritz vectors `Q y` and `M Q y` of the columns `sel` of `y`.
    pub(crate) fn vectors(&self, y: MatRef<'_, f64>, sel: &[usize]) -> (Mat<f64>, Mat<f64>) {
        let par = LANCZOS_PAR;
        let k = self.k;
        let n = self.q.nrows();
        let ys = Mat::<f64>::from_fn(k, sel.len(), |r, c| y[(r, sel[c])]);
        let mut v = Mat::<f64>::zeros(n, sel.len());
        let mut mv = Mat::<f64>::zeros(n, sel.len());
        matmul(
            v.as_mut(),
            Accum::Replace,
            self.q.subcols(0, k),
            ys.as_ref(),
            1.0,
            par,
        );
        matmul(
            mv.as_mut(),
            Accum::Replace,
            self.mq.subcols(0, k),
            ys.as_ref(),
            1.0,
            par,
        );
        (v, mv)
    }
}

/// Lower Cholesky factor of the Gram matrix `W^T (M W)` when it is well conditioned (no
/// column below `1e-13 scale` in M-norm, condition below about 1e12); None otherwise.
fn chol_gram(w: MatRef<'_, f64>, mw: MatRef<'_, f64>, scale: f64) -> Option<Mat<f64>> {
    let p = w.ncols();
    let mut g = Mat::<f64>::zeros(p, p);
    matmul(g.as_mut(), Accum::Replace, w.transpose(), mw, 1.0, Par::Seq);
    for i in 0..p {
        for j in 0..i {
            let s = 0.5 * (g[(i, j)] + g[(j, i)]);
            g[(i, j)] = s;
            g[(j, i)] = s;
        }
        if !(g[(i, i)].is_finite() && g[(i, i)].sqrt() > 1e-13 * scale) {
            return None;
        }
    }
    let l = g.llt(Side::Lower).ok()?.L().to_owned();
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for i in 0..p {
        lo = lo.min(l[(i, i)]);
        hi = hi.max(l[(i, i)]);
    }
    // NOTE: CholQR loses orthogonality like cond(W)^2 eps; the second pass repairs it only
    // for cond(W) below about 1e6, beyond that modified Gram-Schmidt takes over.
    (lo > 1e-6 * hi).then_some(l)
}

/// `X L^-T` for lower-triangular `L` (p x p).
fn right_solve_lt(x: MatRef<'_, f64>, l: MatRef<'_, f64>) -> Mat<f64> {
    // (X L^-T)^T = L^-1 X^T.
    let mut xt = x.transpose().to_owned();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, xt.as_mut(), Par::Seq);
    xt.transpose().to_owned()
}

/// M-dot product of two columns given one of them multiplied by M.
fn dot(a: MatRef<'_, f64>, ma: MatRef<'_, f64>) -> f64 {
    (0..a.nrows()).map(|i| a[(i, 0)] * ma[(i, 0)]).sum()
}

/// Modified Gram-Schmidt (twice) in the M-inner product among the columns of `w`; a column
/// that vanishes relative to `scale` is replaced by a random direction orthogonalised against
/// the basis `q` (with `mq = M q`), the deflation set and the previous columns (zero row in R).
/// Returns R, or None when no independent direction is left.
#[allow(clippy::too_many_arguments)]
fn mgs_block(
    m: SparseColMatRef<'_, usize, f64>,
    mut w: MatMut<'_, f64>,
    q: MatRef<'_, f64>,
    mq: MatRef<'_, f64>,
    defl: MatRef<'_, f64>,
    mdefl: MatRef<'_, f64>,
    scale: f64,
    rng: &mut SplitMix,
) -> Option<Mat<f64>> {
    let par = LANCZOS_PAR;
    let (n, p) = (w.nrows(), w.ncols());
    let mut r = Mat::<f64>::zeros(p, p);
    let mut mx = Mat::<f64>::zeros(n, 1);
    for c in 0..p {
        let mut is_random = false;
        let mut tries = 0;
        loop {
            for _ in 0..2 {
                mmul(mx.as_mut(), m, w.rb().subcols(c, 1), par);
                for c2 in 0..c {
                    let h = dot(w.rb().subcols(c2, 1), mx.as_ref());
                    if !is_random {
                        r[(c2, c)] += h;
                    }
                    for i in 0..n {
                        let v = w[(i, c2)];
                        w[(i, c)] -= h * v;
                    }
                }
            }
            mmul(mx.as_mut(), m, w.rb().subcols(c, 1), par);
            let nrm = dot(w.rb().subcols(c, 1), mx.as_ref()).max(0.0).sqrt();
            // NOTE: a column is dependent when its reorthogonalised remainder is at roundoff
            // level relative to the operator norm (the Krylov space became invariant); the run
            // continues in a fresh random direction.
            let threshold = if is_random {
                1e-6
            } else {
                1e-13 * scale.max(f64::MIN_POSITIVE)
            };
            if nrm > threshold && nrm.is_finite() {
                if !is_random {
                    r[(c, c)] = nrm;
                }
                for i in 0..n {
                    w[(i, c)] /= nrm;
                }
                break;
            }
            tries += 1;
            if tries > 3 {
                return None;
            }
            is_random = true;
            let mut x = Mat::<f64>::from_fn(n, 1, |_, _| rng.next_f64());
            for _ in 0..2 {
                for (b, mb) in [(q, mq), (defl, mdefl)] {
                    if b.ncols() == 0 {
                        continue;
                    }
                    let mut coef = Mat::<f64>::zeros(b.ncols(), 1);
                    matmul(
                        coef.as_mut(),
                        Accum::Replace,
                        mb.transpose(),
                        x.as_ref(),
                        1.0,
                        par,
                    );
                    matmul(x.as_mut(), Accum::Add, b, coef.as_ref(), -1.0, par);
                }
            }
            mmul(mx.as_mut(), m, x.as_ref(), par);
            let xn = dot(x.as_ref(), mx.as_ref()).max(0.0).sqrt();
            if xn.is_nan() || xn <= 0.0 {
                return None;
            }
            for i in 0..n {
                w[(i, c)] = x[(i, 0)] / xn;
            }
        }
    }
    Some(r)
}

/// For a remainder block W that is not normalised (basis full), an upper-triangular-like
/// factor `R` with `R^T R = W^T M W`, used only for the residual estimates.
fn gram_root(m: SparseColMatRef<'_, usize, f64>, w: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let (n, p) = (w.nrows(), w.ncols());
    let mut mw = Mat::<f64>::zeros(n, p);
    mmul(mw.as_mut(), m, w, par);
    let mut g = Mat::<f64>::zeros(p, p);
    matmul(
        g.as_mut(),
        Accum::Replace,
        w.transpose(),
        mw.as_ref(),
        1.0,
        par,
    );
    // Eigen-based square root (robust to rank deficiency): R = diag(sqrt(s)) U^T.
    match symmetric_eigen(g.as_ref(), "Lanczos residual block") {
        Ok((s, u)) => Mat::from_fn(p, p, |i, j| s[i].max(0.0).sqrt() * u[(j, i)]),
        Err(_) => Mat::from_fn(p, p, |i, j| if i == j { f64::INFINITY } else { 0.0 }),
    }
}
