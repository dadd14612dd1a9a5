//! The free prediction of a step (everything before its contact solve): the free modal
//! velocity `v_free` (all forces but this step's contact force), the free end-gap displacement
//! `x_p` and velocity `v_c` of the boundary step at the contact time level with the
//! extrapolation `x_q`, and the open prediction of the pairs handed to the contact solver
//! (see `predict.rs`).

use super::super::model::{Model, Workspace};
use super::super::predict::{OffsetGap, Prediction};
use super::super::{Coupling, State};

/// Free modal velocity `v_free = (b .* v^{j-1/2} - Omega^2 eta^j - beta a_base + f_load) ./ a`
/// into `ws.vf`.
#[inline(always)]
pub(super) fn free_velocity(
    md: &Model,
    ws: &mut Workspace,
    st: &State,
    a_base: f64,
    load: &[(usize, f64)],
) {
    let m = md.m;
    let (eta, v) = (&st.eta[..m], &st.eta_dot[..m]);
    let (w2, beta, b, inv_a) = (&md.omega2[..m], &md.beta[..m], &md.b[..m], &md.inv_a[..m]);
    let vf = &mut ws.vf[..m];
    for i in 0..m {
        vf[i] = (b[i] * v[i] - w2[i] * eta[i] - beta[i] * a_base) * inv_a[i];
    }
    // Extra modal forces (empty unless the caller passes a load): the same expression
    // with the force inside, for the few loaded modes only.
    for &(i, f) in load {
        vf[i] = (b[i] * v[i] - w2[i] * eta[i] - beta[i] * a_base + f) * inv_a[i];
    }
}

/// Contact time level: free end-gap displacement `x_p` and velocity `v_c` of the boundary
/// step (`eta^j`, `v^{j-1/2}` for the explicit coupling; `eta^j + dt v_free`, `v_free` at the
/// end of the step); `x_q = x_p + kappa dt v_c` extrapolates kappa further steps.
#[inline(always)]
pub(super) fn contact_level(md: &Model, ws: &mut Workspace, st: &State) {
    let m = md.m;
    let h = md.dt;
    match md.coupling {
        Coupling::Explicit => {
            ws.x_p.copy_from_slice(&st.eta);
            ws.v_c.copy_from_slice(&st.eta_dot);
        }
        Coupling::EndOfStep => {
            let (eta, vf, x_p) = (&st.eta[..m], &ws.vf[..m], &mut ws.x_p[..m]);
            for i in 0..m {
                x_p[i] = eta[i] + h * vf[i];
            }
            ws.v_c.copy_from_slice(&ws.vf);
        }
    }
    let kh = md.kappa * h;
    let (x_p, v_c, x_q) = (&ws.x_p[..m], &ws.v_c[..m], &mut ws.x_q[..m]);
    for i in 0..m {
        x_q[i] = x_p[i] + kh * v_c[i];
    }
}

/// Open prediction: the candidate pairs of the step and their free normal gaps `p`
/// (`ws.cand`, `ws.p_cand`; with `report_gaps` the free normal gap of every pair in
/// `ws.gap_n`).
#[inline(always)]
pub(super) fn predict_candidates(md: &mut Model, ws: &mut Workspace, st: &State) {
    let kappa = md.kappa;
    let has_prev = !st.closed.is_empty();
    let r_prev = if has_prev {
        Some(&st.g_lambda[..])
    } else {
        None
    };
    let prediction = Prediction {
        cand: &mut ws.cand,
        p_cand: &mut ws.p_cand,
        p_all: if md.report_gaps {
            Some(&mut ws.gap_n[..])
        } else {
            None
        },
    };
    match &md.gap_offset {
        None => md.predictor.predict(
            &ws.x_p,
            &ws.x_q,
            md.clearance,
            &st.lambda,
            r_prev,
            kappa,
            prediction,
        ),
        Some(offset) => md.predictor.predict(
            &ws.x_p,
            &ws.x_q,
            OffsetGap {
                clearance: md.clearance,
                offset,
                range: md.gap_offset_range,
            },
            &st.lambda,
            r_prev,
            kappa,
            prediction,
        ),
    }
}
