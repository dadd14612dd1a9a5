//! The model re-run on the steps that carry the evidence ([`ModelRunner`]): a hypothesis is
//! judged by running the twin, with the hypothesis' extensions, over the recorded base motion
//! of some tests and comparing it with the measurement step by step, as `replay --twin` does.
//!
//! A run covers whole tests, or a test's steps up to one that ends the evidence (e.g. two
//! steps past its first contact, [`ModelRunner::run_spans`]), each group of consecutive tests
//! in one stretch, from rest at the start of the lead-in, `LEAD_IN_STEPS` steps before the
//! group's first step (the previous test's last steps, or the session's start; for the steps
//! near a resonance, before the first of them, [`LeadIn::Span`]): the twin's own state cannot
//! be carried in from another model (a state belongs to the model that made it), and a free
//! transient from rest decays over the lead-in's steps and the first step's settling before
//! the first compared record window. A stretch longer than `LONG_STRETCH_S` of rig time is
//! split at a test boundary, each piece from rest at its lead-in. Groups run on the runner's
//! threads, the longest first, each thread taking the next one left; the results do not
//! depend on the number of threads. A hypothesis that changes the clearance over the session
//! (wear) runs the whole session in one stretch, unless a run of it at another twin step left
//! the clearance and wear at each test's lead-in to start from
//! ([`ModelRunner::set_wear_from`]).

use std::collections::{BTreeMap, HashMap, VecDeque};

use crate::config::PhysicsSpec;
use crate::control::{EventKind, StepInfo, StepSummary};
use crate::rom::Rom;
use crate::session::replay::Recording;
use crate::session::summary::{SessionSummary, StepResult};
use crate::twin::{ClearanceSchedule, FeatureComparison, TwinModel, TwinSpec, TwinWindows};

use super::outcome::{Regime, StepScores};
use super::DiagnoseError;

/// A record window of the session with its measurement and where it belongs.
#[derive(Clone, Debug)]
pub struct SessionStep {
    /// The step's record window.
    pub info: StepInfo,
    /// The measured summary.
    pub measured: StepSummary,
    /// Index of the test in the session, from 0.
    pub test_index: usize,
    /// Base level of the test / l.
    pub level: f64,
    /// The step's regime (from the measurement).
    pub regime: Regime,
}

impl SessionStep {
    /// Whether the measured record window had no contact.
    pub fn impact_free(&self) -> bool {
        self.regime != Regime::Impacts
    }

    /// The step compared: its `features` (none when the model missed part of the window).
    pub fn scores(&self, features: Vec<FeatureComparison>) -> StepScores {
        StepScores {
            test: self.info.test.clone(),
            test_index: self.test_index,
            step: self.info.step,
            omega_ratio: self.info.omega_ratio,
            regime: self.regime,
            level: self.level,
            features,
        }
    }
}

/// The steps of a session, in order, with the samples where the tests' steps start.
#[derive(Clone, Debug)]
pub struct SessionSteps {
    /// Test names in session order.
    pub tests: Vec<String>,
    /// Base level / l per test.
    pub levels: Vec<f64>,
    /// The record windows, in session order.
    pub steps: Vec<SessionStep>,
    /// (test index, step, sample) of every `step_start` event, in order.
    starts: Vec<(usize, usize, u64)>,
}

/// Whether the rig had contact in step `s`'s record window (its regime is the impact band).
pub fn had_contact(s: &StepResult) -> bool {
    s.measured.metrics.contact_fraction > 0.0
}

impl SessionSteps {
    /// Those of `tests` without measured contact, where there are any; else `tests`. What
    /// impact-free evidence is validated on: a test with contact also holds impact-free steps
    /// beside its contact, which move with where the model's contact begins.
    pub fn without_contact_where_any(&self, tests: Vec<usize>) -> Vec<usize> {
        let with_contact = self.tests_with(false);
        let free: Vec<usize> = (tests.iter().copied())
            .filter(|t| !with_contact.contains(t))
            .collect();
        if free.is_empty() {
            tests
        } else {
            free
        }
    }

    /// The indices of the tests named in `names`, in session order.
    pub fn indices_of(&self, names: &[String]) -> Vec<usize> {
        (self.tests.iter().enumerate())
            .filter(|(_, t)| names.contains(t))
            .map(|(i, _)| i)
            .collect()
    }

    /// Tests (indices) with at least one step of regime other than `Impacts` (`impact_free`)
    /// or of `Impacts`.
    pub fn tests_with(&self, impact_free: bool) -> Vec<usize> {
        let mut t: Vec<usize> = self
            .steps
            .iter()
            .filter(|s| s.impact_free() == impact_free)
            .map(|s| s.test_index)
            .collect();
        t.dedup();
        t
    }

    /// The steps of recording `rec` whose replayed summary is `summary`.
    pub fn of(rec: &Recording, summary: &SessionSummary) -> SessionSteps {
        let mut tests: Vec<String> = Vec::new();
        let mut levels: Vec<f64> = Vec::new();
        let mut starts = Vec::new();
        for e in &rec.events {
            match &e.kind {
                EventKind::TestStart { test, level, .. } => {
                    tests.push(test.clone());
                    levels.push(*level);
                }
                EventKind::StepStart { test, step, .. } => {
                    let ti = tests.iter().rposition(|t| t == test).unwrap_or(0);
                    starts.push((ti, *step, e.sample));
                }
                _ => {}
            }
        }
        let lowest = levels.iter().copied().fold(f64::INFINITY, f64::min);
        let steps = rec
            .record_windows()
            .zip(summary.steps())
            .map(|(info, s)| {
                let test_index = tests.iter().rposition(|t| *t == info.test).unwrap_or(0);
                let level = levels.get(test_index).copied().unwrap_or(0.0);
                let regime = if had_contact(s) {
                    Regime::Impacts
                } else if level <= lowest * (1.0 + 1e-9) {
                    Regime::ImpactFreeLow
                } else {
                    Regime::ImpactFreeHigh
                };
                SessionStep {
                    info: info.clone(),
                    measured: s.measured.clone(),
                    test_index,
                    level,
                    regime,
                }
            })
            .collect();
        SessionSteps {
            tests,
            levels,
            steps,
            starts,
        }
    }

    /// The first step of test `ti` with measured contact.
    pub fn first_contact(&self, ti: usize) -> Option<usize> {
        self.steps
            .iter()
            .find(|s| s.test_index == ti && !s.impact_free())
            .map(|s| s.info.step)
    }

