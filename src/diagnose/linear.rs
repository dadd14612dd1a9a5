//! Linear natural frequency and damping of 1FL and 1FU from the impact-free steps (reference
//! section 3.2), and their dependence on the amplitude across levels (the clamp's friction).
//!
//! Per test and tip, the complex fundamental response of the tip's displacement relative to
//! the base over the base acceleration, `G(Omega) = X / A_base`, against frequency (impact-free
//! record windows only), is fitted by a single mode of base excitation plus the quasi-static
//! share of the other modes:
//!
//! `G(s) omega_2^2 = alpha / (nu^2 - s^2 + 2 i zeta nu s) + beta_0 + beta_1 (s^2 - s_c^2)`,
//!
//! `s = Omega / omega_2`, `nu = omega_n / omega_2`, `zeta` the damping ratio, `alpha` complex
//! (the modal participation times the mode shape at the tip, phase free for sensors whose
//! phases differ), `beta_0`, `beta_1` real (the other modes, a line in `s^2` over the band;
//! `s_c` the band's centre). Least squares on the real and imaginary parts with
//! Levenberg-Marquardt, started from the best point of a grid over `(nu, zeta)` on which the
//! linear parameters are solved exactly; standard errors from the residual variance and the
//! Jacobian at the optimum. The upper tip's peak is 1FU, the lower tip's 1FL; a tip counts only
//! where its peak lies inside the test's impact-free steps (not at an end) and it moves more
//! than the other tip there.
//!
//! NOTE: a step's record window starts before the free transient of the frequency change has
//! died out (the 1F modes ring for hundreds of periods at 0.2 % damping), and that transient
//! biases the window's fundamental, most near the peak: the damping came out about 17 % high.
//! The fit therefore iterates: with the fitted mode, each window's per-period fundamentals
//! are split into the steady state and the free transient (`ss + c z^p`, `z` the transient's
//! decay and beat over one excitation period), and the steady states are fitted again.
//!
//! Across tests, [`amplitude_dependence`] regresses each mode's frequency and damping on the
//! tip amplitude at resonance, weighted by their standard errors, and (with three or more
//! tests whose amplitudes are not in session order) on the session order too: the clamp's
//! friction lowers the frequency and raises the damping with the amplitude, reversibly (no
//! time trend).

use std::f64::consts::TAU;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};
use rustfft::num_complex::Complex64;
use serde::Serialize;

use crate::session::replay::Recording;

use super::error::EvidenceError;
use super::evidence::{session_evidence, SessionEvidence, WindowEvidence};

/// Settings of the linear fits.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct LinearOptions {
    /// Impact-free steps a fit needs at least (6 real parameters), -. Default 5.
    pub min_steps: usize,
    /// Half width of the fitted band around the peak, in Omega / omega_2. Default 0.03 (1FL and
    /// 1FU lie about 0.08 apart).
    pub half_band: f64,
    /// Standard errors beyond which a trend counts as significant, -. Default 3.
    pub significance: f64,
}

impl Default for LinearOptions {
    fn default() -> Self {
        LinearOptions {
            min_steps: 5,
            half_band: 0.03,
            significance: 3.0,
        }
    }
}

/// A tip of the rig and the mode its impact-free peak belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tip {
    Upper,
    Lower,
}

impl Tip {
    fn mode(self) -> &'static str {
        match self {
            Tip::Upper => "1FU",
            Tip::Lower => "1FL",
        }
    }
    fn periods(self, w: &WindowEvidence) -> &[Complex64] {
        match self {
            Tip::Upper => &w.upper_periods,
            Tip::Lower => &w.lower_periods,
        }
    }
    fn velocity(self, w: &WindowEvidence) -> Complex64 {
        match self {
            Tip::Upper => w.upper_velocity,
            Tip::Lower => w.lower_velocity,
        }
    }
    fn other(self) -> Tip {
        match self {
            Tip::Upper => Tip::Lower,
            Tip::Lower => Tip::Upper,
        }
    }
}

