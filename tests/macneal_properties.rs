//! Guards the MacNeal reduction and its eigen solver on small solid-hex models built here
//! (two clamped hex8 cantilevers with conforming contact pairs between their tips, and a
//! square-section cantilever with repeated eigenvalues), against dense reference solutions:
//! - static boundary flexibility of the ROM equals the FE model's (random boundary loads);
//! - with the boundary free, the ROM's frequencies equal the FE model's lowest ones;
//! - reduction basis: retained modes M-orthonormal, residual attachment modes M-orthogonal to
//!   them, reduced stiffness in the DESIGN.md stiffness form; the neglected residual mass is
//!   reported;
//! - sensor rows and base participation factors reproduce the FE static response;
//! - the Lanczos solver finds exactly the dense eigenvalues, repeated ones included;
//! - labels, reference mode and stability limits are consistent.

// Element and matrix code below indexes by (row, column) on purpose.
#![allow(clippy::needless_range_loop)]

use faer::linalg::matmul::matmul;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Accum, Mat, MatRef, Par, Side};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rigtwin::fe::grid::BoxGrid;
use rigtwin::fe::hex8::shape_derivatives;
use rigtwin::fe::hex8::shape_functions;
use rigtwin::fe::{DofGroup, DofInfo, FeModel, OutputDofs, PairDofs};
use rigtwin::rom::eigen::{symmetric_eigen, EigenOptions, EigenSolver, EigenTarget};
use rigtwin::rom::macneal::{apply_b, b_transpose, reduce};
use rigtwin::rom::stability::{closed_limit, steps_per_period};
use rigtwin::rom::{ModeSelection, Rom, RomError};

const E: f64 = 210e9;
const NU: f64 = 0.3;
const RHO: f64 = 7850.0;

/// Stiffness and consistent mass of a trilinear hex (2x2x2 Gauss), DOFs node-major (x, y, z).
fn hex8(x: &[[f64; 3]; 8]) -> ([[f64; 24]; 24], [[f64; 24]; 24]) {
    let lam = E * NU / ((1.0 + NU) * (1.0 - 2.0 * NU));
    let mu = E / (2.0 * (1.0 + NU));
    let g = 1.0 / 3f64.sqrt();
    let mut ke = [[0.0; 24]; 24];
    let mut me = [[0.0; 24]; 24];
    for &xi in &[-g, g] {
        for &eta in &[-g, g] {
            for &zeta in &[-g, g] {
                let dn = shape_derivatives(xi, eta, zeta);
                let nf = shape_functions(xi, eta, zeta);
                let mut j = [[0.0; 3]; 3];
                for a in 0..8 {
                    for r in 0..3 {
                        for c in 0..3 {
                            j[r][c] += dn[a][r] * x[a][c];
                        }
                    }
                }
                let det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1])
                    - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
                    + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
                let inv = |r: usize, c: usize| {
                    let (r1, r2) = ((c + 1) % 3, (c + 2) % 3);
                    let (c1, c2) = ((r + 1) % 3, (r + 2) % 3);
                    (j[r1][c1] * j[r2][c2] - j[r1][c2] * j[r2][c1]) / det
                };
                // dN/dx_c = sum_r invJ[c][r] dN/dxi_r
                let mut d = [[0.0; 3]; 8];
                for a in 0..8 {
                    for c in 0..3 {
                        d[a][c] = (0..3).map(|r| inv(c, r) * dn[a][r]).sum();
                    }
                }
                let mut b = [[0.0; 24]; 6];
                for a in 0..8 {
                    let [dx, dy, dz] = d[a];
                    b[0][3 * a] = dx;
                    b[1][3 * a + 1] = dy;
                    b[2][3 * a + 2] = dz;
                    b[3][3 * a] = dy;
                    b[3][3 * a + 1] = dx;
                    b[4][3 * a + 1] = dz;
                    b[4][3 * a + 2] = dy;
                    b[5][3 * a] = dz;
                    b[5][3 * a + 2] = dx;
                }
                let mut dmat = [[0.0; 6]; 6];
                for r in 0..3 {
                    for c in 0..3 {
                        dmat[r][c] = lam;
                    }
                    dmat[r][r] += 2.0 * mu;
                    dmat[r + 3][r + 3] = mu;
                }
                for p in 0..24 {
                    let mut db = [0.0; 6];
                    for r in 0..6 {
                        db[r] = (0..6).map(|s| dmat[r][s] * b[s][p]).sum();
                    }
                    for q in 0..24 {
                        ke[q][p] += (0..6).map(|r| b[r][q] * db[r]).sum::<f64>() * det;
                    }
                }
                for a in 0..8 {
                    for bb in 0..8 {
                        for c in 0..3 {
                            me[3 * a + c][3 * bb + c] += RHO * nf[a] * nf[bb] * det;
                        }
                    }
                }
            }
        }
    }
    (ke, me)
}

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..=n).map(|i| a + (b - a) * i as f64 / n as f64).collect()
}

/// A beam: (grid, group).
struct Part {
    grid: BoxGrid,
    group: DofGroup,
}

