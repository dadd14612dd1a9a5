//! Static condensation of the internal DOFs of an imported model (ccx's C3D8I bubble DOFs)
//! onto the node DOFs, with the static internal response (Guyan): the model the native
//! Hex8I element builds. Pure numerics.

use std::collections::{BTreeSet, HashMap};

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

use crate::fe::model::{DofGroup, FeModel, OutputDofs, PairDofs};

/// Why the internal DOFs could not be condensed.
#[derive(Debug, thiserror::Error)]
pub enum CondenseError {
    /// The stiffness of a group of coupled internal DOFs is not positive definite.
    #[error(
        "the stiffness of the internal DOFs {dofs:?} (free-DOF indices) is not positive \
         definite: expected each group of coupled internal DOFs to be restrained by its element"
    )]
    NotPositiveDefinite {
        /// The group's free-DOF indices.
        dofs: Vec<usize>,
    },
    /// A pair or sensor refers to an internal DOF (only node DOFs can be kept).
    #[error("{what} refers to internal DOF {dof}: expected node DOFs only")]
    InternalReference {
        /// "contact pair k" or "sensor NAME".
        what: String,
        /// The free-DOF index.
        dof: usize,
    },
    /// The condensed matrices could not be built.
    #[error("cannot build the condensed {n}x{n} matrices: {what}")]
    Build {
        /// Dimension.
        n: usize,
        /// faer's reason.
        what: String,
    },
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Condenses every [`DofGroup::Internal`] DOF of `model`: with internal DOFs `i` and node
/// DOFs `r`, `T = -K_ii^-1 K_ir`, `K' = K_rr + K_ri T`,
/// `M' = M_rr + M_ri T + T^T M_ir + T^T M_ii T`. Groups of internal DOFs coupled to each
/// other (one C3D8I element each) are condensed one at a time with small dense solves. The
/// result keeps the node DOFs in their order, with pairs, sensors and the base vector
/// renumbered. A model without internal DOFs is returned unchanged (cloned).
///
/// For ccx's C3D8I this reproduces the native [`assemble`](crate::fe::assemble) matrices of
/// the same mesh to round-off (measured 2e-14 relative on the two-cantilever test mesh).
pub fn condense_internal_dofs(model: &FeModel) -> Result<FeModel, CondenseError> {
    let n = model.n_dof();
    let is_internal: Vec<bool> = model
        .dofs
        .iter()
        .map(|d| d.group == DofGroup::Internal)
        .collect();
    if !is_internal.iter().any(|&b| b) {
        return Ok(model.clone());
    }
    let mut new_index = vec![usize::MAX; n];
    let mut kept = 0;
    for (i, &internal) in is_internal.iter().enumerate() {
        if !internal {
            new_index[i] = kept;
            kept += 1;
        }
    }

    // Groups of coupled internal DOFs (union-find over K and M couplings).
    let mut parent: Vec<usize> = (0..n).collect();
    for mat in [&model.k, &model.m] {
        for j in (0..n).filter(|&j| is_internal[j]) {
            for &i in mat.row_idx_of_col_raw(j) {
                if is_internal[i] {
                    let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                    parent[a] = b;
                }
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for j in (0..n).filter(|&j| is_internal[j]) {
        let root = find(&mut parent, j);
        groups.entry(root).or_default().push(j);
    }
    let mut groups: Vec<Vec<usize>> = groups.into_values().collect();
    groups.sort();

    let mut kt = Vec::new();
    let mut mt = Vec::new();
    for (mat, out) in [(&model.k, &mut kt), (&model.m, &mut mt)] {
        for j in (0..n).filter(|&j| !is_internal[j]) {
            let rows = mat.row_idx_of_col_raw(j);
            let vals = mat.val_of_col(j);
            for (&i, &v) in rows.iter().zip(vals) {
                if !is_internal[i] {
                    out.push(Triplet::new(new_index[i], new_index[j], v));
                }
            }
        }
    }

    for b in &groups {
        // Node DOFs coupled to the group.
        let mut r: BTreeSet<usize> = BTreeSet::new();
        for mat in [&model.k, &model.m] {
            for &j in b {
                r.extend(
                    mat.row_idx_of_col_raw(j)
                        .iter()
                        .copied()
                        .filter(|&i| !is_internal[i]),
                );
            }
        }
        let r: Vec<usize> = r.into_iter().collect();
        let dense = |mat: &SparseColMat<usize, f64>, rows: &[usize], cols: &[usize]| {
            let pos: HashMap<usize, usize> =
                rows.iter().enumerate().map(|(a, &i)| (i, a)).collect();
            let mut d = Mat::<f64>::zeros(rows.len(), cols.len());
            for (c, &j) in cols.iter().enumerate() {
                let (ri, vals) = (mat.row_idx_of_col_raw(j), mat.val_of_col(j));
                for (&i, &v) in ri.iter().zip(vals) {
                    if let Some(&a) = pos.get(&i) {
                        d[(a, c)] = v;
                    }
                }
            }
            d
        };
        let kbb = dense(&model.k, b, b);
        let kbr = dense(&model.k, b, &r);
        let mbb = dense(&model.m, b, b);
        let mbr = dense(&model.m, b, &r);
        let llt = kbb
            .llt(Side::Lower)
            .map_err(|_| CondenseError::NotPositiveDefinite { dofs: b.clone() })?;
        let t = -llt.solve(&kbr);
        let dk = kbr.transpose() * &t;
        let mrt = mbr.transpose() * &t;
        let dm = &mrt + mrt.transpose() + t.transpose() * &mbb * &t;
        for (a, &ia) in r.iter().enumerate() {
            for (c, &ic) in r.iter().enumerate() {
                // NOTE: both corrections are symmetric in exact arithmetic; averaging the
                // two triangles keeps K' and M' exactly symmetric.
                let k = 0.5 * (dk[(a, c)] + dk[(c, a)]);
                let m = 0.5 * (dm[(a, c)] + dm[(c, a)]);
                kt.push(Triplet::new(new_index[ia], new_index[ic], k));
                mt.push(Triplet::new(new_index[ia], new_index[ic], m));
            }
        }
    }
    let build = |t: &[Triplet<usize, usize, f64>]| {
        SparseColMat::try_new_from_triplets(kept, kept, t).map_err(|e| CondenseError::Build {
            n: kept,
            what: format!("{e:?}"),
        })
    };
    let (k, m) = (build(&kt)?, build(&mt)?);

    let remap = |dof: usize, what: &dyn Fn() -> String| {
        if is_internal[dof] {
            Err(CondenseError::InternalReference { what: what(), dof })
        } else {
            Ok(new_index[dof])
        }
    };
    let mut pairs = Vec::with_capacity(model.pairs.len());
    for (p_i, p) in model.pairs.iter().enumerate() {
        let what = || format!("contact pair {p_i}");
        let mut lower = [0; 3];
        let mut upper = [0; 3];
        for c in 0..3 {
            lower[c] = remap(p.lower[c], &what)?;
            upper[c] = remap(p.upper[c], &what)?;
        }
        pairs.push(PairDofs { lower, upper, ..*p });
    }
    let mut outputs = Vec::with_capacity(model.outputs.len());
    for o in &model.outputs {
        let what = || format!("sensor {}", o.name);
        let terms = o
            .terms
            .iter()
            .map(|&(d, w)| remap(d, &what).map(|i| (i, w)))
            .collect::<Result<Vec<_>, _>>()?;
        outputs.push(OutputDofs {
            name: o.name.clone(),
            terms,
        });
    }
    let keep = |i: &usize| !is_internal[*i];
    Ok(FeModel {
        k,
        m,
        dofs: (0..n).filter(keep).map(|i| model.dofs[i]).collect(),
        base: (0..n).filter(keep).map(|i| model.base[i]).collect(),
        pairs,
        clearance: model.clearance,
        outputs,
        node_coords: model.node_coords.clone(),
        n_elements: model.n_elements,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fe::model::DofInfo;

    /// Node DOF 0 tied to ground through an internal DOF 1: springs k (0-1) and k (1-ground).
    fn chain(k_ground: f64) -> FeModel {
        let (k, m0, mi) = (3.0, 2.0, 0.5);
        let t = |r, c, v| Triplet::new(r, c, v);
        let kk = SparseColMat::try_new_from_triplets(
            2,
            2,
            &[t(0, 0, k), t(0, 1, -k), t(1, 0, -k), t(1, 1, k + k_ground)],
        )
        .unwrap();
        let mm = SparseColMat::try_new_from_triplets(2, 2, &[t(0, 0, m0), t(1, 1, mi)]).unwrap();
        let dof = |node, group| DofInfo {
            node,
            dir: 2,
            group,
        };
        FeModel {
            k: kk,
            m: mm,
            dofs: vec![dof(0, DofGroup::Lower), dof(1, DofGroup::Internal)],
            base: vec![1.0, 0.0],
            pairs: vec![],
            clearance: 0.0,
            outputs: vec![OutputDofs {
                name: "tip".into(),
                terms: vec![(0, 1.0)],
            }],
            node_coords: vec![[0.0; 3]],
            n_elements: 1,
        }
    }

    #[test]
    fn spring_chain_condenses_to_series_stiffness_and_guyan_mass() {
        let c = condense_internal_dofs(&chain(3.0)).unwrap();
        let (k, m) = (c.k.to_dense(), c.m.to_dense());
        assert_eq!((k.nrows(), c.dofs.len(), c.base.len()), (1, 1, 1));
        // series springs 3 and 3; internal DOF follows with T = 1/2
        assert!((k[(0, 0)] - 1.5).abs() < 1e-15);
        assert!((m[(0, 0)] - (2.0 + 0.25 * 0.5)).abs() < 1e-15);
        assert_eq!(c.outputs[0].terms, vec![(0, 1.0)]);
    }

    #[test]
    fn unrestrained_internal_dof_is_an_error() {
        // K_ii = k - k = 0 with a negative ground spring: not positive definite
        let err = condense_internal_dofs(&chain(-3.0)).unwrap_err();
        assert!(matches!(err, CondenseError::NotPositiveDefinite { ref dofs } if dofs == &[1]));
    }
}
