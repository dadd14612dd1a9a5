//! The twin's settings (`[twin]`): described in [`crate::config::twin`], re-exported here for
//! the twin's users. A bad value becomes [`super::TwinError::Spec`] (key, value, expected).

pub use crate::config::{AfterGap, TwinSpec};
