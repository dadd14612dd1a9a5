//! The physical sensors: per truth step, the value of every DAQ channel in its physical unit
//! (before anti-alias filtering, noise and quantisation), in layout order:
//! platform accelerometers, beam accelerometers ([`BEAM_SENSORS`]), vibrometer, contact
//! voltage, drive voltage, drive current.
//!
//! All values stand at the step's start time `t^j`: accelerations are the base acceleration
//! plus the change of the sensor's relative velocity over the half steps around `t^j`;
//! velocities average the half-step velocities around `t^j`.

use crate::physics::contact_detection::ContactCircuit;

use super::spec::ContactCircuitSpec;
use super::truth::{StepValues, BEAM_SENSORS, UPPER_TIP};

/// The sensors' state (the contact circuit's RC response) and layout.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensors {
    n_platform: usize,
    dt: f64,
    /// The contact-resistance circuit, stepped with the truth.
    circuit: ContactCircuit,
}

impl Sensors {
    /// Sensors for `n_platform` platform accelerometers, truth step `dt` (s) and the contact
    /// circuit `circuit` (valid), resting with the probes apart.
    pub fn new(n_platform: usize, dt: f64, circuit: &ContactCircuitSpec) -> Sensors {
        Sensors {
            n_platform,
            dt,
            circuit: ContactCircuit::new(circuit, dt),
        }
    }

    /// Number of channels.
    pub fn n_channels(&self) -> usize {
        self.n_platform + BEAM_SENSORS.len() + 4
    }

    /// The resting value of every channel (for settling the filters), in layout order.
    pub fn rest(&self, out: &mut [f64]) {
        out.fill(0.0);
        out[self.n_platform + BEAM_SENSORS.len() + 1] = self.circuit.open_voltage();
    }

    /// Reads every channel for one truth step into `out` (length [`Sensors::n_channels`]).
    #[inline]
    pub fn read(&mut self, s: &StepValues, out: &mut [f64]) {
        let np = self.n_platform;
        let inv_dt = 1.0 / self.dt;
        out[..np].fill(s.base_acceleration);
        let [rel_before, rel_after] = &s.relative_velocity;
        for (o, (b, a)) in out[np..np + BEAM_SENSORS.len()]
            .iter_mut()
            .zip(rel_before.iter().zip(rel_after))
        {
            *o = s.base_acceleration + (a - b) * inv_dt;
        }
        let k = np + BEAM_SENSORS.len();
        out[k] = 0.5
            * (s.base_velocity[0]
                + s.base_velocity[1]
                + rel_before[UPPER_TIP]
                + rel_after[UPPER_TIP]);
        // The RC response is integrated exactly (see `physics::contact_detection`).
        out[k + 1] = self.circuit.step(s.any_closed);
        out[k + 2] = s.amplifier_output;
        out[k + 3] = s.current;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contact_voltage_follows_the_rc_response() {
        let circuit = ContactCircuitSpec::default();
        let dt = 1e-5;
        let mut s = Sensors::new(3, dt, &circuit);
        let mut out = vec![0.0; s.n_channels()];
        assert_eq!(out.len(), 11);
        let closed = StepValues {
            any_closed: true,
            ..StepValues::default()
        };
        let n = 5; // 5 dt = tau
        for _ in 0..n {
            s.read(&closed, &mut out);
        }
        let expected = circuit.closed_voltage
            + (circuit.open_voltage - circuit.closed_voltage) * (-1.0f64).exp();
        assert!(
            (out[8] - expected).abs() < 1e-12,
            "{} vs {expected}",
            out[8]
        );
    }

    #[test]
    fn accelerations_and_velocities_are_absolute() {
        let dt = 1e-5;
        let mut s = Sensors::new(1, dt, &ContactCircuitSpec::default());
        let mut out = vec![0.0; s.n_channels()];
        let v = StepValues {
            base_acceleration: 2.0,
            base_velocity: [0.1, 0.3],
            relative_velocity: [[0.0, 0.0, 1.0, 0.0], [1e-5, 0.0, 1.2, 0.0]],
            amplifier_output: 3.0,
            current: 4.0,
            ..StepValues::default()
        };
        s.read(&v, &mut out);
        assert_eq!(out[0], 2.0);
        assert!((out[1] - 3.0).abs() < 1e-9);
        assert!((out[3] - (2.0 + 0.2 / dt)).abs() < 1e-6);
        assert!((out[5] - (0.2 + 1.1)).abs() < 1e-12);
        assert_eq!(&out[7..], &[3.0, 4.0]);
    }
}
