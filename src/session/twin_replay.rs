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
#[derive(Clone, Copy)]
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
pub struct DiscretisationMember<'a> {
    /// The finer model.
    pub model: TwinModel<'a>,
    /// Its settings: the twin's with the member's steps per sample.
    pub spec: TwinSpec,
}

/// The ensemble's runner: one twin per thread, the recording, the clearances from the start,
/// and the discretisation member's twin, if any.
struct Ensemble<'r> {
    rec: &'r Recording,
    schedule: ClearanceSchedule,
    observation: Observation,
    tolerance: ComparisonTolerance,
    options: EnsembleOptions<'r>,
    twins: Vec<Twin>,
    fine: Option<Twin>,
}

impl<'r> Ensemble<'r> {
    fn new(
        rec: &'r Recording,
        model: &TwinModel<'_>,
        spec: &TwinSpec,
        schedule: &ClearanceSchedule,
        options: EnsembleOptions<'r>,
    ) -> Result<Ensemble<'r>, TwinReplayError> {
        let threads = if options.members == 0 {
            0
        } else {
            options.jobs.clamp(1, options.members)
        };
        let twins = (0..threads)
            .map(|_| Twin::new(model, spec, &rec.layout, schedule.first().unwrap_or(0.0)))
            .collect::<Result<Vec<_>, _>>()?;
        let fine = match options.discretisation {
            Some(m) if threads > 0 => Some(Twin::new(
                &m.model,
                &m.spec,
                &rec.layout,
                schedule.first().unwrap_or(0.0),
            )?),
            _ => None,
        };
        let observation = match twins.first() {
            Some(t) => t.observation().clone(),
            None => Observation::nominal(&model.circuit, model.contact_threshold_v),
        };
        Ok(Ensemble {
            rec,
            schedule: schedule.clone(),
            observation,
            tolerance: spec.tolerance,
            options,
            twins,
            fine,
        })
    }

    /// `c` (the twin's comparison over the record window of `info`) with the model spread of
    /// the ensemble started from `state`, and, in a window with contact (measured or
    /// modelled) or right after one (`after_contact`: the measured window before had contact;
    /// the response there still carries the state the contact left), the discretisation
    /// member's difference, the member run from rest at `lead_in` (the twin's state at the
    /// start of the step before; `None`: the recording's start).
    fn apply(
        &mut self,
        info: &StepInfo,
        (state, lead_in): (&TwinState, Option<&TwinState>),
        after_contact: bool,
        c: TwinComparison,
    ) -> Result<TwinComparison, TwinReplayError> {
        if self.twins.is_empty() {
            return Ok(c);
        }
        let measured_contact = c.metrics.contact_fraction - c.contact_fraction_error;
        let contact_window =
            after_contact || c.metrics.contact_fraction > 0.0 || measured_contact > 0.0;
        if self.options.contact_windows_only && !contact_window {
            return Ok(c);
        }
        let fine = self.fine.as_mut().filter(|_| contact_window);
        let mut channels: Vec<&str> = Vec::new();
        for f in &c.features {
            if f.channel != CONTACT_CHANNEL && !channels.contains(&f.channel.as_str()) {
                channels.push(&f.channel);
            }
        }
        let threads = self.twins.len();
        let members = self.options.members;
        let (rec, schedule, o, tolerance, relative) = (
            self.rec,
            &self.schedule,
            &self.observation,
            self.tolerance,
            self.options.perturbation,
        );
        let window = &Window {
            info,
            observation: o,
            tolerance,
            channels: &channels,
            noise: c.observation_noise.as_slice(),
        };
        let (runs, fine): (Vec<Result<Vec<MemberRun>, TwinReplayError>>, _) =
            std::thread::scope(|scope| {
                let fine = fine.map(|twin| {
                    scope.spawn(move || {
                        let Some(start) = lead_in_start(twin, rec, schedule, lead_in)? else {
                            return Ok(None);
                        };
                        run_window(twin, rec, start, window)
                    })
                });
                let handles: Vec<_> = self
                    .twins
                    .iter_mut()
                    .enumerate()
                    .map(|(j, twin)| {
                        scope.spawn(move || {
                            (1..=members)
                                .skip(j)
                                .step_by(threads)
                                .map(|m| {
                                    let s = state.perturbed(
                                        &info.test,
                                        info.step,
                                        info.record_attempt,
                                        m,
                                        relative,
                                    );
                                    let f = run_member(twin, rec, schedule, &s, window)?;
                                    Ok((m, f))
                                })
                                .collect()
                        })
                    })
                    .collect();
                let runs = handles
                    .into_iter()
                    .map(|h| h.join().expect("an ensemble thread panicked"))
                    .collect();
                let fine: Result<Option<Vec<Feature>>, TwinReplayError> = match fine {
                    Some(h) => h
                        .join()
                        .expect("the discretisation member's thread panicked"),
                    None => Ok(None),
                };
                (runs, fine)
            });
        let mut all = Vec::with_capacity(members);
        for r in runs {
            all.extend(r?);
        }
        // Member order, whatever thread ran it: the result does not depend on `jobs`.
        all.sort_by_key(|(m, _)| *m);
        let features: Vec<Vec<Feature>> = all.into_iter().filter_map(|(_, f)| f).collect();
        let c = c.with_ensemble(&features, &self.tolerance);
        Ok(match fine? {
            Some(f) => c.with_discretisation(&f, &self.tolerance),
            None => c,
        })
    }
}

