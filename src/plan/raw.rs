//! The plan as written: serde structs with `deny_unknown_fields` and every per-test key
//! optional (so `[defaults]` can supply it), plus the error mapping that turns toml/serde
//! errors into [`PlanError`]s naming the line, the test and the key.

use serde::Deserialize;
use toml::Spanned;

use super::error::{line_column, PlanError, PlanLocation};

/// The top level of a plan file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDocument {
    name: Option<String>,
    description: Option<String>,
    defaults: Option<Spanned<toml::Table>>,
    #[serde(default)]
    test: Vec<Spanned<toml::Table>>,
}

/// The per-test keys. Integers are read as `i64` so that a negative count is reported by the
/// validation with the key's meaning, not as a bare serde type error.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTest {
    pub name: Option<String>,
    pub level: Option<f64>,
    pub direction: Option<String>,
    pub clearance: Option<f64>,
    pub omega_start: Option<f64>,
    pub omega_end: Option<f64>,
    pub steps: Option<i64>,
    pub settle_periods: Option<i64>,
    pub record_periods: Option<i64>,
    pub steps_per_period: Option<i64>,
}

/// A parsed plan before defaults are merged and values validated.
#[derive(Debug)]
pub(super) struct RawPlan {
    pub name: Option<String>,
    pub description: Option<String>,
    pub defaults: RawTest,
    pub tests: Vec<RawTest>,
}

/// Parses the text: TOML syntax, then the top-level schema, then each table's schema.
pub(super) fn parse(text: &str, file: &str) -> Result<RawPlan, PlanError> {
    // Pass 1: syntax only, so a syntax error is never mistaken for a schema error.
    if let Err(e) = toml::from_str::<toml::Table>(text) {
        let (line, column) = e.span().map_or((0, 0), |s| line_column(text, s.start));
        return Err(PlanError::Syntax {
            file: file.into(),
            line,
            column,
            message: e.message().trim().to_string(),
        });
    }
    // Pass 2: the top level, from the text so errors carry a span.
    let doc: RawDocument = toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((0, 0), |s| line_column(text, s.start));
        let message = e.message().trim().to_string();
        let key = unknown_field(&message)
            .or_else(|| key_at(text, e.span().map(|s| s.start)))
            .unwrap_or_else(|| "?".to_string());
        PlanError::Schema {
            file: file.into(),
            line,
            column,
            location: PlanLocation::Plan,
            key,
            message: explain(&message),
        }
    })?;
    // Pass 3: each table. `toml::Value` errors carry the key path but no span; the span of
    // the table locates the key's line.
    let defaults = match doc.defaults {
        Some(t) => table(text, file, t, PlanLocation::Defaults)?,
        None => RawTest::default(),
    };
    let mut tests = Vec::with_capacity(doc.test.len());
    for (index, t) in doc.test.into_iter().enumerate() {
        let name = t
            .get_ref()
            .get("name")
            .and_then(|v| v.as_str())
            .map(str::to_string);
        tests.push(table(text, file, t, PlanLocation::Test { index, name })?);
    }
    Ok(RawPlan {
        name: doc.name,
        description: doc.description,
        defaults,
        tests,
    })
}

/// Deserialises one `[defaults]` or `[[test]]` table.
fn table(
    text: &str,
    file: &str,
    t: Spanned<toml::Table>,
    location: PlanLocation,
) -> Result<RawTest, PlanError> {
    let start = t.span().start;
    let value = toml::Value::Table(t.into_inner());
    RawTest::deserialize(value).map_err(|e| {
        let message = e.message().trim().to_string();
        let key = unknown_field(&message)
            .or_else(|| error_key_path(&e.to_string()))
            .unwrap_or_else(|| "?".to_string());
        let (line, column) = find_key(text, start, &key).unwrap_or((0, 0));
        PlanError::Schema {
            file: file.into(),
            line,
            column,
            location,
            key,
            message: explain(&message),
        }
    })
}

/// The key of serde's "unknown field `x`, expected ..." message.
fn unknown_field(message: &str) -> Option<String> {
    message
        .strip_prefix("unknown field `")
        .and_then(|r| r.split('`').next())
        .map(str::to_string)
}

/// The key path of a `toml::Value` deserialisation error ("... in `steps`").
fn error_key_path(display: &str) -> Option<String> {
    display
        .lines()
        .rev()
        .find_map(|l| l.trim().strip_prefix("in `"))
        .and_then(|r| r.strip_suffix('`'))
        .map(str::to_string)
}

/// Rewords serde's messages for a plan author: an unknown key lists the accepted keys.
fn explain(message: &str) -> String {
    if let Some(rest) = message.strip_prefix("unknown field `") {
        if let Some((_, expected)) = rest.split_once("`, expected ") {
            return format!("unknown key; expected {expected}");
        }
    }
    // serde names Rust types; a plan author thinks in TOML values.
    message
        .replace("expected i64", "expected an integer")
        .replace("expected f64", "expected a number")
        .replace("expected a string", "expected a quoted string")
}

/// The key written on the line holding `offset` (`key = value`).
fn key_at(text: &str, offset: Option<usize>) -> Option<String> {
    let offset = offset?.min(text.len());
    let start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    let line = text[start..].lines().next()?;
    let (key, _) = line.split_once('=')?;
    let key = key.trim().trim_matches('"');
    (!key.is_empty()).then(|| key.to_string())
}

/// 1-based (line, column) of `key = ...` in the table starting at byte `table_start`: the
/// first such line before the next table header.
fn find_key(text: &str, table_start: usize, key: &str) -> Option<(usize, usize)> {
    let table_start = table_start.min(text.len());
    let line_start = text[..table_start].rfind('\n').map_or(0, |i| i + 1);
    let mut offset = line_start;
    for (i, line) in text[line_start..].split_inclusive('\n').enumerate() {
        let trimmed = line.trim_start();
        if i > 0 && trimmed.starts_with('[') {
            return None;
        }
        let bare = trimmed.trim_start_matches('"');
        if let Some(after) = bare.strip_prefix(key) {
            let after = after.trim_start_matches('"').trim_start();
            if after.starts_with('=') {
                let indent = line.len() - trimmed.len();
                return Some(line_column(text, offset + indent));
            }
        }
        offset += line.len();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn find_key_stops_at_the_next_header() {
        let text = "[[test]]\nname = \"a\"\n[[test]]\nlevel = 1\n";
        assert_eq!(find_key(text, 0, "name"), Some((2, 1)));
        assert_eq!(find_key(text, 0, "level"), None);
        assert_eq!(find_key(text, 20, "level"), Some((4, 1)));
    }

    #[test]
    fn wrong_type_names_the_key_and_its_line() {
        let text = "[[test]]\nname = \"a\"\n  steps = 4.5\n";
        let err = parse(text, "p.toml").unwrap_err();
        match err {
            PlanError::Schema {
                key, line, column, ..
            } => {
                assert_eq!(key, "steps");
                assert_eq!((line, column), (3, 3));
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn explain_speaks_toml() {
        let m = explain("invalid type: floating point `4.5`, expected i64");
        assert_eq!(m, "invalid type: floating point `4.5`, expected an integer");
    }

    #[test]
    fn explain_lists_expected_keys() {
        let m = explain("unknown field `levle`, expected one of `name`, `level`");
        assert_eq!(m, "unknown key; expected one of `name`, `level`");
    }
}
