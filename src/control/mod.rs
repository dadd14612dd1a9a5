//! The experiment side's control: closed-loop amplitude control of the fundamental base
//! displacement ([`amplitude`]), settle detection ([`settle`]), safety limits and abort reasons
//! ([`safety`]), the stepped-sine procedure as a synchronous state machine over DAQ blocks
//! ([`procedure`]), the per-step summary from raw counts shared with replay ([`summary`]) and
//! the logged records ([`events`]). `[control]` and `[safety]` of the rig description:
//! [`spec`]. The async session that drives a rig backend through the procedure is
//! the session's (`src/session/`).

pub mod amplitude;
pub mod events;
pub mod procedure;
pub mod safety;
pub mod settle;
pub mod spec;
pub mod summary;

pub use amplitude::{AmplitudeController, ControlUpdate};
pub use events::{ControlState, EventKind, Phase, SessionEvent};
pub use procedure::{BlockOutcome, Procedure, SessionSetup, SetupError};
pub use safety::{AbortReason, SafetyMonitor};
pub use spec::{ControlSpec, SafetySpec};
pub use summary::{summarize, window_signals, StepInfo, StepSummary, WindowSignals};