/// An ensemble member (1, 2, ...) and its features over the window (`None`: the recording
/// does not hold the block its state starts at).
type MemberRun = (usize, Option<Vec<Feature>>);

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
    match out.features(info, rec.layout.dt(), channels, noise) {
        Some(Ok(f)) => Ok(Some(f)),
        Some(Err(source)) => Err(TwinReplayError::Metrics {
            test: info.test.clone(),
            step: info.step,
            source,
        }),
        None => Ok(None),
    }
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
    let mut results: Vec<Option<TwinComparison>> = Vec::new();
    let o = twin.observation();
    let mut out = TwinWindows::new(o, spec.tolerance);
    let mut stats = TwinReplayStats::default();
    let mut members = Ensemble::new(rec, model, spec, &clearances, ensemble)?;
    let after_contact = after_contact(rec, summary);
    let mut starts: HashMap<(String, usize), TwinState> = HashMap::new();
    let mut take = |done: Vec<Completed>,
                    starts: &HashMap<(String, usize), TwinState>,
                    results: &mut Vec<Option<TwinComparison>>,
                    sink: &mut dyn TwinSink|
     -> Result<(), TwinReplayError> {
        for (info, c) in done {
            sink.pointwise(&info, c.as_ref().and_then(|c| c.as_ref().ok()))?;
            let c = match c {
                Some(Ok(c)) => match starts.get(&(info.test.clone(), info.step)) {
                    Some(state) => {
                        let lead_in = lead_in(starts.values(), state);
                        let after = after_contact.contains(&(info.test.clone(), info.step));
                        Some(members.apply(&info, (state, lead_in), after, c)?)
                    }
                    None => Some(c),
                },
                Some(Err(source)) => {
                    return Err(TwinReplayError::Metrics {
                        test: info.test,
                        step: info.step,
                        source,
                    })
                }
                None => None,
            };
            sink.step(&info, c.as_ref())?;
            results.push(c);
        }
        Ok(())
    };
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
        take(done, &starts, &mut results, sink)?;
    }
    let done = out.complete(&mut pending, dt, true);
    take(done, &starts, &mut results, sink)?;
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
    let mut members = Ensemble::new(rec, model, spec, &first_schedule, ensemble)?;
    let after_contact = after_contact(rec, summary);
    let mut stats = TwinReplayStats::default();
    let mut rig_seconds = 0.0;
    let mut results = Vec::new();
    let first_block = rec.blocks.first().map_or(0, |b| b.first_sample);
    for (info, measured) in rec
        .record_windows()
        .zip(summary.steps().map(|s| &s.measured))
    {
        if !select.contains(&info.test, info.step) {
            results.push(None);
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
        let start = from.and_then(|from| rec.blocks.iter().position(|b| b.first_sample == from));
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
        let c = match c {
            Some(Ok(c)) => match logged {
                Some(m) => {
                    let lead_in = lead_in(rec.twin_states.iter().map(|m| &m.state), &m.state);
                    let after = after_contact.contains(&(info.test.clone(), info.step));
                    Some(members.apply(info, (&m.state, lead_in), after, c)?)
                }
                None => Some(c),
            },
            Some(Err(source)) => {
                return Err(TwinReplayError::Metrics {
                    test: info.test.clone(),
                    step: info.step,
                    source,
                })
            }
            None => None,
        };
        sink.step(info, c.as_ref())?;
        results.push(c);
    }
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
