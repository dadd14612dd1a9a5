//! The tilt stage of the diagnosis: a tilted contact face (`[model.tilt]`, `physics::tilt`)
//! against a smaller clearance.
//!
//! A face tilted by `angle` about the axis `[0, 1]` (y: the gap varies along the beams) closes
//! first at one edge of the patch, `sin(angle) x_edge` earlier than the mean gap (`x_edge` the
//! edge's distance from the patch's centroid along x, from the ROM's pair positions): before
//! the first impact it looks exactly like a clearance smaller by that much. What can separate
//! them is what follows the first contact: the contact-regime statistics (contact fraction,
//! impacts per period, the tip amplitudes in contact), as the pairs close progressively
//! instead of all at once.
//!
//! Parameterisation: the angle about y, signed (positive: the tip-side edge, larger x, closes
//! first), the axis fixed at `[0, 1]`. A slope across the beams (about x) is not fitted: the
//! channels (bending along the beams, one contact voltage) carry no torsion, so it would be a
//! smaller clearance to them. The angle starts from the clearance the train tests show before
//! their first impact (the model-run clearance per test,
//! `clearance_fit::test_clearance_by_runs`): `sin(angle) x_edge = c_model - c_measured`, for
//! either edge; a grid of model runs of the train tests (their steps from two before the first
//! measured contact to two past the last, started from a state of open contact) over both
//! signs and 0.6-1.5 times that angle, refined once (0.9-1.1 times the best), fits it, at the
//! clearance fit's 3x finer twin step: at the twin's own step its contact excess chose the
//! other edge and a 21 % larger angle for a hidden 0.02 rad; at the finer step the minimum is
//! at the hidden angle and edge (BENCHMARKS.md, "A hidden tilt").
//!
//! Selection: the tilt is judged by the pipeline's rule against the model without the
//! clearance offset (the two compete for the same evidence), where it was fitted: on the train
//! and validation tests' contact steps at the fit's finer twin step (the whole tests' errors at
//! the twin's step are kept in the evidence: there even the hidden tilt leaves an error near
//! 2.5, set by the steps before the first contact and the twin's own contact excess). Where
//! the clearance offset was accepted too, the offset's model is run on the same steps at the
//! same twin step: the one with the lower validation error there stays in the model if it is
//! lower by more than the impact band's null spread; otherwise both are reported as equal
//! alternatives of each other (the clearance, with one parameter and first identified, stays
//! in the model): the session cannot tell them apart, and the diagnosis says so.

use serde_json::json;

use crate::config::{PhysicsSpec, TiltSpec};
use crate::rom::Rom;

use super::clearance::{ClearanceEvidence, TestClearance};
use super::clearance_fit::{test_clearance_by_runs, FIT_REFINEMENT};
use super::judge::{alternate, grid_then_refine, set_error, set_error_of, Candidate, Steps, Work};
use super::rerun::Span;
use super::{DiagnoseError, DiagnoseProgress};

/// The tilt axis fitted, `[x, y]`.
const AXIS: [f64; 2] = [0.0, 1.0];

/// The patch's edges along x from its area centroid, m: (tip side, larger x; clamp side),
/// both >= 0.
fn edges(rom: &Rom) -> (f64, f64) {
    let total: f64 = rom.pair_area.iter().sum();
    let cx = if total > 0.0 {
        rom.pair_position
            .iter()
            .zip(&rom.pair_area)
            .map(|(p, a)| a * p[0])
            .sum::<f64>()
            / total
    } else {
        0.0
    };
    rom.pair_position
        .iter()
        .fold((0.0f64, 0.0f64), |(t, c), p| {
            (t.max(p[0] - cx), c.max(cx - p[0]))
        })
}

