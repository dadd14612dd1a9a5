//! Best-effort mode labels `<order><F|E|T|A><L|U|C>` (1FL, 1FU, 1EL, ..., 2FL) from the mode
//! shapes, as the reference names its modes: F flap-wise (z) bending, E edge-wise (y) bending,
//! T torsion, A axial (x); L lower beam, U upper beam, C clamping.
//!
//! - Part: the group ([`DofGroup`]) holding most of the mode's kinetic energy
//!   `phi_i (M phi)_i` (internal DOFs without a node are ignored).
//! - Type: within that part, the direction with most kinetic energy (z flap, y edge, x axial);
//!   a z-dominant mode is torsion when its z motion is mostly antisymmetric across the width:
//!   at each x-station of the part, `w = a + b dy` is fitted (dy the offset from the station's
//!   centre line) and the antisymmetric part `b dy` carries more than half of the sum of w^2.
//! - Order: running count per (type, part) in ascending frequency.

use std::collections::HashMap;

use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, Mat, MatRef};

use crate::fe::{DofGroup, FeModel};

/// Kind of a mode shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModeKind {
    /// Flap-wise (z) bending.
    Flap,
    /// Edge-wise (y) bending.
    Edge,
    /// Torsion about the beam axis (x).
    Torsion,
    /// Axial (x).
    Axial,
}

impl ModeKind {
    /// The label letter.
    pub fn letter(self) -> char {
        match self {
            ModeKind::Flap => 'F',
            ModeKind::Edge => 'E',
            ModeKind::Torsion => 'T',
            ModeKind::Axial => 'A',
        }
    }
}

/// Classification of one mode shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeClass {
    /// Part with most kinetic energy (Lower, Upper or Clamp).
    pub group: DofGroup,
    /// Mode type.
    pub kind: ModeKind,
    /// Share of the kinetic energy in that part, 0..1.
    pub energy_share: f64,
    /// Share of the part's z motion that is antisymmetric across the width, 0..1.
    pub torsion_share: f64,
}

fn group_letter(g: DofGroup) -> char {
    match g {
        DofGroup::Lower => 'L',
        DofGroup::Upper => 'U',
        DofGroup::Clamp => 'C',
        DofGroup::Internal => 'I',
    }
}

fn group_slot(g: DofGroup) -> Option<usize> {
    match g {
        DofGroup::Lower => Some(0),
        DofGroup::Upper => Some(1),
        DofGroup::Clamp => Some(2),
        DofGroup::Internal => None,
    }
}

const GROUPS: [DofGroup; 3] = [DofGroup::Lower, DofGroup::Upper, DofGroup::Clamp];

/// Classifies one mode from its shape `phi` and `M phi` (both of length n_dof). Returns None
/// when no node DOF carries kinetic energy.
pub fn classify_mode(model: &FeModel, phi: &[f64], m_phi: &[f64]) -> Option<ModeClass> {
    let n_nodes = model.n_nodes();
    let mut energy = [[0.0f64; 3]; 3];
    for (i, info) in model.dofs.iter().enumerate() {
        let (Some(g), Some(&p), Some(&mp)) = (group_slot(info.group), phi.get(i), m_phi.get(i))
        else {
            continue;
        };
        if info.node >= n_nodes || info.dir > 2 {
            continue;
        }
        energy[g][info.dir as usize] += p * mp;
    }
    let totals: Vec<f64> = energy.iter().map(|e| e.iter().sum::<f64>()).collect();
    let all: f64 = totals.iter().map(|t| t.max(0.0)).sum();
    let (g, &best) = totals
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    if best.is_nan() || best <= 0.0 {
        return None;
    }
    let group = GROUPS[g];
    let e = energy[g];
    let dir = (0..3).max_by(|&a, &b| e[a].total_cmp(&e[b])).unwrap_or(2);
    let torsion_share = torsion_share(model, group, phi);
    let kind = if dir == 2 && torsion_share > 0.5 {
        ModeKind::Torsion
    } else {
        match dir {
            0 => ModeKind::Axial,
            1 => ModeKind::Edge,
            _ => ModeKind::Flap,
        }
    };
    Some(ModeClass {
        group,
        kind,
        energy_share: best / all,
        torsion_share,
    })
}

/// Share of the z motion of `group`'s nodes that is antisymmetric across the width: per
/// x-station, `w = a + b dy` fitted by least squares, share = sum (b dy)^2 / sum w^2.
fn torsion_share(model: &FeModel, group: DofGroup, phi: &[f64]) -> f64 {
    // z displacements of the group's nodes.
    let mut w_of: HashMap<usize, f64> = HashMap::new();
    for (i, info) in model.dofs.iter().enumerate() {
        if info.group != group || info.node >= model.n_nodes() || info.dir != 2 {
            continue;
        }
        if let Some(&p) = phi.get(i) {
            w_of.insert(info.node, p);
        }
    }
    if w_of.len() < 2 {
        return 0.0;
    }
    let mut nodes: Vec<usize> = w_of.keys().copied().collect();
    nodes.sort_by(|&a, &b| model.node_coords[a][0].total_cmp(&model.node_coords[b][0]));
    let x_of = |n: usize| model.node_coords[n][0];
    let extent = x_of(nodes[nodes.len() - 1]) - x_of(nodes[0]);
    let tol = 1e-9 * extent.abs().max(f64::MIN_POSITIVE);
    let (mut anti, mut total) = (0.0, 0.0);
    let mut start = 0;
    while start < nodes.len() {
        let mut end = start + 1;
        while end < nodes.len() && x_of(nodes[end]) - x_of(nodes[end - 1]) <= tol {
            end += 1;
        }
        let station = &nodes[start..end];
        start = end;
        let yc = station
            .iter()
            .map(|&n| model.node_coords[n][1])
            .sum::<f64>()
            / station.len() as f64;
        let (mut num, mut den, mut sq) = (0.0, 0.0, 0.0);
        for &n in station {
            let w = w_of[&n];
            let dy = model.node_coords[n][1] - yc;
            num += w * dy;
            den += dy * dy;
            sq += w * w;
        }
        total += sq;
        if den > 0.0 {
            anti += num * num / den;
        }
    }
    if total > 0.0 {
        (anti / total).min(1.0)
    } else {
        0.0
    }
}

