//! The writer thread of a session log: owns the MCAP writer and the file, turns queued
//! commands into records, flushes at least every flush interval (also when idle), and on close
//! (or when every handle is gone) writes the summary and footer and syncs the file.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use super::{LogError, MESSAGE_ENCODING, SCHEMA_ENCODING};

/// What the handles send to the writer thread.
pub(super) enum Command {
    /// Register a channel with the id the handle chose.
    Channel {
        id: u16,
        topic: String,
        schema_name: String,
        schema: Vec<u8>,
    },
    /// One JSON message.
    Message {
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        data: Vec<u8>,
    },
    /// Write what is queued, finish the file and stop.
    Close,
    /// Test hook: report that the thread got here, then wait until `release` yields or closes.
    #[cfg(test)]
    Stall {
        entered: std::sync::mpsc::SyncSender<()>,
        release: Receiver<()>,
    },
}

/// What the writer thread shares with the handles and the join side.
pub(super) struct ThreadShared {
    /// The log file.
    pub(super) path: PathBuf,
    /// Set by `LogJoin::close` and when the writer thread stops.
    pub(super) closed: AtomicBool,
    /// Why the writer thread stopped early (an I/O error).
    pub(super) failure: OnceLock<String>,
    /// Written by the writer thread.
    pub(super) progress: Progress,
}

/// Counters the writer thread updates as it goes.
#[derive(Default)]
pub(super) struct Progress {
    pub(super) messages_written: AtomicU64,
    pub(super) messages_flushed: AtomicU64,
    pub(super) flushes: AtomicU64,
}

/// What the writer thread returns when it finishes.
pub(super) struct WriterOutcome {
    pub(super) messages_per_topic: BTreeMap<String, u64>,
    pub(super) bytes_written: u64,
    pub(super) flushes: u64,
}

/// The writer thread's state.
pub(super) struct WriterTask {
    writer: mcap::Writer<BufWriter<File>>,
    shared: Arc<ThreadShared>,
    flush_interval: Duration,
    /// Topic per channel id.
    topics: HashMap<u16, String>,
    /// Messages written per topic.
    counts: BTreeMap<String, u64>,
    /// Messages written since the last flush.
    unflushed: u64,
    written: u64,
    flushes: u64,
}

impl WriterTask {
    pub(super) fn new(
        writer: mcap::Writer<BufWriter<File>>,
        shared: Arc<ThreadShared>,
        flush_interval: Duration,
    ) -> Self {
        Self {
            writer,
            shared,
            flush_interval,
            topics: HashMap::new(),
            counts: BTreeMap::new(),
            unflushed: 0,
            written: 0,
            flushes: 0,
        }
    }

    /// Runs until closed or until every sender is gone. On an error the thread records it for
    /// the handles, stops taking messages and returns it.
    pub(super) fn run(mut self, rx: Receiver<Command>) -> Result<WriterOutcome, LogError> {
        let result = self.serve(&rx);
        // From here on `log` fails fast instead of filling a queue nobody reads.
        self.shared.closed.store(true, Ordering::Release);
        drop(rx);
        match result {
            Ok(()) => self.finish(),
            Err(err) => {
                let _ = self.shared.failure.set(err.to_string());
                Err(err)
            }
        }
    }

    fn serve(&mut self, rx: &Receiver<Command>) -> Result<(), LogError> {
        let mut next_flush = Instant::now() + self.flush_interval;
        loop {
            let wait = next_flush.saturating_duration_since(Instant::now());
            match rx.recv_timeout(wait) {
                Ok(Command::Close) => {
                    // Messages that raced with the close still go in.
                    while let Ok(command) = rx.try_recv() {
                        self.apply(command)?;
                    }
                    return Ok(());
                }
                Ok(command) => self.apply(command)?,
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Ok(()),
            }
            if Instant::now() >= next_flush {
                if self.unflushed > 0 {
                    self.flush()?;
                }
                next_flush = Instant::now() + self.flush_interval;
            }
        }
    }

    fn apply(&mut self, command: Command) -> Result<(), LogError> {
        match command {
            Command::Channel {
                id,
                topic,
                schema_name,
                schema,
            } => {
                let schema_id = self
                    .writer
                    .add_schema(&schema_name, SCHEMA_ENCODING, &schema)
                    .map_err(|source| self.mcap_error(format!("schema {schema_name}"), source))?;
                self.writer
                    .add_channel_with_id(id, schema_id, &topic, MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(|source| self.mcap_error(format!("channel {topic}"), source))?;
                self.counts.entry(topic.clone()).or_insert(0);
                self.topics.insert(id, topic);
            }
            Command::Message {
                channel_id,
                sequence,
                log_time,
                data,
            } => {
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time,
                    publish_time: log_time,
                };
                self.writer
                    .write_to_known_channel(&header, &data)
                    .map_err(|source| {
                        let topic = self.topics.get(&channel_id).map_or("?", String::as_str);
                        self.mcap_error(format!("a message on {topic}"), source)
                    })?;
                if let Some(n) = self
                    .topics
                    .get(&channel_id)
                    .and_then(|t| self.counts.get_mut(t))
                {
                    *n += 1;
                }
                self.unflushed += 1;
                self.written += 1;
                self.shared
                    .progress
                    .messages_written
                    .store(self.written, Ordering::Relaxed);
            }
            Command::Close => {}
            #[cfg(test)]
            Command::Stall { entered, release } => {
                let _ = entered.send(());
                let _ = release.recv();
            }
        }
        Ok(())
    }

    /// Finishes the current chunk and hands everything to the OS.
    fn flush(&mut self) -> Result<(), LogError> {
        self.writer
            .flush()
            .map_err(|source| self.mcap_error("flush".into(), source))?;
        self.unflushed = 0;
        self.flushes += 1;
        let progress = &self.shared.progress;
        progress
            .messages_flushed
            .store(self.written, Ordering::Relaxed);
        progress.flushes.store(self.flushes, Ordering::Relaxed);
        Ok(())
    }

    /// Writes the summary and footer, syncs the file.
    fn finish(mut self) -> Result<WriterOutcome, LogError> {
        self.writer
            .finish()
            .map_err(|source| self.mcap_error("summary and footer".into(), source))?;
        self.flushes += 1;
        let path = self.shared.path.clone();
        let io_error = |what| {
            let path = path.clone();
            move |source| LogError::Io { path, what, source }
        };
        let file = self
            .writer
            .into_inner()
            .into_inner()
            .map_err(|e| io_error("cannot write the end of the file")(e.into_error()))?;
        file.sync_all()
            .map_err(io_error("cannot sync the file to disk"))?;
        let bytes_written = file
            .metadata()
            .map_err(io_error("cannot read the file size"))?
            .len();
        let progress = &self.shared.progress;
        progress
            .messages_flushed
            .store(self.written, Ordering::Relaxed);
        progress.flushes.store(self.flushes, Ordering::Relaxed);
        Ok(WriterOutcome {
            messages_per_topic: self.counts,
            bytes_written,
            flushes: self.flushes,
        })
    }

    fn mcap_error(&self, what: String, source: mcap::McapError) -> LogError {
        LogError::Mcap {
            path: self.shared.path.clone(),
            what: format!("cannot write {what}"),
            source,
        }
    }
}
