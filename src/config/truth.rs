//! The simulated rig's truth model (`[truth]`): which ROM stands for the real rig, its time
//! step, and the physics the twin does not know (`[truth.variants]`, see [`super::physics`]).
//! Every field states its unit and default; [`TruthSpec::validate`] names the key of a bad
//! value. Not part of the model: not hashed. The truth model itself lives in
//! `rig::sim::truth`.

use serde::{Deserialize, Serialize};

use super::daq::DaqSpec;
use super::error::{check, positive, SpecError};
use super::physics::TruthVariants;

/// The truth model (TOML `[truth]`): which ROM stands for the real rig and its time step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthSpec {
    /// Mode cutoff of the truth ROM as a multiple of f(1FU) (> 0). The backend's builder
    /// builds the truth ROM with it; richer than the twin's 180 so the twin does not know
    /// everything the "rig" does. Default 400.
    pub cutoff_ratio: f64,
    /// Truth steps per DAQ sample (>= 1), overriding the automatic choice. The truth step is
    /// `dt = 1 / (sample_rate * oversampling)` and must stay below the open stability limit
    /// of the truth ROM with the base attached. Default: none (automatic).
    pub oversampling: Option<u32>,
    /// Automatic choice: the largest fraction of the open stability limit the truth step may
    /// use, in (0, 1) (`dt_max_open = 2 / w_max`, `w_max` the highest frequency of the truth
    /// ROM with the base attached, about max(Omega)). Default 0.5.
    pub stability_margin: f64,
    /// Automatic choice: at least this many truth steps per 1FU period (> 0). Default 1000
    /// (the reference's resolution).
    pub min_steps_per_reference_period: f64,
    /// Physics the twin does not know (`[truth.variants]`): clamp friction, wear, a tilted
    /// protrusion, sensor sensitivity errors. Default: all off.
    pub variants: TruthVariants,
}

impl Default for TruthSpec {
    fn default() -> Self {
        TruthSpec {
            cutoff_ratio: 400.0,
            oversampling: None,
            stability_margin: 0.5,
            min_steps_per_reference_period: 1000.0,
            variants: TruthVariants::default(),
        }
    }
}

impl TruthSpec {
    /// Truth steps per DAQ sample for a DAQ rate `sample_rate` (Hz) and a ROM with open
    /// stability limit `dt_max_open` (s) and reference circular frequency `omega_ref` (rad/s):
    /// the override if given, else the smallest integer >= 1 with
    /// `dt <= stability_margin * dt_max_open` and at least `min_steps_per_reference_period`
    /// steps per 1FU period. The spec must be valid.
    pub fn oversampling_for(&self, sample_rate: f64, dt_max_open: f64, omega_ref: f64) -> u32 {
        if let Some(n) = self.oversampling {
            return n;
        }
        let dt_stable = self.stability_margin * dt_max_open;
        let dt_resolution =
            2.0 * std::f64::consts::PI / (omega_ref * self.min_steps_per_reference_period);
        let dt = dt_stable.min(dt_resolution);
        let n = (1.0 / (sample_rate * dt)).ceil();
        if n.is_finite() && n >= 1.0 {
            n.min(f64::from(u32::MAX)) as u32
        } else {
            1
        }
    }

    /// Checks every field against the range in its documentation; `daq` gives the channel
    /// names the sensor-gain variant may use. The ROM-dependent check (the truth step against
    /// the stability limit) is done by `rig::sim::SimRig::new`.
    pub fn validate(&self, daq: &DaqSpec) -> Result<(), SpecError> {
        let t = self;
        positive("truth.cutoff_ratio", t.cutoff_ratio)?;
        if t.oversampling == Some(0) {
            return Err(SpecError::new(
                "truth.oversampling",
                0,
                ">= 1 truth steps per DAQ sample",
            ));
        }
        check(
            "truth.stability_margin",
            t.stability_margin,
            t.stability_margin > 0.0 && t.stability_margin < 1.0,
            "a fraction in (0, 1)",
        )?;
        positive(
            "truth.min_steps_per_reference_period",
            t.min_steps_per_reference_period,
        )?;
        t.variants.validate("truth.variants", daq)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn automatic_oversampling_respects_stability_and_resolution() {
        let t = TruthSpec::default();
        let w_ref = 2.0 * std::f64::consts::PI * 55.0;
        // Stability limits: dt_max_open = 3.24e-5 s (modes to 9.8 kHz): 0.5 * that needs
        // 1 / (10240 * 1.62e-5) = 6.03 -> 7 steps per sample.
        assert_eq!(t.oversampling_for(10240.0, 3.24e-5, w_ref), 7);
        // A ROM with only low modes: the resolution rule (1000 per 1FU period) decides:
        // 55000 / 10240 = 5.37 -> 6.
        assert_eq!(t.oversampling_for(10240.0, 1.0, w_ref), 6);
        let t = TruthSpec {
            oversampling: Some(3),
            ..TruthSpec::default()
        };
        assert_eq!(t.oversampling_for(10240.0, 3.24e-5, w_ref), 3);
    }
}
