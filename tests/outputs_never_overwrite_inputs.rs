//! Issue 17, cases 2, 3 and 8 (paths): no command writes an output onto one of its inputs or
//! onto another of its outputs — by path, through a hard link or a symbolic link — and a bad
//! output path is refused before anything runs; a session that fails before it starts leaves
//! an existing log of its name byte for byte as it was (the log is written under a temporary
//! name and moves into place only when the backend has started).

mod cli_support;

use std::path::Path;

use cli_support::{default_rig_with, rigtwin, text, write_plan};

const PLAN: &str = r#"
name = "paths"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 2
settle_periods = 20
record_periods = 20
steps_per_period = 1000

[[test]]
name = "t"
direction = "down"
omega_start = 1.01
omega_end = 0.99
"#;

/// Runs `rigtwin args`, expects it to fail without touching `kept` (whose content is
/// `content`), and returns its output.
fn refused(args: &[&str], kept: &Path, content: &[u8]) -> String {
    let o = rigtwin(args);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {out}");
    assert_eq!(
        std::fs::read(kept).unwrap(),
        content,
        "{args:?} changed {}: {out}",
        kept.display()
    );
    assert!(!out.contains("panicked"), "{out}");
    out
}

/// The files of `dir` (names), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn an_output_on_an_input_is_refused_by_path_and_by_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).display().to_string();
    let log = dir.path().join("s.mcap");
    let content = b"\x89MCAP0\r\n a session log stand-in".to_vec();
    std::fs::write(&log, &content).unwrap();
    let plan = write_plan(dir.path(), PLAN);
    let plan_text = std::fs::read(&plan).unwrap();

    // The issue's examples.
    let out = refused(
        &["replay", &d("s.mcap"), "--json", &d("s.mcap")],
        &log,
        &content,
    );
    assert!(
        out.contains("--json") && out.contains("FILE") && out.contains("s.mcap"),
        "{out}"
    );
    let out = refused(
        &[
            "run",
            "--plan",
            &plan,
            "--out",
            &d("s.mcap"),
            "--json",
            &d("s.mcap"),
        ],
        &log,
        &content,
    );
    assert!(out.contains("--json") && out.contains("--out"), "{out}");
    let out = refused(
        &["run", "--plan", &plan, "--out", &plan],
        Path::new(&plan),
        &plan_text,
    );
    assert!(out.contains("--out") && out.contains("--plan"), "{out}");
    // A hard link: `ln -f s.mcap b.mcap; replay b.mcap --twin --out s.mcap`.
    std::fs::hard_link(&log, dir.path().join("b.mcap")).unwrap();
    let out = refused(
        &["replay", &d("b.mcap"), "--twin", "--out", &d("s.mcap")],
        &log,
        &content,
    );
    assert!(out.contains("same file"), "{out}");
    // A symbolic link, and the same path spelled differently.
    std::os::unix::fs::symlink(&log, dir.path().join("l.mcap")).unwrap();
    refused(
        &["replay", &d("l.mcap"), "--json", &d("s.mcap")],
        &log,
        &content,
    );
    let dotted = format!("{}/./s.mcap", dir.path().display());
    refused(&["replay", &d("s.mcap"), "--json", &dotted], &log, &content);
    // Every other command with an input and an output.
    refused(
        &["report", &d("s.mcap"), "--out", &d("s.mcap")],
        &log,
        &content,
    );
    refused(
        &["rom", "info", &d("s.mcap"), "--json", &d("s.mcap")],
        &log,
        &content,
    );
    refused(
        &[
            "diagnose",
            &d("s.mcap"),
            "--json",
            &d("s.mcap"),
            "--out",
            &d("fig"),
        ],
        &log,
        &content,
    );
    refused(
        &[
            "diagnose",
            &d("s.mcap"),
            "--json",
            &d("d.json"),
            "--out",
            &d("fig"),
            "--write-config",
            &d("s.mcap"),
        ],
        &log,
        &content,
    );
    refused(
        &["simulate", "--plan", &plan, "--json", &plan],
        Path::new(&plan),
        &plan_text,
    );
    refused(
        &[
            "simulate",
            "--rom",
            &d("s.mcap"),
            "--plan",
            &plan,
            "--json",
            &d("b.mcap"),
        ],
        &log,
        &content,
    );
    refused(
        &["rom", "build", &plan, "--out", &d("r.rom"), "--json", &plan],
        Path::new(&plan),
        &plan_text,
    );
    refused(
        &[
            "rom",
            "build",
            "--out",
            &d("s.mcap"),
            "--json",
            &d("b.mcap"),
        ],
        &log,
        &content,
    );
    refused(
        &[
            "simulate",
            "convergence",
            "--kind",
            "dt",
            "--rom",
            &d("s.mcap"),
            "--json",
            &d("l.mcap"),
        ],
        &log,
        &content,
    );
    // A figures folder holding an input it would overwrite.
    let figs = dir.path().join("figs");
    std::fs::create_dir(&figs).unwrap();
    let png = figs.join("rms_response.png");
    std::fs::write(&png, b"png").unwrap();
    refused(
        &[
            "simulate",
            "--rom",
            &png.display().to_string(),
            "--plan",
            &plan,
            "--figures",
            &d("figs"),
        ],
        &png,
        b"png",
    );
    assert_eq!(
        listing(dir.path()),
        ["b.mcap", "figs", "l.mcap", "plan.toml", "s.mcap"]
    );
}

