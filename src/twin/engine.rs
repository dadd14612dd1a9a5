//! The twin's synchronous core ([`Twin`]): the ROM integrator (end-of-step contact coupling,
//! fixed `dt`) driven step by step by the measured base acceleration, block by block, with
//! outputs per DAQ sample on the measurement's time base. No threads, no clock; the same
//! blocks give the same bits (replay relies on it).
//!
//! Time base and resampling. With `N` twin steps per DAQ sample (`dt = 1 / (N fs)`), sample
//! `i` at `t_i` drives the `N` steps that start at `t_{i-1} + k dt`, `k = 1..=N`, the last one
//! starting exactly at `t_i`. Each step takes the base acceleration at its start time,
//! interpolated linearly between the samples `i - 1` and `i`:
//! `a(t_{i-1} + k dt) = (1 - k/N) a_{i-1} + (k/N) a_i` (`a_i` itself for `k = N`). So the
//! twin needs no future sample (causal, no delay) and its output for sample `i` stands at
//! `t_i`: the relative velocities are the mean of the half-step velocities at `t_i - dt/2`
//! and `t_i + dt/2` (the last two steps), the definition the simulated rig's sensors use;
//! contact and mean forces cover the `N` steps that start in `(t_{i-1}, t_i]` (the sample
//! interval ending at `t_i`, one twin step later). Sample `i` of a [`TwinBlock`] is sample `i`
//! of the input block.
//!
//! Model extensions and observation. The twin ROM carries the `[model]` extensions
//! ([`crate::sim::effects`]: modal corrections, clamp friction, clearance per test, wear,
//! tilt), and its prediction passes through the rig's channels ([`super::observe`]): the
//! measured base acceleration without the platform accelerometers' declared sensitivity
//! errors, and the contact state through the contact-resistance circuit and threshold per
//! sample.
//!
//! Start and gaps. The twin starts at rest. For the first sample of the stream, and the first
//! sample after a gap, there is no previous sample: the base acceleration is held at that
//! sample over its `N` steps. After a gap (a block whose first sample does not follow the
//! last one) the twin keeps its state or restarts at rest (`[twin] after_gap`) and reports
//! the gap in the block's output. A block that starts before the end of the last one is
//! rejected (the state is left as it was).

use crate::config::PhysicsSpec;
use crate::physics::contact_detection::SampleDetector;
use crate::rig::daq::{DaqBlock, DaqLayout};
use crate::sim::driven::{DrivenError, DrivenRom, SensorStep};
use crate::sim::effects::{self, Effects};
use crate::sim::{StabilityLimits, TimeStep};

use super::error::{BlockError, TwinError};
use super::input::{InputMap, TwinInput};
use super::model::TwinModel;
use super::observe::Observation;
use super::output::{TwinBlock, TwinGap, TWIN_SENSORS};
use super::spec::{AfterGap, TwinSpec};
use super::state::{StateError, TwinState};

/// Cumulative counters of a [`Twin`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwinCounters {
    /// Blocks processed.
    pub blocks: u64,
    /// Samples processed.
    pub samples: u64,
    /// Twin steps done.
    pub steps: u64,
    /// Gaps in the input resumed after.
    pub gaps: u64,
    /// Contact solves that stopped at the sweep limit or diverged.
    pub solver_failures: u64,
    /// Restarts at rest after a non-finite state.
    pub restarts: u64,
}

/// The contact of one sample: what its twin steps' contact forces add up to.
#[derive(Clone, Copy, Debug, Default)]
struct SampleContact {
    normal: f64,
    tangential: f64,
}

impl SampleContact {
    /// Adds one twin step.
    #[inline]
    fn add(&mut self, step: &SensorStep<4>) {
        if step.contact.any_closed {
            self.normal += step.contact.normal_force;
            self.tangential += step.contact.tangential_force;
        }
    }
}

