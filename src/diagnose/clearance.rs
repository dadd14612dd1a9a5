//! The clearance per test from the relative tip displacement before the first impact
//! (reference section 4, Table 2), and its trend over the session (wear).
//!
//! In every record window the tips' displacements relative to the base (drift-free integrals
//! of the measured relative velocities) give the largest closing excursion `max(-(x_upper -
//! x_lower))` ([`super::evidence::WindowEvidence::closing_peak`]). The probes touch when it
//! reaches the clearance, so per test, in session order:
//! - every impact-free window before the first window with contact (contact-resistance
//!   channel) bounds the clearance from below: the largest of their closing excursions;
//! - the first window with contact bounds it from above: its closing excursion reached the
//!   clearance (its zero-mean displacement even overstates it by the mean opening the impacts
//!   push the tips to, a bound all the same).
//!
//! The estimate is the upper bound: in the first window with contact the impacts cap the
//! closing excursion at the clearance, so it measures the clearance itself (overstated by the
//! mean opening, a few per cent on the default rig), while the last impact-free window falls
//! short of it by however much the response still grows to the next frequency step (tens of
//! per cent in 0.005 omega_2 steps near the band). The bracket is the uncertainty: the
//! clearance lies between the bounds.
//!
//! A second estimate does not depend on the plan's frequency steps: at every contact onset (a
//! closed sample of the contact-resistance channel after an open one) the probes have just
//! met, so the closing excursion there is the clearance. Its mean over every onset of the
//! test's windows with contact ([`TestClearance::onset_clearance_m`]; tens of onsets per
//! test on a grazing sweep) scatters much less than the upper bound, though each onset's
//! reading is off by tens of per cent (the higher modes ring after an impact), and it reads
//! up to 5 % low where the impacts push the probes apart (the zero-mean displacement hides
//! the mean opening; BENCHMARKS.md, "Wear on six probes, and the clearance at the contact
//! onsets").
//!
//! The sensors sit at the tips, the contact nearer the
//! clamp: excursions are scaled to the contact by [`ClearanceOptions::contact_over_sensor`]
//! (the ratio of the first bending mode's displacements there) and the model's static
//! relative offset at the contact, if any, is
//! added. A test without contact gives a lower bound only; a test in contact from its first
//! window gives none. Across tests, [`clearance_trend`] fits the clearances against any
//! abscissa: the session order here, the accumulated normal contact impulse once a model
//! supplies it
//! ([`TestClearance::accumulated_contact_impulse_ns`] is the hook).

use serde::Serialize;

use crate::config::RigConfig;
use crate::session::replay::Recording;
use crate::signal::features::standard_error;

use super::error::EvidenceError;
use super::evidence::{session_evidence, SessionEvidence, WindowEvidence};

/// What the clearance estimate needs from the rig description.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ClearanceOptions {
    /// Beam length l, m (clearances in units of l).
    pub beam_length: f64,
    /// Displacement at the contact over displacement at the tip sensors in the first bending
    /// mode, -: scales the measured excursions to the contact. 1 for sensors at the contact.
    pub contact_over_sensor: f64,
    /// The model's static relative displacement upper - lower at the contact at rest, m
    /// (positive: opening), added to the bounds. Default 0 (no static load in the model).
    pub static_offset: f64,
}

impl ClearanceOptions {
    /// The options of rig description `cfg`: its beam length, and the ratio of a uniform
    /// Euler-Bernoulli cantilever's first mode shape at the probe seat's centre to that at the
    /// `upper_tip` sensor (1 without such a sensor).
    pub fn of_rig(cfg: &RigConfig) -> ClearanceOptions {
        let l = cfg.rig.beam_length;
        let sensor_x = cfg
            .sensors
            .iter()
            .find(|s| s.name == crate::rig::channels::UPPER_TIP)
            .map(|s| s.x);
        let contact_over_sensor = sensor_x.map_or(1.0, |x| {
            cantilever_first_mode(cfg.probe_seat.x_center / l) / cantilever_first_mode(x / l)
        });
        ClearanceOptions {
            beam_length: l,
            contact_over_sensor,
            static_offset: 0.0,
        }
    }
}

