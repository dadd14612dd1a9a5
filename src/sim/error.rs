//! The error type of the simulation module: what was wrong with the ROM, the integrator
//! parameters, the excitation or a state, naming the field, the index and what was expected.
//!
//! Errors are for bad input only. What happens during a run (a contact solve that did not
//! converge, a state that became non-finite) is data in the run's report and the step outputs.

use crate::contact::ContactError;

/// Why the integrator rejected its input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter of [`crate::sim::IntegratorParameters`] or of an excitation is out of range.
    #[error("{field} = {value} is invalid, expected {expected}")]
    InvalidParameter {
        /// Parameter name with its unit, e.g. "time_step.dt (s)".
        field: &'static str,
        /// The value found.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// The time step exceeds the stability limit of the explicit modal step.
    #[error(
        "time step dt = {dt:.4e} s ({steps_given:.1} steps per 1FU period) is beyond the stability \
         limit {limit}: dt must be below {dt_max:.4e} s, i.e. at least {steps_needed:.1} steps per \
         1FU period (w_max = {omega_max:.5e} rad/s, w_max dt < 2){hint}"
    )]
    TimeStepTooLarge {
        /// The requested step, s.
        dt: f64,
        /// The largest stable step, s.
        dt_max: f64,
        /// The highest circular frequency the explicit step sees, rad/s.
        omega_max: f64,
        /// Steps per reference (1FU) period of the requested step.
        steps_given: f64,
        /// Steps per reference (1FU) period needed.
        steps_needed: f64,
        /// Which limit: "with all pairs open" or "with all pairs closed (Explicit coupling)".
        limit: &'static str,
        /// What to do about it (starts with "; " or is empty).
        hint: &'static str,
    },
    /// The ROM's arrays do not fit together.
    #[error("ROM: {what} has {found} entries, expected {expected}")]
    RomDimension {
        /// Which array, e.g. "phi_g rows (3 x pairs)".
        what: String,
        /// Size found.
        found: usize,
        /// Size expected.
        expected: usize,
    },
    /// A ROM entry is NaN, infinite or out of its domain.
    #[error("ROM: {what}[{index}] = {value} is invalid, expected {expected}")]
    RomValue {
        /// Which array.
        what: &'static str,
        /// Flat index (row-major for matrices).
        index: usize,
        /// The value found.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// The residual flexibility is not symmetric positive definite.
    #[error("ROM: residual flexibility G_res is not symmetric positive definite: {detail}")]
    RomFlexibility {
        /// What failed.
        detail: String,
    },
    /// A sampled excitation contains a non-finite sample.
    #[error(
        "excitation: sample {index} of the base acceleration is {value} (samples must be finite)"
    )]
    ExcitationSample {
        /// Index of the first bad sample.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// The run reaches outside the time span of a sampled excitation.
    #[error(
        "excitation: the run needs base acceleration from t = {start:.6} s to {end:.6} s, but the \
         samples cover 0 to {available:.6} s"
    )]
    ExcitationSpan {
        /// Time of the first step, s.
        start: f64,
        /// Time of the last step, s.
        end: f64,
        /// Time of the last sample, s.
        available: f64,
    },
    /// A base acceleration passed to a single step is not finite.
    #[error("base acceleration {value} m/s^2 at t = {time} s is not finite")]
    BaseAcceleration {
        /// The value.
        value: f64,
        /// Time of the step, s.
        time: f64,
    },
    /// A state does not belong to this ROM (sizes) or holds non-finite values.
    #[error("state: {what} has {found} entries, expected {expected} for this ROM")]
    StateDimension {
        /// Which vector.
        what: &'static str,
        /// Size found.
        found: usize,
        /// Size expected.
        expected: usize,
    },
    /// A state entry is not finite.
    #[error("state: {what}[{index}] = {value} is not finite")]
    StateValue {
        /// Which vector.
        what: &'static str,
        /// Index.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// The contact solver rejected its input.
    #[error("contact solver: {0}")]
    Contact(#[from] ContactError),
}
