//! The diagnosis' model runs started from a captured state of open contact
//! (`ModelRunner::capture_open`, `Span`): the clearance and tilt fits run many contact
//! geometries over the same steps, and the steps before the first contact are the same for
//! all of them. Guards, on a session of the simulated rig sweeping down into the impact band:
//! - a run of a test's steps from a state captured two steps before the first contact, with
//!   a clearance no smaller than the capture's, compares exactly (bit for bit) what a run of
//!   the same steps from rest compares, for less rig time;
//! - a geometry closer than the capture's (a smaller clearance, or a tilt whose edge closes
//!   below it) is run from rest instead, with the same results as without any capture;
//! - a capture during which a pair closed is not kept;
//! - runs made side by side on two threads (`ModelRunner::run_many`, a fit's grid) give what
//!   the same runs one after the other give;
//! - a run with wear starts a test worn as a run from the session's start at the step asked
//!   left it (`ModelRunner::set_wear_from`);
//! - an ensemble member's run (`ModelRunner::run_members`, the judge's draws in the band)
//!   differs from the plain run only from the first step with contact, and draws the same
//!   perturbations whatever it runs beside.

mod cli_support;
mod default_rom;
mod diagnose_support;

use std::path::PathBuf;
use std::sync::OnceLock;

use diagnose_support::{process_dir, sim_session};
use rigtwin::config::{ClearanceSpec, PhysicsSpec, RigConfig, TiltSpec, WearSpec};
use rigtwin::diagnose::rerun::{MemberRun, ModelRunner, SessionSteps, Span};
use rigtwin::session::replay::{replay, Replay};
use rigtwin::twin::TwinModel;

/// 2e-5 l down from 1.03 omega_2 in 0.01 steps into the band: the first steps impact-free.
const PLAN: &str = r#"
name = "open-starts"
[defaults]
clearance = 2.33e-3
settle_periods = 40
record_periods = 30
steps_per_period = 1000

[[test]]
name = "down"
level = 2e-5
direction = "down"
omega_start = 1.03
omega_end = 0.98
steps = 6
"#;

/// The log of `PLAN` on the simulated rig, recorded once per process for the tests that
/// replay it ([`process_dir`]).
fn down_session() -> &'static PathBuf {
    static SESSION: OnceLock<PathBuf> = OnceLock::new();
    SESSION.get_or_init(|| {
        let dir = process_dir("diagnose_open_starts-down");
        sim_session(&dir, "down", "[safety]\ndaq_timeout_s = 30\n", PLAN).0
    })
}

/// A runner of the default rig's model over `r` on `jobs` threads.
fn runner_of<'a>(
    r: &'a Replay,
    steps: &'a SessionSteps,
    cfg: &'a RigConfig,
    jobs: usize,
) -> ModelRunner<'a> {
    ModelRunner::new(
        &r.recording,
        steps,
        TwinModel::of_config(default_rom::default_rom(), cfg),
        &cfg.twin,
        cfg.rig.beam_length,
        jobs,
    )
}

fn offset(o: f64) -> PhysicsSpec {
    PhysicsSpec {
        clearance: Some(ClearanceSpec {
            offset: o,
            tests: Vec::new(),
        }),
        ..PhysicsSpec::default()
    }
}

