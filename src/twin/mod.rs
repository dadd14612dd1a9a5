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
//! - [`model`]: what the twin models ([`TwinModel`]: ROM, `[model]` extensions, contact
//!   observation).
//! - [`observe`]: how the prediction becomes what the rig's channels record (sensor
//!   sensitivities, contact detection through the circuit and threshold).
//! - [`compare`]: the per-step comparison with the measurement ([`TwinComparison`]) over the
//!   record windows cut from the twin's output ([`TwinWindows`]).
//! - [`state`]: warm starts ([`TwinState`]: what a twin carries between blocks, captured and
//!   restored bit for bit).
//! - [`clearance`]: the twin's clearance test by test ([`ClearanceSchedule`]), one rule for
//!   the live twin and the twin replay.
//!
//! The twin beside a running session and the twin re-run on a recording are the session's
//! (`session/twin.rs`, `session/twin_replay.rs`): the twin itself knows no log.
//! - [`error`]: the error type [`TwinError`].

// NOTE: validation uses negated comparisons such as `!(dt < limit)` on purpose: they reject
// NaN together with out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod clearance;
pub mod compare;
pub mod engine;
pub mod error;
pub mod input;
pub mod model;
pub mod observe;
pub mod output;
pub mod spec;
pub mod state;
pub mod task;

pub use clearance::ClearanceSchedule;
pub use compare::{ComparisonTolerance, Completed, FeatureComparison, TwinComparison, TwinWindows};
pub use engine::{Twin, TwinCounters};
pub use error::{BlockError, LayoutError, TaskError, TwinError};
pub use input::{InputMap, TwinInput};
pub use model::TwinModel;
pub use observe::{Observation, TipObservation};
pub use output::{TwinBlock, TwinEvent, TwinGap, TwinSamples, TwinStatus, TwinTrace, TWIN_SENSORS};
pub use spec::{AfterGap, TwinSpec};
pub use state::{StateError, StepStarts, TwinState};
pub use task::{Pushed, TwinReceiver, TwinTask};

#[cfg(test)]
mod tests;
