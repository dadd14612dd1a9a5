//! The judging machinery of a diagnosis, shared by its stages (the pipeline's, wear's and
//! tilt's): the settings and progress of a diagnosis, which steps an
//! error covers and the error itself (RMS of the compared features' scores), a candidate
//! effect, and the diagnosis state ([`Work`]) that runs the model, judges a candidate against
//! the accepted model on its validation tests (beyond the null spread plus a penalty per
//! parameter) and keeps the results.

use std::collections::HashMap;

use crate::config::PhysicsSpec;

use super::outcome::{EffectResult, Regime, SetError, StageCost, StepScores, Undecided};
use super::rerun::{MemberRun, ModelRunner, RunCost, SessionSteps, Span};
use super::DiagnoseError;

/// How many times finer than the twin's own step a candidate judged on the impact band is
/// judged again before it is accepted ([`Work::judge`]).
pub(super) const CONFIRM_REFINEMENT: u32 = 3;

/// Settings of a diagnosis.
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseOptions {
    /// Score above which a feature counts as a mismatch, -. Default 3.
    pub threshold: f64,
    /// The error's spread when the model is right (RMS score units): a candidate must lower
    /// the validation error by more than this, -. Default 0.3.
    pub null_spread: f64,
    /// Further validation improvement asked per fitted parameter, -. Default 0.1.
    pub parameter_penalty: f64,
    /// And by at least this share of the error before, -. Default 0.2.
    pub min_relative_improvement: f64,
    /// The null spread for effects judged on the impact band (clearance), -. Default 1: the
    /// band is non-periodic and the nominal twin's own truncation scores its steps around 4-6
    /// where the rig matches the model (BENCHMARKS.md, "The comparison's spread").
    pub contact_null_spread: f64,
    /// The null spread for a band candidate judged where it was fitted at a finer twin step
    /// (`Candidate::judged_where_fitted`), -. Default 0.5. There the twin's own contact
    /// excess, which `contact_null_spread` allows for, is gone: on `identify.toml` with
    /// nothing hidden (two noise seeds), offsets of -25, -45 and +30 um forced there raised
    /// the error by 0.24-5.9, and a right model's error there was 0.86-1.18; hidden
    /// clearances of -6e-5 and -8e-5 m fell by 0.89 and 1.04, under the band's 1.1 with the
    /// penalty (BENCHMARKS.md, "The null spread where a clearance was fitted").
    pub fitted_steps_null_spread: f64,
    /// The share of the error before such an effect must remove, -. Default 0.5: on
    /// `identify.toml` with nothing hidden, a smaller clearance absorbs part of the twin's
    /// truncation error and lowers the validation error 1.3x; a hidden +14 % clearance
    /// lowers it 4x.
    pub contact_min_relative_improvement: f64,
    /// Runs of each model whose errors judge a candidate on the impact band: the model as
    /// given and `band_members - 1` draws from perturbed states at the band's steps
    /// ([`ModelRunner::run_members`]); the error takes each step's median over them
    /// (`members_error`). Default 3: one run of a non-periodic response is one draw, and a
    /// right model's draw can land on another attractor than the rig's in a step or two
    /// (BENCHMARKS.md, "The judge's errors in the band over three draws", "The judge's draws
    /// compared per step").
    pub band_members: usize,
    /// Threads for model runs.
    pub jobs: usize,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            threshold: 3.0,
            null_spread: 0.3,
            parameter_penalty: 0.1,
            min_relative_improvement: 0.2,
            contact_null_spread: 1.0,
            fitted_steps_null_spread: 0.5,
            contact_min_relative_improvement: 0.5,
            band_members: 3,
            jobs: 1,
        }
    }
}

/// Progress of a diagnosis, for the terminal.
#[derive(Clone, Debug, PartialEq)]
pub enum DiagnoseProgress {
    /// A stage begins.
    Stage(String),
    /// A model run for a hypothesis.
    Evaluation(String),
    /// What a stage found, in words.
    Note(String),
}

/// Which steps an error covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Steps {
    /// Impact-free steps, motion channels.
    ImpactFree,
    /// Every step, every channel (the model's contact where the measurement had none counts).
    All,
}

