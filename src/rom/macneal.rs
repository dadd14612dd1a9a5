//! MacNeal reduction of an [`FeModel`] to a [`Rom`] (DESIGN.md "The model", steps 2-3).
//!
//! - Boundary operator B (3C x n): the row block of pair k is `frame_k (u_upper - u_lower)`,
//!   so the gaps are `g = B u + g0`, `g0 = [clearance, 0, 0]` per pair.
//! - Free-interface modes Phi (n x m, M-orthonormal): the modes of the FE model as given
//!   (contact open), `Omega = sqrt(lambda)`, `Phi_g = B Phi`, `beta = Phi^T M b`.
//! - Static flexibility `G = B K^-1 B^T` (3C solves), residual flexibility
//!   `G_res = G - Phi_g Omega^-2 Phi_g^T`, `K_gg = G_res^-1`.
//! - Sensor rows: `c_eta = o . Phi`, `c_lambda = o . Psi_res` with the residual attachment
//!   modes `Psi_res = (K^-1 - Phi Omega^-2 Phi^T) B^T`.
//!
//! The ROM `g = Phi_g eta + G_res lambda (+ g0)` reproduces the parent model's static boundary
//! flexibility exactly, and its boundary is massless (M_red = diag(0, I)).
//!
//! NOTE: the build reads the wall clock only to fill [`BuildTimings`]; no result depends on it.

use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, Mat, MatRef, Side};

use crate::fe::FeModel;
use crate::rom::eigen::{EigenOptions, EigenProgress, EigenSolver, EigenTarget};
use crate::rom::error::RomError;
use crate::rom::labels::label_modes;
use crate::rom::stability::{closed_limit, open_limit, steps_per_period};
use crate::rom::{BuildTimings, ModeSelection, Rom, RomMeta, RomOutput};

/// Modes solved first when the cutoff is a multiple of f(1FU), to find 1FU.
const FIRST_BATCH: usize = 16;
/// Largest first batch searched for 1FU.
const MAX_REFERENCE_SEARCH: usize = 128;
/// Random boundary loads of the static flexibility check.
const FLEXIBILITY_CHECKS: usize = 3;

/// Reduces `model` with the default eigen solver options; see [`reduce_with`].
pub fn reduce(
    model: &FeModel,
    selection: ModeSelection,
    progress: &mut dyn FnMut(EigenProgress),
) -> Result<Rom, RomError> {
    reduce_with(model, selection, EigenOptions::default(), progress)
}

