//! The twin's settings (`[twin]`): described in [`crate::config::twin`], re-exported here for
//! the twin's users. A bad value becomes [`TwinError::Spec`] with the key in its message.

use super::error::TwinError;
use crate::config::SpecError;

pub use crate::config::{AfterGap, TwinSpec};

impl From<SpecError> for TwinError {
    fn from(e: SpecError) -> TwinError {
        TwinError::Spec(e.to_string())
    }
}
