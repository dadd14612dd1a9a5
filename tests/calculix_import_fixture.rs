//! Guards the CalculiX import against files ccx really wrote (sim-fixtures/calculix/
//! cantilever, no ccx needed): the imported K and M reproduce ccx's eigenfrequencies, the DOF
//! table, groups, internal DOFs, contact pairs (from a re-ordered contact set, without
//! metadata), sensors and a few entries derivable by hand; and deck syntax variants (keyword
//! continuation, comments inside data, blank lines, Fortran `D` exponents) parse the same.

mod calculix_support;

use std::path::{Path, PathBuf};

use calculix_support::max_rel_diff;
use rigtwin::fe::calculix::{condense_internal_dofs, import, read_dat_frequencies};
use rigtwin::fe::{DofGroup, FeModel};

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sim-fixtures/calculix/cantilever")
}

fn dof_of(model: &FeModel, ccx_node: usize, dir: u8) -> usize {
    model
        .dofs
        .iter()
        .position(|d| d.node == ccx_node - 1 && d.dir == dir)
        .unwrap_or_else(|| panic!("no DOF {ccx_node}.{}", dir + 1))
}

#[test]
fn fixture_import_reproduces_ccx_and_rebuilds_the_index_data() {
    let model = import(&fixture_dir().join("cantilever")).expect("import fixture");
    let ccx = read_dat_frequencies(&fixture_dir().join("cantilever_freq.dat")).unwrap();
    assert_eq!(ccx.len(), 6);
    let ours = calculix_support::dense_frequencies(&model.k, &model.m, ccx.len());
    let diff = max_rel_diff(&ours, &ccx);
    eprintln!("ccx {ccx:.2?}\nours {ours:.2?}\nmax rel diff {diff:.2e}");
    assert!(diff < 2e-6, "{diff:e}");

    // Condensing the 18 bubble DOFs leaves the 72 node DOFs with a positive definite M.
    let condensed = condense_internal_dofs(&model).unwrap();
    assert_eq!(condensed.n_dof(), 72);
    assert!(condensed.m.to_dense().llt(faer::Side::Lower).is_ok());
    let cf = calculix_support::dense_frequencies(&condensed.k, &condensed.m, ccx.len());
    let cdiff = max_rel_diff(&cf, &ccx);
    eprintln!("condensed {cf:.2?}: max rel diff {cdiff:.2e}");
    assert!(cdiff < 2e-3, "{cdiff:e}");
    assert!(
        cf.iter().zip(&ccx).all(|(c, f)| c >= &(f * (1.0 - 1e-9))),
        "condensing stiffens"
    );

    // 12 lower (4 fixed), 12 upper, 8 clamp (4 fixed) nodes; 2 C3D8I with 3 extra nodes each.
    assert_eq!(model.n_dof(), 3 * (8 + 12 + 4) + 18);
    assert_eq!(model.n_nodes(), 32);
    assert_eq!(model.n_elements, 5);
    for d in &model.dofs {
        let ccx_node = d.node + 1;
        let expected = match ccx_node {
            1..=12 => DofGroup::Lower,
            13..=24 => DofGroup::Upper, // from the element set UPPER
            25..=32 => DofGroup::Clamp,
            _ => DofGroup::Internal,
        };
        assert_eq!(d.group, expected, "{d:?}");
    }
    let internal: Vec<usize> = model
        .dofs
        .iter()
        .filter(|d| d.group == DofGroup::Internal)
        .map(|d| d.node + 1)
        .collect();
    assert_eq!(internal.first(), Some(&33));
    assert_eq!(internal.last(), Some(&38));
    for (i, d) in model.dofs.iter().enumerate() {
        let on_z_of_node = d.dir == 2 && d.group != DofGroup::Internal;
        assert_eq!(model.base[i], if on_z_of_node { 1.0 } else { 0.0 });
    }

    // Both triangles stored, symmetric.
    let k = model.k.to_dense();
    let m = model.m.to_dense();
    for i in 0..model.n_dof() {
        for j in 0..i {
            assert_eq!(k[(i, j)], k[(j, i)]);
            assert_eq!(m[(i, j)], m[(j, i)]);
        }
    }
    // Spring 26-13 along x (1e8 N/m) is the only coupling of these coincident nodes.
    assert_eq!(k[(dof_of(&model, 26, 0), dof_of(&model, 13, 0))], -1e8);
    assert_eq!(k[(dof_of(&model, 26, 1), dof_of(&model, 13, 1))], -5e7);
    // Node 3: corner of one C3D8 (consistent mass rho V / 27) plus the 1 g MASS element.
    let corner = 7850.0 * (0.01 * 0.01 * 0.003) / 27.0;
    let m33 = m[(dof_of(&model, 3, 2), dof_of(&model, 3, 2))];
    assert!((m33 - (corner + 1e-3)).abs() < 1e-12 * m33, "{m33}");

    // Contact pairs: CONTACT_UPPER is listed as 18, 17, 15, 14, paired by position.
    let pairs: Vec<(usize, usize)> = model
        .pairs
        .iter()
        .map(|p| {
            (
                model.dofs[p.lower[0]].node + 1,
                model.dofs[p.upper[0]].node + 1,
            )
        })
        .collect();
    assert_eq!(pairs, [(8, 14), (9, 15), (11, 17), (12, 18)]);
    for p in &model.pairs {
        assert_eq!(p.frame, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        // structured 2 x 2 patch of 10 mm x 10 mm: a quarter each
        assert!((p.area - 2.5e-5).abs() < 1e-18, "{}", p.area);
        for c in 0..3 {
            assert_eq!(model.dofs[p.lower[c]].dir as usize, c);
            assert_eq!(model.dofs[p.upper[c]].dir as usize, c);
        }
    }
    assert!(
        (model.clearance - 5e-4).abs() < 1e-15,
        "{}",
        model.clearance
    );
    assert_eq!(model.pairs[0].position, [0.02, 0.0, 0.003]);

    // Sensors: upper_tip from the metadata comment, lower_tip with the defaults.
    assert_eq!(model.outputs.len(), 2);
    let lower = &model.outputs[0];
    assert_eq!(lower.name, "lower_tip");
    assert_eq!(lower.terms, vec![(dof_of(&model, 3, 2), 1.0)]);
    let upper = &model.outputs[1];
    assert_eq!(upper.name, "upper_tip");
    assert_eq!(
        upper.terms,
        vec![(dof_of(&model, 24, 1), 0.6), (dof_of(&model, 24, 2), 0.8)]
    );
}

#[test]
fn deck_syntax_variants_import_the_same_model() {
    let dir = tempfile::tempdir().unwrap();
    for f in std::fs::read_dir(fixture_dir()).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.path().join(f.file_name().unwrap())).unwrap();
    }
    let model_path = dir.path().join("cantilever_model.inc");
    let text = std::fs::read_to_string(&model_path).unwrap();
    let text = text
        .replace(
            "*NSET,NSET=CONTACT_LOWER\n",
            "*Nset,\n** a comment between\n  nset = Contact_Lower\n",
        )
        .replace(
            "8, 9, 11, 12\n",
            "8, 9,\n\n** comment inside the data\n11, 12,\n",
        )
        .replace(
            "*NSET,NSET=LOWER,GENERATE\n1, 12\n",
            "*NSET,NSET=LOWER,GENERATE\n1, 11, 2\n2, 12, 2\n",
        );
    std::fs::write(&model_path, text).unwrap();
    let nodes_path = dir.path().join("cantilever_nodes.inc");
    let nodes = std::fs::read_to_string(&nodes_path).unwrap();
    assert!(nodes.contains(", 0.003\n"));
    std::fs::write(&nodes_path, nodes.replace(", 0.003\n", ", 3.0D-3\n")).unwrap();
    let a = import(&fixture_dir().join("cantilever.inp")).unwrap();
    let b = import(&dir.path().join("cantilever.inp")).unwrap();
    assert_eq!(a.dofs, b.dofs);
    assert_eq!(a.pairs, b.pairs);
    assert_eq!(a.outputs, b.outputs);
    assert_eq!(a.clearance, b.clearance);
}
