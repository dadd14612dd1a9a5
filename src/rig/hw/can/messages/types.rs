//! The typed contents of each message (raw signal values; physical value = raw x the
//! signal's factor, see the `*_RES` constants) and their conversions to and from the rig's
//! drive types.

use super::table::{AMPLITUDE_RES, FREQUENCY_RES, PHASE_RES, RAMP_RES, SAMPLES_PER_FRAME};

/// FAULT codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FaultCode {
    /// The device saw no HOST_HEARTBEAT for 500 ms and ramped the drive down.
    HeartbeatLost = 1,
    /// The rig's interlock opened (the drive is off).
    Interlock = 2,
    /// The power amplifier reported an overload.
    AmplifierOverload = 3,
    /// A DAQ channel clipped (FaultChannel).
    OverRange = 4,
    /// The amplifier output saturated at FaultValue V.
    DriveSaturated = 5,
    /// Any other device error.
    DeviceError = 6,
}

impl FaultCode {
    pub(super) fn from_raw(v: i128) -> Option<FaultCode> {
        Some(match v {
            1 => FaultCode::HeartbeatLost,
            2 => FaultCode::Interlock,
            3 => FaultCode::AmplifierOverload,
            4 => FaultCode::OverRange,
            5 => FaultCode::DriveSaturated,
            6 => FaultCode::DeviceError,
            _ => return None,
        })
    }
}

/// FAULT.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// What happened.
    pub code: FaultCode,
    /// Channel index (OverRange), 255 otherwise.
    pub channel: u8,
    /// Raw value (`* FAULT_VALUE_RES` V).
    pub value: i32,
    /// Faults raised since the start.
    pub count: u16,
}

/// STREAM_CONTROL commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamCommand {
    /// Start streaming from BlockSeq 0 with the drive at zero.
    Start = 1,
    /// Stop: drive off, no more blocks.
    Stop = 2,
}

/// STREAM_CONTROL.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamControl {
    /// Start or stop.
    pub command: StreamCommand,
    /// Host's session number.
    pub session: u32,
}

/// DRIVE_SETPOINT (raw fields; see the `*_RES` constants).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveSetpoint {
    /// Counter.
    pub seq: u16,
    /// Drive on.
    pub enable: bool,
    /// Frequency / FREQUENCY_RES.
    pub frequency: u64,
    /// Amplitude / AMPLITUDE_RES.
    pub amplitude: u32,
    /// Ramp time / RAMP_RES.
    pub ramp: u32,
}

/// A drive command that does not fit DRIVE_SETPOINT's signals.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SetpointError {
    /// Amplitude or ramp time beyond its 32-bit raw range (or not finite).
    #[error(
        "DRIVE_SETPOINT {signal} = {value}: outside 0..={} ({res} per count, 32 bits)",
        f64::from(u32::MAX) * .res
    )]
    Range {
        /// Signal ("Amplitude", "RampTime").
        signal: &'static str,
        /// The commanded value.
        value: f64,
        /// The signal's resolution per count.
        res: f64,
    },
    /// A frequency that is not finite and > 0 (or beyond the field).
    #[error("DRIVE_SETPOINT Frequency = {frequency_hz} Hz: expected > 0 and finite")]
    Frequency {
        /// The commanded frequency, Hz.
        frequency_hz: f64,
    },
    /// A frequency that rounds to 0.
    #[error("DRIVE_SETPOINT Frequency = {frequency_hz} Hz: expected > 0")]
    ZeroFrequency {
        /// The commanded frequency, Hz.
        frequency_hz: f64,
    },
}

impl DriveSetpoint {
    /// Quantises a drive command (nearest raw values); `Err` names the field out of range.
    pub fn from_command(
        seq: u16,
        cmd: &crate::rig::DriveCommand,
    ) -> Result<DriveSetpoint, SetpointError> {
        let q = |signal: &'static str, value: f64, res: f64| -> Result<u32, SetpointError> {
            let r = (value / res).round();
            if value.is_finite() && r >= 0.0 && r <= f64::from(u32::MAX) {
                Ok(r as u32)
            } else {
                Err(SetpointError::Range { signal, value, res })
            }
        };
        let f = (cmd.frequency_hz / FREQUENCY_RES).round();
        if !(cmd.frequency_hz.is_finite() && (1.0..1.8e19).contains(&f)) {
            return Err(SetpointError::Frequency {
                frequency_hz: cmd.frequency_hz,
            });
        }
        let frequency = f as u64;
        if frequency == 0 {
            return Err(SetpointError::ZeroFrequency {
                frequency_hz: cmd.frequency_hz,
            });
        }
        Ok(DriveSetpoint {
            seq,
            enable: true,
            frequency,
            amplitude: q("Amplitude", cmd.amplitude_v, AMPLITUDE_RES)?,
            ramp: q("RampTime", cmd.ramp_s, RAMP_RES)?,
        })
    }

    /// The command it stands for (amplitude 0 when not enabled).
    pub fn command(&self) -> crate::rig::DriveCommand {
        crate::rig::DriveCommand {
            frequency_hz: self.frequency as f64 * FREQUENCY_RES,
            amplitude_v: if self.enable {
                f64::from(self.amplitude) * AMPLITUDE_RES
            } else {
                0.0
            },
            ramp_s: f64::from(self.ramp) * RAMP_RES,
        }
    }
}

