//! The discretisation stage of the diagnosis: whether the twin's own modal truncation or time
//! step is the mismatch. A twin coarser than the reference resolution (the default
//! `[reduction] cutoff_ratio = 180` on the `[contact] nodes` patch, and about 1000 twin steps
//! per 1FU period) is re-run refined to it over the tests with contact; the refinement is
//! accepted like any effect, only if it predicts its validation tests better beyond the null
//! spread, and from then on every model run of the diagnosis uses it.
//!
//! Why before the contact stages: a twin whose modal basis stops below the second bending
//! modes keeps each impact closed about ten times longer (BENCHMARKS.md, "A ROM with few
//! modes"), and a clearance, a tilt or wear fitted to that twin would absorb its slow impacts.
//! Why it is judged and not applied as a rule: a coarser twin than the reference can be as
//! good on a session (modes up to 17 x f(1FU) were, on the nominal `identify.toml` session,
//! within the comparison's spread), and then the refinement is rejected with its numbers.
//!
//! The options are the coarse axes refined: the modal basis (the reference ROM, built by the
//! caller, [`refined_reduction`]), the step, or both; the one with the smallest error on the
//! train tests is judged on the validation tests. The modal basis alone is not tried with a
//! step too coarse for the reference ROM's stability limit: the step is then refined with it.

use serde_json::json;

use crate::config::{ReductionSpec, RigConfig};
use crate::rom::info::RomInfo;
use crate::rom::Rom;
use crate::signal::features::CONTACT_CHANNEL;
use crate::twin::{TwinModel, TwinSpec};

use super::judge::{alternate, set_error, Candidate, Steps, Work};
use super::outcome::{
    DiscretisationEvidence, DiscretisedStep, DiscretisedTwin, Refinement, SetError, StepScores,
};
use super::rerun::{ModelRunner, SessionSteps};
use super::{DiagnoseError, DiagnoseProgress};

/// The reference modal basis: modes up to this multiple of f(1FU) (`[reduction]`'s default).
pub const REFERENCE_CUTOFF_RATIO: f64 = 180.0;

/// A twin is refined when it is coarser than the reference by more than this share (the
/// highest retained mode falls somewhat below the cutoff; the automatic step rounds to whole
/// steps per sample).
const COARSER_BY: f64 = 0.9;

/// The reference reduction (`cutoff_ratio = 180` on the `[contact] nodes` patch).
fn reference_reduction() -> ReductionSpec {
    ReductionSpec {
        cutoff_ratio: Some(REFERENCE_CUTOFF_RATIO),
        ..ReductionSpec::default()
    }
}

/// The rig description of the reference ROM when the twin's ROM `rom` (of `cfg`) is coarser
/// than it: its highest mode below 0.9 x 180 x f(1FU), or a contact patch of its own
/// (`[reduction] contact_nodes`). The caller builds (or loads) that ROM for
/// [`super::DiagnoseInput::refined`]; None: the twin's modal basis is the reference's or finer.
pub fn refined_reduction(cfg: &RigConfig, rom: &Rom) -> Option<RigConfig> {
    let info = RomInfo::new(rom);
    let few = info.highest_mode_over_1fu < COARSER_BY * REFERENCE_CUTOFF_RATIO;
    (few || cfg.reduction.contact_nodes.is_some()).then(|| RigConfig {
        reduction: reference_reduction(),
        ..cfg.clone()
    })
}

/// The model the diagnosis runs: its ROM and twin settings.
#[derive(Clone)]
pub(super) struct Resolution<'a> {
    pub(super) rom: &'a Rom,
    pub(super) spec: TwinSpec,
}

/// The twin's discretisation `rom` and `spec` at `sample_rate` (`refined`: what is refined,
/// in words) with its run: `scores` on the tests with contact, or why it could not run, and
/// its error on the train and validation tests.
fn discretised(
    refined: Option<&str>,
    r: &Resolution<'_>,
    sample_rate: f64,
    run: Result<&[StepScores], &str>,
    error: Option<SetError>,
) -> DiscretisedTwin {
    let steps = run.map_or_else(
        |_| Vec::new(),
        |scores| {
            (scores.iter())
                .map(|s| {
                    let contact = s.feature(CONTACT_CHANNEL, "contact_fraction");
                    DiscretisedStep {
                        test: s.test.clone(),
                        step: s.step,
                        omega_ratio: s.omega_ratio,
                        score: s.rms_score(),
                        contact_measured: contact.map(|f| f.measured),
                        contact_model: contact.map(|f| f.model),
                    }
                })
                .collect()
        },
    );
    DiscretisedTwin {
        refined: refined.map(str::to_string),
        modes: r.rom.n_modes(),
        highest_mode_over_1fu: RomInfo::new(r.rom).highest_mode_over_1fu,
        contact_pairs: r.rom.n_pairs(),
        steps_per_sample: r.spec.steps_per_sample_for(sample_rate, r.rom.omega_ref()),
        steps_per_1fu_period: steps_per_period(r.rom, &r.spec, sample_rate),
        error,
        failure: run.err().map(str::to_string),
        steps,
    }
}

