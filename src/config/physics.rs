//! The physics the nominal ROM leaves out, as parameters ([`PhysicsSpec`]): one schema for
//! the simulated rig's hidden truth (`[truth.variants]`) and the model's declared extensions
//! (`[model]`), so both use the same key names and ranges. Each effect is off by default and
//! switched on by its table or list:
//!
//! - `modes = [{ mode = "1FU", frequency_hz = ..., damping_ratio = ... }]`: linear modal
//!   corrections (reference section 3.2's updating, without rebuilding the ROM).
//! - `clamp_friction`: friction in the clamping joint, an Iwan element on the first bending
//!   mode of each listed beam: amplitude-dependent softening and damping.
//! - `clearance`: the clearance per test (the plan's value plus an offset, or an absolute value
//!   per test).
//! - `wear`: the clearance grows with the accumulated normal contact impulse, carried
//!   across the tests of a session.
//! - `tilt`: the protrusion's contact face is tilted about an axis in the contact plane,
//!   giving every pair its own initial gap.
//! - `sensor_gains`: per-channel sensitivity (true over nominal): in the truth applied before
//!   the ADC while the DAQ layout keeps the nominal sensitivity; in the model an observation on
//!   the predicted channels (and on the measured base acceleration the twin consumes).
//!
//! The physics of each lives in `physics`. Neither table is part of the ROM hash (changing
//! them never rebuilds a ROM). [`PhysicsSpec::validate`] names the key of a bad value under
//! the table's prefix (`truth.variants` or `model`); a mode label is checked against the ROM
//! when the model is built.

use serde::{Deserialize, Serialize};

use super::daq::DaqSpec;
use super::error::SpecError;

/// Physics the nominal ROM leaves out (`[truth.variants]` of the simulated rig, `[model]` of
/// the model). Everything off by default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicsSpec {
    /// Linear modal corrections, at most one entry per mode label
    /// (`modes = [{ mode = "1FU", frequency_hz = 101.2, damping_ratio = 0.0012 }]`). Default:
    /// none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<ModalCorrectionSpec>,
    /// Friction in the clamping joint (`clamp_friction` table). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clamp_friction: Option<ClampFrictionSpec>,
    /// Clearance per test (`clearance` table). Default: the plan's clearance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clearance: Option<ClearanceSpec>,
    /// Clearance growth from wear (`wear` table). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear: Option<WearSpec>,
    /// Tilted protrusion (`tilt` table). Default: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tilt: Option<TiltSpec>,
    /// Sensor sensitivities, at most one per channel
    /// (`sensor_gains = [{ channel = "upper_tip", gain = 1.03 }]`). Default: none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensor_gains: Vec<SensorGainSpec>,
}

/// The simulated rig's hidden physics (`[truth.variants]`).
pub type TruthVariants = PhysicsSpec;

/// The model's declared extensions (`[model]`).
pub type ModelExtensions = PhysicsSpec;

/// One entry of `modes`: a corrected natural frequency and/or damping ratio of a ROM mode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalCorrectionSpec {
    /// Mode label of the ROM (`1FL`, `1FU`, `1EU`, `2FL`, ...; `rigtwin rom info` lists them).
    /// Required.
    pub mode: String,
    /// Natural frequency, Hz, > 0 and within [`MODAL_FREQUENCY_RANGE`] times the ROM's.
    /// Default: the ROM's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frequency_hz: Option<f64>,
    /// Modal damping ratio, -, in [0, 1). Default: the ROM's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
}

/// The corrected natural frequency of a mode must lie within this factor range of the ROM's
/// (a correction, not another mode: beyond it the mode would cross its neighbours and the
/// residual flexibility would no longer describe what is left out).
pub const MODAL_FREQUENCY_RANGE: (f64, f64) = (0.5, 2.0);

