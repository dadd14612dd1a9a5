//! Unit tests of the eigen solver against dense reference solves.

use super::*;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Par, Side};

/// A spring lattice on an `nx x ny x nz` node grid (unit spacing), springs along the grid axes
/// acting on all three displacement directions (stiffness `k` per spring and direction), nodes
/// at x = 0 clamped, lumped masses `mass(node)`. Returns (K, M) on the free DOFs.
pub(crate) fn lattice(
    dims: [usize; 3],
    k: f64,
    mass: impl Fn(usize, usize, usize) -> f64,
) -> (SparseColMat<usize, f64>, SparseColMat<usize, f64>) {
    let [nx, ny, nz] = dims;
    let free_index = |i: usize, j: usize, l: usize| -> Option<usize> {
        (i > 0).then(|| (i - 1) + (nx - 1) * (j + ny * l))
    };
    let n = 3 * (nx - 1) * ny * nz;
    let mut kt = Vec::new();
    let mut mt = Vec::new();
    let mut spring = |a: Option<usize>, b: Option<usize>| {
        for d in 0..3 {
            let ia = a.map(|x| 3 * x + d);
            let ib = b.map(|x| 3 * x + d);
            if let Some(ia) = ia {
                kt.push(Triplet::new(ia, ia, k));
            }
            if let Some(ib) = ib {
                kt.push(Triplet::new(ib, ib, k));
            }
            if let (Some(ia), Some(ib)) = (ia, ib) {
                kt.push(Triplet::new(ia, ib, -k));
                kt.push(Triplet::new(ib, ia, -k));
            }
        }
    };
    for l in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if i + 1 < nx {
                    spring(free_index(i, j, l), free_index(i + 1, j, l));
                }
                if j + 1 < ny {
                    spring(free_index(i, j, l), free_index(i, j + 1, l));
                }
                if l + 1 < nz {
                    spring(free_index(i, j, l), free_index(i, j, l + 1));
                }
            }
        }
    }
    for l in 0..nz {
        for j in 0..ny {
            for i in 1..nx {
                let f = free_index(i, j, l).unwrap();
                for d in 0..3 {
                    mt.push(Triplet::new(3 * f + d, 3 * f + d, mass(i, j, l)));
                }
            }
        }
    }
    (
        SparseColMat::try_new_from_triplets(n, n, &kt).unwrap(),
        SparseColMat::try_new_from_triplets(n, n, &mt).unwrap(),
    )
}

