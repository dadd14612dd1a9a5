//! The simulated rig's synchronous core ([`SimRig`]): a truth ROM coupled two-way to an
//! electrodynamic shaker, physical sensors, and a DAQ that filters, decimates, adds noise and
//! quantises, block by block on virtual time. The async backend ([`backend`]: threads,
//! real-time pacing, the [`crate::rig::RigBackend`] impl) wraps it.
//!
//! Per DAQ sample, `oversampling` truth steps of `dt = 1 / (sample_rate * oversampling)`:
//! drive generator ([`drive`]) -> amplifier, coil, base and ROM ([`shaker`], [`truth`]) ->
//! channel values ([`sensors`]) -> anti-alias filter at the truth rate ([`filter`]) ->
//! decimation, noise and ADC ([`daq`]). Parameters live in [`spec`]; faults can be injected
//! at given rig times ([`InjectedFault`]). Physics the twin does not know (clamp friction,
//! wear, a tilted protrusion, sensor sensitivity errors) is switched on per variant in
//! `[truth.variants]` ([`variants`]); all off by default.
//!
//! Deterministic: the same ROM, spec, clearance, commands and injected faults give
//! bit-identical blocks. No clock, no I/O; the per-step loop does not allocate.

// NOTE: validation uses negated comparisons such as `!(dt < limit)` on purpose: they reject
// NaN together with out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod backend;
pub mod daq;
pub mod drive;
pub mod filter;
pub mod sensors;
pub mod shaker;
pub mod spec;
pub mod truth;
pub mod variants;

pub use backend::SimBackend;
pub use shaker::{base_acceleration_frf, BaseMode, Complex};
pub use spec::{
    ChannelNoise, ChannelRanges, ContactCircuitSpec, DaqSpec, ShakerSpec, SimRigSpec, TruthSpec,
};
pub use variants::{Beam, ClampFrictionSpec, SensorGainSpec, TiltSpec, TruthVariants, WearSpec};

use serde::{Deserialize, Serialize};

use crate::rig::daq::{CommandError, DaqBlock, DaqLayout, DriveCommand, DriveState, RigFault};
use crate::rig::RigError;
use crate::rom::Rom;
use crate::sim::SimError;

use self::daq::Daq;
use self::drive::DriveGenerator;
use self::sensors::Sensors;
use self::truth::Truth;

/// Why the simulated rig rejected its setup or a call.
#[derive(Debug, thiserror::Error)]
pub enum SimRigError {
    /// A spec value is out of range (names the key).
    #[error("simulated rig spec: {0}")]
    Spec(String),
    /// The truth ROM lacks something the simulated rig needs.
    #[error("simulated rig truth ROM: {0}")]
    Rom(String),
    /// A hidden effect does not fit the truth ROM or the DAQ channels (names the key).
    #[error("simulated rig truth ROM: {0}")]
    Physics(#[from] crate::physics::PhysicsError),
    /// The integrator rejected the truth ROM or its time step.
    #[error("simulated rig truth model: {0}")]
    Sim(#[from] SimError),
    /// A drive command out of range.
    #[error("drive command rejected: {0}")]
    Command(CommandError),
    /// An injected fault that cannot apply.
    #[error("injected fault rejected: {0}")]
    Fault(String),
}

impl From<SimRigError> for RigError {
    fn from(e: SimRigError) -> RigError {
        match e {
            SimRigError::Command(m) => RigError::command(m),
            other => RigError::config(other),
        }
    }
}

/// A fault injected into the simulated rig, active from the first DAQ sample at or after its
/// rig time `at_s` (s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum InjectedFault {
    /// The DAQ stops delivering: [`SimRig::stalled`] turns true once the next sample's time
    /// reaches `at_s` (the block holding `at_s` is still complete).
    DaqStall {
        /// Rig time, s.
        at_s: f64,
    },
    /// A channel reads 0 counts from then on.
    DeadChannel {
        /// Rig time, s.
        at_s: f64,
        /// The channel's name in the layout.
        channel: String,
    },
    /// The amplifier's output limit drops to `limit_v`.
    DriveSaturation {
        /// Rig time, s.
        at_s: f64,
        /// New output limit, V (>= 0).
        limit_v: f64,
    },
    /// The truth's clearance jumps (e.g. wear, a loosened probe).
    ClearanceChange {
        /// Rig time, s.
        at_s: f64,
        /// New clearance, m.
        clearance_m: f64,
    },
}

impl InjectedFault {
    /// Checks the fault's values before it is scheduled on a rig with beams of `beam_length_m`
    /// (m): a finite time >= 0, a finite amplifier limit >= 0, and a new clearance within the
    /// bounds a plan's clearance obeys ([`crate::plan::check_clearance`], as a fraction of
    /// the beam length). (The channel name is checked against the layout by
    /// [`SimRig::schedule`].)
    pub fn check(&self, beam_length_m: f64) -> Result<(), String> {
        let at_s = self.at_s();
        if !(at_s.is_finite() && at_s >= 0.0) {
            return Err(format!("at_s = {at_s}: expected a finite rig time >= 0 s"));
        }
        match self {
            InjectedFault::DriveSaturation { limit_v, .. }
                if !(limit_v.is_finite() && *limit_v >= 0.0) =>
            {
                Err(format!(
                    "drive_saturation: limit_v = {limit_v}: expected a finite limit >= 0 V"
                ))
            }
            InjectedFault::ClearanceChange { clearance_m, .. } => {
                crate::plan::check_clearance(clearance_m / beam_length_m).map_err(|expected| {
                    format!(
                        "clearance_change: clearance_m = {clearance_m} m ({:e} l on a \
                         {beam_length_m} m beam): expected {expected}",
                        clearance_m / beam_length_m
                    )
                })
            }
            _ => Ok(()),
        }
    }