/// The live twin's synchronous core. See the module docs for the time base.
#[derive(Clone, Debug)]
pub struct Twin {
    /// The twin ROM driven by the measured base acceleration, read at [`TWIN_SENSORS`] (its
    /// last step's relative velocities stand at the half step before the next sample).
    rom: DrivenRom<4>,
    /// The `[model]` extensions acting during the integration (clamp friction, wear) and the
    /// clearance they act on.
    effects: Effects,
    /// The contact state as the contact channel detects it.
    detector: SampleDetector,
    /// How the prediction is observed through the rig's channels.
    observation: Observation,
    map: InputMap,
    /// The model's identity in warm-start states ([`TwinState::model`]).
    identity: String,
    /// The same without the contact's geometry ([`Twin::set_open_state`]).
    open_identity: String,
    /// The ROM's part of both.
    rom_identity: String,
    after_gap: AfterGap,
    steps_per_sample: u32,
    /// `k / N` for `k = 1..=N`.
    weights: Vec<f64>,
    /// Base acceleration of the last sample processed (none at the start and after a reset).
    last_accel: Option<f64>,
    /// The sample the next block should start with, and the last block's sequence number.
    next_sample: Option<u64>,
    last_seq: u64,
    counters: TwinCounters,
}

impl Twin {
    /// The twin of `model` (ROM, `[model]` extensions, contact observation), settings `spec`,
    /// the DAQ stream `layout` and clearance `clearance_m` (m), at rest. Checks the spec, the
    /// layout (platform accelerometers; the channels the extensions name), the ROM (the beam
    /// sensor outputs [`TWIN_SENSORS`], sizes and values; the modes and outputs the extensions
    /// need) and the twin step against the (corrected) ROM's open stability limit; errors name
    /// the key or what is missing.
    pub fn new(
        model: &TwinModel<'_>,
        spec: &TwinSpec,
        layout: &DaqLayout,
        clearance_m: f64,
    ) -> Result<Twin, TwinError> {
        spec.validate()?;
        let observation = Observation::new(
            layout,
            &model.extensions,
            &model.circuit,
            model.contact_threshold_v,
        )?;
        let map = InputMap::with_gains(layout, &observation.platform_gains)?;
        if !clearance_m.is_finite() {
            return Err(TwinError::Clearance(clearance_m));
        }
        let model_rom = &*effects::prepare(model.rom, &model.extensions, "model")?;
        // A provisional step far inside any stability limit lets the integrator check the ROM
        // and compute its limits; the twin step follows from them.
        let mut rom = DrivenRom::provisional(model_rom, TWIN_SENSORS).map_err(|e| match e {
            DrivenError::Output(missing) => TwinError::Rom(missing),
            DrivenError::Sim(e) => e.into(),
        })?;
        let limits = *rom.limits();
        let fs = map.sample_rate();
        let n = spec.steps_per_sample_for(fs, limits.omega_ref);
        let dt = 1.0 / (fs * f64::from(n));
        if !(dt < limits.dt_max_open()) {
            let key = spec.step_key();
            let value = match spec.steps_per_sample {
                Some(s) => s.to_string(),
                None => format!(
                    "{} (-> {n} steps per sample)",
                    spec.steps_per_reference_period
                ),
            };
            return Err(TwinError::StepBeyondLimit {
                key,
                value,
                sample_rate: fs,
                steps_per_sample: n,
                dt,
                dt_max: limits.dt_max_open(),
                omega_open: limits.omega_open,
                steps_per_period: limits.steps_per_period_open(),
                min_steps_per_sample: (1.0 / (fs * limits.dt_max_open())).floor() + 1.0,
            });
        }
        rom.set_time_step(TimeStep::Dt { dt })?;
        let effects = Effects::new(model_rom, &model.extensions, "model", clearance_m)?;
        effects.attach(&mut rom)?;
        let detector =
            SampleDetector::new(&observation.circuit, dt, observation.contact_threshold_v);
        let weights = (1..=n).map(|k| f64::from(k) / f64::from(n)).collect();
        let rom_identity = format!(
            "ROM {} ({} modes, {} pairs)",
            model.rom.meta.config_hash,
            model.rom.n_modes(),
            model.rom.n_pairs(),
        );
        let open_identity = identity(
            &rom_identity,
            &model.extensions.without_contact_geometry(),
            dt,
        );
        let identity = identity(&rom_identity, &model.extensions, dt);
        Ok(Twin {
            rom,
            effects,
            detector,
            observation,
            map,
            identity,
            open_identity,
            rom_identity,
            after_gap: spec.after_gap,
            steps_per_sample: n,
            weights,
            last_accel: None,
            next_sample: None,
            last_seq: 0,
            counters: TwinCounters::default(),
        })
    }