/// Assembles parts (disjoint node sets) clamped at x = 0 into an FE model without pairs.
fn assemble(parts: &[Part]) -> (FeModel, Vec<usize>) {
    let mut coords = Vec::new();
    let mut groups = Vec::new();
    let mut offsets = Vec::new();
    for p in parts {
        offsets.push(coords.len());
        coords.extend_from_slice(&p.grid.nodes);
        groups.extend(std::iter::repeat_n(p.group, p.grid.nodes.len()));
    }
    let mut free = vec![usize::MAX; 3 * coords.len()];
    let mut dofs = Vec::new();
    for (node, c) in coords.iter().enumerate() {
        if c[0].abs() < 1e-12 {
            continue;
        }
        for dir in 0..3u8 {
            free[3 * node + dir as usize] = dofs.len();
            dofs.push(DofInfo {
                node,
                dir,
                group: groups[node],
            });
        }
    }
    let (mut kt, mut mt) = (Vec::new(), Vec::new());
    let mut n_elements = 0;
    for (p, &off) in parts.iter().zip(&offsets) {
        for cell in &p.grid.cells {
            n_elements += 1;
            let x = cell.map(|n| coords[n + off]);
            let (ke, me) = hex8(&x);
            for a in 0..24 {
                let ga = free[3 * (cell[a / 3] + off) + a % 3];
                if ga == usize::MAX {
                    continue;
                }
                for b in 0..24 {
                    let gb = free[3 * (cell[b / 3] + off) + b % 3];
                    if gb == usize::MAX {
                        continue;
                    }
                    kt.push(Triplet::new(ga, gb, ke[a][b]));
                    mt.push(Triplet::new(ga, gb, me[a][b]));
                }
            }
        }
    }
    let n = dofs.len();
    let base = dofs
        .iter()
        .map(|d| if d.dir == 2 { 1.0 } else { 0.0 })
        .collect();
    let model = FeModel {
        k: SparseColMat::try_new_from_triplets(n, n, &kt).unwrap(),
        m: SparseColMat::try_new_from_triplets(n, n, &mt).unwrap(),
        dofs,
        base,
        pairs: Vec::new(),
        clearance: 0.0,
        outputs: Vec::new(),
        node_coords: coords,
        n_elements,
    };
    (model, free)
}

/// Two cantilevers along x (length 0.3 m, width 0.02 m), the lower 4 mm thick, the upper
/// 4.4 mm thick above it across a 1 mm clearance, with conforming pairs between the lower top
/// face and the upper bottom face on the last two x-stations.
fn two_cantilevers() -> FeModel {
    two_cantilevers_sized(16, 2, 2, 2)
}

/// [`two_cantilevers`] with `nx x ny x nz` cells per beam and pairs on the last
/// `pair_stations` x-stations.
fn two_cantilevers_sized(nx: usize, ny: usize, nz: usize, pair_stations: usize) -> FeModel {
    let (l, w, t_l, t_u, c) = (0.3, 0.02, 0.004, 0.0044, 0.001);
    let lower = BoxGrid::new(
        &linspace(0.0, l, nx),
        &linspace(0.0, w, ny),
        &linspace(0.0, t_l, nz),
        |p| p,
    );
    let z0 = t_l + c;
    let upper = BoxGrid::new(
        &linspace(0.0, l, nx),
        &linspace(0.0, w, ny),
        &linspace(z0, z0 + t_u, nz),
        |p| p,
    );
    let n_lower = lower.nodes.len();
    let parts = [
        Part {
            grid: lower,
            group: DofGroup::Lower,
        },
        Part {
            grid: upper,
            group: DofGroup::Upper,
        },
    ];
    let (mut model, free) = assemble(&parts);
    let dof3 = |node: usize| [0, 1, 2].map(|d| free[3 * node + d]);
    let (lg, ug) = (&parts[0].grid, &parts[1].grid);
    for i in nx + 1 - pair_stations..=nx {
        for j in 0..=ny {
            let lo = lg.node(i, j, nz);
            let up = ug.node(i, j, 0) + n_lower;
            model.pairs.push(PairDofs {
                lower: dof3(lo),
                upper: dof3(up),
                frame: [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                area: (l / nx as f64) * (w / ny as f64),
                position: model.node_coords[lo],
            });
        }
    }
    model.clearance = c;
    for (name, node) in [
        ("lower_tip", lg.node(nx, ny / 2, nz)),
        ("upper_tip", ug.node(nx, ny / 2, nz) + n_lower),
    ] {
        model.outputs.push(OutputDofs {
            name: name.into(),
            terms: vec![(free[3 * node + 2], 1.0)],
        });
    }
    model
}

fn dense(a: &SparseColMat<usize, f64>) -> Mat<f64> {
    a.to_dense()
}

/// All eigenvalues (ascending) and M-orthonormal eigenvectors of the dense generalized
/// problem, from the inverse form `L^-1 M L^-T u = (1 / lambda) u` with `K = L L^T`: accurate
/// for the lowest modes (the standard form `L_M^-1 K L_M^-T` loses eps lambda_max / lambda).
fn dense_eigen(model: &FeModel) -> (Vec<f64>, Mat<f64>) {
    let (k, m) = (dense(&model.k), dense(&model.m));
    let n = k.nrows();
    let l = k.llt(Side::Lower).unwrap().L().to_owned();
    let mut x = m.clone();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(
        l.as_ref(),
        x.as_mut(),
        Par::Seq,
    );
    let mut c = x.transpose().to_owned();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(
        l.as_ref(),
        c.as_mut(),
        Par::Seq,
    );
    let c = Mat::from_fn(n, n, |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    let (mu, mut v) = symmetric_eigen(c.as_ref(), "reference").unwrap();
    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
        l.transpose(),
        v.as_mut(),
        Par::Seq,
    );
    // Descending mu = ascending lambda; v^T M v = mu.
    let order: Vec<usize> = (0..n).rev().collect();
    let lambda = order.iter().map(|&j| 1.0 / mu[j]).collect();
    let vecs = Mat::from_fn(n, n, |i, c| v[(i, order[c])] / mu[order[c]].sqrt());
    (lambda, vecs)
}

/// Dense K^-1 X (independent of the library's sparse factorisation).
fn dense_solve(model: &FeModel, x: MatRef<'_, f64>) -> Mat<f64> {
    use faer::linalg::solvers::Solve;
    let llt = dense(&model.k).llt(Side::Lower).unwrap();
    let mut out = x.to_owned();
    llt.solve_in_place(out.as_mut());
    out
}

fn max_abs(a: MatRef<'_, f64>) -> f64 {
    a.col_iter()
        .flat_map(|c| c.iter().map(|v| v.abs()).collect::<Vec<_>>())
        .fold(0.0, f64::max)
}

fn mul(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a, b, 1.0, Par::Seq);
    out
}

