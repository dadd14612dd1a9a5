//! The driven ROM ([`DrivenRom`]): a ROM driven by a base acceleration (step by step, given
//! per step, or from an [`Excitation`] over a run), read through named sensor outputs. In:
//! the base acceleration (m/s^2) and optionally extra modal loads; out per step
//! ([`SensorStep`]): the named sensors' displacements and velocities relative to the base,
//! the contact state and the integrated contact forces, the energies.
//!
//! One implementation used by the simulated rig's truth model, the twin and the virtual
//! stepped sine: the output lookup by name ([`output_index`]; the ROM knows its outputs, see
//! [`crate::rom::RomOutput`]), the provisional time step from which the caller's real step
//! follows ([`DrivenRom::provisional`]), and the sensor sink.
//!
//! Numerics only: the driven ROM adds no floating-point operation to the integrator's; a run
//! gives the bits the integrator gives.

use crate::contact::SolveStats;
use crate::rom::Rom;

use super::energy::Energy;
use super::error::SimError;
use super::excitation::Excitation;
use super::integrator::{
    Integrator, IntegratorParameters, RunReport, StabilityLimits, State, TimeStep,
};
use super::output::{ContactSummary, NullSink, StepOutput, StepSink};

/// The beam sensors of the rig: the ROM outputs of the beam accelerometers (and the
/// vibrometer's spot), relative motion of the beam points, in channel order.
pub const BEAM_SENSORS: [&str; 4] = ["lower_tip", "lower_mid", "upper_tip", "upper_mid"];

/// Index of the lower tip in [`BEAM_SENSORS`].
pub const LOWER_TIP: usize = 0;

/// Index of the lower beam's middle in [`BEAM_SENSORS`].
pub const LOWER_MID: usize = 1;

/// Index of the upper tip in [`BEAM_SENSORS`] (the vibrometer's spot).
pub const UPPER_TIP: usize = 2;

/// Index of the upper beam's middle in [`BEAM_SENSORS`].
pub const UPPER_MID: usize = 3;

/// The provisional time step of [`DrivenRom::provisional`]: far inside any stability limit,
/// so that the integrator can check the ROM and compute its limits before the real step is
/// known.
pub const PROVISIONAL_TIME_STEP: TimeStep = TimeStep::StepsPerReferencePeriod { steps: 1.0e6 };

/// A sensor the driven ROM should read is not among the ROM's outputs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("no output {name:?} (outputs: {available:?})")]
pub struct MissingOutput {
    /// The sensor name looked for.
    pub name: String,
    /// The ROM's output names, in order.
    pub available: Vec<String>,
}

/// Why a [`DrivenRom`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DrivenError {
    /// A sensor is not among the ROM's outputs.
    #[error(transparent)]
    Output(#[from] MissingOutput),
    /// The integrator rejected the ROM or the parameters.
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// Index of the ROM output (sensor) named `name`.
pub fn output_index(rom: &Rom, name: &str) -> Result<usize, MissingOutput> {
    rom.outputs
        .iter()
        .position(|o| o.name == name)
        .ok_or_else(|| MissingOutput {
            name: name.to_owned(),
            available: rom.outputs.iter().map(|o| o.name.clone()).collect(),
        })
}

/// Indices of the ROM outputs named `names`, in that order (the first missing one fails).
pub fn output_indices<const N: usize>(
    rom: &Rom,
    names: [&str; N],
) -> Result<[usize; N], MissingOutput> {
    let mut index = [0; N];
    for (slot, name) in index.iter_mut().zip(names) {
        *slot = output_index(rom, name)?;
    }
    Ok(index)
}

/// What one step of a [`DrivenRom`] produced, as its `N` sensors read it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorStep<const N: usize> {
    /// Contact time level of the step, s (see [`StepOutput`]).
    pub time: f64,
    /// Sensor displacements relative to the base at `time`, m.
    pub displacement: [f64; N],
    /// Sensor velocities relative to the base at the half step `time - dt/2`, m/s.
    pub velocity: [f64; N],
    /// Contact activity and integrated contact forces.
    pub contact: ContactSummary,
    /// Statistics of the contact solve, `None` when no pair was a candidate.
    pub solve: Option<SolveStats>,
    /// Energy terms after the step.
    pub energy: Energy,
}

