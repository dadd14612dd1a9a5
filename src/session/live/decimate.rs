//! Min/max decimation of the DAQ stream for plotting: every channel's samples are gathered in
//! bins of a fixed number of samples, aligned to the absolute sample index, and each bin becomes
//! one point holding the channel's minimum, maximum and mean in physical units.
//!
//! NOTE: min/max is the plotting choice, not an anti-alias filter: a Plot panel drawing a
//! channel's `min` and `max` shows the band the signal swept through, impact spikes included
//! (an impact lasts about a sample, a low-pass would smear it away), and never invents content
//! that was not there. The `mean` is a boxcar average: good for slow content (drift, the
//! contact-voltage duty) but not alias-free for content above half the point rate.
//!
//! Pure and synchronous: no clock, no I/O; the accumulators are allocated once in
//! [`MinMaxDecimator::new`], pushing blocks does not allocate.

use crate::rig::{DaqBlock, DaqLayout};

/// One finished bin: a decimated time point of every channel, in physical units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecimatedPoint<'a> {
    /// Index of the bin's first sample since the stream started.
    pub first_sample: u64,
    /// Rig time of the bin's first sample, s (`first_sample / sample_rate`).
    pub time: f64,
    /// Samples in the bin: the bin size, fewer for a bin cut short by a gap in the stream or by
    /// the end of the session.
    pub samples: u32,
    /// Smallest value per channel (layout order), in the channel's unit.
    pub min: &'a [f64],
    /// Largest value per channel.
    pub max: &'a [f64],
    /// Mean value per channel.
    pub mean: &'a [f64],
}

/// Samples per bin for `points_per_second` decimated points per second at `sample_rate`:
/// the nearest whole number of samples, at least 1 (no decimation when the rate asked for is
/// at or above the sample rate).
pub fn bin_samples(sample_rate: f64, points_per_second: f64) -> usize {
    let n = (sample_rate / points_per_second).round();
    if n.is_finite() && n >= 1.0 {
        n as usize
    } else {
        1
    }
}

/// Min/max decimator of one DAQ stream (or of any set of channels sampled on the DAQ's time
/// base, such as the twin's predictions: [`MinMaxDecimator::push_values`]).
#[derive(Clone, Debug)]
pub struct MinMaxDecimator {
    /// Samples per bin.
    bin: u64,
    sample_rate: f64,
    scales: Vec<f64>,
    /// First sample of the open bin.
    start: u64,
    /// Sample index the open bin expects next.
    next: u64,
    /// Samples in the open bin (0: no bin open).
    n: u64,
    // NOTE: accumulated in f64 in the channels' raw units (counts for DAQ blocks): sums of up
    // to 2^29 counts of 24-bit ADCs are exact in f64, so DAQ points equal integer accumulation.
    lo: Vec<f64>,
    hi: Vec<f64>,
    sum: Vec<f64>,
    /// Physical values of the bin being handed out.
    out_min: Vec<f64>,
    out_max: Vec<f64>,
    out_mean: Vec<f64>,
    /// Blocks skipped because their counts did not match the layout.
    skipped: u64,
}

impl MinMaxDecimator {
    /// A decimator for `layout`'s channels with `bin_samples` samples per bin (at least 1).
    pub fn new(layout: &DaqLayout, bin_samples: usize) -> Self {
        let scales = layout.channels.iter().map(|c| c.scale).collect();
        Self::with_scales(layout.sample_rate, scales, bin_samples)
    }

    /// A decimator for channels sampled at `sample_rate` (Hz) whose raw values become physical
    /// ones times `scales` (1.0 for values already in physical units), `bin_samples` samples per
    /// bin (at least 1).
    pub fn with_scales(sample_rate: f64, scales: Vec<f64>, bin_samples: usize) -> Self {
        let k = scales.len();
        Self {
            bin: bin_samples.max(1) as u64,
            sample_rate,
            scales,
            start: 0,
            next: 0,
            n: 0,
            lo: vec![0.0; k],
            hi: vec![0.0; k],
            sum: vec![0.0; k],
            out_min: vec![0.0; k],
            out_max: vec![0.0; k],
            out_mean: vec![0.0; k],
            skipped: 0,
        }
    }

    /// Samples per bin.
    pub fn bin_samples(&self) -> usize {
        self.bin as usize
    }

    /// Decimated points per second of rig time.
    pub fn points_per_second(&self) -> f64 {
        self.sample_rate / self.bin as f64
    }