    /// The last step of test `ti` with measured contact; `None` without any.
    pub fn last_contact(&self, ti: usize) -> Option<usize> {
        (self.steps.iter())
            .rfind(|s| s.test_index == ti && !s.impact_free())
            .map(|s| s.info.step)
    }

    /// The step `before` steps before the first measured contact step of test `ti` (where a
    /// fit of the contact's geometry starts comparing: the steps before are the same for every
    /// geometry it tries), the first step when that is earlier, or the test has no contact.
    pub fn before_first_contact(&self, ti: usize, before: usize) -> usize {
        self.first_contact(ti)
            .map_or(0, |f| f.saturating_sub(before))
    }

    /// Test `ti`'s steps before its first measured contact: the whole test without contact,
    /// `None` when its first step has contact. A run over them stops before the contact (the
    /// slowest part to run, and chaotic) and compares what the linear model and the clamp see.
    pub fn before_contact(&self, ti: usize) -> Option<Span> {
        match self.first_contact(ti) {
            None => Some(Span::whole(ti)),
            Some(0) => None,
            Some(f) => Some(Span::of_test(ti, 0, Some(f - 1))),
        }
    }

    /// [`SessionSteps::before_contact`] cut to the steps near test `ti`'s resonance: from the
    /// first to the last step whose measured response (both tips' RMS velocities over the
    /// base's, summed) rises above the span's smallest by at least `fraction` of the largest
    /// rise, run from rest at their own lead-in ([`LeadIn::Span`]). Off resonance the tips move
    /// little and a joint in the clamp hardly slips: those steps carry little of the evidence
    /// a resonance fit looks for, and a run from rest at steps below the cut starts with a
    /// free transient that small, decayed over the lead-in's steps and the first one's
    /// settling (`LEAD_IN_STEPS`) before the first compared record window.
    pub fn near_resonance(&self, ti: usize, fraction: f64) -> Option<Span> {
        self.near_resonance_of(self.before_contact(ti)?, fraction)
    }

    /// Test `ti`'s steps after its last measured contact where its first step has contact
    /// (an up-sweep that starts in the impact band and leaves it), cut to those near the
    /// resonance as [`SessionSteps::near_resonance`] cuts: the impact-free steps such a test
    /// has. `None` where the test has none, or where its first step is impact-free.
    pub fn near_resonance_after_contact(&self, ti: usize, fraction: f64) -> Option<Span> {
        if self.first_contact(ti) != Some(0) {
            return None;
        }
        let from = self.last_contact(ti)? + 1;
        (from <= self.last_step(ti)?).then_some(())?;
        let tail = Span {
            test: ti,
            from,
            through: None,
            lead_in: LeadIn::Span,
        };
        self.near_resonance_of(tail, fraction)
    }

    /// `span`'s steps (impact-free) cut to those near the resonance: see
    /// [`SessionSteps::near_resonance`].
    fn near_resonance_of(&self, span: Span, fraction: f64) -> Option<Span> {
        let ti = span.test;
        let size = |s: &SessionStep| s.measured.metrics.rms_upper + s.measured.metrics.rms_lower;
        let steps: Vec<&SessionStep> = self.steps.iter().filter(|s| span.covers(s)).collect();
        let peak = steps.iter().map(|s| size(s)).fold(0.0, f64::max);
        let floor = steps.iter().map(|s| size(s)).fold(peak, f64::min);
        if !(peak.is_finite() && floor.is_finite() && peak > floor) {
            return Some(span);
        }
        let near = steps
            .iter()
            .filter(|s| size(s) - floor >= fraction * (peak - floor))
            .map(|s| s.info.step);
        let from = near.clone().min()?;
        let through = near.max()?;
        Some(Span {
            test: ti,
            from,
            through: Some(through),
            lead_in: LeadIn::Span,
        })
    }

    /// The step `past` steps after the first (`first`) or last measured contact step of test
    /// `ti`, to cut a run there; `None` (the whole test) when the test has no contact or that
    /// step is its last or beyond.
    pub fn past_contact(&self, ti: usize, past: usize, first: bool) -> Option<usize> {
        let at = if first {
            self.first_contact(ti)
        } else {
            self.last_contact(ti)
        }? + past;
        (at < self.last_step(ti)?).then_some(at)
    }

    /// The last step of test `ti` recorded; `None` without any.
    pub fn last_step(&self, ti: usize) -> Option<usize> {
        (self.steps.iter())
            .filter(|s| s.test_index == ti)
            .map(|s| s.info.step)
            .max()
    }

    /// The sample where the step of record window `w` starts: the last `step_start` of its
    /// test and step before its record window (a step recorded again starts again).
    pub fn step_start(&self, w: &SessionStep) -> Option<u64> {
        (self.starts.iter())
            .filter(|s| s.0 == w.test_index && s.1 == w.info.step)
            .map(|s| s.2)
            .rfind(|&at| at <= w.info.record_first_sample)
    }

    /// The sample where the lead-in of test `ti` starts: [`LEAD_IN_STEPS`] steps before its
    /// first step, or `None` (the recording's start) for a test that many steps from the
    /// session's start or fewer.
    fn lead_in(&self, ti: usize) -> Option<u64> {
        let first = self.starts.iter().position(|s| s.0 == ti)?;
        self.lead_in_before(first)
    }

    /// The sample [`LEAD_IN_STEPS`] step starts before the `k`-th, or `None` (the recording's
    /// start) when there are not that many.
    fn lead_in_before(&self, k: usize) -> Option<u64> {
        k.checked_sub(LEAD_IN_STEPS).map(|k| self.starts[k].2)
    }

    /// The sample where a run of `span` from rest starts ([`LeadIn`]); `None` (the
    /// recording's start) where fewer than [`LEAD_IN_STEPS`] steps come before it.
    fn lead_in_of(&self, span: &Span) -> Option<u64> {
        if span.lead_in == LeadIn::Test || span.from == 0 {
            return self.lead_in(span.test);
        }
        let Some(at) = self
            .starts
            .iter()
            .position(|s| s.0 == span.test && s.1 == span.from)
        else {
            return self.lead_in(span.test);
        };
        self.lead_in_before(at)
    }
}

/// How many steps before the first it compares a run from rest starts (the lead-in). The
/// free transient from rest decays as `exp(-zeta omega t)`: over one step (settling and
/// record window, 150-300 periods) a 1F mode at 0.15-0.2 % damping keeps 15-40 % of it, and
/// where the rig's response has two branches (a clamp joint softening 1FU at a high level
/// near resonance) the rest of it can put the model on the other one. Measured on
/// `identify.toml` with an upper clamp joint (share 0.2, half-slip 1.5e-4 m): from rest one
/// step before `high-up`, the hidden joint scored 18.4 on that test's impact-free steps and
/// the clamp fit took a share of 0.29 (+47 %); from rest three steps before, 1.66, and the
/// fit took 0.1999 and 1.498e-4 m (BENCHMARKS.md, "A run's lead-in from rest").
const LEAD_IN_STEPS: usize = 3;

