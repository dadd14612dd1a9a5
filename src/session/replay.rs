//! Replay of a recorded session: every per-step metric recomputed from the raw DAQ blocks of
//! the log with the live session's own code ([`crate::control::summarize`]), and the session
//! summary rebuilt from the logged events. For a session that ran to its end (or aborted
//! cleanly) the result equals the live summary bit for bit. A log cut off by a crash or
//! damaged after writing replays what it holds, and the summary says what is missing
//! ([`Missing`]: `complete` false, the rig time and steps lost; a session cut off while it ran
//! is `aborted`, with the cut as its reason). The twin re-run on a recording is the sibling
//! module `twin_replay`'s.
//!
//! [`replay`] streams the file (two passes: the small topics, then the DAQ blocks) and keeps
//! a [`Recording`] of what its consumers need: the platform accelerometers' counts of every
//! block and every channel's only inside the record windows, packed. [`replay_read`] does the
//! same over a log read whole, with the same result.

use std::path::Path;

use crate::config::RigConfig;
use crate::control::{summarize, EventKind, SessionEvent, StepInfo};
use crate::log::{stream_session, LogReadError, LoggedMessage, SessionRead};
use crate::rig::channels::platform_accelerometers;
use crate::rig::{DaqBlock, DaqLayout};
use crate::rom::Rom;
use crate::twin::{TwinModel, TwinSpec};

use super::packed::{pack, unpack};
use super::summary::{Missing, SessionSummary};
use super::topics::{
    StepMessage, TwinStateMessage, PLAN_ATTACHMENT, RIG_ATTACHMENT, TOPIC_DAQ, TOPIC_EVENTS,
    TOPIC_LAYOUT, TOPIC_STEPS, TOPIC_TWIN_STATE,
};

/// Errors of a replay.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The log could not be read.
    #[error(transparent)]
    Read(#[from] LogReadError),
    /// The log lacks something replay needs, or it is inconsistent.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// A replayed session.
#[derive(Debug, Clone)]
pub struct Replay {
    /// The summary rebuilt from the raw recording.
    pub summary: SessionSummary,
    /// The per-step summaries the live session logged (for comparison).
    pub logged_steps: Vec<StepMessage>,
    /// The DAQ layout.
    pub layout: DaqLayout,
    /// Whether the file was complete (false: recovered after a crash).
    pub complete: bool,
    /// What was lost, for an incomplete file.
    pub note: Option<String>,
    /// The rig description the session ran with (the log's `rig.toml` attachment), if any.
    pub rig_toml: Option<String>,
    /// The clearances / l of the session's tests: the plan's (the log's `plan.toml`
    /// attachment), else those of the tests recorded. They chose the live twin's contact
    /// patch ([`RigConfig::held_contact_twin`]).
    pub clearances: Vec<f64>,
    /// The raw recording (layout, blocks, events).
    pub recording: Recording,
}

/// A DAQ block of a recording without its counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockHead {
    /// Block sequence number.
    pub seq: u64,
    /// Index of the block's first sample since the stream started.
    pub first_sample: u64,
    /// Rig time of the first sample, s.
    pub time: f64,
    /// Samples per channel.
    pub len: usize,
}

/// The session's DAQ stream, kept as its consumers need it and no more: every block's base
/// motion (the platform accelerometers' counts: what the twin runs on), every channel's counts
/// only inside the steps' record windows (what a step's summary and evidence are computed
/// from), both packed losslessly (`super::packed`); and the layout, events and logged twin
/// states. A one-hour session at the default rates holds a few hundred megabytes here, where
/// all its counts would take 1.9 GB.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The layout.
    pub layout: DaqLayout,
    /// The blocks, in sequence order (with gaps where chunks of the log were damaged).
    pub blocks: Vec<BlockHead>,
    /// Events, in order.
    pub events: Vec<SessionEvent>,
    /// Blocks missing inside the recording, in order (empty for an intact log).
    pub gaps: Vec<BlockGap>,
    /// The twin's states at the start of its steps, as logged (warm starts; empty for a log
    /// without them).
    pub twin_states: Vec<TwinStateMessage>,
    /// Layout indices of the platform accelerometers, in layout order.
    platform: Vec<usize>,
    /// The platform channels' counts of every block, packed channel after channel; block `i`
    /// starts at `platform_at[i]`.
    platform_packed: Vec<u8>,
    platform_at: Vec<usize>,
    /// The complete record windows of the `record_end` events: (first sample, samples, every
    /// channel's counts packed channel after channel).
    windows: Vec<(u64, usize, Vec<u8>)>,
}