/// Reduces `model` to a ROM keeping the modes chosen by `selection`.
///
/// Fills every numeric field of the [`Rom`] and of its [`RomMeta`] except the provenance
/// (`config_hash`, `source`, `rig_name` stay empty), the modal damping ratios (zeros), the
/// friction coefficient (0) and the assembly time; `build_seconds` is the time spent here.
pub fn reduce_with(
    model: &FeModel,
    selection: ModeSelection,
    options: EigenOptions,
    progress: &mut dyn FnMut(EigenProgress),
) -> Result<Rom, RomError> {
    let t_build = Instant::now();
    validate(model)?;
    validate_selection(selection)?;
    let n = model.n_dof();

    // Free-interface modes.
    let mut solver = EigenSolver::new(model.k.as_ref(), model.m.as_ref(), options)?;
    let target = match selection {
        ModeSelection::Count { count } => EigenTarget::Count(count.min(n)),
        ModeSelection::CutoffHz { hz } => EigenTarget::BelowOmega(2.0 * std::f64::consts::PI * hz),
        ModeSelection::CutoffRatio { ratio } => {
            let w_ref = reference_omega(model, &mut solver, progress)?;
            EigenTarget::BelowOmega(ratio * w_ref)
        }
    };
    solver.solve(target, progress)?;
    let modes = solver.modes(target);
    let m = modes.len();
    if m == 0 {
        return Err(RomError::EmptyModel(format!(
            "no mode below the cutoff ({selection:?})"
        )));
    }
    let omega = modes.omega();
    let labels = label_modes(model, modes.vectors.as_ref());
    let reference_mode = match labels.iter().position(|l| l == "1FU") {
        Some(i) => i,
        None => {
            if matches!(selection, ModeSelection::CutoffRatio { .. }) {
                return Err(RomError::NoReferenceMode {
                    searched: m,
                    labels: labels.join(","),
                });
            }
            tracing::warn!(
                "no mode labelled 1FU among {m} modes; mode 0 is taken as the reference"
            );
            0
        }
    };
    let stats = solver.stats();
    let t_attach = Instant::now();

    // Boundary quantities.
    let c3 = 3 * model.pairs.len();
    let phi = modes.vectors.as_ref();
    let phi_g = apply_b(model, phi);
    let mut m_b = Mat::<f64>::zeros(n, 1);
    let base = Mat::<f64>::from_fn(n, 1, |i, _| model.base[i]);
    let par = faer::get_global_parallelism();
    sparse_dense_matmul(
        m_b.as_mut(),
        Accum::Replace,
        model.m.as_ref(),
        base.as_ref(),
        1.0,
        par,
    );
    let beta: Vec<f64> = (0..m)
        .map(|j| (0..n).map(|i| phi[(i, j)] * m_b[(i, 0)]).sum())
        .collect();

    // Static flexibility G = B K^-1 B^T and the sensor rows of K^-1 B^T, by chunks of
    // right-hand sides (K^-1 B^T itself is n x 3C: too large to keep for big models).
    solver.release_workspace();
    let (g_full, x_out) = static_flexibility(model, &solver)?;
    let inv_l: Vec<f64> = modes.lambda.iter().map(|l| 1.0 / l).collect();
    // Phi_g Omega^-2 (3C x m).
    let phi_g_scaled = Mat::<f64>::from_fn(c3, m, |i, j| phi_g[(i, j)] * inv_l[j]);
    let mut g_res = g_full.clone();
    matmul(
        g_res.as_mut(),
        Accum::Add,
        phi_g_scaled.as_ref(),
        phi_g.transpose(),
        -1.0,
        par,
    );
    symmetrise(&mut g_res);
    if g_res.col_iter().any(|c| c.iter().any(|v| !v.is_finite())) {
        return Err(RomError::NonFinite {
            what: "residual boundary flexibility".into(),
        });
    }
    let k_gg = invert_spd(&g_res, m)?;

    // Sensor rows.
    let outputs = model
        .outputs
        .iter()
        .enumerate()
        .map(|(oi, o)| {
            let mut c_eta = vec![0.0; m];
            let mut c_lambda = x_out[oi].clone();
            for &(dof, w) in &o.terms {
                for (j, c) in c_eta.iter_mut().enumerate() {
                    *c += w * phi[(dof, j)];
                }
            }
            // Residual part: subtract c_eta Omega^-2 Phi_g^T.
            for (r, c) in c_lambda.iter_mut().enumerate() {
                *c -= (0..m).map(|j| c_eta[j] * phi_g_scaled[(r, j)]).sum::<f64>();
            }
            RomOutput {
                name: o.name.clone(),
                c_eta,
                c_lambda,
            }
        })
        .collect();

    let static_flexibility_error = static_flexibility_check(
        model,
        &solver,
        phi_g.as_ref(),
        phi_g_scaled.as_ref(),
        g_res.as_ref(),
    )?;
    let attachment = t_attach.elapsed().as_secs_f64();

    let omega_ref = omega[reference_mode];
    let w_open = open_limit(&omega);
    let w_closed = closed_limit(&omega, phi_g.as_ref(), k_gg.as_ref())?;

    let meta = RomMeta {
        config_hash: String::new(),
        source: String::new(),
        rig_name: String::new(),
        beam_length: 0.0,
        n_dof: n,
        n_nodes: model.n_nodes(),
        n_elements: model.n_elements,
        selection,
        reference_mode,
        max_eigen_residual: modes.residuals.iter().copied().fold(0.0, f64::max),
        static_flexibility_error,
        timings: BuildTimings {
            assembly: 0.0,
            factorisation: stats.factorisation_seconds,
            eigen: stats.solve_seconds,
            attachment,
        },
        build_seconds: t_build.elapsed().as_secs_f64(),
        stable_steps_per_period_open: steps_per_period(w_open, omega_ref),
        stable_steps_per_period_closed: steps_per_period(w_closed, omega_ref),
    };
    Ok(Rom {
        meta,
        damping_ratio: vec![0.0; m],
        labels,
        omega,
        phi_g,
        g_res,
        k_gg,
        beta,
        pair_area: model.pairs.iter().map(|p| p.area).collect(),
        pair_position: model.pairs.iter().map(|p| p.position).collect(),
        clearance: model.clearance,
        friction: 0.0,
        outputs,
    })
}

