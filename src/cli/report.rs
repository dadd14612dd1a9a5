//! `rigtwin report FILE.mcap --out DIR`: the paper-style figures of a recorded session, drawn
//! from the raw recording (the same signal processing as the live summary): RMS response and
//! amplitude ranges of every test, time histories and contact activity of the step nearest
//! Omega = omega_2 of each test, and its Morlet scalogram; plus the replayed summary as JSON.
//! A session run with `--twin` (or a log written by `replay --twin --out`) has the twin drawn
//! beside the measurement in every figure: its RMS response and amplitude ranges dashed (from
//! `/twin/steps`), its time histories and contact activity over the same record windows dashed
//! in the measurement's colour, and its own scalogram (`scalogram_TEST_twin.png`), from
//! `/twin/blocks`.

use anyhow::Context;
use clap::Args;
use std::path::{Path, PathBuf};

use crate::control::{window_signals, EventKind, StepInfo, TestSummary};
use crate::log::replay::{recording, replay, window_counts};
use crate::plan::Direction;
use crate::report::{self, Beam, FigureOptions, FrequencyResponse, Source, TestCurve, TimeHistory};
use crate::signal::StepMetrics;

/// `rigtwin report`
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// The session log (MCAP).
    pub file: PathBuf,
    /// Output folder for the figures and the summary.
    #[arg(long)]
    pub out: PathBuf,
}

pub(crate) fn run(a: ReportArgs) -> anyhow::Result<()> {
    for p in figures(&a.file, &a.out)? {
        println!("{}", p.display());
    }
    Ok(())
}

/// The frequency-response curve of test `t` from `(Omega / omega_2, metrics)` per step.
fn test_curve(t: &TestSummary, source: Source, steps: &[(f64, &StepMetrics)]) -> TestCurve {
    let col =
        |f: fn(&StepMetrics) -> f64| -> Vec<f64> { steps.iter().map(|(_, m)| f(m)).collect() };
    TestCurve {
        name: t.name.clone(),
        level: t.level,
        direction: if t.direction == "up" {
            Direction::Up
        } else {
            Direction::Down
        },
        source,
        omega_ratio: steps.iter().map(|(w, _)| *w).collect(),
        rms_upper: col(|m| m.rms_upper),
        rms_lower: col(|m| m.rms_lower),
        amp_min_upper: col(|m| m.amp_min_upper),
        amp_mean_upper: col(|m| m.amp_mean_upper),
        amp_max_upper: col(|m| m.amp_max_upper),
        amp_min_lower: col(|m| m.amp_min_lower),
        amp_mean_lower: col(|m| m.amp_mean_lower),
        amp_max_lower: col(|m| m.amp_max_lower),
    }
}

