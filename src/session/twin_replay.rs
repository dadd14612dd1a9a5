//! The twin re-run on a recorded session (`rigtwin replay --twin`): [`replay_twin`] runs the
//! twin over the recording's base motion with the plan's clearances ([`ClearanceSchedule`], the
//! live twin's rule) and writes each step's comparison into the replayed summary
//! (deterministic: the same recording and model give the same bits, and the live twin's
//! comparisons where it made them). Its output can also go to a copy of the session log
//! ([`TwinLogCopy`], `--out NEW.mcap`): every message, metadata record and attachment of the
//! original except the recorded twin's topics (`/twin/...`), then the re-run twin's
//! `/twin/blocks` and `/twin/steps`, and a `twin_replay` metadata record naming the model;
//! `rigtwin report NEW.mcap` draws the re-run twin beside the measurement.

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::control::{StepInfo, StepSummary};
use crate::log::{
    log_time_ns, stream_session, Attachment, LogChannel, LogError, LogHandle, LogJoin, LogOptions,
    LogReadError, LogStats, MetadataRecord, SessionLog, RIGTWIN_METADATA,
};
use crate::signal::features::CONTACT_CHANNEL;
use crate::signal::{Feature, NoiseFloor, SignalError};
use crate::twin::{
    ClearanceSchedule, ComparisonTolerance, Completed, Observation, StepStarts, Twin, TwinBlock,
    TwinComparison, TwinError, TwinModel, TwinSamples, TwinSpec, TwinState, TwinWindows,
};

use super::replay::Recording;
use super::summary::SessionSummary;
use super::topics::{
    TwinStateMessage, TwinStepMessage, TOPIC_TWIN_BLOCKS, TOPIC_TWIN_STATE, TOPIC_TWIN_STEPS,
    TWIN_REPLAY_METADATA,
};

/// Errors of a twin replay.
#[derive(Debug, thiserror::Error)]
pub enum TwinReplayError {
    /// The twin failed (bad model, non-finite input, ...).
    #[error(transparent)]
    Twin(#[from] TwinError),
    /// The twin's metrics over a record window failed.
    #[error("twin comparison: metrics of step {step} of test {test}: {source}")]
    Metrics {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// What failed.
        source: SignalError,
    },
    /// Writing the copy of the session log failed.
    #[error("twin log: {0}")]
    Log(#[from] LogError),
    /// Reading the session log to copy failed.
    #[error("twin log: {0}")]
    Read(#[from] LogReadError),
    /// A message could not be serialised.
    #[error("twin log: {0}")]
    Serialize(#[from] serde_json::Error),
    /// The copy would replace the log it is made from.
    #[error(
        "twin log: {path}: the copy would overwrite the session it is made from; name another file"
    )]
    Overwrite {
        /// The file asked for.
        path: String,
    },
    /// The recording has gaps (damaged chunks of the log): the twin's state cannot be carried
    /// across them.
    #[error(
        "the recording has gaps ({blocks} DAQ blocks, {seconds:.2} s of rig time lost in damaged \
         parts of the log): the twin cannot be re-run across them; replay without --twin"
    )]
    Gaps {
        /// Blocks missing.
        blocks: u64,
        /// Rig time missing, s.
        seconds: f64,
    },
    /// Steps asked for that the recording does not have.
    #[error("--steps: the recording has no step {steps} (its tests and steps: {have})")]
    NoSuchSteps {
        /// The selection items that match nothing.
        steps: String,
        /// What the recording has.
        have: String,
    },
    /// No logged twin state to start a selected step from.
    #[error(
        "--steps: no twin state logged at the start of step {step} of test {test} (the log has          {states} twin states; states are logged by `run --twin` and `replay --twin --out` since          warm starts exist): re-run the whole session with `replay --twin`, or write a copy          with states by `replay --twin --out COPY.mcap` first"
    )]
    NoState {
        /// Test name.
        test: String,
        /// Step, counted from 1.
        step: usize,
        /// Twin states in the log.
        states: usize,
    },
    /// The source log has a channel without a schema (not a rigtwin session log).
    #[error(
        "twin log: {path}: channel {topic} has no schema; only rigtwin session logs can be copied"
    )]
    NoSchema {
        /// The source log.
        path: String,
        /// The channel's topic.
        topic: String,
    },
}

/// What a twin replay did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwinReplayStats {
    /// Blocks the twin ran through.
    pub blocks: u64,
    /// Steps compared.
    pub steps_compared: usize,
    /// Contact-solver failures over the session.
    pub solver_failures: u64,
    /// Twin seconds of computation per second of rig time, -.
    pub wall_per_rig_second: f64,
}

/// The ensemble behind each step's model spread ([`TwinComparison::with_ensemble`]): `members`
/// runs of the twin from its state at the step's start with the modal velocities perturbed by
/// `perturbation` of their norm ([`TwinState::perturbed`]), through the end of the step's
/// record window, on `jobs` threads. A step that starts with the recording (from rest) gets
/// no ensemble; with `contact_windows_only`, neither does a window without contact.
#[derive(Clone, Copy, Debug)]
pub struct EnsembleOptions<'a> {
    /// Members besides the twin's own run (0: none).
    pub members: usize,
    /// Relative size of a member's perturbation.
    pub perturbation: f64,
    /// Threads (>= 1).
    pub jobs: usize,
    /// The discretisation member run beside the members (none without members).
    pub discretisation: Option<&'a DiscretisationMember<'a>>,
    /// Members (and the discretisation member) only in the windows where the discretisation
    /// member runs (contact measured or modelled, or right after a measured one): the
    /// non-periodic ones. The periodic windows keep the twin's own sub-window spread.
    pub contact_windows_only: bool,
}

