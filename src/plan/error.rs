//! Errors of a test plan: reading, TOML syntax, schema (unknown keys, wrong types) and
//! validation. Every message names the file, where in it (line:column when known, the test by
//! 1-based number and name, or `[defaults]`), the key and what was expected.

use std::fmt;

/// Where in a plan an entry sits: the plan itself, its `[defaults]` table, or one test.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PlanLocation {
    /// A top-level key of the plan.
    Plan,
    /// The `[defaults]` table.
    Defaults,
    /// The `[[test]]` with this 0-based index and (when it has one) name.
    Test {
        /// 0-based position in the file.
        index: usize,
        /// The test's `name`, if given.
        name: Option<String>,
    },
}

impl fmt::Display for PlanLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlanLocation::Plan => write!(f, "plan"),
            PlanLocation::Defaults => write!(f, "[defaults]"),
            PlanLocation::Test {
                index,
                name: Some(name),
            } => write!(f, "test {} \"{name}\"", index + 1),
            PlanLocation::Test { index, name: None } => write!(f, "test {}", index + 1),
        }
    }
}

/// An error in a test plan. (`file` is a `Box<str>` to keep the error small enough to
/// return by value.)
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The file could not be read.
    #[error("{file}: cannot read the test plan: {source}")]
    Io {
        /// File name.
        file: Box<str>,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The text is not valid TOML.
    #[error("{file}:{line}:{column}: TOML syntax error: {message}")]
    Syntax {
        /// File name.
        file: Box<str>,
        /// 1-based line.
        line: usize,
        /// 1-based column (in characters).
        column: usize,
        /// What the TOML parser expected.
        message: String,
    },
    /// Valid TOML that does not match the schema: unknown key or wrong type.
    #[error("{file}:{line}:{column}: {location}: `{key}`: {message}")]
    Schema {
        /// File name.
        file: Box<str>,
        /// 1-based line (0 when unknown).
        line: usize,
        /// 1-based column (0 when unknown).
        column: usize,
        /// The table holding the key.
        location: PlanLocation,
        /// The offending key.
        key: String,
        /// What was expected (for an unknown key: the accepted keys).
        message: String,
    },
    /// A key that neither the test nor `[defaults]` gives.
    #[error(
        "{file}: {location}: `{key}` is missing: give it in the test or in [defaults] ({expected})"
    )]
    Missing {
        /// File name.
        file: Box<str>,
        /// The test lacking the key.
        location: PlanLocation,
        /// The missing key.
        key: String,
        /// What the key means and accepts.
        expected: String,
    },
    /// A value that parses but is not acceptable.
    #[error("{file}: {location}: `{key}` = {value}: expected {expected}")]
    Invalid {
        /// File name.
        file: Box<str>,
        /// Where the value was written (the test, or `[defaults]` when it came from there).
        location: PlanLocation,
        /// The offending key (always one of the plan's known keys).
        key: &'static str,
        /// The value as parsed.
        value: String,
        /// What would be accepted.
        expected: String,
    },
    /// The plan has no `[[test]]`.
    #[error("{file}: the plan has no [[test]] table: add at least one test")]
    NoTests {
        /// File name.
        file: Box<str>,
    },
}

impl PlanError {
    /// The key an error is about, if it is about one.
    pub fn key(&self) -> Option<&str> {
        match self {
            PlanError::Schema { key, .. } | PlanError::Missing { key, .. } => Some(key),
            PlanError::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }

    /// Where in the plan the error is, if it is inside one.
    pub fn location(&self) -> Option<&PlanLocation> {
        match self {
            PlanError::Schema { location, .. }
            | PlanError::Missing { location, .. }
            | PlanError::Invalid { location, .. } => Some(location),
            _ => None,
        }
    }
}

/// 1-based (line, column) of a byte offset in `text`; the column counts characters.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut at = offset.min(text.len());
    // Back off to a char boundary so slicing cannot panic on a span inside a multi-byte char.
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
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

    #[test]
    fn location_names_test_by_number_and_name() {
        let l = PlanLocation::Test {
            index: 2,
            name: Some("high-up".into()),
        };
        assert_eq!(l.to_string(), "test 3 \"high-up\"");
        assert_eq!(PlanLocation::Defaults.to_string(), "[defaults]");
    }
}