/// The steps of tests `tests` that carry a tilt: from two before the first measured contact to
/// two past the last, from a state of open contact captured with `closest` where one can be
/// ([`Work::open_span`]), at the runner's refinement in force.
fn contact_spans(
    work: &mut Work<'_>,
    tests: &[usize],
    closest: &PhysicsSpec,
) -> Result<Vec<Span>, DiagnoseError> {
    let mut spans = Vec::new();
    for &ti in tests {
        let from = work.steps.before_first_contact(ti, 2);
        let through = work.steps.past_contact(ti, 2, false);
        spans.push(work.open_span(closest, ti, from, through)?);
    }
    Ok(spans)
}

/// What [`fit_angle`] gives: (angle, train error) of every run, and the spans run.
type AngleFit = (Vec<(f64, f64)>, Vec<Span>);

/// The angle's grid search on the train tests' contact steps ([`contact_spans`]), refined
/// once around the best point: (angle, train error) of every run, and the spans run.
fn fit_angle(
    work: &mut Work<'_>,
    train: &[usize],
    closest: &PhysicsSpec,
    grid: Vec<f64>,
    with: &dyn Fn(f64) -> PhysicsSpec,
) -> Result<AngleFit, DiagnoseError> {
    let spans = contact_spans(work, train, closest)?;
    let tried = grid_then_refine(
        work,
        grid,
        |best| vec![0.9 * best, 0.95 * best, 1.05 * best, 1.1 * best],
        &|_, angle| (with(angle), spans.clone()),
        |work, angle, s| {
            (work.progress)(DiagnoseProgress::Evaluation(format!(
                "tilt {angle:.3e} rad about y on the train tests at a {FIT_REFINEMENT}x finer twin step"
            )));
            set_error(s, train, Steps::All)
        },
    )?;
    Ok((tried, spans))
}