    /// Activation time, s.
    pub fn at_s(&self) -> f64 {
        match *self {
            InjectedFault::DaqStall { at_s }
            | InjectedFault::DeadChannel { at_s, .. }
            | InjectedFault::DriveSaturation { at_s, .. }
            | InjectedFault::ClearanceChange { at_s, .. } => at_s,
        }
    }
}

/// The truth's state, for tests and diagnostics (never for control).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TruthSnapshot {
    /// Rig time of the next DAQ sample, s.
    pub time: f64,
    /// Truth steps done.
    pub truth_steps: u64,
    /// Truth step, s.
    pub dt: f64,
    /// Base displacement at the start of the last truth step, m.
    pub base_displacement: f64,
    /// Base velocity after the last truth step (half step), m/s.
    pub base_velocity: f64,
    /// Base acceleration of the last truth step, m/s^2.
    pub base_acceleration: f64,
    /// Coil current at the start of the last truth step, A.
    pub coil_current: f64,
    /// Amplifier output of the last truth step, V.
    pub amplifier_output: f64,
    /// Amplifier output limit in force, V.
    pub amplifier_limit_v: f64,
    /// Whether any pair was closed in the last truth step.
    pub contact_closed: bool,
    /// Pairs closed in the last truth step.
    pub closed_pairs: usize,
    /// Clearance in force, m (with the wear variant: the nominal clearance plus
    /// `clearance_growth`).
    pub clearance: f64,
    /// Wear variant: clearance growth so far, m (0 when off).
    pub clearance_growth: f64,
    /// Wear variant: accumulated normal contact impulse that drove it, N s (0 when off).
    pub wear_impulse: f64,
    /// Clamp-friction variant: energy dissipated in the clamping joints, J (0 when off).
    pub joint_dissipation: f64,
    /// Contact solves that stopped at the sweep limit or diverged.
    pub solver_failures: u64,
    /// Whether the truth stopped (non-finite state or solver error; see the Device fault).
    pub failed: bool,
}

/// Truth values at every DAQ sample instant (appended by [`SimRig::next_block_traced`]), for
/// tests and diagnostics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TruthTrace {
    /// Sample time, s.
    pub time: Vec<f64>,
    /// Base acceleration, m/s^2.
    pub base_acceleration: Vec<f64>,
    /// Base displacement, m.
    pub base_displacement: Vec<f64>,
    /// Coil current, A.
    pub coil_current: Vec<f64>,
    /// Amplifier output, V.
    pub amplifier_output: Vec<f64>,
    /// Truth steps of the sample period with at least one closed pair.
    pub closed_steps: Vec<u32>,
    /// Clearance in force after the sample period's truth steps, m.
    pub clearance: Vec<f64>,
    /// Relative velocities of the beam sensors ([`truth::BEAM_SENSORS`] order) at the sample
    /// instant, the mean of the truth's half-step velocities around it, m/s.
    pub relative_velocity: Vec<[f64; 4]>,
}

