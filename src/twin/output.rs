//! What the twin emits: the predicted channels of every DAQ block on the measurement's time
//! base ([`TwinBlock`], logged), gaps in its input ([`TwinGap`]), the twin task's status
//! ([`TwinStatus`]: lag, queue, skipped blocks, speed) and the task's output messages
//! ([`TwinEvent`]). All are serde- and JSON-schema-serialisable like the other logged types.

use serde::{Deserialize, Serialize};

/// The ROM outputs the twin predicts, in the order of [`TwinBlock::velocity`] (the beam
/// sensors of the rig, [`crate::sim::driven::BEAM_SENSORS`]).
pub const TWIN_SENSORS: [&str; 4] = crate::sim::driven::BEAM_SENSORS;

/// A jump in the twin's input: samples that never reached it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinGap {
    /// The first missing sample (the sample after the last one the twin processed).
    pub from_sample: u64,
    /// Number of missing samples.
    pub samples: u64,
    /// Number of missing blocks (difference of the block sequence numbers minus one).
    pub blocks: u64,
    /// Rig time of the first missing sample, s.
    pub from_time: f64,
    /// Whether the twin restarted at rest after the gap (`[twin] after_gap`); otherwise it
    /// kept its state.
    pub restarted: bool,
}

/// The twin's prediction for one DAQ block: sample `i` of every array belongs to sample `i`
/// of the input block (`first_sample + i`, rig time `time + i / sample_rate`).
///
/// Velocities are relative to the base (vertical, m/s) at the sample instant, the mean of the
/// twin's half-step velocities around it, as the simulated rig's sensors define them. Contact
/// and forces cover the twin steps of the sample interval that ends at the sample: the steps
/// starting in `(t_{i-1}, t_i]` (see [`super::Twin`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinBlock {
    /// Sequence number of the input block.
    pub seq: u64,
    /// Index of the block's first sample since the stream started.
    pub first_sample: u64,
    /// Rig time of the first sample, s.
    pub time: f64,
    /// Samples per channel.
    pub len: usize,
    /// Relative velocities of the beam sensors ([`TWIN_SENSORS`]: lower tip, lower mid, upper
    /// tip, upper mid), channel-major: `velocity[k * len + i]` is sample `i` of sensor `k`,
    /// m/s.
    pub velocity: Vec<f64>,
    /// The base acceleration the twin was driven with at each sample (the measured one
    /// without the declared platform sensitivity errors), m/s^2.
    pub base_acceleration: Vec<f64>,
    /// Whether the contact channel would detect contact at the sample: the twin's contact
    /// state through the contact-resistance circuit, a minimum-hold over the sample interval
    /// and the threshold ([`super::observe`]).
    pub contact: Vec<bool>,
    /// Mean over the sample interval of the integrated normal contact force
    /// `sum_k lambda_n,k` (the impulse over the interval divided by its length), N.
    pub normal_force: Vec<f64>,
    /// Mean over the sample interval of the integrated tangential contact force
    /// `sum_k |lambda_t,k|`, N.
    pub tangential_force: Vec<f64>,
    /// Twin steps of the sample whose contact solve stopped at the sweep limit or diverged
    /// (the step then used the last iterate or zero forces).
    pub solver_failures: Vec<u32>,
    /// The gap in the input before this block, if the block does not follow the last one.
    pub gap: Option<TwinGap>,
    /// Samples at which the twin's state became non-finite; the twin restarted at rest
    /// there (the sample's outputs are those of the restarted state).
    pub restarts: Vec<u64>,
}

impl TwinBlock {
    /// Contact solves of the block that missed the tolerance, over all its samples.
    pub fn solver_failure_count(&self) -> u64 {
        self.solver_failures.iter().map(|&f| u64::from(f)).sum()
    }

    /// The relative velocity of sensor `k` ([`TWIN_SENSORS`]), m/s.
    pub fn sensor(&self, k: usize) -> &[f64] {
        &self.velocity[k * self.len..(k + 1) * self.len]
    }

