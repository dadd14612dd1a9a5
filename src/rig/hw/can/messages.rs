//! The rig's CAN FD messages, exactly as `firmware-interfaces/rig.dbc` defines them: one table
//! ([`MESSAGES`]) of identifiers, lengths, senders and byte-aligned little-endian integer
//! signals with their scale factors, from which the frames are packed and unpacked and the DBC
//! file is written ([`dbc`]; a test keeps the file and the table identical). Typed messages
//! ([`Message`]) hold raw signal values; physical values are `raw * factor`.
//!
//! Decoding is strict: an unknown identifier, a classic or extended frame, a wrong length or a
//! field out of its documented set is a [`DecodeError`] naming the frame id, the byte and the
//! signal. Reserved bytes are sent as zero and ignored on receipt.

use super::frame::CanFrame;

/// Who sends a message (the DBC's nodes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// rigtwin (`rigtwin run --backend hw`).
    Host,
    /// The rig's DAQ front-end and signal generator (`rigtwin firmware-sim` stands in for it).
    Daq,
}

impl Node {
    /// The node's name in the DBC.
    pub fn dbc_name(self) -> &'static str {
        match self {
            Node::Host => "HOST",
            Node::Daq => "RIG_DAQ",
        }
    }
}

/// One signal: `bits` wide, starting at byte `byte`, little-endian (Intel), physical value
/// `raw * factor`.
#[derive(Clone, Copy, Debug)]
pub struct SignalDef {
    /// Name in the DBC.
    pub name: &'static str,
    /// First byte.
    pub byte: usize,
    /// Width, bits (8, 16, 24, 32 or 64).
    pub bits: u32,
    /// Two's-complement signed.
    pub signed: bool,
    /// Physical value per raw count.
    pub factor: f64,
    /// Physical unit.
    pub unit: &'static str,
    /// What it means.
    pub comment: &'static str,
}

/// One message.
#[derive(Clone, Copy, Debug)]
pub struct MessageDef {
    /// 11-bit identifier (lower wins arbitration).
    pub id: u32,
    /// Name in the DBC.
    pub name: &'static str,
    /// Data length, bytes (a CAN FD length).
    pub len: usize,
    /// Sender.
    pub sender: Node,
    /// Signals in byte order.
    pub signals: &'static [SignalDef],
    /// What it is for.
    pub comment: &'static str,
}

const fn sig(
    name: &'static str,
    byte: usize,
    bits: u32,
    signed: bool,
    factor: f64,
    unit: &'static str,
    comment: &'static str,
) -> SignalDef {
    SignalDef {
        name,
        byte,
        bits,
        signed,
        factor,
        unit,
        comment,
    }
}

/// Frequency resolution, Hz (1 nHz: the controller holds a step's frequency to 1e-9
/// relative, and the device applies what it receives).
pub const FREQUENCY_RES: f64 = 0.000000001;
/// Drive amplitude resolution, V.
pub const AMPLITUDE_RES: f64 = 0.000001;
/// Ramp-time resolution, s.
pub const RAMP_RES: f64 = 0.000001;
/// Sample-rate resolution, Hz.
pub const SAMPLE_RATE_RES: f64 = 0.001;
/// Phase resolution, rad.
pub const PHASE_RES: f64 = 0.0001;
/// Fault value resolution, V.
pub const FAULT_VALUE_RES: f64 = 0.001;
/// Samples in one DAQ_SAMPLES frame.
pub const SAMPLES_PER_FRAME: usize = 20;
/// `HOST_HEARTBEAT.ConsumedSeq` before the first block.
pub const NO_BLOCK: u32 = u32::MAX;

/// Identifiers.
pub mod id {
    /// FAULT (device -> host).
    pub const FAULT: u32 = 0x010;
    /// STREAM_CONTROL (host -> device).
    pub const STREAM_CONTROL: u32 = 0x020;
    /// DRIVE_SETPOINT (host -> device).
    pub const DRIVE_SETPOINT: u32 = 0x030;
    /// DRIVE_STATUS (device -> host).
    pub const DRIVE_STATUS: u32 = 0x031;
    /// HOST_HEARTBEAT (host -> device).
    pub const HOST_HEARTBEAT: u32 = 0x040;
    /// DEVICE_HEARTBEAT (device -> host).
    pub const DEVICE_HEARTBEAT: u32 = 0x041;
    /// TIME_SYNC_REQUEST (host -> device).
    pub const TIME_SYNC_REQUEST: u32 = 0x050;
    /// TIME_SYNC_RESPONSE (device -> host).
    pub const TIME_SYNC_RESPONSE: u32 = 0x051;
    /// DAQ_BLOCK_HEADER (device -> host).
    pub const DAQ_BLOCK_HEADER: u32 = 0x100;
    /// DAQ_SAMPLES (device -> host).
    pub const DAQ_SAMPLES: u32 = 0x101;
}

