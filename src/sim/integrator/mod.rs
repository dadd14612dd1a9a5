//! The leapfrog time integrator with an implicit contact boundary on the MacNeal ROM
//! (DESIGN.md "The model" 3-4, reference section 3.3.2).
//!
//! The ROM: `g = Phi_g eta + G_res lambda + g0` (`g0 = [clearance, 0, 0]` per pair, or
//! `[clearance + offset_k, 0, 0]` with per-pair gap offsets, [`Integrator::set_gap_offsets`];
//! positive normal gap = open) and `eta'' + D eta' + Omega^2 eta = Phi_g^T lambda - beta a_base`,
//! `D = diag(2 zeta_i w_i)`. Leapfrog with a fixed `dt`, modal velocities at half steps, modal
//! damping averaged over the half steps (`a = 1/dt + D/2`, `b = 1/dt - D/2`):
//!
//! `a .* v^{j+1/2} = b .* v^{j-1/2} - Omega^2 eta^j + Phi_g^T lambda - beta a_base(t^j)`,
//! `eta^{j+1} = eta^j + dt v^{j+1/2}`.
//!
//! Per step the contact forces come from one frictional contact problem
//! `gamma = W lambda + c`, `-gamma in N_C(lambda)` (solved by [`crate::contact`]) on the pairs
//! predicted to be closed (see `predict.rs`); the two couplings ([`Coupling`]) differ in
//! where the gap is imposed. See `step/mod.rs` for the equations of both.
//!
//! One [`Integrator`] holds everything that depends on the ROM and `dt` (precomputed matrices,
//! the contact solver, workspace); a [`State`] holds what evolves and can be carried from one
//! run to the next (stepped sine: a new frequency, the same state). Runs are deterministic:
//! the same integrator parameters, ROM, state and excitation give bit-identical outputs.
//!
//! Files: `parameters.rs` (what the caller chooses), `state.rs` (what evolves), `model.rs` (the
//! per-ROM precomputation), `validation.rs` (input checks), `limits.rs` (stability limits),
//! `predict.rs` (open-contact prediction), `step/` (the stages of one step), `kernels.rs`
//! (the dense kernels with their fixed evaluation order).

mod kernels;
pub mod limits;
mod model;
mod parameters;
mod predict;
mod state;
mod step;
mod validation;

pub use limits::{stability_limits, StabilityLimits};
pub use parameters::{Coupling, IntegratorParameters, TimeStep};
pub use state::{RunReport, RunStop, SolverCounters, State, StateMismatch};

use crate::contact::ContactSolver;
use crate::rom::Rom;

use super::error::SimError;
use super::excitation::Excitation;
use super::output::StepSink;
use kernels::dot;
use model::{Model, Workspace};
use parameters::resolve_dt;
use validation::{check_rom, check_time_step};

/// The leapfrog integrator with implicit contact boundary for one ROM and one time step.
#[derive(Clone, Debug)]
pub struct Integrator {
    params: IntegratorParameters,
    limits: StabilityLimits,
    output_names: Vec<String>,
    pub(crate) model: Model,
    pub(crate) ws: Workspace,
    pub(crate) solver: ContactSolver,
    use_avx2: bool,
}

impl Integrator {
    /// Builds the integrator: checks the parameters and the ROM, computes the stability
    /// limits and rejects a time step beyond the one the coupling relies on, precomputes the
    /// Delassus matrix and the prediction data, and sets up the contact solver.
    pub fn new(rom: &Rom, params: IntegratorParameters) -> Result<Integrator, SimError> {
        params.validate()?;
        let (m, n) = check_rom(rom)?;
        let limits = stability_limits(rom)?;
        let dt = resolve_dt(&params.time_step, limits.omega_ref);
        check_time_step(dt, &limits, params.coupling, params.enforce_closed_bound)?;

        let mut model = Model::new(rom, &params, (m, n), dt);
        let solver = model.set_dt(dt, &params.contact)?;
        let ws = Workspace::new(m, n, model.n_out);
        Ok(Integrator {
            params,
            limits,
            output_names: rom.outputs.iter().map(|o| o.name.clone()).collect(),
            model,
            ws,
            solver,
            use_avx2: kernels::has_avx2(),
        })
    }

    /// Changes the time step (e.g. a new excitation frequency at fixed steps per period),
    /// keeping the ROM data. Checks the stability limit and rebuilds the Delassus matrix and
    /// the contact solver.
    ///
    // NOTE: a state carried across a change of dt keeps its half-step velocity v^{j-1/2},
    // which now stands at t^j - dt_new/2 instead of t^j - dt_old/2: an O(|dt_new - dt_old|)
    // perturbation once, negligible against the settling of a stepped-sine step. The boundary
    // needs nothing: g^start = Phi_g eta + g0 + G_res lambda does not depend on dt.
    pub fn set_time_step(&mut self, time_step: TimeStep) -> Result<(), SimError> {
        let mut params = self.params.clone();
        params.time_step = time_step;
        params.validate()?;
        let dt = resolve_dt(&time_step, self.limits.omega_ref);
        check_time_step(
            dt,
            &self.limits,
            params.coupling,
            params.enforce_closed_bound,
        )?;
        self.solver = self.model.set_dt(dt, &params.contact)?;
        self.params = params;
        Ok(())
    }