/// The first bending mode of a uniform Euler-Bernoulli cantilever at `xi = x / l` (clamp at
/// 0), unnormalised.
pub fn cantilever_first_mode(xi: f64) -> f64 {
    // NOTE: beta l of the first mode, 1.8751; sigma = (cosh + cos) / (sinh + sin) at beta l.
    let b: f64 = 1.875_104_068_711_961;
    let sigma = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let x = b * xi.clamp(0.0, 1.0);
    x.cosh() - x.cos() - sigma * (x.sinh() - x.sin())
}

/// The clearance of one test.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct TestClearance {
    /// Test name.
    pub test: String,
    /// Index of the test in the session, from 0.
    pub test_index: usize,
    /// Base level / l (the plan's).
    pub level: f64,
    /// Rig time of the test's first record window, s.
    pub start_s: f64,
    /// The plan's clearance (what the model assumed), m.
    pub plan_clearance_m: f64,
    /// Estimate: the closing excursion of the first window with contact, m (None without both
    /// bounds; module docs).
    pub clearance_m: Option<f64>,
    /// The estimate / l.
    pub clearance_l: Option<f64>,
    /// The bracket's width (upper - lower bound), m: the clearance lies between the bounds.
    pub uncertainty_m: Option<f64>,
    /// Lower bound: the largest closing excursion before the first contact, m.
    pub lower_bound_m: Option<f64>,
    /// Upper bound: the closing excursion of the first window with contact, m.
    pub upper_bound_m: Option<f64>,
    /// Omega / omega_2 of the window giving the lower bound.
    pub lower_bound_omega_ratio: Option<f64>,
    /// Omega / omega_2 of the first window with contact.
    pub first_contact_omega_ratio: Option<f64>,
    /// Impact-free windows before the first contact.
    pub impact_free_windows: usize,
    /// Second estimate: the mean closing excursion at the contact onsets of the test's windows
    /// with contact (all of them), scaled to the contact like the bounds, m (None without an
    /// onset; module docs).
    pub onset_clearance_m: Option<f64>,
    /// Contact onsets behind [`Self::onset_clearance_m`].
    pub onsets: usize,
    /// Standard error of [`Self::onset_clearance_m`], m: the onsets' sample standard deviation
    /// over the square root of their number (None with fewer than two onsets).
    pub onset_standard_error_m: Option<f64>,
    /// Normal contact impulse the model accumulated before the test, N s: not measured,
    /// filled in by a model run (the abscissa of the wear trend). None here.
    pub accumulated_contact_impulse_ns: Option<f64>,
    /// What limits the estimate, in words (empty for a bracketed test).
    pub note: String,
}

/// A trend of the clearance over the tests.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ClearanceTrend {
    /// What the abscissa is (`session order`, `accumulated normal contact impulse, N s`, ...).
    pub against: String,
    /// Clearance at abscissa 0, m.
    pub intercept_m: f64,
    /// Clearance change per unit of the abscissa, m.
    pub slope_m: f64,
    /// Standard error of the slope, m.
    pub slope_standard_error_m: f64,
    /// Tests used.
    pub tests: usize,
}

/// The clearance evidence of a session.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ClearanceEvidence {
    /// The options used.
    pub options: ClearanceOptions,
    /// Every test, in session order.
    pub tests: Vec<TestClearance>,
    /// The bracketed clearances against the session order; None with fewer than two.
    pub trend: Option<ClearanceTrend>,
}

impl ClearanceEvidence {
    /// Why only `n` tests bracket the clearance where a stage needs more (`needs`, e.g. "two
    /// are needed, one to fit and one to validate"): with no measured contact in any test,
    /// that the contact physics leaves no trace in the session.
    pub(crate) fn too_few_brackets(&self, n: usize, needs: &str) -> String {
        if self
            .tests
            .iter()
            .all(|t| t.first_contact_omega_ratio.is_none())
        {
            format!("no test of the session has measured contact: the clearance, its wear and the contact face's tilt leave no trace in it (a plan with levels that reach the contact, or a smaller planned clearance, would carry them); {needs}")
        } else {
            format!("{n} test(s) bracket the clearance (impact-free steps, then contact); {needs}")
        }
    }
}

