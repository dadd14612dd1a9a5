//! Input checks of the integrator and the errors they raise ([`SimError`]): the ROM's sizes
//! and values, the time step against the stability limit the coupling relies on, and a state
//! against the ROM it is used with.

use crate::rom::Rom;

use super::super::error::SimError;
use super::limits::StabilityLimits;
use super::parameters::Coupling;
use super::{Integrator, State};

impl Integrator {
    /// Checks that a state belongs to this ROM (sizes) and is finite.
    ///
    // NOTE: a state that a finite step of an integrator produced (`State::verified`) is finite
    // and its closed pairs are pairs of a ROM with its sizes, so only the sizes are checked
    // (the twin and the simulated rig step one sample at a time: the full scan before every
    // step took 3-4 % of the simulated rig's time in held contact, issue 16).
    pub fn check_state(&self, state: &State) -> Result<(), SimError> {
        let (m, nb) = (self.model.m, 3 * self.model.n_pairs);
        for (what, v, expected) in [
            ("eta", &state.eta, m),
            ("eta_dot", &state.eta_dot, m),
            ("lambda", &state.lambda, nb),
            ("g_lambda", &state.g_lambda, nb),
        ] {
            if v.len() != expected {
                return Err(SimError::StateDimension {
                    what,
                    found: v.len(),
                    expected,
                });
            }
        }
        if state.verified.0 {
            return Ok(());
        }
        for (what, v) in [
            ("eta", &state.eta),
            ("eta_dot", &state.eta_dot),
            ("lambda", &state.lambda),
            ("g_lambda", &state.g_lambda),
        ] {
            if let Some(index) = first_non_finite(v) {
                return Err(SimError::StateValue {
                    what,
                    index,
                    value: v[index],
                });
            }
        }
        if let Some(&k) = state.closed.iter().find(|&&k| k >= self.model.n_pairs) {
            return Err(SimError::StateDimension {
                what: "closed pair index",
                found: k,
                expected: self.model.n_pairs,
            });
        }
        // The open prediction takes the previous step's contact from the closed pairs alone
        // (predict.rs), as the step leaves a state: a positive normal force only on them.
        let n_pairs = self.model.n_pairs;
        if let Some(k) =
            (0..n_pairs).find(|&k| state.lambda[3 * k] > 0.0 && !state.closed.contains(&k))
        {
            return Err(SimError::StateValue {
                what: "lambda (a normal force on a pair the state does not list as closed)",
                index: 3 * k,
                value: state.lambda[3 * k],
            });
        }
        if !state.time.is_finite() {
            return Err(SimError::StateValue {
                what: "time",
                index: 0,
                value: state.time,
            });
        }
        Ok(())
    }
}

/// Index of the first non-finite entry of `v`, if any.
// NOTE: `step_loaded` checks the state before every step (the twin steps one sample at a
// time), about 1,200 entries on the default ROM; the early-exit scan took 5-6 % of the
// twin's time in held contact (perf, issue 16 fourth pass). The OR-reduction has no early
// exit and vectorises; the position is searched only when something is not finite.
#[inline]
fn first_non_finite(v: &[f64]) -> Option<usize> {
    if v.iter().fold(false, |bad, x| bad | !x.is_finite()) {
        v.iter().position(|x| !x.is_finite())
    } else {
        None
    }
}

/// Rejects a step at or beyond the limit the coupling relies on.
pub(super) fn check_time_step(
    dt: f64,
    limits: &StabilityLimits,
    coupling: Coupling,
    enforce_closed: bool,
) -> Result<(), SimError> {
    let steps_given = 2.0 * std::f64::consts::PI / (limits.omega_ref * dt);
    if !(dt < limits.dt_max_open()) {
        return Err(SimError::TimeStepTooLarge {
            dt,
            dt_max: limits.dt_max_open(),
            omega_max: limits.omega_open,
            steps_given,
            steps_needed: limits.steps_per_period_open(),
            limit: "with all pairs open",
            hint: "; use a smaller dt (more steps per period)",
        });
    }
    if coupling == Coupling::Explicit && enforce_closed && !(dt < limits.dt_max_closed()) {
        return Err(SimError::TimeStepTooLarge {
            dt,
            dt_max: limits.dt_max_closed(),
            omega_max: limits.omega_closed,
            steps_given,
            steps_needed: limits.steps_per_period_closed(),
            limit: "with all pairs closed (Explicit coupling)",
            hint: "; use Coupling::EndOfStep, which needs only the open limit, or a smaller dt",
        });
    }
    Ok(())
}