    /// Sets the clearance (initial normal gap of every pair, `g0 = [clearance, 0, 0]`), m,
    /// replacing the ROM's nominal one (e.g. a test plan's clearance). Nothing else depends on
    /// it; a carried state stays valid.
    pub fn set_clearance(&mut self, clearance: f64) -> Result<(), SimError> {
        if !clearance.is_finite() {
            return Err(SimError::InvalidParameter {
                field: "clearance (m)",
                value: clearance,
                expected: "a finite normal gap",
            });
        }
        self.model.clearance = clearance;
        Ok(())
    }

    /// The clearance in use, m.
    pub fn clearance(&self) -> f64 {
        self.model.clearance
    }

    /// Sets per-pair offsets of the initial normal gap, `g0_k = [clearance + offset_k, 0, 0]`
    /// (m, one per pair, finite), e.g. a tilted contact face; `None` removes them. The
    /// clearance stays separate ([`Integrator::set_clearance`] changes it under the offsets).
    /// Zero offsets give the same results bit for bit as none.
    pub fn set_gap_offsets(&mut self, offsets: Option<&[f64]>) -> Result<(), SimError> {
        if let Some(off) = offsets {
            if off.len() != self.model.n_pairs {
                return Err(SimError::StateDimension {
                    what: "gap offsets (one per contact pair)",
                    found: off.len(),
                    expected: self.model.n_pairs,
                });
            }
            if let Some(&value) = off.iter().find(|x| !x.is_finite()) {
                return Err(SimError::InvalidParameter {
                    field: "gap offset (m)",
                    value,
                    expected: "a finite normal gap offset",
                });
            }
        }
        self.model.gap_offset = offsets.map(<[f64]>::to_vec);
        self.model.gap_offset_range = offsets.map_or((0.0, 0.0), |off| {
            off.iter().fold((f64::INFINITY, 0.0f64), |(lo, big), &o| {
                (lo.min(o), big.max(o.abs()))
            })
        });
        Ok(())
    }

    /// The per-pair gap offsets in use, m (`None`: none).
    pub fn gap_offsets(&self) -> Option<&[f64]> {
        self.model.gap_offset.as_deref()
    }

    /// The contact solver (e.g. to capture the problem of the last step with
    /// [`ContactSolver::last_active_problem`]).
    pub fn contact_solver(&self) -> &ContactSolver {
        &self.solver
    }

    /// Forgets the contact solver's history ([`ContactSolver::forget_history`]): the next
    /// steps give the same bits as a new integrator's from the same state.
    pub fn forget_contact_history(&mut self) {
        self.solver.forget_history();
    }

    /// The time step, s.
    pub fn dt(&self) -> f64 {
        self.model.dt
    }

    /// The parameters in use.
    pub fn parameters(&self) -> &IntegratorParameters {
        &self.params
    }

    /// The ROM's stability limits.
    pub fn limits(&self) -> &StabilityLimits {
        &self.limits
    }

    /// Number of modes.
    pub fn n_modes(&self) -> usize {
        self.model.m
    }

    /// Number of contact pairs.
    pub fn n_pairs(&self) -> usize {
        self.model.n_pairs
    }

    /// Sensor names, in the order of the step outputs.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// A state at rest at time 0 for this ROM.
    pub fn state_at_rest(&self) -> State {
        State::at_rest(self.model.m, self.model.n_pairs, 0.0)
    }

    /// Runs `n_steps` steps from `state` under `excitation`, handing every step's output to
    /// `sink`. Step `i` starts at `t = state.time() + i dt` (no accumulated round-off within
    /// a run). Stops early, with the reason in the report, if the state becomes non-finite.
    pub fn run<S: StepSink>(
        &mut self,
        state: &mut State,
        excitation: &Excitation,
        n_steps: u64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        self.check_state(state)?;
        excitation.validate()?;
        if n_steps > 0 {
            let t0 = state.time;
            excitation.check_span(t0, t0 + (n_steps - 1) as f64 * self.model.dt)?;
        }
        #[cfg(target_arch = "x86_64")]
        if self.use_avx2 {
            // SAFETY: `use_avx2` is true only if the CPU reports AVX2 (`kernels::has_avx2`).
            return unsafe { self.run_avx2(state, excitation, n_steps, sink) };
        }
        self.run_steps(state, excitation, n_steps, sink)
    }

    /// One step with a given base acceleration `a_base` (m/s^2) at the state's time, e.g. fed
    /// sample by sample from a measurement. The state's time advances by `dt` (repeated
    /// single steps accumulate the round-off of the additions; [`Integrator::run`] does not).
    pub fn step<S: StepSink>(
        &mut self,
        state: &mut State,
        a_base: f64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        self.step_loaded(state, a_base, &[], sink)
    }

