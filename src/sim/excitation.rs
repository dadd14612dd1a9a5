//! Base excitation of the rig: a prescribed sine (virtual stepped sine) or sampled base
//! acceleration (measured, replayed), evaluated at the integrator's step times.
//!
//! The base acceleration enters the modal equations as the inertia load `-beta a_base`
//! (DESIGN.md "The model" 2-3); displacements are relative to the base.

use super::error::SimError;

/// Base excitation, as base acceleration `a_base(t)` (m/s^2) at absolute simulation time `t` (s).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Excitation {
    /// Harmonic base displacement `u(t) = amplitude_m sin(omega t + phase)`, so
    /// `a_base(t) = -amplitude_m omega^2 sin(omega t + phase)`.
    Sine {
        /// Base displacement amplitude, m.
        amplitude_m: f64,
        /// Excitation circular frequency, rad/s (> 0).
        omega: f64,
        /// Phase at t = 0, rad. Use [`continuous_phase`] to keep the drive continuous when
        /// the frequency changes in a stepped sine.
        #[serde(default)]
        phase: f64,
    },
    /// A sine whose acceleration amplitude ramps linearly from `from_amplitude_m` to
    /// `amplitude_m`, as the rig's drive does at the start of a test:
    /// `a_base(t) = -A(t) omega^2 sin(omega t + phase)` with `A` going from `from_amplitude_m`
    /// at `ramp_start` to `amplitude_m` at `ramp_start + ramp_s` (constant before and after).
    /// After the ramp it equals [`Excitation::Sine`] bit for bit.
    RampedSine {
        /// Base displacement amplitude before the ramp, m (0: from rest).
        #[serde(default)]
        from_amplitude_m: f64,
        /// Base displacement amplitude reached after the ramp, m.
        amplitude_m: f64,
        /// Excitation circular frequency, rad/s (> 0).
        omega: f64,
        /// Phase at t = 0, rad.
        #[serde(default)]
        phase: f64,
        /// Time the ramp starts, s.
        ramp_start: f64,
        /// Ramp time, s (>= 0; 0: a step to the full amplitude).
        ramp_s: f64,
    },
    /// Base acceleration samples `accel[i]` at `t = i dt_sample`, linearly interpolated to the
    /// step times. A run must stay within `0 <= t <= (accel.len() - 1) dt_sample`.
    Sampled {
        /// Base acceleration samples, m/s^2 (at least two, all finite).
        accel: Vec<f64>,
        /// Sample interval, s (> 0).
        dt_sample: f64,
    },
}