fn build(count: usize) -> (FeModel, Rom) {
    let model = two_cantilevers();
    let rom = reduce(&model, ModeSelection::Count { count }, &mut |_| {}).unwrap();
    (model, rom)
}

/// The retained modes as the ROM sees them, recomputed densely (sign-independent quantities
/// only are compared).
fn modal_matrix(model: &FeModel, m: usize) -> Mat<f64> {
    let mut solver =
        EigenSolver::new(model.k.as_ref(), model.m.as_ref(), EigenOptions::default()).unwrap();
    solver.solve(EigenTarget::Count(m), &mut |_| {}).unwrap();
    solver.modes(EigenTarget::Count(m)).vectors
}

#[test]
fn static_boundary_flexibility_is_exact() {
    let (model, rom) = build(20);
    assert!(
        rom.meta.static_flexibility_error < 1e-8,
        "{:e}",
        rom.meta.static_flexibility_error
    );
    let c3 = 3 * model.pairs.len();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let loads = Mat::<f64>::from_fn(c3, 5, |_, _| rng.gen_range(-1.0..1.0));
    // Full FE: g = B K^-1 B^T lambda (dense, independent solve).
    let bt = b_transpose(&model);
    let u = dense_solve(&model, mul(bt.as_ref(), loads.as_ref()).as_ref());
    let g_fe = apply_b(&model, u.as_ref());
    // ROM static: eta = Omega^-2 Phi_g^T lambda, g = Phi_g eta + G_res lambda.
    let mut eta = mul(rom.phi_g.transpose(), loads.as_ref());
    for j in 0..eta.ncols() {
        for i in 0..eta.nrows() {
            eta[(i, j)] /= rom.omega[i] * rom.omega[i];
        }
    }
    let mut g_rom = mul(rom.phi_g.as_ref(), eta.as_ref());
    matmul(
        g_rom.as_mut(),
        Accum::Add,
        rom.g_res.as_ref(),
        loads.as_ref(),
        1.0,
        Par::Seq,
    );
    for j in 0..5 {
        let num: f64 = (0..c3)
            .map(|i| (g_rom[(i, j)] - g_fe[(i, j)]).powi(2))
            .sum();
        let den: f64 = (0..c3).map(|i| g_fe[(i, j)].powi(2)).sum();
        let rel = (num / den).sqrt();
        assert!(rel < 1e-8, "load {j}: relative error {rel:e}");
    }
    // Sensor rows: y = c_eta eta + c_lambda lambda equals the FE static output.
    for o in &rom.outputs {
        let terms = &model
            .outputs
            .iter()
            .find(|x| x.name == o.name)
            .unwrap()
            .terms;
        for j in 0..5 {
            let y_fe: f64 = terms.iter().map(|&(d, w)| w * u[(d, j)]).sum();
            let y_rom: f64 = (0..rom.n_modes())
                .map(|i| o.c_eta[i] * eta[(i, j)])
                .sum::<f64>()
                + (0..c3).map(|r| o.c_lambda[r] * loads[(r, j)]).sum::<f64>();
            assert!(
                (y_rom - y_fe).abs() < 1e-8 * y_fe.abs().max(1e-12),
                "{}: {y_rom} vs {y_fe}",
                o.name
            );
        }
    }
}