/// DRIVE_STATUS (raw fields).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveStatus {
    /// Block whose last sample this describes.
    pub block_seq: u32,
    /// Last setpoint applied.
    pub applied_seq: u16,
    /// 0 idle, 1 running, 2 safety ramp-down, 3 off after a fault.
    pub state: u8,
    /// Frequency / FREQUENCY_RES.
    pub frequency: u64,
    /// Amplitude / AMPLITUDE_RES.
    pub amplitude: u32,
    /// Target amplitude / AMPLITUDE_RES.
    pub target: u32,
    /// Phase / PHASE_RES.
    pub phase: u16,
}

impl DriveStatus {
    /// Quantises a drive state (saturating at the field limits).
    pub fn from_state(
        block_seq: u32,
        applied_seq: u16,
        state: u8,
        d: &crate::rig::DriveState,
    ) -> DriveStatus {
        let q = |v: f64, res: f64| (v / res).round().clamp(0.0, f64::from(u32::MAX)) as u32;
        DriveStatus {
            block_seq,
            applied_seq,
            state,
            frequency: (d.frequency_hz / FREQUENCY_RES).round().clamp(0.0, 1.8e19) as u64,
            amplitude: q(d.amplitude_v, AMPLITUDE_RES),
            target: q(d.target_amplitude_v, AMPLITUDE_RES),
            phase: (d.phase / PHASE_RES).round().clamp(0.0, 65535.0) as u16,
        }
    }

    /// As the rig's drive state.
    pub fn drive(&self) -> crate::rig::DriveState {
        crate::rig::DriveState {
            frequency_hz: self.frequency as f64 * FREQUENCY_RES,
            amplitude_v: f64::from(self.amplitude) * AMPLITUDE_RES,
            target_amplitude_v: f64::from(self.target) * AMPLITUDE_RES,
            phase: f64::from(self.phase) * PHASE_RES,
        }
    }
}

/// HOST_HEARTBEAT.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HostHeartbeat {
    /// Counter.
    pub counter: u32,
    /// Last block consumed ([`NO_BLOCK`](super::table::NO_BLOCK) = none).
    pub consumed: u32,
}

/// DEVICE_HEARTBEAT.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceHeartbeat {
    /// Counter.
    pub counter: u32,
    /// 0 idle, 1 streaming, 2 safety ramp-down, 3 faulted.
    pub state: u8,
    /// Latched fault flags (see rig.dbc).
    pub flags: u8,
    /// Malformed frames the device received.
    pub rx_errors: u16,
}

/// TIME_SYNC_REQUEST.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeSyncRequest {
    /// Counter.
    pub seq: u32,
    /// Host clock, us.
    pub host_time_us: u64,
}

/// TIME_SYNC_RESPONSE.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeSyncResponse {
    /// The request's counter.
    pub seq: u32,
    /// The request's host clock, us.
    pub host_time_us: u64,
    /// Device clock at receipt, us.
    pub device_time_us: u64,
}

/// DAQ_BLOCK_HEADER.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockHeader {
    /// Block sequence number.
    pub seq: u32,
    /// Sample-clock index of the first sample.
    pub first_sample: u64,
    /// Device clock at the first sample, us.
    pub timestamp_us: u64,
    /// Channels present.
    pub channel_mask: u16,
    /// Samples per channel.
    pub block_size: u16,
    /// Sample rate / SAMPLE_RATE_RES.
    pub sample_rate: u32,
    /// CRC-32 of the payload.
    pub crc: u32,
}

impl BlockHeader {
    /// Sample frames that follow: `ceil(channels * block_size / 20)`.
    pub fn frame_count(&self) -> usize {
        let n = self.channel_mask.count_ones() as usize * usize::from(self.block_size);
        n.div_ceil(SAMPLES_PER_FRAME)
    }
}

/// DAQ_SAMPLES.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleFrame {
    /// BlockSeq mod 65536.
    pub block_seq: u16,
    /// Frame index in the block.
    pub index: u8,
    /// Valid samples.
    pub count: u8,
    /// The samples (24-bit signed; beyond `count`: 0).
    pub samples: [i32; SAMPLES_PER_FRAME],
}
