//! The tilt stage of the diagnosis: a tilted contact face (`[model.tilt]`, `physics::tilt`)
//! against a smaller clearance.
//!
//! A face tilted by `angle` about an axis in the contact plane closes first at one edge of the
//! patch, `sin(angle) edge` earlier than the mean gap (`edge` the edge's distance from the
//! patch's centroid across the axis, from the ROM's pair positions): before
//! the first impact it looks exactly like a clearance smaller by that much. What can separate
//! them is what follows the first contact: the contact-regime statistics (contact fraction,
//! impacts per period, the tip amplitudes in contact), as the pairs close progressively
//! instead of all at once.
//!
//! Parameterisation: the angle about an in-plane axis, signed, and the edge it closes first:
//! the tip side (about y, positive: larger x), the clamp side (about y, negative) or a side
//! across the beams (about x, positive: the side at smaller y; negative: at larger y).
//! The edge closing starts from the clearance the train tests show before their first impact
//! (the model-run clearance per test, `clearance_fit::test_clearance_by_runs`, which fits a
//! flat face): `sin(angle) edge = c_model - c_measured`. The fit ([`fit_by_runs`]) searches 0.4
//! to 2 times that closing, within what the train tests' brackets admit, on the steps that carry
//! a face's geometry, as the clearance offset is fitted: each train test's steps from two before
//! its first measured contact to two past it, at a 3x finer twin step, each angle's error the
//! median per step over the band's draws, the tests weighted by how sharply their own runs told
//! their clearance. The tip-side edge on a grid of 9 closings, refined once, its angle the mean
//! of the valley's floor (within the chaos, the best run is a draw from it); then every other
//! edge at 0.85, 1 and 1.15 times that closing, and the face as given, on the same steps (the
//! landscape's reference, `evidence-tilt`). The tip side is taken unless another edge's best
//! point scores lower by more than the null spread of those steps; the evidence says whether every other one is higher by more than the null spread of those
//! steps (`other_edge.told`): where it is not, the session places the closing but not the
//! edge, and the angle only through the edge's distance from the centroid (3.0 mm along the
//! beams, 2.1 mm across them on the embedded rig's patch); the edges not told apart are named
//! in the tilt's `alternatives` with their own angle and axis.
//!
//! Selection: the tilt is judged by the pipeline's rule against the model without the
//! clearance offset (the two compete for the same evidence): on the whole tests, and where
//! they reject it, where it was fitted (each judged test's steps about its first contact at
//! the fit's finer step), as the offset is. Where the clearance offset was accepted too, the one
//! with the lower validation error stays in the model if it is lower by more than the null
//! spread (on the steps both were judged on; where one was judged on the whole tests and the
//! other where it was fitted, where a tilt acts); otherwise both are reported as equal
//! alternatives of each other (the clearance, with one parameter and first identified, stays in
//! the model): the session cannot tell them apart, and the diagnosis says so. Where the tilt is
//! rejected but the clearance offset was accepted, the two are compared where a tilt acts (each
//! judged test's steps from two before its first measured contact to two past its last, the
//! median of the band's runs per step): within the null spread of each other there, they are
//! named equal alternatives too. A hidden tilt of 0.02 rad on `identify.toml` is named so: the
//! offset -74 um accepted where it was fitted (2.29 -> 0.88), the tilt's validation error
//! where it acts 1.985 against the offset's 1.676.
//!
//! NOTE: judged on the whole tests alone, a hidden 0.04 rad about x on `identify.toml` (an 84
//! um closing) was named by nothing: the offset and the tilt each lowered the validation error
//! by 49 % (2.565 -> 1.31), the band asks 50 %; the offset fell 44 % where it was fitted.

use serde_json::json;

use crate::config::{PhysicsSpec, TiltSpec};
use crate::rom::Rom;

use super::clearance::{ClearanceEvidence, TestClearance};
use super::clearance_fit::{
    common_offsets, evidence_steps, refined_around, sharpness_weights, test_clearance_by_runs,
    valley_spread, weighted_tests_error, FIT_REFINEMENT,
};
use super::judge::{alternate, grid_then_refine, set_error_of, Candidate, Steps, Work};
use super::outcome::EffectResult;
use super::rerun::Span;
use super::{DiagnoseError, DiagnoseProgress};

/// An edge of the contact patch that a tilt closes first: the axis the face tilts about, the
/// sign of the angle that closes this edge, and its distance from the patch's area centroid
/// across that axis (`physics::tilt`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Edge {
    /// What the evidence calls it.
    name: &'static str,
    /// The tilt axis, `[x, y]`.
    axis: [f64; 2],
    /// The sign of the angles that close this edge first.
    sign: f64,
    /// Its distance from the centroid, m (>= 0).
    extent: f64,
}

