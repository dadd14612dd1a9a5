//! Truth variants: physics of the simulated rig that the twin does not know (TOML table
//! `[truth.variants]`), each off by default and switched on by its table or list:
//!
//! - `[truth.variants.clamp_friction]`: friction in the clamping joint, an Iwan element on the
//!   first bending mode of each beam: amplitude-dependent softening and damping.
//! - `[truth.variants.wear]`: the clearance grows with the contact's dissipated work
//!   (Archard-like).
//! - `[truth.variants.tilt]`: the protrusion's contact face is tilted about an axis in the
//!   contact plane, giving every pair its own initial gap.
//! - `truth.variants.sensor_gains`: per-channel sensitivity errors applied before the ADC
//!   while the DAQ layout keeps the nominal sensitivity.
//!
//! The physics of each lives in `rig::sim::variants`. The variants live in the truth only:
//! the rig description's hash (the ROM identity) does not include them, like the rest of
//! `[truth]`. [`TruthVariants::validate`] names the key of a bad value.

use serde::{Deserialize, Serialize};

use super::daq::DaqSpec;
use super::error::SpecError;

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
/// max_growth)`, `W` the dissipated contact work since the rig started (J, see `rig::sim::variants::wear`).
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

fn bad(key: &str, value: impl std::fmt::Display, expected: &str) -> SpecError {
    SpecError::new(key, value, expected)
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
    pub fn validate(&self, daq: &DaqSpec) -> Result<(), SpecError> {
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
        let names: Vec<&str> = daq.channel_names().collect();
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
