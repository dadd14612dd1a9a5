//! Helpers shared by the FE integration tests: a small, robust solver for the lowest modes
//! of `K x = lambda M x` (subspace iteration on a sparse Cholesky factor of K), independent
//! of the project's own eigen solver so that the element tests do not depend on it, and
//! builders for box-shaped cantilever meshes.

#![allow(dead_code)]

use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::prelude::*;
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, Side};
use rigtwin::fe::grid::BoxGrid;
use rigtwin::fe::{ElementBlock, ElementKind, FeModel, HexElement, Material, Mesh};

/// One mode: frequency (Hz) and the mode shape on the free DOFs (M-normalised).
pub struct Mode {
    pub freq: f64,
    pub shape: Vec<f64>,
}

/// The `n` lowest modes of (K, M), K positive definite, by subspace iteration with
/// `n + 8` vectors until the `n` lowest eigenvalues change by less than 1e-12 (relative).
pub fn lowest_modes(model: &FeModel, n: usize) -> Vec<Mode> {
    let dim = model.n_dof();
    let p = (n + 8).min(dim);
    let llt = model
        .k
        .sp_cholesky(Side::Lower)
        .expect("K positive definite");
    // Deterministic, non-degenerate start vectors.
    let mut x = Mat::from_fn(dim, p, |i, j| {
        let s = ((i * 7919 + j * 104_729) % 1009) as f64 / 1009.0;
        s - 0.5 + if i % p == j { 1.0 } else { 0.0 }
    });
    let mut prev = vec![0.0; n];
    let mut y = Mat::<f64>::zeros(dim, p);
    for iter in 0..300 {
        sparse_dense_matmul(
            y.as_mut(),
            Accum::Replace,
            model.m.as_ref(),
            x.as_ref(),
            1.0,
            Par::Seq,
        );
        let mut z = y.clone();
        llt.solve_in_place(z.as_mut());
        // Rayleigh-Ritz on span(Z): Kr = Z^T K Z = Z^T (M X), Mr = Z^T M Z.
        let kr = z.transpose() * &y;
        let mut mz = Mat::<f64>::zeros(dim, p);
        sparse_dense_matmul(
            mz.as_mut(),
            Accum::Replace,
            model.m.as_ref(),
            z.as_ref(),
            1.0,
            Par::Seq,
        );
        let mr = z.transpose() * &mz;
        let mr = Mat::from_fn(p, p, |i, j| 0.5 * (mr[(i, j)] + mr[(j, i)]));
        let l_fac = mr.llt(Side::Lower).expect("Mr positive definite");
        let l = l_fac.L();
        // C = L^-1 Kr L^-T.
        let mut c = Mat::from_fn(p, p, |i, j| 0.5 * (kr[(i, j)] + kr[(j, i)]));
        solve_lower_triangular_in_place(l, c.as_mut(), Par::Seq);
        let mut c = c.transpose().to_owned();
        solve_lower_triangular_in_place(l, c.as_mut(), Par::Seq);
        let eig = c
            .self_adjoint_eigen(Side::Lower)
            .expect("small eigenproblem");
        let mut q = eig.U().to_owned();
        solve_upper_triangular_in_place(l.transpose(), q.as_mut(), Par::Seq);
        x = &z * &q;
        let lambdas: Vec<f64> = (0..n).map(|i| eig.S()[i]).collect();
        let converged = lambdas
            .iter()
            .zip(&prev)
            .all(|(a, b)| ((a - b) / a).abs() < 1e-12);
        prev = lambdas;
        if converged && iter > 2 {
            break;
        }
    }
    (0..n)
        .map(|j| Mode {
            freq: prev[j].sqrt() / (2.0 * std::f64::consts::PI),
            shape: (0..dim).map(|i| x[(i, j)]).collect(),
        })
        .collect()
}

/// Effective-mass fractions of a mode along x, y, z: `(r_d^T M phi)^2 / (phi^T M phi)`
/// divided by the model mass along d, with r_d the unit translation along d.
pub fn effective_mass_fractions(model: &FeModel, shape: &[f64]) -> [f64; 3] {
    let dim = model.n_dof();
    let phi = Mat::from_fn(dim, 1, |i, _| shape[i]);
    let mut mphi = Mat::<f64>::zeros(dim, 1);
    sparse_dense_matmul(
        mphi.as_mut(),
        Accum::Replace,
        model.m.as_ref(),
        phi.as_ref(),
        1.0,
        Par::Seq,
    );
    let modal_mass: f64 = (0..dim).map(|i| shape[i] * mphi[(i, 0)]).sum();
    std::array::from_fn(|d| {
        let r = Mat::from_fn(dim, 1, |i, _| {
            if model.dofs[i].dir as usize == d {
                1.0
            } else {
                0.0
            }
        });
        let mut mr = Mat::<f64>::zeros(dim, 1);
        sparse_dense_matmul(
            mr.as_mut(),
            Accum::Replace,
            model.m.as_ref(),
            r.as_ref(),
            1.0,
            Par::Seq,
        );
        let total: f64 = (0..dim).map(|i| r[(i, 0)] * mr[(i, 0)]).sum();
        let gamma: f64 = (0..dim).map(|i| r[(i, 0)] * mphi[(i, 0)]).sum();
        gamma * gamma / modal_mass / total
    })
}

/// A box cantilever along x on the grid lines `xs`, `ys`, `zs`, one block of `kind`, all
/// nodes at x = xs[0] fixed.
pub fn box_cantilever(
    xs: &[f64],
    ys: &[f64],
    zs: &[f64],
    kind: ElementKind,
    material: Material,
    map: impl Fn([f64; 3]) -> [f64; 3],
) -> Mesh {
    let grid = BoxGrid::new(xs, ys, zs, map);
    let x0 = xs[0];
    let fixed_nodes = (0..grid.nodes.len())
        .filter(|&n| {
            let i = n % grid.dims[0];
            i == 0 && xs[i] == x0
        })
        .collect();
    Mesh {
        elements: grid
            .cells
            .iter()
            .map(|&nodes| HexElement { nodes, block: 0 })
            .collect(),
        nodes: grid.nodes,
        blocks: vec![ElementBlock {
            name: "beam".into(),
            material: 0,
            kind,
        }],
        materials: vec![material],
        fixed_nodes,
        ..Mesh::default()
    }
}

/// `n + 1` equally spaced points from `a` to `b`.
pub fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..=n).map(|i| a + (b - a) * i as f64 / n as f64).collect()
}