#[test]
fn free_boundary_frequencies_match_fe() {
    let (model, rom) = build(24);
    let m = rom.n_modes();
    let c3 = 3 * model.pairs.len();
    // Stiffness form [K_gg, K_g_eta; K_eta_g, K_eta_eta], mass diag(0, I); condense g out.
    let k_ge = {
        let mut a = mul(rom.k_gg.as_ref(), rom.phi_g.as_ref());
        a.col_iter_mut()
            .for_each(|c| c.iter_mut().for_each(|v| *v = -*v));
        a
    };
    let mut k_ee = mul(
        rom.phi_g.transpose(),
        mul(rom.k_gg.as_ref(), rom.phi_g.as_ref()).as_ref(),
    );
    for i in 0..m {
        k_ee[(i, i)] += rom.omega[i] * rom.omega[i];
    }
    use faer::linalg::solvers::Solve;
    let llt = rom.k_gg.llt(Side::Lower).unwrap();
    let mut x = k_ge.clone();
    llt.solve_in_place(x.as_mut());
    let corr = mul(k_ge.transpose(), x.as_ref());
    let cond = Mat::<f64>::from_fn(m, m, |i, j| {
        let v = k_ee[(i, j)] - corr[(i, j)];
        let w = k_ee[(j, i)] - corr[(j, i)];
        0.5 * (v + w)
    });
    let ev = cond.self_adjoint_eigenvalues(Side::Lower).unwrap();
    let (reference, _) = dense_eigen(&model);
    for i in 0..m {
        let rel = (ev[i] - reference[i]).abs() / reference[i];
        assert!(
            rel < 1e-8,
            "mode {i}: {} vs {} ({rel:e})",
            ev[i],
            reference[i]
        );
    }
    assert_eq!(c3, rom.g_res.nrows());
}

#[test]
fn reduction_basis_massless_boundary() {
    let (model, rom) = build(20);
    let m = rom.n_modes();
    let phi = modal_matrix(&model, m);
    // Psi_res = (K^-1 - Phi Omega^-2 Phi^T) B^T; basis for (h, eta), h = g - Phi_g eta.
    let bt = b_transpose(&model);
    let mut psi = dense_solve(&model, bt.as_ref());
    let phi_g = apply_b(&model, phi.as_ref());
    let scaled = Mat::<f64>::from_fn(phi_g.nrows(), m, |i, j| {
        phi_g[(i, j)] / rom.omega[j].powi(2)
    });
    matmul(
        psi.as_mut(),
        Accum::Add,
        phi.as_ref(),
        scaled.transpose(),
        -1.0,
        Par::Seq,
    );
    let att = mul(psi.as_ref(), rom.k_gg.as_ref());
    let c3 = att.ncols();
    let n = model.n_dof();
    let r = Mat::<f64>::from_fn(n, c3 + m, |i, j| {
        if j < c3 {
            att[(i, j)]
        } else {
            phi[(i, j - c3)]
        }
    });
    let md = dense(&model.m);
    let kd = dense(&model.k);
    let mr = mul(r.transpose(), mul(md.as_ref(), r.as_ref()).as_ref());
    let kr = mul(r.transpose(), mul(kd.as_ref(), r.as_ref()).as_ref());
    // eta-eta block of the mass: identity.
    let ee = Mat::<f64>::from_fn(m, m, |i, j| {
        mr[(c3 + i, c3 + j)] - if i == j { 1.0 } else { 0.0 }
    });
    assert!(
        max_abs(ee.as_ref()) < 1e-10,
        "eta-eta mass block deviates by {:e}",
        max_abs(ee.as_ref())
    );
    // Coupling of residual attachment modes and retained modes: M-orthogonal. Phi^T M Psi_res
    // is the difference of Phi^T M K^-1 B^T and Omega^-2 Phi_g^T; it must vanish relative to
    // them. (As cosines between the vectors it is larger: Psi_res is 1e3 times smaller than
    // K^-1 B^T here and both carry the ~1e-9 relative solve accuracy of this stiff mesh.)
    let hh = Mat::<f64>::from_fn(c3, c3, |i, j| mr[(i, j)]);
    let x = dense_solve(&model, bt.as_ref());
    let pmx = mul(phi.transpose(), mul(md.as_ref(), x.as_ref()).as_ref());
    let pmpsi = mul(phi.transpose(), mul(md.as_ref(), psi.as_ref()).as_ref());
    let rel = max_abs(pmpsi.as_ref()) / max_abs(pmx.as_ref());
    assert!(rel < 1e-8, "attachment/mode mass coupling {rel:e}");
    let cosine = (0..c3)
        .flat_map(|i| (0..m).map(move |j| (i, j)))
        .map(|(i, j)| mr[(i, c3 + j)].abs() / mr[(i, i)].sqrt())
        .fold(0.0, f64::max);
    eprintln!(
        "Phi^T M Psi_res relative to Phi^T M K^-1 B^T: {rel:.2e}; largest cosine {cosine:.2e}"
    );
    // Stiffness: diag(K_gg, Omega^2) in (h, eta), i.e. the DESIGN stiffness form in (g, eta).
    let kgg_dev = Mat::<f64>::from_fn(c3, c3, |i, j| kr[(i, j)] - rom.k_gg[(i, j)]);
    assert!(max_abs(kgg_dev.as_ref()) < 1e-8 * max_abs(rom.k_gg.as_ref()));
    let ke = Mat::<f64>::from_fn(c3, m, |i, j| kr[(i, c3 + j)]);
    assert!(max_abs(ke.as_ref()) < 1e-8 * max_abs(rom.k_gg.as_ref()).sqrt() * rom.omega[m - 1]);
    // phi^T K phi carries roundoff of about eps lambda_max / lambda (1e-8 for the lowest
    // mode of this mesh).
    for i in 0..m {
        let rel = (kr[(c3 + i, c3 + i)] / rom.omega[i].powi(2) - 1.0).abs();
        assert!(rel < 5e-8, "mode {i}: phi^T K phi / Omega^2 - 1 = {rel:e}");
    }
    // The neglected residual mass (MacNeal's massless boundary).
    let ev = hh.self_adjoint_eigenvalues(Side::Lower).unwrap();
    let total_mass: f64 = {
        let b = Mat::<f64>::from_fn(n, 1, |i, _| model.base[i]);
        mul(b.transpose(), mul(md.as_ref(), b.as_ref()).as_ref())[(0, 0)]
    };
    eprintln!(
        "neglected residual mass: largest {:.3e} kg, trace {:.3e} kg; model mass {:.3e} kg \
         (modal mass 1 per mode)",
        ev.last().unwrap(),
        ev.iter().sum::<f64>(),
        total_mass
    );
    // beta = Phi^T M b.
    let b = Mat::<f64>::from_fn(n, 1, |i, _| model.base[i]);
    let beta = mul(phi.transpose(), mul(md.as_ref(), b.as_ref()).as_ref());
    for i in 0..m {
        assert!((beta[(i, 0)].abs() - rom.beta[i].abs()).abs() < 1e-9 * total_mass.sqrt());
    }
}

