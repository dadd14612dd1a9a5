//! The plain data the figures are drawn from. Everything is serde-serialisable, so the same
//! figures can be drawn from a simulation result, a recorded session or a JSON file, and
//! several sources (simulation, measurement, twin) can be overlaid in one figure.
//!
//! Normalisations follow the reference (section 4): velocities of the response are divided
//! by the excitation circular frequency Omega and a length (the base displacement amplitude
//! q_base for the frequency responses, the beam length l for time histories), which makes
//! them dimensionless displacement-like amplitudes.

use serde::{Deserialize, Serialize};

use crate::plan::Direction;
use crate::signal::StepMetrics;

/// Where a curve came from. Sources are drawn with different line styles so that overlays
/// stay readable: simulation solid, measurement markers on a thin line, twin dashed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// The virtual stepped sine on the ROM (`rigtwin simulate`).
    Simulation,
    /// Measured on the rig (real or simulated backend).
    Measurement,
    /// The live twin, driven by the measured base acceleration.
    Twin,
}

impl Source {
    /// `"simulation"`, `"measurement"` or `"twin"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Source::Simulation => "simulation",
            Source::Measurement => "measurement",
            Source::Twin => "twin",
        }
    }
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Which beam a quantity belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Beam {
    /// The upper beam (the one whose 1F mode, 1FU, is omega_2).
    Upper,
    /// The lower beam.
    Lower,
}

impl Beam {
    /// `"upper"` or `"lower"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Beam::Upper => "upper",
            Beam::Lower => "lower",
        }
    }
}

/// The frequency response of one stepped-sine test from one source: one value per
/// frequency step, in the order the steps were run. Vectors of one curve have the length of
/// `omega_ratio`; the per-period amplitude vectors may instead be empty (not computed).
/// Non-finite values (a diverged or missing step) are skipped when drawing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TestCurve {
    /// Test name (as in the plan); curves of the same test from different sources share a
    /// colour.
    pub name: String,
    /// Base displacement amplitude / l.
    pub level: f64,
    /// Stepping direction.
    pub direction: Direction,
    /// Where the curve came from.
    pub source: Source,
    /// Excitation frequency of each step, Omega / omega_2.
    pub omega_ratio: Vec<f64>,
    /// RMS of the upper tip velocity over the record window, divided by Omega q_base (-).
    pub rms_upper: Vec<f64>,
    /// RMS of the lower tip velocity, divided by Omega q_base (-).
    pub rms_lower: Vec<f64>,
    /// Smallest per-period zero-to-peak amplitude of the upper tip velocity in the record
    /// window, divided by Omega q_base (-).
    #[serde(default)]
    pub amp_min_upper: Vec<f64>,
    /// Mean per-period amplitude of the upper tip velocity / (Omega q_base) (-).
    #[serde(default)]
    pub amp_mean_upper: Vec<f64>,
    /// Largest per-period amplitude of the upper tip velocity / (Omega q_base) (-).
    #[serde(default)]
    pub amp_max_upper: Vec<f64>,
    /// Smallest per-period amplitude of the lower tip velocity / (Omega q_base) (-).
    #[serde(default)]
    pub amp_min_lower: Vec<f64>,
    /// Mean per-period amplitude of the lower tip velocity / (Omega q_base) (-).
    #[serde(default)]
    pub amp_mean_lower: Vec<f64>,
    /// Largest per-period amplitude of the lower tip velocity / (Omega q_base) (-).
    #[serde(default)]
    pub amp_max_lower: Vec<f64>,
}

impl TestCurve {
    /// The curve of a test from `(Omega / omega_2, metrics)` per step, in step order.
    pub fn from_steps(
        name: &str,
        level: f64,
        direction: Direction,
        source: Source,
        steps: &[(f64, &StepMetrics)],
    ) -> TestCurve {
        let col =
            |f: fn(&StepMetrics) -> f64| -> Vec<f64> { steps.iter().map(|(_, m)| f(m)).collect() };
        TestCurve {
            name: name.to_owned(),
            level,
            direction,
            source,
            omega_ratio: steps.iter().map(|(w, _)| *w).collect(),
            rms_upper: col(|m| m.rms_upper),
            rms_lower: col(|m| m.rms_lower),
            amp_min_upper: col(|m| m.amp_min_upper),
            amp_mean_upper: col(|m| m.amp_mean_upper),
            amp_max_upper: col(|m| m.amp_max_upper),
            amp_min_lower: col(|m| m.amp_min_lower),
            amp_mean_lower: col(|m| m.amp_mean_lower),
            amp_max_lower: col(|m| m.amp_max_lower),
        }
    }