/// The twin's logged prediction (`/twin/blocks`) over the record window of `info` (samples `dt`
/// s apart): `None` when the log has no twin output there (a session without `--twin`, or
/// blocks the twin skipped). Only the blocks around the window are decoded.
fn twin_window(
    session: &crate::log::SessionRead,
    info: &StepInfo,
    dt: f64,
) -> anyhow::Result<Option<crate::twin::TwinTrace>> {
    let topic = crate::twin::TOPIC_TWIN_BLOCKS;
    let (from, n) = (info.record_first_sample, info.record_samples);
    // Log time = rig time of a block's first sample: blocks starting up to a second before the
    // window (far longer than any block) down to its last sample.
    let t0 = crate::log::recorder::log_time_ns((from as f64 * dt - 1.0).max(0.0));
    let t1 = crate::log::recorder::log_time_ns((from + n as u64) as f64 * dt);
    let blocks = session
        .messages_on(topic)
        .filter(|m| m.log_time >= t0 && m.log_time <= t1)
        .map(|m| {
            serde_json::from_slice::<crate::twin::TwinSamples>(&m.data).with_context(|| {
                format!(
                    "{}: {topic} message {} does not decode",
                    session.path.display(),
                    m.sequence
                )
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(crate::twin::TwinTrace::cut(&blocks, from, n))
}

/// Draws the figures of the session log `file` into `out` (created); returns the files
/// written (figures and `summary.json`).
pub(crate) fn figures(file: &Path, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let a = ReportArgs {
        file: file.to_path_buf(),
        out: out.to_path_buf(),
    };
    let r = replay(&a.file)?;
    let session = crate::log::read_session(&a.file)?;
    let rec = recording(&session)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let meta = session.metadata("session").cloned().unwrap_or_default();
    let l: f64 = meta
        .get("beam_length_m")
        .and_then(|s| s.parse().ok())
        .context("the log's session metadata has no beam_length_m")?;
    let fig = FigureOptions::default();
    let mut written = Vec::new();

    // The measurement's curves, then the live twin's (sessions run with `--twin`, from
    // `/twin/steps`), dashed beside them.
    let twin_steps = session
        .decode::<crate::twin::TwinStepMessage>(crate::twin::TOPIC_TWIN_STEPS)
        .unwrap_or_default();
    let mut curves = Vec::new();
    for t in r.summary.tests.iter().filter(|t| !t.steps.is_empty()) {
        let measured: Vec<(f64, &StepMetrics)> = t
            .steps
            .iter()
            .map(|s| (s.omega_ratio, &s.metrics))
            .collect();
        curves.push(test_curve(t, Source::Measurement, &measured));
    }
    for t in r.summary.tests.iter().filter(|t| !t.steps.is_empty()) {
        let twin: Vec<(f64, &StepMetrics)> = twin_steps
            .iter()
            .filter(|(_, _, m)| m.test == t.name)
            .filter_map(|(_, _, m)| Some((m.omega_ratio, &m.twin.as_ref()?.metrics)))
            .collect();
        if !twin.is_empty() {
            curves.push(test_curve(t, Source::Twin, &twin));
        }
    }
    if !curves.is_empty() {
        let data = FrequencyResponse { tests: curves };
        let p = a.out.join("rms_response.png");
        report::rms_response(&data, &p, &fig)?;
        written.push(p);
        for (beam, file) in [
            (Beam::Upper, "amplitude_upper.png"),
            (Beam::Lower, "amplitude_lower.png"),
        ] {
            let p = a.out.join(file);
            report::amplitude_range(&data, beam, &p, &fig)?;
            written.push(p);
        }
    }

    // The step nearest Omega = omega_2 of each test.
    let mut nearest: Vec<StepInfo> = Vec::new();
    for e in &rec.events {
        if let EventKind::RecordEnd { info } = &e.kind {
            match nearest.iter_mut().find(|n| n.test == info.test) {
                Some(n) if (info.omega_ratio - 1.0).abs() < (n.omega_ratio - 1.0).abs() => {
                    *n = info.clone()
                }
                Some(_) => {}
                None => nearest.push(info.clone()),
            }
        }
    }
    let mut histories = Vec::new();
    for info in &nearest {
        let Some(counts) = window_counts(&rec, info) else {
            continue;
        };
        let w = window_signals(&rec.layout, info, &counts)?;
        let s = 1.0 / (info.omega * l);
        // The measurement, then the twin over the same window where the log holds its
        // predicted channels: one time history and one scalogram each.
        let mut sources = vec![(
            w.upper.clone(),
            TimeHistory {
                name: info.test.clone(),
                source: Source::Measurement,
                omega_ratio: info.omega_ratio,
                t: (0..w.upper.len()).map(|k| k as f64 * w.dt).collect(),
                upper: w.upper.iter().map(|v| v * s).collect(),
                lower: w.lower.iter().map(|v| v * s).collect(),
                contact_closed: w.closed.clone(),
                normal_force: Vec::new(),
                tangential_force: Vec::new(),
            },
        )];
        if let Some(twin) = twin_window(&session, info, w.dt)? {
            sources.push((
                twin.upper_tip.clone(),
                TimeHistory {
                    name: info.test.clone(),
                    source: Source::Twin,
                    omega_ratio: info.omega_ratio,
                    t: (0..twin.upper_tip.len()).map(|k| k as f64 * w.dt).collect(),
                    upper: twin.upper_tip.iter().map(|v| v * s).collect(),
                    lower: twin.lower_tip.iter().map(|v| v * s).collect(),
                    contact_closed: twin.contact,
                    normal_force: twin.normal_force,
                    tangential_force: twin.tangential_force,
                },
            ));
        }
        for (upper, h) in sources {
            let source = h.source;
            let suffix = if source == Source::Twin { "_twin" } else { "" };
            let p = a.out.join(format!(
                "scalogram_{}{suffix}.png",
                super::simulate::sanitize(&info.test)
            ));
            super::simulate::scalogram_of(
                &upper,
                w.dt,
                info.omega,
                l,
                &format!(
                    "{source}, {}, upper beam, Omega/omega_2 = {:.3}",
                    info.test, info.omega_ratio
                ),
                &p,
            )?;
            written.push(p);
            histories.push(h);
        }
    }
    let period = nearest
        .iter()
        .map(|i| std::f64::consts::TAU / i.omega)
        .fold(0.0, f64::max);
    written.extend(super::simulate::time_figures(&histories, period, &a.out)?);
    let json = a.out.join("summary.json");
    super::write_json(&json, &r.summary)?;
    written.push(json);
    Ok(written)
}
