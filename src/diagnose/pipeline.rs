//! The diagnosis ([`diagnose`]): locate the mismatch, name the physics the model left out, fit
//! it, keep it only if it predicts tests it was not fitted on (DESIGN.md, "Diagnosis").
//!
//! 1. **Locate**: the twin (the model as given) re-run over the whole session, every step's
//!    features scored against the measurement with both spreads
//!    ([`crate::twin::TwinComparison`]), grouped by regime.
//! 2. **Identify and fit**, in the order in which effects confound each other, each on top
//!    of the effects accepted before it, one module per stage:
//!    - `sensor_gain` (`gains`): the redundant channels' ratios
//!      ([`super::sensors`]); for a channel without a redundant partner, the measured/model
//!      ratio over the impact-free steps: flat in frequency and different from its beam's
//!      other channel;
//!    - `linear_frequency`, `linear_damping` of 1FU and 1FL (`modes`): the
//!      impact-free fits ([`super::linear`]) at the lowest level (at zero amplitude where the
//!      clamp's friction shows);
//!    - `clamp_friction` (`clamp`): the frequency falling and the damping rising with
//!      the amplitude; the slopes fix the ratio of the joint's stiffness share to its slip
//!      amplitude, model runs over a few stiffness shares fix the rest;
//!    - `discretisation` (`resolution`): only for a twin coarser than the reference (its
//!      modes, contact patch or step): the tests with contact re-run with it refined; if
//!      accepted, every later run (and the show run) uses the refined twin;
//!    - `wear` ([`super::wear`]): the clearance per test ([`super::clearance`], refined by
//!      model runs, `clearance_fit`) growing with the model's normal contact impulse;
//!    - `clearance` (`clearance_fit`): as an offset to the plan's when the tests
//!      agree; `tilt` (`tilt`): a tilted face against that offset.
//! 3. **Select**: each candidate is fitted on some tests (`train`) and judged on others
//!    (`validation`) by model runs with and without it ([`ModelRunner`]); the error is the RMS
//!    of the compared features' scores over the regime the effect shows in. It is accepted
//!    only if the validation error falls by more than the null spread plus a penalty per
//!    parameter; rejected candidates are reported with the reason. The accepted effects'
//!    validation tests are reported with the comparison's spread as well
//!    (`validation_with_spread`, from the locate and show runs; for a lone band effect, each
//!    step's median over those and the judge's runs of the same models).
//! 4. **Verdict**: a mismatch when an effect was accepted, or when a regime's typical step
//!    (the median of the steps' largest scores) lies above the threshold: the impact-free
//!    regimes compared pointwise, the impact band with the comparison's own spread (the
//!    locate run's ensemble and discretisation member in the windows with contact,
//!    [`BandSpread`]): pointwise, the band's chaos and the twin's own step put a right
//!    model's band steps above the threshold.
//!
//! A diagnosis never reads the simulated rig's hidden physics: its inputs are the recording
//! (DAQ counts, layout, events), its replayed summary and the model, from whose rig
//! description the caller has removed the simulated rig's tables.

use serde_json::json;

use crate::config::{PhysicsSpec, RigConfig};
use crate::control::summary::StepInfo;
use crate::rom::Rom;
use crate::session::replay::Recording;
use crate::session::summary::SessionSummary;
use crate::session::twin_replay::{
    replay_twin, DiscretisationMember, EnsembleOptions, TwinReplayError, TwinSink,
};
use crate::twin::{
    ComparisonTolerance, FeatureComparison, TwinBlock, TwinComparison, TwinModel, TwinSpec,
};

use super::clearance::{clearance_per_test_of, ClearanceOptions};
use super::clearance_fit::{clearance_stage, unexplained_offset};
use super::evidence::session_evidence;
use super::gains::{sensor_stage, unpartnered_gains, GainSplit};
use super::judge::{members_error, set_error, DiagnoseOptions, DiagnoseProgress, Steps, Work};
use super::linear::{linear_modes_of, LinearOptions};
use super::modes::linear_stage;
use super::outcome::{
    BandSpread, BandStep, Diagnosis, DiagnosisCost, EffectResult, Located, Regime, RegimeScores,
    SetError, StageCost, StepScores, ValidationWithSpread, Verdict,
};
use super::rerun::{had_contact, ModelRunner, SessionSteps, Span};
use super::resolution::Resolution;
use super::wear::WearFound;
use super::{DiagnoseError, EvidenceError};

/// What a diagnosis works on.
pub struct DiagnoseInput<'a> {
    /// The recording.
    pub rec: &'a Recording,
    /// Its replayed summary (the measurement).
    pub summary: &'a SessionSummary,
    /// The model's rig description, without the simulated rig's tables (the caller's work).
    pub cfg: &'a RigConfig,
    /// Its ROM.
    pub rom: &'a Rom,
    /// The finer ROM of the comparison's discretisation member (`[twin.discretisation]`),
    /// for the impact band's verdict ([`BandSpread`]); None: the ensemble's spread alone.
    pub finer: Option<&'a Rom>,
    /// The reference ROM where the twin's modal basis is coarser than it
    /// ([`super::refined_reduction`]), for the discretisation stage; None: not coarser (or
    /// the caller did not build it).
    pub refined: Option<&'a Rom>,
}

