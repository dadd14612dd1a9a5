//! Shared by the `calculix_*` tests: a small two-cantilever mesh with everything the
//! CalculiX exchange carries (C3D8I and C3D8 blocks, interface springs, point masses, fixed
//! nodes, contact pairs, sensors, node sets) and a dense generalized eigen solver.
#![allow(dead_code)]

use std::collections::BTreeMap;

use faer::sparse::SparseColMat;
use faer::{Mat, Par, Side};
use rigtwin::fe::grid::{graded, BoxGrid};
use rigtwin::fe::{
    ContactPair, ElementBlock, ElementKind, HexElement, Material, Mesh, PointMass, SensorPoint,
    Spring,
};

/// Beam length, width, thickness and clearance of the test rig, m.
pub const LENGTH: f64 = 0.1;
pub const WIDTH: f64 = 0.02;
pub const THICKNESS: [f64; 2] = [0.006, 0.007];
pub const CLEARANCE: f64 = 5e-4;
/// Interface stiffness per area of the clamp layers (normal, tangential), N/m^3.
pub const LAYER_STIFFNESS: [f64; 2] = [2e13, 8e12];
/// Number of cells along the beam.
pub const NX: usize = 8;

/// Half-spacing tributary lengths of grid lines.
fn tributary(lines: &[f64]) -> Vec<f64> {
    (0..lines.len())
        .map(|i| {
            let l = if i > 0 { lines[i] - lines[i - 1] } else { 0.0 };
            let r = if i + 1 < lines.len() {
                lines[i + 1] - lines[i]
            } else {
                0.0
            };
            0.5 * (l + r)
        })
        .collect()
}

