//! Guards the CalculiX readers against malformed and truncated input: each broken variant of
//! the fixture's `.sti`, `.mas`, `.dof`, `.inp` (and included file) and `.dat` must give a
//! `CalculixError` that names the file, the line where there is one, and what was expected,
//! never a panic or a silently wrong model.

use std::path::{Path, PathBuf};

use rigtwin::fe::calculix::{import, read_dat_frequencies, CalculixError};
use tempfile::TempDir;

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sim-fixtures/calculix/cantilever")
}

/// A scratch copy of the fixture with `file` rewritten by `edit`.
fn broken(file: &str, edit: impl FnOnce(String) -> String) -> TempDir {
    let dir = tempfile::tempdir().unwrap();
    for f in std::fs::read_dir(fixture_dir()).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.path().join(f.file_name().unwrap())).unwrap();
    }
    let path = dir.path().join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, edit(text)).unwrap();
    dir
}

/// Imports the broken copy; returns the error and its message.
fn import_err(dir: &TempDir) -> (CalculixError, String) {
    let err = import(&dir.path().join("cantilever")).expect_err("broken input must not import");
    let msg = err.to_string();
    eprintln!("{msg}");
    (err, msg)
}

fn replace_line(text: &str, line: usize, with: &str) -> String {
    text.lines()
        .enumerate()
        .map(|(i, l)| if i + 1 == line { with } else { l })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

fn drop_last_lines(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[..lines.len() - n].join("\n") + "\n"
}

// ---- .sti -------------------------------------------------------------------------------

#[test]
fn sti_row_with_two_fields() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| replace_line(&t, 5, "1 3")));
    assert!(matches!(err, CalculixError::Parse { line: 5, .. }));
    assert!(
        msg.contains("cantilever.sti:5") && msg.contains("3 fields"),
        "{msg}"
    );
}

#[test]
fn sti_truncated_in_the_middle_of_a_line() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| {
        let cut = t.trim_end().rfind('\n').unwrap() + 5;
        t[..cut].to_string()
    }));
    assert!(
        matches!(err, CalculixError::Parse { line: 1350, .. }),
        "{msg}"
    );
    assert!(msg.contains("cantilever.sti:1350"), "{msg}");
}

#[test]
fn sti_truncated_at_a_line_boundary_is_a_size_mismatch() {
    // the last column (DOF 90) holds 33 entries; drop them all
    let (err, msg) = import_err(&broken("cantilever.sti", |t| drop_last_lines(&t, 33)));
    assert!(
        matches!(
            err,
            CalculixError::SizeMismatch {
                n_sti: 89,
                n_mas: 90,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("cantilever.sti") && msg.contains("cantilever.mas"),
        "{msg}"
    );
}

#[test]
fn sti_malformed_number() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| {
        replace_line(&t, 7, "2 3  1.2.3e+08")
    }));
    assert!(matches!(err, CalculixError::Parse { line: 7, .. }));
    assert!(
        msg.contains("cantilever.sti:7") && msg.contains("finite real"),
        "{msg}"
    );
}

#[test]
fn sti_zero_index() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| t + "0 1 1.0\n"));
    assert!(
        msg.contains("cantilever.sti:1351") && msg.contains("1-based row index"),
        "{msg}"
    );
    assert!(matches!(err, CalculixError::Parse { .. }));
}

