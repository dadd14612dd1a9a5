//! Native assembly of the FE parent model: validates a [`Mesh`], numbers the free DOFs
//! (node-major, fixed nodes skipped), assembles the element stiffness and consistent mass
//! ([`crate::fe::hex8`]), the interface-layer springs and the point masses into sparse
//! symmetric K and M on the free DOFs, and maps contact pairs, sensors and node groups onto
//! those DOFs ([`FeModel`]). Errors are [`FeError`].

use faer::sparse::{SparseColMat, SymbolicSparseColMat};

use crate::fe::hex8::{self, ElementError, Isotropic};
use crate::fe::mesh::Mesh;
use crate::fe::model::{DofGroup, DofInfo, FeModel, OutputDofs, PairDofs};

/// Why a mesh could not be assembled (or, later, why a FE step failed). Every message names
/// the offending item and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum FeError {
    /// No nodes or no elements.
    #[error(
        "empty mesh ({n_nodes} nodes, {n_elements} elements): expected at least one hex element"
    )]
    EmptyMesh {
        /// Number of nodes.
        n_nodes: usize,
        /// Number of elements.
        n_elements: usize,
    },
    /// A node coordinate is NaN or infinite.
    #[error("node {node} has a non-finite coordinate {coords:?}; expected finite metres")]
    NonFiniteCoordinate {
        /// Node index.
        node: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// An item refers to a node index beyond the node list.
    #[error("{what} refers to node {node}, but the mesh has only {n_nodes} nodes")]
    MissingNode {
        /// The referring item, e.g. "element 12 (block 'lower_beam')".
        what: String,
        /// The bad node index.
        node: usize,
        /// Number of nodes.
        n_nodes: usize,
    },
    /// An element refers to a block that does not exist.
    #[error("element {element} refers to block {block}, but the mesh has only {n_blocks} blocks")]
    MissingBlock {
        /// Element index.
        element: usize,
        /// The bad block index.
        block: usize,
        /// Number of blocks.
        n_blocks: usize,
    },
    /// A block refers to a material that does not exist.
    #[error("block '{block}' refers to material {material}, but the mesh has only {n_materials} materials")]
    MissingMaterial {
        /// Block name.
        block: String,
        /// The bad material index.
        material: usize,
        /// Number of materials.
        n_materials: usize,
    },
    /// A material constant is out of range.
    #[error("material '{material}': {what} = {value} is invalid; expected {expected}")]
    InvalidMaterial {
        /// Material name.
        material: String,
        /// Which constant.
        what: &'static str,
        /// Its value.
        value: f64,
        /// The admissible range.
        expected: &'static str,
    },
    /// An element matrix could not be formed (e.g. a non-positive Jacobian).
    #[error("element {element} (block '{block}'): {source}")]
    Element {
        /// Element index.
        element: usize,
        /// Block name.
        block: String,
        /// What went wrong inside the element.
        #[source]
        source: ElementError,
    },
    /// A spring stiffness is negative or not finite.
    #[error("spring {spring} (layer {layer}, nodes {a}-{b}): stiffness {stiffness:?} N/m; expected finite non-negative values")]
    InvalidSpring {
        /// Spring index.
        spring: usize,
        /// Layer name (or index if unnamed).
        layer: String,
        /// First node.
        a: usize,
        /// Second node.
        b: usize,
        /// Stiffness along x, y, z.
        stiffness: [f64; 3],
    },
    /// A point mass is negative or not finite.
    #[error(
        "point mass '{name}' on node {node}: mass {mass} kg; expected a finite non-negative value"
    )]
    InvalidPointMass {
        /// Item name.
        name: String,
        /// Node.
        node: usize,
        /// Mass.
        mass: f64,
    },
    /// A contact pair uses a fixed node.
    #[error("contact pair {pair}: {side} node {node} is fixed; both nodes of a pair must be free")]
    FixedPairNode {
        /// Pair index.
        pair: usize,
        /// "lower" or "upper".
        side: &'static str,
        /// The fixed node.
        node: usize,
    },
    /// A sensor sits on a fixed node, so its output would be identically zero.
    #[error("sensor '{name}' sits on fixed node {node}; expected a free node (its output would be zero)")]
    FixedSensorNode {
        /// Sensor name.
        name: String,
        /// The fixed node.
        node: usize,
    },
    /// A free node is attached to no element and no spring: K would be singular.
    #[error("node {node} at {coords:?} is free but attached to no element and no spring; K would be singular")]
    IsolatedNode {
        /// Node index.
        node: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// Every node is fixed.
    #[error("all {n_nodes} nodes are fixed: the model has no free DOF")]
    NoFreeDof {
        /// Number of nodes.
        n_nodes: usize,
    },
}

