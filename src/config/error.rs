//! Errors of the rig description: reading, TOML syntax, schema (unknown keys, wrong types)
//! and semantic validation ([`ConfigError`]), and the out-of-range value of a rig-service
//! table ([`SpecError`], returned by the specs' own `validate`). Every message names the file
//! (where there is one), where in it (line:column or the dotted key path) and what was
//! expected.

/// An error in a rig description.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read the rig description: {source}")]
    Io {
        /// File name.
        file: String,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The text is not valid TOML.
    #[error("{file}:{line}:{column}: TOML syntax error: {message}")]
    Syntax {
        /// File name.
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column (in characters).
        column: usize,
        /// What the TOML parser expected.
        message: String,
    },
    /// Valid TOML that does not match the schema: unknown key, wrong type, missing key.
    #[error("{file}:{line}:{column}: `{key}`: {message}")]
    Schema {
        /// File name.
        file: String,
        /// 1-based line (0 when unknown).
        line: usize,
        /// 1-based column (0 when unknown).
        column: usize,
        /// Dotted key path of the offending entry (may be a table path for a missing key).
        key: String,
        /// What serde expected.
        message: String,
    },
    /// A rig-service setting (`[control]`, `[safety]`, `[shaker]`, `[daq]`, `[truth]`, `[twin]`) that is
    /// not acceptable; the message names the key.
    #[error("{file}: {message}")]
    Service {
        /// File name.
        file: String,
        /// The key, its value and what was expected.
        message: String,
    },
    /// A value that parses but is not acceptable.
    #[error("{file}: `{key}` = {value}: expected {expected}")]
    Invalid {
        /// File name.
        file: String,
        /// Dotted key path, e.g. `parts.upper_beam.width_root`.
        key: String,
        /// The offending value as written (or as derived).
        value: String,
        /// What would be accepted.
        expected: String,
    },
}

/// A value of a rig-service table (`[control]`, `[safety]`, `[shaker]`, `[daq]`, `[truth]`,
/// `[twin]`) or of a service's options (the session log's, the live view's) out of the range
/// documented on its field: `<key> = <value>: expected <what>`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{key} = {value}: expected {expected}")]
pub struct SpecError {
    /// Dotted key path, e.g. `control.kp` or `truth.variants.sensor_gains[0].channel`.
    pub key: String,
    /// The offending value as displayed.
    pub value: String,
    /// What would be accepted.
    pub expected: String,
}

impl SpecError {
    /// The error for `key = value`, which should have been `expected`.
    pub fn new(
        key: impl Into<String>,
        value: impl std::fmt::Display,
        expected: impl Into<String>,
    ) -> Self {
        SpecError {
            key: key.into(),
            value: value.to_string(),
            expected: expected.into(),
        }
    }
}

/// `Ok` when `value` is finite and `ok` holds, else the error `key = value: expected ...`.
pub(super) fn check(key: &str, value: f64, ok: bool, expected: &str) -> Result<(), SpecError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(SpecError::new(key, value, expected))
    }
}

/// `key = value: expected > 0` unless `value` is finite and positive.
pub(super) fn positive(key: &str, value: f64) -> Result<(), SpecError> {
    check(key, value, value > 0.0, "> 0")
}

/// `key = value: expected >= 0` unless `value` is finite and not negative.
pub(super) fn non_negative(key: &str, value: f64) -> Result<(), SpecError> {
    check(key, value, value >= 0.0, ">= 0")
}

impl ConfigError {
    /// The dotted key path of a schema or validation error, if the error has one.
    pub fn key(&self) -> Option<&str> {
        match self {
            ConfigError::Schema { key, .. } | ConfigError::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// 1-based (line, column) of a byte offset in `text`; the column counts characters.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    // Back off to a char boundary so slicing cannot panic on a span inside a multi-byte char.
    let mut at = offset;
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_column_counts_from_one() {
        let t = "a = 1\nbb = 2\n";
        assert_eq!(line_column(t, 0), (1, 1));
        assert_eq!(line_column(t, 6), (2, 1));
        assert_eq!(line_column(t, 11), (2, 6));
        assert_eq!(line_column(t, 1000), (3, 1));
    }
}
