//! The rig description (`rig-config/*.toml`): geometry, materials, interface layers,
//! sensors, contact patch, modal damping, mesh resolution and reduction settings (the model,
//! [`RigModel`]: [`schema`], [`damping`]), and the rig service's tables ([`control`],
//! [`twin`], and the simulated rig's [`shaker`], [`daq`], [`truth`] with its hidden
//! physics, and the model's declared extensions `[model]` (both [`physics`]),
//! parsed with serde, validated (`validate`) and hashed for ROM provenance. Errors
//! ([`ConfigError`]) name the file, the line:column or key path, the bad value and what was
//! expected; a service spec checked on its own returns a [`SpecError`].
//!
//! A leaf: imports nothing of the crate. The code that builds from a description takes the
//! part it needs (the mesher and the ROM builder a [`RigModel`], the simulated rig its
//! shaker, DAQ and truth specs).

pub mod control;
pub mod damping;
pub mod daq;
pub mod error;
pub mod model;
pub mod physics;
pub mod schema;
pub mod shaker;
pub mod truth;
pub mod twin;
mod validate;

use std::path::Path;

use serde::{Deserialize, Serialize};

pub use control::{ControlSpec, SafetySpec};
pub use damping::{DampingSpec, ModalDamping};
pub use daq::{ChannelNoise, ChannelRanges, ContactCircuitSpec, DaqSpec, FIXED_CHANNEL_NAMES};
pub use error::{ConfigError, SpecError};
pub use model::RigModel;
pub use physics::{
    Beam, ClampFrictionSpec, ClearanceSpec, ModalCorrectionSpec, ModelExtensions, PhysicsSpec,
    SensorGainSpec, TestClearanceSpec, TiltSpec, TruthVariants, WearSpec,
};
pub use schema::{
    BeamMesh, BeamSpec, BlockMesh, ClampSpec, ContactSpec, ElementKind, LayerSpec, Layers,
    LowerProbeSpec, MaterialSpec, Materials, MeshSpec, Mount, Parts, ProbeMesh, ProbeSeat,
    ProtrusionSpec, ReductionSpec, RigSection, SensorSpec, TaperedBeamSpec, UpperProbeSpec,
};
pub use shaker::ShakerSpec;
pub use truth::TruthSpec;
pub use twin::{AfterGap, HeldContactSpec, TwinSpec};

/// Text of the embedded default rig description.
pub const DEFAULT_RIG_TOML: &str = include_str!("../../rig-config/two-beam.toml");
/// Source name used for the embedded default rig in messages.
pub const DEFAULT_RIG_SOURCE: &str = "rig-config/two-beam.toml (embedded)";

/// A parsed and validated rig description: the model sections (viewed together as
/// [`RigConfig::model`]) and the rig service's tables.
///
// NOTE: the model fields must stay in the order and with the names of `RigModel`'s (the
// canonical hash is the JSON of either); the service tables are `skip_serializing`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigConfig {
    /// Where the description came from (file name), for error messages. Not part of the
    /// description (not serialised, not hashed).
    #[serde(skip)]
    pub source: String,
    /// `[rig]`: name and beam length.
    pub rig: RigSection,
    /// `[materials.<name>]`.
    pub materials: Materials,
    /// `[parts.*]`.
    pub parts: Parts,
    /// `[probe_seat]`: the probes' shared plan footprint.
    pub probe_seat: ProbeSeat,
    /// `[layers.*]`: elastic interface layers.
    pub layers: Layers,
    /// `[[sensors]]`: accelerometers.
    #[serde(default)]
    pub sensors: Vec<SensorSpec>,
    /// `[contact]`: patch resolution, clearance, friction.
    pub contact: ContactSpec,
    /// `[damping]`: identified modal damping ratios.
    pub damping: DampingSpec,
    /// `[mesh]`: element sizes. Defaults apply when absent.
    #[serde(default)]
    pub mesh: MeshSpec,
    /// `[reduction]`: mode selection. Default 180 x f(1FU).
    #[serde(default)]
    pub reduction: ReductionSpec,
    /// `[control]`: the amplitude controller and settle detection of the rig service. Not
    /// part of the model: not hashed (changing a gain does not rebuild the ROM).
    #[serde(default, skip_serializing)]
    pub control: ControlSpec,
    /// `[safety]`: limits of the rig service. Not hashed.
    #[serde(default, skip_serializing)]
    pub safety: SafetySpec,
    /// `[shaker]`: the simulated rig's shaker and amplifier. Not hashed.
    #[serde(default, skip_serializing)]
    pub shaker: ShakerSpec,
    /// `[daq]`: the simulated rig's DAQ (sample rate, ranges, noise). Not hashed.
    #[serde(default, skip_serializing)]
    pub daq: DaqSpec,
    /// `[truth]`: the simulated rig's truth model (its own ROM and time step). Not hashed.
    #[serde(default, skip_serializing)]
    pub truth: TruthSpec,
    /// `[twin]`: the live twin's step, input queue and gap handling. Not hashed.
    #[serde(default, skip_serializing)]
    pub twin: TwinSpec,
    /// `[model]`: the model's extensions, the physics the nominal ROM leaves out, declared
    /// (see [`physics`]). Used by `simulate`, the twin of `run` and `replay`, and `diagnose`.
    /// Not part of the ROM's identity: not hashed.
    #[serde(default, skip_serializing)]
    pub model: ModelExtensions,
}