/// Whether a diagnosis of the session `summary` with the rig description `cfg` compares its
/// impact band with the discretisation member, so needs its finer ROM
/// ([`DiagnoseInput::finer`]): the rig had contact in some step, and `[twin]` has an
/// ensemble and the member enabled. A caller builds that ROM only then.
pub fn needs_finer_rom(summary: &SessionSummary, cfg: &RigConfig) -> bool {
    let spec = &cfg.twin;
    spec.discretisation.enabled && spec.ensemble_members > 0 && summary.steps().any(had_contact)
}

/// Per regime: steps, steps above the threshold, median largest score.
fn regimes(scores: &[StepScores], threshold: f64) -> Vec<RegimeScores> {
    [
        Regime::ImpactFreeLow,
        Regime::ImpactFreeHigh,
        Regime::Impacts,
    ]
    .into_iter()
    .filter_map(|r| {
        let mut max: Vec<f64> = scores
            .iter()
            .filter(|s| s.regime == r)
            .filter_map(StepScores::max_score)
            .collect();
        if max.is_empty() {
            return None;
        }
        max.sort_by(f64::total_cmp);
        Some(RegimeScores {
            regime: r,
            steps: max.len(),
            steps_above: max.iter().filter(|&&m| m > threshold).count(),
            median_max_score: max[max.len() / 2],
        })
    })
    .collect()
}

/// Collects each step's comparison with the twin's own spread only
/// ([`TwinSink::pointwise`]), in record-window order.
#[derive(Default)]
struct Pointwise(Vec<Vec<FeatureComparison>>);

impl TwinSink for Pointwise {
    fn block(&mut self, _: &TwinBlock) -> Result<(), TwinReplayError> {
        Ok(())
    }
    fn steps_in_time_order(&self) -> bool {
        false
    }
    fn step(&mut self, _: &StepInfo, _: Option<&TwinComparison>) -> Result<(), TwinReplayError> {
        Ok(())
    }
    fn pointwise(
        &mut self,
        _: &StepInfo,
        twin: Option<&TwinComparison>,
    ) -> Result<(), TwinReplayError> {
        self.0
            .push(twin.map(|c| c.features.clone()).unwrap_or_default());
        Ok(())
    }
}

/// A model's run over the whole session ([`whole_session`]).
struct WholeSession {
    /// Every step compared pointwise (the twin's own spread).
    plain: Vec<StepScores>,
    /// The impact band with the comparison's spread, and every step so compared (the
    /// windows without contact as pointwise); None without a band run.
    band: Option<(BandSpread, Vec<StepScores>)>,
}

/// One run of the model with extensions `ext` on the twin `resolution` (its ROM and settings)
/// over the whole session: every step compared pointwise (the twin's own spread: `rigtwin
/// replay --twin --ensemble 0` of that model), and,
/// `with_band`, the impact band with the comparison's spread ([`BandSpread`]; None without a
/// step with contact or without an ensemble, `[twin] ensemble_members = 0`). The band's
/// spread comes from the `[twin]` ensemble and the discretisation member (with
/// `input.finer`), run in the windows with contact only.
fn whole_session(
    input: &DiagnoseInput<'_>,
    resolution: &Resolution<'_>,
    steps: &SessionSteps,
    ext: &PhysicsSpec,
    opts: &DiagnoseOptions,
    with_band: bool,
) -> Result<WholeSession, DiagnoseError> {
    let spec = &resolution.spec;
    let mut model = TwinModel::of_config(resolution.rom, input.cfg);
    model.extensions = ext.clone();
    let band = with_band && steps.steps.iter().any(|s| s.regime == Regime::Impacts);
    let members = if band { spec.ensemble_members } else { 0 };
    let d = &spec.discretisation;
    let member = (input.finer)
        .filter(|_| d.enabled && members > 0)
        .map(|rom| DiscretisationMember {
            model: TwinModel {
                rom,
                ..model.clone()
            },
            spec: TwinSpec {
                steps_per_sample: Some(d.steps_per_sample),
                ..spec.clone()
            },
        });
    let ensemble = EnsembleOptions {
        members,
        perturbation: spec.ensemble_perturbation,
        jobs: opts.jobs,
        discretisation: member.as_ref(),
        contact_windows_only: true,
    };
    let mut summary = input.summary.clone();
    let mut pointwise = Pointwise::default();
    replay_twin(
        input.rec,
        &mut summary,
        &model,
        spec,
        input.cfg.rig.beam_length,
        ensemble,
        &mut pointwise,
    )?;
    let scores_of = |features: Vec<Vec<FeatureComparison>>| -> Vec<StepScores> {
        (steps.steps.iter())
            .zip(features)
            .map(|(s, f)| s.scores(f))
            .collect()
    };
    let plain = scores_of(pointwise.0);
    if members == 0 {
        return Ok(WholeSession { plain, band: None });
    }
    let spread = scores_of(
        summary
            .steps()
            .map(|r| {
                (r.twin.as_ref())
                    .map(|t| t.features.clone())
                    .unwrap_or_default()
            })
            .collect(),
    );
    let Some(r) = regimes(&spread, opts.threshold)
        .into_iter()
        .find(|r| r.regime == Regime::Impacts)
    else {
        return Ok(WholeSession { plain, band: None });
    };
    let band = BandSpread {
        members,
        finer_modes: member.as_ref().map(|m| m.model.rom.n_modes()),
        beyond: r.median_max_score > opts.threshold,
        scores: r,
        steps: (spread.iter())
            .filter(|s| s.regime == Regime::Impacts)
            .filter_map(|s| {
                s.max_score().map(|m| BandStep {
                    test: s.test.clone(),
                    step: s.step,
                    omega_ratio: s.omega_ratio,
                    max_score: m,
                })
            })
            .collect(),
    };
    Ok(WholeSession {
        plain,
        band: Some((band, spread)),
    })
}

