//! Issue 15: `stream_session` reads a session log in memory bounded by its largest chunk, not
//! by the file: a counting allocator measures the peak of the bytes allocated while a log of
//! over 30 MB of message payloads (1 MiB chunks) is streamed, and while it is read whole
//! (`read_session`, which keeps every message: the measure must tell the two apart). The
//! streamed read hands over the same messages as the whole read, in the same order.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use rigtwin::log::{read_session, stream_session, LogOptions, LogReadError, SessionLog};

/// The system allocator, counting the bytes live and their peak since the last reset.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One measurement at a time (the counters are global).
static MEASURING: Mutex<()> = Mutex::new(());

/// The peak of the bytes allocated by `f` beyond those live when it starts, and its result.
fn peak_of<T>(f: impl FnOnce() -> T) -> (usize, T) {
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (PEAK.load(Ordering::Relaxed).saturating_sub(base), out)
}

#[derive(serde::Serialize, schemars::JsonSchema)]
struct Block {
    seq: u64,
    counts: Vec<i32>,
}

#[test]
fn streaming_holds_a_chunk_not_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.mcap");
    let (log, join) = SessionLog::create(&path, LogOptions::default(), vec![], vec![]).unwrap();
    let daq = log.channel::<Block>("/daq").unwrap();
    // Incompressible-ish counts: over 30 MB of JSON payloads in 1 MiB chunks.
    let mut state = 7u64;
    let mut payload_bytes = 0usize;
    for seq in 0..4000u64 {
        let counts = (0..1000)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 40) as i32
            })
            .collect();
        let b = Block { seq, counts };
        payload_bytes += serde_json::to_vec(&b).unwrap().len();
        log.log_json_waiting(daq.raw(), seq * 1000, serde_json::to_vec(&b).unwrap())
            .unwrap();
    }
    join.close().unwrap();
    assert!(payload_bytes > 30_000_000, "{payload_bytes}");

    let mut streamed = Vec::new();
    let (stream_peak, s) = peak_of(|| {
        stream_session(&path, |m| {
            // What a consumer keeps of each message: here, its size.
            streamed.push((m.sequence, m.data.len()));
            Ok::<(), LogReadError>(())
        })
        .unwrap()
    });
    assert!(s.complete && s.damage.is_empty() && s.messages.is_empty());
    let (whole_peak, whole) = peak_of(|| read_session(&path).unwrap());
    let kept: Vec<(u32, usize)> = whole
        .messages
        .iter()
        .map(|m| (m.sequence, m.data.len()))
        .collect();
    assert_eq!(streamed, kept);
    assert_eq!(s.channels, whole.channels);
    // The whole read holds every payload; the stream one chunk (1 MiB uncompressed, its
    // compressed bytes and its records) and what the consumer keeps (64 kB here).
    assert!(
        whole_peak > payload_bytes,
        "{whole_peak} <= {payload_bytes}"
    );
    assert!(
        stream_peak < 8 << 20,
        "streaming a {payload_bytes}-byte log peaked at {stream_peak} bytes"
    );
}
