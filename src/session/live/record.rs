//! What the session hands to the live view's publisher thread, and what the view did.

use std::collections::BTreeMap;

use crate::control::{ControlState, SessionEvent};
use crate::rig::{DaqBlock, DaqLayout};
use crate::twin::{TwinBlock, TwinStatus};

use super::super::topics::{StatusMessage, StepMessage, TwinStepMessage};

/// What the session hands to the publisher thread.
pub(super) enum Record {
    Layout(DaqLayout),
    Block(DaqBlock),
    Control(ControlState),
    Event(SessionEvent),
    Status(StatusMessage),
    /// A finished step and its log time (end of its record window), s.
    Step(f64, Box<StepMessage>),
    /// The live twin's prediction for one DAQ block.
    TwinBlock(Box<TwinBlock>),
    /// The live twin's status at a rig time, s.
    TwinStatus(f64, Box<TwinStatus>),
    /// The live twin's comparison of a step and its log time (end of its record window), s.
    TwinStep(f64, Box<TwinStepMessage>),
    /// Publish what is queued, close the open decimation bin and stop.
    Close,
}

/// What a live view did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LiveStats {
    /// Messages handed to the server per topic while at least one client was subscribed to it.
    pub sent: BTreeMap<String, u64>,
    /// Decimated DAQ points made (also those no client was subscribed to).
    pub points: u64,
    /// Records the session could not queue (the publisher thread was behind); never waited for.
    pub dropped_records: u64,
    /// DAQ blocks skipped by the decimator because they did not match the layout.
    pub skipped_blocks: u64,
}

impl LiveStats {
    /// Messages handed to the server, all topics.
    pub fn sent_total(&self) -> u64 {
        self.sent.values().sum()
    }
}
