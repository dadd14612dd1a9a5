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
//! signs and 0.6-1.5 times that angle, refined once, gives the landscape; the angle is the
//! mean of its floor around the best point (within the band's chaos the best point is a draw
//! from the floor); the face as given on the same steps is the landscape's reference
//! (`evidence-tilt`).
//!
//! Selection: the tilt is judged by the pipeline's rule against the model without the
//! clearance offset (the two compete for the same evidence). Where the clearance offset was
//! accepted too, the one with the lower validation error stays in the model if it is lower by
//! more than the impact band's null spread; otherwise both are reported as equal alternatives
//! of each other (the clearance, with one parameter and first identified, stays in the model):
//! the session cannot tell them apart, and the diagnosis says so. Where the tilt is rejected
//! on the whole tests but the clearance offset was accepted, the two are compared where a tilt
//! acts (each judged test's steps from two before its first measured contact to two past its
//! last, the median of the band's runs per step): within the null spread of each other there,
//! they are named equal alternatives too. A hidden tilt of 0.02 rad on `identify.toml` is
//! named so: the offset -74 um accepted where it was fitted (2.29 -> 0.88), the tilt's
//! validation error where it acts 1.985 against the offset's 1.676.

use serde_json::json;

use crate::config::{PhysicsSpec, TiltSpec};
use crate::rom::Rom;

use super::clearance::{ClearanceEvidence, TestClearance};
use super::clearance_fit::test_clearance_by_runs;
use super::judge::{alternate, grid_then_refine, set_error, set_error_of, Candidate, Steps, Work};
use super::outcome::EffectResult;
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

/// The train errors within this share of the smallest one are the valley's floor: the band's
/// chaos moves a run's error by about that much (the floor of a hidden 0.025 rad tilt on the
/// four-probe plan: 1.52, 1.52, 1.49 at 0.0265, 0.0286, 0.0318 rad; of a hidden 0.02 rad on
/// `identify.toml`: 3.61-3.97 from -0.0166 to -0.0277 rad).
const FLOOR_SHARE: f64 = 0.1;

