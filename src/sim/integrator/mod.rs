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
//! where the gap is imposed. See `step.rs` for the equations of both.
//!
//! One [`Integrator`] holds everything that depends on the ROM and `dt` (precomputed matrices,
//! the contact solver, workspace); a [`State`] holds what evolves and can be carried from one
//! run to the next (stepped sine: a new frequency, the same state). Runs are deterministic:
//! the same integrator parameters, ROM, state and excitation give bit-identical outputs.

mod kernels;
pub mod limits;
mod predict;
mod step;

pub use limits::{stability_limits, StabilityLimits};

use crate::contact::{ContactParameters, ContactSolver, PairState};
use crate::rom::Rom;

use super::energy::EnergyAccounts;
use super::error::SimError;
use super::excitation::Excitation;
use super::output::StepSink;
use kernels::dot;
use predict::Predictor;

/// Where the contact condition of a step is imposed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Coupling {
    /// The reference's coupling: the gap `g^j = Phi_g eta^j + g0 + G_res lambda^j` at the start
    /// of the modal step, `W = G_res / dt`; the modal step then sees the closed pairs' stiffness
    /// explicitly and is stable only below the closed bound
    /// ([`StabilityLimits::dt_max_closed`]).
    Explicit,
    /// The contact is imposed at the end of the step with the modal response inside the step
    /// included, `W' = (G_res + dt Phi_g diag(1/a) Phi_g^T) / dt`; only the open bound applies.
    #[default]
    EndOfStep,
}

/// How the fixed time step is given.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TimeStep {
    /// The step itself, s.
    Dt {
        /// Time step, s (> 0).
        dt: f64,
    },
    /// Steps per period of an excitation at circular frequency `omega`: `dt = 2 pi / (omega steps)`.
    StepsPerPeriod {
        /// Steps per excitation period (> 0).
        steps: f64,
        /// Excitation circular frequency, rad/s (> 0).
        omega: f64,
    },
    /// Steps per period of the ROM's reference (1FU) mode.
    StepsPerReferencePeriod {
        /// Steps per 1FU period (> 0).
        steps: f64,
    },
}

/// Parameters of the integrator. Defaults: 1000 steps per 1FU period (the reference's
/// resolution), end-of-step coupling, the contact solver's defaults with Gauss-Seidel sweeps
/// (on the default rig's impacts about 3x faster than the reference's Jacobi sweeps, which also
/// hit the sweep limit on long closed phases; see BENCHMARKS.md), one step of extrapolation in
/// the open prediction.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntegratorParameters {
    /// The fixed time step. Default: 1000 steps per 1FU period.
    pub time_step: TimeStep,
    /// Contact coupling. Default: [`Coupling::EndOfStep`].
    pub coupling: Coupling,
    /// Contact solver parameters (default: Gauss-Seidel sweeps). Their `open_gap_margin` is not used: the integrator's own
    /// open prediction chooses the pairs of each solve (see `open_margin_steps`).
    pub contact: ContactParameters,
    /// Open-prediction margin kappa, in steps (>= 0). A pair is handed to the contact solver if
    /// its free normal gap at the contact time level, or that gap extrapolated kappa further
    /// steps at the step's closing rate, is closed. Larger values hand more pairs to the solver
    /// (which leaves the ones that stay open at zero force); 0 trusts the prediction exactly.
    /// Default 1.0.
    pub open_margin_steps: f64,
    /// Explicit coupling only: reject a `dt` beyond the all-pairs-closed stability bound.
    /// Default true; switch off only to study the instability.
    pub enforce_closed_bound: bool,
    /// Compute the free normal gap of every pair exactly each step (one pass over the normal
    /// rows of Phi_g instead of the bound-based prediction) and report the normal gaps in the
    /// step output. Same trajectory bit for bit, slower. Default false.
    pub report_gaps: bool,
}

