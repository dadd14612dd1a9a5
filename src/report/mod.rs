//! Paper-style figures (reference section 4) as PNG or SVG, drawn with plotters from the plain
//! data structs of [`data`]:
//! - [`rms_response`]: RMS tip velocity vs frequency, both beams, each level, forward and
//!   backward (the reference's "plot_rms"),
//! - [`amplitude_range`]: min/mean/max per-period amplitude vs frequency per level,
//! - [`time_histories`]: tip velocities u/(Omega l) over time,
//! - [`contact_activity`]: contact state and integrated contact forces normalised by their
//!   maximum in the window,
//! - [`scalogram()`]: Morlet scalogram heat map with a log10 colour scale,
//! - [`convergence()`]: relative RMS error vs time steps per period or number of modes.
//!
//! Overlays of several sources are part of the data model ([`Source`]): colours tell tests
//! apart, line styles tell sources apart, and the legend sits in its own strip below the
//! panels so it never covers data. The format follows the file extension (`.png`, `.svg`).
//! Text uses the embedded DejaVu Sans (`assets/fonts/`), so no system font is needed.

pub mod data;
mod draw;
pub mod figures;
mod render;
pub mod session;
pub mod stepped;

use std::path::PathBuf;

pub use data::{
    Beam, Convergence, ConvergenceKind, ConvergenceSignal, FrequencyResponse, Source, TestCurve,
    TimeHistory,
};
pub use figures::{
    amplitude_range, contact_activity, convergence, rms_response, scalogram, time_histories,
    ScalogramOptions, TimeWindow,
};

/// Size of a figure. For PNG the image has exactly these pixels; SVG uses them as its
/// user-space size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FigureOptions {
    /// Width, px (default 1600).
    pub width: u32,
    /// Height, px (default 1000).
    pub height: u32,
}

impl Default for FigureOptions {
    fn default() -> Self {
        FigureOptions {
            width: 1600,
            height: 1000,
        }
    }
}

/// An error while drawing a figure. Every message names the output file.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The data holds nothing drawable (empty, or no finite value).
    #[error("{path}: nothing to plot: {what}")]
    NothingToPlot {
        /// The figure that was not written.
        path: PathBuf,
        /// What was missing.
        what: String,
    },
    /// The data is inconsistent (e.g. vectors of different lengths).
    #[error("{path}: invalid figure data: {what}")]
    InvalidData {
        /// The figure that was not written.
        path: PathBuf,
        /// What is wrong and where.
        what: String,
    },
    /// The extension is not `.png` or `.svg`.
    #[error("{path}: unsupported figure format: use a .png or .svg file name")]
    UnsupportedFormat {
        /// The requested output.
        path: PathBuf,
    },
    /// The figure size is unusable.
    #[error("{path}: figure size {width} x {height} px: expected at least {min} x {min} px")]
    InvalidSize {
        /// The requested output.
        path: PathBuf,
        /// Requested width, px.
        width: u32,
        /// Requested height, px.
        height: u32,
        /// Smallest accepted side, px.
        min: u32,
    },
    /// The output directory could not be created.
    #[error("{path}: cannot create the output directory: {source}")]
    Io {
        /// The requested output.
        path: PathBuf,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The signal processing behind the figure failed (e.g. a record too short to analyse).
    #[error("{path}: {source}")]
    Signal {
        /// The figure that was not written.
        path: PathBuf,
        /// What failed.
        #[source]
        source: crate::signal::SignalError,
    },
    /// plotters failed while drawing or writing the file.
    #[error("{path}: drawing failed: {message}")]
    Draw {
        /// The requested output.
        path: PathBuf,
        /// plotters' message.
        message: String,
    },
}
