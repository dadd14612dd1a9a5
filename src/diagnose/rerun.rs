//! The model re-run on the steps that carry the evidence ([`ModelRunner`]): a hypothesis is
//! judged by running the twin, with the hypothesis' extensions, over the recorded base motion
//! of some tests and comparing it with the measurement step by step, as `replay --twin` does.
//!
//! A run covers whole tests, each group of consecutive tests in one stretch, from rest at the
//! start of the step before the group's first step (the lead-in: the previous test's last
//! step, or the session's start): the twin's own state cannot be carried in from another
//! model (a state belongs to the model that made it), and a free transient from rest decays
//! over the lead-in step and the first step's settling (250 periods and more; e^-5 at 0.3 %
//! damping) before the first compared record window. Groups run on separate threads; the
//! results do not depend on the number of threads. A hypothesis that changes the clearance
//! over the session (wear) runs the whole session in one stretch.

use std::collections::VecDeque;

use crate::config::PhysicsSpec;
use crate::control::{EventKind, StepInfo, StepSummary};
use crate::rom::Rom;
use crate::session::replay::Recording;
use crate::session::summary::SessionSummary;
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

impl SessionSteps {
    /// The steps of recording `rec` whose replayed summary is `summary`.
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
                let regime = if s.measured.metrics.contact_fraction > 0.0 {
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

    /// The sample where the step before test `ti`'s first step starts (the lead-in), or
    /// `None` for the session's first step.
    fn lead_in(&self, ti: usize) -> Option<u64> {
        let first = self.starts.iter().position(|s| s.0 == ti)?;
        first.checked_sub(1).map(|k| self.starts[k].2)
    }
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
    /// Per test of the session: the dissipated contact work at its start in the last run, J
    /// (`None`: not run, or no wear in the model).
    last_contact_work: Vec<Option<f64>>,
}

/// What one stretch of tests gave.
struct GroupRun {
    scores: Vec<StepScores>,
    rig_seconds: f64,
    /// (test index, dissipated contact work at its start, J), with wear in the model.
    work: Vec<(usize, f64)>,
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
            last_contact_work: Vec::new(),
        }
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
        let mut wanted: Vec<usize> = tests.to_vec();
        wanted.sort_unstable();
        wanted.dedup();
        // Stretches of consecutive tests; the whole session for wear.
        let mut groups: Vec<Vec<usize>> = Vec::new();
        if ext.wear.is_some() {
            groups.push((0..self.steps.tests.len()).collect());
        } else {
            for &t in &wanted {
                match groups.last_mut() {
                    Some(g) if g.last() == Some(&(t.wrapping_sub(1))) => g.push(t),
                    _ => groups.push(vec![t]),
                }
            }
        }
        let wall = std::time::Instant::now();
        let model = TwinModel {
            rom: self.rom,
            extensions: ext.clone(),
            circuit: self.base.circuit.clone(),
            contact_threshold_v: self.base.contact_threshold_v,
        };
        let mut results: Vec<Result<GroupRun, DiagnoseError>> = Vec::new();
        let this: &ModelRunner<'_> = self;
        for chunk in groups.chunks(this.jobs) {
            let done: Vec<_> = std::thread::scope(|s| {
                let handles: Vec<_> = chunk
                    .iter()
                    .map(|g| {
                        let model = &model;
                        s.spawn(move || this.run_group(model, g))
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|_| Err(DiagnoseError::Panicked)))
                    .collect()
            });
            results.extend(done);
        }
        let mut out = Vec::new();
        let mut work = vec![None; self.steps.tests.len()];
        for r in results {
            let g = r?;
            self.cost.runs += 1;
            self.cost.rig_seconds += g.rig_seconds;
            out.extend(g.scores);
            for (t, w) in g.work {
                if let Some(slot) = work.get_mut(t) {
                    *slot = Some(w);
                }
            }
        }
        out.sort_by_key(|s| (s.test_index, s.step));
        out.retain(|s| wanted.contains(&s.test_index));
        self.cost.wall_seconds += wall.elapsed().as_secs_f64();
        self.last_contact_work = work;
        Ok(out)
    }

    /// The model's dissipated contact work `W` (J, `physics::wear`) at the start of every
    /// test, over the whole session run with extensions `ext` (wear on, with a zero coefficient
    /// when `ext` has none: `W` is counted whatever the coefficient; the clearances stay
    /// `ext`'s), with the compared steps of that run. The contact work of a test before its
    /// first impact is its start's: the clearance measured there has seen exactly this `W`.
    pub fn contact_work(
        &mut self,
        ext: &PhysicsSpec,
    ) -> Result<(Vec<Option<f64>>, Vec<StepScores>), DiagnoseError> {
        let mut ext = ext.clone();
        if ext.wear.is_none() {
            ext.wear = Some(crate::config::WearSpec {
                coefficient: 0.0,
                max_growth: None,
            });
        }
        let all: Vec<usize> = (0..self.steps.tests.len()).collect();
        let scores = self.run(&ext, &all)?;
        Ok((self.last_contact_work.clone(), scores))
    }

    /// One stretch of consecutive tests `group`, from rest at its lead-in.
    fn run_group(&self, model: &TwinModel<'_>, group: &[usize]) -> Result<GroupRun, DiagnoseError> {
        let rec = self.rec;
        let empty = GroupRun {
            scores: Vec::new(),
            rig_seconds: 0.0,
            work: Vec::new(),
        };
        let Some(&first) = group.first() else {
            return Ok(empty);
        };
        let windows: Vec<&SessionStep> = self
            .steps
            .steps
            .iter()
            .filter(|s| group.contains(&s.test_index))
            .collect();
        let Some(last) = windows.last() else {
            return Ok(empty);
        };
        // The first step start of each test of the group: where its contact work is read.
        let mut test_starts: VecDeque<(usize, u64)> = VecDeque::new();
        for &(t, _, sample) in &self.steps.starts {
            if group.contains(&t) && test_starts.iter().all(|x| x.0 != t) {
                test_starts.push_back((t, sample));
            }
        }
        let mut work = Vec::new();
        let end = last.info.record_end_sample();
        let from = self.steps.lead_in(first).unwrap_or(0);
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
        let mut clearance = clearances.first().unwrap_or(0.0);
        while let Some(c) = clearances.next_due(begin) {
            clearance = c;
        }
        let mut twin = crate::twin::Twin::new(model, &self.spec, &rec.layout, clearance)?;
        let dt = rec.layout.dt();
        let mut pending: VecDeque<(StepInfo, StepSummary)> = windows
            .iter()
            .map(|s| (s.info.clone(), s.measured.clone()))
            .collect();
        let mut out = TwinWindows::new(twin.observation(), self.spec.tolerance);
        let mut compared = Vec::new();
        let mut rig_seconds = 0.0;
        for b in rec.base_blocks(start) {
            if b.first_sample >= end {
                break;
            }
            while let Some(c) = clearances.next_due(b.first_sample) {
                twin.set_clearance(c)?;
            }
            while test_starts
                .front()
                .is_some_and(|&(_, s)| s < b.first_sample + b.len as u64)
            {
                let Some((t, _)) = test_starts.pop_front() else {
                    break;
                };
                // NOTE: read at the block holding the test's first sample (blocks are a few
                // ms; no contact happens across a test's start, the sweep starts off the band).
                if let Some(w) = twin.state().and_then(|s| s.effects.wear) {
                    work.push((t, w.work));
                } else if model.extensions.wear.is_some() {
                    work.push((t, 0.0));
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
            work,
        })
    }
}
