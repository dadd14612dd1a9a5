//! The hardware backend: the rig's electronics over a CAN FD link (DAQ front-end and signal
//! generator, [`can`]) and two serial links (laser vibrometer controller and power amplifier,
//! [`serial`]), speaking the protocols of `firmware-interfaces/` ([`backend`]: [`HwBackend`]).
//! [`firmware_sim`] is the other end of both links driven by the simulated rig, so the whole
//! hardware path runs without hardware (`rigtwin firmware-sim`).

pub mod backend;
pub mod can;
pub mod crc;
pub mod firmware_sim;
pub mod serial;

pub use backend::{HwBackend, HwOptions};