#[test]
fn runs_from_an_open_state_compare_what_runs_from_rest_do() {
    let r = replay(down_session()).unwrap();
    let cfg = RigConfig::default_rig();
    let steps = SessionSteps::of(&r.recording, &r.summary);
    let runner = || runner_of(&r, &steps, &cfg, 1);
    let first = steps.first_contact(0).expect("the sweep reaches the band");
    assert!(
        first >= 3,
        "first contact at step {first}: too early for the test"
    );
    let from = first - 2;
    let span = Span::of_test(0, from, Some(first + 1));

    // Captured with a clearance 5e-5 m smaller than the plan's; run with the plan's and a
    // larger one (no closer), and with smaller ones (closer: from rest).
    let closest = offset(-5e-5);
    let mut warm = runner();
    assert!(warm.capture_open(&closest, 0, from).unwrap());
    let capture_cost = warm.cost.rig_seconds;
    let mut cold = runner();
    let tilted = PhysicsSpec {
        tilt: Some(TiltSpec {
            angle: 0.05,
            axis: [0.0, 1.0],
        }),
        ..PhysicsSpec::default()
    };
    let cases = [
        (PhysicsSpec::default(), true),
        (offset(1e-4), true),
        (offset(-5e-5), true),
        (offset(-1e-4), false),
        (tilted, false),
    ];
    let mut sequential = Vec::new();
    for (ext, served) in cases.clone() {
        let (w0, c0) = (warm.cost.rig_seconds, cold.cost.rig_seconds);
        let a = warm.run_spans(&ext, &[span]).unwrap();
        sequential.push(a.clone());
        let b = cold.run_spans(&ext, &[span]).unwrap();
        assert_eq!(a, b, "{ext:?}");
        assert!(a.iter().all(|s| s.step >= from && s.step <= first + 1));
        assert_eq!(a.len(), 4, "{ext:?}");
        assert!(a.iter().all(|s| !s.features.is_empty()), "{ext:?}");
        let (dw, dc) = (warm.cost.rig_seconds - w0, cold.cost.rig_seconds - c0);
        if served {
            assert!(
                dw < 0.75 * dc,
                "{ext:?}: {dw} s from the state, {dc} s from rest"
            );
        } else {
            assert_eq!(dw, dc, "{ext:?}: run from rest");
        }
    }
    assert!(capture_cost > 0.0);

    // The same runs side by side on two threads (a fit's grid, `ModelRunner::run_many`):
    // the same results, in order.
    let mut side_by_side = runner_of(&r, &steps, &cfg, 2);
    assert!(side_by_side.capture_open(&closest, 0, from).unwrap());
    let runs: Vec<(PhysicsSpec, Vec<Span>)> = cases
        .iter()
        .map(|(ext, _)| (ext.clone(), vec![span]))
        .collect();
    assert_eq!(side_by_side.run_many(&runs).unwrap(), sequential);

    // A clearance so small that the probes touch before the capture's step: not kept.
    let mut touching = runner();
    assert!(!touching.capture_open(&offset(-6.5e-4), 0, from).unwrap());
}

/// After [`PLAN`]'s test into the band: a rest at a low level far below the resonance, and
/// into the band again.
const WORN_TESTS: &str = r#"
[[test]]
name = "quiet"
level = 3e-6
direction = "up"
omega_start = 0.90
omega_end = 0.915
steps = 4

[[test]]
name = "again"
level = 2e-5
direction = "down"
omega_start = 1.03
omega_end = 0.99
steps = 3
"#;

/// `ModelRunner::set_wear_from`: a run of a model with wear starts a test from rest at its
/// lead-in, with the clearance and wear a run from the session's start at the step asked had
/// there. The lead-in of `again` (the last three steps of `quiet`) has no contact, so the
/// normal contact impulse at `again`'s start is the run from the start's exactly: at the
/// twin's step and at a 3x finer one from the twin's step's states, and at the finer step
/// from the states of its own run from the session's start (which exchanges its own).
#[test]
fn a_run_with_wear_starts_a_test_worn_as_a_run_at_the_step_asked_left_it() {
    let dir = tempfile::tempdir().unwrap();
    let (log, _) = sim_session(
        dir.path(),
        "worn",
        "[safety]\ndaq_timeout_s = 30\n",
        &format!("{PLAN}{WORN_TESTS}"),
    );
    let r = replay(&log).unwrap();
    let cfg = RigConfig::default_rig();
    let steps = SessionSteps::of(&r.recording, &r.summary);
    let mut runner = runner_of(&r, &steps, &cfg, 1);
    let wear = PhysicsSpec {
        wear: Some(WearSpec {
            coefficient: 2e-5,
            max_growth: None,
        }),
        ..PhysicsSpec::default()
    };
    let from_start = runner.contact_impulse(&wear, (2, 0)).unwrap();
    let whole = runner.cost.rig_seconds;
    let p = from_start.at_test_start[2].expect("the impulse at the start of `again`");
    assert!(p > 0.0, "no contact in `down`");
    assert_eq!(
        from_start.at_test_start[1], from_start.at_test_start[2],
        "contact in `quiet`"
    );
    // At the record windows: growing through `down`'s contact, within what it exchanges;
    // `quiet`'s all `again`'s start; `again` read through its first step only.
    let at = |t: usize| -> Vec<f64> {
        (from_start.at_record.range((t, 0)..(t + 1, 0)))
            .map(|(_, p)| *p)
            .collect()
    };
    let down = at(0);
    assert!(!down.is_empty());
    assert!(down.windows(2).all(|w| w[0] <= w[1]), "{down:?}");
    assert!(down[0] >= 0.0 && down[down.len() - 1] <= p, "{down:?}, {p}");
    assert!(
        down[0] < down[down.len() - 1],
        "no contact within `down`: {down:?}"
    );
    assert!(at(1).iter().all(|&q| q == p), "{:?}", at(1));
    assert_eq!(at(2), vec![p]);
    let mean = from_start.over_records(0, 0, 99).unwrap();
    assert!(mean > down[0] && mean < down[down.len() - 1], "{mean}");

    // From the states a run at refinement `r` left, `again` starts as that run had it
    // (`expected` N s), for less than half the rig time of the run from the start (`whole`).
    let from_states = |runner: &mut ModelRunner<'_>, r: u32, expected: f64, whole: f64| {
        runner.set_wear_from(Some(r));
        let c = runner.cost.rig_seconds;
        let worn = runner.contact_impulse(&wear, (2, 0)).unwrap();
        assert_eq!(
            worn.at_test_start[2],
            Some(expected),
            "from the states at x{r}"
        );
        let short = runner.cost.rig_seconds - c;
        assert!(
            short < 0.5 * whole,
            "from the states at x{r}: {short} s of rig time, {whole} s from the start"
        );
    };
    from_states(&mut runner, 1, p, whole);

    runner.set_refinement(3);
    let fine_worn = runner.contact_impulse(&wear, (2, 0)).unwrap();
    assert_eq!(fine_worn.at_test_start[2], Some(p));
    let fine_scores = runner.run_spans(&wear, &[Span::whole(2)]).unwrap();
    assert_eq!(fine_scores.len(), 3);
    assert!(fine_scores.iter().all(|s| !s.features.is_empty()));
    runner.set_wear_from(None);
    let c0 = runner.cost.rig_seconds;
    let fine_from_start = runner.contact_impulse(&wear, (2, 0)).unwrap();
    let fine_whole = runner.cost.rig_seconds - c0;
    let q = fine_from_start.at_test_start[2].expect("the impulse at the start of `again`");
    assert!(
        q > 0.0 && q != p,
        "{q} N s at the finer step, {p} N s at the twin's"
    );

    // That run left the finer step's own states, which runs at that step start from.
    from_states(&mut runner, 3, q, fine_whole);
}