/// The rig time (s) above which a stretch of consecutive tests run from rest is split in two
/// at a test boundary, the tail from rest at its own lead-in ([`ModelRunner::split_long`]),
/// and each piece again while it is longer: a judgement's one model over a whole
/// `identify.toml` session (714 s) ran on one thread while the other idled, for 105 s of
/// `f2`'s diagnosis (BENCHMARKS.md, "The clamp's fit settled"). The split depends on the
/// steps run only, not on what runs beside them or on the number of threads; it costs a
/// lead-in (three steps) per piece.
const LONG_STRETCH_S: f64 = 400.0;

/// Where a run of a [`Span`] from rest starts: `LEAD_IN_STEPS` steps before the first it
/// needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LeadIn {
    /// Before the test's first step (the previous test's last steps, or the session's
    /// start): the steps before the span's first run too, and shape the state it starts in.
    Test,
    /// Before the span's first step: the test's steps before the lead-in are not run (a span
    /// whose steps depend on the earlier ones only through a free transient that has
    /// decayed).
    Span,
}

/// The steps of a test a run compares: `from` (a step index) through `through` (`None`: the
/// last). A run starts from rest at its lead-in ([`LeadIn`]: the test's, whatever `from` is,
/// or the span's own), unless a state of open contact captured at `from` can stand in for
/// the steps before it ([`ModelRunner::capture_open`]): the compared steps are the same
/// either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Span {
    /// Test index.
    pub test: usize,
    /// First compared step.
    pub from: usize,
    /// Last compared step (`None`: the test's last).
    pub through: Option<usize>,
    /// Where a run from rest starts.
    pub lead_in: LeadIn,
}

impl Span {
    /// Every step of test `test`.
    pub fn whole(test: usize) -> Span {
        Span {
            test,
            from: 0,
            through: None,
            lead_in: LeadIn::Test,
        }
    }

    /// Steps `from` through `through` of test `test`, run from the test's lead-in.
    pub fn of_test(test: usize, from: usize, through: Option<usize>) -> Span {
        Span {
            test,
            from,
            through,
            lead_in: LeadIn::Test,
        }
    }

    /// Whether step `s` is compared.
    fn covers(&self, s: &SessionStep) -> bool {
        s.test_index == self.test
            && s.info.step >= self.from
            && self.through.is_none_or(|l| s.info.step <= l)
    }
}

/// A state of open contact captured at the start of a step ([`ModelRunner::capture_open`]).
struct OpenStart {
    test: usize,
    step: usize,
    /// The extensions it was captured with (the closest contact geometry of those it serves).
    captured_with: PhysicsSpec,
    /// The twin step's refinement it was captured at.
    refinement: u32,
    state: crate::twin::TwinState,
}

/// The tests of `queue` ((test, sample), in sample order) whose sample comes before `end`,
/// taken off it in order.
fn due_before(queue: &mut VecDeque<(usize, u64)>, end: u64) -> impl Iterator<Item = usize> + '_ {
    std::iter::from_fn(move || {
        (queue.front().is_some_and(|&(_, s)| s < end))
            .then(|| queue.pop_front())
            .flatten()
            .map(|(t, _)| t)
    })
}

/// Where a stretch of tests starts.
enum Start {
    /// From rest at the lead-in of its first span.
    Rest,
    /// From a captured state of open contact (an index into the runner's open starts).
    Open(usize),
    /// From rest at the lead-in of its one span, with the contact's geometry (clearance and
    /// wear so far) of a state recorded there ([`ModelRunner::set_wear_from`]).
    Worn(Box<crate::twin::TwinState>),
}

/// What a model run did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunCost {
    /// Runs (stretches of consecutive tests).
    pub runs: usize,
    /// Rig time run, s.
    pub rig_seconds: f64,
    /// Wall time, s.
    pub wall_seconds: f64,
}

impl RunCost {
    /// Adds `other`'s runs, rig time and wall time.
    pub fn add(&mut self, other: RunCost) {
        self.runs += other.runs;
        self.rig_seconds += other.rig_seconds;
        self.wall_seconds += other.wall_seconds;
    }
}

/// Runs the twin with given extensions over tests of a recording (see the module docs).
pub struct ModelRunner<'a> {
    rec: &'a Recording,
    steps: &'a SessionSteps,
    rom: &'a Rom,
    base: TwinModel<'a>,
    spec: TwinSpec,
    /// The twin settings as given (`spec` is them with the step refined).
    own_spec: TwinSpec,
    /// How many times finer than the given twin step the runs are (1: the given step).
    refinement: u32,
    beam_length: f64,
    jobs: usize,
    /// What the runs cost so far.
    pub cost: RunCost,
    /// Per run of the last [`ModelRunner::run_many`]: the normal contact impulse accumulated
    /// at each test's start and each step's record window (empty: not run, or no wear in the
    /// model).
    last_impulses: Vec<Impulses>,
    /// States of open contact that can start runs ([`ModelRunner::capture_open`]).
    open_starts: Vec<OpenStart>,
    /// Every capture tried: (test, step, extensions and refinement) and whether it was kept.
    captures: std::collections::HashMap<(usize, usize, String), bool>,
    /// The states of the runs of models with wear at each test's lead-in, per (extensions,
    /// refinement): test index -> state ([`ModelRunner::set_wear_from`]).
    worn: HashMap<(String, u32), BTreeMap<usize, crate::twin::TwinState>>,
    /// Whether runs of models with wear start each test from the state recorded at its lead-in
    /// by a run at this refinement ([`ModelRunner::set_wear_from`]).
    wear_from: Option<u32>,
}

/// The normal contact impulse a model with wear accumulated over a run from the session's
/// start (`physics::wear`), N s.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Impulses {
    /// Per test of the session, at its start (`None`: not run).
    pub at_test_start: Vec<Option<f64>>,
    /// Per (test index, step) run, at the middle of the step's record window.
    pub at_record: BTreeMap<(usize, usize), f64>,
}