/// The rig description `text` with its `[model]` table replaced by `model` (removed when no
/// extension is on), for a program that writes a fitted model out (`diagnose
/// --write-config`). The other tables are kept as parsed (comments and key order are not):
/// reading the result gives the same description with `model` as its `[model]`.
pub fn with_model(
    text: &str,
    source_name: &str,
    model: &PhysicsSpec,
) -> Result<String, ConfigError> {
    let mut table = parse_table(text, source_name)?;
    table.remove("model");
    if model.any() {
        let value = toml::Value::try_from(model).map_err(|e| ConfigError::Service {
            file: source_name.to_string(),
            message: format!("model: cannot write the extensions as TOML: {e}"),
        })?;
        table.insert("model".to_string(), value);
    }
    write_table(&table, source_name)
}

/// The rig description `text` with the twin's discretisation changed (`diagnose
/// --write-config` where the `discretisation` effect was accepted): its `[reduction]` table
/// replaced by `reduction` where given, and its `[twin] steps_per_reference_period` set to
/// `steps_per_reference_period` where given, `[twin] steps_per_sample` removed (the step
/// then follows the ROM). The other tables are kept as parsed, as by [`with_model`].
pub fn with_discretisation(
    text: &str,
    source_name: &str,
    reduction: Option<&ReductionSpec>,
    steps_per_reference_period: Option<f64>,
) -> Result<String, ConfigError> {
    let mut table = parse_table(text, source_name)?;
    if let Some(r) = reduction {
        let value = toml::Value::try_from(r).map_err(|e| ConfigError::Service {
            file: source_name.to_string(),
            message: format!("reduction: cannot write it as TOML: {e}"),
        })?;
        table.insert("reduction".to_string(), value);
    }
    if let Some(s) = steps_per_reference_period {
        let twin = table
            .entry("twin")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        let Some(twin) = twin.as_table_mut() else {
            return Err(ConfigError::Service {
                file: source_name.to_string(),
                message: "twin: not a table".to_string(),
            });
        };
        twin.remove("steps_per_sample");
        twin.insert(
            "steps_per_reference_period".to_string(),
            toml::Value::Float(s),
        );
    }
    write_table(&table, source_name)
}

/// The rig description `text` without its `[truth]` tables (the simulated rig's truth model
/// and hidden physics), for a program that must not see them (`diagnose`). The other tables
/// are kept as parsed (comments and key order are not).
pub fn without_truth(text: &str, source_name: &str) -> Result<String, ConfigError> {
    let mut table = parse_table(text, source_name)?;
    table.remove("truth");
    write_table(&table, source_name)
}

/// `text` parsed as a TOML table; a syntax error names the file, line and column.
fn parse_table(text: &str, source_name: &str) -> Result<toml::Table, ConfigError> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map_or((0, 0), |s| error::line_column(text, s.start));
        ConfigError::Syntax {
            file: source_name.to_string(),
            line,
            column,
            message: e.message().trim().to_string(),
        }
    })
}

fn write_table(table: &toml::Table, source_name: &str) -> Result<String, ConfigError> {
    toml::to_string(table).map_err(|e| ConfigError::Service {
        file: source_name.to_string(),
        message: format!("cannot write the rig description as TOML: {e}"),
    })
}

