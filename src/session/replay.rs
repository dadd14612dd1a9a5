//! Replay of a recorded session: every per-step metric recomputed from the raw DAQ blocks of
//! the log with the live session's own code ([`crate::control::summarize`]), and the session
//! summary rebuilt from the logged events. For a session that ran to its end (or aborted
//! cleanly) the result equals the live summary bit for bit. The twin re-run on a recording is
//! the sibling module `twin_replay`'s.

use std::path::Path;

use crate::config::RigConfig;
use crate::control::{summarize, EventKind, SessionEvent, StepInfo};
use crate::log::{read_session, LogReadError, SessionRead};
use crate::rig::{DaqBlock, DaqLayout};
use crate::rom::Rom;
use crate::twin::{TwinModel, TwinSpec};

use super::summary::SessionSummary;
use super::topics::{
    StepMessage, RIG_ATTACHMENT, TOPIC_DAQ, TOPIC_EVENTS, TOPIC_LAYOUT, TOPIC_STEPS,
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
    /// Blocks, in sequence order.
    pub blocks: Vec<DaqBlock>,
    /// Events, in order.
    pub events: Vec<SessionEvent>,
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

/// Decodes the layout, the DAQ blocks and the events of a session log.
pub fn recording(session: &SessionRead) -> Result<Recording, ReplayError> {
    let path = &session.path;
    session.require_rigtwin()?;
    let layout = session
        .decode::<DaqLayout>(TOPIC_LAYOUT)?
        .into_iter()
        .next()
        .map(|(_, _, l)| l)
        .ok_or_else(|| {
            content(
                path,
                format!("no {TOPIC_LAYOUT} message: not a session log"),
            )
        })?;
    let blocks: Vec<DaqBlock> = session
        .decode::<DaqBlock>(TOPIC_DAQ)?
        .into_iter()
        .map(|(_, _, b)| b)
        .collect();
    for (i, b) in blocks.iter().enumerate() {
        if b.seq != i as u64 {
            return Err(content(
                path,
                format!("{TOPIC_DAQ}: block {} where {i} was due (lost data)", b.seq),
            ));
        }
        b.check(&layout).map_err(|e| content(path, e.to_string()))?;
    }
    let events = session
        .decode::<SessionEvent>(TOPIC_EVENTS)?
        .into_iter()
        .map(|(_, _, e)| e)
        .collect();
    Ok(Recording {
        layout,
        blocks,
        events,
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
    let session = read_session(path)?;
    let rec = recording(&session)?;
    let mut summary = SessionSummary {
        blocks: rec.blocks.len() as u64,
        rig_seconds: rec.rig_seconds(),
        ..SessionSummary::default()
    };
    for e in &rec.events {
        summary.apply_event(e);
        if let EventKind::RecordEnd { info } = &e.kind {
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
    let logged_steps = session
        .decode::<StepMessage>(TOPIC_STEPS)?
        .into_iter()
        .map(|(_, _, m)| m)
        .collect();
    let rig_toml = session
        .attachment(RIG_ATTACHMENT)
        .map(|a| String::from_utf8_lossy(&a.data).into_owned());
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
