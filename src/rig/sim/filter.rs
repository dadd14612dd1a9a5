//! The DAQ's anti-alias filter: a 4th-order Butterworth low-pass as two biquad sections
//! (bilinear transform with the cutoff prewarped, so the -3 dB point is exact), run at the
//! truth rate on every channel before decimation.

use std::f64::consts::PI;

/// One second-order section, transposed direct form II.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Biquad {
    b0: f64,
    b1: f64,
    b2: f64,
    a1: f64,
    a2: f64,
    s1: f64,
    s2: f64,
}

impl Biquad {
    /// Low-pass section of the analog prototype `1 / (s^2 + s / q + 1)` with the prewarped
    /// cutoff `k = tan(pi fc / fs)`.
    fn low_pass(k: f64, q: f64) -> Biquad {
        let k2 = k * k;
        let norm = 1.0 / (1.0 + k / q + k2);
        let b0 = k2 * norm;
        Biquad {
            b0,
            b1: 2.0 * b0,
            b2: b0,
            a1: 2.0 * (k2 - 1.0) * norm,
            a2: (1.0 - k / q + k2) * norm,
            s1: 0.0,
            s2: 0.0,
        }
    }

    #[inline(always)]
    fn push(&mut self, x: f64) -> f64 {
        let y = self.b0 * x + self.s1;
        self.s1 = self.b1 * x - self.a1 * y + self.s2;
        self.s2 = self.b2 * x - self.a2 * y;
        y
    }

    /// The state of a section that has seen the constant input `x` forever (output `x`: the
    /// DC gain is 1).
    fn settle_at(&mut self, x: f64) {
        self.s2 = (self.b2 - self.a2) * x;
        self.s1 = (self.b1 - self.a1) * x + self.s2;
    }

    /// Complex gain at normalised frequency `theta = 2 pi f / fs` as (re, im).
    fn response(&self, theta: f64) -> (f64, f64) {
        // H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2), z^-1 = e^{-i theta}.
        let (c1, s1) = (theta.cos(), -theta.sin());
        let (c2, s2) = ((2.0 * theta).cos(), -(2.0 * theta).sin());
        let (nr, ni) = (
            self.b0 + self.b1 * c1 + self.b2 * c2,
            self.b1 * s1 + self.b2 * s2,
        );
        let (dr, di) = (
            1.0 + self.a1 * c1 + self.a2 * c2,
            self.a1 * s1 + self.a2 * s2,
        );
        let d2 = dr * dr + di * di;
        ((nr * dr + ni * di) / d2, (ni * dr - nr * di) / d2)
    }
}

/// 4th-order Butterworth low-pass (two cascaded biquads).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Butterworth4 {
    sections: [Biquad; 2],
}

impl Butterworth4 {
    /// Low-pass with -3 dB cutoff `cutoff_hz` for samples at `sample_rate_hz`; requires
    /// `0 < cutoff_hz < sample_rate_hz / 2` (checked by the spec's validation).
    pub fn new(cutoff_hz: f64, sample_rate_hz: f64) -> Butterworth4 {
        let k = (PI * cutoff_hz / sample_rate_hz).tan();
        // Butterworth pole pairs of order 4: q = 1 / (2 cos(pi/8)), 1 / (2 cos(3 pi/8)).
        let q1 = 1.0 / (2.0 * (PI / 8.0).cos());
        let q2 = 1.0 / (2.0 * (3.0 * PI / 8.0).cos());
        Butterworth4 {
            sections: [Biquad::low_pass(k, q1), Biquad::low_pass(k, q2)],
        }
    }

    /// Filters the next sample.
    #[inline(always)]
    pub fn push(&mut self, x: f64) -> f64 {
        let y = self.sections[0].push(x);
        self.sections[1].push(y)
    }

    /// Sets the state to the steady state of a constant input `x` (no start-up transient for
    /// a channel that rests at a nonzero value).
    pub fn settle_at(&mut self, x: f64) {
        for s in &mut self.sections {
            s.settle_at(x);
        }
    }

    /// Magnitude of the frequency response at `f_hz` for samples at `sample_rate_hz`, -.
    pub fn gain(&self, f_hz: f64, sample_rate_hz: f64) -> f64 {
        let theta = 2.0 * PI * f_hz / sample_rate_hz;
        self.sections
            .iter()
            .map(|s| {
                let (re, im) = s.response(theta);
                re.hypot(im)
            })
            .product()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FS_DAQ: f64 = 10240.0;
    const OS: f64 = 7.0;

    fn filter() -> Butterworth4 {
        Butterworth4::new(0.25 * FS_DAQ, OS * FS_DAQ)
    }

    /// Amplitude of the filtered sine after the transient, by a least-squares fit.
    fn measured_gain(f: f64) -> f64 {
        let fs = OS * FS_DAQ;
        let mut flt = filter();
        let n = 200_000;
        let (mut sc, mut ss, mut cc, mut cs) = (0.0, 0.0, 0.0, 0.0);
        for k in 0..n {
            let ph = 2.0 * PI * f * k as f64 / fs;
            let y = flt.push(ph.sin());
            if k >= n / 2 {
                sc += y * ph.cos();
                ss += y * ph.sin();
                cc += ph.cos() * ph.cos();
                cs += ph.sin() * ph.sin();
            }
        }
        ((sc / cc).powi(2) + (ss / cs).powi(2)).sqrt()
    }

    #[test]
    fn dc_gain_is_one() {
        let mut f = filter();
        let mut y = 0.0;
        for _ in 0..20_000 {
            y = f.push(3.5);
        }
        assert!((y - 3.5).abs() < 1e-12, "{y}");
        assert!((f.gain(0.0, OS * FS_DAQ) - 1.0).abs() < 1e-12);
        let mut f = filter();
        f.settle_at(-2.0);
        assert!((f.push(-2.0) + 2.0).abs() < 1e-12);
    }

    #[test]
    fn minus_three_db_at_the_cutoff() {
        let g = filter().gain(0.25 * FS_DAQ, OS * FS_DAQ);
        assert!((g - 0.5f64.sqrt()).abs() < 1e-12, "{g}");
        let m = measured_gain(0.25 * FS_DAQ);
        assert!((m - 0.5f64.sqrt()).abs() < 1e-4, "{m}");
        // Flat in the test band (the 1FU mode and its low harmonics).
        let g55 = filter().gain(55.0, OS * FS_DAQ);
        assert!((g55 - 1.0).abs() < 1e-9, "{g55}");
    }

    #[test]
    fn attenuates_at_the_daq_nyquist_frequency() {
        // 4th order: |H(2 fc)| = 1 / sqrt(1 + 2^8) = -24.1 dB (analog); the bilinear
        // transform at 7x oversampling attenuates a little more.
        let g = filter().gain(0.5 * FS_DAQ, OS * FS_DAQ);
        let db = 20.0 * g.log10();
        assert!(db < -24.0 && db > -26.0, "{db} dB");
        let m = measured_gain(0.5 * FS_DAQ);
        assert!((m - g).abs() < 1e-4 * g.max(1e-3), "{m} vs {g}");
        // And far more at the truth-rate content that would alias onto the band.
        assert!(filter().gain(FS_DAQ, OS * FS_DAQ) < 0.005);
    }
}
