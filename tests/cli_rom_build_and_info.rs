//! Guards the `rigtwin rom build|info` and `fe export-calculix` commands end to end on a
//! coarse rig: the ROM file round-trips, the info JSON has the documented keys, and bad input
//! (a broken rig description, a file that is not a ROM) fails with a message naming the file
//! and the key instead of a panic.

use std::path::{Path, PathBuf};
use std::process::Command;

fn rigtwin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rigtwin"))
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("sim-fixtures")
        .join(name)
}

#[test]
fn build_then_info_writes_the_documented_json() {
    let dir = tempfile::tempdir().unwrap();
    let rom = dir.path().join("small.rom");
    let json = dir.path().join("build.json");
    let out = rigtwin()
        .args(["rom", "build", "--quiet", "--out"])
        .arg(&rom)
        .arg("--json")
        .arg(&json)
        .arg(fixture("small-rig.toml"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rom build failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The console says where the ROM came from (issue 18, item 4): built now, or read.
    assert!(String::from_utf8_lossy(&out.stdout).contains(", built in "));
    let info_json = dir.path().join("info.json");
    let out = rigtwin()
        .args(["rom", "info"])
        .arg(&rom)
        .arg("--json")
        .arg(&info_json)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rom info failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("read from the file (its build took") && !said.contains(", built in "),
        "{said}"
    );
    // The same file in the ROM cache: "loaded from the cache".
    let cache = dir.path().join("cache");
    std::fs::create_dir(&cache).unwrap();
    std::fs::copy(&rom, cache.join("small.rom")).unwrap();
    let out = rigtwin()
        .env("RIGTWIN_CACHE", &cache)
        .args(["rom", "info"])
        .arg(cache.join("small.rom"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("loaded from the cache"), "{said}");
    // A ROM with too few modes: `simulate` warns before it starts that impacts will be slow;
    // with the coarse rig's own modes it does not.
    let few = dir.path().join("few.rom");
    let out = rigtwin()
        .args(["rom", "build", "--quiet", "--modes", "2", "--out"])
        .arg(&few)
        .arg(fixture("small-rig.toml"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let plan = dir.path().join("dwell.toml");
    std::fs::write(
        &plan,
        "[[test]]\nname = \"d\"\nlevel = 6e-5\nclearance = 2.78e-3\ndirection = \"up\"\n\
         omega_start = 1.0\nomega_end = 1.0\nsteps = 1\nsettle_periods = 1\nrecord_periods = 1\n",
    )
    .unwrap();
    for (file, warns) in [(&few, true), (&rom, false)] {
        let out = rigtwin()
            .args(["simulate", "--quiet", "--rom"])
            .arg(file)
            .arg("--plan")
            .arg(&plan)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            err.contains("warning: the ROM keeps 2 modes") && err.contains("slow"),
            warns,
            "{}: {err}",
            file.display()
        );
    }
    // Into a pipe whose reader is gone (`rigtwin rom info FILE | true`; the reader closes
    // before the ROM is read and anything printed): ends quietly, no panic message.
    let mut child = rigtwin()
        .args(["rom", "info"])
        .arg(&rom)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    let built: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&info_json).unwrap()).unwrap();
    assert_eq!(
        built, info,
        "info of the written file equals what the build reported"
    );
    for key in [
        "n_dof",
        "n_modes",
        "n_contact_pairs",
        "frequencies_hz",
        "labels",
        "build_seconds",
        "max_eigen_residual",
        "static_flexibility_error",
        "stable_steps_per_period_open",
        "stable_steps_per_period_closed",
    ] {
        assert!(info.get(key).is_some(), "info JSON lacks `{key}`");
    }
    assert_eq!(info["n_modes"], 40);
    assert_eq!(info["n_contact_pairs"], 20);
    let f: Vec<f64> = serde_json::from_value(info["frequencies_hz"].clone()).unwrap();
    assert!(f.windows(2).all(|w| w[0] <= w[1]), "frequencies ascending");
    assert!(info["max_eigen_residual"].as_f64().unwrap() < 1e-6);
    assert!(info["static_flexibility_error"].as_f64().unwrap() < 1e-8);
    let open = info["stable_steps_per_period_open"].as_f64().unwrap();
    let closed = info["stable_steps_per_period_closed"].as_f64().unwrap();
    assert!(
        open > 0.0 && closed >= open,
        "closed contact bound is the tighter one: open {open}, closed {closed}"
    );
}

#[test]
fn a_broken_rig_description_names_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("small-rig.toml")).unwrap();
    let bad = text.replacen("thickness = 0.006", "thickness = -0.006", 1);
    assert_ne!(bad, text);
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, bad).unwrap();
    let out = rigtwin()
        .args(["rom", "build", "--quiet", "--out"])
        .arg(dir.path().join("x.rom"))
        .arg(&cfg)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.toml"), "names the file: {err}");
    assert!(err.contains("thickness"), "names the key: {err}");
    assert!(!err.contains("panicked"), "no panic: {err}");
    assert!(
        !dir.path().join("x.rom").exists(),
        "no ROM written on error"
    );
}

#[test]
fn info_on_a_file_that_is_not_a_rom_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("notes.rom");
    std::fs::write(&f, "hello").unwrap();
    let out = rigtwin().args(["rom", "info"]).arg(&f).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("notes.rom") && err.contains("not a rigtwin ROM"),
        "{err}"
    );
}

#[test]
fn export_calculix_writes_both_decks() {
    let dir = tempfile::tempdir().unwrap();
    let out = rigtwin()
        .args(["fe", "export-calculix"])
        .arg(fixture("small-rig.toml"))
        .arg("--out")
        .arg(dir.path())
        .args(["--job", "small"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let deck = std::fs::read_to_string(dir.path().join("small.inp")).unwrap();
    let matrix = std::fs::read_to_string(dir.path().join("small_matrix.inp")).unwrap();
    assert!(deck.to_uppercase().contains("*FREQUENCY"));
    assert!(matrix.to_uppercase().contains("SOLVER=MATRIXSTORAGE"));
    assert!(deck.contains("CONTACT_LOWER") && deck.contains("C3D8I"));
}
