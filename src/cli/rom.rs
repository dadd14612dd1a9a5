//! `rigtwin rom build|info`.

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use std::path::PathBuf;

use super::paths::Files;
use super::progress::BuildProgress;
use crate::rom::build::{build_calculix, build_native, BuildOptions};
use crate::rom::info::{RomInfo, RomOrigin};
use crate::rom::ModeSelection;

/// `rigtwin rom ...`
#[derive(Subcommand, Debug)]
pub enum RomCommand {
    /// Build a ROM from a rig description (default: the embedded default rig) or from CalculiX matrices.
    Build(BuildArgs),
    /// Summarise a ROM file.
    Info(InfoArgs),
}

/// Mode-selection flags shared by commands that build ROMs.
#[derive(Args, Debug, Clone, Default)]
pub struct SelectionArgs {
    /// Keep all modes up to this multiple of f(1FU) (overrides the rig description).
    #[arg(long, conflicts_with = "modes")]
    pub cutoff_ratio: Option<f64>,
    /// Keep this many modes (overrides the rig description).
    #[arg(long)]
    pub modes: Option<usize>,
}

impl SelectionArgs {
    /// The selection the flags ask for, if any.
    pub fn selection(&self) -> anyhow::Result<Option<ModeSelection>> {
        match (self.cutoff_ratio, self.modes) {
            (Some(r), _) if !(r.is_finite() && r > 1.0) => {
                bail!("--cutoff-ratio must be a number > 1 (multiple of f(1FU)), got {r}")
            }
            (Some(ratio), _) => Ok(Some(ModeSelection::CutoffRatio { ratio })),
            (None, Some(0)) => bail!("--modes must be at least 1"),
            (None, Some(count)) => Ok(Some(ModeSelection::Count { count })),
            (None, None) => Ok(None),
        }
    }
}

/// `rigtwin rom build`
#[derive(Args, Debug)]
pub struct BuildArgs {
    /// Rig description (TOML). Default: the embedded default rig (rig-config/two-beam.toml).
    pub config: Option<PathBuf>,
    /// Build from CalculiX matrices instead: path of the job without extension (JOB.inp,
    /// JOB.sti, JOB.mas, JOB.dof). CONFIG (or the default) still supplies damping and friction.
    #[arg(long, value_name = "JOB")]
    pub calculix: Option<PathBuf>,
    /// Output ROM file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the `rom info` JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub selection: SelectionArgs,
}

/// `rigtwin rom info`
#[derive(Args, Debug)]
pub struct InfoArgs {
    /// ROM file.
    pub file: PathBuf,
    /// Write the summary as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub(crate) fn run(cmd: RomCommand) -> anyhow::Result<()> {
    match cmd {
        RomCommand::Build(a) => {
            let mut files = Files::new()
                .input_opt("CONFIG", a.config.as_deref(), "the rig description")
                .output("--out", &a.out, "the ROM")
                .output_opt("--json", a.json.as_deref(), "the ROM summary");
            if let Some(job) = &a.calculix {
                for ext in ["inp", "sti", "mas", "dof"] {
                    let file = crate::fe::calculix::job_file(job, ext);
                    files = files.input("--calculix", &file, "a CalculiX file");
                }
            }
            files.ready()?;
            let cfg = super::models::load_config(a.config.as_deref())?;
            let opts = BuildOptions {
                selection: a.selection.selection()?,
            };
            let progress = BuildProgress::new(a.quiet);
            let mut on_event = |e: crate::rom::build::BuildEvent| progress.event(&e);
            let rom = match &a.calculix {
                Some(job) => build_calculix(job, cfg.model(), &opts, &mut on_event)?,
                None => build_native(cfg.model(), &opts, &mut on_event)?,
            };
            progress.finish();
            crate::rom::file::write(&rom, &a.out)?;
            let info = RomInfo::new(&rom);
            println!("{}", info.text(RomOrigin::Built));
            println!("wrote {}", a.out.display());
            if let Some(j) = &a.json {
                super::write_json(j, &info)?;
            }
            Ok(())
        }
        RomCommand::Info(a) => {
            Files::new()
                .input("FILE", &a.file, "the ROM")
                .output_opt("--json", a.json.as_deref(), "the ROM summary")
                .ready()?;
            let rom =
                crate::rom::file::read(&a.file).with_context(|| "reading the ROM".to_string())?;
            let info = RomInfo::new(&rom);
            // A file of the ROM cache is "loaded from the cache" as `demo` says of it.
            let in_cache = a.file.parent().is_some_and(|d| {
                let cache = super::cache_dir();
                d.canonicalize().ok() == cache.canonicalize().ok() && cache.canonicalize().is_ok()
            });
            let origin = if in_cache {
                RomOrigin::Cache
            } else {
                RomOrigin::File
            };
            println!("{}", info.text(origin));
            if let Some(j) = &a.json {
                super::write_json(j, &info)?;
            }
            Ok(())
        }
    }
}