/// The effects judged on every step, the impact band's with the others ([`Steps::All`]).
const BAND_EFFECTS: [&str; 3] = ["clearance", "wear", "tilt"];

/// Where the one accepted effect is a band effect, it was judged against the model as given
/// and the fixed model is the model with it: its errors are reported with the comparison's
/// spread, and the judge's pointwise errors move to its evidence (`pointwise`). Pointwise at
/// the twin's step the band keeps a floor a right model does not go below (the twin's own
/// step at the band's edges, its chaos; BENCHMARKS.md, "The validation error with the
/// comparison's spread").
///
/// Each model's band is drawn more than once, as the judge drew it: the locate (`before`) or
/// show (`after`) run, and the judge's runs of the same model over the effect's whole tests
/// ([`Work::band_runs_made`]; no extra runs), each scored against the spreads of the locate
/// or show run's comparison ([`FeatureComparison::with_model_value`]); per step the median
/// over the draws ([`members_error`]). Where the judge's runs are not at hand, the locate and
/// show runs alone.
///
/// NOTE: one draw of the band decided the reported fall before: a clearance offset of
/// +1e-4 m on `identify.toml` read 2.1x with the fitted +112 um and 3.1x with +113 um; over
/// the four draws, 2.1x (BENCHMARKS.md, "The validation error with the spread over the
/// judge's draws").
fn lone_band_effect_with_spread(
    work: &mut Work<'_>,
    given: &PhysicsSpec,
    tolerance: &ComparisonTolerance,
    before: &[StepScores],
    after: &[StepScores],
) -> Option<(SetError, SetError)> {
    let mut accepted = work.effects.iter().filter(|e| e.accepted);
    let (Some(e), None) = (accepted.next(), accepted.next()) else {
        return None;
    };
    if !BAND_EFFECTS.contains(&e.effect.as_str()) {
        return None;
    }
    let (train, validation, spans) = judged_tests(work.steps, e);
    // Both models' draws, or neither's: the two sides are compared like with like.
    let made = work
        .band_runs_made(given, &spans)
        .zip(work.band_runs_made(&work.accepted, &spans))
        .unwrap_or_default();
    let (before_runs, after_runs) = (
        draws_against(before, &made.0, tolerance),
        draws_against(after, &made.1, tolerance),
    );
    let error = |runs: &[Vec<StepScores>]| set_error_over(runs, &train, &validation);
    let one = |s: &[StepScores]| error(&[s.to_vec()]);
    let (b, a) = (error(&before_runs)?, error(&after_runs)?);
    let draws = before_runs.len();
    let (b1, a1) = (one(before), one(after));
    let whose = if draws > 1 {
        format!("the locate and show runs and the judge's {} runs of each model, each step's median over the {draws} draws", draws - 1)
    } else {
        "the locate and show runs".to_string()
    };
    let e = work.effects.iter_mut().find(|e| e.accepted)?;
    reported_with_spread(
        e,
        (b, a),
        &whose,
        json!({
            "draws": draws,
            "per_step": "the median over the draws of the step's mean squared score, each draw against the locate (before) or show (after) run's spreads",
            "locate_and_show_runs_alone": {"error_before": b1, "error_after": a1},
        }),
    );
    equal_alternatives_with_spread(work, given, tolerance, before, after);
    Some((b, a))
}

/// `show`'s run, then each run of `made` scored against the spreads of `show`'s comparison
/// ([`scored_as`]): the draws of one model's band.
fn draws_against(
    show: &[StepScores],
    made: &[Vec<StepScores>],
    tolerance: &ComparisonTolerance,
) -> Vec<Vec<StepScores>> {
    std::iter::once(show.to_vec())
        .chain(made.iter().map(|r| scored_as(show, r, tolerance)))
        .collect()
}

/// The train and validation errors of the draws `runs` ([`members_error`]: each step's median
/// over them); None where a set was not compared.
fn set_error_over(
    runs: &[Vec<StepScores>],
    train: &[usize],
    validation: &[usize],
) -> Option<SetError> {
    Some(SetError {
        train: members_error(runs, train, Steps::All, None)?,
        validation: members_error(runs, validation, Steps::All, None)?,
    })
}

