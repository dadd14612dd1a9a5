//! The update of a step after its contact solve: the modal velocity with the contact forces
//! `v^{j+1/2} = v_free + (Phi_g^T lambda) ./ a`, `eta^{j+1} = eta^j + dt v^{j+1/2}` with the
//! energy sums in the same pass, the sensors, the integrated forces and the boundary
//! displacement `G_res lambda`, the energy accounts and the step output handed to the sink,
//! and the commit of the new state.

use super::super::super::energy::{Energy, EnergyAccounts};
use super::super::super::output::{ContactSummary, StepOutput, StepSink};
use super::super::kernels::{axpy, dot, Lanes4};
use super::super::model::{Model, Workspace};
use super::super::state::Verified;
use super::super::{Coupling, State};
use super::contact::ContactOutcome;

/// The energy sums of one step, per lane (summed when the energies are formed).
#[derive(Clone, Copy, Default)]
pub(super) struct EnergySums {
    /// `v^{j+1/2} . v^{j+1/2}`.
    kin: Lanes4,
    /// `eta^{j+1} . Omega^2 eta^{j+1}`.
    pot: Lanes4,
    /// `eta^j . Omega^2 eta^{j+1}`.
    mid: Lanes4,
    /// `s . D s`, `s = v^{j-1/2} + v^{j+1/2}`.
    damp: Lanes4,
    /// `beta . s`.
    base: Lanes4,
    /// Work of the contact forces on the modes in the step, J.
    contact_work: f64,
}

/// The integrated contact forces of the step and the boundary's elastic energy term.
#[derive(Clone, Copy, Default)]
pub(super) struct BoundaryForces {
    /// `sum_k lambda_n,k`, N.
    normal: f64,
    /// `sum_k |lambda_t,k|`, N.
    tangential: f64,
    /// `lambda . G_res lambda` over the closed pairs, J (twice the boundary energy).
    boundary2: f64,
}

/// The new modal velocity `v^{j+1/2} = v_free + (Phi_g^T lambda) ./ a` into `ws.v_new`
/// (the generalised contact force `Phi_g^T lambda` in `ws.f_c`).
#[inline(always)]
pub(super) fn modal_velocity(md: &Model, ws: &mut Workspace, any_closed: bool) {
    let m = md.m;
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
}

/// `eta^{j+1}` into `ws.eta_next` and the energy sums in one pass (four fixed lanes,
/// lane = i % 4), then the contact work.
#[inline(always)]
pub(super) fn advance(md: &Model, ws: &mut Workspace, st: &State, any_closed: bool) -> EnergySums {
    let m = md.m;
    let h = md.dt;
    let mut sums = EnergySums::default();
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
            sums.kin.add(lane, v1 * v1);
            sums.pot.add(lane, w2[i] * e1 * e1);
            sums.mid.add(lane, w2[i] * e0 * e1);
            sums.damp.add(lane, dd[i] * s * s);
            sums.base.add(lane, beta[i] * s);
        }
    }
    if any_closed {
        let mut cw = Lanes4::default();
        let (v, v_new, fc) = (&st.eta_dot[..m], &ws.v_new[..m], &ws.f_c[..m]);
        for i in 0..m {
            cw.add(i & 3, fc[i] * (v[i] + v_new[i]));
        }
        sums.contact_work = 0.5 * h * cw.sum();
    }
    sums
}

/// Sensors into `ws.disp` and `ws.vel`: displacement at the contact time level, velocity over
/// the last step.
#[inline(always)]
pub(super) fn sensors(md: &Model, ws: &mut Workspace, st: &State) {
    let m = md.m;
    let nb = 3 * md.n_pairs;
    let inv_h = 1.0 / md.dt;
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

/// Integrated forces, the boundary displacement `G_res lambda` (into `ws.g_lambda_new`) and
/// its elastic energy term.
#[inline(always)]
pub(super) fn boundary(md: &Model, ws: &mut Workspace, any_closed: bool) -> BoundaryForces {
    let nb = 3 * md.n_pairs;
    let mut f = BoundaryForces::default();
    if any_closed {
        ws.g_lambda_new.fill(0.0);
        for &k in &ws.closed_new {
            let l = &ws.lambda[3 * k..3 * k + 3];
            f.normal += l[0];
            f.tangential += l[1].hypot(l[2]);
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
                f.boundary2 += ws.lambda[3 * k + a] * ws.g_lambda_new[3 * k + a];
            }
        }
    }
    f
}

/// Energy accounts (into the state) and the step output handed to `sink`; returns the
/// step's energies.
#[allow(clippy::too_many_arguments)] // the step's stages' results, each used once
#[inline(always)]
pub(super) fn record<S: StepSink>(
    md: &Model,
    ws: &Workspace,
    st: &mut State,
    a_base: f64,
    t0: f64,
    contact: &ContactOutcome,
    sums: &EnergySums,
    forces: &BoundaryForces,
    sink: &mut S,
) -> Energy {
    let h = md.dt;
    let accounts = EnergyAccounts {
        base_work: st.accounts.base_work - 0.5 * h * a_base * sums.base.sum(),
        damping_dissipated: st.accounts.damping_dissipated + 0.25 * h * sums.damp.sum(),
        contact_work: st.accounts.contact_work + sums.contact_work,
    };
    st.accounts = accounts;
    let energy = Energy {
        kinetic: 0.5 * sums.kin.sum(),
        potential: 0.5 * sums.pot.sum(),
        potential_mid: 0.5 * sums.mid.sum(),
        boundary: 0.5 * forces.boundary2,
        accounts,
    };
    let solve = contact.solve;
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
            open: md.n_pairs - stick - slip,
            stick,
            slip,
            any_closed: contact.any_closed,
            normal_force: forces.normal,
            tangential_force: forces.tangential,
        },
        solve,
        energy,
    });
    energy
}

/// Commits the new state: `eta^{j+1}`, `v^{j+1/2}`, the forces, the closed pairs and their
/// boundary displacement, the step count.
#[inline(always)]
pub(super) fn commit(ws: &mut Workspace, st: &mut State, contact: &ContactOutcome) {
    std::mem::swap(&mut st.eta, &mut ws.eta_next);
    std::mem::swap(&mut st.eta_dot, &mut ws.v_new);
    if contact.solve.is_some() {
        st.lambda.copy_from_slice(&ws.lambda);
    } else {
        for &k in &st.closed {
            st.lambda[3 * k..3 * k + 3].fill(0.0);
        }
    }
    std::mem::swap(&mut st.closed, &mut ws.closed_new);
    if contact.any_closed {
        std::mem::swap(&mut st.g_lambda, &mut ws.g_lambda_new);
    }
    st.step += 1;
}

/// Marks the committed state as produced by a finite step ([`Verified`]), so the next step
/// skips the scan for non-finite values. The step's modal state is finite when its kinetic and
/// potential energies are (every entry enters them squared, and `0 * inf` is NaN); the forces
/// are finite on the solved pairs (the others keep the step's start state's, which was checked
/// or verified before the step, or are cleared); the boundary displacement is a sum of finite
/// forces times `G_res` rows, finite with the closed pairs' boundary energy.
#[inline(always)]
pub(super) fn verify(ws: &Workspace, st: &mut State, finite: bool, energy: &Energy) {
    let forces_finite = ws
        .cand
        .iter()
        .all(|&k| st.lambda[3 * k..3 * k + 3].iter().all(|l| l.is_finite()));
    st.verified = Verified(finite && forces_finite && energy.boundary.is_finite());
}