impl<'a> EnsembleOptions<'a> {
    /// No ensemble.
    pub const NONE: EnsembleOptions<'static> = EnsembleOptions {
        members: 0,
        perturbation: 1e-3,
        jobs: 1,
        discretisation: None,
        contact_windows_only: false,
    };

    /// The ensemble of `[twin]` (`spec`) on `jobs` threads, without a discretisation member.
    pub fn of(spec: &TwinSpec, jobs: usize) -> EnsembleOptions<'a> {
        EnsembleOptions {
            members: spec.ensemble_members,
            perturbation: spec.ensemble_perturbation,
            jobs: jobs.max(1),
            discretisation: None,
            contact_windows_only: false,
        }
    }
}

/// The comparison's discretisation member (`[twin.discretisation]`): a finer model than the
/// twin's (more modes, a finer step; the same extensions and contact observation), run beside
/// the ensemble in every record window with contact.
#[derive(Debug)]
pub struct DiscretisationMember<'a> {
    /// The finer model.
    pub model: TwinModel<'a>,
    /// Its settings: the twin's with the member's steps per sample.
    pub spec: TwinSpec,
}

/// The ensemble's runners: a pool of worker threads, each with a twin of the model (and of the
/// discretisation member's model), that run the members and the discretisation member of every
/// window submitted ([`EnsembleQueue`]). A window's runs go on beside each other and beside
/// the twin's own run of the next steps, so that the long discretisation run of one window does
/// not hold the others up.
struct Ensemble<'r> {
    rec: &'r Recording,
    schedule: ClearanceSchedule,
    observation: Observation,
    tolerance: ComparisonTolerance,
    options: EnsembleOptions<'r>,
    /// Per worker: its twin, and its discretisation member's twin.
    twins: Vec<(Twin, Option<Twin>)>,
}

impl<'r> Ensemble<'r> {
    fn new(
        rec: &'r Recording,
        model: &TwinModel<'_>,
        spec: &TwinSpec,
        schedule: &ClearanceSchedule,
        options: EnsembleOptions<'r>,
    ) -> Result<Ensemble<'r>, TwinReplayError> {
        let runs = options.members + usize::from(options.discretisation.is_some());
        let workers = if options.members == 0 {
            0
        } else {
            options.jobs.clamp(1, runs)
        };
        let clearance = schedule.first().unwrap_or(0.0);
        let twins = (0..workers)
            .map(|_| {
                let twin = Twin::new(model, spec, &rec.layout, clearance)?;
                let fine = match options.discretisation {
                    Some(m) => Some(Twin::new(&m.model, &m.spec, &rec.layout, clearance)?),
                    None => None,
                };
                Ok((twin, fine))
            })
            .collect::<Result<Vec<_>, TwinReplayError>>()?;
        let observation = match twins.first() {
            Some((t, _)) => t.observation().clone(),
            None => Observation::nominal(&model.circuit, model.contact_threshold_v),
        };
        Ok(Ensemble {
            rec,
            schedule: schedule.clone(),
            observation,
            tolerance: spec.tolerance,
            options,
            twins,
        })
    }

    /// Runs `body` with the workers started; they stop when it returns (the runs still queued
    /// then are dropped).
    fn run<T>(
        self,
        body: impl FnOnce(&mut EnsembleQueue) -> Result<T, TwinReplayError>,
    ) -> Result<T, TwinReplayError> {
        let Ensemble {
            rec,
            schedule,
            observation,
            tolerance,
            options,
            twins,
        } = self;
        let tasks = Tasks::default();
        let (send, receive) = std::sync::mpsc::channel();
        let mut queue = EnsembleQueue {
            fine: options.discretisation.is_some(),
            members: options.members,
            contact_windows_only: options.contact_windows_only,
            tolerance,
            windows: VecDeque::new(),
            next: 0,
            done: receive,
            tasks: &tasks,
        };
        let context = RunContext {
            rec,
            schedule: &schedule,
            observation: &observation,
            tolerance,
            relative: options.perturbation,
        };
        std::thread::scope(|scope| {
            for (mut twin, mut fine) in twins {
                let (context, tasks, send) = (&context, &tasks, send.clone());
                scope.spawn(move || {
                    let _close = CloseOnPanic(tasks);
                    while let Some(task) = tasks.next() {
                        let result = context.run(&mut twin, fine.as_mut(), &task);
                        if send.send((task.window, task.run, result)).is_err() {
                            break;
                        }
                    }
                });
            }
            drop(send);
            let out = body(&mut queue);
            tasks.close();
            out
        })
    }
}

/// What a worker needs besides its twins: the recording, the clearances from its start, how
/// the model is observed and compared, the members' perturbation.
struct RunContext<'a> {
    rec: &'a Recording,
    schedule: &'a ClearanceSchedule,
    observation: &'a Observation,
    tolerance: ComparisonTolerance,
    relative: f64,
}

