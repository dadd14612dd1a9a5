//! Reading a session log back: [`read_session`] loads every message, channel, metadata record
//! and attachment of an MCAP file into a [`SessionRead`], also from a file cut off by a crash
//! (then `complete` is false and `note` says what was lost). Typed access by topic with
//! [`SessionRead::decode`]; [`SessionRead::require_rigtwin`] tells a rigtwin session from an
//! MCAP file written by another tool.
//!
//! [`stream_session`] reads a file of any length in bounded memory: it hands every message to
//! a visitor as the walk reaches it (a chunk at a time: the file is read record by record,
//! never whole) and keeps only the rest (channels, metadata, attachments: small). Both read
//! the file with the same walk (`scan`), so they see the same messages.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use serde::de::DeserializeOwned;

use super::scan::{scan, summary_channels, Input, ScanEnd};
use super::writer::{Attachment, MetadataRecord};
use super::{LogReadError, FORMAT_VERSION, RIGTWIN_METADATA};

/// A channel's schema.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema name (for rigtwin channels the Rust type's schema name, e.g. "DaqBlock").
    pub name: String,
    /// Schema encoding ("jsonschema" for rigtwin channels).
    pub encoding: String,
    /// The schema (a JSON Schema document for rigtwin channels).
    pub data: Vec<u8>,
}

/// A channel of the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelInfo {
    /// MCAP channel id.
    pub id: u16,
    /// Topic.
    pub topic: String,
    /// Message encoding ("json" for rigtwin channels).
    pub message_encoding: String,
    /// The schema, if the channel has one.
    pub schema: Option<SchemaInfo>,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
}

/// One message as stored.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoggedMessage {
    /// MCAP channel id.
    pub channel_id: u16,
    /// The channel's topic.
    pub topic: Arc<str>,
    /// Per-channel sequence number (0, 1, 2, ...; a gap marks a dropped message).
    pub sequence: u32,
    /// Log time, ns (rig time for rigtwin sessions).
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
    /// The payload (JSON for rigtwin channels).
    pub data: Vec<u8>,
}

/// Identity of the rigtwin writer of a session (its "rigtwin" metadata record).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RigtwinInfo {
    /// Version of the rigtwin crate that wrote the file.
    pub crate_version: String,
    /// Session log format version.
    pub format_version: u32,
}

/// The contents of a session log.
#[derive(Clone, Debug)]
pub struct SessionRead {
    /// The file.
    pub path: PathBuf,
    /// Whether the file was closed properly (footer and closing magic present).
    pub complete: bool,
    /// For an incomplete file: what was lost at its end, for people.
    pub note: Option<String>,
    /// Damaged regions the reader skipped (chunks failing their CRC, records that do not
    /// parse, a damaged summary), for people; empty for an intact file. What they cost is in
    /// the data: missing sequence numbers.
    pub damage: Vec<String>,
    /// File size, bytes.
    pub file_bytes: u64,
    /// Bytes up to the end of the last complete record, bytes.
    pub valid_bytes: u64,
    /// The header's profile.
    pub profile: String,
    /// The header's library (the writer).
    pub library: String,
    /// Channels in order of appearance.
    pub channels: Vec<ChannelInfo>,
    /// Every message, in file order (empty from [`stream_session`], which hands them over).
    pub messages: Vec<LoggedMessage>,
    /// Metadata records, in file order.
    pub metadata: Vec<MetadataRecord>,
    /// Attachments, in file order.
    pub attachments: Vec<Attachment>,
}

/// Reads the session log at `path` (every message into memory; the file is read a record at
/// a time), recovering what a crash left.
pub fn read_session(path: impl AsRef<Path>) -> Result<SessionRead, LogReadError> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|source| LogReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut input = Input::file(&file, path)?;
    read_input(path, &mut input)
}

/// Like [`read_session`] for a file already in memory; `path` names it in errors.
pub fn read_session_bytes(path: &Path, bytes: &[u8]) -> Result<SessionRead, LogReadError> {
    read_input(path, &mut Input::Memory(bytes))
}

fn read_input(path: &Path, input: &mut Input<'_>) -> Result<SessionRead, LogReadError> {
    let mut builder = Builder::default();
    let end = scan(path, input, |offset, record| {
        if let Err((opcode, reason)) = builder.add(record) {
            builder.damage.push(format!(
                "byte offset {offset}: record (opcode {opcode:#04x}) ignored: {reason}"
            ));
        }
        Ok::<(), LogReadError>(())
    })?;
    builder.resolve_orphans();
    let messages = std::mem::take(&mut builder.messages);
    Ok(builder.finish(path, end, input.len() as u64, messages))
}

