//! Stepped-sine test plans (`rig-config/plans/*.toml`): which tests to run, at which base
//! displacement level and clearance, over which excitation frequencies, with how many settle
//! and record periods per frequency step. The same plan drives the virtual stepped sine
//! (`rigtwin simulate`) and the rig service.
//!
//! A plan is TOML: optional top-level `name` and `description`, an optional `[defaults]`
//! table giving any per-test key except `name`, and one `[[test]]` table per test:
//!
//! ```toml
//! name = "demo"
//! [defaults]
//! level = 6.0e-5            # base displacement amplitude / l
//! clearance = 2.78e-3       # / l
//! steps = 13
//! settle_periods = 30
//! record_periods = 20
//! [[test]]
//! name = "high-down"
//! direction = "down"
//! omega_start = 1.06        # Omega / omega_2
//! omega_end = 0.94
//! ```
//!
//! Parsing is serde with `deny_unknown_fields` (`raw.rs`); validation (`validate.rs`) checks
//! every value and reports the file, the test (number and name) or `[defaults]`, the key and
//! what was expected ([`PlanError`]).

pub mod error;
mod raw;
mod validate;

use std::path::Path;

use serde::{Deserialize, Serialize};

pub use error::{PlanError, PlanLocation};

/// Default number of time steps per excitation period of the simulation (the reference's
/// choice, section 4.1).
pub const DEFAULT_STEPS_PER_PERIOD: u32 = 1000;

/// Ramp time of the drive that starts a test, s: the rig's procedure (`src/control`) commands
/// each test's first drive level as a linear ramp over this time (from rest for the first test,
/// from the previous test's level after that), and the virtual stepped sine (`src/sim`) ramps
/// the base acceleration amplitude of each test in from zero over the same time. Steps within a
/// test change frequency without a ramp.
pub const TEST_START_RAMP_S: f64 = 0.25;

/// Direction of the frequency stepping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Increasing frequency (forward stepping): `omega_start < omega_end`.
    Up,
    /// Decreasing frequency (backward stepping): `omega_start > omega_end`.
    Down,
}

impl Direction {
    /// `"up"` or `"down"`, as written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Up => "up",
            Direction::Down => "down",
        }
    }
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One stepped-sine test: a sequence of frequency steps at a constant base displacement
/// level. Each step settles for `settle_periods` excitation periods, then records for
/// `record_periods`; the next step starts from the state the previous one ended in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TestSpec {
    /// Unique name within the plan.
    pub name: String,
    /// Fundamental harmonic amplitude of the base displacement, divided by the beam length l
    /// (e.g. 6e-5: 18 um for l = 300 mm). In (0, 1e-2].
    pub level: f64,
    /// Stepping direction; consistent with `omega_start`/`omega_end`.
    pub direction: Direction,
    /// Clearance between the probes before the test, divided by l (the model's clearance; on
    /// the rig, the estimated one). In [-1e-4, 0.1]: 0 means the probes touch at rest (held
    /// contact), a negative value a pre-load, the faces overlapping by |clearance| from the
    /// start (bounded; see `validate::CLEARANCE_PRELOAD_MAX` for what the model does with it).
    pub clearance: f64,
    /// First excitation frequency, Omega / omega_2 (omega_2: the ROM's 1FU circular frequency).
    /// In (0, 10).
    pub omega_start: f64,
    /// Last excitation frequency, Omega / omega_2. In (0, 10).
    pub omega_end: f64,
    /// Number of frequency steps, both ends included (>= 1; 1 means a single dwell at
    /// `omega_start`, which must then equal `omega_end`).
    pub steps: u32,
    /// Excitation periods waited at each step before recording (>= 1).
    pub settle_periods: u32,
    /// Excitation periods recorded at each step (>= 1).
    pub record_periods: u32,
    /// Time steps per excitation period of the simulation (>= 1; default
    /// [`DEFAULT_STEPS_PER_PERIOD`]). Ignored by the rig, whose DAQ rate is fixed.
    pub steps_per_period: u32,
}

/// Checks a clearance / l against the bounds every plan obeys (`[-CLEARANCE_PRELOAD_MAX,
/// 0.1]`: 0 the probes touching, negative a bounded pre-load); `Err` says what is expected.
/// Also the rule for a clearance given elsewhere (an injected `clearance_change`,
/// `firmware-sim --clearance`).
pub fn check_clearance(value_over_l: f64) -> Result<(), String> {
    validate::check_clearance(value_over_l)
}

