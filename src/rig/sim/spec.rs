//! The simulated rig's parameters (TOML tables `[shaker]`, `[daq]`, `[truth]`): the
//! electrodynamic shaker and its amplifier, the DAQ (rate, ADC, anti-alias filter, ranges,
//! noise, contact circuit), the truth model's time step and its hidden physics
//! (`[truth.variants]`, see [`super::variants`]). Every field states its unit and default;
//! [`SimRigSpec::validate`] names the key of a bad value.
//!
//! The defaults model a large electrodynamic shaker carrying the small two-beam rig
//! (reference section 5: the total moving mass is large compared with the beams' modal mass,
//! so exciter-structure interaction is weak, yet the resonant force drop is visible): 50 kg
//! moving on a soft suspension (5.7 Hz), a low-impedance coil (0.8 ohm, 1 mH, 40 N/A) behind a
//! voltage amplifier, and a 24-bit DAQ at 10240 Hz. With the default ROM (sum(beta_i^2) =
//! 0.74 kg, 1FU: beta^2 = 0.21 kg at 0.18 % damping) the linear base acceleration at a
//! constant drive dips to about 0.6 of its value at 0.9 / 1.1 omega_1FU (30 kg: 0.39,
//! 100 kg: 0.84); under impacts the tips cannot build up the resonance and the dip mostly
//! disappears.

use serde::{Deserialize, Serialize};

use super::variants::TruthVariants;
use super::SimRigError;

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

/// An electrodynamic shaker driven by a voltage amplifier: moving mass on a suspension, coil
/// with resistance, inductance and force constant (TOML `[shaker]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShakerSpec {
    /// Everything that moves with the table, kg: armature, table, clamping blocks and the
    /// beams themselves (the beams' modal reaction is subtracted from it, so it must exceed
    /// `sum_i beta_i^2` of the truth ROM). Default 50 (a large shaker: armature about 25 kg,
    /// table/head expander 15 kg, clamping blocks 9 kg, beams with probes 0.74 kg).
    pub moving_mass: f64,
    /// Axial stiffness of the armature suspension, N/m (>= 0). Default 6.5e4 (suspension
    /// frequency 5.7 Hz with the default mass, well below the test band).
    pub suspension_stiffness: f64,
    /// Damping ratio of the suspension alone, - (>= 0; the coil adds electrical damping
    /// `Bl^2 / R` under voltage drive). Default 0.05.
    pub suspension_damping_ratio: f64,
    /// Coil resistance R, ohm (> 0). Default 0.8.
    pub coil_resistance: f64,
    /// Coil inductance L, H (> 0). Default 1.0e-3 (electrical corner R / (2 pi L) = 127 Hz).
    pub coil_inductance: f64,
    /// Force constant Bl, N/A (= back-EMF constant, V s/m) (> 0). Default 40.
    pub force_constant: f64,
    /// Voltage gain of the power amplifier, V/V (> 0). Default 20.
    pub amplifier_gain: f64,
    /// Largest output voltage magnitude of the amplifier, V (> 0); beyond it the output clips
    /// and the rig reports drive saturation. Default 60.
    pub amplifier_limit_v: f64,
}

impl Default for ShakerSpec {
    fn default() -> Self {
        ShakerSpec {
            moving_mass: 50.0,
            suspension_stiffness: 6.5e4,
            suspension_damping_ratio: 0.05,
            coil_resistance: 0.8,
            coil_inductance: 1.0e-3,
            force_constant: 40.0,
            amplifier_gain: 20.0,
            amplifier_limit_v: 60.0,
        }
    }
}

impl ShakerSpec {
    /// Suspension damping coefficient `c = 2 zeta sqrt(k M)`, N s/m.
    pub fn suspension_damping(&self) -> f64 {
        2.0 * self.suspension_damping_ratio * (self.suspension_stiffness * self.moving_mass).sqrt()
    }
}

/// Full-scale range (largest measurable magnitude) per channel kind, in the channel's unit
/// (TOML `[daq.full_scale]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChannelRanges {
    /// Platform accelerometers, m/s^2 (> 0). Default 100 (about 10 g).
    pub platform_acceleration: f64,
    /// Beam accelerometers, m/s^2 (> 0). Default 1.0e4 (about 1000 g; impacts at the paper's
    /// high level peak near 1.5e3 m/s^2 after the anti-alias filter).
    pub beam_acceleration: f64,
    /// Vibrometer, m/s (> 0). Default 2.
    pub vibrometer: f64,
    /// Contact-circuit voltage, V (> 0). Default 10.
    pub contact_voltage: f64,
    /// Amplifier output voltage, V (> 0). Default 100 (above the amplifier limit).
    pub drive_voltage: f64,
    /// Coil current, A (> 0). Default 100 (above amplifier limit / coil resistance).
    pub drive_current: f64,
}