    /// How the prediction is observed through the rig's channels.
    pub fn observation(&self) -> &Observation {
        &self.observation
    }

    /// The twin step, s.
    pub fn dt(&self) -> f64 {
        self.rom.dt()
    }

    /// Twin steps per DAQ sample.
    pub fn steps_per_sample(&self) -> u32 {
        self.steps_per_sample
    }

    /// Sample rate of the input stream, Hz.
    pub fn sample_rate(&self) -> f64 {
        self.map.sample_rate()
    }

    /// The ROM's stability limits.
    pub fn limits(&self) -> &StabilityLimits {
        self.rom.limits()
    }

    /// How blocks are turned into the twin's input (for extracting it elsewhere, e.g. on the
    /// producer side of the twin task).
    pub fn input_map(&self) -> &InputMap {
        &self.map
    }

    /// Cumulative counters.
    pub fn counters(&self) -> TwinCounters {
        self.counters
    }

    /// The contact solver's cumulative counters (solves, sweeps, failures) since the twin
    /// was created or last restarted at rest.
    pub fn solver_counters(&self) -> crate::sim::SolverCounters {
        self.rom.state().counters()
    }

    /// The clearance in use, m.
    pub fn clearance(&self) -> f64 {
        self.rom.clearance()
    }

    /// The clearance set at start or by [`Twin::set_clearance`], m (without the growth a
    /// `[model.wear]` adds).
    pub fn nominal_clearance(&self) -> f64 {
        self.effects.nominal_clearance()
    }

    /// Changes the clearance (e.g. per test of a plan), m, from the next sample on; the state
    /// is kept.
    pub fn set_clearance(&mut self, clearance_m: f64) -> Result<(), TwinError> {
        if !clearance_m.is_finite() {
            return Err(TwinError::Clearance(clearance_m));
        }
        self.effects.set_clearance(&mut self.rom, clearance_m)?;
        Ok(())
    }

    /// The sample the next block is expected to start with (none before the first block).
    pub fn next_sample(&self) -> Option<u64> {
        self.next_sample
    }

    /// Rig time up to which the twin has produced outputs (end of its last block), s.
    pub fn time(&self) -> Option<f64> {
        self.next_sample.map(|n| n as f64 / self.map.sample_rate())
    }

    /// Back to rest, forgetting the stream position (the next block is taken as the first);
    /// the counters are kept.
    pub fn reset(&mut self) {
        self.rom.reset();
        self.effects.reset_state();
        self.detector.reset();
        self.last_accel = None;
        self.next_sample = None;
    }

    /// The state between two blocks, for a warm start ([`TwinState`]); `None` before the first
    /// block (a twin at rest needs none).
    pub fn state(&self) -> Option<TwinState> {
        Some(TwinState {
            model: self.identity.clone(),
            next_sample: self.next_sample?,
            last_seq: self.last_seq,
            last_accel: self.last_accel,
            rom: self.rom.state().clone(),
            last_velocity: self.rom.last().velocity,
            effects: self.effects.state(),
            contact_voltage: self.detector.voltage(),
        })
    }