    /// Blocks skipped so far because their sample count did not match the layout.
    pub fn skipped_blocks(&self) -> u64 {
        self.skipped
    }

    /// Adds a block; calls `emit` for every bin it completes, in time order. A block that does
    /// not continue the previous one (lost blocks) first closes the open bin as it is. A block
    /// whose counts do not match the layout is skipped (and closes the open bin).
    pub fn push(&mut self, block: &DaqBlock, emit: &mut dyn FnMut(&DecimatedPoint<'_>)) {
        if block.counts.len() != self.scales.len() * block.len {
            self.skipped += 1;
            self.finish(emit);
            return;
        }
        let counts = &block.counts;
        self.push_with(block.first_sample, block.len, emit, |at| {
            f64::from(counts[at])
        });
    }

    /// Adds `len` samples per channel from sample `first_sample` on, channel-major in
    /// `values` (`values[k * len + i]`), like [`MinMaxDecimator::push`]. Values that do not
    /// match the channel count are skipped like a bad block.
    pub fn push_values(
        &mut self,
        first_sample: u64,
        len: usize,
        values: &[f64],
        emit: &mut dyn FnMut(&DecimatedPoint<'_>),
    ) {
        if values.len() != self.scales.len() * len {
            self.skipped += 1;
            self.finish(emit);
            return;
        }
        self.push_with(first_sample, len, emit, |at| values[at]);
    }

    fn push_with(
        &mut self,
        first_sample: u64,
        len: usize,
        emit: &mut dyn FnMut(&DecimatedPoint<'_>),
        value: impl Fn(usize) -> f64,
    ) {
        let channels = self.scales.len();
        let mut i = 0usize;
        while i < len {
            let s = first_sample + i as u64;
            if self.n > 0 && s != self.next {
                self.emit(emit);
            }
            let bin_end = (s / self.bin + 1) * self.bin;
            let take = ((bin_end - s) as usize).min(len - i);
            for k in 0..channels {
                let (mut lo, mut hi, mut sum) = if self.n == 0 {
                    (f64::INFINITY, f64::NEG_INFINITY, 0.0)
                } else {
                    (self.lo[k], self.hi[k], self.sum[k])
                };
                for at in k * len + i..k * len + i + take {
                    let c = value(at);
                    lo = lo.min(c);
                    hi = hi.max(c);
                    sum += c;
                }
                self.lo[k] = lo;
                self.hi[k] = hi;
                self.sum[k] = sum;
            }
            if self.n == 0 {
                self.start = s;
            }
            self.n += take as u64;
            self.next = s + take as u64;
            i += take;
            if self.next == bin_end {
                self.emit(emit);
            }
        }
    }

    /// Closes the open bin, if any (end of the stream).
    pub fn finish(&mut self, emit: &mut dyn FnMut(&DecimatedPoint<'_>)) {
        if self.n > 0 {
            self.emit(emit);
        }
    }

    fn emit(&mut self, emit: &mut dyn FnMut(&DecimatedPoint<'_>)) {
        let n = self.n as f64;
        for (k, &scale) in self.scales.iter().enumerate() {
            self.out_min[k] = self.lo[k] * scale;
            self.out_max[k] = self.hi[k] * scale;
            self.out_mean[k] = self.sum[k] / n * scale;
        }
        let point = DecimatedPoint {
            first_sample: self.start,
            time: self.start as f64 / self.sample_rate,
            samples: self.n as u32,
            min: &self.out_min,
            max: &self.out_max,
            mean: &self.out_mean,
        };
        emit(&point);
        self.n = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::{ChannelKind, ChannelSpec};

    fn layout(sample_rate: f64, block_size: usize, scales: &[f64]) -> DaqLayout {
        DaqLayout {
            sample_rate,
            block_size,
            channels: scales
                .iter()
                .enumerate()
                .map(|(k, &scale)| ChannelSpec {
                    name: format!("ch{k}"),
                    kind: ChannelKind::BeamAcceleration,
                    scale,
                    full_scale_counts: 1 << 23,
                })
                .collect(),
        }
    }

    /// A block of `len` samples from `first`, channel k's sample s being `f(k, s)`.
    fn block(
        seq: u64,
        first: u64,
        len: usize,
        k: usize,
        f: impl Fn(usize, u64) -> i32,
    ) -> DaqBlock {
        let mut counts = Vec::with_capacity(k * len);
        for ch in 0..k {
            counts.extend((0..len as u64).map(|i| f(ch, first + i)));
        }
        DaqBlock {
            seq,
            first_sample: first,
            time: first as f64 / 1000.0,
            len,
            counts,
        }
    }

    #[derive(Debug, PartialEq)]
    struct Owned {
        first: u64,
        time: f64,
        samples: u32,
        min: Vec<f64>,
        max: Vec<f64>,
        mean: Vec<f64>,
    }

    impl Owned {
        fn of(p: &DecimatedPoint<'_>) -> Owned {
            Owned {
                first: p.first_sample,
                time: p.time,
                samples: p.samples,
                min: p.min.to_vec(),
                max: p.max.to_vec(),
                mean: p.mean.to_vec(),
            }
        }
    }

    fn collect(d: &mut MinMaxDecimator, blocks: &[DaqBlock], finish: bool) -> Vec<Owned> {
        let mut out = Vec::new();
        let mut emit = |p: &DecimatedPoint<'_>| out.push(Owned::of(p));
        for b in blocks {
            d.push(b, &mut emit);
        }
        if finish {
            d.finish(&mut emit);
        }
        out
    }

    #[test]
    fn bin_size_follows_the_rate_asked_for() {
        assert_eq!(bin_samples(10_240.0, 200.0), 51);
        assert_eq!(bin_samples(10_240.0, 160.0), 64);
        assert_eq!(bin_samples(1000.0, 5000.0), 1);
        assert_eq!(bin_samples(1000.0, 0.0), 1);
        assert_eq!(bin_samples(1000.0, f64::NAN), 1);
    }

    #[test]
    fn bins_span_blocks_and_keep_min_max_mean_in_physical_units() {
        // Bins of 4 samples over blocks of 6: bins cross block boundaries.
        let l = layout(1000.0, 6, &[0.5, 2.0]);
        let mut d = MinMaxDecimator::new(&l, 4);
        let f = |ch: usize, s: u64| if ch == 0 { s as i32 } else { -(s as i32) };
        let blocks: Vec<DaqBlock> = (0..4).map(|b| block(b, b * 6, 6, 2, f)).collect();
        let pts = collect(&mut d, &blocks, false);
        assert_eq!(pts.len(), 6, "24 samples in bins of 4");
        for (j, p) in pts.iter().enumerate() {
            let s0 = 4 * j as u64;
            assert_eq!(p.first, s0);
            assert_eq!(p.samples, 4);
            assert!((p.time - s0 as f64 / 1000.0).abs() < 1e-15);
            assert_eq!(p.min, vec![0.5 * s0 as f64, -2.0 * (s0 + 3) as f64]);
            assert_eq!(p.max, vec![0.5 * (s0 + 3) as f64, -2.0 * s0 as f64]);
            assert_eq!(
                p.mean,
                vec![0.5 * (s0 as f64 + 1.5), -2.0 * (s0 as f64 + 1.5)]
            );
        }
    }

    #[test]
    fn values_in_physical_units_decimate_like_counts_times_their_scales() {
        // The same samples as scaled counts (DAQ) and as physical values (the twin's path),
        // over blocks of 7 with a gap: identical points.
        let l = layout(1000.0, 7, &[0.5, 2.0]);
        let f = |ch: usize, s: u64| ((s * 37 + ch as u64 * 11) % 23) as i32 - 11;
        let blocks: Vec<DaqBlock> = [0u64, 1, 2, 4]
            .iter()
            .map(|&b| block(b, b * 7, 7, 2, f))
            .collect();
        let from_counts = collect(&mut MinMaxDecimator::new(&l, 5), &blocks, true);
        let mut d = MinMaxDecimator::with_scales(1000.0, vec![1.0, 1.0], 5);
        let mut from_values = Vec::new();
        let mut emit = |p: &DecimatedPoint<'_>| from_values.push(Owned::of(p));
        for b in &blocks {
            let values: Vec<f64> = (0..2)
                .flat_map(|k| {
                    b.channel(k)
                        .iter()
                        .map(move |&c| f64::from(c) * [0.5, 2.0][k])
                })
                .collect();
            d.push_values(b.first_sample, b.len, &values, &mut emit);
        }
        d.push_values(99, 3, &[0.0; 5], &mut emit);
        d.finish(&mut emit);
        assert_eq!(
            d.skipped_blocks(),
            1,
            "values of the wrong length are skipped"
        );
        assert_eq!(from_values.len(), from_counts.len());
        for (a, b) in from_values.iter().zip(&from_counts) {
            assert_eq!(
                (a.first, a.samples, &a.min, &a.max),
                (b.first, b.samples, &b.min, &b.max)
            );
            for (x, y) in a.mean.iter().zip(&b.mean) {
                assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0), "{x} {y}");
            }
        }
    }

    #[test]
    fn a_one_sample_spike_survives_decimation() {
        // A 50 Hz sine of amplitude 1000 counts at 10 kHz with one impact spike of 20000 counts:
        // a bin average would bury it, the bin maximum keeps it.
        let l = layout(10_000.0, 256, &[1e-3]);
        let mut d = MinMaxDecimator::new(&l, 50);
        let spike_at = 1234u64;
        let f = |_: usize, s: u64| {
            if s == spike_at {
                20_000
            } else {
                (1000.0 * (2.0 * std::f64::consts::PI * 50.0 * s as f64 / 10_000.0).sin()).round()
                    as i32
            }
        };
        let blocks: Vec<DaqBlock> = (0..8).map(|b| block(b, b * 256, 256, 1, f)).collect();
        let pts = collect(&mut d, &blocks, true);
        let peak = pts.iter().map(|p| p.max[0]).fold(f64::MIN, f64::max);
        assert_eq!(peak, 20.0);
        let with_spike = pts
            .iter()
            .find(|p| p.first <= spike_at && spike_at < p.first + u64::from(p.samples))
            .unwrap();
        assert_eq!(with_spike.max[0], 20.0);
        assert!(with_spike.mean[0] < 2.0, "{}", with_spike.mean[0]);
        // The sine's envelope: every bin within +-1, the extremes reached.
        assert!(pts.iter().all(|p| p.min[0] >= -1.0 - 1e-12));
        assert!(pts.iter().any(|p| p.min[0] <= -0.999));
    }

    #[test]
    fn bins_are_aligned_to_the_sample_index_and_a_gap_closes_the_open_bin() {
        let l = layout(1000.0, 10, &[1.0]);
        let mut d = MinMaxDecimator::new(&l, 4);
        // Samples 0..10, then a lost block, then 20..30.
        let blocks = [
            block(0, 0, 10, 1, |_, s| s as i32),
            block(2, 20, 10, 1, |_, s| s as i32),
        ];
        let pts = collect(&mut d, &blocks, true);
        let spans: Vec<(u64, u32)> = pts.iter().map(|p| (p.first, p.samples)).collect();
        // 0-3, 4-7, 8-9 (cut by the gap), 20-23, 24-27, 28-29 (end of stream).
        assert_eq!(
            spans,
            vec![(0, 4), (4, 4), (8, 2), (20, 4), (24, 4), (28, 2)]
        );
        assert_eq!(pts[2].max, vec![9.0]);
        assert_eq!(pts[3].min, vec![20.0]);
    }

    #[test]
    fn a_malformed_block_is_skipped_without_panicking() {
        let l = layout(1000.0, 4, &[1.0, 1.0]);
        let mut d = MinMaxDecimator::new(&l, 2);
        let mut bad = block(1, 4, 4, 2, |_, s| s as i32);
        bad.counts.pop();
        let blocks = [block(0, 0, 3, 2, |_, s| s as i32), bad];
        let pts = collect(&mut d, &blocks, true);
        assert_eq!(d.skipped_blocks(), 1);
        let spans: Vec<(u64, u32)> = pts.iter().map(|p| (p.first, p.samples)).collect();
        assert_eq!(spans, vec![(0, 2), (2, 1)]);
    }

    #[test]
    fn the_point_rate_is_the_sample_rate_over_the_bin() {
        let l = layout(10_240.0, 256, &[1.0; 11]);
        let mut d = MinMaxDecimator::new(&l, bin_samples(10_240.0, 200.0));
        // One second of blocks.
        let blocks: Vec<DaqBlock> = (0..40)
            .map(|b| block(b, b * 256, 256, 11, |k, s| (k as i32) * 7 - (s % 13) as i32))
            .collect();
        let pts = collect(&mut d, &blocks, false);
        assert_eq!(pts.len(), 10_240 / 51);
        assert!((d.points_per_second() - 200.78).abs() < 0.01);
    }
}
