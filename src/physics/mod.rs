//! What the nominal ROM leaves out, one implementation each, used by the simulated rig's truth
//! (hidden, `[truth.variants]`) and by the model (declared, `[model]`); the parameters and
//! their checks are [`crate::config::physics`] (re-exported here), so both tables use the same
//! key names and ranges.
//!
//! - [`modal`]: linear modal corrections (natural frequency, damping ratio per mode label),
//!   keeping the MacNeal ROM consistent.
//! - [`iwan`]: friction in the clamping joint, an Iwan element on the first bending mode of
//!   each listed beam: amplitude-dependent softening and damping.
//! - clearance per test: [`PhysicsSpec::test_clearance`]; [`wear`]: the clearance grows with
//!   the contact's dissipated work (Archard-like).
//! - [`tilt`]: the protrusion's contact face is tilted about an axis in the contact plane,
//!   giving every pair its own initial gap.
//! - [`sensor_gain`]: per-channel sensitivities (true over nominal).
//! - [`contact_detection`]: the contact-resistance circuit and its threshold, through which
//!   a contact state becomes the measured one.
//!
//! Numerics: pure and deterministic, no I/O; errors ([`PhysicsError`]) name the key.

// NOTE: validation uses negated comparisons such as `!(d > w)` on purpose: they reject NaN
// together with out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod contact_detection;
pub mod error;
pub mod iwan;
pub mod modal;
pub mod sensor_gain;
pub mod tilt;
pub mod wear;

pub use crate::config::physics::{
    Beam, ClampFrictionSpec, ClearanceSpec, ModalCorrectionSpec, ModelExtensions, PhysicsSpec,
    SensorGainSpec, TestClearanceSpec, TiltSpec, TruthVariants, WearSpec, MAX_CLEARANCE,
    MAX_SLIDERS, MAX_TILT, MODAL_FREQUENCY_RANGE,
};
pub use error::PhysicsError;
