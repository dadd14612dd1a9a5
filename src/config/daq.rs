//! The simulated rig's data acquisition (`[daq]`): rate, block size, ADC, anti-alias filter,
//! full-scale ranges, sensor noise, the platform accelerometers' names and the contact
//! circuit. Every field states its unit and default; [`DaqSpec::validate`] names the key of a
//! bad value. Not part of the model: not hashed. The DAQ model itself lives in
//! `rig::sim::daq`.

use serde::{Deserialize, Serialize};

use super::error::{check, non_negative, positive, SpecError};

/// Names of the DAQ channels after the platform accelerometers, in layout order (the beam
/// accelerometers, the vibrometer, the contact circuit, the drive voltage and current). The
/// simulated rig's channel layout gives each its kind.
pub const FIXED_CHANNEL_NAMES: [&str; 8] = [
    "lower_tip",
    "lower_mid",
    "upper_tip",
    "upper_mid",
    "vibrometer",
    "contact_voltage",
    "drive_voltage",
    "drive_current",
];

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

impl DaqSpec {
    /// Checks every field against the range in its documentation.
    pub fn validate(&self) -> Result<(), SpecError> {
        let d = self;
        positive("daq.sample_rate", d.sample_rate)?;
        if d.block_size == 0 {
            return Err(SpecError::new("daq.block_size", 0, ">= 1"));
        }
        if !(2..=32).contains(&d.adc_bits) {
            return Err(SpecError::new("daq.adc_bits", d.adc_bits, "2..=32"));
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
            return Err(SpecError::new(
                "daq.platform_accelerometers",
                "[]",
                "at least one name",
            ));
        }
        for (i, name) in d.platform_accelerometers.iter().enumerate() {
            let clash = name.is_empty()
                || d.platform_accelerometers[..i].contains(name)
                || FIXED_CHANNEL_NAMES.contains(&name.as_str());
            if clash {
                return Err(SpecError::new(
                    format!("daq.platform_accelerometers[{i}]"),
                    format!("{name:?}"),
                    "a non-empty name used by no other channel",
                ));
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
        positive("daq.contact_circuit.time_constant", c.time_constant)
    }

    /// Names of all channels in layout order: the platform accelerometers, then
    /// [`FIXED_CHANNEL_NAMES`].
    pub fn channel_names(&self) -> impl Iterator<Item = &str> {
        self.platform_accelerometers
            .iter()
            .map(String::as_str)
            .chain(FIXED_CHANNEL_NAMES.iter().copied())
    }
}