/// RMS score of the features of the steps of `tests` in `which` (of channel `channel` only,
/// when given); None without any.
pub(super) fn set_error_of(
    scores: &[StepScores],
    tests: &[usize],
    which: Steps,
    channel: Option<&str>,
) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for s in scores.iter().filter(|s| tests.contains(&s.test_index)) {
        add_step_squares(s, which, channel, &mut sum, &mut n);
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// [`set_error_of`] over every channel.
pub(super) fn set_error(scores: &[StepScores], tests: &[usize], which: Steps) -> Option<f64> {
    set_error_of(scores, tests, which, None)
}

/// Adds the squared scores of the features of step `s` that [`set_error_of`] counts to
/// `sum`, and their count to `n` (none where the step is not in `which`).
fn add_step_squares(
    s: &StepScores,
    which: Steps,
    channel: Option<&str>,
    sum: &mut f64,
    n: &mut usize,
) {
    if which == Steps::ImpactFree && s.regime == Regime::Impacts {
        return;
    }
    for f in &s.features {
        if which == Steps::ImpactFree && f.channel == "contact" {
            continue;
        }
        if channel.is_some_and(|c| c != f.channel) {
            continue;
        }
        *sum += f.score * f.score;
        *n += 1;
    }
}

/// [`set_error_of`] over several runs of one model (`members`, each over the same steps):
/// per step, the median over the runs of the mean squared score of its features; the root of
/// their mean, weighted by the features' count. None where a run compares nothing.
///
/// A step of the chaotic band is one draw per run, and a run can land on another attractor
/// than the rig's at a step or two, e.g. stay on the impacting branch a step past where the
/// rig dropped off it: that run's score there is ten times the others'. The median keeps the
/// typical draw's; a mean would let one such step decide between two models (BENCHMARKS.md,
/// "The judge's draws compared per step").
pub(super) fn members_error(
    members: &[Vec<StepScores>],
    tests: &[usize],
    which: Steps,
    channel: Option<&str>,
) -> Option<f64> {
    let mut steps: std::collections::BTreeMap<(usize, usize), Vec<(f64, usize)>> =
        std::collections::BTreeMap::new();
    for run in members {
        let mut compared = false;
        for s in run.iter().filter(|s| tests.contains(&s.test_index)) {
            let (mut sum, mut n) = (0.0, 0usize);
            add_step_squares(s, which, channel, &mut sum, &mut n);
            if n > 0 {
                compared = true;
                steps
                    .entry((s.test_index, s.step))
                    .or_default()
                    .push((sum / n as f64, n));
            }
        }
        if !compared {
            return None;
        }
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for runs in steps.values_mut() {
        runs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let k = runs.len();
        let median = if k % 2 == 1 {
            runs[k / 2].0
        } else {
            0.5 * (runs[k / 2 - 1].0 + runs[k / 2].0)
        };
        let count = runs.iter().map(|r| r.1).max().unwrap_or(0);
        sum += median * count as f64;
        n += count;
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// A candidate effect.
pub(super) struct Candidate {
    pub(super) effect: &'static str,
    /// The model with the candidate on top of the accepted effects.
    pub(super) ext: PhysicsSpec,
    pub(super) parameters: serde_json::Value,
    pub(super) n_params: usize,
    pub(super) evidence: serde_json::Value,
    pub(super) alternatives: Vec<String>,
    pub(super) train: Vec<usize>,
    pub(super) validation: Vec<usize>,
    pub(super) steps: Steps,
    /// The one channel the effect acts on (a sensor gain), whose features judge it.
    pub(super) channel: Option<String>,
    /// Where it was fitted ([`Candidate::judged_where_fitted`]): the steps of its tests and
    /// the twin step refinement it is judged on when the judging on every step rejects it.
    pub(super) where_fitted: Option<WhereFitted>,
    /// Why the regime's share of the error before is not asked of it (evidence that it is no
    /// absorbed contact excess; [`Candidate::share_waived_by`]), if it is not.
    pub(super) share_waived: Option<String>,
}

/// The steps and the twin step a candidate was fitted on, where it is judged as well.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct WhereFitted {
    /// The compared steps of the train and validation tests.
    pub(super) spans: Vec<Span>,
    /// The twin step's refinement of the fit (and the judging).
    pub(super) refinement: u32,
    /// What the spans are, in words (for the reason).
    pub(super) what: String,
}

impl Candidate {
    /// Candidate `effect`: the model `ext`, its `parameters` (`n_params` fitted) and the
    /// `evidence` for it, fitted on the train tests and judged on the validation tests of
    /// `split` over `steps`, on every channel, no alternatives named.
    pub(super) fn new(
        effect: &'static str,
        ext: PhysicsSpec,
        parameters: serde_json::Value,
        n_params: usize,
        evidence: serde_json::Value,
        split: (Vec<usize>, Vec<usize>),
        steps: Steps,
    ) -> Candidate {
        Candidate {
            effect,
            ext,
            parameters,
            n_params,
            evidence,
            alternatives: Vec::new(),
            train: split.0,
            validation: split.1,
            steps,
            channel: None,
            where_fitted: None,
            share_waived: None,
        }
    }

    /// Judged without the regime's share of the error before (the fall beyond the null spread
    /// and the penalty is still asked): the share guards against an effect that absorbs the
    /// default twin's own contact excess, and `why` says what rules that out.
    pub(super) fn share_waived_by(mut self, why: Option<String>) -> Candidate {
        self.share_waived = why;
        self
    }

    /// Judged as well on the steps `spans` of its tests at a twin step `refinement` times
    /// finer than the given one, as it was fitted, when the judging on every step at the
    /// twin's step (with the finer step's confirmation) rejects it ([`Work::judge`]); `what`
    /// says what the spans are.
    pub(super) fn judged_where_fitted(
        mut self,
        spans: Vec<Span>,
        refinement: u32,
        what: impl Into<String>,
    ) -> Candidate {
        self.where_fitted = Some(WhereFitted {
            spans,
            refinement,
            what: what.into(),
        });
        self
    }

    /// Every step of its train and validation tests, in session order: what it is judged on
    /// unless it names where it was fitted.
    pub(super) fn whole_tests(&self) -> Vec<Span> {
        let mut all: Vec<usize> = self.train.iter().chain(&self.validation).copied().collect();
        all.sort_unstable();
        all.dedup();
        all.into_iter().map(Span::whole).collect()
    }

    /// Judged on the features of `channel` only (when given): the one channel it acts on.
    pub(super) fn on_channel(mut self, channel: Option<String>) -> Candidate {
        self.channel = channel;
        self
    }

    /// With the other effects that explain the data as well.
    pub(super) fn with_alternatives(mut self, alternatives: Vec<String>) -> Candidate {
        self.alternatives = alternatives;
        self
    }
}

/// The diagnosis state: the runner, the model so far, the results.
pub(super) struct Work<'a> {
    pub(super) runner: ModelRunner<'a>,
    pub(super) steps: &'a SessionSteps,
    pub(super) opts: DiagnoseOptions,
    pub(super) accepted: PhysicsSpec,
    pub(super) effects: Vec<EffectResult>,
    pub(super) undecided: Vec<Undecided>,
    /// Mismatches a stage located beyond their errors that no accepted effect explains, in
    /// words: each makes the verdict `mismatch` (and is said in `undecided` as well).
    pub(super) unexplained: Vec<String>,
    /// Runs made: (model, steps, twin step refinement, ensemble member) -> scores.
    cache: HashMap<(String, Vec<Span>, u32, usize), Vec<StepScores>>,
    pub(super) progress: &'a mut dyn FnMut(DiagnoseProgress),
    /// What the stages' model runs cost, as each ended.
    pub(super) stage_costs: Vec<StageCost>,
    /// The stage under way and the runner's cost at its start.
    stage_start: Option<(&'static str, RunCost)>,
    /// The lines [`Work::note_once`] has shown.
    notes_shown: std::collections::HashSet<String>,
    /// The model each judged effect was judged with, by its index in `effects`.
    judged_models: HashMap<usize, PhysicsSpec>,
}

impl<'a> Work<'a> {
    /// A diagnosis that starts from the model `given`, nothing judged yet.
    pub(super) fn new(
        runner: ModelRunner<'a>,
        steps: &'a SessionSteps,
        opts: DiagnoseOptions,
        given: PhysicsSpec,
        progress: &'a mut dyn FnMut(DiagnoseProgress),
    ) -> Work<'a> {
        Work {
            runner,
            steps,
            opts,
            accepted: given,
            effects: Vec::new(),
            undecided: Vec::new(),
            unexplained: Vec::new(),
            cache: HashMap::new(),
            progress,
            stage_costs: Vec::new(),
            stage_start: None,
            notes_shown: std::collections::HashSet::new(),
            judged_models: HashMap::new(),
        }
    }
}

impl<'a> Work<'a> {
    /// `f` with the twin step `factor` times finer than the one in force, then the step and
    /// the worn starts ([`ModelRunner::set_wear_from`]) as they were, whatever `f` returned.
    pub(super) fn at_finer_step<T>(&mut self, factor: u32, f: impl FnOnce(&mut Self) -> T) -> T {
        let (own, wear_from) = (self.runner.refinement(), self.runner.wear_from());
        self.runner.set_refinement(own * factor);
        let out = f(self);
        self.runner.set_refinement(own);
        self.runner.set_wear_from(wear_from);
        out
    }

    /// Stage `stage` begins (`line` on the terminal); the stage before ends.
    pub(super) fn stage(&mut self, stage: &'static str, line: impl Into<String>) {
        self.end_stage();
        self.stage_start = Some((stage, self.runner.cost));
        (self.progress)(DiagnoseProgress::Stage(line.into()));
    }

    /// `line` on the terminal, unless it was shown before (a result several stages share, the
    /// same runs found in the cache, is shown once).
    pub(super) fn note_once(&mut self, line: String) {
        if self.notes_shown.insert(line.clone()) {
            (self.progress)(DiagnoseProgress::Note(line));
        }
    }

    /// The stage under way ends: its model runs' cost is kept in `stage_costs`.
    pub(super) fn end_stage(&mut self) {
        if let Some((stage, at)) = self.stage_start.take() {
            let c = self.runner.cost;
            self.stage_costs.push(StageCost {
                stage: stage.to_string(),
                model_runs: c.runs - at.runs,
                model_rig_seconds: c.rig_seconds - at.rig_seconds,
                model_wall_seconds: c.wall_seconds - at.wall_seconds,
            });
        }
    }

    /// From now on the model runs are `runner`'s (the twin's discretisation refined): the
    /// runs remembered are forgotten, and the cost goes on from the runner's so far.
    pub(super) fn replace_runner(&mut self, runner: ModelRunner<'a>) {
        let cost = self.runner.cost;
        self.runner = runner;
        self.runner.cost.add(cost);
        self.cache.clear();
    }

    /// The cost of the runs of `runners` (runners of other models) joins the diagnosis'.
    pub(super) fn absorb_cost(&mut self, runners: impl IntoIterator<Item = ModelRunner<'a>>) {
        for r in runners {
            self.runner.cost.add(r.cost);
        }
    }

    /// The compared steps of tests `tests` (every step) with extensions `ext`; a run made
    /// before for the same model, tests and twin step is not made again.
    pub(super) fn scores(
        &mut self,
        ext: &PhysicsSpec,
        tests: &[usize],
    ) -> Result<Vec<StepScores>, DiagnoseError> {
        let spans: Vec<Span> = tests.iter().map(|&t| Span::whole(t)).collect();
        self.scores_spans(ext, &spans)
    }

    /// [`Work::scores`] over the steps `spans` name ([`ModelRunner::run_spans`]).
    pub(super) fn scores_spans(
        &mut self,
        ext: &PhysicsSpec,
        spans: &[Span],
    ) -> Result<Vec<StepScores>, DiagnoseError> {
        self.member_scores(ext, spans, 0)
    }

    /// [`Work::scores_spans`] of ensemble member `member` ([`ModelRunner::run_members`]).
    fn member_scores(
        &mut self,
        ext: &PhysicsSpec,
        spans: &[Span],
        member: usize,
    ) -> Result<Vec<StepScores>, DiagnoseError> {
        let key = self.cache_key(ext, spans, member);
        if let Some(s) = self.cache.get(&key) {
            return Ok(s.clone());
        }
        let run = (ext.clone(), spans.to_vec(), member);
        let s = (self.runner.run_members(std::slice::from_ref(&run))?)
            .pop()
            .unwrap_or_default();
        self.cache.insert(key, s.clone());
        Ok(s)
    }

    /// [`Work::member_scores`] of the members `0..members`, one run each ([`members_error`]
    /// judges them).
    fn member_runs(
        &mut self,
        ext: &PhysicsSpec,
        spans: &[Span],
        members: usize,
    ) -> Result<Vec<Vec<StepScores>>, DiagnoseError> {
        (0..members)
            .map(|m| self.member_scores(ext, spans, m))
            .collect()
    }

    /// The model the effect at index `i` of `effects` was judged with (None: not judged).
    pub(super) fn judged_model(&self, i: usize) -> Option<&PhysicsSpec> {
        self.judged_models.get(&i)
    }

    /// The band's runs of `ext` over `spans` (members 0, 1, ... [`DiagnoseOptions::band_members`])
    /// made so far at the runner's twin step as it is now; None where one was not made.
    pub(super) fn band_runs_made(
        &self,
        ext: &PhysicsSpec,
        spans: &[Span],
    ) -> Option<Vec<Vec<StepScores>>> {
        (0..self.members(Steps::All))
            .map(|m| self.cache.get(&self.cache_key(ext, spans, m)).cloned())
            .collect()
    }

    /// What a run of `ext` over `spans` is remembered by: the model, the steps, the twin step's
    /// refinement, and, with wear, where its tests start ([`ModelRunner::set_wear_from`]).
    fn cache_key(
        &self,
        ext: &PhysicsSpec,
        spans: &[Span],
        member: usize,
    ) -> (String, Vec<Span>, u32, usize) {
        let mut model = ext.to_json();
        if let Some(r) = self.runner.wear_from().filter(|_| ext.wear.is_some()) {
            model.push_str(&format!(" worn as at x{r}"));
        }
        (model, spans.to_vec(), self.runner.refinement(), member)
    }

    /// Runs the model for every `(ext, spans)` of `runs` not run before, side by side on the
    /// runner's threads ([`ModelRunner::run_many`]), so that the [`Work::scores_spans`] calls
    /// for them that follow find them made.
    pub(super) fn prefetch(
        &mut self,
        runs: Vec<(PhysicsSpec, Vec<Span>)>,
    ) -> Result<(), DiagnoseError> {
        self.prefetch_members(runs.into_iter().map(|(e, s)| (e, s, 0)).collect())
    }

    /// [`Work::prefetch`] of ensemble members' runs ([`ModelRunner::run_members`]).
    fn prefetch_members(&mut self, runs: Vec<MemberRun>) -> Result<(), DiagnoseError> {
        let (mut keys, mut todo) = (Vec::new(), Vec::new());
        for (ext, spans, member) in runs {
            let key = self.cache_key(&ext, &spans, member);
            if self.cache.contains_key(&key) || keys.contains(&key) {
                continue;
            }
            keys.push(key);
            todo.push((ext, spans, member));
        }
        if todo.len() < 2 {
            return Ok(());
        }
        let out = self.runner.run_members(&todo)?;
        for (key, s) in keys.into_iter().zip(out) {
            self.cache.insert(key, s);
        }
        Ok(())
    }

    /// The steps of test `test` from `from` through `through` for runs whose contact geometry
    /// is nowhere closer than `closest`'s: from a state of open contact captured at `from`
    /// with `closest` ([`ModelRunner::capture_open`]), or, where a pair closes before `from`
    /// with `closest` (the earlier steps carry evidence then), every step through `through`.
    pub(super) fn open_span(
        &mut self,
        closest: &PhysicsSpec,
        test: usize,
        from: usize,
        through: Option<usize>,
    ) -> Result<Span, DiagnoseError> {
        let open = from > 0 && self.runner.capture_open(closest, test, from)?;
        Ok(Span::of_test(test, if open { from } else { 0 }, through))
    }

    pub(super) fn names(&self, tests: &[usize]) -> Vec<String> {
        tests.iter().map(|&t| self.steps.tests[t].clone()).collect()
    }

    /// The errors of the model `ext` on the candidate's tests: on every step of them, or,
    /// with `where_fitted`, on the steps its fit compared ([`Candidate::judged_where_fitted`]).
    ///
    /// A candidate judged on the impact band is judged over [`Work::members`] runs of each
    /// model ([`DiagnoseOptions::band_members`]): the errors take each step's median over
    /// them ([`members_error`]).
    pub(super) fn errors(
        &mut self,
        ext: &PhysicsSpec,
        c: &Candidate,
        where_fitted: bool,
    ) -> Result<Option<SetError>, DiagnoseError> {
        let spans = Self::judged_spans(c, where_fitted);
        let runs = self.member_runs(ext, &spans, self.members(c.steps))?;
        let channel = c.channel.as_deref();
        Ok(members_error(&runs, &c.train, c.steps, channel)
            .zip(members_error(&runs, &c.validation, c.steps, channel))
            .map(|(train, validation)| SetError { train, validation }))
    }

    /// [`Work::errors`] of each model of `exts` on the candidate's tests (every step), their
    /// runs made side by side on the runner's threads first.
    pub(super) fn errors_of_models(
        &mut self,
        exts: &[PhysicsSpec],
        c: &Candidate,
    ) -> Result<Vec<Option<SetError>>, DiagnoseError> {
        let spans = Self::judged_spans(c, false);
        let members = self.members(c.steps);
        let runs = (0..members)
            .flat_map(|m| exts.iter().map(move |e| (e.clone(), m)))
            .map(|(e, m)| (e, spans.clone(), m))
            .collect();
        self.prefetch_members(runs)?;
        exts.iter().map(|e| self.errors(e, c, false)).collect()
    }

    /// The runs of each model a candidate judged on `steps` is judged over: the band's
    /// members for the impact band, one run otherwise.
    fn members(&self, steps: Steps) -> usize {
        match steps {
            Steps::All => self.opts.band_members.max(1),
            Steps::ImpactFree => 1,
        }
    }

    /// The spans [`Work::errors`] compares: every step of the candidate's tests, or, with
    /// `where_fitted`, the steps its fit compared.
    fn judged_spans(c: &Candidate, where_fitted: bool) -> Vec<Span> {
        match c.where_fitted.as_ref().filter(|_| where_fitted) {
            Some(w) => w.spans.clone(),
            None => c.whole_tests(),
        }
    }

    /// [`Work::errors`] of the model `before` and of the candidate's, their runs side by side
    /// on the runner's threads.
    fn errors_before_after(
        &mut self,
        before: &PhysicsSpec,
        c: &Candidate,
        where_fitted: bool,
    ) -> Result<(Option<SetError>, Option<SetError>), DiagnoseError> {
        let spans = Self::judged_spans(c, where_fitted);
        let runs = (0..self.members(c.steps))
            .flat_map(|m| {
                [
                    (before.clone(), spans.clone(), m),
                    (c.ext.clone(), spans.clone(), m),
                ]
            })
            .collect();
        self.prefetch_members(runs)?;
        Ok((
            self.errors(before, c, where_fitted)?,
            self.errors(&c.ext, c, where_fitted)?,
        ))
    }

    /// Judges candidate `c` against the accepted model; accepts it if it predicts its
    /// validation tests better beyond the null spread. Returns whether accepted.
    ///
    /// A candidate judged on the impact band (every step) is judged on [`Work::members`] runs
    /// of each model, each step's median over them ([`members_error`]), the model before and
    /// the candidate's drawing the same perturbations ([`ModelRunner::run_members`]). One
    /// that passes is judged again at a twin step [`CONFIRM_REFINEMENT`] times finer, on its
    /// validation tests: the default twin over-counts contact in the band (its step,
    /// BENCHMARKS.md "Why the nominal twin over-counts contact"), and a smaller clearance or a
    /// tilt can absorb part of that excess (on `identify.toml` with nothing hidden, a tilt of
    /// -0.012 rad lowered the validation error 3x at the twin's step). What passes at the
    /// finer step as well is missing physics; what does not is the twin's own
    /// discretisation. A candidate with wear runs each validation test there from its
    /// lead-in, worn as the run at the twin's step left it ([`ModelRunner::set_wear_from`]).
    ///
    /// A candidate that also names where it was fitted ([`Candidate::judged_where_fitted`])
    /// and is not accepted so is judged there as well ([`Work::judge_where_fitted`]).
    pub(super) fn judge(&mut self, mut c: Candidate) -> Result<bool, DiagnoseError> {
        let members = self.members(c.steps);
        if members > 1 {
            c.evidence["judged_over_runs"] = serde_json::json!({
                "members": members,
                "perturbation": self.runner.perturbation(),
                "per_step": "the median over the runs of the step's mean squared score",
            });
        }
        self.show(&c, (members > 1).then(|| format!("each model's error per step the median of {members} runs from perturbed states in the band")).as_deref());
        let (ok, before, after, reason) = self.judge_on_whole_tests(&mut c)?;
        let Some(w) = c.where_fitted.clone().filter(|_| !ok) else {
            return Ok(self.record(c, before, after, ok, reason));
        };
        c.evidence["on_whole_tests"] = serde_json::json!({
            "validation_before": before.map(|e| e.validation),
            "validation_after": after.map(|e| e.validation),
            "reason": reason,
        });
        self.judge_where_fitted(c, &w, &reason)
    }

    /// [`Work::judge`] on every step of the candidate's tests (with the finer step's
    /// confirmation in the band): whether accepted, the errors before and after, why.
    fn judge_on_whole_tests(
        &mut self,
        c: &mut Candidate,
    ) -> Result<(bool, Option<SetError>, Option<SetError>, String), DiagnoseError> {
        let accepted = self.accepted.clone();
        let (before, after) = self.errors_before_after(&accepted, c, false)?;
        let (ok, reason) = self.assess(c, before, after);
        if !ok || c.steps != Steps::All {
            return Ok((ok, before, after, reason));
        }
        let line = format!(
            "{} again at a {CONFIRM_REFINEMENT}x finer twin step on {}",
            c.effect,
            self.names(&c.validation).join(", ")
        );
        (self.progress)(DiagnoseProgress::Evaluation(line));
        let (validation, steps, channel) = (c.validation.clone(), c.steps, c.channel.clone());
        let whole: Vec<Span> = validation.iter().map(|&t| Span::whole(t)).collect();
        let members = self.members(steps);
        let cand_ext = c.ext.clone();
        let fine = |w: &mut Self, ext: &PhysicsSpec| -> Result<Option<f64>, DiagnoseError> {
            let runs = w.member_runs(ext, &whole, members)?;
            Ok(members_error(&runs, &validation, steps, channel.as_deref()))
        };
        let own = self.runner.refinement();
        let (fb, fa) = self.at_finer_step(CONFIRM_REFINEMENT, |w| {
            // With wear: each validation test from its lead-in, worn as the twin's step left it.
            w.runner.set_wear_from(Some(own));
            let both = w.prefetch_members(
                (0..members)
                    .flat_map(|m| {
                        [
                            (accepted.clone(), whole.clone(), m),
                            (cand_ext.clone(), whole.clone(), m),
                        ]
                    })
                    .collect(),
            );
            let fb = both.and_then(|()| fine(w, &accepted));
            let fa = fb.as_ref().ok().map(|_| fine(w, &cand_ext));
            (fb, fa)
        });
        let (fb, fa) = (fb?, fa.transpose()?.flatten());
        let as_set = |v: Option<f64>, train: Option<SetError>| {
            v.zip(train).map(|(validation, t)| SetError {
                train: t.train,
                validation,
            })
        };
        // NOTE: the finer step asks the fall beyond the null spread and the penalty, not
        // the regime's share: the share guards against the default twin's own contact excess,
        // which the finer step removes, while the finer twin's chaotic band lands on other
        // attractors than the default one's (a hidden +14 % clearance: 2.37 -> 0.59 at the
        // twin's step, 4.74 -> 2.53 at the 3x finer one).
        let (ok2, reason2) =
            self.assess_with(c, as_set(fb, before), as_set(fa, after), false, None);
        c.evidence["finer_twin_step"] = serde_json::json!({
            "refinement": own * CONFIRM_REFINEMENT,
            "validation_before": fb,
            "validation_after": fa,
        });
        let reason = if ok2 {
            format!("{reason}; at a {CONFIRM_REFINEMENT}x finer twin step: {reason2}")
        } else {
            format!("at the twin's step {reason}, but at a {CONFIRM_REFINEMENT}x finer twin step {reason2}: the twin's own discretisation, not missing physics")
        };
        Ok((ok2, before, after, reason))
    }

    /// [`Work::judge`] of a candidate where it was fitted ([`Candidate::judged_where_fitted`]):
    /// its errors before and after on those steps at that twin step decide, by the regime's
    /// rule (the fall beyond the null spread and the penalty, and the regime's share; at a
    /// finer twin step in the band, the null spread
    /// [`DiagnoseOptions::fitted_steps_null_spread`]). What the whole tests said is kept in
    /// the evidence (`on_whole_tests`) and the reason.
    ///
    /// `w` is the candidate's `where_fitted`, `whole` why the whole tests rejected it.
    fn judge_where_fitted(
        &mut self,
        mut c: Candidate,
        w: &WhereFitted,
        whole: &str,
    ) -> Result<bool, DiagnoseError> {
        (self.progress)(DiagnoseProgress::Evaluation(format!(
            "{} where it was fitted ({}) at a {}x finer twin step",
            c.effect, w.what, w.refinement
        )));
        let accepted = self.accepted.clone();
        let own = self.runner.refinement();
        let (before, after) = self.at_finer_step(w.refinement, |work| {
            // A wear candidate's tests each from their lead-in, worn as the twin's step left
            // them (as the confirmation runs them); any other candidate's as it was fitted.
            if c.ext.wear.is_some() && c.ext.wear != accepted.wear {
                work.runner.set_wear_from(Some(own));
            }
            work.errors_before_after(&accepted, &c, true)
        })?;
        let null = where_fitted_null_spread(&self.opts, w, c.steps);
        let (ok, reason) = self.assess_with(&c, before, after, true, null);
        c.evidence["judged_on"] = serde_json::json!({
            "steps": w.what,
            "refinement": own * w.refinement,
        });
        let reason = format!(
            "on the whole tests {whole}; where it was fitted ({}, at a {}x finer twin step) {reason}",
            w.what, w.refinement
        );
        Ok(self.record(c, before, after, ok, reason))
    }

    /// Judges candidate `c`, a refit of an accepted effect with as many parameters (the same
    /// physics on the same evidence, so no null spread or penalty to clear), against the
    /// accepted model on every step of its tests: accepted if it lowers both the train and the
    /// validation error. Accepted, it replaces the accepted effects `replaces` picks, and its
    /// `error_before` is that of the model `without` the effect (the refit's own fall is in
    /// its evidence, `refit`). Returns whether accepted.
    pub(super) fn judge_refit(
        &mut self,
        mut c: Candidate,
        without: &PhysicsSpec,
        replaces: impl Fn(&EffectResult) -> bool,
    ) -> Result<bool, DiagnoseError> {
        self.show(
            &c,
            Some("a refit of an accepted effect: it must lower both errors"),
        );
        let accepted = self.accepted.clone();
        let (before, after) = self.errors_before_after(&accepted, &c, false)?;
        let (ok, reason) = match (before, after) {
            (Some(b), Some(a)) if a.train < b.train && a.validation < b.validation => (
                true,
                format!(
                    "a refit: the train error falls {:.3} -> {:.3}, the validation error {:.3} -> {:.3}",
                    b.train, a.train, b.validation, a.validation
                ),
            ),
            (Some(b), Some(a)) => (
                false,
                format!(
                    "a refit that does not lower both errors (train {:.3} -> {:.3}, validation {:.3} -> {:.3})",
                    b.train, a.train, b.validation, a.validation
                ),
            ),
            _ => (false, "no compared step: cannot be judged".to_string()),
        };
        if !ok {
            return Ok(self.record(c, before, after, ok, reason));
        }
        c.evidence["refit"] = serde_json::json!({"error_before": before, "error_after": after});
        let without_error = self.errors(without, &c, false)?;
        let first = (self.effects.iter()).position(|e| e.accepted && replaces(e));
        self.supersede(
            replaces,
            &format!("refitted: the accepted {} in its place", c.effect),
        );
        let ok = self.record(c, without_error.or(before), after, ok, reason);
        // The refit takes the place in identification order of the first effect it replaces
        // (an upper joint refitted after 1FU's damping found under it is still named first).
        if let Some(i) = first {
            let last = self.effects.len() - 1;
            self.effects[i..].rotate_right(1);
            // Each judged model follows its effect: the last to `i`, the rest one on.
            let models: Vec<_> = (i..=last).map(|k| self.judged_models.remove(&k)).collect();
            for (old, m) in (i..=last).zip(models) {
                let new = if old == last { i } else { old + 1 };
                if let Some(m) = m {
                    self.judged_models.insert(new, m);
                }
            }
        }
        Ok(ok)
    }

    /// [`Work::judge`] with the errors `before` and `after` computed elsewhere, on what
    /// `judged_on` names (a redundancy of channels rather than model runs).
    pub(super) fn judge_on(
        &mut self,
        c: Candidate,
        judged_on: &str,
        before: Option<SetError>,
        after: Option<SetError>,
    ) -> bool {
        self.show(&c, Some(judged_on));
        self.decide(c, before, after)
    }

    /// The candidate on the terminal: effect, parameters, its tests and what judges it.
    fn show(&mut self, c: &Candidate, judged_on: Option<&str>) {
        let line = format!(
            "{} {} (fit on {}, validated on {}{})",
            c.effect,
            c.parameters,
            self.names(&c.train).join(", "),
            self.names(&c.validation).join(", "),
            judged_on.map_or(String::new(), |j| format!(": {j}"))
        );
        (self.progress)(DiagnoseProgress::Evaluation(line));
    }

    /// Accepts candidate `c` if its validation error falls from `before` to `after` by more
    /// than the null spread plus the penalty for its parameters, and by the regime's share;
    /// records the result. Returns whether accepted.
    fn decide(&mut self, c: Candidate, before: Option<SetError>, after: Option<SetError>) -> bool {
        let (ok, reason) = self.assess(&c, before, after);
        self.record(c, before, after, ok, reason)
    }

    /// Whether candidate `c`'s validation error falls from `before` to `after` by more than
    /// the null spread plus the penalty for its parameters, and by the regime's share; why.
    fn assess(
        &self,
        c: &Candidate,
        before: Option<SetError>,
        after: Option<SetError>,
    ) -> (bool, String) {
        self.assess_with(c, before, after, true, None)
    }

    /// [`Work::assess`], asking the regime's share of the error before only with `share`,
    /// and with the null spread `null_spread` in place of the regime's where given.
    fn assess_with(
        &self,
        c: &Candidate,
        before: Option<SetError>,
        after: Option<SetError>,
        share: bool,
        null_spread: Option<f64>,
    ) -> (bool, String) {
        match (before, after) {
            (Some(b), Some(a)) => {
                let gain = b.validation - a.validation;
                let (regime_null, regime_share) = match c.steps {
                    Steps::All => (
                        self.opts.contact_null_spread,
                        self.opts.contact_min_relative_improvement,
                    ),
                    Steps::ImpactFree => {
                        (self.opts.null_spread, self.opts.min_relative_improvement)
                    }
                };
                let share = if share && c.share_waived.is_none() {
                    regime_share
                } else {
                    0.0
                };
                let waived = (c.share_waived.as_ref()).map_or(String::new(), |w| {
                    format!("; the band's share not asked: {w}")
                });
                let null = null_spread.unwrap_or(regime_null);
                let needed = null + self.opts.parameter_penalty * c.n_params as f64;
                if a.validation >= b.validation {
                    (
                        false,
                        format!(
                            "the validation error does not fall ({:.3} -> {:.3})",
                            b.validation, a.validation
                        ),
                    )
                } else if gain <= needed || a.validation > (1.0 - share) * b.validation {
                    let by_less = if share > 0.0 {
                        format!(" or by less than {:.0} %", 100.0 * share)
                    } else {
                        String::new()
                    };
                    (false, format!(
                        "the validation error falls by {gain:.3} ({:.3} -> {:.3}), within the null spread and the penalty for {} parameter(s) ({needed:.3}){by_less}",
                        b.validation, a.validation, c.n_params
                    ))
                } else {
                    (true, format!(
                        "the validation error falls {:.1}x ({:.3} -> {:.3}), beyond the null spread and the penalty ({needed:.3}){waived}",
                        b.validation / a.validation.max(1e-12), b.validation, a.validation
                    ))
                }
            }
            _ => (
                false,
                "no compared step of the regime on the train or validation tests: cannot be judged"
                    .to_string(),
            ),
        }
    }

    /// Records candidate `c`'s result (accepted: the model from now on). Returns `ok`.
    fn record(
        &mut self,
        c: Candidate,
        before: Option<SetError>,
        after: Option<SetError>,
        ok: bool,
        reason: String,
    ) -> bool {
        if ok {
            self.accepted = c.ext.clone();
        }
        self.judged_models.insert(self.effects.len(), c.ext.clone());
        self.effects.push(EffectResult {
            effect: c.effect.to_string(),
            rank: 0,
            accepted: ok,
            parameters: c.parameters,
            alternatives: c.alternatives,
            evidence: c.evidence,
            reason,
            train_tests: self.names(&c.train),
            validation_tests: self.names(&c.validation),
            error_before: before,
            error_after: after,
        });
        ok
    }

    /// Withdraws the accepted effects `which` picks (a later effect explains their evidence
    /// in their place; the accepted model no longer holds them), saying `why`.
    pub(super) fn supersede(&mut self, which: impl Fn(&EffectResult) -> bool, why: &str) {
        for e in self.effects.iter_mut().filter(|e| e.accepted && which(e)) {
            e.accepted = false;
            e.reason = format!("{}; superseded: {why}", e.reason);
        }
    }

    pub(super) fn undecided(&mut self, effect: &str, reason: impl Into<String>) {
        self.undecided.push(Undecided {
            effect: effect.to_string(),
            reason: reason.into(),
        });
    }
}

/// The model run a point of a search needs: its extensions and the steps scored.
pub(super) type PointRun<'p> = &'p dyn Fn(&Work<'_>, f64) -> (PhysicsSpec, Vec<Span>);

/// A one-parameter search by model runs: the error of every point of `grid`, then of the
/// points `refine(best)` around the best one (a point tried before is not run again).
/// Returns every (value, error) tried. A point's model run is `plan`'s (its extensions and
/// the steps scored), made `members` times (member 0 the model as given, the others draws
/// from perturbed states in the band, common to every point: [`ModelRunner::run_members`]);
/// the points' runs are made side by side on the runner's threads before each round
/// ([`Work::prefetch_members`]), and `error` turns a point's runs' scores into its error
/// (`None` where nothing was compared).
pub(super) fn grid_then_refine(
    work: &mut Work<'_>,
    grid: Vec<f64>,
    refine: impl Fn(f64) -> Vec<f64>,
    plan: PointRun<'_>,
    members: usize,
    mut error: impl FnMut(&mut Work<'_>, f64, &[Vec<StepScores>]) -> Option<f64>,
) -> Result<Vec<(f64, f64)>, DiagnoseError> {
    let members = members.max(1);
    let mut tried: Vec<(f64, f64)> = Vec::new();
    let mut grid = grid;
    for round in 0..2 {
        let runs = grid
            .iter()
            .filter(|&&x| !tried.iter().any(|p| p.0 == x))
            .flat_map(|&x| {
                let (ext, spans) = plan(work, x);
                (0..members).map(move |m| (ext.clone(), spans.clone(), m))
            })
            .collect();
        work.prefetch_members(runs)?;
        for &x in &grid {
            if tried.iter().any(|p| p.0 == x) {
                continue;
            }
            let (ext, spans) = plan(work, x);
            let s = work.member_runs(&ext, &spans, members)?;
            if let Some(e) = error(work, x, &s) {
                tried.push((x, e));
            }
        }
        let Some(&(best, _)) = tried.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
            break;
        };
        if round == 0 {
            grid = refine(best);
        }
    }
    Ok(tried)
}

/// The null spread of a candidate judged where it was fitted, `w`, on `steps`, in place of
/// the regime's: [`DiagnoseOptions::fitted_steps_null_spread`] in the band at a finer twin
/// step, where the twin's own contact excess is gone; None (the regime's) otherwise.
fn where_fitted_null_spread(opts: &DiagnoseOptions, w: &WhereFitted, steps: Steps) -> Option<f64> {
    (w.refinement > 1 && steps == Steps::All).then_some(opts.fitted_steps_null_spread)
}

/// Tests split alternately: positions 0, 2, ... train, 1, 3, ... validation.
pub(super) fn alternate(tests: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let train = tests.iter().step_by(2).copied().collect();
    let validation = tests.iter().skip(1).step_by(2).copied().collect();
    (train, validation)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_band_fit_at_a_finer_step_takes_the_fitted_steps_null_spread() {
        let opts = DiagnoseOptions::default();
        let at = |refinement| WhereFitted {
            spans: Vec::new(),
            refinement,
            what: String::new(),
        };
        assert_eq!(
            where_fitted_null_spread(&opts, &at(3), Steps::All),
            Some(opts.fitted_steps_null_spread)
        );
        // The tilt's contact steps at the twin's own step keep the band's.
        assert_eq!(where_fitted_null_spread(&opts, &at(1), Steps::All), None);
        assert_eq!(
            where_fitted_null_spread(&opts, &at(3), Steps::ImpactFree),
            None
        );
        assert!(opts.fitted_steps_null_spread < opts.contact_null_spread);
    }

    #[test]
    fn tests_split_alternately() {
        assert_eq!(alternate(&[3, 5, 6, 9]), (vec![3, 6], vec![5, 9]));
        assert_eq!(alternate(&[2]), (vec![2], vec![]));
    }

    /// A step of test `test` with one `contact` and one `lower_tip` feature of these scores.
    fn step(test: usize, step: usize, regime: Regime, scores: [f64; 2]) -> StepScores {
        let feature = |channel: &str, score: f64| crate::twin::compare::FeatureComparison {
            channel: channel.to_string(),
            feature: "rms".to_string(),
            measured: 1.0,
            measured_spread: None,
            model: 1.0,
            model_spread: None,
            score,
        };
        StepScores {
            test: format!("t{test}"),
            test_index: test,
            step,
            omega_ratio: 1.0,
            regime,
            level: 2e-5,
            features: vec![
                feature("contact", scores[0]),
                feature("lower_tip", scores[1]),
            ],
        }
    }

    #[test]
    fn runs_of_a_model_are_judged_by_each_steps_median() {
        // Three runs over two band steps of test 0 and one of test 1: the second run lands on
        // another attractor at step 1 (scores 20).
        let run = |s1: f64, s0: f64, t1: f64| {
            vec![
                step(0, 0, Regime::Impacts, [s0, s0]),
                step(0, 1, Regime::Impacts, [s1, s1]),
                step(1, 0, Regime::ImpactFreeHigh, [t1, 3.0 * t1]),
            ]
        };
        let runs = [run(1.0, 2.0, 1.0), run(20.0, 3.0, 2.0), run(2.0, 1.0, 3.0)];
        // Test 0, per step: median of the mean squares {4, 9, 1} = 4 and {1, 400, 4} = 4.
        let e = members_error(&runs, &[0], Steps::All, None).unwrap();
        assert!((e - 2.0).abs() < 1e-12, "{e}");
        // The plain error of each run alone, for contrast: the outlier run's is 14.3.
        let alone = set_error_of(&runs[1], &[0], Steps::All, None).unwrap();
        assert!((alone - (409.0f64 / 2.0).sqrt()).abs() < 1e-12, "{alone}");
        // Impact-free steps leave out the contact channel; one channel alone is its features.
        let e = members_error(&runs, &[1], Steps::ImpactFree, None).unwrap();
        assert!((e - 6.0).abs() < 1e-12, "{e}");
        let e = members_error(&runs, &[0, 1], Steps::All, Some("contact")).unwrap();
        assert!(
            (e - ((4.0 + 4.0 + 4.0) / 3.0f64).sqrt()).abs() < 1e-12,
            "{e}"
        );
        // One run is the plain error; an even count takes the mean of the middle two.
        let e = members_error(&runs[..1], &[0, 1], Steps::All, None).unwrap();
        assert_eq!(Some(e), set_error_of(&runs[0], &[0, 1], Steps::All, None));
        let e = members_error(&runs[..2], &[0], Steps::All, None).unwrap();
        assert!((e - ((6.5 + 200.5) / 2.0f64).sqrt()).abs() < 1e-12, "{e}");
        // A run that compares nothing there: no error.
        assert_eq!(members_error(&runs, &[2], Steps::All, None), None);
        assert_eq!(members_error(&runs, &[0], Steps::ImpactFree, None), None);
    }
}