/// Solves growing batches of the lowest modes until one is labelled 1FU; returns its circular
/// frequency, rad/s.
fn reference_omega(
    model: &FeModel,
    solver: &mut EigenSolver<'_>,
    progress: &mut dyn FnMut(EigenProgress),
) -> Result<f64, RomError> {
    let n = model.n_dof();
    let mut batch = FIRST_BATCH.min(n);
    loop {
        let target = EigenTarget::Count(batch);
        solver.solve(target, progress)?;
        let modes = solver.modes(target);
        let labels = label_modes(model, modes.vectors.as_ref());
        if let Some(i) = labels.iter().position(|l| l == "1FU") {
            return Ok(modes.omega()[i]);
        }
        if batch >= MAX_REFERENCE_SEARCH.min(n) {
            return Err(RomError::NoReferenceMode {
                searched: batch,
                labels: labels.join(","),
            });
        }
        batch = (2 * batch).min(MAX_REFERENCE_SEARCH).min(n);
    }
}

/// Checks sizes, indices and finiteness of the model's vectors.
fn validate(model: &FeModel) -> Result<(), RomError> {
    let n = model.n_dof();
    if n == 0 {
        return Err(RomError::EmptyModel("no free DOFs".into()));
    }
    if model.pairs.is_empty() {
        return Err(RomError::EmptyModel(
            "no contact pairs: the MacNeal boundary is empty".into(),
        ));
    }
    for (what, found) in [
        ("stiffness matrix rows", model.k.nrows()),
        ("stiffness matrix columns", model.k.ncols()),
        ("mass matrix rows", model.m.nrows()),
        ("mass matrix columns", model.m.ncols()),
        ("base direction vector", model.base.len()),
    ] {
        if found != n {
            return Err(RomError::Dimension {
                what: what.into(),
                expected: n,
                found,
            });
        }
    }
    if model.base.iter().any(|v| !v.is_finite()) {
        return Err(RomError::NonFinite {
            what: "base direction vector".into(),
        });
    }
    if !model.clearance.is_finite() {
        return Err(RomError::NonFinite {
            what: "clearance".into(),
        });
    }
    const AXES: [char; 3] = ['x', 'y', 'z'];
    for (k, p) in model.pairs.iter().enumerate() {
        for (side, dofs) in [("lower", p.lower), ("upper", p.upper)] {
            for (d, &dof) in dofs.iter().enumerate() {
                if dof >= n {
                    return Err(RomError::DofOutOfRange {
                        what: format!("contact pair {k} ({side} node, {})", AXES[d]),
                        dof,
                        n_dof: n,
                    });
                }
            }
        }
        if p.frame.iter().flatten().any(|v| !v.is_finite()) || !p.area.is_finite() {
            return Err(RomError::NonFinite {
                what: format!("frame or area of contact pair {k}"),
            });
        }
    }
    for o in &model.outputs {
        for &(dof, w) in &o.terms {
            if dof >= n {
                return Err(RomError::DofOutOfRange {
                    what: format!("sensor output '{}'", o.name),
                    dof,
                    n_dof: n,
                });
            }
            if !w.is_finite() {
                return Err(RomError::NonFinite {
                    what: format!("weight of sensor output '{}'", o.name),
                });
            }
        }
    }
    Ok(())
}

fn validate_selection(selection: ModeSelection) -> Result<(), RomError> {
    let ok = match selection {
        ModeSelection::CutoffRatio { ratio } => ratio.is_finite() && ratio > 0.0,
        ModeSelection::CutoffHz { hz } => hz.is_finite() && hz > 0.0,
        ModeSelection::Count { count } => count > 0,
    };
    if ok {
        Ok(())
    } else {
        Err(RomError::InvalidSelection(format!(
            "{selection:?}: the cutoff must be a positive number and the count at least 1"
        )))
    }
}

