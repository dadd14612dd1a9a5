//! The caller side of the session log: [`SessionLog::create`] opens the file and starts the
//! writer thread; [`LogHandle`] registers channels and hands messages to the thread without
//! ever waiting; [`LogJoin`] closes the log and returns its [`LogStats`].
//!
//! Messages are serialised to JSON on the caller's thread and queued on a bounded channel with
//! `try_send`: a full queue is reported as [`LogError::Backlog`], never waited on, so the
//! control loop cannot stall on a slow disk. The writer thread (`task.rs`) owns the file.
//!
//! The file is written under a temporary name beside its destination ([`Staged`]) and renamed
//! into place by [`LogHandle::publish`] (a session does that when it starts) or by a successful
//! [`LogJoin::close`]; a log that is never published is removed, so a session that fails before
//! it starts leaves an existing file of that name untouched.

use std::collections::{BTreeMap, HashMap};
use std::io::BufWriter;
use std::marker::PhantomData;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, Weak};
use std::thread::JoinHandle;

use serde::Serialize;

use super::staged::Staged;
use super::task::{Command, Progress, ThreadShared, WriterOutcome, WriterTask};
use super::{
    LogError, LogOptions, FORMAT_VERSION, MESSAGE_ENCODING, RIGTWIN_METADATA, SCHEMA_ENCODING,
};

/// A file stored in the session log (e.g. the rig configuration TOML).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Attachment {
    /// File name (e.g. "rig.toml").
    pub name: String,
    /// Media type (e.g. "application/toml", "application/octet-stream").
    pub media_type: String,
    /// The content.
    pub data: Vec<u8>,
}

/// A metadata record: a name and string key-value pairs (e.g. "session", "rom").
pub type MetadataRecord = (String, BTreeMap<String, String>);

/// Opens session logs.
pub struct SessionLog;