/// Effect `e` reported with the comparison's spread: its errors `(before, after)`, the judge's
/// pointwise ones moved to `evidence.pointwise`, how they were drawn (`with_spread`, `whose`
/// in words) in the evidence and the reason.
fn reported_with_spread(
    e: &mut EffectResult,
    (b, a): (SetError, SetError),
    whose: &str,
    with_spread: serde_json::Value,
) {
    e.evidence["pointwise"] = json!({
        "error_before": e.error_before,
        "error_after": e.error_after,
    });
    e.evidence["with_spread"] = with_spread;
    e.reason = format!(
        "{}; with the comparison's spread ({whose}, reported as its error) the validation error falls {:.1}x ({:.3} -> {:.3})",
        e.reason,
        b.validation / a.validation.max(1e-12),
        b.validation,
        a.validation
    );
    e.error_before = Some(b);
    e.error_after = Some(a);
}

/// The train and validation tests of effect `e` (indices in `steps`) and the whole of each,
/// as the judge ran them.
fn judged_tests(steps: &SessionSteps, e: &EffectResult) -> (Vec<usize>, Vec<usize>, Vec<Span>) {
    let (train, validation) = (
        steps.indices_of(&e.train_tests),
        steps.indices_of(&e.validation_tests),
    );
    let mut whole: Vec<usize> = train.iter().chain(&validation).copied().collect();
    whole.sort_unstable();
    whole.dedup();
    let spans = whole.into_iter().map(Span::whole).collect();
    (train, validation, spans)
}

/// The equal alternatives of the lone accepted band effect (band effects the session cannot
/// tell from it: named in its `alternatives`, on the whole tests or where they act), reported
/// on its footing: their errors
/// with the comparison's spread, the judge's pointwise ones moved to their evidence
/// (`pointwise`). Before, as the accepted effect's (the locate run and the judge's runs of the
/// model as given); after, the judge's runs of the alternative's own model over its whole
/// tests, scored against the spreads of the show run's comparison (the fixed model's: the
/// alternative has no show run of its own). Where the judge's runs are not at hand, the
/// pointwise errors stay.
///
/// NOTE: pointwise at the twin's step an equal alternative kept the twin's own floor while
/// the accepted effect reported past it: a hidden 0.02 rad tilt on the four-probe plan read
/// 4.30 -> 1.83 for the tilt beside 2.18 -> 0.85 for the clearance offset it equals
/// (BENCHMARKS.md, "The tilt fitted about the first contact").
fn equal_alternatives_with_spread(
    work: &mut Work<'_>,
    given: &PhysicsSpec,
    tolerance: &ComparisonTolerance,
    before: &[StepScores],
    after: &[StepScores],
) {
    let steps = work.steps;
    let Some(named) = (work.effects.iter())
        .find(|e| e.accepted)
        .map(|e| e.alternatives.clone())
    else {
        return;
    };
    let alternatives: Vec<usize> = (0..work.effects.len())
        .filter(|&i| {
            let e = &work.effects[i];
            !e.accepted
                && BAND_EFFECTS.contains(&e.effect.as_str())
                && named
                    .iter()
                    .any(|a| a.starts_with(&format!("{}:", e.effect)))
                && e.reason.contains("an equal alternative")
        })
        .collect();
    for i in alternatives {
        let Some(model) = work.judged_model(i).cloned() else {
            continue;
        };
        let (train, validation, spans) = judged_tests(steps, &work.effects[i]);
        let Some((made_before, made_after)) = work
            .band_runs_made(given, &spans)
            .zip(work.band_runs_made(&model, &spans))
        else {
            continue;
        };
        let before_runs = draws_against(before, &made_before, tolerance);
        // The alternative has no show run: its draws are the judge's runs alone.
        let after_runs: Vec<Vec<StepScores>> = (made_after.iter())
            .map(|r| scored_as(after, r, tolerance))
            .collect();
        let (Some(b), Some(a)) = (
            set_error_over(&before_runs, &train, &validation),
            set_error_over(&after_runs, &train, &validation),
        ) else {
            continue;
        };
        reported_with_spread(
            &mut work.effects[i],
            (b, a),
            &format!(
                "as the accepted effect's: the judge's {} runs of this model against the fixed model's spreads",
                after_runs.len()
            ),
            json!({
                "draws_before": before_runs.len(),
                "draws_after": after_runs.len(),
                "per_step": "the median over the draws of the step's mean squared score; before, the locate run and the judge's runs of the model as given against the locate run's spreads; after, the judge's runs of this effect's model against the show run's spreads (the fixed model's)",
            }),
        );
    }
}

/// The runs `draw` of a model scored against the spreads of `show`'s comparison of the same
/// steps (matched by test and step, features by channel and feature); a step `show` did not
/// compare is left out.
fn scored_as(
    show: &[StepScores],
    draw: &[StepScores],
    tolerance: &ComparisonTolerance,
) -> Vec<StepScores> {
    draw.iter()
        .filter_map(|d| {
            let s = (show.iter()).find(|s| s.test_index == d.test_index && s.step == d.step)?;
            let features = (s.features.iter())
                .filter_map(|f| {
                    let x = (d.features.iter())
                        .find(|x| x.channel == f.channel && x.feature == f.feature)?;
                    Some(f.with_model_value(x.model, tolerance))
                })
                .collect();
            Some(StepScores {
                features,
                ..s.clone()
            })
        })
        .collect()
}

