//! Export of a [`Mesh`] as two self-contained CalculiX decks: `JOB.inp` (eigenfrequencies)
//! and `JOB_matrix.inp` (stiffness and mass matrices). The layout and the set and comment
//! conventions are described in the module docs of [`crate::fe::calculix`].

use std::collections::{BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::CalculixError;
use crate::fe::mesh::Mesh;

/// The files [`export`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportedFiles {
    /// `dir/JOB.inp`: the model with a `*FREQUENCY` step for the requested number of modes.
    pub frequency_deck: PathBuf,
    /// `dir/JOB_matrix.inp`: the same model with `*FREQUENCY,SOLVER=MATRIXSTORAGE`.
    pub matrix_deck: PathBuf,
    /// Job name of the frequency deck (`JOB`, for `ccx -i JOB`).
    pub job: String,
    /// Job name of the matrix deck (`JOB_matrix`).
    pub matrix_job: String,
}

impl ExportedFiles {
    /// Both decks: the frequency deck, then the matrix deck.
    pub fn paths(&self) -> [&Path; 2] {
        [&self.frequency_deck, &self.matrix_deck]
    }
}

/// CalculiX reads names up to this length.
const MAX_NAME: usize = 80;
/// Characters ccx reads of a numeric field.
const FIELD_WIDTH: usize = 20;
/// Ids per `*NSET` data line.
const IDS_PER_LINE: usize = 16;

/// The CalculiX spelling of a name: upper case, characters other than `A-Z`, `0-9`, `_`
/// replaced by `_`.
pub(crate) fn ccx_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            let c = c.to_ascii_uppercase();
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A real in at most 20 characters (ccx reads numeric fields as 20 characters) with a
/// decimal point (ccx takes `1e6` on a `*SPRING` line for the DOF line): the shortest exact
/// form when it fits, else the most digits that fit (at least 13).
fn real(x: f64) -> String {
    let mut exact = format!("{x:e}");
    if !exact.contains('.') {
        if let Some(e) = exact.find('e') {
            exact.insert_str(e, ".0");
        }
    }
    if exact.len() <= FIELD_WIDTH {
        return exact;
    }
    (12..16)
        .rev()
        .map(|p| format!("{x:.p$e}"))
        .find(|s| s.len() <= FIELD_WIDTH)
        .unwrap_or_else(|| format!("{x:.12e}"))
}

fn invalid(what: impl Into<String>) -> CalculixError {
    CalculixError::InvalidMesh { what: what.into() }
}

/// Writes `dir/JOB.inp` (a `*FREQUENCY` step for `n_modes` modes) and `dir/JOB_matrix.inp`
/// (`*FREQUENCY,SOLVER=MATRIXSTORAGE`) for `mesh`. Both decks hold the complete model
/// (ccx resolves `*INCLUDE` against its working directory, so they include nothing).
///
/// Note that ccx's eigen solver fails when more than about a fifth of the equations are
/// requested as modes (see the module docs); the matrix deck has no such limit.
pub fn export(
    mesh: &Mesh,
    dir: &Path,
    job: &str,
    n_modes: usize,
) -> Result<ExportedFiles, CalculixError> {
    if job.is_empty()
        || !job
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(invalid(format!(
            "job name `{job}`: expected letters, digits, `_` or `-` (it becomes a file name)"
        )));
    }
    if n_modes == 0 {
        return Err(invalid("n_modes = 0: expected at least one mode"));
    }
    validate(mesh)?;
    let model = model_text(mesh, job)?;
    let matrix_job = format!("{job}_matrix");
    let frequency_deck = dir.join(format!("{job}.inp"));
    let matrix_deck = dir.join(format!("{matrix_job}.inp"));
    let write = |path: &Path, step: &str| {
        std::fs::write(path, format!("{model}{step}")).map_err(|e| CalculixError::io(path, e))
    };
    write(
        &frequency_deck,
        &format!("*STEP\n*FREQUENCY\n{n_modes}\n*END STEP\n"),
    )?;
    write(
        &matrix_deck,
        &format!(
            "** K, M and the DOF list go to {matrix_job}.sti, .mas, .dof (no eigenvalues)\n\
             *STEP\n*FREQUENCY,SOLVER=MATRIXSTORAGE\n*END STEP\n"
        ),
    )?;
    Ok(ExportedFiles {
        frequency_deck,
        matrix_deck,
        job: job.to_string(),
        matrix_job,
    })
}

