//! The truth model: the ROM integrator (end-of-step coupling, fixed `dt`) coupled two-way to
//! the shaker. Per truth step the base acceleration is solved from the base equation with the
//! beams' modal reaction, the ROM steps under it, then base and coil advance.
//!
//! Base equation: `M a_b + sum_i beta_i eta_i'' = F`, `F = Bl i - k x_b - c v_b`. The
//! integrator's damped leapfrog gives the modal acceleration of the step as
//! `eta_i'' = (v_i^{j+1/2} - v_i^{j-1/2}) / dt = alpha_i (F_i - beta_i a_b)`,
//! `F_i = -D_i v_i^{j-1/2} - omega_i^2 eta_i^j + (Phi_g^T lambda)_i`, `alpha_i = 1 / (1 + D_i dt / 2)`,
//! so `(M - sum_i alpha_i beta_i^2 + c dt / 2) a_b = Bl i - k x_b - c v_b^{j-1/2} - sum_i alpha_i beta_i F_i`
//! (the suspension damping averaged over the half steps like the modal damping).
//!
// NOTE (momentum balance): with `alpha_i` the base sees exactly the modal acceleration the
// integrator then applies, so base and beams exchange momentum consistently step by step;
// `alpha_i = 1` (the continuous equation) would leave an O(D dt) mismatch per step.
//
// NOTE (contact forces): the contact forces are internal to the beams: their direct load on
// the base, `b^T f`, is zero, and their modal part `sum_i beta_i (Phi_g^T lambda)_i` tends to
// zero as the modes become complete (~0 for the truth ROM). It is kept for consistency with
// the truncated modal reaction but taken from the previous step (`lambda` of this step is only
// known after the modal step): a one-step lag on a term that is nearly zero.
//
// NOTE (truth variants): the effects are the model's ([`crate::sim::effects`]): modal
// corrections change the truth ROM before anything is computed from it; the clamp joint's
// modal load `f_load` (see `physics::iwan`) is evaluated at `eta^j` before the step and enters
// both the modal step and `F_i` above, so the base sees the modal acceleration the integrator
// applies. Wear moves the clearance after a step (from that step's normal contact impulse); a
// tilt sets per-pair gap offsets once. With every variant off the step does exactly what it
// did without them.

use crate::rom::Rom;
use crate::sim::driven::{DrivenError, DrivenRom};
use crate::sim::effects::{self, Effects};
use crate::sim::{StabilityLimits, State, TimeStep};

use super::shaker::Shaker;
use super::variants::TruthVariants;
use super::{ShakerSpec, SimRigError};

/// The ROM outputs the beam sensors read, in channel order, and the upper tip's index among
/// them (the vibrometer's spot): the driven ROM's, [`crate::sim::driven`].
pub use crate::sim::driven::{BEAM_SENSORS, UPPER_TIP};

/// What one truth step produced: the physical quantities the sensors read.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepValues {
    /// Start time of the step `t^j`, s.
    pub time: f64,
    /// Base acceleration `a_b^j`, m/s^2.
    pub base_acceleration: f64,
    /// Base displacement `x_b^j`, m.
    pub base_displacement: f64,
    /// Base velocity before and after the step, `v_b^{j-1/2}`, `v_b^{j+1/2}`, m/s.
    pub base_velocity: [f64; 2],
    /// Relative velocities of the beam sensors ([`BEAM_SENSORS`]) before and after the step,
    /// at `t^{j-1/2}` and `t^{j+1/2}`, m/s.
    pub relative_velocity: [[f64; 4]; 2],
    /// Amplifier output `u^j`, V.
    pub amplifier_output: f64,
    /// Whether the amplifier clipped.
    pub clipped: bool,
    /// Coil current `i^j`, A.
    pub current: f64,
    /// Whether any contact pair was closed in the step.
    pub any_closed: bool,
}