/// The validation error of the model as given (`before`) and of the fixed model (`after`)
/// on `tests`, every step compared with the comparison's spread (the impact band's windows
/// with the ensemble and the finer model, the others pointwise); None where a side has no
/// compared step.
fn validation_with_spread(
    steps: &SessionSteps,
    tests: &[String],
    before: &[StepScores],
    after: &[StepScores],
) -> Option<ValidationWithSpread> {
    let indices = steps.indices_of(tests);
    let b = set_error(before, &indices, Steps::All)?;
    let a = set_error(after, &indices, Steps::All)?;
    Some(ValidationWithSpread {
        tests: tests.to_vec(),
        before: b,
        after: a,
    })
}

/// The `discretisation` effect of a band whose steps score above the threshold pointwise
/// (`pointwise`, the fixed model's regime) while the impact-free steps match: within the
/// comparison's spread (`band`; the model as given's, `given`, where the fixed model's band
/// was not run) the twin's own truncation and the band's chaos; beyond it, contact physics
/// the stages did not identify. Never accepted: not a model extension.
fn discretisation(
    pointwise: &RegimeScores,
    band: Option<&BandSpread>,
    given: bool,
    threshold: f64,
) -> EffectResult {
    let seen = format!(
        "{} of {} impact-band steps score above {threshold} pointwise (median largest score {:.2}) while the impact-free steps match",
        pointwise.steps_above, pointwise.steps, pointwise.median_max_score
    );
    let reason = match band {
        Some(b) => {
            let spread = format!(
                "with the comparison's spread{} (an ensemble of {} from perturbed states{}) {} of {} do, median {:.2}",
                if given { ", the model as given," } else { "" },
                b.members,
                b.finer_modes
                    .map(|m| format!(" and a finer model of {m} modes"))
                    .unwrap_or_default(),
                b.scores.steps_above,
                b.scores.steps,
                b.scores.median_max_score
            );
            if b.beyond {
                format!("{seen}; {spread}: beyond the model's chaos and its discretisation, so contact physics the model leaves out that no stage identified")
            } else {
                format!("{seen}; {spread}: the band's chaos and the twin's own modal truncation and time step, not missing physics")
            }
        }
        None => format!("{seen}: the twin's modal truncation and time step (the null case of the nominal twin shows about a third of the impact-band steps above 3) or contact physics the session cannot separate; not a model extension"),
    };
    EffectResult {
        effect: "discretisation".into(),
        rank: 0,
        accepted: false,
        parameters: json!({}),
        alternatives: if band.is_some_and(|b| !b.beyond) {
            Vec::new()
        } else {
            vec!["tilt".into(), "clearance".into(), "wear".into()]
        },
        evidence: json!({
            "impact_steps": pointwise.steps,
            "impact_steps_above_threshold": pointwise.steps_above,
            "median_max_score": pointwise.median_max_score,
            "with_spread": band.map(|b| json!({
                "ensemble_members": b.members,
                "finer_modes": b.finer_modes,
                "impact_steps_above_threshold": b.scores.steps_above,
                "median_max_score": b.scores.median_max_score,
                "beyond": b.beyond,
            })),
        }),
        reason,
        train_tests: Vec::new(),
        validation_tests: Vec::new(),
        error_before: None,
        error_after: None,
    }
}