#[test]
fn sti_index_beyond_the_dof_list() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| t + "1 95 1.0\n"));
    assert!(
        matches!(
            err,
            CalculixError::IndexOutOfRange {
                line: 1351,
                index: 95,
                dim: 90,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("cantilever.dof") && msg.contains("1..=90"),
        "{msg}"
    );
}

#[test]
fn sti_conflicting_mirrored_entry() {
    let (err, msg) = import_err(&broken("cantilever.sti", |t| t + "2 1 123.0\n"));
    assert!(
        matches!(
            err,
            CalculixError::ConflictingEntry {
                row: 1,
                col: 2,
                line: 1351,
                first_line: 2,
                ..
            }
        ),
        "{msg}"
    );
    // the same value mirrored is accepted
    let dir = broken("cantilever.sti", |t| {
        let second = t
            .lines()
            .nth(1)
            .unwrap()
            .split_whitespace()
            .collect::<Vec<_>>();
        assert_eq!(&second[..2], ["1", "2"]);
        format!("{t}2 1 {}\n", second[2])
    });
    import(&dir.path().join("cantilever")).expect("an exact mirrored duplicate is harmless");
}

#[test]
fn sti_missing_file() {
    let dir = broken("cantilever.sti", |t| t);
    std::fs::remove_file(dir.path().join("cantilever.sti")).unwrap();
    let (err, msg) = import_err(&dir);
    assert!(matches!(err, CalculixError::Io { .. }));
    assert!(msg.contains("cantilever.sti"), "{msg}");
}

// ---- .mas -------------------------------------------------------------------------------

#[test]
fn mas_of_another_size() {
    // the last column (DOF 90) holds 33 entries; drop them all
    let (err, msg) = import_err(&broken("cantilever.mas", |t| drop_last_lines(&t, 33)));
    assert!(
        matches!(
            err,
            CalculixError::SizeMismatch {
                n_sti: 90,
                n_mas: 89,
                ..
            }
        ),
        "{msg}"
    );
}

#[test]
fn mas_truncated_inside_the_last_column() {
    let (err, msg) = import_err(&broken("cantilever.mas", |t| drop_last_lines(&t, 9)));
    assert!(
        matches!(err, CalculixError::MissingDiagonal { dof: 90, .. }),
        "{msg}"
    );
    assert!(
        msg.contains("cantilever.mas") && msg.contains("truncated"),
        "{msg}"
    );
}

#[test]
fn mas_non_finite_value() {
    let (err, msg) = import_err(&broken("cantilever.mas", |t| {
        replace_line(&t, 3, "2 2 nan")
    }));
    assert!(matches!(err, CalculixError::Parse { line: 3, .. }));
    assert!(msg.contains("cantilever.mas:3"), "{msg}");
}

#[test]
fn mas_repeated_entry_with_another_value() {
    let (err, msg) = import_err(&broken("cantilever.mas", |t| t + "3 3 1.0\n"));
    assert!(
        matches!(err, CalculixError::ConflictingEntry { row: 3, col: 3, .. }),
        "{msg}"
    );
    assert!(msg.contains("cantilever.mas:1351"), "{msg}");
}

#[test]
fn mas_empty() {
    let (err, msg) = import_err(&broken("cantilever.mas", |_| String::new()));
    assert!(matches!(err, CalculixError::Parse { .. }));
    assert!(
        msg.contains("cantilever.mas") && msg.contains("empty"),
        "{msg}"
    );
}

// ---- .dof -------------------------------------------------------------------------------

#[test]
fn dof_shorter_than_the_matrices() {
    let (err, msg) = import_err(&broken("cantilever.dof", |t| drop_last_lines(&t, 3)));
    assert!(
        matches!(
            err,
            CalculixError::DofCount {
                lines: 87,
                dim: 90,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("cantilever.dof") && msg.contains("node.dir"),
        "{msg}"
    );
}

#[test]
fn dof_malformed_line() {
    let (err, msg) = import_err(&broken("cantilever.dof", |t| replace_line(&t, 4, "5.x")));
    assert!(matches!(err, CalculixError::Parse { line: 4, .. }));
    assert!(msg.contains("cantilever.dof:4"), "{msg}");
}

#[test]
fn dof_direction_out_of_range() {
    let (err, msg) = import_err(&broken("cantilever.dof", |t| replace_line(&t, 2, "2.4")));
    assert!(
        msg.contains("cantilever.dof:2") && msg.contains("direction 1, 2 or 3"),
        "{msg}"
    );
    assert!(matches!(err, CalculixError::Parse { .. }));
}

#[test]
fn dof_listed_twice() {
    let (err, msg) = import_err(&broken("cantilever.dof", |t| replace_line(&t, 2, "2.1")));
    assert!(
        msg.contains("cantilever.dof:2") && msg.contains("line 1"),
        "{msg}"
    );
    assert!(matches!(err, CalculixError::Parse { .. }));
}

// ---- .inp and included files --------------------------------------------------------------

#[test]
fn inp_malformed_coordinate_in_an_included_file() {
    let (err, msg) = import_err(&broken("cantilever_nodes.inc", |t| {
        t.replace("5, 0.02, 0.01, 0.0\n", "5, 0.02, O.01, 0.0\n")
    }));
    assert!(matches!(err, CalculixError::Parse { line: 7, .. }), "{msg}");
    assert!(
        msg.contains("cantilever_nodes.inc:7") && msg.contains("O.01"),
        "{msg}"
    );
}

#[test]
fn inp_node_line_with_too_many_fields() {
    let (_, msg) = import_err(&broken("cantilever_nodes.inc", |t| {
        t.replace("5, 0.02, 0.01, 0.0\n", "5, 0.02, 0.01, 0.0, 1.0\n")
    }));
    assert!(
        msg.contains("cantilever_nodes.inc:7") && msg.contains("x, y, z"),
        "{msg}"
    );
}

#[test]
fn inp_unknown_node_in_a_set() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("8, 9, 11, 12\n", "8, 9, 11, 99\n")
    }));
    assert!(
        matches!(
            err,
            CalculixError::UnknownNode {
                id: 99,
                what: "node",
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("cantilever_model.inc:") && msg.contains("CONTACT_LOWER"),
        "{msg}"
    );
}

#[test]
fn inp_element_with_an_undefined_node() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("18, 3\n", "18, 300\n")
    }));
    assert!(
        matches!(err, CalculixError::UnknownNode { id: 300, .. }),
        "{msg}"
    );
    assert!(msg.contains("element 18"), "{msg}");
}

