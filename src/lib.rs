//! rigtwin: hardware-in-the-loop controller and digital twin for vibro-impact test rigs.
//!
//! The model side builds a reduced-order model (ROM) of a two-beam rig from a rig description:
//! [`config`] (TOML rig description) -> [`fe`] (structured hex mesh, element matrices, interface
//! layers, sparse assembly, CalculiX exchange) -> [`rom`] (sparse eigen solver, MacNeal reduction
//! with a massless contact boundary, the ROM file) -> [`contact`] and [`sim`] (implicit frictional
//! contact inside a leapfrog integrator). [`signal`] holds the per-period metrics shared by
//! simulation and measurement. [`plan`] holds the stepped-sine test plans and [`report`]
//! draws the paper-style figures. The experiment side: [`rig`] (the backend trait, the DAQ
//! types, the simulated rig, the hardware backend), [`control`] (amplitude control, settling,
//! safety, the stepped-sine procedure), [`twin`] (the live digital twin: the ROM on the
//! measured base acceleration, on its own thread), [`log`] (MCAP files: writer and reader) and
//! [`session`] (the composition root: backend, procedure, recorders, log, twin and live view;
//! replay; the session summary). [`diagnose`] reads a recorded session for the physics the
//! model leaves out (sensor sensitivities, linear modes, clearance). [`cli`] parses the `rigtwin` binary's commands and prints.
//!
//! Numerical modules are synchronous, deterministic and never read the clock; async (tokio)
//! lives in the session and the simulated rig's pacing.

pub mod cli;
pub mod config;
pub mod contact;
pub mod control;
pub mod diagnose;
pub mod fe;
pub mod log;
pub mod physics;
pub mod plan;
pub mod report;
pub mod rig;
pub mod rom;
pub mod session;
pub mod signal;
pub mod sim;
pub mod twin;
