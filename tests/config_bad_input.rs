//! Guards the rig description's error reporting: every bad input (TOML syntax, unknown or
//! mistyped keys, non-positive dimensions, unknown materials, a contact patch that does not
//! fit the probe or the beam, bad node counts, clearance, friction, damping, reduction,
//! sensors, the simulated rig's truth variants, unreadable file) is rejected with a message
//! that names the file, the key (or line:column) and what was expected. Also guards the
//! canonical hash (sim-only tables such as `[truth.variants]` stay out of it).

use std::path::{Path, PathBuf};

use rigtwin::config::{ConfigError, RigConfig};
use rigtwin::rig::sim::SimRigSpec;

const FILE: &str = "bad-rig.toml";

fn reference_text() -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rig-config/two-beam.toml");
    std::fs::read_to_string(path).expect("reference rig description")
}

/// The reference text with `key` of table `section` set to `value` (the key must exist in
/// that table; the rest of the line, including its comment, is replaced).
fn set(section: &str, key: &str, value: &str) -> String {
    let text = reference_text();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let header = format!("[{section}]");
    let start = lines
        .iter()
        .position(|l| l.trim_start().starts_with(&header))
        .unwrap_or_else(|| panic!("no table {section}"));
    let at = lines[start + 1..]
        .iter()
        .take_while(|l| !l.trim_start().starts_with('['))
        .position(|l| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|r| r.trim_start().starts_with('='))
        })
        .unwrap_or_else(|| panic!("no key {key} in {section}"));
    lines[start + 1 + at] = format!("{key} = {value}");
    lines.join("\n")
}

fn parse(text: &str) -> Result<RigConfig, ConfigError> {
    RigConfig::from_str(text, FILE)
}

/// Asserts an invalid-value error naming the file, the key and containing `expect`.
fn assert_invalid(text: &str, key: &str, expect: &str) {
    let err = parse(text).expect_err("bad input must be rejected");
    let msg = err.to_string();
    assert!(matches!(err, ConfigError::Invalid { .. }), "{msg}");
    assert_eq!(err.key(), Some(key), "{msg}");
    assert!(msg.contains(FILE), "file missing: {msg}");
    assert!(msg.contains(&format!("`{key}`")), "key missing: {msg}");
    assert!(msg.contains(expect), "expectation missing: {msg}");
}

#[test]
fn reference_rig_is_valid() {
    let cfg = parse(&reference_text()).unwrap();
    assert_eq!(cfg.source, FILE);
    assert_eq!(cfg.rig.name, "two-beam");
    assert_eq!(cfg.contact.nodes, [12, 16]);
}

#[test]
fn toml_syntax_error_reports_line_and_column() {
    let text = reference_text().replacen("beam_length = 0.300", "beam_length 0.300", 1);
    let line = text
        .lines()
        .position(|l| l.starts_with("beam_length 0.300"))
        .unwrap()
        + 1;
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    match err {
        ConfigError::Syntax {
            line: l, column, ..
        } => {
            assert_eq!(l, line, "{msg}");
            assert_eq!(column, 13, "{msg}");
        }
        other => panic!("expected a syntax error, got {other}"),
    }
    assert!(
        msg.starts_with(&format!("{FILE}:{line}:13: TOML syntax error")),
        "{msg}"
    );
    assert!(msg.contains("expected"), "{msg}");
}

#[test]
fn unknown_key_names_its_path_and_line() {
    let text = reference_text().replacen("thickness = 0.006", "thicknes = 0.006", 1);
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ConfigError::Schema { .. }), "{msg}");
    assert_eq!(err.key(), Some("parts.lower_beam.thicknes"), "{msg}");
    assert!(
        msg.contains(FILE) && msg.contains("unknown field `thicknes`"),
        "{msg}"
    );
    assert!(msg.contains("expected one of"), "{msg}");
    let line = text
        .lines()
        .position(|l| l.starts_with("thicknes "))
        .unwrap()
        + 1;
    assert!(msg.starts_with(&format!("{FILE}:{line}:")), "{msg}");
}