impl RigConfig {
    /// Reads, parses and validates a rig description file.
    pub fn from_path(path: &Path) -> Result<RigConfig, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            file: file.clone(),
            source,
        })?;
        RigConfig::from_str(&text, &file)
    }

    /// Parses and validates a rig description; `source_name` names it in errors.
    #[allow(clippy::should_implement_trait)] // takes the source name too
    pub fn from_str(text: &str, source_name: &str) -> Result<RigConfig, ConfigError> {
        let file = source_name.to_string();
        // Pass 1: TOML syntax (spans point at the offending character).
        let table: toml::Table = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map_or((0, 0), |s| error::line_column(text, s.start));
            ConfigError::Syntax {
                file: file.clone(),
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })?;
        // Pass 2: the schema, from the text so the error carries a span.
        let mut cfg: RigConfig = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map_or((0, 0), |s| error::line_column(text, s.start));
            let message = e.message().trim().to_string();
            let mut key = schema_key_path(&table);
            // An unknown key is reported on its table: name the key itself.
            if let Some(name) = message
                .strip_prefix("unknown field `")
                .and_then(|r| r.split('`').next())
            {
                key = if key == DOCUMENT {
                    name.to_string()
                } else {
                    format!("{key}.{name}")
                };
            }
            ConfigError::Schema {
                file: file.clone(),
                line,
                column,
                key,
                message,
            }
        })?;
        cfg.source = file;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The description the twin runs on in a session whose tests have the clearances
    /// `clearances` (/ l), where that differs from this one: `[reduction] contact_nodes` set
    /// to `[twin.held_contact] contact_nodes` when every test holds the probes in contact
    /// ([`twin::HeldContactSpec`]), this description sets no patch of its own, and the
    /// held-contact patch has fewer pairs than `[contact] nodes`. None: the twin runs on this
    /// description's model.
    pub fn held_contact_twin(&self, clearances: &[f64]) -> Option<RigConfig> {
        if self.reduction.contact_nodes.is_some() {
            return None;
        }
        let nodes = self.twin.held_contact.patch_for(clearances)?;
        let pairs = |n: [usize; 2]| n[0] * n[1];
        if pairs(nodes) >= pairs(self.contact.nodes) {
            return None;
        }
        let mut twin = self.clone();
        twin.reduction.contact_nodes = Some(nodes);
        Some(twin)
    }

    /// The model sections: what the FE model and its reduction are built from, and what the
    /// canonical hash covers.
    pub fn model(&self) -> RigModel<'_> {
        RigModel {
            source: &self.source,
            rig: &self.rig,
            materials: &self.materials,
            parts: &self.parts,
            probe_seat: &self.probe_seat,
            layers: &self.layers,
            sensors: &self.sensors,
            contact: &self.contact,
            damping: &self.damping,
            mesh: &self.mesh,
            reduction: &self.reduction,
        }
    }

    /// SHA-256 (lower-case hex) of the canonical serialisation of the model sections
    /// ([`RigModel::canonical_hash`]): comments, whitespace, key order, number spelling and
    /// the service tables do not change it; explicit defaults hash like omitted ones.
    pub fn canonical_hash(&self) -> String {
        self.model().canonical_hash()
    }

    /// Checks the description: the model sections ([`RigModel::validate`]), then the service
    /// tables (`[control]`, `[safety]`, `[twin]`, `[shaker]`, `[daq]`, `[truth]`). Parsing runs
    /// it; call it after building or editing a description in code.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.model().validate()?;
        validate::service(self)
    }

    /// The embedded default rig (`rig-config/two-beam.toml`, compiled into the binary).
    pub fn default_rig() -> RigConfig {
        RigConfig::from_str(DEFAULT_RIG_TOML, DEFAULT_RIG_SOURCE)
            .expect("the embedded default rig description is valid (checked by tests)")
    }

    /// Material by name (validated to exist for every part).
    pub fn material(&self, name: &str) -> Option<&MaterialSpec> {
        self.materials.get(name)
    }

    /// Vertical gap between the beams: [`RigModel::beam_gap`], m.
    pub fn beam_gap(&self) -> f64 {
        self.model().beam_gap()
    }

    /// Width of the upper beam at x: [`RigModel::upper_width_at`], m.
    pub fn upper_width_at(&self, x: f64) -> f64 {
        self.model().upper_width_at(x)
    }
}

/// Key path reported for errors at the top level of the document.
const DOCUMENT: &str = "(document)";

/// The key path of a schema error, recovered by deserialising the span-less value tree:
/// toml then reports the keys it unwound through ("... in `a.b.c`").
fn schema_key_path(table: &toml::Table) -> String {
    match table.clone().try_into::<RigConfig>() {
        Ok(_) => String::from(DOCUMENT),
        Err(e) => e
            .to_string()
            .lines()
            .rev()
            .find_map(|l| {
                l.strip_prefix("in `")
                    .and_then(|k| k.strip_suffix('`'))
                    .map(str::to_string)
            })
            .unwrap_or_else(|| String::from(DOCUMENT)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The canonical hash of the embedded default rig as computed before the model sections
    /// were viewed as [`RigModel`] (main at d653aa3). ROM cache keys and the config hashes in
    /// session logs depend on it: change the expected value only with a deliberate change of
    /// `rig-config/two-beam.toml`.
    #[test]
    fn default_rig_canonical_hash_is_pinned() {
        let cfg = RigConfig::default_rig();
        assert_eq!(
            cfg.canonical_hash(),
            "509d7350a050439305888cef6ffe9f2a85defd0b54213572cb98f9ef0943cfce"
        );
        assert_eq!(cfg.model().canonical_hash(), cfg.canonical_hash());
        // The truth ROM's description (the same rig with `cutoff_ratio = 400`).
        let mut truth = cfg.clone();
        truth.reduction.cutoff_ratio = Some(400.0);
        assert_eq!(
            truth.canonical_hash(),
            "6b0c7588468545b90954e9bf097f6b5926b62b69379cf7338acc9d6343cda36c"
        );
    }

    #[test]
    fn service_tables_do_not_change_the_hash() {
        let base = RigConfig::default_rig();
        let text = format!(
            "{DEFAULT_RIG_TOML}\n[control]\nkp = 0.1\n[safety]\nmax_drive_v = 3.0\n\
             [shaker]\nmoving_mass = 40.0\n[daq]\nblock_size = 128\n[truth]\ncutoff_ratio = 300.0\n"
        );
        let cfg = RigConfig::from_str(&text, "service.toml").unwrap();
        assert_eq!(cfg.canonical_hash(), base.canonical_hash());
    }
}