/// Stage 5: tilt (module docs). `base` is the model before the clearance stage (without its
/// offset); `ce` the clearance evidence.
pub(super) fn tilt_stage(
    work: &mut Work<'_>,
    rom: &Rom,
    base: &PhysicsSpec,
    ce: &ClearanceEvidence,
) -> Result<(), DiagnoseError> {
    let bracketed: Vec<&TestClearance> = ce
        .tests
        .iter()
        .filter(|t| t.clearance_m.is_some() && t.lower_bound_m.is_some())
        .collect();
    if bracketed.len() < 2 {
        work.undecided(
            "tilt",
            format!("{} test(s) bracket the first contact; a tilt is fitted on one and validated on another", bracketed.len()),
        );
        return Ok(());
    }
    let (tip_edge, clamp_edge) = edges(rom);
    if tip_edge <= 0.0 || clamp_edge <= 0.0 {
        work.undecided(
            "tilt",
            "the contact patch has no extent along the beams in the ROM",
        );
        return Ok(());
    }
    let idx: Vec<usize> = bracketed.iter().map(|t| t.test_index).collect();
    let (train, validation) = alternate(&idx);
    // The train tests' clearance before the first impact against the base model's, by the
    // same model runs as the clearance stage (shared through the cache).
    let after_clearance = std::mem::replace(&mut work.accepted, base.clone());
    let mut closes = Vec::new();
    for t in bracketed.iter().filter(|t| train.contains(&t.test_index)) {
        if let Some(r) = test_clearance_by_runs(work, t)? {
            closes.push(base.test_clearance(&t.test, t.plan_clearance_m) - r.clearance_m);
        }
    }
    let plan = bracketed[0].plan_clearance_m;
    let closing = if closes.is_empty() {
        0.0
    } else {
        closes.iter().sum::<f64>() / closes.len() as f64
    };
    if closing.is_nan() || closing <= 0.02 * plan {
        work.accepted = after_clearance;
        (work.progress)(DiagnoseProgress::Note(format!(
            "tilt: the train tests' first contact comes {closing:+.2e} m from the model's clearance: no edge closes early, a tilt is not indicated"
        )));
        work.effects.push(super::outcome::EffectResult {
            effect: "tilt".into(),
            rank: 0,
            accepted: false,
            parameters: json!({}),
            alternatives: Vec::new(),
            evidence: json!({"edge_closing_m": closing, "plan_clearance_m": plan}),
            reason: format!("not indicated: a tilted face closes one edge early, but the train tests' first contact is not earlier than the model's clearance by 2 % of it ({closing:+.2e} m)"),
            train_tests: work.names(&train),
            validation_tests: work.names(&validation),
            error_before: None,
            error_after: None,
        });
        return Ok(());
    }
    let with = |angle: f64| {
        let mut ext = base.clone();
        ext.tilt = Some(TiltSpec { angle, axis: AXIS });
        ext
    };
    let start_tip = (closing / tip_edge).min(1.0).asin();
    let start_clamp = -(closing / clamp_edge).min(1.0).asin();
    let grid: Vec<f64> = [start_tip, start_clamp]
        .iter()
        .flat_map(|s| [0.6, 0.8, 1.0, 1.2, 1.5].map(|m| (m * s).clamp(-0.1, 0.1)))
        .collect();
    // The train tests' steps from two before their first measured contact to two past their
    // last: a tilt acts in contact. The steps before are the same for every angle tried, run
    // once: with the clearance closed by the largest edge closing tried, nothing closes there.
    let widest = grid.iter().fold(0.0f64, |m, a| m.max(a.abs())) * 1.1;
    let closing_max = widest.sin() * tip_edge.max(clamp_edge);
    let mut closest = base.clone();
    for &ti in train.iter().chain(&validation) {
        let name = &work.steps.tests[ti];
        let plan = bracketed
            .iter()
            .find(|b| b.test_index == ti)
            .map_or(0.0, |b| b.plan_clearance_m);
        closest = closest.with_test_clearance(name, base.test_clearance(name, plan) - closing_max);
    }
    // NOTE: the fit runs at the clearance fit's finer twin step (FIT_REFINEMENT): at its own
    // step the twin over-counts contact in the band (BENCHMARKS.md, "Why the nominal twin
    // over-counts contact"), and the fit there chose the wrong edge and a 21 % larger angle
    // for a hidden 0.02 rad (BENCHMARKS.md, "A hidden tilt"); at the finer step the objective
    // has its minimum at the hidden angle and sign.
    let own = work.runner.refinement();
    work.runner.set_refinement(own * FIT_REFINEMENT);
    let tried = fit_angle(work, &train, &closest, grid, &with);
    work.runner.set_refinement(own);
    let (tried, train_spans) = tried?;
    let Some(&(angle, train_error)) = tried.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        work.accepted = after_clearance;
        return Ok(());
    };
    (work.progress)(DiagnoseProgress::Note(format!(
        "tilt: {angle:.3e} rad about y by {} runs of the train tests' contact steps at a {FIT_REFINEMENT}x finer twin step (error {train_error:.3}; the edge closes {closing:.2e} m early)",
        tried.len()
    )));
    // The contact channel's statistics on the validation tests, before and with the tilt and
    // with the clearance offset: what separates the two.
    let mut all: Vec<usize> = train.iter().chain(&validation).copied().collect();
    all.sort_unstable();
    let contact_rms = |s: &[super::outcome::StepScores]| {
        set_error_of(s, &validation, Steps::All, Some("contact"))
    };
    let s_base = work.scores(base, &all)?;
    let s_tilt = work.scores(&with(angle), &all)?;
    let s_clear = work.scores(&after_clearance, &all)?;
    let evidence = json!({
        "edge_closing_m": closing,
        "patch_edges_m": {"tip_side": tip_edge, "clamp_side": clamp_edge},
        "axis": AXIS,
        "validation_contact_score_rms": {
            "model_before": contact_rms(&s_base),
            "with_tilt": contact_rms(&s_tilt),
            "with_clearance_stage": contact_rms(&s_clear),
        },
        "on_whole_tests": {
            "validation_before": set_error(&s_base, &validation, Steps::All),
            "validation_after": set_error(&s_tilt, &validation, Steps::All),
            "reason": format!(
                "at the twin's own step (not judged there: its contact excess and the band's chaos set a floor near 2 that the hidden tilt itself does not go below; clearance stage's model {:.3})",
                set_error(&s_clear, &validation, Steps::All).unwrap_or(f64::NAN)
            ),
        },
        "angles_tried": tried.iter().map(|(a, e)| json!({"angle": a, "train_error": e})).collect::<Vec<_>>(),
    });
    let cand = Candidate::new(
        "tilt",
        with(angle),
        json!({"angle": angle, "axis": AXIS}),
        1,
        evidence,
        (train.clone(), validation.clone()),
        Steps::All,
    );
    // NOTE: judged where it was fitted: the train and validation tests' contact steps at the
    // fit's finer twin step, from a state of open contact captured with the closest geometry
    // tried. On the whole tests at the twin's own step even the hidden tilt leaves an error
    // near 2.5 (0.02 rad: 4.33 -> 2.48): the steps before the first contact (the same for
    // every geometry) and the twin's contact excess hold the error up (BENCHMARKS.md, "A
    // hidden tilt"). The whole tests' errors stay in the evidence (`on_whole_tests`).
    let mut judged_spans = train_spans;
    work.runner.set_refinement(own * FIT_REFINEMENT);
    let more = contact_spans(work, &validation, &closest).and_then(|v| {
        judged_spans.extend(v);
        // The clearance stage's model on the same steps: the tilt's competitor, compared
        // where the tilt is judged.
        work.scores_spans(&after_clearance, &judged_spans)
    });
    work.runner.set_refinement(own);
    let c_where = set_error(&more?, &validation, Steps::All);
    let cand = cand.judged_where_fitted(
        judged_spans,
        FIT_REFINEMENT,
        "each test's steps from two before its first measured contact to two past its last",
    );
    let tilt_ok = work.judge_where_fitted_first(cand)?;
    // The clearance offset judged before, if it was accepted.
    let Some(ci) = work
        .effects
        .iter()
        .rposition(|e| e.effect == "clearance" && e.accepted)
    else {
        return Ok(());
    };
    let ti = work.effects.len() - 1;
    let (Some(c_after), Some(t_after)) =
        (c_where, work.effects[ti].error_after.map(|e| e.validation))
    else {
        work.accepted = after_clearance;
        return Ok(());
    };
    let null = work.opts.contact_null_spread;
    if !tilt_ok {
        work.accepted = after_clearance;
        return Ok(());
    }
    let c_param = work.effects[ci].parameters.clone();
    if t_after + null < c_after {
        // The tilt predicts the validation tests better beyond the null spread: it replaces
        // the offset (the model is `base` with the tilt, as judged).
        let c = &mut work.effects[ci];
        c.accepted = false;
        c.reason = format!("replaced by the tilt, which predicts the validation tests' contact steps better at the finer twin step ({t_after:.3} against {c_after:.3}, beyond the null spread {null})");
        c.alternatives.push(format!(
            "tilt: {angle:.3e} rad about y (better on validation)"
        ));
        work.effects[ti].alternatives.push(format!(
            "clearance {c_param}: the same first contact, worse on the validation tests' contact steps ({c_after:.3})"
        ));
    } else {
        // Equal: the session cannot tell them apart. The clearance (one parameter, first
        // identified) stays in the model; both name each other.
        work.accepted = after_clearance;
        let t = &mut work.effects[ti];
        t.accepted = false;
        t.reason = format!("an equal alternative of the clearance offset: both lower the validation error beyond the null spread, to {t_after:.3} (tilt) and {c_after:.3} (clearance) on the validation tests' contact steps at the finer twin step, within the impact band's null spread {null} of each other; the channels cannot tell a tilted face from a smaller clearance here, the clearance stays in the model");
        t.alternatives.push(format!(
            "clearance {c_param} (equal: validation {c_after:.3})"
        ));
        work.effects[ci].alternatives.push(format!(
            "tilt: {angle:.3e} rad about y (equal: validation {t_after:.3}; the channels cannot tell them apart)"
        ));
    }
    Ok(())
}