#[test]
fn wrong_type_names_key_and_expected_type() {
    let text = set("parts.upper_beam", "width_root", "\"wide\"");
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    assert_eq!(err.key(), Some("parts.upper_beam.width_root"), "{msg}");
    assert!(msg.contains("expected f64"), "{msg}");
}

#[test]
fn missing_key_is_reported() {
    let text = reference_text().replacen("clearance = 0.699e-3", "", 1);
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("missing field `clearance`"), "{msg}");
    assert_eq!(err.key(), Some("contact"), "{msg}");
}

#[test]
fn zero_and_negative_dimensions() {
    assert_invalid(
        &set("parts.lower_beam", "thickness", "0.0"),
        "parts.lower_beam.thickness",
        "a finite value > 0 (m)",
    );
    assert_invalid(
        &set("parts.upper_beam", "width_root", "-0.027"),
        "parts.upper_beam.width_root",
        "> 0",
    );
    assert_invalid(&set("rig", "beam_length", "0.0"), "rig.beam_length", "> 0");
    assert_invalid(
        &set("parts.clamp", "base_height", "-1.0"),
        "parts.clamp.base_height",
        "> 0",
    );
    assert_invalid(
        &set("materials.steel", "youngs_modulus", "0.0"),
        "materials.steel.youngs_modulus",
        "> 0 (Pa)",
    );
    assert_invalid(
        &set("materials.nickel_alloy", "poisson_ratio", "0.5"),
        "materials.nickel_alloy.poisson_ratio",
        "(-1, 0.5)",
    );
}

#[test]
fn unknown_material() {
    let text = set("parts.upper_probe", "material", "\"titanium\"");
    assert_invalid(
        &text,
        "parts.upper_probe.material",
        "defined under [materials]",
    );
    let msg = parse(&text).unwrap_err().to_string();
    assert!(
        msg.contains("\"titanium\"") && msg.contains("nickel_alloy, steel"),
        "{msg}"
    );
}

#[test]
fn protrusion_larger_than_the_probe_face() {
    assert_invalid(
        &set("parts.protrusion", "length", "0.020"),
        "parts.protrusion.length",
        "no longer than the probe face",
    );
    assert_invalid(
        &set("parts.protrusion", "width", "0.015"),
        "parts.protrusion.width",
        "no wider than the probe face",
    );
    assert_invalid(
        &set("parts.protrusion", "offset", "[0.005, 0.0]"),
        "parts.protrusion.offset",
        "inside the probe face along x",
    );
}

#[test]
fn protrusion_outside_the_beam_width() {
    assert_invalid(
        &set("parts.protrusion", "offset", "[0.0, 0.009]"),
        "parts.protrusion.offset",
        "inside the beam width",
    );
    // Inside the beam but past the probe's edge.
    assert_invalid(
        &set("parts.protrusion", "offset", "[0.0, -0.006]"),
        "parts.protrusion.offset",
        "inside the probe face along y",
    );
}

#[test]
fn probe_seat_must_fit_the_beams() {
    assert_invalid(
        &set("probe_seat", "width", "0.024"),
        "probe_seat.width",
        "no wider than the beams",
    );
    assert_invalid(
        &set("probe_seat", "x_center", "0.295"),
        "probe_seat.x_center",
        "inside the free span",
    );
    assert_invalid(
        &set("parts.clamp", "width", "0.025"),
        "parts.clamp.width",
        "covering the widest beam root",
    );
}

#[test]
fn contact_node_counts_below_two() {
    assert_invalid(
        &set("contact", "nodes", "[1, 16]"),
        "contact.nodes",
        "at least 2 nodes",
    );
    assert_invalid(
        &set("contact", "nodes", "[12, 0]"),
        "contact.nodes",
        "at least 2 nodes",
    );
    // The model's own patch (`[reduction] contact_nodes`) is checked alike.
    let text = set("reduction", "cutoff_ratio", "180.0\ncontact_nodes = [8, 1]");
    assert_invalid(&text, "reduction.contact_nodes", "at least 2 nodes");
    let text = set(
        "reduction",
        "cutoff_ratio",
        "180.0\ncontact_nodes = [200, 200]",
    );
    assert_invalid(
        &text,
        "reduction.contact_nodes",
        "at most 10000 contact pairs",
    );
}