#[test]
fn lanczos_matches_dense_with_repeated_eigenvalues() {
    // Square section, symmetric mesh: flap and edge bending modes are exactly repeated.
    let grid = BoxGrid::new(
        &linspace(0.0, 0.2, 14),
        &linspace(0.0, 0.01, 2),
        &linspace(0.0, 0.01, 2),
        |p| p,
    );
    let (model, _) = assemble(&[Part {
        grid,
        group: DofGroup::Lower,
    }]);
    let (reference, _) = dense_eigen(&model);
    let want = 30;
    let options = EigenOptions {
        max_basis: 48,
        ..EigenOptions::default()
    };
    let mut solver = EigenSolver::new(model.k.as_ref(), model.m.as_ref(), options).unwrap();
    solver.solve(EigenTarget::Count(want), &mut |_| {}).unwrap();
    let modes = solver.modes(EigenTarget::Count(want));
    assert_eq!(modes.len(), want);
    let mut repeated = 0;
    for i in 0..want {
        let rel = (modes.lambda[i] - reference[i]).abs() / reference[i];
        assert!(
            rel < 1e-9,
            "mode {i}: {} vs {} ({rel:e})",
            modes.lambda[i],
            reference[i]
        );
        assert!(
            modes.residuals[i] < 1e-8,
            "mode {i}: residual {:e}",
            modes.residuals[i]
        );
        if i > 0 && (reference[i] - reference[i - 1]).abs() < 1e-9 * reference[i] {
            repeated += 1;
        }
    }
    assert!(
        repeated >= 4,
        "the square beam should have repeated eigenvalues ({repeated})"
    );
    // M-orthonormal eigenvectors.
    let mv = mul(dense(&model.m).as_ref(), modes.vectors.as_ref());
    let g = mul(modes.vectors.transpose(), mv.as_ref());
    let dev = Mat::<f64>::from_fn(want, want, |i, j| {
        g[(i, j)] - if i == j { 1.0 } else { 0.0 }
    });
    assert!(
        max_abs(dev.as_ref()) < 1e-10,
        "M-orthonormality {:e}",
        max_abs(dev.as_ref())
    );
    eprintln!("stats {:?}", solver.stats());
}

#[test]
fn cutoff_ratio_labels_and_stability() {
    let model = two_cantilevers();
    let rom = reduce(
        &model,
        ModeSelection::CutoffRatio { ratio: 40.0 },
        &mut |_| {},
    )
    .unwrap();
    let (reference, _) = dense_eigen(&model);
    let w_ref = rom.omega_ref();
    assert_eq!(rom.labels[rom.meta.reference_mode], "1FU");
    assert_eq!(
        &rom.labels[..4],
        ["1FL", "1FU", "1EL", "1EU"],
        "{:?}",
        rom.labels
    );
    let mut seen = std::collections::HashSet::new();
    assert!(
        rom.labels.iter().all(|l| seen.insert(l.clone())),
        "labels unique: {:?}",
        rom.labels
    );
    // Exactly the FE modes below 40 x w(1FU).
    let cut = 40.0 * w_ref;
    let expected = reference.partition_point(|&l| l <= cut * cut);
    assert_eq!(rom.n_modes(), expected);
    // The residual of the lowest mode is at the roundoff floor of K phi on this stiff mesh,
    // about eps lambda_max / lambda_1 = 1.2e-8.
    assert!(
        rom.meta.max_eigen_residual < 5e-8,
        "{:e}",
        rom.meta.max_eigen_residual
    );
    // Stability: open limit pi w_max / w_ref, closed limit tighter.
    let open = steps_per_period(*rom.omega.last().unwrap(), w_ref);
    assert!((rom.meta.stable_steps_per_period_open - open).abs() < 1e-12 * open);
    let closed = closed_limit(&rom.omega, rom.phi_g.as_ref(), rom.k_gg.as_ref()).unwrap();
    assert!(
        (rom.meta.stable_steps_per_period_closed - steps_per_period(closed, w_ref)).abs()
            < 1e-9 * open
    );
    assert!(rom.meta.stable_steps_per_period_closed > rom.meta.stable_steps_per_period_open);
    eprintln!(
        "{} modes, labels {:?}\nsteps/period open {:.1}, closed {:.1}; timings {:?}",
        rom.n_modes(),
        rom.labels,
        rom.meta.stable_steps_per_period_open,
        rom.meta.stable_steps_per_period_closed,
        rom.meta.timings
    );
}

