//! The paper-style figures of a recorded session (`rigtwin report FILE.mcap --out DIR`), drawn
//! from the raw recording with the live summary's own signal processing: RMS response and
//! amplitude ranges of every test, time histories and contact activity of the step nearest
//! Omega = omega_2 of each test, and its Morlet scalogram. A session run with `--twin` (or a
//! log written by `replay --twin --out`) has the twin drawn beside the measurement in every
//! figure: its RMS response and amplitude ranges dashed (from `/twin/steps`), its time
//! histories and contact activity over the same record windows dashed in the measurement's
//! colour, and its own scalogram (`scalogram_TEST_twin.png`), from `/twin/blocks`.

use std::path::{Path, PathBuf};

use crate::control::summary::SummaryError;
use crate::control::{window_signals, StepInfo};
use crate::log::{log_time_ns, stream_session, LogReadError, SessionRead};
use crate::plan::Direction;
use crate::session::replay::{replay, window_counts, Recording, ReplayError};
use crate::session::topics::{
    TwinStepMessage, SESSION_METADATA, TOPIC_TWIN_BLOCKS, TOPIC_TWIN_STEPS,
};
use crate::session::{SessionSummary, TestSummary};
use crate::signal::StepMetrics;
use crate::twin::{TwinSamples, TwinTrace};

use super::stepped::{sanitize, scalogram_of, time_figures};
use super::{Beam, FigureOptions, FrequencyResponse, ReportError, Source, TestCurve, TimeHistory};