/// Diagnoses the recording of `input` (module docs); `progress` hears of stages and model
/// runs.
pub fn diagnose(
    input: &DiagnoseInput<'_>,
    opts: &DiagnoseOptions,
    progress: &mut dyn FnMut(DiagnoseProgress),
) -> Result<Diagnosis, DiagnoseError> {
    let rec = input.rec;
    if rec.record_windows().next().is_none() {
        return Err(EvidenceError::NoRecordWindows.into());
    }
    let steps = SessionSteps::of(rec, input.summary);
    let given = input.cfg.model.clone();
    let as_given = Resolution {
        rom: input.rom,
        spec: input.cfg.twin.clone(),
    };

    let band_steps = (steps.steps.iter())
        .filter(|s| s.regime == Regime::Impacts)
        .count();
    let members = input.cfg.twin.ensemble_members;
    progress(DiagnoseProgress::Stage(format!(
        "locate: the model as given over the whole session ({} steps){}",
        steps.steps.len(),
        match (band_steps, members) {
            (0, _) | (_, 0) => String::new(),
            (n, m) => format!(
                "; the {n} impact-band steps also with the comparison's spread (an ensemble of {m}{})",
                if input.finer.is_some() { " and a finer model" } else { "" }
            ),
        }
    )));
    let t0 = std::time::Instant::now();
    let WholeSession {
        plain: before,
        band: band_before,
    } = whole_session(input, &as_given, &steps, &given, opts, true)?;
    let mut stages = vec![StageCost {
        stage: "locate".into(),
        model_runs: 1,
        model_rig_seconds: rec.rig_seconds(),
        model_wall_seconds: t0.elapsed().as_secs_f64(),
    }];
    let mut located: Vec<Located> = before
        .iter()
        .flat_map(|s| {
            s.features
                .iter()
                .filter(|f| f.score > opts.threshold)
                .map(|f| Located {
                    test: s.test.clone(),
                    step: s.step,
                    omega_ratio: s.omega_ratio,
                    regime: s.regime,
                    channel: f.channel.clone(),
                    feature: f.feature.clone(),
                    score: f.score,
                    measured: f.measured,
                    model: f.model,
                })
        })
        .collect();
    located.sort_by(|a, b| b.score.total_cmp(&a.score));

    let mut base = TwinModel::of_config(input.rom, input.cfg);
    base.extensions = given.clone();
    let runner = ModelRunner::new(
        rec,
        &steps,
        base,
        &input.cfg.twin,
        input.cfg.rig.beam_length,
        opts.jobs,
    );
    let mut work = Work::new(runner, &steps, opts.clone(), given.clone(), progress);

    // 1. Sensor sensitivities.
    work.stage("sensor_gain", "identify: sensor sensitivities");
    let ev = session_evidence(rec, &[])?;
    let sensors = sensor_stage(&mut work, &ev, &before)?;

    // 2. Linear frequency and damping of 1FU and 1FL.
    work.stage(
        "linear",
        "identify: linear frequency and damping of 1FU and 1FL (impact-free steps)",
    );
    let gains: Vec<(String, f64)> = work
        .accepted
        .sensor_gains
        .iter()
        .map(|g| (g.channel.clone(), g.gain))
        .collect();
    let ev = session_evidence(rec, &gains)?;
    let linear = match linear_modes_of(&ev, &LinearOptions::default()) {
        Ok(l) => Some(l),
        Err(e) => {
            work.undecided("linear_frequency", e.to_string());
            work.undecided("linear_damping", e.to_string());
            work.undecided("clamp_friction", e.to_string());
            None
        }
    };
    if let Some(lin) = &linear {
        linear_stage(&mut work, input.rom, lin)?;
        work.stage(
            "clamp_friction",
            "identify: amplitude dependence without contact (the clamp's friction)",
        );
        super::clamp::clamp_stage(&mut work, lin)?;
    }

    // The beam channels' gains once more, against the model with the linear and clamp
    // effects: a gain hides behind a beam's wrong physics in the first pass.
    let since = work
        .effects
        .iter()
        .any(|e| e.accepted && e.effect != "sensor_gain");
    let GainSplit {
        free,
        free_train,
        free_validation,
        ..
    } = GainSplit::of(&steps);
    if since && !free_train.is_empty() && !free_validation.is_empty() {
        work.stage(
            "sensor_gain_again",
            "identify: the beam channels' sensitivities against the corrected model",
        );
        super::gains::spot_gain_again(&mut work, &free, &free_train)?;
        let accepted = work.accepted.clone();
        let scores = work.scores(&accepted, &free)?;
        unpartnered_gains(&mut work, &scores, &free_train, &free_validation)?;
        // The joint fitted before a gain found now carries the gain's misfit.
        let gain_found = work.accepted.sensor_gains.len() > accepted.sensor_gains.len();
        if gain_found && work.accepted.clamp_friction.is_some() {
            work.stage(
                "clamp_friction_again",
                "identify: the clamp's friction against the model with the beam channels' gains",
            );
            super::clamp::refit_joint(
                &mut work,
                "against the model with the beam channel gain found after it",
            )?;
        }
    }

    // 3. The twin's own discretisation, before the contact effects that would absorb it.
    let staged = super::resolution::resolution_stage(&mut work, &as_given, input.refined)?;
    let discretisation_evidence = staged.evidence;
    let refined = staged.accepted;
    let resolution = refined.as_ref().map_or(&as_given, |r| &r.1);

    // 4. Clearance per test.
    work.stage(
        "clearance_per_test",
        "identify: clearance per test before the first impact",
    );
    let mut ce = clearance_per_test_of(&ev, &ClearanceOptions::of_rig(input.cfg))?;
    let before_contact = work.accepted.clone();
    work.stage(
        "wear",
        "identify: the clearance per test against the normal contact impulse before it (wear)",
    );
    let wear = super::wear::wear_stage(&mut work, &mut ce)?;
    // The clearance stage's offset: what it locates if no clearance is accepted.
    let mut fitted_offset = None;
    // NOTE: a trend the wear stage saw but did not validate is evidence against a constant
    // offset all the same: on the six-probe wear plan with 2.5e-5 m/(N s) hidden, the wear
    // was fitted within 11 % (the probes' clearances on its line within their spreads, 12.9
    // standard errors) and rejected on the probes' chaotic band, and a constant offset of
    // +141 um, the session's mean growth, was then accepted: off by -95 / -12 / +53 um at
    // the validation probes' own clearances, against spreads of 9-17 um (BENCHMARKS.md, "A
    // wear trend not validated is no constant offset").
    match wear {
        WearFound::Accepted => work.undecided(
            "tilt",
            "not fitted on top of the wear: the clearance changes over the session, and a tilt's early edge contact would be fitted against a moving clearance",
        ),
        WearFound::TrendOnly => {
            work.undecided(
                "clearance",
                "not fitted as a constant offset: the clearance per test moves with the contact impulse (the wear's trend, undecided), and an offset would be fitted against a moving clearance",
            );
            work.undecided(
                "tilt",
                "not fitted: the clearance per test moves with the contact impulse (the wear's trend, undecided), and a tilt's early edge contact would be fitted against a moving clearance",
            );
        }
        WearFound::NoTrend | WearFound::TrendAcrossLevels { .. } => {
            work.stage(
                "clearance",
                "identify: the clearance as an offset to the plan's (model runs within the brackets)",
            );
            fitted_offset = clearance_stage(&mut work, &ce)?;
            work.stage(
                "tilt",
                "identify: tilt against the clearance (contact-regime statistics)",
            );
            let rom = work.runner.rom();
            super::tilt::tilt_stage(&mut work, rom, &before_contact, &ce)?;
        }
    }
    if let WearFound::TrendAcrossLevels { levels, trend } = wear {
        levels_trend(&mut work, &levels, &trend);
    }
    let clearance = Some(ce);

    // Show: the whole session with the accepted effects.
    work.end_stage();
    stages.append(&mut work.stage_costs);
    let any = work.effects.iter().any(|e| e.accepted);
    let (after, band_after) = if any {
        (work.progress)(DiagnoseProgress::Stage(
            "show: the fixed model over the whole session".into(),
        ));
        let t = std::time::Instant::now();
        // The band once more where the model as given was beyond its spread: whether the
        // accepted effects bring it within; and with the twin's discretisation refined: the
        // discretisation member's part of the spread was the coarse twin's own error.
        let band = band_before.as_ref().is_some_and(|(b, _)| b.beyond) || refined.is_some();
        let s = whole_session(input, resolution, &steps, &work.accepted, opts, band)?;
        stages.push(StageCost {
            stage: "show".into(),
            model_runs: 1,
            model_rig_seconds: rec.rig_seconds(),
            model_wall_seconds: t.elapsed().as_secs_f64(),
        });
        (s.plain, s.band)
    } else {
        (before.clone(), None)
    };
    let refined_twin = refined.map(|r| r.0);
    let lone = match (&band_before, &band_after) {
        (Some((_, b)), Some((_, a))) => {
            lone_band_effect_with_spread(&mut work, &given, &input.cfg.twin.tolerance, b, a)
        }
        _ => None,
    };
    let mut validation_tests: Vec<String> = (work.effects.iter())
        .filter(|e| e.accepted)
        .flat_map(|e| e.validation_tests.clone())
        .collect();
    validation_tests.sort();
    validation_tests.dedup();
    // With the twin's discretisation refined, the model as given's spread holds that
    // twin's own discretisation error (its discretisation member's difference): no before.
    // A lone band effect's are over its draws (the same tests: its validation tests).
    let with_spread = match (&band_before, &band_after, lone) {
        (_, _, Some((b, a))) if refined_twin.is_none() => Some(ValidationWithSpread {
            tests: validation_tests.clone(),
            before: b.validation,
            after: a.validation,
        }),
        (Some((_, b)), Some((_, a)), _) if refined_twin.is_none() => {
            validation_with_spread(&steps, &validation_tests, b, a)
        }
        _ => None,
    };
    let band_before = band_before.map(|(b, _)| b);
    let band_after = band_after.map(|(b, _)| b);
    let regimes_before = regimes(&before, opts.threshold);
    let regimes_after = regimes(&after, opts.threshold);
    // The impact band is judged with the comparison's spread: pointwise, its steps score
    // above the threshold where the model is right (BENCHMARKS.md, "The impact band's
    // verdict").
    let band = band_after.as_ref().or(band_before.as_ref());
    if band.is_none() && regimes_after.iter().any(|r| r.regime == Regime::Impacts) {
        work.undecided(
            "discretisation",
            "the impact band: no ensemble ([twin] ensemble_members = 0), so no spread to judge its non-periodic steps against",
        );
    }
    // The twin's own truncation: impact-band mismatches where the impact-free steps match.
    let free_ok = regimes_after
        .iter()
        .filter(|r| r.regime != Regime::Impacts)
        .all(|r| r.median_max_score <= opts.threshold);
    if let Some(r) = regimes_after.iter().find(|r| r.regime == Regime::Impacts) {
        if r.steps_above > 0 && free_ok {
            let given = any && band_after.is_none();
            let note = discretisation(r, band, given, opts.threshold);
            match work
                .effects
                .iter_mut()
                .find(|e| e.effect == "discretisation")
            {
                // The stage judged the twin refined: the band's note joins its result.
                Some(e) => {
                    e.evidence["impact_band"] = note.evidence;
                    let whose = if e.accepted {
                        "the fixed model's"
                    } else {
                        "the"
                    };
                    e.reason = format!("{}; {whose} impact band: {}", e.reason, note.reason);
                }
                None => work.effects.push(note),
            }
        }
    }

    // Impact-free steps are periodic and their spread is small: a regime whose typical step
    // scores above the threshold is a mismatch even when no effect explains it. The impact
    // band is judged so with the comparison's spread.
    let free_mismatch = regimes_after
        .iter()
        .filter(|r| r.regime != Regime::Impacts)
        .any(|r| r.median_max_score > opts.threshold);
    let band_mismatch = band.is_some_and(|b| b.beyond);
    // A clearance offset not accepted but far beyond its error on the tests it was fitted
    // on: the first contact there is not the model's, whatever the cause (as a trend of the
    // clearance over the session that no effect explained is: the wear stage's, already in
    // `work.unexplained`).
    if let Some(why) = (fitted_offset.as_ref()).and_then(|f| unexplained_offset(f, &work.effects)) {
        work.undecided("clearance", why.clone());
        work.unexplained.push(why);
    }
    let contact_mismatch = !work.unexplained.is_empty();
    let verdict = if any || free_mismatch || band_mismatch || contact_mismatch {
        Verdict::Mismatch
    } else {
        Verdict::NoSignificantMismatch
    };
    // Ranks: accepted first, in identification order, then the rest.
    let mut effects = std::mem::take(&mut work.effects);
    effects.sort_by_key(|e| !e.accepted);
    for (i, e) in effects.iter_mut().enumerate() {
        e.rank = i + 1;
    }
    let cost = DiagnosisCost {
        model_runs: stages.iter().map(|c| c.model_runs).sum(),
        model_rig_seconds: stages.iter().map(|c| c.model_rig_seconds).sum(),
        model_wall_seconds: stages.iter().map(|c| c.model_wall_seconds).sum(),
        stages,
    };
    Ok(Diagnosis {
        verdict,
        threshold: opts.threshold,
        located,
        scores_before: before,
        scores_after: if any { after } else { Vec::new() },
        regimes_before,
        regimes_after,
        band_before,
        band_after,
        effects,
        undecided: work.undecided,
        model_before: given,
        model_after: work.accepted,
        discretisation_after: refined_twin,
        discretisation: discretisation_evidence,
        model: None,
        validation_tests,
        validation_with_spread: with_spread,
        sensors,
        linear,
        clearance,
        cost,
        wall_seconds: 0.0,
    })
}