impl SessionLog {
    /// Creates the MCAP file for `path` (under a temporary name until published: see the
    /// module documentation), writes the header, the writer's own
    /// "rigtwin" metadata record (crate and format version), then `metadata` and
    /// `attachments` in order, flushes them to the OS and starts the writer thread.
    ///
    /// The name "rigtwin" is reserved for the writer's record. Returns the handle to log with
    /// (clone it for other tasks) and the join side that closes the log.
    pub fn create(
        path: impl AsRef<Path>,
        options: LogOptions,
        metadata: Vec<MetadataRecord>,
        attachments: Vec<Attachment>,
    ) -> Result<(LogHandle, LogJoin), LogError> {
        let path = path.as_ref().to_path_buf();
        options.check().map_err(|reason| LogError::Options {
            path: path.clone(),
            reason: Box::new(reason),
        })?;
        if let Some((name, _)) = metadata.iter().find(|(n, _)| n == RIGTWIN_METADATA) {
            return Err(LogError::ReservedMetadata {
                path,
                name: name.clone(),
            });
        }
        let mcap_err = |what: String| {
            let path = path.clone();
            move |source| LogError::Mcap { path, what, source }
        };
        let (file, staged) = Staged::create(&path).map_err(|source| LogError::Io {
            path: path.clone(),
            what: "cannot create the file",
            source,
        })?;
        let mut write_options = mcap::WriteOptions::new()
            .compression(options.compression.to_mcap())
            .chunk_size(Some(options.chunk_size_bytes))
            .library(format!(
                "rigtwin/{} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        // NOTE: zstd's worker threads would compete with the control loop for the cores; the
        // writer thread compresses on its own.
        write_options = write_options.compression_threads(0);
        let mut writer = write_options
            .create(BufWriter::new(file))
            .map_err(mcap_err("cannot write the MCAP header".into()))?;

        let own = BTreeMap::from([
            (
                "crate_version".to_string(),
                env!("CARGO_PKG_VERSION").to_string(),
            ),
            ("format_version".to_string(), FORMAT_VERSION.to_string()),
            ("message_encoding".to_string(), MESSAGE_ENCODING.to_string()),
            ("schema_encoding".to_string(), SCHEMA_ENCODING.to_string()),
        ]);
        for (name, entries) in std::iter::once((RIGTWIN_METADATA.to_string(), own)).chain(metadata)
        {
            let record = mcap::records::Metadata {
                name,
                metadata: entries,
            };
            writer.write_metadata(&record).map_err(mcap_err(format!(
                "cannot write metadata record {}",
                record.name
            )))?;
        }
        for a in attachments {
            let record = mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: a.name,
                media_type: a.media_type,
                data: a.data.into(),
            };
            writer
                .attach(&record)
                .map_err(mcap_err(format!("cannot write attachment {}", record.name)))?;
        }
        writer
            .flush()
            .map_err(mcap_err("cannot flush the header".into()))?;

        let shared = Arc::new(Shared {
            thread: Arc::new(ThreadShared {
                path: path.clone(),
                closed: AtomicBool::new(false),
                failure: OnceLock::new(),
                progress: Progress::default(),
            }),
            capacity: options.queue_capacity,
            registry: Mutex::new(Registry::default()),
            backlog_drops: AtomicU64::new(0),
            staged: Mutex::new(staged),
        });
        let (tx, rx) = mpsc::sync_channel(shared.capacity);
        let task = WriterTask::new(writer, Arc::clone(&shared.thread), options.flush_interval);
        let thread = std::thread::Builder::new()
            .name("rigtwin-log".into())
            .spawn(move || task.run(rx))
            .map_err(|source| LogError::Io {
                path: path.clone(),
                what: "cannot start the writer thread",
                source,
            })?;
        let inner = Arc::new(HandleInner {
            tx,
            shared: Arc::clone(&shared),
        });
        let join = LogJoin {
            handle: Arc::downgrade(&inner),
            shared,
            thread,
        };
        Ok((LogHandle { inner }, join))
    }
}

/// State shared by the handles and the join side; the part the writer thread sees is
/// [`ThreadShared`].
pub(super) struct Shared {
    /// What the writer thread shares: the path, the closed flag, the failure, the progress.
    pub(super) thread: Arc<ThreadShared>,
    /// Queue capacity, messages.
    pub(super) capacity: usize,
    /// The registered channels.
    pub(super) registry: Mutex<Registry>,
    /// Messages dropped because the queue was full.
    pub(super) backlog_drops: AtomicU64,
    /// The file's temporary name and destination; removed with the last reference unless
    /// published.
    pub(super) staged: Mutex<Staged>,
}

impl Shared {
    /// Renames the file into place (once).
    fn publish(&self) -> Result<(), LogError> {
        self.staged
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .publish()
            .map_err(|source| LogError::Io {
                path: self.thread.path.clone(),
                what: "cannot move the file into place",
                source,
            })
    }

    /// Where the file is now: the destination once published, else its temporary name.
    fn current_path(&self) -> std::path::PathBuf {
        let staged = self.staged.lock().unwrap_or_else(PoisonError::into_inner);
        if staged.is_published() {
            staged.dest().to_path_buf()
        } else {
            staged.temp().to_path_buf()
        }
    }

    fn closed_error(&self) -> LogError {
        let path = &self.thread.path;
        // The failure is a log error that names the file already: said once.
        let prefix = format!("session log {}: ", path.display());
        let reason = match self.thread.failure.get() {
            Some(f) => f.strip_prefix(&prefix).unwrap_or(f).to_string(),
            None => "the log was closed".into(),
        };
        LogError::Closed {
            path: path.clone(),
            reason,
        }
    }
}

/// The registered channels, by topic.
#[derive(Default)]
pub(super) struct Registry {
    pub(super) by_topic: HashMap<String, RawChannel>,
}

/// Per-channel counters shared by every copy of a channel.
#[derive(Debug, Default)]
struct ChannelCounters {
    next_sequence: AtomicU32,
    drops: AtomicU64,
}

/// An MCAP channel of a session log, without a Rust type: messages are JSON bytes matching the
/// channel's schema. Obtained from [`LogHandle::raw_channel`] (or [`LogChannel::raw`]).
#[derive(Clone, Debug)]
pub struct RawChannel {
    id: u16,
    topic: Arc<str>,
    schema_name: Arc<str>,
    counters: Arc<ChannelCounters>,
    /// The log the channel belongs to (compared by address only).
    log: Weak<Shared>,
}

impl RawChannel {
    /// The topic.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The schema name.
    pub fn schema_name(&self) -> &str {
        &self.schema_name
    }