const SAMPLE_SIGNALS: [SignalDef; 24] = {
    const NAMES: [&str; 20] = [
        "Sample00", "Sample01", "Sample02", "Sample03", "Sample04", "Sample05", "Sample06",
        "Sample07", "Sample08", "Sample09", "Sample10", "Sample11", "Sample12", "Sample13",
        "Sample14", "Sample15", "Sample16", "Sample17", "Sample18", "Sample19",
    ];
    let mut s = [sig("", 0, 8, false, 1.0, "", ""); 24];
    s[0] = sig(
        "SampleBlockSeq",
        0,
        16,
        false,
        1.0,
        "",
        "BlockSeq of the block this frame belongs to, modulo 65536",
    );
    s[1] = sig(
        "FrameIndex",
        2,
        8,
        false,
        1.0,
        "",
        "Index of this frame in its block, 0-based",
    );
    s[2] = sig(
        "SampleCount",
        3,
        8,
        false,
        1.0,
        "",
        "Valid samples in this frame (20 except in a block's last frame; the rest are 0)",
    );
    let mut i = 0;
    while i < 20 {
        s[3 + i] = sig(
            NAMES[i],
            4 + 3 * i,
            24,
            true,
            1.0,
            "count",
            "ADC counts; element 20*FrameIndex+i of the block's sample-major stream \
             (sample n of channel k is element n*channels+k)",
        );
        i += 1;
    }
    // Slot 23 unused: a 24-entry array keeps the table const; `SAMPLES_DEF` uses 23.
    s
};

