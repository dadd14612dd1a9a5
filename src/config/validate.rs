//! Semantic checks of a parsed rig description: positive dimensions, known materials, a
//! contact patch that fits the probes and the beams, node counts, clearance, friction,
//! damping ratios, mesh sizes, sensors and the reduction ([`model`]), then the rig-service
//! tables ([`service`]). The first failing check is reported with its key path, the bad value
//! and what was expected.

use super::damping::is_valid_label;
use super::schema::Mount;
use super::{ConfigError, RigConfig, RigModel};

/// Collects the file name for the error constructors.
struct Check<'a> {
    file: &'a str,
}

impl Check<'_> {
    fn fail(&self, key: &str, value: impl std::fmt::Display, expected: &str) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_string(),
            key: key.to_string(),
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }

    fn positive(&self, key: &str, v: f64, unit: &str) -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, v, &format!("a finite value > 0 ({unit})")))
        }
    }

    fn finite(&self, key: &str, v: f64, unit: &str) -> Result<(), ConfigError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(self.fail(key, v, &format!("a finite value ({unit})")))
        }
    }

    fn material(&self, cfg: &RigModel, key: &str, name: &str) -> Result<(), ConfigError> {
        if cfg.materials.contains_key(name) {
            Ok(())
        } else {
            let known: Vec<&str> = cfg.materials.keys().map(String::as_str).collect();
            Err(self.fail(
                key,
                format!("\"{name}\""),
                &format!(
                    "the name of a material defined under [materials] (known: {})",
                    known.join(", ")
                ),
            ))
        }
    }
}

/// Validates the model part of a description.
pub(super) fn model(cfg: &RigModel) -> Result<(), ConfigError> {
    let c = Check { file: cfg.source };
    if cfg.rig.name.trim().is_empty() {
        return Err(c.fail("rig.name", "\"\"", "a non-empty rig name"));
    }
    c.positive("rig.beam_length", cfg.rig.beam_length, "m")?;
    materials(&c, cfg)?;
    parts(&c, cfg)?;
    seat_and_patch(&c, cfg)?;
    layers(&c, cfg)?;
    contact(&c, cfg)?;
    damping(&c, cfg)?;
    mesh(&c, cfg)?;
    sensors(&c, cfg)?;
    reduction(&c, cfg)
}

/// Validates the rig-service tables of a description: `[control]`, `[safety]`, `[twin]`,
/// then the simulated rig's `[shaker]`, `[daq]` and `[truth]`, and the model's `[model]`.
pub(super) fn service(cfg: &RigConfig) -> Result<(), ConfigError> {
    let service = |message: String| ConfigError::Service {
        file: cfg.source.clone(),
        message,
    };
    cfg.control.validate().map_err(|e| service(e.to_string()))?;
    cfg.safety.validate().map_err(|e| service(e.to_string()))?;
    // NOTE: the prefixes are those the twin's and the simulated rig's errors put on a bad
    // value (`TwinError::Spec`, `SimRigError::Spec`); the messages carried them before the
    // specs moved here.
    cfg.twin
        .validate()
        .map_err(|e| service(format!("twin spec: {e}")))?;
    let sim = |e: super::SpecError| service(format!("simulated rig spec: {e}"));
    cfg.shaker.validate().map_err(sim)?;
    cfg.daq.validate().map_err(sim)?;
    cfg.truth.validate(&cfg.daq).map_err(sim)?;
    cfg.model
        .validate("model", &cfg.daq)
        .map_err(|e| service(e.to_string()))
}

fn materials(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    if cfg.materials.is_empty() {
        return Err(c.fail("materials", "{}", "at least one [materials.<name>] table"));
    }
    for (name, m) in cfg.materials {
        let key = |f: &str| format!("materials.{name}.{f}");
        c.positive(&key("youngs_modulus"), m.youngs_modulus, "Pa")?;
        c.positive(&key("density"), m.density, "kg/m^3")?;
        if !(m.poisson_ratio > -1.0 && m.poisson_ratio < 0.5) {
            return Err(c.fail(
                &key("poisson_ratio"),
                m.poisson_ratio,
                "a Poisson's ratio in (-1, 0.5)",
            ));
        }
    }
    Ok(())
}

