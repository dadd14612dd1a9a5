//! The wear stage of the diagnosis: the clearance per test against the contact work the
//! model has dissipated before it (not the wall time), and `[model.wear]` fitted by re-runs
//! of the whole session (wear carries across tests).
//!
//! 1. The clearance of every test that brackets it (impact-free steps, then contact;
//!    [`super::clearance`], reference section 4, Table 2) is refined by model runs of that
//!    test alone over its bracket (`clearance_fit::test_clearance_by_runs`, shared with the
//!    clearance and tilt stages).
//! 2. The accumulated contact work `W` at the start of each test comes from one run of the
//!    model as accepted so far from the session's start to the last bracketed test's first
//!    step, with the wear counter on and a zero coefficient
//!    ([`super::rerun::ModelRunner::contact_work`]): what the contact dissipated before the
//!    test's first impact.
//! 3. The clearances against `W`: a straight line `c - c_plan = a + k W`. A constant offset
//!    has no trend with `W` (`k` within 3 standard errors of zero, or a growth over the
//!    session below 2 % of the plan's clearance): no wear, the pipeline's clearance stage
//!    judges the offset. A trend is wear: its coefficient `k` (m/J) from the train tests'
//!    points, then refined by whole-session model runs scored on the train tests only
//!    (every step and channel), validated on the other bracketed tests by the pipeline's rule.
//!    `max_growth` is fitted only where the clearance levels off within the session: the
//!    largest growth seen is compared with the line's.

use serde_json::json;

use crate::config::{ClearanceSpec, WearSpec};

use super::clearance::{ClearanceEvidence, TestClearance};
use super::clearance_fit::test_clearance_by_runs;
use super::judge::{alternate, grid_then_refine, set_error, Candidate, Steps, Work};
use super::outcome::EffectResult;
use super::rerun::Span;
use super::{DiagnoseError, DiagnoseProgress};

/// Least-squares line `y = a + k x`: (a, k, standard error of k, NaN with two points); `None`
/// with fewer than two points or no spread in `x`.
fn line(points: &[(f64, f64)]) -> Option<(f64, f64, f64)> {
    let n = points.len();
    if n < 2 {
        return None;
    }
    let nf = n as f64;
    let mx = points.iter().map(|p| p.0).sum::<f64>() / nf;
    let my = points.iter().map(|p| p.1).sum::<f64>() / nf;
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    // NOTE: relative to the scale of x: equal x's leave a round-off spread, not zero.
    let scale: f64 = points.iter().map(|p| p.0 * p.0).sum();
    if sxx.is_nan() || sxx <= 1e-12 * scale {
        return None;
    }
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let k = sxy / sxx;
    let a = my - k * mx;
    let se = if n > 2 {
        let rss: f64 = points.iter().map(|p| (p.1 - a - k * p.0).powi(2)).sum();
        (rss / (nf - 2.0) / sxx).sqrt()
    } else {
        f64::NAN
    };
    Some((a, k, se))
}

/// What the wear stage measured, for the evidence figure.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WearPoint {
    /// Test name.
    pub test: String,
    /// The model's dissipated contact work before the test, J.
    pub contact_work_j: f64,
    /// The measured clearance (refined by model runs within the bracket), m.
    pub clearance_m: f64,
    /// The plan's clearance, m.
    pub plan_clearance_m: f64,
    /// The bracket of the first contact, m.
    pub bracket_m: [f64; 2],
    /// Whether the point was used to fit (else it validates).
    pub train: bool,
}

