//! The one table of a session's topics: every channel of the MCAP session log and of the live
//! view, with the message types that go on them. Log time = rig time (ns since the stream
//! started); message encoding JSON, schemas JSON Schema ([`crate::log`]).

use crate::control::{StepInfo, StepSummary};
use crate::rig::RigStatus;
use crate::twin::TwinComparison;

/// The DAQ layout (channels, scales, sample rate), logged once at the start
/// ([`crate::rig::DaqLayout`]).
pub const TOPIC_LAYOUT: &str = "/daq/layout";
/// Raw DAQ blocks, ADC counts ([`crate::rig::DaqBlock`]; log only, the live view decimates
/// them to [`TOPIC_LIVE_DAQ`]).
pub const TOPIC_DAQ: &str = "/daq/blocks";
/// Control state after every block ([`crate::control::ControlState`]).
pub const TOPIC_CONTROL: &str = "/control/state";
/// Session events: step boundaries, record windows, aborts ([`crate::control::SessionEvent`]).
pub const TOPIC_EVENTS: &str = "/session/events";
/// Rig status, about once a second of rig time ([`StatusMessage`]).
pub const TOPIC_STATUS: &str = "/rig/status";
/// Per-step summaries ([`StepMessage`]).
pub const TOPIC_STEPS: &str = "/session/steps";
/// The twin's predicted channels for every block it processed
/// ([`crate::twin::TwinSamples`]; log only, the live view decimates them to
/// [`TOPIC_LIVE_TWIN`]).
pub const TOPIC_TWIN_BLOCKS: &str = "/twin/blocks";
/// The twin's status: lag, queue, skipped blocks, speed ([`crate::twin::TwinStatus`]).
pub const TOPIC_TWIN_STATUS: &str = "/twin/status";
/// The twin's comparison of every step ([`TwinStepMessage`]).
pub const TOPIC_TWIN_STEPS: &str = "/twin/steps";
/// The twin's state at the start of every step, for warm starts ([`TwinStateMessage`]; log
/// only; `rigtwin replay --twin --steps`).
pub const TOPIC_TWIN_STATE: &str = "/twin/state";
/// Decimated DAQ points, one message per time point with every channel's min, max and mean in
/// physical units (live view only).
pub const TOPIC_LIVE_DAQ: &str = "/live/daq";
/// The twin's prediction decimated like [`TOPIC_LIVE_DAQ`], in the same bins (live view only).
pub const TOPIC_LIVE_TWIN: &str = "/live/twin";

/// Where a topic is published.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Published {
    /// In the MCAP session log only.
    Log,
    /// In the live view only.
    Live,
    /// In both, with the same schema.
    Both,
}

/// Every topic of a session: name, where it is published, and the name of its message type.
pub const TOPICS: [(&str, Published, &str); 12] = [
    (TOPIC_LAYOUT, Published::Both, "DaqLayout"),
    (TOPIC_DAQ, Published::Log, "DaqBlock"),
    (TOPIC_CONTROL, Published::Both, "ControlState"),
    (TOPIC_EVENTS, Published::Both, "SessionEvent"),
    (TOPIC_STATUS, Published::Both, "StatusMessage"),
    (TOPIC_STEPS, Published::Both, "StepMessage"),
    (TOPIC_TWIN_BLOCKS, Published::Log, "TwinSamples"),
    (TOPIC_TWIN_STATUS, Published::Both, "TwinStatus"),
    (TOPIC_TWIN_STEPS, Published::Both, "TwinStepMessage"),
    (TOPIC_TWIN_STATE, Published::Log, "TwinStateMessage"),
    (TOPIC_LIVE_DAQ, Published::Live, "LiveDaqPoint"),
    (TOPIC_LIVE_TWIN, Published::Live, "LiveTwinPoint"),
];

/// Name of the metadata record that describes the session (backend, plan, references).
pub const SESSION_METADATA: &str = "session";
/// Name of the metadata record that identifies the twin's ROM.
pub const ROM_METADATA: &str = "rom";
/// Name of the metadata record that says which model a re-run twin ran
/// (`rigtwin replay --twin --out`).
pub const TWIN_REPLAY_METADATA: &str = "twin_replay";
/// Name of the rig description attachment.
pub const RIG_ATTACHMENT: &str = "rig.toml";
/// Name of the plan attachment.
pub const PLAN_ATTACHMENT: &str = "plan.toml";

/// A finished step as logged on [`TOPIC_STEPS`]: what the summary was computed from, and the
/// summary.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StepMessage {
    /// The step.
    pub info: StepInfo,
    /// Its summary.
    pub summary: StepSummary,
}

/// Rig status as logged on [`TOPIC_STATUS`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StatusMessage {
    /// Rig time of the first sample of the block after which the status was read, s (the
    /// message's log time). The status's own `time` is that of the last delivered sample.
    pub block_time: f64,
    /// The status.
    #[serde(flatten)]
    pub status: RigStatus,
}

/// One step's comparison, as logged on [`TOPIC_TWIN_STEPS`] (log time: the end of the step's
/// record window, [`StepInfo::record_end_time`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct TwinStepMessage {
    /// Test name.
    pub test: String,
    /// Step index.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The comparison; `None` when the twin missed samples of the window (skipped blocks).
    pub twin: Option<TwinComparison>,
}

impl TwinStepMessage {
    /// The message of a step's comparison.
    pub fn of(info: &StepInfo, twin: Option<&TwinComparison>) -> TwinStepMessage {
        TwinStepMessage {
            test: info.test.clone(),
            step: info.step,
            omega_ratio: info.omega_ratio,
            twin: twin.cloned(),
        }
    }
}

/// The twin's state at the start of a step, as logged on [`TOPIC_TWIN_STATE`] (log time: the
/// first sample of the block the step starts with).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct TwinStateMessage {
    /// Test name.
    pub test: String,
    /// Step index.
    pub step: usize,
    /// The state (its `next_sample` is the step's first block).
    pub state: crate::twin::TwinState,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Flattening must not repeat a key: JSON with duplicate keys, and a schema whose
    /// `required` repeats a name, are invalid for the Foxglove app and JSON Schema validators.
    #[test]
    fn logged_messages_have_unique_keys_and_valid_required_lists() {
        let m = StatusMessage {
            block_time: 1.0,
            status: RigStatus::default(),
        };
        let json = serde_json::to_string(&m).unwrap();
        let value: serde_json::Map<String, serde_json::Value> =
            serde_json::from_str(&json).unwrap();
        assert_eq!(json.matches("\"time\"").count(), 1, "{json}");
        assert!(value.contains_key("block_time"));
        let schema = serde_json::to_value(schemars::schema_for!(StatusMessage)).unwrap();
        let required: Vec<&str> = schema["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        let unique: std::collections::BTreeSet<&str> = required.iter().copied().collect();
        assert_eq!(unique.len(), required.len(), "{required:?}");
    }

    #[test]
    fn every_topic_is_listed_once() {
        let names: std::collections::BTreeSet<&str> = TOPICS.iter().map(|t| t.0).collect();
        assert_eq!(names.len(), TOPICS.len());
    }
}
