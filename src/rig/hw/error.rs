//! The hardware backend's errors, carried by [`crate::rig::RigError`]: what is wrong with the
//! setup ([`ConfigError`]: the channel map, the links' arguments, what the devices report) and
//! how a link was lost ([`LinkError`]). Each names the device, port, link or frame.

use std::path::PathBuf;

use super::can::block::{BlockFormatError, FormatMismatch};
use super::can::transport::TransportError;
use super::serial::port::{OpenError, SerialError};
use super::serial::protocol::ProtocolError;

/// The hardware backend cannot be used as configured.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The channel map cannot travel in the CAN block header.
    #[error("{0}")]
    Format(BlockFormatError),
    /// Not exactly one vibrometer channel in the channel map.
    #[error("the hardware backend needs exactly one vibrometer channel in the channel map")]
    Vibrometers {
        /// Vibrometer channels in the map.
        count: usize,
    },
    /// The CAN link (`--can`) could not be opened.
    #[error("--can: {0}")]
    Can(TransportError),
    /// The candump log (`--can-log`) could not be created.
    #[error("--can-log {}: {error}", path.display())]
    CanLog {
        /// The log's path.
        path: PathBuf,
        /// What happened.
        error: std::io::Error,
    },
    /// A serial port (`--ldv`, `--amp`) could not be opened.
    #[error("{flag} ({device}): {error}")]
    SerialPort {
        /// The argument ("--ldv", "--amp").
        flag: &'static str,
        /// The device ("vibrometer controller", "power amplifier").
        device: &'static str,
        /// What happened.
        error: OpenError,
    },
    /// A serial request was refused or not answered in time during setup.
    #[error("{0}")]
    Serial(SerialError),
    /// A device's STATUS answer does not follow the protocol.
    #[error("{0}")]
    Status(ProtocolError),
    /// The vibrometer did not take the range the channel map needs.
    #[error(
        "vibrometer ({port}): RANGE {range_mm_s} mm/s after setting {set_mm_s} mm/s (the \
         channel map's full scale of {channel})"
    )]
    VibrometerRange {
        /// The vibrometer's port.
        port: String,
        /// The range it reports, mm/s.
        range_mm_s: u32,
        /// The range set, mm/s.
        set_mm_s: u32,
        /// The vibrometer channel.
        channel: String,
    },
    /// The amplifier's GAIN answer is not a number.
    #[error("power amplifier ({port}): GAIN answer {answer:?}")]
    GainAnswer {
        /// The amplifier's port.
        port: String,
        /// The answer's values.
        answer: Vec<String>,
    },
    /// The amplifier's gain is not the rig description's.
    #[error(
        "power amplifier ({port}): gain {gain} V/V, but the rig description says \
         shaker.amplifier_gain = {want}: set the amplifier or the description"
    )]
    Gain {
        /// The amplifier's port.
        port: String,
        /// Its gain, V/V.
        gain: f64,
        /// The rig description's, V/V.
        want: f64,
    },
    /// A block header that does not match the channel map.
    #[error("{0}")]
    Header(FormatMismatch),
}

/// The link to the rig is gone. Cloned: the backend keeps the first one and reports it to
/// every later call.
#[derive(Clone, Debug, thiserror::Error)]
pub enum LinkError {
    /// The CAN transport failed.
    #[error("CAN link {link}: {error}")]
    Can {
        /// The link (`--can`).
        link: String,
        /// What failed.
        error: String,
    },
    /// No DEVICE_HEARTBEAT at connection.
    #[error(
        "CAN link {link}: no DEVICE_HEARTBEAT within {wait_s:.1} s: is the rig (or `rigtwin \
         firmware-sim`) running and listening there?"
    )]
    NoDevice {
        /// The link (`--can`).
        link: String,
        /// How long the backend waited, s.
        wait_s: f64,
    },
    /// The device's heartbeat stopped.
    #[error(
        "CAN link {link}: no DEVICE_HEARTBEAT for {since_s:.2} s (timeout {timeout_s:.2} s): \
         the rig DAQ is gone"
    )]
    HeartbeatLost {
        /// The link (`--can`).
        link: String,
        /// Time since the last heartbeat, s.
        since_s: f64,
        /// The heartbeat timeout, s.
        timeout_s: f64,
    },
    /// A serial device is gone.
    #[error("{0}")]
    Serial(SerialError),
    /// The candump log could not be written.
    #[error("--can-log: {error}")]
    CanLog {
        /// What happened.
        error: String,
    },
}