/// Marks a fixed node in the free-node numbering.
const FIXED: usize = usize::MAX;

/// Assembles the free-DOF model of `mesh`. `clearance` (m) is the nominal normal gap at the
/// contact pairs and is stored in the model unchanged.
///
/// K and M are stored with both triangles and share one sparsity pattern (the node graph of
/// elements and springs, 3x3 blocks), so M holds explicit zeros at spring couplings.
pub fn assemble(mesh: &Mesh, clearance: f64) -> Result<FeModel, FeError> {
    validate(mesh)?;
    let n_nodes = mesh.n_nodes();

    // Free-node numbering (node-major DOFs: free node f owns DOFs 3f, 3f+1, 3f+2).
    let mut free = vec![0usize; n_nodes];
    for &n in &mesh.fixed_nodes {
        free[n] = FIXED;
    }
    let mut n_free = 0;
    for f in free.iter_mut() {
        if *f != FIXED {
            *f = n_free;
            n_free += 1;
        }
    }
    if n_free == 0 {
        return Err(FeError::NoFreeDof { n_nodes });
    }
    let n_dof = 3 * n_free;

    let graph = NodeGraph::new(mesh, &free, n_free);
    if let Some(node) = (0..n_nodes).find(|&n| free[n] != FIXED && !graph.attached[n]) {
        return Err(FeError::IsolatedNode {
            node,
            coords: mesh.nodes[node],
        });
    }
    let (col_ptr, row_idx) = graph.pattern();
    let nnz = row_idx.len();
    let mut kv = vec![0.0; nnz];
    let mut mv = vec![0.0; nnz];

    // Solid elements.
    let mut slots = [[0usize; 8]; 8];
    for (e, el) in mesh.elements.iter().enumerate() {
        let block = &mesh.blocks[el.block];
        let m = &mesh.materials[block.material];
        let material = Isotropic {
            youngs_modulus: m.youngs_modulus,
            poisson_ratio: m.poisson_ratio,
            density: m.density,
        };
        let x = el.nodes.map(|n| mesh.nodes[n]);
        let wrap = |source| FeError::Element {
            element: e,
            block: block.name.clone(),
            source,
        };
        let em = hex8::element_matrices(block.kind, &x, &material).map_err(wrap)?;
        let (ke, me) = (&em.stiffness, &em.mass);
        let fe = el.nodes.map(|n| free[n]);
        for b in 0..8 {
            if fe[b] == FIXED {
                continue;
            }
            for a in 0..8 {
                if fe[a] != FIXED {
                    slots[a][b] = graph.slot(fe[a], fe[b]);
                }
            }
        }
        for b in 0..8 {
            if fe[b] == FIXED {
                continue;
            }
            for j in 0..3 {
                let col = col_ptr[3 * fe[b] + j];
                for a in 0..8 {
                    if fe[a] == FIXED {
                        continue;
                    }
                    let base = col + 3 * slots[a][b];
                    for i in 0..3 {
                        kv[base + i] += ke[3 * a + i][3 * b + j];
                        mv[base + i] += me[3 * a + i][3 * b + j];
                    }
                }
            }
        }
    }

    // Interface springs: k (u_a - u_b)^2 / 2 per direction; a fixed end only adds diagonal.
    for s in &mesh.springs {
        let (fa, fb) = (free[s.a], free[s.b]);
        for (i, &k) in s.stiffness.iter().enumerate() {
            for (p, q, sign) in [(fa, fa, 1.0), (fb, fb, 1.0), (fa, fb, -1.0), (fb, fa, -1.0)] {
                if p != FIXED && q != FIXED {
                    kv[col_ptr[3 * q + i] + 3 * graph.slot(p, q) + i] += sign * k;
                }
            }
        }
    }

    // Point masses (translational, on the node's three DOFs; ignored on fixed nodes).
    for pm in &mesh.point_masses {
        let f = free[pm.node];
        if f != FIXED {
            let slot = graph.slot(f, f);
            for i in 0..3 {
                mv[col_ptr[3 * f + i] + 3 * slot + i] += pm.mass;
            }
        }
    }

    let symbolic = SymbolicSparseColMat::new_checked(n_dof, n_dof, col_ptr, None, row_idx);
    let k = SparseColMat::new(symbolic.clone(), kv);
    let m = SparseColMat::new(symbolic, mv);

    let groups = node_groups(mesh);
    let mut dofs = Vec::with_capacity(n_dof);
    for (node, &f) in free.iter().enumerate() {
        if f != FIXED {
            for dir in 0..3u8 {
                dofs.push(DofInfo {
                    node,
                    dir,
                    group: groups[node],
                });
            }
        }
    }
    let base = dofs
        .iter()
        .map(|d| if d.dir == 2 { 1.0 } else { 0.0 })
        .collect();

    let mut pairs = Vec::with_capacity(mesh.contact_pairs.len());
    for (i, p) in mesh.contact_pairs.iter().enumerate() {
        for (side, node) in [("lower", p.lower), ("upper", p.upper)] {
            if free[node] == FIXED {
                return Err(FeError::FixedPairNode {
                    pair: i,
                    side,
                    node,
                });
            }
        }
        let dofs_of = |n: usize| [0, 1, 2].map(|d| 3 * free[n] + d);
        pairs.push(PairDofs {
            lower: dofs_of(p.lower),
            upper: dofs_of(p.upper),
            frame: p.frame,
            area: p.area,
            position: mesh.nodes[p.lower],
        });
    }

    let mut outputs = Vec::with_capacity(mesh.sensors.len());
    for s in &mesh.sensors {
        let f = free[s.node];
        if f == FIXED {
            return Err(FeError::FixedSensorNode {
                name: s.name.clone(),
                node: s.node,
            });
        }
        let terms = (0..3)
            .filter(|&d| s.direction[d] != 0.0)
            .map(|d| (3 * f + d, s.direction[d]))
            .collect();
        outputs.push(OutputDofs {
            name: s.name.clone(),
            terms,
        });
    }

    Ok(FeModel {
        k,
        m,
        dofs,
        base,
        pairs,
        clearance,
        outputs,
        node_coords: mesh.nodes.clone(),
        n_elements: mesh.elements.len(),
    })
}