/// Checks indices, values and names before anything is written.
fn validate(mesh: &Mesh) -> Result<(), CalculixError> {
    let n = mesh.nodes.len();
    let node = |i: usize, what: String| {
        if i < n {
            Ok(())
        } else {
            Err(invalid(format!(
                "{what} refers to node {i}, but the mesh has {n} nodes (0-based)"
            )))
        }
    };
    for (i, x) in mesh.nodes.iter().enumerate() {
        if !x.iter().all(|v| v.is_finite()) {
            return Err(invalid(format!(
                "node {i} has a non-finite coordinate {x:?}"
            )));
        }
    }
    for (e, el) in mesh.elements.iter().enumerate() {
        for &a in &el.nodes {
            node(a, format!("element {e}"))?;
        }
        if el.block >= mesh.blocks.len() {
            return Err(invalid(format!(
                "element {e} is in block {}, but the mesh has {} blocks",
                el.block,
                mesh.blocks.len()
            )));
        }
    }
    for b in &mesh.blocks {
        if b.material >= mesh.materials.len() {
            return Err(invalid(format!(
                "block {} uses material {}, but the mesh has {} materials",
                b.name,
                b.material,
                mesh.materials.len()
            )));
        }
    }
    for m in &mesh.materials {
        let ok = m.youngs_modulus > 0.0
            && m.youngs_modulus.is_finite()
            && m.poisson_ratio > -1.0
            && m.poisson_ratio < 0.5
            && m.density >= 0.0
            && m.density.is_finite();
        if !ok {
            return Err(invalid(format!(
                "material {}: expected E > 0 Pa, -1 < nu < 0.5, density >= 0 kg/m^3, found \
                 E = {:e}, nu = {}, density = {:e}",
                m.name, m.youngs_modulus, m.poisson_ratio, m.density
            )));
        }
    }
    for (s, sp) in mesh.springs.iter().enumerate() {
        node(sp.a, format!("spring {s}"))?;
        node(sp.b, format!("spring {s}"))?;
        if sp.a == sp.b {
            return Err(invalid(format!(
                "spring {s} connects node {} to itself",
                sp.a
            )));
        }
        if !sp.stiffness.iter().all(|k| *k >= 0.0 && k.is_finite()) {
            return Err(invalid(format!(
                "spring {s}: expected finite stiffnesses >= 0 N/m, found {:?}",
                sp.stiffness
            )));
        }
        if sp.layer >= mesh.layers.len() {
            return Err(invalid(format!(
                "spring {s} is in layer {}, but the mesh names {} layers",
                sp.layer,
                mesh.layers.len()
            )));
        }
    }
    for p in &mesh.point_masses {
        node(p.node, format!("point mass {}", p.name))?;
        if !(p.mass > 0.0 && p.mass.is_finite()) {
            return Err(invalid(format!(
                "point mass {}: expected a mass > 0 kg, found {:e}",
                p.name, p.mass
            )));
        }
    }
    for &f in &mesh.fixed_nodes {
        node(f, "the fixed nodes".into())?;
    }
    for (k, p) in mesh.contact_pairs.iter().enumerate() {
        node(p.lower, format!("contact pair {k}"))?;
        node(p.upper, format!("contact pair {k}"))?;
        if p.lower == p.upper {
            return Err(invalid(format!(
                "contact pair {k} pairs node {} with itself",
                p.lower
            )));
        }
        let f = &p.frame;
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let t2 = super::patch::cross(f[0], f[1]);
        let orthonormal = (0..3).all(|i| (dot(f[i], f[i]) - 1.0).abs() < 1e-9)
            && dot(f[0], f[1]).abs() < 1e-9
            && (dot(t2, f[2]) - 1.0).abs() < 1e-9;
        if !orthonormal {
            return Err(invalid(format!(
                "contact pair {k}: expected an orthonormal right-handed frame (n, t1, t2), \
                 found {f:?}"
            )));
        }
        if !(p.area > 0.0 && p.area.is_finite()) {
            return Err(invalid(format!(
                "contact pair {k}: expected an area > 0 m^2, found {:e}",
                p.area
            )));
        }
    }
    for s in &mesh.sensors {
        node(s.node, format!("sensor {}", s.name))?;
        if s.name.is_empty() || s.name.chars().any(char::is_whitespace) {
            return Err(invalid(format!(
                "sensor name `{}`: expected a non-empty name without spaces",
                s.name
            )));
        }
        let l2: f64 = s.direction.iter().map(|d| d * d).sum();
        if !(l2 > 0.0 && l2.is_finite()) {
            return Err(invalid(format!(
                "sensor {}: expected a nonzero direction, found {:?}",
                s.name, s.direction
            )));
        }
    }
    for (name, members) in &mesh.node_sets {
        for &m in members {
            node(m, format!("node set {name}"))?;
        }
    }
    Ok(())
}

