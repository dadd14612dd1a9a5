//! Guards the CalculiX round trip with the real solver as the oracle: a two-cantilever mesh
//! is exported, `ccx` computes its eigenfrequencies and writes its K and M, the import must
//! reproduce those frequencies and rebuild the contact pairs, sensors and DOF groups, also
//! from a deck without rigtwin's metadata comments and with a re-sorted contact set.
//! Skipped (with a message) when `ccx` is not on PATH; CI installs it.

mod calculix_support;

use std::path::Path;

use calculix_support::{dense_frequencies, max_rel_diff, two_cantilevers, CLEARANCE, LENGTH};
use rigtwin::fe::calculix::{
    ccx_available, ccx_command, export, import, read_dat_frequencies, run_ccx,
};
use rigtwin::fe::{DofGroup, FeModel, Mesh};

const N_MODES: usize = 10;

fn ccx_or_skip() -> bool {
    if ccx_available() {
        return true;
    }
    assert!(
        !rigtwin::fe::calculix::ccx_required(),
        "RIGTWIN_REQUIRE_CCX is set but ccx cannot be started"
    );
    eprintln!(
        "SKIPPED: `{}` is not on PATH (install calculix-ccx or set RIGTWIN_CCX)",
        ccx_command()
    );
    false
}

/// Exports, runs both decks; returns (ccx frequencies, imported model).
fn through_ccx(mesh: &Mesh, dir: &Path) -> (Vec<f64>, FeModel) {
    let files = export(mesh, dir, "beams", N_MODES).expect("export");
    let run = run_ccx(dir, &files.job).expect("ccx frequency run");
    let freqs = read_dat_frequencies(&run.dat).expect("frequencies in .dat");
    let run = run_ccx(dir, &files.matrix_job).expect("ccx matrix run");
    let model = import(&run.job_path).expect("import");
    (freqs, model)
}

#[test]
fn imported_matrices_reproduce_ccx_frequencies() {
    if !ccx_or_skip() {
        return;
    }
    let mesh = two_cantilevers();
    let dir = tempfile::tempdir().unwrap();
    let (ccx_freqs, model) = through_ccx(&mesh, dir.path());
    assert_eq!(ccx_freqs.len(), N_MODES);
    let ours = dense_frequencies(&model.k, &model.m, N_MODES);
    let diff = max_rel_diff(&ours, &ccx_freqs);
    eprintln!("ccx .dat  : {ccx_freqs:.3?}");
    eprintln!("imported  : {ours:.3?}");
    eprintln!("max relative difference {diff:.2e}");
    // .dat prints 7 significant digits
    assert!(diff < 2e-6, "imported K, M do not reproduce ccx: {diff:e}");
    // the two beams' first bending modes are in the range of a 0.1 m steel cantilever
    assert!(
        ccx_freqs[0] > 300.0 && ccx_freqs[0] < 700.0,
        "{ccx_freqs:?}"
    );

    // DOF table: every non-fixed mesh node has 3 DOFs, each C3D8I adds 3 internal nodes.
    let n_hex8i = mesh
        .elements
        .iter()
        .filter(|e| mesh.blocks[e.block].kind == rigtwin::fe::ElementKind::Hex8I)
        .count();
    let free_nodes = mesh.nodes.len() - mesh.fixed_nodes.len();
    let internal = model
        .dofs
        .iter()
        .filter(|d| d.group == DofGroup::Internal)
        .count();
    assert_eq!(internal, 9 * n_hex8i);
    assert_eq!(model.n_dof(), 3 * free_nodes + 9 * n_hex8i);
    assert_eq!(model.n_nodes(), mesh.nodes.len());
    assert_eq!(model.n_elements, mesh.elements.len());
    // ccx's C3D8I mass is rank-deficient: its three bubble functions per direction are equal
    // at the 2x2x2 Gauss points, so 6 of each element's 9 internal DOF combinations carry no
    // mass. M is positive semidefinite with exactly that null space.
    let mu = calculix_support::dense_inverse_eigenvalues(&model.k, &model.m);
    let massless = mu.iter().filter(|&&m| m.abs() <= 1e-12 * mu[0]).count();
    eprintln!("massless DOF combinations: {massless} ({n_hex8i} C3D8I elements)");
    assert_eq!(massless, 6 * n_hex8i);
    for d in &model.dofs {
        let expected = if d.node >= mesh.nodes.len() {
            DofGroup::Internal
        } else if mesh.node_sets["LOWER"].contains(&d.node) {
            DofGroup::Lower
        } else if mesh.node_sets["UPPER"].contains(&d.node) {
            DofGroup::Upper
        } else {
            DofGroup::Clamp
        };
        assert_eq!(d.group, expected, "{d:?}");
        assert!(
            !mesh.fixed_nodes.contains(&d.node),
            "fixed node {} has DOFs",
            d.node
        );
    }
    // Base vector: 1 on z of real nodes; the mass it moves is the total free mass.
    let mb: f64 = {
        let b = faer::Mat::from_fn(model.n_dof(), 1, |i, _| model.base[i]);
        let mb = &model.m * &b;
        (0..model.n_dof()).map(|i| model.base[i] * mb[(i, 0)]).sum()
    };
    let total = mesh.total_mass();
    eprintln!("b^T M b = {mb:.6e} kg, mesh total mass {total:.6e} kg");
    assert!(
        mb < total && mb > 0.9 * total,
        "b^T M b {mb} vs total {total}"
    );

    // Pairs, clearance and sensors come back as exported.
    assert_eq!(model.pairs.len(), mesh.contact_pairs.len());
    for (p, q) in model.pairs.iter().zip(&mesh.contact_pairs) {
        for c in 0..3 {
            assert_eq!(model.dofs[p.lower[c]].node, q.lower);
            assert_eq!(model.dofs[p.upper[c]].node, q.upper);
            assert_eq!(model.dofs[p.lower[c]].dir as usize, c);
        }
        assert_eq!(p.frame, q.frame);
        assert_eq!(p.area, q.area);
        let x = mesh.nodes[q.lower];
        assert!((0..3).all(|c| (p.position[c] - x[c]).abs() <= 1e-15 * LENGTH));
    }
    assert!(
        (model.clearance - CLEARANCE).abs() < 1e-15,
        "{}",
        model.clearance
    );
    let names: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["lower_tip", "upper_tip", "upper_mid"]);
    let mid = &model.outputs[2];
    assert_eq!(mid.terms.len(), 2);
    assert_eq!(model.dofs[mid.terms[0].0].dir, 1);
    assert!((mid.terms[0].1 - 0.6).abs() < 1e-15 && (mid.terms[1].1 - 0.8).abs() < 1e-15);
}