/// The simulated rig's deterministic core. See the module docs.
#[derive(Clone, Debug)]
pub struct SimRig {
    layout: DaqLayout,
    oversampling: u32,
    truth: Truth,
    sensors: Sensors,
    /// Hidden physics in use (for status and logs).
    variants: TruthVariants,
    /// Sensor-gain variant: `(channel, gain)`; empty when off.
    gains: Vec<(usize, f64)>,
    daq: Daq,
    drive: DriveGenerator,
    /// Channel values of the current truth step (layout order).
    values: Vec<f64>,
    faults: Vec<RigFault>,
    /// Amplifier limit of the last latched DriveSaturated fault.
    saturation_latched: Option<f64>,
    over_range_reported: Vec<bool>,
    failure_reported: bool,
    /// Injected faults not yet active (DaqStall excluded), by activation time.
    pending: Vec<InjectedFault>,
    /// Earliest scheduled DAQ stall, s.
    stall_at: Option<f64>,
    seq: u64,
    next_sample: u64,
}

impl SimRig {
    /// The simulated rig with `truth` as the real structure, at rest, drive off, clearance
    /// `clearance_m` (m) between the probes, with the truth variants of `spec.truth.variants`.
    /// Checks the spec, the ROM (outputs named by the beam sensors; with clamp friction the
    /// 1FL/1FU labels), the moving mass against the beams' modal mass and the truth step
    /// against the open stability limit of the ROM with the shaker attached.
    pub fn new(truth: &Rom, spec: &SimRigSpec, clearance_m: f64) -> Result<SimRig, SimRigError> {
        spec.validate()?;
        if !clearance_m.is_finite() {
            return Err(SimRigError::Spec(format!(
                "clearance_m = {clearance_m}: expected a finite clearance (m)"
            )));
        }
        let fs = spec.daq.sample_rate;
        let mut oversampling = 1;
        let hidden = &spec.truth.variants;
        let truth_model = Truth::new(truth, &spec.shaker, clearance_m, hidden, |limits| {
            oversampling = spec
                .truth
                .oversampling_for(fs, limits.dt_max_open(), limits.omega_ref);
            let dt = 1.0 / (fs * f64::from(oversampling));
            if !(dt < limits.dt_max_open()) {
                return Err(SimRigError::Spec(format!(
                    "truth.oversampling = {oversampling}: the truth step 1 / ({fs} Hz x \
                     {oversampling}) = {dt:.4e} s is beyond the open stability limit of the \
                     truth ROM with the shaker attached, {:.4e} s; use at least {} or leave \
                     it out (automatic)",
                    limits.dt_max_open(),
                    (1.0 / (fs * limits.dt_max_open())).floor() + 1.0
                )));
            }
            Ok(dt)
        })?;
        let layout = crate::rig::channels::layout(&spec.daq);
        let gains = crate::physics::sensor_gain::resolve(
            &hidden.sensor_gains,
            layout.channels.iter().map(|c| c.name.as_str()),
            "truth.variants",
        )?;
        let sensors = Sensors::new(
            spec.daq.platform_accelerometers.len(),
            truth_model.dt(),
            &spec.daq.contact_circuit,
        );
        let nc = sensors.n_channels();
        debug_assert_eq!(nc, layout.channels.len());
        let mut rest = vec![0.0; nc];
        sensors.rest(&mut rest);
        let daq = Daq::new(&spec.daq, &layout, oversampling, &rest);
        Ok(SimRig {
            layout,
            oversampling,
            truth: truth_model,
            sensors,
            variants: hidden.clone(),
            gains,
            daq,
            drive: DriveGenerator::default(),
            values: rest,
            faults: Vec::new(),
            saturation_latched: None,
            over_range_reported: vec![false; nc],
            failure_reported: false,
            pending: Vec::new(),
            stall_at: None,
            seq: 0,
            next_sample: 0,
        })
    }

    /// The DAQ channel layout.
    pub fn layout(&self) -> &DaqLayout {
        &self.layout
    }

    /// Truth steps per DAQ sample.
    pub fn oversampling(&self) -> u32 {
        self.oversampling
    }

