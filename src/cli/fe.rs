//! `rigtwin fe export-calculix`.

use clap::{Args, Subcommand};
use std::path::PathBuf;

use super::paths::Files;

/// `rigtwin fe ...`
#[derive(Subcommand, Debug)]
pub enum FeCommand {
    /// Write the native FE mesh as CalculiX decks: JOB.inp (*FREQUENCY) and JOB_matrix.inp
    /// (*FREQUENCY,SOLVER=MATRIXSTORAGE), with node sets for parts, contact pairs and sensors.
    ExportCalculix(ExportArgs),
}

/// `rigtwin fe export-calculix`
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Rig description (TOML). Default: the embedded default rig.
    pub config: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Job name (file stem).
    #[arg(long, default_value = "rig")]
    pub job: String,
    /// Number of eigenmodes the *FREQUENCY steps ask for.
    #[arg(long, default_value_t = 20)]
    pub modes: usize,
}

pub(crate) fn run(cmd: FeCommand) -> anyhow::Result<()> {
    match cmd {
        FeCommand::ExportCalculix(a) => {
            Files::new()
                .input_opt("CONFIG", a.config.as_deref(), "the rig description")
                .output_folder("--out", &a.out, "the CalculiX decks", &["inp"])
                .ready()?;
            let cfg = super::models::load_config(a.config.as_deref())?;
            let mesh = crate::fe::rig::mesh_rig(cfg.model())?;
            let files = crate::fe::calculix::export(&mesh, &a.out, &a.job, a.modes)?;
            println!(
                "{} nodes, {} elements -> {}",
                mesh.n_nodes(),
                mesh.elements.len(),
                files
                    .paths()
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            Ok(())
        }
    }
}