#[test]
fn all_modes_retained_is_rejected() {
    // A tiny model: retaining every mode leaves no residual flexibility.
    let grid = BoxGrid::new(
        &linspace(0.0, 0.02, 2),
        &linspace(0.0, 0.01, 1),
        &linspace(0.0, 0.01, 1),
        |p| p,
    );
    let grid2 = BoxGrid::new(
        &linspace(0.0, 0.02, 2),
        &linspace(0.0, 0.01, 1),
        &linspace(0.011, 0.021, 1),
        |p| p,
    );
    let (mut model, free) = assemble(&[
        Part {
            grid,
            group: DofGroup::Lower,
        },
        Part {
            grid: grid2,
            group: DofGroup::Upper,
        },
    ]);
    let dof3 = |node: usize| [0, 1, 2].map(|d| free[3 * node + d]);
    model.pairs.push(PairDofs {
        lower: dof3(8),
        upper: dof3(12 + 2),
        frame: [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        area: 1e-4,
        position: model.node_coords[8],
    });
    let n = model.n_dof();
    let err = reduce(&model, ModeSelection::Count { count: n }, &mut |_| {}).unwrap_err();
    assert!(
        matches!(err, RomError::ResidualFlexibilityNotPositive { .. }),
        "{err}"
    );
    // A few modes are fine.
    assert!(reduce(&model, ModeSelection::Count { count: 3 }, &mut |_| {}).is_ok());
}

/// Size and speed on hex8 cantilevers of rig size (default 150 x 12 x 3 cells per beam,
/// 46800 DOFs, 16 x 13 = 208 pairs): run with
/// `cargo test --release --test macneal_properties -- --ignored --nocapture`; the environment
/// variables RIG_SIZE (nx,ny,nz,pair stations), RATIO (cutoff / f(1FU)) and BLOCK (Lanczos
/// block size) vary the case, RUST_LOG=rigtwin=debug shows the Lanczos runs.
#[test]
#[ignore = "takes tens of seconds in a debug build; a speed measurement"]
fn rig_sized_model_builds() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .try_init();
    let size: Vec<usize> = std::env::var("RIG_SIZE")
        .unwrap_or_else(|_| "150,12,3,16".into())
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let model = two_cantilevers_sized(size[0], size[1], size[2], size[3]);
    let t0 = std::time::Instant::now();
    let mut last = std::time::Instant::now();
    let block: usize = std::env::var("BLOCK").map_or(4, |b| b.parse().unwrap());
    let ratio: f64 = std::env::var("RATIO").map_or(180.0, |b| b.parse().unwrap());
    let options = EigenOptions {
        block_size: block,
        ..EigenOptions::default()
    };
    let rom = rigtwin::rom::macneal::reduce_with(
        &model,
        ModeSelection::CutoffRatio { ratio },
        options,
        &mut |p| {
            if last.elapsed().as_secs_f64() > 1.0 {
                last = std::time::Instant::now();
                eprintln!("{:.1} s: {p:?}", t0.elapsed().as_secs_f64());
            }
        },
    )
    .unwrap();
    eprintln!(
        "{} DOFs, {} pairs, {} modes (labels {:?}...), {:.2} s: {:?}\nmax residual {:.2e}, \
         static flexibility error {:.2e}, steps/period open {:.0} closed {:.0}",
        model.n_dof(),
        model.pairs.len(),
        rom.n_modes(),
        &rom.labels[..6],
        t0.elapsed().as_secs_f64(),
        rom.meta.timings,
        rom.meta.max_eigen_residual,
        rom.meta.static_flexibility_error,
        rom.meta.stable_steps_per_period_open,
        rom.meta.stable_steps_per_period_closed
    );
    assert!(rom.meta.static_flexibility_error < 1e-8);
}

