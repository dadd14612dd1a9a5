//! The error type of the signal module: what was wrong with a record or a parameter, naming
//! the channel, the sample index and what was expected.

/// Errors of the signal functions. Every variant names the offending channel or parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SignalError {
    /// A scalar parameter is out of its domain (e.g. `omega <= 0`).
    #[error("{name} must be {expected}, got {value}")]
    InvalidParameter {
        /// Parameter name, with unit, e.g. "omega (rad/s)".
        name: &'static str,
        /// Value passed.
        value: f64,
        /// What was expected, e.g. "finite and > 0".
        expected: &'static str,
    },
    /// A channel has no samples.
    #[error("channel `{channel}` is empty")]
    Empty {
        /// Channel name.
        channel: &'static str,
    },
    /// Two channels that must be sampled together have different lengths.
    #[error(
        "channel `{channel}` has {len} samples but `{reference}` has {expected}; \
         all channels of a record must have one sample per time step"
    )]
    LengthMismatch {
        /// Channel whose length differs.
        channel: &'static str,
        /// Its length.
        len: usize,
        /// The channel it is compared with.
        reference: &'static str,
        /// The length of `reference`.
        expected: usize,
    },
    /// A sample is NaN or infinite.
    #[error("channel `{channel}`: sample {index} is {value} (samples must be finite)")]
    NonFinite {
        /// Channel name.
        channel: &'static str,
        /// Index of the first non-finite sample.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// The record does not contain one whole excitation period.
    #[error(
        "record of {samples} samples spans only {periods:.4} excitation periods \
         ({samples_per_period:.4} samples per period); at least one whole period is needed"
    )]
    TooShort {
        /// Number of samples in the record.
        samples: usize,
        /// Samples per excitation period, 2 pi / (Omega dt).
        samples_per_period: f64,
        /// Record length in periods.
        periods: f64,
    },
    /// The sampling is too coarse for per-period processing.
    #[error(
        "only {samples_per_period:.4} samples per excitation period (dt = {dt} s, \
         Omega = {omega} rad/s); at least {min} are needed"
    )]
    TooCoarse {
        /// Samples per excitation period.
        samples_per_period: f64,
        /// Sample interval, s.
        dt: f64,
        /// Excitation frequency, rad/s.
        omega: f64,
        /// Minimum samples per period.
        min: f64,
    },
    /// A frequency of a wavelet transform is outside (0, Nyquist).
    #[error(
        "wavelet frequency {index} is {value} Hz; it must lie in (0, {nyquist}] Hz \
         (the Nyquist frequency of dt)"
    )]
    FrequencyOutOfRange {
        /// Index in the frequency list.
        index: usize,
        /// Frequency, Hz.
        value: f64,
        /// Nyquist frequency 1 / (2 dt), Hz.
        nyquist: f64,
    },
    /// The reference signal of a relative error has no energy.
    #[error(
        "reference signal `{channel}` is zero over the compared span of {samples} samples; \
         the relative RMS error is undefined"
    )]
    ZeroReference {
        /// Channel name.
        channel: &'static str,
        /// Number of compared samples.
        samples: usize,
    },
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn require_positive(name: &'static str, value: f64) -> Result<(), SignalError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SignalError::InvalidParameter {
            name,
            value,
            expected: "finite and > 0",
        })
    }
}

/// Returns the first non-finite sample of `x` as an error naming `channel`.
pub(crate) fn require_finite(channel: &'static str, x: &[f64]) -> Result<(), SignalError> {
    match x.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(SignalError::NonFinite {
            channel,
            index,
            value: x[index],
        }),
    }
}

/// Checks that `channel` has `expected` samples (the length of `reference`).
pub(crate) fn require_len(
    channel: &'static str,
    len: usize,
    reference: &'static str,
    expected: usize,
) -> Result<(), SignalError> {
    if len == expected {
        Ok(())
    } else {
        Err(SignalError::LengthMismatch {
            channel,
            len,
            reference,
            expected,
        })
    }
}
