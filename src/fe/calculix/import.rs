//! Import of a CalculiX model: the deck `JOB.inp` for nodes, sets and rigtwin metadata, and
//! the matrices `JOB.sti`, `JOB.mas`, `JOB.dof` written by `*FREQUENCY,SOLVER=MATRIXSTORAGE`,
//! into an [`FeModel`] on CalculiX's free DOFs (in `.dof` order).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use super::deck::{read_deck, Deck};
use super::matrix::{read_dof, read_sym_matrix, to_sparse, DofLine};
use super::patch::{cross, frame_from_normal, mean_normal, pair_up, structured_areas, unit};
use super::CalculixError;
use crate::fe::model::{DofGroup, DofInfo, FeModel, OutputDofs, PairDofs};

/// Reads `JOB.inp`, `JOB.sti`, `JOB.mas` and `JOB.dof` into an [`FeModel`].
///
/// `job_path` is the deck (`dir/JOB.inp`) or the job without extension (`dir/JOB`). K and M
/// hold both triangles; the DOFs are CalculiX's free DOFs in `.dof` order. DOFs of nodes the
/// deck does not define (C3D8I's incompatible modes) are [`DofGroup::Internal`]; node groups
/// come from the sets `LOWER`, `UPPER`, `CLAMP`; contact pairs from `CONTACT_LOWER` /
/// `CONTACT_UPPER`; outputs from the `SENSOR_<NAME>` sets (see the module docs for the
/// conventions and the optional `** rigtwin` metadata).
pub fn import(job_path: &Path) -> Result<FeModel, CalculixError> {
    let (inp, stem) = job_paths(job_path);
    let deck = read_deck(&inp)?;
    let with_ext = |ext: &str| {
        let mut s = stem.clone().into_os_string();
        s.push(ext);
        PathBuf::from(s)
    };
    let (sti_path, mas_path, dof_path) = (with_ext(".sti"), with_ext(".mas"), with_ext(".dof"));
    let sti = read_sym_matrix(&sti_path)?;
    let mas = read_sym_matrix(&mas_path)?;
    let dof_lines = read_dof(&dof_path)?;
    let n = dof_lines.len();
    // Which file is wrong: both matrices agree and the .dof does not -> the .dof; one
    // matrix reaches beyond the .dof that the other matches -> that matrix's stray index;
    // otherwise the matrices disagree.
    if sti.dim == mas.dim && sti.dim != n {
        return Err(CalculixError::DofCount {
            path: dof_path,
            lines: n,
            matrix: sti_path,
            dim: sti.dim,
        });
    }
    if sti.dim != mas.dim && !(sti.dim > n && mas.dim == n) && !(mas.dim > n && sti.dim == n) {
        return Err(CalculixError::SizeMismatch {
            sti: sti_path,
            n_sti: sti.dim,
            mas: mas_path,
            n_mas: mas.dim,
        });
    }
    let k = to_sparse(&sti, &dof_path, n)?;
    let m = to_sparse(&mas, &dof_path, n)?;
    build(&inp, &deck, &dof_lines, k, m)
}

/// The file `JOB.ext` of the job `job_path` (`dir/JOB` or `dir/JOB.inp`): the files
/// [`import`] reads are `inp`, `sti`, `mas` and `dof`.
pub fn job_file(job_path: &Path, ext: &str) -> PathBuf {
    let (inp, stem) = job_paths(job_path);
    if ext == "inp" {
        return inp;
    }
    let mut s = stem.into_os_string();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

/// (`dir/JOB.inp`, `dir/JOB`) from either form.
fn job_paths(job_path: &Path) -> (PathBuf, PathBuf) {
    let is_inp = job_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("inp"));
    if is_inp {
        (job_path.to_path_buf(), job_path.with_extension(""))
    } else {
        let mut s = job_path.as_os_str().to_owned();
        s.push(".inp");
        (PathBuf::from(s), job_path.to_path_buf())
    }
}

/// Nodes of the set `name`: the node set, or the nodes of the element set of that name.
fn group_nodes(deck: &Deck, name: &str) -> Option<HashSet<usize>> {
    if let Some(set) = deck.node_sets.get(name) {
        return Some(set.members.iter().copied().collect());
    }
    deck.element_sets.get(name).map(|els| {
        els.iter()
            .filter_map(|e| deck.elements.get(e))
            .flat_map(|e| e.nodes.iter().copied())
            .collect()
    })
}