/// One mode fitted on one test's impact-free steps.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ModeFit {
    /// Mode label (`1FU` from the upper tip, `1FL` from the lower tip).
    pub mode: String,
    /// Test name.
    pub test: String,
    /// Index of the test in the session, from 0.
    pub test_index: usize,
    /// Base level of the test / l (the plan's).
    pub level: f64,
    /// Mean target base-displacement amplitude of the fitted steps, m.
    pub base_amplitude_m: f64,
    /// Impact-free steps fitted.
    pub steps: usize,
    /// Omega / omega_2 of the first and last fitted step.
    pub omega_ratio_range: [f64; 2],
    /// Natural frequency, Hz.
    pub frequency_hz: f64,
    /// Its standard error, Hz.
    pub frequency_hz_standard_error: f64,
    /// Natural frequency / omega_2 of the session (the ROM's 1FU), -.
    pub frequency_ratio: f64,
    /// Modal damping ratio, -.
    pub damping_ratio: f64,
    /// Its standard error, -.
    pub damping_ratio_standard_error: f64,
    /// Modal term `alpha` (module docs), [re, im], -.
    pub participation: [f64; 2],
    /// Quasi-static terms `beta_0`, `beta_1` (module docs), -.
    pub residual_terms: [f64; 2],
    /// The tip's displacement amplitude relative to the base at resonance, from the fit, m.
    pub peak_tip_amplitude_m: f64,
    /// RMS of the fit's residual over the RMS of the data, -.
    pub relative_residual: f64,
    /// Mean size of the steps' free transients at the record window's start over their
    /// steady states, -: what the fit took out (module docs).
    pub transient_share: f64,
}

/// A test/tip the fits skipped, and why.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct SkippedFit {
    /// Test name.
    pub test: String,
    /// The mode the tip would show.
    pub mode: String,
    /// Why no fit.
    pub reason: String,
}

/// A linear trend `y = y0 + slope x` (weighted least squares) with standard errors.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct Trend {
    /// Value at x = 0.
    pub intercept: f64,
    /// Slope, units of y per unit of x.
    pub slope: f64,
    /// Standard error of the slope.
    pub slope_standard_error: f64,
    /// Whether |slope| exceeds the significance times its standard error.
    pub significant: bool,
}

/// How a mode's frequency and damping depend on the amplitude across tests.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct AmplitudeDependence {
    /// Mode label.
    pub mode: String,
    /// Tests fitted, in session order.
    pub tests: Vec<String>,
    /// Distinct levels among them.
    pub levels: usize,
    /// Natural frequency (Hz) against the tip amplitude at resonance (m).
    pub frequency_vs_amplitude: Trend,
    /// Damping ratio (-) against the tip amplitude at resonance (m).
    pub damping_vs_amplitude: Trend,
    /// Natural frequency (Hz) against the test's index in the session, with the amplitude's
    /// share taken out; None when the session cannot separate the two (fewer than three tests,
    /// or amplitudes in session order).
    pub frequency_vs_session_order: Option<Trend>,
    /// Damping ratio against the test's index in the session, as above.
    pub damping_vs_session_order: Option<Trend>,
    /// Frequency falling and damping rising with the amplitude, both significant, and no
    /// significant time trend where the session can tell: the clamp friction's signature.
    pub clamp_friction_signature: bool,
}

/// The linear evidence of a session.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct LinearEvidence {
    /// The options used.
    pub options: LinearOptions,
    /// The fits, in session order.
    pub fits: Vec<ModeFit>,
    /// Tests and tips without a fit, and why.
    pub skipped: Vec<SkippedFit>,
    /// Per mode fitted at two or more levels: the amplitude dependence.
    pub amplitude_dependence: Vec<AmplitudeDependence>,
    /// Per mode fitted at fewer levels: why the amplitude dependence cannot be told.
    pub amplitude_dependence_undecided: Vec<SkippedFit>,
}

impl LinearEvidence {
    /// The fits of mode `mode`, in session order.
    pub fn fits_of<'a>(&'a self, mode: &'a str) -> impl Iterator<Item = &'a ModeFit> + 'a {
        self.fits.iter().filter(move |f| f.mode == mode)
    }
}

/// The linear evidence of the recording `rec` (as recorded, no sensor corrections).
///
/// Errors: those of [`session_evidence`]; no impact-free window at all
/// ([`EvidenceError::NoImpactFreeSteps`]); no test with a resonance inside its impact-free
/// steps ([`EvidenceError::NoResonance`]).
pub fn linear_modes(
    rec: &Recording,
    opts: &LinearOptions,
) -> Result<LinearEvidence, EvidenceError> {
    linear_modes_of(&session_evidence(rec, &[])?, opts)
}