/// DAQ blocks missing inside a recording (damaged chunks of the log).
#[derive(Debug, Clone, PartialEq)]
pub struct BlockGap {
    /// Sequence number of the first missing block.
    pub first_seq: u64,
    /// Missing blocks, -.
    pub blocks: u64,
    /// Rig time missing: from the end of the block before to the start of the block after, s.
    pub seconds: f64,
}

impl Recording {
    /// Rig time covered by the blocks, s (the end of the last block).
    pub fn rig_seconds(&self) -> f64 {
        self.blocks
            .last()
            .map_or(0.0, |b| b.time + b.len as f64 / self.layout.sample_rate)
    }

    /// The steps' record windows, in order (from the `record_end` events).
    pub fn record_windows(&self) -> impl Iterator<Item = &StepInfo> {
        self.events.iter().filter_map(|e| match &e.kind {
            EventKind::RecordEnd { info } => Some(info),
            _ => None,
        })
    }

    /// Block `i` as the twin consumes it: the platform accelerometers' counts as recorded,
    /// every other channel's zero (the recording keeps those only inside record windows:
    /// [`window_counts`]). Panics if there is no block `i`.
    pub fn base_block(&self, i: usize) -> DaqBlock {
        let head = self.blocks[i];
        let n = head.len;
        let mut counts = vec![0; self.layout.channels.len() * n];
        let mut pos = self.platform_at[i];
        let mut values = Vec::with_capacity(n);
        for &k in &self.platform {
            values.clear();
            unpack(&self.platform_packed, &mut pos, n, &mut values);
            counts[k * n..(k + 1) * n].copy_from_slice(&values);
        }
        DaqBlock {
            seq: head.seq,
            first_sample: head.first_sample,
            time: head.time,
            len: n,
            counts,
        }
    }

    /// Blocks `from..` as [`Recording::base_block`] gives them, unpacked one at a time.
    pub fn base_blocks(&self, from: usize) -> impl Iterator<Item = DaqBlock> + '_ {
        (from..self.blocks.len()).map(move |i| self.base_block(i))
    }

    /// Bytes of counts the recording holds (packed base motion and record windows).
    pub fn count_bytes(&self) -> usize {
        self.platform_packed.len() + self.windows.iter().map(|w| w.2.len()).sum::<usize>()
    }

    /// Samples of every channel the recording holds counts of: those inside its complete
    /// record windows (all the others are zero in [`Recording::base_block`]).
    pub fn window_samples(&self) -> u64 {
        self.windows.iter().map(|w| w.1 as u64).sum()
    }
}

fn content(path: &Path, message: impl Into<String>) -> ReplayError {
    ReplayError::Content {
        path: path.display().to_string(),
        message: message.into(),
    }
}

/// Whether the reader lost or skipped anything of `session`.
fn damaged_or_cut(session: &SessionRead) -> bool {
    !session.complete || !session.damage.is_empty()
}

/// The messages of one topic decoded as `T`, in order, as they pass; the first that does not
/// decode is kept as the error [`SessionRead::decode`] gives.
struct Decoded<T> {
    topic: &'static str,
    count: usize,
    values: Vec<T>,
    error: Option<LogReadError>,
}

impl<T: serde::de::DeserializeOwned> Decoded<T> {
    fn new(topic: &'static str) -> Decoded<T> {
        Decoded {
            topic,
            count: 0,
            values: Vec::new(),
            error: None,
        }
    }

    /// Takes `m` if it is on this topic: its value, or `None` (another topic, or an error).
    fn decode(&mut self, path: &Path, m: &LoggedMessage) -> Option<T> {
        if &*m.topic != self.topic {
            return None;
        }
        let index = self.count;
        self.count += 1;
        if self.error.is_some() {
            return None;
        }
        match serde_json::from_slice(&m.data) {
            Ok(v) => Some(v),
            Err(source) => {
                self.error = Some(LogReadError::Decode {
                    path: path.to_path_buf(),
                    topic: self.topic.to_string(),
                    index,
                    sequence: m.sequence,
                    type_name: std::any::type_name::<T>(),
                    source,
                });
                None
            }
        }
    }