impl Impulses {
    /// The mean over steps `first..=last` of test `ti` of the impulse at their record
    /// windows' middles (those run; `None`: none was).
    pub fn over_records(&self, ti: usize, first: usize, last: usize) -> Option<f64> {
        let ps: Vec<f64> = (self.at_record.range((ti, first)..=(ti, last)))
            .map(|(_, p)| *p)
            .collect();
        (!ps.is_empty()).then(|| ps.iter().sum::<f64>() / ps.len() as f64)
    }
}

/// A run of [`ModelRunner::run_members`]: its extensions, the steps it scores and its
/// ensemble member (0: unperturbed; [`ModelRunner::run_members`]).
pub type MemberRun = (PhysicsSpec, Vec<Span>, usize);

/// What one stretch of tests gave.
struct GroupRun {
    scores: Vec<StepScores>,
    rig_seconds: f64,
    /// (test index, accumulated normal contact impulse at its start, N s), with wear in the
    /// model.
    impulse: Vec<(usize, f64)>,
    /// ((test index, step), the impulse at the middle of its record window, N s), with wear
    /// in the model.
    at_record: Vec<((usize, usize), f64)>,
    /// (test index, the twin's state at its lead-in), with wear in the model.
    lead_ins: Vec<(usize, crate::twin::TwinState)>,
}