/// Why a session's figures could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum SessionReportError {
    /// The session log could not be replayed.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// The session log could not be read.
    #[error(transparent)]
    Read(#[from] LogReadError),
    /// The output folder could not be created.
    #[error("creating {path}: {source}")]
    Io {
        /// The folder.
        path: String,
        /// What failed.
        #[source]
        source: std::io::Error,
    },
    /// The log's `session` metadata lacks the beam length (the figures' length unit).
    #[error("{path}: the log's session metadata has no beam_length_m")]
    NoBeamLength {
        /// The log.
        path: String,
    },
    /// A logged twin block does not decode.
    #[error("{path}: {topic} message {sequence} does not decode: {source}")]
    Decode {
        /// The log.
        path: String,
        /// The topic.
        topic: &'static str,
        /// The message's sequence number.
        sequence: u32,
        /// What failed.
        #[source]
        source: serde_json::Error,
    },
    /// A record window's signals could not be computed.
    #[error("{path}: {source}")]
    Window {
        /// The log.
        path: String,
        /// What failed.
        #[source]
        source: SummaryError,
    },
    /// A figure could not be drawn.
    #[error(transparent)]
    Figure(#[from] ReportError),
}

/// The frequency-response curve of test `t` from `(Omega / omega_2, metrics)` per step.
fn test_curve(t: &TestSummary, source: Source, steps: &[(f64, &StepMetrics)]) -> TestCurve {
    let direction = if t.direction == "up" {
        Direction::Up
    } else {
        Direction::Down
    };
    TestCurve::from_steps(&t.name, t.level, direction, source, steps)
}

/// The log times (ns) of the twin blocks (`/twin/blocks`) that can hold samples of the record
/// window of `info` (samples `dt` s apart): a block's log time is the rig time of its first
/// sample, so blocks starting up to a second before the window (far longer than any block)
/// through its last sample.
fn twin_block_times(info: &StepInfo, dt: f64) -> (u64, u64) {
    let from = info.record_first_sample;
    (
        log_time_ns((from as f64 * dt - 1.0).max(0.0)),
        log_time_ns(info.record_end_time(dt)),
    )
}

/// The twin's logged prediction (`/twin/blocks`) over the record window of `info` (samples `dt`
/// s apart): `None` when the log has no twin output there (a session without `--twin`, or
/// blocks the twin skipped). Only the blocks around the window are decoded.
fn twin_window(
    session: &SessionRead,
    info: &StepInfo,
    dt: f64,
) -> Result<Option<TwinTrace>, SessionReportError> {
    let topic = TOPIC_TWIN_BLOCKS;
    let (from, n) = (info.record_first_sample, info.record_samples);
    let (t0, t1) = twin_block_times(info, dt);
    let blocks = session
        .messages_on(topic)
        .filter(|m| m.log_time >= t0 && m.log_time <= t1)
        .map(|m| {
            serde_json::from_slice::<TwinSamples>(&m.data).map_err(|source| {
                SessionReportError::Decode {
                    path: session.path.display().to_string(),
                    topic,
                    sequence: m.sequence,
                    source,
                }
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(TwinTrace::cut(&blocks, from, n))
}

/// The record window nearest Omega = omega_2 of each test of `rec`, in session order.
fn nearest_windows(rec: &Recording) -> Vec<StepInfo> {
    let mut nearest: Vec<StepInfo> = Vec::new();
    for info in rec.record_windows() {
        match nearest.iter_mut().find(|n| n.test == info.test) {
            Some(n) if (info.omega_ratio - 1.0).abs() < (n.omega_ratio - 1.0).abs() => {
                *n = info.clone()
            }
            Some(_) => {}
            None => nearest.push(info.clone()),
        }
    }
    nearest
}

/// Draws the figures of the session log `file` into `out` (created); returns the figures
/// written and the replayed summary (which the caller writes as `summary.json`).
///
/// The log is streamed, never held whole: the replay's two passes, then one more that keeps
/// only the twin's per-step messages and the twin blocks around the windows drawn.
pub fn session_figures(
    file: &Path,
    out: &Path,
) -> Result<(Vec<PathBuf>, SessionSummary), SessionReportError> {
    let r = replay(file)?;
    let rec = &r.recording;
    let nearest = nearest_windows(rec);
    let dt = rec.layout.dt();
    let spans: Vec<(u64, u64)> = nearest.iter().map(|i| twin_block_times(i, dt)).collect();
    let mut kept = Vec::new();
    let mut session = stream_session(file, |m| {
        let keep = match &*m.topic {
            TOPIC_TWIN_STEPS => true,
            TOPIC_TWIN_BLOCKS => spans
                .iter()
                .any(|&(t0, t1)| m.log_time >= t0 && m.log_time <= t1),
            _ => false,
        };
        if keep {
            kept.push(m.clone());
        }
        Ok::<(), SessionReportError>(())
    })?;
    session.messages = kept;
    std::fs::create_dir_all(out).map_err(|source| SessionReportError::Io {
        path: out.display().to_string(),
        source,
    })?;
    let meta = session
        .metadata(SESSION_METADATA)
        .cloned()
        .unwrap_or_default();
    let l: f64 = meta
        .get("beam_length_m")
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| SessionReportError::NoBeamLength {
            path: file.display().to_string(),
        })?;
    let fig = FigureOptions::default();
    let mut written = Vec::new();

    // The measurement's curves, then the live twin's (sessions run with `--twin`, from
    // `/twin/steps`), dashed beside them.
    let twin_steps = session
        .decode::<TwinStepMessage>(TOPIC_TWIN_STEPS)
        .unwrap_or_default();
    let mut curves = Vec::new();
    for t in r.summary.tests.iter().filter(|t| !t.steps.is_empty()) {
        let measured: Vec<(f64, &StepMetrics)> = t
            .steps
            .iter()
            .map(|s| (s.measured.omega_ratio, &s.measured.metrics))
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
        let p = out.join("rms_response.png");
        super::rms_response(&data, &p, &fig)?;
        written.push(p);
        for (beam, file) in [
            (Beam::Upper, "amplitude_upper.png"),
            (Beam::Lower, "amplitude_lower.png"),
        ] {
            let p = out.join(file);
            super::amplitude_range(&data, beam, &p, &fig)?;
            written.push(p);
        }
    }

    // The step nearest Omega = omega_2 of each test.
    let mut histories = Vec::new();
    for info in &nearest {
        let Some(counts) = window_counts(rec, info) else {
            continue;
        };
        let w = window_signals(&rec.layout, info, &counts).map_err(|source| {
            SessionReportError::Window {
                path: file.display().to_string(),
                source,
            }
        })?;
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
            let p = out.join(format!("scalogram_{}{suffix}.png", sanitize(&info.test)));
            scalogram_of(
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
    written.extend(time_figures(&histories, period, out)?);
    Ok((written, r.summary))
}
