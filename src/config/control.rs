//! Controller and safety parameters: the `[control]` and `[safety]` sections of a rig
//! description. Every field has a default, so both sections may be omitted. Not part of the
//! model: not hashed (changing a gain does not rebuild the ROM). The controller itself lives
//! in `control`.

use serde::{Deserialize, Serialize};

use super::error::SpecError;

/// `[control]`: amplitude control of the fundamental base displacement, settle detection and
/// the contact channel threshold.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControlSpec {
    /// Proportional gain on the log-amplitude error `ln(target / measured)`, -. Default 0.05.
    pub kp: f64,
    /// Integral gain on the log-amplitude error, per excitation period, -. Default 0.08.
    pub ki: f64,
    /// Periods the fundamental is demodulated over for each control update (a sliding window
    /// of whole periods), -. Default 8: long enough to average out the beat of the beams'
    /// free transients against the drive in the base reaction (the resonant force drop makes
    /// the base motion beat by +-15 % after a change), short enough for the loop.
    pub window_periods: u32,
    /// Largest change of the drive amplitude per control update, as a ratio (>= 1), -.
    /// Default 1.5.
    pub max_step_ratio: f64,
    /// Drive amplitude that the first step of a test starts from, V (amplifier input);
    /// 0 = estimate from the shaker's static gain. Default 0.
    pub initial_drive_v: f64,
    /// Settling: the mean control error over the settle window must be within this relative
    /// tolerance, -. Default 0.01.
    pub settle_tolerance: f64,
    /// Settling: the response envelope (RMS of the vibrometer over `settle_window_periods`)
    /// may change by at most this relative amount between consecutive windows, -. Default 0.15.
    pub envelope_tolerance: f64,
    /// Settling: window of the control-error and envelope checks, periods. Default 25.
    pub settle_window_periods: u32,
    /// Settling gives up after this multiple of the plan's settle periods and records anyway
    /// (the step is marked not settled), -. Default 4.
    pub max_settle_factor: f64,
    /// Contact-resistance voltage below which the beams are in contact, V. Default 2.5.
    pub contact_threshold_v: f64,
    /// A record window whose fundamental base-displacement amplitude misses the target by
    /// more than this relative tolerance is rejected and recorded again, -. Default 0.01.
    pub record_tolerance: f64,
    /// Record windows a step may take to meet `record_tolerance` (>= 1); the last one is kept
    /// whatever its error (the summary's `record_attempt`, `base_amp_measured` and
    /// `base_amp_off_tolerance` show it; the console flags it). Default 3.
    ///
    // NOTE: in the impact regime the beams' free response beats against the drive at 1-2 Hz
    // and moves the base amplitude by +-15 % period by period (the reaction on the shaker's
    // moving mass); no amplitude-only loop with a block of latency cancels a component that is
    // not at Omega, and a window of 50-200 periods holds a non-integer number of beats, so its
    // fundamental scatters by up to 1-2 %. The experiment's answer is a tolerance gate on the
    // excitation of every record window.
    pub record_attempts: u32,
}

impl Default for ControlSpec {
    fn default() -> Self {
        ControlSpec {
            kp: 0.05,
            ki: 0.08,
            window_periods: 8,
            max_step_ratio: 1.5,
            initial_drive_v: 0.0,
            settle_tolerance: 0.01,
            envelope_tolerance: 0.15,
            settle_window_periods: 25,
            max_settle_factor: 4.0,
            contact_threshold_v: 2.5,
            record_tolerance: 0.01,
            record_attempts: 3,
        }
    }
}

/// `[safety]`: limits that abort a test, and the abort ramp.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetySpec {
    /// Largest drive amplitude the controller may command, V (amplifier input). Default 2.0.
    pub max_drive_v: f64,
    /// Periods the controller may sit at `max_drive_v` with the base amplitude still short of
    /// the target (beyond `settle_tolerance`) before aborting, -. Default 20.
    pub saturation_periods: u32,
    /// Largest magnitude of any acceleration channel, m/s^2. Default 3000.
    pub max_acceleration: f64,
    /// Largest share of samples in contact over `contact_window_s`, in (0, 1]. Default 0.6.
    pub max_contact_duty: f64,
    /// Window of the contact-duty check, s. Default 1.0.
    pub contact_window_s: f64,
    /// Longest wait for the next DAQ block (wall clock), s. Default 2.0.
    pub daq_timeout_s: f64,
    /// A sensor channel whose counts stay constant for this long while the drive is on is
    /// dead, s. Default 0.5.
    pub dead_channel_s: f64,
    /// Time of the drive ramp-down after an abort or at the end of a session, s. Default 0.5.
    pub ramp_down_s: f64,
}

