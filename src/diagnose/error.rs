//! The errors of the identification stage: what a recording cannot tell.

use crate::control::summary::SummaryError;

/// Why an estimate cannot be made from a recording.
#[derive(Debug, thiserror::Error)]
pub enum EvidenceError {
    /// The recording has no record window (no `record_end` event): nothing was measured in
    /// steady state.
    #[error(
        "the recording has no record window (no record_end event): no step reached its record \
         window, nothing to estimate from"
    )]
    NoRecordWindows,
    /// Every record window's counts are missing from the recording (a damaged or cut log).
    #[error(
        "none of the recording's {windows} record windows is complete in its DAQ blocks (the \
         log was damaged or cut off): nothing to estimate from"
    )]
    NoCompleteWindows {
        /// Record windows named by the events.
        windows: usize,
    },
    /// A sensor-gain correction names a channel the layout lacks.
    #[error("sensor-gain correction for channel {channel:?}: the DAQ layout has no such channel")]
    UnknownChannel {
        /// The channel named.
        channel: String,
    },
    /// A sensor-gain correction is not a positive finite number.
    #[error("sensor-gain correction for channel {channel:?}: {gain} is not a gain > 0")]
    BadGain {
        /// The channel.
        channel: String,
        /// The gain given.
        gain: f64,
    },
    /// The layout lacks a channel an estimator needs.
    #[error("the DAQ layout has no {0} channel")]
    MissingChannel(&'static str),
    /// A record window's signals could not be computed.
    #[error(transparent)]
    Window(#[from] SummaryError),
    /// No record window of the recording is free of contact.
    #[error(
        "no impact-free record window in the recording ({windows} windows, all with contact in \
         the contact-resistance channel): the linear frequencies and damping cannot be \
         estimated"
    )]
    NoImpactFreeSteps {
        /// Record windows in the recording.
        windows: usize,
    },
    /// No test has a resonance of 1FL or 1FU inside its impact-free steps.
    #[error(
        "no test has a resonance peak inside its impact-free steps (at least {min_steps} \
         impact-free steps around an interior peak are needed): {why}"
    )]
    NoResonance {
        /// Impact-free steps needed per fit.
        min_steps: usize,
        /// Why each test was skipped.
        why: String,
    },
    /// The amplitude dependence of a mode needs fits at two or more levels.
    #[error(
        "mode {mode}: impact-free fits at {levels} level(s) only ({tests}): the amplitude \
         dependence (clamp friction) needs impact-free steps over the resonance at two or more \
         levels"
    )]
    SingleLevel {
        /// Mode label.
        mode: String,
        /// Distinct levels with a fit.
        levels: usize,
        /// The tests with a fit.
        tests: String,
    },
    /// A trend needs two or more points with distinct abscissae.
    #[error("{what}: {points} point(s) with distinct abscissae, a trend needs two or more")]
    TooFewPoints {
        /// What trend.
        what: String,
        /// Usable points.
        points: usize,
    },
    /// The abscissae of a trend do not match its points.
    #[error("{what}: {given} abscissae for {points} points")]
    AbscissaeMismatch {
        /// What trend.
        what: String,
        /// Abscissae given.
        given: usize,
        /// Points.
        points: usize,
    },
    /// The beam length for clearances in units of l is not a positive length.
    #[error("beam length {0} m: expected a length > 0")]
    BadBeamLength(f64),
}

/// Why a diagnosis cannot be made or failed.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// The recording cannot give the evidence (no record windows, a damaged log, ...).
    #[error("cannot diagnose: {0}")]
    Evidence(#[from] EvidenceError),
    /// The model cannot run (bad model, non-finite input, ...).
    #[error("the model: {0}")]
    Twin(#[from] crate::twin::TwinError),
    /// The whole-session re-run of the model failed.
    #[error("the model's re-run: {0}")]
    Replay(#[from] crate::session::twin_replay::TwinReplayError),
    /// The model's metrics over a record window failed.
    #[error("the model's metrics of step {step} of test {test}: {source}")]
    Metrics {
        /// Test name.
        test: String,
        /// Step index.
        step: usize,
        /// What failed.
        source: crate::signal::SignalError,
    },
    /// A model run's thread panicked (a bug: reported, never hidden).
    #[error("a model run's thread panicked")]
    Panicked,
}