/// Labels for the columns of `vectors` (mode shapes on the model's free DOFs, ascending
/// frequency). Modes that cannot be classified are labelled "?".
pub fn label_modes(model: &FeModel, vectors: MatRef<'_, f64>) -> Vec<String> {
    let n = model.n_dof();
    if vectors.nrows() != n || model.m.nrows() != n || model.m.ncols() != n {
        return vec!["?".to_string(); vectors.ncols()];
    }
    let mut m_phi = Mat::<f64>::zeros(n, vectors.ncols());
    sparse_dense_matmul(
        m_phi.as_mut(),
        Accum::Replace,
        model.m.as_ref(),
        vectors,
        1.0,
        faer::get_global_parallelism(),
    );
    let mut counts: HashMap<(char, char), usize> = HashMap::new();
    (0..vectors.ncols())
        .map(|j| {
            let phi: Vec<f64> = vectors.col(j).iter().copied().collect();
            let mphi: Vec<f64> = m_phi.col(j).iter().copied().collect();
            match classify_mode(model, &phi, &mphi) {
                Some(c) => {
                    let key = (c.kind.letter(), group_letter(c.group));
                    let order = counts.entry(key).or_insert(0);
                    *order += 1;
                    format!("{}{}{}", order, key.0, key.1)
                }
                None => "?".to_string(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fe::DofInfo;
    use faer::sparse::{SparseColMat, Triplet};

    /// Two flat beams (x along the length, 5 stations x 3 across the width y x 2 through the
    /// thickness z), lower at z = 0, upper at z = 1, unit lumped masses.
    fn two_beams() -> FeModel {
        let mut node_coords = Vec::new();
        let mut dofs = Vec::new();
        for (b, group) in [DofGroup::Lower, DofGroup::Upper].into_iter().enumerate() {
            for i in 0..5 {
                for j in 0..3 {
                    for k in 0..2 {
                        let node = node_coords.len();
                        node_coords.push([
                            i as f64 + 1.0,
                            j as f64 * 2.0 - 2.0,
                            b as f64 + 0.2 * k as f64,
                        ]);
                        for dir in 0..3 {
                            dofs.push(DofInfo { node, dir, group });
                        }
                    }
                }
            }
        }
        let n = dofs.len();
        let eye: Vec<Triplet<usize, usize, f64>> =
            (0..n).map(|i| Triplet::new(i, i, 1.0)).collect();
        let m = SparseColMat::try_new_from_triplets(n, n, &eye).unwrap();
        FeModel {
            k: m.clone(),
            m,
            dofs,
            base: vec![0.0; n],
            pairs: Vec::new(),
            clearance: 0.0,
            outputs: Vec::new(),
            node_coords,
            n_elements: 0,
        }
    }

    fn shape(model: &FeModel, group: DofGroup, f: impl Fn([f64; 3]) -> [f64; 3]) -> Vec<f64> {
        model
            .dofs
            .iter()
            .map(|d| {
                if d.group == group {
                    f(model.node_coords[d.node])[d.dir as usize]
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn flap_edge_torsion_axial_and_order() {
        let model = two_beams();
        let modes = [
            shape(&model, DofGroup::Lower, |x| [0.0, 0.0, x[0] * x[0]]),
            shape(&model, DofGroup::Upper, |x| [0.0, 0.0, x[0] * x[0]]),
            shape(&model, DofGroup::Lower, |x| [0.0, x[0] * x[0], 0.1 * x[0]]),
            shape(&model, DofGroup::Upper, |x| {
                [0.0, -0.3 * x[0] * (x[2] - 1.1), x[0] * x[1]]
            }),
            shape(&model, DofGroup::Lower, |x| [x[0], 0.0, 0.0]),
            shape(&model, DofGroup::Lower, |x| {
                [0.0, 0.0, x[0] * x[0] * (x[0] - 3.0)]
            }),
        ];
        let n = model.n_dof();
        let v = Mat::<f64>::from_fn(n, modes.len(), |i, j| modes[j][i]);
        let labels = label_modes(&model, v.as_ref());
        assert_eq!(labels, ["1FL", "1FU", "1EL", "1TU", "1AL", "2FL"]);
    }

    #[test]
    fn unclassifiable_mode() {
        let model = two_beams();
        let v = Mat::<f64>::zeros(model.n_dof(), 1);
        assert_eq!(label_modes(&model, v.as_ref()), ["?"]);
    }
}