    /// The hidden physics switched on in the truth (`[truth.variants]`).
    pub fn variants(&self) -> &TruthVariants {
        &self.variants
    }

    /// Sets the drive; applies from the next sample (phase-continuous frequency change,
    /// linear amplitude ramp from the current amplitude over `ramp_s`).
    pub fn set_drive(&mut self, cmd: DriveCommand) -> Result<(), SimRigError> {
        DriveGenerator::check(&cmd, 0.5 * self.layout.sample_rate).map_err(SimRigError::Command)?;
        self.drive.set(&cmd);
        Ok(())
    }

    /// The drive as applied.
    pub fn drive(&self) -> DriveState {
        self.drive.state()
    }

    /// Faults raised since the start (latched): DriveSaturated when the amplifier clips (once
    /// per output limit), OverRange per clipping channel, Device when the truth stops.
    pub fn faults(&self) -> &[RigFault] {
        &self.faults
    }

    /// Schedules an injected fault. Rejects a non-finite or negative time, an unknown channel
    /// name, a negative or non-finite amplifier limit and a non-finite clearance. A time in
    /// the past activates at the next sample.
    pub fn schedule(&mut self, fault: InjectedFault) -> Result<(), SimRigError> {
        let at_s = fault.at_s();
        if !(at_s.is_finite() && at_s >= 0.0) {
            return Err(SimRigError::Fault(format!(
                "{fault:?}: at_s = {at_s}: expected a finite rig time >= 0 s"
            )));
        }
        match &fault {
            InjectedFault::DaqStall { at_s } => {
                self.stall_at = Some(self.stall_at.map_or(*at_s, |t| t.min(*at_s)));
                return Ok(());
            }
            InjectedFault::DeadChannel { channel, .. } => {
                if self.layout.index(channel).is_none() {
                    return Err(SimRigError::Fault(format!(
                        "dead channel {channel:?}: no such channel (channels: {})",
                        self.layout
                            .channels
                            .iter()
                            .map(|c| c.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )));
                }
            }
            InjectedFault::DriveSaturation { limit_v, .. } => {
                if !(limit_v.is_finite() && *limit_v >= 0.0) {
                    return Err(SimRigError::Fault(format!(
                        "drive saturation: limit_v = {limit_v}: expected a finite limit >= 0 V"
                    )));
                }
            }
            InjectedFault::ClearanceChange { clearance_m, .. } => {
                if !clearance_m.is_finite() {
                    return Err(SimRigError::Fault(format!(
                        "clearance change: clearance_m = {clearance_m}: expected a finite \
                         clearance (m)"
                    )));
                }
            }
        }
        // Stable by time: faults at the same time apply in scheduling order.
        let pos = self.pending.partition_point(|f| f.at_s() <= at_s);
        self.pending.insert(pos, fault);
        Ok(())
    }

    /// Whether a scheduled DAQ stall is due: the wrapper then stops delivering blocks.
    pub fn stalled(&self) -> bool {
        self.stall_at
            .is_some_and(|t| t <= self.sample_time(self.next_sample))
    }

    /// The truth's state after the last block.
    pub fn truth(&self) -> TruthSnapshot {
        let last = self.truth.last();
        TruthSnapshot {
            time: self.sample_time(self.next_sample),
            truth_steps: self.truth.steps(),
            dt: self.truth.dt(),
            base_displacement: last.base_displacement,
            base_velocity: last.base_velocity[1],
            base_acceleration: last.base_acceleration,
            coil_current: last.current,
            amplifier_output: last.amplifier_output,
            amplifier_limit_v: self.truth.shaker().limit_v(),
            contact_closed: last.any_closed,
            closed_pairs: self.truth.closed_pairs(),
            clearance: self.truth.clearance(),
            clearance_growth: self.truth.wear().map_or(0.0, |w| w.1),
            wear_impulse: self.truth.wear().map_or(0.0, |w| w.0),
            joint_dissipation: self.truth.joint_dissipation().unwrap_or(0.0),
            solver_failures: self.truth.solver_failures(),
            failed: self.truth.failure().is_some(),
        }
    }

    /// Advances the truth by one block and returns it: `seq` counts blocks from 0,
    /// `first_sample = seq * block_size`, `time = first_sample / sample_rate`.
    pub fn next_block(&mut self) -> DaqBlock {
        self.block(None)
    }

    /// [`SimRig::next_block`], also appending the truth at every sample instant to `trace`.
    pub fn next_block_traced(&mut self, trace: &mut TruthTrace) -> DaqBlock {
        self.block(Some(trace))
    }

    fn sample_time(&self, n: u64) -> f64 {
        n as f64 / self.layout.sample_rate
    }

    fn block(&mut self, mut trace: Option<&mut TruthTrace>) -> DaqBlock {
        let len = self.layout.block_size;
        let nc = self.layout.channels.len();
        let mut counts = vec![0; nc * len];
        let first_sample = self.next_sample;
        let dt = self.truth.dt();
        if let Some(tr) = trace.as_deref_mut() {
            tr.time.reserve(len);
            tr.base_acceleration.reserve(len);
            tr.base_displacement.reserve(len);
            tr.coil_current.reserve(len);
            tr.amplifier_output.reserve(len);
            tr.closed_steps.reserve(len);
            tr.clearance.reserve(len);
            tr.relative_velocity.reserve(len);
        }
        for i in 0..len {
            let t = self.sample_time(first_sample + i as u64);
            if self.pending.first().is_some_and(|f| f.at_s() <= t) {
                self.activate_due(t);
            }
            let mut closed_steps = 0;
            let mut at_sample = None;
            for sub in 0..self.oversampling {
                let d = self.drive.next(dt);
                let v = self.truth.step(d);
                if v.clipped {
                    self.latch_saturation();
                }
                closed_steps += u32::from(v.any_closed);
                self.sensors.read(&v, &mut self.values);
                crate::physics::sensor_gain::apply(&self.gains, &mut self.values);
                self.daq.filter(&self.values, sub == 0);
                if sub == 0 {
                    at_sample = Some(v);
                }
            }
            self.daq.sample(&mut counts, i, len);
            if let (Some(tr), Some(v)) = (trace.as_deref_mut(), at_sample) {
                tr.time.push(t);
                tr.base_acceleration.push(v.base_acceleration);
                tr.base_displacement.push(v.base_displacement);
                tr.coil_current.push(v.current);
                tr.amplifier_output.push(v.amplifier_output);
                tr.closed_steps.push(closed_steps);
                tr.clearance.push(self.truth.clearance());
                let [before, after] = v.relative_velocity;
                tr.relative_velocity
                    .push(std::array::from_fn(|k| 0.5 * (before[k] + after[k])));
            }
        }
        self.latch_block_faults();
        let block = DaqBlock {
            seq: self.seq,
            first_sample,
            time: self.sample_time(first_sample),
            len,
            counts,
        };
        self.seq += 1;
        self.next_sample += len as u64;
        block
    }

    /// Activates every pending fault due at sample time `t`.
    #[cold]
    fn activate_due(&mut self, t: f64) {
        let n = self.pending.partition_point(|f| f.at_s() <= t);
        for fault in self.pending.drain(..n) {
            match fault {
                InjectedFault::DaqStall { .. } => {}
                InjectedFault::DeadChannel { channel, .. } => {
                    if let Some(k) = self.layout.index(&channel) {
                        self.daq.kill(k);
                    }
                }
                InjectedFault::DriveSaturation { limit_v, .. } => {
                    self.truth.set_amplifier_limit(limit_v);
                }
                InjectedFault::ClearanceChange { clearance_m, .. } => {
                    // Checked finite at scheduling: cannot fail.
                    let _ = self.truth.set_clearance(clearance_m);
                }
            }
        }
    }

    #[cold]
    fn latch_saturation(&mut self) {
        let limit_v = self.truth.shaker().limit_v();
        if self.saturation_latched != Some(limit_v) {
            self.saturation_latched = Some(limit_v);
            self.faults.push(RigFault::DriveSaturated { limit_v });
        }
    }

    fn latch_block_faults(&mut self) {
        if !self.failure_reported {
            if let Some(msg) = self.truth.failure() {
                self.faults.push(RigFault::Device {
                    message: msg.to_string(),
                });
                self.failure_reported = true;
            }
        }
        for (k, &over) in self.daq.over_range().iter().enumerate() {
            if over && !self.over_range_reported[k] {
                self.over_range_reported[k] = true;
                self.faults.push(RigFault::OverRange {
                    channel: self.layout.channels[k].name.clone(),
                });
            }
        }
    }
}

#[cfg(test)]
mod tests;