/// Node graph of the free nodes (elements and springs), sorted adjacency per node.
struct NodeGraph {
    /// Adjacency offsets per free node.
    ptr: Vec<usize>,
    /// Neighbouring free nodes (including the node itself), sorted.
    adj: Vec<usize>,
    /// Whether a mesh node is attached to an element or a spring.
    attached: Vec<bool>,
}

impl NodeGraph {
    fn new(mesh: &Mesh, free: &[usize], n_free: usize) -> Self {
        let mut attached = vec![false; mesh.n_nodes()];
        // (column, row) free-node pairs.
        let mut links: Vec<(usize, usize)> =
            Vec::with_capacity(64 * mesh.elements.len() + 4 * mesh.springs.len() + n_free);
        for el in &mesh.elements {
            for &b in &el.nodes {
                attached[b] = true;
                if free[b] == FIXED {
                    continue;
                }
                for &a in &el.nodes {
                    if free[a] != FIXED {
                        links.push((free[b], free[a]));
                    }
                }
            }
        }
        for s in &mesh.springs {
            attached[s.a] = true;
            attached[s.b] = true;
            let (fa, fb) = (free[s.a], free[s.b]);
            for f in [fa, fb] {
                if f != FIXED {
                    links.push((f, f));
                }
            }
            if fa != FIXED && fb != FIXED {
                links.push((fa, fb));
                links.push((fb, fa));
            }
        }
        for f in 0..n_free {
            links.push((f, f));
        }
        links.sort_unstable();
        links.dedup();
        let mut ptr = vec![0usize; n_free + 1];
        for &(c, _) in &links {
            ptr[c + 1] += 1;
        }
        for f in 0..n_free {
            ptr[f + 1] += ptr[f];
        }
        let adj = links.into_iter().map(|(_, r)| r).collect();
        NodeGraph { ptr, adj, attached }
    }

