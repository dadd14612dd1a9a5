//! The serial links to the laser vibrometer controller and the power amplifier: the checked
//! line codec ([`line`](mod@line)), both devices' protocols ([`protocol`]) and the host's client thread
//! on a `serialport` port ([`port`]). Documented in `firmware-interfaces/README.md`.

pub mod line;
pub mod port;
pub mod protocol;
