//! `rigtwin run --backend hw` end to end over the hardware links, with `rigtwin firmware-sim`
//! (the simulated rig behind the documented CAN FD messages on a UDP tunnel and the serial
//! protocols on two pseudo-terminals) as the rig's electronics. Guards:
//! - the control holds the fundamental base displacement within 1 % of the target in every
//!   record window, as on the simulated backend;
//! - the session log is complete: closed, DAQ blocks gap-free from 0, as many as the session
//!   received, the same channel layout as the simulated rig, link counters on `/rig/status`
//!   (all frames well-formed), and `rigtwin replay` recomputes the summary bit for bit; the
//!   official Python `mcap` reader reads it (skipped without it unless
//!   `RIGTWIN_REQUIRE_MCAP_PY` is set);
//! - the device ended the session with the drive at zero;
//! - wrong or missing link arguments and a missing SocketCAN are clear errors.

mod cli_support;
mod hw_support;
mod log_support;

use cli_support::{json, rigtwin, text};
use hw_support::{hw_args, run_hw, FirmwareSim};
use rigtwin::log::read_session;
use rigtwin::session::topics::{TOPIC_DAQ, TOPIC_STATUS};

/// Two steps through the impact band at the high level; 100-period record windows as in the
/// simulated-backend test (a 30-period window's fundamental scatters by up to 3 %).
pub const PLAN: &str = r#"
name = "hw-session-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 2
settle_periods = 60
record_periods = 100
steps_per_period = 1000

[[test]]
name = "high-down"
direction = "down"
omega_start = 1.01
omega_end = 0.99
"#;

#[test]
fn a_stepped_sine_over_can_and_serial_holds_the_amplitude_and_logs_a_complete_session() {
    let dir = tempfile::tempdir().unwrap();
    let fw = FirmwareSim::start(&[]);
    let (o, mcap, summary) = run_hw(dir.path(), PLAN, &fw, &[]);
    let end = fw.session_end();
    println!("{}\nfirmware-sim: {end}", text(&o));
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(end["reason"], "stop");
    assert_eq!(end["final_amplitude_v"], 0.0);
    assert_eq!(end["rx_errors"], 0);
    let s = json(&summary);
    assert_eq!(s["aborted"], false);
    let steps = s["tests"][0]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2);
    for st in steps {
        cli_support::assert_base_amplitude_within(st, 0.01);
    }

    // The log: complete, every block in order, the simulated rig's layout.
    let session = read_session(&mcap).unwrap();
    assert!(session.complete, "{:?}", session.note);
    let blocks = session.decode::<serde_json::Value>(TOPIC_DAQ).unwrap();
    assert_eq!(blocks.len() as u64, s["blocks"].as_u64().unwrap());
    for (i, (_, seq, b)) in blocks.iter().enumerate() {
        assert_eq!(*seq, i as u64);
        assert_eq!(b["seq"].as_u64(), Some(i as u64));
        assert_eq!(b["counts"].as_array().unwrap().len(), 11 * 256);
    }
    assert_eq!(session.metadata("session").unwrap()["backend"], "hw");
    let statuses = session.decode::<serde_json::Value>(TOPIC_STATUS).unwrap();
    let last = &statuses.last().unwrap().2;
    let link = &last["link"];
    println!("link counters: {link}");
    assert!(link["frames_received"].as_u64().unwrap() > 140 * blocks.len() as u64);
    for k in [
        "malformed",
        "sequence_gaps",
        "crc_errors",
        "serial_checksum_errors",
    ] {
        assert_eq!(link[k], 0, "{k}: {link}");
    }
    assert!(link["round_trip_s"].as_f64().is_some(), "{link}");

    let replayed = dir.path().join("replay.json");
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--json",
        replayed.to_str().unwrap(),
    ]);
    assert!(
        o.status.success() && text(&o).contains("identical to"),
        "{}",
        text(&o)
    );
    assert_eq!(
        std::fs::read_to_string(&summary).unwrap(),
        std::fs::read_to_string(&replayed).unwrap()
    );

    // The official Python reader reads the hardware session like a simulated one, the link
    // counters included.
    let Some(python) = log_support::mcap_python_or_skip("hw session log in python") else {
        return;
    };
    let py = log_support::read_with_python(&python, &mcap);
    for topic in [TOPIC_DAQ, TOPIC_STATUS, "/session/steps", "/session/events"] {
        let ch = &py["channels"][topic];
        assert_eq!(ch["message_encoding"], "json", "{topic}: {ch}");
        assert_eq!(ch["schema_encoding"], "jsonschema", "{topic}: {ch}");
        assert_eq!(py["sequences_contiguous_from_0"][topic], true, "{topic}");
    }
    assert_eq!(py["payload_errors"].as_array().unwrap().len(), 0);
    assert_eq!(py["counts"][TOPIC_DAQ], s["blocks"]);
    assert!(
        py["first_payloads"][TOPIC_STATUS]["link"].is_object(),
        "{py}"
    );
}

#[test]
fn missing_links_and_missing_socketcan_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let plan = cli_support::write_plan(dir.path(), PLAN);
    let out = dir.path().join("x.mcap");
    let o = rigtwin(&[
        "run",
        "--plan",
        &plan,
        "--quiet",
        "--backend",
        "hw",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("--backend hw needs --can, --ldv and --amp"),
        "{}",
        text(&o)
    );
    let o = rigtwin(&hw_args(
        &plan,
        "udp:nohost",
        "a",
        "b",
        out.to_str().unwrap(),
    ));
    assert!(!o.status.success());
    assert!(
        text(&o).contains("udp:nohost") && text(&o).contains("HOST:PORT"),
        "{}",
        text(&o)
    );
    // A serial port that does not exist is named.
    let fw_less = "udp:127.0.0.1:9";
    let o = rigtwin(&hw_args(
        &plan,
        fw_less,
        "/dev/rigtwin-no-such-tty",
        "/dev/rigtwin-no-such-tty2",
        out.to_str().unwrap(),
    ));
    assert!(!o.status.success());
    assert!(
        text(&o).contains("/dev/rigtwin-no-such-tty"),
        "{}",
        text(&o)
    );
    // SocketCAN: this kernel has no CAN address family; where it has one, can interface
    // `rtwnone0` does not exist.
    let o = rigtwin(&hw_args(&plan, "rtwnone0", "a", "b", out.to_str().unwrap()));
    assert!(!o.status.success());
    let t = text(&o);
    let kernel_has_can = std::process::Command::new("python3")
        .args([
            "-c",
            "import socket; socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if kernel_has_can {
        assert!(
            t.contains("rtwnone0") && t.contains("no such interface"),
            "{t}"
        );
    } else {
        assert!(
            t.contains("SocketCAN is not available in this kernel")
                && t.contains("AF_CAN")
                && t.contains("can_raw"),
            "{t}"
        );
    }
    assert!(!t.contains("panicked"), "{t}");
}