    fn push(&mut self, path: &Path, m: &LoggedMessage) {
        if let Some(v) = self.decode(path, m) {
            self.values.push(v);
        }
    }

    fn result(self) -> Result<Vec<T>, ReplayError> {
        match self.error {
            Some(e) => Err(e.into()),
            None => Ok(self.values),
        }
    }
}

/// The small topics of a session log (first pass over its messages).
struct Outline {
    layout: Decoded<DaqLayout>,
    events: Decoded<SessionEvent>,
    twin_states: Decoded<TwinStateMessage>,
    steps: Decoded<StepMessage>,
    daq_messages: usize,
}

impl Outline {
    fn new() -> Outline {
        Outline {
            layout: Decoded::new(TOPIC_LAYOUT),
            events: Decoded::new(TOPIC_EVENTS),
            twin_states: Decoded::new(TOPIC_TWIN_STATE),
            steps: Decoded::new(TOPIC_STEPS),
            daq_messages: 0,
        }
    }

    fn message(&mut self, path: &Path, m: &LoggedMessage) {
        match &*m.topic {
            TOPIC_DAQ => self.daq_messages += 1,
            TOPIC_LAYOUT => self.layout.push(path, m),
            TOPIC_EVENTS => self.events.push(path, m),
            TOPIC_TWIN_STATE => self.twin_states.push(path, m),
            TOPIC_STEPS => self.steps.push(path, m),
            _ => {}
        }
    }
}

/// The DAQ blocks of a session log made into a [`Recording`] as they pass (second pass).
struct BlockPass<'a> {
    path: &'a Path,
    layout: &'a DaqLayout,
    cut: bool,
    decoded: Decoded<DaqBlock>,
    /// The first inconsistency; later blocks are still decoded (a block that does not decode
    /// is reported first, as when all were decoded before any was checked).
    failed: Option<ReplayError>,
    next_seq: u64,
    last_end: f64,
    blocks: Vec<BlockHead>,
    gaps: Vec<BlockGap>,
    platform: Vec<usize>,
    platform_packed: Vec<u8>,
    platform_at: Vec<usize>,
    /// The record windows (first sample, samples), sorted, with their counts while they fill
    /// (channel-major) and the samples filled.
    windows: Vec<(u64, usize)>,
    filling: Vec<Option<(Vec<i32>, usize)>>,
    packed: Vec<Option<Vec<u8>>>,
    /// Windows before this one are complete or passed.
    cursor: usize,
}

