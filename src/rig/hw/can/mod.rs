//! The CAN (FD) link to the rig's DAQ front-end and signal generator: frames
//! ([`frame`]), the messages of `firmware-interfaces/rig.dbc` ([`messages`]), DAQ block
//! splitting and reassembly ([`block`]), transports ([`transport`]: a UDP tunnel everywhere,
//! SocketCAN on Linux) and the candump log of a session's frames ([`candump`]).

pub mod block;
pub mod candump;
pub mod frame;
pub mod messages;
pub mod transport;

pub use frame::CanFrame;
pub use messages::Message;