/// The truth: ROM + shaker, stepped together.
#[derive(Clone, Debug)]
pub struct Truth {
    /// The ROM driven by the base acceleration, read at [`BEAM_SENSORS`].
    rom: DrivenRom<4>,
    shaker: Shaker,
    dt: f64,
    /// Per mode: `alpha_i beta_i`, `D_i = 2 zeta_i omega_i`, `omega_i^2`.
    alpha_beta: Vec<f64>,
    damping: Vec<f64>,
    omega2: Vec<f64>,
    /// `Phi_g (alpha .* beta)`, 3C: the contact term `sum_i alpha_i beta_i (Phi_g^T lambda)_i
    /// = lambda . p`.
    p: Vec<f64>,
    /// `1 / (M - sum_i alpha_i beta_i^2 + c dt / 2)`, 1/kg.
    inv_mass: f64,
    last: StepValues,
    steps: u64,
    failure: Option<String>,
    solver_failures: u64,
    /// The hidden physics acting during the integration (clamp friction, wear) and the
    /// clearance they act on.
    effects: Effects,
}

/// The ROM's stability limits with the base attached: the open bound becomes a bound on the
/// highest frequency of the coupled base-coil-modes system.
///
// NOTE: the mechanical part has the mass matrix `[[M, beta^T], [beta, I]]` and the stiffness
// `diag(k + Bl^2 / L, Omega^2)` (at high frequency the coil is an electrical spring: with
// `L di/dt = -Bl v`, `F = Bl i = -(Bl^2 / L) x`); its highest frequency satisfies
// `w^2 <= max(k + Bl^2 / L, max Omega^2) / mu_min`, `mu_min` the smallest eigenvalue of the
// mass matrix (it is 1 off the plane of the base and beta). The coil's resistive back-EMF acts
// on the base as a damper `Bl^2 / R` taken from the previous half step, stable for
// `dt < 2 mu_min R / Bl^2`, i.e. like a frequency `Bl^2 / (R mu_min)`. With the default
// shaker (M = 50 kg, |beta|^2 ~ 0.74 kg) mu_min ~ 0.985 and both coil terms are far below
// the modes, so the ROM's own bound moves by ~0.8 %; a moving mass close to sum(beta_i^2) makes
// the explicit base coupling stiff, and this keeps the step stable.
fn coupled_limits(
    limits: &StabilityLimits,
    shaker: &ShakerSpec,
    modal_mass: f64,
) -> StabilityLimits {
    let m = shaker.moving_mass;
    // Smallest eigenvalue of [[M, |beta|], [|beta|, 1]] as det / largest (no cancellation).
    let mu_max = 0.5 * (m + 1.0) + (0.25 * (m - 1.0) * (m - 1.0) + modal_mass).sqrt();
    let mu_min = (m - modal_mass) / mu_max;
    let bl2 = shaker.force_constant * shaker.force_constant;
    let k = shaker.suspension_stiffness + bl2 / shaker.coil_inductance;
    let w_elastic = (k.max(limits.omega_open * limits.omega_open) / mu_min).sqrt();
    let w_damping = bl2 / (shaker.coil_resistance * mu_min);
    StabilityLimits {
        omega_open: w_elastic.max(w_damping).max(limits.omega_open),
        ..*limits
    }
}

