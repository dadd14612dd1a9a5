//! The records a session logs besides the raw DAQ blocks: the control state after every block
//! and the session events (step boundaries, settling, record windows, aborts).

use super::safety::AbortReason;
use super::summary::StepInfo;

/// What the procedure is doing.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// A new frequency starts with the next block.
    Transition,
    /// Settling at the step's frequency.
    Settle,
    /// Recording the step's window.
    Record,
    /// The plan is complete.
    Done,
    /// The drive ramps down (end of session or abort).
    RampDown,
}

/// The control state after a block.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct ControlState {
    /// Rig time of the block's first sample, s.
    pub time: f64,
    /// Block sequence number.
    pub seq: u64,
    /// Test index in the plan.
    pub test: usize,
    /// Step index in the test.
    pub step: usize,
    /// Procedure phase.
    pub phase: Phase,
    /// Drive frequency, Hz.
    pub frequency_hz: f64,
    /// Target fundamental base-displacement amplitude, m.
    pub target_m: f64,
    /// Fundamental base-displacement amplitude over the control window, m (none before the
    /// first update of a step).
    pub measured_m: Option<f64>,
    /// Fundamental base-displacement amplitude of the last period, m.
    pub period_amplitude_m: Option<f64>,
    /// Relative control error (measured - target) / target.
    pub error: Option<f64>,
    /// Drive amplitude commanded, V.
    pub drive_v: f64,
}

/// A session event.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct SessionEvent {
    /// Rig time, s.
    pub time: f64,
    /// DAQ sample index at which it happened.
    pub sample: u64,
    /// What happened.
    #[serde(flatten)]
    pub kind: EventKind,
}

/// Kinds of session events.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum EventKind {
    /// The session started.
    SessionStart {
        /// Plan name.
        plan: String,
        /// Test names in order.
        tests: Vec<String>,
    },
    /// A test starts.
    TestStart {
        /// Test name.
        test: String,
        /// Base level / l.
        level: f64,
        /// "up" or "down".
        direction: String,
        /// Clearance / l of the plan.
        clearance: f64,
    },
    /// A step starts (its frequency applies from the next block).
    StepStart {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// Omega / omega_2.
        omega_ratio: f64,
        /// Drive frequency, Hz.
        frequency_hz: f64,
    },
    /// Settling ended; the record window starts at `sample`.
    RecordStart {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// Settle criteria met (false: timed out).
        settled: bool,
        /// Settle time, s.
        settle_seconds: f64,
    },
    /// The record window ended: everything replay needs to recompute the step.
    RecordEnd {
        /// The step.
        info: StepInfo,
    },
    /// A record window missed `[control] record_tolerance` and is recorded again from the
    /// next sample (the step's summary comes from a later window).
    RecordRejected {
        /// The rejected window.
        info: StepInfo,
        /// Relative error of its fundamental base-displacement amplitude, -.
        base_amp_error: f64,
    },
    /// A test ended.
    TestEnd {
        /// Test name.
        test: String,
    },
    /// The session aborts; the drive ramps down.
    Abort {
        /// Why.
        reason: AbortReason,
        /// The reason as text.
        message: String,
    },
    /// The session ended (after the ramp-down).
    SessionEnd {
        /// Whether it was aborted.
        aborted: bool,
    },
}
