//! The virtual stepped sine (reference section 4, DESIGN.md "The model" 5): the ROM driven by a
//! prescribed base sine that steps through the frequencies of a test plan, the state carried
//! from step to step as on the rig; per step a settle window and a record window, and the step
//! metrics of [`crate::signal`] over the record window.
//!
//! How a test starts, as in the rig's procedure (`src/control`): the plan's tests run in order,
//! each from the state the previous one left (the beams keep vibrating between tests, and the
//! model's wear grows on), and the drive moves from the previous test's level (zero for the
//! first test, from rest) to the test's over [`TEST_START_RAMP_S`] at its first frequency: here
//! the base acceleration amplitude, linearly; on the rig the drive voltage, under amplitude
//! control. So an up test that follows a down test at its starting frequency stays on the branch
//! the down test left it on. `carry_state = false` runs every test from rest instead (the drive
//! still ramped in), the tests in parallel.
//!
//! Per test ([`run_test`]): one [`DrivenRom`] (read at the tips) at the test's clearance; per frequency step the
//! time step is `2 pi / (Omega steps_per_period)` and the base displacement is
//! `q sin(Omega t + phi)` with the phase chosen so that the displacement is continuous at the
//! frequency change ([`continuous_phase`]), also from one test to the next. Independent tests
//! (from rest) run on worker threads ([`run_plan`]); each test is sequential and deterministic,
//! so the results do not depend on the number of workers. No clock and no I/O here: the caller times the run and renders
//! progress from the [`TestProgress`] callbacks.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::config::PhysicsSpec;
use crate::contact::{ContactProblem, ContactSolution};
use crate::plan::{per_l_to_metres, Plan, TestSpec, TEST_START_RAMP_S};
use crate::rom::Rom;
use crate::signal::{step_metrics, MetricsParams, SignalError, StepMetrics, StepRecord};

use super::driven::{
    DrivenError, DrivenRom, MissingOutput, SensorSink, SensorStep, BEAM_SENSORS, LOWER_TIP,
    UPPER_TIP,
};
use super::effects::{self, Effects};
use super::error::SimError;
use super::excitation::{continuous_phase, Excitation};
use super::integrator::{
    stability_limits, IntegratorParameters, RunStop, SolverCounters, TimeStep,
};

/// Sensor (ROM output) names the metrics are computed from, upper then lower: the vertical
/// tip velocities.
const TIPS: [&str; 2] = [BEAM_SENSORS[UPPER_TIP], BEAM_SENSORS[LOWER_TIP]];

/// The ROM driven by the test's base sine, read at the [`TIPS`].
type Tips = DrivenRom<2>;

/// Options of a virtual stepped sine beyond the plan.
#[derive(Clone, Debug, PartialEq)]
pub struct SteppedSineOptions {
    /// Integrator parameters. The time step is replaced per frequency step by the test's
    /// `steps_per_period`; coupling and contact solver are used as given.
    pub integrator: IntegratorParameters,
    /// Metrics tuning.
    pub metrics: MetricsParams,
    /// Keep the record window of the step whose Omega / omega_2 is nearest to this value as a
    /// [`StepTrace`] (for time histories, contact activity and the scalogram). `None`: none.
    pub trace_at: Option<f64>,
    /// Capture contact problems from the traced step (see [`CaptureOptions`]). Needs `trace_at`.
    pub capture: Option<CaptureOptions>,
    /// Progress granularity: a [`TestProgress`] callback at least every this many excitation
    /// periods (>= 1).
    pub progress_periods: u32,
    /// The model's extensions (`[model]`, valid): modal corrections, clamp friction, clearance
    /// per test, wear (carried across tests with `carry_state`), tilt. Sensor gains are an
    /// observation of a rig's channels and do not apply to the ROM's own outputs. Frequencies
    /// stay in units of the nominal ROM's omega_2 (a plan means the same Hz whatever the
    /// model). Default: none.
    pub model: PhysicsSpec,
    /// Run the plan's tests in order, each from the state the previous test left (the beams,
    /// the model's effects, the drive level it ramps from), as the rig's procedure does. Off:
    /// every test from rest, the tests in parallel. Either way a test's drive ramps in over
    /// [`TEST_START_RAMP_S`]. Default: on.
    pub carry_state: bool,
}