/// `clearance`: the clearance of each test. A test listed in `tests` gets that clearance; any
/// other test gets the plan's clearance plus `offset`. Wear (if on) grows on top.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClearanceSpec {
    /// Added to the plan's clearance of every test not listed in `tests`, m,
    /// |offset| <= [`MAX_CLEARANCE`]. Default 0.
    pub offset: f64,
    /// Absolute clearance per test, by the plan's test name, each test at most once. Default:
    /// none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tests: Vec<TestClearanceSpec>,
}

impl ClearanceSpec {
    /// The clearance of test `test` whose plan clearance is `plan_m` (m): its entry of
    /// `tests`, else the plan's plus `offset` (the plan's itself, bit for bit, with no offset).
    pub fn of_test(&self, test: &str, plan_m: f64) -> f64 {
        match self.tests.iter().find(|t| t.test == test) {
            Some(t) => t.clearance,
            None if self.offset == 0.0 => plan_m,
            None => plan_m + self.offset,
        }
    }
}

/// The clearance of test `test` whose plan clearance is `plan_m` (m) under the clearance
/// table `spec` ([`ClearanceSpec::of_test`]; the plan's without one).
pub fn test_clearance(spec: Option<&ClearanceSpec>, test: &str, plan_m: f64) -> f64 {
    spec.map_or(plan_m, |c| c.of_test(test, plan_m))
}

/// One entry of `clearance.tests`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestClearanceSpec {
    /// The plan's test name. Required.
    pub test: String,
    /// Clearance of that test, m, |clearance| <= [`MAX_CLEARANCE`] (negative: the probes
    /// overlap, a pre-load). Required.
    pub clearance: f64,
}

/// Largest clearance (or offset) magnitude accepted, m: far beyond any gap of the rig, it
/// only catches unit mistakes (a clearance in mm or in units of l).
pub const MAX_CLEARANCE: f64 = 0.01;

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

/// `[truth.variants.wear]`: the clearance grows with the normal contact impulse the beams have
/// exchanged: `clearance = nominal + min(coefficient * P, max_growth)`, `P` the accumulated
/// normal contact impulse since the rig started (N s: the time integral of the total normal
/// contact force, see `physics::wear`; it converges with the integrator's step, where the
/// dissipated contact work of the first version did not). The nominal clearance is the one set
/// at start or by a test (a plan's clearance); the growth stays across tests.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WearSpec {
    /// Clearance growth per accumulated normal contact impulse, m/(N s) (>= 0). Required.
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

impl PhysicsSpec {
    /// Whether any effect is on.
    pub fn any(&self) -> bool {
        !self.modes.is_empty()
            || self.clamp_friction.is_some()
            || self.clearance.is_some()
            || self.wear.is_some()
            || self.tilt.is_some()
            || !self.sensor_gains.is_empty()
    }