impl Truth {
    /// The truth for ROM `rom`, shaker `shaker`, clearance `clearance_m` (m) and the hidden
    /// physics `variants` (valid), at rest. The truth step (s) is chosen by `choose_dt` from
    /// the ROM's stability limits (the ROM is checked by the integrator before its limits are
    /// computed).
    pub fn new(
        rom: &Rom,
        shaker: &ShakerSpec,
        clearance_m: f64,
        variants: &TruthVariants,
        choose_dt: impl FnOnce(&StabilityLimits) -> Result<f64, SimRigError>,
    ) -> Result<Truth, SimRigError> {
        // Hidden modal corrections change the truth ROM itself.
        let rom = &*effects::prepare(rom, variants, "truth.variants")?;
        // A provisional step far inside any stability limit lets the integrator check the ROM
        // and compute its limits; the real step follows from them.
        let mut driven = DrivenRom::provisional(rom, BEAM_SENSORS).map_err(|e| match e {
            DrivenError::Output(missing) => SimRigError::Rom(format!(
                "the truth ROM has no output {:?} (outputs: {:?}); the beam accelerometers \
                 and the vibrometer read the outputs {BEAM_SENSORS:?}",
                missing.name, missing.available
            )),
            DrivenError::Sim(e) => e.into(),
        })?;
        let modal_mass: f64 = rom.beta.iter().map(|b| b * b).sum();
        if !(shaker.moving_mass > modal_mass) {
            return Err(SimRigError::Spec(format!(
                "shaker.moving_mass = {}: expected more than the beams' modal mass \
                 sum(beta_i^2) = {modal_mass:.4} kg of the truth ROM (the moving mass includes \
                 the beams)",
                shaker.moving_mass
            )));
        }
        let limits = coupled_limits(driven.limits(), shaker, modal_mass);
        let dt = choose_dt(&limits)?;
        driven.set_time_step(TimeStep::Dt { dt })?;
        let effects = Effects::new(rom, variants, "truth.variants", clearance_m)?;
        effects.attach(&mut driven)?;

        let m = rom.n_modes();
        let damping: Vec<f64> = (0..m)
            .map(|i| 2.0 * rom.damping_ratio[i] * rom.omega[i])
            .collect();
        let alpha_beta: Vec<f64> = (0..m)
            .map(|i| rom.beta[i] / (1.0 + 0.5 * damping[i] * dt))
            .collect();
        // alpha_i < 1: at least the free mass checked above.
        let free_mass = shaker.moving_mass
            - alpha_beta
                .iter()
                .zip(&rom.beta)
                .map(|(a, b)| a * b)
                .sum::<f64>();
        let nb = 3 * rom.n_pairs();
        let p: Vec<f64> = (0..nb)
            .map(|r| (0..m).map(|i| rom.phi_g[(r, i)] * alpha_beta[i]).sum())
            .collect();
        let shaker_model = Shaker::new(shaker, dt);
        let inv_mass = 1.0 / (free_mass + 0.5 * shaker_model.damping() * dt);
        Ok(Truth {
            rom: driven,
            shaker: shaker_model,
            dt,
            alpha_beta,
            damping,
            omega2: rom.omega.iter().map(|w| w * w).collect(),
            p,
            inv_mass,
            last: StepValues::default(),
            steps: 0,
            failure: None,
            solver_failures: 0,
            effects,
        })
    }

