//! Convergence studies (reference section 4.3): the upper tip velocity over the first periods
//! at one excitation frequency, from fixed initial conditions, for a series of time steps or
//! of mode counts, and the relative RMS error of each run against the finest one.
//!
//! Initial conditions ([`ConvergenceStart`]): by default the modal state reached after
//! `prerun_periods` at 1000 steps per period (more if the ROM's highest mode needs it),
//! continued to a period start with every pair open that is followed by impacts; the same
//! displacement and velocity for every run, no contact force. Five periods from rest do not
//! reach the impacts at the high level: that start shows the open scheme's second order and
//! the round-off plateau instead. The mode study truncates one ROM exactly
//! ([`Rom::truncated`]); its initial modal state is the prerun state of the full ROM
//! restricted to the kept modes.
//!
//! Measured on the default rig (BENCHMARKS.md): with impacts the error is first order
//! (0.43 at 1000 steps per period, 0.023 at 64,000 against 128,000) while the RMS value moves
//! by 0.8 % at 1000; from rest it is second order down to about 1e-10 at 1,024,000 steps per
//! period, where round-off takes over.

use crate::plan::per_l_to_metres;
use crate::rom::Rom;
use crate::signal::{relative_rms_error, SignalError};

use super::driven::{BEAM_SENSORS, UPPER_TIP};
use super::error::SimError;
use super::excitation::Excitation;
use super::integrator::{Integrator, IntegratorParameters, State, TimeStep};
use super::output::StepOutput;
use super::stepped::{beam_length, output_index};

/// The operating point and window of a convergence study.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConvergenceSetup {
    /// Excitation frequency, Omega / omega_2. Default 1.0.
    pub omega_ratio: f64,
    /// Base displacement amplitude / l. Default 6e-5 (the high level).
    pub level: f64,
    /// Clearance / l. Default 2.78e-3.
    pub clearance: f64,
    /// Excitation periods compared. Default 5.
    pub periods: u32,
    /// Where the compared window starts. Default [`ConvergenceStart::Impacts`].
    #[serde(default)]
    pub start: ConvergenceStart,
    /// Periods of the prerun that produces the initial conditions (at 1000 steps per period;
    /// [`ConvergenceStart::Impacts`] only). Default 200.
    pub prerun_periods: u32,
    /// Integrator parameters (the time step is set by the study).
    pub integrator: IntegratorParameters,
}

impl Default for ConvergenceSetup {
    fn default() -> Self {
        ConvergenceSetup {
            omega_ratio: 1.0,
            level: 6e-5,
            clearance: 2.78e-3,
            periods: 5,
            start: ConvergenceStart::Impacts,
            prerun_periods: 200,
            integrator: IntegratorParameters::default(),
        }
    }
}

/// The fixed initial conditions of a study.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConvergenceStart {
    /// After a prerun, at the start of an open period followed by impacts: the window holds
    /// impacts, so the scheme converges at first order (the impact instants are resolved to
    /// a step) and the error stays far above round-off at every practical step.
    #[default]
    Impacts,
    /// From rest relative to the base at t = 0: the response builds up from zero, as in a
    /// start-up; at the high level the first five periods stay open, the scheme converges at
    /// second order and the error falls to the round-off plateau.
    Rest,
}

/// One run of a study.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConvergenceRun {
    /// Steps per excitation period, or number of modes.
    pub x: f64,
    /// Time step, s.
    pub dt: f64,
    /// Relative RMS error against the reference run (0 for the reference itself).
    pub error: f64,
    /// RMS of the compared signal u / (Omega l) over the window.
    pub rms: f64,
    /// Relative difference of `rms` from the reference's: the quantity the stepped-sine
    /// response curves show (reference section 4.3: below 1 % at 1000 steps per period).
    pub rms_change: f64,
    /// Steps with at least one closed pair.
    pub closed_steps: u64,
    /// Contact solves that did not converge.
    pub solver_failures: u64,
    /// Upper tip velocity / (Omega l) at the time levels t_0 + k dt, k = 0 .. steps - 1.
    #[serde(skip)]
    pub u: Vec<f64>,
}

/// A finished study.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConvergenceStudy {
    /// "dt" or "modes".
    pub kind: String,
    /// The setup.
    pub setup: ConvergenceSetup,
    /// The x of the reference (finest) run.
    pub reference: f64,
    /// All runs, ascending in x (the reference last).
    pub runs: Vec<ConvergenceRun>,
}