impl<'a> BlockPass<'a> {
    fn new(
        path: &'a Path,
        layout: &'a DaqLayout,
        cut: bool,
        events: &[SessionEvent],
    ) -> BlockPass<'a> {
        let mut windows: Vec<(u64, usize)> = events
            .iter()
            .filter_map(|e| match &e.kind {
                EventKind::RecordEnd { info } => {
                    Some((info.record_first_sample, info.record_samples))
                }
                _ => None,
            })
            .collect();
        windows.sort_unstable();
        windows.dedup();
        let n = windows.len();
        BlockPass {
            path,
            layout,
            cut,
            decoded: Decoded::new(TOPIC_DAQ),
            failed: None,
            next_seq: 0,
            last_end: 0.0,
            blocks: Vec::new(),
            gaps: Vec::new(),
            platform: platform_accelerometers(layout)
                .into_iter()
                .map(|(k, _)| k)
                .collect(),
            platform_packed: Vec::new(),
            platform_at: Vec::new(),
            windows,
            filling: vec![None; n],
            packed: vec![None; n],
            cursor: 0,
        }
    }

    fn message(&mut self, m: &LoggedMessage) {
        let Some(b) = self.decoded.decode(self.path, m) else {
            return;
        };
        if self.failed.is_none() {
            if let Err(e) = self.block(b) {
                self.failed = Some(e);
            }
        }
    }

    /// Takes one block (the checks and gaps of the whole-recording replay, block by block).
    fn block(&mut self, b: DaqBlock) -> Result<(), ReplayError> {
        let path = self.path;
        let next_seq = self.next_seq;
        if b.seq < next_seq {
            return Err(content(
                path,
                format!(
                    "{TOPIC_DAQ}: block {} after block {} (out of order)",
                    b.seq,
                    next_seq - 1
                ),
            ));
        }
        b.check(self.layout)
            .map_err(|e| content(path, e.to_string()))?;
        if b.seq > next_seq {
            if !self.cut {
                return Err(content(
                    path,
                    format!(
                        "{TOPIC_DAQ}: block {} where {next_seq} was due (lost data)",
                        b.seq
                    ),
                ));
            }
            self.gaps.push(BlockGap {
                first_seq: next_seq,
                blocks: b.seq - next_seq,
                seconds: (b.time - self.last_end).max(0.0),
            });
        }
        self.next_seq = b.seq + 1;
        self.last_end = b.time + b.len as f64 / self.layout.sample_rate;
        self.platform_at.push(self.platform_packed.len());
        for &k in &self.platform {
            pack(b.channel(k), &mut self.platform_packed);
        }
        self.windows_take(&b);
        self.blocks.push(BlockHead {
            seq: b.seq,
            first_sample: b.first_sample,
            time: b.time,
            len: b.len,
        });
        Ok(())
    }

    /// Copies the part of block `b` inside record windows; packs the windows it completes.
    fn windows_take(&mut self, b: &DaqBlock) {
        let nch = self.layout.channels.len();
        let (b0, b1) = (b.first_sample, b.first_sample + b.len as u64);
        // Windows that ended before this block cannot fill any more.
        while self
            .windows
            .get(self.cursor)
            .is_some_and(|&(w0, n)| w0 + n as u64 <= b0)
        {
            self.filling[self.cursor] = None;
            self.cursor += 1;
        }
        for j in self.cursor..self.windows.len() {
            let (w0, n) = self.windows[j];
            if w0 >= b1 {
                break;
            }
            let w1 = w0 + n as u64;
            let (s, e) = (b0.max(w0), b1.min(w1));
            if s >= e || self.packed[j].is_some() {
                continue;
            }
            let (counts, filled) = self.filling[j].get_or_insert_with(|| (vec![0; n * nch], 0));
            for k in 0..nch {
                let src = &b.channel(k)[(s - b0) as usize..(e - b0) as usize];
                counts[k * n + (s - w0) as usize..k * n + (e - w0) as usize].copy_from_slice(src);
            }
            *filled += (e - s) as usize;
            if *filled == n {
                let mut bytes = Vec::new();
                for k in 0..nch {
                    pack(&counts[k * n..(k + 1) * n], &mut bytes);
                }
                bytes.shrink_to_fit();
                self.packed[j] = Some(bytes);
                self.filling[j] = None;
            }
        }
    }

    /// The recording, without events and twin states.
    fn finish(mut self) -> Result<Recording, ReplayError> {
        if let Some(e) = self.decoded.error.take() {
            return Err(e.into());
        }
        if let Some(e) = self.failed {
            return Err(e);
        }
        self.platform_packed.shrink_to_fit();
        let windows = self
            .windows
            .iter()
            .zip(self.packed)
            .filter_map(|(&(w0, n), p)| p.map(|p| (w0, n, p)))
            .collect();
        Ok(Recording {
            layout: self.layout.clone(),
            blocks: self.blocks,
            events: Vec::new(),
            gaps: self.gaps,
            twin_states: Vec::new(),
            platform: self.platform,
            platform_packed: self.platform_packed,
            platform_at: self.platform_at,
            windows,
        })
    }
}

