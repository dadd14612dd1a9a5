//! The live digital twin (DESIGN.md "Rig service", Twin): the ROM integrated beside the
//! experiment on the measured base acceleration, with predicted beam velocities, contact
//! state and contact forces on the measurement's time base.
//!
//! - [`spec`]: the `[twin]` settings (twin step, queue, gap handling, test throttle).
//! - [`input`]: the twin's input, the mean platform acceleration of a DAQ block.
//! - [`engine`]: the synchronous core [`Twin`] (deterministic, no threads, no clock; replay
//!   runs it directly).
//! - [`task`]: [`TwinTask`], the core on a dedicated thread behind a bounded queue that never
//!   blocks the producer, with lag and skipped blocks in its status.
//! - [`output`]: the logged types ([`TwinBlock`], [`TwinSamples`], [`TwinStatus`],
//!   [`TwinEvent`]).
//! - [`compare`]: the per-step comparison with the measurement and the twin replay.
//! - [`live`]: the twin beside a running session ([`TwinRecorder`]).
//! - [`relog`]: a copy of a session log with a re-run twin's output ([`TwinLogCopy`]).
//! - [`error`]: the error type [`TwinError`].

// NOTE: validation uses negated comparisons such as `!(dt < limit)` on purpose: they reject
// NaN together with out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod compare;
pub mod engine;
pub mod error;
pub mod input;
pub mod live;
pub mod output;
pub mod relog;
pub mod spec;
pub mod task;

pub use compare::{replay_twin, TwinComparison, TwinReplayStats, TwinSink, TwinWindows};
pub use engine::{Twin, TwinCounters};
pub use error::TwinError;
pub use input::{InputMap, TwinInput};
pub use live::{TwinOutcome, TwinRecorder, TwinStepMessage, TOPIC_TWIN_STATUS, TOPIC_TWIN_STEPS};
pub use output::{
    TwinBlock, TwinEvent, TwinGap, TwinSamples, TwinStatus, TwinTrace, TOPIC_TWIN_BLOCKS,
    TWIN_SENSORS,
};
pub use relog::{TwinLogCopy, TWIN_REPLAY_METADATA};
pub use spec::{AfterGap, TwinSpec};
pub use task::{Pushed, TwinReceiver, TwinTask};

#[cfg(test)]
mod tests;
