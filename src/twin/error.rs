//! The error type of the twin: bad settings (naming the `[twin]` key), a ROM or DAQ layout
//! the twin cannot use, a block that does not fit the layout or the stream, and a twin task
//! that stopped.
//!
//! Errors are for bad input only. What happens while the twin runs (a contact solve that hit
//! its sweep limit, a state that became non-finite, skipped blocks) is data in its outputs.

use crate::config::SpecError;
use crate::sim::{MissingOutput, SimError};

/// Why the twin rejected its setup or an input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TwinError {
    /// A `[twin]` value out of range.
    #[error("twin spec: {0}")]
    Spec(#[from] SpecError),
    /// A `[model]` extension that does not fit the twin ROM or the DAQ channels (names the
    /// key).
    #[error("model: {0}")]
    Model(#[from] crate::physics::PhysicsError),
    /// The twin step the `[twin]` table gives is beyond the twin ROM's stability limit.
    #[error(
        "twin spec: {key} = {value}: the twin step 1 / ({sample_rate} Hz x {steps_per_sample}) \
         = {dt:.4e} s is beyond the open stability limit of the twin ROM, {dt_max:.4e} s \
         (max(Omega) = {omega_open:.5e} rad/s, w_max dt < 2, at least {steps_per_period:.1} \
         steps per 1FU period); use twin.steps_per_sample >= {min_steps_per_sample}"
    )]
    StepBeyondLimit {
        /// The `[twin]` key that sets the step.
        key: &'static str,
        /// Its value as written (and what it gives).
        value: String,
        /// DAQ sample rate, Hz.
        sample_rate: f64,
        /// Twin steps per DAQ sample.
        steps_per_sample: u32,
        /// The twin step, s.
        dt: f64,
        /// The open stability limit, s.
        dt_max: f64,
        /// Highest circular frequency with every pair open, rad/s.
        omega_open: f64,
        /// Steps per 1FU period the open limit needs.
        steps_per_period: f64,
        /// The smallest `twin.steps_per_sample` inside the limit.
        min_steps_per_sample: f64,
    },
    /// The ROM lacks a beam sensor output the twin predicts.
    #[error("twin ROM: {0}; the twin predicts the beam sensors {sensors:?}", sensors = super::TWIN_SENSORS)]
    Rom(#[from] MissingOutput),
    /// The DAQ layout lacks something the twin needs.
    #[error("twin input: DAQ layout: {0}")]
    Layout(#[from] LayoutError),
    /// A DAQ block that does not fit the layout or the stream.
    #[error("twin input: {0}")]
    Block(#[from] BlockError),
    /// A warm-start state that does not fit the twin.
    #[error(transparent)]
    State(#[from] super::state::StateError),
    /// A clearance that is not a finite number.
    #[error("twin: clearance = {0} m: expected a finite normal gap (m)")]
    Clearance(f64),
    /// The integrator rejected the twin ROM or its parameters.
    #[error("twin model: {0}")]
    Sim(#[from] SimError),
    /// The twin task's thread is gone or could not start.
    #[error("twin task: {0}")]
    Task(#[from] TaskError),
}

/// What the twin needs from a DAQ layout and did not find.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LayoutError {
    /// The sample rate is not a finite number > 0.
    #[error("sample_rate = {0}: expected a finite sample rate > 0 (Hz)")]
    SampleRate(f64),
    /// No platform accelerometer: the twin is driven by the measured base acceleration.
    #[error(
        "no platform accelerometer (a channel of kind platform_acceleration) among the \
         channels [{}]: the twin is driven by the measured base acceleration",
        channels.join(", ")
    )]
    NoPlatform {
        /// The layout's channel names.
        channels: Vec<String>,
    },
    /// A platform accelerometer's scale is not finite.
    #[error("channel {channel}: scale = {scale}: expected a finite value per count (m/s^2)")]
    Scale {
        /// The channel's name.
        channel: String,
        /// Its scale, m/s^2 per count.
        scale: f64,
    },
}

/// A DAQ block (or its extracted input) the twin cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BlockError {
    /// The block has no samples.
    #[error("block {seq}: no samples")]
    Empty {
        /// The block's sequence number.
        seq: u64,
    },
    /// The number of counts is not channels x samples.
    #[error(
        "block {seq}: {counts} counts, expected {channels} channels x {len} samples = {} \
         (channel-major); the block does not fit the DAQ layout",
        channels * len
    )]
    Shape {
        /// The block's sequence number.
        seq: u64,
        /// Counts in the block.
        counts: usize,
        /// Channels of the layout.
        channels: usize,
        /// Samples in the block.
        len: usize,
    },
    /// A base acceleration that is not finite.
    #[error("block {seq}: base acceleration of sample {sample} is {value} (must be finite)")]
    NonFinite {
        /// The block's sequence number.
        seq: u64,
        /// The sample within the block.
        sample: usize,
        /// Its value, m/s^2.
        value: f64,
    },
    /// The block starts before the end of the previous one.
    #[error(
        "block {seq} starts at sample {first_sample}, before the end of the previous block \
         (next sample {next_sample}): blocks out of order or repeated"
    )]
    OutOfOrder {
        /// The block's sequence number.
        seq: u64,
        /// Its first sample.
        first_sample: u64,
        /// The sample the previous block ended before.
        next_sample: u64,
    },
}

/// The twin task's thread could not start or has stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TaskError {
    /// The operating system refused the thread.
    #[error("cannot start the twin thread: {0}")]
    Spawn(String),
    /// The task was shut down before the block was offered.
    #[error("the twin task was shut down")]
    ShutDown,
    /// The thread stopped; `finish` reports why.
    #[error("the twin thread has stopped (block {seq} not taken); finish() reports why")]
    Stopped {
        /// The block that was not taken.
        seq: u64,
    },
    /// The thread panicked.
    #[error("the twin thread panicked: {0}")]
    Panicked(String),
}