impl Excitation {
    /// Checks the parameters and samples (finite, in range).
    pub fn validate(&self) -> Result<(), SimError> {
        match self {
            Excitation::RampedSine {
                from_amplitude_m,
                amplitude_m,
                omega,
                phase,
                ramp_start,
                ramp_s,
            } => {
                if !from_amplitude_m.is_finite() {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.from_amplitude_m (m)",
                        value: *from_amplitude_m,
                        expected: "a finite base displacement amplitude",
                    });
                }
                if !ramp_start.is_finite() {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.ramp_start (s)",
                        value: *ramp_start,
                        expected: "a finite time",
                    });
                }
                if !(ramp_s.is_finite() && *ramp_s >= 0.0) {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.ramp_s (s)",
                        value: *ramp_s,
                        expected: "a finite ramp time >= 0",
                    });
                }
                Excitation::Sine {
                    amplitude_m: *amplitude_m,
                    omega: *omega,
                    phase: *phase,
                }
                .validate()
            }
            Excitation::Sine {
                amplitude_m,
                omega,
                phase,
            } => {
                if !amplitude_m.is_finite() {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.amplitude_m (m)",
                        value: *amplitude_m,
                        expected: "a finite base displacement amplitude",
                    });
                }
                if !(omega.is_finite() && *omega > 0.0) {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.omega (rad/s)",
                        value: *omega,
                        expected: "a finite circular frequency > 0",
                    });
                }
                if !phase.is_finite() {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.phase (rad)",
                        value: *phase,
                        expected: "a finite phase",
                    });
                }
                Ok(())
            }
            Excitation::Sampled { accel, dt_sample } => {
                if !(dt_sample.is_finite() && *dt_sample > 0.0) {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.dt_sample (s)",
                        value: *dt_sample,
                        expected: "a finite sample interval > 0",
                    });
                }
                if accel.len() < 2 {
                    return Err(SimError::InvalidParameter {
                        field: "excitation.accel (number of samples)",
                        value: accel.len() as f64,
                        expected: "at least 2 samples",
                    });
                }
                match accel.iter().position(|a| !a.is_finite()) {
                    Some(index) => Err(SimError::ExcitationSample {
                        index,
                        value: accel[index],
                    }),
                    None => Ok(()),
                }
            }
        }
    }

    /// Checks that the excitation covers the times `start ..= end` (s).
    pub fn check_span(&self, start: f64, end: f64) -> Result<(), SimError> {
        if let Excitation::Sampled { accel, dt_sample } = self {
            let available = (accel.len() - 1) as f64 * dt_sample;
            // NOTE: step times are t0 + i dt; allow round-off of a few ulps at the last sample.
            let slack = 1e-12 * available.abs().max(dt_sample.abs());
            if start < -slack || end > available + slack || start.is_nan() || end.is_nan() {
                return Err(SimError::ExcitationSpan {
                    start,
                    end,
                    available,
                });
            }
        }
        Ok(())
    }

    /// Base acceleration at time `t` (s), m/s^2. For [`Excitation::Sampled`] times outside the
    /// samples are clamped to the first or last sample (a run checks its span beforehand).
    #[inline]
    pub fn accel_at(&self, t: f64) -> f64 {
        match self {
            Excitation::Sine {
                amplitude_m,
                omega,
                phase,
            } => -amplitude_m * omega * omega * (omega * t + phase).sin(),
            Excitation::RampedSine {
                from_amplitude_m,
                amplitude_m,
                omega,
                phase,
                ramp_start,
                ramp_s,
            } => {
                let a = ramped(t, *ramp_start, *ramp_s, *from_amplitude_m, *amplitude_m);
                -a * omega * omega * (omega * t + phase).sin()
            }
            Excitation::Sampled { accel, dt_sample } => {
                let u = t / dt_sample;
                let last = accel.len() - 1;
                if !(u > 0.0) {
                    return accel[0];
                }
                // `u` is positive and finite here; the cast saturates for huge values.
                let i = u.floor() as usize;
                if i >= last {
                    return accel[last];
                }
                let frac = u - i as f64;
                accel[i] + frac * (accel[i + 1] - accel[i])
            }
        }
    }

    /// Base displacement at time `t` for [`Excitation::Sine`], m; `None` for sampled
    /// acceleration (its displacement is not defined without integration constants).
    pub fn displacement_at(&self, t: f64) -> Option<f64> {
        match self {
            Excitation::Sine {
                amplitude_m,
                omega,
                phase,
            } => Some(amplitude_m * (omega * t + phase).sin()),
            // NOTE: the ramped amplitude times the sine: the displacement the ramped
            // acceleration drives, up to terms of order amplitude_m / (omega ramp_s) while the
            // ramp runs (exact after it, as the base's drift does not enter the relative motion).
            Excitation::RampedSine {
                from_amplitude_m,
                amplitude_m,
                omega,
                phase,
                ramp_start,
                ramp_s,
            } => Some(
                ramped(t, *ramp_start, *ramp_s, *from_amplitude_m, *amplitude_m)
                    * (omega * t + phase).sin(),
            ),
            Excitation::Sampled { .. } => None,
        }
    }
}

/// The amplitude of [`Excitation::RampedSine`] at `t`: `from` until `start`, `to` (exactly)
/// from `start + ramp_s` on, linear in between.
#[inline]
fn ramped(t: f64, start: f64, ramp_s: f64, from: f64, to: f64) -> f64 {
    if t >= start + ramp_s {
        to
    } else if t <= start {
        from
    } else {
        from + (to - from) * ((t - start) / ramp_s)
    }
}

