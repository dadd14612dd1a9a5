//! Guards the plan error messages: every bad input is rejected with a message naming the
//! file, where in it (test number and name, `[defaults]`, or line:column) and the key, with
//! what was expected.

use rigtwin::plan::{Direction, Plan, PlanError, PlanLocation};

/// A valid two-test plan; the cases below change one thing in it.
const GOOD: &str = r#"
name = "good"

[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 13
settle_periods = 30
record_periods = 20

[[test]]
name = "down"
direction = "down"
omega_start = 1.06
omega_end = 0.94

[[test]]
name = "up"
direction = "up"
omega_start = 0.94
omega_end = 1.06
"#;

fn parse(text: &str) -> Result<Plan, PlanError> {
    Plan::from_str(text, "bad.toml")
}

/// Replaces the first occurrence of `from` (which must exist) by `to`.
fn edit(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "{from:?} not in the good plan");
    GOOD.replacen(from, to, 1)
}

/// Replaces `from` inside the second test only.
fn edit_second(from: &str, to: &str) -> String {
    let at = GOOD.rfind("[[test]]").unwrap();
    let (head, tail) = GOOD.split_at(at);
    assert!(tail.contains(from), "{from:?} not in the second test");
    format!("{head}{}", tail.replacen(from, to, 1))
}

#[test]
fn the_good_plan_parses() {
    let p = parse(GOOD).unwrap();
    assert_eq!(p.tests.len(), 2);
    assert_eq!(p.tests[0].steps_per_period, 1000, "built-in default");
    assert_eq!(p.tests[1].direction, Direction::Up);
    assert_eq!(p.source, "bad.toml");
    p.validate().unwrap();
}

/// (what, text, key, location, fragments the message must contain)
type Case = (
    &'static str,
    String,
    &'static str,
    PlanLocation,
    Vec<&'static str>,
);

fn test2() -> PlanLocation {
    PlanLocation::Test {
        index: 1,
        name: Some("up".into()),
    }
}

fn cases() -> Vec<Case> {
    vec![
        (
            "zero settle periods",
            edit("settle_periods = 30", "settle_periods = 0"),
            "settle_periods",
            PlanLocation::Defaults,
            vec!["[defaults]", "= 0", ">= 1"],
        ),
        (
            "negative record periods in a test",
            edit_second("name = \"up\"", "name = \"up\"\nrecord_periods = -5"),
            "record_periods",
            test2(),
            vec!["test 2 \"up\"", "= -5", ">= 1"],
        ),
        (
            "zero steps",
            edit_second("name = \"up\"", "name = \"up\"\nsteps = 0"),
            "steps",
            test2(),
            vec!["test 2 \"up\"", "frequency steps", ">= 1"],
        ),
        (
            "zero steps per period",
            edit("steps = 13", "steps = 13\nsteps_per_period = 0"),
            "steps_per_period",
            PlanLocation::Defaults,
            vec![">= 1"],
        ),
        (
            "record periods beyond the memory guard (issue 17: 4e9 aborted the session)",
            edit_second(
                "name = \"up\"",
                "name = \"up\"\nrecord_periods = 4000000000",
            ),
            "record_periods",
            test2(),
            vec!["test 2 \"up\"", "= 4000000000", "<= 100000"],
        ),
        (
            "frequency steps beyond the guard (issue 17: 1e8 aborted simulate)",
            edit("steps = 13", "steps = 100000000"),
            "steps",
            PlanLocation::Defaults,
            vec!["= 100000000", "<= 10000"],
        ),
        (
            "a simulated record window too large for memory",
            edit("steps = 13", "steps = 13\nsteps_per_period = 10000000"),
            "steps_per_period",
            PlanLocation::Defaults,
            vec!["record_periods x steps_per_period <= 1e8", "= 2e8"],
        ),
        (
            "negative level",
            edit("level = 6.0e-5", "level = -6.0e-5"),
            "level",
            PlanLocation::Defaults,
            vec!["-0.00006", "(0, 1e-2]"],
        ),
        (
            "zero level in a test",
            edit_second("name = \"up\"", "name = \"up\"\nlevel = 0.0"),
            "level",
            test2(),
            vec!["test 2 \"up\"", "= 0"],
        ),
        (
            "omega above 10",
            edit_second("omega_end = 1.06", "omega_end = 12.0"),
            "omega_end",
            test2(),
            vec!["= 12", "(0, 10)"],
        ),
        (
            "zero omega",
            edit("omega_end = 0.94", "omega_end = 0.0"),
            "omega_end",
            PlanLocation::Test {
                index: 0,
                name: Some("down".into()),
            },
            vec!["test 1 \"down\"", "(0, 10)"],
        ),
        (
            "unknown direction",
            edit_second("direction = \"up\"", "direction = \"sideways\""),
            "direction",
            test2(),
            vec!["\"sideways\"", "\"up\"", "\"down\""],
        ),
        (
            "direction against the frequencies",
            edit_second("direction = \"up\"", "direction = \"down\""),
            "direction",
            test2(),
            vec![
                "omega_start > omega_end",
                "omega_start = 0.94",
                "omega_end = 1.06",
            ],
        ),
        (
            "misspelled key",
            edit_second("direction = \"up\"", "direction = \"up\"\nlevle = 2e-5"),
            "levle",
            test2(),
            vec![
                "bad.toml:20:1",
                "unknown key",
                "`level`",
                "`settle_periods`",
            ],
        ),
        (
            "misspelled default",
            edit("steps = 13", "stpes = 13"),
            "stpes",
            PlanLocation::Defaults,
            vec!["bad.toml:7:1", "unknown key", "`steps`"],
        ),
        (
            "misspelled table",
            GOOD.replace("[[test]]", "[[tests]]"),
            "tests",
            PlanLocation::Plan,
            vec!["unknown key", "`test`"],
        ),
        (
            "fractional step count",
            edit("steps = 13", "steps = 13.5"),
            "steps",
            PlanLocation::Defaults,
            vec!["bad.toml:7:1", "integer"],
        ),
        (
            "missing clearance",
            edit("clearance = 2.78e-3\n", ""),
            "clearance",
            PlanLocation::Test {
                index: 0,
                name: Some("down".into()),
            },
            vec!["missing", "[defaults]", "clearance / l"],
        ),
        (
            "missing name",
            edit_second("name = \"up\"\n", ""),
            "name",
            PlanLocation::Test {
                index: 1,
                name: None,
            },
            vec!["test 2:", "missing"],
        ),
        (
            "duplicate name",
            edit_second("name = \"up\"", "name = \"down\""),
            "name",
            PlanLocation::Test {
                index: 1,
                name: Some("down".into()),
            },
            vec!["test 1 already"],
        ),
        (
            "default name",
            edit("level = 6.0e-5", "name = \"x\"\nlevel = 6.0e-5"),
            "name",
            PlanLocation::Defaults,
            vec!["each [[test]] names itself"],
        ),
        (
            "single step that is not a dwell",
            edit("steps = 13", "steps = 1"),
            "direction",
            PlanLocation::Test {
                index: 0,
                name: Some("down".into()),
            },
            vec!["single step"],
        ),
    ]
}

