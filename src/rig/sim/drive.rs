//! The drive signal generator: the sine at the amplifier input, advanced once per truth step.
//! The phase accumulates `2 pi f dt` (a frequency change is phase-continuous); the amplitude
//! moves linearly to its target over the commanded ramp time.

use std::f64::consts::TAU;

use crate::rig::daq::{CommandError, DriveCommand, DriveState};

/// The sine generator at the amplifier input.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DriveGenerator {
    state: DriveState,
    /// Amplitude change per second of the running ramp, V/s (>= 0).
    rate: f64,
}

impl DriveGenerator {
    /// Checks a command's ranges: frequency finite, > 0 and below `nyquist_hz`; amplitude and
    /// ramp finite and >= 0. Returns the first problem.
    pub fn check(cmd: &DriveCommand, nyquist_hz: f64) -> Result<(), CommandError> {
        if !(cmd.frequency_hz.is_finite()
            && cmd.frequency_hz > 0.0
            && cmd.frequency_hz < nyquist_hz)
        {
            return Err(CommandError::Frequency {
                frequency_hz: cmd.frequency_hz,
                nyquist_hz,
            });
        }
        if !(cmd.amplitude_v.is_finite() && cmd.amplitude_v >= 0.0) {
            return Err(CommandError::Amplitude {
                amplitude_v: cmd.amplitude_v,
            });
        }
        if !(cmd.ramp_s.is_finite() && cmd.ramp_s >= 0.0) {
            return Err(CommandError::Ramp { ramp_s: cmd.ramp_s });
        }
        Ok(())
    }

    /// Applies a (checked) command: new frequency from the next step on, amplitude ramp from
    /// the current amplitude.
    pub fn set(&mut self, cmd: &DriveCommand) {
        self.state.frequency_hz = cmd.frequency_hz;
        self.state.target_amplitude_v = cmd.amplitude_v;
        if cmd.ramp_s > 0.0 {
            self.rate = (cmd.amplitude_v - self.state.amplitude_v).abs() / cmd.ramp_s;
        } else {
            self.state.amplitude_v = cmd.amplitude_v;
            self.rate = 0.0;
        }
    }

    /// The drive as applied.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// The amplifier input of this step, V (`amplitude sin(phase)`), then advances the phase
    /// and the ramp by one step of `dt` s.
    #[inline]
    pub fn next(&mut self, dt: f64) -> f64 {
        let s = &mut self.state;
        let value = s.amplitude_v * s.phase.sin();
        s.phase += TAU * s.frequency_hz * dt;
        if s.phase >= TAU {
            s.phase -= TAU;
        }
        if s.amplitude_v != s.target_amplitude_v {
            let step = self.rate * dt;
            let gap = s.target_amplitude_v - s.amplitude_v;
            s.amplitude_v = if gap.abs() <= step {
                s.target_amplitude_v
            } else {
                s.amplitude_v + step.copysign(gap)
            };
        }
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_linear_and_frequency_change_is_phase_continuous() {
        let dt = 1e-4;
        let mut g = DriveGenerator::default();
        g.set(&DriveCommand {
            frequency_hz: 50.0,
            amplitude_v: 1.0,
            ramp_s: 0.1,
        });
        for _ in 0..500 {
            g.next(dt);
        }
        assert!((g.state().amplitude_v - 0.5).abs() < 1e-9);
        for _ in 0..600 {
            g.next(dt);
        }
        assert_eq!(g.state().amplitude_v, 1.0);
        let before = g.next(dt);
        let phase = g.state().phase;
        g.set(&DriveCommand {
            frequency_hz: 60.0,
            amplitude_v: 1.0,
            ramp_s: 0.0,
        });
        assert_eq!(g.state().phase, phase);
        let after = g.next(dt);
        // One step of 50 Hz then 60 Hz: the sine continues without a jump.
        assert!((after - before).abs() < 2.0 * TAU * 60.0 * dt);
        assert!(g.state().phase >= 0.0 && g.state().phase < TAU);
    }

    #[test]
    fn commands_out_of_range_are_rejected() {
        let ok = DriveCommand {
            frequency_hz: 55.0,
            amplitude_v: 0.1,
            ramp_s: 1.0,
        };
        assert!(DriveGenerator::check(&ok, 5120.0).is_ok());
        for bad in [
            DriveCommand {
                frequency_hz: 0.0,
                ..ok
            },
            DriveCommand {
                frequency_hz: 6000.0,
                ..ok
            },
            DriveCommand {
                amplitude_v: f64::NAN,
                ..ok
            },
            DriveCommand { ramp_s: -1.0, ..ok },
        ] {
            assert!(DriveGenerator::check(&bad, 5120.0).is_err(), "{bad:?}");
        }
    }
}