/// [`linear_modes`] of evidence already computed.
pub fn linear_modes_of(
    ev: &SessionEvidence,
    opts: &LinearOptions,
) -> Result<LinearEvidence, EvidenceError> {
    if !ev.windows.iter().any(WindowEvidence::impact_free) {
        return Err(EvidenceError::NoImpactFreeSteps {
            windows: ev.windows.len(),
        });
    }
    let mut fits = Vec::new();
    let mut skipped = Vec::new();
    for (ti, test) in ev.tests.iter().enumerate() {
        let mut ws: Vec<&WindowEvidence> = ev
            .windows
            .iter()
            .filter(|w| w.test_index == ti && w.impact_free())
            .collect();
        ws.sort_by(|a, b| a.omega_ratio.total_cmp(&b.omega_ratio));
        for tip in [Tip::Upper, Tip::Lower] {
            let skip = |reason: String| SkippedFit {
                test: test.name.clone(),
                mode: tip.mode().to_string(),
                reason,
            };
            match fit_tip(&ws, tip, ti, test.level, opts) {
                Ok(f) => fits.push(f),
                Err(reason) => skipped.push(skip(reason)),
            }
        }
    }
    if fits.is_empty() {
        let why = skipped
            .iter()
            .map(|s| format!("{} {}: {}", s.test, s.mode, s.reason))
            .collect::<Vec<_>>()
            .join("; ");
        return Err(EvidenceError::NoResonance {
            min_steps: opts.min_steps,
            why,
        });
    }
    let mut amplitude = Vec::new();
    let mut undecided = Vec::new();
    for mode in ["1FL", "1FU"] {
        let of: Vec<ModeFit> = fits.iter().filter(|f| f.mode == mode).cloned().collect();
        if of.is_empty() {
            continue;
        }
        match amplitude_dependence(&of, opts) {
            Ok(a) => amplitude.push(a),
            Err(e) => undecided.push(SkippedFit {
                test: of
                    .iter()
                    .map(|f| f.test.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                mode: mode.to_string(),
                reason: e.to_string(),
            }),
        }
    }
    Ok(LinearEvidence {
        options: opts.clone(),
        fits,
        skipped,
        amplitude_dependence: amplitude,
        amplitude_dependence_undecided: undecided,
    })
}

/// The fit of one tip's mode on one test's impact-free windows (sorted by frequency), or why
/// not.
fn fit_tip(
    ws: &[&WindowEvidence],
    tip: Tip,
    test_index: usize,
    level: f64,
    opts: &LinearOptions,
) -> Result<ModeFit, String> {
    if ws.len() < opts.min_steps {
        return Err(format!(
            "{} impact-free steps, a fit needs {}",
            ws.len(),
            opts.min_steps
        ));
    }
    let omega_2 = ws[0].omega / ws[0].omega_ratio;
    // g = G omega_2^2 = V / (i Omega A) omega_2^2.
    let g = |w: &WindowEvidence| -> Complex64 {
        tip.velocity(w) / (Complex64::new(0.0, w.omega) * w.base_acceleration) * omega_2 * omega_2
    };
    let peak = (0..ws.len())
        .max_by(|&a, &b| g(ws[a]).norm().total_cmp(&g(ws[b]).norm()))
        .unwrap_or(0);
    if peak == 0 || peak + 1 == ws.len() {
        return Err(format!(
            "the tip's largest response is at the end of the impact-free steps (Omega/omega_2 \
             {:.4}): no resonance inside them",
            ws[peak].omega_ratio
        ));
    }
    let other = tip.other().velocity(ws[peak]).norm();
    if tip.velocity(ws[peak]).norm() < other {
        return Err(format!(
            "at its peak (Omega/omega_2 {:.4}) the other tip moves more: the peak is the other \
             beam's mode",
            ws[peak].omega_ratio
        ));
    }
    let s_peak = ws[peak].omega_ratio;
    let band: Vec<&WindowEvidence> = ws
        .iter()
        .copied()
        .filter(|w| (w.omega_ratio - s_peak).abs() <= opts.half_band)
        .collect();
    if band.len() < opts.min_steps {
        return Err(format!(
            "{} impact-free steps within {} of the peak at Omega/omega_2 {:.4}, a fit needs {}",
            band.len(),
            opts.half_band,
            s_peak,
            opts.min_steps
        ));
    }
    let s: Vec<f64> = band.iter().map(|w| w.omega_ratio).collect();
    let y: Vec<Complex64> = band.iter().map(|w| g(w)).collect();
    let s_c = 0.5 * (s[0] + s[s.len() - 1]);
    let failed = || {
        format!(
            "the least-squares fit of the {} band steps did not converge",
            band.len()
        )
    };
    let mut fit = fit_mode(&s, &y, s_c).ok_or_else(failed)?;
    // The steps' free transients: refit on the steady states separated from them with the
    // fitted mode, until the frequency settles.
    let mut transient = 0.0;
    for _ in 0..TRANSIENT_ITERATIONS {
        let (nu, zeta) = (fit.params[0], fit.params[1]);
        let mut share = 0.0;
        let y: Vec<Complex64> = band
            .iter()
            .zip(&y)
            .map(|(w, &whole)| {
                let per: Vec<Complex64> = tip
                    .periods(w)
                    .iter()
                    .zip(&w.base_periods)
                    .map(|(v, a)| v / (Complex64::new(0.0, w.omega) * a) * omega_2 * omega_2)
                    .collect();
                match steady_state(&per, nu * omega_2, zeta, w.omega) {
                    Some((ss, c)) => {
                        share += c.norm() / ss.norm().max(f64::MIN_POSITIVE);
                        ss
                    }
                    None => whole,
                }
            })
            .collect();
        transient = share / band.len() as f64;
        let Some(next) = fit_mode(&s, &y, s_c) else {
            break;
        };
        let moved = (next.params[0] - nu).abs();
        fit = next;
        if moved < 1e-7 {
            break;
        }
    }
    let base_amp = band.iter().map(|w| w.base_amp_target).sum::<f64>() / band.len() as f64;
    let p = &fit.params;
    let at_peak = model(p, p[0], s_c).norm();
    let hz = omega_2 / TAU;
    Ok(ModeFit {
        mode: tip.mode().to_string(),
        test: ws[0].test.clone(),
        test_index,
        level,
        base_amplitude_m: base_amp,
        steps: band.len(),
        omega_ratio_range: [s[0], s[s.len() - 1]],
        frequency_hz: p[0] * hz,
        frequency_hz_standard_error: fit.standard_errors[0] * hz,
        frequency_ratio: p[0],
        damping_ratio: p[1],
        damping_ratio_standard_error: fit.standard_errors[1],
        participation: [p[2], p[3]],
        residual_terms: [p[4], p[5]],
        // X = G A = g / omega_2^2 * q Omega^2 = g q s^2.
        peak_tip_amplitude_m: at_peak * base_amp * p[0] * p[0],
        relative_residual: fit.relative_residual,
        transient_share: transient,
    })
}

/// Refits of the steady states against the steps' free transients (module docs).
const TRANSIENT_ITERATIONS: usize = 4;

/// The steady state of a step's per-period fundamentals `per` (one per whole period from the
/// window's start) with the free transient of a mode at `omega_n` (rad/s) with damping `zeta`
/// taken out, under excitation `omega`: `per_p = ss + c z^p`, `z = exp(lambda T)`,
/// `lambda = -zeta omega_n + i (omega_d - Omega)`, `T = 2 pi / Omega` (the transient seen by a
/// demodulator at Omega). Returns `(ss, c)`; None with fewer than four periods.
fn steady_state(
    per: &[Complex64],
    omega_n: f64,
    zeta: f64,
    omega: f64,
) -> Option<(Complex64, Complex64)> {
    if per.len() < 4 {
        return None;
    }
    let period = TAU / omega;
    let omega_d = omega_n * (1.0 - zeta * zeta).max(0.0).sqrt();
    let z = (Complex64::new(-zeta * omega_n, omega_d - omega) * period).exp();
    // Linear least squares for [ss, c] with columns 1 and z^p (complex normal equations).
    let (mut a11, mut a12, mut a22) = (0.0, Complex64::new(0.0, 0.0), 0.0);
    let (mut b1, mut b2) = (Complex64::new(0.0, 0.0), Complex64::new(0.0, 0.0));
    let mut zp = Complex64::new(1.0, 0.0);
    for &y in per {
        a11 += 1.0;
        a12 += zp;
        a22 += zp.norm_sqr();
        b1 += y;
        b2 += zp.conj() * y;
        zp *= z;
    }
    // [[a11, a12], [conj(a12), a22]] [ss, c] = [b1, b2]
    let det = a11 * a22 - a12.norm_sqr();
    if det.is_nan() || det <= 1e-9 * a11 * a22 {
        return None;
    }
    let ss = (b1 * a22 - a12 * b2) / det;
    let c = (b2 * a11 - a12.conj() * b1) / det;
    Some((ss, c))
}

/// The model `g(s)` for parameters `[nu, zeta, alpha_re, alpha_im, beta_0, beta_1]`.
fn model(p: &[f64], s: f64, s_c: f64) -> Complex64 {
    let d = Complex64::new(p[0] * p[0] - s * s, 2.0 * p[1] * p[0] * s);
    Complex64::new(p[2], p[3]) / d + p[4] + p[5] * (s * s - s_c * s_c)
}

/// A converged fit.
struct Fitted {
    params: Vec<f64>,
    standard_errors: Vec<f64>,
    relative_residual: f64,
}

/// The least-squares problem of [`model`] against data `y` at `s`.
struct ModeProblem<'a> {
    s: &'a [f64],
    y: &'a [Complex64],
    s_c: f64,
    p: DVector<f64>,
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for ModeProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.p.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.p.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let m = self.s.len();
        let mut r = DVector::zeros(2 * m);
        for (k, (&s, y)) in self.s.iter().zip(self.y).enumerate() {
            let e = model(self.p.as_slice(), s, self.s_c) - y;
            r[k] = e.re;
            r[m + k] = e.im;
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let m = self.s.len();
        let p = self.p.as_slice();
        let alpha = Complex64::new(p[2], p[3]);
        let mut j = DMatrix::zeros(2 * m, 6);
        for (k, &s) in self.s.iter().enumerate() {
            let d = Complex64::new(p[0] * p[0] - s * s, 2.0 * p[1] * p[0] * s);
            let inv = 1.0 / d;
            let a_d2 = -alpha * inv * inv;
            let cols = [
                a_d2 * Complex64::new(2.0 * p[0], 2.0 * p[1] * s),
                a_d2 * Complex64::new(0.0, 2.0 * p[0] * s),
                inv,
                Complex64::new(0.0, 1.0) * inv,
                Complex64::new(1.0, 0.0),
                Complex64::new(s * s - self.s_c * self.s_c, 0.0),
            ];
            for (c, z) in cols.iter().enumerate() {
                j[(k, c)] = z.re;
                j[(m + k, c)] = z.im;
            }
        }
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

/// The linear parameters `[alpha_re, alpha_im, beta_0, beta_1]` solved exactly for fixed
/// `(nu, zeta)`, and the sum of squared residuals.
fn linear_part(
    s: &[f64],
    y: &[Complex64],
    s_c: f64,
    nu: f64,
    zeta: f64,
) -> Option<([f64; 4], f64)> {
    let m = s.len();
    let mut a = DMatrix::zeros(2 * m, 4);
    let mut b = DVector::zeros(2 * m);
    for (k, (&sk, yk)) in s.iter().zip(y).enumerate() {
        let inv = 1.0 / Complex64::new(nu * nu - sk * sk, 2.0 * zeta * nu * sk);
        let q = sk * sk - s_c * s_c;
        let cols = [inv, Complex64::new(0.0, 1.0) * inv, 1.0.into(), q.into()];
        for (c, z) in cols.iter().enumerate() {
            a[(k, c)] = z.re;
            a[(m + k, c)] = z.im;
        }
        b[k] = yk.re;
        b[m + k] = yk.im;
    }
    let x = a.clone().svd(true, true).solve(&b, 1e-12).ok()?;
    let r = &a * &x - &b;
    Some(([x[0], x[1], x[2], x[3]], r.norm_squared()))
}

/// Fits [`model`] to `y` at `s` (see the module docs).
fn fit_mode(s: &[f64], y: &[Complex64], s_c: f64) -> Option<Fitted> {
    // Grid start: nu over the data's span, zeta on a log scale from 1e-4 to 0.1.
    let (lo, hi) = (s[0], s[s.len() - 1]);
    let mut best: Option<(f64, [f64; 6])> = None;
    for i in 0..=120 {
        let nu = lo + (hi - lo) * i as f64 / 120.0;
        for j in 0..=40 {
            let zeta = 1e-4 * 1e3f64.powf(j as f64 / 40.0);
            if let Some((lin, ssr)) = linear_part(s, y, s_c, nu, zeta) {
                if best.as_ref().is_none_or(|b| ssr < b.0) {
                    best = Some((ssr, [nu, zeta, lin[0], lin[1], lin[2], lin[3]]));
                }
            }
        }
    }
    let (_, p0) = best?;
    let problem = ModeProblem {
        s,
        y,
        s_c,
        p: DVector::from_column_slice(&p0),
    };
    let (problem, report) = LevenbergMarquardt::new().minimize(problem);
    if !report.termination.was_successful() {
        return None;
    }
    let p = problem.params();
    if !(p[1] > 0.0 && p[0] > 0.0) {
        return None;
    }
    let r = problem.residuals()?;
    let j = problem.jacobian()?;
    let dof = (r.len() as f64 - 6.0).max(1.0);
    let sigma2 = r.norm_squared() / dof;
    let cov = (j.transpose() * &j).try_inverse()? * sigma2;
    let data_rms = (y.iter().map(|z| z.norm_sqr()).sum::<f64>() / y.len() as f64).sqrt();
    let res_rms = (r.norm_squared() / y.len() as f64).sqrt();
    Some(Fitted {
        params: p.iter().copied().collect(),
        standard_errors: (0..6).map(|i| cov[(i, i)].max(0.0).sqrt()).collect(),
        relative_residual: res_rms / data_rms,
    })
}

/// Weighted least squares `y ~ X b` (weights `w`), returning `b` and its covariance (scaled by
/// the reduced chi-square when that exceeds 1 and there are degrees of freedom left).
fn weighted_ls(x: &DMatrix<f64>, y: &[f64], w: &[f64]) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let (n, p) = (x.nrows(), x.ncols());
    let mut xw = x.clone();
    let mut yw = DVector::zeros(n);
    for i in 0..n {
        let sw = w[i].sqrt();
        for c in 0..p {
            xw[(i, c)] *= sw;
        }
        yw[i] = y[i] * sw;
    }
    let xtx = xw.transpose() * &xw;
    let inv = xtx.try_inverse()?;
    let b = &inv * (xw.transpose() * &yw);
    let r = &xw * &b - &yw;
    let scale = if n > p {
        (r.norm_squared() / (n - p) as f64).max(1.0)
    } else {
        1.0
    };
    Some((b, inv * scale))
}

/// How the fits of one mode (`fits`, one mode, session order) depend on the tip amplitude
/// and, where the session can tell, on the session order (module docs).
///
/// Errors: fits at fewer than two distinct levels ([`EvidenceError::SingleLevel`]).
pub fn amplitude_dependence(
    fits: &[ModeFit],
    opts: &LinearOptions,
) -> Result<AmplitudeDependence, EvidenceError> {
    let mode = fits.first().map_or("?", |f| f.mode.as_str()).to_string();
    let mut levels: Vec<f64> = fits.iter().map(|f| f.level).collect();
    levels.sort_by(f64::total_cmp);
    levels.dedup_by(|a, b| (*a - *b).abs() <= 1e-6 * b.abs().max(1e-30));
    let tests = fits.iter().map(|f| f.test.clone()).collect::<Vec<_>>();
    if levels.len() < 2 {
        return Err(EvidenceError::SingleLevel {
            mode,
            levels: levels.len(),
            tests: tests.join(", "),
        });
    }
    let trend = |ys: &[f64], ses: &[f64], cols: &[&dyn Fn(&ModeFit) -> f64]| {
        let x = DMatrix::from_fn(fits.len(), cols.len() + 1, |i, c| {
            if c == 0 {
                1.0
            } else {
                cols[c - 1](&fits[i])
            }
        });
        let w: Vec<f64> = ses.iter().map(|s| 1.0 / (s * s).max(1e-300)).collect();
        weighted_ls(&x, ys, &w)
    };
    let make = |b: &DVector<f64>, cov: &DMatrix<f64>, i: usize| Trend {
        intercept: b[0],
        slope: b[i],
        slope_standard_error: cov[(i, i)].max(0.0).sqrt(),
        significant: b[i].abs() > opts.significance * cov[(i, i)].max(0.0).sqrt(),
    };
    let f: Vec<f64> = fits.iter().map(|x| x.frequency_hz).collect();
    let fse: Vec<f64> = fits.iter().map(|x| x.frequency_hz_standard_error).collect();
    let z: Vec<f64> = fits.iter().map(|x| x.damping_ratio).collect();
    let zse: Vec<f64> = fits
        .iter()
        .map(|x| x.damping_ratio_standard_error)
        .collect();
    let amp = |x: &ModeFit| x.peak_tip_amplitude_m;
    let order = |x: &ModeFit| x.test_index as f64;
    let too_few = || EvidenceError::TooFewPoints {
        what: format!("mode {mode} against the amplitude"),
        points: fits.len(),
    };
    let (bf, cf) = trend(&f, &fse, &[&amp]).ok_or_else(too_few)?;
    let (bz, cz) = trend(&z, &zse, &[&amp]).ok_or_else(too_few)?;
    let frequency_vs_amplitude = make(&bf, &cf, 1);
    let damping_vs_amplitude = make(&bz, &cz, 1);
    // Time: with three or more fits whose amplitudes do not follow the session order.
    let separable = fits.len() >= 3 && {
        let a: Vec<f64> = fits.iter().map(amp).collect();
        let rising = a.windows(2).all(|p| p[1] >= p[0]);
        let falling = a.windows(2).all(|p| p[1] <= p[0]);
        !(rising || falling)
    };
    let (fo, zo) = if separable {
        let fo = trend(&f, &fse, &[&amp, &order]).map(|(b, c)| make(&b, &c, 2));
        let zo = trend(&z, &zse, &[&amp, &order]).map(|(b, c)| make(&b, &c, 2));
        (fo, zo)
    } else {
        (None, None)
    };
    let time_trend =
        fo.as_ref().is_some_and(|t| t.significant) || zo.as_ref().is_some_and(|t| t.significant);
    let clamp_friction_signature = frequency_vs_amplitude.significant
        && frequency_vs_amplitude.slope < 0.0
        && damping_vs_amplitude.significant
        && damping_vs_amplitude.slope > 0.0
        && !time_trend;
    Ok(AmplitudeDependence {
        mode,
        tests,
        levels: levels.len(),
        frequency_vs_amplitude,
        damping_vs_amplitude,
        frequency_vs_session_order: fo,
        damping_vs_session_order: zo,
        clamp_friction_signature,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Synthetic steps of a mode at `nu`, `zeta` with residual terms.
    fn synthetic(nu: f64, zeta: f64) -> (Vec<f64>, Vec<Complex64>, f64) {
        let s: Vec<f64> = (0..11).map(|k| 0.985 + 0.003 * k as f64).collect();
        let s_c = 1.0;
        let p = [nu, zeta, -1.5, 0.05, 1.1, 150.0];
        let y = s.iter().map(|&x| model(&p, x, s_c)).collect();
        (s, y, s_c)
    }

    #[test]
    fn the_fit_recovers_a_synthetic_mode() {
        for (nu, zeta) in [(0.993, 0.003), (1.006, 0.0012)] {
            let (s, y, s_c) = synthetic(nu, zeta);
            let f = fit_mode(&s, &y, s_c).unwrap();
            assert!((f.params[0] / nu - 1.0).abs() < 1e-9, "{:?}", f.params);
            assert!((f.params[1] / zeta - 1.0).abs() < 1e-6, "{:?}", f.params);
            assert!(f.relative_residual < 1e-9);
        }
    }

    #[test]
    fn a_free_transient_is_separated_from_the_steady_state() {
        let (omega_n, zeta, omega): (f64, f64, f64) = (320.0, 0.002, 322.0);
        let period = TAU / omega;
        let omega_d = omega_n * (1.0 - zeta * zeta).sqrt();
        let z = (Complex64::new(-zeta * omega_n, omega_d - omega) * period).exp();
        let (ss, c) = (Complex64::new(3.0, -1.0), Complex64::new(0.8, 0.4));
        let per: Vec<Complex64> = (0..40).map(|p| ss + c * z.powu(p)).collect();
        let (a, b) = steady_state(&per, omega_n, zeta, omega).unwrap();
        assert!((a - ss).norm() < 1e-9 && (b - c).norm() < 1e-9, "{a} {b}");
        assert!(steady_state(&per[..3], omega_n, zeta, omega).is_none());
    }
}