/// The clearance per test of the recording `rec` (as recorded, no sensor corrections).
///
/// Errors: those of [`session_evidence`]; a beam length that is not > 0.
pub fn clearance_per_test(
    rec: &Recording,
    opts: &ClearanceOptions,
) -> Result<ClearanceEvidence, EvidenceError> {
    clearance_per_test_of(&session_evidence(rec, &[])?, opts)
}

/// [`clearance_per_test`] of evidence already computed.
pub fn clearance_per_test_of(
    ev: &SessionEvidence,
    opts: &ClearanceOptions,
) -> Result<ClearanceEvidence, EvidenceError> {
    if !(opts.beam_length.is_finite() && opts.beam_length > 0.0) {
        return Err(EvidenceError::BadBeamLength(opts.beam_length));
    }
    // A closing excursion of the tips, scaled to the contact.
    let at_contact = |x: f64| x * opts.contact_over_sensor + opts.static_offset;
    let to_contact = |w: &WindowEvidence| at_contact(w.closing_peak);
    let mut tests = Vec::new();
    for (ti, test) in ev.tests.iter().enumerate() {
        let ws: Vec<&WindowEvidence> = ev.windows.iter().filter(|w| w.test_index == ti).collect();
        let Some(first) = ws.first() else { continue };
        let contact = ws.iter().position(|w| !w.impact_free());
        let before = &ws[..contact.unwrap_or(ws.len())];
        let lower = before
            .iter()
            .max_by(|a, b| to_contact(a).total_cmp(&to_contact(b)));
        let upper = contact.map(|k| ws[k]);
        let (lo, hi) = (lower.map(|w| to_contact(w)), upper.map(to_contact));
        let (clearance, uncertainty) = match (lo, hi) {
            (Some(a), Some(b)) => (Some(b), Some((b - a).abs())),
            _ => (None, None),
        };
        let at_onsets: Vec<f64> = ws
            .iter()
            .flat_map(|w| w.closing_at_onsets.iter())
            .map(|&x| at_contact(x))
            .collect();
        let onset_clearance =
            (!at_onsets.is_empty()).then(|| at_onsets.iter().sum::<f64>() / at_onsets.len() as f64);
        let onset_standard_error = (at_onsets.len() > 1).then(|| standard_error(&at_onsets));
        let note = match (lo, hi) {
            (Some(_), Some(_)) => String::new(),
            (Some(_), None) => "no contact in the test: the clearance is above the lower bound".into(),
            (None, Some(_)) => "contact from the test's first record window: no impact-free window bounds the clearance from below".into(),
            (None, None) => unreachable!("a test with windows has a first window"),
        };
        tests.push(TestClearance {
            test: test.name.clone(),
            test_index: ti,
            level: test.level,
            start_s: first.record_start_s,
            plan_clearance_m: test.plan_clearance * opts.beam_length,
            clearance_m: clearance,
            clearance_l: clearance.map(|c| c / opts.beam_length),
            uncertainty_m: uncertainty,
            lower_bound_m: lo,
            upper_bound_m: hi,
            lower_bound_omega_ratio: lower.map(|w| w.omega_ratio),
            first_contact_omega_ratio: upper.map(|w| w.omega_ratio),
            impact_free_windows: before.len(),
            onset_clearance_m: onset_clearance,
            onsets: at_onsets.len(),
            onset_standard_error_m: onset_standard_error,
            accumulated_contact_impulse_ns: None,
            note,
        });
    }
    let order: Vec<f64> = tests.iter().map(|t| t.test_index as f64).collect();
    let trend = clearance_trend(&tests, &order, "session order").ok();
    Ok(ClearanceEvidence {
        options: opts.clone(),
        tests,
        trend,
    })
}