/// Chunk of right-hand sides for the static solves.
const STATIC_CHUNK: usize = 64;

/// `G = B K^-1 B^T` (3C x 3C) and, for each sensor output row o, `o . K^-1 B^T` (length 3C).
fn static_flexibility(
    model: &FeModel,
    solver: &EigenSolver<'_>,
) -> Result<(Mat<f64>, Vec<Vec<f64>>), RomError> {
    let n = model.n_dof();
    let c3 = 3 * model.pairs.len();
    let mut g = Mat::<f64>::zeros(c3, c3);
    let mut rows = vec![vec![0.0; c3]; model.outputs.len()];
    let mut start = 0;
    while start < c3 {
        let width = STATIC_CHUNK.min(c3 - start);
        // Columns start..start+width of B^T.
        let mut x = Mat::<f64>::zeros(n, width);
        for col in 0..width {
            let (k, r) = ((start + col) / 3, (start + col) % 3);
            let p = &model.pairs[k];
            for d in 0..3 {
                x[(p.upper[d], col)] += p.frame[r][d];
                x[(p.lower[d], col)] -= p.frame[r][d];
            }
        }
        solver.static_solve(x.as_mut())?;
        let bx = apply_b(model, x.as_ref());
        g.subcols_mut(start, width).copy_from(&bx);
        for (o, row) in model.outputs.iter().zip(rows.iter_mut()) {
            for col in 0..width {
                row[start + col] = o.terms.iter().map(|&(dof, w)| w * x[(dof, col)]).sum();
            }
        }
        start += width;
    }
    Ok((g, rows))
}

/// `B v` for the columns of `v` (n x s): 3C x s.
pub fn apply_b(model: &FeModel, v: MatRef<'_, f64>) -> Mat<f64> {
    let c3 = 3 * model.pairs.len();
    let mut out = Mat::<f64>::zeros(c3, v.ncols());
    for (k, p) in model.pairs.iter().enumerate() {
        for r in 0..3 {
            for col in 0..v.ncols() {
                let mut s = 0.0;
                for d in 0..3 {
                    s += p.frame[r][d] * (v[(p.upper[d], col)] - v[(p.lower[d], col)]);
                }
                out[(3 * k + r, col)] = s;
            }
        }
    }
    out
}

/// `B^T l` for the columns of `l` (3C x s): n x s.
pub fn apply_bt(model: &FeModel, l: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(model.n_dof(), l.ncols());
    for (k, p) in model.pairs.iter().enumerate() {
        for col in 0..l.ncols() {
            for r in 0..3 {
                let v = l[(3 * k + r, col)];
                for d in 0..3 {
                    out[(p.upper[d], col)] += p.frame[r][d] * v;
                    out[(p.lower[d], col)] -= p.frame[r][d] * v;
                }
            }
        }
    }
    out
}

/// `B^T` as a dense n x 3C matrix (for small models and tests).
pub fn b_transpose(model: &FeModel) -> Mat<f64> {
    let n = model.n_dof();
    let mut bt = Mat::<f64>::zeros(n, 3 * model.pairs.len());
    for (k, p) in model.pairs.iter().enumerate() {
        for r in 0..3 {
            for d in 0..3 {
                bt[(p.upper[d], 3 * k + r)] += p.frame[r][d];
                bt[(p.lower[d], 3 * k + r)] -= p.frame[r][d];
            }
        }
    }
    bt
}

fn symmetrise(a: &mut Mat<f64>) {
    for i in 0..a.nrows() {
        for j in 0..i {
            let s = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = s;
            a[(j, i)] = s;
        }
    }
}

