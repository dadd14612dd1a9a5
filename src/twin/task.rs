//! The twin task ([`TwinTask`]): a [`Twin`] on a dedicated std thread, fed through a bounded
//! queue, with its outputs on a channel the async side polls without blocking.
//!
//! - Input: [`TwinTask::push`] extracts the base acceleration of a DAQ block (checking the
//!   block) and offers it to the queue with `try_send`: the producer never waits for the
//!   twin. The clearance set by [`TwinTask::set_clearance`] travels with every queued block,
//!   so it applies from the next block pushed, in order.
//! - Falling behind: when the queue is full the task declares itself behind and skips blocks
//!   (each push returns [`Pushed::Skipped`]; the status counts them and names the last) until
//!   the twin has drained the queue, then queues again. Skipping in one stretch instead of
//!   one block whenever a slot frees up bounds the lag by the queue length and leaves a few
//!   large gaps instead of many small ones. The twin resumes after a gap as `[twin]
//!   after_gap` says (default: it keeps its state) and reports the gap, where it was and how
//!   long, in the next [`TwinBlock`] (`gap`). Nothing is dropped silently.
//! - Output: [`TwinEvent`]s on an unbounded tokio channel ([`TwinReceiver`]: `try_recv`
//!   never blocks, `recv().await` in a select loop). The twin produces at most one event per
//!   input block, so it grows only if the consumer stops reading.
//! - Status: [`TwinTask::status`] on demand: lag (newest input time minus twin time), queue
//!   depth, skipped blocks, steps per second, real-time factor.
//! - Shutdown: [`TwinTask::finish`] closes the queue, lets the twin process what is queued and
//!   joins the thread; [`TwinTask::abort`] (and drop) discards the queued blocks (counted)
//!   and joins. Both return the final status.
//!
//! The wall clock is read only to measure the thread's busy time (steps per second) and for
//! the test throttle (`[twin] throttle`).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tokio::sync::mpsc::{unbounded_channel, UnboundedSender};

use crate::rig::daq::DaqBlock;

use super::engine::Twin;
use super::error::{BlockError, TaskError, TwinError};
use super::input::{InputMap, TwinInput};
use super::output::{TwinEvent, TwinStatus};
use super::spec::TwinSpec;

#[cfg(doc)]
use super::output::TwinBlock;

/// The receiving end of the twin task's outputs.
pub type TwinReceiver = tokio::sync::mpsc::UnboundedReceiver<TwinEvent>;

/// What became of a block offered to the twin task.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Pushed {
    /// Queued for the twin.
    Queued,
    /// Skipped: the twin is behind (its queue overflowed and has not drained yet).
    Skipped {
        /// Sequence number of the skipped block.
        seq: u64,
        /// Whether this block starts a stretch of skipped blocks (the twin just fell behind).
        first: bool,
        /// Blocks skipped since the task started.
        skipped_blocks: u64,
    },
}

/// A queued block: the twin's input, the clearance in force for it, and the step whose start
/// state the twin reports before running it.
struct Queued {
    input: TwinInput,
    clearance: f64,
    capture: Option<(String, usize)>,
}

/// What the twin thread reports (under a mutex the producer never touches on push).
#[derive(Clone, Copy, Debug, Default)]
struct Progress {
    twin_time: Option<f64>,
    processed: u64,
    steps: u64,
    busy: Duration,
    data_s: f64,
    solver_failures: u64,
    restarts: u64,
    gaps: u64,
    discarded: u64,
    running: bool,
}

struct Shared {
    /// Blocks taken off the queue by the thread.
    taken: AtomicU64,
    stop: AtomicBool,
    progress: Mutex<Progress>,
}

impl Shared {
    fn progress(&self) -> std::sync::MutexGuard<'_, Progress> {
        self.progress.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A [`Twin`] running on its own thread. See the module docs.
pub struct TwinTask {
    tx: Option<SyncSender<Queued>>,
    handle: Option<JoinHandle<()>>,
    shared: Arc<Shared>,
    map: InputMap,
    clearance: f64,
    /// The step whose start state the next queued block asks for.
    capture: Option<(String, usize)>,
    capacity: u64,
    offered: u64,
    queued: u64,
    skipped: u64,
    samples_skipped: u64,
    last_skipped_seq: Option<u64>,
    behind: bool,
    /// First sample of the first block offered, and the sample after the newest one.
    first_sample: Option<u64>,
    next_sample: Option<u64>,
    /// Why the thread ended abnormally, once joined.
    failure: Option<TaskError>,
}

impl std::fmt::Debug for TwinTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwinTask")
            .field("status", &self.status())
            .finish_non_exhaustive()
    }
}