#[test]
fn clearance_must_be_positive() {
    assert_invalid(
        &set("contact", "clearance", "0.0"),
        "contact.clearance",
        "> 0 (m)",
    );
    assert_invalid(
        &set("contact", "clearance", "-1e-4"),
        "contact.clearance",
        "> 0 (m)",
    );
}

#[test]
fn friction_must_not_be_negative() {
    assert_invalid(
        &set("contact", "friction", "-0.1"),
        "contact.friction",
        "friction coefficient >= 0",
    );
}

#[test]
fn damping_outside_zero_one() {
    let text = reference_text();
    let bad = text.replacen("ratio = 0.00183", "ratio = 1.0", 1);
    assert_invalid(&bad, "damping.ratios[1].ratio", "in [0, 1)");
    let bad = text.replacen("ratio = 0.00153", "ratio = -0.001", 1);
    assert_invalid(&bad, "damping.ratios[0].ratio", "in [0, 1)");
    let bad = text.replacen("label = \"1EU\"", "label = \"1XU\"", 1);
    assert_invalid(&bad, "damping.ratios[2].label", "<order><F|E|T|A><L|U|C>");
}

#[test]
fn reduction_takes_one_selection() {
    let text = reference_text().replacen(
        "cutoff_ratio = 180.0",
        "cutoff_ratio = 180.0\nmodes = 40",
        1,
    );
    assert_invalid(&text, "reduction", "exactly one of");
    assert_invalid(
        &set("reduction", "cutoff_ratio", "0.0"),
        "reduction.cutoff_ratio",
        "> 0",
    );
}

#[test]
fn mesh_settings() {
    assert_invalid(
        &set("mesh.beams", "thickness_cells", "0"),
        "mesh.beams.thickness_cells",
        "2 or more nodes",
    );
    assert_invalid(&set("mesh", "growth", "0.9"), "mesh.growth", ">= 1");
    assert_invalid(
        &set("mesh.probes", "element", "0.0"),
        "mesh.probes.element",
        "> 0",
    );
}

#[test]
fn sensor_off_its_face() {
    let text = reference_text().replacen("x = 0.150 ", "x = 0.350 ", 1);
    assert_invalid(&text, "sensors[1].x", "x in [0, 0.3] m");
    let text = reference_text().replacen("y = -0.015", "y = -0.030", 1);
    assert_invalid(&text, "sensors[4].y", "|y| <= 0.02 m");
}

#[test]
fn unreadable_file_names_the_path() {
    let err = RigConfig::from_path(Path::new("/nonexistent/rig.toml")).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ConfigError::Io { .. }));
    assert!(msg.contains("/nonexistent/rig.toml"), "{msg}");
}

#[test]
fn canonical_hash_ignores_layout_but_not_values() {
    let text = reference_text();
    let h = parse(&text).unwrap().canonical_hash();
    assert_eq!(h.len(), 64);
    assert!(h.chars().all(|c| c.is_ascii_hexdigit()));
    // Comments, blank lines and number spelling do not matter.
    let stripped: String = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim_end())
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("\n")
        .replace("clearance = 0.699e-3", "clearance = 0.000699");
    let other = RigConfig::from_str(&stripped, "elsewhere.toml").unwrap();
    assert_eq!(other.canonical_hash(), h);
    // Omitting a key that holds its default does not matter.
    let no_friction = text.replacen("friction = 0.4", "", 1);
    assert_eq!(parse(&no_friction).unwrap().canonical_hash(), h);
    // A changed value does.
    let changed = set("contact", "clearance", "0.0007");
    assert_ne!(parse(&changed).unwrap().canonical_hash(), h);
}

/// The reference text with the simulated rig's hidden physics appended.
fn with_variants(tables: &str) -> String {
    format!("{}\n{tables}", reference_text())
}