impl Edge {
    /// The angle (rad, signed) that closes this edge `closing` (m) earlier than the mean gap.
    fn angle(&self, closing: f64) -> f64 {
        self.sign * (closing / self.extent).clamp(-1.0, 1.0).asin()
    }

    /// How much earlier (m) than the mean gap this edge closes at `angle` (rad).
    fn closing(&self, angle: f64) -> f64 {
        angle.abs().sin() * self.extent
    }
}

/// The patch's edges from its area centroid (the ROM's lower pair positions and tributary
/// areas): the tip side (larger x) and the clamp side, closed first by a tilt about y, positive
/// and negative; the sides at smaller and larger y, closed first by a tilt about x, positive and
/// negative. The two sides across the beams are mirror images on a rig symmetric about y = 0,
/// but the band's draws start from perturbed states that are not: both are run.
fn edges(rom: &Rom) -> [Edge; 4] {
    let total: f64 = rom.pair_area.iter().sum();
    let centroid = |d: usize| {
        if total > 0.0 {
            (rom.pair_position.iter().zip(&rom.pair_area))
                .map(|(p, a)| a * p[d])
                .sum::<f64>()
                / total
        } else {
            0.0
        }
    };
    let (cx, cy) = (centroid(0), centroid(1));
    let reach = |f: &dyn Fn(&[f64; 3]) -> f64| rom.pair_position.iter().map(f).fold(0.0, f64::max);
    [
        Edge {
            name: "tip_side",
            axis: [0.0, 1.0],
            sign: 1.0,
            extent: reach(&|p| p[0] - cx),
        },
        Edge {
            name: "clamp_side",
            axis: [0.0, 1.0],
            sign: -1.0,
            extent: reach(&|p| cx - p[0]),
        },
        Edge {
            name: "smaller_y_side",
            axis: [1.0, 0.0],
            sign: 1.0,
            extent: reach(&|p| cy - p[1]),
        },
        Edge {
            name: "larger_y_side",
            axis: [1.0, 0.0],
            sign: -1.0,
            extent: reach(&|p| p[1] - cy),
        },
    ]
}

/// What the tilt's fit compares, in words.
const FIT_STEPS: &str = "each train test's steps from two before its first measured contact to two past it, at a 3x finer twin step, each angle's error the median per step over the band's draws";

/// `base` with its face tilted by `angle` about `axis` (`base` itself at 0).
fn with_tilt(base: &PhysicsSpec, axis: [f64; 2], angle: f64) -> PhysicsSpec {
    let mut ext = base.clone();
    ext.tilt = (angle != 0.0).then_some(TiltSpec { angle, axis });
    ext
}

/// An axis in words.
fn axis_name(axis: [f64; 2]) -> &'static str {
    if axis[0].abs() > axis[1].abs() {
        "x"
    } else {
        "y"
    }
}

/// The edge closings (m: how much earlier than the mean gap an edge closes) a tilt's fit
/// searches, (lowest, highest): 0.4 to 2 times `closing` (the train tests' first contact
/// before the model's, by their clearance runs, which fit a flat face: on the four-probe plan
/// they put hidden closings of 60, 79 and 90 um at 84, 51 and 91 um), within what every train
/// test's bracket admits where they admit a common range (test `t`'s first contact lies between
/// its bounds, so an edge closing lies within `base`'s clearance for it less the bounds).
fn closing_range(base: &PhysicsSpec, train: &[&TestClearance], closing: f64) -> (f64, f64) {
    let runs = (0.4 * closing, 2.0 * closing);
    let current: Vec<f64> = (train.iter())
        .map(|t| base.test_clearance(&t.test, t.plan_clearance_m))
        .collect();
    // A closing is an offset to the model's clearances with the sign turned.
    match common_offsets(train, &current) {
        Some((o_lo, o_hi)) if runs.1.min(-o_lo) > runs.0.max(-o_hi) => {
            (runs.0.max(-o_hi), runs.1.min(-o_lo))
        }
        _ => runs,
    }
}

/// The train errors within this share of the smallest one are the valley's floor: the band's
/// chaos moves a run's error by about that much (on the steps about the first contact, over
/// three draws, a hidden 0.02 rad on `identify.toml`: 1.51, 1.42, 1.47, 1.40, 1.41 from
/// 0.0201 to 0.0245 rad, 1.77 at 0.0251, 9.1 past the cliff at 0.0268).
const FLOOR_SHARE: f64 = 0.1;