impl Default for IntegratorParameters {
    fn default() -> Self {
        IntegratorParameters {
            time_step: TimeStep::StepsPerReferencePeriod { steps: 1000.0 },
            coupling: Coupling::EndOfStep,
            contact: ContactParameters {
                method: crate::contact::SweepMethod::GaussSeidel,
                ..ContactParameters::default()
            },
            open_margin_steps: 1.0,
            enforce_closed_bound: true,
            report_gaps: false,
        }
    }
}

impl IntegratorParameters {
    /// Checks the ranges documented on the fields (the time step against the ROM is checked
    /// by [`Integrator::new`]).
    pub fn validate(&self) -> Result<(), SimError> {
        let positive = |field, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SimError::InvalidParameter {
                    field,
                    value,
                    expected: "a finite number > 0",
                })
            }
        };
        match self.time_step {
            TimeStep::Dt { dt } => positive("time_step.dt (s)", dt)?,
            TimeStep::StepsPerPeriod { steps, omega } => {
                positive("time_step.steps (per excitation period)", steps)?;
                positive("time_step.omega (rad/s)", omega)?;
            }
            TimeStep::StepsPerReferencePeriod { steps } => {
                positive("time_step.steps (per 1FU period)", steps)?
            }
        }
        if !(self.open_margin_steps.is_finite() && self.open_margin_steps >= 0.0) {
            return Err(SimError::InvalidParameter {
                field: "open_margin_steps (steps)",
                value: self.open_margin_steps,
                expected: "a finite number >= 0",
            });
        }
        self.contact.validate()?;
        Ok(())
    }
}

/// Contact-solver bookkeeping, cumulative (in a [`State`]) or per run (in a [`RunReport`]).
/// Failures are counted here and reported per step in [`crate::sim::StepOutput::solve`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverCounters {
    /// Steps with a contact solve (at least one candidate pair).
    pub solves: u64,
    /// Steps with at least one closed pair.
    pub closed_steps: u64,
    /// Total sweeps of the contact solver.
    pub iterations: u64,
    /// Solves that stopped at the sweep limit (last iterate used).
    pub max_iterations: u64,
    /// Solves that diverged (forces set to zero for that step).
    pub diverged: u64,
    /// Largest relative natural-map residual of a solve, -.
    pub worst_relative_residual: f64,
}

impl SolverCounters {
    /// The counts since `before` (an earlier copy of the same cumulative counters); the worst
    /// residual stays the cumulative one.
    pub(crate) fn since(&self, before: &SolverCounters) -> SolverCounters {
        SolverCounters {
            solves: self.solves - before.solves,
            closed_steps: self.closed_steps - before.closed_steps,
            iterations: self.iterations - before.iterations,
            max_iterations: self.max_iterations - before.max_iterations,
            diverged: self.diverged - before.diverged,
            worst_relative_residual: self.worst_relative_residual,
        }
    }
}

/// What evolves during a run. Created at rest or from modal initial conditions; afterwards
/// changed only by the integrator, so it can be carried across runs and across integrators of
/// the same ROM (e.g. when the excitation frequency and with it `dt` change).
///
/// At step count `j` it holds `eta^j`, the modal velocity of the last step `v^{j-1/2}`, the
/// contact forces of the last step and their boundary displacement `G_res lambda`, the time
/// `t^j`, and the cumulative energy accounts and solver counters.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    eta: Vec<f64>,
    eta_dot: Vec<f64>,
    lambda: Vec<f64>,
    g_lambda: Vec<f64>,
    closed: Vec<usize>,
    time: f64,
    step: u64,
    accounts: EnergyAccounts,
    counters: SolverCounters,
}

impl State {
    /// At rest at time `time` (s): zero modal displacements and velocities, no contact force.
    pub fn at_rest(n_modes: usize, n_pairs: usize, time: f64) -> State {
        State::from_modal(vec![0.0; n_modes], vec![0.0; n_modes], n_pairs, time)
    }