impl<const N: usize> Default for SensorStep<N> {
    /// Zero (a ROM at rest before its first step).
    fn default() -> Self {
        SensorStep {
            time: 0.0,
            displacement: [0.0; N],
            velocity: [0.0; N],
            contact: ContactSummary::default(),
            solve: None,
            energy: Energy::default(),
        }
    }
}

impl<const N: usize> SensorStep<N> {
    /// The sensors `index` of a step output.
    #[inline(always)]
    fn read(&mut self, out: &StepOutput<'_>, index: &[usize; N]) {
        self.time = out.time;
        for ((d, v), &i) in self
            .displacement
            .iter_mut()
            .zip(self.velocity.iter_mut())
            .zip(index)
        {
            *d = out.displacement[i];
            *v = out.velocity[i];
        }
        self.contact = out.contact;
        self.solve = out.solve;
        self.energy = out.energy;
    }
}

/// Receives every step of a [`DrivenRom::run`].
pub trait SensorSink<const N: usize> {
    /// Called once per step, in order.
    fn record(&mut self, step: &SensorStep<N>);
}

impl<const N: usize, F: FnMut(&SensorStep<N>)> SensorSink<N> for F {
    fn record(&mut self, step: &SensorStep<N>) {
        self(step)
    }
}

impl<const N: usize> SensorSink<N> for NullSink {
    fn record(&mut self, _step: &SensorStep<N>) {}
}

/// Reads the sensors of every step into the driven ROM's last step and hands it on.
struct Reader<'a, const N: usize, S> {
    index: &'a [usize; N],
    last: &'a mut SensorStep<N>,
    sink: &'a mut S,
}

impl<const N: usize, S: SensorSink<N>> StepSink for Reader<'_, N, S> {
    #[inline]
    fn record(&mut self, out: &StepOutput<'_>) {
        self.last.read(out, self.index);
        self.sink.record(self.last);
    }
}

/// A ROM driven by a base acceleration, read through `N` named sensors: the integrator, its
/// state and the last step's sensor values. See the module docs.
#[derive(Clone, Debug)]
pub struct DrivenRom<const N: usize> {
    integrator: Integrator,
    state: State,
    sensors: [usize; N],
    last: SensorStep<N>,
}

impl<const N: usize> DrivenRom<N> {
    /// The ROM `rom` read through the outputs named `sensors`, integrated with `params`, at
    /// rest at time 0. Looks the sensors up first, then builds the integrator (which checks
    /// the ROM and the time step).
    pub fn new(
        rom: &Rom,
        sensors: [&str; N],
        params: IntegratorParameters,
    ) -> Result<DrivenRom<N>, DrivenError> {
        let sensors = output_indices(rom, sensors)?;
        let integrator = Integrator::new(rom, params)?;
        let state = integrator.state_at_rest();
        Ok(DrivenRom {
            integrator,
            state,
            sensors,
            last: SensorStep::default(),
        })
    }

    /// [`DrivenRom::new`] with the default parameters at the [`PROVISIONAL_TIME_STEP`]: the
    /// caller chooses the real step from [`DrivenRom::limits`] and sets it with
    /// [`DrivenRom::set_time_step`].
    pub fn provisional(rom: &Rom, sensors: [&str; N]) -> Result<DrivenRom<N>, DrivenError> {
        let params = IntegratorParameters {
            time_step: PROVISIONAL_TIME_STEP,
            ..IntegratorParameters::default()
        };
        DrivenRom::new(rom, sensors, params)
    }

