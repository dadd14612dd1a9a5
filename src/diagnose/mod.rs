//! The diagnosis: from "the twin does not match" to "this physics was missing". This module
//! owns the identification stage, the estimators that read a recorded session
//! ([`crate::session::replay::Recording`]) and return physical evidence and first parameter
//! estimates, without the twin: synchronous numerics, no I/O, deterministic.
//!
//! In the order in which effects confound each other (DESIGN.md, "Signatures and order"):
//! - [`sensors`]: sensor sensitivities from redundant channels (the platform accelerometers
//!   see one base, the vibrometer and the upper-tip accelerometer one spot);
//! - [`linear`]: linear natural frequency and damping of 1FL and 1FU from the impact-free
//!   steps of each test (reference section 3.2), and their dependence on the amplitude across
//!   levels (the clamp's friction);
//! - `resolution`: whether a twin coarser than the reference (modes, contact patch, step) is
//!   the mismatch itself, judged by re-running it refined before the contact effects;
//! - [`clearance`]: the clearance per test from the relative tip displacement before the
//!   first impact (reference section 4, Table 2);
//! - [`wear`]: the clearance per test against the model's accumulated normal contact
//!   impulse, and `[model.wear]` fitted by whole-session model runs; `tilt`: a tilted contact face
//!   against a smaller clearance (both stages of [`pipeline`]).
//!
//! Every estimator works on [`evidence::SessionEvidence`], the fundamental complex amplitudes
//! and contact state of every record window, built once per recording (optionally with
//! sensor-gain corrections applied). An estimator never reads the simulated rig's hidden
//! physics (neither the rig description's tables of it nor the log's metadata of it): it
//! sees the DAQ counts, the layout and the session's events only. What a session cannot tell is a typed
//! error ([`EvidenceError`]) or an explicit "undecided" in the result, never a guess.

mod clamp;
pub mod clearance;
mod clearance_fit;
mod error;
pub mod evidence;
mod gains;
mod judge;
pub mod linear;
mod modes;
pub mod outcome;
pub mod pipeline;
pub mod rerun;
mod resolution;
mod runfit;
pub mod sensors;
mod tilt;
pub mod wear;

pub use clearance::{clearance_per_test, ClearanceEvidence, ClearanceOptions, TestClearance};
pub use error::{DiagnoseError, EvidenceError};
pub use evidence::{session_evidence, SessionEvidence, WindowEvidence};
pub use judge::{DiagnoseOptions, DiagnoseProgress};
pub use linear::{linear_modes, LinearEvidence, LinearOptions, ModeFit};
pub use outcome::{Diagnosis, Refinement, Verdict};
pub use pipeline::{diagnose, needs_finer_rom, DiagnoseInput};
pub use resolution::{refined_reduction, REFERENCE_CUTOFF_RATIO};
pub use sensors::{sensor_sensitivities, SensorEvidence, SensorOptions};
