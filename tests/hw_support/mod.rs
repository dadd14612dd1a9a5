//! Shared by the tests of the hardware path: `rigtwin firmware-sim` as a child process (its
//! endpoints from the JSON line it prints, its session reports), `rigtwin run --backend hw`
//! against it, and the `cantools` peer.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Output, Stdio};

/// A running `rigtwin firmware-sim`.
pub struct FirmwareSim {
    /// The process.
    pub child: Child,
    /// Its stdout, after the endpoints line.
    pub out: BufReader<ChildStdout>,
    /// `--can`.
    pub can: String,
    /// `--ldv`.
    pub ldv: String,
    /// `--amp`.
    pub amp: String,
}

impl FirmwareSim {
    /// Starts it (virtual pacing, one session, the plan's clearance) with `extra` arguments.
    pub fn start(extra: &[&str]) -> FirmwareSim {
        FirmwareSim::start_at("2.78e-3", extra)
    }

    /// Starts it (virtual pacing, one session) at `clearance` (per beam length, as a plan's)
    /// with `extra` arguments.
    pub fn start_at(clearance: &str, extra: &[&str]) -> FirmwareSim {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rigtwin"))
            .env("RIGTWIN_CACHE", super::cli_support::cache())
            .args([
                "firmware-sim",
                "--pace",
                "virtual",
                "--once",
                "--quiet",
                "--clearance",
                clearance,
            ])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start rigtwin firmware-sim");
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        let v: serde_json::Value = serde_json::from_str(&line)
            .unwrap_or_else(|e| panic!("firmware-sim's first line {line:?}: {e}"));
        let e = &v["firmware_sim"];
        let s = |k: &str| e[k].as_str().unwrap().to_string();
        FirmwareSim {
            can: s("can"),
            ldv: s("ldv"),
            amp: s("amp"),
            child,
            out,
        }
    }

    /// The report of the session that ended, then waits for the process (with `--once`).
    pub fn session_end(mut self) -> serde_json::Value {
        let mut line = String::new();
        self.out.read_line(&mut line).unwrap();
        let _ = self.child.wait();
        let v: serde_json::Value = serde_json::from_str(&line)
            .unwrap_or_else(|e| panic!("firmware-sim's session line {line:?}: {e}"));
        v["session_end"].clone()
    }

    /// Ends it (SIGKILL) if still running.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The arguments of `rigtwin run --plan PLAN --quiet --backend hw` on the links `can`, `ldv`
/// and `amp`, logging to `out`.
pub fn hw_args<'a>(
    plan: &'a str,
    can: &'a str,
    ldv: &'a str,
    amp: &'a str,
    out: &'a str,
) -> Vec<&'a str> {
    vec![
        "run",
        "--plan",
        plan,
        "--quiet",
        "--backend",
        "hw",
        "--can",
        can,
        "--ldv",
        ldv,
        "--amp",
        amp,
        "--out",
        out,
    ]
}

/// `rigtwin run PLAN --backend hw` against `fw`, with `extra` arguments: (output, mcap,
/// summary json).
pub fn run_hw(
    dir: &Path,
    plan_text: &str,
    fw: &FirmwareSim,
    extra: &[&str],
) -> (Output, PathBuf, PathBuf) {
    let plan = super::cli_support::write_plan(dir, plan_text);
    let mcap = dir.join("session.mcap");
    let summary = dir.join("summary.json");
    let mut args = hw_args(&plan, &fw.can, &fw.ldv, &fw.amp, mcap.to_str().unwrap());
    args.extend_from_slice(&["--json", summary.to_str().unwrap()]);
    args.extend_from_slice(extra);
    (super::cli_support::rigtwin(&args), mcap, summary)
}

/// Environment variable that makes a missing `cantools` a failure (CI).
pub const REQUIRE_CANTOOLS: &str = "RIGTWIN_REQUIRE_CANTOOLS_PY";

/// The Python interpreter when it can import `cantools`; `None` (skipped) otherwise, unless
/// `RIGTWIN_REQUIRE_CANTOOLS_PY` is set, when it panics.
pub fn cantools_python_or_skip(name: &str) -> Option<String> {
    let python = std::env::var("RIGTWIN_PYTHON").unwrap_or_else(|_| "python3".to_string());
    let why = match Command::new(&python)
        .args(["-c", "import cantools"])
        .output()
    {
        Ok(o) if o.status.success() => return Some(python),
        Ok(o) => format!(
            "`{python} -c 'import cantools'` failed ({}): install it with `{python} -m pip \
             install cantools`",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => format!("cannot start `{python}` ({e}); set RIGTWIN_PYTHON"),
    };
    if std::env::var_os(REQUIRE_CANTOOLS).is_some() {
        panic!("{REQUIRE_CANTOOLS} is set but {why}");
    }
    eprintln!("SKIPPED {name}: {why}");
    None
}

/// The drive of a session's recorded ramp-down blocks, over the links: it ends at zero and,
/// from its peak on, only falls. The blocks the device computed before the command reached it
/// (at most those in flight, as in the runner's allowance) may still carry a rising drive,
/// e.g. the last steps of a setpoint ramp-up.
pub fn assert_ramp_falls_to_zero(drives: &[f64], what: &str) {
    println!("{what}: ramp-down drive {drives:?}");
    assert!(
        drives.len() >= 10,
        "{what}: ramp-down blocks {}",
        drives.len()
    );
    assert!(drives[drives.len() - 1] < 1e-9, "{what}: {drives:?}");
    let peak = (0..drives.len())
        .max_by(|&a, &b| drives[a].total_cmp(&drives[b]).then(b.cmp(&a)))
        .unwrap();
    assert!(
        peak < 4,
        "{what}: the ramp peaks at block {peak}: {drives:?}"
    );
    assert!(
        drives[peak..].windows(2).all(|w| w[1] <= w[0] + 1e-12),
        "{what}: {drives:?}"
    );
}
