//! The assembled FE parent model on its free DOFs: sparse symmetric stiffness and mass,
//! the DOF table, the base-excitation direction vector and the index data the reduction
//! needs (contact pairs, sensors, node groups). Built natively (`fe/assembly.rs`) or
//! imported from CalculiX (`fe/calculix/`).

use faer::sparse::SparseColMat;

/// Which part of the rig a DOF belongs to; used to label modes and to report where modal
/// energy sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum DofGroup {
    /// Lower beam with its probe.
    Lower,
    /// Upper beam with its probe and protrusion.
    Upper,
    /// Clamping blocks and anything else.
    Clamp,
    /// Internal DOFs without a mesh node (e.g. CalculiX's incompatible-mode DOFs).
    Internal,
}

/// One free DOF: the node it belongs to (mesh numbering, 0-based; for CalculiX internal
/// DOFs the CalculiX node number minus one) and the global direction 0 = x, 1 = y, 2 = z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DofInfo {
    /// Node index.
    pub node: usize,
    /// Direction 0..3.
    pub dir: u8,
    /// Part group.
    pub group: DofGroup,
}

/// A contact pair expressed on free DOFs: the three DOFs of the lower and the upper node and
/// the local frame (rows n, t1, t2). The boundary coordinate of the pair is
/// `g = frame * (u_upper - u_lower) + [clearance, 0, 0]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairDofs {
    /// Free-DOF indices of the lower node (x, y, z).
    pub lower: [usize; 3],
    /// Free-DOF indices of the upper node (x, y, z).
    pub upper: [usize; 3],
    /// Local frame rows n, t1, t2.
    pub frame: [[f64; 3]; 3],
    /// Tributary area, m^2.
    pub area: f64,
    /// Position of the lower node, m (for figures and diagnostics).
    pub position: [f64; 3],
}

/// A sensor output on free DOFs: a linear combination of DOF displacements.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputDofs {
    /// Channel name.
    pub name: String,
    /// (free DOF, weight) terms; the weights are the measuring direction's components.
    pub terms: Vec<(usize, f64)>,
}

/// Assembled model on free DOFs.
#[derive(Clone, Debug)]
pub struct FeModel {
    /// Stiffness, both triangles stored, N/m.
    pub k: SparseColMat<usize, f64>,
    /// Consistent mass, both triangles stored, kg.
    pub m: SparseColMat<usize, f64>,
    /// One entry per free DOF, in matrix order.
    pub dofs: Vec<DofInfo>,
    /// Base-excitation direction: 1 on DOFs along the shaker axis (z), 0 elsewhere, so the
    /// inertia load of a base acceleration a is `-M b a`.
    pub base: Vec<f64>,
    /// Contact pairs on free DOFs.
    pub pairs: Vec<PairDofs>,
    /// Nominal clearance at the pairs (normal gap with no load), m.
    pub clearance: f64,
    /// Sensor outputs.
    pub outputs: Vec<OutputDofs>,
    /// Coordinates of the mesh nodes, m (indexed by [`DofInfo::node`]; internal DOFs have
    /// no entry here).
    pub node_coords: Vec<[f64; 3]>,
    /// Number of solid elements (for reports).
    pub n_elements: usize,
}

impl FeModel {
    /// Number of mesh nodes.
    pub fn n_nodes(&self) -> usize {
        self.node_coords.len()
    }

    /// Number of free DOFs.
    pub fn n_dof(&self) -> usize {
        self.dofs.len()
    }
}
