//! `rigtwin replay`: a recorded session's summary recomputed from its raw DAQ blocks, and with
//! `--twin` the twin re-run on its base motion ([`crate::session::replay`],
//! [`crate::session::twin_replay`]); this picks the twin's model and prints.

use anyhow::Context;
use clap::Args;
use std::path::PathBuf;

use crate::session::replay::{twin_model_source, TwinModelChoice, TwinRom};
use crate::session::twin_replay::{
    replay_twin, replay_twin_steps, DiscretisationMember, EnsembleOptions, StepSelection,
    TwinLogCopy, TwinSink,
};
use crate::twin::{TwinModel, TwinSpec};

use super::models;
use super::paths::Files;
use super::run::print_summary;

/// `rigtwin replay`
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// The session log (MCAP).
    pub file: PathBuf,
    /// Write the recomputed summary (JSON) here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Re-run the twin on the recorded base motion and compare it with the measurement step
    /// by step (`tests[].steps[].twin`). The model is the rig description the session ran
    /// with (stored in the log) unless `--rom` or `--config` names another.
    #[arg(long)]
    pub twin: bool,
    /// The twin's ROM file (with `--twin`; the `[twin]` settings are those of the rig
    /// description in the log, their defaults if it holds none).
    #[arg(long, requires = "twin", conflicts_with = "config")]
    pub rom: Option<PathBuf>,
    /// The twin's rig description (with `--twin`): its ROM is built or taken from the cache,
    /// its `[twin]` table sets the twin.
    #[arg(long, requires = "twin")]
    pub config: Option<PathBuf>,
    /// Rebuild the twin ROM even if cached (with `--twin`).
    #[arg(long, requires = "twin")]
    pub rebuild: bool,
    /// With `--twin`: write a copy of the session log holding the re-run twin's output
    /// (`/twin/blocks`, `/twin/steps`) in place of the recorded twin's, for `rigtwin report`.
    #[arg(long, requires = "twin")]
    pub out: Option<PathBuf>,
    /// With `--twin`: re-run only these steps, each from the twin's state logged at its start
    /// (warm start; the log's `/twin/state`, written by `run --twin` and `replay --twin
    /// --out`): `TEST`, `TEST:N` or `TEST:N-M` (steps counted from 1), comma-separated, e.g.
    /// `high-down:3-5,high-up`. With the model the states were logged with, each step's
    /// comparison equals the whole run's bit for bit.
    #[arg(long, requires = "twin", conflicts_with = "out")]
    pub steps: Option<StepSelection>,
    /// With `--twin`: runs of the twin from perturbed states at each step's start behind the
    /// model spread of the comparison's scores (default: `[twin] ensemble_members`, 4; 0 =
    /// none, the twin's own sub-windows only).
    #[arg(long, requires = "twin", value_parser = clap::value_parser!(u16).range(0..=64))]
    pub ensemble: Option<u16>,
    /// Threads for the ensemble (default: the machine's cores).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: Option<u16>,
}

