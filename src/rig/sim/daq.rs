//! The simulated DAQ: the anti-alias filter at the truth rate on every channel, decimation to
//! the DAQ rate, white sensor noise from a seeded ChaCha8 generator (deterministic), and
//! quantisation to ADC counts with clipping at full scale. The channel layout is the rig's
//! channel map ([`crate::rig::channels::layout`]).
//!
//! Decimation keeps the filtered value of the first truth step of every DAQ sample period (the
//! contact channel: its minimum over the period), so
//! DAQ sample `n` stands at rig time `n / sample_rate` exactly.

use crate::rig::daq::{ChannelKind, DaqLayout};
use crate::signal::noise::Gaussian;

use super::filter::Butterworth4;
use super::spec::DaqSpec;

/// Counts for a physical value: `round(value / scale)` clipped to `+-full_scale_counts`;
/// returns whether it clipped (a non-finite value reads 0 and counts as clipped).
#[inline]
pub fn quantise(value: f64, scale: f64, full_scale_counts: i32) -> (i32, bool) {
    let c = (value / scale).round();
    let fs = f64::from(full_scale_counts);
    if c.is_nan() {
        (0, true)
    } else if c > fs {
        (full_scale_counts, true)
    } else if c < -fs {
        (-full_scale_counts, true)
    } else {
        (c as i32, false)
    }
}

/// Filters, noise and ADC of all channels.
#[derive(Clone, Debug)]
pub struct Daq {
    filters: Vec<Butterworth4>,
    filtered: Vec<f64>,
    /// Channels sampled by a minimum-hold detector instead of the anti-alias filter (the
    /// contact circuit).
    min_hold: Vec<bool>,
    noise_rms: Vec<f64>,
    scale: Vec<f64>,
    full_scale_counts: Vec<i32>,
    dead: Vec<bool>,
    over_range: Vec<bool>,
    noise: Gaussian,
}

impl Daq {
    /// The DAQ for a (valid) spec and its layout, with filters at the truth rate
    /// `sample_rate * oversampling`, settled at the resting channel values `rest`.
    pub fn new(spec: &DaqSpec, layout: &DaqLayout, oversampling: u32, rest: &[f64]) -> Daq {
        let truth_rate = spec.sample_rate * f64::from(oversampling);
        let prototype = Butterworth4::new(spec.anti_alias_cutoff * spec.sample_rate, truth_rate);
        let filters = rest
            .iter()
            .map(|&x| {
                let mut f = prototype;
                f.settle_at(x);
                f
            })
            .collect();
        let n = &spec.noise_rms;
        let noise_rms = layout
            .channels
            .iter()
            .map(|c| match c.kind {
                ChannelKind::PlatformAcceleration => n.platform_acceleration,
                ChannelKind::BeamAcceleration => n.beam_acceleration,
                ChannelKind::Vibrometer => n.vibrometer,
                ChannelKind::ContactVoltage => n.contact_voltage,
                ChannelKind::DriveVoltage => n.drive_voltage,
                ChannelKind::DriveCurrent => n.drive_current,
            })
            .collect();
        let nc = layout.channels.len();
        Daq {
            filters,
            filtered: rest.to_vec(),
            min_hold: layout
                .channels
                .iter()
                .map(|c| c.kind == ChannelKind::ContactVoltage)
                .collect(),
            noise_rms,
            scale: layout.channels.iter().map(|c| c.scale).collect(),
            full_scale_counts: layout
                .channels
                .iter()
                .map(|c| c.full_scale_counts)
                .collect(),
            dead: vec![false; nc],
            over_range: vec![false; nc],
            noise: Gaussian::new(spec.noise_seed),
        }
    }

    /// Feeds one truth step of physical values (layout order) through the filters; with
    /// `keep` the outputs become the next DAQ sample.
    #[inline]
    ///
    /// NOTE (contact channel): the contact-resistance circuit feeds a minimum-hold detector,
    /// not the anti-alias filter: an impact lasts a few tens of microseconds, far shorter than
    /// a DAQ sample, and a low-pass would shave it to a dip that never crosses the threshold.
    /// Its sample is the lowest circuit voltage over the sample period's truth steps (the
    /// first of which is `keep`), so every contact shows in the sample that holds it.
    pub fn filter(&mut self, values: &[f64], keep: bool) {
        for (((f, &x), y), &hold) in self
            .filters
            .iter_mut()
            .zip(values)
            .zip(self.filtered.iter_mut())
            .zip(&self.min_hold)
        {
            if hold {
                *y = if keep { x } else { y.min(x) };
                continue;
            }
            let out = f.push(x);
            if keep {
                *y = out;
            }
        }
    }