fn parts(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let p = &cfg.parts;
    c.material(cfg, "parts.clamp.material", &p.clamp.material)?;
    c.material(cfg, "parts.lower_beam.material", &p.lower_beam.material)?;
    c.material(cfg, "parts.upper_beam.material", &p.upper_beam.material)?;
    c.material(cfg, "parts.lower_probe.material", &p.lower_probe.material)?;
    c.material(cfg, "parts.upper_probe.material", &p.upper_probe.material)?;
    c.material(cfg, "parts.protrusion.material", &p.protrusion.material)?;
    for (key, v) in [
        ("parts.clamp.length", p.clamp.length),
        ("parts.clamp.width", p.clamp.width),
        ("parts.clamp.base_height", p.clamp.base_height),
        ("parts.clamp.top_height", p.clamp.top_height),
        ("parts.lower_beam.width", p.lower_beam.width),
        ("parts.lower_beam.thickness", p.lower_beam.thickness),
        ("parts.upper_beam.width_root", p.upper_beam.width_root),
        ("parts.upper_beam.width_tip", p.upper_beam.width_tip),
        ("parts.upper_beam.thickness", p.upper_beam.thickness),
        ("parts.lower_probe.height", p.lower_probe.height),
        ("parts.upper_probe.height", p.upper_probe.height),
        ("parts.protrusion.length", p.protrusion.length),
        ("parts.protrusion.width", p.protrusion.width),
        ("parts.protrusion.height", p.protrusion.height),
    ] {
        c.positive(key, v, "m")?;
    }
    let widest = p.lower_beam.width.max(p.upper_beam.width_root);
    if p.clamp.width < widest {
        return Err(c.fail(
            "parts.clamp.width",
            p.clamp.width,
            &format!("a block width covering the widest beam root ({widest} m)"),
        ));
    }
    Ok(())
}

fn seat_and_patch(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let s = &cfg.probe_seat;
    let l = cfg.rig.beam_length;
    c.finite("probe_seat.x_center", s.x_center, "m")?;
    c.positive("probe_seat.length", s.length, "m")?;
    c.positive("probe_seat.width", s.width, "m")?;
    let (x0, x1) = (s.x_center - 0.5 * s.length, s.x_center + 0.5 * s.length);
    if !(x0 > 0.0 && x1 <= l * (1.0 + 1e-12)) {
        return Err(c.fail(
            "probe_seat.x_center",
            s.x_center,
            &format!(
                "a seat [x_center -+ length/2] = [{x0}, {x1}] m inside the free span (0, {l}] m"
            ),
        ));
    }
    let narrowest = cfg
        .parts
        .lower_beam
        .width
        .min(cfg.parts.upper_beam.width_tip);
    if s.width > narrowest * (1.0 + 1e-12) {
        return Err(c.fail(
            "probe_seat.width",
            s.width,
            &format!("a probe footprint no wider than the beams under it ({narrowest} m)"),
        ));
    }
    let pr = &cfg.parts.protrusion;
    c.finite("parts.protrusion.offset", pr.offset[0], "m")?;
    c.finite("parts.protrusion.offset", pr.offset[1], "m")?;
    if pr.length > s.length {
        return Err(c.fail(
            "parts.protrusion.length",
            pr.length,
            &format!(
                "a protrusion no longer than the probe face (probe_seat.length = {} m)",
                s.length
            ),
        ));
    }
    if pr.width > s.width {
        return Err(c.fail(
            "parts.protrusion.width",
            pr.width,
            &format!(
                "a protrusion no wider than the probe face (probe_seat.width = {} m)",
                s.width
            ),
        ));
    }
    let tol = 1e-12 * l;
    let px = (
        pr.offset[0] - 0.5 * pr.length,
        pr.offset[0] + 0.5 * pr.length,
    );
    if px.0 < -0.5 * s.length - tol || px.1 > 0.5 * s.length + tol {
        return Err(c.fail(
            "parts.protrusion.offset",
            format!("[{}, {}]", pr.offset[0], pr.offset[1]),
            &format!(
                "a protrusion inside the probe face along x: |offset x| + length/2 <= {} m",
                0.5 * s.length
            ),
        ));
    }
    let py = (pr.offset[1] - 0.5 * pr.width, pr.offset[1] + 0.5 * pr.width);
    let half_beam = 0.5
        * cfg
            .parts
            .lower_beam
            .width
            .min(cfg.parts.upper_beam.width_tip);
    if py.0 < -half_beam - tol || py.1 > half_beam + tol {
        return Err(c.fail(
            "parts.protrusion.offset",
            format!("[{}, {}]", pr.offset[0], pr.offset[1]),
            &format!("a protrusion inside the beam width: |offset y| + width/2 <= {half_beam} m"),
        ));
    }
    if py.0 < -0.5 * s.width - tol || py.1 > 0.5 * s.width + tol {
        return Err(c.fail(
            "parts.protrusion.offset",
            format!("[{}, {}]", pr.offset[0], pr.offset[1]),
            &format!(
                "a protrusion inside the probe face along y: |offset y| + width/2 <= {} m",
                0.5 * s.width
            ),
        ));
    }
    Ok(())
}