pub(crate) fn run(a: ReplayArgs) -> anyhow::Result<()> {
    Files::new()
        .input("FILE", &a.file, "the session log")
        .input_opt("--rom", a.rom.as_deref(), "the twin's ROM")
        .input_opt(
            "--config",
            a.config.as_deref(),
            "the twin's rig description",
        )
        .output_opt("--out", a.out.as_deref(), "the session log copy")
        .output_opt("--json", a.json.as_deref(), "the summary")
        .ready()?;
    let r = crate::session::replay::replay(&a.file)?;
    if !r.complete {
        println!(
            "note: the log was not closed ({}); replaying what it holds",
            r.note.as_deref().unwrap_or("truncated")
        );
    } else if !r.summary.complete {
        println!("note: the log is damaged; replaying what it holds");
    }
    let same = r.matches_logged();
    println!(
        "replay: {} blocks, {:.1} s of rig time, {} steps recomputed ({} the logged summaries)",
        r.summary.blocks,
        r.summary.rig_seconds,
        r.logged_steps.len(),
        if same {
            "identical to"
        } else {
            "DIFFERENT from"
        }
    );
    let mut summary = r.summary;
    if a.twin {
        let choice = match (&a.rom, &a.config) {
            (Some(rom), _) => TwinModelChoice::Rom(rom),
            (None, Some(config)) => TwinModelChoice::Config(config),
            (None, None) => TwinModelChoice::Logged,
        };
        let model = twin_model_source(choice, &a.file, r.rig_toml.as_deref())?;
        let mut spec = model.spec.clone();
        if let Some(n) = a.ensemble {
            spec.ensemble_members = usize::from(n);
        }
        let jobs = a.jobs.map_or_else(
            || std::thread::available_parallelism().map_or(1, |n| n.get()),
            usize::from,
        );
        let ensemble = EnsembleOptions::of(&spec, jobs);
        let (rom, source) = match &model.rom {
            TwinRom::File(path) => {
                let rom = crate::rom::file::read(path)
                    .with_context(|| format!("--rom {}", path.display()))?;
                models::warn_few_modes(&rom);
                (rom, model.source.clone())
            }
            TwinRom::Description(cfg) => {
                // The live twin's patch: a coarser one where the plan holds the probes in
                // contact.
                let (rom, path) =
                    match models::held_contact_twin_rom(cfg, &r.clearances, a.rebuild, true)? {
                        Some(twin) => twin,
                        None => {
                            let (rom, path, _) = models::cached_rom(cfg, a.rebuild, true)?;
                            (rom, path)
                        }
                    };
                let source = format!("{} (ROM {})", model.source, path.display());
                (rom, source)
            }
        };
        let twin_model = model.model(&rom);
        super::check_extensions(&rom, &twin_model.extensions, &model.source)?;
        println!(
            "twin model extensions: {}",
            super::extensions_line(&twin_model.extensions)
        );
        // The comparison's discretisation member: with an ensemble and a rig description to
        // build its finer ROM from.
        let d = &spec.discretisation;
        let finer = match &model.rom {
            TwinRom::Description(cfg) if d.enabled && ensemble.members > 0 => {
                Some(models::finer_rom(cfg, d.cutoff_ratio, a.rebuild, true)?)
            }
            TwinRom::File(_) if d.enabled && ensemble.members > 0 => {
                println!("note: no discretisation member with --rom (it is built from a rig description); the model spreads are the ensemble's");
                None
            }
            _ => None,
        };
        let member = finer.as_ref().map(|f| DiscretisationMember {
            model: TwinModel {
                rom: f,
                ..twin_model.clone()
            },
            spec: TwinSpec {
                steps_per_sample: Some(d.steps_per_sample),
                ..spec.clone()
            },
        });
        let ensemble = EnsembleOptions {
            discretisation: member.as_ref(),
            ..ensemble
        };
        if let Some(m) = &member {
            println!(
                "discretisation member: {} modes at {} steps per sample, in the windows with contact",
                m.model.rom.n_modes(),
                d.steps_per_sample
            );
        }
        let mut copy = match &a.out {
            Some(out) => Some(
                TwinLogCopy::create(out, &a.file, &source, r.recording.layout.dt())
                    .with_context(|| format!("--out {}", out.display()))?,
            ),
            None => None,
        };
        let sink: &mut dyn TwinSink = match &mut copy {
            Some(c) => c,
            None => &mut (),
        };
        let stats = match &a.steps {
            Some(select) => replay_twin_steps(
                &r.recording,
                &mut summary,
                &twin_model,
                &spec,
                rom.meta.beam_length,
                select,
                ensemble,
                sink,
            ),
            None => replay_twin(
                &r.recording,
                &mut summary,
                &twin_model,
                &spec,
                rom.meta.beam_length,
                ensemble,
                sink,
            ),
        }
        .with_context(|| format!("twin replay of {}", a.file.display()))?;
        summary.twin_model = Some(twin_model.extensions);
        println!(
            "twin: {source}: {} blocks, {} steps compared, {} contact-solver failures, {:.3} s \
             per rig second",
            stats.blocks, stats.steps_compared, stats.solver_failures, stats.wall_per_rig_second
        );
        if let (Some(c), Some(out)) = (copy, &a.out) {
            let st = c
                .close()
                .with_context(|| format!("--out {}", out.display()))?;
            println!(
                "session log with the re-run twin: {} ({:.1} MB)",
                out.display(),
                st.bytes_written as f64 / 1e6
            );
        }
    }
    if let Some(j) = &a.json {
        super::write_json(j, &summary)?;
    }
    print_summary(&summary);
    if let Some(j) = &a.json {
        println!("summary: {}", j.display());
    }
    Ok(())
}