impl RunContext<'_> {
    /// Runs `task` on `twin` (a member) or `fine` (the discretisation member): its features
    /// over the window (`None`: the recording does not hold the block its state starts at).
    fn run(
        &self,
        twin: &mut Twin,
        fine: Option<&mut Twin>,
        task: &Task,
    ) -> Result<Option<Vec<Feature>>, TwinReplayError> {
        let job = &task.job;
        let channels: Vec<&str> = job.channels.iter().map(String::as_str).collect();
        let window = &Window {
            info: &job.info,
            observation: self.observation,
            tolerance: self.tolerance,
            channels: &channels,
            noise: &job.noise,
        };
        match task.run {
            EnsembleRun::Member(m) => {
                let info = &job.info;
                let s = (job.state).perturbed(
                    &info.test,
                    info.step,
                    info.record_attempt,
                    m,
                    self.relative,
                );
                run_member(twin, self.rec, self.schedule, &s, window)
            }
            EnsembleRun::Discretisation => {
                let Some(fine) = fine else { return Ok(None) };
                match lead_in_start(fine, self.rec, self.schedule, job.lead_in.as_ref())? {
                    Some(start) => run_window(fine, self.rec, start, window),
                    None => Ok(None),
                }
            }
        }
    }
}

/// One run of a window's ensemble.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum EnsembleRun {
    /// Member `m` (1, 2, ...) from the step's start with its perturbation.
    Member(usize),
    /// The discretisation member, from rest at the lead-in.
    Discretisation,
}

/// A window's ensemble, as its runs need it: the step, the twin's state at its start and at
/// the lead-in, the compared channels and the measurement's noise floor.
struct Job {
    info: StepInfo,
    state: TwinState,
    lead_in: Option<TwinState>,
    channels: Vec<String>,
    noise: Vec<NoiseFloor>,
}

/// One run to make: which window (in submission order), which run.
struct Task {
    window: u64,
    run: EnsembleRun,
    job: std::sync::Arc<Job>,
}

/// A run's result, back from a worker.
type Done = (
    u64,
    EnsembleRun,
    Result<Option<Vec<Feature>>, TwinReplayError>,
);

/// The runs still to make, shared by the workers.
#[derive(Default)]
struct Tasks {
    queue: std::sync::Mutex<TaskQueue>,
    ready: std::sync::Condvar,
}

/// The runs queued, and whether the queue is closed (the workers stop).
#[derive(Default)]
struct TaskQueue {
    runs: VecDeque<Task>,
    closed: bool,
}

impl Tasks {
    fn lock(&self) -> std::sync::MutexGuard<'_, TaskQueue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn push(&self, tasks: impl IntoIterator<Item = Task>) {
        self.lock().runs.extend(tasks);
        self.ready.notify_all();
    }

    /// The next run, waiting for one; `None` once closed.
    fn next(&self) -> Option<Task> {
        let mut q = self.lock();
        loop {
            if q.closed {
                return None;
            }
            if let Some(t) = q.runs.pop_front() {
                return Some(t);
            }
            q = self.ready.wait(q).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// Drops the runs still queued and stops the workers.
    fn close(&self) {
        let mut q = self.lock();
        q.runs.clear();
        q.closed = true;
        drop(q);
        self.ready.notify_all();
    }
}

/// Closes the runs still to make if its worker panics: the other workers then stop, and a
/// wait for their results ends (and the scope raises the panic) instead of waiting for a run
/// that no worker will return.
struct CloseOnPanic<'a>(&'a Tasks);

impl Drop for CloseOnPanic<'_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.close();
        }
    }
}

/// The windows submitted to the ensemble, released in submission order with their spread as
/// their runs complete.
struct EnsembleQueue<'t> {
    /// Whether a discretisation member runs.
    fine: bool,
    /// Members per window (0: no ensemble, and no workers).
    members: usize,
    contact_windows_only: bool,
    tolerance: ComparisonTolerance,
    windows: VecDeque<Pending>,
    /// The next window's number.
    next: u64,
    done: std::sync::mpsc::Receiver<Done>,
    tasks: &'t Tasks,
}

/// A window released: the step and the twin's comparison with its spread (`None`: the twin
/// missed part of the window).
type Released = (StepInfo, Option<TwinComparison>);

/// A window submitted and not yet released.
struct Pending {
    window: u64,
    /// A window not re-run ([`EnsembleQueue::skip`]).
    skipped: bool,
    info: StepInfo,
    c: Option<TwinComparison>,
    /// Runs not yet back.
    waiting: usize,
    members: Vec<(usize, Option<Vec<Feature>>)>,
    fine: Option<Vec<Feature>>,
    error: Option<TwinReplayError>,
}