impl Default for SteppedSineOptions {
    fn default() -> Self {
        SteppedSineOptions {
            integrator: IntegratorParameters::default(),
            metrics: MetricsParams::default(),
            trace_at: Some(1.0),
            capture: None,
            progress_periods: 10,
            model: PhysicsSpec::default(),
            carry_state: true,
        }
    }
}

/// Capture of real contact problems (the sub-problem on the active pairs, as solved) from the
/// traced step's record window, for cross-checks against other solvers. The capture re-runs
/// the window's first periods from a copy of the state, so it does not change the results.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureOptions {
    /// Stop after this many problems.
    pub max_problems: usize,
    /// Only solves with at least this many pairs in the sweep.
    pub min_active_pairs: usize,
    /// Keep every `stride`-th qualifying solve (>= 1), so the problems spread over impacts.
    pub stride: usize,
    /// Search at most this many excitation periods.
    pub max_periods: u32,
}

/// Where a test is, for progress displays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TestProgress<'a> {
    /// Index of the test in the plan.
    pub test: usize,
    /// Its name.
    pub name: &'a str,
    /// Frequency step being run (0-based) and the number of steps.
    pub step: usize,
    /// Number of frequency steps of the test.
    pub steps: usize,
    /// Omega / omega_2 of the step.
    pub omega_ratio: f64,
    /// Excitation periods done in the test so far and in total.
    pub periods_done: u64,
    /// Excitation periods of the whole test.
    pub periods_total: u64,
    /// Set once, when the test has ended.
    pub finished: bool,
}

/// Result of one frequency step.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepResult {
    /// Index of the step in the test.
    pub index: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// Excitation frequency, Hz.
    pub frequency_hz: f64,
    /// Time step, s.
    pub dt: f64,
    /// The metrics over the record window.
    #[serde(flatten)]
    pub metrics: StepMetrics,
    /// Contact solves of the step (settle and record) that did not converge (sweep limit
    /// reached or diverged).
    pub solver_failures: u64,
    /// Contact-solver counters of the step (settle and record).
    pub solver: SolverCounters,
}

/// Result of one test.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TestResult {
    /// The test as planned.
    pub spec: TestSpec,
    /// Base displacement amplitude q = level l, m.
    pub base_level_m: f64,
    /// Clearance = clearance l, m.
    pub clearance_m: f64,
    /// The completed frequency steps, in run order.
    pub steps: Vec<StepResult>,
    /// Time steps integrated.
    pub time_steps: u64,
    /// Sum of the steps' solver failures.
    pub solver_failures: u64,
    /// Why the test ended early, if it did (the completed steps are kept).
    pub stopped: Option<String>,
    /// The traced step's record window.
    #[serde(skip)]
    pub trace: Option<StepTrace>,
    /// Captured contact problems with rigtwin's solutions.
    #[serde(skip)]
    pub captured: Vec<(ContactProblem, ContactSolution)>,
}

/// The record window of one step, sample by sample (contact time level of each step; the
/// velocities are at the half step before, see [`super::output::StepOutput`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepTrace {
    /// Omega / omega_2 of the step.
    pub omega_ratio: f64,
    /// Excitation circular frequency, rad/s.
    pub omega: f64,
    /// Base displacement amplitude, m.
    pub base_level_m: f64,
    /// Sample interval (= the time step), s.
    pub dt: f64,
    /// Times, s.
    pub time: Vec<f64>,
    /// Tip displacements relative to the base, m.
    pub displacement_upper: Vec<f64>,
    /// See `displacement_upper`.
    pub displacement_lower: Vec<f64>,
    /// Tip velocities relative to the base, m/s.
    pub velocity_upper: Vec<f64>,
    /// See `velocity_upper`.
    pub velocity_lower: Vec<f64>,
    /// Base displacement, m.
    pub base_displacement: Vec<f64>,
    /// Whether any pair was closed.
    pub any_closed: Vec<bool>,
    /// Integrated normal contact force, N.
    pub normal_force: Vec<f64>,
    /// Integrated tangential contact force, N.
    pub tangential_force: Vec<f64>,
}