#[test]
fn import_without_metadata_and_with_resorted_contact_set_rebuilds_the_same_pairs() {
    if !ccx_or_skip() {
        return;
    }
    let mesh = two_cantilevers();
    let dir = tempfile::tempdir().unwrap();
    let files = export(&mesh, dir.path(), "beams", N_MODES).unwrap();
    run_ccx(dir.path(), &files.matrix_job).unwrap();
    let with_meta = import(&files.matrix_deck).unwrap();

    // Strip rigtwin comments, reverse CONTACT_UPPER, write lower-case keywords.
    let text = std::fs::read_to_string(&files.matrix_deck).unwrap();
    let mut out = String::new();
    let mut lines = text.lines().peekable();
    while let Some(l) = lines.next() {
        if l.starts_with("** rigtwin") {
            continue;
        }
        if l == "*NSET,NSET=CONTACT_UPPER" {
            let mut ids = Vec::new();
            while lines.peek().is_some_and(|n| !n.starts_with('*')) {
                ids.extend(
                    lines
                        .next()
                        .unwrap()
                        .split(',')
                        .map(|s| s.trim().to_string()),
                );
            }
            ids.reverse();
            out.push_str("*nset, nset=contact_upper\n");
            for chunk in ids.chunks(4) {
                out.push_str(&chunk.join(", "));
                out.push_str(",\n");
            }
            continue;
        }
        out.push_str(&l.to_lowercase());
        out.push('\n');
    }
    let bare = dir.path().join("bare.inp");
    std::fs::write(&bare, out).unwrap();
    for ext in ["sti", "mas", "dof"] {
        std::fs::copy(
            dir.path().join(format!("{}.{ext}", files.matrix_job)),
            dir.path().join(format!("bare.{ext}")),
        )
        .unwrap();
    }
    let bare = import(&dir.path().join("bare")).unwrap();

    assert_eq!(bare.pairs.len(), with_meta.pairs.len());
    for (a, b) in bare.pairs.iter().zip(&with_meta.pairs) {
        assert_eq!(a.lower, b.lower);
        assert_eq!(
            a.upper, b.upper,
            "re-sorted CONTACT_UPPER must pair by position"
        );
        assert_eq!(a.frame, b.frame);
        assert!(
            (a.area - b.area).abs() <= 1e-12 * b.area,
            "{} vs {}",
            a.area,
            b.area
        );
    }
    assert!((bare.clearance - with_meta.clearance).abs() < 1e-15);
    // Without comments: names from the set suffix, direction z.
    let mid = bare.outputs.iter().find(|o| o.name == "upper_mid").unwrap();
    assert_eq!(mid.terms.len(), 1);
    assert_eq!(bare.dofs[mid.terms[0].0].dir, 2);
    assert_eq!(bare.k.compute_nnz(), with_meta.k.compute_nnz());
}

#[test]
fn ccx_failures_are_errors_although_ccx_exits_0() {
    if !ccx_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let err = run_ccx(dir.path(), "absent").unwrap_err();
    assert!(err.to_string().contains("absent.inp"), "{err}");
    // ARPACK asked for more modes than a fifth of the 612 equations (see the module docs)
    export(&two_cantilevers(), dir.path(), "many_modes", 200).unwrap();
    let err = run_ccx(dir.path(), "many_modes").unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(
        msg.contains("*ERROR") && msg.contains("many_modes"),
        "{msg}"
    );
}