    /// Messages of this channel dropped because the writer queue was full.
    pub fn backlog_drops(&self) -> u64 {
        self.counters.drops.load(Ordering::Relaxed)
    }
}

/// A typed channel: messages of type `T`, JSON-encoded, with `T`'s JSON Schema.
#[derive(Debug)]
pub struct LogChannel<T> {
    raw: RawChannel,
    _type: PhantomData<fn(&T)>,
}

impl<T> Clone for LogChannel<T> {
    fn clone(&self) -> Self {
        Self {
            raw: self.raw.clone(),
            _type: PhantomData,
        }
    }
}

impl<T> LogChannel<T> {
    /// The topic.
    pub fn topic(&self) -> &str {
        self.raw.topic()
    }

    /// The untyped channel (to log pre-serialised JSON).
    pub fn raw(&self) -> &RawChannel {
        &self.raw
    }
}

struct HandleInner {
    tx: SyncSender<Command>,
    shared: Arc<Shared>,
}

/// Logs messages to a session log from any thread. Cheap to clone; `Send + Sync`.
///
/// When every handle is dropped the writer thread finishes the file (summary and footer);
/// [`LogJoin::close`] does the same explicitly and reports the outcome.
#[derive(Clone)]
pub struct LogHandle {
    inner: Arc<HandleInner>,
}

/// What the writer thread has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LogProgress {
    /// Messages handed to the MCAP writer.
    pub messages_written: u64,
    /// Messages in the file up to the last flush (what a crash now would keep).
    pub messages_flushed: u64,
    /// Flushes done (chunk finished and handed to the OS).
    pub flushes: u64,
    /// Messages dropped because the queue was full.
    pub backlog_drops: u64,
}

impl LogHandle {
    /// The log file (its destination).
    pub fn path(&self) -> &Path {
        &self.inner.shared.thread.path
    }

    /// Renames the file from its temporary name into place, replacing a file of that name;
    /// the writer goes on writing it. From then on the log is kept whatever happens (a crash
    /// leaves it at its own name). Later calls do nothing.
    pub fn publish(&self) -> Result<(), LogError> {
        self.inner.shared.publish()
    }

    /// Where the file is now: its destination once published, else its temporary name.
    pub fn current_path(&self) -> std::path::PathBuf {
        self.inner.shared.current_path()
    }

    /// Registers (or returns the existing) channel `topic` for messages of type `T`: message
    /// encoding "json", schema named after `T` (schemars' schema name) with encoding
    /// "jsonschema" and `T`'s JSON Schema as data.
    ///
    /// May wait for queue space: register channels at setup, not in the control loop.
    pub fn channel<T: Serialize + schemars::JsonSchema>(
        &self,
        topic: &str,
    ) -> Result<LogChannel<T>, LogError> {
        let schema = schemars::schema_for!(T);
        let data = serde_json::to_vec(&schema).map_err(|source| LogError::Serialize {
            path: self.inner.shared.thread.path.clone(),
            topic: topic.to_string(),
            source,
        })?;
        let raw = self.raw_channel(topic, &T::schema_name(), data)?;
        Ok(LogChannel {
            raw,
            _type: PhantomData,
        })
    }

