//! `rigtwin report FILE.mcap --out DIR`: the paper-style figures of a recorded session
//! ([`crate::report::session`]) and the replayed summary as JSON (`summary.json`).

use clap::Args;
use std::path::{Path, PathBuf};

use super::paths::Files;
use crate::session::SessionSummary;

/// The kinds of file `report` writes into its folder.
pub(crate) const FOLDER_FILES: &[&str] = &["png", "svg", "json"];

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
    Files::new()
        .input("FILE", &a.file, "the session log")
        .output_folder("--out", &a.out, "the figures and summary", FOLDER_FILES)
        .ready()?;
    let (written, summary) = figures(&a.file, &a.out)?;
    for p in written {
        println!("{}", p.display());
    }
    if let Some(m) = &summary.missing {
        println!("INCOMPLETE: {}", m.description);
    }
    if let Some(r) = &summary.abort_reason {
        println!("ABORTED: {r}");
    }
    if summary.steps().next().is_none() {
        println!(
            "no step of the session was finished: there is no step to draw, only the summary \
             ({} blocks, {:.2} s of rig time recorded)",
            summary.blocks, summary.rig_seconds
        );
    }
    Ok(())
}

/// Draws the figures of the session log `file` into `out` and writes the replayed summary
/// there (`summary.json`); returns the files written and the summary.
pub(crate) fn figures(file: &Path, out: &Path) -> anyhow::Result<(Vec<PathBuf>, SessionSummary)> {
    let (mut written, summary) = crate::report::session::session_figures(file, out)?;
    let json = out.join("summary.json");
    super::write_json(&json, &summary)?;
    written.push(json);
    Ok((written, summary))
}
