//! Guards the native FE parent model (C3D8I element matrices + sparse assembly) against beam
//! theory: a uniform steel cantilever 300 x 20 x 6 mm at the project's default beam
//! resolution (60 x 4 x 2 hex elements) must give the first three vertical (z) bending
//! frequencies within 1 % and the first edgewise (y) bending frequency within 2 % of
//! Euler-Bernoulli, while plain C3D8 on the same mesh locks (is clearly too stiff), so a
//! broken incompatible-mode element cannot pass. Also reports the assembly time of a
//! 30k-DOF box mesh.

mod support;

use std::f64::consts::PI;
use std::time::Instant;

use rigtwin::fe::{assemble, ElementKind, FeModel, Material};
use support::{box_cantilever, effective_mass_fractions, linspace, lowest_modes, Mode};

const L: f64 = 0.300;
const B: f64 = 0.020;
const H: f64 = 0.006;
const E: f64 = 210e9;
const RHO: f64 = 7850.0;
const BETA_L: [f64; 3] = [1.875_104_07, 4.694_091_13, 7.854_757_44];

fn steel() -> Material {
    Material {
        name: "steel".into(),
        youngs_modulus: E,
        poisson_ratio: 0.3,
        density: RHO,
    }
}

fn beam(kind: ElementKind) -> FeModel {
    let mesh = box_cantilever(
        &linspace(0.0, L, 60),
        &linspace(-B / 2.0, B / 2.0, 4),
        &linspace(-H / 2.0, H / 2.0, 2),
        kind,
        steel(),
        |p| p,
    );
    assemble(&mesh, 0.0).expect("valid cantilever mesh")
}

/// Euler-Bernoulli cantilever frequency, Hz, for bending stiffness with second moment `i`.
fn euler_bernoulli(beta_l: f64, i: f64) -> f64 {
    beta_l * beta_l / (2.0 * PI * L * L) * (E * i / (RHO * B * H)).sqrt()
}

/// Bending modes along direction `dir` (1 = y, 2 = z): the modes whose effective mass is
/// largest along `dir` (torsion and axial modes carry none along y or z).
fn bending_modes<'a>(model: &FeModel, modes: &'a [Mode], dir: usize) -> Vec<&'a Mode> {
    modes
        .iter()
        .filter(|m| {
            let f = effective_mass_fractions(model, &m.shape);
            f[dir] > 0.01 && f[dir] >= f[0].max(f[1]).max(f[2])
        })
        .collect()
}

#[test]
fn cantilever_bending_frequencies_match_euler_bernoulli() {
    let model = beam(ElementKind::Hex8I);
    assert_eq!(model.n_dof(), 3 * 60 * 5 * 3);
    let modes = lowest_modes(&model, 8);
    for (i, m) in modes.iter().enumerate() {
        let f = effective_mass_fractions(&model, &m.shape);
        println!(
            "mode {:2}: {:9.3} Hz, effective mass x/y/z = {:.4} / {:.4} / {:.4}",
            i + 1,
            m.freq,
            f[0],
            f[1],
            f[2]
        );
    }

    let i_z = B * H.powi(3) / 12.0;
    let vertical = bending_modes(&model, &modes, 2);
    assert!(
        vertical.len() >= 3,
        "found {} vertical modes",
        vertical.len()
    );
    for (n, (m, beta_l)) in vertical.iter().zip(BETA_L).enumerate() {
        let eb = euler_bernoulli(beta_l, i_z);
        let err = m.freq / eb - 1.0;
        println!(
            "vertical bending {}: FE {:9.3} Hz, Euler-Bernoulli {:9.3} Hz, error {:+.3} %",
            n + 1,
            m.freq,
            eb,
            100.0 * err
        );
        assert!(
            err.abs() < 0.01,
            "vertical mode {} off by {:.3} %",
            n + 1,
            100.0 * err
        );
    }

    let i_y = H * B.powi(3) / 12.0;
    let edgewise = bending_modes(&model, &modes, 1);
    assert!(
        !edgewise.is_empty(),
        "no edgewise bending mode among the lowest 8"
    );
    let eb = euler_bernoulli(BETA_L[0], i_y);
    let err = edgewise[0].freq / eb - 1.0;
    println!(
        "edgewise bending 1: FE {:9.3} Hz, Euler-Bernoulli {:9.3} Hz, error {:+.3} %",
        edgewise[0].freq,
        eb,
        100.0 * err
    );
    assert!(
        err.abs() < 0.02,
        "edgewise mode off by {:.3} %",
        100.0 * err
    );
}

#[test]
fn plain_hex8_locks_on_the_same_mesh() {
    let i_z = B * H.powi(3) / 12.0;
    let eb = euler_bernoulli(BETA_L[0], i_z);
    let first_vertical = |kind| {
        let model = beam(kind);
        let modes = lowest_modes(&model, 3);
        bending_modes(&model, &modes, 2)[0].freq
    };
    let f8i = first_vertical(ElementKind::Hex8I);
    let f8 = first_vertical(ElementKind::Hex8);
    println!(
        "first vertical bending: C3D8I {f8i:.3} Hz ({:+.2} %), C3D8 {f8:.3} Hz ({:+.2} %), \
         Euler-Bernoulli {eb:.3} Hz",
        100.0 * (f8i / eb - 1.0),
        100.0 * (f8 / eb - 1.0)
    );
    assert!(
        f8 / eb > 1.10,
        "C3D8 with 2 elements through the thickness should lock (>10 % too stiff)"
    );
    assert!((f8i / eb - 1.0).abs() < 0.01);
}

/// Not a timed assert (timings go to the report): prints the assembly time of a box mesh
/// with 30k free DOFs so regressions are visible in the test log.
#[test]
fn assembly_of_a_30k_dof_box_reports_its_time() {
    let mesh = box_cantilever(
        &linspace(0.0, L, 200),
        &linspace(-B / 2.0, B / 2.0, 9),
        &linspace(-H / 2.0, H / 2.0, 4),
        ElementKind::Hex8I,
        steel(),
        |p| p,
    );
    let start = Instant::now();
    let model = assemble(&mesh, 0.0).expect("valid box mesh");
    let elapsed = start.elapsed();
    println!(
        "assembled {} elements, {} free DOFs, nnz(K) = {} in {:.3} s",
        model.n_elements,
        model.n_dof(),
        model.k.compute_nnz(),
        elapsed.as_secs_f64()
    );
    assert_eq!(model.n_dof(), 3 * 200 * 10 * 5);
    let total: f64 = mesh.total_mass();
    assert!((total - RHO * L * B * H).abs() < 1e-9 * total);
}