    /// Changes the time step, keeping the state (see [`Integrator::set_time_step`]).
    pub fn set_time_step(&mut self, time_step: TimeStep) -> Result<(), SimError> {
        self.integrator.set_time_step(time_step)
    }

    /// Sets the clearance, m (see [`Integrator::set_clearance`]).
    pub fn set_clearance(&mut self, clearance_m: f64) -> Result<(), SimError> {
        self.integrator.set_clearance(clearance_m)
    }

    /// The clearance in use, m.
    pub fn clearance(&self) -> f64 {
        self.integrator.clearance()
    }

    /// Sets per-pair gap offsets, m (see [`Integrator::set_gap_offsets`]).
    pub fn set_gap_offsets(&mut self, offsets: Option<&[f64]>) -> Result<(), SimError> {
        self.integrator.set_gap_offsets(offsets)
    }

    /// The time step, s.
    pub fn dt(&self) -> f64 {
        self.integrator.dt()
    }

    /// The ROM's stability limits.
    pub fn limits(&self) -> &StabilityLimits {
        self.integrator.limits()
    }

    /// The integrator (parameters, gap offsets, contact solver), for diagnostics.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }

    /// The integrator state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The sensor names, as the ROM's outputs name them, in the order of the sensor values.
    pub fn sensor_names(&self) -> [&str; N] {
        let names = self.integrator.output_names();
        self.sensors.map(|i| names[i].as_str())
    }

    /// The last step's sensor values (zero before the first step and after a reset).
    pub fn last(&self) -> &SensorStep<N> {
        &self.last
    }

    /// Restores a state captured from a ROM like this one (e.g. [`DrivenRom::state`] of an
    /// earlier run, read back from a log), with the sensor velocities of its last step
    /// `last_velocity` (the other last-step values start at zero): the run continues from
    /// there as it did after the capture, bit for bit. Fails, changing nothing, on a state that
    /// does not fit the ROM.
    pub fn set_state(
        &mut self,
        state: State,
        last_velocity: [f64; N],
    ) -> Result<(), crate::sim::StateMismatch> {
        self.check_state(&state, &last_velocity)?;
        self.state = state;
        self.last = SensorStep {
            velocity: last_velocity,
            time: self.state.time(),
            ..SensorStep::default()
        };
        Ok(())
    }

    /// Whether [`DrivenRom::set_state`] would take `state` and `last_velocity` (sizes,
    /// finiteness), without changing anything.
    pub fn check_state(
        &self,
        state: &State,
        last_velocity: &[f64; N],
    ) -> Result<(), crate::sim::StateMismatch> {
        state.check(self.integrator.n_modes(), self.integrator.n_pairs())?;
        match last_velocity.iter().position(|v| !v.is_finite()) {
            Some(k) => Err(crate::sim::StateMismatch::NonFinite {
                field: "last_velocity",
                index: k,
            }),
            None => Ok(()),
        }
    }

    /// Back to rest at time 0, the last sensor values zero, the contact solver's history
    /// forgotten (the ROM then runs as a new one would, bit for bit).
    pub fn reset(&mut self) {
        self.state = self.integrator.state_at_rest();
        self.integrator.forget_contact_history();
        self.last = SensorStep::default();
    }

    /// One step with base acceleration `a_base` (m/s^2) at the state's time; the sensors in
    /// [`DrivenRom::last`] (see [`Integrator::step`]).
    #[inline]
    pub fn step(&mut self, a_base: f64) -> Result<RunReport, SimError> {
        self.step_loaded(a_base, &[])
    }

    /// [`DrivenRom::step`] with extra modal forces `(mode, force)` evaluated at the state's
    /// displacement (see [`Integrator::step_loaded`]).
    #[inline]
    pub fn step_loaded(
        &mut self,
        a_base: f64,
        load: &[(usize, f64)],
    ) -> Result<RunReport, SimError> {
        let mut reader = Reader {
            index: &self.sensors,
            last: &mut self.last,
            sink: &mut NullSink,
        };
        self.integrator
            .step_loaded(&mut self.state, a_base, load, &mut reader)
    }

