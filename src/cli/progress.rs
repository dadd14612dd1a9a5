//! Progress display for long commands (indicatif): one spinner line per build stage, a bar
//! for the eigen solve, and a closing summary. Hidden when stderr is not a terminal.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Duration;

use crate::rom::build::BuildEvent;

/// Renders [`BuildEvent`]s of a ROM build.
pub struct BuildProgress {
    bar: ProgressBar,
}

impl BuildProgress {
    /// A progress display on stderr (hidden if `quiet`).
    pub fn new(quiet: bool) -> Self {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new_spinner()
        };
        if !quiet {
            bar.set_draw_target(ProgressDrawTarget::stderr());
            bar.enable_steady_tick(Duration::from_millis(120));
        }
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {prefix:>12} {wide_msg}")
                .expect("template"),
        );
        BuildProgress { bar }
    }

    /// Shows one event.
    pub fn event(&self, e: &BuildEvent) {
        match e {
            BuildEvent::Stage { name, detail } => {
                self.bar.set_prefix(name.to_string());
                self.bar.set_message(detail.clone());
            }
            BuildEvent::StageDone {
                name,
                seconds,
                detail,
            } => {
                self.bar
                    .println(format!("  {name:>12}  {seconds:7.2} s  {detail}"));
            }
            BuildEvent::Eigen {
                converged,
                target,
                target_hz,
                highest_hz,
            } => {
                self.bar.set_prefix("eigen");
                let goal = match (target, target_hz) {
                    (Some(n), _) => format!("/{n} modes"),
                    (None, Some(hz)) => format!(" modes (cutoff {hz:.0} Hz)"),
                    (None, None) => " modes".to_string(),
                };
                self.bar.set_message(format!(
                    "{converged}{goal} converged, up to {highest_hz:.0} Hz"
                ));
            }
        }
    }

    /// Removes the spinner line.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
