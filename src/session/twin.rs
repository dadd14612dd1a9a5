//! The live twin in a session (`rigtwin run --twin`): a [`SessionRecorder`] that hands every
//! DAQ block to the [`TwinTask`] (never waiting: a full queue skips the block and says so),
//! applies each test's clearance by the [`ClearanceSchedule`] (the rule replay uses too, so live
//! and replay cut at the same place), collects the twin's output, and compares it with the
//! measurement as each record window completes.
//!
//! Logged (when given a log): [`TOPIC_TWIN_BLOCKS`] (the predicted channels of every block the
//! twin processed, [`TwinSamples`]), [`TOPIC_TWIN_STATUS`] (lag, queue, skipped blocks, speed)
//! about once a second of rig time, [`TOPIC_TWIN_STEPS`] (the comparison of every step) as it
//! completes, [`TOPIC_TWIN_STATE`] (the twin's state at the start of every step, for warm
//! starts). With a live view ([`TwinRecorder::with_live`]) the same status and comparisons,
//! and the predicted channels decimated, go to the Foxglove app.

use std::collections::VecDeque;

use crate::control::{ControlState, SessionEvent, StepInfo, StepSummary};
use crate::log::{log_time_ns, LogChannel, LogError, LogHandle};
use crate::rig::{DaqBlock, DaqLayout, RigStatus};
use crate::twin::{
    ClearanceSchedule, Pushed, StepStarts, TwinComparison, TwinEvent, TwinReceiver, TwinSamples,
    TwinStatus, TwinTask, TwinWindows,
};

use super::live::LiveRecorder;
use super::recorder::{RecordError, SessionRecorder};
use super::runner::STATUS_PERIOD_S;
use super::topics::{
    TwinStateMessage, TwinStepMessage, TOPIC_TWIN_BLOCKS, TOPIC_TWIN_STATE, TOPIC_TWIN_STATUS,
    TOPIC_TWIN_STEPS,
};

struct Logs {
    log: LogHandle,
    blocks: LogChannel<TwinSamples>,
    states: LogChannel<TwinStateMessage>,
    status: LogChannel<TwinStatus>,
    steps: LogChannel<TwinStepMessage>,
}

/// The live twin beside a session (see the module documentation).
pub struct TwinRecorder {
    task: TwinTask,
    rx: TwinReceiver,
    dt: f64,
    clearances: ClearanceSchedule,
    /// Where the twin's state is captured for warm starts (step starts).
    step_starts: StepStarts,
    windows: VecDeque<(StepInfo, StepSummary)>,
    out: TwinWindows,
    /// Comparisons in step order (`None`: the twin missed part of the window).
    results: Vec<Option<TwinComparison>>,
    logs: Option<Logs>,
    live: Option<LiveRecorder>,
    last_status: f64,
    /// Twin errors (reported once at the end; the session goes on without the twin).
    errors: Vec<String>,
    failed: bool,
}

impl std::fmt::Debug for TwinRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwinRecorder")
            .field("results", &self.results.len())
            .finish()
    }
}

/// What the live twin left at the end of a session.
#[derive(Debug)]
pub struct TwinOutcome {
    /// The comparison of every step, in step order.
    pub comparisons: Vec<Option<TwinComparison>>,
    /// The task's final status.
    pub status: TwinStatus,
    /// Errors of the twin (the session went on without it).
    pub errors: Vec<String>,
}

impl TwinRecorder {
    /// The live twin on `task` (its output `rx`), for a stream of `dt` s samples, with the
    /// twin's clearance per test from `clearances` and its record windows observed as `out`
    /// sets up (see [`crate::twin::observe`]); logging to `log` if given.
    pub fn new(
        task: TwinTask,
        rx: TwinReceiver,
        clearances: ClearanceSchedule,
        out: TwinWindows,
        dt: f64,
        log: Option<LogHandle>,
    ) -> Result<TwinRecorder, LogError> {
        let logs = match log {
            Some(log) => Some(Logs {
                blocks: log.channel(TOPIC_TWIN_BLOCKS)?,
                states: log.channel(TOPIC_TWIN_STATE)?,
                status: log.channel(TOPIC_TWIN_STATUS)?,
                steps: log.channel(TOPIC_TWIN_STEPS)?,
                log,
            }),
            None => None,
        };
        Ok(TwinRecorder {
            task,
            rx,
            dt,
            clearances,
            step_starts: StepStarts::default(),
            windows: VecDeque::new(),
            out,
            results: Vec::new(),
            logs,
            live: None,
            last_status: f64::NEG_INFINITY,
            errors: Vec::new(),
            failed: false,
        })
    }