/// The angle the tried `(angle, train error)` points fit, the smallest error and the floor's
/// angles: the mean angle of the valley's floor around the best point, i.e. the contiguous
/// points of the best one's sign whose errors are within [`FLOOR_SHARE`] of the smallest.
/// Where the floor is flat within the chaos the best point is a draw from it, at either end as
/// often as in the middle (BENCHMARKS.md, "The tilt's angle from the valley's floor"); None
/// without points.
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

/// The closings at which every edge but the tip side is run, as shares of the tip side's
/// fitted closing: the same first contact is not the same closing for every edge (a hidden
/// 0.03 rad about x, a 63 um closing of a side, fitted on the tip side at 71 um, scored 1.89
/// there against the tip side's 0.83 on the four-probe plan).
const EDGE_CLOSINGS: [f64; 3] = [0.85, 1.0, 1.15];

/// An edge's run about the tip side's fit: the edge, its angle (rad, signed) and its train
/// error (-; NaN where nothing compared).
#[derive(Clone, Copy, Debug, PartialEq)]
struct EdgeRun {
    edge: Edge,
    angle: f64,
    error: f64,
}

/// The tilt fitted by model runs ([`fit_by_runs`]).
#[derive(Clone, Debug, PartialEq)]
struct TiltFit {
    /// The edge taken, its angle (rad, about its axis, signed) and its error (-).
    taken: EdgeRun,
    /// The runs' own spread in the taken edge's angle, rad ([`valley_spread`]).
    spread: f64,
    /// The runs of the tip-side edge, (angle rad, error -).
    tried: Vec<(f64, f64)>,
    /// The tip-side angles of the valley's floor ([`valley_floor`]), rad.
    floor: Vec<f64>,
    /// Every edge's best point (the tip side's own run first).
    edges: Vec<EdgeRun>,
    /// Every edge's points: the tip side's floor mean, the others at [`EDGE_CLOSINGS`].
    points: Vec<EdgeRun>,
    /// The edge not taken with the lowest error.
    other: EdgeRun,
    /// Whether every other edge's error exceeds the taken one's by more than the null spread.
    edge_told: bool,
    /// The face as given on the same steps, -.
    flat: Option<f64>,
}

/// The edge taken among `runs` (each edge's best point, the fitted tip side's first): the tip
/// side, unless another edge scores lower by more than `null` (then the lowest, NaN last); the
/// best of the others; and whether every other one is higher than the one taken by more than
/// `null`. None with fewer than two edges.
///
/// NOTE: taking the lowest outright let the edges run at three closings (a best of three draws
/// of the chaos) win over the tip side's one: a hidden 0.03 rad about y on the four-probe plan
/// was taken on the clamp side at -0.0357 (0.70 against the hidden edge's 1.02).
fn edge_taken(runs: &[EdgeRun], null: f64) -> Option<(EdgeRun, EdgeRun, bool)> {
    let lowest = |it: &mut dyn Iterator<Item = &EdgeRun>| {
        it.min_by(|a, b| nan_last(a.error).total_cmp(&nan_last(b.error)))
            .copied()
    };
    let (tip, best) = (*runs.first()?, lowest(&mut runs.iter())?);
    let taken = match best.error + null < nan_last(tip.error) {
        true => best,
        false => tip,
    };
    let other = lowest(&mut runs.iter().filter(|r| r.edge != taken.edge))?;
    Some((taken, other, other.error - taken.error > null))
}

