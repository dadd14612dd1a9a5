//! The table of the rig's CAN FD messages: identifiers, lengths, senders and signals with
//! their scale factors (what `firmware-interfaces/rig.dbc` says, and what it is generated
//! from).

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

/// HOST_HEARTBEAT and DEVICE_HEARTBEAT period (10/s, `firmware-interfaces/README.md`).
pub const HEARTBEAT_PERIOD: std::time::Duration = std::time::Duration::from_millis(100);
/// No heartbeat from the other end for this long: the link is lost (the host aborts, the
/// device ramps the drive down by itself).
pub const HEARTBEAT_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(500);
/// TIME_SYNC_REQUEST period (at start, then 1/s).
pub const TIME_SYNC_PERIOD: std::time::Duration = std::time::Duration::from_secs(1);
/// How long the host waits at least for the first DEVICE_HEARTBEAT after opening the link.
pub const FIRST_HEARTBEAT_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

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