/// Two steel cantilevers along x (lower z in [0, 6 mm], upper 0.5 mm above it, 7 mm thick),
/// each joined at x = 0 by an elastic layer to a clamp block whose far face is fixed. The
/// beams are C3D8I except their last cell column (the probes, C3D8); the contact patch is the
/// top face of the lower probe against the bottom face of the upper probe (2 x 3 node pairs).
pub fn two_cantilevers() -> Mesh {
    let steel = Material {
        name: "steel".into(),
        youngs_modulus: 2.1e11,
        poisson_ratio: 0.3,
        density: 7850.0,
    };
    let clamp_steel = Material {
        name: "clamp steel".into(),
        density: 7800.0,
        ..steel.clone()
    };
    let mut mesh = Mesh {
        materials: vec![steel, clamp_steel],
        blocks: vec![
            block("lower_beam", 0, ElementKind::Hex8I),
            block("lower_probe", 0, ElementKind::Hex8),
            block("upper_beam", 0, ElementKind::Hex8I),
            block("upper_probe", 0, ElementKind::Hex8),
            block("clamp", 1, ElementKind::Hex8),
        ],
        layers: vec!["lower clamp".into(), "upper clamp".into()],
        ..Default::default()
    };
    let xs = graded(0.0, LENGTH, NX, 0.5);
    let ys = [0.0, 0.4 * WIDTH, WIDTH];
    let (wy, nx1) = (tributary(&ys), xs.len());
    let mut sets: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    let mut tips = Vec::new();
    for (b, name) in ["LOWER", "UPPER"].iter().enumerate() {
        let z0 = if b == 0 {
            0.0
        } else {
            THICKNESS[0] + CLEARANCE
        };
        let zs = [z0, z0 + THICKNESS[b]];
        let wz = tributary(&zs);
        let beam = BoxGrid::new(&xs, &ys, &zs, |p| p);
        let off = mesh.nodes.len();
        mesh.nodes.extend_from_slice(&beam.nodes);
        for (c, cell) in beam.cells.iter().enumerate() {
            let probe = c % (nx1 - 1) == nx1 - 2;
            mesh.elements.push(HexElement {
                nodes: cell.map(|n| n + off),
                block: 2 * b + usize::from(probe),
            });
        }
        sets.entry(name.to_string())
            .or_default()
            .extend(off..off + beam.nodes.len());
        let clamp = BoxGrid::new(&[-0.01, 0.0], &ys, &zs, |p| p);
        let coff = mesh.nodes.len();
        mesh.nodes.extend_from_slice(&clamp.nodes);
        for cell in &clamp.cells {
            mesh.elements.push(HexElement {
                nodes: cell.map(|n| n + coff),
                block: 4,
            });
        }
        sets.entry("CLAMP".into())
            .or_default()
            .extend(coff..coff + clamp.nodes.len());
        for (k, wz_k) in wz.iter().enumerate() {
            for (j, wy_j) in wy.iter().enumerate() {
                let area = wy_j * wz_k;
                mesh.springs.push(Spring {
                    a: coff + clamp.node(1, j, k),
                    b: off + beam.node(0, j, k),
                    stiffness: [
                        LAYER_STIFFNESS[0] * area,
                        LAYER_STIFFNESS[1] * area,
                        LAYER_STIFFNESS[1] * area,
                    ],
                    layer: b,
                });
                mesh.fixed_nodes.push(coff + clamp.node(0, j, k));
            }
        }
        let accel_k = if b == 0 { 0 } else { 1 };
        mesh.point_masses.push(PointMass {
            name: format!("{}_accelerometer", name.to_lowercase()),
            node: off + beam.node(nx1 - 1, 1, accel_k),
            mass: 0.002,
        });
        mesh.sensors.push(SensorPoint {
            name: format!("{}_tip", name.to_lowercase()),
            node: off + beam.node(nx1 - 1, 1, accel_k),
            direction: [0.0, 0.0, 1.0],
        });
        if b == 1 {
            mesh.sensors.push(SensorPoint {
                name: "upper_mid".into(),
                node: off + beam.node(nx1 / 2, 1, 1),
                direction: [0.0, 0.6, 0.8],
            });
        }
        tips.push((off, beam));
    }
    // Contact patch: last two x grid lines, all y lines.
    let (lo, lg) = &tips[0];
    let (uo, ug) = &tips[1];
    let px = [xs[nx1 - 2], xs[nx1 - 1]];
    let wx = tributary(&px);
    for (j, wy_j) in wy.iter().enumerate() {
        for (i, &w) in wx.iter().enumerate() {
            mesh.contact_pairs.push(ContactPair {
                lower: lo + lg.node(nx1 - 2 + i, j, 1),
                upper: uo + ug.node(nx1 - 2 + i, j, 0),
                frame: [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                area: w * wy_j,
            });
        }
    }
    let mut lower: Vec<usize> = mesh.contact_pairs.iter().map(|p| p.lower).collect();
    let mut upper: Vec<usize> = mesh.contact_pairs.iter().map(|p| p.upper).collect();
    lower.sort_unstable();
    upper.sort_unstable();
    sets.insert("CONTACT_LOWER".into(), lower);
    sets.insert("CONTACT_UPPER".into(), upper);
    let mut fixed = mesh.fixed_nodes.clone();
    fixed.sort_unstable();
    sets.insert("FIXED".into(), fixed);
    mesh.node_sets = sets;
    mesh
}

fn block(name: &str, material: usize, kind: ElementKind) -> ElementBlock {
    ElementBlock {
        name: name.into(),
        material,
        kind,
    }
}

/// Eigenvalues mu = 1/omega^2 of `M x = mu K x` (K > 0, M >= 0), descending: the first
/// entries belong to the lowest frequencies, zeros to massless DOF combinations.
pub fn dense_inverse_eigenvalues(
    k: &SparseColMat<usize, f64>,
    m: &SparseColMat<usize, f64>,
) -> Vec<f64> {
    // NOTE: ccx's C3D8I mass matrix is only semidefinite (see fe::calculix), so the
    // Cholesky factor is taken of K and the problem solved for 1/omega^2.
    let stiffness: Mat<f64> = k.to_dense();
    let mut a: Mat<f64> = m.to_dense();
    let llt = stiffness
        .llt(Side::Lower)
        .expect("stiffness matrix positive definite");
    let l = llt.L();
    // B = L^-1 M L^-T
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, a.as_mut(), Par::Seq);
    let mut at = a.transpose().to_owned();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, at.as_mut(), Par::Seq);
    let sym = (&at + at.transpose()) * 0.5;
    let mut mu = sym
        .self_adjoint_eigenvalues(Side::Lower)
        .expect("symmetric eigenvalues");
    mu.reverse();
    mu
}

/// Frequencies, Hz, of the `count` lowest modes of `K x = omega^2 M x`.
pub fn dense_frequencies(
    k: &SparseColMat<usize, f64>,
    m: &SparseColMat<usize, f64>,
    count: usize,
) -> Vec<f64> {
    dense_inverse_eigenvalues(k, m)
        .iter()
        .take(count)
        .map(|&mu| 1.0 / (2.0 * std::f64::consts::PI * mu.sqrt()))
        .collect()
}

/// Largest relative difference of two frequency lists of equal length.
pub fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / y.abs())
        .fold(0.0, f64::max)
}
