//! Guards that CalculiX and the native assembly (`fe::assemble`) build the same parent model
//! for the two-cantilever mesh: ccx keeps 9 bubble DOFs per C3D8I element with bubble mass,
//! the native Hex8I condenses them with the static bubble response, so ccx's K and M
//! reduced onto the node DOFs by that same response (Guyan) must equal the native K and M
//! entry by entry; the DOF table, contact pairs, sensors and base vector must agree; and the
//! native eigenfrequencies must match ccx's within 0.1 %.
//! Skipped (with a message) when `ccx` is not on PATH; CI installs it.

mod calculix_support;

use std::collections::HashMap;

use calculix_support::{dense_frequencies, max_rel_diff, two_cantilevers, CLEARANCE};
use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use rigtwin::fe::calculix::{
    ccx_available, ccx_command, condense_internal_dofs, export, import, read_dat_frequencies,
    run_ccx,
};
use rigtwin::fe::{assemble, DofGroup};

fn max_abs(m: &Mat<f64>) -> f64 {
    let mut a: f64 = 0.0;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            a = a.max(m[(i, j)].abs());
        }
    }
    a
}

#[test]
fn ccx_matrices_condensed_equal_the_native_assembly() {
    if !ccx_available() {
        assert!(
            !rigtwin::fe::calculix::ccx_required(),
            "RIGTWIN_REQUIRE_CCX is set but ccx cannot be started"
        );
        eprintln!(
            "SKIPPED: `{}` is not on PATH (install calculix-ccx)",
            ccx_command()
        );
        return;
    }
    let mesh = two_cantilevers();
    let dir = tempfile::tempdir().unwrap();
    let files = export(&mesh, dir.path(), "beams", 10).unwrap();
    let dat = run_ccx(dir.path(), &files.job).unwrap().dat;
    let ccx_freqs = read_dat_frequencies(&dat).unwrap();
    let run = run_ccx(dir.path(), &files.matrix_job).unwrap();
    let ccx = import(&run.job_path).unwrap();
    let native = assemble(&mesh, CLEARANCE).expect("native assembly");

    // Node DOFs of ccx <-> native DOFs, by (node, direction).
    let native_index: HashMap<(usize, u8), usize> = native
        .dofs
        .iter()
        .enumerate()
        .map(|(i, d)| ((d.node, d.dir), i))
        .collect();
    let (mut r, mut internal) = (Vec::new(), Vec::new());
    for (i, d) in ccx.dofs.iter().enumerate() {
        if d.group == DofGroup::Internal {
            internal.push(i);
        } else {
            r.push(i);
        }
    }
    assert_eq!(r.len(), native.n_dof(), "same node DOFs");
    let to_native: Vec<usize> = r
        .iter()
        .map(|&i| native_index[&(ccx.dofs[i].node, ccx.dofs[i].dir)])
        .collect();
    for (a, &i) in r.iter().enumerate() {
        let (c, n) = (&ccx.dofs[i], &native.dofs[to_native[a]]);
        assert_eq!(c.group, n.group, "group of {c:?}");
        assert_eq!(ccx.base[i], native.base[to_native[a]]);
    }

    // Guyan reduction of ccx's (K, M) onto the node DOFs: u_i = T u_r, T = -Kii^-1 Kir.
    let (kc, mc) = (ccx.k.to_dense(), ccx.m.to_dense());
    let sub = |m: &Mat<f64>, rows: &[usize], cols: &[usize]| {
        Mat::from_fn(rows.len(), cols.len(), |a, b| m[(rows[a], cols[b])])
    };
    let kii = sub(&kc, &internal, &internal);
    let kir = sub(&kc, &internal, &r);
    let t = -kii
        .llt(Side::Lower)
        .expect("bubble stiffness > 0")
        .solve(&kir);
    let kg = sub(&kc, &r, &r) + sub(&kc, &r, &internal) * &t;
    let mri_t = sub(&mc, &r, &internal) * &t;
    let mg = sub(&mc, &r, &r)
        + &mri_t
        + mri_t.transpose()
        + t.transpose() * sub(&mc, &internal, &internal) * &t;

    let (kn, mn) = (native.k.to_dense(), native.m.to_dense());
    let kn = Mat::from_fn(r.len(), r.len(), |a, b| kn[(to_native[a], to_native[b])]);
    let mn = Mat::from_fn(r.len(), r.len(), |a, b| mn[(to_native[a], to_native[b])]);
    let dk = max_abs(&(&kg - &kn)) / max_abs(&kn);
    let dm = max_abs(&(&mg - &mn)) / max_abs(&mn);
    eprintln!("max |K_ccx,condensed - K_native| / max |K_native| = {dk:.2e}");
    eprintln!("max |M_ccx,condensed - M_native| / max |M_native| = {dm:.2e}");
    // ccx writes 13 significant digits
    assert!(dk < 1e-10, "stiffness differs: {dk:e}");
    assert!(dm < 1e-10, "mass differs: {dm:e}");

    // The library's sparse condensation gives the same, with the index data renumbered.
    let condensed = condense_internal_dofs(&ccx).expect("condense");
    assert_eq!(
        condensed.dofs, native.dofs,
        "ccx and native number node DOFs alike"
    );
    let dk2 = max_abs(&(condensed.k.to_dense() - native.k.to_dense())) / max_abs(&kn);
    let dm2 = max_abs(&(condensed.m.to_dense() - native.m.to_dense())) / max_abs(&mn);
    eprintln!("condense_internal_dofs: dK {dk2:.2e}, dM {dm2:.2e}");
    assert!(dk2 < 1e-10 && dm2 < 1e-10, "{dk2:e} {dm2:e}");
    assert_eq!(condensed.pairs, native.pairs);
    assert_eq!(condensed.outputs, native.outputs);
    assert_eq!(condensed.base, native.base);

    // Frequencies: native vs ccx's own eigen solution, where the bubble DOFs are dynamic.
    // Condensing them with the static response stiffens the higher modes of this coarse
    // mesh (8 cells along the beam): 0.17 % at modes 9-10 (7.2 kHz, 17 f1); the first 8
    // modes must agree within 0.1 %.
    let ours = dense_frequencies(&native.k, &native.m, ccx_freqs.len());
    eprintln!("ccx    {ccx_freqs:.2?}\nnative {ours:.2?}");
    let diff8 = max_rel_diff(&ours[..8], &ccx_freqs[..8]);
    let diff10 = max_rel_diff(&ours, &ccx_freqs);
    eprintln!("max relative difference: modes 1-8 {diff8:.2e}, modes 1-10 {diff10:.2e}");
    assert!(diff8 < 1e-3, "{diff8:e}");
    assert!(diff10 < 3e-3, "{diff10:e}");

    // Index data.
    assert_eq!(ccx.pairs.len(), native.pairs.len());
    for (p, q) in ccx.pairs.iter().zip(&native.pairs) {
        for c in 0..3 {
            let lower = r.iter().position(|&i| i == p.lower[c]).unwrap();
            let upper = r.iter().position(|&i| i == p.upper[c]).unwrap();
            assert_eq!(to_native[lower], q.lower[c]);
            assert_eq!(to_native[upper], q.upper[c]);
        }
        assert_eq!((p.frame, p.area), (q.frame, q.area));
    }
    assert!((ccx.clearance - native.clearance).abs() < 1e-15);
    assert_eq!(ccx.outputs.len(), native.outputs.len());
    for (o, q) in ccx.outputs.iter().zip(&native.outputs) {
        assert_eq!(o.name, q.name);
        let mapped: Vec<(usize, f64)> = o
            .terms
            .iter()
            .map(|&(i, w)| (to_native[r.iter().position(|&j| j == i).unwrap()], w))
            .collect();
        assert_eq!(mapped, q.terms);
    }
}
