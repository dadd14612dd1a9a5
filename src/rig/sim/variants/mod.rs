//! Truth variants: physics of the simulated rig that the twin does not know (TOML table
//! `[truth.variants]`), each off by default and switched on by its table or list:
//!
//! - `[truth.variants.clamp_friction]`: friction in the clamping joint, an Iwan element on the
//!   first bending mode of each beam ([`iwan`]): amplitude-dependent softening and damping.
//! - `[truth.variants.wear]`: the clearance grows with the contact's dissipated work
//!   (Archard-like, [`wear`]).
//! - `[truth.variants.tilt]`: the protrusion's contact face is tilted about an axis in the
//!   contact plane, giving every pair its own initial gap ([`tilt`]).
//! - `truth.variants.sensor_gains`: per-channel sensitivity errors applied before the ADC
//!   while the DAQ layout keeps the nominal sensitivity ([`sensor_gain`]).
//!
//! The variants live in the truth only: the rig description's hash (the ROM identity) does not
//! include them, like the rest of `[truth]`. [`TruthVariants::validate`] names the key of a
//! bad value.

pub mod iwan;
pub mod sensor_gain;
pub mod tilt;
pub mod wear;

use serde::{Deserialize, Serialize};

use super::daq::FIXED_CHANNELS;
use super::spec::DaqSpec;
use super::SimRigError;

/// `[truth.variants]`: hidden physics of the simulated rig. Everything off by default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthVariants {
    /// Friction in the clamping joint (`[truth.variants.clamp_friction]`). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clamp_friction: Option<ClampFrictionSpec>,
    /// Clearance growth from wear (`[truth.variants.wear]`). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear: Option<WearSpec>,
    /// Tilted protrusion (`[truth.variants.tilt]`). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tilt: Option<TiltSpec>,
    /// Sensor sensitivity errors, at most one per channel
    /// (`sensor_gains = [{ channel = "upper_tip", gain = 1.03 }]`). Default: none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensor_gains: Vec<SensorGainSpec>,
}

/// A beam of the rig.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Beam {
    /// The lower beam (its first bending mode is labelled 1FL, its tip output `lower_tip`).
    Lower,
    /// The upper beam (1FU, `upper_tip`).
    Upper,
}

impl Beam {
    /// Label of the beam's first flap-wise bending mode in the ROM.
    pub fn first_bending_label(self) -> &'static str {
        match self {
            Beam::Lower => "1FL",
            Beam::Upper => "1FU",
        }
    }

    /// Name of the ROM output at the beam's tip.
    pub fn tip_output(self) -> &'static str {
        match self {
            Beam::Lower => "lower_tip",
            Beam::Upper => "upper_tip",
        }
    }
}

/// `[truth.variants.clamp_friction]`: microslip in the bolted clamping joint, as an Iwan
/// element (N Jenkins elements in parallel: spring `k_J / N` in series with a Coulomb slider,
/// slip forces uniformly distributed from 0 to a maximum) acting on the modal coordinate of
/// each listed beam's first bending mode. The linear truth ROM holds the stuck joint; the
/// element adds what the slipped sliders take away, so below the first slip nothing changes,
/// and with growing amplitude the mode softens (fully slipped: `f_1F sqrt(1 -
/// stiffness_fraction)`) and its damping rises (energy lost per cycle ~ amplitude^3 while
/// few sliders slip).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClampFrictionSpec {
    /// Share of the first bending mode's modal stiffness `omega_1F^2` carried through the
    /// joint's sliders, -, in [0, 1) (0: the element is inert). Required.
    pub stiffness_fraction: f64,
    /// Amplitude of the beam's tip displacement in its first bending mode (m, relative to the
    /// base) at which half of the sliders slip on first loading: slip starts at
    /// `half_slip_tip_amplitude / sliders` and all sliders slip beyond twice it. Required, > 0.
    pub half_slip_tip_amplitude: f64,
    /// Number of Jenkins elements, 1..=10000. Default 64.
    #[serde(default = "default_sliders")]
    pub sliders: usize,
    /// Beams whose clamp slips (`"lower"`, `"upper"`), each at most once, at least one.
    /// Default both.
    #[serde(default = "both_beams")]
    pub beams: Vec<Beam>,
}