/// Reads the session log at `path` in bounded memory: every message goes to `visit` in file
/// order as the walk reaches it, with its topic (also one whose channel record was lost with
/// a damaged chunk, when the summary section names it), and is not kept. Returns the rest: a
/// [`SessionRead`] whose `messages` is empty. The file is read a record at a time (at most one
/// chunk and its decompressed records are held). Errors of `visit` stop the walk.
///
/// The same messages as [`read_session`] reaches, in the same order, except a message whose
/// channel is defined only after it in the data section and not in the summary (the writer
/// never does that): [`read_session`] keeps it, this drops it and says so in `damage`.
pub fn stream_session<E: From<LogReadError>>(
    path: &Path,
    mut visit: impl FnMut(&LoggedMessage) -> Result<(), E>,
) -> Result<SessionRead, E> {
    let file = std::fs::File::open(path).map_err(|source| LogReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut input = Input::file(&file, path)?;
    // The channels the summary defines: a message whose channel record was in a damaged chunk
    // gets its topic where it is read (read_session resolves such orphans at the end).
    let mut known = Builder::default();
    if input.len() > 0 {
        for record in summary_channels(&mut input)? {
            // NOTE: an inconsistent summary record is ignored here; the walk reports it.
            let _ = known.add(record);
        }
    }
    let mut builder = Builder {
        stream: true,
        ..Builder::default()
    };
    let mut dropped = 0usize;
    let end = scan(path, &mut input, |offset, record| -> Result<(), E> {
        match builder.add(record) {
            Err((opcode, reason)) => builder.damage.push(format!(
                "byte offset {offset}: record (opcode {opcode:#04x}) ignored: {reason}"
            )),
            Ok(Some(mut m)) => {
                if &*m.topic == NO_TOPIC {
                    match known.channel_index.get(&m.channel_id) {
                        Some(&c) => m.topic = Arc::clone(&known.channels[c].1),
                        None => {
                            dropped += 1;
                            return Ok(());
                        }
                    }
                }
                visit(&m)?;
            }
            Ok(None) => {}
        }
        Ok(())
    })?;
    if dropped > 0 {
        builder.damage.push(format!(
            "{dropped} messages on channels not defined before them in the readable file (nor \
             in its summary) were dropped"
        ));
    }
    Ok(builder.finish(path, end, input.len() as u64, Vec::new()))
}

/// Collects records into the parts of a [`SessionRead`].
#[derive(Default)]
struct Builder {
    profile: String,
    library: String,
    schemas: HashMap<u16, SchemaInfo>,
    /// Channels with their topic, shared by their messages.
    channels: Vec<(ChannelInfo, Arc<str>)>,
    channel_index: HashMap<u16, usize>,
    messages: Vec<LoggedMessage>,
    metadata: Vec<MetadataRecord>,
    attachments: Vec<Attachment>,
    /// Indices of messages whose channel was not yet defined where they were read (its chunk
    /// was damaged): resolved against the summary's channels at the end.
    orphans: Vec<usize>,
    /// Records that did not fit (damage), for people.
    damage: Vec<String>,
    /// Messages are handed back by [`Builder::add`] instead of kept (orphans with an empty
    /// topic).
    stream: bool,
}

/// The topic of a message whose channel is not known yet.
const NO_TOPIC: &str = "";

impl Builder {
    /// The [`SessionRead`] of file `path` (`file_bytes` long) whose walk ended as `end`, with
    /// `messages` (the builder's damage joins the walk's).
    fn finish(
        mut self,
        path: &Path,
        mut end: ScanEnd,
        file_bytes: u64,
        messages: Vec<LoggedMessage>,
    ) -> SessionRead {
        end.damage.append(&mut self.damage);
        SessionRead {
            path: path.to_path_buf(),
            complete: end.complete,
            note: end.lost,
            damage: end.damage,
            file_bytes,
            valid_bytes: end.valid_bytes,
            profile: self.profile,
            library: self.library,
            channels: self.channels.into_iter().map(|(c, _)| c).collect(),
            messages,
            metadata: self.metadata,
            attachments: self.attachments,
        }
    }

    /// Gives orphaned messages the topic of their channel (defined later, e.g. in the
    /// summary); drops those whose channel never appears.
    fn resolve_orphans(&mut self) {
        if self.orphans.is_empty() {
            return;
        }
        let mut lost = 0usize;
        for &i in &self.orphans {
            let m = &mut self.messages[i];
            if let Some(&c) = self.channel_index.get(&m.channel_id) {
                m.topic = Arc::clone(&self.channels[c].1);
            } else {
                lost += 1;
            }
        }
        if lost > 0 {
            self.damage.push(format!(
                "{lost} messages on channels defined nowhere in the readable file were dropped"
            ));
            self.messages.retain(|m| &*m.topic != NO_TOPIC);
        }
    }

    /// Takes one record (a message is handed back when streaming); on an inconsistency its
    /// opcode and what is wrong.
    fn add(&mut self, record: Record<'static>) -> Result<Option<LoggedMessage>, (u8, String)> {
        use mcap::records::op;
        match record {
            Record::Header(h) => {
                self.profile = h.profile;
                self.library = h.library;
            }
            Record::Schema { header, data } => {
                let schema = SchemaInfo {
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                };
                match self.schemas.get(&header.id) {
                    Some(known) if *known != schema => {
                        return Err((
                            op::SCHEMA,
                            format!("schema {} redefined differently", header.id),
                        ))
                    }
                    Some(_) => {}
                    None => {
                        self.schemas.insert(header.id, schema);
                    }
                }
            }
            Record::Channel(c) => {
                let schema = match c.schema_id {
                    0 => None,
                    id => Some(self.schemas.get(&id).cloned().ok_or_else(|| {
                        (
                            op::CHANNEL,
                            format!("channel {} refers to unknown schema {id}", c.topic),
                        )
                    })?),
                };
                let info = ChannelInfo {
                    id: c.id,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                    schema,
                    metadata: c.metadata,
                };
                match self.channel_index.get(&c.id) {
                    Some(&i) if self.channels[i].0 != info => {
                        return Err((
                            op::CHANNEL,
                            format!("channel {} redefined differently", c.id),
                        ))
                    }
                    Some(_) => {}
                    None => {
                        self.channel_index.insert(c.id, self.channels.len());
                        let topic: Arc<str> = info.topic.as_str().into();
                        self.channels.push((info, topic));
                    }
                }
            }
            Record::Message { header, data } => {
                let topic = match self.channel_index.get(&header.channel_id) {
                    Some(&i) => Arc::clone(&self.channels[i].1),
                    None => {
                        if !self.stream {
                            self.orphans.push(self.messages.len());
                        }
                        NO_TOPIC.into()
                    }
                };
                let m = LoggedMessage {
                    channel_id: header.channel_id,
                    topic,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: data.into_owned(),
                };
                if self.stream {
                    return Ok(Some(m));
                }
                self.messages.push(m);
            }
            Record::Metadata(m) => self.metadata.push((m.name, m.metadata)),
            Record::Attachment { header, data, .. } => self.attachments.push(Attachment {
                name: header.name,
                media_type: header.media_type,
                data: data.into_owned(),
            }),
            // Indexes, statistics, data end, footer and unknown records carry nothing the
            // session needs.
            _ => {}
        }
        Ok(None)
    }
}

impl SessionRead {
    /// The channel with topic `topic` (the first, if several).
    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.iter().find(|c| c.topic == topic)
    }

    /// The messages on `topic`, in file order.
    pub fn messages_on<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a LoggedMessage> {
        self.messages.iter().filter(move |m| &*m.topic == topic)
    }

    /// The entries of the first metadata record called `name`.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, entries)| entries)
    }

    /// The first attachment called `name`.
    pub fn attachment(&self, name: &str) -> Option<&Attachment> {
        self.attachments.iter().find(|a| a.name == name)
    }

    /// Decodes every message on `topic` as `T` (JSON): `(log_time ns, sequence, value)` in
    /// file order. A topic without channel is an error; a channel without messages gives an
    /// empty vector.
    pub fn decode<T: DeserializeOwned>(
        &self,
        topic: &str,
    ) -> Result<Vec<(u64, u64, T)>, LogReadError> {
        if self.channel(topic).is_none() {
            let known: Vec<&str> = self.channels.iter().map(|c| c.topic.as_str()).collect();
            return Err(LogReadError::UnknownTopic {
                path: self.path.clone(),
                topic: topic.to_string(),
                known: if known.is_empty() {
                    "none".to_string()
                } else {
                    known.join(", ")
                },
            });
        }
        self.messages_on(topic)
            .enumerate()
            .map(|(index, m)| {
                serde_json::from_slice(&m.data)
                    .map(|value| (m.log_time, u64::from(m.sequence), value))
                    .map_err(|source| LogReadError::Decode {
                        path: self.path.clone(),
                        topic: topic.to_string(),
                        index,
                        sequence: m.sequence,
                        type_name: std::any::type_name::<T>(),
                        source,
                    })
            })
            .collect()
    }

    /// Checks that rigtwin wrote the file (its "rigtwin" metadata record) in a format this
    /// version reads, and returns the writer's identity.
    pub fn require_rigtwin(&self) -> Result<RigtwinInfo, LogReadError> {
        let not_rigtwin = |detail: String| LogReadError::NotRigtwin {
            path: self.path.clone(),
            detail,
        };
        let Some(entries) = self.metadata(RIGTWIN_METADATA) else {
            let mut detail = format!("the MCAP file has no {RIGTWIN_METADATA:?} metadata record");
            if !self.library.is_empty() {
                detail.push_str(&format!(" (written by {:?})", self.library));
            }
            if let Some(note) = self.note.as_deref().filter(|_| self.metadata.is_empty()) {
                detail.push_str(&format!("; the file is incomplete: {note}"));
            }
            return Err(not_rigtwin(detail));
        };
        let crate_version = entries.get("crate_version").cloned().unwrap_or_default();
        let format_version = entries
            .get("format_version")
            .and_then(|v| v.parse::<u32>().ok())
            .ok_or_else(|| {
                not_rigtwin(format!(
                    "its {RIGTWIN_METADATA:?} metadata record has no numeric format_version"
                ))
            })?;
        if format_version > FORMAT_VERSION {
            return Err(not_rigtwin(format!(
                "it has format version {format_version} (rigtwin {crate_version}), this \
                 rigtwin reads up to {FORMAT_VERSION}: update rigtwin"
            )));
        }
        Ok(RigtwinInfo {
            crate_version,
            format_version,
        })
    }
}