    /// The names of the effects that are on, in the order of the fields (`modes`,
    /// `clamp_friction`, `clearance`, `wear`, `tilt`, `sensor_gains`), for consoles and
    /// summaries.
    pub fn effects(&self) -> Vec<&'static str> {
        [
            ("modes", !self.modes.is_empty()),
            ("clamp_friction", self.clamp_friction.is_some()),
            ("clearance", self.clearance.is_some()),
            ("wear", self.wear.is_some()),
            ("tilt", self.tilt.is_some()),
            ("sensor_gains", !self.sensor_gains.is_empty()),
        ]
        .into_iter()
        .filter_map(|(name, on)| on.then_some(name))
        .collect()
    }

    /// The active effects as compact JSON (`{}` when none), for session metadata.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| String::from("{}"))
    }

    /// The clearance of test `test` whose plan clearance is `plan_m` (m), before wear: the
    /// test's entry of `clearance.tests`, else the plan's plus `clearance.offset`.
    pub fn test_clearance(&self, test: &str, plan_m: f64) -> f64 {
        test_clearance(self.clearance.as_ref(), test, plan_m)
    }

    /// These extensions with test `test`'s clearance set to `clearance_m` (m), replacing its
    /// entry of `clearance.tests` if it had one.
    pub fn with_test_clearance(&self, test: &str, clearance_m: f64) -> PhysicsSpec {
        let mut spec = self.clearance.clone().unwrap_or(ClearanceSpec {
            offset: 0.0,
            tests: Vec::new(),
        });
        spec.tests.retain(|x| x.test != test);
        spec.tests.push(TestClearanceSpec {
            test: test.to_string(),
            clearance: clearance_m,
        });
        PhysicsSpec {
            clearance: Some(spec),
            ..self.clone()
        }
    }

    /// These extensions without the contact's geometry (clearance, tilt): what a model's
    /// motion depends on while the contact stays open.
    pub fn without_contact_geometry(&self) -> PhysicsSpec {
        PhysicsSpec {
            clearance: None,
            tilt: None,
            ..self.clone()
        }
    }

    /// Checks every field against the range in its documentation; `daq` gives the channel
    /// names the sensor gains may use. Keys are named `<prefix>.<...>` (`prefix`:
    /// `truth.variants` or `model`). Mode labels are checked against the ROM when the model
    /// is built.
    pub fn validate(&self, prefix: &str, daq: &DaqSpec) -> Result<(), SpecError> {
        let p = prefix;
        for (i, m) in self.modes.iter().enumerate() {
            let key = |f: &str| format!("{p}.modes[{i}].{f}");
            if m.mode.trim().is_empty() {
                return Err(bad(
                    &key("mode"),
                    "\"\"",
                    "a ROM mode label such as \"1FU\"",
                ));
            }
            if self.modes[..i].iter().any(|o| o.mode == m.mode) {
                return Err(bad(
                    &key("mode"),
                    format!("{:?}", m.mode),
                    "each mode listed once",
                ));
            }
            if m.frequency_hz.is_none() && m.damping_ratio.is_none() {
                return Err(bad(
                    &key("frequency_hz"),
                    "(missing)",
                    "a natural frequency (Hz) and/or a damping_ratio for the mode",
                ));
            }
            if let Some(f) = m.frequency_hz {
                if !(f.is_finite() && f > 0.0) {
                    return Err(bad(&key("frequency_hz"), f, "a natural frequency > 0 (Hz)"));
                }
            }
            if let Some(z) = m.damping_ratio {
                if !(z.is_finite() && (0.0..1.0).contains(&z)) {
                    return Err(bad(&key("damping_ratio"), z, "a damping ratio in [0, 1)"));
                }
            }
        }
        if let Some(c) = &self.clearance {
            let key = |f: &str| format!("{p}.clearance.{f}");
            if !(c.offset.is_finite() && c.offset.abs() <= MAX_CLEARANCE) {
                return Err(bad(
                    &key("offset"),
                    c.offset,
                    &format!("a clearance offset in metres with |offset| <= {MAX_CLEARANCE}"),
                ));
            }
            for (i, t) in c.tests.iter().enumerate() {
                let key = |f: &str| format!("{p}.clearance.tests[{i}].{f}");
                if t.test.trim().is_empty() || c.tests[..i].iter().any(|o| o.test == t.test) {
                    return Err(bad(
                        &key("test"),
                        format!("{:?}", t.test),
                        "a test name of the plan, each test listed once",
                    ));
                }
                if !(t.clearance.is_finite() && t.clearance.abs() <= MAX_CLEARANCE) {
                    return Err(bad(
                        &key("clearance"),
                        t.clearance,
                        &format!("a clearance in metres with |clearance| <= {MAX_CLEARANCE}"),
                    ));
                }
            }
        }
        if let Some(c) = &self.clamp_friction {
            let key = |f: &str| format!("{p}.clamp_friction.{f}");
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
            let key = |f: &str| format!("{p}.wear.{f}");
            if !(w.coefficient.is_finite() && w.coefficient >= 0.0) {
                return Err(bad(
                    &key("coefficient"),
                    w.coefficient,
                    "a clearance growth per normal contact impulse >= 0 (m/(N s))",
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
            let key = |f: &str| format!("{p}.tilt.{f}");
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
            let key = |f: &str| format!("{p}.sensor_gains[{i}].{f}");
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