/// Why a stepped sine could not run. Problems during a run (non-convergence, a state that
/// became non-finite) are data in the [`TestResult`], not errors.
#[derive(Debug, thiserror::Error)]
pub enum SteppedSineError {
    /// The ROM lacks something the stepped sine needs.
    #[error("ROM: {0}")]
    Rom(String),
    /// A test's settings do not work with this ROM.
    #[error("plan {source_name}, test {index} ({name}): {key}: {detail}")]
    Test {
        /// The plan's source (file).
        source_name: String,
        /// Test number in the plan (1-based).
        index: usize,
        /// Test name.
        name: String,
        /// The plan key at fault.
        key: &'static str,
        /// What is wrong.
        detail: String,
    },
    /// A `[model]` extension does not fit the ROM (names the key).
    #[error("model: {0}")]
    Model(#[from] crate::physics::PhysicsError),
    /// The integrator rejected its setup.
    #[error("test {name}: {source}")]
    Sim {
        /// Test name.
        name: String,
        /// The integrator's error.
        source: SimError,
    },
    /// The metrics of a step could not be computed.
    #[error("test {name}, step {step} (Omega/omega_2 = {omega_ratio}): metrics: {source}")]
    Metrics {
        /// Test name.
        name: String,
        /// Step index.
        step: usize,
        /// Omega / omega_2.
        omega_ratio: f64,
        /// The signal error.
        source: SignalError,
    },
}

/// The stepped sine's error for a ROM without a sensor output it reads.
fn missing_output(missing: MissingOutput) -> SteppedSineError {
    SteppedSineError::Rom(format!(
        "no sensor output named \"{}\" (outputs: {}); the rig description must define \
         sensors \"{}\" and \"{}\"",
        missing.name,
        missing.available.join(", "),
        TIPS[0],
        TIPS[1]
    ))
}

/// Index of the ROM output (sensor) named `name`.
pub(crate) fn output_index(rom: &Rom, name: &str) -> Result<usize, SteppedSineError> {
    super::driven::output_index(rom, name).map_err(missing_output)
}

/// Checks that the ROM has the tip outputs.
fn check_tips(rom: &Rom) -> Result<(), SteppedSineError> {
    super::driven::output_indices(rom, TIPS).map_err(missing_output)?;
    Ok(())
}

/// The ROM's beam length l, m (the unit of plan levels and clearances).
pub(crate) fn beam_length(rom: &Rom) -> Result<f64, SteppedSineError> {
    let l = rom.meta.beam_length;
    if l.is_finite() && l > 0.0 {
        Ok(l)
    } else {
        Err(SteppedSineError::Rom(format!(
            "meta.beam_length = {l} (the length unit of plan levels and clearances) is not a \
             length > 0; rebuild the ROM with `rigtwin rom build`"
        )))
    }
}

/// Checks a plan against a ROM before anything runs: the ROM has the tip outputs and the beam
/// length, and every step's time step is below the stability limit the coupling needs.
pub fn check_plan(
    rom: &Rom,
    plan: &Plan,
    opts: &SteppedSineOptions,
) -> Result<(), SteppedSineError> {
    check_tips(rom)?;
    beam_length(rom)?;
    opts.integrator
        .validate()
        .map_err(|source| SteppedSineError::Sim {
            name: "(all)".into(),
            source,
        })?;
    let model = effects::prepare(rom, &opts.model, "model")?;
    let limits = stability_limits(&model).map_err(|source| SteppedSineError::Sim {
        name: "(all)".into(),
        source,
    })?;
    // The limits count steps per period of the model's omega_2; plans count in the nominal's.
    let scale = rom.omega_ref() / model.omega_ref();
    let needs_closed = opts.integrator.coupling == super::Coupling::Explicit
        && opts.integrator.enforce_closed_bound;
    let (steps_needed_ref, which) = if needs_closed {
        (
            limits.steps_per_period_closed(),
            "all pairs closed, explicit coupling",
        )
    } else {
        (limits.steps_per_period_open(), "all pairs open")
    };
    for (i, t) in plan.tests.iter().enumerate() {
        let fastest = t.omega_start.max(t.omega_end);
        // Steps per excitation period needed at Omega = r omega_2: steps_needed_ref * r.
        let needed = steps_needed_ref * fastest * scale;
        if !(f64::from(t.steps_per_period) > needed) {
            return Err(SteppedSineError::Test {
                source_name: plan.source.clone(),
                index: i + 1,
                name: t.name.clone(),
                key: "steps_per_period",
                detail: format!(
                    "{} steps per excitation period is beyond the explicit stability limit of \
                     this ROM ({which}) at Omega/omega_2 = {fastest}: at least {:.0} are needed",
                    t.steps_per_period,
                    needed.floor() + 1.0
                ),
            });
        }
    }
    Ok(())
}

/// Collects the channels of the record window (and optionally the full trace) from the
/// [`TIPS`] (index 0 upper, 1 lower).
struct Recorder<'a> {
    vu: Vec<f64>,
    vl: Vec<f64>,
    closed: Vec<bool>,
    normal: Vec<f64>,
    trace: Option<(&'a mut StepTrace, &'a Excitation)>,
}

