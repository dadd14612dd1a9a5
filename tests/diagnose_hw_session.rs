//! `rigtwin diagnose` on a hardware session: `rigtwin run --backend hw` on the nominal
//! default rig against `rigtwin firmware-sim` whose rig description hides a wrong 1FU
//! (`[truth.variants]`, frequency +1.0 %, damping x1.5) on the device side. Guards, on the
//! short plan of tests/diagnose_command.rs:
//! - the host's log holds no trace of the hidden physics (its rig description never had it);
//! - the diagnosis is the simulated session's: `mismatch`, `linear_frequency` of 1FU
//!   accepted first within 0.5 %, the validation error at least 3x lower, `linear_damping`
//!   of 1FU accepted within 20 %.

mod cli_support;
mod diagnose_support;
mod hw_support;

use cli_support::{default_rig_with, json, text};
use diagnose_support::{accepted, diagnose};
use hw_support::{run_hw, FirmwareSim};

/// The plan of tests/diagnose_command.rs: 1FU impact-free at 0.1e-5 l and 0.4e-5 l, then
/// 0.1e-5 l again, in about 60 s of rig time.
const PLAN: &str = r#"
name = "diagnose-short"
[defaults]
clearance = 2.33e-3
settle_periods = 60
record_periods = 50
steps_per_period = 1000
steps = 7
direction = "up"
omega_start = 0.985
omega_end = 1.015

[[test]]
name = "1fu-low"
level = 0.1e-5

[[test]]
name = "1fu-high"
level = 0.4e-5

[[test]]
name = "1fu-low-again"
level = 0.1e-5
"#;

#[test]
fn a_wrong_1fu_behind_the_hardware_links_is_diagnosed_as_on_the_simulated_rig() {
    let dir = tempfile::tempdir().unwrap();
    let (f_true, z_true) = (51.8, 0.0027);
    let device_rig = default_rig_with(
        dir.path(),
        &format!(
            "[truth.variants]\nmodes = [{{ mode = \"1FU\", frequency_hz = {f_true}, \
             damping_ratio = {z_true} }}]\n"
        ),
    );
    let fw = FirmwareSim::start_at("2.33e-3", &[device_rig.to_str().unwrap()]);
    let (o, log, summary) = run_hw(dir.path(), PLAN, &fw, &[]);
    let end = fw.session_end();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(end["reason"], "stop", "{end}");
    assert_eq!(end["rx_errors"], 0, "{end}");
    assert_eq!(json(&summary)["aborted"], false);

    // The host's log: the nominal rig description, no hidden physics anywhere.
    let session = rigtwin::log::read_session(&log).unwrap();
    assert!(session.complete, "{:?}", session.note);
    assert_eq!(session.metadata("session").unwrap()["backend"], "hw");
    let rig_toml = session
        .attachment("rig.toml")
        .expect("a rig.toml attachment");
    let rig: toml::Value = toml::from_str(std::str::from_utf8(&rig_toml.data).unwrap()).unwrap();
    let variants = rig.get("truth").and_then(|t| t.get("variants"));
    assert!(
        variants.and_then(|v| v.get("modes")).is_none(),
        "{variants:?}"
    );

    let d = diagnose(&log, dir.path(), "diagnosis", &[]);
    assert_eq!(d["verdict"], "mismatch", "{d:#}");
    let f = accepted(&d, "linear_frequency");
    assert_eq!(f.len(), 1, "{d:#}");
    assert_eq!(f[0]["rank"], 1);
    assert_eq!(f[0]["parameters"]["mode"], "1FU");
    let fit = f[0]["parameters"]["frequency_hz"].as_f64().unwrap();
    assert!((fit / f_true - 1.0).abs() < 0.005, "{fit} for {f_true}");
    let (b, a) = (
        f[0]["error_before"]["validation"].as_f64().unwrap(),
        f[0]["error_after"]["validation"].as_f64().unwrap(),
    );
    assert!(b >= 3.0 * a, "validation {b} -> {a}");
    let z = accepted(&d, "linear_damping");
    assert_eq!(z.len(), 1, "{d:#}");
    assert_eq!(z[0]["parameters"]["mode"], "1FU");
    let zeta = z[0]["parameters"]["damping_ratio"].as_f64().unwrap();
    assert!((zeta / z_true - 1.0).abs() < 0.2, "{zeta} for {z_true}");
    assert!(
        z[0]["error_after"]["validation"].as_f64().unwrap()
            < z[0]["error_before"]["validation"].as_f64().unwrap()
    );
}
