//! Parameters of the session log writer: chunk compression, chunk size, flush interval and
//! queue capacity.

use crate::config::SpecError;
use std::time::Duration;

/// Compression of the MCAP chunks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Compression {
    /// Zstandard (default): the best ratio, fast enough for DAQ rates.
    #[default]
    Zstd,
    /// LZ4: faster, larger files.
    Lz4,
    /// No compression.
    None,
}

impl Compression {
    /// The mcap crate's setting.
    pub(crate) fn to_mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        }
    }
}

/// How the session log is written.
#[derive(Clone, Debug, PartialEq)]
pub struct LogOptions {
    /// Chunk compression. Default [`Compression::Zstd`].
    pub compression: Compression,
    /// Target uncompressed chunk size, bytes: a chunk is finished once it grows past this.
    /// Default 1 MiB. Flushes finish chunks early, so at low data rates chunks are smaller.
    pub chunk_size_bytes: u64,
    /// Longest time between flushes, s (as a [`Duration`]): the writer finishes the current
    /// chunk and hands the file to the OS at least this often, even when no messages arrive.
    /// A crash (SIGKILL) loses at most the messages of the last interval. Default 1 s.
    pub flush_interval: Duration,
    /// Capacity of the queue between the callers and the writer thread, messages. When it is
    /// full, `log` returns [`LogError::Backlog`](super::LogError::Backlog) instead of waiting.
    /// Default 4096 (4 s of 1 kHz blocks).
    pub queue_capacity: usize,
}

impl LogOptions {
    /// Shortest accepted flush interval: shorter ones would keep the writer thread busy.
    pub const MIN_FLUSH_INTERVAL: Duration = Duration::from_millis(1);

    /// Checks the values; the first problem (option, value, what was expected).
    pub fn check(&self) -> Result<(), SpecError> {
        if self.chunk_size_bytes == 0 {
            return Err(SpecError::new(
                "chunk_size_bytes",
                0,
                "a positive size in bytes",
            ));
        }
        if self.flush_interval < Self::MIN_FLUSH_INTERVAL {
            return Err(SpecError::new(
                "flush_interval",
                format!("{:?}", self.flush_interval),
                format!("at least {:?}", Self::MIN_FLUSH_INTERVAL),
            ));
        }
        if self.queue_capacity == 0 {
            return Err(SpecError::new("queue_capacity", 0, "at least 1 message"));
        }
        Ok(())
    }
}

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            chunk_size_bytes: 1024 * 1024,
            flush_interval: Duration::from_secs(1),
            queue_capacity: 4096,
        }
    }
}