/// Every message of the rig bus, by identifier.
pub static MESSAGES: [MessageDef; 10] = [
    MessageDef {
        id: id::FAULT,
        name: "FAULT",
        len: 8,
        sender: Node::Daq,
        comment: "A fault or interlock the device raised: sent once when raised; the \
                  latched flags are in every DEVICE_HEARTBEAT (FaultFlags)",
        signals: &[
            sig("FaultCode", 0, 8, false, 1.0, "", "What happened"),
            sig("FaultChannel", 1, 8, false, 1.0, "", "DAQ channel index for OVER_RANGE, 255 otherwise"),
            sig("FaultValue", 2, 32, true, FAULT_VALUE_RES, "V", "Amplifier output limit for DRIVE_SATURATED, 0 otherwise"),
            sig("FaultCount", 6, 16, false, 1.0, "", "Faults raised since the stream started"),
        ],
    },
    MessageDef {
        id: id::STREAM_CONTROL,
        name: "STREAM_CONTROL",
        len: 8,
        sender: Node::Host,
        comment: "Start (BlockSeq restarts at 0, drive at zero) or stop (drive off) the DAQ stream",
        signals: &[
            sig("StreamCommand", 0, 8, false, 1.0, "", "1 = start, 2 = stop"),
            sig("SessionId", 4, 32, false, 1.0, "", "Host's session number, echoed nowhere, logged by the device"),
        ],
    },
    MessageDef {
        id: id::DRIVE_SETPOINT,
        name: "DRIVE_SETPOINT",
        len: 20,
        sender: Node::Host,
        comment: "Drive sine at the amplifier input: frequency changes phase-continuously, \
                  amplitude ramps linearly from its current value over RampTime; applied \
                  from the next sample after receipt",
        signals: &[
            sig("SetpointSeq", 0, 16, false, 1.0, "", "Counter, +1 per setpoint"),
            sig("DriveEnable", 2, 8, false, 1.0, "", "1 = drive on, 0 = ramp to zero"),
            sig("Frequency", 4, 64, false, FREQUENCY_RES, "Hz", "Drive frequency"),
            sig("Amplitude", 12, 32, false, AMPLITUDE_RES, "V", "Amplitude the ramp heads for"),
            sig("RampTime", 16, 32, false, RAMP_RES, "s", "Ramp duration, 0 = at the next sample"),
        ],
    },
    MessageDef {
        id: id::DRIVE_STATUS,
        name: "DRIVE_STATUS",
        len: 32,
        sender: Node::Daq,
        comment: "The drive as applied at the end of block StatusBlockSeq; sent before that \
                  block's DAQ_BLOCK_HEADER",
        signals: &[
            sig("StatusBlockSeq", 0, 32, false, 1.0, "", "Block whose last sample this describes"),
            sig("AppliedSeq", 4, 16, false, 1.0, "", "SetpointSeq of the last setpoint applied"),
            sig("DriveState", 6, 8, false, 1.0, "", "0 idle, 1 running, 2 safety ramp-down, 3 off after a fault"),
            sig("AppliedFrequency", 8, 64, false, FREQUENCY_RES, "Hz", "Drive frequency"),
            sig("AppliedAmplitude", 16, 32, false, AMPLITUDE_RES, "V", "Current amplitude"),
            sig("TargetAmplitude", 20, 32, false, AMPLITUDE_RES, "V", "Amplitude the ramp heads for"),
            sig("Phase", 24, 16, false, PHASE_RES, "rad", "Drive phase, [0, 2 pi)"),
        ],
    },
    MessageDef {
        id: id::HOST_HEARTBEAT,
        name: "HOST_HEARTBEAT",
        len: 8,
        sender: Node::Host,
        comment: "Every 100 ms and after each block the host consumed; the device ramps \
                  the drive down after 500 ms without one",
        signals: &[
            sig("HostCounter", 0, 32, false, 1.0, "", "Counter, +1 per heartbeat"),
            sig("ConsumedSeq", 4, 32, false, 1.0, "", "Last block the host consumed, 4294967295 = none"),
        ],
    },
    MessageDef {
        id: id::DEVICE_HEARTBEAT,
        name: "DEVICE_HEARTBEAT",
        len: 8,
        sender: Node::Daq,
        comment: "Every 100 ms; the host declares the link lost after 500 ms without one",
        signals: &[
            sig("DeviceCounter", 0, 32, false, 1.0, "", "Counter, +1 per heartbeat"),
            sig("DeviceState", 4, 8, false, 1.0, "", "0 idle, 1 streaming, 2 safety ramp-down, 3 faulted"),
            sig("FaultFlags", 5, 8, false, 1.0, "", "Latched: bit 0 interlock, 1 host heartbeat lost, 2 amplifier overload, 3 over-range, 4 device error"),
            sig("RxErrors", 6, 16, false, 1.0, "", "Malformed frames the device received"),
        ],
    },
    MessageDef {
        id: id::TIME_SYNC_REQUEST,
        name: "TIME_SYNC_REQUEST",
        len: 16,
        sender: Node::Host,
        comment: "Once per second: the host's clock at sending",
        signals: &[
            sig("SyncSeq", 0, 32, false, 1.0, "", "Counter"),
            sig("HostTime", 8, 64, false, 1.0, "us", "Host clock at sending"),
        ],
    },
    MessageDef {
        id: id::TIME_SYNC_RESPONSE,
        name: "TIME_SYNC_RESPONSE",
        len: 24,
        sender: Node::Daq,
        comment: "Answer to TIME_SYNC_REQUEST: round trip and clock offset for the host",
        signals: &[
            sig("SyncSeq", 0, 32, false, 1.0, "", "The request's SyncSeq"),
            sig("EchoHostTime", 8, 64, false, 1.0, "us", "The request's HostTime"),
            sig("DeviceTime", 16, 64, false, 1.0, "us", "Device clock at receipt"),
        ],
    },
    MessageDef {
        id: id::DAQ_BLOCK_HEADER,
        name: "DAQ_BLOCK_HEADER",
        len: 32,
        sender: Node::Daq,
        comment: "Starts a block: followed by its DAQ_SAMPLES frames 0..ceil(channels*BlockSize/20)-1",
        signals: &[
            sig("BlockSeq", 0, 32, false, 1.0, "", "0 for the first block after start, +1 per block"),
            sig("FirstSample", 4, 64, false, 1.0, "", "Sample-clock index of the block's first sample"),
            sig("Timestamp", 12, 64, false, 1.0, "us", "Device clock at the first sample"),
            sig("ChannelMask", 20, 16, false, 1.0, "", "Bit k set: channel k of the rig's channel map is in the block"),
            sig("BlockSize", 22, 16, false, 1.0, "", "Samples per channel"),
            sig("SampleRate", 24, 32, false, SAMPLE_RATE_RES, "Hz", "Samples per second per channel"),
            sig("PayloadCrc", 28, 32, false, 1.0, "", "CRC-32 (IEEE) of the block's samples as 3-byte little-endian counts in stream order"),
        ],
    },
    MessageDef {
        id: id::DAQ_SAMPLES,
        name: "DAQ_SAMPLES",
        len: 64,
        sender: Node::Daq,
        comment: "20 samples of a block's sample-major stream",
        signals: SAMPLES_DEF,
    },
];

