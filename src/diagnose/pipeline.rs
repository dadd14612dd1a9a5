//! The diagnosis ([`diagnose`]): locate the mismatch, name the physics the model left out, fit
//! it, keep it only if it predicts tests it was not fitted on (DESIGN.md, "Diagnosis").
//!
//! 1. **Locate**: the twin (the model as given) re-run over the whole session, every step's
//!    features scored against the measurement with both spreads
//!    ([`crate::twin::TwinComparison`]), grouped by regime.
//! 2. **Identify and fit**, in the order in which effects confound each other, each on top
//!    of the effects accepted before it:
//!    - `sensor_gain`: the redundant channels' ratios ([`super::sensors`]); for a channel
//!      without a redundant partner, the measured/model ratio over the impact-free steps:
//!      flat in frequency and different from its beam's other channel;
//!    - `linear_frequency`, `linear_damping` of 1FU and 1FL: the impact-free fits
//!      ([`super::linear`]) at the lowest level (at zero amplitude where the clamp's friction
//!      shows);
//!    - `clamp_friction`: the frequency falling and the damping rising with the amplitude; the
//!      slopes fix the ratio of the joint's stiffness share to its slip amplitude, model runs
//!      over a few stiffness shares fix the rest;
//!    - `clearance`: the clearance per test before the first impact ([`super::clearance`]),
//!      as an offset to the plan's when the tests agree.
//! 3. **Select**: each candidate is fitted on some tests (`train`) and judged on others
//!    (`validation`) by model runs with and without it ([`ModelRunner`]); the error is the RMS
//!    of the compared features' scores over the regime the effect shows in. It is accepted
//!    only if the validation error falls by more than the null spread plus a penalty per
//!    parameter; rejected candidates are reported with the reason.
//!
//! A diagnosis never reads the simulated rig's hidden physics: its inputs are the recording
//! (DAQ counts, layout, events), its replayed summary and the model, from whose rig
//! description the caller has removed the simulated rig's tables.

use std::f64::consts::PI;

use serde_json::json;

use crate::config::{ClearanceSpec, ModalCorrectionSpec, PhysicsSpec, RigConfig, SensorGainSpec};
use crate::rom::Rom;
use crate::session::replay::Recording;
use crate::session::summary::SessionSummary;
use crate::session::twin_replay::{replay_twin, EnsembleOptions};
use crate::twin::{TwinModel, TwinSpec};

use super::clearance::{clearance_per_test_of, ClearanceOptions};
use super::evidence::{session_evidence, SessionEvidence};
use super::judge::{
    alternate, set_error, Candidate, DiagnoseOptions, DiagnoseProgress, Steps, Work,
};
use super::linear::{linear_modes_of, LinearEvidence, LinearOptions, ModeFit};
use super::outcome::{
    Diagnosis, DiagnosisCost, EffectResult, Located, Regime, RegimeScores, SetError, StepScores,
    Verdict,
};
use super::rerun::{ModelRunner, SessionSteps};
use super::sensors::{sensor_sensitivities_of, SensitivityStatus, SensorOptions};
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

/// The tests split for the sensor gains: all of them alternately, and the impact-free ones
/// (with at least one impact-free step) as they fall in that split.
struct GainSplit {
    train: Vec<usize>,
    validation: Vec<usize>,
    free: Vec<usize>,
    free_train: Vec<usize>,
    free_validation: Vec<usize>,
}

impl GainSplit {
    fn of(steps: &SessionSteps) -> GainSplit {
        let all: Vec<usize> = (0..steps.tests.len()).collect();
        let (train, validation) = alternate(&all);
        let free = steps.tests_with(true);
        let within = |set: &[usize]| free.iter().copied().filter(|t| set.contains(t)).collect();
        GainSplit {
            free_train: within(&train),
            free_validation: within(&validation),
            train,
            validation,
            free,
        }
    }
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
    let mut cost = DiagnosisCost {
        model_runs: 1,
        model_rig_seconds: rec.rig_seconds(),
        model_wall_seconds: t0.elapsed().as_secs_f64(),
    };
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
    (work.progress)(DiagnoseProgress::Stage(
        "identify: sensor sensitivities".into(),
    ));
    let ev = session_evidence(rec, &[])?;
    let sensors = sensor_stage(&mut work, &ev, &before)?;