/// Errors of a study.
#[derive(Debug, thiserror::Error)]
pub enum ConvergenceError {
    /// Bad setup or a rejected time step.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The ROM cannot be used or truncated.
    #[error("{0}")]
    Rom(String),
    /// The error could not be computed.
    #[error("relative RMS error: {0}")]
    Signal(#[from] SignalError),
    /// A run did not stay finite.
    #[error("the run with x = {x} became non-finite at step {step}")]
    NonFinite {
        /// Steps per period or modes.
        x: f64,
        /// Step index.
        step: u64,
    },
}

fn tip_index(rom: &Rom) -> Result<usize, ConvergenceError> {
    output_index(rom, BEAM_SENSORS[UPPER_TIP]).map_err(|e| ConvergenceError::Rom(e.to_string()))
}

fn excitation(rom: &Rom, setup: &ConvergenceSetup) -> Result<(Excitation, f64), ConvergenceError> {
    let l = beam_length(rom).map_err(|e| ConvergenceError::Rom(e.to_string()))?;
    let omega = setup.omega_ratio * rom.omega_ref();
    Ok((
        Excitation::Sine {
            amplitude_m: per_l_to_metres(setup.level, l),
            omega,
            phase: 0.0,
        },
        omega,
    ))
}

/// The fixed initial conditions (eta_0, v_0, t_0). From rest: zero at t = 0. Otherwise: prerun from rest, then on, one excitation
/// period at a time, to the first period that starts with every pair open and has an impact
/// within its first two periods (so the compared window holds impacts). `v_0` is the modal
/// velocity at `t_0` (second order: the prerun's half-step velocity plus half a step of the
/// free acceleration), so that every run can start its own half-step velocity consistently.
fn initial_conditions(
    rom: &Rom,
    setup: &ConvergenceSetup,
) -> Result<(Vec<f64>, Vec<f64>, f64), ConvergenceError> {
    if setup.start == ConvergenceStart::Rest {
        let n = rom.n_modes();
        return Ok((vec![0.0; n], vec![0.0; n], 0.0));
    }
    let (exc, omega) = excitation(rom, setup)?;
    let mut params = setup.integrator.clone();
    let spp = u64::from(stable_steps_per_period(rom, setup.omega_ratio)?);
    params.time_step = TimeStep::StepsPerPeriod {
        steps: spp as f64,
        omega,
    };
    let mut integ = Integrator::new(rom, params)?;
    integ.set_clearance(per_l_to_metres(setup.clearance, rom.meta.beam_length))?;
    let mut st = integ.state_at_rest();
    integ.run(
        &mut st,
        &exc,
        u64::from(setup.prerun_periods) * spp,
        &mut super::NullSink,
    )?;
    let mut candidate: Option<State> = None;
    let mut chosen = None;
    for _ in 0..400 {
        let start = st.clone();
        let rep = integ.run(&mut st, &exc, spp, &mut super::NullSink)?;
        if rep.counters.closed_steps > 0 {
            if let Some(c) = candidate.take() {
                chosen = Some(c);
                break;
            }
        }
        // The start of this period qualifies if it is open; it is kept for one more period.
        candidate = if start.closed_pairs().is_empty() && rep.counters.closed_steps == 0 {
            Some(start)
        } else {
            None
        };
    }
    // Without impacts the last state is as good as any.
    let st = chosen.unwrap_or(st);
    let t0 = st.time();
    let v0 = consistent_velocity(rom, &st, integ.dt(), exc.accel_at(t0), 0.5);
    Ok((st.eta().to_vec(), v0, t0))
}

/// Steps per excitation period at `omega_ratio` x omega_2: 1000, doubled until stable (with 5 %
/// margin) for the ROM's highest mode with all pairs open (e.g. 4000 for a ROM covering
/// 800 x f(1FU)). Used by the prerun and as the mode study's default.
pub fn stable_steps_per_period(rom: &Rom, omega_ratio: f64) -> Result<u32, ConvergenceError> {
    let limits = super::integrator::stability_limits(rom)?;
    let needed = limits.steps_per_period_open() * omega_ratio;
    let mut spp = 1000u32;
    while f64::from(spp) <= 1.05 * needed {
        spp *= 2;
    }
    Ok(spp)
}

/// `v + s dt a_free` with the free modal acceleration `a_free = -D v - Omega^2 eta - beta a_base`
/// (no contact force: all pairs open). `s = +1/2` turns a half-step velocity `v^{-1/2}` into
/// the velocity at `t_0`; `s = -1/2` turns the velocity at `t_0` into `v^{-1/2}`.
fn consistent_velocity(rom: &Rom, st: &State, dt: f64, a_base: f64, s: f64) -> Vec<f64> {
    (0..rom.n_modes())
        .map(|i| {
            let w = rom.omega[i];
            let d = 2.0 * rom.damping_ratio[i] * w;
            let v = st.eta_dot()[i];
            let a = -d * v - w * w * st.eta()[i] - rom.beta[i] * a_base;
            v + s * dt * a
        })
        .collect()
}

/// One run: `periods` excitation periods at `steps` steps per period from the given modal
/// state, returning the upper tip velocity / (Omega l) at the time levels.
fn run_one(
    rom: &Rom,
    setup: &ConvergenceSetup,
    steps: u32,
    ic: (&[f64], &[f64], f64),
    x: f64,
) -> Result<ConvergenceRun, ConvergenceError> {
    let (exc, omega) = excitation(rom, setup)?;
    let iu = tip_index(rom)?;
    let mut params = setup.integrator.clone();
    params.time_step = TimeStep::StepsPerPeriod {
        steps: f64::from(steps),
        omega,
    };
    let mut integ = Integrator::new(rom, params)?;
    integ.set_clearance(per_l_to_metres(setup.clearance, rom.meta.beam_length))?;
    // The run's half-step velocity v^{-1/2} from the velocity at t_0.
    let at_t0 = State::from_modal(ic.0.to_vec(), ic.1.to_vec(), rom.n_pairs(), ic.2);
    let v_half = consistent_velocity(rom, &at_t0, integ.dt(), exc.accel_at(ic.2), -0.5);
    let mut st = State::from_modal(ic.0.to_vec(), v_half, rom.n_pairs(), ic.2);
    let n = u64::from(setup.periods) * u64::from(steps);
    let scale = 1.0 / (omega * rom.meta.beam_length);
    // NOTE (sample times): the integrator's velocities belong to the half steps
    // t_0 + (j + 1/2) dt, which differ between runs by half a step: comparing them sample by
    // sample would charge a first-order time shift to every run. The study compares the
    // velocity at the time levels t_0 + k dt instead: the initial velocity (every pair open,
    // no contact force: C_eta v_0), then the mean of consecutive half-step velocities
    // (second order, like the scheme). With an integer ratio of steps, coarse and fine
    // samples coincide in time.
    let c_eta = &rom.outputs[iu].c_eta;
    let v0: f64 = c_eta.iter().zip(ic.1).map(|(c, v)| c * v).sum();
    let mut u = Vec::with_capacity(n as usize);
    u.push(v0 * scale);
    let mut prev: Option<f64> = None;
    let rep = integ.run(&mut st, &exc, n, &mut |o: &StepOutput<'_>| {
        let v = o.velocity[iu];
        if let Some(p) = prev {
            u.push(0.5 * (p + v) * scale);
        }
        prev = Some(v);
    })?;
    if let Some(super::RunStop::NonFinite { step, .. }) = rep.stop {
        return Err(ConvergenceError::NonFinite { x, step });
    }
    Ok(ConvergenceRun {
        x,
        dt: integ.dt(),
        error: 0.0,
        rms: (u.iter().map(|x| x * x).sum::<f64>() / u.len() as f64).sqrt(),
        rms_change: 0.0,
        closed_steps: rep.counters.closed_steps,
        solver_failures: rep.counters.max_iterations + rep.counters.diverged,
        u,
    })
}