impl<'a> ModelRunner<'a> {
    /// A runner over `rec` (its steps `steps`) of the model `base` (ROM, contact observation;
    /// its extensions are replaced by each run's), twin settings `spec` (no ensemble), beam
    /// length `beam_length` m, on `jobs` threads.
    pub fn new(
        rec: &'a Recording,
        steps: &'a SessionSteps,
        base: TwinModel<'a>,
        spec: &TwinSpec,
        beam_length: f64,
        jobs: usize,
    ) -> ModelRunner<'a> {
        let mut spec = spec.clone();
        spec.ensemble_members = 0;
        ModelRunner {
            rec,
            steps,
            rom: base.rom,
            base,
            own_spec: spec.clone(),
            spec,
            refinement: 1,
            beam_length,
            jobs: jobs.max(1),
            cost: RunCost::default(),
            last_impulses: Vec::new(),
            open_starts: Vec::new(),
            captures: std::collections::HashMap::new(),
            worn: HashMap::new(),
            wear_from: None,
        }
    }

    /// A runner over the same recording, steps, beam length and threads with another model
    /// (`base`: another ROM, the twin's discretisation refined) and twin settings `spec`; its
    /// own cost, captures and states.
    pub fn with_model(&self, base: TwinModel<'a>, spec: &TwinSpec) -> ModelRunner<'a> {
        ModelRunner::new(
            self.rec,
            self.steps,
            base,
            spec,
            self.beam_length,
            self.jobs,
        )
    }

    /// The model it runs (ROM, contact observation; each run's extensions replace these).
    pub fn base_model(&self) -> &TwinModel<'a> {
        &self.base
    }

    /// The ROM it runs.
    pub fn rom(&self) -> &'a Rom {
        self.rom
    }

    /// The recording's sample rate, Hz.
    pub fn sample_rate(&self) -> f64 {
        self.rec.layout.sample_rate
    }

    /// From now on, with `Some(r)`, a run of a model with wear runs each test it is asked for
    /// on its own, from rest at the test's lead-in with the clearance and wear so far that a
    /// run of the same model at refinement `r` had there (where such a run went through the
    /// test; else from the session's start as usual); `None`: every run with wear goes from
    /// the session's start.
    ///
    // NOTE: for the finer twin step's confirmation of a wear candidate. Its coefficient was
    // fitted against the impulse of the twin at its own step, so the clearance it predicts at a
    // test's start is that twin's; the finer twin then runs the test (and its lead-in step)
    // with wear going on, so the contact compared is the finer twin's. It spares the run of
    // the session from its start at the finer step, one thread for 129 s of a 798 s diagnosis
    // of `identify.toml` with wear and a sensor gain (BENCHMARKS.md, "The diagnosis' time").
    pub fn set_wear_from(&mut self, refinement: Option<u32>) {
        self.wear_from = refinement;
    }

    /// What [`ModelRunner::set_wear_from`] set.
    pub fn wear_from(&self) -> Option<u32> {
        self.wear_from
    }

    /// Runs from now on at a twin step `refinement` (>= 1) times finer than the given one (1:
    /// the given step): the twin's own discretisation error shrinks, at `refinement` times the
    /// cost.
    pub fn set_refinement(&mut self, refinement: u32) {
        let r = refinement.max(1);
        self.refinement = r;
        self.spec = self.own_spec.clone();
        if r > 1 {
            self.spec.steps_per_sample = self.own_spec.steps_per_sample.map(|n| n * r);
            self.spec.steps_per_reference_period =
                self.own_spec.steps_per_reference_period * f64::from(r);
        }
    }

    /// The refinement of the twin step in force ([`ModelRunner::set_refinement`]).
    pub fn refinement(&self) -> u32 {
        self.refinement
    }

    /// The compared steps of tests `tests` (indices, any order) with extensions `ext`, in
    /// session order; a step the model missed part of has no features.
    pub fn run(
        &mut self,
        ext: &PhysicsSpec,
        tests: &[usize],
    ) -> Result<Vec<StepScores>, DiagnoseError> {
        let spans: Vec<Span> = tests.iter().map(|&t| Span::whole(t)).collect();
        self.run_spans(ext, &spans)
    }

    /// [`ModelRunner::run`] over the steps `spans` name (one span per test): a run stops after
    /// the last step that carries the evidence, and starts from a captured state of open
    /// contact where one serves ([`ModelRunner::capture_open`]). A test cut short or started
    /// from a state runs alone. With wear (the clearance carries across tests) one run goes
    /// from the session's start through the last test asked for, every test between whole.
    pub fn run_spans(
        &mut self,
        ext: &PhysicsSpec,
        spans: &[Span],
    ) -> Result<Vec<StepScores>, DiagnoseError> {
        let mut all = self.run_many(&[(ext.clone(), spans.to_vec())])?;
        Ok(all.pop().unwrap_or_default())
    }

    /// Several [`ModelRunner::run_spans`] at once, their stretches of tests spread over the
    /// `jobs` threads together (the points of a fit's grid run side by side, where one run of
    /// a single test would keep one thread busy). Results in the order of `runs`.
    pub fn run_many(
        &mut self,
        runs: &[(PhysicsSpec, Vec<Span>)],
    ) -> Result<Vec<Vec<StepScores>>, DiagnoseError> {
        let runs: Vec<MemberRun> = (runs.iter())
            .map(|(ext, spans)| (ext.clone(), spans.clone(), 0))
            .collect();
        self.run_members(&runs)
    }

    /// [`ModelRunner::run_many`] of ensemble members: a run of member `m` > 0 is the run of
    /// member 0 (the model as [`ModelRunner::run_many`] runs it) with the twin's modal
    /// velocities perturbed at the start of each step whose record window had contact on the
    /// rig, by the `[twin]` ensemble's relative perturbation, from a seed of the step and the
    /// member only ([`crate::twin::TwinState::perturbed`]). In the impact band, whose response
    /// is not periodic, each member is another draw of the same model; common random numbers:
    /// every model run as member `m` gets the same perturbations. Only member 0's runs keep
    /// the contact impulse and the states at the tests' lead-ins.
    pub fn run_members(
        &mut self,
        runs: &[MemberRun],
    ) -> Result<Vec<Vec<StepScores>>, DiagnoseError> {
        let mut wanted_of: Vec<Vec<Span>> = Vec::with_capacity(runs.len());
        // (run, stretch of consecutive tests, where it starts); the whole session for wear.
        let mut groups: Vec<(usize, Vec<Span>, Start)> = Vec::new();
        for (r, (ext, spans, _)) in runs.iter().enumerate() {
            let mut wanted: Vec<Span> = spans.clone();
            wanted.sort_unstable();
            wanted.dedup_by_key(|s| s.test);
            let first = groups.len();
            let worn = self
                .wear_from
                .filter(|_| ext.wear.is_some())
                .and_then(|f| self.worn.get(&(ext.to_json(), f)))
                .filter(|w| wanted.iter().all(|s| w.contains_key(&s.test)));
            if let Some(worn) = worn {
                for &span in &wanted {
                    let span = Span {
                        lead_in: LeadIn::Test,
                        ..span
                    };
                    let state = Box::new(worn[&span.test].clone());
                    groups.push((r, vec![span], Start::Worn(state)));
                }
            } else if ext.wear.is_some() {
                // From the session's start through the last test asked for.
                let last = wanted.last().map_or(0, |s| s.test);
                let group = (0..=last)
                    .map(|t| {
                        wanted
                            .iter()
                            .find(|s| s.test == t)
                            .copied()
                            .unwrap_or(Span::whole(t))
                    })
                    .collect();
                groups.push((r, group, Start::Rest));
            } else {
                for &span in &wanted {
                    let start = self.open_start_for(ext, &span);
                    // Only this run's own stretches are extended.
                    let own = groups.len() > first;
                    // A span run from its own lead-in starts a stretch of its own.
                    let own_lead_in = span.from > 0 && span.lead_in == LeadIn::Span;
                    match groups.last_mut() {
                        Some((_, g, Start::Rest))
                            if own
                                && start.is_none()
                                && !own_lead_in
                                && g.last().is_some_and(|p| {
                                    p.test + 1 == span.test && p.through.is_none()
                                }) =>
                        {
                            g.push(span)
                        }
                        _ => groups.push((r, vec![span], start.map_or(Start::Rest, Start::Open))),
                    }
                }
                let mut k = first;
                while k < groups.len() {
                    let (_, group, start) = &mut groups[k];
                    match self.split_long(group, start) {
                        Some(tail) => groups.insert(k + 1, (r, tail, Start::Rest)),
                        None => k += 1,
                    }
                }
            }
            wanted_of.push(wanted);
        }
        let wall = std::time::Instant::now();
        let models: Vec<TwinModel<'_>> = runs.iter().map(|(ext, ..)| self.model(ext)).collect();
        let this: &ModelRunner<'_> = self;
        // The longest stretches first, each thread taking the next one left when it is done:
        // the threads finish close together whatever the mix of long and short stretches.
        let mut order: Vec<usize> = (0..groups.len()).collect();
        order.sort_by_key(|&k| {
            let (_, g, start) = &groups[k];
            std::cmp::Reverse(this.extent(g, start))
        });
        let next = std::sync::atomic::AtomicUsize::new(0);
        // Every stretch is taken by exactly one thread: with none panicked, `done` holds one
        // result per stretch.
        let mut done: Vec<(usize, Result<GroupRun, DiagnoseError>)> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..this.jobs.min(groups.len()))
                .map(|_| {
                    let (order, next, groups, models) = (&order, &next, &groups, &models);
                    s.spawn(move || {
                        let mut done = Vec::new();
                        loop {
                            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            let Some(&g) = order.get(k) else {
                                break done;
                            };
                            let (r, spans, start) = &groups[g];
                            let member = runs[*r].2;
                            let t0 = std::time::Instant::now();
                            done.push((g, this.run_group(&models[*r], spans, start, member)));
                            tracing::debug!(
                                run = *r,
                                tests = ?spans.iter().map(|s| s.test).collect::<Vec<_>>(),
                                samples = this.extent(spans, start),
                                seconds = t0.elapsed().as_secs_f64(),
                                "model run stretch"
                            );
                        }
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().map_err(|_| DiagnoseError::Panicked))
                .collect::<Result<Vec<_>, _>>()
        })?
        .into_iter()
        .flatten()
        .collect();
        done.sort_unstable_by_key(|d| d.0);
        let results = done.into_iter().map(|(_, r)| r);
        let mut out: Vec<Vec<StepScores>> = vec![Vec::new(); runs.len()];
        let mut impulse = vec![
            Impulses {
                at_test_start: vec![None; self.steps.tests.len()],
                at_record: BTreeMap::new(),
            };
            runs.len()
        ];
        for ((r, _, start), g) in groups.iter().zip(results) {
            let g = g?;
            self.cost.runs += 1;
            self.cost.rig_seconds += g.rig_seconds;
            out[*r].extend(g.scores);
            if runs[*r].2 > 0 {
                continue;
            }
            if matches!(start, Start::Rest) && !g.lead_ins.is_empty() {
                self.worn
                    .entry((runs[*r].0.to_json(), self.refinement))
                    .or_default()
                    .extend(g.lead_ins);
            }
            for (t, p) in g.impulse {
                if let Some(slot) = impulse[*r].at_test_start.get_mut(t) {
                    *slot = Some(p);
                }
            }
            impulse[*r].at_record.extend(g.at_record);
        }
        for (o, wanted) in out.iter_mut().zip(&wanted_of) {
            o.sort_by_key(|s| (s.test_index, s.step));
            o.retain(|s| wanted.iter().any(|w| w.test == s.test_index));
        }
        self.cost.wall_seconds += wall.elapsed().as_secs_f64();
        self.last_impulses = impulse;
        Ok(out)
    }

    /// Runs test `test` with extensions `ext` from its lead-in to the start of its step
    /// `step` and keeps the state there, if no contact pair closed on the way, to start later
    /// runs of that test's steps from `step` on ([`Span`]) with extensions whose contact
    /// geometry is nowhere closer than `ext`'s (and that differ from `ext` in nothing else):
    /// with the contact open, the motion up to there does not depend on the geometry, so
    /// those runs compare exactly what runs from rest would. Returns whether it was kept.
    pub fn capture_open(
        &mut self,
        ext: &PhysicsSpec,
        test: usize,
        step: usize,
    ) -> Result<bool, DiagnoseError> {
        let key = (
            test,
            step,
            format!("{} x{}", ext.to_json(), self.refinement),
        );
        if let Some(&kept) = self.captures.get(&key) {
            return Ok(kept);
        }
        let kept = self.capture(ext, test, step)?;
        self.captures.insert(key, kept);
        Ok(kept)
    }

    /// [`ModelRunner::capture_open`] without the memory of captures tried.
    fn capture(
        &mut self,
        ext: &PhysicsSpec,
        test: usize,
        step: usize,
    ) -> Result<bool, DiagnoseError> {
        if ext.wear.is_some() {
            return Ok(false);
        }
        let Some(&(_, _, at)) = self
            .steps
            .starts
            .iter()
            .find(|s| s.0 == test && s.1 == step)
        else {
            return Ok(false);
        };
        let wall = std::time::Instant::now();
        let model = self.model(ext);
        let (mut twin, start, mut clearances) = self.twin_at(&model, self.steps.lead_in(test))?;
        let dt = self.rec.layout.dt();
        for b in self.rec.base_blocks(start) {
            if b.first_sample >= at {
                break;
            }
            while let Some(c) = clearances.next_due(b.first_sample) {
                twin.set_clearance(c)?;
            }
            twin.push_block(&b)?;
            self.cost.rig_seconds += b.len as f64 * dt;
        }
        self.cost.runs += 1;
        self.cost.wall_seconds += wall.elapsed().as_secs_f64();
        let Some(state) = twin.state() else {
            return Ok(false);
        };
        if state.rom.counters().closed_steps > 0 {
            return Ok(false);
        }
        self.open_starts.push(OpenStart {
            test,
            step,
            captured_with: ext.clone(),
            refinement: self.refinement,
            state,
        });
        Ok(true)
    }

    /// The captured open state (index) that can start `span` with extensions `ext`: same
    /// test and step, the same extensions but for the contact's geometry, no wear, and every
    /// pair's initial gap at least the captured one's.
    fn open_start_for(&self, ext: &PhysicsSpec, span: &Span) -> Option<usize> {
        if span.from == 0 || ext.wear.is_some() {
            return None;
        }
        let strip = |e: &PhysicsSpec| e.without_contact_geometry().to_json();
        let own = strip(ext);
        let at = self
            .steps
            .starts
            .iter()
            .find(|s| s.0 == span.test && s.1 == span.from)?
            .2;
        self.open_starts.iter().position(|o| {
            o.test == span.test
                && o.step == span.from
                && o.refinement == self.refinement
                && strip(&o.captured_with) == own
                && self.no_closer(ext, &o.captured_with, at)
        })
    }

    /// Whether every pair's initial gap with extensions `ext` at sample `at` is at least its
    /// gap with extensions `than` (clearance and tilt).
    fn no_closer(&self, ext: &PhysicsSpec, than: &PhysicsSpec, at: u64) -> bool {
        let gaps = |e: &PhysicsSpec| {
            let c = ClearanceSchedule::of_events(
                self.beam_length,
                e.clearance.as_ref(),
                &self.rec.events,
            )
            .in_force_at(at);
            let offsets = e.tilt.as_ref().map(|t| {
                crate::physics::tilt::gap_offsets(&self.rom.pair_position, &self.rom.pair_area, t)
            });
            (0..self.rom.n_pairs())
                .map(|k| c + offsets.as_ref().map_or(0.0, |o| o[k]))
                .collect::<Vec<f64>>()
        };
        gaps(ext).iter().zip(gaps(than)).all(|(a, b)| *a >= b)
    }

    /// The model with extensions `ext` (ROM and contact observation the runner's).
    fn model(&self, ext: &PhysicsSpec) -> TwinModel<'a> {
        TwinModel {
            rom: self.rom,
            extensions: ext.clone(),
            circuit: self.base.circuit.clone(),
            contact_threshold_v: self.base.contact_threshold_v,
        }
    }

    /// A twin of `model` at rest at the block holding sample `from` (the session's first
    /// block for `None`), with the clearance in force there: (twin, block index, the
    /// clearance schedule from there on).
    fn twin_at(
        &self,
        model: &TwinModel<'_>,
        from: Option<u64>,
    ) -> Result<(crate::twin::Twin, usize, ClearanceSchedule), DiagnoseError> {
        let rec = self.rec;
        let from = from.unwrap_or(0);
        let start = rec
            .blocks
            .iter()
            .position(|b| b.first_sample + b.len as u64 > from)
            .unwrap_or(rec.blocks.len());
        let mut clearances = ClearanceSchedule::of_events(
            self.beam_length,
            model.extensions.clearance.as_ref(),
            &rec.events,
        );
        let begin = rec.blocks.get(start).map_or(0, |b| b.first_sample);
        let clearance = clearances.in_force_at(begin);
        let twin = crate::twin::Twin::new(model, &self.spec, &rec.layout, clearance)?;
        Ok((twin, start, clearances))
    }

    /// The model's accumulated normal contact impulse `P` (N s, `physics::wear`) at the start
    /// of every test and at every step's record window up to step `through.1` of test
    /// `through.0` (indices), over the session run from its start with extensions `ext` (wear
    /// on, with a zero coefficient when `ext` has none: `P` is counted whatever the
    /// coefficient; the clearances stay `ext`'s). The impulse of a test before its first
    /// impact is its start's; within its contact the wear grows from step to step.
    pub fn contact_impulse(
        &mut self,
        ext: &PhysicsSpec,
        through: (usize, usize),
    ) -> Result<Impulses, DiagnoseError> {
        let mut all = self.contact_impulses(std::slice::from_ref(ext), through)?;
        Ok(all.pop().unwrap_or_default())
    }

    /// [`ModelRunner::contact_impulse`] of several models, run side by side on the runner's
    /// threads; in the order of `exts`.
    pub fn contact_impulses(
        &mut self,
        exts: &[PhysicsSpec],
        through: (usize, usize),
    ) -> Result<Vec<Impulses>, DiagnoseError> {
        let spans = vec![Span::of_test(through.0, 0, Some(through.1))];
        let runs: Vec<(PhysicsSpec, Vec<Span>)> = exts
            .iter()
            .map(|ext| {
                let mut ext = ext.clone();
                if ext.wear.is_none() {
                    ext.wear = Some(crate::config::WearSpec {
                        coefficient: 0.0,
                        max_growth: None,
                    });
                }
                (ext, spans.clone())
            })
            .collect();
        self.run_many(&runs)?;
        Ok(std::mem::take(&mut self.last_impulses))
    }

    /// The relative perturbation of an ensemble member's modal velocities
    /// ([`ModelRunner::run_members`]).
    pub fn perturbation(&self) -> f64 {
        self.spec.ensemble_perturbation
    }

    /// The threads the runs are spread over.
    pub fn jobs(&self) -> usize {
        self.jobs
    }

    /// The samples a run of `group` from rest at its lead-in, or from `start`, covers (to
    /// order the stretches by length).
    fn extent(&self, group: &[Span], start: &Start) -> u64 {
        if group.is_empty() {
            return 0;
        }
        let begin = self.start_sample(group, start).unwrap_or(0);
        let end = (self.windows_of(group).last()).map_or(begin, |s| s.info.record_end_sample());
        end.saturating_sub(begin)
    }

    /// The tail of `group` split off where the stretch from rest is longer than
    /// [`LONG_STRETCH_S`] of rig time, at the test boundary that leaves the two pieces
    /// closest in length (the tail runs from rest at its own lead-in); `group` keeps the
    /// head. `None` (nothing split) for a shorter stretch, a single test, or another start.
    fn split_long(&self, group: &mut Vec<Span>, start: &Start) -> Option<Vec<Span>> {
        let long = (LONG_STRETCH_S / self.rec.layout.dt()) as u64;
        if !matches!(start, Start::Rest) || group.len() < 2 || self.extent(group, start) <= long {
            return None;
        }
        let at = (1..group.len()).min_by_key(|&i| {
            let (head, tail) = group.split_at(i);
            self.extent(head, start).abs_diff(self.extent(tail, start))
        })?;
        Some(group.split_off(at))
    }

    /// The record windows the steps `group` names, in session order.
    fn windows_of(&self, group: &[Span]) -> Vec<&SessionStep> {
        (self.steps.steps.iter())
            .filter(|s| group.iter().any(|g| g.covers(s)))
            .collect()
    }

    /// Where a run of `group` from `start` starts: the open state's next sample, or the
    /// group's lead-in (None: the recording's start).
    fn start_sample(&self, group: &[Span], start: &Start) -> Option<u64> {
        match start {
            Start::Open(i) => Some(self.open_starts[*i].state.next_sample),
            Start::Rest | Start::Worn(_) => self.steps.lead_in_of(group.first()?),
        }
    }

    /// One stretch of consecutive tests (the steps `group` names), from rest at its lead-in
    /// or from the open state `start`, as ensemble member `member`
    /// ([`ModelRunner::run_members`]).
    fn run_group(
        &self,
        model: &TwinModel<'_>,
        group: &[Span],
        start: &Start,
        member: usize,
    ) -> Result<GroupRun, DiagnoseError> {
        let rec = self.rec;
        let empty = GroupRun {
            scores: Vec::new(),
            rig_seconds: 0.0,
            impulse: Vec::new(),
            at_record: Vec::new(),
            lead_ins: Vec::new(),
        };
        if group.is_empty() {
            return Ok(empty);
        }
        let windows = self.windows_of(group);
        let tests: Vec<usize> = group.iter().map(|r| r.test).collect();
        let Some(last) = windows.last() else {
            return Ok(empty);
        };
        // The first step start of each test of the group: where its contact impulse is read.
        let mut test_starts: VecDeque<(usize, u64)> = VecDeque::new();
        for &(t, _, sample) in &self.steps.starts {
            if tests.contains(&t) && test_starts.iter().all(|x| x.0 != t) {
                test_starts.push_back((t, sample));
            }
        }
        let mut impulse = Vec::new();
        // With wear, where each test's lead-in is (to keep the state there, for
        // `ModelRunner::set_wear_from`).
        let mut lead_in_at: VecDeque<(usize, u64)> = VecDeque::new();
        if model.extensions.wear.is_some() && matches!(start, Start::Rest) {
            lead_in_at = tests
                .iter()
                .filter_map(|&t| Some((t, self.steps.lead_in(t)?)))
                .collect();
        }
        let mut lead_ins = Vec::new();
        // With wear, the middle of each record window (an index into `windows`): where the
        // impulse the clearance of that window has seen is read.
        let mut record_mids: VecDeque<(usize, u64)> = VecDeque::new();
        if model.extensions.wear.is_some() {
            record_mids = (windows.iter().enumerate())
                .map(|(k, w)| {
                    (
                        k,
                        w.info.record_first_sample + w.info.record_samples as u64 / 2,
                    )
                })
                .collect();
            record_mids.make_contiguous().sort_by_key(|x| x.1);
        }
        let mut at_record = Vec::new();
        // A member's perturbations: at the start of each step with contact on the rig.
        let mut perturb_at: VecDeque<(usize, u64)> = VecDeque::new();
        if member > 0 {
            for (k, w) in windows.iter().enumerate() {
                if w.regime == Regime::Impacts {
                    if let Some(at) = self.steps.step_start(w) {
                        perturb_at.push_back((k, at));
                    }
                }
            }
            perturb_at.make_contiguous().sort_by_key(|x| x.1);
        }
        let relative = self.spec.ensemble_perturbation;
        let end = last.info.record_end_sample();
        let (mut twin, first_block, mut clearances) =
            self.twin_at(model, self.start_sample(group, start))?;
        match start {
            Start::Rest => {}
            Start::Open(i) => {
                // NOTE: the state was captured before the block at its `next_sample`, which
                // `twin_at` finds; no test starts after it in this one-test group.
                let o = &self.open_starts[*i];
                twin.set_open_state(&o.state, &o.captured_with)?;
                test_starts.clear();
            }
            // The state was kept before the block that holds the lead-in, where `twin_at`
            // starts.
            Start::Worn(state) => twin.reset_keeping_geometry(state)?,
        }
        let dt = rec.layout.dt();
        let mut pending: VecDeque<(StepInfo, StepSummary)> = windows
            .iter()
            .map(|s| (s.info.clone(), s.measured.clone()))
            .collect();
        let mut out = TwinWindows::new(twin.observation(), self.spec.tolerance);
        let mut compared = Vec::new();
        let mut rig_seconds = 0.0;
        for b in rec.base_blocks(first_block) {
            if b.first_sample >= end {
                break;
            }
            while let Some(c) = clearances.next_due(b.first_sample) {
                twin.set_clearance(c)?;
            }
            let block_end = b.first_sample + b.len as u64;
            // NOTE: the block `twin_at` starts a run from this lead-in at (the first that ends
            // past it).
            for t in due_before(&mut lead_in_at, block_end) {
                if let Some(state) = twin.state() {
                    lead_ins.push((t, state));
                }
            }
            for t in due_before(&mut test_starts, block_end) {
                // NOTE: read at the block holding the test's first sample (blocks are a few
                // ms; no contact happens across a test's start, the sweep starts off the band).
                if let Some(w) = twin.state().and_then(|s| s.effects.wear) {
                    impulse.push((t, w.impulse));
                } else if model.extensions.wear.is_some() {
                    impulse.push((t, 0.0));
                }
            }
            for k in due_before(&mut record_mids, block_end) {
                if let Some(w) = twin.state().and_then(|s| s.effects.wear) {
                    let info = &windows[k];
                    at_record.push(((info.test_index, info.info.step), w.impulse));
                }
            }
            // NOTE: at the first block that starts at or after the step's start (blocks are a
            // few ms), so that the step before's record window, which ends there, is not
            // perturbed.
            for k in due_before(&mut perturb_at, b.first_sample + 1) {
                let info = &windows[k].info;
                if let Some(state) = twin.state() {
                    let s = state.perturbed(
                        &info.test,
                        info.step,
                        info.record_attempt,
                        member,
                        relative,
                    );
                    twin.set_state(&s)?;
                }
            }
            let tb = twin.push_block(&b)?;
            rig_seconds += b.len as f64 * dt;
            out.push(&tb);
            compared.extend(out.complete(&mut pending, dt, false));
        }
        compared.extend(out.complete(&mut pending, dt, true));
        let mut scores = Vec::new();
        for (info, c) in compared {
            let Some(step) = windows
                .iter()
                .find(|s| s.info.test == info.test && s.info.step == info.step)
            else {
                continue;
            };
            let features = match c {
                Some(Ok(c)) => c.features,
                Some(Err(source)) => {
                    return Err(DiagnoseError::Metrics {
                        test: info.test,
                        step: info.step,
                        source,
                    })
                }
                None => Vec::new(),
            };
            scores.push(step.scores(features));
        }
        Ok(GroupRun {
            scores,
            rig_seconds,
            impulse,
            at_record,
            lead_ins,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::metrics::StepMetrics;

    /// Two tests of 8 and 6 steps (each step 1000 samples from the start of the session)
    /// whose measured responses are `a` and `b`, the second test's from its step `contact` on
    /// with contact.
    fn session(a: &[f64], b: &[f64], contact: usize) -> SessionSteps {
        let mut steps = Vec::new();
        let mut starts = Vec::new();
        let mut sample = 0;
        for (ti, sizes) in [a, b].into_iter().enumerate() {
            for (k, &size) in sizes.iter().enumerate() {
                starts.push((ti, k, sample));
                let mut info = StepInfo::synthetic(300.0, 1e-4, 500);
                info.test = ["a", "b"][ti].into();
                info.step = k;
                info.record_first_sample = sample + 500;
                let contact = ti == 1 && k >= contact;
                let measured = StepSummary {
                    omega_ratio: 1.0,
                    metrics: StepMetrics {
                        rms_upper: 0.75 * size,
                        rms_lower: 0.25 * size,
                        contact_fraction: if contact { 0.1 } else { 0.0 },
                        ..StepMetrics::default()
                    },
                    base_amp_target: 1e-4,
                    base_amp_measured: 1e-4,
                    drive_amplitude: 0.1,
                    settle_seconds: 1.0,
                    settled: true,
                    record_start_s: 0.0,
                    record_attempt: 1,
                    base_amp_off_tolerance: false,
                    features: Vec::new(),
                    noise_floor: Vec::new(),
                };
                let regime = if contact {
                    Regime::Impacts
                } else {
                    Regime::ImpactFreeLow
                };
                steps.push(SessionStep {
                    info,
                    measured,
                    test_index: ti,
                    level: 1e-6,
                    regime,
                });
                sample += 1000;
            }
        }
        SessionSteps {
            tests: vec!["a".into(), "b".into()],
            levels: vec![1e-6, 1e-6],
            steps,
            starts,
        }
    }

    #[test]
    fn the_steps_near_a_resonance_run_from_their_own_lead_in() {
        let a = [30.0, 32.0, 40.0, 70.0, 130.0, 90.0, 50.0, 35.0];
        let b = [10.0, 12.0, 20.0, 30.0, 50.0, 80.0];
        let s = session(&a, &b, 4);
        // Rise over the smallest (30): 100 at the peak; half of it: 80 and above.
        let near = s.near_resonance(0, 0.5).expect("a test without contact");
        assert_eq!((near.from, near.through), (4, Some(5)));
        assert_eq!(near.lead_in, LeadIn::Span);
        // From rest at step 1's start, three steps before step 4; the whole test from the
        // session's start.
        assert_eq!(s.lead_in_of(&near), Some(1000));
        assert_eq!(s.lead_in_of(&Span::whole(0)), None);
        // Test b is cut before its contact (steps 0-3: rise 20, half of it from 20 on).
        let near = s.near_resonance(1, 0.5).expect("steps before the contact");
        assert_eq!((near.from, near.through), (2, Some(3)));
        assert_eq!(s.lead_in_of(&near), Some(7000));
        // The test's own lead-in is test a's last three steps.
        let tested = Span::of_test(1, 2, Some(3));
        assert_eq!(s.lead_in_of(&tested), Some(5000));
        // Fewer steps than the lead-in before a span: from the session's start.
        let early = Span {
            test: 0,
            from: 2,
            through: Some(3),
            lead_in: LeadIn::Span,
        };
        assert_eq!(s.lead_in_of(&early), None);
        // A flat response keeps every step before the contact.
        let s = session(&a, &[20.0; 6], 2);
        let near = s.near_resonance(1, 0.5).expect("steps before the contact");
        assert_eq!((near.from, near.through), (0, Some(1)));
        // Contact from the first step: nothing to run.
        let s = session(&a, &b, 0);
        assert!(s.near_resonance(1, 0.5).is_none());
    }
}