/// A length given in units of the beam length l (plan levels and clearances), in metres.
///
/// The one place where plan units become SI: plans, session events and summaries carry
/// clearances and levels divided by l; the rig description, the ROM and the simulated rig
/// work in metres.
pub fn per_l_to_metres(value_over_l: f64, beam_length_m: f64) -> f64 {
    value_over_l * beam_length_m
}

impl TestSpec {
    /// The test's clearance in metres, for a rig of beam length `beam_length_m`.
    pub fn clearance_m(&self, beam_length_m: f64) -> f64 {
        per_l_to_metres(self.clearance, beam_length_m)
    }

    /// The step frequencies Omega / omega_2 in the order they are run: `steps` values evenly
    /// spaced from `omega_start` to `omega_end`, both included exactly.
    pub fn omega_ratios(&self) -> Vec<f64> {
        let n = self.steps.max(1) as usize;
        if n == 1 {
            return vec![self.omega_start];
        }
        let span = self.omega_end - self.omega_start;
        let mut w: Vec<f64> = (0..n)
            .map(|i| self.omega_start + span * (i as f64 / (n - 1) as f64))
            .collect();
        // NOTE: pin the last step so that a plan's end frequency is hit bit-for-bit.
        w[n - 1] = self.omega_end;
        w
    }

    /// Excitation periods per frequency step (settle + record).
    pub fn periods_per_step(&self) -> u64 {
        u64::from(self.settle_periods) + u64::from(self.record_periods)
    }

    /// Excitation periods of the whole test.
    pub fn total_periods(&self) -> u64 {
        u64::from(self.steps) * self.periods_per_step()
    }
}

/// A parsed and validated test plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Where the plan came from (file name), for error messages.
    pub source: String,
    /// Optional plan name (top-level `name`).
    pub name: Option<String>,
    /// Optional free text (top-level `description`).
    pub description: Option<String>,
    /// The tests in the order they are run.
    pub tests: Vec<TestSpec>,
}

impl Plan {
    /// Reads, parses and validates a plan file.
    pub fn from_path(path: &Path) -> Result<Plan, PlanError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| PlanError::Io {
            file: file.as_str().into(),
            source,
        })?;
        Plan::from_str(&text, &file)
    }

    /// Parses and validates a plan; `source` names it in errors (usually the file name).
    #[allow(clippy::should_implement_trait)] // takes the source name too
    pub fn from_str(text: &str, source: &str) -> Result<Plan, PlanError> {
        let doc = raw::parse(text, source)?;
        let plan = validate::build(doc, source)?;
        Ok(plan)
    }

    /// Re-checks a plan built in code or deserialised from a recording.
    pub fn validate(&self) -> Result<(), PlanError> {
        validate::check_plan(self)
    }

    /// The test with this name.
    pub fn test(&self, name: &str) -> Option<&TestSpec> {
        self.tests.iter().find(|t| t.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(start: f64, end: f64, steps: u32) -> TestSpec {
        TestSpec {
            name: "t".into(),
            level: 6e-5,
            direction: if end >= start {
                Direction::Up
            } else {
                Direction::Down
            },
            clearance: 2.78e-3,
            omega_start: start,
            omega_end: end,
            steps,
            settle_periods: 1,
            record_periods: 1,
            steps_per_period: DEFAULT_STEPS_PER_PERIOD,
        }
    }

    #[test]
    fn omega_ratios_include_both_ends_in_order() {
        let w = spec(1.06, 0.94, 13).omega_ratios();
        assert_eq!(w.len(), 13);
        assert_eq!(w[0], 1.06);
        assert_eq!(w[12], 0.94);
        for pair in w.windows(2) {
            assert!((pair[0] - pair[1] - 0.01).abs() < 1e-12, "{pair:?}");
        }
    }

    #[test]
    fn single_step_is_a_dwell() {
        assert_eq!(spec(1.0, 1.0, 1).omega_ratios(), vec![1.0]);
    }

    #[test]
    fn period_counts() {
        let mut s = spec(0.94, 1.06, 41);
        s.settle_periods = 200;
        s.record_periods = 200;
        assert_eq!(s.periods_per_step(), 400);
        assert_eq!(s.total_periods(), 16_400);
    }
}