fn layers(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    for (name, l) in cfg.layers.named() {
        c.positive(&format!("layers.{name}.normal"), l.normal, "N/m^3")?;
        c.positive(&format!("layers.{name}.tangential"), l.tangential, "N/m^3")?;
    }
    Ok(())
}

/// What is wrong with a contact patch grid `[across y, along x]` (`[contact] nodes`,
/// `[reduction] contact_nodes`, `[twin.held_contact] contact_nodes`), if anything: at least 2
/// nodes along each edge, at most 10000 pairs.
pub(super) fn patch_nodes_problem(nodes: [usize; 2]) -> Option<&'static str> {
    if nodes.iter().any(|&n| n < 2) {
        Some("at least 2 nodes along each edge of the patch ([across y, along x])")
    } else if nodes[0].saturating_mul(nodes[1]) > 10_000 {
        Some("at most 10000 contact pairs")
    } else {
        None
    }
}

fn patch_nodes(c: &Check, key: &str, nodes: [usize; 2]) -> Result<(), ConfigError> {
    match patch_nodes_problem(nodes) {
        Some(expected) => Err(c.fail(key, format!("[{}, {}]", nodes[0], nodes[1]), expected)),
        None => Ok(()),
    }
}

fn contact(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let k = &cfg.contact;
    patch_nodes(c, "contact.nodes", k.nodes)?;
    c.positive("contact.clearance", k.clearance, "m")?;
    if !(k.friction.is_finite() && k.friction >= 0.0) {
        return Err(c.fail(
            "contact.friction",
            k.friction,
            "a friction coefficient >= 0",
        ));
    }
    Ok(())
}

fn damping(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let d = &cfg.damping;
    if d.ratios.is_empty() {
        return Err(c.fail(
            "damping.ratios",
            "[]",
            "at least one identified ratio { label, ratio }",
        ));
    }
    for (i, m) in d.ratios.iter().enumerate() {
        if !is_valid_label(&m.label) {
            return Err(c.fail(
                &format!("damping.ratios[{i}].label"),
                format!("\"{}\"", m.label),
                "a mode label <order><F|E|T|A><L|U|C>, e.g. 1FL, 2FU, 1EL, 1FC",
            ));
        }
        if d.ratios[..i].iter().any(|o| o.label == m.label) {
            return Err(c.fail(
                &format!("damping.ratios[{i}].label"),
                format!("\"{}\"", m.label),
                "each label listed once",
            ));
        }
        if !(m.ratio >= 0.0 && m.ratio < 1.0) {
            return Err(c.fail(
                &format!("damping.ratios[{i}].ratio"),
                m.ratio,
                "a damping ratio in [0, 1) (a fraction, not percent)",
            ));
        }
    }
    Ok(())
}

