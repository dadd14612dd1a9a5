//! Faults `rigtwin firmware-sim` can inject: the simulated rig's own ([`InjectedFault`]) and
//! faults of the links ([`LinkFault`]), by block of the session or by rig time.

use crate::rig::sim::InjectedFault;

use super::serial::Port;

/// A link fault to inject (JSON `{"kind": ...}`), at a block of the session or a rig time.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LinkFault {
    /// Sample frame `frame` of block `block` is not sent (a lost frame).
    DropFrame {
        /// Block.
        block: u64,
        /// Sample frame index.
        frame: usize,
    },
    /// Sample frames 1 and 2 of block `block` go out in swapped order.
    SwapFrames {
        /// Block.
        block: u64,
    },
    /// A sample of block `block` is changed after its CRC was computed.
    CorruptSample {
        /// Block.
        block: u64,
    },
    /// Before block `block`: a DAQ_SAMPLES frame of 48 bytes, a frame with an unknown id and
    /// a datagram that is not a tunnel frame.
    BadFrames {
        /// Block.
        block: u64,
    },
    /// The interlock opens at rig time `at_s` (amplifier output off, FAULT INTERLOCK).
    Interlock {
        /// Rig time, s.
        at_s: f64,
    },
    /// From rig time `at_s`, a serial device answers after garbage and a bad-checksum line
    /// (once).
    SerialGarbage {
        /// Rig time, s.
        at_s: f64,
        /// Which device.
        port: Port,
    },
    /// From rig time `at_s`, a serial device stops answering.
    SerialSilent {
        /// Rig time, s.
        at_s: f64,
        /// Which device.
        port: Port,
    },
    /// At rig time `at_s` the device disappears: the process exits without a word.
    Vanish {
        /// Rig time, s.
        at_s: f64,
    },
    /// From rig time `at_s` the device sends nothing (no blocks, no heartbeats) but still
    /// listens: a hung front-end.
    Mute {
        /// Rig time, s.
        at_s: f64,
    },
}

/// A fault to inject: the simulated rig's or the link's.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(untagged)]
pub enum Inject {
    /// A link fault.
    Link(LinkFault),
    /// A fault of the simulated rig.
    Rig(InjectedFault),
}