/// A discretisation in numbers (the effect's evidence; its steps are in the diagnosis'
/// [`DiscretisationEvidence`]).
fn described(t: &DiscretisedTwin) -> serde_json::Value {
    json!({
        "modes": t.modes,
        "highest_mode_over_1fu": t.highest_mode_over_1fu,
        "contact_pairs": t.contact_pairs,
        "steps_per_sample": t.steps_per_sample,
        "steps_per_1fu_period": t.steps_per_1fu_period,
    })
}

/// The twin's discretisation in words (the terminal).
fn in_words(rom: &Rom, spec: &TwinSpec, sample_rate: f64) -> String {
    format!(
        "{} modes up to {:.1} x f(1FU), {} contact pairs, {:.0} steps per 1FU period",
        rom.n_modes(),
        RomInfo::new(rom).highest_mode_over_1fu,
        rom.n_pairs(),
        steps_per_period(rom, spec, sample_rate)
    )
}

/// Twin steps per 1FU period of `spec` on `rom` at `sample_rate`.
fn steps_per_period(rom: &Rom, spec: &TwinSpec, sample_rate: f64) -> f64 {
    let n = spec.steps_per_sample_for(sample_rate, rom.omega_ref());
    f64::from(n) * sample_rate * 2.0 * std::f64::consts::PI / rom.omega_ref()
}

/// What the stage found: its evidence, and the accepted refinement with its model.
#[derive(Default)]
pub(super) struct Staged<'a> {
    /// The twin as given and each refinement tried (None: nothing tried).
    pub(super) evidence: Option<DiscretisationEvidence>,
    /// The accepted refinement and its model, with which the work's runner runs from then on.
    pub(super) accepted: Option<(Refinement, Resolution<'a>)>,
}

/// One refinement tried.
struct Choice<'a> {
    /// Which axes it refines, in words.
    what: &'static str,
    refinement: Refinement,
    resolution: Resolution<'a>,
    axes: usize,
}