/// Makes the recording of a session from two passes over its messages (`each`: calls its
/// argument on every message in file order): the small topics, then the DAQ blocks. `session`
/// is the log as read (its messages need not be held). Also returns the logged steps' decoder.
fn build(
    session: &SessionRead,
    outline: Outline,
    mut each: impl FnMut(&mut dyn FnMut(&LoggedMessage)) -> Result<(), ReplayError>,
) -> Result<(Recording, Decoded<StepMessage>), ReplayError> {
    let path = session.path.as_path();
    session.require_rigtwin()?;
    let Outline {
        layout,
        events,
        twin_states,
        steps,
        daq_messages,
    } = outline;
    let Some(layout) = layout.result()?.into_iter().next() else {
        let blocks = daq_messages;
        if blocks > 0 {
            return Err(content(
                path,
                format!(
                    "the DAQ layout ({TOPIC_LAYOUT}, logged once at the start) was in a damaged \
                     part of the file: the {blocks} DAQ blocks that remain cannot be interpreted \
                     without it; damage: {}",
                    session.damage.join("; ")
                ),
            ));
        }
        if damaged_or_cut(session) {
            let why = session
                .note
                .iter()
                .chain(&session.damage)
                .cloned()
                .collect::<Vec<_>>()
                .join("; ");
            return Err(content(
                path,
                format!(
                    "the log holds no DAQ data, nothing to replay: it was cut off or damaged \
                     before the session's first data reached the disk (the writer flushes \
                     once a second, so a session cut off within its first second keeps only \
                     its header and rig description): {why}"
                ),
            ));
        }
        return Err(content(
            path,
            format!("no {TOPIC_LAYOUT} message: not a session log"),
        ));
    };
    let mut pass = BlockPass::new(path, &layout, damaged_or_cut(session), &events.values);
    each(&mut |m| {
        if &*m.topic == TOPIC_DAQ {
            pass.message(m);
        }
    })?;
    // NOTE: errors in the order the whole-file replay met them: layout, blocks, events,
    // twin states.
    let rec = pass.finish()?;
    Ok((
        Recording {
            events: events.result()?,
            twin_states: twin_states.result()?,
            ..rec
        },
        steps,
    ))
}

/// Decodes the layout, the DAQ blocks and the events of a session log read whole.
pub fn recording(session: &SessionRead) -> Result<Recording, ReplayError> {
    recording_and_steps(session).map(|(rec, _)| rec)
}

fn recording_and_steps(
    session: &SessionRead,
) -> Result<(Recording, Decoded<StepMessage>), ReplayError> {
    let path = session.path.as_path();
    let mut outline = Outline::new();
    for m in &session.messages {
        outline.message(path, m);
    }
    build(session, outline, |visit| {
        for m in &session.messages {
            visit(m);
        }
        Ok(())
    })
}

/// The counts of a record window (channel-major) of the recording: `info` is one of its
/// `record_end` events' windows, complete in the blocks (otherwise `None`).
pub fn window_counts(rec: &Recording, info: &StepInfo) -> Option<Vec<i32>> {
    let n = info.record_samples;
    let (_, _, bytes) = rec
        .windows
        .iter()
        .find(|w| w.0 == info.record_first_sample && w.1 == n)?;
    let mut out = Vec::with_capacity(n * rec.layout.channels.len());
    let mut pos = 0;
    for _ in 0..rec.layout.channels.len() {
        unpack(bytes, &mut pos, n, &mut out);
    }
    Some(out)
}

/// Replays the session log at `path`, streaming it: two passes over the file (the small
/// topics, then the DAQ blocks), neither holding the file or its messages.
pub fn replay(path: &Path) -> Result<Replay, ReplayError> {
    let mut outline = Outline::new();
    let session = stream_session(path, |m| {
        outline.message(path, m);
        Ok::<(), ReplayError>(())
    })?;
    let (rec, steps) = build(&session, outline, |visit| {
        stream_session(path, |m| {
            visit(m);
            Ok::<(), ReplayError>(())
        })?;
        Ok(())
    })?;
    replay_of(&session, rec, steps)
}

/// Replays a session log already read (e.g. by [`crate::log::read_session_bytes`]).
pub fn replay_read(session: SessionRead) -> Result<Replay, ReplayError> {
    let (rec, steps) = recording_and_steps(&session)?;
    replay_of(&session, rec, steps)
}

fn replay_of(
    session: &SessionRead,
    rec: Recording,
    steps: Decoded<StepMessage>,
) -> Result<Replay, ReplayError> {
    let path = session.path.clone();
    let path = path.as_path();
    let mut summary = SessionSummary {
        blocks: rec.blocks.len() as u64,
        rig_seconds: rec.rig_seconds(),
        ..SessionSummary::default()
    };
    let cut = damaged_or_cut(session);
    let mut steps_lost = Vec::new();
    for e in &rec.events {
        summary.apply_event(e);
        if let EventKind::RecordEnd { info } = &e.kind {
            let counts = window_counts(&rec, info);
            if cut && counts.is_none() {
                steps_lost.push(format!("{} step {}", info.test, info.step + 1));
                continue;
            }
            let counts = counts.ok_or_else(|| {
                content(
                    path,
                    format!(
                        "record window of step {} of test {} (samples {}..{}) is not in the DAQ blocks",
                        info.step,
                        info.test,
                        info.record_first_sample,
                        info.record_end_sample()
                    ),
                )
            })?;
            let s =
                summarize(&rec.layout, info, &counts).map_err(|e| content(path, e.to_string()))?;
            summary.push_step(&info.test, s);
        }
    }
    let logged_steps = steps.result()?;
    let rig_toml = session
        .attachment(RIG_ATTACHMENT)
        .map(|a| String::from_utf8_lossy(&a.data).into_owned());
    let plan = logged_plan(session);
    let clearances = match &plan {
        Some(plan) => plan.tests.iter().map(|t| t.clearance).collect(),
        None => summary.tests.iter().map(|t| t.clearance).collect(),
    };
    mark_missing(&mut summary, session, plan.as_ref(), &rec, steps_lost);
    Ok(Replay {
        summary,
        logged_steps,
        layout: rec.layout.clone(),
        complete: session.complete,
        note: session.note.clone(),
        rig_toml,
        clearances,
        recording: rec,
    })
}