/// Case 8: an output that cannot be written is found before the run or simulation, not after.
#[test]
fn an_unwritable_output_is_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let plan = write_plan(dir.path(), PLAN);
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let under_file = file.join("out.json").display().to_string();
    let t0 = std::time::Instant::now();
    for args in [
        vec!["simulate", "--plan", &plan, "--json", &under_file],
        vec!["simulate", "--plan", &plan, "--figures", &under_file],
        vec!["run", "--plan", &plan, "--out", &under_file],
        vec![
            "run",
            "--plan",
            &plan,
            "--out",
            dir.path().join("s.mcap").to_str().unwrap(),
            "--json",
            &under_file,
        ],
    ] {
        let o = rigtwin(&args);
        let out = text(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {out}");
        assert!(out.contains("not a folder"), "{args:?}: {out}");
    }
    let folder = dir.path().display().to_string();
    let o = rigtwin(&["simulate", "--plan", &plan, "--json", &folder]);
    assert!(text(&o).contains("is a folder"), "{}", text(&o));
    assert!(
        t0.elapsed().as_secs() < 20,
        "the checks ran the simulation first"
    );
    assert_eq!(listing(dir.path()), ["file", "plan.toml"]);
}

/// Case 3, the issue's reproduction: a rig description the twin refuses (`[twin]
/// steps_per_sample = 1`, below the stability bound) with `--twin`, against an existing log:
/// exit 1 and the old log byte for byte as it was, no temporary file left behind.
#[test]
fn a_session_that_fails_to_start_leaves_the_existing_log_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let rig = default_rig_with(dir.path(), "[twin]\nsteps_per_sample = 1\n");
    let plan = write_plan(dir.path(), PLAN);
    let log = dir.path().join("s.mcap");
    let content = b"\x89MCAP0\r\n the previous session".to_vec();
    std::fs::write(&log, &content).unwrap();
    let json = dir.path().join("s.json");
    std::fs::write(&json, b"{}").unwrap();
    let out = refused(
        &[
            "run",
            rig.to_str().unwrap(),
            "--plan",
            &plan,
            "--twin",
            "--quiet",
            "--out",
            log.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ],
        &log,
        &content,
    );
    assert!(out.contains("steps_per_sample"), "{out}");
    assert_eq!(std::fs::read(&json).unwrap(), b"{}");
    assert_eq!(
        listing(dir.path()),
        ["plan.toml", "rig.toml", "s.json", "s.mcap"]
    );
}

/// Issue 18, item 3: every `--out`, `--json` and `--figures` creates its missing folders, as a
/// fresh clone in CI meets them (`run --out new/dir/s.mcap` and `fe export-calculix --out
/// new/dir` used to fail), and an OS error's text is said once.
#[test]
fn missing_output_folders_are_created() {
    let dir = tempfile::tempdir().unwrap();
    let plan = write_plan(
        dir.path(),
        &PLAN
            .replace("steps = 2", "steps = 1")
            .replace("omega_start = 1.01", "omega_start = 0.99"),
    );
    let new = |rest: &str| dir.path().join("new").join(rest);
    let mcap = new("run/s.mcap");
    let json = new("run-json/deep/s.json");
    let o = rigtwin(&[
        "run",
        "--plan",
        &plan,
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(mcap.is_file() && json.is_file());
    let decks = new("calculix/dir");
    let o = rigtwin(&["fe", "export-calculix", "--out", decks.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(decks.join("rig.inp").is_file(), "{}", text(&o));
    let figures = new("report/figures");
    let o = rigtwin(&[
        "report",
        mcap.to_str().unwrap(),
        "--out",
        figures.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(figures.is_dir());
    // An OS error is said once.
    let missing = dir.path().join("missing.mcap");
    let o = rigtwin(&["replay", missing.to_str().unwrap()]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert_eq!(out.matches("(os error 2)").count(), 1, "{out}");
}