/// The phase (rad, in `[0, 2 pi)`) that keeps a sine drive continuous when its circular
/// frequency changes from `omega_old` (phase `phase_old`) to `omega_new` at time `t` (s):
/// `omega_new t + phase_new = omega_old t + phase_old` (mod 2 pi).
pub fn continuous_phase(omega_old: f64, phase_old: f64, omega_new: f64, t: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    ((omega_old - omega_new) * t + phase_old).rem_euclid(two_pi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_acceleration_is_second_derivative_of_displacement() {
        let e = Excitation::Sine {
            amplitude_m: 2e-5,
            omega: 300.0,
            phase: 0.3,
        };
        let t = 0.0123;
        let h = 1e-5;
        let u = |t| e.displacement_at(t).unwrap();
        let fd = (u(t + h) - 2.0 * u(t) + u(t - h)) / (h * h);
        assert!((fd - e.accel_at(t)).abs() < 1e-5 * e.accel_at(t).abs().max(1.0));
    }

    #[test]
    fn a_ramped_sine_rises_linearly_then_equals_the_sine() {
        let (amplitude_m, omega, phase) = (2e-5, 300.0, 0.3);
        let sine = Excitation::Sine {
            amplitude_m,
            omega,
            phase,
        };
        let ramped = Excitation::RampedSine {
            from_amplitude_m: 0.0,
            amplitude_m,
            omega,
            phase,
            ramp_start: 0.1,
            ramp_s: 0.25,
        };
        assert!(ramped.validate().is_ok());
        assert_eq!(ramped.accel_at(0.05), 0.0);
        assert_eq!(ramped.accel_at(0.1), 0.0);
        for t in [0.15, 0.2, 0.3] {
            let r = (t - 0.1) / 0.25;
            let expected = r * sine.accel_at(t);
            assert!((ramped.accel_at(t) - expected).abs() < 1e-12 * expected.abs().max(1.0));
        }
        for t in [0.35, 0.4, 1.234] {
            assert_eq!(ramped.accel_at(t), sine.accel_at(t));
            assert_eq!(ramped.displacement_at(t), sine.displacement_at(t));
        }
        let from_half = Excitation::RampedSine {
            from_amplitude_m: 0.5 * amplitude_m,
            amplitude_m,
            omega,
            phase,
            ramp_start: 0.0,
            ramp_s: 0.2,
        };
        let t = 0.1;
        assert!((from_half.accel_at(t) - 0.75 * sine.accel_at(t)).abs() < 1e-9);
        let bad = Excitation::RampedSine {
            from_amplitude_m: 0.0,
            amplitude_m,
            omega,
            phase,
            ramp_start: 0.0,
            ramp_s: -1.0,
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn sampled_interpolates_linearly_and_clamps() {
        let e = Excitation::Sampled {
            accel: vec![0.0, 1.0, -1.0],
            dt_sample: 0.5,
        };
        assert_eq!(e.accel_at(0.0), 0.0);
        assert_eq!(e.accel_at(0.25), 0.5);
        assert_eq!(e.accel_at(0.5), 1.0);
        assert_eq!(e.accel_at(0.75), 0.0);
        assert_eq!(e.accel_at(1.0), -1.0);
        assert_eq!(e.accel_at(7.0), -1.0);
        assert_eq!(e.accel_at(-1.0), 0.0);
        assert!(e.check_span(0.0, 1.0).is_ok());
        assert!(matches!(
            e.check_span(0.0, 1.1),
            Err(SimError::ExcitationSpan { .. })
        ));
    }

    #[test]
    fn non_finite_samples_and_parameters_are_rejected() {
        let e = Excitation::Sampled {
            accel: vec![0.0, f64::NAN, 1.0],
            dt_sample: 1e-3,
        };
        assert!(matches!(
            e.validate(),
            Err(SimError::ExcitationSample { index: 1, .. })
        ));
        let s = Excitation::Sine {
            amplitude_m: f64::INFINITY,
            omega: 1.0,
            phase: 0.0,
        };
        assert!(s.validate().is_err());
        let s = Excitation::Sine {
            amplitude_m: 1.0,
            omega: 0.0,
            phase: 0.0,
        };
        assert!(s.validate().is_err());
    }

    #[test]
    fn continuous_phase_keeps_the_drive_continuous() {
        let (w0, p0, w1, t) = (310.0, 0.4, 313.5, 12.345);
        let p1 = continuous_phase(w0, p0, w1, t);
        let a = (w0 * t + p0).sin();
        let b = (w1 * t + p1).sin();
        assert!((a - b).abs() < 1e-9);
    }
}