/// Registers a CalculiX name, rejecting collisions and over-long names.
struct Names {
    used: HashMap<String, String>,
    kind: &'static str,
}

impl Names {
    fn new(kind: &'static str) -> Self {
        Names {
            used: HashMap::new(),
            kind,
        }
    }

    fn add(&mut self, ccx: String, origin: &str) -> Result<String, CalculixError> {
        if ccx.is_empty() || ccx.len() > MAX_NAME {
            return Err(invalid(format!(
                "{} name `{ccx}` (from {origin}): expected 1 to {MAX_NAME} characters",
                self.kind
            )));
        }
        if let Some(first) = self.used.insert(ccx.clone(), origin.to_string()) {
            return Err(invalid(format!(
                "{origin} and {first} both become the CalculiX {} {ccx}: expected distinct names",
                self.kind
            )));
        }
        Ok(ccx)
    }
}

fn write_ids(out: &mut String, ids: impl IntoIterator<Item = usize>) {
    let ids: Vec<usize> = ids.into_iter().collect();
    for chunk in ids.chunks(IDS_PER_LINE) {
        let line: Vec<String> = chunk.iter().map(|i| i.to_string()).collect();
        let _ = writeln!(out, "{}", line.join(", "));
    }
}

/// The model part of both decks (everything before `*STEP`).
fn model_text(mesh: &Mesh, job: &str) -> Result<String, CalculixError> {
    let mut out = String::new();
    let mut elsets = Names::new("element set");
    let mut nsets = Names::new("node set");
    let id = |i: usize| i + 1;

    // Header and metadata.
    let _ = writeln!(out, "** rigtwin FE parent model, job {job}");
    let _ = writeln!(
        out,
        "** {} nodes, {} solid elements, {} interface springs, {} point masses, {} contact \
         pairs, {} sensors; SI units (m, kg, Pa, N/m)",
        mesh.nodes.len(),
        mesh.elements.len(),
        mesh.springs.len(),
        mesh.point_masses.len(),
        mesh.contact_pairs.len(),
        mesh.sensors.len()
    );
    let _ = writeln!(
        out,
        "** CONTACT_LOWER and CONTACT_UPPER list the contact pairs in pair order: pair k = \
         k-th node of each set"
    );
    if !mesh.contact_pairs.is_empty() {
        let gaps: f64 = mesh
            .contact_pairs
            .iter()
            .map(|p| {
                let (l, u) = (mesh.nodes[p.lower], mesh.nodes[p.upper]);
                (0..3).map(|c| p.frame[0][c] * (u[c] - l[c])).sum::<f64>()
            })
            .sum();
        let clearance = gaps / mesh.contact_pairs.len() as f64;
        let _ = writeln!(out, "** rigtwin clearance {clearance:e}");
        for p in &mesh.contact_pairs {
            let [n, t1, _] = p.frame;
            let _ = writeln!(
                out,
                "** rigtwin pair {} {} area {:e} n {:e} {:e} {:e} t1 {:e} {:e} {:e}",
                id(p.lower),
                id(p.upper),
                p.area,
                n[0],
                n[1],
                n[2],
                t1[0],
                t1[1],
                t1[2]
            );
        }
    }
    for s in &mesh.sensors {
        let d = s.direction;
        let _ = writeln!(
            out,
            "** rigtwin sensor {} dir {:e} {:e} {:e}",
            s.name, d[0], d[1], d[2]
        );
    }

    // Nodes.
    out.push_str("*NODE\n");
    for (i, x) in mesh.nodes.iter().enumerate() {
        let _ = writeln!(
            out,
            "{}, {}, {}, {}",
            id(i),
            real(x[0]),
            real(x[1]),
            real(x[2])
        );
    }

    // Solids, one element set per non-empty block.
    let mut next_element = 1usize;
    let mut block_sets = Vec::new();
    for (b, block) in mesh.blocks.iter().enumerate() {
        let members: Vec<_> = mesh.elements.iter().filter(|e| e.block == b).collect();
        if members.is_empty() {
            continue;
        }
        let name = elsets.add(ccx_name(&block.name), &format!("block {}", block.name))?;
        let _ = writeln!(
            out,
            "*ELEMENT,TYPE={},ELSET={name}",
            block.kind.calculix_name()
        );
        for e in members {
            let nodes: Vec<String> = e.nodes.iter().map(|&n| id(n).to_string()).collect();
            let _ = writeln!(out, "{}, {}", next_element, nodes.join(", "));
            next_element += 1;
        }
        block_sets.push((name, block.material));
    }

    // Springs: per layer and direction, one set per distinct stiffness.
    let axes = ["X", "Y", "Z"];
    let mut spring_sets: Vec<(String, usize, f64)> = Vec::new();
    for (l, layer) in mesh.layers.iter().enumerate() {
        for (d, axis) in axes.iter().enumerate() {
            let mut groups: Vec<(f64, Vec<(usize, usize)>)> = Vec::new();
            let mut by_value: HashMap<u64, usize> = HashMap::new();
            for s in mesh.springs.iter().filter(|s| s.layer == l) {
                let k = s.stiffness[d];
                if k == 0.0 {
                    continue;
                }
                let g = *by_value.entry(k.to_bits()).or_insert_with(|| {
                    groups.push((k, Vec::new()));
                    groups.len() - 1
                });
                groups[g].1.push((s.a, s.b));
            }
            for (g, (k, springs)) in groups.into_iter().enumerate() {
                let name = elsets.add(
                    format!("SPR_{}_{axis}_{}", ccx_name(layer), g + 1),
                    &format!("layer {layer}"),
                )?;
                let _ = writeln!(out, "*ELEMENT,TYPE=SPRING2,ELSET={name}");
                for (a, b) in springs {
                    let _ = writeln!(out, "{}, {}, {}", next_element, id(a), id(b));
                    next_element += 1;
                }
                spring_sets.push((name, d + 1, k));
            }
        }
    }

    // Point masses.
    let mut mass_sets = Vec::new();
    for (k, p) in mesh.point_masses.iter().enumerate() {
        let name = elsets.add(format!("MASS_{}", k + 1), &format!("point mass {}", p.name))?;
        let _ = writeln!(out, "** point mass {}", p.name);
        let _ = writeln!(out, "*ELEMENT,TYPE=MASS,ELSET={name}");
        let _ = writeln!(out, "{}, {}", next_element, id(p.node));
        next_element += 1;
        mass_sets.push((name, p.mass));
    }

    // Node sets: the mesh's. The contact sets are rewritten in pair order below, and a
    // mesh set that is exactly a sensor's one-node set is rewritten from the sensor.
    let reserved = ["CONTACT_LOWER", "CONTACT_UPPER"];
    let sensor_set = |ccx: &str, members: &[usize]| {
        mesh.sensors
            .iter()
            .any(|s| format!("SENSOR_{}", ccx_name(&s.name)) == ccx && members == [s.node])
    };
    for (name, members) in &mesh.node_sets {
        let ccx = ccx_name(name);
        if reserved.contains(&ccx.as_str()) || members.is_empty() || sensor_set(&ccx, members) {
            continue;
        }
        let ccx = nsets.add(ccx, &format!("node set {name}"))?;
        let _ = writeln!(out, "*NSET,NSET={ccx}");
        write_ids(&mut out, members.iter().map(|&n| id(n)));
    }
    if !mesh.contact_pairs.is_empty() {
        for (name, pick) in [("CONTACT_LOWER", 0usize), ("CONTACT_UPPER", 1usize)] {
            let name = nsets.add(name.to_string(), "the contact pairs")?;
            let _ = writeln!(out, "*NSET,NSET={name}");
            write_ids(
                &mut out,
                mesh.contact_pairs
                    .iter()
                    .map(|p| id(if pick == 0 { p.lower } else { p.upper })),
            );
        }
    }
    for s in &mesh.sensors {
        let name = nsets.add(
            format!("SENSOR_{}", ccx_name(&s.name)),
            &format!("sensor {}", s.name),
        )?;
        let _ = writeln!(out, "*NSET,NSET={name}\n{}", id(s.node));
    }
    let fixed: BTreeSet<usize> = mesh.fixed_nodes.iter().copied().collect();
    let fixed_set = if fixed.is_empty() {
        None
    } else {
        let name = nsets.add("BC_FIXED".into(), "the fixed nodes")?;
        let _ = writeln!(out, "*NSET,NSET={name}");
        write_ids(&mut out, fixed.iter().map(|&n| id(n)));
        Some(name)
    };

    // Materials and sections.
    let mut materials = Names::new("material");
    let mut material_names = Vec::with_capacity(mesh.materials.len());
    for m in &mesh.materials {
        let name = materials.add(ccx_name(&m.name), &format!("material {}", m.name))?;
        let _ = writeln!(
            out,
            "*MATERIAL,NAME={name}\n*ELASTIC\n{}, {}\n*DENSITY\n{}",
            real(m.youngs_modulus),
            real(m.poisson_ratio),
            real(m.density)
        );
        material_names.push(name);
    }
    for (set, material) in &block_sets {
        let _ = writeln!(
            out,
            "*SOLID SECTION,ELSET={set},MATERIAL={}",
            material_names[*material]
        );
    }
    for (set, dof, k) in &spring_sets {
        let _ = writeln!(out, "*SPRING,ELSET={set}\n{dof},{dof}\n{}", real(*k));
    }
    for (set, m) in &mass_sets {
        let _ = writeln!(out, "*MASS,ELSET={set}\n{}", real(*m));
    }
    if let Some(set) = fixed_set {
        let _ = writeln!(out, "*BOUNDARY\n{set},1,3");
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reals_fit_ccx_fields_and_keep_their_digits() {
        for x in [
            0.006,
            0.09138459521993812,
            -1.2345678901234567e-2,
            2.1e11,
            -9.87654321e-300,
        ] {
            let s = real(x);
            assert!(s.len() <= FIELD_WIDTH && s.contains('.'), "{s}");
            let back: f64 = s.parse().unwrap();
            // at least 13 significant digits
            assert!((back - x).abs() <= 5e-13 * x.abs(), "{x} -> {s}");
        }
        assert_eq!(real(0.006), "6.0e-3");
        assert_eq!(real(0.0), "0.0e0");
        assert_eq!(real(0.09138459521993812), "9.138459521993812e-2");
        assert_eq!(real(-1.2345678901234567e-2), "-1.23456789012346e-2");
    }
}
