//! Faults of the hardware links, injected into `rigtwin firmware-sim`, seen end to end by
//! `rigtwin run --backend hw`. Guards:
//! - problems the session survives (reordered, malformed frames; serial garbage and bad
//!   checksums) are counted on `/rig/status` and the session completes;
//! - problems that make the test impossible (a lost frame or corrupted block: a sequence gap;
//!   a silent amplifier; the interlock; amplifier overload; the device vanishing) abort the
//!   session with a clear reason (a hung device: by the heartbeat supervision), with the drive
//!   ramped down over the link when it is alive,
//!   every block so far recorded and the log complete;
//! - when the host dies mid-test, the device ramps the drive down by itself.

mod cli_support;
mod hw_support;

use cli_support::{cache, json, text};
use hw_support::{assert_ramp_falls_to_zero, hw_args, run_hw, FirmwareSim};
use rigtwin::control::{ControlState, EventKind, Phase, SessionEvent};
use rigtwin::log::read_session;
use rigtwin::session::topics::{TOPIC_CONTROL, TOPIC_DAQ, TOPIC_EVENTS, TOPIC_STATUS};

/// Two steps through the impact band (about 4 s of rig time).
const PLAN: &str = r#"
name = "hw-fault-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 2
settle_periods = 40
record_periods = 30
steps_per_period = 1000

[[test]]
name = "high-down"
direction = "down"
omega_start = 1.01
omega_end = 0.99
"#;

struct Outcome {
    summary: serde_json::Value,
    link: serde_json::Value,
    text: String,
    abort_kind: Option<String>,
    ramp: Vec<ControlState>,
    device: serde_json::Value,
}

fn session_with(fault: &str) -> Outcome {
    session_on(PLAN, fault)
}

/// Six steps (about 12 s of rig time): long enough that faults supervised on the wall clock
/// (serial timeouts: 3 x 250 ms) surely end it however fast the virtual-time rig runs.
fn long_session_with(fault: &str) -> Outcome {
    session_on(&PLAN.replace("steps = 2", "steps = 6"), fault)
}

fn session_on(plan: &str, fault: &str) -> Outcome {
    let dir = tempfile::tempdir().unwrap();
    let fw = FirmwareSim::start(&["--inject", fault]);
    let (o, mcap, summary) = run_hw(dir.path(), plan, &fw, &[]);
    let device = if fault.contains("vanish") {
        fw.kill();
        serde_json::Value::Null
    } else {
        fw.session_end()
    };
    let t = text(&o);
    let s = read_session(&mcap).unwrap();
    assert!(s.complete, "{fault}: log not closed: {:?}\n{t}", s.note);
    // Every block received is recorded, in order, without gaps in the log's own sequence.
    let blocks = s.decode::<serde_json::Value>(TOPIC_DAQ).unwrap();
    let summary = json(&summary);
    assert_eq!(
        blocks.len() as u64,
        summary["blocks"].as_u64().unwrap(),
        "{fault}"
    );
    let link = s
        .decode::<serde_json::Value>(TOPIC_STATUS)
        .unwrap()
        .last()
        .map(|x| x.2["link"].clone())
        .unwrap();
    let abort_kind = s
        .decode::<SessionEvent>(TOPIC_EVENTS)
        .unwrap()
        .into_iter()
        .find_map(|(_, _, e)| match e.kind {
            EventKind::Abort { reason, .. } => Some(
                serde_json::to_value(reason).unwrap()["kind"]
                    .as_str()
                    .unwrap()
                    .to_string(),
            ),
            _ => None,
        });
    let ramp = s
        .decode::<ControlState>(TOPIC_CONTROL)
        .unwrap()
        .into_iter()
        .map(|x| x.2)
        .filter(|c| c.phase == Phase::RampDown)
        .collect();
    assert_eq!(o.status.success(), abort_kind.is_none(), "{fault}: {t}");
    println!(
        "{fault}:\n  abort {abort_kind:?}: {}\n  link {link}\n  device {device}",
        summary["abort_reason"]
    );
    Outcome {
        summary,
        link,
        text: t,
        abort_kind,
        ramp,
        device,
    }
}

fn assert_ramped_down(o: &Outcome, what: &str) {
    let drives: Vec<f64> = o.ramp.iter().map(|c| c.drive_v).collect();
    assert_ramp_falls_to_zero(&drives, what);
}

