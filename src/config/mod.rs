//! The rig description (`rig-config/*.toml`): geometry, materials, interface layers,
//! sensors, contact patch, modal damping, mesh resolution and reduction settings, parsed
//! with serde ([`schema`], [`damping`]), validated (`validate`) and hashed for ROM
//! provenance. Errors ([`ConfigError`]) name the file, the line:column or key path, the bad
//! value and what was expected.

pub mod damping;
pub mod error;
pub mod schema;
mod validate;

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

pub use damping::{DampingSpec, ModalDamping};
pub use error::ConfigError;
pub use schema::{
    BeamMesh, BeamSpec, BlockMesh, ClampSpec, ContactSpec, LayerSpec, Layers, LowerProbeSpec,
    MaterialSpec, Materials, MeshSpec, Mount, Parts, ProbeMesh, ProbeSeat, ProtrusionSpec,
    ReductionSpec, RigSection, SensorSpec, TaperedBeamSpec, UpperProbeSpec,
};

/// Text of the embedded default rig description.
pub const DEFAULT_RIG_TOML: &str = include_str!("../../rig-config/two-beam.toml");
/// Source name used for the embedded default rig in messages.
pub const DEFAULT_RIG_SOURCE: &str = "rig-config/two-beam.toml (embedded)";

/// A parsed and validated rig description.
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
    pub control: crate::control::ControlSpec,
    /// `[safety]`: limits of the rig service. Not hashed.
    #[serde(default, skip_serializing)]
    pub safety: crate::control::SafetySpec,
    /// `[shaker]`: the simulated rig's shaker and amplifier. Not hashed.
    #[serde(default, skip_serializing)]
    pub shaker: crate::rig::sim::ShakerSpec,
    /// `[daq]`: the simulated rig's DAQ (sample rate, ranges, noise). Not hashed.
    #[serde(default, skip_serializing)]
    pub daq: crate::rig::sim::DaqSpec,
    /// `[truth]`: the simulated rig's truth model (its own ROM and time step). Not hashed.
    #[serde(default, skip_serializing)]
    pub truth: crate::rig::sim::TruthSpec,
    /// `[twin]`: the live twin's step, input queue and gap handling. Not hashed.
    #[serde(default, skip_serializing)]
    pub twin: crate::twin::TwinSpec,
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

    /// SHA-256 (lower-case hex) of the canonical serialisation (JSON of the parsed
    /// description): comments, whitespace, key order and number spelling do not change it;
    /// explicit defaults hash like omitted ones.
    pub fn canonical_hash(&self) -> String {
        // NOTE: serde_json writes struct fields in declaration order and BTreeMap keys
        // sorted, and f64 with the shortest round-trip representation: a canonical form.
        let json = serde_json::to_string(self).unwrap_or_default();
        let digest = Sha256::digest(json.as_bytes());
        digest.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Checks the description (positive dimensions, known materials, a patch that fits,
    /// node counts, clearance, friction, damping, mesh sizes, sensors, reduction). Parsing
    /// runs it; call it after building or editing a description in code.
    pub fn validate(&self) -> Result<(), ConfigError> {
        validate::validate(self)
    }

    /// The embedded default rig (`rig-config/two-beam.toml`, compiled into the binary).
    pub fn default_rig() -> RigConfig {
        RigConfig::from_str(DEFAULT_RIG_TOML, DEFAULT_RIG_SOURCE)
            .expect("the embedded default rig description is valid (checked by tests)")
    }

    /// The simulated rig's settings (`[shaker]`, `[daq]`, `[truth]`).
    pub fn sim_rig_spec(&self) -> crate::rig::sim::SimRigSpec {
        crate::rig::sim::SimRigSpec {
            shaker: self.shaker.clone(),
            daq: self.daq.clone(),
            truth: self.truth.clone(),
        }
    }

    /// Material by name (validated to exist for every part).
    pub fn material(&self, name: &str) -> Option<&MaterialSpec> {
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
