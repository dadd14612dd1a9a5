//! Settle detection of a stepped-sine step: the step may be recorded once the base amplitude
//! is under control and the response no longer drifts.
//!
//! Checked at every control update (once per excitation period): at least the plan's settle
//! periods have passed; the mean control error over the last `settle_window_periods` periods
//! is within `settle_tolerance`; and the response envelope — the RMS of the vibrometer over a
//! window of `settle_window_periods` periods — changed by at most `envelope_tolerance` against
//! the window before. In the modulated impact regime the per-period amplitude varies by a
//! factor of several and the beams' reaction makes the base amplitude beat by a few per cent
//! around the target, so both are judged as window means, not period by period. After
//! `max_settle_factor` times the plan's settle periods the step is recorded anyway and marked
//! not settled.

use super::spec::ControlSpec;

/// Outcome of a settle check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Settle {
    /// Keep settling.
    Wait,
    /// Settled: record from the next sample.
    Settled,
    /// Gave up: record from the next sample, marked not settled.
    TimedOut,
}

/// Settle detector of one step.
#[derive(Debug, Clone)]
pub struct SettleDetector {
    min_periods: u64,
    max_periods: u64,
    window: usize,
    tolerance: f64,
    envelope_tolerance: f64,
    periods: u64,
    /// Control errors of the last `window` periods (ring, same order as `ms`).
    errors: Vec<f64>,
    /// Mean square of the response per period, ring of 2 windows (newest at `next - 1`).
    ms: Vec<f64>,
    next: usize,
    /// Running sums of the current period: sum of squares and samples.
    acc: (f64, u64),
}

impl SettleDetector {
    /// Detector for a step with `settle_periods` periods of the plan (minimum).
    pub fn new(spec: &ControlSpec, settle_periods: u32) -> SettleDetector {
        let min = u64::from(settle_periods).max(1);
        let w = spec.settle_window_periods as usize;
        SettleDetector {
            min_periods: min,
            max_periods: ((min as f64) * spec.max_settle_factor).ceil() as u64,
            window: w,
            tolerance: spec.settle_tolerance,
            envelope_tolerance: spec.envelope_tolerance,
            periods: 0,
            errors: vec![f64::NAN; w],
            ms: vec![f64::NAN; 2 * w],
            next: 0,
            acc: (0.0, 0),
        }
    }

    /// Feeds one sample of the response (vibrometer velocity, m/s).
    pub fn push_response(&mut self, v: f64) {
        if v.is_finite() {
            self.acc.0 += v * v;
            self.acc.1 += 1;
        }
    }

    /// Periods since the step started.
    pub fn periods(&self) -> u64 {
        self.periods
    }

    /// At the end of a period, with the control error of the update.
    pub fn period_done(&mut self, control_error: f64) -> Settle {
        self.periods += 1;
        let ms = if self.acc.1 > 0 {
            self.acc.0 / self.acc.1 as f64
        } else {
            f64::NAN
        };
        self.acc = (0.0, 0);
        self.ms[self.next] = ms;
        self.errors[self.next % self.window] = control_error;
        self.next = (self.next + 1) % self.ms.len();
        if self.periods >= self.max_periods {
            return Settle::TimedOut;
        }
        let mean_error = self.errors.iter().sum::<f64>() / self.window as f64;
        // A window not yet full gives NaN, which is not within tolerance.
        let within = mean_error.is_finite() && mean_error.abs() <= self.tolerance;
        if self.periods < self.min_periods || !within {
            return Settle::Wait;
        }
        // Envelope: the newest window against the one before (ring order from `next`).
        let n = self.ms.len();
        let older: f64 = (0..self.window).map(|i| self.ms[(self.next + i) % n]).sum();
        let newer: f64 = (self.window..n).map(|i| self.ms[(self.next + i) % n]).sum();
        if !(older.is_finite() && newer.is_finite()) || older <= 0.0 {
            return Settle::Wait;
        }
        let change = ((newer / older).sqrt() - 1.0).abs();
        if change <= self.envelope_tolerance {
            Settle::Settled
        } else {
            Settle::Wait
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> ControlSpec {
        ControlSpec::default()
    }

    #[test]
    fn settles_after_the_minimum_once_error_and_envelope_are_steady() {
        // Two full windows (50 periods) are needed for the envelope; the minimum is 60.
        let mut d = SettleDetector::new(&spec(), 60);
        let mut got = None;
        for p in 0..200 {
            for _ in 0..100 {
                d.push_response(1.0);
            }
            if d.period_done(0.001) != Settle::Wait {
                got = Some(p + 1);
                break;
            }
        }
        assert_eq!(got, Some(60));
    }

    #[test]
    fn a_growing_response_or_a_large_error_keeps_it_waiting_until_the_timeout() {
        let mut d = SettleDetector::new(&spec(), 10);
        let mut last = Settle::Wait;
        for p in 0..40 {
            for _ in 0..100 {
                d.push_response(1.0 + 0.05 * p as f64); // grows 5 % per period
            }
            last = d.period_done(0.001);
            if last != Settle::Wait {
                assert_eq!(p + 1, 40, "stopped waiting at {p}");
            }
        }
        assert_eq!(last, Settle::TimedOut);

        let mut d = SettleDetector::new(&spec(), 10);
        for _ in 0..39 {
            d.push_response(1.0);
            assert_eq!(d.period_done(0.02), Settle::Wait);
        }
    }
}
