//! One leapfrog step with the implicit contact boundary: free modal velocity, open
//! prediction, contact solve on the candidate pairs, modal update, outputs.
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
//! - [`Coupling::Explicit`] (reference, Eqs. algebraic/boundaryStep): the boundary step is
//!   `g^{j-1} -> g^j` with `g^j = Phi_g eta^j + g0 + G_res lambda^j`, so `W = G_res / dt` and
//!   `c = (Phi_g eta^j + g0 - g^{j-1}) / dt = Phi_g v^{j-1/2} - G_res lambda^{j-1} / dt`
//!   (using `eta^j - eta^{j-1} = dt v^{j-1/2}` and `g^{j-1} = Phi_g eta^{j-1} + g0 + G_res lambda^{j-1}`).
//!   The free end gap is `p = Phi_g eta^j + g0`.
//!
//! - [`Coupling::EndOfStep`]: the boundary step is `g^j -> g^{j+1}` and `lambda` is the force
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
//
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

use crate::contact::PairState;

use super::super::energy::{Energy, EnergyAccounts};
use super::super::error::SimError;
use super::super::output::{ContactSummary, StepOutput, StepSink};
use super::kernels::{axpy, dot, Lanes4};
use super::predict::{OffsetGap, Prediction};
use super::{Coupling, Integrator, State};

impl Integrator {
    /// One step from `st` with base acceleration `a_base` at the step's start time `t0` and
    /// the extra modal forces `load` (`(mode, force)`, indices checked by the caller).
    /// Returns whether the new state is finite.
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
        let m = md.m;
        let n = md.n_pairs;
        let nb = 3 * n;
        let h = md.dt;
        let inv_h = 1.0 / h;
        let kappa = md.kappa;