#[test]
fn inp_missing_contact_set() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("*nset,nset=contact_upper\n18, 17, 15, 14\n", "")
    }));
    assert!(
        matches!(&err, CalculixError::MissingSet { name, .. } if name == "CONTACT_UPPER"),
        "{msg}"
    );
    assert!(msg.contains("cantilever.inp"), "{msg}");
}

#[test]
fn inp_missing_group_set() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("*NSET,NSET=LOWER,GENERATE\n1, 12\n", "")
    }));
    assert!(
        matches!(&err, CalculixError::MissingSet { name, .. } if name == "LOWER"),
        "{msg}"
    );
}

#[test]
fn inp_set_refers_to_an_undefined_set() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("UPPER_BEAM, UPPER_PROBE\n", "UPPER_BEAM, UPPER_PROBES\n")
    }));
    assert!(
        matches!(&err, CalculixError::MissingSet { name, .. } if name == "UPPER_PROBES"),
        "{msg}"
    );
    assert!(msg.contains("line"), "{msg}");
}

#[test]
fn inp_missing_include() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("INPUT=cantilever_nodes.inc", "INPUT=nodes_missing.inc")
    }));
    assert!(matches!(err, CalculixError::Parse { line: 5, .. }), "{msg}");
    assert!(
        msg.contains("cantilever_model.inc:5") && msg.contains("nodes_missing.inc"),
        "{msg}"
    );
}

#[test]
fn inp_element_cut_short_before_the_next_keyword() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("5, 25,26,28,27,29,30,32,31\n", "5, 25,26,28,27\n")
    }));
    assert!(matches!(err, CalculixError::Parse { .. }), "{msg}");
    assert!(msg.contains("cantilever_model.inc:17"), "{msg}");
    assert!(msg.contains("8 node numbers for a C3D8"), "{msg}");
}

#[test]
fn inp_truncated_file_ends_inside_an_element() {
    let (_, msg) = import_err(&broken("cantilever_model.inc", |t| {
        let cut = t.find("19,20,23,22").unwrap();
        t[..cut].to_string()
    }));
    // reported at the line where the element starts
    assert!(
        msg.contains("cantilever_model.inc:12") && msg.contains("C3D8I"),
        "{msg}"
    );
}

#[test]
fn inp_unknown_element_type() {
    let (_, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("TYPE=C3D8,ELSET=CLAMP", "TYPE=C3D99,ELSET=CLAMP")
    }));
    assert!(msg.contains("C3D99") && msg.contains("known type"), "{msg}");
}