    /// Restores a [`Twin::state`] of a twin of the same model: the next block is expected at
    /// its `next_sample`, and the twin continues as the captured one did, bit for bit. Fails,
    /// changing nothing, on a state of another model or one that does not fit. The counters
    /// are kept.
    pub fn set_state(&mut self, state: &TwinState) -> Result<(), TwinError> {
        if state.model != self.identity {
            return Err(StateError::Model {
                state: state.model.clone(),
                twin: self.identity.clone(),
            }
            .into());
        }
        if state.last_accel.is_some_and(|a| !a.is_finite()) {
            return Err(StateError::NonFinite("last_accel").into());
        }
        if !state.contact_voltage.is_finite() {
            return Err(StateError::NonFinite("contact_voltage").into());
        }
        // Checked before the effects change the ROM's clearance, so a misfit changes nothing.
        self.rom
            .check_state(&state.rom, &state.last_velocity)
            .map_err(StateError::from)?;
        // Changes nothing (the ROM's clearance included) unless it fits.
        self.effects
            .set_state(&mut self.rom, &state.effects)
            .map_err(StateError::from)?;
        self.rom
            .set_state(state.rom.clone(), state.last_velocity)
            .map_err(StateError::from)?;
        self.detector.set_voltage(state.contact_voltage);
        self.last_accel = state.last_accel;
        self.next_sample = Some(state.next_sample);
        self.last_seq = state.last_seq;
        Ok(())
    }

    /// Restores `state`, captured by a twin whose model differed from this one's at most in
    /// the contact's geometry (`captured_with`: its extensions; the clearance and the tilt may
    /// differ) before any pair had closed since rest. While the contact stays open the motion
    /// does not depend on that geometry, so this twin continues bit for bit as if it had run
    /// from rest with its own geometry, provided its own gaps stayed open up to there too
    /// (e.g. its geometry is nowhere closer than the captured one's: the caller's part). The
    /// clearance stays this twin's. Fails, changing nothing, when a pair had closed, when
    /// wear is on (its state depends on the contact), or when the models differ otherwise.
    pub fn set_open_state(
        &mut self,
        state: &TwinState,
        captured_with: &PhysicsSpec,
    ) -> Result<(), TwinError> {
        let captured = identity(&self.rom_identity, captured_with, self.dt());
        let open = identity(
            &self.rom_identity,
            &captured_with.without_contact_geometry(),
            self.dt(),
        );
        if captured != state.model || open != self.open_identity {
            return Err(StateError::Model {
                state: state.model.clone(),
                twin: self.identity.clone(),
            }
            .into());
        }
        if state.effects.wear.is_some() {
            return Err(StateError::Open("wear is on").into());
        }
        if state.rom.counters().closed_steps > 0 || state.rom.lambda().iter().any(|&l| l != 0.0) {
            return Err(StateError::Open("a contact pair had closed").into());
        }
        let mut own = state.clone();
        own.model = self.identity.clone();
        own.effects.nominal_clearance = self.effects.state().nominal_clearance;
        self.set_state(&own)
    }

    /// Resets the twin to rest, keeping of `state` (a state of a twin with the same
    /// extensions, possibly of another ROM or step: e.g. the comparison's discretisation
    /// member started from the twin's state) what the contact has made of the geometry: the
    /// clearance and the wear so far. The clamp joints' sliders start unslipped, as the beams
    /// are at rest. Fails, leaving the twin at rest with its own clearance, when the state's
    /// effects do not fit (other extensions).
    pub fn reset_keeping_geometry(&mut self, state: &TwinState) -> Result<(), TwinError> {
        self.reset();
        let mut effects = self.effects.state();
        effects.nominal_clearance = state.effects.nominal_clearance;
        effects.wear = state.effects.wear;
        self.effects
            .set_state(&mut self.rom, &effects)
            .map_err(StateError::from)?;
        Ok(())
    }

    /// Runs the twin over one DAQ block (see the module docs). Fails, leaving the twin as it
    /// was, on a block that does not fit the layout or starts before the end of the last one.
    pub fn push_block(&mut self, block: &DaqBlock) -> Result<TwinBlock, TwinError> {
        let input = self.map.extract(block)?;
        self.push_input(&input)
    }

