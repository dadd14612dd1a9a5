//! The model part of a rig description ([`RigModel`]): the sections the parent FE model and
//! its reduction are built from (`[rig]`, `[materials]`, `[parts]`, `[probe_seat]`, `[layers]`,
//! `[[sensors]]`, `[contact]`, `[damping]`, `[mesh]`, `[reduction]`), and nothing of the rig
//! service. It is exactly what the canonical hash (the ROM's identity) covers: the mesher and
//! the ROM builder take a `RigModel`, so a change outside it cannot change a ROM.

use serde::Serialize;
use sha2::{Digest, Sha256};

use super::damping::DampingSpec;
use super::schema::{
    ContactSpec, Layers, MaterialSpec, Materials, MeshSpec, Parts, ProbeSeat, ReductionSpec,
    RigSection, SensorSpec,
};
use super::{validate, ConfigError};

/// A borrowed view of the model sections of a [`super::RigConfig`] (from
/// [`super::RigConfig::model`]); cheap to copy. Each field is the section of the same name.
///
// NOTE: the fields are the model fields of `RigConfig`, with the same names and in the same
// order, and the service tables of `RigConfig` are `skip_serializing`: both serialise to the
// same JSON, so `RigModel::canonical_hash` is the description's canonical hash (pinned by a
// test, since ROM cache keys and logged config hashes depend on it).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RigModel<'a> {
    /// Where the description came from (file name), for error messages. Not hashed.
    #[serde(skip)]
    pub source: &'a str,
    /// `[rig]`: name and beam length.
    pub rig: &'a RigSection,
    /// `[materials.<name>]`.
    pub materials: &'a Materials,
    /// `[parts.*]`.
    pub parts: &'a Parts,
    /// `[probe_seat]`: the probes' shared plan footprint.
    pub probe_seat: &'a ProbeSeat,
    /// `[layers.*]`: elastic interface layers.
    pub layers: &'a Layers,
    /// `[[sensors]]`: accelerometers.
    pub sensors: &'a [SensorSpec],
    /// `[contact]`: patch resolution, clearance, friction.
    pub contact: &'a ContactSpec,
    /// `[damping]`: identified modal damping ratios.
    pub damping: &'a DampingSpec,
    /// `[mesh]`: element sizes.
    pub mesh: &'a MeshSpec,
    /// `[reduction]`: mode selection.
    pub reduction: &'a ReductionSpec,
}

impl<'a> RigModel<'a> {
    /// The contact patch grid the model is meshed with, `[across y, along x]`:
    /// `[reduction] contact_nodes` when given, else `[contact] nodes`.
    pub fn patch_nodes(&self) -> [usize; 2] {
        self.reduction.contact_nodes.unwrap_or(self.contact.nodes)
    }

    /// The key [`RigModel::patch_nodes`] comes from, for error messages.
    pub fn patch_nodes_key(&self) -> &'static str {
        if self.reduction.contact_nodes.is_some() {
            "reduction.contact_nodes"
        } else {
            "contact.nodes"
        }
    }

    /// SHA-256 (lower-case hex) of the canonical serialisation (JSON of the parsed model
    /// sections): comments, whitespace, key order and number spelling do not change it;
    /// explicit defaults hash like omitted ones.
    pub fn canonical_hash(&self) -> String {
        // NOTE: serde_json writes struct fields in declaration order and BTreeMap keys
        // sorted, and f64 with the shortest round-trip representation: a canonical form.
        let json = serde_json::to_string(self).unwrap_or_default();
        let digest = Sha256::digest(json.as_bytes());
        digest.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Checks the model sections (positive dimensions, known materials, a patch that fits,
    /// node counts, clearance, friction, damping, mesh sizes, sensors, reduction).
    pub fn validate(&self) -> Result<(), ConfigError> {
        validate::model(self)
    }

    /// Material by name (validated to exist for every part).
    pub fn material(&self, name: &str) -> Option<&'a MaterialSpec> {
        self.materials.get(name)
    }

    /// Vertical gap between the beams (= spacer block height): lower probe + upper probe +
    /// protrusion heights + clearance, m.
    pub fn beam_gap(&self) -> f64 {
        self.parts.lower_probe.height
            + self.parts.upper_probe.height
            + self.parts.protrusion.height
            + self.contact.clearance
    }

    /// Width of the upper beam at x (clamp root width for x <= 0, linear taper to the tip
    /// width at the start of the probe seat, tip width beyond), m.
    pub fn upper_width_at(&self, x: f64) -> f64 {
        let b = &self.parts.upper_beam;
        let x_seat = self.probe_seat.x_center - 0.5 * self.probe_seat.length;
        if x <= 0.0 {
            b.width_root
        } else if x >= x_seat {
            b.width_tip
        } else {
            b.width_root + (b.width_tip - b.width_root) * (x / x_seat)
        }
    }
}