/// The tilt whose model runs match the train tests `train` best where a tilted face first
/// closes: each test's steps from two before its first measured contact to two past it
/// ([`evidence_steps`]) at the clearance fits' finer twin step, each angle's error the median
/// per step over the band's draws, the tests weighted by how sharply their own clearance fits
/// told their first contact (`spreads`, m: [`sharpness_weights`]), as the clearance offset is
/// fitted. The tip-side edge (`edges[0]`) on a grid of 9 over the edge closings `range` (m),
/// refined once around the best; its angle the mean of the valley's floor ([`valley_floor`]);
/// then every other edge of `edges` at [`EDGE_CLOSINGS`] of that closing, and the face as
/// given; the edge taken by [`edge_taken`]. `None` where no run compared.
///
/// NOTE: over the whole band the angles' errors are draws of its chaos: a grid over every
/// contact step of the train tests took -0.0282 rad (+41 %, the other edge) for a hidden 0.02
/// and -0.0362 (+21 %) for 0.03 on the four-probe plan, its best points 5 % apart differing by
/// 0.3-0.6 (BENCHMARKS.md, "A hidden tilt (issue 15)"). The steps about the first contact carry
/// the face's geometry (where an edge first touches, how much contact follows), as they carry a
/// clearance; the later ones, chaos and the twin's own step.
fn fit_by_runs(
    work: &mut Work<'_>,
    base: &PhysicsSpec,
    edges: &[Edge],
    train: &[&TestClearance],
    spreads: &[f64],
    (lo, hi): (f64, f64),
) -> Result<Option<TiltFit>, DiagnoseError> {
    let tip = edges[0];
    let (a_lo, a_hi) = (tip.angle(lo), tip.angle(hi));
    let h = (a_hi - a_lo) / 8.0;
    let grid: Vec<f64> = (0..9)
        .map(|k| a_lo + h * k as f64)
        .filter(|a| *a > 0.0)
        .collect();
    let weighted: Vec<(usize, f64)> = (train.iter().map(|t| t.test_index))
        .zip(sharpness_weights(spreads))
        .collect();
    // Every run starts from a state of open contact two steps before each test's first
    // contact, captured with the clearances closed by more than any edge tried.
    let widest = 1.1 * tip.closing(a_hi + 0.5 * h);
    let train_idx: Vec<usize> = weighted.iter().map(|w| w.0).collect();
    let spans = open_spans(
        work,
        base,
        (train, &train_idx),
        widest,
        FIT_REFINEMENT,
        evidence_steps,
    )?;
    let members = work.opts.band_members;
    let error = |_: &mut Work<'_>, _: f64, runs: &[Vec<super::outcome::StepScores>]| {
        weighted_tests_error(runs, &weighted)
    };
    // The edges' points about the tip side's `mean`, (edge, angle): the tip side's own, every
    // other edge at [`EDGE_CLOSINGS`] of its closing (within the widest the spans admit).
    let points_at = |mean: f64| -> Vec<(usize, f64)> {
        let c = tip.closing(mean);
        std::iter::once((0, mean))
            .chain(
                (edges.iter().enumerate().skip(1))
                    .flat_map(|(k, e)| EDGE_CLOSINGS.map(|f| (k, e.angle((f * c).min(widest))))),
            )
            .collect()
    };
    let (tried, checks) = work.at_finer_step(FIT_REFINEMENT, |w| {
        let plan = |_: &Work<'_>, a: f64| (with_tilt(base, tip.axis, a), spans.clone());
        let tried = grid_then_refine(
            w,
            grid,
            |best| {
                refined_around(best, h)
                    .into_iter()
                    .filter(|a| *a > 0.0)
                    .collect()
            },
            &plan,
            members,
            error,
        )?;
        let Some((mean, _, _)) = valley_floor(&tried) else {
            return Ok::<_, DiagnoseError>((tried, Vec::new()));
        };
        // The face as given (point 0) and the edges' points (point j + 1, `points_at`'s j).
        let models: Vec<PhysicsSpec> = std::iter::once(base.clone())
            .chain((points_at(mean).into_iter()).map(|(k, a)| with_tilt(base, edges[k].axis, a)))
            .collect();
        let by_index = |_: &Work<'_>, k: f64| (models[k as usize].clone(), spans.clone());
        let points = (0..models.len()).map(|k| k as f64).collect();
        let checks = grid_then_refine(w, points, |_| Vec::new(), &by_index, members, error)?;
        Ok((tried, checks))
    })?;
    let (Some(&(best, best_error)), Some((mean, _, floor))) = (
        tried.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
        valley_floor(&tried),
    ) else {
        return Ok(None);
    };
    let at = |k: usize| checks.iter().find(|c| c.0 == k as f64).map(|c| c.1);
    let flat = at(0);
    let points: Vec<EdgeRun> = (points_at(mean).into_iter().enumerate())
        .map(|(j, (k, angle))| EdgeRun {
            edge: edges[k],
            angle,
            error: at(j + 1).unwrap_or(f64::NAN),
        })
        .collect();
    // Each edge's best point (NaN last).
    let runs: Vec<EdgeRun> = (edges.iter())
        .filter_map(|e| {
            (points.iter().filter(|p| p.edge == *e))
                .min_by(|a, b| nan_last(a.error).total_cmp(&nan_last(b.error)))
                .copied()
        })
        .collect();
    // The null spread of a band fit's own steps at the finer step (its valley, the edges).
    let null = work.opts.fitted_steps_null_spread;
    let Some((taken, other, edge_told)) = edge_taken(&runs, null) else {
        return Ok(None);
    };
    let mut tried = tried;
    if !tried.iter().any(|p| p.0 == mean) && runs[0].error.is_finite() {
        tried.push((mean, runs[0].error));
    }
    // The spread in the taken edge's angle: the tip side's valley, scaled to its edge.
    let scale = tip.extent / taken.edge.extent;
    Ok(Some(TiltFit {
        taken,
        spread: scale * valley_spread(&tried, (best, best_error), null),
        edge_told,
        tried,
        floor,
        edges: runs,
        points,
        other,
        flat,
    }))
}