/// The least-squares line of the bracketed clearances of `tests` against `x` (one abscissa
/// per test, e.g. the session order or the accumulated normal contact impulse), each clearance
/// weighted by its inverse squared uncertainty.
///
/// Errors: `x` not one per test, fewer than two bracketed tests with distinct abscissae.
pub fn clearance_trend(
    tests: &[TestClearance],
    x: &[f64],
    against: &str,
) -> Result<ClearanceTrend, EvidenceError> {
    if x.len() != tests.len() {
        return Err(EvidenceError::AbscissaeMismatch {
            what: format!("clearance against {against}"),
            given: x.len(),
            points: tests.len(),
        });
    }
    let pts: Vec<(f64, f64, f64)> = tests
        .iter()
        .zip(x)
        .filter_map(|(t, &x)| {
            let (c, u) = (t.clearance_m?, t.uncertainty_m?);
            x.is_finite()
                .then_some((x, c, 1.0 / (u * u).max(1e-30 * c * c).max(1e-300)))
        })
        .collect();
    let mut xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    if xs.len() < 2 {
        return Err(EvidenceError::TooFewPoints {
            what: format!("clearance against {against}"),
            points: xs.len(),
        });
    }
    let (mut a, mut b, mut c, mut d, mut e) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y, w) in &pts {
        a += w;
        b += w * x;
        c += w * x * x;
        d += w * y;
        e += w * x * y;
    }
    let det = a * c - b * b;
    let slope = (a * e - b * d) / det;
    let intercept = (d - slope * b) / a;
    let n = pts.len();
    let chi2: f64 = pts
        .iter()
        .map(|&(x, y, w)| w * (y - intercept - slope * x).powi(2))
        .sum();
    let scale = if n > 2 {
        (chi2 / (n - 2) as f64).max(1.0)
    } else {
        1.0
    };
    Ok(ClearanceTrend {
        against: against.to_string(),
        intercept_m: intercept,
        slope_m: slope,
        slope_standard_error_m: (a / det * scale).sqrt(),
        tests: n,
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    #[test]
    fn the_cantilever_mode_is_zero_at_the_clamp_and_largest_at_the_tip() {
        assert!(cantilever_first_mode(0.0).abs() < 1e-12);
        assert!((cantilever_first_mode(1.0) - 2.0).abs() < 1e-5);
        let r = cantilever_first_mode(0.95) / cantilever_first_mode(1.0);
        assert!((r - 0.9312).abs() < 1e-3, "{r}");
    }

    /// A test `t{i}` of clearance `c` (m; uncertain by 10 um where given), nothing else.
    pub(crate) fn test(i: usize, c: Option<f64>) -> TestClearance {
        TestClearance {
            test: format!("t{i}"),
            test_index: i,
            level: 2e-5,
            start_s: 0.0,
            plan_clearance_m: 7e-4,
            clearance_m: c,
            clearance_l: None,
            uncertainty_m: c.map(|_| 1e-5),
            lower_bound_m: None,
            upper_bound_m: None,
            lower_bound_omega_ratio: None,
            first_contact_omega_ratio: None,
            impact_free_windows: 3,
            onset_clearance_m: None,
            onsets: 0,
            onset_standard_error_m: None,
            accumulated_contact_impulse_ns: None,
            note: String::new(),
        }
    }

    #[test]
    fn a_session_without_contact_says_so_where_a_stage_lacks_brackets() {
        let mut ce = ClearanceEvidence {
            options: ClearanceOptions {
                beam_length: 0.3,
                contact_over_sensor: 1.0,
                static_offset: 0.0,
            },
            tests: (0..3).map(|i| test(i, None)).collect(),
            trend: None,
        };
        let why = ce.too_few_brackets(0, "two are needed");
        assert!(
            why.starts_with("no test of the session has measured contact"),
            "{why}"
        );
        assert!(why.ends_with("two are needed"), "{why}");
        ce.tests[1].first_contact_omega_ratio = Some(1.0);
        let why = ce.too_few_brackets(0, "two are needed");
        assert!(why.starts_with("0 test(s) bracket the clearance"), "{why}");
    }

    #[test]
    fn the_trend_is_the_line_through_the_bracketed_tests() {
        let tests: Vec<_> = (0..4)
            .map(|i| test(i, (i != 2).then_some(7e-4 + 2e-5 * i as f64)))
            .collect();
        let x: Vec<f64> = (0..4).map(|i| i as f64).collect();
        let t = clearance_trend(&tests, &x, "session order").unwrap();
        assert_eq!(t.tests, 3);
        assert!((t.slope_m - 2e-5).abs() < 1e-12 && (t.intercept_m - 7e-4).abs() < 1e-12);
        assert!(matches!(
            clearance_trend(&tests, &x[..2], "x"),
            Err(EvidenceError::AbscissaeMismatch { .. })
        ));
        assert!(matches!(
            clearance_trend(&tests[..1], &x[..1], "x"),
            Err(EvidenceError::TooFewPoints { .. })
        ));
    }
}