fn finish(
    kind: &str,
    setup: &ConvergenceSetup,
    mut runs: Vec<ConvergenceRun>,
) -> Result<ConvergenceStudy, ConvergenceError> {
    runs.sort_by(|a, b| a.x.total_cmp(&b.x));
    let reference = runs.last().expect("at least one run");
    let (u_ref, dt_ref, x_ref) = (reference.u.clone(), reference.dt, reference.x);
    let rms_ref = reference.rms;
    for r in runs.iter_mut() {
        r.rms_change = (r.rms - rms_ref).abs() / rms_ref;
        r.error = if r.x == x_ref {
            0.0
        } else {
            relative_rms_error(&r.u, r.dt, &u_ref, dt_ref)?
        };
    }
    Ok(ConvergenceStudy {
        kind: kind.into(),
        setup: setup.clone(),
        reference: x_ref,
        runs,
    })
}

/// Time-step study: one run per entry of `steps_per_period` (the largest is the reference).
/// `on_run` is called after each run with its x.
pub fn dt_study(
    rom: &Rom,
    setup: &ConvergenceSetup,
    steps_per_period: &[u32],
    on_run: &mut dyn FnMut(f64),
) -> Result<ConvergenceStudy, ConvergenceError> {
    if steps_per_period.is_empty() {
        return Err(ConvergenceError::Rom("no time steps to compare".into()));
    }
    let (eta, eta_dot, t0) = initial_conditions(rom, setup)?;
    let mut runs = Vec::new();
    for &s in steps_per_period {
        runs.push(run_one(rom, setup, s, (&eta, &eta_dot, t0), f64::from(s))?);
        on_run(f64::from(s));
    }
    finish("dt", setup, runs)
}

/// Mode study: one run per entry of `modes` on the ROM truncated to that many modes, at
/// `steps_per_period` (the largest count is the reference; counts above the ROM's are an
/// error).
pub fn modes_study(
    rom: &Rom,
    setup: &ConvergenceSetup,
    modes: &[usize],
    steps_per_period: u32,
    on_run: &mut dyn FnMut(f64),
) -> Result<ConvergenceStudy, ConvergenceError> {
    if modes.is_empty() {
        return Err(ConvergenceError::Rom("no mode counts to compare".into()));
    }
    let (eta, eta_dot, t0) = initial_conditions(rom, setup)?;
    let mut runs = Vec::new();
    for &m in modes {
        let r = rom
            .truncated(m)
            .map_err(|e| ConvergenceError::Rom(e.to_string()))?;
        runs.push(run_one(
            &r,
            setup,
            steps_per_period,
            (&eta[..m], &eta_dot[..m], t0),
            m as f64,
        )?);
        on_run(m as f64);
    }
    finish("modes", setup, runs)
}
