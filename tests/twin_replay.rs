//! `rigtwin replay --twin`: the twin re-run on a recorded session's base motion. Guards:
//! - every step gets the twin's metrics and its errors against the measurement
//!   (`tests[].steps[].twin`), the twin following the measurement closely outside the
//!   impact band (same model as the simulated rig's structure, fewer modes);
//! - the same recording and model give the same bits; a changed model changes them;
//! - a bad model argument is a clear error;
//! - the live twin's predicted channels are logged (`/twin/blocks`), a replay's copy of the log
//!   (`--out`) holds the same bytes, and `report` draws them;
//! - warm starts: the twin's state is logged at every step start (`/twin/state`), and
//!   `replay --twin --steps` re-runs a subset of steps from there, bit for bit equal to the
//!   whole run, with every model extension on;
//! - the diagnosis' runs: an ensemble in the windows with contact only
//!   (`EnsembleOptions::contact_windows_only`), and the comparison before the ensemble joins it
//!   (`TwinSink::pointwise`) equal to the run without an ensemble; with an ensemble, a
//!   failing sink stops the replay with its own error.

mod cli_support;
mod default_rom;

use std::path::PathBuf;

use cli_support::{default_rig_with, json, rigtwin, text};
use rigtwin::control::summary::StepInfo;
use rigtwin::session::twin_replay::{replay_twin, EnsembleOptions, TwinReplayError, TwinSink};
use rigtwin::twin::{TwinBlock, TwinComparison, TwinModel};

const PLAN: &str = r#"
name = "twin-replay-test"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 3
settle_periods = 60
record_periods = 30
steps_per_period = 1000

[[test]]
name = "high-down"
direction = "down"
omega_start = 1.08
omega_end = 1.00
"#;

