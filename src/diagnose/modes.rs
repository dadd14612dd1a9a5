//! The linear stage of the diagnosis (stage 2): per mode (1FU, 1FL), the natural frequency
//! and damping ratio at zero amplitude from the impact-free fits of some tests
//! ([`super::linear`]; the intercept of the amplitude dependence where the clamp's friction
//! shows), as `[model.modes]` corrections judged by model runs on the other tests.

use std::f64::consts::PI;

use serde_json::json;

use crate::config::{ModalCorrectionSpec, PhysicsSpec};
use crate::rom::Rom;

use super::judge::{Candidate, DiagnoseProgress, Steps, Work};
use super::linear::{LinearEvidence, ModeFit};
use super::DiagnoseError;

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
pub(super) fn linear_stage(
    work: &mut Work<'_>,
    rom: &Rom,
    lin: &LinearEvidence,
) -> Result<(), DiagnoseError> {
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
            let cand = Candidate::new(
                "linear_frequency",
                with_mode(&work.accepted, mode, Some(f), None),
                json!({"mode": mode, "frequency_hz": f}),
                1,
                evidence.clone(),
                (train.clone(), validation.clone()),
                Steps::ImpactFree,
            );
            work.judge(cand)?;
        }
        if (z - z0).abs() > (3.0 * zse).max(0.05 * z0) {
            let cand = Candidate::new(
                "linear_damping",
                with_mode(&work.accepted, mode, None, Some(z)),
                json!({"mode": mode, "damping_ratio": z}),
                1,
                evidence,
                (train, validation),
                Steps::ImpactFree,
            );
            work.judge(cand)?;
        }
    }
    Ok(())
}
