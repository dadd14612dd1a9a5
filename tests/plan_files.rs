//! Guards the test plans shipped in `rig-config/plans/`: the reference's Table 2, the demo
//! plan and the held-contact plan parse to the expected tests and step frequencies.

use std::path::PathBuf;

use rigtwin::plan::{Direction, Plan};

fn plan(name: &str) -> Plan {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("rig-config/plans")
        .join(name);
    match Plan::from_path(&path) {
        Ok(p) => p,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn paper_table2_holds_the_four_reference_tests_in_order() {
    let p = plan("paper-table2.toml");
    assert_eq!(p.name.as_deref(), Some("paper-table2"));
    // Reference Table 2: (level / l, direction, clearance / l).
    let expected = [
        (2.0e-5, Direction::Down, 2.33e-3),
        (2.0e-5, Direction::Up, 2.33e-3),
        (6.0e-5, Direction::Up, 2.41e-3),
        (6.0e-5, Direction::Down, 2.78e-3),
    ];
    assert_eq!(p.tests.len(), expected.len());
    for (t, (level, direction, clearance)) in p.tests.iter().zip(expected) {
        assert_eq!(t.level, level, "{}", t.name);
        assert_eq!(t.direction, direction, "{}", t.name);
        assert_eq!(t.clearance, clearance, "{}", t.name);
        assert_eq!(t.steps, 41, "{}", t.name);
        assert_eq!(
            (t.settle_periods, t.record_periods),
            (200, 200),
            "{}",
            t.name
        );
        assert_eq!(t.steps_per_period, 1000, "{}", t.name);
        let w = t.omega_ratios();
        assert_eq!(w.len(), 41);
        let (first, last) = match direction {
            Direction::Up => (0.94, 1.06),
            Direction::Down => (1.06, 0.94),
        };
        assert_eq!((w[0], w[40]), (first, last), "{}", t.name);
        for pair in w.windows(2) {
            let step = (pair[1] - pair[0]).abs();
            assert!((step - 0.003).abs() < 1e-12, "{}: step {step}", t.name);
            assert_eq!(pair[1] > pair[0], direction == Direction::Up, "{}", t.name);
        }
        // Omega = omega_2 is one of the steps (the reference's detailed analysis).
        assert!(w.iter().any(|x| (x - 1.0).abs() < 1e-12), "{}", t.name);
    }
}

#[test]
fn demo_is_a_short_down_up_pair_at_the_high_level() {
    let p = plan("demo.toml");
    assert_eq!(p.tests.len(), 2);
    let (down, up) = (&p.tests[0], &p.tests[1]);
    assert_eq!(
        (down.direction, up.direction),
        (Direction::Down, Direction::Up)
    );
    for t in [down, up] {
        assert_eq!(t.level, 6.0e-5);
        assert_eq!(t.clearance, 2.78e-3);
        assert_eq!(t.steps, 13);
        assert_eq!((t.settle_periods, t.record_periods), (100, 100));
    }
    let wd = down.omega_ratios();
    let mut wu = up.omega_ratios();
    assert_eq!((wd[0], wd[12]), (1.06, 0.94));
    wu.reverse();
    for (a, b) in wd.iter().zip(&wu) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
    assert_eq!(p.test("high-up"), Some(up));
}

#[test]
fn held_contact_plan_has_touching_small_clearance_and_preload_tests() {
    let p = plan("held-contact.toml");
    let got: Vec<(&str, f64, u32)> = p
        .tests
        .iter()
        .map(|t| (t.name.as_str(), t.clearance, t.steps))
        .collect();
    assert_eq!(
        got,
        vec![
            ("touching", 0.0, 5),
            ("small-clearance", 1e-5, 5),
            ("preload", -1e-5, 3)
        ]
    );
    for t in &p.tests {
        assert_eq!(t.level, 0.5e-5);
        assert_eq!(t.direction, Direction::Up);
        assert_eq!(t.omega_start, 0.98);
    }
}
