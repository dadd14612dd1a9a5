//! The live twin in a session (`rigtwin run --twin`): a [`SessionRecorder`] that hands every
//! DAQ block to the [`TwinTask`] (never waiting: a full queue skips the block and says so),
//! applies each test's clearance from the first block at or after its `test_start` sample
//! (the rule of [`super::replay_twin`], so live and replay cut at the same place), collects
//! the twin's output, and compares it with the measurement as each record window completes.
//!
//! Logged (when given a log): `/twin/blocks` (the predicted channels of every block the twin
//! processed, [`TwinSamples`]), `/twin/status` (lag, queue, skipped blocks, speed) about once a
//! second of rig time, `/twin/steps` (the comparison of every step) as it completes. With a
//! live view ([`TwinRecorder::with_live`]) the same status and comparisons, and the predicted
//! channels decimated, go to the Foxglove app.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::control::{EventKind, SessionEvent, SessionRecorder, StepInfo, StepSummary};
use crate::log::live::LiveRecorder;
use crate::log::recorder::log_time_ns;
use crate::log::{LogChannel, LogHandle};
use crate::rig::{DaqBlock, DaqLayout, RigStatus};

use super::output::{TwinSamples, TOPIC_TWIN_BLOCKS};
use super::{Pushed, TwinComparison, TwinEvent, TwinReceiver, TwinStatus, TwinTask, TwinWindows};

/// Topic of the twin's status.
pub const TOPIC_TWIN_STATUS: &str = "/twin/status";
/// Topic of the twin's per-step comparison.
pub const TOPIC_TWIN_STEPS: &str = "/twin/steps";

/// One step's comparison, as logged on [`TOPIC_TWIN_STEPS`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinStepMessage {
    /// Test name.
    pub test: String,
    /// Step index.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The comparison; `None` when the twin missed samples of the window (skipped blocks).
    pub twin: Option<TwinComparison>,
}

impl TwinStepMessage {
    /// The message of a step's comparison.
    pub fn of(info: &StepInfo, twin: Option<&TwinComparison>) -> TwinStepMessage {
        TwinStepMessage {
            test: info.test.clone(),
            step: info.step,
            omega_ratio: info.omega_ratio,
            twin: twin.cloned(),
        }
    }

    /// Its log time: the end of the step's record window (samples `dt` s apart), s.
    pub fn log_time(info: &StepInfo, dt: f64) -> f64 {
        (info.record_first_sample + info.record_samples as u64) as f64 * dt
    }
}

struct Logs {
    log: LogHandle,
    blocks: LogChannel<TwinSamples>,
    status: LogChannel<TwinStatus>,
    steps: LogChannel<TwinStepMessage>,
}

/// The live twin beside a session (see the module documentation).
pub struct TwinRecorder {
    task: TwinTask,
    rx: TwinReceiver,
    beam_length: f64,
    dt: f64,
    clearances: VecDeque<(u64, f64)>,
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
    /// The live twin on `task` (its output `rx`), for a stream of `dt` s samples and a rig of
    /// beam length `beam_length` m; logging to `log` if given.
    pub fn new(
        task: TwinTask,
        rx: TwinReceiver,
        beam_length: f64,
        dt: f64,
        log: Option<LogHandle>,
    ) -> Result<TwinRecorder, crate::log::LogError> {
        let logs = match log {
            Some(log) => Some(Logs {
                blocks: log.channel(TOPIC_TWIN_BLOCKS)?,
                status: log.channel(TOPIC_TWIN_STATUS)?,
                steps: log.channel(TOPIC_TWIN_STEPS)?,
                log,
            }),
            None => None,
        };
        Ok(TwinRecorder {
            task,
            rx,
            beam_length,
            dt,
            clearances: VecDeque::new(),
            windows: VecDeque::new(),
            out: TwinWindows::default(),
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
            let end = TwinStepMessage::log_time(&info, self.dt);
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
    fn layout(&mut self, _: &DaqLayout) -> Result<(), String> {
        Ok(())
    }

    fn block(&mut self, block: &DaqBlock) -> Result<(), String> {
        if self.failed {
            return Ok(());
        }
        while let Some(&(sample, c)) = self.clearances.front() {
            if sample > block.first_sample {
                break;
            }
            if let Err(e) = self.task.set_clearance(c) {
                self.fail(e);
            }
            self.clearances.pop_front();
        }
        match self.task.push(block) {
            Ok(Pushed::Queued) => {}
            Ok(Pushed::Skipped { .. }) => {} // counted by the task, visible in its status
            Err(e) => self.fail(e),
        }
        self.drain(false);
        if block.time - self.last_status >= 1.0 {
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

    fn control(&mut self, _: &crate::control::ControlState) -> Result<(), String> {
        Ok(())
    }

    fn event(&mut self, event: &SessionEvent) -> Result<(), String> {
        if let EventKind::TestStart { clearance, .. } = &event.kind {
            self.clearances
                .push_back((event.sample, clearance * self.beam_length));
        }
        Ok(())
    }

    fn status(&mut self, _: f64, _: &RigStatus) -> Result<(), String> {
        Ok(())
    }

    fn step(&mut self, _: f64, info: &StepInfo, summary: &StepSummary) -> Result<(), String> {
        self.windows.push_back((info.clone(), summary.clone()));
        self.drain(false);
        Ok(())
    }
}
