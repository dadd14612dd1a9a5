//! Shared by the tests that read session logs with the official Python `mcap` reader.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// Environment variable naming the Python interpreter (default `python3`).
pub const PYTHON_ENV: &str = "RIGTWIN_PYTHON";

/// The Python interpreter to use.
pub fn python() -> String {
    std::env::var(PYTHON_ENV).unwrap_or_else(|_| "python3".to_string())
}

/// The Python interpreter when it can import `mcap`; `None` (test skipped) otherwise, unless
/// `RIGTWIN_REQUIRE_MCAP_PY` is set (CI), when it panics.
pub fn mcap_python_or_skip(name: &str) -> Option<String> {
    let python = python();
    let why = match Command::new(&python)
        .args(["-c", "import mcap.reader"])
        .output()
    {
        Ok(out) if out.status.success() => return Some(python),
        Ok(out) => format!(
            "`{python} -c 'import mcap.reader'` failed ({}): install it with \
             `{python} -m pip install mcap`",
            String::from_utf8_lossy(&out.stderr).trim()
        ),
        Err(e) => format!("cannot start `{python}` ({e}); set {PYTHON_ENV}"),
    };
    if std::env::var_os("RIGTWIN_REQUIRE_MCAP_PY").is_some() {
        panic!("RIGTWIN_REQUIRE_MCAP_PY is set but {why}");
    }
    eprintln!("SKIPPED {name}: {why}");
    None
}

/// What `tests/log_support/read_mcap.py` reports about a file (JSON).
pub fn read_with_python(python: &str, path: &Path) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/log_support/read_mcap.py");
    let out = Command::new(python)
        .arg(&script)
        .arg(path)
        .output()
        .expect("run read_mcap.py");
    assert!(
        out.status.success(),
        "read_mcap.py failed on {}:\n{}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("read_mcap.py prints JSON")
}