impl EnsembleQueue<'_> {
    /// Submits the window of `info` with the twin's comparison `c` (`None`: the twin missed
    /// part of it) and the twin's state at the step's start and at the lead-in (`start`;
    /// `None`: no ensemble for it). The ensemble runs where there is one and the window asks
    /// for it: with `contact_windows_only`, where contact was measured or modelled, or right
    /// after a measured one (`after_contact`: the response still carries the state the
    /// contact left); the discretisation member only there.
    fn submit(
        &mut self,
        info: &StepInfo,
        start: Option<(&TwinState, Option<&TwinState>)>,
        after_contact: bool,
        c: Option<TwinComparison>,
    ) {
        let window = self.next;
        self.next += 1;
        let mut runs = Vec::new();
        if let (Some(c), Some((state, lead_in)), true) = (&c, start, self.members > 0) {
            let measured_contact = c.metrics.contact_fraction - c.contact_fraction_error;
            let contact_window =
                after_contact || c.metrics.contact_fraction > 0.0 || measured_contact > 0.0;
            if contact_window || !self.contact_windows_only {
                if self.fine && contact_window {
                    runs.push(EnsembleRun::Discretisation);
                }
                runs.extend((1..=self.members).map(EnsembleRun::Member));
            }
            if !runs.is_empty() {
                let mut channels: Vec<String> = Vec::new();
                for f in &c.features {
                    if f.channel != CONTACT_CHANNEL && !channels.contains(&f.channel) {
                        channels.push(f.channel.clone());
                    }
                }
                let job = std::sync::Arc::new(Job {
                    info: info.clone(),
                    state: state.clone(),
                    lead_in: lead_in.cloned(),
                    channels,
                    noise: c.observation_noise.clone(),
                });
                // The discretisation member first: the longest run.
                self.tasks.push(runs.iter().map(|&run| Task {
                    window,
                    run,
                    job: job.clone(),
                }));
            }
        }
        self.windows.push_back(Pending {
            window,
            skipped: false,
            info: info.clone(),
            c,
            waiting: runs.len(),
            members: Vec::new(),
            fine: None,
            error: None,
        });
    }

    /// Submits a window that is not run at all (a warm-start replay's step not selected): it
    /// is released in its place as `None`.
    fn skip(&mut self, info: &StepInfo) {
        self.submit(info, None, false, None);
        if let Some(w) = self.windows.back_mut() {
            w.skipped = true;
        }
    }

    /// Releases the windows ready ([`EnsembleQueue::ready`]; with `all`, every window) into
    /// `sink` and `results`, a skipped one into `results` alone (as `None`).
    fn release(
        &mut self,
        all: bool,
        sink: &mut dyn TwinSink,
        results: &mut Vec<Option<TwinComparison>>,
    ) -> Result<(), TwinReplayError> {
        for r in self.ready(all)? {
            match r {
                Some((info, c)) => {
                    sink.step(&info, c.as_ref())?;
                    results.push(c);
                }
                None => results.push(None),
            }
        }
        Ok(())
    }

    /// The windows whose runs are all back, in submission order, with the ensemble's spread
    /// and the discretisation member's difference (`None`: a window skipped); with `all`,
    /// waits for every window submitted.
    fn ready(&mut self, all: bool) -> Result<Vec<Option<Released>>, TwinReplayError> {
        let mut out = Vec::new();
        loop {
            while self.windows.front().is_some_and(|w| w.waiting == 0) {
                if let Some(w) = self.windows.pop_front() {
                    out.push(
                        (!w.skipped)
                            .then(|| w.release(&self.tolerance))
                            .transpose()?,
                    );
                }
            }
            if self.windows.is_empty() {
                break;
            }
            let done = if all {
                // NOTE: the workers hold the senders; all gone with runs still out means one
                // panicked, which the scope's join raises.
                Some(self.done.recv().expect("an ensemble thread panicked"))
            } else {
                self.done.try_recv().ok()
            };
            let Some((window, run, result)) = done else {
                break;
            };
            let Some(w) = self.windows.iter_mut().find(|w| w.window == window) else {
                continue;
            };
            w.waiting -= 1;
            match (result, run) {
                (Ok(f), EnsembleRun::Member(m)) => w.members.push((m, f)),
                (Ok(f), EnsembleRun::Discretisation) => w.fine = f,
                (Err(e), _) => {
                    w.error.get_or_insert(e);
                }
            }
        }
        Ok(out)
    }
}

impl Pending {
    /// The window's comparison with its spread.
    fn release(self, tolerance: &ComparisonTolerance) -> Result<Released, TwinReplayError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let Some(c) = self.c else {
            return Ok((self.info, None));
        };
        if self.members.is_empty() && self.fine.is_none() {
            return Ok((self.info, Some(c)));
        }
        let mut members = self.members;
        // Member order, whatever worker ran it: the result does not depend on `jobs`.
        members.sort_by_key(|(m, _)| *m);
        let features: Vec<Vec<Feature>> = members.into_iter().filter_map(|(_, f)| f).collect();
        let c = c.with_ensemble(&features, tolerance);
        let c = match self.fine {
            Some(f) => c.with_discretisation(&f, tolerance),
            None => c,
        };
        Ok((self.info, Some(c)))
    }
}

/// The record window an ensemble run is compared over: the step, how the model is observed,
/// the compared beam channels and the measurement's noise floor laid on them.
struct Window<'a> {
    info: &'a StepInfo,
    observation: &'a Observation,
    tolerance: ComparisonTolerance,
    channels: &'a [&'a str],
    noise: &'a [NoiseFloor],
}

/// The index of the block of `rec` that starts at sample `sample`, if it holds one.
fn block_at(rec: &Recording, sample: u64) -> Option<usize> {
    let k = rec.blocks.partition_point(|b| b.first_sample < sample);
    (rec.blocks.get(k).map(|b| b.first_sample) == Some(sample)).then_some(k)
}

/// One run of `twin` from `state` through the end of `window`: its features over the window
/// (`None` if the recording does not hold the state's block).
fn run_member(
    twin: &mut Twin,
    rec: &Recording,
    schedule: &ClearanceSchedule,
    state: &TwinState,
    window: &Window<'_>,
) -> Result<Option<Vec<Feature>>, TwinReplayError> {
    let Some(start) = block_at(rec, state.next_sample) else {
        return Ok(None);
    };
    twin.reset();
    twin.set_state(state)?;
    let mut clearances = schedule.clone();
    while clearances.next_due(state.next_sample).is_some() {}
    run_window(twin, rec, (start, clearances), window)
}

