//! Per-step signal processing shared by the virtual stepped sine and recorded measurements:
//! whole-period bookkeeping and quadrature ([`periods`]), the step metrics of the reference's
//! frequency-response figures ([`metrics`]), synchronous demodulation of the fundamental in
//! batch and streaming form ([`demod`]), contact intervals, impacts per period and impact
//! clusters ([`mod@contact_activity`]), drift-free integration of measured accelerations ([`integrate`]), sensor noise floors ([`noise`]), the analytic Morlet wavelet transform ([`wavelet`]), half-harmonic band spectra and their
//! log-spectral distance ([`spectrum`]) and
//! the relative RMS error of the convergence studies ([`relative_error`]).
//!
//! Everything here is pure and deterministic: slices in, values out, no I/O, no clock; the
//! streaming demodulator does not allocate. Records are uniformly sampled, `t_k = t_0 + k dt`,
//! and need not hold an integer number of samples per excitation period (a DAQ samples at a
//! fixed rate): see [`periods`] for how fractional period boundaries are handled.

pub mod contact_activity;
pub mod demod;
mod error;
pub mod features;
mod fft;
pub mod integrate;
pub mod metrics;
pub mod noise;
pub mod periods;
pub mod relative_error;
pub mod spectrum;
pub mod wavelet;

pub use contact_activity::{
    contact_activity, contact_intervals, count_impacts, ActivityParams, ContactActivity,
    ContactInterval, ImpactCluster,
};
pub use demod::{demodulate, Demodulator, Harmonic, PeriodHarmonic};
pub use error::SignalError;
pub use features::{ensemble_features, window_features, Feature, FeatureWindow};
pub use integrate::integrate_periodic;
pub use metrics::{step_metrics, MetricsParams, StepMetrics, StepRecord};
pub use noise::{add_white_noise, noise_floor, NoiseFloor};
pub use periods::PeriodGrid;
pub use relative_error::relative_rms_error;
pub use spectrum::{band_spectrum, spectrum_distance_db, SPECTRUM_BANDS};
pub use wavelet::{log_spaced, morlet_scalogram, MorletParams, Scalogram, WaveletNorm};