const SAMPLES_DEF: &[SignalDef] = {
    let (head, _) = SAMPLE_SIGNALS.split_at(23);
    head
};

/// The definition of identifier `id`.
pub fn def(id: u32) -> Option<&'static MessageDef> {
    MESSAGES.iter().find(|m| m.id == id)
}

/// Why a frame does not decode.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// No message has this identifier.
    #[error("CAN frame {id:#05x}: unknown identifier (rig.dbc has none)")]
    UnknownId {
        /// The identifier.
        id: u32,
    },
    /// Not a standard-identifier CAN FD frame.
    #[error("CAN frame {id:#05x} ({name}): {what}")]
    Format {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// What is wrong.
        what: &'static str,
    },
    /// Wrong data length.
    #[error("CAN frame {id:#05x} ({name}): {len} data bytes, expected {expected}")]
    Length {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// Bytes received.
        len: usize,
        /// Bytes defined.
        expected: usize,
    },
    /// A field outside its documented values.
    #[error("CAN frame {id:#05x} ({name}), byte {byte}, {signal} = {value}: {what}")]
    Field {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// First byte of the signal.
        byte: usize,
        /// Signal name.
        signal: &'static str,
        /// Raw value.
        value: i128,
        /// What was expected.
        what: &'static str,
    },
}

/// Raw value of `s` in `data` (which has the message's length).
pub fn raw(data: &[u8], s: &SignalDef) -> i128 {
    let n = (s.bits / 8) as usize;
    let mut v: u64 = 0;
    for (i, b) in data[s.byte..s.byte + n].iter().enumerate() {
        v |= u64::from(*b) << (8 * i);
    }
    if s.signed && s.bits < 64 && v & (1 << (s.bits - 1)) != 0 {
        i128::from(v) - (1i128 << s.bits)
    } else if s.signed {
        i128::from(v as i64)
    } else {
        i128::from(v)
    }
}

fn put(data: &mut [u8], s: &SignalDef, value: i128) {
    let n = (s.bits / 8) as usize;
    let v = value as u64; // two's complement, truncated to the signal's width below
    for (i, b) in data[s.byte..s.byte + n].iter_mut().enumerate() {
        *b = (v >> (8 * i)) as u8;
    }
}

/// A decoded signal value as the DBC defines it: integers where the factor is 1, `raw *
/// factor` otherwise.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum SignalValue {
    /// Unscaled integer.
    Int(i128),
    /// Scaled value.
    Float(f64),
}

/// Every signal of a well-formed frame of a known message, with its physical value. Used for
/// the decoded-values log that the `cantools` cross-check compares.
pub fn signal_values(frame: &CanFrame) -> Result<Vec<(&'static str, SignalValue)>, DecodeError> {
    let d = checked_def(frame)?;
    Ok(d.signals
        .iter()
        .map(|s| {
            let r = raw(frame.data(), s);
            let v = if s.factor == 1.0 {
                SignalValue::Int(r)
            } else {
                SignalValue::Float(r as f64 * s.factor)
            };
            (s.name, v)
        })
        .collect())
}

