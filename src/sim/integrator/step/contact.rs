//! The contact solve of a step: the frictional contact problem `gamma = W lambda + c`,
//! `-gamma in N_C(lambda)` on the candidate pairs (`c` formed on their rows only, with the
//! closing-velocity shift of the normal law below), the solve with the previous forces as the
//! warm start, the pairs that closed, and the solver's bookkeeping in the state's counters.
//!
// NOTE (normal law, closing-velocity shift). The reference applies the velocity-level law
// -gamma in N_C(lambda) to pairs whose gap is closed (g_n <= 0). Applied to a pair that
// starts the boundary step open (g_n^start > 0) but would close within it, the velocity law
// stops it at g_n^start > 0 (early by up to one step), and a pair not handed to the solver
// penetrates by up to one step. Here the normal component of the law is applied to
//   gamma~_n = gamma_n + max(g_n^start, 0) / dt,  i.e.  c~_n = max(c_n, p_n / dt)
// (since g_n^start = p_n - dt c_n): for a pair starting open, lambda_n > 0 implies
// g_n^end = 0 exactly and lambda_n = 0 implies g_n^end >= 0 (position-level Signorini, the
// exact condition of the massless boundary `K_gg g + K_g_eta eta = lambda`); for a pair
// starting closed or penetrated (g_n^start <= 0) it is the reference's velocity law
// unchanged (an existing penetration is kept, never pushed out, so no energy is injected).
// Friction stays on the velocity level. Consequently handing extra (open) pairs to the
// solver does not change the result, which is what makes the open-prediction margin safe.

use crate::contact::{ContactSolver, PairState, SolvePath, SolveStats, SolveStatus};

use super::super::super::error::SimError;
use super::super::kernels::dot;
use super::super::model::{Model, Workspace};
use super::super::{SolverCounters, State};

/// What the contact stage decided for the rest of the step.
#[derive(Clone, Copy, Debug)]
pub(super) struct ContactOutcome {
    /// Statistics of the solve, `None` when no pair was a candidate (no solve).
    pub(super) solve: Option<SolveStats>,
    /// Whether any pair closed (`ws.closed_new` not empty).
    pub(super) any_closed: bool,
}

/// Solves the contact problem on the candidates (forces in `ws.lambda`, pair states in
/// `ws.pair_states`, closed pairs in `ws.closed_new`), or clears the forces and states when
/// there is no candidate; counts the solve and the closed step in `st`.
#[inline(always)]
pub(super) fn solve(
    md: &Model,
    ws: &mut Workspace,
    solver: &mut ContactSolver,
    st: &mut State,
) -> Result<ContactOutcome, SimError> {
    let h = md.dt;
    let mut solve = None;
    ws.closed_new.clear();
    if !ws.cand.is_empty() {
        assemble(md, ws, st);
        ws.lambda.copy_from_slice(&st.lambda);
        let stats = solver.solve(&ws.c_full, Some(&ws.mask), &mut ws.lambda, &mut ws.gamma)?;
        ws.lambda_dirty = true;
        if md.report_gaps {
            // g_n^end = p + dt (W lambda)_n, and the solver returned gamma = W lambda + c
            // with c = 0 on the non-candidates.
            for (k, g) in ws.gap_n.iter_mut().enumerate() {
                *g += h * (ws.gamma[3 * k] - ws.c_full[3 * k]);
            }
        }
        for &k in &ws.cand {
            ws.c_full[3 * k..3 * k + 3].fill(0.0);
            ws.mask[k] = 1.0;
            if ws.lambda[3 * k] > 0.0 {
                ws.closed_new.push(k);
            }
        }
        ws.pair_states.copy_from_slice(solver.pair_states());
        ws.states_dirty = true;
        count(&mut st.counters, &stats);
        solve = Some(stats);
    } else {
        if ws.lambda_dirty {
            ws.lambda.fill(0.0);
            ws.lambda_dirty = false;
        }
        if ws.states_dirty {
            ws.pair_states.fill(PairState::Open);
            ws.states_dirty = false;
        }
    }
    let any_closed = !ws.closed_new.is_empty();
    if any_closed {
        st.counters.closed_steps += 1;
    }
    Ok(ContactOutcome { solve, any_closed })
}

/// The candidates' rows of `c = Phi_g v_c - G_res lambda^prev / dt` into `ws.c_full`, with the
/// closing-velocity shift of the normal row (see the module NOTE), and their solver mask.
#[inline(always)]
fn assemble(md: &Model, ws: &mut Workspace, st: &State) {
    let m = md.m;
    let inv_h = 1.0 / md.dt;
    let has_prev = !st.closed.is_empty();
    for (&k, &p) in ws.cand.iter().zip(&ws.p_cand) {
        for a in 0..3 {
            let row = 3 * k + a;
            let mut c = dot(&md.phi_g[row * m..(row + 1) * m], &ws.v_c);
            if has_prev {
                c -= st.g_lambda[row] * inv_h;
            }
            ws.c_full[row] = c;
        }
        // Closing-velocity shift of the normal law (see the module NOTE).
        let pc = p * inv_h;
        if pc > ws.c_full[3 * k] {
            ws.c_full[3 * k] = pc;
        }
        ws.mask[k] = -1.0;
    }
}

/// Adds one solve to the cumulative counters.
#[inline(always)]
fn count(c: &mut SolverCounters, stats: &SolveStats) {
    c.solves += 1;
    c.iterations += stats.iterations as u64;
    match stats.status {
        SolveStatus::Converged => {}
        SolveStatus::MaxIterations => c.max_iterations += 1,
        SolveStatus::Diverged => c.diverged += 1,
    }
    if stats.newton_iterations > 0 {
        c.newton_solves += 1;
        c.newton_iterations += stats.newton_iterations as u64;
    }
    if stats.path == SolvePath::NewtonFallback {
        c.newton_fallbacks += 1;
    }
    if stats.relative_residual > c.worst_relative_residual {
        c.worst_relative_residual = stats.relative_residual;
    }
}
