//! Time integration of the ROM: the leapfrog integrator with an implicit contact boundary
//! ([`integrator`]), base excitation ([`excitation`]), energy terms ([`energy`]), per-step
//! outputs and sinks ([`output`]), the driven ROM (base acceleration in, named sensor outputs
//! out: [`driven`]), the physics effects that act during the integration ([`effects`]), the virtual stepped sine ([`stepped`]), the convergence studies
//! ([`convergence`]) and the error type ([`error`]).
//!
//! Numerics only: no I/O, no clock, no threads inside a run; the hot loop does not allocate.
//! A run is deterministic: the same ROM, parameters, state and excitation give bit-identical
//! outputs (also between the portable and the AVX2 build of the step).

// NOTE: validation uses negated comparisons such as `!(dt < limit)` on purpose: they reject
// NaN together with out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod convergence;
pub mod driven;
pub mod effects;
pub mod energy;
pub mod error;
pub mod excitation;
pub mod integrator;
pub mod output;
pub mod stepped;

pub use driven::{DrivenError, DrivenRom, MissingOutput, SensorSink, SensorStep};
pub use energy::{Energy, EnergyAccounts};
pub use error::SimError;
pub use excitation::{continuous_phase, Excitation};
pub use integrator::{
    stability_limits, Coupling, Integrator, IntegratorParameters, RunReport, RunStop,
    SolverCounters, StabilityLimits, State, StateMismatch, TimeStep,
};
pub use output::{ContactSummary, NullSink, StepOutput, StepSink, TraceRecorder};