    /// Writes the kept sample, with noise, quantised, as sample `i` of a channel-major block
    /// of `len` samples per channel. Latches over-range per channel.
    #[inline]
    pub fn sample(&mut self, counts: &mut [i32], i: usize, len: usize) {
        for k in 0..self.filtered.len() {
            // Every channel draws its deviate, dead or not, so one channel's state does not
            // shift the others' noise.
            let z = self.noise.next();
            let value = self.filtered[k] + self.noise_rms[k] * z;
            let (c, clipped) = quantise(value, self.scale[k], self.full_scale_counts[k]);
            counts[k * len + i] = if self.dead[k] { 0 } else { c };
            if clipped && !self.dead[k] {
                self.over_range[k] = true;
            }
        }
    }

    /// Channel `k` reads 0 counts from now on.
    pub fn kill(&mut self, k: usize) {
        self.dead[k] = true;
    }

    /// Channels that clipped since the start (latched).
    pub fn over_range(&self) -> &[bool] {
        &self.over_range
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantisation_rounds_and_clips() {
        let (scale, fs) = (0.5, 100);
        assert_eq!(quantise(1.24, scale, fs), (2, false));
        assert_eq!(quantise(1.26, scale, fs), (3, false));
        assert_eq!(quantise(-1.26, scale, fs), (-3, false));
        assert_eq!(quantise(50.0, scale, fs), (100, false));
        assert_eq!(quantise(50.3, scale, fs), (100, true));
        assert_eq!(quantise(-60.0, scale, fs), (-100, true));
        assert_eq!(quantise(f64::NAN, scale, fs), (0, true));
        assert_eq!(quantise(f64::INFINITY, scale, fs), (100, true));
        // 32-bit ADC: full scale is i32::MAX.
        let fsc = ((1u64 << 31) - 1) as i32;
        assert_eq!(quantise(1e30, 1.0, fsc), (i32::MAX, true));
    }

    fn run(seed: u64, value: f64, adc_bits: u32) -> (Vec<i32>, Vec<bool>) {
        let spec = DaqSpec {
            noise_seed: seed,
            adc_bits,
            ..DaqSpec::default()
        };
        let l = crate::rig::channels::layout(&spec);
        let nc = l.channels.len();
        let rest = vec![0.0; nc];
        let mut daq = Daq::new(&spec, &l, 4, &rest);
        let len = 64;
        let mut counts = vec![0; nc * len];
        let values = vec![value; nc];
        for i in 0..len {
            for sub in 0..4 {
                daq.filter(&values, sub == 0);
            }
            daq.sample(&mut counts, i, len);
        }
        (counts, daq.over_range().to_vec())
    }

    #[test]
    fn noise_is_deterministic_per_seed() {
        let (a, over) = run(7, 0.0, 24);
        let (b, _) = run(7, 0.0, 24);
        let (c, _) = run(8, 0.0, 24);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(over.iter().all(|o| !o));
        // At 24 bits every channel's noise spans several counts (the beam accelerometers'
        // 1e-2 m/s^2 RMS against 1e4 / 2^23 = 1.2e-3 m/s^2 per count has the fewest).
        let len = 64;
        for k in 0..11 {
            let ch = &a[k * len..(k + 1) * len];
            let distinct = ch.iter().collect::<std::collections::BTreeSet<_>>().len();
            assert!(distinct >= 5, "channel {k}: {distinct} distinct counts");
        }
    }

    #[test]
    fn over_range_latches_per_channel() {
        // 60 on every channel: beyond the vibrometer's 2 m/s and the contact circuit's 10 V,
        // within the other ranges (platform 100, beam 1e4, drive voltage 100, current 100).
        let (_, over) = run(1, 60.0, 12);
        assert_eq!(
            over,
            [false, false, false, false, false, false, false, true, true, false, false]
        );
    }

    #[test]
    fn gaussian_has_unit_variance() {
        let mut g = Gaussian::new(3);
        let n = 200_000;
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let z = g.next();
            s += z;
            s2 += z * z;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.01, "{var}");
    }
}