impl TwinTask {
    /// Starts `twin` on a thread named `rigtwin-twin` with an input queue of
    /// `spec.queue_blocks` blocks and the test throttle `spec.throttle` (the twin's own
    /// settings were taken by [`Twin::new`]). Returns the task and its output channel.
    pub fn spawn(twin: Twin, spec: &TwinSpec) -> Result<(TwinTask, TwinReceiver), TwinError> {
        spec.validate()?;
        let (tx, rx) = sync_channel(spec.queue_blocks);
        let (out_tx, out_rx) = unbounded_channel();
        let shared = Arc::new(Shared {
            taken: AtomicU64::new(0),
            stop: AtomicBool::new(false),
            progress: Mutex::new(Progress {
                running: true,
                ..Progress::default()
            }),
        });
        let map = twin.input_map().clone();
        let clearance = twin.nominal_clearance();
        let throttle = spec.throttle;
        let thread_shared = Arc::clone(&shared);
        let handle = std::thread::Builder::new()
            .name("rigtwin-twin".into())
            .spawn(move || run(twin, rx, out_tx, &thread_shared, throttle))
            .map_err(|e| TaskError::Spawn(e.to_string()))?;
        Ok((
            TwinTask {
                tx: Some(tx),
                handle: Some(handle),
                shared,
                map,
                clearance,
                capture: None,
                capacity: spec.queue_blocks as u64,
                offered: 0,
                queued: 0,
                skipped: 0,
                samples_skipped: 0,
                last_skipped_seq: None,
                behind: false,
                first_sample: None,
                next_sample: None,
                failure: None,
            },
            out_rx,
        ))
    }

    /// Offers a DAQ block to the twin without waiting: queued, or skipped when the twin is
    /// behind. Fails on a block that does not fit the layout or starts before the end of the
    /// last one offered, and once the twin thread has stopped.
    pub fn push(&mut self, block: &DaqBlock) -> Result<Pushed, TwinError> {
        let input = self.map.extract(block)?;
        self.push_input(input)
    }

    /// [`TwinTask::push`] for an input already extracted with this twin's [`InputMap`].
    pub fn push_input(&mut self, input: TwinInput) -> Result<Pushed, TwinError> {
        if input.is_empty() {
            return Err(BlockError::Empty { seq: input.seq }.into());
        }
        if let Some(next) = self.next_sample {
            if input.first_sample < next {
                return Err(BlockError::OutOfOrder {
                    seq: input.seq,
                    first_sample: input.first_sample,
                    next_sample: next,
                }
                .into());
            }
        }
        let Some(tx) = &self.tx else {
            return Err(TaskError::ShutDown.into());
        };
        self.offered += 1;
        self.first_sample.get_or_insert(input.first_sample);
        self.next_sample = Some(input.first_sample + input.len() as u64);
        if self.behind {
            let depth = self.queued - self.shared.taken.load(Ordering::Acquire);
            if depth > 0 {
                return Ok(self.skip(&input, false));
            }
            self.behind = false;
        }
        let seq = input.seq;
        match tx.try_send(Queued {
            input,
            clearance: self.clearance,
            capture: self.capture.take(),
        }) {
            Ok(()) => {
                self.queued += 1;
                Ok(Pushed::Queued)
            }
            Err(TrySendError::Full(q)) => {
                self.behind = true;
                self.capture = q.capture;
                Ok(self.skip(&q.input, true))
            }
            Err(TrySendError::Disconnected(_)) => Err(TaskError::Stopped { seq }.into()),
        }
    }

    fn skip(&mut self, input: &TwinInput, first: bool) -> Pushed {
        self.skipped += 1;
        self.samples_skipped += input.len() as u64;
        self.last_skipped_seq = Some(input.seq);
        Pushed::Skipped {
            seq: input.seq,
            first,
            skipped_blocks: self.skipped,
        }
    }

    /// Changes the twin's clearance (m, finite) from the next block pushed on.
    pub fn set_clearance(&mut self, clearance_m: f64) -> Result<(), TwinError> {
        if !clearance_m.is_finite() {
            return Err(TwinError::Clearance(clearance_m));
        }
        self.clearance = clearance_m;
        Ok(())
    }

    /// Asks for the twin's state at the start of step `step` of test `test`: the twin reports
    /// it ([`TwinEvent::State`]) before it runs the next block queued (the next one pushed,
    /// or the first queued after skipped ones).
    pub fn capture_next(&mut self, test: &str, step: usize) {
        self.capture = Some((test.to_string(), step));
    }

    /// The clearance for the next block pushed, m.
    pub fn clearance(&self) -> f64 {
        self.clearance
    }