/// Puts the discretisation member's `twin` at rest at the start of the step whose state the
/// twin had at `lead_in` (`None`: the recording's first block), with the clearance and wear
/// of that state: (the block index there, the clearances still due), or `None` if the
/// recording does not hold that block.
fn lead_in_start(
    twin: &mut Twin,
    rec: &Recording,
    schedule: &ClearanceSchedule,
    lead_in: Option<&TwinState>,
) -> Result<Option<(usize, ClearanceSchedule)>, TwinReplayError> {
    let mut clearances = schedule.clone();
    let from = match lead_in {
        Some(s) => {
            twin.reset_keeping_geometry(s)?;
            // The clearances due up to the state are in it.
            while clearances.next_due(s.next_sample).is_some() {}
            s.next_sample
        }
        None => {
            let Some(first) = rec.blocks.first() else {
                return Ok(None);
            };
            twin.reset();
            twin.set_clearance(schedule.first().unwrap_or(0.0))?;
            first.first_sample
        }
    };
    Ok(block_at(rec, from).map(|start| (start, clearances)))
}

/// Runs `twin` (ready at block `start`, with the clearances still due) through the end of
/// `window`: its features over the window with the measurement's noise floor laid on its
/// channels (`None` if the twin missed part of the window).
fn run_window(
    twin: &mut Twin,
    rec: &Recording,
    (start, mut clearances): (usize, ClearanceSchedule),
    window: &Window<'_>,
) -> Result<Option<Vec<Feature>>, TwinReplayError> {
    let Window {
        info,
        observation,
        tolerance,
        channels,
        noise,
    } = *window;
    let mut out = TwinWindows::new(observation, tolerance);
    for b in rec.base_blocks(start) {
        if b.first_sample >= info.record_end_sample() {
            break;
        }
        while let Some(c) = clearances.next_due(b.first_sample) {
            twin.set_clearance(c)?;
        }
        out.push(&twin.push_block(&b)?);
    }
    checked(info, out.features(info, rec.layout.dt(), channels, noise))
}

/// The model's result over the record window of `info` (`None`: the model missed part of
/// it), a failure of its metrics as the replay's error naming the step.
fn checked<T>(
    info: &StepInfo,
    result: Option<Result<T, SignalError>>,
) -> Result<Option<T>, TwinReplayError> {
    result
        .transpose()
        .map_err(|source| TwinReplayError::Metrics {
            test: info.test.clone(),
            step: info.step,
            source,
        })
}

/// Where a twin replay's output goes besides the summary (e.g. a copy of the session log,
/// [`TwinLogCopy`]). `()` keeps nothing.
pub trait TwinSink {
    /// The twin's prediction for one block, in block order.
    fn block(&mut self, block: &TwinBlock) -> Result<(), TwinReplayError>;
    /// A step's comparison as its record window completes (`None`: the twin missed part of
    /// the window).
    fn step(
        &mut self,
        info: &StepInfo,
        twin: Option<&TwinComparison>,
    ) -> Result<(), TwinReplayError>;
    /// The twin's state at the start of a step (warm starts), before the step's first block.
    fn state(&mut self, _state: &TwinStateMessage) -> Result<(), TwinReplayError> {
        Ok(())
    }
    /// Whether [`TwinSink::step`] must come in time order with the blocks (a log copy): each
    /// window's ensemble is then waited for as the window completes; else (a sink that keeps
    /// no log) the twin runs on while the ensemble runs, and the steps come later, still in
    /// record-window order.
    fn steps_in_time_order(&self) -> bool {
        true
    }
    /// A step's comparison with the twin's own spread only (its sub-windows), before the
    /// ensemble's joins it ([`TwinSink::step`] has it after): the `--ensemble 0` comparison,
    /// got from the same run.
    fn pointwise(
        &mut self,
        _info: &StepInfo,
        _twin: Option<&TwinComparison>,
    ) -> Result<(), TwinReplayError> {
        Ok(())
    }
}

impl TwinSink for () {
    fn block(&mut self, _: &TwinBlock) -> Result<(), TwinReplayError> {
        Ok(())
    }
    fn steps_in_time_order(&self) -> bool {
        false
    }
    fn step(&mut self, _: &StepInfo, _: Option<&TwinComparison>) -> Result<(), TwinReplayError> {
        Ok(())
    }
}

