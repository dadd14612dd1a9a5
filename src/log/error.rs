//! Errors of the session log: [`LogError`] for writing, [`LogReadError`] for reading. Every
//! message names the file and says what went wrong.

use std::path::PathBuf;

/// Errors of writing a session log.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The log file could not be created or written.
    #[error("session log {path}: {what}: {source}")]
    Io {
        /// The log file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The log options are out of range.
    #[error("session log {path}: bad options: {reason}")]
    Options {
        /// The log file.
        path: PathBuf,
        /// The option, its value and what was expected.
        reason: Box<crate::config::SpecError>,
    },
    /// The MCAP writer refused a record (e.g. too many channels) or failed to write it.
    #[error("session log {path}: {what}: {source}")]
    Mcap {
        /// The log file.
        path: PathBuf,
        /// What was being written.
        what: String,
        /// The MCAP error.
        source: mcap::McapError,
    },
    /// The writer queue was full: the writer thread is behind (slow disk). The message was
    /// dropped, its sequence number stays unused (a gap in the file marks the loss); the caller
    /// decides whether to abort.
    #[error(
        "session log {path}: writer queue full ({capacity} messages), message on {topic} \
         dropped: the disk is slower than the data rate"
    )]
    Backlog {
        /// The log file.
        path: PathBuf,
        /// Topic of the dropped message.
        topic: String,
        /// Queue capacity, messages.
        capacity: usize,
    },
    /// A value could not be serialised to JSON.
    #[error("session log {path}: cannot serialise a message on {topic} to JSON: {source}")]
    Serialize {
        /// The log file.
        path: PathBuf,
        /// Topic of the message.
        topic: String,
        /// The serde error.
        source: serde_json::Error,
    },
    /// A topic was registered twice with different schemas.
    #[error(
        "session log {path}: topic {topic} is already registered with schema {existing}, \
         not {requested}; use one message type per topic"
    )]
    TopicConflict {
        /// The log file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Schema name of the first registration.
        existing: String,
        /// Schema name of the rejected registration.
        requested: String,
    },
    /// A channel of another session log was passed to this log's handle.
    #[error("session log {path}: channel {topic} belongs to another session log")]
    ForeignChannel {
        /// The log file.
        path: PathBuf,
        /// The channel's topic.
        topic: String,
    },
    /// The caller passed a metadata record with the name the writer reserves for itself.
    #[error(
        "session log {path}: metadata record name {name:?} is reserved for the writer's own \
         record; choose another name"
    )]
    ReservedMetadata {
        /// The log file.
        path: PathBuf,
        /// The reserved name.
        name: String,
    },
    /// The log was closed or the writer thread stopped; nothing more can be written.
    #[error("session log {path}: writer stopped ({reason}); the message was not logged")]
    Closed {
        /// The log file.
        path: PathBuf,
        /// Why the writer stopped.
        reason: String,
    },
    /// The writer thread panicked.
    #[error("session log {path}: writer thread panicked; the file may lack its summary")]
    WriterPanicked {
        /// The log file.
        path: PathBuf,
    },
}

/// Errors of reading a session log. A file cut off by a crash is not an error: the reader
/// returns what it holds and marks the session incomplete. Nor is damage after writing (a
/// chunk failing its CRC, a record that does not parse): the reader skips it, salvages the
/// rest and describes what was lost in the session's note, so no variant stands for it.
#[derive(Debug, thiserror::Error)]
pub enum LogReadError {
    /// The file could not be opened or read.
    #[error("session log {path}: cannot read the file: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is empty.
    #[error("session log {path}: the file is empty (0 bytes), not an MCAP session log")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// The file does not start with the MCAP magic.
    #[error(
        "session log {path}: not an MCAP file: it starts with {found}, an MCAP file starts \
         with 89 4D 43 41 50 30 0D 0A (\"\\x89MCAP0\\r\\n\")"
    )]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// The first bytes, described (hex, and text when printable).
        found: String,
    },
    /// The file ends inside the MCAP magic: the writer died before writing anything.
    #[error(
        "session log {path}: only {len} bytes, cut off inside the MCAP magic: nothing was \
         logged (the writer stopped right after creating the file)"
    )]
    TruncatedMagic {
        /// The file.
        path: PathBuf,
        /// File length, bytes.
        len: usize,
    },
    /// The MCAP file was not written by rigtwin (no "rigtwin" metadata record), or by a newer
    /// rigtwin with a format this version cannot read.
    #[error("session log {path}: not a rigtwin session log: {detail}")]
    NotRigtwin {
        /// The file.
        path: PathBuf,
        /// What is missing or wrong.
        detail: String,
    },
    /// No channel with the requested topic.
    #[error("session log {path}: no channel with topic {topic:?} (topics: {known})")]
    UnknownTopic {
        /// The file.
        path: PathBuf,
        /// The requested topic.
        topic: String,
        /// The topics in the file, comma separated.
        known: String,
    },
    /// A message could not be decoded into the requested type.
    #[error(
        "session log {path}: topic {topic}, message {index} (sequence {sequence}): cannot \
         decode as {type_name}: {source}"
    )]
    Decode {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Index of the message among the topic's messages (0-based, file order).
        index: usize,
        /// The message's sequence number.
        sequence: u32,
        /// The requested Rust type.
        type_name: &'static str,
        /// The serde error.
        source: serde_json::Error,
    },
}