/// The plan the session ran (the log's `plan.toml` attachment), if it holds a valid one.
fn logged_plan(session: &SessionRead) -> Option<crate::plan::Plan> {
    let a = session.attachment(PLAN_ATTACHMENT)?;
    let text = String::from_utf8_lossy(&a.data);
    crate::plan::Plan::from_str(&text, "plan.toml (attached to the log)").ok()
}

/// Marks `summary` incomplete with what is missing when the log was cut off or damaged, or the
/// session did not log its end (the steps `plan`, the log's, had planned); a session cut off
/// while it ran is marked aborted.
fn mark_missing(
    summary: &mut SessionSummary,
    session: &SessionRead,
    plan: Option<&crate::plan::Plan>,
    rec: &Recording,
    steps_lost: Vec<String>,
) {
    let session_end = rec
        .events
        .iter()
        .any(|e| matches!(e.kind, EventKind::SessionEnd { .. }));
    if session_end && !damaged_or_cut(session) && rec.gaps.is_empty() {
        return;
    }
    let steps_planned = plan.map(|p| p.tests.iter().map(|t| t.steps as usize).sum::<usize>());
    let steps_finished = summary.steps().count();
    let recorded_until_s = rec.rig_seconds();
    let lost_blocks: u64 = rec.gaps.iter().map(|g| g.blocks).sum();
    let lost_seconds: f64 = rec.gaps.iter().map(|g| g.seconds).sum();
    let mut parts = Vec::new();
    if !session_end {
        // Where the session was when the log ends: the last step started.
        let at = rec
            .events
            .iter()
            .rev()
            .find_map(|e| match &e.kind {
                EventKind::StepStart { test, step, .. } => {
                    Some(format!(" in step {} of test {test}", step + 1))
                }
                _ => None,
            })
            .unwrap_or_default();
        let not_recorded = match steps_planned {
            Some(n) => format!(
                "; {steps_finished} of {n} planned steps finished, {} not recorded",
                n.saturating_sub(steps_finished)
            ),
            None => format!("; {steps_finished} steps finished"),
        };
        parts.push(format!(
            "the session was cut off (killed, crashed or out of disk space): the log ends at \
             rig time {recorded_until_s:.2} s{at} without session_end{not_recorded}"
        ));
    } else if !session.complete {
        parts.push(
            "the session ended, but its log was not closed (the summary section is missing)"
                .to_string(),
        );
    }
    if lost_blocks > 0 {
        parts.push(format!(
            "{lost_blocks} DAQ blocks ({lost_seconds:.2} s of rig time) lost in damaged parts \
             of the file"
        ));
    }
    if !steps_lost.is_empty() {
        parts.push(format!(
            "{} steps lost with them ({})",
            steps_lost.len(),
            steps_lost.join(", ")
        ));
    }
    if parts.is_empty() {
        parts.push("the file was damaged, but no DAQ data were lost".to_string());
    }
    if !session_end && !summary.aborted {
        summary.aborted = true;
        summary.abort_reason = Some(format!(
            "the log ends at rig time {recorded_until_s:.2} s without session_end: the session \
             was cut off (killed, crashed or out of disk space)"
        ));
    }
    summary.complete = false;
    summary.missing = Some(Missing {
        description: parts.join("; "),
        session_end,
        recorded_until_s,
        lost_blocks,
        lost_seconds,
        steps_planned,
        steps_finished,
        steps_lost,
        file: session
            .note
            .iter()
            .chain(&session.damage)
            .cloned()
            .collect(),
    });
}