/// Runs the twin (`model`: ROM, `[model]` extensions, contact observation; settings `spec`;
/// beam length `beam_length` m for the plan's clearances) over the recording `rec` and writes each step's comparison into `summary`
/// (`tests[].steps[].twin`, in the order of the recording's record windows; `summary` is the
/// replayed summary of the same recording), each with the model spread of the ensemble
/// `ensemble`. Every output block and comparison also goes to `sink`.
pub fn replay_twin(
    rec: &Recording,
    summary: &mut SessionSummary,
    model: &TwinModel<'_>,
    spec: &TwinSpec,
    beam_length: f64,
    ensemble: EnsembleOptions<'_>,
    sink: &mut dyn TwinSink,
) -> Result<TwinReplayStats, TwinReplayError> {
    if !rec.gaps.is_empty() {
        return Err(TwinReplayError::Gaps {
            blocks: rec.gaps.iter().map(|g| g.blocks).sum(),
            seconds: rec.gaps.iter().map(|g| g.seconds).sum(),
        });
    }
    let wall = std::time::Instant::now();
    let mut clearances = ClearanceSchedule::of_events(
        beam_length,
        model.extensions.clearance.as_ref(),
        &rec.events,
    );
    let mut twin = Twin::new(model, spec, &rec.layout, clearances.first().unwrap_or(0.0))?;
    let mut step_starts = StepStarts::of_events(&rec.events);
    let dt = rec.layout.dt();
    // The measured step summaries are in record-window order.
    let mut pending: VecDeque<(StepInfo, StepSummary)> = rec
        .record_windows()
        .cloned()
        .zip(summary.steps().map(|s| s.measured.clone()))
        .collect();
    let o = twin.observation();
    let mut out = TwinWindows::new(o, spec.tolerance);
    let mut stats = TwinReplayStats::default();
    let members = Ensemble::new(rec, model, spec, &clearances, ensemble)?;
    let after_contact = after_contact(rec, summary);
    let mut starts: HashMap<(String, usize), TwinState> = HashMap::new();
    // With a sink that takes the steps in time order, each window's ensemble is waited for
    // as it completes; else the twin runs on while it runs.
    let wait = sink.steps_in_time_order();
    let submit = |done: Vec<Completed>,
                  queue: &mut EnsembleQueue,
                  starts: &HashMap<(String, usize), TwinState>,
                  sink: &mut dyn TwinSink|
     -> Result<(), TwinReplayError> {
        for (info, c) in done {
            sink.pointwise(&info, c.as_ref().and_then(|c| c.as_ref().ok()))?;
            let c = checked(&info, c)?;
            let start = starts
                .get(&(info.test.clone(), info.step))
                .map(|state| (state, lead_in(starts.values(), state)));
            let after = after_contact.contains(&(info.test.clone(), info.step));
            queue.submit(&info, start, after, c);
        }
        Ok(())
    };
    let results = members.run(|queue| {
        let mut results: Vec<Option<TwinComparison>> = Vec::new();
        for b in rec.base_blocks(0) {
            while let Some(c) = clearances.next_due(b.first_sample) {
                twin.set_clearance(c)?;
            }
            if let Some((test, step)) = step_starts.next_due(b.first_sample) {
                if let Some(state) = twin.state() {
                    let message = TwinStateMessage { test, step, state };
                    sink.state(&message)?;
                    if ensemble.members > 0 {
                        starts.insert((message.test, message.step), message.state);
                    }
                }
            }
            let tb = twin.push_block(&b)?;
            stats.blocks += 1;
            stats.solver_failures += tb.solver_failure_count();
            sink.block(&tb)?;
            out.push(&tb);
            let done = out.complete(&mut pending, dt, false);
            if !done.is_empty() {
                submit(done, queue, &starts, sink)?;
                queue.release(wait, sink, &mut results)?;
            }
        }
        let done = out.complete(&mut pending, dt, true);
        submit(done, queue, &starts, sink)?;
        queue.release(true, sink, &mut results)?;
        Ok(results)
    })?;
    stats.steps_compared = summary.attach_twin(results);
    stats.wall_per_rig_second =
        wall.elapsed().as_secs_f64() / rec.rig_seconds().max(f64::MIN_POSITIVE);
    Ok(stats)
}

/// The steps a warm-start twin replay re-runs (`rigtwin replay --twin --steps`): a list of
/// `TEST` (every step of the test) and `TEST:N` or `TEST:N-M` (steps N to M, counted from 1),
/// comma-separated.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StepSelection {
    /// (test, first step, last step) with 0-based steps; `None`: every step.
    items: Vec<(String, Option<(usize, usize)>)>,
}

/// A step selection that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "--steps {text:?}: {why}; expected TEST, TEST:N or TEST:N-M (steps counted from 1),      comma-separated"
)]
pub struct StepSelectionError {
    /// The selection given.
    pub text: String,
    /// What is wrong.
    pub why: String,
}

impl std::str::FromStr for StepSelection {
    type Err = StepSelectionError;

    fn from_str(text: &str) -> Result<StepSelection, StepSelectionError> {
        let err = |why: String| StepSelectionError {
            text: text.to_string(),
            why,
        };
        let mut items = Vec::new();
        for item in text.split(',').map(str::trim) {
            let (test, range) = match item.rsplit_once(':') {
                Some((test, range)) => (test, Some(range)),
                None => (item, None),
            };
            if test.is_empty() {
                return Err(err(format!("{item:?} names no test")));
            }
            let number = |s: &str| -> Result<usize, StepSelectionError> {
                match s.trim().parse::<usize>() {
                    Ok(n) if n >= 1 => Ok(n - 1),
                    _ => Err(err(format!(
                        "{s:?} in {item:?} is not a step number (1, 2, ...)"
                    ))),
                }
            };
            let range = match range {
                None => None,
                Some(r) => {
                    let (a, b) = match r.split_once('-') {
                        Some((a, b)) => (number(a)?, number(b)?),
                        None => (number(r)?, number(r)?),
                    };
                    if b < a {
                        return Err(err(format!("{item:?}: the range runs backwards")));
                    }
                    Some((a, b))
                }
            };
            items.push((test.to_string(), range));
        }
        Ok(StepSelection { items })
    }
}

impl StepSelection {
    /// Whether step `step` (0-based) of test `test` is selected.
    pub fn contains(&self, test: &str, step: usize) -> bool {
        self.items
            .iter()
            .any(|(t, r)| t == test && r.is_none_or(|(a, b)| (a..=b).contains(&step)))
    }