/// Checks the ROM's sizes and values; returns (modes, pairs).
pub(super) fn check_rom(rom: &Rom) -> Result<(usize, usize), SimError> {
    let m = rom.omega.len();
    let n = rom.pair_area.len();
    let nb = 3 * n;
    if m == 0 {
        return Err(SimError::RomDimension {
            what: "omega (modes)".into(),
            found: 0,
            expected: 1,
        });
    }
    let dim = |what: String, found: usize, expected: usize| {
        if found == expected {
            Ok(())
        } else {
            Err(SimError::RomDimension {
                what,
                found,
                expected,
            })
        }
    };
    dim("damping_ratio".into(), rom.damping_ratio.len(), m)?;
    dim("beta".into(), rom.beta.len(), m)?;
    dim(
        "phi_g rows (3 x pairs; pairs = pair_area.len())".into(),
        rom.phi_g.nrows(),
        nb,
    )?;
    dim("phi_g columns (modes)".into(), rom.phi_g.ncols(), m)?;
    dim("g_res rows (3 x pairs)".into(), rom.g_res.nrows(), nb)?;
    dim("g_res columns (3 x pairs)".into(), rom.g_res.ncols(), nb)?;
    if rom.meta.reference_mode >= m {
        return Err(SimError::RomValue {
            what: "meta.reference_mode",
            index: 0,
            value: rom.meta.reference_mode as f64,
            expected: "the index of the 1FU mode, below the number of modes",
        });
    }
    for (o, out) in rom.outputs.iter().enumerate() {
        dim(
            format!("outputs[{o}] ({}).c_eta", out.name),
            out.c_eta.len(),
            m,
        )?;
        dim(
            format!("outputs[{o}] ({}).c_lambda", out.name),
            out.c_lambda.len(),
            nb,
        )?;
        check_values("outputs.c_eta", &out.c_eta, |_| true, "finite")?;
        check_values("outputs.c_lambda", &out.c_lambda, |_| true, "finite")?;
    }
    check_values(
        "omega",
        &rom.omega,
        |w| w > 0.0,
        "a finite circular frequency > 0 (rad/s)",
    )?;
    check_values(
        "damping_ratio",
        &rom.damping_ratio,
        |z| z >= 0.0,
        "a finite damping ratio >= 0",
    )?;
    check_values("beta", &rom.beta, |_| true, "finite")?;
    let phi: Vec<f64> = (0..nb)
        .flat_map(|r| (0..m).map(move |i| (r, i)))
        .map(|(r, i)| rom.phi_g[(r, i)])
        .collect();
    check_values("phi_g", &phi, |_| true, "finite")?;
    let g: Vec<f64> = (0..nb)
        .flat_map(|r| (0..nb).map(move |s| (r, s)))
        .map(|(r, s)| rom.g_res[(r, s)])
        .collect();
    check_values("g_res", &g, |_| true, "finite")?;
    let scale = g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    for r in 0..nb {
        for s in r + 1..nb {
            let (u, l) = (g[r * nb + s], g[s * nb + r]);
            // NOTE: round-off from building G_res is symmetrised away; a relative asymmetry
            // above 1e-8 means a wrong matrix, not round-off.
            if (u - l).abs() > 1e-8 * scale {
                return Err(SimError::RomFlexibility {
                    detail: format!(
                        "G_res[{r},{s}] = {u:e} but G_res[{s},{r}] = {l:e} (not symmetric)"
                    ),
                });
            }
        }
    }
    check_values(
        "clearance",
        &[rom.clearance],
        |_| true,
        "a finite clearance (m)",
    )?;
    check_values(
        "friction",
        &[rom.friction],
        |mu| mu >= 0.0,
        "a finite friction coefficient >= 0",
    )?;
    Ok((m, n))
}

/// The first entry of `v` that is not finite or not `ok`, as a [`SimError::RomValue`].
fn check_values(
    what: &'static str,
    v: &[f64],
    ok: impl Fn(f64) -> bool,
    expected: &'static str,
) -> Result<(), SimError> {
    match v.iter().position(|&x| !(x.is_finite() && ok(x))) {
        Some(index) => Err(SimError::RomValue {
            what,
            index,
            value: v[index],
            expected,
        }),
        None => Ok(()),
    }
}
