//! Controller and safety parameters (`[control]`, `[safety]`): described in
//! [`crate::config::control`], re-exported here for the controller's users.

pub use crate::config::{ControlSpec, SafetySpec};