/// The discretisation stage (module docs) on the model accepted so far, before the contact
/// stages. `given` is the twin as given, `refined` the reference ROM where the caller found
/// the twin's modal basis coarser ([`refined_reduction`]). Returns the evidence and the
/// accepted refinement with its model, with which the work's runner runs from then on.
pub(super) fn resolution_stage<'a>(
    work: &mut Work<'a>,
    given: &Resolution<'a>,
    refined: Option<&'a Rom>,
) -> Result<Staged<'a>, DiagnoseError> {
    let steps: &SessionSteps = work.steps;
    let fs = work.runner.sample_rate();
    let reference_steps = TwinSpec::default().steps_per_reference_period;
    let own_steps = steps_per_period(given.rom, &given.spec, fs);
    let coarse_step = own_steps < COARSER_BY * reference_steps;
    let refined = refined.filter(|r| {
        RomInfo::new(r).highest_mode_over_1fu > RomInfo::new(given.rom).highest_mode_over_1fu
            || r.n_pairs() > given.rom.n_pairs()
    });
    if refined.is_none() && !coarse_step {
        return Ok(Staged::default());
    }
    work.stage(
        "discretisation",
        format!(
            "identify: the twin's own modal truncation and time step ({}), coarser than the reference",
            in_words(given.rom, &given.spec, fs)
        ),
    );
    let tests = steps.tests_with(false);
    if tests.len() < 2 {
        work.undecided(
            "discretisation",
            format!(
                "the twin is coarser than the reference ({}), but the session has {} test(s) with contact: none left to validate a refined twin on",
                in_words(given.rom, &given.spec, fs),
                tests.len()
            ),
        );
        return Ok(Staged::default());
    }
    let step_spec = TwinSpec {
        steps_per_sample: None,
        steps_per_reference_period: reference_steps,
        ..given.spec.clone()
    };
    let mut options: Vec<Choice<'a>> = Vec::new();
    if coarse_step {
        options.push(Choice {
            what: "the twin step",
            refinement: Refinement {
                reduction: None,
                steps_per_reference_period: Some(reference_steps),
            },
            resolution: Resolution {
                rom: given.rom,
                spec: step_spec.clone(),
            },
            axes: 1,
        });
    }
    if let Some(rom) = refined {
        let (what, spec, step, axes) = if coarse_step {
            (
                "the modal basis and the twin step",
                step_spec,
                Some(reference_steps),
                2,
            )
        } else {
            ("the modal basis", given.spec.clone(), None, 1)
        };
        options.push(Choice {
            what,
            refinement: Refinement {
                reduction: Some(reference_reduction()),
                steps_per_reference_period: step,
            },
            resolution: Resolution { rom, spec },
            axes,
        });
    }

    let (train, validation) = alternate(&tests);
    let accepted = work.accepted.clone();
    let before = work.scores(&accepted, &tests)?;
    let error_of = |s: &[StepScores]| -> Option<SetError> {
        Some(SetError {
            train: set_error(s, &train, Steps::All)?,
            validation: set_error(s, &validation, Steps::All)?,
        })
    };
    let given_twin = discretised(None, given, fs, Ok(&before), error_of(&before));
    // Per option: its runner and how it did (a refined twin the reference ROM's stability
    // limit or the session does not allow could not run: that option is out).
    let mut runners: Vec<ModelRunner<'a>> = Vec::new();
    let mut twins: Vec<DiscretisedTwin> = Vec::new();
    let names = work.names(&tests).join(", ");
    for o in &options {
        (work.progress)(DiagnoseProgress::Evaluation(format!(
            "discretisation: {} refined ({}) on {}",
            o.what,
            in_words(o.resolution.rom, &o.resolution.spec, fs),
            names
        )));
        let mut runner = work.runner.with_model(
            TwinModel {
                rom: o.resolution.rom,
                ..work.runner.base_model().clone()
            },
            &o.resolution.spec,
        );
        let t = match runner.run(&accepted, &tests) {
            Ok(s) => discretised(Some(o.what), &o.resolution, fs, Ok(&s), error_of(&s)),
            Err(e) => discretised(Some(o.what), &o.resolution, fs, Err(&e.to_string()), None),
        };
        runners.push(runner);
        twins.push(t);
    }
    let evidence = DiscretisationEvidence {
        train_tests: work.names(&train),
        validation_tests: work.names(&validation),
        given: given_twin,
        options: twins,
    };
    let best = (evidence.options.iter().enumerate())
        .filter_map(|(i, t)| t.error.map(|e| (i, e.train)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i);
    let evidence_json = json!({
        "twin": described(&evidence.given),
        "reference": {
            "cutoff_ratio": REFERENCE_CUTOFF_RATIO,
            "steps_per_reference_period": reference_steps,
        },
        "options": evidence.options.iter().map(|t| json!({
            "refined": t.refined,
            "model": described(t),
            "error": t.error,
            "failure": t.failure,
        })).collect::<Vec<_>>(),
    });
    let Some(best) = best else {
        let failed: Vec<String> = (evidence.options.iter())
            .filter_map(|t| t.failure.clone())
            .collect();
        work.absorb_cost(runners);
        work.undecided(
            "discretisation",
            if failed.is_empty() {
                "no compared step of the refined twin on the train or validation tests".to_string()
            } else {
                format!("the refined twin could not run: {}", failed.join("; "))
            },
        );
        return Ok(Staged {
            evidence: Some(evidence),
            accepted: None,
        });
    };
    let o = &options[best];
    let mut parameters = json!({});
    if o.refinement.reduction.is_some() {
        parameters["reduction"] = json!({ "cutoff_ratio": REFERENCE_CUTOFF_RATIO });
        parameters["modes"] = json!(o.resolution.rom.n_modes());
    }
    if let Some(s) = o.refinement.steps_per_reference_period {
        parameters["twin"] = json!({ "steps_per_reference_period": s });
        parameters["steps_per_sample"] = json!(evidence.options[best].steps_per_sample);
    }
    let c = Candidate::new(
        "discretisation",
        accepted.clone(),
        parameters,
        o.axes,
        evidence_json,
        (train.clone(), validation.clone()),
        Steps::All,
    );
    let ok = work.judge_on(
        c,
        &format!("the twin with {} refined to the reference", o.what),
        evidence.given.error,
        evidence.options[best].error,
    );
    let chosen = runners.swap_remove(best);
    work.absorb_cost(runners);
    if !ok {
        work.absorb_cost(std::iter::once(chosen));
        return Ok(Staged {
            evidence: Some(evidence),
            accepted: None,
        });
    }
    (work.progress)(DiagnoseProgress::Note(format!(
        "discretisation: the stages after this one run the twin with {} refined",
        o.what
    )));
    work.replace_runner(chosen);
    Ok(Staged {
        evidence: Some(evidence),
        accepted: Some((o.refinement.clone(), o.resolution.clone())),
    })
}