    /// The items that select no record window of `rec` (as written, for an error).
    fn unmatched(&self, rec: &Recording) -> Vec<String> {
        self.items
            .iter()
            .filter(|(t, r)| {
                !rec.record_windows()
                    .any(|w| &w.test == t && r.is_none_or(|(a, b)| (a..=b).contains(&w.step)))
            })
            .map(|(t, r)| match r {
                None => t.clone(),
                Some((a, b)) if a == b => format!("{t}:{}", a + 1),
                Some((a, b)) => format!("{t}:{}-{}", a + 1, b + 1),
            })
            .collect()
    }
}

/// Re-runs the twin on the selected steps of the recording only, each from the twin's state
/// logged at the step's start (`/twin/state`, a warm start; from rest for a step that starts
/// with the recording), through the end of its record window, and writes their comparisons
/// into `summary` (the other steps get none). With the model the states were logged with, each
/// comparison equals, bit for bit, the one the whole session's twin (live or replayed) made.
/// Arguments as for [`replay_twin`]; only the comparisons go to `sink`.
#[allow(clippy::too_many_arguments)]
pub fn replay_twin_steps(
    rec: &Recording,
    summary: &mut SessionSummary,
    model: &TwinModel<'_>,
    spec: &TwinSpec,
    beam_length: f64,
    select: &StepSelection,
    ensemble: EnsembleOptions<'_>,
    sink: &mut dyn TwinSink,
) -> Result<TwinReplayStats, TwinReplayError> {
    let unmatched = select.unmatched(rec);
    if !unmatched.is_empty() {
        let mut have: Vec<String> = Vec::new();
        for w in rec.record_windows() {
            match have.last_mut() {
                Some(last) if last.starts_with(&format!("{}:", w.test)) => {
                    *last = format!("{}:1-{}", w.test, w.step + 1);
                }
                _ => have.push(format!("{}:1-{}", w.test, w.step + 1)),
            }
        }
        return Err(TwinReplayError::NoSuchSteps {
            steps: unmatched.join(", "),
            have: have.join(", "),
        });
    }
    let wall = std::time::Instant::now();
    let first_schedule = ClearanceSchedule::of_events(
        beam_length,
        model.extensions.clearance.as_ref(),
        &rec.events,
    );
    let mut twin = Twin::new(
        model,
        spec,
        &rec.layout,
        first_schedule.first().unwrap_or(0.0),
    )?;
    let dt = rec.layout.dt();
    let o = twin.observation().clone();
    let members = Ensemble::new(rec, model, spec, &first_schedule, ensemble)?;
    let after_contact = after_contact(rec, summary);
    let mut stats = TwinReplayStats::default();
    let mut rig_seconds = 0.0;
    let first_block = rec.blocks.first().map_or(0, |b| b.first_sample);
    // As in `replay_twin`: the ensemble waited for per window only for a sink in time order.
    let wait = sink.steps_in_time_order();
    let results = members.run(|queue| {
        let mut results = Vec::new();
        for (info, measured) in rec
            .record_windows()
            .zip(summary.steps().map(|s| &s.measured))
        {
            if !select.contains(&info.test, info.step) {
                queue.skip(info);
                continue;
            }
            let logged = rec
                .twin_states
                .iter()
                .rev()
                .find(|m| m.test == info.test && m.step == info.step);
            let mut clearances = first_schedule.clone();
            twin.reset();
            let from = match logged {
                Some(m) => {
                    twin.set_state(&m.state)?;
                    // The clearances due up to the state are in it.
                    while clearances.next_due(m.state.next_sample).is_some() {}
                    Some(m.state.next_sample)
                }
                None if step_start(rec, info).is_some_and(|s| s <= first_block) => {
                    twin.set_clearance(first_schedule.first().unwrap_or(0.0))?;
                    Some(first_block)
                }
                None => None,
            };
            let start =
                from.and_then(|from| rec.blocks.iter().position(|b| b.first_sample == from));
            let Some(start) = start else {
                return Err(TwinReplayError::NoState {
                    test: info.test.clone(),
                    step: info.step + 1,
                    states: rec.twin_states.len(),
                });
            };
            let mut out = TwinWindows::new(&o, spec.tolerance);
            for b in rec.base_blocks(start) {
                if b.first_sample >= info.record_end_sample() {
                    break;
                }
                while let Some(c) = clearances.next_due(b.first_sample) {
                    twin.set_clearance(c)?;
                }
                let tb = twin.push_block(&b)?;
                stats.blocks += 1;
                rig_seconds += b.len as f64 * dt;
                stats.solver_failures += tb.solver_failure_count();
                out.push(&tb);
            }
            let c = out.compare(info, measured, dt);
            sink.pointwise(info, c.as_ref().and_then(|c| c.as_ref().ok()))?;
            let c = checked(info, c)?;
            let start = logged.map(|m| {
                let lead_in = lead_in(rec.twin_states.iter().map(|m| &m.state), &m.state);
                (&m.state, lead_in)
            });
            let after = after_contact.contains(&(info.test.clone(), info.step));
            queue.submit(info, start, after, c);
            queue.release(wait, sink, &mut results)?;
        }
        queue.release(true, sink, &mut results)?;
        Ok(results)
    })?;
    stats.steps_compared = summary.attach_twin(results);
    stats.wall_per_rig_second = wall.elapsed().as_secs_f64() / rig_seconds.max(f64::MIN_POSITIVE);
    Ok(stats)
}

/// The record windows (test, step) whose measured window before (in the recording's order)
/// had contact.
fn after_contact(rec: &Recording, summary: &SessionSummary) -> HashSet<(String, usize)> {
    let mut out = HashSet::new();
    let mut before = false;
    for (info, s) in rec.record_windows().zip(summary.steps()) {
        if before {
            out.insert((info.test.clone(), info.step));
        }
        before = s.measured.metrics.contact_fraction > 0.0;
    }
    out
}

