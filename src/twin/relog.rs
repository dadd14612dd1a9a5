//! A copy of a session log with a re-run twin's output (`rigtwin replay --twin --out NEW.mcap`):
//! every message, metadata record and attachment of the original except the recorded twin's
//! topics (`/twin/...`), then the re-run twin's `/twin/blocks` and `/twin/steps`, and a
//! `twin_replay` metadata record naming the model. `rigtwin report NEW.mcap` draws the re-run
//! twin beside the measurement, as it draws a live twin's.

use std::path::Path;

use crate::control::StepInfo;
use crate::log::{
    Attachment, LogChannel, LogHandle, LogJoin, LogOptions, LogStats, MetadataRecord, SessionLog,
    SessionRead, RIGTWIN_METADATA,
};

use super::compare::TwinSink;
use super::output::{TwinSamples, TOPIC_TWIN_BLOCKS};
use super::{TwinBlock, TwinComparison, TwinError, TwinStepMessage, TOPIC_TWIN_STEPS};

/// Name of the metadata record that says which model the copy's twin ran.
pub const TWIN_REPLAY_METADATA: &str = "twin_replay";

/// Topics of the recorded twin, left out of the copy.
fn is_twin_topic(topic: &str) -> bool {
    topic.starts_with("/twin/")
}

/// The copy being written (see the module documentation).
pub struct TwinLogCopy {
    handle: LogHandle,
    join: LogJoin,
    blocks: LogChannel<TwinSamples>,
    steps: LogChannel<TwinStepMessage>,
    /// DAQ sample interval, s (log time of a step's comparison).
    dt: f64,
}

impl std::fmt::Debug for TwinLogCopy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwinLogCopy")
            .field("path", &self.handle.path())
            .finish()
    }
}

fn log_error(e: impl std::fmt::Display) -> TwinError {
    TwinError::Log(e.to_string())
}

impl TwinLogCopy {
    /// Creates `path` and copies `session` into it (all but its twin topics); the twin's output
    /// follows through [`TwinSink`]. `model` says which model the twin runs (for the metadata),
    /// `dt` is the DAQ sample interval, s.
    pub fn create(
        path: &Path,
        session: &SessionRead,
        model: &str,
        dt: f64,
    ) -> Result<TwinLogCopy, TwinError> {
        if let (Ok(a), Ok(b)) = (path.canonicalize(), session.path.canonicalize()) {
            if a == b {
                return Err(TwinError::Log(format!(
                    "{}: the copy would overwrite the session it is made from; name another file",
                    path.display()
                )));
            }
        }
        let mut metadata: Vec<MetadataRecord> = session
            .metadata
            .iter()
            .filter(|(name, _)| name != RIGTWIN_METADATA && name != TWIN_REPLAY_METADATA)
            .cloned()
            .collect();
        metadata.push((
            TWIN_REPLAY_METADATA.into(),
            [
                ("model".to_string(), model.to_string()),
                ("source_log".to_string(), session.path.display().to_string()),
            ]
            .into_iter()
            .collect(),
        ));
        let attachments: Vec<Attachment> = session.attachments.clone();
        let (handle, join) = SessionLog::create(path, LogOptions::default(), metadata, attachments)
            .map_err(log_error)?;
        let mut channels = std::collections::BTreeMap::new();
        for c in session.channels.iter().filter(|c| !is_twin_topic(&c.topic)) {
            let Some(schema) = &c.schema else {
                return Err(TwinError::Log(format!(
                    "{}: channel {} has no schema; only rigtwin session logs can be copied",
                    session.path.display(),
                    c.topic
                )));
            };
            let raw = handle
                .raw_channel(&c.topic, &schema.name, schema.data.clone())
                .map_err(log_error)?;
            channels.insert(c.id, raw);
        }
        for m in &session.messages {
            if let Some(raw) = channels.get(&m.channel_id) {
                handle
                    .log_json_waiting(raw, m.log_time, m.data.clone())
                    .map_err(log_error)?;
            }
        }
        Ok(TwinLogCopy {
            blocks: handle.channel(TOPIC_TWIN_BLOCKS).map_err(log_error)?,
            steps: handle.channel(TOPIC_TWIN_STEPS).map_err(log_error)?,
            handle,
            join,
            dt,
        })
    }

    /// Finishes the file.
    pub fn close(self) -> Result<LogStats, TwinError> {
        drop(self.handle);
        self.join.close().map_err(log_error)
    }

    fn put<T: serde::Serialize>(
        &self,
        channel: &LogChannel<T>,
        time: f64,
        value: &T,
    ) -> Result<(), TwinError> {
        let json = serde_json::to_vec(value).map_err(log_error)?;
        self.handle
            .log_json_waiting(channel.raw(), crate::log::recorder::log_time_ns(time), json)
            .map_err(log_error)
    }
}

impl TwinSink for TwinLogCopy {
    fn block(&mut self, block: &TwinBlock) -> Result<(), TwinError> {
        self.put(&self.blocks, block.time, &TwinSamples::from(block))
    }

    fn step(&mut self, info: &StepInfo, twin: Option<&TwinComparison>) -> Result<(), TwinError> {
        let time = TwinStepMessage::log_time(info, self.dt);
        self.put(&self.steps, time, &TwinStepMessage::of(info, twin))
    }
}
