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

/// What a replayed session log lacks (issue 17, case 7): a log cut off by a crash (SIGKILL,
/// power, a full disk) or damaged after writing. Losses are given in rig time and steps; the
/// bytes are in `file`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Missing {
    /// What is missing, in words.
    pub description: String,
    /// Whether the session logged its end (`session_end`): false for a session cut off while
    /// it ran.
    pub session_end: bool,
    /// Rig time where the recording ends (the end of the last DAQ block kept), s.
    pub recorded_until_s: f64,
    /// DAQ blocks lost inside the recording (damaged chunks), -.
    pub lost_blocks: u64,
    /// Rig time lost inside the recording (damaged chunks), s.
    pub lost_seconds: f64,
    /// Steps the plan holds (when the log holds the plan), -.
    pub steps_planned: Option<usize>,
    /// Steps finished in the recording (with a summary), -.
    pub steps_finished: usize,
    /// Steps whose record window was (partly) lost in damaged chunks: `TEST step K`.
    pub steps_lost: Vec<String>,
    /// What the reader says about the file: how it ends (bytes lost) and damage it skipped.
    pub file: Vec<String>,
}

/// The summary of a session: reproducible from the log alone (`rigtwin replay`), so nothing
/// here depends on the wall clock.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SessionSummary {
    /// Plan name.
    pub plan: String,
    /// Whether the summary covers the whole session: false for a replayed log that was cut
    /// off or damaged (then `missing` says what is missing). Written only when false.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub complete: bool,
    /// What a replayed log lacks (with `complete` false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing: Option<Missing>,
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

fn yes() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

impl Default for SessionSummary {
    fn default() -> Self {
        SessionSummary {
            plan: String::new(),
            complete: true,
            missing: None,
            aborted: false,
            abort_reason: None,
            blocks: 0,
            rig_seconds: 0.0,
            tests: Vec::new(),
            twin_model: None,
        }
    }
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