        // 1. Free modal velocity.
        {
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

        // 2. Contact time level: free end-gap displacement x_p and velocity v_c of the
        //    boundary step; x_q extrapolates kappa further steps.
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
        {
            let kh = kappa * h;
            let (x_p, v_c, x_q) = (&ws.x_p[..m], &ws.v_c[..m], &mut ws.x_q[..m]);
            for i in 0..m {
                x_q[i] = x_p[i] + kh * v_c[i];
            }
        }

        // 3. Open prediction.
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
                },
                &st.lambda,
                r_prev,
                kappa,
                prediction,
            ),
        }

        // 4. Contact solve on the candidates.
        let mut solve = None;
        ws.closed_new.clear();
        if !ws.cand.is_empty() {
            for (&k, &p) in ws.cand.iter().zip(&ws.p_cand) {
                for a in 0..3 {
                    let row = 3 * k + a;
                    let mut c = dot(&md.phi_g[row * m..(row + 1) * m], &ws.v_c);
                    if has_prev {
                        c -= st.g_lambda[row] * inv_h;
                    }
                    ws.c_full[row] = c;
                }
                // Closing-velocity shift of the normal law (see the NOTE above).
                let pc = p * inv_h;
                if pc > ws.c_full[3 * k] {
                    ws.c_full[3 * k] = pc;
                }
                ws.mask[k] = -1.0;
            }
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
            let c = &mut st.counters;
            c.solves += 1;
            c.iterations += stats.iterations as u64;
            match stats.status {
                crate::contact::SolveStatus::Converged => {}
                crate::contact::SolveStatus::MaxIterations => c.max_iterations += 1,
                crate::contact::SolveStatus::Diverged => c.diverged += 1,
            }
            if stats.relative_residual > c.worst_relative_residual {
                c.worst_relative_residual = stats.relative_residual;
            }
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

        // 5. Modal update with the contact forces.
        if any_closed {
            ws.f_c.fill(0.0);
            for &k in &ws.closed_new {
                for a in 0..3 {
                    let row = 3 * k + a;
                    let l = ws.lambda[row];
                    if l != 0.0 {
                        axpy(l, &md.phi_g[row * m..(row + 1) * m], &mut ws.f_c);
                    }
                }
            }
            let (vf, fc, inv_a, v_new) = (
                &ws.vf[..m],
                &ws.f_c[..m],
                &md.inv_a[..m],
                &mut ws.v_new[..m],
            );
            for i in 0..m {
                v_new[i] = vf[i] + fc[i] * inv_a[i];
            }
        } else {
            ws.v_new.copy_from_slice(&ws.vf);
        }

        // eta^{j+1} and the energy sums in one pass (four fixed lanes, lane = i % 4).
        let (mut kin, mut pot, mut mid, mut damp, mut base) = (
            Lanes4::default(),
            Lanes4::default(),
            Lanes4::default(),
            Lanes4::default(),
            Lanes4::default(),
        );
        {
            let (eta, v, v_new) = (&st.eta[..m], &st.eta_dot[..m], &ws.v_new[..m]);
            let (w2, dd, beta) = (&md.omega2[..m], &md.damping[..m], &md.beta[..m]);
            let eta_next = &mut ws.eta_next[..m];
            for i in 0..m {
                let lane = i & 3;
                let (e0, v1) = (eta[i], v_new[i]);
                let e1 = e0 + h * v1;
                eta_next[i] = e1;
                let s = v[i] + v1;
                kin.add(lane, v1 * v1);
                pot.add(lane, w2[i] * e1 * e1);
                mid.add(lane, w2[i] * e0 * e1);
                damp.add(lane, dd[i] * s * s);
                base.add(lane, beta[i] * s);
            }
        }
        let mut contact_work = 0.0;
        if any_closed {
            let mut cw = Lanes4::default();
            let (v, v_new, fc) = (&st.eta_dot[..m], &ws.v_new[..m], &ws.f_c[..m]);
            for i in 0..m {
                cw.add(i & 3, fc[i] * (v[i] + v_new[i]));
            }
            contact_work = 0.5 * h * cw.sum();
        }

        // 6. Sensors: displacement at the contact time level, velocity over the last step.
        {
            let (eta_s, v_s) = match md.coupling {
                Coupling::Explicit => (&st.eta[..m], &st.eta_dot[..m]),
                Coupling::EndOfStep => (&ws.eta_next[..m], &ws.v_new[..m]),
            };
            for o in 0..md.n_out {
                let ce = &md.c_eta[o * m..(o + 1) * m];
                let cl = &md.c_lambda[o * nb..(o + 1) * nb];
                let mut s_new = 0.0;
                for &k in &ws.closed_new {
                    for a in 0..3 {
                        s_new += cl[3 * k + a] * ws.lambda[3 * k + a];
                    }
                }
                let mut s_old = 0.0;
                for &k in &st.closed {
                    for a in 0..3 {
                        s_old += cl[3 * k + a] * st.lambda[3 * k + a];
                    }
                }
                ws.disp[o] = dot(ce, eta_s) + s_new;
                ws.vel[o] = dot(ce, v_s) + (s_new - s_old) * inv_h;
            }
        }

        // 7. Integrated forces, boundary displacement G_res lambda and its elastic energy.
        let (mut normal_force, mut tangential_force, mut boundary2) = (0.0, 0.0, 0.0);
        if any_closed {
            ws.g_lambda_new.fill(0.0);
            for &k in &ws.closed_new {
                let l = &ws.lambda[3 * k..3 * k + 3];
                normal_force += l[0];
                tangential_force += l[1].hypot(l[2]);
                for (a, &la) in l.iter().enumerate() {
                    if la != 0.0 {
                        let row = 3 * k + a;
                        axpy(
                            la,
                            &md.g_res[row * nb..(row + 1) * nb],
                            &mut ws.g_lambda_new,
                        );
                    }
                }
            }
            for &k in &ws.closed_new {
                for a in 0..3 {
                    boundary2 += ws.lambda[3 * k + a] * ws.g_lambda_new[3 * k + a];
                }
            }
        }

        // 8. Energy accounts and output.
        let accounts = EnergyAccounts {
            base_work: st.accounts.base_work - 0.5 * h * a_base * base.sum(),
            damping_dissipated: st.accounts.damping_dissipated + 0.25 * h * damp.sum(),
            contact_work: st.accounts.contact_work + contact_work,
        };
        st.accounts = accounts;
        let energy = Energy {
            kinetic: 0.5 * kin.sum(),
            potential: 0.5 * pot.sum(),
            potential_mid: 0.5 * mid.sum(),
            boundary: 0.5 * boundary2,
            accounts,
        };
        let (stick, slip) = solve.map_or((0, 0), |s| (s.stick, s.slip));
        let time = match md.coupling {
            Coupling::Explicit => t0,
            Coupling::EndOfStep => t0 + h,
        };
        sink.record(&StepOutput {
            step: st.step,
            time,
            velocity_time: time - 0.5 * h,
            base_acceleration: a_base,
            displacement: &ws.disp,
            velocity: &ws.vel,
            lambda: &ws.lambda,
            pair_states: &ws.pair_states,
            gap_n: if md.report_gaps {
                Some(&ws.gap_n)
            } else {
                None
            },
            contact: ContactSummary {
                candidates: ws.cand.len(),
                open: n - stick - slip,
                stick,
                slip,
                any_closed,
                normal_force,
                tangential_force,
            },
            solve,
            energy,
        });

        // 9. Commit the state.
        std::mem::swap(&mut st.eta, &mut ws.eta_next);
        std::mem::swap(&mut st.eta_dot, &mut ws.v_new);
        if solve.is_some() {
            st.lambda.copy_from_slice(&ws.lambda);
        } else {
            for &k in &st.closed {
                st.lambda[3 * k..3 * k + 3].fill(0.0);
            }
        }
        std::mem::swap(&mut st.closed, &mut ws.closed_new);
        if any_closed {
            std::mem::swap(&mut st.g_lambda, &mut ws.g_lambda_new);
        }
        st.step += 1;
        Ok(energy.kinetic.is_finite() && energy.potential.is_finite())
    }
}