    /// Also feeds the live view: the twin's status, comparisons and decimated predictions.
    pub fn with_live(mut self, live: LiveRecorder) -> TwinRecorder {
        self.live = Some(live);
        self
    }

    fn fail(&mut self, e: impl std::fmt::Display) {
        if self.errors.len() < 16 {
            self.errors.push(e.to_string());
        }
        self.failed = true;
    }

    /// Takes what the twin produced so far and completes the windows it covers (all of them
    /// when `all`).
    fn drain(&mut self, all: bool) {
        while let Ok(ev) = self.rx.try_recv() {
            match ev {
                TwinEvent::Block(b) => {
                    if let Some(l) = &self.logs {
                        // A full log queue drops the message and counts it (the log's stats).
                        let _ = l
                            .log
                            .log(&l.blocks, log_time_ns(b.time), &TwinSamples::from(&b));
                    }
                    if let Some(live) = &self.live {
                        live.twin_block(&b);
                    }
                    self.out.push(&b);
                }
                TwinEvent::State { test, step, state } => {
                    if let Some(l) = &self.logs {
                        let time = state.next_sample as f64 * self.dt;
                        let message = TwinStateMessage {
                            test,
                            step,
                            state: *state,
                        };
                        let _ = l.log.log(&l.states, log_time_ns(time), &message);
                    }
                }
                TwinEvent::Error { seq, message } => {
                    // The twin skipped that block and goes on: a gap in its output.
                    if self.errors.len() < 16 {
                        self.errors.push(format!("block {seq}: {message}"));
                    }
                }
            }
        }
        for (info, c) in self.out.complete(&mut self.windows, self.dt, all) {
            let c = match c {
                Some(Ok(c)) => Some(c),
                Some(Err(e)) => {
                    self.fail(format!(
                        "metrics of step {} of test {}: {e}",
                        info.step, info.test
                    ));
                    None
                }
                None => None,
            };
            let end = info.record_end_time(self.dt);
            let message = TwinStepMessage::of(&info, c.as_ref());
            if let Some(l) = &self.logs {
                let _ = l.log.log(&l.steps, log_time_ns(end), &message);
            }
            if let Some(live) = &self.live {
                live.twin_step(end, &message);
            }
            self.results.push(c);
        }
    }

    /// Waits for the twin to finish what is queued, compares the last windows and stops the
    /// task.
    pub fn finish(mut self) -> TwinOutcome {
        let status = match self.task.finish() {
            Ok(s) => s,
            Err(e) => {
                self.fail(&e);
                self.task.status()
            }
        };
        self.drain(true);
        TwinOutcome {
            comparisons: self.results,
            status,
            errors: self.errors,
        }
    }
}

impl SessionRecorder for TwinRecorder {
    fn layout(&mut self, _: &DaqLayout) -> Result<(), RecordError> {
        Ok(())
    }

    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
        if self.failed {
            return Ok(());
        }
        while let Some(c) = self.clearances.next_due(block.first_sample) {
            if let Err(e) = self.task.set_clearance(c) {
                self.fail(e);
            }
        }
        if let Some((test, step)) = self.step_starts.next_due(block.first_sample) {
            self.task.capture_next(&test, step);
        }
        match self.task.push(block) {
            Ok(Pushed::Queued) => {}
            Ok(Pushed::Skipped { .. }) => {} // counted by the task, visible in its status
            Err(e) => self.fail(e),
        }
        self.drain(false);
        if block.time - self.last_status >= STATUS_PERIOD_S {
            self.last_status = block.time;
            let status = self.task.status();
            if let Some(l) = &self.logs {
                let _ = l.log.log(&l.status, log_time_ns(block.time), &status);
            }
            if let Some(live) = &self.live {
                live.twin_status(block.time, &status);
            }
        }
        Ok(())
    }

    fn control(&mut self, _: &ControlState) -> Result<(), RecordError> {
        Ok(())
    }

    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
        self.clearances.on_event(event);
        self.step_starts.on_event(event);
        Ok(())
    }

    fn status(&mut self, _: f64, _: &RigStatus) -> Result<(), RecordError> {
        Ok(())
    }

    fn step(&mut self, _: f64, info: &StepInfo, summary: &StepSummary) -> Result<(), RecordError> {
        self.windows.push_back((info.clone(), summary.clone()));
        self.drain(false);
        Ok(())
    }
}