impl Default for ChannelRanges {
    fn default() -> Self {
        ChannelRanges {
            platform_acceleration: 100.0,
            beam_acceleration: 1.0e4,
            vibrometer: 2.0,
            contact_voltage: 10.0,
            drive_voltage: 100.0,
            drive_current: 100.0,
        }
    }
}

/// RMS of the white sensor noise added at the DAQ rate per channel kind, in the channel's
/// unit (TOML `[daq.noise_rms]`); 0 switches a kind's noise off.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChannelNoise {
    /// Platform accelerometers, m/s^2 (>= 0). Default 2.0e-3.
    pub platform_acceleration: f64,
    /// Beam accelerometers, m/s^2 (>= 0). Default 1.0e-2.
    pub beam_acceleration: f64,
    /// Vibrometer, m/s (>= 0). Default 2.0e-5.
    pub vibrometer: f64,
    /// Contact-circuit voltage, V (>= 0). Default 2.0e-3.
    pub contact_voltage: f64,
    /// Amplifier output voltage, V (>= 0). Default 5.0e-3.
    pub drive_voltage: f64,
    /// Coil current, A (>= 0). Default 2.0e-3.
    pub drive_current: f64,
}

impl Default for ChannelNoise {
    fn default() -> Self {
        ChannelNoise {
            platform_acceleration: 2.0e-3,
            beam_acceleration: 1.0e-2,
            vibrometer: 2.0e-5,
            contact_voltage: 2.0e-3,
            drive_voltage: 5.0e-3,
            drive_current: 2.0e-3,
        }
    }
}

/// The contact-resistance circuit across the probes (TOML `[daq.contact_circuit]`): a voltage
/// that drops while any pair is closed, with a first-order (RC) response.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactCircuitSpec {
    /// Voltage with the probes apart, V. Default 5.
    pub open_voltage: f64,
    /// Voltage with the probes touching, V (below `open_voltage`). Default 0.05.
    pub closed_voltage: f64,
    /// Time constant of the circuit, s (> 0). Default 5.0e-5.
    pub time_constant: f64,
}

impl Default for ContactCircuitSpec {
    fn default() -> Self {
        ContactCircuitSpec {
            open_voltage: 5.0,
            closed_voltage: 0.05,
            time_constant: 5.0e-5,
        }
    }
}

/// The data acquisition (TOML `[daq]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaqSpec {
    /// Samples per second per channel, Hz (> 0). Default 10240.
    pub sample_rate: f64,
    /// Samples per channel per block (>= 1). Default 256 (25 ms at the default rate).
    pub block_size: usize,
    /// ADC resolution, bits (2..=32); counts span +-(2^(bits-1) - 1). Default 24.
    pub adc_bits: u32,
    /// Full-scale ranges per channel kind.
    pub full_scale: ChannelRanges,
    /// Cutoff (-3 dB) of the 4th-order Butterworth anti-alias filter, as a fraction of
    /// `sample_rate` (in (0, 0.5)). Default 0.25 (2560 Hz at the default rate; -24 dB at the
    /// DAQ's Nyquist frequency).
    pub anti_alias_cutoff: f64,
    /// Sensor noise per channel kind.
    pub noise_rms: ChannelNoise,
    /// Seed of the (deterministic) noise generator. Default 1.
    pub noise_seed: u64,
    /// Names of the platform accelerometers, one channel each (at least one, unique, none of
    /// the other channels' names). Default ["platform_1", "platform_2", "platform_3"].
    pub platform_accelerometers: Vec<String>,
    /// The contact-resistance circuit.
    pub contact_circuit: ContactCircuitSpec,
}

impl Default for DaqSpec {
    fn default() -> Self {
        DaqSpec {
            sample_rate: 10240.0,
            block_size: 256,
            adc_bits: 24,
            full_scale: ChannelRanges::default(),
            anti_alias_cutoff: 0.25,
            noise_rms: ChannelNoise::default(),
            noise_seed: 1,
            platform_accelerometers: vec![
                "platform_1".into(),
                "platform_2".into(),
                "platform_3".into(),
            ],
            contact_circuit: ContactCircuitSpec::default(),
        }
    }
}

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
}