#[test]
fn each_bad_value_names_file_location_and_key() {
    for (what, text, key, location, fragments) in cases() {
        let err = match parse(&text) {
            Ok(_) => panic!("{what}: accepted"),
            Err(e) => e,
        };
        let msg = err.to_string();
        assert_eq!(err.key(), Some(key), "{what}: {msg}");
        assert_eq!(err.location(), Some(&location), "{what}: {msg}");
        assert!(msg.starts_with("bad.toml"), "{what}: {msg}");
        assert!(msg.contains(&format!("`{key}`")), "{what}: {msg}");
        for f in fragments {
            assert!(msg.contains(f), "{what}: {msg:?} lacks {f:?}");
        }
    }
}

#[test]
fn syntax_error_gives_line_and_column() {
    let text = edit("steps = 13", "steps = = 13");
    let err = parse(&text).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, PlanError::Syntax { line: 7, .. }), "{msg}");
    assert!(msg.starts_with("bad.toml:7:"), "{msg}");
    assert!(msg.contains("TOML syntax error"), "{msg}");
}

#[test]
fn a_plan_without_tests_is_rejected() {
    let text = GOOD.split("[[test]]").next().unwrap();
    let msg = parse(text).unwrap_err().to_string();
    assert!(
        msg.contains("bad.toml") && msg.contains("no [[test]]"),
        "{msg}"
    );
}

#[test]
fn missing_file_names_the_file() {
    let err = Plan::from_path(std::path::Path::new("/nonexistent/plan.toml")).unwrap_err();
    assert!(matches!(err, PlanError::Io { .. }));
    assert!(err.to_string().contains("/nonexistent/plan.toml"), "{err}");
}

#[test]
fn validate_rechecks_a_plan_built_in_code() {
    let mut p = parse(GOOD).unwrap();
    p.tests[1].record_periods = 0;
    let err = p.validate().unwrap_err();
    assert_eq!(err.key(), Some("record_periods"), "{err}");
    assert!(err.to_string().contains("test 2 \"up\""), "{err}");
    let mut p = parse(GOOD).unwrap();
    p.tests[0].record_periods = 4_000_000_000;
    let err = p.validate().unwrap_err();
    assert_eq!(err.key(), Some("record_periods"), "{err}");
    assert!(err.to_string().contains("<= 100000"), "{err}");
    let mut p = parse(GOOD).unwrap();
    p.tests[0].direction = Direction::Up;
    assert_eq!(p.validate().unwrap_err().key(), Some("direction"));
}

#[test]
fn touching_and_small_preload_clearances_are_accepted_larger_overlaps_are_not() {
    // Issue 16: held contact runs as a session: the probes touching (0) and a bounded
    // pre-load (negative, at most 1e-4 l) are valid clearances.
    for ok in ["0.0", "-5.0e-6", "-1.0e-4", "0.1"] {
        let plan = parse(&edit("clearance = 2.78e-3", &format!("clearance = {ok}")))
            .unwrap_or_else(|e| panic!("clearance {ok}: {e}"));
        assert_eq!(plan.tests[0].clearance, ok.parse::<f64>().unwrap());
    }
    for bad in ["-1.1e-4", "-0.01", "0.11", "nan"] {
        let err = parse(&edit("clearance = 2.78e-3", &format!("clearance = {bad}")))
            .expect_err(bad)
            .to_string();
        assert!(
            err.contains("clearance") && err.contains("pre-load") && err.contains("bad.toml"),
            "{bad}: {err}"
        );
    }
}
