//! What a rig backend streams and accepts: the DAQ channel layout, timestamped DAQ blocks of
//! raw ADC counts with sequence numbers, drive commands, rig status and faults. Hardware and
//! simulated backends produce exactly these types, so control, logging and replay never know
//! which backend they talk to.
//!
//! Samples travel as integer ADC counts (what a DAQ delivers); the physical value of count `c`
//! on channel `k` is `c * channels[k].scale` in the channel's unit. Keeping counts makes the
//! log exact and replay bit-for-bit: every consumer converts with the same scale.

use serde::{Deserialize, Serialize};

/// What a DAQ channel measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChannelKind {
    /// Accelerometer on the shaker platform (vertical, absolute), m/s^2.
    PlatformAcceleration,
    /// Accelerometer on a beam (vertical, absolute), m/s^2.
    BeamAcceleration,
    /// Laser vibrometer velocity at the upper tip (vertical, absolute), m/s.
    Vibrometer,
    /// Voltage across the beam-to-beam contact-resistance circuit, V (high = open, low = closed).
    ContactVoltage,
    /// Amplifier output voltage at the shaker coil, V.
    DriveVoltage,
    /// Shaker coil current, A.
    DriveCurrent,
}

impl ChannelKind {
    /// SI unit of the physical value.
    pub fn unit(self) -> &'static str {
        match self {
            ChannelKind::PlatformAcceleration | ChannelKind::BeamAcceleration => "m/s^2",
            ChannelKind::Vibrometer => "m/s",
            ChannelKind::ContactVoltage | ChannelKind::DriveVoltage => "V",
            ChannelKind::DriveCurrent => "A",
        }
    }
}

/// One DAQ channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ChannelSpec {
    /// Channel name, unique in the layout (e.g. "platform_1", "upper_tip", "vibrometer").
    pub name: String,
    /// What it measures.
    pub kind: ChannelKind,
    /// Physical value per ADC count, in the unit of `kind` (full scale / 2^(bits-1)).
    pub scale: f64,
    /// Largest count magnitude the ADC delivers (2^(bits-1) - 1); counts at +-this are clipped.
    pub full_scale_counts: i32,
}

impl ChannelSpec {
    /// Physical value of a count.
    #[inline]
    pub fn value(&self, count: i32) -> f64 {
        f64::from(count) * self.scale
    }
}

/// The channel layout and sample rate of a DAQ stream (fixed for a session).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DaqLayout {
    /// Samples per second per channel, Hz.
    pub sample_rate: f64,
    /// Samples per channel in every block.
    pub block_size: usize,
    /// The channels, in the order of [`DaqBlock::counts`].
    pub channels: Vec<ChannelSpec>,
}

impl DaqLayout {
    /// Index of the channel called `name`.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.channels.iter().position(|c| c.name == name)
    }

    /// Indices of all channels of a kind, in layout order.
    pub fn indices_of(&self, kind: ChannelKind) -> Vec<usize> {
        self.channels
            .iter()
            .enumerate()
            .filter(|(_, c)| c.kind == kind)
            .map(|(i, _)| i)
            .collect()
    }

    /// Sample interval, s.
    pub fn dt(&self) -> f64 {
        1.0 / self.sample_rate
    }
}

/// One block of samples of every channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DaqBlock {
    /// Block sequence number, 0 for the first block of a session, +1 per block. A gap means
    /// lost data.
    pub seq: u64,
    /// Index of the block's first sample since the stream started (`seq * block_size` unless
    /// blocks were lost).
    pub first_sample: u64,
    /// Rig time of the first sample, s (the DAQ's sample clock: `first_sample / sample_rate`).
    pub time: f64,
    /// Samples per channel in this block.
    pub len: usize,
    /// ADC counts, channel-major: `counts[k * len + i]` is sample `i` of channel `k`.
    pub counts: Vec<i32>,
}

impl DaqBlock {
    /// The counts of channel `k`.
    pub fn channel(&self, k: usize) -> &[i32] {
        &self.counts[k * self.len..(k + 1) * self.len]
    }

    /// Checks the block against a layout: length and count range. Returns the first problem
    /// (a block from hardware is external data).
    pub fn check(&self, layout: &DaqLayout) -> Result<(), BlockError> {
        let n_ch = layout.channels.len();
        if self.len == 0 {
            return Err(BlockError::Empty { seq: self.seq });
        }
        if self.counts.len() != n_ch * self.len {
            return Err(BlockError::Shape {
                seq: self.seq,
                counts: self.counts.len(),
                channels: n_ch,
                len: self.len,
            });
        }
        for (k, ch) in layout.channels.iter().enumerate() {
            if let Some(c) = self
                .channel(k)
                .iter()
                .find(|c| c.unsigned_abs() > ch.full_scale_counts.unsigned_abs())
            {
                return Err(BlockError::FullScale {
                    seq: self.seq,
                    channel: ch.name.clone(),
                    count: *c,
                    full_scale_counts: ch.full_scale_counts,
                });
            }
        }
        Ok(())
    }
}

/// A block that does not fit its layout.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BlockError {
    /// No samples.
    #[error("block {seq}: no samples")]
    Empty {
        /// Block sequence number.
        seq: u64,
    },
    /// Not `channels x len` counts.
    #[error("block {seq}: {counts} counts for {channels} channels x {len} samples")]
    Shape {
        /// Block sequence number.
        seq: u64,
        /// Counts in the block.
        counts: usize,
        /// Channels of the layout.
        channels: usize,
        /// Samples per channel of the block.
        len: usize,
    },
    /// A count beyond its channel's full scale.
    #[error("block {seq}, channel {channel}: count {count} beyond full scale {full_scale_counts}")]
    FullScale {
        /// Block sequence number.
        seq: u64,
        /// Channel name.
        channel: String,
        /// The count.
        count: i32,
        /// The channel's full scale, counts.
        full_scale_counts: i32,
    },
}