    /// Registers (or returns the existing) channel `topic` with message encoding "json" and a
    /// "jsonschema" schema given as name and JSON bytes (for replay and re-logging tools).
    /// Registering a topic again with another schema is an error.
    ///
    /// May wait for queue space: register channels at setup, not in the control loop.
    pub fn raw_channel(
        &self,
        topic: &str,
        schema_name: &str,
        schema_json: Vec<u8>,
    ) -> Result<RawChannel, LogError> {
        let shared = &self.inner.shared;
        if shared.thread.closed.load(Ordering::Acquire) {
            return Err(shared.closed_error());
        }
        let mut registry = shared
            .registry
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(existing) = registry.by_topic.get(topic) {
            if &*existing.schema_name != schema_name {
                return Err(LogError::TopicConflict {
                    path: shared.thread.path.clone(),
                    topic: topic.to_string(),
                    existing: existing.schema_name.to_string(),
                    requested: schema_name.to_string(),
                });
            }
            return Ok(existing.clone());
        }
        let id = u16::try_from(registry.by_topic.len() + 1).map_err(|_| LogError::Mcap {
            path: shared.thread.path.clone(),
            what: format!("cannot register channel {topic}"),
            source: mcap::McapError::TooManyChannels,
        })?;
        // NOTE: sent under the registry lock so channel records reach the writer in id order
        // and before any message of the channel.
        self.inner
            .tx
            .send(Command::Channel {
                id,
                topic: topic.to_string(),
                schema_name: schema_name.to_string(),
                schema: schema_json,
            })
            .map_err(|_| shared.closed_error())?;
        let channel = RawChannel {
            id,
            topic: topic.into(),
            schema_name: schema_name.into(),
            counters: Arc::default(),
            log: Arc::downgrade(shared),
        };
        registry.by_topic.insert(topic.to_string(), channel.clone());
        Ok(channel)
    }

    /// Serialises `value` to JSON and queues it on `channel` with the next sequence number of
    /// the channel. `log_time_ns` is the rig time of the message, ns (also its publish time).
    ///
    /// Never blocks: a full queue returns [`LogError::Backlog`] (the message is dropped and
    /// counted, its sequence number stays unused); a closed log returns [`LogError::Closed`].
    pub fn log<T: Serialize>(
        &self,
        channel: &LogChannel<T>,
        log_time_ns: u64,
        value: &T,
    ) -> Result<(), LogError> {
        let data = serde_json::to_vec(value).map_err(|source| LogError::Serialize {
            path: self.inner.shared.thread.path.clone(),
            topic: channel.topic().to_string(),
            source,
        })?;
        self.log_json(&channel.raw, log_time_ns, data)
    }

    /// Queues pre-serialised JSON bytes on `channel` (not checked against the schema), like
    /// [`LogHandle::log`]. Never blocks.
    pub fn log_json(
        &self,
        channel: &RawChannel,
        log_time_ns: u64,
        json: Vec<u8>,
    ) -> Result<(), LogError> {
        self.queue_json(channel, log_time_ns, json, false)
    }

    /// Like [`LogHandle::log_json`], but waits for queue space instead of dropping: for
    /// offline tools that write a whole log as fast as they can (e.g. `rigtwin replay --out`).
    /// Never call it from a control loop.
    pub fn log_json_waiting(
        &self,
        channel: &RawChannel,
        log_time_ns: u64,
        json: Vec<u8>,
    ) -> Result<(), LogError> {
        self.queue_json(channel, log_time_ns, json, true)
    }

    fn queue_json(
        &self,
        channel: &RawChannel,
        log_time_ns: u64,
        json: Vec<u8>,
        wait: bool,
    ) -> Result<(), LogError> {
        let shared = &self.inner.shared;
        if !self.owns(channel) {
            return Err(LogError::ForeignChannel {
                path: shared.thread.path.clone(),
                topic: channel.topic.to_string(),
            });
        }
        if shared.thread.closed.load(Ordering::Acquire) {
            return Err(shared.closed_error());
        }
        let sequence = channel
            .counters
            .next_sequence
            .fetch_add(1, Ordering::Relaxed);
        let command = Command::Message {
            channel_id: channel.id,
            sequence,
            log_time: log_time_ns,
            data: json,
        };
        if wait {
            return self
                .inner
                .tx
                .send(command)
                .map_err(|_| shared.closed_error());
        }
        match self.inner.tx.try_send(command) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => {
                channel.counters.drops.fetch_add(1, Ordering::Relaxed);
                shared.backlog_drops.fetch_add(1, Ordering::Relaxed);
                Err(LogError::Backlog {
                    path: shared.thread.path.clone(),
                    topic: channel.topic.to_string(),
                    capacity: shared.capacity,
                })
            }
            Err(TrySendError::Disconnected(_)) => Err(shared.closed_error()),
        }
    }

    /// What the writer thread has done so far (for health displays and tests).
    pub fn progress(&self) -> LogProgress {
        self.inner.shared.progress_snapshot()
    }

    fn owns(&self, channel: &RawChannel) -> bool {
        std::ptr::eq(channel.log.as_ptr(), Arc::as_ptr(&self.inner.shared))
    }

    #[cfg(test)]
    pub(super) fn send_for_test(&self, command: Command) {
        // The test hook may wait: it is only used to stall the writer thread.
        let _ = self.inner.tx.send(command);
    }
}