    /// The upper-tip relative velocity (the vibrometer's spot), m/s.
    pub fn upper_tip(&self) -> &[f64] {
        self.sensor(crate::sim::driven::UPPER_TIP)
    }
}

/// The twin's prediction for one DAQ block as logged on the session's `/twin/blocks`: the channels of
/// a [`TwinBlock`] in single precision, one array per sensor (so the Foxglove app can plot
/// `/twin/blocks.upper_tip`), contact as 0/1.
///
/// NOTE: single precision halves the log's size against `f64` (shortest round-trip JSON of an
/// `f32` has about 9 digits, of an `f64` 17); its relative resolution, 6e-8, is far below any
/// sensor's noise. The step comparisons are computed from the twin's `f64` output before it is
/// logged, so they do not depend on this.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinSamples {
    /// Sequence number of the input block.
    pub seq: u64,
    /// Index of the block's first sample since the stream started.
    pub first_sample: u64,
    /// Rig time of the first sample, s.
    pub time: f64,
    /// Samples per channel.
    pub len: usize,
    /// Relative velocity of the lower tip sensor, m/s.
    pub lower_tip: Vec<f32>,
    /// Relative velocity of the lower mid sensor, m/s.
    pub lower_mid: Vec<f32>,
    /// Relative velocity of the upper tip sensor (the vibrometer's spot), m/s.
    pub upper_tip: Vec<f32>,
    /// Relative velocity of the upper mid sensor, m/s.
    pub upper_mid: Vec<f32>,
    /// 1 where any contact pair was closed in a twin step of the sample, else 0.
    pub contact: Vec<u8>,
    /// Mean integrated normal contact force over the sample interval, N.
    pub normal_force: Vec<f32>,
    /// Mean integrated tangential contact force over the sample interval, N.
    pub tangential_force: Vec<f32>,
    /// Contact solves of the block that stopped at the sweep limit or diverged.
    pub solver_failures: u64,
    /// The gap in the input before this block, if any.
    pub gap: Option<TwinGap>,
    /// Samples at which the twin restarted at rest after a non-finite state.
    pub restarts: Vec<u64>,
}

impl From<&TwinBlock> for TwinSamples {
    fn from(b: &TwinBlock) -> TwinSamples {
        let f32s = |x: &[f64]| x.iter().map(|&v| v as f32).collect::<Vec<f32>>();
        // TWIN_SENSORS order: lower tip, lower mid, upper tip, upper mid.
        TwinSamples {
            seq: b.seq,
            first_sample: b.first_sample,
            time: b.time,
            len: b.len,
            lower_tip: f32s(b.sensor(0)),
            lower_mid: f32s(b.sensor(1)),
            upper_tip: f32s(b.sensor(2)),
            upper_mid: f32s(b.sensor(3)),
            contact: b.contact.iter().map(|&c| u8::from(c)).collect(),
            normal_force: f32s(&b.normal_force),
            tangential_force: f32s(&b.tangential_force),
            solver_failures: b.solver_failure_count(),
            gap: b.gap,
            restarts: b.restarts.clone(),
        }
    }
}

/// The logged twin channels over a range of samples (e.g. a record window), in `f64`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TwinTrace {
    /// Upper tip relative velocity, m/s.
    pub upper_tip: Vec<f64>,
    /// Lower tip relative velocity, m/s.
    pub lower_tip: Vec<f64>,
    /// Contact closed per sample.
    pub contact: Vec<bool>,
    /// Integrated normal contact force, N.
    pub normal_force: Vec<f64>,
    /// Integrated tangential contact force, N.
    pub tangential_force: Vec<f64>,
}

