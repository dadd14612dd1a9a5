//! What evolves during a run ([`State`]), the contact-solver bookkeeping ([`SolverCounters`])
//! and the summary of a run ([`RunReport`], [`RunStop`]).

use super::super::energy::EnergyAccounts;

/// Contact-solver bookkeeping, cumulative (in a [`State`]) or per run (in a [`RunReport`]).
/// Failures are counted here and reported per step in [`crate::sim::StepOutput::solve`].
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
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
///
/// It serialises (serde) for warm starts: the contact vectors, zero for every open pair, as
/// their non-zero entries only (`sparse`); every number round-trips exactly through JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct State {
    pub(super) eta: Vec<f64>,
    pub(super) eta_dot: Vec<f64>,
    #[serde(with = "sparse")]
    #[schemars(with = "sparse::Sparse")]
    pub(super) lambda: Vec<f64>,
    #[serde(with = "sparse")]
    #[schemars(with = "sparse::Sparse")]
    pub(super) g_lambda: Vec<f64>,
    pub(super) closed: Vec<usize>,
    pub(super) time: f64,
    pub(super) step: u64,
    pub(super) accounts: EnergyAccounts,
    pub(super) counters: SolverCounters,
    #[serde(skip)]
    #[schemars(skip)]
    pub(super) verified: Verified,
}

/// Whether the integrator itself produced a state by a finite step, so that its next step needs
/// only the size checks and not the scan for non-finite values (`Integrator::check_state`).
/// Not part of the state's value: every state compares equal in it, it is not serialised (a
/// state read back is checked in full), and anything else that changes the state clears it.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Verified(pub(super) bool);

impl PartialEq for Verified {
    fn eq(&self, _: &Verified) -> bool {
        true
    }
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
            verified: Verified(false),
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

    /// Adds to the modal velocities a random vector of norm `relative` times theirs, drawn
    /// from the seed `seed` (deterministic: the same seed gives the same bits); a state at
    /// rest is left unchanged. An ensemble member's initial state.
    ///
    // NOTE: the direction is uniform in the cube [-1, 1]^n, normalised: not isotropic, which
    // does not matter for a perturbation whose only job is to be small, reproducible and to
    // excite every mode.
    pub fn perturb_velocities(&mut self, seed: u64, relative: f64) {
        use rand::{Rng, SeedableRng};
        self.verified = Verified(false);
        let norm = self.eta_dot.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 || !norm.is_finite() {
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let d: Vec<f64> = (0..self.eta_dot.len())
            .map(|_| rng.gen_range(-1.0..=1.0))
            .collect();
        let dn = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        if dn == 0.0 {
            return;
        }
        let scale = relative * norm / dn;
        for (v, d) in self.eta_dot.iter_mut().zip(d) {
            *v += scale * d;
        }
    }

    /// Checks that the state fits a ROM of `n_modes` modes and `n_pairs` contact pairs and is
    /// finite (a state read back from a log, before it replaces a run's).
    pub fn check(&self, n_modes: usize, n_pairs: usize) -> Result<(), StateMismatch> {
        let sizes = [
            ("eta", self.eta.len(), n_modes),
            ("eta_dot", self.eta_dot.len(), n_modes),
            ("lambda", self.lambda.len(), 3 * n_pairs),
            ("g_lambda", self.g_lambda.len(), 3 * n_pairs),
        ];
        for (field, got, expected) in sizes {
            if got != expected {
                return Err(StateMismatch::Size {
                    field,
                    got,
                    expected,
                });
            }
        }
        let vectors = [
            ("eta", &self.eta),
            ("eta_dot", &self.eta_dot),
            ("lambda", &self.lambda),
            ("g_lambda", &self.g_lambda),
        ];
        for (field, v) in vectors {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(StateMismatch::NonFinite { field, index: i });
            }
        }
        if !self.time.is_finite() {
            return Err(StateMismatch::NonFinite {
                field: "time",
                index: 0,
            });
        }
        let ascending = self.closed.windows(2).all(|w| w[0] < w[1]);
        if !ascending || self.closed.last().is_some_and(|&p| p >= n_pairs) {
            return Err(StateMismatch::ClosedPairs { n_pairs });
        }
        Ok(())
    }
}

/// Why a state does not fit a ROM ([`State::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StateMismatch {
    /// A vector has the wrong length.
    #[error("state field {field} has {got} entries, the ROM needs {expected}")]
    Size {
        /// Field name.
        field: &'static str,
        /// Its length.
        got: usize,
        /// The ROM's.
        expected: usize,
    },
    /// A value is NaN or infinite.
    #[error("state field {field} is not finite at index {index}")]
    NonFinite {
        /// Field name.
        field: &'static str,
        /// Index of the first bad value.
        index: usize,
    },
    /// The closed pairs are not ascending pair indices of the ROM.
    #[error("state field closed is not a list of ascending pair indices below {n_pairs}")]
    ClosedPairs {
        /// The ROM's pair count.
        n_pairs: usize,
    },
}

/// A vector stored by its non-zero entries: `{"len": n, "index": [...], "value": [...]}`.
mod sparse {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// A vector by its length and non-zero entries.
    #[derive(Serialize, Deserialize, schemars::JsonSchema)]
    pub struct Sparse {
        /// Length.
        len: usize,
        /// Indices of the non-zero entries, ascending.
        index: Vec<usize>,
        /// Their values.
        value: Vec<f64>,
    }

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        // NOTE: -0.0 is kept (it is not == 0.0 bitwise and may matter to a bit-for-bit rerun).
        let (index, value) = v
            .iter()
            .enumerate()
            .filter(|(_, x)| x.to_bits() != 0)
            .map(|(i, &x)| (i, x))
            .unzip();
        Sparse {
            len: v.len(),
            index,
            value,
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let sp = Sparse::deserialize(d)?;
        if sp.index.len() != sp.value.len() {
            return Err(serde::de::Error::custom(format!(
                "sparse vector: {} indices but {} values",
                sp.index.len(),
                sp.value.len()
            )));
        }
        if sp.len > 1 << 24 {
            return Err(serde::de::Error::custom(format!(
                "sparse vector: length {} beyond the limit {}",
                sp.len,
                1 << 24
            )));
        }
        let mut v = vec![0.0; sp.len];
        for (&i, &x) in sp.index.iter().zip(&sp.value) {
            let slot = v.get_mut(i).ok_or_else(|| {
                serde::de::Error::custom(format!(
                    "sparse vector: index {i} beyond length {}",
                    sp.len
                ))
            })?;
            *slot = x;
        }
        Ok(v)
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