impl SensorSink<2> for Recorder<'_> {
    fn record(&mut self, out: &SensorStep<2>) {
        self.vu.push(out.velocity[0]);
        self.vl.push(out.velocity[1]);
        self.closed.push(out.contact.any_closed);
        self.normal.push(out.contact.normal_force);
        if let Some((tr, exc)) = &mut self.trace {
            tr.time.push(out.time);
            tr.displacement_upper.push(out.displacement[0]);
            tr.displacement_lower.push(out.displacement[1]);
            tr.velocity_upper.push(out.velocity[0]);
            tr.velocity_lower.push(out.velocity[1]);
            tr.base_displacement
                .push(exc.displacement_at(out.time).unwrap_or(f64::NAN));
            tr.any_closed.push(out.contact.any_closed);
            tr.normal_force.push(out.contact.normal_force);
            tr.tangential_force.push(out.contact.tangential_force);
        }
    }
}

/// Runs `periods` excitation periods in chunks of at most `chunk` periods, reporting after
/// each chunk through `on_chunk(periods in the chunk)`. Stops early when the state becomes
/// non-finite. Returns the time steps done and the stop, if any.
#[allow(clippy::too_many_arguments)] // the run's parts, passed through
fn run_periods<S: SensorSink<2>>(
    rom: &mut Tips,
    effects: &mut Effects,
    exc: &Excitation,
    periods: u64,
    steps_per_period: u64,
    chunk: u64,
    sink: &mut S,
    on_chunk: &mut dyn FnMut(u64),
) -> Result<(u64, Option<RunStop>), SimError> {
    let (mut left, mut steps) = (periods, 0);
    while left > 0 {
        let p = left.min(chunk);
        let rep = effects.run(rom, exc, p * steps_per_period, sink)?;
        steps += rep.steps;
        left -= p;
        on_chunk(p);
        if rep.stop.is_some() {
            return Ok((steps, rep.stop));
        }
    }
    Ok((steps, None))
}

/// Index of the step whose ratio is nearest to `target` (first on ties).
fn nearest_step(ratios: &[f64], target: f64) -> usize {
    let mut best = 0;
    for (i, r) in ratios.iter().enumerate() {
        if (r - target).abs() < (ratios[best] - target).abs() {
            best = i;
        }
    }
    best
}