/// `ModelRunner::run_members`: member 0 is the plain run; member m > 0 is perturbed at the
/// start of each step with contact on the rig, so the impact-free steps before the band
/// compare exactly as member 0's and the band's steps do not; the same member gives the same
/// scores alone and beside other runs on two threads (common random numbers), another member
/// other ones.
#[test]
fn ensemble_members_differ_from_the_plain_run_only_in_the_band() {
    let r = replay(down_session()).unwrap();
    let cfg = RigConfig::default_rig();
    let steps = SessionSteps::of(&r.recording, &r.summary);
    let first = steps.first_contact(0).expect("the sweep reaches the band");
    assert!(first >= 2, "first contact at step {first}");
    let mut runner = runner_of(&r, &steps, &cfg, 1);
    let whole = vec![Span::whole(0)];
    let nominal = PhysicsSpec::default();
    let member = |runner: &mut ModelRunner<'_>, m: usize| {
        let run: MemberRun = (nominal.clone(), whole.clone(), m);
        runner.run_members(&[run]).unwrap().pop().unwrap()
    };
    let plain = runner.run_spans(&nominal, &whole).unwrap();
    assert_eq!(member(&mut runner, 0), plain);
    let one = member(&mut runner, 1);
    let two = member(&mut runner, 2);
    assert_eq!(one.len(), plain.len());
    for (k, ((p, a), b)) in plain.iter().zip(&one).zip(&two).enumerate() {
        assert!(!p.features.is_empty() && !a.features.is_empty(), "step {k}");
        if k < first {
            assert_eq!(p, a, "step {k}: before the band");
            assert_eq!(p, b, "step {k}: before the band");
        }
    }
    assert_ne!(
        plain[first..],
        one[first..],
        "member 1 is member 0 in the band"
    );
    assert_ne!(one[first..], two[first..], "members 1 and 2 draw the same");

    let mut side_by_side = runner_of(&r, &steps, &cfg, 2);
    let runs: Vec<MemberRun> = vec![
        (offset(2e-5), whole.clone(), 1),
        (nominal.clone(), whole.clone(), 1),
        (nominal.clone(), whole.clone(), 2),
    ];
    let out = side_by_side.run_members(&runs).unwrap();
    assert_eq!(out[1], one);
    assert_eq!(out[2], two);
}
