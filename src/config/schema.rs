//! The sections of the rig description (serde structs, one per TOML table). Units are SI.
//! Coordinates: x along the beams (clamp exit at x = 0, tips at x = l), y across (width),
//! z vertical = shaker axis. Every field says its unit and its default ("required" when it
//! has none).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// `[rig]`: identity and the one length both beams share.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigSection {
    /// Rig name (reports, ROM metadata). Required.
    pub name: String,
    /// Free length l of both beams, clamp exit (x = 0) to tip (x = l), m. Required.
    pub beam_length: f64,
}

/// `[materials.<name>]`: an isotropic linear-elastic material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Young's modulus, Pa. Required.
    pub youngs_modulus: f64,
    /// Poisson's ratio, -. Required, in (-1, 0.5).
    pub poisson_ratio: f64,
    /// Mass density, kg/m^3 (effective: may include unmodelled fixtures). Required.
    pub density: f64,
}

/// Hex element formulation of a part (`element = "hex8"` or `"hex8i"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ElementKind {
    /// Trilinear 8-node hex, full 2x2x2 Gauss integration (CalculiX C3D8). Used where the
    /// displacement field on a face must be exactly bilinear (contact faces).
    Hex8,
    /// 8-node hex with incompatible (bubble) modes, condensed at element level (CalculiX
    /// C3D8I): free of shear locking in thin-beam bending.
    Hex8I,
}

/// `[parts]`: the solids of the rig.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Parts {
    /// The three clamping blocks (base, spacer, top).
    pub clamp: ClampSpec,
    /// Lower beam (uniform).
    pub lower_beam: BeamSpec,
    /// Upper beam (width tapered from the clamp exit to the probe seat).
    pub upper_beam: TaperedBeamSpec,
    /// Probe on top of the lower beam (its top face is the flat contact face).
    pub lower_probe: LowerProbeSpec,
    /// Probe hanging below the upper beam (carries the protrusion).
    pub upper_probe: UpperProbeSpec,
    /// Protrusion on the upper probe's bottom face (the contact patch).
    pub protrusion: ProtrusionSpec,
}

/// `[parts.clamp]`: the clamping blocks. The base block sits below the lower beam root and
/// its bottom face is fixed (interface to the shaker platform); the spacer block fills the
/// vertical gap between the beam roots (its height is derived: lower probe + upper probe +
/// protrusion heights + clearance); the top block sits above the upper beam root.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClampSpec {
    /// Material name (a key of `[materials]`). Required.
    pub material: String,
    /// Clamped length along x (blocks span x in [-length, 0]), m. Required.
    pub length: f64,
    /// Block width along y (centred on y = 0), m. Required, at least the widest beam root.
    pub width: f64,
    /// Base block height below the lower beam, m. Required.
    pub base_height: f64,
    /// Top block height above the upper beam, m. Required.
    pub top_height: f64,
    /// Element formulation of the blocks. Default `hex8i`.
    #[serde(default = "hex8i")]
    pub element: ElementKind,
}

/// `[parts.lower_beam]`: uniform rectangular beam, bottom face at z = 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeamSpec {
    /// Material name. Required.
    pub material: String,
    /// Width along y (centred on y = 0), m. Required.
    pub width: f64,
    /// Thickness along z, m. Required.
    pub thickness: f64,
    /// Element formulation. Default `hex8i` (bending without shear locking).
    #[serde(default = "hex8i")]
    pub element: ElementKind,
}

/// `[parts.upper_beam]`: rectangular beam whose width is `width_root` inside the clamp,
/// tapers linearly from the clamp exit to the start of the probe seat and is `width_tip`
/// from there to the tip (so the probe footprint is a box).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaperedBeamSpec {
    /// Material name. Required.
    pub material: String,
    /// Width at the clamp exit and inside the clamp, m. Required.
    pub width_root: f64,
    /// Width from the probe seat to the tip, m. Required.
    pub width_tip: f64,
    /// Thickness along z, m. Required.
    pub thickness: f64,
    /// Element formulation. Default `hex8i`.
    #[serde(default = "hex8i")]
    pub element: ElementKind,
}

/// `[parts.lower_probe]`: box on the lower beam's top face over the probe seat; its top face
/// is the flat contact face.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LowerProbeSpec {
    /// Material name. Required.
    pub material: String,
    /// Height along z, m. Required.
    pub height: f64,
    /// Element formulation. Default `hex8` (linear shape functions on the contact face).
    #[serde(default = "hex8")]
    pub element: ElementKind,
}