/// The angle the tried `(angle, train error)` points fit, the smallest error and the floor's
/// angles: the mean angle of the valley's floor around the best point, i.e. the contiguous
/// points of the best one's sign whose errors are within [`FLOOR_SHARE`] of the smallest. Where the floor is
/// flat within the chaos the best point is a draw from it, at either end as often as in the
/// middle (BENCHMARKS.md, "The tilt's angle from the valley's floor"); None without points.
fn valley_floor(tried: &[(f64, f64)]) -> Option<(f64, f64, Vec<f64>)> {
    let &(best, smallest) = tried.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let mut side: Vec<(f64, f64)> = (tried.iter().copied())
        .filter(|p| p.0.signum() == best.signum() && p.1.is_finite())
        .collect();
    side.sort_by(|a, b| a.0.total_cmp(&b.0));
    let k = side.iter().position(|p| p.0 == best)?;
    let on_floor = |p: &(f64, f64)| p.1 <= smallest * (1.0 + FLOOR_SHARE);
    let lo = (0..k)
        .rev()
        .take_while(|&i| on_floor(&side[i]))
        .last()
        .unwrap_or(k);
    let hi = (k + 1..side.len())
        .take_while(|&i| on_floor(&side[i]))
        .last()
        .unwrap_or(k);
    let floor = &side[lo..=hi];
    let angle = floor.iter().map(|p| p.0).sum::<f64>() / floor.len() as f64;
    Some((angle, smallest, floor.iter().map(|p| p.0).collect()))
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
            ce.too_few_brackets(
                bracketed.len(),
                "a tilt is fitted on one and validated on another",
            ),
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
        work.effects.push(EffectResult {
            train_tests: work.names(&train),
            validation_tests: work.names(&validation),
            ..EffectResult::unfitted(
                "tilt",
                json!({"edge_closing_m": closing, "plan_clearance_m": plan}),
                format!("not indicated: a tilted face closes one edge early, but the train tests' first contact is not earlier than the model's clearance by 2 % of it ({closing:+.2e} m)"),
            )
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
    let train_spans = contact_spans(work, base, &bracketed, &train, closing_max)?;
    let tried = grid_then_refine(
        work,
        grid,
        |best| vec![0.9 * best, 1.1 * best],
        &|_, angle| (with(angle), train_spans.clone()),
        1,
        |work, angle, s| {
            (work.progress)(DiagnoseProgress::Evaluation(format!(
                "tilt {angle:.3e} rad about y on the train tests"
            )));
            set_error(&s[0], &train, Steps::All)
        },
    )?;
    let Some((angle, train_error, floor)) = valley_floor(&tried) else {
        work.accepted = after_clearance;
        return Ok(());
    };
    // The face as given on the same steps: the reference of the angles' errors (the
    // evidence's landscape).
    let flat = work.scores_spans(base, &train_spans)?;
    let train_error_flat = set_error(&flat, &train, Steps::All);
    (work.progress)(DiagnoseProgress::Note(format!(
        "tilt: {angle:.3e} rad about y by {} runs of the train tests' contact steps (the mean of the valley's floor, {} angles within {:.0} % of the smallest error {train_error:.3}; the edge closes {closing:.2e} m early)",
        tried.len(),
        floor.len(),
        100.0 * FLOOR_SHARE
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
        "angles_tried": tried.iter().map(|(a, e)| json!({"angle": a, "train_error": e})).collect::<Vec<_>>(),
        "train_error_without_tilt": train_error_flat,
        "floor_angles": floor,
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
    let tilt_ok = work.judge(cand)?;
    // The clearance offset judged before, if it was accepted.
    let Some(ci) = work
        .effects
        .iter()
        .rposition(|e| e.effect == "clearance" && e.accepted)
    else {
        return Ok(());
    };
    let ti = work.effects.len() - 1;
    let (Some(c_after), Some(t_after)) = (
        work.effects[ci].error_after.map(|e| e.validation),
        work.effects[ti].error_after.map(|e| e.validation),
    ) else {
        work.accepted = after_clearance;
        return Ok(());
    };
    let null = work.opts.contact_null_spread;
    if !tilt_ok {
        work.accepted = after_clearance.clone();
        // Rejected on the whole tests beside an accepted clearance offset: the two compared
        // where a tilt acts. Within the null spread of each other there, the session cannot
        // tell them apart.
        let spans = contact_spans(work, base, &bracketed, &all, closing_max)?;
        let cmp = Candidate::new(
            "tilt",
            with(angle),
            json!({}),
            1,
            json!({}),
            (train, validation),
            Steps::All,
        )
        .judged_where_fitted(spans, 1, IN_CONTACT);
        let (Some(t), Some(c)) = (
            work.errors(&with(angle), &cmp, true)?,
            work.errors(&after_clearance, &cmp, true)?,
        ) else {
            return Ok(());
        };
        let c_param = work.effects[ci].parameters.clone();
        let tilt = &mut work.effects[ti];
        tilt.evidence["in_contact_against_clearance"] = json!({
            "steps": IN_CONTACT,
            "validation_with_tilt": t.validation,
            "validation_with_clearance": c.validation,
        });
        if t.validation <= c.validation + null {
            tilt.reason = format!(
                "{}; where a tilt acts ({IN_CONTACT}) its validation error {:.3} is within the impact band's null spread {null} of the clearance offset's {:.3}: an equal alternative of it, the channels cannot tell a tilted face from a smaller clearance here",
                tilt.reason, t.validation, c.validation
            );
            tilt.alternatives.push(format!(
                "clearance {c_param} (equal where a tilt acts: validation {:.3})",
                c.validation
            ));
            work.effects[ci].alternatives.push(format!(
                "tilt: {angle:.3e} rad about y (equal where a tilt acts, {IN_CONTACT}: validation {:.3} against {:.3}; rejected on the whole tests)",
                t.validation, c.validation
            ));
        }
        return Ok(());
    }
    let c_param = work.effects[ci].parameters.clone();
    if t_after + null < c_after {
        // The tilt predicts the validation tests better beyond the null spread: it replaces
        // the offset (the model is `base` with the tilt, as judged).
        let c = &mut work.effects[ci];
        c.accepted = false;
        c.reason = format!("replaced by the tilt, which predicts the validation tests better ({t_after:.3} against {c_after:.3}, beyond the null spread {null})");
        c.alternatives.push(format!(
            "tilt: {angle:.3e} rad about y (better on validation)"
        ));
        work.effects[ti].alternatives.push(format!(
            "clearance {c_param}: the same first contact, worse on validation ({c_after:.3})"
        ));
    } else {
        // Equal: the session cannot tell them apart. The clearance (one parameter, first
        // identified) stays in the model; both name each other.
        work.accepted = after_clearance;
        let t = &mut work.effects[ti];
        t.accepted = false;
        t.reason = format!("an equal alternative of the clearance offset: both lower the validation error beyond the null spread, to {t_after:.3} (tilt) and {c_after:.3} (clearance), within the impact band's null spread {null} of each other; the channels cannot tell a tilted face from a smaller clearance here, the clearance stays in the model");
        t.alternatives.push(format!(
            "clearance {c_param} (equal: validation {c_after:.3})"
        ));
        work.effects[ci].alternatives.push(format!(
            "tilt: {angle:.3e} rad about y (equal: validation {t_after:.3}; the channels cannot tell them apart)"
        ));
    }
    Ok(())
}

/// What [`contact_spans`] compares, in words.
const IN_CONTACT: &str =
    "each test's steps from two before its first measured contact to two past its last";

/// The steps of tests `tests` where a tilt acts, from two before each one's first measured
/// contact to two past its last, each from a state of open contact captured with the
/// clearances of `base` closed by `closing` (m; [`Work::open_span`]).
fn contact_spans(
    work: &mut Work<'_>,
    base: &PhysicsSpec,
    bracketed: &[&TestClearance],
    tests: &[usize],
    closing: f64,
) -> Result<Vec<Span>, DiagnoseError> {
    let mut closest = base.clone();
    for &ti in tests {
        let name = work.steps.tests[ti].clone();
        let plan = (bracketed.iter())
            .find(|b| b.test_index == ti)
            .map_or(0.0, |b| b.plan_clearance_m);
        closest = closest.with_test_clearance(&name, base.test_clearance(&name, plan) - closing);
    }
    let mut spans = Vec::new();
    for &ti in tests {
        let from = work.steps.before_first_contact(ti, 2);
        let through = work.steps.past_contact(ti, 2, false);
        spans.push(work.open_span(&closest, ti, from, through)?);
    }
    Ok(spans)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_angle_is_the_mean_of_the_floor_around_the_best_point() {
        // A flat floor at 0.0265-0.0318 rad, a cliff beyond, the other sign as low.
        let tried = [
            (0.0159, 3.35),
            (0.0212, 2.34),
            (0.0265, 1.52),
            (0.0286, 1.52),
            (0.0318, 1.49),
            (0.0350, 16.9),
            (-0.0318, 1.50),
            (-0.0265, 1.51),
        ];
        let (angle, smallest, floor) = valley_floor(&tried).unwrap();
        assert_eq!(floor, [0.0265, 0.0286, 0.0318]);
        assert!((angle - 0.0869 / 3.0).abs() < 1e-12, "{angle}");
        assert_eq!(smallest, 1.49);
    }

    #[test]
    fn a_floor_interrupted_by_a_higher_point_ends_there() {
        let tried = [
            (-0.03, 1.0),
            (-0.025, 2.0),
            (-0.02, 1.05),
            (-0.015, 1.08),
            (-0.01, 3.0),
        ];
        let (angle, _, floor) = valley_floor(&tried).unwrap();
        assert_eq!(floor, [-0.03]);
        assert_eq!(angle, -0.03);
        let tried = [(0.01, 5.0), (0.02, 1.0), (0.03, 4.0)];
        assert_eq!(valley_floor(&tried).unwrap().0, 0.02);
        assert_eq!(valley_floor(&[]), None);
    }
}
