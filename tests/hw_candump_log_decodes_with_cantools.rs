//! Independent decoding of the hardware link: a session over `rigtwin firmware-sim` writes
//! every CAN frame it sent and received as a candump log (`--can-log`) with rigtwin's own
//! decoded values beside it; `cantools` (PyPI), a decoder not written here, reads the log
//! against `firmware-interfaces/rig.dbc` and must find every message and every signal value
//! equal to rigtwin's (`tests/hw_support/check_candump.py`).
//!
//! Without python3 or its `cantools` module the test says why and passes, unless
//! `RIGTWIN_REQUIRE_CANTOOLS_PY` is set (CI), when it fails.

mod cli_support;
mod hw_support;

use std::path::Path;
use std::process::Command;

use cli_support::text;
use hw_support::{cantools_python_or_skip, run_hw, FirmwareSim};

/// One short step: enough for every message type to appear.
const PLAN: &str = r#"
name = "cantools-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 1
settle_periods = 20
record_periods = 10
steps_per_period = 1000

[[test]]
name = "one-step"
direction = "down"
omega_start = 1.01
omega_end = 1.01
"#;

#[test]
fn cantools_decodes_the_candump_log_to_rigtwins_values() {
    let Some(python) =
        cantools_python_or_skip("cantools_decodes_the_candump_log_to_rigtwins_values")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("can.log");
    // A few malformed frames too (cantools and rigtwin must agree on those as well), and a
    // drive saturation late in the session so that FAULT appears (the session then aborts).
    let fw = FirmwareSim::start(&[
        "--inject",
        r#"{"kind":"bad_frames","block":3}"#,
        "--inject",
        r#"{"kind":"drive_saturation","at_s":0.3,"limit_v":0.01}"#,
    ]);
    let (o, _, _) = run_hw(dir.path(), PLAN, &fw, &["--can-log", log.to_str().unwrap()]);
    fw.session_end();
    assert!(text(&o).contains("saturated"), "{}", text(&o));
    let decoded = rigtwin::rig::hw::can::candump::decoded_path(&log);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/hw_support/check_candump.py");
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware-interfaces/rig.dbc");
    let out = Command::new(&python)
        .arg(&script)
        .arg(&dbc)
        .arg(&log)
        .arg(&decoded)
        .output()
        .unwrap();
    let report = String::from_utf8_lossy(&out.stdout);
    println!("{report}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "cantools disagrees with rigtwin: {report}"
    );
    let r: serde_json::Value = serde_json::from_str(&report).unwrap();
    // Every message of rig.dbc appeared and was compared.
    for m in [
        "FAULT",
        "STREAM_CONTROL",
        "DRIVE_SETPOINT",
        "DRIVE_STATUS",
        "HOST_HEARTBEAT",
        "DEVICE_HEARTBEAT",
        "TIME_SYNC_REQUEST",
        "TIME_SYNC_RESPONSE",
        "DAQ_BLOCK_HEADER",
        "DAQ_SAMPLES",
    ] {
        assert!(
            r["counts"][m].as_u64().unwrap_or(0) > 0,
            "{m} missing: {report}"
        );
    }
    assert!(
        r["counts"]["(undecodable)"].as_u64().unwrap_or(0) >= 2,
        "{report}"
    );
}
