//! What the twin models ([`TwinModel`]): the twin ROM, the `[model]` extensions it carries, and
//! how its prediction is observed through the rig's contact channel (the contact-resistance
//! circuit of `[daq.contact_circuit]` and the threshold of `[control]`).

use crate::config::{ContactCircuitSpec, ControlSpec, PhysicsSpec, RigConfig};
use crate::rom::Rom;

/// The twin's model: ROM, extensions and contact observation.
#[derive(Clone, Debug)]
pub struct TwinModel<'a> {
    /// The (nominal) twin ROM.
    pub rom: &'a Rom,
    /// The extensions (`[model]`), valid.
    pub extensions: PhysicsSpec,
    /// The contact-resistance circuit.
    pub circuit: ContactCircuitSpec,
    /// Contact-voltage threshold, V.
    pub contact_threshold_v: f64,
}

impl<'a> TwinModel<'a> {
    /// The model a rig description declares for `rom`: its `[model]`, its contact circuit and
    /// threshold.
    pub fn of_config(rom: &'a Rom, cfg: &RigConfig) -> TwinModel<'a> {
        TwinModel {
            rom,
            extensions: cfg.model.clone(),
            circuit: cfg.daq.contact_circuit.clone(),
            contact_threshold_v: cfg.control.contact_threshold_v,
        }
    }

    /// The model `cfg` declares for `rom` ([`TwinModel::of_config`]), or without one
    /// [`TwinModel::nominal`].
    pub fn of(rom: &'a Rom, cfg: Option<&RigConfig>) -> TwinModel<'a> {
        match cfg {
            Some(c) => TwinModel::of_config(rom, c),
            None => TwinModel::nominal(rom),
        }
    }

    /// `rom` without extensions, observed through the default circuit and threshold of a rig
    /// description.
    pub fn nominal(rom: &'a Rom) -> TwinModel<'a> {
        TwinModel {
            rom,
            extensions: PhysicsSpec::default(),
            circuit: ContactCircuitSpec::default(),
            contact_threshold_v: ControlSpec::default().contact_threshold_v,
        }
    }

    /// This model with the extensions `extensions` (valid).
    pub fn with_extensions(mut self, extensions: PhysicsSpec) -> TwinModel<'a> {
        self.extensions = extensions;
        self
    }
}