fn mesh(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let m = &cfg.mesh;
    if !(m.growth.is_finite() && m.growth >= 1.0) {
        return Err(c.fail("mesh.growth", m.growth, "a growth ratio >= 1"));
    }
    let b = &m.beams;
    for (key, v) in [
        ("mesh.beams.free_element", b.free_element),
        ("mesh.beams.clamp_exit_element", b.clamp_exit_element),
        ("mesh.beams.clamp_element", b.clamp_element),
        ("mesh.beams.seat_element", b.seat_element),
        ("mesh.beams.width_element", b.width_element),
        ("mesh.blocks.element", m.blocks.element),
        ("mesh.probes.element", m.probes.element),
    ] {
        c.positive(key, v, "m")?;
        // NOTE: a size far below the geometry would explode the node count.
        if v < 1e-5 * cfg.rig.beam_length {
            return Err(c.fail(
                key,
                v,
                &format!("an element size >= {} m", 1e-5 * cfg.rig.beam_length),
            ));
        }
    }
    if b.thickness_cells < 1 || b.thickness_cells > 64 {
        return Err(c.fail(
            "mesh.beams.thickness_cells",
            b.thickness_cells,
            "1 to 64 cells through the thickness (2 or more nodes)",
        ));
    }
    if !(m.probes.growth.is_finite() && m.probes.growth >= 1.0) {
        return Err(c.fail("mesh.probes.growth", m.probes.growth, "a growth ratio >= 1"));
    }
    Ok(())
}

fn sensors(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let l = cfg.rig.beam_length;
    let clamp = &cfg.parts.clamp;
    for (i, s) in cfg.sensors.iter().enumerate() {
        let key = |f: &str| format!("sensors[{i}].{f}");
        if s.name.is_empty()
            || !s
                .name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
        {
            return Err(c.fail(
                &key("name"),
                format!("\"{}\"", s.name),
                "a non-empty name of letters, digits and '_'",
            ));
        }
        if cfg.sensors[..i].iter().any(|o| o.name == s.name) {
            return Err(c.fail(
                &key("name"),
                format!("\"{}\"", s.name),
                "a unique sensor name",
            ));
        }
        c.finite(&key("x"), s.x, "m")?;
        c.finite(&key("y"), s.y, "m")?;
        if !(s.mass.is_finite() && s.mass >= 0.0) {
            return Err(c.fail(&key("mass"), s.mass, "a mass >= 0 (kg)"));
        }
        let norm = s.direction.iter().map(|d| d * d).sum::<f64>().sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(c.fail(
                &key("direction"),
                format!("{:?}", s.direction),
                "a non-zero direction vector",
            ));
        }
        let (x_range, half_width) = match s.mount {
            Mount::LowerBeamTop | Mount::LowerBeamBottom => {
                ((0.0, l), 0.5 * cfg.parts.lower_beam.width)
            }
            Mount::UpperBeamTop | Mount::UpperBeamBottom => {
                ((0.0, l), 0.5 * cfg.upper_width_at(s.x.clamp(0.0, l)))
            }
            Mount::Platform => ((-clamp.length, 0.0), 0.5 * clamp.width),
        };
        let tol = 1e-12 * l;
        if s.x < x_range.0 - tol || s.x > x_range.1 + tol {
            return Err(c.fail(
                &key("x"),
                s.x,
                &format!(
                    "a position on the mounting face, x in [{}, {}] m",
                    x_range.0, x_range.1
                ),
            ));
        }
        if s.y.abs() > half_width + tol {
            return Err(c.fail(
                &key("y"),
                s.y,
                &format!("a position on the mounting face, |y| <= {half_width} m"),
            ));
        }
    }
    Ok(())
}

fn reduction(c: &Check, cfg: &RigModel) -> Result<(), ConfigError> {
    let r = &cfg.reduction;
    let set = [
        r.cutoff_ratio.is_some(),
        r.cutoff_hz.is_some(),
        r.modes.is_some(),
    ]
    .iter()
    .filter(|&&b| b)
    .count();
    if set > 1 {
        return Err(c.fail(
            "reduction",
            "several selections",
            "exactly one of cutoff_ratio, cutoff_hz, modes",
        ));
    }
    if let Some(v) = r.cutoff_ratio {
        c.positive("reduction.cutoff_ratio", v, "multiple of f(1FU)")?;
    }
    if let Some(v) = r.cutoff_hz {
        c.positive("reduction.cutoff_hz", v, "Hz")?;
    }
    if r.modes == Some(0) {
        return Err(c.fail("reduction.modes", 0, "at least 1 mode"));
    }
    if let Some(nodes) = r.contact_nodes {
        patch_nodes(c, "reduction.contact_nodes", nodes)?;
    }
    Ok(())
}
