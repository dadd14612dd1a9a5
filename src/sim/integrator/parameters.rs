//! The integrator's parameters: where the contact condition is imposed ([`Coupling`]), how the
//! fixed time step is given ([`TimeStep`]) and the documented parameter struct
//! ([`IntegratorParameters`]) with its range checks.

use crate::contact::ContactParameters;

use super::super::error::SimError;

/// Where the contact condition of a step is imposed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Coupling {
    /// The reference's coupling: the gap `g^j = Phi_g eta^j + g0 + G_res lambda^j` at the start
    /// of the modal step, `W = G_res / dt`; the modal step then sees the closed pairs' stiffness
    /// explicitly and is stable only below the closed bound
    /// ([`super::StabilityLimits::dt_max_closed`]).
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
    /// by [`super::Integrator::new`]).
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

/// The time step for a [`TimeStep`] (already validated), s.
pub(super) fn resolve_dt(time_step: &TimeStep, omega_ref: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    match *time_step {
        TimeStep::Dt { dt } => dt,
        TimeStep::StepsPerPeriod { steps, omega } => two_pi / (omega * steps),
        TimeStep::StepsPerReferencePeriod { steps } => two_pi / (omega_ref * steps),
    }
}