    // 2. Linear frequency and damping of 1FU and 1FL.
    (work.progress)(DiagnoseProgress::Stage(
        "identify: linear frequency and damping of 1FU and 1FL (impact-free steps)".into(),
    ));
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
        (work.progress)(DiagnoseProgress::Stage(
            "identify: amplitude dependence without contact (the clamp's friction)".into(),
        ));
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
        (work.progress)(DiagnoseProgress::Stage(
            "identify: the beam channels' sensitivities against the corrected model".into(),
        ));
        let accepted = work.accepted.clone();
        let scores = work.scores(&accepted, &free)?;
        unpartnered_gains(&mut work, &scores, &free_train, &free_validation)?;
    }

    // 4. Clearance per test.
    (work.progress)(DiagnoseProgress::Stage(
        "identify: clearance per test before the first impact".into(),
    ));
    let mut ce = clearance_per_test_of(&ev, &ClearanceOptions::of_rig(input.cfg))?;
    let before_contact = work.accepted.clone();
    (work.progress)(DiagnoseProgress::Stage(
        "identify: the clearance per test against the contact work before it (wear)".into(),
    ));
    let worn = super::wear::wear_stage(&mut work, &mut ce)?;
    if worn {
        work.undecided(
            "tilt",
            "not fitted on top of the wear: the clearance changes over the session, and a tilt's early edge contact would be fitted against a moving clearance",
        );
    } else {
        clearance_stage(&mut work, &ce)?;
        (work.progress)(DiagnoseProgress::Stage(
            "identify: tilt against the clearance (contact-regime statistics)".into(),
        ));
        super::tilt::tilt_stage(&mut work, input.rom, &before_contact, &ce)?;
    }
    let clearance = Some(ce);

    // Show: the whole session with the accepted effects.
    let any = work.effects.iter().any(|e| e.accepted);
    let after = if any {
        (work.progress)(DiagnoseProgress::Stage(
            "show: the fixed model over the whole session".into(),
        ));
        let t = std::time::Instant::now();
        let s = whole_session(input, &steps, &work.accepted)?;
        cost.model_runs += 1;
        cost.model_rig_seconds += rec.rig_seconds();
        cost.model_wall_seconds += t.elapsed().as_secs_f64();
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
    cost.model_runs += work.runner.cost.runs;
    cost.model_rig_seconds += work.runner.cost.rig_seconds;
    cost.model_wall_seconds += work.runner.cost.wall_seconds;
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

/// The measured/model ratio of feature `rms` of `channel` over the impact-free steps of
/// `tests`, robustly (a few steps near a resonance the model places slightly off must not
/// hide a flat ratio): (median, its standard error, spread of the per-step ratios from their
/// median absolute deviation).
fn channel_ratio(scores: &[StepScores], channel: &str, tests: &[usize]) -> Option<(f64, f64, f64)> {
    let mut r: Vec<f64> = scores
        .iter()
        .filter(|s| s.regime != Regime::Impacts && tests.contains(&s.test_index))
        .filter_map(|s| {
            s.features
                .iter()
                .find(|f| f.channel == channel && f.feature == "rms")
                .filter(|f| f.model > 0.0 && f.measured > 0.0)
                .map(|f| f.measured / f.model)
        })
        .collect();
    if r.len() < 3 {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    let m = median(&mut r);
    let mut dev: Vec<f64> = r.iter().map(|x| (x - m).abs()).collect();
    // NOTE: 1.4826 MAD estimates the standard deviation of normal scatter; the median's
    // standard error is 1.2533 sigma / sqrt(n).
    let sd = 1.4826 * median(&mut dev);
    Some((m, 1.2533 * sd / (r.len() as f64).sqrt(), sd))
}

fn with_gain(ext: &PhysicsSpec, channel: &str, gain: f64) -> PhysicsSpec {
    let mut e = ext.clone();
    e.sensor_gains.retain(|g| g.channel != channel);
    e.sensor_gains.push(SensorGainSpec {
        channel: channel.to_string(),
        gain,
    });
    e
}

/// Stage 1: sensor sensitivities.
fn sensor_stage(
    work: &mut Work<'_>,
    ev: &SessionEvidence,
    before: &[StepScores],
) -> Result<Option<super::sensors::SensorEvidence>, DiagnoseError> {
    let GainSplit {
        train,
        validation,
        free,
        free_train,
        free_validation,
    } = GainSplit::of(work.steps);
    // The redundant channels' estimate on the train tests only.
    let train_names = work.names(&train);
    let mut ev_train = ev.clone();
    ev_train.windows.retain(|w| train_names.contains(&w.test));
    let opts = SensorOptions::default();
    let sens = if ev_train.windows.is_empty() {
        None
    } else {
        Some(sensor_sensitivities_of(&ev_train, &opts))
    };
    if validation.is_empty() {
        work.undecided(
            "sensor_gain",
            "a single test: nothing to validate a gain on",
        );
        return Ok(sens);
    }
    let Some(sens) = sens else {
        return Ok(None);
    };
    // The same estimate on the validation tests (the platform gains' judge).
    let validation_names = work.names(&validation);
    let mut ev_validation = ev.clone();
    ev_validation
        .windows
        .retain(|w| validation_names.contains(&w.test));
    let sens_validation = sensor_sensitivities_of(&ev_validation, &opts);
    for c in &sens.channels {
        if c.status == SensitivityStatus::Off {
            let gain = c.gain.unwrap_or(1.0);
            let platform = sens
                .platform_ratios
                .iter()
                .any(|r| r.numerator == c.channel);
            let cand = Candidate {
                effect: "sensor_gain",
                ext: with_gain(&work.accepted, &c.channel, gain),
                parameters: json!({"channel": c.channel, "gain": gain}),
                n_params: 1,
                evidence: json!({"redundant_channels": c.reason, "standard_error": c.standard_error}),
                alternatives: Vec::new(),
                train: train.clone(),
                validation: validation.clone(),
                steps: Steps::ImpactFree,
                channel: (!platform).then(|| c.channel.clone()),
            };
            if platform {
                // NOTE: a platform accelerometer's gain moves the base the model consumes by
                // a third of it (the mean of three), within the comparison's tolerance for a
                // gain of a few percent: model runs cannot judge it. Its own observation model
                // can — every platform accelerometer sees one base — so it is judged on its
                // ratio to the others' mean over the validation tests' windows.
                let of = |ev: &super::sensors::SensorEvidence| {
                    ev.platform_ratios
                        .iter()
                        .find(|r| r.numerator == c.channel)
                        .map(|r| (r.ratio, r.spread))
                };
                let (before, after) =
                    redundancy_errors(of(&sens), of(&sens_validation), gain, &opts);
                let mut cand = cand;
                cand.evidence["judged_on"] =
                    json!("its ratio to the other platform accelerometers' mean");
                work.judge_on(cand, "the platform channels' ratios", before, after);
            } else {
                work.judge(cand)?;
            }
        }
    }
    // The vibrometer and the upper-tip accelerometer disagree: the model tells which.
    if let Some(r) = &sens.upper_tip_over_vibrometer {
        if !r.is_one(&opts) && !free_train.is_empty() && !free_validation.is_empty() {
            let mut tried = Vec::new();
            for (channel, gain) in [("upper_tip", r.ratio), ("vibrometer", 1.0 / r.ratio)] {
                let ext = with_gain(&work.accepted, channel, gain);
                let mut all_t: Vec<usize> = free.clone();
                all_t.sort_unstable();
                let s = work.scores(&ext, &all_t)?;
                tried.push((
                    channel,
                    gain,
                    set_error(&s, &free_train, Steps::ImpactFree).unwrap_or(f64::INFINITY),
                ));
            }
            tried.sort_by(|a, b| a.2.total_cmp(&b.2));
            let (channel, gain, best) = tried[0];
            let (other, _, second) = tried[1];
            let alternatives = if second - best <= work.opts.null_spread {
                vec![format!("sensor_gain of {other}: the train error is within the null spread ({best:.3} vs {second:.3})")]
            } else {
                Vec::new()
            };
            let cand = Candidate {
                effect: "sensor_gain",
                ext: with_gain(&work.accepted, channel, gain),
                parameters: json!({"channel": channel, "gain": gain}),
                n_params: 1,
                evidence: json!({"upper_tip_over_vibrometer": r.ratio, "standard_error": r.standard_error, "train_error_upper_tip": tried.iter().find(|t| t.0 == "upper_tip").map(|t| t.2), "train_error_vibrometer": tried.iter().find(|t| t.0 == "vibrometer").map(|t| t.2), "judged_on": "the two channels' ratio over the validation tests; the model's train error chose the channel"}),
                alternatives,
                train: train.clone(),
                validation: validation.clone(),
                steps: Steps::ImpactFree,
                channel: Some(channel.to_string()),
            };
            // NOTE: judged like a platform gain, on the redundancy (one spot, two sensors)
            // over the validation tests: model runs on tests where the upper beam hardly
            // moves (1FL) judge the vibrometer by its noise floor (hidden vibrometer 0.97:
            // found 0.9699, train error 1.14 -> 0.07, rejected on the 1FL tests 1.50 ->
            // 1.62). Which of the two is off stays the model's call, above.
            let ratio_of = |ev: &super::sensors::SensorEvidence| {
                ev.upper_tip_over_vibrometer.as_ref().map(|q| {
                    if channel == "upper_tip" {
                        (q.ratio, q.spread)
                    } else {
                        (1.0 / q.ratio, q.spread / (q.ratio * q.ratio))
                    }
                })
            };
            // A gain is flat in frequency: a ratio that drifts with it is something else
            // (the model's judgement on the impact-free steps, below).
            let flat = match (r.slope_per_omega_ratio, r.slope_standard_error) {
                (Some(slope), Some(se)) => slope.abs() <= opts.significance * se,
                _ => true,
            };
            if !flat {
                let mut cand = cand;
                cand.train = free_train.clone();
                cand.validation = free_validation.clone();
                cand.evidence["judged_on"] =
                    json!("the model: the two channels' ratio varies with the frequency");
                work.judge(cand)?;
            } else {
                let (before, after) =
                    redundancy_errors(ratio_of(&sens), ratio_of(&sens_validation), gain, &opts);
                work.judge_on(cand, "the two channels' ratio", before, after);
            }
        }
    }
    // Channels without a redundant partner: measured over model, flat in frequency, and
    // unlike the beam's other channel.
    if free_train.is_empty() || free_validation.is_empty() {
        work.undecided(
            "sensor_gain",
            "the beams' channels without a redundant partner need impact-free steps in two tests (one to fit, one to validate)",
        );
        return Ok(Some(sens));
    }
    unpartnered_gains(work, before, &free_train, &free_validation)?;
    Ok(Some(sens))
}

/// The errors of a redundant channel before (gain 1) and after (gain `gain`) on the train and
/// validation tests, from its (ratio, spread) to its partners on each ([`redundancy_error`]);
/// None where a set has no ratio.
fn redundancy_errors(
    train: Option<(f64, f64)>,
    validation: Option<(f64, f64)>,
    gain: f64,
    opts: &SensorOptions,
) -> (Option<SetError>, Option<SetError>) {
    let (Some(t), Some(v)) = (train, validation) else {
        return (None, None);
    };
    let err = |(ratio, spread): (f64, f64), g: f64| {
        redundancy_error(ratio, spread, g, opts.min_deviation)
    };
    (
        Some(SetError {
            train: err(t, 1.0),
            validation: err(v, 1.0),
        }),
        Some(SetError {
            train: err(t, gain),
            validation: err(v, gain),
        }),
    )
}

/// The error of a redundant channel whose ratio to its partners is `ratio` (per-window spread
/// `spread`) once divided by the gain `gain`: |ratio / gain - 1| in units of the relative
/// spread, which is floored at `min_deviation` (the agreement two channels of one motion
/// are allowed whatever their spread), like the comparison's scores.
fn redundancy_error(ratio: f64, spread: f64, gain: f64, min_deviation: f64) -> f64 {
    let relative = if ratio > 0.0 {
        spread / ratio
    } else {
        f64::NAN
    };
    let tolerance = if relative.is_finite() {
        relative.max(min_deviation)
    } else {
        min_deviation
    };
    (ratio / gain - 1.0).abs() / tolerance
}

/// The sensor gains of the beam channels without a redundant partner, against the model
/// whose comparison is `scores`: a measured/model ratio off 1, flat in frequency, and unlike
/// the beam's other channel (a beam's physics moves both). Channels with a gain accepted
/// already are skipped. Returns how many were accepted.
fn unpartnered_gains(
    work: &mut Work<'_>,
    scores: &[StepScores],
    free_train: &[usize],
    free_validation: &[usize],
) -> Result<usize, DiagnoseError> {
    let partner = |c: &str| match c {
        "lower_tip" => Some("lower_mid"),
        "lower_mid" => Some("lower_tip"),
        "upper_mid" => Some("upper_tip"),
        _ => None,
    };
    let mut n = 0;
    for channel in ["lower_tip", "lower_mid", "upper_mid"] {
        if work
            .accepted
            .sensor_gains
            .iter()
            .any(|g| g.channel == channel)
        {
            continue;
        }
        let Some((ratio, se, sd)) = channel_ratio(scores, channel, free_train) else {
            continue;
        };
        let Some(p) = partner(channel) else { continue };
        let Some((pr, pse, _)) = channel_ratio(scores, p, free_train) else {
            continue;
        };
        let off = (ratio - 1.0).abs() > 0.01 && (ratio - 1.0).abs() > 4.0 * se;
        let flat = sd < 0.02 * ratio;
        let unlike =
            (ratio - pr).abs() > 0.01 && (ratio - pr).abs() > 4.0 * (se * se + pse * pse).sqrt();
        if off && flat && unlike {
            let cand = Candidate {
                effect: "sensor_gain",
                ext: with_gain(&work.accepted, channel, ratio),
                parameters: json!({"channel": channel, "gain": ratio}),
                n_params: 1,
                evidence: json!({"measured_over_model": ratio, "standard_error": se, "spread_over_steps": sd, "partner": p, "partner_measured_over_model": pr}),
                alternatives: Vec::new(),
                train: free_train.to_vec(),
                validation: free_validation.to_vec(),
                steps: Steps::ImpactFree,
                channel: Some(channel.to_string()),
            };
            if work.judge(cand)? {
                n += 1;
            }
        }
    }
    Ok(n)
}

/// The model's natural frequency (Hz) and damping ratio of mode `label` under `ext`.
fn model_mode(rom: &Rom, ext: &PhysicsSpec, label: &str) -> Option<(f64, f64)> {
    let i = rom.labels.iter().position(|l| l == label)?;
    let mut f = rom.omega[i] / (2.0 * PI);
    let mut z = rom.damping_ratio[i];
    if let Some(m) = ext.modes.iter().find(|m| m.mode == label) {
        f = m.frequency_hz.unwrap_or(f);
        z = m.damping_ratio.unwrap_or(z);
    }
    Some((f, z))
}

fn with_mode(ext: &PhysicsSpec, label: &str, f: Option<f64>, z: Option<f64>) -> PhysicsSpec {
    let mut e = ext.clone();
    match e.modes.iter_mut().find(|m| m.mode == label) {
        Some(m) => {
            if f.is_some() {
                m.frequency_hz = f;
            }
            if z.is_some() {
                m.damping_ratio = z;
            }
        }
        None => e.modes.push(ModalCorrectionSpec {
            mode: label.to_string(),
            frequency_hz: f,
            damping_ratio: z,
        }),
    }
    e
}

/// The linear (zero-amplitude) frequency and damping of a mode from its fits on tests
/// `train`, with standard errors: the fits' weighted mean at the lowest level, or the
/// intercept of the amplitude dependence when it is significant.
fn linear_values(
    fits: &[&ModeFit],
    lin: &LinearEvidence,
    mode: &str,
) -> Option<(f64, f64, f64, f64)> {
    let dep = lin.amplitude_dependence.iter().find(|d| d.mode == mode);
    let lowest = fits.iter().map(|f| f.level).fold(f64::INFINITY, f64::min);
    let low: Vec<&&ModeFit> = fits
        .iter()
        .filter(|f| f.level <= lowest * (1.0 + 1e-9))
        .collect();
    if low.is_empty() {
        return None;
    }
    let wmean = |v: &dyn Fn(&ModeFit) -> (f64, f64)| {
        let (mut s, mut w) = (0.0, 0.0);
        for f in &low {
            let (x, se) = v(f);
            let wi = 1.0 / (se * se).max(1e-300);
            s += wi * x;
            w += wi;
        }
        (s / w, (1.0 / w).sqrt())
    };
    let (mut f, fse) = wmean(&|m| (m.frequency_hz, m.frequency_hz_standard_error));
    let (mut z, zse) = wmean(&|m| (m.damping_ratio, m.damping_ratio_standard_error));
    if let Some(d) = dep.filter(|d| d.clamp_friction_signature) {
        f = d.frequency_vs_amplitude.intercept;
        z = d.damping_vs_amplitude.intercept;
    }
    Some((f, fse, z, zse))
}

/// Stage 2: linear frequency and damping per mode.
fn linear_stage(work: &mut Work<'_>, rom: &Rom, lin: &LinearEvidence) -> Result<(), DiagnoseError> {
    for mode in ["1FU", "1FL"] {
        let fits: Vec<&ModeFit> = lin.fits_of(mode).collect();
        let mut tests: Vec<usize> = fits.iter().map(|f| f.test_index).collect();
        tests.dedup();
        if tests.len() < 2 {
            work.undecided(
                "linear_frequency",
                format!(
                    "{mode}: fitted in {} test(s); one to fit and one to validate are needed",
                    tests.len()
                ),
            );
            continue;
        }
        // Fit on the lowest-level tests but one; validate on the rest.
        let lowest = fits.iter().map(|f| f.level).fold(f64::INFINITY, f64::min);
        let low: Vec<usize> = fits
            .iter()
            .filter(|f| f.level <= lowest * (1.0 + 1e-9))
            .map(|f| f.test_index)
            .collect();
        let train = vec![low[0]];
        let validation: Vec<usize> = tests.iter().copied().filter(|t| *t != low[0]).collect();
        let train_fits: Vec<&ModeFit> = fits
            .iter()
            .copied()
            .filter(|f| f.test_index == low[0])
            .collect();
        let Some((f, fse, z, zse)) = linear_values(&train_fits, lin, mode) else {
            continue;
        };
        let Some((f0, z0)) = model_mode(rom, &work.accepted, mode) else {
            work.undecided("linear_frequency", format!("the model has no mode {mode}"));
            continue;
        };
        (work.progress)(DiagnoseProgress::Note(format!(
            "{mode} on {}: {f:.4} +- {fse:.4} Hz, damping {z:.5} +- {zse:.5}; the model: {f0:.4} Hz, {z0:.5}",
            work.steps.tests[low[0]]
        )));
        let evidence = json!({"mode": mode, "measured_frequency_hz": f, "standard_error_hz": fse, "model_frequency_hz": f0, "measured_damping_ratio": z, "damping_standard_error": zse, "model_damping_ratio": z0});
        if (f - f0).abs() > (3.0 * fse).max(1e-4 * f0) {
            let cand = Candidate {
                effect: "linear_frequency",
                ext: with_mode(&work.accepted, mode, Some(f), None),
                parameters: json!({"mode": mode, "frequency_hz": f}),
                n_params: 1,
                evidence: evidence.clone(),
                alternatives: Vec::new(),
                train: train.clone(),
                validation: validation.clone(),
                steps: Steps::ImpactFree,
                channel: None,
            };
            work.judge(cand)?;
        }
        if (z - z0).abs() > (3.0 * zse).max(0.05 * z0) {
            let cand = Candidate {
                effect: "linear_damping",
                ext: with_mode(&work.accepted, mode, None, Some(z)),
                parameters: json!({"mode": mode, "damping_ratio": z}),
                n_params: 1,
                evidence,
                alternatives: Vec::new(),
                train,
                validation,
                steps: Steps::ImpactFree,
                channel: None,
            };
            work.judge(cand)?;
        }
    }
    Ok(())
}

/// Stage 4: the clearance per test, as an offset to the plan's.
fn clearance_stage(
    work: &mut Work<'_>,
    ce: &super::clearance::ClearanceEvidence,
) -> Result<(), DiagnoseError> {
    let bracketed: Vec<&super::clearance::TestClearance> = ce
        .tests
        .iter()
        .filter(|t| t.clearance_m.is_some())
        .collect();
    if bracketed.len() < 2 {
        work.undecided(
            "clearance",
            format!("{} test(s) bracket the clearance (impact-free steps, then contact); two are needed, one to fit and one to validate", bracketed.len()),
        );
        return Ok(());
    }
    let idx: Vec<usize> = bracketed.iter().map(|t| t.test_index).collect();
    let (train, validation) = alternate(&idx);
    // Per train test: the clearance within its bracket whose model run matches the test best
    // (every step and channel: where the first contact falls, how much contact follows), on
    // a grid refined once around the best point; the offset to the model's clearance is the
    // mean over the train tests.
    let mut fitted = Vec::new();
    for t in bracketed.iter().filter(|t| train.contains(&t.test_index)) {
        if let Some(best) = super::wear::test_clearance_by_runs(work, t)? {
            fitted.push((*t, best.clearance_m));
        }
    }
    if fitted.is_empty() {
        return Ok(());
    }
    let current = |t: &super::clearance::TestClearance| {
        work.accepted.test_clearance(&t.test, t.plan_clearance_m)
    };
    let offs: Vec<f64> = fitted.iter().map(|(t, c)| c - current(t)).collect();
    let offset = offs.iter().sum::<f64>() / offs.len() as f64;
    let plan = bracketed[0].plan_clearance_m;
    if offset.abs() < 0.02 * plan {
        (work.progress)(DiagnoseProgress::Note(format!(
            "clearance: the fitted offset {offset:+.2e} m is within 2 % of the plan's {plan:.3e} m"
        )));
        return Ok(());
    }
    let spread = if offs.len() > 1 {
        (offs.iter().map(|o| (o - offset).powi(2)).sum::<f64>() / (offs.len() - 1) as f64).sqrt()
    } else {
        f64::NAN
    };
    let mut ext = work.accepted.clone();
    let base_offset = ext.clearance.as_ref().map_or(0.0, |c| c.offset);
    ext.clearance = Some(ClearanceSpec {
        offset: base_offset + offset,
        tests: Vec::new(),
    });
    let cand = Candidate {
        effect: "clearance",
        ext,
        parameters: json!({"offset": base_offset + offset, "tests": fitted.iter().map(|(t, c)| json!({"test": t.test, "clearance": c})).collect::<Vec<_>>()}),
        n_params: 1,
        evidence: json!({"offset_m": offset, "offset_spread_m": spread.is_finite().then_some(spread), "plan_clearance_m": plan, "brackets_m": bracketed.iter().map(|t| json!({"test": t.test, "lower": t.lower_bound_m, "upper": t.upper_bound_m})).collect::<Vec<_>>()}),
        alternatives: Vec::new(),
        train,
        validation,
        steps: Steps::All,
        channel: None,
    };
    work.judge(cand)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::FeatureComparison;

    fn step(test_index: usize, ratio: f64, regime: Regime) -> StepScores {
        StepScores {
            test: format!("t{test_index}"),
            test_index,
            step: 0,
            omega_ratio: 1.0,
            regime,
            level: 1e-6,
            features: vec![FeatureComparison {
                channel: "lower_tip".into(),
                feature: "rms".into(),
                measured: ratio,
                measured_spread: None,
                model: 1.0,
                model_spread: None,
                score: 0.0,
            }],
        }
    }

    #[test]
    fn the_measured_over_model_ratio_is_robust_to_a_few_steps() {
        let mut s: Vec<StepScores> = (0..9)
            .map(|k| step(0, 0.95 + 0.001 * (k % 3) as f64, Regime::ImpactFreeLow))
            .collect();
        // Two steps near a resonance the model places off, and an impact step.
        s.push(step(0, 0.7, Regime::ImpactFreeLow));
        s.push(step(0, 1.3, Regime::ImpactFreeLow));
        s.push(step(0, 3.0, Regime::Impacts));
        let (m, se, sd) = channel_ratio(&s, "lower_tip", &[0]).unwrap();
        assert!((m - 0.951).abs() < 1e-9, "{m}");
        assert!(sd < 0.01 && se < sd, "{sd} {se}");
        assert!(channel_ratio(&s, "lower_tip", &[1]).is_none());
    }

    #[test]
    fn tests_split_alternately() {
        assert_eq!(alternate(&[3, 5, 6, 9]), (vec![3, 6], vec![5, 9]));
        assert_eq!(alternate(&[2]), (vec![2], vec![]));
    }
}