    /// The task's status now (lag, queue, skipped blocks, speed). Never waits for the twin
    /// beyond a short lock of its progress counters.
    pub fn status(&self) -> TwinStatus {
        let p = *self.shared.progress();
        let fs = self.map.sample_rate();
        let input_time = self.next_sample.map_or(0.0, |n| n as f64 / fs);
        let twin_time = p
            .twin_time
            .or(self.first_sample.map(|n| n as f64 / fs))
            .unwrap_or(0.0);
        let busy = p.busy.as_secs_f64();
        let per_busy = |x: f64| if busy > 0.0 { x / busy } else { 0.0 };
        TwinStatus {
            input_time,
            twin_time,
            lag_s: (input_time - twin_time).max(0.0),
            queue_depth: self
                .queued
                .saturating_sub(self.shared.taken.load(Ordering::Acquire)),
            queue_capacity: self.capacity,
            behind: self.behind,
            blocks_offered: self.offered,
            blocks_processed: p.processed,
            blocks_skipped: self.skipped,
            samples_skipped: self.samples_skipped,
            last_skipped_seq: self.last_skipped_seq,
            gaps: p.gaps,
            blocks_discarded: p.discarded,
            steps: p.steps,
            steps_per_s: per_busy(p.steps as f64),
            realtime_factor: per_busy(p.data_s),
            solver_failures: p.solver_failures,
            restarts: p.restarts,
            running: p.running,
        }
    }

    /// Closes the queue, lets the twin process every queued block, joins the thread and
    /// returns the final status. The outputs stay readable on the receiver. Fails if the
    /// thread panicked.
    pub fn finish(&mut self) -> Result<TwinStatus, TwinError> {
        self.shutdown(false)
    }

    /// Stops the twin after the block it is working on, discards the queued blocks (counted
    /// in `blocks_discarded`), joins the thread and returns the final status.
    pub fn abort(&mut self) -> Result<TwinStatus, TwinError> {
        self.shutdown(true)
    }

    fn shutdown(&mut self, stop: bool) -> Result<TwinStatus, TwinError> {
        if stop {
            self.shared.stop.store(true, Ordering::Release);
        }
        self.tx = None;
        if let Some(handle) = self.handle.take() {
            if let Err(panic) = handle.join() {
                let what = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                self.shared.progress().running = false;
                self.failure = Some(TaskError::Panicked(what));
            }
        }
        match &self.failure {
            Some(f) => Err(f.clone().into()),
            None => Ok(self.status()),
        }
    }
}

impl Drop for TwinTask {
    fn drop(&mut self) {
        if self.handle.is_some() {
            let _ = self.abort();
        }
    }
}

/// The twin thread: takes blocks until the queue is closed.
fn run(
    mut twin: Twin,
    rx: Receiver<Queued>,
    out: UnboundedSender<TwinEvent>,
    shared: &Shared,
    throttle: f64,
) {
    let fs = twin.sample_rate();
    // The twin may have run before (e.g. settled): the status counts this task's work.
    let base = twin.counters();
    while let Ok(q) = rx.recv() {
        shared.taken.fetch_add(1, Ordering::AcqRel);
        if shared.stop.load(Ordering::Acquire) {
            shared.progress().discarded += 1;
            continue;
        }
        let start = Instant::now();
        if q.clearance != twin.nominal_clearance() {
            // Checked finite by the producer: cannot fail.
            let _ = twin.set_clearance(q.clearance);
        }
        if let Some((test, step)) = q.capture {
            if let Some(state) = twin.state() {
                let _ = out.send(TwinEvent::State {
                    test,
                    step,
                    state: Box::new(state),
                });
            }
        }
        let result = twin.push_input(&q.input);
        let data_s = q.input.len() as f64 / fs;
        if throttle > 0.0 {
            let target = Duration::from_secs_f64(throttle * data_s);
            let spent = start.elapsed();
            if spent < target {
                std::thread::sleep(target - spent);
            }
        }
        let busy = start.elapsed();
        {
            let c = twin.counters();
            let mut p = shared.progress();
            p.busy += busy;
            p.twin_time = twin.time();
            p.processed = c.blocks - base.blocks;
            p.steps = c.steps - base.steps;
            p.data_s += data_s;
            p.solver_failures = c.solver_failures - base.solver_failures;
            p.restarts = c.restarts - base.restarts;
            p.gaps = c.gaps - base.gaps;
        }
        let event = match result {
            Ok(block) => TwinEvent::Block(block),
            Err(e) => TwinEvent::Error {
                seq: q.input.seq,
                message: e.to_string(),
            },
        };
        // A dropped receiver only means nobody reads the outputs: the status still counts.
        let _ = out.send(event);
    }
    shared.progress().running = false;
}