/// `x`, or infinity where it is NaN: an ordering key that puts NaN last.
fn nan_last(x: f64) -> f64 {
    if x.is_nan() {
        f64::INFINITY
    } else {
        x
    }
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
    let all_edges = edges(rom);
    if all_edges[0].extent <= 0.0 || all_edges[1].extent <= 0.0 {
        work.undecided(
            "tilt",
            "the contact patch has no extent along the beams in the ROM",
        );
        return Ok(());
    }
    // A patch one pair wide has no edge across the beams.
    let edges: Vec<Edge> = (all_edges.into_iter()).filter(|e| e.extent > 0.0).collect();
    let idx: Vec<usize> = bracketed.iter().map(|t| t.test_index).collect();
    let (train, validation) = alternate(&idx);
    // The train tests' clearance before the first impact against the base model's, by the
    // same model runs as the clearance stage (shared through the cache).
    let after_clearance = std::mem::replace(&mut work.accepted, base.clone());
    let mut closes = Vec::new();
    let mut spreads = Vec::new();
    for t in bracketed.iter().filter(|t| train.contains(&t.test_index)) {
        // One spread per train test (NaN where its runs compared nothing: equal weights).
        match test_clearance_by_runs(work, t)? {
            Some(r) => {
                closes.push(base.test_clearance(&t.test, t.plan_clearance_m) - r.clearance_m);
                spreads.push(r.spread_m);
            }
            None => spreads.push(f64::NAN),
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
    let train_tests: Vec<&TestClearance> = (bracketed.iter().copied())
        .filter(|t| train.contains(&t.test_index))
        .collect();
    let range = closing_range(base, &train_tests, closing);
    let fit = fit_by_runs(work, base, &edges, &train_tests, &spreads, range)?;
    let Some(fit) = fit else {
        work.accepted = after_clearance;
        return Ok(());
    };
    let (taken, other) = (fit.taken, fit.other);
    let (angle, axis) = (taken.angle, taken.edge.axis);
    let about = axis_name(axis);
    let with = |angle: f64| with_tilt(base, axis, angle);
    (work.progress)(DiagnoseProgress::Note(format!(
        "tilt: {angle:.3e} +- {:.1e} rad about {about} by {} angles tried on the train tests' steps about their first contact (the {} edge, closing {:.2e} m early, scores {:.3}; the {} edge's best {:.3})",
        fit.spread,
        // The tip side's runs (its floor mean among them), every other edge's points.
        fit.tried.len() + fit.points.len() - 1,
        taken.edge.name,
        taken.edge.closing(angle),
        taken.error,
        other.edge.name,
        other.error,
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
    // The clearance offset as fitted, accepted or not (the model as given where none was).
    let offset_model = (work.effects.iter())
        .rposition(|e| e.effect == "clearance")
        .and_then(|i| work.judged_model(i).cloned())
        .unwrap_or_else(|| after_clearance.clone());
    let s_clear = work.scores(&offset_model, &all)?;
    let edge_run = |r: &EdgeRun| {
        json!({
            "edge": r.edge.name,
            "axis": r.edge.axis,
            "angle": r.angle,
            "closing_m": r.edge.closing(r.angle),
            "train_error": r.error,
        })
    };
    let mut other_edge = edge_run(&other);
    other_edge["told"] = json!(fit.edge_told);
    let evidence = json!({
        "edge": taken.edge.name,
        "edge_closing_m": taken.edge.closing(angle),
        "runs_closing_m": closing,
        "patch_edges_m": (edges.iter())
            .map(|e| (e.name.to_string(), json!(e.extent)))
            .collect::<serde_json::Map<_, _>>(),
        "axis": axis,
        "validation_contact_score_rms": {
            "model_before": contact_rms(&s_base),
            "with_tilt": contact_rms(&s_tilt),
            "with_clearance_offset": contact_rms(&s_clear),
        },
        "closing_range_m": [range.0, range.1],
        "angles_tried": (fit.tried.iter())
            .map(|&(a, e)| json!({"angle": a, "closing_m": edges[0].closing(a), "train_error": e}))
            .collect::<Vec<_>>(),
        "edges": fit.edges.iter().map(edge_run).collect::<Vec<_>>(),
        "edge_points": fit.points.iter().map(edge_run).collect::<Vec<_>>(),
        "train_error_without_tilt": fit.flat,
        "angle_spread": fit.spread,
        "closing_spread_m": fit.spread * taken.edge.extent,
        "floor_angles": fit.floor,
        "other_edge": other_edge,
        "steps": FIT_STEPS,
    });
    // Where the whole tests reject it, judged where it was fitted, as the clearance offset is:
    // each judged test's steps about its first contact at the fit's finer step.
    let fitted_spans = open_spans(
        work,
        base,
        (&bracketed, &all),
        1.1 * range.1,
        FIT_REFINEMENT,
        evidence_steps,
    )?;
    let cand = Candidate::new(
        "tilt",
        with(angle),
        json!({"angle": angle, "axis": axis}),
        1,
        evidence,
        (train.clone(), validation.clone()),
        Steps::All,
    )
    .judged_where_fitted(fitted_spans, FIT_REFINEMENT, WHERE_FITTED);
    let tilt_ok = work.judge(cand)?;
    // The edges the runs do not tell from the one taken: about the same closing, another
    // angle.
    let edge_null = work.opts.fitted_steps_null_spread;
    let untold: Vec<String> = (fit.edges.iter())
        .filter(|r| r.edge != taken.edge && r.error <= taken.error + edge_null)
        .map(|r| {
            format!(
                "tilt {} (the {} edge, closing {:.1} um early: train error {:.3} against {:.3}, within the null spread {edge_null} of the steps about the first contact)",
                json!({"angle": r.angle, "axis": r.edge.axis}),
                r.edge.name.replace('_', " "),
                1e6 * r.edge.closing(r.angle),
                r.error,
                taken.error
            )
        })
        .collect();
    if let Some(t) = work.effects.last_mut().filter(|e| e.effect == "tilt") {
        t.alternatives.extend(untold);
    }
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
    // The tilt and the offset compared where a tilt acts (validation errors, with the tilt and
    // with the offset), recorded in the tilt's evidence; None where nothing compared.
    let in_contact = |work: &mut Work<'_>| -> Result<Option<(f64, f64)>, DiagnoseError> {
        let spans = open_spans(
            work,
            base,
            (&bracketed, &all),
            1.1 * range.1,
            1,
            |w: &Work<'_>, ti| {
                let from = w.steps.before_first_contact(ti, 2);
                (from, w.steps.past_contact(ti, 2, false))
            },
        )?;
        let cmp = Candidate::new(
            "tilt",
            with(angle),
            json!({}),
            1,
            json!({}),
            (train.clone(), validation.clone()),
            Steps::All,
        )
        .judged_where_fitted(spans, 1, IN_CONTACT);
        let (Some(t), Some(c)) = (
            work.errors(&with(angle), &cmp, true)?,
            work.errors(&after_clearance, &cmp, true)?,
        ) else {
            return Ok(None);
        };
        work.effects[ti].evidence["in_contact_against_clearance"] = json!({
            "steps": IN_CONTACT,
            "validation_with_tilt": t.validation,
            "validation_with_clearance": c.validation,
        });
        Ok(Some((t.validation, c.validation)))
    };
    if !tilt_ok {
        work.accepted = after_clearance.clone();
        // Rejected beside an accepted clearance offset: the two compared where a tilt acts.
        // Within the null spread of each other there, the session cannot tell them apart.
        let Some((t, c)) = in_contact(work)? else {
            return Ok(());
        };
        let c_param = work.effects[ci].parameters.clone();
        let tilt = &mut work.effects[ti];
        if t <= c + null {
            tilt.reason = format!(
                "{}; where a tilt acts ({IN_CONTACT}) its validation error {t:.3} is within the impact band's null spread {null} of the clearance offset's {c:.3}: an equal alternative of it, the channels cannot tell a tilted face from a smaller clearance here",
                tilt.reason
            );
            tilt.alternatives.push(format!(
                "clearance {c_param} (equal where a tilt acts: validation {c:.3})"
            ));
            work.effects[ci].alternatives.push(format!(
                "tilt: {angle:.3e} rad about {about} (equal where a tilt acts, {IN_CONTACT}: validation {t:.3} against {c:.3}; rejected)"
            ));
        }
        return Ok(());
    }
    // Both accepted: compared on the steps both were judged on (the whole tests, or where
    // each was fitted), else where a tilt acts.
    let where_fitted = |e: &EffectResult| e.evidence.get("judged_on").is_some();
    let (t_after, c_after, null) =
        match where_fitted(&work.effects[ti]) == where_fitted(&work.effects[ci]) {
            true if where_fitted(&work.effects[ti]) => {
                (t_after, c_after, work.opts.fitted_steps_null_spread)
            }
            true => (t_after, c_after, null),
            // Nothing compared where a tilt acts: errors on different steps do not tell the
            // two apart, so neither replaces the other (an infinite spread).
            false => match in_contact(work)? {
                Some((t, c)) => (t, c, null),
                None => (t_after, c_after, f64::INFINITY),
            },
        };
    let within = match null.is_finite() {
        true => format!("within the null spread {null} of each other"),
        false => {
            "judged on different steps, and no step where a tilt acts compared them".to_string()
        }
    };
    let c_param = work.effects[ci].parameters.clone();
    if t_after + null < c_after {
        // The tilt predicts the validation tests better beyond the null spread: it replaces
        // the offset (the model is `base` with the tilt, as judged).
        let c = &mut work.effects[ci];
        c.accepted = false;
        c.reason = format!("replaced by the tilt, which predicts the validation tests better ({t_after:.3} against {c_after:.3}, beyond the null spread {null})");
        c.alternatives.push(format!(
            "tilt: {angle:.3e} rad about {about} (better on validation)"
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
        t.reason = format!("an equal alternative of the clearance offset: both lower the validation error beyond the null spread, to {t_after:.3} (tilt) and {c_after:.3} (clearance), {within}; the channels cannot tell a tilted face from a smaller clearance here, the clearance stays in the model");
        t.alternatives.push(format!(
            "clearance {c_param} (equal: validation {c_after:.3})"
        ));
        work.effects[ci].alternatives.push(format!(
            "tilt: {angle:.3e} rad about {about} (equal: validation {t_after:.3}; the channels cannot tell them apart)"
        ));
    }
    Ok(())
}

/// Where a tilt acts ([`open_spans`] from two before each test's first measured contact to two
/// past its last), in words.
const IN_CONTACT: &str =
    "each test's steps from two before its first measured contact to two past its last";

/// Where a tilt is fitted ([`evidence_steps`]), in words.
const WHERE_FITTED: &str =
    "each test's steps from two before its first measured contact to two past it";

/// The spans `steps` gives (first step, last or None for the test's end) of tests `tests`
/// (indices, with `bracketed` for their plan clearances) at a twin step `refinement` times
/// finer than the given one, each from a state of open contact captured with the clearances
/// of `base` closed by `closing` (m; [`Work::open_span`]).
fn open_spans(
    work: &mut Work<'_>,
    base: &PhysicsSpec,
    (bracketed, tests): (&[&TestClearance], &[usize]),
    closing: f64,
    refinement: u32,
    steps: impl Fn(&Work<'_>, usize) -> (usize, Option<usize>),
) -> Result<Vec<Span>, DiagnoseError> {
    let named: Vec<(&str, f64)> = (tests.iter())
        .map(|&ti| {
            let plan = (bracketed.iter())
                .find(|b| b.test_index == ti)
                .map_or(0.0, |b| b.plan_clearance_m);
            (work.steps.tests[ti].as_str(), plan)
        })
        .collect();
    let closest = closed_by(base, &named, closing);
    work.at_finer_step(refinement, |w| {
        let mut spans = Vec::new();
        for &ti in tests {
            let (from, through) = steps(w, ti);
            spans.push(w.open_span(&closest, ti, from, through)?);
        }
        Ok(spans)
    })
}

/// `base` with the clearance of each test of `tests`, (name, the plan's clearance m), closed
/// by `closing` (m): a geometry nowhere more open than the runs that start from its state.
fn closed_by(base: &PhysicsSpec, tests: &[(&str, f64)], closing: f64) -> PhysicsSpec {
    (tests.iter()).fold(base.clone(), |ext, &(name, plan)| {
        ext.with_test_clearance(name, base.test_clearance(name, plan) - closing)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A train test `name` bracketed by `bounds` (m) about the plan's 699 um.
    fn bracketed(name: &str, bounds: (f64, f64)) -> TestClearance {
        TestClearance {
            test: name.into(),
            plan_clearance_m: 699e-6,
            lower_bound_m: Some(bounds.0),
            upper_bound_m: Some(bounds.1),
            ..super::super::clearance::tests::test(0, Some(bounds.1))
        }
    }

    #[test]
    fn the_closings_searched_lie_about_the_runs_within_every_bracket() {
        let base = PhysicsSpec::default();
        let near = |(lo, hi): (f64, f64), (a, b): (f64, f64)| {
            assert!(
                (lo - a).abs() < 1e-12 && (hi - b).abs() < 1e-12,
                "{lo} {hi} for {a} {b}"
            );
        };
        // Brackets wide about the plan: 0.4 times the runs' closing, to what the second admits
        // (699 - 591 um).
        let (a, b) = (
            bracketed("probe-1", (439e-6, 1065e-6)),
            bracketed("probe-3", (591e-6, 1523e-6)),
        );
        near(closing_range(&base, &[&a, &b], 80e-6), (32e-6, 108e-6));
        near(closing_range(&base, &[&a], 80e-6), (32e-6, 160e-6));
        // A bracket whose first contact came no earlier than 699 - 620 = 79 um before the
        // model's, and one no later than 699 - 660 = 39 um: 39 to 79 um.
        let c = bracketed("probe-1", (620e-6, 700e-6));
        let d = bracketed("probe-3", (500e-6, 660e-6));
        near(closing_range(&base, &[&c, &d], 80e-6), (39e-6, 79e-6));
        near(closing_range(&base, &[&d], 60e-6), (39e-6, 120e-6));
        // Brackets that share no closing with the runs': the runs' range alone.
        let e = bracketed("probe-1", (690e-6, 700e-6));
        near(closing_range(&base, &[&e], 80e-6), (32e-6, 160e-6));
    }

    #[test]
    fn the_face_as_given_carries_no_tilt() {
        let base = PhysicsSpec::default();
        assert_eq!(with_tilt(&base, [0.0, 1.0], 0.0), base);
        let t = with_tilt(&base, [1.0, 0.0], -0.02).tilt.unwrap();
        assert_eq!((t.angle, t.axis), (-0.02, [1.0, 0.0]));
    }

    /// The embedded rig's patch edges: 3 mm along the beams each side, 2.1 mm across them.
    fn patch_edges() -> [Edge; 4] {
        let e = |name, axis, sign, extent| Edge {
            name,
            axis,
            sign,
            extent,
        };
        [
            e("tip_side", [0.0, 1.0], 1.0, 3e-3),
            e("clamp_side", [0.0, 1.0], -1.0, 3e-3),
            e("smaller_y_side", [1.0, 0.0], 1.0, 2.1e-3),
            e("larger_y_side", [1.0, 0.0], -1.0, 2.1e-3),
        ]
    }

    #[test]
    fn each_edge_closes_as_early_at_its_own_angle() {
        let edges = patch_edges();
        let closing = 63e-6;
        let angles: Vec<f64> = edges.iter().map(|e| e.angle(closing)).collect();
        assert!(
            (angles[0] - 0.021).abs() < 1e-5 && angles[1] == -angles[0],
            "{angles:?}"
        );
        assert!(
            (angles[2] - 0.03).abs() < 1e-5 && angles[3] == -angles[2],
            "{angles:?}"
        );
        for (e, a) in edges.iter().zip(&angles) {
            assert!((e.closing(*a) - closing).abs() < 1e-15);
            // The tilt the model carries closes that edge by as much (`physics::tilt`).
            let x = if e.axis[1] != 0.0 {
                e.sign * e.extent
            } else {
                0.0
            };
            let y = if e.axis[0] != 0.0 {
                -e.sign * e.extent
            } else {
                0.0
            };
            let spec = TiltSpec {
                angle: *a,
                axis: e.axis,
            };
            let off = crate::physics::tilt::gap_offsets(
                &[[x, y, 0.0], [-x, -y, 0.0]],
                &[1.0, 1.0],
                &spec,
            );
            assert!((off[0] + closing).abs() < 1e-12, "{}: {off:?}", e.name);
        }
    }

    #[test]
    fn the_fitted_tip_side_is_taken_unless_another_edge_is_lower_beyond_the_null_spread() {
        let [tip, clamp, across, _] = patch_edges();
        let run = |edge, error| EdgeRun {
            edge,
            angle: 0.02,
            error,
        };
        let runs = [run(tip, 1.4), run(clamp, 2.1), run(across, 0.8)];
        let (taken, other, told) = edge_taken(&runs, 0.5).unwrap();
        assert_eq!(
            (taken.edge.name, other.edge.name, told),
            ("smaller_y_side", "tip_side", true)
        );
        let (_, _, told) = edge_taken(&runs, 0.7).unwrap();
        assert!(!told);
        // Lower within the null spread: the fitted tip side stays, told from nothing.
        let runs = [run(tip, 1.2), run(clamp, 2.1), run(across, 0.8)];
        let (taken, other, told) = edge_taken(&runs, 0.5).unwrap();
        assert_eq!(
            (taken.edge.name, other.edge.name, told),
            ("tip_side", "smaller_y_side", false)
        );
        // A run that compared nothing is never taken, and tells nothing.
        let runs = [run(tip, f64::NAN), run(clamp, 2.1)];
        let (taken, other, told) = edge_taken(&runs, 0.5).unwrap();
        assert_eq!(
            (taken.edge.name, other.edge.name, told),
            ("clamp_side", "tip_side", false)
        );
        assert_eq!(edge_taken(&runs[..1], 0.5), None);
    }

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
