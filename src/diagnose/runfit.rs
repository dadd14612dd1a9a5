//! Least squares over model runs: Levenberg-Marquardt on residuals that only a model run
//! gives (the signed scores of measured features), with a forward-difference Jacobian. Shared
//! by the linear refinement (`modes`) and the clamp's fit (`clamp`).

use std::cell::RefCell;

use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};

use crate::signal::features::CONTACT_CHANNEL;

use super::outcome::{Regime, StepScores};

/// The residuals of a fit by model runs: the signed scores (model above measured positive) of
/// every motion feature of the impact-free steps of `tests`.
pub(super) fn signed_scores(scores: &[StepScores], tests: &[usize]) -> Vec<f64> {
    scores
        .iter()
        .filter(|s| tests.contains(&s.test_index) && s.regime != Regime::Impacts)
        .flat_map(|s| s.features.iter())
        .filter(|c| c.channel != CONTACT_CHANNEL)
        .map(|c| c.score.copysign(c.model - c.measured))
        .collect()
}

/// Residuals at scaled parameters, one model run each; `None` when the run fails or the
/// parameters are outside the model's range (the implementor keeps why).
pub(super) trait RunResiduals {
    /// The residuals at the scaled parameters `x`.
    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>>;

    /// Makes the runs at every point of `xs` side by side (a Jacobian's), so that the
    /// [`RunResiduals::residuals_at`] calls that follow find them made. A run's result does
    /// not depend on what runs beside it. Nothing by default.
    fn prefetch(&self, _xs: &[DVector<f64>]) {}
}

/// A [`RunResiduals`] at the scaled parameters `x` as a [`LeastSquaresProblem`], its Jacobian
/// by forward differences of `step` in every parameter (one run each).
pub(super) struct RunProblem<R> {
    /// The residuals.
    pub(super) runs: R,
    /// The current scaled parameters.
    pub(super) x: DVector<f64>,
    /// The forward-difference step, in the scaled parameters.
    pub(super) step: f64,
    /// The fit stops, without a run, at a trial step that moves every scaled parameter by
    /// less than this from the current point (0: never). Levenberg-Marquardt's own `xtol` is
    /// relative to the parameters' norm, which a fit started at zero (the parameters relative
    /// to a grid's best point) does not have, and its trust region shrinks step by step
    /// where the residuals' noise floor rejects every trial (one run each).
    pub(super) settled: f64,
    /// The current point: where the last Jacobian was made (the crate makes one at every
    /// point it accepts).
    current: RefCell<Option<DVector<f64>>>,
}

impl<R> RunProblem<R> {
    /// The problem of `runs` from `x`, forward differences of `step`, stopping at a trial
    /// step of less than `settled` ([`RunProblem::settled`]).
    pub(super) fn new(runs: R, x: DVector<f64>, step: f64, settled: f64) -> Self {
        RunProblem {
            runs,
            x,
            step,
            settled,
            current: RefCell::new(None),
        }
    }
}

impl<R: RunResiduals> LeastSquaresProblem<f64, Dyn, Dyn> for RunProblem<R> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    /// `None` (the fit stops) at a trial step that moves no parameter by
    /// [`RunProblem::settled`] or more from the current point.
    fn residuals(&self) -> Option<DVector<f64>> {
        let current = self.current.borrow();
        if (current.as_ref()).is_some_and(|c| (&self.x - c).amax() < self.settled) {
            return None;
        }
        self.runs.residuals_at(&self.x)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        *self.current.borrow_mut() = Some(self.x.clone());
        let n = self.x.len();
        let shifted = |k: usize| {
            let mut x = self.x.clone();
            x[k] += self.step;
            x
        };
        let points: Vec<DVector<f64>> = std::iter::once(self.x.clone())
            .chain((0..n).map(shifted))
            .collect();
        self.runs.prefetch(&points);
        let r0 = self.runs.residuals_at(&self.x)?;
        let mut j = DMatrix::zeros(r0.len(), n);
        for k in 0..n {
            let r = self.runs.residuals_at(&shifted(k))?;
            if r.len() != r0.len() {
                return None;
            }
            j.set_column(k, &((r - &r0) / self.step));
        }
        Some(j)
    }
}
