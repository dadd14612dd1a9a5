//! Least squares over model runs: Levenberg-Marquardt on residuals that only a model run
//! gives (the signed scores of measured features), with a forward-difference Jacobian. Shared
//! by the linear refinement (`modes`) and the clamp's fit (`clamp`).

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

    fn residuals(&self) -> Option<DVector<f64>> {
        self.runs.residuals_at(&self.x)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
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