/// `[parts.upper_probe]`: box under the upper beam's bottom face over the probe seat.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UpperProbeSpec {
    /// Material name. Required.
    pub material: String,
    /// Height along z (without the protrusion), m. Required.
    pub height: f64,
    /// Element formulation. Default `hex8i`.
    #[serde(default = "hex8i")]
    pub element: ElementKind,
}

/// `[parts.protrusion]`: rectangular block fused to the upper probe's bottom face; its
/// bottom face is the contact patch facing the lower probe across the clearance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProtrusionSpec {
    /// Material name. Required.
    pub material: String,
    /// Extent along x, m. Required.
    pub length: f64,
    /// Extent along y, m. Required.
    pub width: f64,
    /// Height along z, m. Required.
    pub height: f64,
    /// Offset (x, y) of its centre from the probe seat centre, m. Default [0, 0].
    #[serde(default)]
    pub offset: [f64; 2],
    /// Element formulation. Default `hex8` (linear shape functions on the contact face).
    #[serde(default = "hex8")]
    pub element: ElementKind,
}

/// `[probe_seat]`: the plan footprint both probes share (they are aligned in plan).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeSeat {
    /// x of the footprint centre, m. Required.
    pub x_center: f64,
    /// Footprint extent along x, m. Required.
    pub length: f64,
    /// Footprint extent along y (centred on y = 0), m. Required.
    pub width: f64,
}

/// An elastic interface layer: stiffness per unit area, normal to the joint face and in
/// its plane (transversely isotropic, as reference section 3.2). These are the tuning knobs
/// of the linear model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerSpec {
    /// Normal stiffness per area, N/m^3. Required.
    pub normal: f64,
    /// Tangential stiffness per area (both in-plane directions), N/m^3. Required.
    pub tangential: f64,
}

/// `[layers]`: the six interface layers of the rig.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layers {
    /// Lower beam root on the base block.
    pub lower_base: LayerSpec,
    /// Lower beam root under the spacer block.
    pub lower_spacer: LayerSpec,
    /// Upper beam root on the spacer block.
    pub upper_spacer: LayerSpec,
    /// Upper beam root under the top block.
    pub upper_top: LayerSpec,
    /// Lower probe on the lower beam.
    pub lower_probe: LayerSpec,
    /// Upper probe under the upper beam.
    pub upper_probe: LayerSpec,
}

impl Layers {
    /// (layer name, spec) in mesh order; the names are the mesh's layer names.
    pub fn named(&self) -> [(&'static str, LayerSpec); 6] {
        [
            ("lower_base", self.lower_base),
            ("lower_spacer", self.lower_spacer),
            ("upper_spacer", self.upper_spacer),
            ("upper_top", self.upper_top),
            ("lower_probe", self.lower_probe),
            ("upper_probe", self.upper_probe),
        ]
    }
}

/// Where an accelerometer is glued.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mount {
    /// Top face of the lower beam.
    LowerBeamTop,
    /// Bottom face of the lower beam.
    LowerBeamBottom,
    /// Top face of the upper beam.
    UpperBeamTop,
    /// Bottom face of the upper beam.
    UpperBeamBottom,
    /// Shaker platform next to the clamp: sits on the fixed base face, carries no modal
    /// mass and is not a model output (it measures the base motion).
    Platform,
}

/// `[[sensors]]`: an accelerometer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Channel name (unique; node set `SENSOR_<name>`). Required.
    pub name: String,
    /// Face it is glued to. Required.
    pub mount: Mount,
    /// Position along x, m (snapped to the nearest mesh node of the face). Required.
    pub x: f64,
    /// Position along y, m (snapped likewise). Default 0.
    #[serde(default)]
    pub y: f64,
    /// Mass, kg (a point mass on the node; ignored on the fixed platform). Required.
    pub mass: f64,
    /// Measuring direction (normalised on use). Default [0, 0, 1] (vertical).
    #[serde(default = "vertical")]
    pub direction: [f64; 3],
}

/// `[contact]`: the contact patch and its law.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    /// Node counts of the patch grid: [across y (protrusion width), along x (protrusion
    /// length)], each at least 2. Default [12, 16].
    #[serde(default = "default_patch_nodes")]
    pub nodes: [usize; 2],
    /// Initial normal gap between the protrusion and the lower probe, m. Required, > 0.
    pub clearance: f64,
    /// Coulomb friction coefficient (static = dynamic), -. Default 0.4.
    #[serde(default = "default_friction")]
    pub friction: f64,
}