/// All eigenvalues of the dense generalized problem, ascending.
pub(crate) fn dense_eigenvalues(
    k: SparseColMatRef<'_, usize, f64>,
    m: SparseColMatRef<'_, usize, f64>,
) -> Vec<f64> {
    let kd = k.to_dense();
    let md = m.to_dense();
    let l = md.llt(Side::Lower).unwrap();
    // C = L^-1 K L^-T
    let lmat = l.L().to_owned();
    let n = kd.nrows();
    let mut x = kd.clone();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(
        lmat.as_ref(),
        x.as_mut(),
        Par::Seq,
    );
    let mut c = x.transpose().to_owned();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(
        lmat.as_ref(),
        c.as_mut(),
        Par::Seq,
    );
    let c = Mat::from_fn(n, n, |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    c.self_adjoint_eigenvalues(Side::Lower).unwrap()
}

fn check(
    k: &SparseColMat<usize, f64>,
    m: &SparseColMat<usize, f64>,
    target: EigenTarget,
    options: EigenOptions,
) -> Modes {
    let reference = dense_eigenvalues(k.as_ref(), m.as_ref());
    let mut solver = EigenSolver::new(k.as_ref(), m.as_ref(), options).unwrap();
    solver.solve(target, &mut |_| {}).unwrap();
    let modes = solver.modes(target);
    let want = match target {
        EigenTarget::Count(c) => c,
        EigenTarget::BelowOmega(w) => reference.partition_point(|&l| l <= w * w),
    };
    assert_eq!(modes.len(), want, "mode count");
    for (i, (&a, &b)) in modes.lambda.iter().zip(&reference).enumerate() {
        assert!((a - b).abs() <= 1e-9 * b, "mode {i}: {a} vs {b}");
    }
    let worst = modes.residuals.iter().copied().fold(0.0, f64::max);
    assert!(worst < 1e-8, "residual {worst:e}");
    eprintln!("stats {:?}", solver.stats());
    modes
}

#[test]
fn chain_matches_dense() {
    let (k, m) = lattice([120, 1, 1], 1e4, |i, _, _| 1.0 + 0.3 * ((i * 7) % 5) as f64);
    check(&k, &m, EigenTarget::Count(25), EigenOptions::default());
}

#[test]
fn repeated_eigenvalues_square_lattice() {
    let (k, m) = lattice([14, 3, 3], 2e3, |_, _, _| 0.5);
    let modes = check(&k, &m, EigenTarget::Count(60), EigenOptions::default());
    eprintln!("{:?}", &modes.lambda[..20]);
}

#[test]
fn below_target_and_resume() {
    let (k, m) = lattice([30, 2, 3], 1e3, |i, j, _| 1.0 + 0.1 * (i + j) as f64);
    let reference = dense_eigenvalues(k.as_ref(), m.as_ref());
    let mut solver = EigenSolver::new(
        k.as_ref(),
        m.as_ref(),
        EigenOptions {
            max_basis: 40,
            ..Default::default()
        },
    )
    .unwrap();
    solver.solve(EigenTarget::Count(5), &mut |_| {}).unwrap();
    // A cutoff in a gap of the spectrum after about 70 modes.
    let j = (70..reference.len())
        .find(|&j| reference[j] - reference[j - 1] > 1e-6 * reference[j])
        .unwrap();
    let cut = (reference[j - 1] + reference[j]) * 0.5;
    solver
        .solve(EigenTarget::BelowOmega(cut.sqrt()), &mut |_| {})
        .unwrap();
    let modes = solver.modes(EigenTarget::BelowOmega(cut.sqrt()));
    assert_eq!(modes.len(), j);
    for (i, (&a, &b)) in modes.lambda.iter().zip(&reference).enumerate() {
        assert!((a - b).abs() <= 1e-9 * b, "mode {i}: {a} vs {b}");
    }
    eprintln!("stats {:?}", solver.stats());
}

#[test]
fn unclamped_stiffness_is_rejected() {
    // A free spring chain: a rigid-body mode, K singular.
    let n = 40;
    let mut kt = Vec::new();
    for i in 0..n - 1 {
        kt.push(Triplet::new(i, i, 1e6));
        kt.push(Triplet::new(i + 1, i + 1, 1e6));
        kt.push(Triplet::new(i, i + 1, -1e6));
        kt.push(Triplet::new(i + 1, i, -1e6));
    }
    let mt: Vec<_> = (0..n).map(|i| Triplet::new(i, i, 1.0)).collect();
    let k = SparseColMat::try_new_from_triplets(n, n, &kt).unwrap();
    let m = SparseColMat::try_new_from_triplets(n, n, &mt).unwrap();
    let err = EigenSolver::new(k.as_ref(), m.as_ref(), EigenOptions::default())
        .err()
        .expect("singular K is rejected");
    assert!(
        matches!(err, RomError::StiffnessNotPositiveDefinite { .. }),
        "{err}"
    );
    // Indefinite K: a negative spring to ground.
    let mut kt2 = kt.clone();
    kt2.push(Triplet::new(0, 0, -5e5));
    let k2 = SparseColMat::try_new_from_triplets(n, n, &kt2).unwrap();
    let err = EigenSolver::new(k2.as_ref(), m.as_ref(), EigenOptions::default())
        .err()
        .expect("indefinite K is rejected");
    assert!(
        matches!(
            err,
            RomError::StiffnessNotPositiveDefinite { negative: 1, .. }
        ),
        "{err}"
    );
}
