//! Dense symmetric eigendecomposition for the small matrices of the ROM build (Lanczos
//! projections, reduced stiffness).
//!
//! NOTE: faer 0.24's `self_adjoint_eigen` switches to divide and conquer above 128 columns,
//! which returned eigenpairs with residuals of 1e-5 relative to the norm on matrices with a
//! wide eigenvalue range (a 900-DOF generalized FE problem reduced to standard form). The
//! tridiagonal QR algorithm, forced here, is accurate on the same matrices.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self, ComputeEigenvectors, SelfAdjointEvdParams};
use faer::{Mat, MatRef, Spec};

use crate::rom::error::RomError;

/// Eigenvalues (ascending) and orthonormal eigenvectors (columns) of the symmetric matrix `a`
/// (its lower triangle is read). `what` names the matrix in errors.
pub fn symmetric_eigen(a: MatRef<'_, f64>, what: &str) -> Result<(Vec<f64>, Mat<f64>), RomError> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(RomError::Dimension {
            what: format!("columns of {what}"),
            expected: n,
            found: a.ncols(),
        });
    }
    let mut params: Spec<SelfAdjointEvdParams, f64> = Default::default();
    params.recursion_threshold = usize::MAX;
    let par = faer::get_global_parallelism();
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let mut u = Mat::<f64>::zeros(n, n);
    let req = evd::self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, par, params);
    let mut mem = MemBuffer::try_new(req).map_err(|_| RomError::Dense {
        what: what.to_string(),
        detail: "out of memory".into(),
    })?;
    evd::self_adjoint_evd(
        a,
        s.as_mut(),
        Some(u.as_mut()),
        par,
        MemStack::new(&mut mem),
        params,
    )
    .map_err(|e| RomError::Dense {
        what: what.to_string(),
        detail: format!("{e:?}"),
    })?;
    let values: Vec<f64> = s.column_vector().iter().copied().collect();
    if values.iter().any(|v| !v.is_finite()) {
        return Err(RomError::NonFinite {
            what: format!("eigenvalues of {what}"),
        });
    }
    Ok((values, u))
}
