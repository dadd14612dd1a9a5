//! The simulated rig's parameters, gathered from the rig description's `[shaker]`, `[daq]` and
//! `[truth]` tables (described, with their defaults and checks, in [`crate::config::shaker`],
//! [`crate::config::daq`], [`crate::config::truth`] and [`crate::config::physics`], and
//! re-exported here). [`SimRigSpec::validate`] names the key of a bad value.

use serde::{Deserialize, Serialize};

use super::SimRigError;
use crate::config::{RigConfig, SpecError};

pub use crate::config::{
    ChannelNoise, ChannelRanges, ContactCircuitSpec, DaqSpec, ShakerSpec, TruthSpec,
};

/// The simulated rig: shaker, DAQ and truth model.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimRigSpec {
    /// The shaker and its amplifier (`[shaker]`).
    pub shaker: ShakerSpec,
    /// The DAQ (`[daq]`).
    pub daq: DaqSpec,
    /// The truth model (`[truth]`).
    pub truth: TruthSpec,
}

impl SimRigSpec {
    /// The simulated rig's settings of a rig description (`[shaker]`, `[daq]`, `[truth]`).
    pub fn from_config(cfg: &RigConfig) -> SimRigSpec {
        SimRigSpec {
            shaker: cfg.shaker.clone(),
            daq: cfg.daq.clone(),
            truth: cfg.truth.clone(),
        }
    }

    /// Checks every field against the range in its documentation (shaker, DAQ, truth, in
    /// that order). The ROM-dependent checks (moving mass against the beams' modal mass, the
    /// truth step against the stability limit) are done by [`super::SimRig::new`].
    pub fn validate(&self) -> Result<(), SimRigError> {
        self.shaker.validate()?;
        self.daq.validate()?;
        self.truth.validate(&self.daq)?;
        Ok(())
    }
}

impl From<SpecError> for SimRigError {
    fn from(e: SpecError) -> SimRigError {
        SimRigError::Spec(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip_through_toml() {
        let spec = SimRigSpec::default();
        spec.validate().unwrap();
        let text = toml::to_string(&spec).unwrap();
        let back: SimRigSpec = toml::from_str(&text).unwrap();
        assert_eq!(back, spec);
        let empty: SimRigSpec = toml::from_str("").unwrap();
        assert_eq!(empty, spec);
    }

    #[test]
    fn partial_tables_keep_the_other_defaults() {
        let spec: SimRigSpec =
            toml::from_str("[shaker]\nmoving_mass = 50.0\n[daq.noise_rms]\nvibrometer = 0.0\n")
                .unwrap();
        assert_eq!(spec.shaker.moving_mass, 50.0);
        assert_eq!(spec.shaker.coil_resistance, 0.8);
        assert_eq!(spec.daq.noise_rms.vibrometer, 0.0);
        assert_eq!(spec.daq.noise_rms.beam_acceleration, 1.0e-2);
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let err = toml::from_str::<SimRigSpec>("[shaker]\nmoving_mas = 1.0\n").unwrap_err();
        assert!(err.to_string().contains("moving_mas"), "{err}");
    }

    #[test]
    fn bad_values_name_the_key() {
        let mut spec = SimRigSpec::default();
        spec.shaker.coil_resistance = -1.0;
        let msg = spec.validate().unwrap_err().to_string();
        assert!(
            msg.contains("shaker.coil_resistance = -1: expected > 0"),
            "{msg}"
        );

        let mut spec = SimRigSpec::default();
        spec.daq.anti_alias_cutoff = 0.6;
        let msg = spec.validate().unwrap_err().to_string();
        assert!(msg.contains("daq.anti_alias_cutoff = 0.6"), "{msg}");

        let mut spec = SimRigSpec::default();
        spec.daq.platform_accelerometers = vec!["vibrometer".into()];
        let msg = spec.validate().unwrap_err().to_string();
        assert!(msg.contains("daq.platform_accelerometers[0]"), "{msg}");

        let mut spec = SimRigSpec::default();
        spec.truth.oversampling = Some(0);
        assert!(spec.validate().is_err());

        let mut spec = SimRigSpec::default();
        spec.daq.contact_circuit.closed_voltage = 6.0;
        let msg = spec.validate().unwrap_err().to_string();
        assert!(msg.contains("daq.contact_circuit.closed_voltage"), "{msg}");
    }
}