/// A drive command out of range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// Frequency not finite, not > 0 or not below the DAQ's Nyquist frequency.
    #[error(
        "frequency_hz = {frequency_hz}: expected > 0 and below the DAQ's Nyquist frequency \
         {nyquist_hz} Hz"
    )]
    Frequency {
        /// The commanded frequency, Hz.
        frequency_hz: f64,
        /// The DAQ's Nyquist frequency, Hz.
        nyquist_hz: f64,
    },
    /// Amplitude not finite or negative.
    #[error("amplitude_v = {amplitude_v}: expected a finite amplitude >= 0 V")]
    Amplitude {
        /// The commanded amplitude, V.
        amplitude_v: f64,
    },
    /// Ramp time not finite or negative.
    #[error("ramp_s = {ramp_s}: expected a finite ramp time >= 0 s")]
    Ramp {
        /// The commanded ramp time, s.
        ramp_s: f64,
    },
    /// A value not finite or out of range (the whole command shown).
    #[error("{command:?}")]
    Invalid {
        /// The command.
        command: DriveCommand,
    },
}

/// A drive command: the shaker amplifier's input sine. The backend changes the frequency
/// phase-continuously and ramps the amplitude linearly from its current value over `ramp_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DriveCommand {
    /// Drive frequency, Hz (> 0).
    pub frequency_hz: f64,
    /// Amplitude of the amplifier input, V (>= 0).
    pub amplitude_v: f64,
    /// Time over which the amplitude moves to the new value, s (>= 0; 0 = at the next sample).
    pub ramp_s: f64,
}

/// The drive as the backend applies it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DriveState {
    /// Current drive frequency, Hz.
    pub frequency_hz: f64,
    /// Current amplitude of the amplifier input, V.
    pub amplitude_v: f64,
    /// Amplitude the current ramp heads for, V.
    pub target_amplitude_v: f64,
    /// Phase of the drive sine, rad (wrapped to [0, 2 pi)).
    pub phase: f64,
}

/// A fault reported by a backend (hardware or simulated). The controller aborts on any.
#[derive(
    Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema, thiserror::Error,
)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RigFault {
    /// The amplifier clipped its output (drive saturation).
    #[error("amplifier output saturated at {limit_v} V")]
    DriveSaturated {
        /// The amplifier's output limit, V.
        limit_v: f64,
    },
    /// A channel's ADC clipped.
    #[error("channel {channel}: ADC over range")]
    OverRange {
        /// Channel name.
        channel: String,
    },
    /// The backend reports a broken link or device.
    // NOTE: a struct variant: serde's internally tagged enums cannot serialize a newtype
    // variant holding a string (as `Device(String)` was, which made every abort and status
    // with a device fault fail to log).
    #[error("{message}")]
    Device {
        /// What happened.
        message: String,
    },
}

impl RigFault {
    /// A device fault with this message.
    pub fn device(message: impl Into<String>) -> RigFault {
        RigFault::Device {
            message: message.into(),
        }
    }
}

/// Backend status.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RigStatus {
    /// Rig time of the last delivered sample, s.
    pub time: f64,
    /// Whether the stream is running.
    pub running: bool,
    /// The drive.
    pub drive: DriveState,
    /// Faults raised since the start (latched).
    pub faults: Vec<RigFault>,
    /// Blocks delivered later than the wall clock allowed (real-time pacing only).
    pub overruns: u64,
    /// Link counters of a hardware backend (CAN and serial links); absent for the simulated
    /// rig and in logs written before the hardware backend existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<LinkCounters>,
}

/// What a hardware backend's links saw since the start: counted, never silently dropped.
/// Logged with the rig status on `/rig/status`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct LinkCounters {
    /// CAN frames received (all messages, well-formed or not).
    pub frames_received: u64,
    /// CAN frames sent.
    pub frames_sent: u64,
    /// CAN frames that did not decode (unknown id, wrong length, bad field, wrong direction,
    /// sample frames of a block without header).
    pub malformed: u64,
    /// DAQ blocks lost (incomplete when a later block was due, or missing headers).
    pub sequence_gaps: u64,
    /// Frames that arrived after a later frame of the same or a later block.
    pub reordered: u64,
    /// Frames received twice.
    pub duplicates: u64,
    /// DAQ blocks whose payload CRC-32 did not match the header's (dropped).
    pub crc_errors: u64,
    /// Device heartbeats that did not arrive in time.
    pub heartbeat_misses: u64,
    /// Serial requests without an answer in time (both ports).
    pub serial_timeouts: u64,
    /// Serial lines with a wrong checksum.
    pub serial_checksum_errors: u64,
    /// Serial input that is not a protocol line (bad bytes, overlong, no checksum, bad reply).
    pub serial_garbage: u64,
    /// Last time-sync round trip, s (None before the first).
    pub round_trip_s: Option<f64>,
    /// Device clock minus host clock from the last time sync, s.
    pub clock_offset_s: Option<f64>,
    /// The last link problem, as text.
    pub last_error: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fault_serializes_and_reads_back() {
        for f in [
            RigFault::DriveSaturated { limit_v: 1.5 },
            RigFault::OverRange {
                channel: "vibrometer".into(),
            },
            RigFault::Device {
                message: "link gone".into(),
            },
        ] {
            let j = serde_json::to_string(&f).unwrap();
            assert_eq!(serde_json::from_str::<RigFault>(&j).unwrap(), f, "{j}");
        }
    }
}