/// After the clearance and tilt stages, a wear `trend` (in words) that runs between drive
/// levels only (`levels`, in words): the wear's undecided reason says so; an accepted clearance
/// offset or tilt names the trend among its alternatives (the level's reading of its contact),
/// else the trend stays unexplained.
fn levels_trend(work: &mut Work<'_>, levels: &str, trend: &str) {
    for u in work.undecided.iter_mut().filter(|u| u.effect == "wear") {
        u.reason = format!(
            "{}; {levels}, so the clearance as an offset and the tilt were fitted as well",
            u.reason
        );
    }
    let explained = (work.effects.iter_mut())
        .filter(|e| e.accepted && (e.effect == "clearance" || e.effect == "tilt"))
        .map(|e| {
            e.alternatives.push(format!(
                "wear: {trend}, but {levels}; read by the flat model's runs, this effect's contact changes with the level as well"
            ))
        })
        .count();
    if explained == 0 {
        work.unexplained.push(format!(
            "wear: {trend}, between drive levels only, and no effect fitted to it was accepted"
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(test_index: usize, step: usize, model: f64, model_spread: f64) -> StepScores {
        let m = FeatureComparison {
            channel: "upper_tip".into(),
            feature: "amp_p50".into(),
            measured: 10.0,
            measured_spread: Some(0.5),
            model,
            model_spread: Some(model_spread),
            score: (model - 10.0).abs() / (0.25 + model_spread * model_spread).sqrt(),
        };
        StepScores {
            test: format!("t{test_index}"),
            test_index,
            step,
            omega_ratio: 1.0,
            regime: Regime::Impacts,
            level: 6e-5,
            features: vec![m],
        }
    }

    /// A draw takes the show run's spreads at the same test and step (its own pointwise spread
    /// is not the ensemble's); a step the show run did not compare is left out; over three
    /// draws a step's median is the typical draw's, not the one that landed elsewhere.
    #[test]
    fn draws_are_scored_against_the_show_runs_spreads() {
        let tol = ComparisonTolerance {
            relative: 0.0,
            contact_fraction: 0.0,
            impacts_per_period: 0.0,
        };
        let show = vec![step(1, 0, 11.0, 2.0), step(1, 1, 30.0, 2.0)];
        let draw = vec![
            step(1, 0, 12.0, 0.1),
            step(1, 1, 11.0, 0.1),
            step(1, 2, 9.0, 0.1),
        ];
        let scored = scored_as(&show, &draw, &tol);
        assert_eq!(scored.len(), 2);
        let f = &scored[0].features[0];
        assert_eq!((f.model, f.model_spread), (12.0, Some(2.0)));
        assert!((f.score - 2.0 / 4.25f64.sqrt()).abs() < 1e-12);
        // Step 1: the show run landed on another branch (20 / 2.06), two draws did not.
        let other = vec![step(1, 0, 10.5, 0.1), step(1, 1, 10.0, 0.1)];
        let runs = vec![show.clone(), scored, scored_as(&show, &other, &tol)];
        let median = members_error(&runs, &[1], Steps::All, None).unwrap();
        let one = members_error(&runs[..1], &[1], Steps::All, None).unwrap();
        assert!(median < 0.6 && one > 6.0, "{median} {one}");
    }
}