    /// Modal displacements `eta` (m kg^0.5) and velocities `eta_dot` (the half-step velocity
    /// `v^{-1/2}`, m/s kg^0.5) at time `time` (s), no contact force. Sizes and finiteness are
    /// checked when the state is first used.
    pub fn from_modal(eta: Vec<f64>, eta_dot: Vec<f64>, n_pairs: usize, time: f64) -> State {
        State {
            eta,
            eta_dot,
            lambda: vec![0.0; 3 * n_pairs],
            g_lambda: vec![0.0; 3 * n_pairs],
            closed: Vec::with_capacity(n_pairs),
            time,
            step: 0,
            accounts: EnergyAccounts::default(),
            counters: SolverCounters::default(),
        }
    }

    /// Modal displacements `eta^j`, m kg^0.5.
    pub fn eta(&self) -> &[f64] {
        &self.eta
    }

    /// Modal velocities of the last step `v^{j-1/2}`, m/s kg^0.5.
    pub fn eta_dot(&self) -> &[f64] {
        &self.eta_dot
    }

    /// Contact forces of the last step, `3C`, N.
    pub fn lambda(&self) -> &[f64] {
        &self.lambda
    }

    /// Pairs with a normal force in the last step, ascending.
    pub fn closed_pairs(&self) -> &[usize] {
        &self.closed
    }

    /// Time `t^j` of the next step's start, s.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Steps done since the state was created.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// Cumulative work and losses, J.
    pub fn accounts(&self) -> EnergyAccounts {
        self.accounts
    }

    /// Cumulative contact-solver counters.
    pub fn counters(&self) -> SolverCounters {
        self.counters
    }
}

/// Why a run ended before its last step.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RunStop {
    /// The state became NaN or infinite in this step (the state is left as it is).
    NonFinite {
        /// Step index.
        step: u64,
        /// Start time of the step, s.
        time: f64,
    },
}

/// Summary of a run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunReport {
    /// Steps done.
    pub steps: u64,
    /// Why the run stopped early, if it did.
    pub stop: Option<RunStop>,
    /// Contact-solver counters of this run (the worst residual is the state's cumulative one).
    pub counters: SolverCounters,
}

/// Everything that depends on the ROM and the time step only.
#[derive(Clone, Debug)]
pub(crate) struct Model {
    pub(crate) m: usize,
    pub(crate) n_pairs: usize,
    pub(crate) n_out: usize,
    pub(crate) dt: f64,
    pub(crate) coupling: Coupling,
    pub(crate) kappa: f64,
    pub(crate) report_gaps: bool,
    pub(crate) clearance: f64,
    /// Per-pair normal gap offsets added to the clearance (`C`), m; `None`: none (the
    /// default, the scalar code path).
    pub(crate) gap_offset: Option<Vec<f64>>,
    /// Omega^2, D = 2 zeta w, beta, per mode.
    pub(crate) omega2: Vec<f64>,
    pub(crate) damping: Vec<f64>,
    pub(crate) beta: Vec<f64>,
    /// `1/a` and `b` of the damped leapfrog step (depend on dt).
    pub(crate) inv_a: Vec<f64>,
    pub(crate) b: Vec<f64>,
    /// Phi_g row-major `3C x m`.
    pub(crate) phi_g: Vec<f64>,
    /// G_res row-major `3C x 3C`, exactly symmetric.
    pub(crate) g_res: Vec<f64>,
    pub(crate) predictor: Predictor,
    /// Sensor rows: `c_eta` row-major `n_out x m`, `c_lambda` row-major `n_out x 3C`.
    pub(crate) c_eta: Vec<f64>,
    pub(crate) c_lambda: Vec<f64>,
    pub(crate) friction: f64,
}

