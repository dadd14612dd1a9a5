//! What the integrator hands out after every step ([`StepOutput`]), the sink trait that
//! receives it ([`StepSink`]) and a preallocated recorder ([`TraceRecorder`]).
//!
//! Step outputs borrow the integrator's buffers, so the hot loop never allocates; a sink copies
//! what it needs.

use crate::contact::{PairState, SolveStats};

use super::energy::Energy;

/// Contact activity of one step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactSummary {
    /// Pairs handed to the contact solver (predicted to close, or closed in the previous step).
    pub candidates: usize,
    /// Pairs without normal force.
    pub open: usize,
    /// Pairs closed and sticking.
    pub stick: usize,
    /// Pairs closed and slipping.
    pub slip: usize,
    /// `stick + slip > 0`.
    pub any_closed: bool,
    /// Integrated normal contact force `sum_k lambda_n,k`, N.
    pub normal_force: f64,
    /// Integrated tangential contact force `sum_k |lambda_t,k|`, N.
    pub tangential_force: f64,
}

/// Everything one step produces. Borrowed slices point into the integrator's workspace and are
/// valid only during [`StepSink::record`].
///
/// Time levels (see [`crate::sim::Coupling`]): the contact forces belong to the gap at `time`,
/// the *contact time level* of the step (`t^j` for the explicit coupling, `t^{j+1}` for the
/// end-of-step coupling, with `t^j` the time at the start of the step). Sensor displacements
/// are given at `time`; sensor velocities are the difference of consecutive sensor
/// displacements over one step, i.e. the velocity at the half step `velocity_time = time - dt/2`
/// (consistent with the displacements: summing them reproduces the displacement history).
#[derive(Clone, Copy, Debug)]
pub struct StepOutput<'a> {
    /// Index of the step (0 for the first step of a fresh state), counted across runs.
    pub step: u64,
    /// Contact time level of the step, s.
    pub time: f64,
    /// Time of the sensor velocities, `time - dt/2`, s.
    pub velocity_time: f64,
    /// Base acceleration used by the step (evaluated at its start time), m/s^2.
    pub base_acceleration: f64,
    /// Sensor displacements relative to the base, one per ROM output, m.
    pub displacement: &'a [f64],
    /// Sensor velocities relative to the base at `velocity_time`, one per ROM output, m/s.
    pub velocity: &'a [f64],
    /// Contact forces of the step, `3 C` (pair-major n, t1, t2), N.
    pub lambda: &'a [f64],
    /// State of every pair.
    pub pair_states: &'a [PairState],
    /// Normal gaps of all pairs at `time`, m, when
    /// [`crate::sim::IntegratorParameters::report_gaps`] is set; `None` otherwise.
    pub gap_n: Option<&'a [f64]>,
    /// Counts and integrated forces.
    pub contact: ContactSummary,
    /// Statistics of the contact solve, `None` when no pair was a candidate (no solve).
    pub solve: Option<SolveStats>,
    /// Energy terms after the step.
    pub energy: Energy,
}

/// Receives the output of every step.
pub trait StepSink {
    /// Called once per step, in order.
    fn record(&mut self, out: &StepOutput<'_>);
}

impl<F: FnMut(&StepOutput<'_>)> StepSink for F {
    fn record(&mut self, out: &StepOutput<'_>) {
        self(out)
    }
}

/// A sink that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct NullSink;

impl StepSink for NullSink {
    fn record(&mut self, _out: &StepOutput<'_>) {}
}

/// Records every `decimation`-th step into buffers reserved up front (no allocation while
/// recording within the capacity): times, sensor displacements and velocities (row per
/// recorded step), contact activity, integrated forces and energies.
#[derive(Clone, Debug, Default)]
pub struct TraceRecorder {
    n_outputs: usize,
    decimation: u64,
    /// Contact time level of each recorded step, s.
    pub time: Vec<f64>,
    /// Sensor displacements, `n_outputs` per recorded step (row-major), m.
    pub displacement: Vec<f64>,
    /// Sensor velocities, `n_outputs` per recorded step (row-major), m/s.
    pub velocity: Vec<f64>,
    /// Whether any pair was closed.
    pub any_closed: Vec<bool>,
    /// Integrated normal contact force, N.
    pub normal_force: Vec<f64>,
    /// Integrated tangential contact force, N.
    pub tangential_force: Vec<f64>,
    /// Energies.
    pub energy: Vec<Energy>,
    /// Contact solver sweeps of each recorded step (0 without a solve).
    pub iterations: Vec<u32>,
}

impl TraceRecorder {
    /// A recorder for `n_outputs` sensors keeping every `decimation`-th step (>= 1; 0 is taken
    /// as 1), with room for `capacity` recorded steps.
    pub fn new(n_outputs: usize, decimation: u64, capacity: usize) -> TraceRecorder {
        TraceRecorder {
            n_outputs,
            decimation: decimation.max(1),
            time: Vec::with_capacity(capacity),
            displacement: Vec::with_capacity(capacity * n_outputs),
            velocity: Vec::with_capacity(capacity * n_outputs),
            any_closed: Vec::with_capacity(capacity),
            normal_force: Vec::with_capacity(capacity),
            tangential_force: Vec::with_capacity(capacity),
            energy: Vec::with_capacity(capacity),
            iterations: Vec::with_capacity(capacity),
        }
    }

    /// Number of recorded steps.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    /// Whether nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// Displacement history of sensor `o`, m.
    pub fn displacement_of(&self, o: usize) -> Vec<f64> {
        self.displacement
            .iter()
            .skip(o)
            .step_by(self.n_outputs.max(1))
            .copied()
            .collect()
    }

    /// Velocity history of sensor `o`, m/s.
    pub fn velocity_of(&self, o: usize) -> Vec<f64> {
        self.velocity
            .iter()
            .skip(o)
            .step_by(self.n_outputs.max(1))
            .copied()
            .collect()
    }
}

impl StepSink for TraceRecorder {
    fn record(&mut self, out: &StepOutput<'_>) {
        if out.step % self.decimation != 0 {
            return;
        }
        self.time.push(out.time);
        self.displacement.extend_from_slice(out.displacement);
        self.velocity.extend_from_slice(out.velocity);
        self.any_closed.push(out.contact.any_closed);
        self.normal_force.push(out.contact.normal_force);
        self.tangential_force.push(out.contact.tangential_force);
        self.energy.push(out.energy);
        self.iterations.push(
            out.solve
                .map(|s| u32::try_from(s.iterations).unwrap_or(u32::MAX))
                .unwrap_or(0),
        );
    }
}
