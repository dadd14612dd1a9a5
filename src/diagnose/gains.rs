//! The sensor-gain stage of the diagnosis (stage 1, and again after the linear and clamp
//! stages): a redundant channel's gain from its ratio to its partners
//! ([`super::sensors`]), judged on that redundancy over the validation tests; a channel
//! without a redundant partner from its measured/model ratio over the impact-free steps
//! (flat in frequency and unlike its beam's other channel), judged by model runs.

use serde_json::json;

use crate::config::{PhysicsSpec, SensorGainSpec};

use super::evidence::SessionEvidence;
use super::judge::{alternate, set_error, Candidate, Steps, Work};
use super::outcome::{Regime, SetError, StepScores};
use super::rerun::{SessionSteps, Span};
use super::sensors::{sensor_sensitivities_of, SensitivityStatus, SensorOptions};
use super::{DiagnoseError, DiagnoseProgress};

/// The tests split for the sensor gains: all of them alternately, and the impact-free ones
/// (with at least one impact-free step) as they fall in that split.
pub(super) struct GainSplit {
    pub(super) train: Vec<usize>,
    pub(super) validation: Vec<usize>,
    pub(super) free: Vec<usize>,
    pub(super) free_train: Vec<usize>,
    pub(super) free_validation: Vec<usize>,
}

