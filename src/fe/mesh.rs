//! The mesh data model shared by the rig mesher, the element assembly and the CalculiX
//! exchange: nodes, hex elements grouped in blocks (one block per part), interface-layer
//! springs, point masses, clamped nodes, contact node pairs, sensor points and named node sets.
//!
//! Units are SI throughout (m, kg, Pa, N/m). Node and element indices are 0-based here;
//! the CalculiX exchange converts to and from its 1-based numbering.

use std::collections::BTreeMap;

/// Hex element formulation of a block (named in the rig description, hence defined there).
pub use crate::config::ElementKind;
use crate::fe::hex8::hex_volume;

// NOTE: an inherent impl on the description's enum: the CalculiX name is FE knowledge.
impl ElementKind {
    /// The CalculiX element type name.
    pub fn calculix_name(self) -> &'static str {
        match self {
            ElementKind::Hex8 => "C3D8",
            ElementKind::Hex8I => "C3D8I",
        }
    }
}

/// Isotropic linear-elastic material.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Material {
    /// Name as in the rig description (e.g. "steel").
    pub name: String,
    /// Young's modulus, Pa.
    pub youngs_modulus: f64,
    /// Poisson's ratio, -.
    pub poisson_ratio: f64,
    /// Mass density, kg/m^3 (effective: may include the mass of fixtures that are not modelled).
    pub density: f64,
}

/// A group of elements of one part with one material and one formulation.
#[derive(Clone, Debug, PartialEq)]
pub struct ElementBlock {
    /// Part name (becomes the CalculiX element set name).
    pub name: String,
    /// Index into [`Mesh::materials`].
    pub material: usize,
    /// Element formulation.
    pub kind: ElementKind,
}

/// An 8-node hex element. Node order follows CalculiX/Abaqus: nodes 0-3 on the face
/// zeta = -1 counter-clockwise seen from +zeta, i.e. natural coordinates
/// (-1,-1,-1), (1,-1,-1), (1,1,-1), (-1,1,-1), then 4-7 the same at zeta = +1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HexElement {
    /// Node indices into [`Mesh::nodes`].
    pub nodes: [usize; 8],
    /// Index into [`Mesh::blocks`].
    pub block: usize,
}

/// A zero-length spring between two coincident nodes of an elastic interface layer,
/// stiff along the global axes: the layer's normal and tangential stiffness per area times
/// the nodal tributary area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    /// First node (on the first part of the layer).
    pub a: usize,
    /// Second node (on the second part of the layer).
    pub b: usize,
    /// Stiffness along global x, y, z, N/m.
    pub stiffness: [f64; 3],
    /// Index into [`Mesh::layers`].
    pub layer: usize,
}

/// A lumped mass on a node (accelerometers), translational only.
#[derive(Clone, Debug, PartialEq)]
pub struct PointMass {
    /// Sensor or item name.
    pub name: String,
    /// Node it sits on.
    pub node: usize,
    /// Mass, kg.
    pub mass: f64,
}

/// A conforming contact node pair with its local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPair {
    /// Node on the lower body (flat lower probe face).
    pub lower: usize,
    /// Node on the upper body (protrusion face).
    pub upper: usize,
    /// Local frame rows: normal n (pointing from lower to upper, so positive relative normal
    /// displacement opens the gap), then tangents t1, t2. Orthonormal, right-handed.
    pub frame: [[f64; 3]; 3],
    /// Tributary area of the pair on the contact face, m^2.
    pub area: f64,
}

/// A named output point: a node and a measuring direction (unit vector, global frame).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorPoint {
    /// Channel name, e.g. "upper_tip".
    pub name: String,
    /// Node.
    pub node: usize,
    /// Measuring direction (unit vector).
    pub direction: [f64; 3],
}

/// The complete parent mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Node coordinates, m.
    pub nodes: Vec<[f64; 3]>,
    /// Solid elements.
    pub elements: Vec<HexElement>,
    /// Element blocks (parts).
    pub blocks: Vec<ElementBlock>,
    /// Materials referenced by blocks.
    pub materials: Vec<Material>,
    /// Interface-layer names, indexed by [`Spring::layer`].
    pub layers: Vec<String>,
    /// Interface-layer springs.
    pub springs: Vec<Spring>,
    /// Point masses.
    pub point_masses: Vec<PointMass>,
    /// Nodes with all three translations fixed (clamp interface to the shaker platform).
    pub fixed_nodes: Vec<usize>,
    /// Contact node pairs.
    pub contact_pairs: Vec<ContactPair>,
    /// Output points (sensors).
    pub sensors: Vec<SensorPoint>,
    /// Named node sets (sorted, unique). By convention the rig mesher provides
    /// `LOWER` (lower beam and its probe), `UPPER` (upper beam, probe and protrusion),
    /// `CLAMP` (clamping blocks), `FIXED`, `CONTACT_LOWER`, `CONTACT_UPPER`.
    pub node_sets: BTreeMap<String, Vec<usize>>,
}

impl Mesh {
    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Total mass of solids and point masses, kg (for checks and reports).
    pub fn total_mass(&self) -> f64 {
        let solid: f64 = self
            .elements
            .iter()
            .map(|e| {
                let rho = self.materials[self.blocks[e.block].material].density;
                rho * hex_volume(&e.nodes.map(|n| self.nodes[n]))
            })
            .sum();
        solid + self.point_masses.iter().map(|p| p.mass).sum::<f64>()
    }
}
