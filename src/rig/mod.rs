//! The rig: the [`RigBackend`] trait every backend implements (the simulated rig, [`sim`], and
//! the CAN/serial hardware, [`hw`]), the data it streams ([`daq`]) and the channel map that
//! says which DAQ channel plays which role ([`channels`]: built from the rig description, the
//! base acceleration computed once). [`device`] is the rig's electronics emulated over the
//! real links, driven by the simulated rig (`rigtwin firmware-sim`): it sits beside the
//! backends, and [`hw`] never imports it nor [`sim`].
//!
//! Control code is generic over the backend and never knows which one it talks to. A backend
//! delivers DAQ blocks in order at a fixed sample rate, their sequence numbers +1 per block;
//! a block lost on the way is passed on as a gap in the sequence numbers (never filled in),
//! which the session treats as lost data and aborts on. It applies drive commands from the
//! next block on and reports faults in its status.

pub mod channels;
pub mod daq;
pub mod device;
pub mod hw;
pub mod sim;

use std::future::Future;

use crate::plan::TestSpec;

pub use daq::{
    BlockError, ChannelKind, ChannelSpec, CommandError, DaqBlock, DaqLayout, DriveCommand,
    DriveState, LinkCounters, RigFault, RigStatus,
};

/// A backend's own typed error, carried by a [`RigError`] (the hardware backend's
/// [`hw::ConfigError`] and [`hw::LinkError`], the simulated rig's [`sim::SimRigError`], ...;
/// downcast to inspect it). Boxed so this trait module does not depend on its backends.
pub type BackendError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Errors of a backend: the category (what the session can do about it) and the backend's
/// typed error with the details.
// NOTE: no `#[source]`: each message already shows the inner error, and the CLI prints the
// chain (`{:#}`), which would then repeat it.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The backend cannot be used as configured.
    #[error("rig backend configuration: {0}")]
    Config(BackendError),
    /// A command was out of range.
    #[error("drive command rejected: {0}")]
    Command(BackendError),
    /// The link to the rig (or the simulation thread) is gone.
    #[error("rig link lost: {0}")]
    Link(BackendError),
    /// The backend was used out of order (e.g. a block requested before start).
    #[error("rig backend: {0}")]
    State(StateError),
}

impl RigError {
    /// A configuration error.
    pub fn config(e: impl Into<BackendError>) -> RigError {
        RigError::Config(e.into())
    }

    /// A rejected command.
    pub fn command(e: impl Into<BackendError>) -> RigError {
        RigError::Command(e.into())
    }

    /// A lost link.
    pub fn link(e: impl Into<BackendError>) -> RigError {
        RigError::Link(e.into())
    }
}

/// A backend used out of order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StateError {
    /// `start` called twice.
    #[error("already started")]
    AlreadyStarted,
    /// `next_block` before `start`.
    #[error("next_block before start")]
    NotStarted,
    /// The simulated rig is missing (a previous block's computation failed).
    #[error("simulation core missing")]
    SimulationCoreMissing,
}

/// A test rig: a shaker drive and a DAQ stream.
///
/// Async methods return `Send` futures so a session can run on a multi-threaded runtime.
/// Timing: a drive command sent before [`RigBackend::next_block`] applies from the first
/// sample of the block that call returns at the latest (hardware: as soon as it arrives).
pub trait RigBackend: Send {
    /// The DAQ channel layout and sample rate (fixed for the session).
    fn layout(&self) -> &DaqLayout;

    /// Starts the DAQ stream with the drive at zero amplitude.
    fn start(&mut self) -> impl Future<Output = Result<(), RigError>> + Send;

    /// Sets the drive (phase-continuous frequency change, amplitude ramp).
    fn set_drive(
        &mut self,
        command: DriveCommand,
    ) -> impl Future<Output = Result<(), RigError>> + Send;

    /// The next DAQ block, `Ok(None)` once the stream has ended. It may wait indefinitely
    /// (a stalled DAQ): callers apply their own watchdog timeout.
    fn next_block(&mut self) -> impl Future<Output = Result<Option<DaqBlock>, RigError>> + Send;

    /// Called before a test of the plan starts. Hardware: nothing to do (the rig is what it
    /// is). The simulated rig sets its truth clearance to the test's (the plan's clearance
    /// stands for the physical rig's state at that test).
    fn begin_test(&mut self, test: &TestSpec) -> impl Future<Output = Result<(), RigError>> + Send {
        let _ = test;
        async { Ok(()) }
    }

    /// Status: drive, latched faults, pacing overruns.
    fn status(&self) -> RigStatus;

    /// Stops the stream. The drive is switched off (callers ramp it down first).
    fn stop(&mut self) -> impl Future<Output = Result<(), RigError>> + Send;
}