    /// Position of free node `row` in the adjacency of free node `col`.
    #[inline]
    fn slot(&self, row: usize, col: usize) -> usize {
        let list = &self.adj[self.ptr[col]..self.ptr[col + 1]];
        // The pattern contains every coupling added during assembly by construction.
        list.binary_search(&row)
            .expect("coupling present in the assembled node graph")
    }

    /// CSC pattern on the DOFs: column 3c + j holds rows 3r + i for every neighbour r of c.
    fn pattern(&self) -> (Vec<usize>, Vec<usize>) {
        let n_free = self.ptr.len() - 1;
        let mut col_ptr = Vec::with_capacity(3 * n_free + 1);
        let mut row_idx = Vec::with_capacity(9 * self.adj.len());
        col_ptr.push(0);
        for c in 0..n_free {
            let list = &self.adj[self.ptr[c]..self.ptr[c + 1]];
            for _ in 0..3 {
                for &r in list {
                    row_idx.extend_from_slice(&[3 * r, 3 * r + 1, 3 * r + 2]);
                }
                col_ptr.push(row_idx.len());
            }
        }
        (col_ptr, row_idx)
    }
}

/// Group of every node from the node sets LOWER, UPPER, CLAMP (default Clamp).
fn node_groups(mesh: &Mesh) -> Vec<DofGroup> {
    let mut groups = vec![DofGroup::Clamp; mesh.n_nodes()];
    for (name, group) in [("UPPER", DofGroup::Upper), ("LOWER", DofGroup::Lower)] {
        if let Some(set) = mesh.node_sets.get(name) {
            for &n in set {
                groups[n] = group;
            }
        }
    }
    groups
}