fn checked_def(frame: &CanFrame) -> Result<&'static MessageDef, DecodeError> {
    let d = def(frame.id)
        .filter(|_| !frame.extended)
        .ok_or(DecodeError::UnknownId { id: frame.id })?;
    if !frame.fd {
        return Err(DecodeError::Format {
            id: d.id,
            name: d.name,
            what: "a classic CAN frame: every rig message is CAN FD",
        });
    }
    if frame.len() != d.len {
        return Err(DecodeError::Length {
            id: d.id,
            name: d.name,
            len: frame.len(),
            expected: d.len,
        });
    }
    Ok(d)
}

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
    fn from_raw(v: i128) -> Option<FaultCode> {
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

impl DriveSetpoint {
    /// Quantises a drive command (nearest raw values); `Err` names the field out of range.
    pub fn from_command(seq: u16, cmd: &crate::rig::DriveCommand) -> Result<DriveSetpoint, String> {
        let q = |name: &str, v: f64, res: f64| -> Result<u32, String> {
            let r = (v / res).round();
            if v.is_finite() && r >= 0.0 && r <= f64::from(u32::MAX) {
                Ok(r as u32)
            } else {
                Err(format!(
                    "DRIVE_SETPOINT {name} = {v}: outside 0..={} ({res} per count, 32 bits)",
                    f64::from(u32::MAX) * res
                ))
            }
        };
        let f = (cmd.frequency_hz / FREQUENCY_RES).round();
        if !(cmd.frequency_hz.is_finite() && (1.0..1.8e19).contains(&f)) {
            return Err(format!(
                "DRIVE_SETPOINT Frequency = {} Hz: expected > 0 and finite",
                cmd.frequency_hz
            ));
        }
        let frequency = f as u64;
        if frequency == 0 {
            return Err(format!(
                "DRIVE_SETPOINT Frequency = {} Hz: expected > 0",
                cmd.frequency_hz
            ));
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
    /// Last block consumed ([`NO_BLOCK`] = none).
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

/// Any rig message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Message {
    /// FAULT.
    Fault(Fault),
    /// STREAM_CONTROL.
    StreamControl(StreamControl),
    /// DRIVE_SETPOINT.
    DriveSetpoint(DriveSetpoint),
    /// DRIVE_STATUS.
    DriveStatus(DriveStatus),
    /// HOST_HEARTBEAT.
    HostHeartbeat(HostHeartbeat),
    /// DEVICE_HEARTBEAT.
    DeviceHeartbeat(DeviceHeartbeat),
    /// TIME_SYNC_REQUEST.
    TimeSyncRequest(TimeSyncRequest),
    /// TIME_SYNC_RESPONSE.
    TimeSyncResponse(TimeSyncResponse),
    /// DAQ_BLOCK_HEADER.
    BlockHeader(BlockHeader),
    /// DAQ_SAMPLES.
    Samples(SampleFrame),
}

/// Largest int24 magnitude on the positive side.
pub const INT24_MAX: i32 = (1 << 23) - 1;
/// Smallest int24.
pub const INT24_MIN: i32 = -(1 << 23);

impl Message {
    /// The message's definition.
    pub fn def(&self) -> &'static MessageDef {
        let id = match self {
            Message::Fault(_) => id::FAULT,
            Message::StreamControl(_) => id::STREAM_CONTROL,
            Message::DriveSetpoint(_) => id::DRIVE_SETPOINT,
            Message::DriveStatus(_) => id::DRIVE_STATUS,
            Message::HostHeartbeat(_) => id::HOST_HEARTBEAT,
            Message::DeviceHeartbeat(_) => id::DEVICE_HEARTBEAT,
            Message::TimeSyncRequest(_) => id::TIME_SYNC_REQUEST,
            Message::TimeSyncResponse(_) => id::TIME_SYNC_RESPONSE,
            Message::BlockHeader(_) => id::DAQ_BLOCK_HEADER,
            Message::Samples(_) => id::DAQ_SAMPLES,
        };
        def(id).expect("every message is in the table")
    }

    /// Raw signal values in table order.
    fn raws(&self) -> Vec<i128> {
        use Message as M;
        match *self {
            M::Fault(f) => vec![
                f.code as i128,
                f.channel.into(),
                f.value.into(),
                f.count.into(),
            ],
            M::StreamControl(s) => vec![s.command as i128, s.session.into()],
            M::DriveSetpoint(s) => vec![
                s.seq.into(),
                i128::from(s.enable),
                s.frequency.into(),
                s.amplitude.into(),
                s.ramp.into(),
            ],
            M::DriveStatus(s) => vec![
                s.block_seq.into(),
                s.applied_seq.into(),
                s.state.into(),
                s.frequency.into(),
                s.amplitude.into(),
                s.target.into(),
                s.phase.into(),
            ],
            M::HostHeartbeat(h) => vec![h.counter.into(), h.consumed.into()],
            M::DeviceHeartbeat(h) => vec![
                h.counter.into(),
                h.state.into(),
                h.flags.into(),
                h.rx_errors.into(),
            ],
            M::TimeSyncRequest(t) => vec![t.seq.into(), t.host_time_us.into()],
            M::TimeSyncResponse(t) => {
                vec![t.seq.into(), t.host_time_us.into(), t.device_time_us.into()]
            }
            M::BlockHeader(h) => vec![
                h.seq.into(),
                h.first_sample.into(),
                h.timestamp_us.into(),
                h.channel_mask.into(),
                h.block_size.into(),
                h.sample_rate.into(),
                h.crc.into(),
            ],
            M::Samples(s) => {
                let mut v = vec![s.block_seq.into(), s.index.into(), s.count.into()];
                v.extend(s.samples.iter().map(|&x| i128::from(x)));
                v
            }
        }
    }

    /// The frame (CAN FD, BRS, standard id). Sample values are truncated to 24 bits: the
    /// block encoder checks their range first.
    pub fn encode(&self) -> CanFrame {
        let d = self.def();
        let mut data = [0u8; 64];
        for (s, v) in d.signals.iter().zip(self.raws()) {
            put(&mut data, s, v);
        }
        CanFrame::fd(d.id, &data[..d.len]).expect("table lengths are CAN FD lengths")
    }

    /// Decodes a frame; see the module docs for what is rejected.
    pub fn decode(frame: &CanFrame) -> Result<Message, DecodeError> {
        let d = checked_def(frame)?;
        let data = frame.data();
        let r: Vec<i128> = d.signals.iter().map(|s| raw(data, s)).collect();
        let bad = |i: usize, what: &'static str| DecodeError::Field {
            id: d.id,
            name: d.name,
            byte: d.signals[i].byte,
            signal: d.signals[i].name,
            value: r[i],
            what,
        };
        // Narrowing casts below are exact: each raw value has its signal's width.
        Ok(match d.id {
            id::FAULT => Message::Fault(Fault {
                code: FaultCode::from_raw(r[0])
                    .ok_or_else(|| bad(0, "expected a fault code 1..=6"))?,
                channel: r[1] as u8,
                value: r[2] as i32,
                count: r[3] as u16,
            }),
            id::STREAM_CONTROL => Message::StreamControl(StreamControl {
                command: match r[0] {
                    1 => StreamCommand::Start,
                    2 => StreamCommand::Stop,
                    _ => return Err(bad(0, "expected 1 (start) or 2 (stop)")),
                },
                session: r[1] as u32,
            }),
            id::DRIVE_SETPOINT => {
                if r[1] > 1 {
                    return Err(bad(1, "expected 0 or 1"));
                }
                if r[2] == 0 {
                    return Err(bad(2, "expected a frequency > 0"));
                }
                Message::DriveSetpoint(DriveSetpoint {
                    seq: r[0] as u16,
                    enable: r[1] == 1,
                    frequency: r[2] as u64,
                    amplitude: r[3] as u32,
                    ramp: r[4] as u32,
                })
            }
            id::DRIVE_STATUS => {
                if r[2] > 3 {
                    return Err(bad(2, "expected a drive state 0..=3"));
                }
                Message::DriveStatus(DriveStatus {
                    block_seq: r[0] as u32,
                    applied_seq: r[1] as u16,
                    state: r[2] as u8,
                    frequency: r[3] as u64,
                    amplitude: r[4] as u32,
                    target: r[5] as u32,
                    phase: r[6] as u16,
                })
            }
            id::HOST_HEARTBEAT => Message::HostHeartbeat(HostHeartbeat {
                counter: r[0] as u32,
                consumed: r[1] as u32,
            }),
            id::DEVICE_HEARTBEAT => {
                if r[1] > 3 {
                    return Err(bad(1, "expected a device state 0..=3"));
                }
                Message::DeviceHeartbeat(DeviceHeartbeat {
                    counter: r[0] as u32,
                    state: r[1] as u8,
                    flags: r[2] as u8,
                    rx_errors: r[3] as u16,
                })
            }
            id::TIME_SYNC_REQUEST => Message::TimeSyncRequest(TimeSyncRequest {
                seq: r[0] as u32,
                host_time_us: r[1] as u64,
            }),
            id::TIME_SYNC_RESPONSE => Message::TimeSyncResponse(TimeSyncResponse {
                seq: r[0] as u32,
                host_time_us: r[1] as u64,
                device_time_us: r[2] as u64,
            }),
            id::DAQ_BLOCK_HEADER => {
                if r[3] == 0 {
                    return Err(bad(3, "expected at least one channel"));
                }
                if r[4] == 0 {
                    return Err(bad(4, "expected at least one sample per channel"));
                }
                if r[5] == 0 {
                    return Err(bad(5, "expected a sample rate > 0"));
                }
                Message::BlockHeader(BlockHeader {
                    seq: r[0] as u32,
                    first_sample: r[1] as u64,
                    timestamp_us: r[2] as u64,
                    channel_mask: r[3] as u16,
                    block_size: r[4] as u16,
                    sample_rate: r[5] as u32,
                    crc: r[6] as u32,
                })
            }
            id::DAQ_SAMPLES => {
                if r[2] == 0 || r[2] > SAMPLES_PER_FRAME as i128 {
                    return Err(bad(2, "expected 1..=20 samples"));
                }
                let count = r[2] as usize;
                let mut samples = [0i32; SAMPLES_PER_FRAME];
                for (i, s) in samples.iter_mut().enumerate() {
                    *s = r[3 + i] as i32;
                    if i >= count && *s != 0 {
                        return Err(bad(3 + i, "expected 0 beyond SampleCount"));
                    }
                }
                Message::Samples(SampleFrame {
                    block_seq: r[0] as u16,
                    index: r[1] as u8,
                    count: count as u8,
                    samples,
                })
            }
            _ => unreachable!("checked_def returns table entries"),
        })
    }
}

/// The DBC text of [`MESSAGES`]: `firmware-interfaces/rig.dbc` is exactly this.
pub fn dbc() -> String {
    use std::fmt::Write;
    let mut s = String::new();
    s.push_str("VERSION \"rigtwin rig bus 1\"\n\n\nNS_ :\n\tCM_\n\tBA_DEF_\n\tBA_\n\tVAL_\n\tBA_DEF_DEF_\n\nBS_:\n\n");
    s.push_str("BU_: HOST RIG_DAQ\n\n");
    for m in &MESSAGES {
        let _ = writeln!(
            s,
            "BO_ {} {}: {} {}",
            m.id,
            m.name,
            m.len,
            m.sender.dbc_name()
        );
        let receiver = match m.sender {
            Node::Host => Node::Daq,
            Node::Daq => Node::Host,
        }
        .dbc_name();
        for g in m.signals {
            let (min, max) = if g.signed {
                (-(1i128 << (g.bits - 1)), (1i128 << (g.bits - 1)) - 1)
            } else {
                (0, (1i128 << g.bits) - 1)
            };
            let (min, max) = if g.factor == 1.0 {
                (min.to_string(), max.to_string())
            } else {
                (
                    format!("{}", min as f64 * g.factor),
                    format!("{}", max as f64 * g.factor),
                )
            };
            let _ = writeln!(
                s,
                " SG_ {} : {}|{}@1{} ({},0) [{}|{}] \"{}\" {}",
                g.name,
                g.byte * 8,
                g.bits,
                if g.signed { '-' } else { '+' },
                g.factor,
                min,
                max,
                g.unit,
                receiver
            );
        }
        s.push('\n');
    }
    s.push('\n');
    s.push_str("CM_ \"rigtwin rig bus: CAN FD, 1 Mbit/s arbitration, 8 Mbit/s data phase, 11-bit identifiers. See README.md.\";\n");
    s.push_str("CM_ BU_ HOST \"rigtwin (rigtwin run --backend hw)\";\n");
    s.push_str("CM_ BU_ RIG_DAQ \"DAQ front-end and signal generator (rigtwin firmware-sim stands in)\";\n");
    for m in &MESSAGES {
        let _ = writeln!(s, "CM_ BO_ {} \"{}\";", m.id, m.comment);
        for g in m.signals {
            let _ = writeln!(s, "CM_ SG_ {} {} \"{}\";", m.id, g.name, g.comment);
        }
    }
    s.push_str("BA_DEF_  \"BusType\" STRING ;\n");
    s.push_str("BA_DEF_ BO_  \"VFrameFormat\" ENUM  \"StandardCAN\",\"ExtendedCAN\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\",\"ExtendedCAN_FD\";\n");
    s.push_str("BA_DEF_ BO_  \"CANFD_BRS\" ENUM  \"0\",\"1\";\n");
    s.push_str("BA_DEF_DEF_  \"BusType\" \"CAN FD\";\n");
    s.push_str("BA_DEF_DEF_  \"VFrameFormat\" \"StandardCAN_FD\";\n");
    s.push_str("BA_DEF_DEF_  \"CANFD_BRS\" \"1\";\n");
    s.push_str("BA_ \"BusType\" \"CAN FD\";\n");
    for m in &MESSAGES {
        let _ = writeln!(s, "BA_ \"VFrameFormat\" BO_ {} 14;", m.id);
        let _ = writeln!(s, "BA_ \"CANFD_BRS\" BO_ {} 1;", m.id);
    }
    let _ = writeln!(s, "VAL_ {} FaultCode 1 \"HEARTBEAT_LOST\" 2 \"INTERLOCK\" 3 \"AMPLIFIER_OVERLOAD\" 4 \"OVER_RANGE\" 5 \"DRIVE_SATURATED\" 6 \"DEVICE_ERROR\" ;", id::FAULT);
    let _ = writeln!(
        s,
        "VAL_ {} StreamCommand 1 \"START\" 2 \"STOP\" ;",
        id::STREAM_CONTROL
    );
    let _ = writeln!(s, "VAL_ {} DriveState 0 \"IDLE\" 1 \"RUNNING\" 2 \"SAFETY_RAMP_DOWN\" 3 \"OFF_AFTER_FAULT\" ;", id::DRIVE_STATUS);
    let _ = writeln!(
        s,
        "VAL_ {} DeviceState 0 \"IDLE\" 1 \"STREAMING\" 2 \"SAFETY_RAMP_DOWN\" 3 \"FAULTED\" ;",
        id::DEVICE_HEARTBEAT
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_dbc_file_is_the_table() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware-interfaces/rig.dbc");
        let file = std::fs::read_to_string(path).unwrap();
        assert!(
            file == dbc(),
            "{path} differs from messages::dbc(): regenerate it with \
             `cargo test --lib rig::hw::can::messages -- --ignored write_dbc`"
        );
    }

    #[test]
    #[ignore]
    fn write_dbc() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware-interfaces/rig.dbc");
        std::fs::write(path, dbc()).unwrap();
    }

    #[test]
    fn table_is_consistent() {
        for m in &MESSAGES {
            assert!(super::super::frame::valid_fd_len(m.len), "{}", m.name);
            let mut used = vec![false; m.len];
            for s in m.signals {
                for b in &mut used[s.byte..s.byte + s.bits as usize / 8] {
                    assert!(!*b, "{}.{} overlaps", m.name, s.name);
                    *b = true;
                }
            }
        }
    }

    #[test]
    fn messages_round_trip_and_bad_fields_name_byte_and_signal() {
        let mut samples = [0; 20];
        samples[0] = INT24_MIN;
        samples[1] = INT24_MAX;
        samples[2] = -1;
        let all = [
            Message::Fault(Fault {
                code: FaultCode::DriveSaturated,
                channel: 255,
                value: -1234,
                count: 2,
            }),
            Message::DriveSetpoint(DriveSetpoint {
                seq: 7,
                enable: true,
                frequency: 55_000_000_000,
                amplitude: 123_456,
                ramp: 500_000,
            }),
            Message::BlockHeader(BlockHeader {
                seq: 3,
                first_sample: 768,
                timestamp_us: u64::MAX - 5,
                channel_mask: 0x7FF,
                block_size: 256,
                sample_rate: 10_240_000,
                crc: 0xDEAD_BEEF,
            }),
            Message::Samples(SampleFrame {
                block_seq: 3,
                index: 140,
                count: 3,
                samples,
            }),
        ];
        for m in all {
            assert_eq!(Message::decode(&m.encode()).unwrap(), m);
        }
        let mut f = Message::StreamControl(StreamControl {
            command: StreamCommand::Start,
            session: 1,
        })
        .encode();
        let mut d = f.data().to_vec();
        d[0] = 9;
        f = CanFrame::fd(id::STREAM_CONTROL, &d).unwrap();
        let e = Message::decode(&f).unwrap_err().to_string();
        assert!(
            e.contains("0x020") && e.contains("byte 0") && e.contains("StreamCommand"),
            "{e}"
        );
        let short = CanFrame::fd(id::DAQ_SAMPLES, &[0; 48]).unwrap();
        let e = Message::decode(&short).unwrap_err().to_string();
        assert!(e.contains("48 data bytes, expected 64"), "{e}");
        let e = Message::decode(&CanFrame::fd(0x7FF, &[]).unwrap()).unwrap_err();
        assert!(matches!(e, DecodeError::UnknownId { id: 0x7FF }));
    }

    proptest! {
        #[test]
        fn decoding_arbitrary_frames_never_panics(
            id in prop::sample::select(vec![0x010u32, 0x020, 0x030, 0x031, 0x040, 0x041, 0x050, 0x051, 0x100, 0x101, 0x7FF, 0]),
            fd in any::<bool>(),
            len_i in 0usize..16,
            bytes in prop::collection::vec(any::<u8>(), 64),
        ) {
            let len = if fd { super::super::frame::FD_LENGTHS[len_i] } else { len_i.min(8) };
            let f = CanFrame::new(id, false, fd, false, false, &bytes[..len]).unwrap();
            if let Ok(m) = Message::decode(&f) {
                // What decodes re-encodes to the same bytes except reserved ones.
                let again = Message::decode(&m.encode()).unwrap();
                prop_assert_eq!(again, m);
                prop_assert!(signal_values(&f).is_ok());
            }
        }
    }
}
