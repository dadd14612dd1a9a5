//! The hardware links of `rigtwin run --backend hw`: where the CAN link and the two serial
//! ports are, and the optional candump log.

use clap::Args;
use std::path::PathBuf;

use crate::rig::hw::can::transport::{CanAddress, CanAddressError};

/// `--can`, `--ldv`, `--amp`, `--can-log` of `rigtwin run`.
#[derive(Args, Debug, Default)]
pub struct HwArgs {
    /// CAN link to the rig's DAQ front-end (with --backend hw): a SocketCAN interface
    /// (`can0`; needs the kernel's CAN support) or the UDP tunnel `udp:[LOCAL@]HOST:PORT`
    /// (one CAN FD frame per datagram, firmware-interfaces/README.md), e.g. the address
    /// `rigtwin firmware-sim` prints.
    #[arg(long, value_name = "IFACE|udp:[LOCAL@]HOST:PORT", value_parser = parse_can)]
    pub can: Option<CanAddress>,
    /// Serial port of the laser vibrometer controller (with --backend hw).
    #[arg(long, value_name = "TTY")]
    pub ldv: Option<String>,
    /// Serial port of the power amplifier (with --backend hw).
    #[arg(long, value_name = "TTY")]
    pub amp: Option<String>,
    /// Write every CAN frame sent and received as a candump log (candump -L format, interface
    /// column tx/rx) and rigtwin's decoded values beside it (FILE.decoded.jsonl).
    #[arg(long, value_name = "FILE")]
    pub can_log: Option<PathBuf>,
}

fn parse_can(s: &str) -> Result<CanAddress, CanAddressError> {
    s.parse()
}