/// The latest of `states` before `state` (the twin's state at the start of the step before):
/// the discretisation member's lead-in.
fn lead_in<'s>(
    states: impl Iterator<Item = &'s TwinState>,
    state: &TwinState,
) -> Option<&'s TwinState> {
    states
        .filter(|s| s.next_sample < state.next_sample)
        .max_by_key(|s| s.next_sample)
}

/// The sample of the `step_start` event of the step of `info`.
fn step_start(rec: &Recording, info: &StepInfo) -> Option<u64> {
    rec.events.iter().find_map(|e| match &e.kind {
        crate::control::EventKind::StepStart { test, step, .. }
            if *test == info.test && *step == info.step =>
        {
            Some(e.sample)
        }
        _ => None,
    })
}

/// Topics of the recorded twin, left out of the copy.
fn is_twin_topic(topic: &str) -> bool {
    topic.starts_with("/twin/")
}

/// The copy being written (see the module documentation).
pub struct TwinLogCopy {
    handle: LogHandle,
    join: LogJoin,
    blocks: LogChannel<TwinSamples>,
    states: LogChannel<TwinStateMessage>,
    steps: LogChannel<TwinStepMessage>,
    /// DAQ sample interval, s (log time of a step's comparison).
    dt: f64,
}

impl std::fmt::Debug for TwinLogCopy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwinLogCopy")
            .field("path", &self.handle.path())
            .finish()
    }
}

impl TwinLogCopy {
    /// Creates `path` and copies the session log `source` into it (all but its twin topics,
    /// streamed: the source is read twice, never whole); the twin's output follows through
    /// [`TwinSink`]. `model` says which model the twin runs (for the metadata), `dt` is the DAQ
    /// sample interval, s.
    pub fn create(
        path: &Path,
        source: &Path,
        model: &str,
        dt: f64,
    ) -> Result<TwinLogCopy, TwinReplayError> {
        let identity = |p: &Path| {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
        };
        let same_path = matches!(
            (path.canonicalize(), source.canonicalize()),
            (Ok(a), Ok(b)) if a == b
        );
        let same_inode = matches!(
            (identity(path), identity(source)),
            (Some(a), Some(b)) if a == b
        );
        if same_path || same_inode {
            return Err(TwinReplayError::Overwrite {
                path: path.display().to_string(),
            });
        }
        // The channels, metadata and attachments first: the copy is created with them.
        let session = stream_session(source, |_| Ok::<(), LogReadError>(()))?;
        let mut metadata: Vec<MetadataRecord> = session
            .metadata
            .iter()
            .filter(|(name, _)| name != RIGTWIN_METADATA && name != TWIN_REPLAY_METADATA)
            .cloned()
            .collect();
        metadata.push((
            TWIN_REPLAY_METADATA.into(),
            [
                ("model".to_string(), model.to_string()),
                ("source_log".to_string(), session.path.display().to_string()),
            ]
            .into_iter()
            .collect(),
        ));
        let attachments: Vec<Attachment> = session.attachments.clone();
        let (handle, join) =
            SessionLog::create(path, LogOptions::default(), metadata, attachments)?;
        let mut channels = std::collections::BTreeMap::new();
        for c in session.channels.iter().filter(|c| !is_twin_topic(&c.topic)) {
            let Some(schema) = &c.schema else {
                return Err(TwinReplayError::NoSchema {
                    path: session.path.display().to_string(),
                    topic: c.topic.clone(),
                });
            };
            let raw = handle.raw_channel(&c.topic, &schema.name, schema.data.clone())?;
            channels.insert(c.id, raw);
        }
        stream_session(source, |m| {
            if let Some(raw) = channels.get(&m.channel_id) {
                handle.log_json_waiting(raw, m.log_time, m.data.clone())?;
            }
            Ok::<(), TwinReplayError>(())
        })?;
        Ok(TwinLogCopy {
            blocks: handle.channel(TOPIC_TWIN_BLOCKS)?,
            states: handle.channel(TOPIC_TWIN_STATE)?,
            steps: handle.channel(TOPIC_TWIN_STEPS)?,
            handle,
            join,
            dt,
        })
    }

    /// Finishes the file.
    pub fn close(self) -> Result<LogStats, TwinReplayError> {
        drop(self.handle);
        Ok(self.join.close()?)
    }

    fn put<T: serde::Serialize>(
        &self,
        channel: &LogChannel<T>,
        time: f64,
        value: &T,
    ) -> Result<(), TwinReplayError> {
        let json = serde_json::to_vec(value)?;
        self.handle
            .log_json_waiting(channel.raw(), log_time_ns(time), json)?;
        Ok(())
    }
}

impl TwinSink for TwinLogCopy {
    fn block(&mut self, block: &TwinBlock) -> Result<(), TwinReplayError> {
        self.put(&self.blocks, block.time, &TwinSamples::from(block))
    }

    fn step(
        &mut self,
        info: &StepInfo,
        twin: Option<&TwinComparison>,
    ) -> Result<(), TwinReplayError> {
        let time = info.record_end_time(self.dt);
        self.put(&self.steps, time, &TwinStepMessage::of(info, twin))
    }

    fn state(&mut self, state: &TwinStateMessage) -> Result<(), TwinReplayError> {
        let time = state.state.next_sample as f64 * self.dt;
        self.put(&self.states, time, state)
    }
}
