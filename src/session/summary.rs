//! The summary of a session: its tests and their steps, each with the measured step summary
//! ([`crate::control::StepSummary`], computed from the record window's raw counts by the
//! procedure and by replay alike) and, with a twin, the twin's comparison over the same window
//! ([`crate::twin::TwinComparison`]). Reproducible from the log alone (`rigtwin replay`), so
//! nothing here depends on the wall clock.

use crate::control::{EventKind, SessionEvent, StepSummary};
use crate::twin::TwinComparison;

/// One step of a session summary: the measurement and the twin over its record window. Its
/// JSON is the measured summary's keys with the twin's comparison under `twin`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepResult {
    /// The measured step.
    #[serde(flatten)]
    pub measured: StepSummary,
    /// The twin over the same window (`rigtwin run --twin`, `rigtwin replay --twin`): its
    /// metrics and its errors against the measurement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin: Option<TwinComparison>,
}

/// One test of a session summary.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TestSummary {
    /// Test name.
    pub name: String,
    /// Base level / l.
    pub level: f64,
    /// "up" or "down".
    pub direction: String,
    /// Clearance / l of the plan.
    pub clearance: f64,
    /// Finished steps.
    pub steps: Vec<StepResult>,
}

/// The summary of a session: reproducible from the log alone (`rigtwin replay`), so nothing
/// here depends on the wall clock.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionSummary {
    /// Plan name.
    pub plan: String,
    /// Whether the session was aborted.
    pub aborted: bool,
    /// Why, as text.
    pub abort_reason: Option<String>,
    /// DAQ blocks received (including the ramp-down).
    pub blocks: u64,
    /// Rig time covered by the blocks, s.
    pub rig_seconds: f64,
    /// The tests that started, with their finished steps.
    pub tests: Vec<TestSummary>,
    /// The `[model]` extensions the twin ran with (`{}`: none), when a twin ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin_model: Option<crate::config::PhysicsSpec>,
}

impl SessionSummary {
    /// Adds an event's effect on the summary (shared with replay).
    pub fn apply_event(&mut self, event: &SessionEvent) {
        match &event.kind {
            EventKind::SessionStart { plan, .. } => self.plan = plan.clone(),
            EventKind::TestStart {
                test,
                level,
                direction,
                clearance,
            } => self.tests.push(TestSummary {
                name: test.clone(),
                level: *level,
                direction: direction.clone(),
                clearance: *clearance,
                steps: Vec::new(),
            }),
            EventKind::Abort { message, .. } => {
                self.aborted = true;
                self.abort_reason = Some(message.clone());
            }
            _ => {}
        }
    }

    /// Adds a finished step to its test (the last test of that name).
    pub fn push_step(&mut self, test: &str, measured: StepSummary) {
        if let Some(t) = self.tests.iter_mut().rev().find(|t| t.name == test) {
            t.steps.push(StepResult {
                measured,
                twin: None,
            });
        }
    }

    /// Every step, in record-window order (tests in order, steps in order).
    pub fn steps(&self) -> impl Iterator<Item = &StepResult> {
        self.tests.iter().flat_map(|t| t.steps.iter())
    }

    /// Sets the twin's comparison of every step, in record-window order; returns how many
    /// steps have one.
    pub fn attach_twin(
        &mut self,
        comparisons: impl IntoIterator<Item = Option<TwinComparison>>,
    ) -> usize {
        let slots = self.tests.iter_mut().flat_map(|t| t.steps.iter_mut());
        let mut n = 0;
        for (slot, c) in slots.zip(comparisons) {
            n += usize::from(c.is_some());
            slot.twin = c;
        }
        n
    }
}
