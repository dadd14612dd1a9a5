//! What evolves during a run ([`State`]), the contact-solver bookkeeping ([`SolverCounters`])
//! and the summary of a run ([`RunReport`], [`RunStop`]).

use super::super::energy::EnergyAccounts;

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
    /// Solves in which the semismooth Newton method ran ([`crate::contact::SolvePath`]; the
    /// rest swept only). Left out of serialised counters when zero, as are the two below.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub newton_solves: u64,
    /// Total Newton iterations (one dense linear solve each).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub newton_iterations: u64,
    /// Newton attempts that did not converge and were finished by the sweeps.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub newton_fallbacks: u64,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
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
            newton_solves: self.newton_solves - before.newton_solves,
            newton_iterations: self.newton_iterations - before.newton_iterations,
            newton_fallbacks: self.newton_fallbacks - before.newton_fallbacks,
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
    pub(super) eta: Vec<f64>,
    pub(super) eta_dot: Vec<f64>,
    pub(super) lambda: Vec<f64>,
    pub(super) g_lambda: Vec<f64>,
    pub(super) closed: Vec<usize>,
    pub(super) time: f64,
    pub(super) step: u64,
    pub(super) accounts: EnergyAccounts,
    pub(super) counters: SolverCounters,
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
