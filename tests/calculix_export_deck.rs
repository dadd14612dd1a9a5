//! Guards the form of the exported CalculiX decks without running ccx: the rules ccx imposes
//! (numeric fields of at most 20 characters with a decimal point, no continued keyword lines,
//! no data line under `*FREQUENCY,SOLVER=MATRIXSTORAGE`), at most 16 ids per `*NSET` line,
//! contact sets in pair order, springs grouped by equal stiffness, and the rejection of
//! inconsistent meshes with a message naming the item.

mod calculix_support;

use std::collections::{BTreeSet, HashMap};

use calculix_support::two_cantilevers;
use rigtwin::fe::calculix::{export, CalculixError};
use rigtwin::fe::Mesh;

fn exported(mesh: &Mesh) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let f = export(mesh, dir.path(), "rig", 12).unwrap();
    assert_eq!(f.frequency_deck, dir.path().join("rig.inp"));
    assert_eq!(f.matrix_deck, dir.path().join("rig_matrix.inp"));
    assert_eq!(
        (f.job.as_str(), f.matrix_job.as_str()),
        ("rig", "rig_matrix")
    );
    (
        std::fs::read_to_string(&f.frequency_deck).unwrap(),
        std::fs::read_to_string(&f.matrix_deck).unwrap(),
    )
}

/// Data lines of the block opened by the keyword line `key`.
fn block<'a>(deck: &'a str, key: &str) -> Vec<&'a str> {
    deck.lines()
        .skip_while(|l| *l != key)
        .skip(1)
        .take_while(|l| !l.starts_with('*'))
        .collect()
}

#[test]
fn decks_follow_the_ccx_input_rules() {
    let mesh = two_cantilevers();
    let (freq, matrix) = exported(&mesh);
    let model_end = freq.find("*STEP").unwrap();
    assert_eq!(
        freq[..model_end],
        matrix[..matrix.find("** K, M").unwrap()],
        "both decks hold the same model"
    );
    assert!(freq.ends_with("*STEP\n*FREQUENCY\n12\n*END STEP\n"));
    assert!(matrix.ends_with("*STEP\n*FREQUENCY,SOLVER=MATRIXSTORAGE\n*END STEP\n"));
    assert!(!freq.to_uppercase().contains("*INCLUDE"));

    let mut keyword = String::new();
    for line in freq[..model_end].lines() {
        if line.starts_with("**") {
            continue;
        }
        if line.starts_with('*') {
            assert!(!line.ends_with(','), "continued keyword line: {line}");
            keyword = line.to_string();
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        for f in &fields {
            assert!(
                f.len() <= 20,
                "field over 20 characters under {keyword}: {f}"
            );
            let name = f.starts_with(|c: char| c.is_ascii_alphabetic());
            if f.parse::<i64>().is_err() && !name {
                assert!(
                    f.contains('.'),
                    "real without a decimal point under {keyword}: {f}"
                );
            }
        }
        if keyword.starts_with("*NSET") {
            assert!(fields.len() <= 16, "{keyword}: {line}");
        }
    }
}

#[test]
fn sets_carry_pairs_sensors_and_grouped_springs() {
    let mesh = two_cantilevers();
    let (deck, _) = exported(&mesh);
    let ids = |key: &str| -> Vec<usize> {
        block(&deck, key)
            .iter()
            .flat_map(|l| l.split(','))
            .map(|s| s.trim().parse().unwrap())
            .collect()
    };
    let lower: Vec<usize> = mesh.contact_pairs.iter().map(|p| p.lower + 1).collect();
    let upper: Vec<usize> = mesh.contact_pairs.iter().map(|p| p.upper + 1).collect();
    assert_eq!(
        ids("*NSET,NSET=CONTACT_LOWER"),
        lower,
        "pair order, 1-based"
    );
    assert_eq!(ids("*NSET,NSET=CONTACT_UPPER"), upper);
    assert_eq!(
        ids("*NSET,NSET=SENSOR_UPPER_MID"),
        vec![mesh.sensors[2].node + 1]
    );
    assert!(deck.contains("** rigtwin sensor upper_mid dir 0e0 6e-1 8e-1\n"));
    let fixed: BTreeSet<usize> = mesh.fixed_nodes.iter().map(|n| n + 1).collect();
    assert_eq!(
        ids("*NSET,NSET=BC_FIXED"),
        fixed.into_iter().collect::<Vec<_>>()
    );
    assert_eq!(block(&deck, "*BOUNDARY"), ["BC_FIXED,1,3"]);
    let lower_set = ids("*NSET,NSET=LOWER");
    assert_eq!(lower_set.len(), mesh.node_sets["LOWER"].len());
    assert!(deck.contains("*ELEMENT,TYPE=C3D8I,ELSET=LOWER_BEAM\n"));
    assert!(deck.contains("*ELEMENT,TYPE=C3D8,ELSET=LOWER_PROBE\n"));
    assert!(deck.contains("*MATERIAL,NAME=CLAMP_STEEL\n"));

    // One SPRING2 element per spring and nonzero direction, one set per distinct stiffness.
    let mut distinct: HashMap<(usize, usize), BTreeSet<u64>> = HashMap::new();
    let mut n_springs = 0;
    for s in &mesh.springs {
        for (d, k) in s.stiffness.iter().enumerate() {
            if *k != 0.0 {
                n_springs += 1;
                distinct
                    .entry((s.layer, d))
                    .or_default()
                    .insert(k.to_bits());
            }
        }
    }
    let spring_sets: Vec<&str> = deck
        .lines()
        .filter(|l| l.starts_with("*ELEMENT,TYPE=SPRING2"))
        .collect();
    assert_eq!(
        spring_sets.len(),
        distinct.values().map(|s| s.len()).sum::<usize>()
    );
    let elements: usize = spring_sets.iter().map(|k| block(&deck, k).len()).sum();
    assert_eq!(elements, n_springs);
    assert!(
        spring_sets.len() < n_springs,
        "grouping keeps the deck small"
    );
    let first = block(&deck, "*SPRING,ELSET=SPR_LOWER_CLAMP_X_1");
    assert_eq!(first[0], "1,1");
    assert_eq!(
        first[1].parse::<f64>().unwrap(),
        mesh.springs[0].stiffness[0]
    );
    assert_eq!(block(&deck, "*MASS,ELSET=MASS_1"), ["2.0e-3"]);
}

fn export_err(mesh: &Mesh, job: &str, n_modes: usize) -> String {
    let dir = tempfile::tempdir().unwrap();
    let err = export(mesh, dir.path(), job, n_modes).expect_err("must be rejected");
    assert!(matches!(err, CalculixError::InvalidMesh { .. }), "{err:?}");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing written"
    );
    err.to_string()
}

