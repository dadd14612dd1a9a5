//! Replay of a recorded session: every per-step metric recomputed from the raw DAQ blocks of
//! the log with the live session's own code ([`crate::control::summarize`]), and the session
//! summary rebuilt from the logged events. For a session that ran to its end (or aborted
//! cleanly) the result equals the live summary bit for bit. A log cut off by a crash or
//! damaged after writing replays what it holds, and the summary says what is missing
//! ([`Missing`]: `complete` false, the rig time and steps lost; a session cut off while it ran
//! is `aborted`, with the cut as its reason). The twin re-run on a recording is the sibling
//! module `twin_replay`'s.

use std::path::Path;

use crate::config::RigConfig;
use crate::control::{summarize, EventKind, SessionEvent, StepInfo};
use crate::log::{read_session, LogReadError, SessionRead};
use crate::rig::{DaqBlock, DaqLayout};
use crate::rom::Rom;
use crate::twin::{TwinModel, TwinSpec};

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
    /// The raw recording (layout, blocks, events).
    pub recording: Recording,
}

/// The session's DAQ stream: layout and blocks in order.
#[derive(Debug, Clone)]
pub struct Recording {
    /// The layout.
    pub layout: DaqLayout,
    /// Blocks, in sequence order (with gaps where chunks of the log were damaged).
    pub blocks: Vec<DaqBlock>,
    /// Events, in order.
    pub events: Vec<SessionEvent>,
    /// Blocks missing inside the recording, in order (empty for an intact log).
    pub gaps: Vec<BlockGap>,
    /// The twin's states at the start of its steps, as logged (warm starts; empty for a log
    /// without them).
    pub twin_states: Vec<TwinStateMessage>,
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
}

fn content(path: &Path, message: impl Into<String>) -> ReplayError {
    ReplayError::Content {
        path: path.display().to_string(),
        message: message.into(),
    }
}

/// The messages on `topic` decoded as `T`; none when the log has no such channel (a log cut
/// off or damaged before its first message on `topic`).
fn decode_or_none<T: serde::de::DeserializeOwned>(
    session: &SessionRead,
    topic: &str,
) -> Result<Vec<T>, ReplayError> {
    match session.decode::<T>(topic) {
        Ok(v) => Ok(v.into_iter().map(|(_, _, t)| t).collect()),
        Err(LogReadError::UnknownTopic { .. }) => Ok(Vec::new()),
        Err(e) => Err(e.into()),
    }
}

/// Whether the reader lost or skipped anything of `session`.
fn damaged_or_cut(session: &SessionRead) -> bool {
    !session.complete || !session.damage.is_empty()
}

/// Decodes the layout, the DAQ blocks and the events of a session log.
pub fn recording(session: &SessionRead) -> Result<Recording, ReplayError> {
    let path = &session.path;
    session.require_rigtwin()?;
    let Some(layout) = decode_or_none::<DaqLayout>(session, TOPIC_LAYOUT)?
        .into_iter()
        .next()
    else {
        let blocks = session.messages_on(TOPIC_DAQ).count();
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
    let blocks: Vec<DaqBlock> = decode_or_none(session, TOPIC_DAQ)?;
    let mut gaps = Vec::new();
    let mut next_seq = 0u64;
    let mut last_end = 0.0;
    for b in &blocks {
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
        b.check(&layout).map_err(|e| content(path, e.to_string()))?;
        if b.seq > next_seq {
            if !damaged_or_cut(session) {
                return Err(content(
                    path,
                    format!(
                        "{TOPIC_DAQ}: block {} where {next_seq} was due (lost data)",
                        b.seq
                    ),
                ));
            }
            gaps.push(BlockGap {
                first_seq: next_seq,
                blocks: b.seq - next_seq,
                seconds: (b.time - last_end).max(0.0),
            });
        }
        next_seq = b.seq + 1;
        last_end = b.time + b.len as f64 / layout.sample_rate;
    }
    let events = decode_or_none(session, TOPIC_EVENTS)?;
    let twin_states = decode_or_none(session, TOPIC_TWIN_STATE)?;
    Ok(Recording {
        layout,
        blocks,
        events,
        gaps,
        twin_states,
    })
}

/// The counts of a record window (channel-major), from the blocks.
pub fn window_counts(rec: &Recording, info: &StepInfo) -> Option<Vec<i32>> {
    let n = info.record_samples;
    let nch = rec.layout.channels.len();
    let first = info.record_first_sample;
    let mut out = vec![0; n * nch];
    let mut filled = 0usize;
    for b in &rec.blocks {
        let (b0, b1) = (b.first_sample, b.first_sample + b.len as u64);
        let (w0, w1) = (first, info.record_end_sample());
        let (s, e) = (b0.max(w0), b1.min(w1));
        if s >= e {
            continue;
        }
        for k in 0..nch {
            let src = &b.channel(k)[(s - b0) as usize..(e - b0) as usize];
            out[k * n + (s - w0) as usize..k * n + (e - w0) as usize].copy_from_slice(src);
        }
        filled += (e - s) as usize;
    }
    (filled == n).then_some(out)
}

/// Replays the session log at `path`.
pub fn replay(path: &Path) -> Result<Replay, ReplayError> {
    replay_read(read_session(path)?)
}

/// Replays a session log already read (e.g. by [`crate::log::read_session_bytes`]).
pub fn replay_read(session: SessionRead) -> Result<Replay, ReplayError> {
    let path = session.path.clone();
    let path = path.as_path();
    let rec = recording(&session)?;
    let mut summary = SessionSummary {
        blocks: rec.blocks.len() as u64,
        rig_seconds: rec.rig_seconds(),
        ..SessionSummary::default()
    };
    let cut = damaged_or_cut(&session);
    let mut steps_lost = Vec::new();
    for e in &rec.events {
        summary.apply_event(e);
        if let EventKind::RecordEnd { info } = &e.kind {
            if cut && window_counts(&rec, info).is_none() {
                steps_lost.push(format!("{} step {}", info.test, info.step + 1));
                continue;
            }
            let counts = window_counts(&rec, info).ok_or_else(|| {
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
    let logged_steps = decode_or_none(&session, TOPIC_STEPS)?;
    let rig_toml = session
        .attachment(RIG_ATTACHMENT)
        .map(|a| String::from_utf8_lossy(&a.data).into_owned());
    mark_missing(&mut summary, &session, &rec, steps_lost);
    Ok(Replay {
        summary,
        logged_steps,
        layout: rec.layout.clone(),
        complete: session.complete,
        note: session.note,
        rig_toml,
        recording: rec,
    })
}

/// Marks `summary` incomplete with what is missing when the log was cut off or damaged, or the
/// session did not log its end; a session cut off while it ran is marked aborted.
fn mark_missing(
    summary: &mut SessionSummary,
    session: &SessionRead,
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
    let steps_planned = session.attachment(PLAN_ATTACHMENT).and_then(|a| {
        let text = String::from_utf8_lossy(&a.data);
        crate::plan::Plan::from_str(&text, "plan.toml (attached to the log)")
            .ok()
            .map(|p| p.tests.iter().map(|t| t.steps as usize).sum::<usize>())
    });
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