    /// Runs `n_steps` steps under `excitation`, handing every step's sensor values to `sink`
    /// (see [`Integrator::run`]); the last one stays in [`DrivenRom::last`].
    pub fn run<S: SensorSink<N>>(
        &mut self,
        excitation: &Excitation,
        n_steps: u64,
        sink: &mut S,
    ) -> Result<RunReport, SimError> {
        let mut reader = Reader {
            index: &self.sensors,
            last: &mut self.last,
            sink,
        };
        self.integrator
            .run(&mut self.state, excitation, n_steps, &mut reader)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rom::{RomMeta, RomOutput};
    use faer::Mat;

    /// One mode, one pair far apart, the given outputs reading the mode.
    fn rom(outputs: &[&str]) -> Rom {
        Rom {
            meta: RomMeta::default(),
            omega: vec![2.0 * std::f64::consts::PI * 50.0],
            damping_ratio: vec![0.01],
            labels: vec!["1FU".into()],
            phi_g: Mat::zeros(3, 1),
            g_res: Mat::from_fn(3, 3, |i, j| if i == j { 1e-6 } else { 0.0 }),
            k_gg: Mat::from_fn(3, 3, |i, j| if i == j { 1e6 } else { 0.0 }),
            beta: vec![0.5],
            pair_area: vec![1e-6],
            pair_position: vec![[0.3, 0.0, 0.0]],
            clearance: 1.0,
            friction: 0.4,
            outputs: outputs
                .iter()
                .enumerate()
                .map(|(k, n)| RomOutput {
                    name: (*n).into(),
                    c_eta: vec![1.0 + k as f64],
                    c_lambda: vec![0.0; 3],
                })
                .collect(),
        }
    }

    #[test]
    fn sensors_are_looked_up_by_the_rom_output_names() {
        let r = rom(&["a", "upper_tip", "lower_tip"]);
        assert_eq!(
            output_indices(&r, [BEAM_SENSORS[UPPER_TIP], BEAM_SENSORS[LOWER_TIP]]),
            Ok([1, 2])
        );
        let e = output_index(&r, "upper_mid").unwrap_err();
        assert_eq!(e.name, "upper_mid");
        assert_eq!(e.available, ["a", "upper_tip", "lower_tip"]);
        assert!(e.to_string().contains("no output \"upper_mid\""), "{e}");
        let d = DrivenRom::provisional(&r, ["lower_tip", "a"]).unwrap();
        assert_eq!(d.sensor_names(), ["lower_tip", "a"]);
        assert!(matches!(
            DrivenRom::provisional(&r, ["lower_mid"]),
            Err(DrivenError::Output(_))
        ));
    }

    #[test]
    fn the_sensors_read_the_integrator_outputs_bit_for_bit() {
        let r = rom(&["a", "b", "c"]);
        let mut d = DrivenRom::provisional(&r, ["c", "a"]).unwrap();
        d.set_time_step(TimeStep::Dt { dt: 1e-4 }).unwrap();
        let mut integ = d.integrator().clone();
        let mut state = integ.state_at_rest();
        for j in 0..200 {
            let a = (j as f64 * 0.1).sin();
            let mut expected = [0.0; 4];
            integ
                .step(&mut state, a, &mut |o: &StepOutput<'_>| {
                    expected = [o.velocity[2], o.velocity[0], o.displacement[2], o.time];
                })
                .unwrap();
            d.step(a).unwrap();
            let s = d.last();
            let got = [s.velocity[0], s.velocity[1], s.displacement[0], s.time];
            assert_eq!(got.map(f64::to_bits), expected.map(f64::to_bits));
        }
        assert_eq!(d.state(), &state);
        d.reset();
        assert_eq!(d.last(), &SensorStep::default());
        assert_eq!(d.state().step(), 0);
    }
}