/// The simulated beams between two tests of a plan run in order ([`SteppedSineOptions`]
/// `carry_state`): the driven ROM with its state, the model's effects (wear grown so far), and
/// the drive (phase, frequency, level) the next test ramps from.
struct Carried {
    driven: Tips,
    effects: Effects,
    phase: f64,
    omega: f64,
    level_m: f64,
}

/// Runs one test of a plan from rest, the drive ramped in over [`TEST_START_RAMP_S`].
/// `test_index` only labels the progress callbacks.
pub fn run_test(
    rom: &Rom,
    spec: &TestSpec,
    test_index: usize,
    opts: &SteppedSineOptions,
    progress: &mut dyn FnMut(&TestProgress<'_>),
) -> Result<TestResult, SteppedSineError> {
    run_test_after(rom, spec, test_index, opts, &mut None, progress)
}

/// Runs one test from the state `carried` holds (from rest when `None`), the drive ramped from
/// the carried level (0 from rest) to the test's over [`TEST_START_RAMP_S`]; leaves the state
/// at the test's end in `carried` (`None` when the test stopped early).
fn run_test_after(
    rom: &Rom,
    spec: &TestSpec,
    test_index: usize,
    opts: &SteppedSineOptions,
    carried: &mut Option<Carried>,
    progress: &mut dyn FnMut(&TestProgress<'_>),
) -> Result<TestResult, SteppedSineError> {
    check_tips(rom)?;
    let l = beam_length(rom)?;
    let sim_err = |source| SteppedSineError::Sim {
        name: spec.name.clone(),
        source,
    };
    let w2 = rom.omega_ref();
    let q = per_l_to_metres(spec.level, l);
    let clearance = opts.model.test_clearance(&spec.name, spec.clearance_m(l));
    let ratios = spec.omega_ratios();
    let spp = f64::from(spec.steps_per_period);
    let chunk = u64::from(opts.progress_periods.max(1));
    let trace_step = opts.trace_at.map(|r| nearest_step(&ratios, r));

    let (mut driven, mut effects, mut phase, mut omega_prev, from_level, fresh) =
        match carried.take() {
            Some(mut c) => {
                // The rig's operator sets the next test's clearance; the wear stays on top.
                c.effects
                    .set_clearance(&mut c.driven, clearance)
                    .map_err(sim_err)?;
                (c.driven, c.effects, c.phase, c.omega, c.level_m, false)
            }
            None => {
                let model = effects::prepare(rom, &opts.model, "model")?;
                let mut params = opts.integrator.clone();
                params.time_step = TimeStep::StepsPerPeriod {
                    steps: spp,
                    omega: ratios[0] * w2,
                };
                let mut driven = Tips::new(&model, TIPS, params).map_err(|e| match e {
                    DrivenError::Output(missing) => missing_output(missing),
                    DrivenError::Sim(source) => sim_err(source),
                })?;
                let effects = Effects::new(&model, &opts.model, "model", clearance)?;
                effects.attach(&mut driven).map_err(sim_err)?;
                (driven, effects, 0.0, ratios[0] * w2, 0.0, true)
            }
        };

    let mut result = TestResult {
        spec: spec.clone(),
        base_level_m: q,
        clearance_m: clearance,
        steps: Vec::with_capacity(ratios.len()),
        time_steps: 0,
        solver_failures: 0,
        stopped: None,
        trace: None,
        captured: Vec::new(),
    };
    let periods_total = spec.total_periods();
    let mut periods_done = 0u64;
    let n_rec = u64::from(spec.record_periods) * u64::from(spec.steps_per_period);
    let report = |step: usize, ratio: f64, done: u64, finished: bool| TestProgress {
        test: test_index,
        name: &spec.name,
        step,
        steps: ratios.len(),
        omega_ratio: ratio,
        periods_done: done,
        periods_total,
        finished,
    };

    'steps: for (s, &ratio) in ratios.iter().enumerate() {
        let omega = ratio * w2;
        if s > 0 || !fresh {
            // The integrator was built at the first step's dt (of this or an earlier test).
            driven
                .set_time_step(TimeStep::StepsPerPeriod { steps: spp, omega })
                .map_err(sim_err)?;
        }
        phase = continuous_phase(omega_prev, phase, omega, driven.state().time());
        omega_prev = omega;
        // NOTE: as the rig's procedure ramps the drive that starts a test, the test's first
        // step ramps the base acceleration amplitude from the previous test's level (zero from
        // rest) over TEST_START_RAMP_S (in its settle window); the later steps change frequency
        // without a ramp.
        let exc = if s == 0 {
            Excitation::RampedSine {
                from_amplitude_m: from_level,
                amplitude_m: q,
                omega,
                phase,
                ramp_start: driven.state().time(),
                ramp_s: TEST_START_RAMP_S,
            }
        } else {
            Excitation::Sine {
                amplitude_m: q,
                omega,
                phase,
            }
        };
        let before = driven.state().counters();
        let spp_steps = u64::from(spec.steps_per_period);

        // Settle.
        let (steps, mut stop) = run_periods(
            &mut driven,
            &mut effects,
            &exc,
            u64::from(spec.settle_periods),
            spp_steps,
            chunk,
            &mut super::NullSink,
            &mut |p| {
                periods_done += p;
                progress(&report(s, ratio, periods_done, false));
            },
        )
        .map_err(sim_err)?;
        result.time_steps += steps;

        // Record.
        let traced = trace_step == Some(s);
        let mut trace = StepTrace {
            omega_ratio: ratio,
            omega,
            base_level_m: q,
            dt: driven.dt(),
            ..Default::default()
        };
        let capture_from =
            (traced && opts.capture.is_some() && stop.is_none()).then(|| driven.clone());
        let cap = n_rec as usize;
        if traced {
            for v in [
                &mut trace.time,
                &mut trace.displacement_upper,
                &mut trace.displacement_lower,
                &mut trace.velocity_upper,
                &mut trace.velocity_lower,
                &mut trace.base_displacement,
                &mut trace.normal_force,
                &mut trace.tangential_force,
            ] {
                v.reserve_exact(cap);
            }
            trace.any_closed.reserve_exact(cap);
        }
        let mut rec = Recorder {
            vu: Vec::with_capacity(cap),
            vl: Vec::with_capacity(cap),
            closed: Vec::with_capacity(cap),
            normal: Vec::with_capacity(cap),
            trace: traced.then_some((&mut trace, &exc)),
        };
        if stop.is_none() {
            let (steps, rec_stop) = run_periods(
                &mut driven,
                &mut effects,
                &exc,
                u64::from(spec.record_periods),
                spp_steps,
                chunk,
                &mut rec,
                &mut |p| {
                    periods_done += p;
                    progress(&report(s, ratio, periods_done, false));
                },
            )
            .map_err(sim_err)?;
            result.time_steps += steps;
            stop = rec_stop;
        }
        let step_counters = driven.state().counters().since(&before);
        let failures = step_counters.max_iterations + step_counters.diverged;
        result.solver_failures += failures;
        if let Some(RunStop::NonFinite { step, time }) = stop {
            result.stopped = Some(format!(
                "the state became non-finite at time step {step} (t = {time:.6} s) in frequency \
                 step {s} (Omega/omega_2 = {ratio}); {} contact solves had failed before",
                result.solver_failures
            ));
            break 'steps;
        }
        let Recorder {
            vu,
            vl,
            closed,
            normal,
            ..
        } = rec;
        let metrics = step_metrics(
            &StepRecord {
                dt: driven.dt(),
                omega,
                base_level: q,
                tip_velocity_upper: &vu,
                tip_velocity_lower: &vl,
                contact_closed: &closed,
                normal_force: Some(&normal),
            },
            &opts.metrics,
        )
        .map_err(|source| SteppedSineError::Metrics {
            name: spec.name.clone(),
            step: s,
            omega_ratio: ratio,
            source,
        })?;
        result.steps.push(StepResult {
            index: s,
            omega_ratio: ratio,
            frequency_hz: omega / (2.0 * std::f64::consts::PI),
            dt: driven.dt(),
            metrics,
            solver_failures: failures,
            solver: step_counters,
        });
        if traced {
            result.trace = Some(trace);
        }
        if let (Some(mut copy), Some(copt)) = (capture_from, opts.capture) {
            result.captured = capture_problems(&mut copy, &exc, &copt, spec, ratio, spp_steps)
                .map_err(sim_err)?;
        }
    }
    progress(&report(
        result.steps.len().saturating_sub(1),
        result.steps.last().map_or(ratios[0], |s| s.omega_ratio),
        periods_done,
        true,
    ));
    // A test that stopped (non-finite state) leaves nothing to carry: the next starts at rest.
    if result.stopped.is_none() {
        *carried = Some(Carried {
            driven,
            effects,
            phase,
            omega: omega_prev,
            level_m: q,
        });
    }
    Ok(result)
}

/// Re-runs steps one at a time and keeps the contact problems of qualifying solves.
fn capture_problems(
    rom: &mut Tips,
    exc: &Excitation,
    opt: &CaptureOptions,
    spec: &TestSpec,
    ratio: f64,
    steps_per_period: u64,
) -> Result<Vec<(ContactProblem, ContactSolution)>, SimError> {
    let mut out = Vec::new();
    let mut qualifying = 0usize;
    let stride = opt.stride.max(1);
    for _ in 0..u64::from(opt.max_periods) * steps_per_period {
        if out.len() >= opt.max_problems {
            break;
        }
        let mut last_active = 0usize;
        let rep = rom.run(exc, 1, &mut |o: &SensorStep<2>| {
            last_active = o.solve.map_or(0, |s| s.active_pairs);
        })?;
        if rep.stop.is_some() {
            break;
        }
        if rep.counters.solves == 1 && last_active >= opt.min_active_pairs.max(1) {
            if qualifying % stride == 0 {
                let label = format!(
                    "{} Omega/omega_2={ratio} step {} active {last_active}",
                    spec.name,
                    rom.state().step() - 1
                );
                out.push(
                    rom.integrator()
                        .contact_solver()
                        .last_active_problem(&label),
                );
            }
            qualifying += 1;
        }
    }
    Ok(out)
}

/// Runs every test of a plan. With `opts.carry_state` (the default) the tests run in plan order
/// on the calling thread, each from the state the previous one left, as on the rig (`jobs` is
/// not used); without, each test runs from rest on up to `jobs` worker threads (the tests are
/// then independent). Results are in plan order. `progress` is called from the workers.
pub fn run_plan(
    rom: &Rom,
    plan: &Plan,
    opts: &SteppedSineOptions,
    jobs: usize,
    progress: &(dyn Fn(&TestProgress<'_>) + Sync),
) -> Result<Vec<TestResult>, SteppedSineError> {
    check_plan(rom, plan, opts)?;
    if opts.carry_state {
        let mut carried = None;
        return plan
            .tests
            .iter()
            .enumerate()
            .map(|(i, t)| run_test_after(rom, t, i, opts, &mut carried, &mut |p| progress(p)))
            .collect();
    }
    let n = plan.tests.len();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<TestResult, SteppedSineError>>>> =
        Mutex::new((0..n).map(|_| None).collect());
    let workers = jobs.clamp(1, n.max(1));
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                let r = run_test(rom, &plan.tests[i], i, opts, &mut |p| progress(p));
                results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.expect("every test index is taken by exactly one worker"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_step_picks_the_closest_ratio() {
        let r = [1.06, 1.03, 1.0, 0.97];
        assert_eq!(nearest_step(&r, 1.0), 2);
        assert_eq!(nearest_step(&r, 1.1), 0);
        assert_eq!(nearest_step(&r, 0.5), 3);
    }
}