    /// The RMS vector of a beam.
    pub fn rms(&self, beam: Beam) -> &[f64] {
        match beam {
            Beam::Upper => &self.rms_upper,
            Beam::Lower => &self.rms_lower,
        }
    }

    /// The (min, mean, max) per-period amplitude vectors of a beam.
    pub fn amplitudes(&self, beam: Beam) -> (&[f64], &[f64], &[f64]) {
        match beam {
            Beam::Upper => (
                &self.amp_min_upper,
                &self.amp_mean_upper,
                &self.amp_max_upper,
            ),
            Beam::Lower => (
                &self.amp_min_lower,
                &self.amp_mean_lower,
                &self.amp_max_lower,
            ),
        }
    }
}

/// Frequency responses of several tests and sources, drawn together.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrequencyResponse {
    /// One curve per (test, source).
    pub tests: Vec<TestCurve>,
}

/// A time history at one excitation frequency from one source. `upper` and `lower` have the
/// length of `t`; the contact and force vectors have it too, or are empty (not available,
/// e.g. forces of a measurement). Non-finite samples are skipped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimeHistory {
    /// Label (e.g. the test name).
    pub name: String,
    /// Where it came from.
    pub source: Source,
    /// Excitation frequency, Omega / omega_2.
    pub omega_ratio: f64,
    /// Time, s.
    pub t: Vec<f64>,
    /// Upper tip velocity divided by Omega l (-).
    pub upper: Vec<f64>,
    /// Lower tip velocity divided by Omega l (-); may be empty.
    #[serde(default)]
    pub lower: Vec<f64>,
    /// Contact closed at the sample (any node pair closed; measured: contact resistance
    /// below threshold); may be empty.
    #[serde(default)]
    pub contact_closed: Vec<bool>,
    /// Normal contact force integrated over the interface, N (compression positive); may be
    /// empty.
    #[serde(default)]
    pub normal_force: Vec<f64>,
    /// Magnitude of the tangential contact force integrated over the interface, N; may be
    /// empty.
    #[serde(default)]
    pub tangential_force: Vec<f64>,
}

/// What a convergence study varies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConvergenceKind {
    /// Time steps per excitation period.
    Dt,
    /// Number of free-interface normal modes kept in the MacNeal basis.
    Modes,
}

impl ConvergenceKind {
    /// Axis label of the varied quantity.
    pub fn axis_label(self) -> &'static str {
        match self {
            ConvergenceKind::Dt => "time steps per excitation period",
            ConvergenceKind::Modes => "normal modes retained",
        }
    }
}

/// A signal of a convergence study (typically the upper tip velocity over the first periods).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceSignal {
    /// The varied quantity of this run (steps per period or number of modes).
    pub x: f64,
    /// Time, s.
    pub t: Vec<f64>,
    /// Upper tip velocity divided by Omega l (-), same length as `t`.
    pub u: Vec<f64>,
}

/// A convergence study: the relative RMS error (reference section 4.3) of runs with a
/// varied time step or number of modes against a reference run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Convergence {
    /// What was varied.
    pub kind: ConvergenceKind,
    /// The varied quantity of each run.
    pub x: Vec<f64>,
    /// Relative RMS error of each run against the reference (-), same length as `x`. Zero
    /// (the reference itself) and non-finite values are not drawn on the log axes.
    pub error: Vec<f64>,
    /// The varied quantity of the reference run, if known (named in the legend).
    #[serde(default)]
    pub reference: Option<f64>,
    /// Time signals to overlay in a second panel; may be empty.
    #[serde(default)]
    pub signals: Vec<ConvergenceSignal>,
}