#[test]
fn inp_bad_generate_range() {
    let (_, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("GENERATE\n1, 12\n", "GENERATE\n12, 1\n")
    }));
    assert!(msg.contains("start <= end"), "{msg}");
}

#[test]
fn inp_generate_beyond_the_defined_nodes() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("GENERATE\n1, 12\n", "GENERATE\n1, 4000000000\n")
    }));
    assert!(
        matches!(err, CalculixError::UnknownNode { id: 4000000000, .. }),
        "{msg}"
    );
    assert!(msg.contains("node set LOWER"), "{msg}");
}

#[test]
fn inp_sparse_node_numbering_is_refused() {
    let (_, msg) = import_err(&broken("cantilever_nodes.inc", |t| {
        t + "900000000, 1.0, 1.0, 1.0\n"
    }));
    assert!(msg.contains("compact numbering"), "{msg}");
}

#[test]
fn inp_malformed_metadata_comment() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("dir 0 0.6 0.8", "dir 0 0.6")
    }));
    assert!(matches!(err, CalculixError::Parse { line: 4, .. }), "{msg}");
    assert!(msg.contains("rigtwin sensor <name> dir <x y z>"), "{msg}");
}

#[test]
fn inp_metadata_for_a_sensor_without_a_set() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("*NSET,NSET=SENSOR_UPPER_TIP\n24\n", "")
    }));
    assert!(
        matches!(&err, CalculixError::MissingSet { name, .. } if name == "SENSOR_UPPER_TIP"),
        "{msg}"
    );
}

#[test]
fn inp_sensor_set_with_two_nodes() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace(
            "*NSET,NSET=SENSOR_LOWER_TIP\n3\n",
            "*NSET,NSET=SENSOR_LOWER_TIP\n3, 6\n",
        )
    }));
    assert!(matches!(err, CalculixError::Model { .. }), "{msg}");
    assert!(
        msg.contains("SENSOR_LOWER_TIP") && msg.contains("exactly one"),
        "{msg}"
    );
}

#[test]
fn inp_sensor_on_a_fixed_node() {
    let (_, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace(
            "*NSET,NSET=SENSOR_LOWER_TIP\n3\n",
            "*NSET,NSET=SENSOR_LOWER_TIP\n1\n",
        )
    }));
    assert!(
        msg.contains("lower_tip") && msg.contains("not free"),
        "{msg}"
    );
}

#[test]
fn inp_contact_sets_that_do_not_face_each_other() {
    let (err, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("18, 17, 15, 14\n", "18, 17, 15, 13\n")
    }));
    assert!(matches!(err, CalculixError::Model { .. }), "{msg}");
    assert!(msg.contains("conforming"), "{msg}");
}

#[test]
fn inp_contact_sets_of_different_length() {
    let (_, msg) = import_err(&broken("cantilever_model.inc", |t| {
        t.replace("18, 17, 15, 14\n", "18, 17, 15\n")
    }));
    assert!(
        msg.contains("CONTACT_LOWER has 4 nodes and CONTACT_UPPER 3"),
        "{msg}"
    );
}

// ---- .dat -------------------------------------------------------------------------------

#[test]
fn dat_truncated_inside_a_mode_line() {
    let dir = broken("cantilever_freq.dat", |t| {
        let cut = t.find("0.3687775E+05").unwrap() + "0.3687775E+05".len();
        t[..cut].to_string()
    });
    let err = read_dat_frequencies(&dir.path().join("cantilever_freq.dat")).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("cantilever_freq.dat:10") && msg.contains("5 numbers"),
        "{msg}"
    );
}

#[test]
fn dat_with_a_skipped_mode_number() {
    let dir = broken("cantilever_freq.dat", |t| {
        t.replacen("      2   0.", "      7   0.", 1)
    });
    let err = read_dat_frequencies(&dir.path().join("cantilever_freq.dat")).unwrap_err();
    assert!(err.to_string().contains("mode number 2"), "{err}");
}