#[test]
fn truth_variants_parse_and_stay_out_of_the_hash() {
    let h = parse(&reference_text()).unwrap().canonical_hash();
    let cfg = parse(&with_variants(
        "[truth.variants]\n\
         sensor_gains = [{ channel = \"upper_tip\", gain = 1.03 }]\n\
         [truth.variants.clamp_friction]\n\
         stiffness_fraction = 0.1\n\
         half_slip_tip_amplitude = 2e-4\n\
         beams = [\"upper\"]\n\
         [truth.variants.wear]\n\
         coefficient = 1e-6\n\
         max_growth = 5e-5\n\
         [truth.variants.tilt]\n\
         angle = 2e-3\n",
    ))
    .unwrap();
    let v = &SimRigSpec::from_config(&cfg).truth.variants;
    assert!(v.any());
    assert_eq!(v.clamp_friction.as_ref().unwrap().sliders, 64);
    assert_eq!(v.wear.as_ref().unwrap().max_growth, Some(5e-5));
    assert_eq!(v.tilt.as_ref().unwrap().axis, [0.0, 1.0]);
    // Sim-only: the ROM identity does not change.
    assert_eq!(cfg.canonical_hash(), h);
    // The embedded default has no hidden physics.
    assert!(!RigConfig::default_rig().truth.variants.any());
}

#[test]
fn truth_variants_bad_input_names_the_key() {
    // A misspelled key: a schema error with its dotted path and line.
    let text = with_variants("[truth.variants.wear]\ncoeficient = 1e-6\n");
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ConfigError::Schema { .. }), "{msg}");
    assert_eq!(err.key(), Some("truth.variants.wear.coeficient"), "{msg}");
    let line = text
        .lines()
        .position(|l| l.starts_with("coeficient"))
        .unwrap()
        + 1;
    assert!(msg.starts_with(&format!("{FILE}:{line}:")), "{msg}");
    assert!(
        msg.contains("expected `coefficient` or `max_growth`"),
        "{msg}"
    );

    let err = parse(&with_variants("[truth.variants]\nclamp = 1\n")).unwrap_err();
    assert_eq!(err.key(), Some("truth.variants.clamp"), "{err}");

    let err = parse(&with_variants(
        "[truth.variants]\nsensor_gains = [{ channel = \"upper_tip\", gain = \"high\" }]\n",
    ))
    .unwrap_err();
    assert!(err.to_string().contains("expected f64"), "{err}");

    // Out-of-range values and an unknown channel: the key, the value and what was expected.
    for (tables, expect) in [
        (
            "[truth.variants.clamp_friction]\nstiffness_fraction = 1.5\n\
             half_slip_tip_amplitude = 2e-4\n",
            "truth.variants.clamp_friction.stiffness_fraction = 1.5: expected a share of the \
             modal stiffness in [0, 1)",
        ),
        (
            "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
             half_slip_tip_amplitude = -2e-4\n",
            "truth.variants.clamp_friction.half_slip_tip_amplitude = -0.0002: expected",
        ),
        (
            "[truth.variants.wear]\ncoefficient = nan\n",
            "truth.variants.wear.coefficient = NaN: expected",
        ),
        (
            "[truth.variants.tilt]\nangle = -0.2\n",
            "truth.variants.tilt.angle = -0.2: expected a tilt angle with |angle| <= 0.1 rad",
        ),
        (
            "[truth.variants]\nsensor_gains = [{ channel = \"upper_tipp\", gain = 1.03 }]\n",
            "truth.variants.sensor_gains[0].channel = \"upper_tipp\": expected a DAQ channel \
             name (channels: platform_1",
        ),
    ] {
        let err = parse(&with_variants(tables)).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, ConfigError::Service { .. }), "{msg}");
        assert!(msg.starts_with(FILE), "{msg}");
        assert!(msg.contains(expect), "{tables}\n-> {msg}");
    }
}

