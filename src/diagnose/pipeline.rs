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
//!    - `wear` ([`super::wear`]): the clearance per test ([`super::clearance`], refined by
//!      model runs, `clearance_fit`) growing with the model's normal contact impulse;
//!    - `clearance` (`clearance_fit`): as an offset to the plan's when the tests
//!      agree; `tilt` (`tilt`): a tilted face against that offset.
//! 3. **Select**: each candidate is fitted on some tests (`train`) and judged on others
//!    (`validation`) by model runs with and without it ([`ModelRunner`]); the error is the RMS
//!    of the compared features' scores over the regime the effect shows in. It is accepted
//!    only if the validation error falls by more than the null spread plus a penalty per
//!    parameter; rejected candidates are reported with the reason.
//!
//! A diagnosis never reads the simulated rig's hidden physics: its inputs are the recording
//! (DAQ counts, layout, events), its replayed summary and the model, from whose rig
//! description the caller has removed the simulated rig's tables.

use serde_json::json;

use crate::config::{PhysicsSpec, RigConfig};
use crate::rom::Rom;
use crate::session::replay::Recording;
use crate::session::summary::SessionSummary;
use crate::session::twin_replay::{replay_twin, EnsembleOptions};
use crate::twin::{TwinModel, TwinSpec};

use super::clearance::{clearance_per_test_of, ClearanceOptions};
use super::clearance_fit::clearance_stage;
use super::evidence::session_evidence;
use super::gains::{sensor_stage, unpartnered_gains, GainSplit};
use super::judge::{DiagnoseOptions, DiagnoseProgress, Work};
use super::linear::{linear_modes_of, LinearOptions};
use super::modes::linear_stage;
use super::outcome::{
    Diagnosis, DiagnosisCost, EffectResult, Located, Regime, RegimeScores, StageCost, StepScores,
    Verdict,
};
use super::rerun::{ModelRunner, SessionSteps};
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

/// The whole session re-run with extensions `ext` (the `replay --twin` of the fixed model).
fn whole_session(
    input: &DiagnoseInput<'_>,
    steps: &SessionSteps,
    ext: &PhysicsSpec,
) -> Result<Vec<StepScores>, DiagnoseError> {
    let mut summary = input.summary.clone();
    let mut model = TwinModel::of_config(input.rom, input.cfg);
    model.extensions = ext.clone();
    let mut spec: TwinSpec = input.cfg.twin.clone();
    spec.ensemble_members = 0;
    replay_twin(
        input.rec,
        &mut summary,
        &model,
        &spec,
        input.cfg.rig.beam_length,
        EnsembleOptions::NONE,
        &mut (),
    )?;
    Ok(steps
        .steps
        .iter()
        .zip(summary.steps())
        .map(|(s, r)| {
            s.scores(
                r.twin
                    .as_ref()
                    .map(|t| t.features.clone())
                    .unwrap_or_default(),
            )
        })
        .collect())
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

    progress(DiagnoseProgress::Stage(format!(
        "locate: the model as given over the whole session ({} steps)",
        steps.steps.len()
    )));
    let t0 = std::time::Instant::now();
    let before = whole_session(input, &steps, &given)?;
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
        let accepted = work.accepted.clone();
        let scores = work.scores(&accepted, &free)?;
        unpartnered_gains(&mut work, &scores, &free_train, &free_validation)?;
    }

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
    let worn = super::wear::wear_stage(&mut work, &mut ce)?;
    if worn {
        work.undecided(
            "tilt",
            "not fitted on top of the wear: the clearance changes over the session, and a tilt's early edge contact would be fitted against a moving clearance",
        );
    } else {
        work.stage(
            "clearance",
            "identify: the clearance as an offset to the plan's (model runs within the brackets)",
        );
        clearance_stage(&mut work, &ce)?;
        work.stage(
            "tilt",
            "identify: tilt against the clearance (contact-regime statistics)",
        );
        super::tilt::tilt_stage(&mut work, input.rom, &before_contact, &ce)?;
    }
    let clearance = Some(ce);

    // Show: the whole session with the accepted effects.
    work.end_stage();
    stages.append(&mut work.stage_costs);
    let any = work.effects.iter().any(|e| e.accepted);
    let after = if any {
        (work.progress)(DiagnoseProgress::Stage(
            "show: the fixed model over the whole session".into(),
        ));
        let t = std::time::Instant::now();
        let s = whole_session(input, &steps, &work.accepted)?;
        stages.push(StageCost {
            stage: "show".into(),
            model_runs: 1,
            model_rig_seconds: rec.rig_seconds(),
            model_wall_seconds: t.elapsed().as_secs_f64(),
        });
        s
    } else {
        before.clone()
    };
    let regimes_before = regimes(&before, opts.threshold);
    let regimes_after = regimes(&after, opts.threshold);
    // The twin's own truncation: impact-band mismatches where the impact-free steps match.
    let free_ok = regimes_after
        .iter()
        .filter(|r| r.regime != Regime::Impacts)
        .all(|r| r.median_max_score <= opts.threshold);
    if let Some(r) = regimes_after.iter().find(|r| r.regime == Regime::Impacts) {
        if r.steps_above > 0 && free_ok {
            work.effects.push(EffectResult {
                effect: "discretisation".into(),
                rank: 0,
                accepted: false,
                parameters: json!({}),
                alternatives: vec!["tilt".into(), "clearance".into()],
                evidence: json!({
                    "impact_steps": r.steps,
                    "impact_steps_above_threshold": r.steps_above,
                    "median_max_score": r.median_max_score,
                }),
                reason: format!(
                    "{} of {} impact-band steps score above {} while the impact-free steps match: the twin's modal truncation and time step (the null case of the nominal twin shows about a third of the impact-band steps above 3) or contact physics the session cannot separate; not a model extension",
                    r.steps_above, r.steps, opts.threshold
                ),
                train_tests: Vec::new(),
                validation_tests: Vec::new(),
                error_before: None,
                error_after: None,
            });
        }
    }

    // Impact-free steps are periodic and their spread is small: a regime whose typical step
    // scores above the threshold is a mismatch even when no effect explains it.
    let free_mismatch = regimes_after
        .iter()
        .filter(|r| r.regime != Regime::Impacts)
        .any(|r| r.median_max_score > opts.threshold);
    let verdict = if any || free_mismatch {
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
    let mut validation_tests: Vec<String> = effects
        .iter()
        .filter(|e| e.accepted)
        .flat_map(|e| e.validation_tests.clone())
        .collect();
    validation_tests.sort();
    validation_tests.dedup();
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
        effects,
        undecided: work.undecided,
        model_before: given,
        model_after: work.accepted,
        model: None,
        validation_tests,
        sensors,
        linear,
        clearance,
        cost,
        wall_seconds: 0.0,
    })
}