    /// [`Integrator::step`] with extra generalised forces on a few modes, `(mode index,
    /// force)` in N kg^-0.5 (the modal equation's right-hand side), evaluated by the caller at
    /// the state's displacement `eta^j`: `a .* v^{j+1/2} = b .* v^{j-1/2} - Omega^2 eta^j +
    /// f_load + Phi_g^T lambda - beta a_base`. For physics the ROM does not hold (e.g. a
    /// hysteretic joint in the clamp); an empty load is [`Integrator::step`].
    /// The load's work is not in the state's energy accounts (the caller owns that physics).
    pub fn step_loaded<S: StepSink>(
        &mut self,
        state: &mut State,
        a_base: f64,
        load: &[(usize, f64)],
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        if let Some(&(i, _)) = load.iter().find(|(i, _)| *i >= self.model.m) {
            return Err(SimError::StateDimension {
                what: "modal load index",
                found: i,
                expected: self.model.m,
            });
        }
        if !a_base.is_finite() {
            return Err(SimError::BaseAcceleration {
                value: a_base,
                time: state.time,
            });
        }
        self.check_state(state)?;
        let before = state.counters;
        let t = state.time;
        #[cfg(target_arch = "x86_64")]
        let finite = if self.use_avx2 {
            // SAFETY: `use_avx2` is true only if the CPU reports AVX2 (`kernels::has_avx2`).
            unsafe { self.step_avx2(state, a_base, load, t, sink)? }
        } else {
            self.step_impl(state, a_base, load, t, sink)?
        };
        #[cfg(not(target_arch = "x86_64"))]
        let finite = self.step_impl(state, a_base, load, t, sink)?;
        state.time = t + self.model.dt;
        Ok(RunReport {
            steps: 1,
            stop: (!finite).then_some(RunStop::NonFinite {
                step: state.step - 1,
                time: t,
            }),
            counters: state.counters.since(&before),
        })
    }

    /// Full gap vector `g = Phi_g eta + g0 + G_res lambda` (`3C`, m) at the contact time level
    /// of the last step of `state` (`t^j` of that step for the explicit coupling, its end for the
    /// end-of-step coupling). `out` must have `3C` entries.
    pub fn gaps(&self, state: &State, out: &mut [f64]) -> Result<(), SimError> {
        self.check_state(state)?;
        let md = &self.model;
        let (m, nb) = (md.m, 3 * md.n_pairs);
        if out.len() != nb {
            return Err(SimError::StateDimension {
                what: "gap output",
                found: out.len(),
                expected: nb,
            });
        }
        let eta: Vec<f64> = match md.coupling {
            Coupling::EndOfStep => state.eta.clone(),
            Coupling::Explicit => state
                .eta
                .iter()
                .zip(&state.eta_dot)
                .map(|(e, v)| e - md.dt * v)
                .collect(),
        };
        for (r, g) in out.iter_mut().enumerate() {
            let offset = match (r % 3, &md.gap_offset) {
                (0, None) => md.clearance,
                (0, Some(off)) => md.clearance + off[r / 3],
                _ => 0.0,
            };
            let gl = if state.closed.is_empty() {
                0.0
            } else {
                state.g_lambda[r]
            };
            *g = offset + dot(&md.phi_g[r * m..(r + 1) * m], &eta) + gl;
        }
        Ok(())
    }

    /// Use the portable build of the step even on AVX2 CPUs (for the test that both builds
    /// agree bit for bit).
    #[doc(hidden)]
    pub fn force_portable_kernels(&mut self) {
        self.use_avx2 = false;
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2<S: StepSink>(
        &mut self,
        state: &mut State,
        excitation: &Excitation,
        n_steps: u64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        self.run_steps(state, excitation, n_steps, sink)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn step_avx2<S: StepSink>(
        &mut self,
        state: &mut State,
        a_base: f64,
        load: &[(usize, f64)],
        t: f64,
        sink: &mut S,
    ) -> Result<bool, SimError> {
        self.step_impl(state, a_base, load, t, sink)
    }

    #[inline(always)]
    fn run_steps<S: StepSink>(
        &mut self,
        state: &mut State,
        excitation: &Excitation,
        n_steps: u64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        let before = state.counters;
        let t0 = state.time;
        let dt = self.model.dt;
        let mut stop = None;
        let mut done = 0;
        for i in 0..n_steps {
            let t = t0 + i as f64 * dt;
            let a = excitation.accel_at(t);
            let finite = self.step_impl(state, a, &[], t, sink)?;
            done += 1;
            state.time = t0 + (i + 1) as f64 * dt;
            if !finite {
                stop = Some(RunStop::NonFinite {
                    step: state.step - 1,
                    time: t,
                });
                break;
            }
        }
        Ok(RunReport {
            steps: done,
            stop,
            counters: state.counters.since(&before),
        })
    }
}
