//! The twin's input: the base acceleration of a DAQ block, the mean of the platform
//! accelerometers in physical units (m/s^2), with the block's place in the stream.
//!
//! Extraction is separate from integration so the twin task can do it on the producer's
//! side (checking the block there, and queueing 8 bytes per sample instead of the whole
//! block) while replay calls [`super::Twin::push_block`]: both run the same code, so they
//! give the same bits.

use crate::rig::channels::{base_acceleration, platform_accelerometers};
use crate::rig::daq::{DaqBlock, DaqLayout};

use super::error::{BlockError, LayoutError, TwinError};

/// The base acceleration of one DAQ block and where the block sits in the stream.
#[derive(Clone, Debug, PartialEq)]
pub struct TwinInput {
    /// Sequence number of the DAQ block.
    pub seq: u64,
    /// Index of the block's first sample since the stream started.
    pub first_sample: u64,
    /// Rig time of the first sample, s.
    pub time: f64,
    /// Base acceleration per sample, m/s^2: the mean of the platform accelerometers.
    pub base_acceleration: Vec<f64>,
}

impl TwinInput {
    /// Samples in the block.
    pub fn len(&self) -> usize {
        self.base_acceleration.len()
    }

    /// Whether the block has no samples.
    pub fn is_empty(&self) -> bool {
        self.base_acceleration.is_empty()
    }
}

/// Where the platform accelerometers are in a DAQ layout, and their scales.
#[derive(Clone, Debug, PartialEq)]
pub struct InputMap {
    /// (channel index, scale in m/s^2 per count) of every platform accelerometer.
    platform: Vec<(usize, f64)>,
    n_channels: usize,
    sample_rate: f64,
}

impl InputMap {
    /// The map for a layout. Fails when the layout has no platform accelerometer, a platform
    /// channel with a non-finite scale, or a sample rate that is not a finite number > 0.
    pub fn new(layout: &DaqLayout) -> Result<InputMap, TwinError> {
        InputMap::with_gains(layout, &[])
    }

    /// [`InputMap::new`] with the platform accelerometers' sensitivities (true over nominal,
    /// `(channel index, gain)`; 1 for a channel not listed) divided out of their scales, so
    /// the base acceleration is the true one (see [`super::observe`]).
    pub fn with_gains(layout: &DaqLayout, gains: &[(usize, f64)]) -> Result<InputMap, TwinError> {
        let fs = layout.sample_rate;
        if !(fs.is_finite() && fs > 0.0) {
            return Err(LayoutError::SampleRate(fs).into());
        }
        let platform: Vec<(usize, f64)> = platform_accelerometers(layout)
            .into_iter()
            .map(|(k, scale)| (k, scale / crate::physics::sensor_gain::gain_of(gains, k)))
            .collect();
        if platform.is_empty() {
            return Err(LayoutError::NoPlatform {
                channels: layout.channels.iter().map(|c| c.name.clone()).collect(),
            }
            .into());
        }
        if let Some(&(k, s)) = platform.iter().find(|(_, s)| !s.is_finite()) {
            return Err(LayoutError::Scale {
                channel: layout.channels[k].name.clone(),
                scale: s,
            }
            .into());
        }
        Ok(InputMap {
            platform,
            n_channels: layout.channels.len(),
            sample_rate: fs,
        })
    }

    /// Sample rate of the stream, Hz.
    pub fn sample_rate(&self) -> f64 {
        self.sample_rate
    }

    /// Number of platform accelerometers averaged.
    pub fn n_platform(&self) -> usize {
        self.platform.len()
    }

    /// The base acceleration of a block. Fails on a block without samples or whose number of
    /// counts is not `channels x len`.
    pub fn extract(&self, block: &DaqBlock) -> Result<TwinInput, TwinError> {
        if block.len == 0 {
            return Err(BlockError::Empty { seq: block.seq }.into());
        }
        if block.counts.len() != self.n_channels * block.len {
            return Err(BlockError::Shape {
                seq: block.seq,
                counts: block.counts.len(),
                channels: self.n_channels,
                len: block.len,
            }
            .into());
        }
        let base_acceleration = (0..block.len)
            .map(|i| base_acceleration(&self.platform, &block.counts, block.len, i))
            .collect();
        Ok(TwinInput {
            seq: block.seq,
            first_sample: block.first_sample,
            time: block.time,
            base_acceleration,
        })
    }
}
