//! The MCAP recorder of a stepped-sine session: the [`SessionRecorder`] that queues every
//! record to the session log's writer thread (never blocking the control loop) on the
//! session's topics ([`super::topics`]).

use crate::control::{ControlState, SessionEvent, StepInfo, StepSummary};
use crate::log::{log_time_ns, LogChannel, LogError, LogHandle};
use crate::rig::{DaqBlock, DaqLayout, RigStatus};

use super::recorder::{RecordError, SessionRecorder};
use super::topics::{
    StatusMessage, StepMessage, TOPIC_CONTROL, TOPIC_DAQ, TOPIC_EVENTS, TOPIC_LAYOUT, TOPIC_STATUS,
    TOPIC_STEPS,
};

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
    ) -> Result<(), RecordError> {
        let ch = which(self);
        self.log.log(ch, log_time_ns(t), value)?;
        self.messages += 1;
        Ok(())
    }
}

impl SessionRecorder for McapRecorder {
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), RecordError> {
        self.put(|r| &r.layout, 0.0, layout)
    }
    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
        self.put(|r| &r.daq, block.time, block)
    }
    fn control(&mut self, state: &ControlState) -> Result<(), RecordError> {
        self.put(|r| &r.control, state.time, state)
    }
    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
        self.put(|r| &r.events, event.time, event)
    }
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), RecordError> {
        let m = StatusMessage {
            block_time: time,
            status: status.clone(),
        };
        self.put(|r| &r.status, time, &m)
    }
    fn step(
        &mut self,
        time: f64,
        info: &StepInfo,
        summary: &StepSummary,
    ) -> Result<(), RecordError> {
        let m = StepMessage {
            info: info.clone(),
            summary: summary.clone(),
        };
        self.put(|r| &r.steps, time, &m)
    }
    fn started(&mut self) -> Result<(), RecordError> {
        Ok(self.log.publish()?)
    }
}