/// The reference rig (rig-config/two-beam.toml) end to end: mesher, native assembly and
/// reduction with its own selection. A speed measurement: run with
/// `cargo test --release --test macneal_properties -- --ignored --nocapture`.
#[test]
#[ignore = "a speed measurement on the full reference rig"]
fn reference_rig_builds() {
    let path =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rig-config/two-beam.toml");
    let cfg = rigtwin::config::RigConfig::from_path(&path).unwrap();
    let t0 = std::time::Instant::now();
    let mesh = rigtwin::fe::rig::mesh_rig(cfg.model()).unwrap();
    let model = rigtwin::fe::assembly::assemble(&mesh, cfg.contact.clearance).unwrap();
    let t_asm = t0.elapsed().as_secs_f64();
    let ratio: f64 = std::env::var("RATIO").map_or(180.0, |b| b.parse().unwrap());
    let rom = reduce(&model, ModeSelection::CutoffRatio { ratio }, &mut |_| {}).unwrap();
    eprintln!(
        "{} DOFs, {} pairs, {} modes, assembly {t_asm:.2} s, build {:.2} s: {:?}\nlabels {:?}\n\
         f = {:?}\nmax residual {:.2e}, static flexibility error {:.2e}, steps/period open {:.0} \
         closed {:.0}",
        model.n_dof(),
        model.pairs.len(),
        rom.n_modes(),
        rom.meta.build_seconds,
        rom.meta.timings,
        rom.labels,
        rom.frequencies_hz()
            .iter()
            .map(|f| (f * 10.0).round() / 10.0)
            .collect::<Vec<_>>(),
        rom.meta.max_eigen_residual,
        rom.meta.static_flexibility_error,
        rom.meta.stable_steps_per_period_open,
        rom.meta.stable_steps_per_period_closed
    );
    assert_eq!(rom.labels[rom.meta.reference_mode], "1FU");
    assert!(rom.meta.static_flexibility_error < 1e-8);
    if std::env::var("LABEL_DEBUG").is_ok() {
        let mut solver =
            EigenSolver::new(model.k.as_ref(), model.m.as_ref(), EigenOptions::default()).unwrap();
        solver.solve(EigenTarget::Count(14), &mut |_| {}).unwrap();
        let modes = solver.modes(EigenTarget::Count(14));
        let md = &model.m;
        for j in 0..14 {
            let phi: Vec<f64> = modes.vectors.col(j).iter().copied().collect();
            let mut mphi = Mat::<f64>::zeros(model.n_dof(), 1);
            faer::sparse::linalg::matmul::sparse_dense_matmul(
                mphi.as_mut(),
                Accum::Replace,
                md.as_ref(),
                modes.vectors.subcols(j, 1),
                1.0,
                Par::Seq,
            );
            let mphi: Vec<f64> = mphi.col(0).iter().copied().collect();
            eprintln!(
                "{j}: {:?}",
                rigtwin::rom::labels::classify_mode(&model, &phi, &mphi)
            );
        }
    }
}

/// A coarse version of the reference rig (mesher, native assembly, 4 x 5 contact patch):
/// the reduction runs on the real part layout, names the modes as the reference does and
/// keeps the exact static boundary flexibility.
#[test]
fn coarse_reference_rig_reduces() {
    let path =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rig-config/two-beam.toml");
    let mut cfg = rigtwin::config::RigConfig::from_path(&path).unwrap();
    cfg.contact.nodes = [4, 5];
    cfg.mesh.beams.free_element = 0.012;
    cfg.mesh.beams.width_element = 0.01;
    cfg.mesh.beams.clamp_element = 0.01;
    cfg.mesh.beams.clamp_exit_element = 0.004;
    cfg.validate().unwrap();
    let mesh = rigtwin::fe::rig::mesh_rig(cfg.model()).unwrap();
    let model = rigtwin::fe::assembly::assemble(&mesh, cfg.contact.clearance).unwrap();
    let rom = reduce(
        &model,
        ModeSelection::CutoffRatio { ratio: 40.0 },
        &mut |_| {},
    )
    .unwrap();
    eprintln!(
        "{} DOFs, {} pairs, {} modes in {:.2} s: {:?}\nlabels {:?}\nf {:?}",
        model.n_dof(),
        model.pairs.len(),
        rom.n_modes(),
        rom.meta.build_seconds,
        rom.meta.timings,
        rom.labels,
        rom.frequencies_hz()
    );
    assert_eq!(rom.n_pairs(), 20);
    assert_eq!(&rom.labels[..6], ["1FL", "1FU", "1EL", "1EU", "2FL", "2FU"]);
    assert_eq!(rom.meta.reference_mode, 1);
    let f = rom.frequencies_hz();
    assert!(
        (0.85..0.97).contains(&(f[0] / f[1])),
        "1FL/1FU = {}",
        f[0] / f[1]
    );
    assert!(*f.last().unwrap() <= 40.0 * f[1] * (1.0 + 1e-12));
    assert!(
        rom.meta.static_flexibility_error < 1e-8,
        "{:e}",
        rom.meta.static_flexibility_error
    );
    assert!(
        rom.meta.max_eigen_residual < 1e-6,
        "{:e}",
        rom.meta.max_eigen_residual
    );
    assert!(rom.meta.stable_steps_per_period_closed > rom.meta.stable_steps_per_period_open);
    assert_eq!(rom.outputs.len(), model.outputs.len());
    assert_eq!(rom.clearance, cfg.contact.clearance);
}

