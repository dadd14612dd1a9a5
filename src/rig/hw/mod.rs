//! The hardware backend: the rig's electronics over a CAN FD link (DAQ front-end and signal
//! generator, [`can`]) and two serial links (laser vibrometer controller and power amplifier,
//! [`serial`]), speaking the protocols of `firmware-interfaces/` ([`backend`]: [`HwBackend`]).
//! The other end of both links, driven by the simulated rig, is the device emulator (`rig/device/`,
//! `rigtwin firmware-sim`), so the whole hardware path runs without hardware. Nothing here
//! imports the simulator or the device: the device imports this module's codecs.

pub mod backend;
pub mod can;
pub mod crc;
pub mod error;
pub mod serial;

pub use backend::{HwBackend, HwOptions};
pub use error::{ConfigError, LinkError};