/// Inverse of the residual flexibility by a dense Cholesky factorisation.
pub(crate) fn invert_spd(g_res: &Mat<f64>, n_modes: usize) -> Result<Mat<f64>, RomError> {
    use faer::linalg::solvers::DenseSolveCore;
    let c3 = g_res.nrows();
    let fail = |detail: String| RomError::ResidualFlexibilityNotPositive {
        n_modes,
        n_boundary: c3,
        detail,
    };
    let llt = match g_res.llt(Side::Lower) {
        Ok(l) => l,
        Err(_) => {
            let ev = g_res
                .self_adjoint_eigenvalues(Side::Lower)
                .unwrap_or_default();
            let (lo, hi) = (
                ev.first().copied().unwrap_or(f64::NAN),
                ev.last().copied().unwrap_or(f64::NAN),
            );
            return Err(fail(format!("eigenvalues from {lo:.3e} to {hi:.3e} m/N")));
        }
    };
    // NOTE: a positive but nearly singular G_res makes K_gg huge and the closed-contact
    // stability limit very tight; the factor's diagonal ratio flags it.
    let l = llt.L();
    let (mut dmin, mut dmax) = (f64::INFINITY, 0.0f64);
    for i in 0..c3 {
        dmin = dmin.min(l[(i, i)]);
        dmax = dmax.max(l[(i, i)]);
    }
    if dmin.is_nan() || dmin <= 1e-7 * dmax {
        return Err(fail(format!(
            "numerically singular: Cholesky diagonal ratio {:.3e}",
            dmin / dmax
        )));
    }
    let mut k_gg = llt.inverse();
    symmetrise(&mut k_gg);
    Ok(k_gg)
}

/// Relative error of the ROM's static boundary response `Phi_g Omega^-2 Phi_g^T lambda +
/// G_res lambda` against fresh solves `B K^-1 B^T lambda` (refined once against K) for a few
/// deterministic pseudo-random boundary loads.
fn static_flexibility_check(
    model: &FeModel,
    solver: &EigenSolver<'_>,
    phi_g: MatRef<'_, f64>,
    phi_g_scaled: MatRef<'_, f64>,
    g_res: MatRef<'_, f64>,
) -> Result<f64, RomError> {
    let par = faer::get_global_parallelism();
    let c3 = phi_g.nrows();
    let n = model.n_dof();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let loads = Mat::<f64>::from_fn(c3, FLEXIBILITY_CHECKS, |_, _| next());
    // Full model: u = K^-1 B^T lambda with one step of iterative refinement.
    let rhs = apply_bt(model, loads.as_ref());
    let mut u = rhs.clone();
    solver.static_solve(u.as_mut())?;
    let mut r = rhs.clone();
    sparse_dense_matmul(
        r.as_mut(),
        Accum::Add,
        model.k.as_ref(),
        u.as_ref(),
        -1.0,
        par,
    );
    solver.static_solve(r.as_mut())?;
    for j in 0..FLEXIBILITY_CHECKS {
        for i in 0..n {
            u[(i, j)] += r[(i, j)];
        }
    }
    let g_fe = apply_b(model, u.as_ref());
    // ROM: Phi_g Omega^-2 Phi_g^T lambda + G_res lambda.
    let mut q = Mat::<f64>::zeros(phi_g.ncols(), FLEXIBILITY_CHECKS);
    matmul(
        q.as_mut(),
        Accum::Replace,
        phi_g.transpose(),
        loads.as_ref(),
        1.0,
        par,
    );
    let mut g_rom = Mat::<f64>::zeros(c3, FLEXIBILITY_CHECKS);
    matmul(
        g_rom.as_mut(),
        Accum::Replace,
        phi_g_scaled,
        q.as_ref(),
        1.0,
        par,
    );
    matmul(g_rom.as_mut(), Accum::Add, g_res, loads.as_ref(), 1.0, par);
    let mut worst = 0.0f64;
    for j in 0..FLEXIBILITY_CHECKS {
        let (mut d2, mut f2) = (0.0, 0.0);
        for i in 0..c3 {
            d2 += (g_rom[(i, j)] - g_fe[(i, j)]).powi(2);
            f2 += g_fe[(i, j)].powi(2);
        }
        worst = worst.max((d2 / f2).sqrt());
    }
    if !worst.is_finite() {
        return Err(RomError::NonFinite {
            what: "static flexibility check".into(),
        });
    }
    Ok(worst)
}
