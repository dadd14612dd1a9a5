//! The session log: one MCAP file per session with the raw DAQ blocks, control state, step
//! boundaries, twin outputs and comparisons as JSON messages (JSON Schema per channel, the
//! encoding the Foxglove app and the official MCAP readers understand), plus metadata records
//! and attachments (session info, rig configuration, ROM identity).
//!
//! - [`writer`]: [`SessionLog::create`] opens the file; [`LogHandle`] registers channels and
//!   queues messages without ever blocking ([`LogError::Backlog`] when the queue is full);
//!   [`LogJoin::close`] finishes the file.
//! - `task` (private): the writer thread that owns the file and flushes at least every
//!   [`LogOptions::flush_interval`], so a crash loses at most the last interval.
//! - [`reader`]: [`read_session`] reads a file back, also one cut off by a crash.
//! - `scan` (private): the record walk that recovers truncated files.
//! - [`staged`]: outputs written under a temporary name and renamed into place.
//!
//! What goes into a session's log (its topics, the recorder, replay) is the session's
//! (`src/session/`); this module knows MCAP, not sessions.
//!
//! Every file carries a metadata record named [`RIGTWIN_METADATA`] with the crate version and
//! [`FORMAT_VERSION`]; [`SessionRead::require_rigtwin`] checks it.

mod error;
mod options;
pub mod reader;
mod scan;
pub mod staged;
mod task;
pub mod writer;

#[cfg(test)]
mod tests;

pub use error::{LogError, LogReadError};
pub use options::{Compression, LogOptions};
pub use reader::{
    read_session, read_session_bytes, stream_session, ChannelInfo, LoggedMessage, RigtwinInfo,
    SchemaInfo, SessionRead,
};
pub use staged::{stale_partials, write_atomically, Staged};
pub use writer::{
    Attachment, LogChannel, LogHandle, LogJoin, LogProgress, LogStats, MetadataRecord, RawChannel,
    SessionLog,
};

/// Name of the metadata record the writer adds to every session log (keys `crate_version`,
/// `format_version`, `message_encoding`, `schema_encoding`). Reserved for the writer.
pub const RIGTWIN_METADATA: &str = "rigtwin";

/// Version of the session log layout (channels, encodings, metadata); bumped when readers
/// must change. History:
/// - 1: DAQ blocks, control state, events, rig status, steps; the twin's status and steps.
/// - 2: `/rig/status` messages carry the rig's time as `block_time` (was a second `time`
///   key); steps carry `spectrum_upper`; the twin's predicted channels on `/twin/blocks`.
///   Readers of version 2 read version 1 logs (the new fields default).
pub const FORMAT_VERSION: u32 = 2;

/// Rig time (s) as MCAP log time (ns); negative times are logged at 0.
pub fn log_time_ns(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}

/// Message encoding of every rigtwin channel.
pub const MESSAGE_ENCODING: &str = "json";

/// Schema encoding of every rigtwin channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";
