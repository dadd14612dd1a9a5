//! The physics effects that act while a driven ROM is integrated ([`Effects`]): the clamp
//! joints (a modal load evaluated before each step), wear (the clearance after each step, from
//! the step's normal contact impulse) and
//! the nominal clearance they grow on, with the ROM prepared for them ([`prepare`]: modal
//! corrections, tilt gap offsets). One composition for the simulated rig's truth (its hidden
//! `[truth.variants]`) and the model (its declared `[model]`): both step the same code.
//!
//! With every effect off, a prepared ROM is the nominal one and a step with [`Effects`] does
//! exactly what it did without them (bit for bit).

use std::borrow::Cow;

use crate::physics::iwan::ClampJoint;
use crate::physics::wear::Wear;
use crate::physics::{modal, tilt, PhysicsError, PhysicsSpec};
use crate::rom::Rom;

use super::driven::{DrivenRom, SensorSink};
use super::error::SimError;
use super::excitation::Excitation;
use super::integrator::RunReport;

/// The ROM with the linear effects of `spec` applied (modal corrections; the nominal ROM
/// itself when there are none). Keys in errors are `<prefix>.<...>`.
pub fn prepare<'a>(
    rom: &'a Rom,
    spec: &PhysicsSpec,
    prefix: &str,
) -> Result<Cow<'a, Rom>, PhysicsError> {
    if spec.modes.is_empty() {
        return Ok(Cow::Borrowed(rom));
    }
    let mut corrected = rom.clone();
    modal::apply(&mut corrected, &spec.modes, prefix)?;
    Ok(Cow::Owned(corrected))
}

/// The effects that act during the integration, and the clearance they act on.
#[derive(Clone, Debug, PartialEq)]
pub struct Effects {
    /// Friction in the clamping joints.
    joint: Option<ClampJoint>,
    /// Clearance growth from wear.
    wear: Option<Wear>,
    /// Per-pair gap offsets of a tilted protrusion, m.
    gap_offsets: Option<Vec<f64>>,
    /// The clearance set at start or by [`Effects::set_clearance`], m (wear grows on top).
    nominal_clearance: f64,
}

/// What evolves in [`Effects`] (see [`Effects::state`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct EffectsState {
    /// The clamp joints' elements, one per beam (`None`: no clamp friction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<Vec<crate::physics::iwan::IwanState>>,
    /// The wear so far (`None`: no wear).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wear: Option<WearState>,
    /// The clearance set at start or by [`Effects::set_clearance`], m (wear grows on top).
    pub nominal_clearance: f64,
}

/// The wear so far.
#[derive(
    Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
pub struct WearState {
    /// `P`: the accumulated normal contact impulse, N s (`physics::wear`).
    pub impulse: f64,
    /// Clearance growth, m.
    pub growth: f64,
}