#[test]
fn inconsistent_meshes_are_rejected_before_writing() {
    let good = two_cantilevers();
    let msg = export_err(&good, "../rig", 10);
    assert!(msg.contains("job name"), "{msg}");
    let msg = export_err(&good, "rig", 0);
    assert!(msg.contains("at least one mode"), "{msg}");

    let mut m = good.clone();
    m.elements[3].nodes[5] = 100_000;
    let msg = export_err(&m, "rig", 10);
    assert!(msg.contains("element 3") && msg.contains("100000"), "{msg}");

    let mut m = good.clone();
    m.springs[2].b = m.springs[2].a;
    assert!(export_err(&m, "rig", 10).contains("spring 2 connects node"));

    let mut m = good.clone();
    m.springs[0].stiffness[1] = f64::NAN;
    assert!(export_err(&m, "rig", 10).contains("spring 0"));

    let mut m = good.clone();
    m.sensors[1].name = "Lower_Tip".into();
    let msg = export_err(&m, "rig", 10);
    assert!(
        msg.contains("SENSOR_LOWER_TIP") && msg.contains("distinct"),
        "{msg}"
    );

    let mut m = good.clone();
    m.sensors[0].name = "lower tip".into();
    assert!(export_err(&m, "rig", 10).contains("without spaces"));

    let mut m = good.clone();
    m.contact_pairs[1].frame[1] = [0.0, 1.0, 0.0];
    let msg = export_err(&m, "rig", 10);
    assert!(
        msg.contains("contact pair 1") && msg.contains("right-handed"),
        "{msg}"
    );

    let mut m = good.clone();
    m.materials[0].poisson_ratio = 0.5;
    assert!(export_err(&m, "rig", 10).contains("material steel"));

    let mut m = good.clone();
    m.point_masses[0].mass = 0.0;
    assert!(export_err(&m, "rig", 10).contains("lower_accelerometer"));

    let mut m = good;
    m.blocks[1].name = "lower beam".into(); // becomes LOWER_BEAM like block 0
    assert!(export_err(&m, "rig", 10).contains("LOWER_BEAM"));
}