/// `[truth.variants.wear]`: the clearance grows with the work the contact has dissipated
/// (impacts and friction), Archard-like: `clearance = nominal + min(coefficient * W,
/// max_growth)`, `W` the dissipated contact work since the rig started (J, see [`wear`]).
/// The nominal clearance is the one set at start or by a test (a plan's clearance); the
/// growth stays across tests.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WearSpec {
    /// Clearance growth per dissipated contact work, m/J (>= 0). Required.
    pub coefficient: f64,
    /// Largest clearance growth, m (> 0). Default: none (unbounded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_growth: Option<f64>,
}

/// `[truth.variants.tilt]`: the protrusion's contact face is rotated by `angle` about an axis
/// in the contact plane (x-y, the contact normal is z) through the patch's area centroid;
/// pair k's initial normal gap becomes `clearance + sin(angle) (a_x d_y - a_y d_x)`, `d` the
/// pair's in-plane offset from the centroid, `a` the unit axis (right-hand rule: with the
/// default axis +y and `angle > 0` the tip-side edge, larger x, moves down and closes first).
/// The mean gap stays the clearance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TiltSpec {
    /// Tilt angle, rad, |angle| <= 0.1 (a small misalignment: the node pairs stay paired).
    /// Required.
    pub angle: f64,
    /// Direction of the tilt axis in the contact plane, [x, y] (normalised on use; not zero).
    /// Default [0, 1] (about y: the gap varies along the beams).
    #[serde(default = "axis_y")]
    pub axis: [f64; 2],
}

/// One entry of `truth.variants.sensor_gains`: a mis-calibrated sensor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorGainSpec {
    /// DAQ channel name (a platform accelerometer, `lower_tip`, `lower_mid`, `upper_tip`,
    /// `upper_mid`, `vibrometer`, `contact_voltage`, `drive_voltage` or `drive_current`).
    /// Required.
    pub channel: String,
    /// True sensitivity over nominal, -, > 0: the channel records `gain` times the physical
    /// value (before anti-alias filter, noise and ADC). Required.
    pub gain: f64,
}

/// Largest accepted tilt, rad.
pub const MAX_TILT: f64 = 0.1;

/// Largest number of sliders per Iwan element.
pub const MAX_SLIDERS: usize = 10_000;

fn default_sliders() -> usize {
    64
}

fn both_beams() -> Vec<Beam> {
    vec![Beam::Lower, Beam::Upper]
}

fn axis_y() -> [f64; 2] {
    [0.0, 1.0]
}

fn bad(key: &str, value: impl std::fmt::Display, expected: &str) -> SimRigError {
    SimRigError::Spec(format!("{key} = {value}: expected {expected}"))
}

impl TruthVariants {
    /// Whether any variant is on.
    pub fn any(&self) -> bool {
        self.clamp_friction.is_some()
            || self.wear.is_some()
            || self.tilt.is_some()
            || !self.sensor_gains.is_empty()
    }