#[test]
fn documented_truth_variants_examples_are_valid() {
    // The commented example at the end of two-beam.toml, uncommented.
    let text = reference_text();
    let start = text
        .find("# [truth.variants]\n")
        .expect("example in two-beam.toml");
    let example: String = text[start..]
        .lines()
        .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
        .collect::<Vec<_>>()
        .join("\n");
    let cfg = parse(&format!("{}\n{example}\n", &text[..start])).unwrap();
    let v = SimRigSpec::from_config(&cfg).truth.variants;
    assert!(v.clamp_friction.is_some() && v.wear.is_some() && v.tilt.is_some());
    assert_eq!(v.sensor_gains.len(), 1);
    // The example in rig-config/README.md.
    let readme = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rig-config/README.md"),
    )
    .unwrap();
    let blocks: Vec<&str> = readme
        .split("```toml\n")
        .skip(1)
        .filter_map(|b| b.split("```").next())
        .collect();
    let block = blocks
        .iter()
        .find(|b| b.starts_with("[truth.variants]"))
        .expect("a [truth.variants] toml block in rig-config/README.md");
    // The `[model]` example is valid and switches on every extension.
    let model_block = blocks
        .iter()
        .find(|b| b.starts_with("[model]"))
        .expect("a [model] toml block in rig-config/README.md");
    let cfg = parse(&format!("{}\n{model_block}", &text[..start])).unwrap();
    assert_eq!(
        cfg.model.effects(),
        [
            "modes",
            "clamp_friction",
            "clearance",
            "wear",
            "tilt",
            "sensor_gains"
        ]
    );
    let from_readme = SimRigSpec::from_config(&parse(&with_variants(block)).unwrap())
        .truth
        .variants;
    assert_eq!(from_readme, v);
    // The `[twin]` example (the last toml block of rig-config/README.md).
    let twin_block = readme
        .split("```toml\n")
        .last()
        .and_then(|b| b.split("```").next())
        .unwrap();
    assert!(twin_block.starts_with("[twin]"), "{twin_block}");
    let cfg = parse(&format!("{}\n{twin_block}", &text[..start])).unwrap();
    assert_eq!(
        (cfg.twin.steps_per_reference_period, cfg.twin.queue_blocks),
        (2000.0, 80)
    );
}

/// `[model]`: a table written by a program reads back identically, and the description stays
/// the same otherwise (its canonical hash: `[model]` is not part of the ROM's identity).
#[test]
fn model_table_round_trips_and_is_not_hashed() {
    use rigtwin::config::{
        with_model, Beam, ClampFrictionSpec, ClearanceSpec, ModalCorrectionSpec, PhysicsSpec,
        RigConfig, SensorGainSpec, TestClearanceSpec, TiltSpec, WearSpec, DEFAULT_RIG_TOML,
    };
    let model = PhysicsSpec {
        modes: vec![ModalCorrectionSpec {
            mode: "1FU".into(),
            frequency_hz: Some(101.23456789012345),
            damping_ratio: Some(0.00104),
        }],
        clamp_friction: Some(ClampFrictionSpec {
            stiffness_fraction: 0.0731,
            half_slip_tip_amplitude: 3.3e-5,
            sliders: 48,
            beams: vec![Beam::Upper],
        }),
        clearance: Some(ClearanceSpec {
            offset: -1.234e-6,
            tests: vec![TestClearanceSpec {
                test: "3-high-up".into(),
                clearance: 1.2345678e-3,
            }],
        }),
        wear: Some(WearSpec {
            coefficient: 2.5e-7,
            max_growth: Some(1e-4),
        }),
        tilt: Some(TiltSpec {
            angle: -2.2e-3,
            axis: [0.6, 0.8],
        }),
        sensor_gains: vec![SensorGainSpec {
            channel: "lower_tip".into(),
            gain: 0.9512345,
        }],
    };
    let text = with_model(DEFAULT_RIG_TOML, "default", &model).unwrap();
    let cfg = RigConfig::from_str(&text, "written").unwrap();
    assert_eq!(cfg.model, model);
    let nominal = RigConfig::default_rig();
    assert_eq!(
        cfg.model().canonical_hash(),
        nominal.model().canonical_hash()
    );
    // Written again from the written text: the same text.
    assert_eq!(with_model(&text, "written", &model).unwrap(), text);
    // No extension: no [model] table.
    let plain = with_model(&text, "written", &PhysicsSpec::default()).unwrap();
    assert!(!plain.contains("[model"), "{plain}");
    assert_eq!(
        RigConfig::from_str(&plain, "plain").unwrap().model,
        PhysicsSpec::default()
    );
}

