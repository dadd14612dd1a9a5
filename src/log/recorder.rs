//! The MCAP recorder of a stepped-sine session: the [`SessionRecorder`] that queues every
//! record to the log's writer thread (never blocking the control loop), and the topics of a
//! session log.
//!
//! Topics (message encoding JSON, schemas JSON Schema): [`TOPIC_LAYOUT`] (once),
//! [`TOPIC_DAQ`] (every raw block), [`TOPIC_CONTROL`] (control state per block),
//! [`TOPIC_EVENTS`] (step boundaries, record windows, aborts), [`TOPIC_STATUS`] (rig status,
//! about once a second), [`TOPIC_STEPS`] (per-step summaries). Log time = rig time.

use crate::control::{ControlState, SessionEvent, SessionRecorder, StepInfo, StepSummary};
use crate::rig::{DaqBlock, DaqLayout, RigStatus};

use super::{LogChannel, LogError, LogHandle};

/// The DAQ layout (channels, scales, sample rate), logged once at the start.
pub const TOPIC_LAYOUT: &str = "/daq/layout";
/// Raw DAQ blocks (ADC counts).
pub const TOPIC_DAQ: &str = "/daq/blocks";
/// Control state after every block.
pub const TOPIC_CONTROL: &str = "/control/state";
/// Session events.
pub const TOPIC_EVENTS: &str = "/session/events";
/// Rig status.
pub const TOPIC_STATUS: &str = "/rig/status";
/// Per-step summaries.
pub const TOPIC_STEPS: &str = "/session/steps";

/// A finished step as logged: what the summary was computed from, and the summary.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StepMessage {
    /// The step.
    pub info: StepInfo,
    /// Its summary.
    pub summary: StepSummary,
}

/// Rig status as logged.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct StatusMessage {
    /// Rig time of the first sample of the block after which the status was read, s (the
    /// message's log time). The status's own `time` is that of the last delivered sample.
    pub block_time: f64,
    /// The status.
    #[serde(flatten)]
    pub status: RigStatus,
}

/// Queues session records to an MCAP session log.
pub struct McapRecorder {
    log: LogHandle,
    layout: LogChannel<DaqLayout>,
    daq: LogChannel<DaqBlock>,
    control: LogChannel<ControlState>,
    events: LogChannel<SessionEvent>,
    status: LogChannel<StatusMessage>,
    steps: LogChannel<StepMessage>,
    messages: u64,
}

impl std::fmt::Debug for McapRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapRecorder")
            .field("messages", &self.messages)
            .finish()
    }
}

/// Rig time (s) as MCAP log time (ns).
pub fn log_time_ns(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}

impl McapRecorder {
    /// Registers the session topics on `log`.
    pub fn new(log: LogHandle) -> Result<McapRecorder, LogError> {
        Ok(McapRecorder {
            layout: log.channel(TOPIC_LAYOUT)?,
            daq: log.channel(TOPIC_DAQ)?,
            control: log.channel(TOPIC_CONTROL)?,
            events: log.channel(TOPIC_EVENTS)?,
            status: log.channel(TOPIC_STATUS)?,
            steps: log.channel(TOPIC_STEPS)?,
            log,
            messages: 0,
        })
    }

    /// Messages queued so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn put<T: serde::Serialize>(
        &mut self,
        which: fn(&McapRecorder) -> &LogChannel<T>,
        t: f64,
        value: &T,
    ) -> Result<(), String> {
        let ch = which(self);
        self.log
            .log(ch, log_time_ns(t), value)
            .map_err(|e| e.to_string())?;
        self.messages += 1;
        Ok(())
    }
}

impl SessionRecorder for McapRecorder {
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), String> {
        self.put(|r| &r.layout, 0.0, layout)
    }
    fn block(&mut self, block: &DaqBlock) -> Result<(), String> {
        self.put(|r| &r.daq, block.time, block)
    }
    fn control(&mut self, state: &ControlState) -> Result<(), String> {
        self.put(|r| &r.control, state.time, state)
    }
    fn event(&mut self, event: &SessionEvent) -> Result<(), String> {
        self.put(|r| &r.events, event.time, event)
    }
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), String> {
        let m = StatusMessage {
            block_time: time,
            status: status.clone(),
        };
        self.put(|r| &r.status, time, &m)
    }
    fn step(&mut self, time: f64, info: &StepInfo, summary: &StepSummary) -> Result<(), String> {
        let m = StepMessage {
            info: info.clone(),
            summary: summary.clone(),
        };
        self.put(|r| &r.steps, time, &m)
    }
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
}
