//! The session: a stepped-sine experiment on a rig backend, put together from the layers
//! below it — the backend (any [`crate::rig::RigBackend`]), the control procedure
//! ([`crate::control`]), the recorders (the MCAP log, the live view, the live twin), the log
//! ([`crate::log`]) and the twin ([`crate::twin`]) — and everything that reads a session back.
//!
//! - [`run`]: the composition root of a live session ([`run::run`]).
//! - [`runner`]: the async session loop: blocks, safety, procedure, ramp-down.
//! - [`recorder`]: the [`SessionRecorder`] trait and its combinators; the recorders:
//!   [`mcap`] (the session log), [`live`] (the live view for the Foxglove app), [`twin`] (the
//!   live twin and its comparison).
//! - [`topics`]: the one table of topics and the logged message types.
//! - [`summary`]: the session summary, each step with the twin's comparison.
//! - [`replay`]: the summary recomputed from a recording; [`twin_replay`]: the twin re-run on
//!   a recording, and the log copy with its output.
//!
//! The session never imports the simulated rig: a simulated session and a hardware session
//! differ only in the backend the caller hands in.

pub mod live;
pub mod mcap;
mod packed;
pub mod recorder;
pub mod replay;
pub mod run;
pub mod runner;
pub mod summary;
pub mod topics;
pub mod twin;
pub mod twin_replay;

pub use recorder::{NullRecorder, RecordError, SessionRecorder, Tee};
pub use run::{runtime, BackendMetadata, RunError, RunOutcome, SessionRequest};
pub use runner::{run_session, SessionError, SessionProgress, STATUS_PERIOD_S};
pub use summary::{Missing, SessionSummary, StepResult, TestSummary};