#[test]
fn survivable_link_faults_are_counted_and_the_session_completes() {
    let o = session_with(r#"{"kind":"swap_frames","block":20}"#);
    assert!(o.abort_kind.is_none(), "{}", o.text);
    assert!(o.link["reordered"].as_u64().unwrap() >= 1, "{}", o.link);
    assert_eq!(o.link["sequence_gaps"], 0);

    let o = session_with(r#"{"kind":"bad_frames","block":20}"#);
    assert!(o.abort_kind.is_none(), "{}", o.text);
    assert!(o.link["malformed"].as_u64().unwrap() >= 3, "{}", o.link);
    let last = o.link["last_error"].as_str().unwrap_or("");
    assert!(
        last.contains("0x7ab") || last.contains("0x101") || last.contains("tunnel"),
        "{last}"
    );

    let o = session_with(r#"{"kind":"serial_garbage","at_s":1.0,"port":"amp"}"#);
    assert!(o.abort_kind.is_none(), "{}", o.text);
    assert!(
        o.link["serial_garbage"].as_u64().unwrap() >= 1,
        "{}",
        o.link
    );
    assert!(
        o.link["serial_checksum_errors"].as_u64().unwrap() >= 1,
        "{}",
        o.link
    );
    assert!(o.text.contains("links:"), "{}", o.text);
}

#[test]
fn fatal_link_faults_abort_with_a_reason_and_a_ramp_down() {
    // A lost frame: the block is incomplete, a sequence gap, the DAQ stream is not trusted
    // (no ramp-down blocks recorded; the ramp-down command still goes out).
    let o = session_with(r#"{"kind":"drop_frame","block":30,"frame":7}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("sequence_gap"), "{}", o.text);
    assert_eq!(o.link["sequence_gaps"], 1, "{}", o.link);
    assert_eq!(o.device["final_amplitude_v"], 0.0, "{}", o.device);

    let o = session_with(r#"{"kind":"corrupt_sample","block":30}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("sequence_gap"), "{}", o.text);
    assert_eq!(o.link["crc_errors"], 1, "{}", o.link);

    // The amplifier stops answering: timeouts, then the link is gone.
    let o = long_session_with(r#"{"kind":"serial_silent","at_s":0.5,"port":"amp"}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("rig"), "{}", o.text);
    let reason = o.summary["abort_reason"].as_str().unwrap();
    assert!(
        reason.contains("power amplifier") && reason.contains("link gone"),
        "{reason}"
    );
    assert!(
        o.link["serial_timeouts"].as_u64().unwrap() >= 3,
        "{}",
        o.link
    );
    assert_ramped_down(&o, "serial_silent");

    let o = long_session_with(r#"{"kind":"interlock","at_s":1.0}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("rig"), "{}", o.text);
    assert!(
        o.summary["abort_reason"]
            .as_str()
            .unwrap()
            .contains("interlock open"),
        "{}",
        o.summary
    );
    assert_ramped_down(&o, "interlock");

    let o = long_session_with(r#"{"kind":"drive_saturation","at_s":1.0,"limit_v":0.05}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("rig"), "{}", o.text);
    let reason = o.summary["abort_reason"].as_str().unwrap();
    assert!(
        reason.contains("saturated") || reason.contains("overload"),
        "{reason}"
    );
    assert_ramped_down(&o, "drive_saturation");

    // The device hangs (sends nothing, still listens): the host's heartbeat supervision
    // declares the link lost before the DAQ watchdog (2 s) would.
    let o = long_session_with(r#"{"kind":"mute","at_s":1.5}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("backend"), "{}", o.text);
    let reason = o.summary["abort_reason"].as_str().unwrap();
    assert!(reason.contains("no DEVICE_HEARTBEAT"), "{reason}");
    assert!(
        o.link["heartbeat_misses"].as_u64().unwrap() >= 1,
        "{}",
        o.link
    );

    // The device disappears mid-test: the link is lost, the log is complete.
    let o = long_session_with(r#"{"kind":"vanish","at_s":1.5}"#);
    assert_eq!(o.abort_kind.as_deref(), Some("backend"), "{}", o.text);
    let reason = o.summary["abort_reason"].as_str().unwrap();
    assert!(
        reason.contains("link lost") && reason.contains("CAN link"),
        "{reason}"
    );
    assert!(
        o.summary["rig_seconds"].as_f64().unwrap() >= 1.4,
        "{}",
        o.summary
    );
    assert!(!o.text.contains("panicked"), "{}", o.text);
}

/// The host is killed mid-test: the device sees no heartbeat, raises HEARTBEAT_LOST and
/// ramps the drive down by itself.
#[test]
fn the_device_ramps_down_by_itself_when_the_host_dies() {
    let dir = tempfile::tempdir().unwrap();
    let fw = FirmwareSim::start(&[]);
    // Six steps: the session surely outlasts the first flushes of its log.
    let plan = cli_support::write_plan(dir.path(), &PLAN.replace("steps = 2", "steps = 6"));
    let mcap = dir.path().join("session.mcap");
    let mut host = std::process::Command::new(env!("CARGO_BIN_EXE_rigtwin"))
        .env("RIGTWIN_CACHE", cache())
        .args(hw_args(
            &plan,
            &fw.can,
            &fw.ldv,
            &fw.amp,
            mcap.to_str().unwrap(),
        ))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill once the log holds a few flushes of DAQ data (the drive is on by then).
    cli_support::wait_for_log_growth(&mut host, &mcap, 300_000);
    host.kill().unwrap();
    host.wait().unwrap();
    let end = fw.session_end();
    println!("device: {end}");
    assert_eq!(end["reason"], "heartbeat_lost");
    assert!(end["amplitude_at_loss_v"].as_f64().unwrap() > 0.0, "{end}");
    assert_eq!(end["final_amplitude_v"], 0.0, "{end}");
    assert!(end["safety_ramp_blocks"].as_u64().unwrap() >= 10, "{end}");
}