impl Shared {
    fn progress_snapshot(&self) -> LogProgress {
        LogProgress {
            messages_written: self
                .thread
                .progress
                .messages_written
                .load(Ordering::Relaxed),
            messages_flushed: self
                .thread
                .progress
                .messages_flushed
                .load(Ordering::Relaxed),
            flushes: self.thread.progress.flushes.load(Ordering::Relaxed),
            backlog_drops: self.backlog_drops.load(Ordering::Relaxed),
        }
    }
}

/// What a closed session log holds.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LogStats {
    /// Messages written per topic (every registered topic, also those without messages).
    pub messages_per_topic: BTreeMap<String, u64>,
    /// Messages dropped because the writer queue was full, per topic (topics with drops).
    pub drops_per_topic: BTreeMap<String, u64>,
    /// Messages dropped because the writer queue was full, in total.
    pub backlog_drops: u64,
    /// Size of the finished file, bytes.
    pub bytes_written: u64,
    /// Flushes done (chunk finished and handed to the OS), including the final one.
    pub flushes: u64,
}

/// The writer side of a session log: closes it and reports the outcome. Dropping it without
/// closing leaves the writer thread running until every [`LogHandle`] is dropped.
pub struct LogJoin {
    handle: Weak<HandleInner>,
    shared: Arc<Shared>,
    thread: JoinHandle<Result<WriterOutcome, LogError>>,
}

impl LogJoin {
    /// Closes the log: later `log` calls fail with [`LogError::Closed`]; the writer thread
    /// writes what is queued, the summary and the footer, syncs the file to disk and stops;
    /// then the file is renamed into place if it was not yet published. Waits for that
    /// (blocking: from async code call it in `spawn_blocking`). Returns the writer's first
    /// error if it failed on the way (an unpublished file is then removed with the last
    /// handle; a published one stays, with what was written).
    pub fn close(self) -> Result<LogStats, LogError> {
        self.shared.thread.closed.store(true, Ordering::Release);
        if let Some(inner) = self.handle.upgrade() {
            // Waits for queue space; fails only if the thread already stopped.
            let _ = inner.tx.send(Command::Close);
        }
        let outcome = self.thread.join().map_err(|_| LogError::WriterPanicked {
            path: self.shared.thread.path.clone(),
        })??;
        self.shared.publish()?;
        let drops_per_topic = self
            .shared
            .registry
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .by_topic
            .iter()
            .filter(|(_, c)| c.backlog_drops() > 0)
            .map(|(t, c)| (t.clone(), c.backlog_drops()))
            .collect();
        Ok(LogStats {
            messages_per_topic: outcome.messages_per_topic,
            drops_per_topic,
            backlog_drops: self.shared.backlog_drops.load(Ordering::Relaxed),
            bytes_written: outcome.bytes_written,
            flushes: outcome.flushes,
        })
    }

    /// The log file (its destination).
    pub fn path(&self) -> &Path {
        &self.shared.thread.path
    }

    /// Where the file is now: its destination once published, else its temporary name.
    pub fn current_path(&self) -> std::path::PathBuf {
        self.shared.current_path()
    }
}
