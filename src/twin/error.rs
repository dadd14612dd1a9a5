//! The error type of the twin: bad settings (naming the `[twin]` key), a ROM or DAQ layout
//! the twin cannot use, a block that does not fit the layout, and a twin task that stopped.
//!
//! Errors are for bad input only. What happens while the twin runs (a contact solve that hit
//! its sweep limit, a state that became non-finite, skipped blocks) is data in its outputs.

use crate::sim::SimError;

/// Why the twin rejected its setup or an input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TwinError {
    /// A `[twin]` value out of range, or a twin step beyond the ROM's stability limit (the
    /// message names the key).
    #[error("twin spec: {0}")]
    Spec(String),
    /// The ROM lacks something the twin needs (e.g. a beam sensor output).
    #[error("twin ROM: {0}")]
    Rom(String),
    /// The DAQ layout lacks something the twin needs (e.g. platform accelerometers).
    #[error("twin input: DAQ layout: {0}")]
    Layout(String),
    /// A DAQ block that does not fit the layout or the stream (wrong shape, out of order).
    #[error("twin input: {0}")]
    Block(String),
    /// A clearance that is not a finite number.
    #[error("twin: clearance = {0} m: expected a finite normal gap (m)")]
    Clearance(f64),
    /// The integrator rejected the twin ROM or its parameters.
    #[error("twin model: {0}")]
    Sim(#[from] SimError),
    /// The metrics of the twin's output over a record window could not be computed.
    #[error("twin comparison: {0}")]
    Metrics(String),
    /// The twin task's thread is gone (it panicked, or the task was shut down).
    #[error("twin task: {0}")]
    Task(String),
    /// Writing the twin's output to a session log failed.
    #[error("twin log: {0}")]
    Log(String),
}