impl TwinTrace {
    /// The samples `from .. from + n` cut from logged blocks (any order); `None` unless the
    /// blocks cover every one of them (the twin skipped or lost part of the range).
    pub fn cut(blocks: &[TwinSamples], from: u64, n: usize) -> Option<TwinTrace> {
        let to = from + n as u64;
        let mut t = TwinTrace {
            upper_tip: vec![f64::NAN; n],
            lower_tip: vec![f64::NAN; n],
            contact: vec![false; n],
            normal_force: vec![f64::NAN; n],
            tangential_force: vec![f64::NAN; n],
        };
        let mut seen = vec![false; n];
        for b in blocks {
            let (lo, hi) = (
                b.first_sample.max(from),
                (b.first_sample + b.len as u64).min(to),
            );
            let consistent = [
                &b.upper_tip,
                &b.lower_tip,
                &b.normal_force,
                &b.tangential_force,
            ]
            .iter()
            .all(|v| v.len() == b.len)
                && b.contact.len() == b.len;
            if lo >= hi || !consistent {
                continue;
            }
            for s in lo..hi {
                let (i, j) = ((s - b.first_sample) as usize, (s - from) as usize);
                seen[j] = true;
                t.upper_tip[j] = f64::from(b.upper_tip[i]);
                t.lower_tip[j] = f64::from(b.lower_tip[i]);
                t.contact[j] = b.contact[i] != 0;
                t.normal_force[j] = f64::from(b.normal_force[i]);
                t.tangential_force[j] = f64::from(b.tangential_force[i]);
            }
        }
        seen.iter().all(|&s| s).then_some(t)
    }
}

/// The twin task's state, computed on demand by [`super::TwinTask::status`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinStatus {
    /// Rig time at the end of the newest block offered to the twin (its last sample plus one
    /// sample interval), s.
    pub input_time: f64,
    /// Rig time up to which the twin has produced outputs (end of its last processed block),
    /// s.
    pub twin_time: f64,
    /// `input_time - twin_time`: how far the twin is behind the measurement, s.
    pub lag_s: f64,
    /// Blocks waiting in the input queue.
    pub queue_depth: u64,
    /// Capacity of the input queue, blocks.
    pub queue_capacity: u64,
    /// Whether the task is skipping input because its queue overflowed (until the twin has
    /// drained it).
    pub behind: bool,
    /// Blocks offered to the task.
    pub blocks_offered: u64,
    /// Blocks the twin has processed (in this task).
    pub blocks_processed: u64,
    /// Blocks skipped because the twin was behind.
    pub blocks_skipped: u64,
    /// Samples in the skipped blocks.
    pub samples_skipped: u64,
    /// Sequence number of the last skipped block.
    pub last_skipped_seq: Option<u64>,
    /// Gaps the twin resumed after (skipped blocks and blocks lost upstream).
    pub gaps: u64,
    /// Blocks still queued when the task was aborted (dropped unprocessed).
    pub blocks_discarded: u64,
    /// Twin steps done (in this task).
    pub steps: u64,
    /// Twin steps per wall second of the twin thread's busy time (including any throttle).
    pub steps_per_s: f64,
    /// Seconds of data processed per wall second of busy time (> 1: faster than real time).
    pub realtime_factor: f64,
    /// Contact solves that stopped at the sweep limit or diverged.
    pub solver_failures: u64,
    /// Restarts after a non-finite state.
    pub restarts: u64,
    /// Whether the twin thread is running.
    pub running: bool,
}

/// A message from the twin task.
// NOTE: a block message (its arrays are on the heap) is a few hundred bytes on the stack, once
// per DAQ block (tens per second): boxing it would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TwinEvent {
    /// The prediction for one block.
    Block(TwinBlock),
    /// The twin's state at the start of a step (asked for with
    /// [`super::TwinTask::capture_next`]), before the block that starts the step.
    State {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// The state.
        state: Box<super::TwinState>,
    },
    /// The twin rejected a block (it is skipped; the twin continues with the next).
    Error {
        /// Sequence number of the block.
        seq: u64,
        /// What was wrong.
        message: String,
    },
}