/// A `[model]` frequency correction of the 1FU mode (`physics::modal`, no rebuild) against a
/// ROM rebuilt from the parent model with the equivalent stiffness change
/// `K' = K + (w'^2 - w^2) (M phi)(M phi)^T` (phi the parent's M-normalised 1FU mode): the
/// corrected and the rebuilt ROM agree within 0.1 % on every retained frequency, on the static
/// boundary flexibility (`G_res + Phi_g W^-2 Phi_g^T`, the contact's static compliance) and on
/// the impact-free resonance of both tips (the ROM's own linear steady-state response to a
/// base sine, peak located on a 0.01 % frequency grid), for a stiffer and a softer 1FU.
#[test]
fn a_frequency_correction_equals_a_rebuilt_rom() {
    use rigtwin::config::physics::ModalCorrectionSpec;
    use rigtwin::physics::modal;

    let model = two_cantilevers();
    let count = 20;
    let rom = reduce(&model, ModeSelection::Count { count }, &mut |_| {}).unwrap();
    let i = rom.labels.iter().position(|l| l == "1FU").unwrap();
    let phi = modal_matrix(&model, count);
    let m_dense = dense(&model.m);
    let m_phi = mul(m_dense.as_ref(), phi.col(i).as_mat());
    // The ROM's mode i is the parent's mode i (same solver): check before relying on it.
    let w_fe = {
        let k_phi = mul(dense(&model.k).as_ref(), phi.col(i).as_mat());
        let num: f64 = (0..k_phi.nrows())
            .map(|r| k_phi[(r, 0)] * phi[(r, i)])
            .sum();
        let den: f64 = (0..m_phi.nrows())
            .map(|r| m_phi[(r, 0)] * phi[(r, i)])
            .sum();
        assert!((den - 1.0).abs() < 1e-9, "mode not M-normalised: {den}");
        num.sqrt()
    };
    assert!((w_fe / rom.omega[i] - 1.0).abs() < 1e-9);

    for factor in [1.04, 0.93] {
        let w_new = factor * rom.omega[i];
        // The rebuilt parent: K plus the rank-one change, as a sparse matrix.
        let n = model.k.nrows();
        let delta = w_new * w_new - rom.omega[i] * rom.omega[i];
        let mut triplets = Vec::new();
        let k_dense = dense(&model.k);
        for c in 0..n {
            for r in 0..n {
                let v = k_dense[(r, c)] + delta * m_phi[(r, 0)] * m_phi[(c, 0)];
                if v != 0.0 {
                    triplets.push(Triplet::new(r, c, v));
                }
            }
        }
        let mut rebuilt_model = model.clone();
        rebuilt_model.k = SparseColMat::try_new_from_triplets(n, n, &triplets).unwrap();
        let mut rebuilt =
            reduce(&rebuilt_model, ModeSelection::Count { count }, &mut |_| {}).unwrap();
        // The same modal damping in both (the test ROMs carry none), so the peaks are finite.
        rebuilt.damping_ratio.fill(0.01);

        let mut corrected = rom.clone();
        corrected.damping_ratio.fill(0.01);
        modal::apply(
            &mut corrected,
            &[ModalCorrectionSpec {
                mode: "1FU".into(),
                frequency_hz: Some(w_new / (2.0 * std::f64::consts::PI)),
                damping_ratio: None,
            }],
            "model",
        )
        .unwrap();

        // Frequencies, mode by mode (the rebuilt ROM's order may change where 1FU crosses a
        // neighbour: compare sorted).
        let mut a = corrected.omega.clone();
        let mut b = rebuilt.omega.clone();
        a.sort_by(f64::total_cmp);
        b.sort_by(f64::total_cmp);
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                (x / y - 1.0).abs() < 1e-3,
                "factor {factor}: frequency {k}: {x} vs {y}"
            );
        }
        // Static boundary flexibility.
        let fa = modal::static_boundary_flexibility(&corrected);
        let fb = modal::static_boundary_flexibility(&rebuilt);
        let diff = max_abs((&fa - &fb).as_ref());
        let rel = diff / max_abs(fb.as_ref());
        assert!(
            rel < 1e-3,
            "factor {factor}: static flexibility differs by {rel:e}"
        );

        // Impact-free resonance of each tip near the corrected 1FU.
        for output in ["lower_tip", "upper_tip"] {
            let peak = |r: &Rom| -> (f64, f64) {
                let o = r.outputs.iter().find(|o| o.name == output).unwrap();
                let amplitude = |w: f64| -> f64 {
                    let (mut re, mut im) = (0.0, 0.0);
                    for j in 0..r.n_modes() {
                        let (wj, z) = (r.omega[j], r.damping_ratio[j]);
                        let (dr, di) = (wj * wj - w * w, 2.0 * z * wj * w);
                        let g = -r.beta[j] * o.c_eta[j] / (dr * dr + di * di);
                        re += g * dr;
                        im -= g * di;
                    }
                    (re * re + im * im).sqrt()
                };
                (0..4001)
                    .map(|k| w_new * (0.8 + 0.4 * k as f64 / 4000.0))
                    .map(|w| (w, amplitude(w)))
                    .fold((0.0, 0.0), |best, x| if x.1 > best.1 { x } else { best })
            };
            let (wa, ha) = peak(&corrected);
            let (wb, hb) = peak(&rebuilt);
            assert!(
                (wa / wb - 1.0).abs() < 1e-3 && (ha / hb - 1.0).abs() < 1e-3,
                "factor {factor}, {output}: resonance {wa} ({ha:e}) vs rebuilt {wb} ({hb:e})"
            );
            println!(
                "factor {factor}, {output}: resonance {:.4} vs {:.4} rad/s, peak {:+.2e} relative",
                wa,
                wb,
                ha / hb - 1.0
            );
        }
        println!("factor {factor}: static flexibility max difference {rel:.2e} relative");
    }
}