impl Default for SafetySpec {
    fn default() -> Self {
        SafetySpec {
            max_drive_v: 2.0,
            saturation_periods: 20,
            max_acceleration: 3000.0,
            max_contact_duty: 0.6,
            contact_window_s: 1.0,
            daq_timeout_s: 2.0,
            dead_channel_s: 0.5,
            ramp_down_s: 0.5,
        }
    }
}

/// `key = v: expected a finite value > 0` unless `v` is finite and positive.
fn positive(key: &str, v: f64) -> Result<(), SpecError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(SpecError::new(key, v, "a finite value > 0"))
    }
}

impl ControlSpec {
    /// Checks the values; the error names the key.
    pub fn validate(&self) -> Result<(), SpecError> {
        if !(self.kp.is_finite() && self.kp >= 0.0) {
            return Err(SpecError::new("control.kp", self.kp, "a finite value >= 0"));
        }
        positive("control.ki", self.ki)?;
        if self.window_periods == 0 {
            return Err(SpecError::new("control.window_periods", 0, "at least 1"));
        }
        if !(self.max_step_ratio.is_finite() && self.max_step_ratio >= 1.0) {
            return Err(SpecError::new(
                "control.max_step_ratio",
                self.max_step_ratio,
                "a finite value >= 1",
            ));
        }
        if !(self.initial_drive_v.is_finite() && self.initial_drive_v >= 0.0) {
            return Err(SpecError::new(
                "control.initial_drive_v",
                self.initial_drive_v,
                ">= 0",
            ));
        }
        positive("control.settle_tolerance", self.settle_tolerance)?;
        positive("control.envelope_tolerance", self.envelope_tolerance)?;
        if self.settle_window_periods == 0 {
            return Err(SpecError::new(
                "control.settle_window_periods",
                0,
                "at least 1",
            ));
        }
        if !(self.max_settle_factor.is_finite() && self.max_settle_factor >= 1.0) {
            return Err(SpecError::new(
                "control.max_settle_factor",
                self.max_settle_factor,
                ">= 1",
            ));
        }
        positive("control.record_tolerance", self.record_tolerance)?;
        if self.record_attempts == 0 {
            return Err(SpecError::new("control.record_attempts", 0, "at least 1"));
        }
        positive("control.contact_threshold_v", self.contact_threshold_v)
    }
}

impl SafetySpec {
    /// Checks the values; the error names the key.
    pub fn validate(&self) -> Result<(), SpecError> {
        positive("safety.max_drive_v", self.max_drive_v)?;
        if self.saturation_periods == 0 {
            return Err(SpecError::new("safety.saturation_periods", 0, "at least 1"));
        }
        positive("safety.max_acceleration", self.max_acceleration)?;
        if !(self.max_contact_duty > 0.0 && self.max_contact_duty <= 1.0) {
            return Err(SpecError::new(
                "safety.max_contact_duty",
                self.max_contact_duty,
                "a share in (0, 1]",
            ));
        }
        positive("safety.contact_window_s", self.contact_window_s)?;
        positive("safety.daq_timeout_s", self.daq_timeout_s)?;
        positive("safety.dead_channel_s", self.dead_channel_s)?;
        positive("safety.ramp_down_s", self.ramp_down_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        ControlSpec::default().validate().unwrap();
        SafetySpec::default().validate().unwrap();
    }

    #[test]
    fn bad_values_name_the_key_the_value_and_what_was_expected() {
        let spec = ControlSpec {
            kp: -1.0,
            ..ControlSpec::default()
        };
        assert_eq!(
            spec.validate().unwrap_err().to_string(),
            "control.kp = -1: expected a finite value >= 0"
        );
        let spec = ControlSpec {
            window_periods: 0,
            ..ControlSpec::default()
        };
        assert_eq!(
            spec.validate().unwrap_err().to_string(),
            "control.window_periods = 0: expected at least 1"
        );
        let spec = SafetySpec {
            max_contact_duty: 1.5,
            ..SafetySpec::default()
        };
        assert_eq!(
            spec.validate().unwrap_err().to_string(),
            "safety.max_contact_duty = 1.5: expected a share in (0, 1]"
        );
        let spec = SafetySpec {
            ramp_down_s: f64::NAN,
            ..SafetySpec::default()
        };
        assert_eq!(
            spec.validate().unwrap_err().to_string(),
            "safety.ramp_down_s = NaN: expected a finite value > 0"
        );
    }
}