/// Buffers reused by every step (sized once; the hot loop does not allocate).
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    pub(crate) vf: Vec<f64>,
    pub(crate) x_p: Vec<f64>,
    pub(crate) x_q: Vec<f64>,
    pub(crate) v_c: Vec<f64>,
    pub(crate) f_c: Vec<f64>,
    pub(crate) v_new: Vec<f64>,
    pub(crate) eta_next: Vec<f64>,
    pub(crate) cand: Vec<usize>,
    pub(crate) p_cand: Vec<f64>,
    pub(crate) closed_new: Vec<usize>,
    pub(crate) c_full: Vec<f64>,
    pub(crate) mask: Vec<f64>,
    pub(crate) lambda: Vec<f64>,
    pub(crate) lambda_dirty: bool,
    pub(crate) gamma: Vec<f64>,
    pub(crate) g_lambda_new: Vec<f64>,
    pub(crate) gap_n: Vec<f64>,
    pub(crate) pair_states: Vec<PairState>,
    pub(crate) states_dirty: bool,
    pub(crate) disp: Vec<f64>,
    pub(crate) vel: Vec<f64>,
}

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

        let nb = 3 * n;
        let phi_g: Vec<f64> = (0..nb)
            .flat_map(|r| (0..m).map(move |i| (r, i)))
            .map(|(r, i)| rom.phi_g[(r, i)])
            .collect();
        let g_res: Vec<f64> = (0..nb)
            .flat_map(|r| (0..nb).map(move |s| (r, s)))
            .map(|(r, s)| 0.5 * (rom.g_res[(r, s)] + rom.g_res[(s, r)]))
            .collect();
        let phi_n: Vec<f64> = (0..n)
            .flat_map(|k| phi_g[3 * k * m..(3 * k + 1) * m].to_vec())
            .collect();
        let predictor = Predictor::new(phi_n, &rom.omega, n);
        let n_out = rom.outputs.len();
        let c_eta: Vec<f64> = rom
            .outputs
            .iter()
            .flat_map(|o| o.c_eta.iter().copied())
            .collect();
        let c_lambda: Vec<f64> = rom
            .outputs
            .iter()
            .flat_map(|o| o.c_lambda.iter().copied())
            .collect();
        let damping: Vec<f64> = rom
            .omega
            .iter()
            .zip(&rom.damping_ratio)
            .map(|(w, z)| 2.0 * z * w)
            .collect();

        let mut model = Model {
            m,
            n_pairs: n,
            n_out,
            dt,
            coupling: params.coupling,
            kappa: params.open_margin_steps,
            report_gaps: params.report_gaps,
            clearance: rom.clearance,
            gap_offset: None,
            omega2: rom.omega.iter().map(|w| w * w).collect(),
            damping,
            beta: rom.beta.clone(),
            inv_a: vec![0.0; m],
            b: vec![0.0; m],
            phi_g,
            g_res,
            predictor,
            c_eta,
            c_lambda,
            friction: rom.friction,
        };
        let solver = model.set_dt(dt, &params.contact)?;
        let ws = Workspace {
            vf: vec![0.0; m],
            x_p: vec![0.0; m],
            x_q: vec![0.0; m],
            v_c: vec![0.0; m],
            f_c: vec![0.0; m],
            v_new: vec![0.0; m],
            eta_next: vec![0.0; m],
            cand: Vec::with_capacity(n),
            p_cand: Vec::with_capacity(n),
            closed_new: Vec::with_capacity(n),
            c_full: vec![0.0; nb],
            mask: vec![1.0; n],
            lambda: vec![0.0; nb],
            lambda_dirty: false,
            gamma: vec![0.0; nb],
            g_lambda_new: vec![0.0; nb],
            gap_n: vec![0.0; n],
            pair_states: vec![PairState::Open; n],
            states_dirty: false,
            disp: vec![0.0; n_out],
            vel: vec![0.0; n_out],
        };
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

    /// Checks that a state belongs to this ROM (sizes) and is finite.
    pub fn check_state(&self, state: &State) -> Result<(), SimError> {
        let (m, nb) = (self.model.m, 3 * self.model.n_pairs);
        for (what, v, expected) in [
            ("eta", &state.eta, m),
            ("eta_dot", &state.eta_dot, m),
            ("lambda", &state.lambda, nb),
            ("g_lambda", &state.g_lambda, nb),
        ] {
            if v.len() != expected {
                return Err(SimError::StateDimension {
                    what,
                    found: v.len(),
                    expected,
                });
            }
            if let Some(index) = v.iter().position(|x| !x.is_finite()) {
                return Err(SimError::StateValue {
                    what,
                    index,
                    value: v[index],
                });
            }
        }
        if let Some(&k) = state.closed.iter().find(|&&k| k >= self.model.n_pairs) {
            return Err(SimError::StateDimension {
                what: "closed pair index",
                found: k,
                expected: self.model.n_pairs,
            });
        }
        if !state.time.is_finite() {
            return Err(SimError::StateValue {
                what: "time",
                index: 0,
                value: state.time,
            });
        }
        Ok(())
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
    /// hysteretic joint, see `rig::sim::variants`); an empty load is [`Integrator::step`].
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

impl Model {
    /// Sets the time step: the damped leapfrog coefficients and the Delassus matrix, and
    /// returns a contact solver for it.
    fn set_dt(&mut self, dt: f64, contact: &ContactParameters) -> Result<ContactSolver, SimError> {
        let (m, nb) = (self.m, 3 * self.n_pairs);
        self.dt = dt;
        for i in 0..m {
            let a = 1.0 / dt + 0.5 * self.damping[i];
            self.inv_a[i] = 1.0 / a;
            self.b[i] = 1.0 / dt - 0.5 * self.damping[i];
        }
        // Delassus matrix, row-major 3C x 3C. Explicit: W = G_res / dt. End of step:
        // W' = G_res / dt + Phi_g diag(1/a) Phi_g^T, built from the upper triangle and mirrored
        // so that it is exactly symmetric.
        let mut w = vec![0.0; nb * nb];
        let mut scaled = vec![0.0; m];
        for r in 0..nb {
            let row_r = &self.phi_g[r * m..(r + 1) * m];
            for ((s, &p), &ia) in scaled.iter_mut().zip(row_r).zip(&self.inv_a) {
                *s = p * ia;
            }
            for s in r..nb {
                let mut v = self.g_res[r * nb + s] / dt;
                if self.coupling == Coupling::EndOfStep {
                    v += dot(&scaled, &self.phi_g[s * m..(s + 1) * m]);
                }
                w[r * nb + s] = v;
                w[s * nb + r] = v;
            }
        }
        let mut params = contact.clone();
        params.open_gap_margin = 0.0;
        let mu = vec![self.friction; self.n_pairs];
        Ok(ContactSolver::new(&w, &mu, params)?)
    }
}

/// The time step for a [`TimeStep`] (already validated), s.
fn resolve_dt(time_step: &TimeStep, omega_ref: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    match *time_step {
        TimeStep::Dt { dt } => dt,
        TimeStep::StepsPerPeriod { steps, omega } => two_pi / (omega * steps),
        TimeStep::StepsPerReferencePeriod { steps } => two_pi / (omega_ref * steps),
    }
}

/// Rejects a step at or beyond the limit the coupling relies on.
fn check_time_step(
    dt: f64,
    limits: &StabilityLimits,
    coupling: Coupling,
    enforce_closed: bool,
) -> Result<(), SimError> {
    let steps_given = 2.0 * std::f64::consts::PI / (limits.omega_ref * dt);
    if !(dt < limits.dt_max_open()) {
        return Err(SimError::TimeStepTooLarge {
            dt,
            dt_max: limits.dt_max_open(),
            omega_max: limits.omega_open,
            steps_given,
            steps_needed: limits.steps_per_period_open(),
            limit: "with all pairs open",
            hint: "; use a smaller dt (more steps per period)",
        });
    }
    if coupling == Coupling::Explicit && enforce_closed && !(dt < limits.dt_max_closed()) {
        return Err(SimError::TimeStepTooLarge {
            dt,
            dt_max: limits.dt_max_closed(),
            omega_max: limits.omega_closed,
            steps_given,
            steps_needed: limits.steps_per_period_closed(),
            limit: "with all pairs closed (Explicit coupling)",
            hint: "; use Coupling::EndOfStep, which needs only the open limit, or a smaller dt",
        });
    }
    Ok(())
}

/// Checks the ROM's sizes and values; returns (modes, pairs).
fn check_rom(rom: &Rom) -> Result<(usize, usize), SimError> {
    let m = rom.omega.len();
    let n = rom.pair_area.len();
    let nb = 3 * n;
    if m == 0 {
        return Err(SimError::RomDimension {
            what: "omega (modes)".into(),
            found: 0,
            expected: 1,
        });
    }
    let dim = |what: String, found: usize, expected: usize| {
        if found == expected {
            Ok(())
        } else {
            Err(SimError::RomDimension {
                what,
                found,
                expected,
            })
        }
    };
    dim("damping_ratio".into(), rom.damping_ratio.len(), m)?;
    dim("beta".into(), rom.beta.len(), m)?;
    dim(
        "phi_g rows (3 x pairs; pairs = pair_area.len())".into(),
        rom.phi_g.nrows(),
        nb,
    )?;
    dim("phi_g columns (modes)".into(), rom.phi_g.ncols(), m)?;
    dim("g_res rows (3 x pairs)".into(), rom.g_res.nrows(), nb)?;
    dim("g_res columns (3 x pairs)".into(), rom.g_res.ncols(), nb)?;
    if rom.meta.reference_mode >= m {
        return Err(SimError::RomValue {
            what: "meta.reference_mode",
            index: 0,
            value: rom.meta.reference_mode as f64,
            expected: "the index of the 1FU mode, below the number of modes",
        });
    }
    for (o, out) in rom.outputs.iter().enumerate() {
        dim(
            format!("outputs[{o}] ({}).c_eta", out.name),
            out.c_eta.len(),
            m,
        )?;
        dim(
            format!("outputs[{o}] ({}).c_lambda", out.name),
            out.c_lambda.len(),
            nb,
        )?;
        check_values("outputs.c_eta", &out.c_eta, |_| true, "finite")?;
        check_values("outputs.c_lambda", &out.c_lambda, |_| true, "finite")?;
    }
    check_values(
        "omega",
        &rom.omega,
        |w| w > 0.0,
        "a finite circular frequency > 0 (rad/s)",
    )?;
    check_values(
        "damping_ratio",
        &rom.damping_ratio,
        |z| z >= 0.0,
        "a finite damping ratio >= 0",
    )?;
    check_values("beta", &rom.beta, |_| true, "finite")?;
    let phi: Vec<f64> = (0..nb)
        .flat_map(|r| (0..m).map(move |i| (r, i)))
        .map(|(r, i)| rom.phi_g[(r, i)])
        .collect();
    check_values("phi_g", &phi, |_| true, "finite")?;
    let g: Vec<f64> = (0..nb)
        .flat_map(|r| (0..nb).map(move |s| (r, s)))
        .map(|(r, s)| rom.g_res[(r, s)])
        .collect();
    check_values("g_res", &g, |_| true, "finite")?;
    let scale = g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    for r in 0..nb {
        for s in r + 1..nb {
            let (u, l) = (g[r * nb + s], g[s * nb + r]);
            // NOTE: round-off from building G_res is symmetrised away; a relative asymmetry
            // above 1e-8 means a wrong matrix, not round-off.
            if (u - l).abs() > 1e-8 * scale {
                return Err(SimError::RomFlexibility {
                    detail: format!(
                        "G_res[{r},{s}] = {u:e} but G_res[{s},{r}] = {l:e} (not symmetric)"
                    ),
                });
            }
        }
    }
    check_values(
        "clearance",
        &[rom.clearance],
        |_| true,
        "a finite clearance (m)",
    )?;
    check_values(
        "friction",
        &[rom.friction],
        |mu| mu >= 0.0,
        "a finite friction coefficient >= 0",
    )?;
    Ok((m, n))
}

fn check_values(
    what: &'static str,
    v: &[f64],
    ok: impl Fn(f64) -> bool,
    expected: &'static str,
) -> Result<(), SimError> {
    match v.iter().position(|&x| !(x.is_finite() && ok(x))) {
        Some(index) => Err(SimError::RomValue {
            what,
            index,
            value: v[index],
            expected,
        }),
        None => Ok(()),
    }
}