impl GainSplit {
    pub(super) fn of(steps: &SessionSteps) -> GainSplit {
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
pub(super) fn sensor_stage(
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
            let cand = Candidate::new(
                "sensor_gain",
                with_gain(&work.accepted, &c.channel, gain),
                json!({"channel": c.channel, "gain": gain}),
                1,
                json!({"redundant_channels": c.reason, "standard_error": c.standard_error}),
                (train.clone(), validation.clone()),
                Steps::ImpactFree,
            )
            .on_channel((!platform).then(|| c.channel.clone()));
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
            let base = work.accepted.clone();
            let tried = spot_choices(work, &base, r.ratio, &free, &free_train)?;
            let (channel, gain, _) = tried[0];
            let alternatives = spot_tie(work, &tried).into_iter().collect();
            let cand = Candidate::new(
                "sensor_gain",
                with_gain(&work.accepted, channel, gain),
                json!({"channel": channel, "gain": gain}),
                1,
                json!({"upper_tip_over_vibrometer": r.ratio, "standard_error": r.standard_error, "train_error_upper_tip": tried.iter().find(|t| t.0 == "upper_tip").map(|t| t.2), "train_error_vibrometer": tried.iter().find(|t| t.0 == "vibrometer").map(|t| t.2), "judged_on": "the two channels' ratio over the validation tests; the model's train error chose the channel"}),
                (train.clone(), validation.clone()),
                Steps::ImpactFree,
            )
            .on_channel(Some(channel.to_string()))
            .with_alternatives(alternatives);
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

/// The two readings of the upper tip's redundancy (the upper-tip accelerometer over the
/// vibrometer `ratio`): the accelerometer off by `ratio`, or the vibrometer by its inverse,
/// each added to `base` and run over the impact-free tests `free`; (channel, gain, train
/// error on `free_train`), the better first.
fn spot_choices(
    work: &mut Work<'_>,
    base: &PhysicsSpec,
    ratio: f64,
    free: &[usize],
    free_train: &[usize],
) -> Result<Vec<(&'static str, f64, f64)>, DiagnoseError> {
    let gains = [("upper_tip", ratio), ("vibrometer", 1.0 / ratio)];
    let mut all_t = free.to_vec();
    all_t.sort_unstable();
    let whole: Vec<Span> = all_t.iter().map(|&t| Span::whole(t)).collect();
    work.prefetch(
        (gains.iter())
            .map(|&(channel, gain)| (with_gain(base, channel, gain), whole.clone()))
            .collect(),
    )?;
    let mut tried = Vec::new();
    for (channel, gain) in gains {
        let s = work.scores(&with_gain(base, channel, gain), &all_t)?;
        let e = set_error(&s, free_train, Steps::ImpactFree).unwrap_or(f64::INFINITY);
        tried.push((channel, gain, e));
    }
    tried.sort_by(|a, b| a.2.total_cmp(&b.2));
    Ok(tried)
}

/// The other reading of [`spot_choices`] as an equal alternative, where the train errors do
/// not tell the two apart (within the null spread).
fn spot_tie(work: &Work<'_>, tried: &[(&str, f64, f64)]) -> Option<String> {
    let ((_, _, best), (other, gain, second)) = (tried[0], tried[1]);
    (second - best <= work.opts.null_spread).then(|| {
        format!("sensor_gain of {other} (gain {gain:.4}): the train error is within the null spread ({best:.3} vs {second:.3})")
    })
}

/// The vibrometer / upper-tip reading once more, against the model with the effects accepted
/// since the first pass: there the upper beam's wrong physics can dominate both train errors
/// so that the two readings tie (a hidden vibrometer gain of 1.04 beside 1FU at 50.8 Hz:
/// 21.937 against 21.947, the accelerometer's 0.9615 taken, the vibrometer named as the equal
/// alternative). Where the other reading is now better by more than the null spread it
/// replaces the one taken (the same effect, judged on the same ratio); where the one taken is,
/// the alternative is dropped. Only where the first pass named the tie.
pub(super) fn spot_gain_again(
    work: &mut Work<'_>,
    free: &[usize],
    free_train: &[usize],
) -> Result<(), DiagnoseError> {
    let Some(i) = work.effects.iter().position(|e| {
        e.accepted
            && e.effect == "sensor_gain"
            && !e.alternatives.is_empty()
            && e.evidence.get("upper_tip_over_vibrometer").is_some()
    }) else {
        return Ok(());
    };
    let (Some(ratio), Some(taken)) = (
        work.effects[i].evidence["upper_tip_over_vibrometer"].as_f64(),
        work.effects[i].parameters["channel"]
            .as_str()
            .map(str::to_string),
    ) else {
        return Ok(());
    };
    let mut base = work.accepted.clone();
    base.sensor_gains.retain(|g| g.channel != taken);
    let tried = spot_choices(work, &base, ratio, free, free_train)?;
    let (channel, gain, best) = tried[0];
    let tie = spot_tie(work, &tried);
    let errors: serde_json::Map<String, serde_json::Value> = (tried.iter())
        .map(|t| (format!("train_error_{}", t.0), json!(t.2)))
        .collect();
    (work.progress)(DiagnoseProgress::Note(format!(
        "sensor_gain: the upper tip's two sensors against the corrected model: {} {:.3}, {} {:.3}",
        tried[0].0, tried[0].2, tried[1].0, tried[1].2
    )));
    let e = &mut work.effects[i];
    e.evidence["chosen_again"] = json!({"against": "the model with the effects accepted after the first pass", "errors": errors});
    if tie.is_some() {
        e.alternatives = tie.into_iter().collect();
        return Ok(());
    }
    e.alternatives.clear();
    if channel != taken {
        e.reason = format!(
            "{}; the channel chosen again against the corrected model: {channel} (train error {best:.3} against {:.3})",
            e.reason, tried[1].2
        );
        e.parameters = json!({"channel": channel, "gain": gain});
        work.accepted = with_gain(&base, channel, gain);
    }
    Ok(())
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
pub(super) fn unpartnered_gains(
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
            let (gain, rounds) = refined_gain(work, channel, ratio, free_train)?;
            (work.progress)(DiagnoseProgress::Note(format!(
                "{channel}: measured over model {ratio:.4} on the impact-free train steps; the gain {gain:.4} after {} model run(s) observing it (ratios {})",
                rounds.len(),
                rounds
                    .iter()
                    .map(|(g, r)| format!("{r:.4} at {g:.4}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
            // Judged on the validation tests without measured contact where there are any: a
            // band test's impact-free steps beside its contact move with where the model's
            // contact begins, which a contact effect not yet found (a strong wear: 0.45 mm of
            // growth) shifts by far more than a gain of a few percent (a hidden lower_mid 0.96
            // was fitted at 0.9602 and rejected, 10.3 -> 9.97 over two band tests and 1FL).
            let validation = work
                .steps
                .without_contact_where_any(free_validation.to_vec());
            let cand = Candidate::new(
                "sensor_gain",
                with_gain(&work.accepted, channel, gain),
                json!({"channel": channel, "gain": gain}),
                1,
                json!({"measured_over_model": ratio, "standard_error": se, "spread_over_steps": sd, "partner": p, "partner_measured_over_model": pr, "refined_by_model_runs": rounds}),
                (free_train.to_vec(), validation),
                Steps::ImpactFree,
            )
                .on_channel(Some(channel.to_string()));
            if work.judge(cand)? {
                n += 1;
            }
        }
    }
    Ok(n)
}

/// Model runs that refine a beam channel's gain from its first measured/model ratio `ratio`
/// over the impact-free steps of `tests` (the model without the gain): the gain times the
/// ratio the model observed with it gives, then the secant through the last two rounds, until
/// that ratio is within [`GAIN_REFINED`] of 1 or after [`GAIN_ROUNDS`] runs. Returns the gain
/// and each round's (gain, ratio).
///
/// NOTE: the beam channels' features are velocities relative to the base, from the sensor's
/// absolute acceleration less the platform's: a gain `g` on the sensor reads
/// `g v_rel + (g - 1) v_base`, so the ratio to the model is `g` only where the beam's own
/// motion outweighs the base's. Off its resonance it is not: a hidden lower-mid gain of 1.04
/// read 1.039-1.043 over the 1FL tests but 1.02-1.03 over the 1FU and band tests (the lower
/// beam above its resonance moves against the base), and the median, 1.030, was accepted
/// (BENCHMARKS.md, "Concealed values on `identify.toml`"). The model with the gain observes
/// the base term as the rig does, so the ratio to it is 1 at every step at the right gain.
fn refined_gain(
    work: &mut Work<'_>,
    channel: &str,
    ratio: f64,
    tests: &[usize],
) -> Result<(f64, Vec<(f64, f64)>), DiagnoseError> {
    // The next gain: the secant through the last two rounds' ratios where they differ (the
    // ratio falls about linearly with the gain), else the gain times the ratio.
    let next = |rounds: &[(f64, f64)]| match *rounds {
        [.., (g0, r0), (g1, r1)] if (r1 - r0).abs() > 1e-9 => {
            g1 + (1.0 - r1) * (g1 - g0) / (r1 - r0)
        }
        [.., (g, r)] => g * r,
        [] => ratio,
    };
    let mut rounds: Vec<(f64, f64)> = Vec::new();
    for _ in 0..GAIN_ROUNDS {
        let gain = next(&rounds);
        let ext = with_gain(&work.accepted, channel, gain);
        let with = work.scores(&ext, tests)?;
        let Some((r, _, _)) = channel_ratio(&with, channel, tests) else {
            break;
        };
        if !(r.is_finite() && r > 0.0) {
            break;
        }
        rounds.push((gain, r));
        if (r - 1.0).abs() <= GAIN_REFINED {
            return Ok((gain, rounds));
        }
    }
    Ok((next(&rounds), rounds))
}

/// Model runs at most in [`refined_gain`].
const GAIN_ROUNDS: usize = 3;

/// A model ratio this close to 1 ends [`refined_gain`].
const GAIN_REFINED: f64 = 2e-4;

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
}