    /// Runs the twin over the base acceleration of one block (from [`InputMap::extract`] of
    /// this twin's map; [`Twin::push_block`] does both). Fails, leaving the twin as it was, on
    /// an empty or non-finite input or one that starts before the end of the last block.
    pub fn push_input(&mut self, input: &TwinInput) -> Result<TwinBlock, TwinError> {
        let len = input.len();
        if len == 0 {
            return Err(BlockError::Empty { seq: input.seq }.into());
        }
        if let Some(i) = input.base_acceleration.iter().position(|a| !a.is_finite()) {
            return Err(BlockError::NonFinite {
                seq: input.seq,
                sample: i,
                value: input.base_acceleration[i],
            }
            .into());
        }
        let fs = self.map.sample_rate();
        let gap = match self.next_sample {
            None => None,
            Some(expected) if input.first_sample == expected => None,
            Some(expected) if input.first_sample > expected => Some(TwinGap {
                from_sample: expected,
                samples: input.first_sample - expected,
                blocks: input.seq.saturating_sub(self.last_seq + 1),
                from_time: expected as f64 / fs,
                restarted: self.after_gap == AfterGap::RestartAtRest,
            }),
            Some(expected) => {
                return Err(BlockError::OutOfOrder {
                    seq: input.seq,
                    first_sample: input.first_sample,
                    next_sample: expected,
                }
                .into());
            }
        };
        if let Some(g) = &gap {
            self.counters.gaps += 1;
            self.last_accel = None;
            if g.restarted {
                self.rom.reset();
                self.effects.reset_state();
                self.detector.reset();
            }
        }

        let mut out = TwinBlock {
            seq: input.seq,
            first_sample: input.first_sample,
            time: input.time,
            len,
            velocity: vec![0.0; 4 * len],
            base_acceleration: input.base_acceleration.clone(),
            contact: vec![false; len],
            normal_force: vec![0.0; len],
            tangential_force: vec![0.0; len],
            solver_failures: vec![0; len],
            gap,
            restarts: Vec::new(),
        };
        let n = self.steps_per_sample as usize;
        let inv_n = 1.0 / n as f64;
        for (i, &a_i) in input.base_acceleration.iter().enumerate() {
            let a_prev = self.last_accel.unwrap_or(a_i);
            let mut contact = SampleContact::default();
            let mut before = self.rom.last().velocity;
            let mut failures = 0u32;
            for (k, &w) in self.weights.iter().enumerate() {
                if k + 1 == n {
                    before = self.rom.last().velocity;
                }
                let a = (1.0 - w) * a_prev + w * a_i;
                let load = self.effects.loads(self.rom.state().eta());
                let report = self.rom.step_loaded(a, load)?;
                self.effects.after_step(&mut self.rom);
                let last = self.rom.last();
                contact.add(last);
                self.detector.step(last.contact.any_closed);
                let c = report.counters;
                failures += (c.max_iterations + c.diverged) as u32;
                if report.stop.is_some() {
                    // NOTE: non-finite state: data, not an error. Restart at rest and go on.
                    self.rom.reset();
                    self.effects.reset_state();
                    self.detector.reset();
                    before = [0.0; 4];
                    contact = SampleContact::default();
                    self.counters.restarts += 1;
                    out.restarts.push(input.first_sample + i as u64);
                }
            }
            let after = &self.rom.last().velocity;
            for (s, (&b, &v)) in before.iter().zip(after).enumerate() {
                out.velocity[s * len + i] = 0.5 * (b + v);
            }
            out.contact[i] = self.detector.sample();
            out.normal_force[i] = contact.normal * inv_n;
            out.tangential_force[i] = contact.tangential * inv_n;
            out.solver_failures[i] = failures;
            self.counters.solver_failures += u64::from(failures);
            self.last_accel = Some(a_i);
        }
        self.counters.blocks += 1;
        self.counters.samples += len as u64;
        self.counters.steps += (len * n) as u64;
        self.next_sample = Some(input.first_sample + len as u64);
        self.last_seq = input.seq;
        Ok(out)
    }
}

/// A model's identity in warm-start states: its ROM's (`rom`), extensions `ext`, twin step
/// `dt` (s).
fn identity(rom: &str, ext: &PhysicsSpec, dt: f64) -> String {
    format!("{rom}, extensions {}, dt {dt:e} s", ext.to_json())
}
