//! `rigtwin report FILE.mcap --out DIR`: the paper-style figures of a recorded session
//! ([`crate::report::session`]) and the replayed summary as JSON (`summary.json`).

use clap::Args;
use std::path::{Path, PathBuf};

use super::paths::Files;

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
        .check()?;
    for p in figures(&a.file, &a.out)? {
        println!("{}", p.display());
    }
    Ok(())
}

/// Draws the figures of the session log `file` into `out` and writes the replayed summary
/// there (`summary.json`); returns the files written.
pub(crate) fn figures(file: &Path, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let (mut written, summary) = crate::report::session::session_figures(file, out)?;
    let json = out.join("summary.json");
    super::write_json(&json, &summary)?;
    written.push(json);
    Ok(written)
}
