//! Sparse LDL^T factorisations of `K - sigma M` on the union pattern of K and M: one symbolic
//! analysis (AMD ordering) shared by all shifts, numeric factorisations with their inertia
//! (Sylvester's law: the number of negative pivots of D is the number of eigenvalues below
//! sigma), and solves.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, supernodal::SupernodalLdltRef, LdltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};

use crate::rom::error::RomError;

/// A numeric LDL^T factorisation of `K - sigma M` with its inertia.
pub(crate) struct Factor {
    pub(crate) sigma: f64,
    values: Vec<f64>,
    pub(crate) negative: usize,
    /// Smallest over largest pivot magnitude.
    pub(crate) pivot_ratio: f64,
}

/// The union pattern of K and M (lower triangle), the value maps and the symbolic analysis,
/// shared by all shifts.
pub(crate) struct Shifted {
    a: SparseColMat<usize, f64>,
    k_pos: Vec<usize>,
    m_pos: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
}

const ABSENT: usize = usize::MAX;

impl Shifted {
    pub(crate) fn new(
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
    pub(crate) fn factor(&mut self, k: &[f64], m: &[f64], sigma: f64) -> Result<Factor, RomError> {
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
        let (mut min_abs, mut max_abs) = (f64::INFINITY, 0.0f64);
        let mut count = |d: f64| {
            min_abs = min_abs.min(d.abs());
            max_abs = max_abs.max(d.abs());
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
            pivot_ratio: min_abs / max_abs,
        })
    }

    pub(crate) fn solve_scratch(&self, ncols: usize, par: Par) -> MemBuffer {
        MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, par))
    }

    /// `rhs <- (K - sigma M)^-1 rhs`.
    pub(crate) fn solve(&self, f: &Factor, rhs: MatMut<'_, f64>, mem: &mut MemBuffer, par: Par) {
        LdltRef::new(&self.symbolic, &f.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            par,
            MemStack::new(mem),
        );
    }
}

pub(crate) fn shift_hz(sigma: f64) -> f64 {
    sigma.signum() * sigma.abs().sqrt() / (2.0 * std::f64::consts::PI)
}

/// Deterministic pseudo-random numbers for start blocks (SplitMix64).
#[derive(Clone, Debug)]
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    pub(crate) fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        // Uniform in [-1, 1).
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}