/// `[mesh]`: element sizes and grading. x grid lines are shared by both beams (the clamp
/// blocks take the beams' lines inside the clamp); every other direction is per part.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Largest ratio between neighbouring element sizes in graded regions of beams and
    /// blocks, -. Default 1.3 (1 = no growth).
    #[serde(default = "default_growth")]
    pub growth: f64,
    /// Beam element sizes.
    #[serde(default)]
    pub beams: BeamMesh,
    /// Clamping block element sizes.
    #[serde(default)]
    pub blocks: BlockMesh,
    /// Probe element sizes (their plan lines are graded down to the contact patch spacing;
    /// the protrusion uses the patch spacing in all three directions).
    #[serde(default)]
    pub probes: ProbeMesh,
}

impl Default for MeshSpec {
    fn default() -> Self {
        MeshSpec {
            growth: default_growth(),
            beams: BeamMesh::default(),
            blocks: BlockMesh::default(),
            probes: ProbeMesh::default(),
        }
    }
}

/// `[mesh.beams]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BeamMesh {
    /// Element length along the free span, m. Default 0.005.
    pub free_element: f64,
    /// Element length at the clamp exit (both sides, graded), m. Default 0.002.
    pub clamp_exit_element: f64,
    /// Element length at the clamped root end (x = -clamp length), m. Default 0.005.
    pub clamp_element: f64,
    /// Element length under the probe seat (a subset of the probe's grid lines), m.
    /// Default 0.0025.
    pub seat_element: f64,
    /// Target element width across the beam (at the tip width for the tapered beam), m.
    /// Default 0.005 (4 across 20 mm; the seat and patch edges add lines).
    pub width_element: f64,
    /// Cells through the thickness, -. Default 2.
    pub thickness_cells: usize,
}

impl Default for BeamMesh {
    fn default() -> Self {
        BeamMesh {
            free_element: 0.005,
            clamp_exit_element: 0.002,
            clamp_element: 0.005,
            seat_element: 0.0025,
            width_element: 0.005,
            thickness_cells: 2,
        }
    }
}

/// `[mesh.blocks]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BlockMesh {
    /// Target element size of the blocks vertically and across y outside the beams, m.
    /// Default 0.008.
    pub element: f64,
}

impl Default for BlockMesh {
    fn default() -> Self {
        BlockMesh { element: 0.008 }
    }
}

/// `[mesh.probes]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProbeMesh {
    /// Largest probe element size, m. Default 0.0035.
    pub element: f64,
    /// Largest ratio between neighbouring element sizes from the patch spacing up, -.
    /// Default 2.0.
    pub growth: f64,
}

impl Default for ProbeMesh {
    fn default() -> Self {
        ProbeMesh {
            element: 0.0035,
            growth: 2.0,
        }
    }
}

/// `[reduction]`: how many free-interface modes the ROM keeps (exactly one of `cutoff_ratio`,
/// `cutoff_hz`, `modes`) and optionally the model's own contact patch (`contact_nodes`);
/// default `cutoff_ratio = 180` (the ROM builder turns it into its mode selection:
/// `ModeSelection::from(&ReductionSpec)` in `rom::build`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ReductionSpec {
    /// Keep modes up to this multiple of f(1FU), -.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutoff_ratio: Option<f64>,
    /// Keep modes up to this frequency, Hz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutoff_hz: Option<f64>,
    /// Keep this many lowest modes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modes: Option<usize>,
    /// The model ROM's contact patch grid [across y, along x], each at least 2, in place of
    /// `[contact] nodes`; the simulated rig's truth ROM keeps `[contact] nodes`. Not a mode
    /// selection (may be given beside one). Default: none (the model uses `[contact] nodes`).
    // NOTE: a MODEL change, for speed in held contact: the contact solve's cost grows with
    // the pairs (dense Delassus matrix, 3 rows per pair), and held contact on the default
    // 12 x 16 patch keeps the twin near 1.5 x real time. On the default rig an 8 x 11 patch
    // (88 pairs) ran held contact 3.8 x faster with the outputs within the chaotic spread of
    // the default patch (velocity RMS within 2.2 %, contact fraction within 7 %, mean normal
    // force within 2.3 %); 6 x 8 moved the impacts' contact fraction by +27 % (BENCHMARKS.md
    // "Held contact, fourth pass").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_nodes: Option<[usize; 2]>,
}

/// Materials by name.
pub type Materials = BTreeMap<String, MaterialSpec>;

fn hex8i() -> ElementKind {
    ElementKind::Hex8I
}

fn hex8() -> ElementKind {
    ElementKind::Hex8
}

fn vertical() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

fn default_patch_nodes() -> [usize; 2] {
    [12, 16]
}

fn default_friction() -> f64 {
    0.4
}

fn default_growth() -> f64 {
    1.3
}