/// Stage 4a: wear (module docs). Returns whether wear was accepted. `ce` is the clearance
/// evidence of the session.
pub(super) fn wear_stage(
    work: &mut Work<'_>,
    ce: &mut ClearanceEvidence,
) -> Result<bool, DiagnoseError> {
    let is_bracketed = |t: &TestClearance| t.clearance_m.is_some() && t.lower_bound_m.is_some();
    let n = ce.tests.iter().filter(|t| is_bracketed(t)).count();
    if n < 3 {
        work.undecided(
            "wear",
            format!("{n} test(s) bracket the clearance (impact-free steps, then contact); its trend with the contact work needs three or more, two to fit and one to validate"),
        );
        return Ok(false);
    }
    let accepted = work.accepted.clone();
    let last = ce
        .tests
        .iter()
        .filter(|t| is_bracketed(t))
        .map(|t| t.test_index)
        .max()
        .unwrap_or(0);
    let contact_work = work.runner.contact_work(&accepted, last)?;
    for t in &mut ce.tests {
        t.accumulated_contact_work_j = contact_work.get(t.test_index).copied().flatten();
    }
    let ce = &*ce;
    let bracketed: Vec<&TestClearance> = ce.tests.iter().filter(|t| is_bracketed(t)).collect();
    let w_of = |t: &TestClearance| contact_work.get(t.test_index).copied().flatten();
    let ws: Vec<f64> = bracketed.iter().filter_map(|t| w_of(t)).collect();
    let (wmin, wmax) = ws
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &w| {
            (a.min(w), b.max(w))
        });
    if ws.len() < 3 || (wmax - wmin).is_nan() || wmax - wmin <= 1e-6 {
        work.undecided(
            "wear",
            format!("the model's contact dissipates {:.2e} J between the first and last bracketed tests: nothing for wear to grow with", (wmax - wmin).max(0.0)),
        );
        return Ok(false);
    }
    (work.progress)(DiagnoseProgress::Note(format!(
        "wear: the model's contact work before the bracketed tests: {}",
        bracketed
            .iter()
            .map(|t| format!("{} {:.3e} J", t.test, w_of(t).unwrap_or(f64::NAN)))
            .collect::<Vec<_>>()
            .join(", ")
    )));
    let idx: Vec<usize> = bracketed.iter().map(|t| t.test_index).collect();
    let (train, validation) = alternate(&idx);
    let mut points: Vec<WearPoint> = Vec::new();
    for t in &bracketed {
        let (Some(w), Some(lo), Some(hi)) = (w_of(t), t.lower_bound_m, t.upper_bound_m) else {
            continue;
        };
        if let Some(r) = test_clearance_by_runs(work, t)? {
            points.push(WearPoint {
                test: t.test.clone(),
                contact_work_j: w,
                clearance_m: r.clearance_m,
                plan_clearance_m: t.plan_clearance_m,
                bracket_m: [lo.min(hi), lo.max(hi)],
                train: train.contains(&t.test_index),
            });
        }
    }
    let xy = |p: &WearPoint| (p.contact_work_j, p.clearance_m - p.plan_clearance_m);
    let all: Vec<(f64, f64)> = points.iter().map(xy).collect();
    let plan = bracketed[0].plan_clearance_m;
    let Some((a_all, k_all, se_all)) = line(&all) else {
        work.undecided(
            "wear",
            "the clearance per test could not be refined by model runs in three or more tests",
        );
        return Ok(false);
    };
    let growth = k_all * (wmax - wmin);
    let evidence = json!({
        "points": points,
        "line": {"intercept_m": a_all, "slope_m_per_j": k_all, "slope_standard_error_m_per_j": se_all},
        "growth_over_session_m": growth,
        "plan_clearance_m": plan,
        "against": "the model's dissipated contact work before each test (J)",
    });
    let trend = k_all > 0.0 && k_all > 3.0 * se_all && growth > 0.02 * plan;
    (work.progress)(DiagnoseProgress::Note(format!(
        "wear: clearance against contact work: slope {k_all:.3e} m/J (standard error {se_all:.1e}), growth {growth:.2e} m over the session: {}",
        if trend { "a trend" } else { "no trend (a constant offset is not wear)" }
    )));
    if !trend {
        work.effects.push(EffectResult {
            effect: "wear".into(),
            rank: 0,
            accepted: false,
            parameters: json!({}),
            alternatives: vec!["clearance: a constant offset (no trend with the contact work)".into()],
            evidence,
            reason: format!("no trend of the clearance with the contact work: slope {k_all:.2e} m/J, standard error {se_all:.1e} m/J, growth {growth:.2e} m over the session (3 standard errors and 2 % of the plan's clearance are needed)"),
            train_tests: Vec::new(),
            validation_tests: Vec::new(),
            error_before: None,
            error_after: None,
        });
        return Ok(false);
    }
    // The train tests' line (all points when they are fewer than two with spread in W).
    let tr: Vec<(f64, f64)> = points.iter().filter(|p| p.train).map(xy).collect();
    let (a0, k0) = match line(&tr) {
        Some((a, k, _)) if k > 0.0 => (a, k),
        _ => (a_all, k_all),
    };
    // A constant offset under the growth only where the train tests show one (2 % of plan).
    let offset = if a0.abs() > 0.02 * plan { a0 } else { 0.0 };
    let acc = work.accepted.clone();
    let base_offset = acc.clearance.as_ref().map_or(0.0, |c| c.offset);
    let with = |k: f64, g: Option<f64>| {
        let mut ext = acc.clone();
        if offset != 0.0 {
            ext.clearance = Some(ClearanceSpec {
                offset: base_offset + offset,
                tests: Vec::new(),
            });
        }
        ext.wear = Some(WearSpec {
            coefficient: k,
            max_growth: g,
        });
        ext
    };
    // The coefficient by whole-session runs scored on the train tests: a grid of 0.5-2 k0,
    // refined once around the best.
    let grid: Vec<f64> = [0.5, 0.75, 1.0, 1.25, 1.5, 2.0]
        .iter()
        .map(|m| m * k0)
        .collect();
    let train_spans: Vec<Span> = train.iter().map(|&t| Span::whole(t)).collect();
    let tried = grid_then_refine(
        work,
        grid,
        |best| vec![0.88 * best, 1.12 * best],
        &|_, k| (with(k, None), train_spans.clone()),
        |work, k, s| {
            (work.progress)(DiagnoseProgress::Evaluation(format!(
                "wear coefficient {k:.3e} m/J over the whole session"
            )));
            set_error(s, &train, Steps::All)
        },
    )?;
    let Some(&(k, train_error)) = tried.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        return Ok(false);
    };
    // max_growth: where the largest growth seen stays clearly under the line's, the clearance
    // levelled off; else it is not identified (none, unbounded).
    let last = points
        .iter()
        .max_by(|a, b| a.contact_work_j.total_cmp(&b.contact_work_j));
    let max_growth = last.and_then(|p| {
        let seen = p.clearance_m - p.plan_clearance_m - offset;
        let line_growth = k * p.contact_work_j;
        (seen > 0.0 && seen < 0.5 * line_growth).then_some(seen)
    });
    (work.progress)(DiagnoseProgress::Note(format!(
        "wear: coefficient {k:.3e} m/J by {} whole-session runs (train error {train_error:.3}; start {k0:.3e} from the train tests' clearances){}",
        tried.len(),
        max_growth.map_or(String::new(), |g| format!(", levelling off at {g:.2e} m"))
    )));
    let ext = with(k, max_growth);
    let mut parameters = json!({"coefficient": k, "max_growth": max_growth});
    if offset != 0.0 {
        parameters["clearance_offset"] = json!(base_offset + offset);
    }
    let cand = Candidate::new(
        "wear",
        ext,
        parameters,
        1 + usize::from(offset != 0.0) + usize::from(max_growth.is_some()),
        evidence,
        (train, validation),
        Steps::All,
    );
    work.judge(cand)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_recovers_a_slope_and_its_error() {
        let pts: Vec<(f64, f64)> = (0..5)
            .map(|i| (0.1 * i as f64, 1e-5 + 2e-4 * 0.1 * i as f64))
            .collect();
        let (a, k, se) = line(&pts).unwrap();
        assert!((a - 1e-5).abs() < 1e-15 && (k - 2e-4).abs() < 1e-12 && se < 1e-12);
        // No spread in W: no line.
        assert!(line(&[(0.1, 1.0), (0.1, 2.0), (0.1, 3.0)]).is_none());
        // Scattered without trend: a slope within its standard error.
        let (_, k, se) =
            line(&[(0.0, 1.0), (1.0, -1.0), (2.0, 1.0), (3.0, -1.0), (4.0, 0.5)]).unwrap();
        assert!(k.abs() < 3.0 * se, "{k} {se}");
    }
}