/// Checks every index and constant the assembly relies on.
fn validate(mesh: &Mesh) -> Result<(), FeError> {
    let n_nodes = mesh.n_nodes();
    if n_nodes == 0 || mesh.elements.is_empty() {
        return Err(FeError::EmptyMesh {
            n_nodes,
            n_elements: mesh.elements.len(),
        });
    }
    if let Some((node, &coords)) = mesh
        .nodes
        .iter()
        .enumerate()
        .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
    {
        return Err(FeError::NonFiniteCoordinate { node, coords });
    }
    let check_node = |what: &dyn Fn() -> String, node: usize| {
        if node < n_nodes {
            Ok(())
        } else {
            Err(FeError::MissingNode {
                what: what(),
                node,
                n_nodes,
            })
        }
    };
    for m in &mesh.materials {
        let bad = |what, value, expected| FeError::InvalidMaterial {
            material: m.name.clone(),
            what,
            value,
            expected,
        };
        let e = m.youngs_modulus;
        if !(e > 0.0 && e.is_finite()) {
            return Err(bad("Young's modulus", e, "a finite value > 0 Pa"));
        }
        let nu = m.poisson_ratio;
        if !(nu > -1.0 && nu < 0.5) {
            return Err(bad("Poisson's ratio", nu, "a value in (-1, 0.5)"));
        }
        let rho = m.density;
        if !(rho > 0.0 && rho.is_finite()) {
            return Err(bad("density", rho, "a finite value > 0 kg/m^3"));
        }
    }
    for b in &mesh.blocks {
        if b.material >= mesh.materials.len() {
            return Err(FeError::MissingMaterial {
                block: b.name.clone(),
                material: b.material,
                n_materials: mesh.materials.len(),
            });
        }
    }
    for (e, el) in mesh.elements.iter().enumerate() {
        let Some(block) = mesh.blocks.get(el.block) else {
            return Err(FeError::MissingBlock {
                element: e,
                block: el.block,
                n_blocks: mesh.blocks.len(),
            });
        };
        for &n in &el.nodes {
            check_node(&|| format!("element {e} (block '{}')", block.name), n)?;
        }
    }
    for (i, s) in mesh.springs.iter().enumerate() {
        check_node(&|| format!("spring {i}"), s.a)?;
        check_node(&|| format!("spring {i}"), s.b)?;
        if s.stiffness.iter().any(|k| !(*k >= 0.0 && k.is_finite())) {
            return Err(FeError::InvalidSpring {
                spring: i,
                layer: mesh
                    .layers
                    .get(s.layer)
                    .cloned()
                    .unwrap_or_else(|| format!("#{}", s.layer)),
                a: s.a,
                b: s.b,
                stiffness: s.stiffness,
            });
        }
    }
    for p in &mesh.point_masses {
        check_node(&|| format!("point mass '{}'", p.name), p.node)?;
        if !(p.mass >= 0.0 && p.mass.is_finite()) {
            return Err(FeError::InvalidPointMass {
                name: p.name.clone(),
                node: p.node,
                mass: p.mass,
            });
        }
    }
    for (i, &n) in mesh.fixed_nodes.iter().enumerate() {
        check_node(&|| format!("fixed-node entry {i}"), n)?;
    }
    for (i, p) in mesh.contact_pairs.iter().enumerate() {
        check_node(&|| format!("contact pair {i} (lower node)"), p.lower)?;
        check_node(&|| format!("contact pair {i} (upper node)"), p.upper)?;
    }
    for s in &mesh.sensors {
        check_node(&|| format!("sensor '{}'", s.name), s.node)?;
    }
    for (name, set) in &mesh.node_sets {
        for &n in set {
            check_node(&|| format!("node set '{name}'"), n)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fe::grid::BoxGrid;
    use crate::fe::mesh::{
        ContactPair, ElementBlock, ElementKind, HexElement, Material, PointMass, SensorPoint,
        Spring,
    };

    fn steel() -> Material {
        Material {
            name: "steel".into(),
            youngs_modulus: 210e9,
            poisson_ratio: 0.3,
            density: 7850.0,
        }
    }

    /// Two separate 2x1x1 boxes (block "a" at z in [0, 1] mm, block "b" above it at the
    /// same z = 1 mm face but with their own nodes) joined by springs on that face.
    fn two_blocks() -> Mesh {
        let mut mesh = Mesh {
            materials: vec![steel()],
            blocks: vec![
                ElementBlock {
                    name: "a".into(),
                    material: 0,
                    kind: ElementKind::Hex8I,
                },
                ElementBlock {
                    name: "b".into(),
                    material: 0,
                    kind: ElementKind::Hex8,
                },
            ],
            layers: vec!["joint".into()],
            ..Mesh::default()
        };
        for (block, z0) in [(0usize, 0.0), (1, 1e-3)] {
            let g = BoxGrid::new(&[0.0, 2e-3, 4e-3], &[0.0, 1e-3], &[z0, z0 + 1e-3], |p| p);
            let off = mesh.nodes.len();
            mesh.nodes.extend_from_slice(&g.nodes);
            for c in &g.cells {
                mesh.elements.push(HexElement {
                    nodes: c.map(|n| n + off),
                    block,
                });
            }
        }
        // Top face of block a: nodes 6..12; bottom face of block b: nodes 12..18.
        for i in 0..6 {
            mesh.springs.push(Spring {
                a: 6 + i,
                b: 12 + i,
                stiffness: [1e6, 2e6, 3e6],
                layer: 0,
            });
        }
        mesh.node_sets.insert("LOWER".into(), (0..12).collect());
        mesh.node_sets.insert("UPPER".into(), (12..24).collect());
        mesh
    }

    fn dense(a: &SparseColMat<usize, f64>) -> Vec<Vec<f64>> {
        let d = a.to_dense();
        (0..d.nrows())
            .map(|i| (0..d.ncols()).map(|j| d[(i, j)]).collect())
            .collect()
    }

    #[test]
    fn matches_a_dense_reference_assembly() {
        let mut mesh = two_blocks();
        mesh.fixed_nodes = vec![0, 3];
        mesh.point_masses.push(PointMass {
            name: "acc".into(),
            node: 23,
            mass: 0.01,
        });
        let model = assemble(&mesh, 1e-4).unwrap();
        let n_free = 22;
        assert_eq!(model.n_dof(), 3 * n_free);
        // Dense reference on all nodes, then the fixed rows/columns removed.
        let n = 3 * mesh.n_nodes();
        let mut kd = vec![vec![0.0; n]; n];
        let mut md = vec![vec![0.0; n]; n];
        for el in &mesh.elements {
            let blk = &mesh.blocks[el.block];
            let mat = Isotropic {
                youngs_modulus: 210e9,
                poisson_ratio: 0.3,
                density: 7850.0,
            };
            let x = el.nodes.map(|i| mesh.nodes[i]);
            let em = hex8::element_matrices(blk.kind, &x, &mat).unwrap();
            let (ke, me) = (em.stiffness, em.mass);
            for a in 0..24 {
                for b in 0..24 {
                    let (r, c) = (3 * el.nodes[a / 3] + a % 3, 3 * el.nodes[b / 3] + b % 3);
                    kd[r][c] += ke[a][b];
                    md[r][c] += me[a][b];
                }
            }
        }
        for s in &mesh.springs {
            for i in 0..3 {
                let (a, b) = (3 * s.a + i, 3 * s.b + i);
                kd[a][a] += s.stiffness[i];
                kd[b][b] += s.stiffness[i];
                kd[a][b] -= s.stiffness[i];
                kd[b][a] -= s.stiffness[i];
            }
        }
        for i in 0..3 {
            md[3 * 23 + i][3 * 23 + i] += 0.01;
        }
        let keep: Vec<usize> = (0..n).filter(|d| ![0, 3].contains(&(d / 3))).collect();
        let (ka, ma) = (dense(&model.k), dense(&model.m));
        let kscale = kd.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        for (r, &gr) in keep.iter().enumerate() {
            for (c, &gc) in keep.iter().enumerate() {
                assert!(
                    (ka[r][c] - kd[gr][gc]).abs() <= 1e-12 * kscale,
                    "K[{r}][{c}]"
                );
                assert!((ma[r][c] - md[gr][gc]).abs() <= 1e-16, "M[{r}][{c}]");
            }
        }
        // DOF table: node-major, fixed nodes skipped, groups from the node sets.
        assert_eq!(model.dofs[0].node, 1);
        assert_eq!(model.dofs[3].node, 2);
        assert_eq!(model.dofs[3 * 3].node, 5);
        assert_eq!(model.dofs[3 * 4].node, 6);
        assert_eq!(model.dofs[5].dir, 2);
        assert_eq!(model.dofs[0].group, DofGroup::Lower);
        assert_eq!(model.dofs.last().unwrap().group, DofGroup::Upper);
        assert!(model
            .base
            .iter()
            .zip(&model.dofs)
            .all(|(b, d)| *b == if d.dir == 2 { 1.0 } else { 0.0 }));
        assert_eq!(model.node_coords.len(), 24);
        assert_eq!(model.n_elements, 4);
        assert_eq!(model.clearance, 1e-4);
    }

    #[test]
    fn free_model_has_rigid_modes_and_total_mass() {
        let mut mesh = two_blocks();
        mesh.point_masses.push(PointMass {
            name: "acc".into(),
            node: 20,
            mass: 0.02,
        });
        let model = assemble(&mesh, 0.0).unwrap();
        let n = model.n_dof();
        let k = dense(&model.k);
        let m = dense(&model.m);
        for dir in 0..3 {
            let t: Vec<f64> = (0..n)
                .map(|d| if d % 3 == dir { 1.0 } else { 0.0 })
                .collect();
            let kt = k
                .iter()
                .map(|row| row.iter().zip(&t).map(|(a, b)| a * b).sum::<f64>());
            assert!(
                kt.map(f64::abs).fold(0.0, f64::max) < 1e-6,
                "translation {dir}"
            );
            let mass: f64 = (0..n)
                .map(|r| t[r] * m[r].iter().zip(&t).map(|(a, b)| a * b).sum::<f64>())
                .sum();
            let expected = mesh.total_mass();
            assert!(
                (mass - expected).abs() < 1e-12 * expected,
                "{mass} vs {expected}"
            );
        }
        // Symmetric, both triangles stored.
        for r in 0..n {
            for c in 0..n {
                assert_eq!(k[r][c], k[c][r]);
                assert_eq!(m[r][c], m[c][r]);
            }
        }
    }

    #[test]
    fn pairs_and_sensors_map_to_free_dofs() {
        let mut mesh = two_blocks();
        mesh.fixed_nodes = vec![0];
        let frame = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        mesh.contact_pairs.push(ContactPair {
            lower: 7,
            upper: 13,
            frame,
            area: 1e-6,
        });
        mesh.sensors.push(SensorPoint {
            name: "tip".into(),
            node: 23,
            direction: [0.0, 0.0, 1.0],
        });
        let model = assemble(&mesh, 2e-4).unwrap();
        let p = &model.pairs[0];
        assert_eq!(p.lower, [18, 19, 20]);
        assert_eq!(p.upper, [36, 37, 38]);
        assert_eq!(p.frame, frame);
        assert_eq!(p.position, mesh.nodes[7]);
        assert_eq!(model.outputs[0].name, "tip");
        assert_eq!(model.outputs[0].terms, vec![(3 * 22 + 2, 1.0)]);
        assert_eq!(model.dofs[3 * 22 + 2].node, 23);

        mesh.contact_pairs[0].upper = 0;
        let err = assemble(&mesh, 2e-4).unwrap_err();
        assert!(matches!(
            err,
            FeError::FixedPairNode {
                pair: 0,
                side: "upper",
                node: 0
            }
        ));
        assert!(err.to_string().contains("contact pair 0"));
    }

    #[test]
    fn spring_to_a_fixed_node_adds_diagonal_stiffness() {
        let mut mesh = two_blocks();
        mesh.fixed_nodes = vec![12];
        let free = assemble(&mesh, 0.0).unwrap();
        mesh.springs.retain(|s| s.b != 12);
        let without = assemble(&mesh, 0.0).unwrap();
        let (kf, kw) = (dense(&free.k), dense(&without.k));
        // Node 6 is free node 6: its diagonal carries the spring to the fixed node 12.
        for i in 0..3 {
            let d = 3 * 6 + i;
            assert!((kf[d][d] - kw[d][d] - [1e6, 2e6, 3e6][i]).abs() < 1e-3);
        }
    }

    #[test]
    fn bad_meshes_are_reported() {
        let msg = |m: &Mesh| assemble(m, 0.0).unwrap_err().to_string();
        assert!(msg(&Mesh::default()).contains("empty mesh"));

        let mut m = two_blocks();
        m.elements[1].nodes[3] = 99;
        let s = msg(&m);
        assert!(
            s.contains("element 1 (block 'a')") && s.contains("node 99"),
            "{s}"
        );

        let mut m = two_blocks();
        m.nodes[5][1] = f64::NAN;
        assert!(msg(&m).contains("node 5 has a non-finite coordinate"));

        for (field, value, key) in [
            (0, 0.0, "Young's modulus"),
            (0, -1.0, "Young's modulus"),
            (1, 0.5, "Poisson's ratio"),
            (1, -1.0, "Poisson's ratio"),
            (2, 0.0, "density"),
            (2, f64::NAN, "density"),
        ] {
            let mut m = two_blocks();
            let mat = &mut m.materials[0];
            *[
                &mut mat.youngs_modulus,
                &mut mat.poisson_ratio,
                &mut mat.density,
            ][field] = value;
            let s = msg(&m);
            assert!(s.contains("material 'steel'") && s.contains(key), "{s}");
        }

        let mut m = two_blocks();
        m.nodes[4][2] = 5e-3; // pushes a top node through the element: inverted
        let s = msg(&m);
        assert!(
            s.contains("block 'a'") && s.contains("non-positive Jacobian"),
            "{s}"
        );

        let mut m = two_blocks();
        m.nodes.push([1.0, 1.0, 1.0]);
        assert!(msg(&m).contains("node 24"));

        let mut m = two_blocks();
        m.sensors.push(SensorPoint {
            name: "base".into(),
            node: 0,
            direction: [0.0, 0.0, 1.0],
        });
        m.fixed_nodes = vec![0];
        assert!(msg(&m).contains("sensor 'base'"));

        let mut m = two_blocks();
        m.springs[2].stiffness[1] = -1.0;
        assert!(msg(&m).contains("spring 2 (layer joint"));
    }
}