fn build(
    inp: &Path,
    deck: &Deck,
    dof_lines: &[DofLine],
    k: faer::sparse::SparseColMat<usize, f64>,
    m: faer::sparse::SparseColMat<usize, f64>,
) -> Result<FeModel, CalculixError> {
    let model_err = |what: String| CalculixError::Model {
        path: inp.to_path_buf(),
        what,
    };
    let missing = |name: &str, needed_for: &str| CalculixError::MissingSet {
        path: inp.to_path_buf(),
        name: name.to_string(),
        needed_for: needed_for.to_string(),
    };

    // Node groups.
    let lower = group_nodes(deck, "LOWER").ok_or_else(|| {
        missing(
            "LOWER",
            "expected a node set of the lower beam and its probe",
        )
    })?;
    let upper = group_nodes(deck, "UPPER").ok_or_else(|| {
        missing(
            "UPPER",
            "expected a node set of the upper beam, its probe and protrusion",
        )
    })?;
    if let Some(both) = lower.intersection(&upper).min() {
        return Err(model_err(format!(
            "node {both} is in both LOWER and UPPER: expected disjoint beam node sets"
        )));
    }

    // DOF table.
    let mut dofs = Vec::with_capacity(dof_lines.len());
    let mut base = Vec::with_capacity(dof_lines.len());
    let mut index: HashMap<(usize, u8), usize> = HashMap::with_capacity(dof_lines.len());
    for (i, d) in dof_lines.iter().enumerate() {
        let dir = d.dir - 1;
        let group = if !deck.nodes.contains_key(&d.node) {
            DofGroup::Internal
        } else if lower.contains(&d.node) {
            DofGroup::Lower
        } else if upper.contains(&d.node) {
            DofGroup::Upper
        } else {
            DofGroup::Clamp
        };
        // NOTE: incompatible-mode amplitudes do not move under a rigid base translation, so
        // the base-excitation vector is 1 only on the z DOFs of real nodes.
        base.push(if group != DofGroup::Internal && dir == 2 {
            1.0
        } else {
            0.0
        });
        dofs.push(DofInfo {
            node: d.node - 1,
            dir,
            group,
        });
        index.insert((d.node, dir), i);
    }

    let n_coords = deck.nodes.keys().next_back().copied().unwrap_or(0);
    // node_coords is indexed by node number: refuse numberings that would make it absurd.
    if n_coords > 16 * deck.nodes.len() + 1024 {
        return Err(model_err(format!(
            "node numbers reach {n_coords} for {} nodes: expected a compact numbering \
             (renumber the deck's nodes)",
            deck.nodes.len()
        )));
    }
    let mut node_coords = vec![[f64::NAN; 3]; n_coords];
    for (&id, &x) in &deck.nodes {
        node_coords[id - 1] = x;
    }
    let node_dofs = |id: usize, what: &str| -> Result<[usize; 3], CalculixError> {
        let mut out = [0; 3];
        for (dir, o) in out.iter_mut().enumerate() {
            *o = *index.get(&(id, dir as u8)).ok_or_else(|| {
                model_err(format!(
                    "{what} node {id} has no free DOF in direction {} in the .dof file: \
                     expected a node that is neither fixed nor unused",
                    dir + 1
                ))
            })?;
        }
        Ok(out)
    };

    // Contact pairs.
    let set = |name: &str| {
        deck.node_sets.get(name).ok_or_else(|| {
            missing(
                name,
                "expected the contact node pairs (CONTACT_LOWER and CONTACT_UPPER, pair k = \
                 k-th node of each)",
            )
        })
    };
    let lower_ids = set("CONTACT_LOWER")?.members.clone();
    let upper_ids = set("CONTACT_UPPER")?.members.clone();
    if lower_ids.is_empty() {
        return Err(model_err(
            "node set CONTACT_LOWER is empty: expected at least one contact pair".into(),
        ));
    }
    let coords = |id: usize| deck.nodes[&id];
    let lower_x: Vec<[f64; 3]> = lower_ids.iter().map(|&i| coords(i)).collect();
    let upper_x: Vec<[f64; 3]> = upper_ids.iter().map(|&i| coords(i)).collect();
    let partner = pair_up(&lower_x, &upper_x).map_err(model_err)?;
    let patch_normal = mean_normal(&lower_x, &upper_x);
    let mut computed_areas: Option<Vec<f64>> = None;
    let mut pairs = Vec::with_capacity(lower_ids.len());
    let mut gaps = Vec::with_capacity(lower_ids.len());
    for (kp, &u) in partner.iter().enumerate() {
        let (l_id, u_id) = (lower_ids[kp], upper_ids[u]);
        let d = [
            upper_x[u][0] - lower_x[kp][0],
            upper_x[u][1] - lower_x[kp][1],
            upper_x[u][2] - lower_x[kp][2],
        ];
        let (frame, area) = match deck.meta.pairs.get(&(l_id, u_id)) {
            Some(meta) => {
                let bad = |what: &str| CalculixError::Parse {
                    path: meta.at.path.clone(),
                    line: meta.at.line,
                    expected: format!("a pair frame with {what}"),
                    found: format!("n {:?} t1 {:?}", meta.normal, meta.t1),
                };
                let n = unit(meta.normal).ok_or_else(|| bad("a nonzero normal"))?;
                let t1 = unit(meta.t1).ok_or_else(|| bad("a nonzero t1"))?;
                let ortho = n[0] * t1[0] + n[1] * t1[1] + n[2] * t1[2];
                if ortho.abs() > 1e-9 {
                    return Err(bad("t1 orthogonal to n"));
                }
                if meta.area.is_nan() || meta.area <= 0.0 {
                    return Err(CalculixError::Parse {
                        path: meta.at.path.clone(),
                        line: meta.at.line,
                        expected: "a positive pair area, m^2".into(),
                        found: format!("{:e}", meta.area),
                    });
                }
                ([n, t1, cross(n, t1)], meta.area)
            }
            None => {
                let n = unit(d).ok_or_else(|| {
                    model_err(format!(
                        "contact nodes {l_id} and {u_id} coincide, so the pair normal is \
                         undefined: expected separated pairs or a `** rigtwin pair` comment"
                    ))
                })?;
                if computed_areas.is_none() {
                    let pn = patch_normal.unwrap_or(n);
                    computed_areas = Some(structured_areas(&lower_x, pn).map_err(model_err)?);
                }
                let area = computed_areas.as_ref().map_or(0.0, |a| a[kp]);
                (frame_from_normal(n), area)
            }
        };
        gaps.push(frame[0][0] * d[0] + frame[0][1] * d[1] + frame[0][2] * d[2]);
        pairs.push(PairDofs {
            lower: node_dofs(l_id, "contact")?,
            upper: node_dofs(u_id, "contact")?,
            frame,
            area,
            position: lower_x[kp],
        });
    }
    let clearance = deck
        .meta
        .clearance
        .unwrap_or_else(|| gaps.iter().sum::<f64>() / gaps.len() as f64);

    // Sensors, in set definition order.
    let mut sensor_sets: Vec<(&String, &super::deck::NodeSet)> = deck
        .node_sets
        .iter()
        .filter(|(name, _)| name.starts_with("SENSOR_"))
        .collect();
    sensor_sets.sort_by_key(|(_, s)| s.order);
    for meta in &deck.meta.sensors {
        let set_name = format!("SENSOR_{}", super::export::ccx_name(&meta.name));
        if !deck.node_sets.contains_key(&set_name) {
            return Err(CalculixError::MissingSet {
                path: meta.at.path.clone(),
                name: set_name,
                needed_for: format!(
                    "line {} describes sensor {} (expected a one-node set for it)",
                    meta.at.line, meta.name
                ),
            });
        }
    }
    let mut outputs = Vec::with_capacity(sensor_sets.len());
    for (set_name, set) in sensor_sets {
        let suffix = &set_name["SENSOR_".len()..];
        let meta = deck
            .meta
            .sensors
            .iter()
            .find(|s| super::export::ccx_name(&s.name) == suffix);
        let (name, direction) = match meta {
            Some(s) => {
                let dir = unit(s.direction).ok_or_else(|| CalculixError::Parse {
                    path: s.at.path.clone(),
                    line: s.at.line,
                    expected: "a nonzero sensor direction".into(),
                    found: format!("{:?}", s.direction),
                })?;
                (s.name.clone(), dir)
            }
            None => (suffix.to_lowercase(), [0.0, 0.0, 1.0]),
        };
        let mut members = set.members.clone();
        members.dedup();
        let [node] = members[..] else {
            return Err(model_err(format!(
                "sensor set {set_name} has {} nodes: expected exactly one",
                members.len()
            )));
        };
        let mut terms = Vec::new();
        for (dir, &w) in direction.iter().enumerate() {
            if w != 0.0 {
                let dof = *index.get(&(node, dir as u8)).ok_or_else(|| {
                    model_err(format!(
                        "sensor {name} (node {node}) measures along direction {} but that DOF \
                         is not free: expected a sensor on a moving node",
                        dir + 1
                    ))
                })?;
                terms.push((dof, w));
            }
        }
        outputs.push(OutputDofs { name, terms });
    }

    let n_elements = deck.elements.values().filter(|e| e.is_solid()).count();
    Ok(FeModel {
        k,
        m,
        dofs,
        base,
        pairs,
        clearance,
        outputs,
        node_coords,
        n_elements,
    })
}