fn check(key: &str, value: f64, ok: bool, expected: &str) -> Result<(), SimRigError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(SimRigError::Spec(format!(
            "{key} = {value}: expected {expected}"
        )))
    }
}

fn positive(key: &str, value: f64) -> Result<(), SimRigError> {
    check(key, value, value > 0.0, "> 0")
}

fn non_negative(key: &str, value: f64) -> Result<(), SimRigError> {
    check(key, value, value >= 0.0, ">= 0")
}

impl SimRigSpec {
    /// Checks every field against the range in its documentation. The ROM-dependent checks
    /// (moving mass against the beams' modal mass, the truth step against the stability
    /// limit) are done by [`super::SimRig::new`].
    pub fn validate(&self) -> Result<(), SimRigError> {
        let s = &self.shaker;
        positive("shaker.moving_mass", s.moving_mass)?;
        non_negative("shaker.suspension_stiffness", s.suspension_stiffness)?;
        non_negative(
            "shaker.suspension_damping_ratio",
            s.suspension_damping_ratio,
        )?;
        positive("shaker.coil_resistance", s.coil_resistance)?;
        positive("shaker.coil_inductance", s.coil_inductance)?;
        positive("shaker.force_constant", s.force_constant)?;
        positive("shaker.amplifier_gain", s.amplifier_gain)?;
        positive("shaker.amplifier_limit_v", s.amplifier_limit_v)?;

        let d = &self.daq;
        positive("daq.sample_rate", d.sample_rate)?;
        if d.block_size == 0 {
            return Err(SimRigError::Spec(
                "daq.block_size = 0: expected >= 1".into(),
            ));
        }
        if !(2..=32).contains(&d.adc_bits) {
            return Err(SimRigError::Spec(format!(
                "daq.adc_bits = {}: expected 2..=32",
                d.adc_bits
            )));
        }
        let r = &d.full_scale;
        positive(
            "daq.full_scale.platform_acceleration",
            r.platform_acceleration,
        )?;
        positive("daq.full_scale.beam_acceleration", r.beam_acceleration)?;
        positive("daq.full_scale.vibrometer", r.vibrometer)?;
        positive("daq.full_scale.contact_voltage", r.contact_voltage)?;
        positive("daq.full_scale.drive_voltage", r.drive_voltage)?;
        positive("daq.full_scale.drive_current", r.drive_current)?;
        check(
            "daq.anti_alias_cutoff",
            d.anti_alias_cutoff,
            d.anti_alias_cutoff > 0.0 && d.anti_alias_cutoff < 0.5,
            "a fraction of the sample rate in (0, 0.5)",
        )?;
        let n = &d.noise_rms;
        non_negative(
            "daq.noise_rms.platform_acceleration",
            n.platform_acceleration,
        )?;
        non_negative("daq.noise_rms.beam_acceleration", n.beam_acceleration)?;
        non_negative("daq.noise_rms.vibrometer", n.vibrometer)?;
        non_negative("daq.noise_rms.contact_voltage", n.contact_voltage)?;
        non_negative("daq.noise_rms.drive_voltage", n.drive_voltage)?;
        non_negative("daq.noise_rms.drive_current", n.drive_current)?;
        if d.platform_accelerometers.is_empty() {
            return Err(SimRigError::Spec(
                "daq.platform_accelerometers = []: expected at least one name".into(),
            ));
        }
        for (i, name) in d.platform_accelerometers.iter().enumerate() {
            let clash = name.is_empty()
                || d.platform_accelerometers[..i].contains(name)
                || super::daq::FIXED_CHANNELS.iter().any(|(n, _)| n == name);
            if clash {
                return Err(SimRigError::Spec(format!(
                    "daq.platform_accelerometers[{i}] = {name:?}: expected a non-empty name \
                     used by no other channel"
                )));
            }
        }
        let c = &d.contact_circuit;
        check(
            "daq.contact_circuit.open_voltage",
            c.open_voltage,
            true,
            "a finite voltage",
        )?;
        check(
            "daq.contact_circuit.closed_voltage",
            c.closed_voltage,
            c.closed_voltage < c.open_voltage,
            "a finite voltage below daq.contact_circuit.open_voltage",
        )?;
        positive("daq.contact_circuit.time_constant", c.time_constant)?;

        let t = &self.truth;
        positive("truth.cutoff_ratio", t.cutoff_ratio)?;
        if t.oversampling == Some(0) {
            return Err(SimRigError::Spec(
                "truth.oversampling = 0: expected >= 1 truth steps per DAQ sample".into(),
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
        t.variants.validate(d)?;
        Ok(())
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