/// A session of [`PLAN`] on the simulated rig, recorded into `dir`; returns the log.
fn record(dir: &std::path::Path) -> PathBuf {
    let plan = dir.join("plan.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let mcap = dir.join("session.mcap");
    let o = rigtwin(&[
        "run",
        "--plan",
        plan.to_str().unwrap(),
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    mcap
}

/// `replay --twin --ensemble 0` of the log `mcap` into `out`, asserted equal to the live
/// twin's summary `live` (the live twin runs no ensemble, issue 14, part 4: its replay without
/// one is its twin); returns the replay's output.
fn assert_replay_equals_live(
    mcap: &std::path::Path,
    live: &std::path::Path,
    out: &std::path::Path,
) -> String {
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--ensemble",
        "0",
        "--json",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        std::fs::read_to_string(live).unwrap(),
        std::fs::read_to_string(out).unwrap(),
        "live twin and replayed twin differ"
    );
    text(&o)
}

#[test]
fn replay_with_the_twin_compares_every_step_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = record(dir.path());

    let replay = |name: &str, extra: &[&str]| -> PathBuf {
        let out = dir.path().join(name);
        let mut args = vec![
            "replay",
            mcap.to_str().unwrap(),
            "--twin",
            "--json",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = rigtwin(&args);
        assert!(o.status.success(), "{}", text(&o));
        assert!(text(&o).contains("3 steps compared"), "{}", text(&o));
        out
    };
    let a = replay("a.json", &[]);
    let b = replay("b.json", &[]);
    assert_eq!(
        std::fs::read_to_string(&a).unwrap(),
        std::fs::read_to_string(&b).unwrap(),
        "the same recording and model give the same bits"
    );
    let s = json(&a);
    let steps = s["tests"][0]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 3);
    for st in steps {
        let w = &st["twin"];
        for key in [
            "rms_upper",
            "rms_lower",
            "amp_min_upper",
            "amp_mean_upper",
            "amp_max_upper",
            "contact_fraction",
            "impacts_per_period",
            "rms_error_upper",
            "rms_error_lower",
            "contact_fraction_error",
            "spectrum_distance_db",
        ] {
            assert!(w[key].as_f64().is_some(), "{key} missing in {w}");
        }
        assert_eq!(w["spectrum_upper"].as_array().unwrap().len(), 20, "{w}");
    }
    // 1.08 and 1.04 omega_2 are outside the impact band: the twin (the rig's own model, fewer
    // modes, driven by the measured base acceleration) follows the upper tip within 2 %.
    // Its spectrum too: the fundamental's band dominates and the level difference over the
    // bands above the noise floor stays within a few dB.
    for st in &steps[..2] {
        assert_eq!(st["contact_fraction"], 0.0, "{st}");
        let e = st["twin"]["rms_error_upper"].as_f64().unwrap();
        assert!(e.abs() < 0.02, "{e} at {}", st["omega_ratio"]);
        let d = st["twin"]["spectrum_distance_db"].as_f64().unwrap();
        assert!(
            (0.0..6.0).contains(&d),
            "spectrum distance {d} dB at {}",
            st["omega_ratio"]
        );
    }

    // The discretisation member ([twin.discretisation], on by default with the ensemble): run
    // in every window with contact, measured or modelled, or right after a measured one, and
    // nowhere else; its difference only widens the model spreads.
    let off = default_rig_with(dir.path(), "[twin.discretisation]\nenabled = false\n");
    let without = json(&replay("off.json", &["--config", off.to_str().unwrap()]));
    let (mut with_member, mut after) = (0, false);
    for (st, bare) in steps
        .iter()
        .zip(without["tests"][0]["steps"].as_array().unwrap())
    {
        let measured = st["contact_fraction"].as_f64().unwrap() > 0.0;
        let contact = measured || st["twin"]["contact_fraction"].as_f64().unwrap() > 0.0;
        let member = st["twin"]["discretisation_member"] == true;
        assert_eq!(member, contact || after, "{}", st["omega_ratio"]);
        after = measured;
        assert!(bare["twin"]["discretisation_member"].is_null(), "{bare}");
        with_member += usize::from(member);
        for (f, g) in st["twin"]["features"]
            .as_array()
            .unwrap()
            .iter()
            .zip(bare["twin"]["features"].as_array().unwrap())
        {
            assert_eq!(
                (&f["channel"], &f["feature"]),
                (&g["channel"], &g["feature"])
            );
            assert_eq!(f["model"], g["model"], "the twin's own values do not move");
            let (a, b) = (
                f["model_spread"].as_f64().unwrap_or(0.0),
                g["model_spread"].as_f64().unwrap_or(0.0),
            );
            assert!(a >= b, "{f} against {g}");
        }
    }
    assert!(
        with_member >= 1,
        "no step with contact: the member was not exercised"
    );

    // A changed model (the twin's time step) changes the twin's output.
    let cfg = default_rig_with(dir.path(), "[twin]\nsteps_per_reference_period = 2000\n");
    let c = replay("c.json", &["--config", cfg.to_str().unwrap()]);
    let sc = json(&c);
    assert_ne!(
        s["tests"][0]["steps"][0]["twin"], sc["tests"][0]["steps"][0]["twin"],
        "another model gives other numbers"
    );
    // The measurement part is the same.
    assert_eq!(
        s["tests"][0]["steps"][0]["rms_upper"],
        sc["tests"][0]["steps"][0]["rms_upper"]
    );

    // Bad model arguments.
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--rom",
        "/nonexistent/twin.rom",
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("--rom /nonexistent/twin.rom"),
        "{}",
        text(&o)
    );
    let o = rigtwin(&["replay", mcap.to_str().unwrap(), "--rom", "x.rom"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--twin"), "{}", text(&o));
}

/// `rigtwin run --twin`: the live twin's comparison equals the replay's, bit for bit, and is
/// logged on its own channels.
#[test]
fn the_live_twin_equals_its_replay_and_is_logged() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, PLAN.replace("steps = 3", "steps = 2")).unwrap();
    let mcap = dir.path().join("session.mcap");
    let live = dir.path().join("live.json");
    let o = rigtwin(&[
        "run",
        "--plan",
        plan.to_str().unwrap(),
        "--quiet",
        "--twin",
        "--out",
        mcap.to_str().unwrap(),
        "--json",
        live.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("2 of 2 steps compared"), "{}", text(&o));
    assert_replay_equals_live(&mcap, &live, &dir.path().join("replay.json"));
    let s = rigtwin::log::read_session(&mcap).unwrap();
    let steps = s
        .decode::<rigtwin::session::topics::TwinStepMessage>(
            rigtwin::session::topics::TOPIC_TWIN_STEPS,
        )
        .unwrap();
    assert_eq!(steps.len(), 2);
    assert!(steps.iter().all(|(_, _, m)| m.twin.is_some()));
    let status = s
        .decode::<rigtwin::twin::TwinStatus>(rigtwin::session::topics::TOPIC_TWIN_STATUS)
        .unwrap();
    assert!(!status.is_empty());

    // The predicted channels of every block are logged, and a replay that writes a copy of the
    // log (`--out`) logs the same bytes: predictions and comparisons alike (without the
    // ensemble the live twin does not run).
    let copy = dir.path().join("copy.mcap");
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--ensemble",
        "0",
        "--out",
        copy.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let c = rigtwin::log::read_session(&copy).unwrap();
    assert!(c.complete);
    let payloads = |s: &rigtwin::log::SessionRead, topic: &str| -> Vec<(u64, Vec<u8>)> {
        s.messages_on(topic)
            .map(|m| (m.log_time, m.data.clone()))
            .collect()
    };
    let blocks = payloads(&s, rigtwin::session::topics::TOPIC_TWIN_BLOCKS);
    assert_eq!(
        blocks.len(),
        s.messages_on(rigtwin::session::topics::TOPIC_DAQ).count(),
        "one twin message per DAQ block"
    );
    assert!(
        blocks == payloads(&c, rigtwin::session::topics::TOPIC_TWIN_BLOCKS),
        "twin blocks differ"
    );
    assert_eq!(
        payloads(&s, rigtwin::session::topics::TOPIC_TWIN_STEPS),
        payloads(&c, rigtwin::session::topics::TOPIC_TWIN_STEPS)
    );
    // The twin's state at every step start (warm starts): the live twin and the replay capture
    // the same states at the same samples.
    let states = payloads(&s, rigtwin::session::topics::TOPIC_TWIN_STATE);
    assert_eq!(
        states.len(),
        1,
        "the second step's start (the first has no block before it)"
    );
    assert!(states == payloads(&c, rigtwin::session::topics::TOPIC_TWIN_STATE));
    // The rest of the session is copied as it was; the copy names its model.
    for topic in [
        rigtwin::session::topics::TOPIC_DAQ,
        rigtwin::session::topics::TOPIC_EVENTS,
        rigtwin::session::topics::TOPIC_STEPS,
    ] {
        assert!(
            payloads(&s, topic) == payloads(&c, topic),
            "{topic} differs"
        );
    }
    assert!(c
        .messages_on(rigtwin::session::topics::TOPIC_TWIN_STATUS)
        .next()
        .is_none());
    assert!(c
        .metadata(rigtwin::session::topics::TWIN_REPLAY_METADATA)
        .unwrap()["model"]
        .contains("the rig description in the log"));
    let samples = s
        .decode::<rigtwin::twin::TwinSamples>(rigtwin::session::topics::TOPIC_TWIN_BLOCKS)
        .unwrap();
    let b = &samples[samples.len() / 2].2;
    assert_eq!(b.upper_tip.len(), b.len);
    assert!(b.upper_tip.iter().any(|v| *v != 0.0));

    // The report draws the twin beside the measurement in the time-domain figures too.
    let figures = dir.path().join("figures");
    let o = rigtwin(&[
        "report",
        copy.to_str().unwrap(),
        "--out",
        figures.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        figures.join("scalogram_high-down_twin.png").is_file(),
        "{}",
        text(&o)
    );
    assert!(figures.join("time_histories.png").is_file());

    // The copy never replaces its source.
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("overwrite"), "{}", text(&o));
}

/// Warm starts with every `[model]` extension acting (clamp friction and wear carry state from
/// step to step): the steps re-run from their logged states equal the live twin's, bit for bit;
/// bad selections and another model are refused with clear errors.
#[test]
fn steps_re_run_from_logged_states_equal_the_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(
        &plan,
        PLAN.replace("steps = 3", "steps = 4")
            .replace("omega_end = 1.00", "omega_end = 0.97"),
    )
    .unwrap();
    let model = r#"
[model]
sensor_gains = [{ channel = "lower_tip", gain = 0.97 }]
modes = [{ mode = "1FL", damping_ratio = 0.002 }]

[model.clamp_friction]
stiffness_fraction = 0.05
half_slip_tip_amplitude = 1.5e-4
sliders = 16
beams = ["upper"]

[model.wear]
coefficient = 5.0e-7
max_growth = 3.0e-5

[model.tilt]
angle = 2.0e-3
axis = [0.6, 0.8]
"#;
    let rig = default_rig_with(dir.path(), model);
    let mcap = dir.path().join("session.mcap");
    let live = dir.path().join("live.json");
    let o = rigtwin(&[
        "run",
        rig.to_str().unwrap(),
        "--plan",
        plan.to_str().unwrap(),
        "--quiet",
        "--twin",
        "--out",
        mcap.to_str().unwrap(),
        "--json",
        live.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let live = json(&live);
    let twin = |s: &serde_json::Value, k: usize| s["tests"][0]["steps"][k]["twin"].clone();
    for k in 0..4 {
        assert!(twin(&live, k).is_object(), "live twin missed step {k}");
    }
    let part = dir.path().join("part.json");
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--ensemble",
        "0",
        "--steps",
        "high-down:2,high-down:4",
        "--json",
        part.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("2 steps compared"), "{}", text(&o));
    let warm = json(&part);
    for k in [1, 3] {
        assert_eq!(twin(&warm, k), twin(&live, k), "step {}", k + 1);
    }
    // With an ensemble (issue 14, part 4): the members of a warm re-run start from the logged
    // state with the same perturbations as in the whole replay, so the spreads and scores
    // are the same bits too.
    let (full_e, part_e) = (
        dir.path().join("full-e.json"),
        dir.path().join("part-e.json"),
    );
    for (out, steps) in [(&full_e, None), (&part_e, Some("high-down:2,high-down:4"))] {
        let mut args = vec![
            "replay",
            mcap.to_str().unwrap(),
            "--twin",
            "--ensemble",
            "2",
        ];
        if let Some(s) = steps {
            args.extend(["--steps", s]);
        }
        args.extend(["--json", out.to_str().unwrap()]);
        let o = rigtwin(&args);
        assert!(o.status.success(), "{}", text(&o));
    }
    let (full_e, part_e) = (json(&full_e), json(&part_e));
    for k in [1, 3] {
        assert_eq!(
            twin(&part_e, k),
            twin(&full_e, k),
            "step {} with an ensemble",
            k + 1
        );
        assert_eq!(twin(&full_e, k)["ensemble_members"], 2, "step {}", k + 1);
    }
    for k in [0, 2] {
        assert!(twin(&warm, k).is_null(), "step {} was not asked for", k + 1);
    }
    // The first step starts with the recording: from rest, as the whole run did.
    let o = rigtwin(&[
        "replay",
        mcap.to_str().unwrap(),
        "--twin",
        "--steps",
        "high-down:1",
        "--json",
        part.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(twin(&json(&part), 0), twin(&live, 0));

    let fails = |steps: &str, extra: &[&str]| -> String {
        let mut args = vec!["replay", mcap.to_str().unwrap(), "--twin", "--steps", steps];
        args.extend_from_slice(extra);
        let o = rigtwin(&args);
        assert!(!o.status.success(), "--steps {steps} {extra:?} succeeded");
        text(&o)
    };
    let e = fails("high-down:9", &[]);
    assert!(
        e.contains("no step high-down:9") && e.contains("high-down:1-4"),
        "{e}"
    );
    let e = fails("other", &[]);
    assert!(e.contains("no step other"), "{e}");
    let e = fails("high-down:0", &[]);
    assert!(e.contains("not a step number"), "{e}");
    let e = fails("high-down:3-2", &[]);
    assert!(e.contains("backwards"), "{e}");
    // Another model: the logged states are not its states.
    let nominal = default_rig_with(dir.path(), "");
    let e = fails("high-down:2", &["--config", nominal.to_str().unwrap()]);
    assert!(e.contains("another model"), "{e}");
}

/// A twin that cannot keep up (throttled to 4 wall seconds per second of data, queue of 8
/// blocks) skips blocks and says so, and the session paced to the wall clock goes on without
/// a single overrun: the twin never holds up control or logging.
#[test]
fn a_twin_that_falls_behind_skips_visibly_and_does_not_stall_the_session() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(
        &plan,
        PLAN.replace("steps = 3", "steps = 2")
            .replace("settle_periods = 60", "settle_periods = 40"),
    )
    .unwrap();
    let cfg = default_rig_with(dir.path(), "[twin]\nthrottle = 4.0\nqueue_blocks = 8\n");
    let mcap = dir.path().join("session.mcap");
    let summary = dir.path().join("summary.json");
    let o = rigtwin(&[
        "run",
        cfg.to_str().unwrap(),
        "--plan",
        plan.to_str().unwrap(),
        "--quiet",
        "--realtime",
        "--twin",
        "--out",
        mcap.to_str().unwrap(),
        "--json",
        summary.to_str().unwrap(),
    ]);
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    // A twin that stalled the producer would make about three blocks in four overrun (it is
    // throttled to a quarter of real time); a loaded machine makes some overrun on its own
    // (a bound of one in ten failed now and then at a load of 4 on the 2 cores: it is half).
    let (blocks, overruns): (u64, u64) = out
        .lines()
        .find_map(|l| {
            let rest = l.strip_prefix("session: ")?;
            let blocks = rest.split(' ').next()?.parse().ok()?;
            let overruns = rest
                .strip_suffix(" overruns")?
                .rsplit(' ')
                .next()?
                .parse()
                .ok()?;
            Some((blocks, overruns))
        })
        .unwrap_or_else(|| panic!("no session line: {out}"));
    assert!(blocks > 50 && overruns * 2 < blocks, "{out}");
    let skipped: u64 = out
        .lines()
        .find_map(|l| {
            l.strip_prefix("twin: ")?
                .split(" (")
                .nth(1)?
                .split(' ')
                .next()?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no twin line: {out}"));
    assert!(skipped > 0, "the throttled twin skipped nothing: {out}");
    // The lag is in the log.
    let s = rigtwin::log::read_session(&mcap).unwrap();
    let status = s
        .decode::<rigtwin::twin::TwinStatus>(rigtwin::session::topics::TOPIC_TWIN_STATUS)
        .unwrap();
    assert!(
        status.iter().any(|(_, _, st)| st.behind && st.lag_s > 0.1),
        "{status:?}"
    );
    // The session's own summary is complete.
    let s = json(&summary);
    assert_eq!(s["aborted"], false);
    assert_eq!(s["tests"][0]["steps"].as_array().unwrap().len(), 2);
}

/// Keeps each step's comparison before the ensemble joins it, and after.
#[derive(Default)]
struct Both {
    pointwise: Vec<Option<String>>,
    after: Vec<Option<TwinComparison>>,
}

impl TwinSink for Both {
    fn block(&mut self, _: &TwinBlock) -> Result<(), TwinReplayError> {
        Ok(())
    }
    fn step(&mut self, _: &StepInfo, c: Option<&TwinComparison>) -> Result<(), TwinReplayError> {
        self.after.push(c.cloned());
        Ok(())
    }
    fn pointwise(
        &mut self,
        _: &StepInfo,
        c: Option<&TwinComparison>,
    ) -> Result<(), TwinReplayError> {
        self.pointwise
            .push(c.map(|c| serde_json::to_string(c).unwrap()));
        Ok(())
    }
}

#[test]
fn an_ensemble_in_the_contact_windows_only_keeps_the_pointwise_comparison() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = record(dir.path());
    let r = rigtwin::session::replay::replay(&mcap).unwrap();
    let cfg = rigtwin::config::RigConfig::default_rig();
    let rom = default_rom::default_rom();
    let model = TwinModel::of_config(rom, &cfg);
    let mut spec = cfg.twin.clone();
    let l = cfg.rig.beam_length;

    // Without an ensemble.
    spec.ensemble_members = 0;
    let mut bare = r.summary.clone();
    replay_twin(
        &r.recording,
        &mut bare,
        &model,
        &spec,
        l,
        EnsembleOptions::NONE,
        &mut (),
    )
    .unwrap();
    // With two members in the windows with contact only.
    spec.ensemble_members = 2;
    let mut with = r.summary.clone();
    let mut both = Both::default();
    let ensemble = EnsembleOptions {
        members: 2,
        contact_windows_only: true,
        ..EnsembleOptions::of(&spec, 1)
    };
    replay_twin(
        &r.recording,
        &mut with,
        &model,
        &spec,
        l,
        ensemble,
        &mut both,
    )
    .unwrap();

    // On two threads into a sink that takes the steps in any order (the twin runs on while
    // each window's ensemble runs): the same bits.
    let mut overlapped = r.summary.clone();
    replay_twin(
        &r.recording,
        &mut overlapped,
        &model,
        &spec,
        l,
        EnsembleOptions {
            jobs: 2,
            ..ensemble
        },
        &mut (),
    )
    .unwrap();
    assert_eq!(
        serde_json::to_string(&overlapped).unwrap(),
        serde_json::to_string(&with).unwrap(),
        "the ensemble's result depends on neither the threads nor the sink's order"
    );

    let bare: Vec<&TwinComparison> = bare.steps().filter_map(|s| s.twin.as_ref()).collect();
    let measured: Vec<f64> = (r.summary.steps())
        .map(|s| s.measured.metrics.contact_fraction)
        .collect();
    assert_eq!(bare.len(), 3);
    assert_eq!(both.pointwise.len(), 3);
    let (mut ensembles, mut after_contact) = (0, false);
    for (i, b) in bare.iter().enumerate() {
        assert_eq!(
            both.pointwise[i].as_deref(),
            Some(serde_json::to_string(b).unwrap().as_str()),
            "step {i}: the comparison before the ensemble is the run without one"
        );
        let c = both.after[i].as_ref().unwrap();
        let contact = after_contact || measured[i] > 0.0 || b.metrics.contact_fraction > 0.0;
        after_contact = measured[i] > 0.0;
        if contact && i > 0 {
            assert_eq!(c.ensemble_members, 2, "step {i}");
            ensembles += 1;
            for (f, g) in c.features.iter().zip(&b.features) {
                assert_eq!(f.model, g.model, "the twin's own values do not move");
            }
        } else {
            assert_eq!(
                serde_json::to_string(c).unwrap(),
                serde_json::to_string(b).unwrap(),
                "step {i}: no contact, no ensemble"
            );
        }
    }
    assert!(
        ensembles >= 1,
        "no window with contact: the ensemble was not exercised"
    );
    assert!(
        ensembles < 3,
        "every window had contact: the impact-free one was not exercised"
    );

    // With an ensemble, a sink that fails stops the replay, and its error is the one reported.
    let mut failing = FailsAtSecondStep(0);
    let mut again = r.summary.clone();
    let err = replay_twin(
        &r.recording,
        &mut again,
        &model,
        &spec,
        l,
        ensemble,
        &mut failing,
    )
    .unwrap_err();
    assert!(
        matches!(&err, TwinReplayError::Overwrite { path } if path == "the sink"),
        "{err}"
    );
    assert_eq!(failing.0, 2);
}

/// A sink whose second step fails.
struct FailsAtSecondStep(usize);

impl TwinSink for FailsAtSecondStep {
    fn block(&mut self, _: &TwinBlock) -> Result<(), TwinReplayError> {
        Ok(())
    }
    fn step(&mut self, _: &StepInfo, _: Option<&TwinComparison>) -> Result<(), TwinReplayError> {
        self.0 += 1;
        if self.0 == 2 {
            return Err(TwinReplayError::Overwrite {
                path: "the sink".into(),
            });
        }
        Ok(())
    }
}

/// A plan whose every test holds the probes in contact (issue 16): the live twin runs on the
/// coarser patch of `[twin.held_contact]`, says so and logs its ROM, and `replay --twin`
/// chooses the same patch from the logged plan (the same bits). A plan with a test at the
/// reference's clearance, or `enabled = false`, keeps the model's patch.
#[test]
fn a_session_that_holds_contact_runs_the_twin_on_the_coarser_patch() {
    const HELD: &str = r#"
name = "held-contact-test"
[defaults]
level = 0.5e-5
steps = 1
settle_periods = 20
record_periods = 20
steps_per_period = 1000
direction = "up"
omega_start = 1.0
omega_end = 1.0

[[test]]
name = "small-clearance"
clearance = 1.0e-5
"#;
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, plan_text: &str, rig: Option<&std::path::Path>| {
        let plan = dir.path().join(format!("{name}.toml"));
        std::fs::write(&plan, plan_text).unwrap();
        let mcap = dir.path().join(format!("{name}.mcap"));
        let json = dir.path().join(format!("{name}.json"));
        let mut args = vec!["run", "--plan", plan.to_str().unwrap(), "--quiet", "--twin"];
        if let Some(rig) = rig {
            args.push(rig.to_str().unwrap());
        }
        args.extend([
            "--out",
            mcap.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ]);
        let o = rigtwin(&args);
        assert!(o.status.success(), "{}", text(&o));
        let rom = rigtwin::log::read_session(&mcap)
            .unwrap()
            .metadata(rigtwin::session::topics::ROM_METADATA)
            .unwrap()
            .clone();
        (mcap, json, text(&o), rom)
    };
    let (mcap, live, out, rom) = run("held", HELD, None);
    assert!(
        out.contains("twin: contact patch 8 x 11 (88 pairs) in place of the model's 12 x 16"),
        "{out}"
    );
    assert_eq!(rom["pairs"], "192", "{rom:?}");
    assert_eq!(rom["twin_pairs"], "88", "{rom:?}");
    assert!(json(&live)["tests"][0]["steps"][0]["twin"].is_object());
    let out = assert_replay_equals_live(&mcap, &live, &dir.path().join("replay.json"));
    assert!(out.contains("twin: contact patch 8 x 11"), "{out}");

    // A test at the reference's clearance: impacts, where the coarse patch rings differently.
    let mixed = format!("{HELD}\n[[test]]\nname = \"apart\"\nclearance = 2.78e-3\n");
    let (_, _, out, rom) = run("mixed", &mixed, None);
    assert!(!out.contains("twin: contact patch"), "{out}");
    assert!(!rom.contains_key("twin_pairs"), "{rom:?}");
    // Switched off.
    let rig = default_rig_with(dir.path(), "[twin.held_contact]\nenabled = false\n");
    let (_, _, out, rom) = run("off", HELD, Some(&rig));
    assert!(!out.contains("twin: contact patch"), "{out}");
    assert!(!rom.contains_key("twin_pairs"), "{rom:?}");
}