    /// The truth step, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// One truth step with amplifier input `drive_v` (V). After a failure (see
    /// [`Truth::failure`]) the truth is frozen and every step reads zero.
    #[inline]
    pub fn step(&mut self, drive_v: f64) -> StepValues {
        let time = self.steps as f64 * self.dt;
        self.steps += 1;
        if self.failure.is_some() {
            return StepValues {
                time,
                ..StepValues::default()
            };
        }
        let (u, clipped) = self.shaker.amplifier(drive_v);

        // Clamp joint (variant): its modal load at eta^j.
        let load = self.effects.loads(self.rom.state().eta());

        // Base acceleration from the base equation (see the module docs).
        let state = self.rom.state();
        let eta = state.eta();
        let v = state.eta_dot();
        let mut modal = 0.0;
        for i in 0..eta.len() {
            let f = -self.damping[i] * v[i] - self.omega2[i] * eta[i];
            modal += self.alpha_beta[i] * f;
        }
        for &(i, f) in load {
            modal += self.alpha_beta[i] * f;
        }
        let lambda = state.lambda();
        for &k in state.closed_pairs() {
            let rows = 3 * k..3 * k + 3;
            for (p, l) in self.p[rows.clone()].iter().zip(&lambda[rows]) {
                modal += p * l;
            }
        }
        let v_prev = self.shaker.velocity_half();
        let x_b = self.shaker.displacement();
        let current = self.shaker.current();
        let a_b = (self.shaker.elastic_and_coil_force() - self.shaker.damping() * v_prev - modal)
            * self.inv_mass;
        if !a_b.is_finite() {
            return self.fail(time, "the base acceleration");
        }

        let before = self.rom.last().velocity;
        match self.rom.step_loaded(a_b, load) {
            Ok(report) => {
                self.solver_failures += report.counters.max_iterations + report.counters.diverged;
                if report.stop.is_some() {
                    return self.fail(time, "the modal state");
                }
            }
            Err(e) => {
                self.failure = Some(format!(
                    "truth model failed at t = {time:.6} s: {e}; the simulated rig stopped"
                ));
                return StepValues {
                    time,
                    ..StepValues::default()
                };
            }
        }
        self.shaker.advance(a_b, u);
        if !self.shaker.is_finite() {
            return self.fail(time, "the shaker state");
        }
        self.effects.after_step(&mut self.rom);
        let after = *self.rom.last();
        self.last = StepValues {
            time,
            base_acceleration: a_b,
            base_displacement: x_b,
            base_velocity: [v_prev, self.shaker.velocity_half()],
            relative_velocity: [before, after.velocity],
            amplifier_output: u,
            clipped,
            current,
            any_closed: after.contact.any_closed,
        };
        self.last
    }

    #[cold]
    fn fail(&mut self, time: f64, what: &str) -> StepValues {
        self.failure = Some(format!(
            "truth model became non-finite at t = {time:.6} s ({what}); the simulated rig \
             stopped: lower the drive or check the truth ROM and shaker parameters"
        ));
        StepValues {
            time,
            ..StepValues::default()
        }
    }

    /// Why the truth stopped, if it did (latched).
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// The values of the last good step.
    pub fn last(&self) -> &StepValues {
        &self.last
    }

    /// Truth steps done.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Contact solves that stopped at the sweep limit or diverged.
    pub fn solver_failures(&self) -> u64 {
        self.solver_failures
    }

    /// The clearance in use, m (the nominal one plus the wear growth).
    pub fn clearance(&self) -> f64 {
        self.rom.clearance()
    }

    /// Changes the nominal clearance (finite, m); wear grown so far stays on top of it.
    pub fn set_clearance(&mut self, clearance_m: f64) -> Result<(), SimRigError> {
        Ok(self.effects.set_clearance(&mut self.rom, clearance_m)?)
    }

    /// Wear (variant): the accumulated normal contact impulse `P` (N s) and the clearance
    /// growth (m) so far; `None` when the variant is off.
    pub fn wear(&self) -> Option<(f64, f64)> {
        self.effects.wear()
    }

    /// Clamp friction (variant): energy dissipated in the joints so far, J; `None` when the
    /// variant is off.
    pub fn joint_dissipation(&self) -> Option<f64> {
        self.effects.joint_dissipation()
    }

    /// The integrator (gap offsets, clearance, limits), for tests and diagnostics.
    pub fn integrator(&self) -> &crate::sim::Integrator {
        self.rom.integrator()
    }

    /// The integrator state, for tests and diagnostics.
    pub fn state(&self) -> &State {
        self.rom.state()
    }

    /// The shaker (state and amplifier limit).
    pub fn shaker(&self) -> &Shaker {
        &self.shaker
    }

    /// Lowers the amplifier's output limit, V.
    pub fn set_amplifier_limit(&mut self, limit_v: f64) {
        self.shaker.set_limit_v(limit_v);
    }

    /// Makes the shaker state non-finite (tests of the failure path).
    #[cfg(test)]
    pub(crate) fn poison(&mut self) {
        self.shaker.poison();
    }

    /// Pairs closed in the last step.
    pub fn closed_pairs(&self) -> usize {
        self.rom.state().closed_pairs().len()
    }
}
