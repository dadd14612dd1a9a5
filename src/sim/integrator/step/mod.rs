//! One leapfrog step with the implicit contact boundary, in three stages: the free prediction
//! (`free.rs`: free modal velocity, contact time level, open prediction), the contact solve on
//! the candidate pairs (`contact.rs`), and the update (`update.rs`: modal update, energy,
//! sensors, boundary, output, commit).
//!
//! Symbols as in DESIGN.md: `eta^j`, `v^{j-1/2}` (modal velocity), `lambda`, `g`,
//! `a = 1/dt + D/2`, `b = 1/dt - D/2` (per mode), `g0 = [clearance, 0, 0]` per pair.
//!
//! Free modal velocity (everything but the contact force of this step):
//! `v_free = (b .* v^{j-1/2} - Omega^2 eta^j - beta a_base(t^j) + f_load) ./ a` (`f_load`: an
//! optional extra modal force evaluated at `eta^j`, zero by default), and with the contact
//! force `v^{j+1/2} = v_free + (Phi_g^T lambda) ./ a`, `eta^{j+1} = eta^j + dt v^{j+1/2}`
//! (the reference's Eq. differential/explicit).
//!
//! Both couplings impose the contact law on a *boundary step* from a start gap `g^start` to
//! an end gap `g^end`, `gamma = (g^end - g^start) / dt = W lambda + c`:
//!
//! - [`Coupling::Explicit`](crate::sim::Coupling::Explicit) (reference, Eqs. algebraic/boundaryStep): the boundary step is
//!   `g^{j-1} -> g^j` with `g^j = Phi_g eta^j + g0 + G_res lambda^j`, so `W = G_res / dt` and
//!   `c = (Phi_g eta^j + g0 - g^{j-1}) / dt = Phi_g v^{j-1/2} - G_res lambda^{j-1} / dt`
//!   (using `eta^j - eta^{j-1} = dt v^{j-1/2}` and `g^{j-1} = Phi_g eta^{j-1} + g0 + G_res lambda^{j-1}`).
//!   The free end gap is `p = Phi_g eta^j + g0`.
//!
//! - [`Coupling::EndOfStep`](crate::sim::Coupling::EndOfStep): the boundary step is `g^j -> g^{j+1}` and `lambda` is the force
//!   acting in the modal step `j -> j+1`. See the NOTE below for `W'` and `c'`.
//!
//! In both, `c = Phi_g v_c - G_res lambda^prev / dt` with `v_c = v^{j-1/2}` (explicit) or
//! `v_free` (end of step), and the free end gap is `p = Phi_g x_p + g0` with `x_p = eta^j`
//! (explicit) or `eta^j + dt v_free` (end of step). Only the candidate rows are formed.
//!
// NOTE (end-of-step coupling, derivation). Write v^{j+1/2} = v_free + diag(1/a) Phi_g^T lambda.
// The gap at the end of the step, with the same lambda acting on the boundary, is
//   g^{j+1} = Phi_g eta^{j+1} + g0 + G_res lambda
//           = Phi_g (eta^j + dt v_free) + g0 + (G_res + dt Phi_g diag(1/a) Phi_g^T) lambda.
// With g^j = Phi_g eta^j + g0 + G_res lambda^prev (lambda^prev: the force of the previous
// step, which defined g^j the same way), the gap velocity of the step is
//   gamma = (g^{j+1} - g^j) / dt = W' lambda + c',
//   W' = (G_res + dt Phi_g diag(1/a) Phi_g^T) / dt = G_res / dt + Phi_g diag(1/a) Phi_g^T,
//   c' = (Phi_g (eta^j + dt v_free) + g0 - g^j) / dt = Phi_g v_free - G_res lambda^prev / dt.
// W' is symmetric positive definite and constant for a fixed dt (precomputed, 3C x 3C).
// Solving -gamma in N_C(lambda) for lambda and then v^{j+1/2} = v_free + (Phi_g^T lambda) ./ a,
// eta^{j+1} = eta^j + dt v^{j+1/2} makes g^{j+1} = Phi_g eta^{j+1} + g0 + G_res lambda hold
// exactly (up to round-off), i.e. the contact law holds for the gap the next step starts from.
// Why it is stable: for closed, stuck pairs lambda = K_gg (g_held - Phi_g eta^{j+1} - g0) is
// taken at eta^{j+1}, so the closed pairs' stiffness Phi_gc^T K_gg,c Phi_gc enters the modal
// step implicitly (backward-Euler-like: for one mode with contact stiffness k the
// amplification factor is |z|^2 = 1/(1 + dt^2 k) < 1) and only the open bound
// max(Omega) dt < 2 remains. The price is a small numerical dissipation of the closed-contact
// oscillation, O(dt^2 k) per step, which also rules out energy growth at impacts.

mod contact;
mod free;
mod update;

use super::super::error::SimError;
use super::super::output::StepSink;
use super::{Integrator, State};

impl Integrator {
    /// One step from `st` with base acceleration `a_base` at the step's start time `t0` and
    /// the extra modal forces `load` (`(mode, force)`, indices checked by the caller).
    /// Returns whether the new state is finite.
    ///
    // NOTE: every stage is `#[inline(always)]`, so the whole step is compiled inside the AVX2
    // build as one function, as before the split; the stages run in the order below and each
    // does its floating-point operations in a fixed order (bit-identical results).
    #[inline(always)]
    pub(super) fn step_impl<S: StepSink>(
        &mut self,
        st: &mut State,
        a_base: f64,
        load: &[(usize, f64)],
        t0: f64,
        sink: &mut S,
    ) -> Result<bool, SimError> {
        let Integrator {
            model: md,
            ws,
            solver,
            ..
        } = self;

        // Free prediction: the modal step without this step's contact force, the contact time
        // level and the pairs that may close.
        free::free_velocity(md, ws, st, a_base, load);
        free::contact_level(md, ws, st);
        free::predict_candidates(md, ws, st);

        // Contact solve on the candidates.
        let contact = contact::solve(md, ws, solver, st)?;

        // Update: modal step with the contact forces, energy, sensors, boundary, output, and
        // the new state.
        update::modal_velocity(md, ws, contact.any_closed);
        let sums = update::advance(md, ws, st, contact.any_closed);
        update::sensors(md, ws, st);
        let boundary = update::boundary(md, ws, contact.any_closed);
        let energy = update::record(md, ws, st, a_base, t0, &contact, &sums, &boundary, sink);
        update::commit(ws, st, &contact);
        let finite = energy.kinetic.is_finite() && energy.potential.is_finite();
        update::verify(ws, st, finite, &energy);
        Ok(finite)
    }
}