/// The twin's discretisation written by `diagnose --write-config` (the `discretisation`
/// effect accepted): `[reduction]` replaced, the twin's step set by steps per 1FU period with
/// `steps_per_sample` removed, everything else as it was.
#[test]
fn discretisation_is_written_into_reduction_and_twin() {
    use rigtwin::config::{with_discretisation, ReductionSpec, DEFAULT_RIG_TOML};
    let coarse = DEFAULT_RIG_TOML.replace("cutoff_ratio = 180.0", "modes = 8")
        + "\n[twin]\nsteps_per_sample = 1\nqueue_blocks = 80\n";
    let given = RigConfig::from_str(&coarse, "coarse").unwrap();
    assert_eq!(given.reduction.modes, Some(8));
    assert_eq!(given.twin.steps_per_sample, Some(1));
    let reference = ReductionSpec {
        cutoff_ratio: Some(180.0),
        ..ReductionSpec::default()
    };
    let text = with_discretisation(&coarse, "coarse", Some(&reference), Some(1000.0)).unwrap();
    let fixed = RigConfig::from_str(&text, "fixed").unwrap();
    assert_eq!(fixed.reduction, reference);
    assert_eq!(fixed.twin.steps_per_sample, None);
    assert_eq!(fixed.twin.steps_per_reference_period, 1000.0);
    assert_eq!(fixed.twin.queue_blocks, 80);
    // The reference reduction is the default rig's: the same ROM.
    assert_eq!(
        fixed.model().canonical_hash(),
        RigConfig::default_rig().model().canonical_hash()
    );
    // The step alone: [reduction] kept, a [twin] table made where there was none.
    let text = with_discretisation(DEFAULT_RIG_TOML, "default", None, Some(2000.0)).unwrap();
    let step = RigConfig::from_str(&text, "step").unwrap();
    assert_eq!(step.reduction, RigConfig::default_rig().reduction);
    assert_eq!(step.twin.steps_per_reference_period, 2000.0);
    // A `twin` key that is not a table is a clear error naming the file.
    let bad = format!("twin = 3\n{DEFAULT_RIG_TOML}");
    let e = with_discretisation(&bad, "bad.toml", None, Some(1000.0)).unwrap_err();
    assert!(e.to_string().contains("bad.toml"), "{e}");
}

/// Bad `[model]` values name the file and the key.
#[test]
fn bad_model_values_name_the_file_and_key() {
    use rigtwin::config::{RigConfig, DEFAULT_RIG_TOML};
    for (table, expect) in [
        (
            "[model]\nmodes = [{ mode = \"1FU\", damping_ratio = -0.01 }]\n",
            "model.modes[0].damping_ratio = -0.01: expected",
        ),
        (
            "[model]\nmodes = [{ mode = \"1FU\" }]\n",
            "model.modes[0].frequency_hz",
        ),
        (
            "[model]\nmodes = [{ mode = \"1FU\", frequency_hz = 100.0 }, { mode = \"1FU\", \
             frequency_hz = 101.0 }]\n",
            "model.modes[1].mode = \"1FU\": expected each mode listed once",
        ),
        (
            "[model.tilt]\nangle = 0.2\n",
            "model.tilt.angle = 0.2: expected",
        ),
        (
            "[model]\nsensor_gains = [{ channel = \"upper_tipp\", gain = 1.1 }]\n",
            "model.sensor_gains[0].channel = \"upper_tipp\": expected a DAQ channel name",
        ),
        (
            "[model.clearance]\noffset = 0.5\n",
            "model.clearance.offset = 0.5: expected",
        ),
        (
            "[model.wear]\ncoefficient = -1.0\n",
            "model.wear.coefficient = -1: expected",
        ),
        ("[model]\nmode = []\n", "unknown field `mode`"),
    ] {
        let text = format!("{DEFAULT_RIG_TOML}\n{table}");
        let msg = RigConfig::from_str(&text, "rig.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("rig.toml") && msg.contains(expect),
            "{table}\n-> {msg}"
        );
    }
}
