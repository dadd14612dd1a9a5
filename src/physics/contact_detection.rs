//! Contact detection as measured: the contact-resistance circuit across the probes (a voltage
//! that drops while any pair is closed, first-order RC response, [`ContactCircuit`]), sampled
//! by a minimum-hold detector per DAQ sample ([`SampleDetector`]) and compared with the
//! threshold (`[control] contact_threshold_v`): a sample is "in contact" when the lowest
//! circuit voltage over its period is below the threshold.
//!
//! The simulated rig's sensors and DAQ run the truth's contact state through it; the model
//! runs its own contact state through the same circuit and detector before the two contact
//! fractions are compared. Without it the model counts a sample as in contact when any of its
//! steps had a closed pair: an impact much shorter than the circuit's time constant (tens of
//! microseconds against 50 us) pulls the voltage only part of the way down and does not cross
//! the threshold, so the raw model overstates the measured contact fraction in the impact
//! band.
//!
// NOTE: the RC response to a contact state held over a step is integrated exactly
// (`v <- target + (v - target) exp(-dt / tau)`), so a contact shorter than a step still moves
// the voltage by the right amount and the result does not depend on the step beyond the
// resolution of the contact state itself.

use crate::config::ContactCircuitSpec;

/// The contact-resistance circuit: its voltage, stepped with the contact state.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactCircuit {
    open_v: f64,
    closed_v: f64,
    /// `exp(-dt / tau)`.
    decay: f64,
    voltage: f64,
}

impl ContactCircuit {
    /// The circuit `spec` (valid) stepped every `dt` s, resting with the probes apart.
    pub fn new(spec: &ContactCircuitSpec, dt: f64) -> ContactCircuit {
        ContactCircuit {
            open_v: spec.open_voltage,
            closed_v: spec.closed_voltage,
            decay: (-dt / spec.time_constant).exp(),
            voltage: spec.open_voltage,
        }
    }

    /// The voltage with the probes apart, V.
    pub fn open_voltage(&self) -> f64 {
        self.open_v
    }

    /// One step with the contact state `closed` held over it; returns the voltage at its end,
    /// V.
    #[inline]
    pub fn step(&mut self, closed: bool) -> f64 {
        let target = if closed { self.closed_v } else { self.open_v };
        self.voltage = target + (self.voltage - target) * self.decay;
        self.voltage
    }

    /// The voltage, V.
    pub fn voltage(&self) -> f64 {
        self.voltage
    }

    /// Back to rest (probes apart).
    pub fn reset(&mut self) {
        self.voltage = self.open_v;
    }
}

/// The circuit and a minimum-hold detector: the lowest voltage over a DAQ sample period,
/// against the threshold.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleDetector {
    circuit: ContactCircuit,
    threshold_v: f64,
    lowest: f64,
}

impl SampleDetector {
    /// The circuit `spec` stepped every `dt` s, read against `threshold_v` (V).
    pub fn new(spec: &ContactCircuitSpec, dt: f64, threshold_v: f64) -> SampleDetector {
        SampleDetector {
            circuit: ContactCircuit::new(spec, dt),
            threshold_v,
            lowest: f64::INFINITY,
        }
    }

    /// One step of the current sample period.
    #[inline]
    pub fn step(&mut self, closed: bool) {
        self.lowest = self.lowest.min(self.circuit.step(closed));
    }

    /// Ends the sample period: whether its lowest voltage was below the threshold (no step:
    /// the voltage now).
    #[inline]
    pub fn sample(&mut self) -> bool {
        let v = if self.lowest.is_finite() {
            self.lowest
        } else {
            self.circuit.voltage()
        };
        self.lowest = f64::INFINITY;
        v < self.threshold_v
    }

    /// Back to rest.
    pub fn reset(&mut self) {
        self.circuit.reset();
        self.lowest = f64::INFINITY;
    }

    /// The circuit's voltage between two sample periods (all the detector carries from one
    /// sample to the next), V.
    pub fn voltage(&self) -> f64 {
        self.circuit.voltage
    }

    /// Restores [`SampleDetector::voltage`] at the start of a sample period; `false` (nothing
    /// changed) when it is not finite.
    pub fn set_voltage(&mut self, voltage: f64) -> bool {
        if voltage.is_finite() {
            self.circuit.voltage = voltage;
            self.lowest = f64::INFINITY;
        }
        voltage.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_voltage_follows_the_rc_response_exactly() {
        let spec = ContactCircuitSpec::default();
        let dt = 1e-5;
        let mut c = ContactCircuit::new(&spec, dt);
        let n = (spec.time_constant / dt).round() as usize;
        for _ in 0..n {
            c.step(true);
        }
        let expected =
            spec.closed_voltage + (spec.open_voltage - spec.closed_voltage) * (-1.0f64).exp();
        assert!((c.voltage() - expected).abs() < 1e-12);
        // The same contact in one step of n dt gives the same voltage.
        let mut one = ContactCircuit::new(&spec, n as f64 * dt);
        one.step(true);
        assert!((one.voltage() - expected).abs() < 1e-12);
    }

    #[test]
    fn a_short_impact_does_not_cross_a_mid_threshold_and_a_long_one_does() {
        let spec = ContactCircuitSpec::default();
        let threshold = 0.5 * (spec.open_voltage + spec.closed_voltage);
        let dt = 1e-6;
        let per_sample = 98;
        // Crossing needs about tau ln 2 = 35 us of contact.
        for (contact_steps, detected) in [(20, false), (30, false), (40, true), (90, true)] {
            let mut d = SampleDetector::new(&spec, dt, threshold);
            let mut seen = false;
            for s in 0..3 {
                for k in 0..per_sample {
                    d.step(s == 1 && k < contact_steps);
                }
                seen |= d.sample();
            }
            assert_eq!(seen, detected, "{contact_steps} us");
        }
        let mut d = SampleDetector::new(&spec, dt, threshold);
        assert!(!d.sample());
    }
}
