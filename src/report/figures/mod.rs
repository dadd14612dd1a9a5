//! The figure functions, one file per family: frequency responses ([`frequency`]), time
//! histories and contact activity ([`time`]), the scalogram ([`scalogram`](mod@scalogram)),
//! convergence studies ([`convergence`](mod@convergence)); `panel.rs` is the shared x-y panel.

pub mod convergence;
pub mod diagnosis;
pub mod frequency;
mod panel;
pub mod scalogram;
pub mod time;

pub use convergence::convergence;
pub use frequency::{amplitude_range, rms_response};
pub use scalogram::scalogram;
pub use time::{contact_activity, time_histories};

/// A time window `[start, end]`, s, for the zoomed views of the time-domain figures.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimeWindow {
    /// First time shown, s.
    pub start: f64,
    /// Last time shown, s.
    pub end: f64,
}

impl TimeWindow {
    /// Whether `t` (s) is inside the window (ends included).
    pub fn contains(&self, t: f64) -> bool {
        t >= self.start && t <= self.end
    }
}

/// Settings of the scalogram figure.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScalogramOptions {
    /// Time of the first sample, s (default 0).
    pub t0: f64,
    /// Colour range: this many decades of |W| below the maximum (default 4).
    pub decades: f64,
    /// Appended to the title, e.g. "simulation, upper beam, Ω = ω₂" (default empty).
    pub label: String,
}

impl Default for ScalogramOptions {
    fn default() -> Self {
        ScalogramOptions {
            t0: 0.0,
            decades: 4.0,
            label: String::new(),
        }
    }
}