impl Replay {
    /// Whether the recomputed step summaries are the ones the live session logged, bit for bit.
    pub fn matches_logged(&self) -> bool {
        let recomputed: Vec<&crate::control::StepSummary> =
            self.summary.steps().map(|s| &s.measured).collect();
        self.logged_steps.len() == recomputed.len()
            && self
                .logged_steps
                .iter()
                .zip(recomputed)
                .all(|(logged, s)| &logged.summary == s)
    }
}

/// Which model a replayed twin runs (`rigtwin replay --twin`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TwinModelChoice<'a> {
    /// The rig description the session ran with (the log's `rig.toml`).
    Logged,
    /// Another rig description (`--config`): its ROM and its `[twin]` table.
    Config(&'a Path),
    /// A ROM file (`--rom`), with the logged rig description's `[twin]` table (the defaults
    /// when the log holds none).
    Rom(&'a Path),
}

/// Where the replayed twin's ROM comes from.
#[derive(Clone, Debug)]
pub enum TwinRom {
    /// A ROM file.
    File(std::path::PathBuf),
    /// The ROM of a rig description (built or taken from the cache by the caller).
    Description(Box<RigConfig>),
}

/// Where the replayed twin's ROM comes from, and its `[twin]` settings.
#[derive(Clone, Debug)]
pub struct TwinModelSource {
    /// The ROM.
    pub rom: TwinRom,
    /// The twin's settings.
    pub spec: TwinSpec,
    /// Where the model came from, for messages and the log copy's metadata.
    pub source: String,
    /// The logged rig description, for a ROM file (`--rom`): its `[model]` and contact
    /// observation go with the ROM.
    logged: Option<Box<RigConfig>>,
}

impl TwinModelSource {
    /// The rig description the model's extensions and contact observation come from (none:
    /// a ROM file with a log that holds no description).
    pub fn description(&self) -> Option<&RigConfig> {
        match &self.rom {
            TwinRom::Description(cfg) => Some(cfg),
            TwinRom::File(_) => self.logged.as_deref(),
        }
    }

    /// The twin's model with ROM `rom` (the one [`TwinModelSource::rom`] names).
    pub fn model<'a>(&self, rom: &'a Rom) -> TwinModel<'a> {
        TwinModel::of(rom, self.description())
    }
}

/// Errors of choosing the replayed twin's model.
#[derive(Debug, thiserror::Error)]
pub enum TwinModelError {
    /// A rig description (named or in the log) is invalid.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The log holds no rig description and none was named.
    #[error(
        "{log}: the log holds no rig description (rig.toml attachment); name the twin's model \
         with --config or --rom"
    )]
    NoRigDescription {
        /// The log file.
        log: String,
    },
}

/// What the replayed twin runs: the model `choice` names, for the log at `log` whose rig
/// description (if any) is `rig_toml`.
pub fn twin_model_source(
    choice: TwinModelChoice<'_>,
    log: &Path,
    rig_toml: Option<&str>,
) -> Result<TwinModelSource, TwinModelError> {
    const LOGGED: &str = "rig.toml (attached to the log)";
    let logged = || {
        rig_toml
            .map(|text| RigConfig::from_str(text, LOGGED))
            .transpose()
    };
    match choice {
        TwinModelChoice::Rom(path) => {
            let logged = logged()?;
            Ok(TwinModelSource {
                spec: logged.as_ref().map(|c| c.twin.clone()).unwrap_or_default(),
                rom: TwinRom::File(path.to_path_buf()),
                source: path.display().to_string(),
                logged: logged.map(Box::new),
            })
        }
        TwinModelChoice::Config(path) => {
            let cfg = RigConfig::from_path(path)?;
            Ok(TwinModelSource {
                spec: cfg.twin.clone(),
                rom: TwinRom::Description(Box::new(cfg)),
                source: path.display().to_string(),
                logged: None,
            })
        }
        TwinModelChoice::Logged => {
            let cfg = logged()?.ok_or_else(|| TwinModelError::NoRigDescription {
                log: log.display().to_string(),
            })?;
            Ok(TwinModelSource {
                spec: cfg.twin.clone(),
                rom: TwinRom::Description(Box::new(cfg)),
                source: "the rig description in the log".to_string(),
                logged: None,
            })
        }
    }
}