/// An [`EffectsState`] that does not fit the effects it is restored into.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("effects state does not fit: {0}")]
pub struct EffectsStateMismatch(pub &'static str);

impl Effects {
    /// The effects of `spec` (valid) on the prepared ROM `rom` (see [`prepare`]) at clearance
    /// `clearance_m` (m), at rest. Keys in errors are `<prefix>.<...>`.
    pub fn new(
        rom: &Rom,
        spec: &PhysicsSpec,
        prefix: &str,
        clearance_m: f64,
    ) -> Result<Effects, PhysicsError> {
        let joint = spec
            .clamp_friction
            .as_ref()
            .map(|c| ClampJoint::new(rom, c, prefix))
            .transpose()?;
        let wear = spec
            .wear
            .as_ref()
            .map(|w| Wear::new(w.coefficient, w.max_growth));
        let gap_offsets = spec
            .tilt
            .as_ref()
            .map(|t| tilt::gap_offsets(&rom.pair_position, &rom.pair_area, t));
        Ok(Effects {
            joint,
            wear,
            gap_offsets,
            nominal_clearance: clearance_m,
        })
    }

    /// Whether nothing acts during the integration (no clamp friction, no wear): a run is the
    /// driven ROM's own.
    pub fn is_inert(&self) -> bool {
        self.joint.is_none() && self.wear.is_none()
    }

    /// Runs `n_steps` steps of `rom` under `excitation` with the effects acting, handing every
    /// step's sensor values to `sink` (see [`DrivenRom::run`], which it is, bit for bit, when
    /// the effects are inert).
    ///
    // NOTE: with effects acting the steps are taken one by one at the excitation's value at
    // `t0 + i dt` (the run's own time grid); the state's time then accumulates `dt` step by
    // step like [`DrivenRom::step`] (a round-off of ~1e-16 relative per step on the clock only).
    pub fn run<const N: usize, S: SensorSink<N>>(
        &mut self,
        rom: &mut DrivenRom<N>,
        excitation: &Excitation,
        n_steps: u64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        if self.is_inert() {
            return rom.run(excitation, n_steps, sink);
        }
        excitation.validate()?;
        let t0 = rom.state().time();
        let dt = rom.dt();
        if n_steps > 0 {
            excitation.check_span(t0, t0 + (n_steps - 1) as f64 * dt)?;
        }
        let before = rom.state().counters();
        let mut done = 0;
        let mut stop = None;
        for i in 0..n_steps {
            let t = t0 + i as f64 * dt;
            let load = self.loads(rom.state().eta());
            let report = rom.step_loaded(excitation.accel_at(t), load)?;
            self.after_step(rom);
            sink.record(rom.last());
            done += 1;
            if let Some(s) = report.stop {
                stop = Some(s);
                break;
            }
        }
        Ok(RunReport {
            steps: done,
            stop,
            counters: rom.state().counters().since(&before),
        })
    }

    /// Sets the clearance and the gap offsets on `rom` (once, after its time step is set).
    pub fn attach<const N: usize>(&self, rom: &mut DrivenRom<N>) -> Result<(), SimError> {
        rom.set_clearance(self.effective_clearance(self.nominal_clearance))?;
        rom.set_gap_offsets(self.gap_offsets.as_deref())
    }

    fn effective_clearance(&self, nominal: f64) -> f64 {
        match self.wear.as_ref().map_or(0.0, Wear::growth) {
            g if g > 0.0 => nominal + g,
            _ => nominal,
        }
    }

    /// The clamp joints' modal load `(mode, force)` for the step about to start from the
    /// modal displacements `eta` (empty without clamp friction).
    #[inline]
    pub fn loads(&mut self, eta: &[f64]) -> &[(usize, f64)] {
        match &mut self.joint {
            Some(j) => j.update(eta),
            None => &[],
        }
    }

    /// After a step of `rom`: wear moves the clearance by the step's normal contact impulse.
    #[inline]
    pub fn after_step<const N: usize>(&mut self, rom: &mut DrivenRom<N>) {
        if let Some(w) = &mut self.wear {
            // The step's normal impulse: its integrated normal force (N) times the step, N s.
            let impulse = rom.last().contact.normal_force * rom.dt();
            if let Some(growth) = w.update(impulse) {
                // Finite: the nominal clearance is finite and the growth is capped or finite.
                let _ = rom.set_clearance(self.nominal_clearance + growth);
            }
        }
    }

    /// Changes the nominal clearance (finite, m) of `rom`; the wear grown so far stays on top.
    pub fn set_clearance<const N: usize>(
        &mut self,
        rom: &mut DrivenRom<N>,
        clearance_m: f64,
    ) -> Result<(), SimError> {
        rom.set_clearance(self.effective_clearance(clearance_m))?;
        self.nominal_clearance = clearance_m;
        Ok(())
    }

    /// The state back to rest with the ROM's (the clamp joints stuck at zero displacement);
    /// the clearance and the wear grown so far are the rig's, not the state's, and stay.
    pub fn reset_state(&mut self) {
        if let Some(j) = &mut self.joint {
            j.reset();
        }
    }

    /// The nominal clearance, m (without the wear growth).
    pub fn nominal_clearance(&self) -> f64 {
        self.nominal_clearance
    }

    /// Wear: the accumulated normal contact impulse `P` (N s) and the clearance growth (m) so
    /// far; `None` when the effect is off.
    pub fn wear(&self) -> Option<(f64, f64)> {
        self.wear.as_ref().map(|w| (w.impulse(), w.growth()))
    }

    /// What evolves in the effects (the joints' sliders, the wear so far) and the nominal
    /// clearance, for a warm start ([`Effects::set_state`]).
    pub fn state(&self) -> EffectsState {
        EffectsState {
            joint: self.joint.as_ref().map(ClampJoint::state),
            wear: self.wear.as_ref().map(|w| WearState {
                impulse: w.impulse(),
                growth: w.growth(),
            }),
            nominal_clearance: self.nominal_clearance,
        }
    }

    /// Restores [`Effects::state`] of effects like these (the same effects on, the same joint
    /// sizes) and sets the clearance it implies on `rom`. Fails, changing nothing, when it
    /// does not fit.
    pub fn set_state<const N: usize>(
        &mut self,
        rom: &mut DrivenRom<N>,
        state: &EffectsState,
    ) -> Result<(), EffectsStateMismatch> {
        let mismatch = |what: &'static str| Err(EffectsStateMismatch(what));
        if state.joint.is_some() != self.joint.is_some() {
            return mismatch("clamp friction on in one and off in the other");
        }
        if state.wear.is_some() != self.wear.is_some() {
            return mismatch("wear on in one and off in the other");
        }
        if !state.nominal_clearance.is_finite() {
            return mismatch("the clearance is not finite");
        }
        let mut next = self.clone();
        if let (Some(j), Some(s)) = (&mut next.joint, &state.joint) {
            if !j.set_state(s) {
                return mismatch("the clamp joints' sliders do not fit");
            }
        }
        if let (Some(w), Some(s)) = (&mut next.wear, &state.wear) {
            if !w.set_state(s.impulse, s.growth) {
                return mismatch("the wear state is negative or not finite");
            }
        }
        next.nominal_clearance = state.nominal_clearance;
        if rom
            .set_clearance(next.effective_clearance(next.nominal_clearance))
            .is_err()
        {
            return mismatch("the clearance is out of range");
        }
        *self = next;
        Ok(())
    }

    /// Clamp friction: energy dissipated in the joints so far, J; `None` when the effect is
    /// off.
    pub fn joint_dissipation(&self) -> Option<f64> {
        self.joint.as_ref().map(ClampJoint::dissipated)
    }
}