    /// The active variants as compact JSON (`{}` when none), for session metadata.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| String::from("{}"))
    }

    /// Checks every field against the range in its documentation; `daq` gives the channel
    /// names the sensor gains may use. Keys are named `truth.variants.<...>`.
    pub fn validate(&self, daq: &DaqSpec) -> Result<(), SimRigError> {
        const P: &str = "truth.variants";
        if let Some(c) = &self.clamp_friction {
            let key = |f: &str| format!("{P}.clamp_friction.{f}");
            let phi = c.stiffness_fraction;
            if !(phi.is_finite() && (0.0..1.0).contains(&phi)) {
                return Err(bad(
                    &key("stiffness_fraction"),
                    phi,
                    "a share of the modal stiffness in [0, 1)",
                ));
            }
            let u = c.half_slip_tip_amplitude;
            if !(u.is_finite() && u > 0.0) {
                return Err(bad(
                    &key("half_slip_tip_amplitude"),
                    u,
                    "a tip displacement amplitude > 0 (m)",
                ));
            }
            if !(1..=MAX_SLIDERS).contains(&c.sliders) {
                return Err(bad(
                    &key("sliders"),
                    c.sliders,
                    &format!("1 to {MAX_SLIDERS} Jenkins elements"),
                ));
            }
            if c.beams.is_empty() {
                return Err(bad(
                    &key("beams"),
                    "[]",
                    "at least one of \"lower\", \"upper\"",
                ));
            }
            for (i, b) in c.beams.iter().enumerate() {
                if c.beams[..i].contains(b) {
                    return Err(bad(
                        &format!("{}[{i}]", key("beams")),
                        format!("{b:?}").to_lowercase(),
                        "each beam listed once",
                    ));
                }
            }
        }
        if let Some(w) = &self.wear {
            let key = |f: &str| format!("{P}.wear.{f}");
            if !(w.coefficient.is_finite() && w.coefficient >= 0.0) {
                return Err(bad(
                    &key("coefficient"),
                    w.coefficient,
                    "a clearance growth per dissipated work >= 0 (m/J)",
                ));
            }
            if let Some(cap) = w.max_growth {
                if !(cap.is_finite() && cap > 0.0) {
                    return Err(bad(
                        &key("max_growth"),
                        cap,
                        "a largest clearance growth > 0 (m), or leave it out (unbounded)",
                    ));
                }
            }
        }
        if let Some(t) = &self.tilt {
            let key = |f: &str| format!("{P}.tilt.{f}");
            if !(t.angle.is_finite() && t.angle.abs() <= MAX_TILT) {
                return Err(bad(
                    &key("angle"),
                    t.angle,
                    &format!("a tilt angle with |angle| <= {MAX_TILT} rad"),
                ));
            }
            let norm = t.axis[0].hypot(t.axis[1]);
            if !(norm.is_finite() && norm > 0.0) {
                return Err(bad(
                    &key("axis"),
                    format!("{:?}", t.axis),
                    "a non-zero direction [x, y] in the contact plane",
                ));
            }
        }
        let names: Vec<&str> = daq
            .platform_accelerometers
            .iter()
            .map(String::as_str)
            .chain(FIXED_CHANNELS.iter().map(|(n, _)| *n))
            .collect();
        for (i, g) in self.sensor_gains.iter().enumerate() {
            let key = |f: &str| format!("{P}.sensor_gains[{i}].{f}");
            if !names.contains(&g.channel.as_str()) {
                return Err(bad(
                    &key("channel"),
                    format!("{:?}", g.channel),
                    &format!("a DAQ channel name (channels: {})", names.join(", ")),
                ));
            }
            if self.sensor_gains[..i]
                .iter()
                .any(|o| o.channel == g.channel)
            {
                return Err(bad(
                    &key("channel"),
                    format!("{:?}", g.channel),
                    "each channel listed once",
                ));
            }
            if !(g.gain.is_finite() && g.gain > 0.0) {
                return Err(bad(
                    &key("gain"),
                    g.gain,
                    "a sensitivity ratio (true / nominal) > 0",
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::sim::SimRigSpec;

    fn parse(text: &str) -> Result<SimRigSpec, String> {
        let spec: SimRigSpec = toml::from_str(text).map_err(|e| e.to_string())?;
        spec.validate().map_err(|e| e.to_string())?;
        Ok(spec)
    }

    #[test]
    fn off_by_default_and_parsed_with_defaults() {
        let spec = parse("").unwrap();
        assert!(!spec.truth.variants.any());
        assert_eq!(spec.truth.variants.to_json(), "{}");
        let spec = parse(
            "[truth.variants]\n\
             sensor_gains = [{ channel = \"upper_tip\", gain = 1.03 }]\n\
             [truth.variants.clamp_friction]\n\
             stiffness_fraction = 0.2\n\
             half_slip_tip_amplitude = 1e-4\n\
             [truth.variants.wear]\n\
             coefficient = 1e-6\n\
             [truth.variants.tilt]\n\
             angle = 1e-3\n",
        )
        .unwrap();
        let v = &spec.truth.variants;
        assert!(v.any());
        let c = v.clamp_friction.as_ref().unwrap();
        assert_eq!((c.sliders, c.beams.as_slice()), (64, &both_beams()[..]));
        assert_eq!(v.wear.as_ref().unwrap().max_growth, None);
        assert_eq!(v.tilt.as_ref().unwrap().axis, [0.0, 1.0]);
        assert_eq!(v.sensor_gains[0].gain, 1.03);
        // The other [truth] keys keep their defaults.
        assert_eq!(spec.truth.cutoff_ratio, 400.0);
        // Round trip through TOML and JSON.
        let back: SimRigSpec = toml::from_str(&toml::to_string(&spec).unwrap()).unwrap();
        assert_eq!(back, spec);
        let json = v.to_json();
        assert!(json.contains("\"clamp_friction\"") && json.contains("\"upper_tip\""));
        let back: TruthVariants = serde_json::from_str(&json).unwrap();
        assert_eq!(&back, v);
    }

    #[test]
    fn misspelled_keys_are_rejected_by_name() {
        for (text, key) in [
            ("[truth.variants]\nwaer = 1\n", "waer"),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = 1e-4\nslider = 3\n",
                "slider",
            ),
            ("[truth.variants.wear]\ncoeficient = 1e-6\n", "coeficient"),
            (
                "[truth.variants.tilt]\nangle = 0.0\naxes = [1.0, 0.0]\n",
                "axes",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"upper_tip\", gian = 1.0 }]\n",
                "gian",
            ),
        ] {
            let msg = parse(text).unwrap_err();
            assert!(msg.contains(&format!("unknown field `{key}`")), "{msg}");
        }
        let msg = parse(
            "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
             half_slip_tip_amplitude = 1e-4\nbeams = [\"middle\"]\n",
        )
        .unwrap_err();
        assert!(msg.contains("middle") && msg.contains("lower"), "{msg}");
        let msg = parse("[truth.variants.wear]\n").unwrap_err();
        assert!(msg.contains("missing field `coefficient`"), "{msg}");
    }

    #[test]
    fn bad_values_name_the_key() {
        let clamp = |body: &str| {
            format!(
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = 1e-4\n{body}"
            )
        };
        for (text, expect) in [
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = -0.1\n\
                 half_slip_tip_amplitude = 1e-4\n"
                    .to_string(),
                "truth.variants.clamp_friction.stiffness_fraction = -0.1: expected",
            ),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 1.0\n\
                 half_slip_tip_amplitude = 1e-4\n"
                    .to_string(),
                "truth.variants.clamp_friction.stiffness_fraction = 1: expected",
            ),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = nan\n"
                    .to_string(),
                "truth.variants.clamp_friction.half_slip_tip_amplitude = NaN: expected",
            ),
            (
                clamp("sliders = 0\n"),
                "truth.variants.clamp_friction.sliders = 0: expected 1 to 10000",
            ),
            (
                clamp("beams = []\n"),
                "truth.variants.clamp_friction.beams = []",
            ),
            (
                clamp("beams = [\"upper\", \"upper\"]\n"),
                "truth.variants.clamp_friction.beams[1] = upper: expected each beam listed once",
            ),
            (
                "[truth.variants.wear]\ncoefficient = -1e-6\n".to_string(),
                "truth.variants.wear.coefficient = -0.000001: expected",
            ),
            (
                "[truth.variants.wear]\ncoefficient = 1e-6\nmax_growth = 0.0\n".to_string(),
                "truth.variants.wear.max_growth = 0: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = 0.5\n".to_string(),
                "truth.variants.tilt.angle = 0.5: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = inf\n".to_string(),
                "truth.variants.tilt.angle = inf: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = 0.01\naxis = [0.0, 0.0]\n".to_string(),
                "truth.variants.tilt.axis = [0.0, 0.0]: expected",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"upper_tipp\", gain = 1.1 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].channel = \"upper_tipp\": expected a DAQ \
                 channel name (channels: platform_1, platform_2, platform_3, lower_tip",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"vibrometer\", gain = 1.1 }, \
                 { channel = \"vibrometer\", gain = 1.2 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[1].channel = \"vibrometer\": expected each channel",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"lower_mid\", gain = -1.0 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].gain = -1: expected",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"lower_mid\", gain = nan }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].gain = NaN: expected",
            ),
        ] {
            let msg = parse(&text).unwrap_err();
            assert!(msg.contains(expect), "{text}\n-> {msg}");
        }
        // A renamed platform accelerometer is a valid channel.
        parse(
            "[daq]\nplatform_accelerometers = [\"table\"]\n[truth.variants]\n\
             sensor_gains = [{ channel = \"table\", gain = 0.98 }]\n",
        )
        .unwrap();
    }
}
