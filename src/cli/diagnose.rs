//! `rigtwin diagnose`: where a recorded session and its model differ, what physics the model
//! left out, fitted and validated ([`crate::diagnose`]); this reads the log, picks the model
//! (the rig description in the log, or `--config`, with `[truth]` stripped: a diagnosis never
//! reads the simulated rig's hidden physics), shows progress and writes the results.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::config::RigConfig;
use crate::diagnose::{diagnose, DiagnoseInput, DiagnoseOptions, DiagnoseProgress, Diagnosis};

use super::models;
use super::paths::Files;

/// `rigtwin diagnose`
#[derive(Args, Debug)]
pub struct DiagnoseArgs {
    /// The session log (MCAP).
    pub file: PathBuf,
    /// The model's rig description (default: the one stored in the log). Its `[truth]` tables
    /// are ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the diagnosis (JSON) here.
    #[arg(long)]
    pub json: PathBuf,
    /// Write the figures (PNG and SVG) into this folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Write the rig description with the accepted extensions in `[model]` here.
    #[arg(long)]
    pub write_config: Option<PathBuf>,
    /// Threads for the model runs (default: the machine's cores).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: Option<u16>,
    /// Rebuild the model's ROM even if cached.
    #[arg(long)]
    pub rebuild: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

pub(crate) fn run(a: DiagnoseArgs) -> anyhow::Result<()> {
    Files::new()
        .input("FILE", &a.file, "the session log")
        .input_opt(
            "--config",
            a.config.as_deref(),
            "the model's rig description",
        )
        .output("--json", &a.json, "the diagnosis")
        .output_folder("--out", &a.out, "the figures", &["png", "svg"])
        .output_opt(
            "--write-config",
            a.write_config.as_deref(),
            "the fixed rig description",
        )
        .ready()?;
    let wall = std::time::Instant::now();
    let r = crate::session::replay::replay(&a.file)?;
    if !r.complete {
        println!(
            "note: the log was not closed ({}); diagnosing what it holds",
            r.note.as_deref().unwrap_or("truncated")
        );
    }
    let (text, source) = match &a.config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("--config {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (
            r.rig_toml.clone().with_context(|| {
                format!(
                    "{}: the log holds no rig description (rig.toml attachment); name the model with --config",
                    a.file.display()
                )
            })?,
            "rig.toml (attached to the log)".to_string(),
        ),
    };
    let text = crate::config::without_truth(&text, &source)?;
    let cfg = RigConfig::from_str(&text, &source)?;
    let (rom, rom_path, _) = models::cached_rom(&cfg, a.rebuild, a.quiet)?;
    super::check_extensions(&rom, &cfg.model, &source)?;
    println!(
        "model: {source} (ROM {}); extensions: {}",
        rom_path.display(),
        super::extensions_line(&cfg.model)
    );
    // The impact band's verdict compares with the discretisation member's spread: its finer
    // ROM, only for a session with contact.
    let finer = if crate::diagnose::needs_finer_rom(&r.summary, &cfg) {
        let cutoff = cfg.twin.discretisation.cutoff_ratio;
        Some(models::finer_rom(&cfg, cutoff, a.rebuild, a.quiet)?)
    } else {
        None
    };
    // The discretisation stage re-runs a twin coarser than the reference on the reference
    // ROM: built (or loaded) only for a session with contact.
    let refined = match crate::diagnose::refined_reduction(&cfg, &rom) {
        Some(reference) if r.summary.steps().any(crate::diagnose::rerun::had_contact) => {
            let (rom, _, _) = models::cached_rom(&reference, a.rebuild, a.quiet)?;
            Some(rom)
        }
        _ => None,
    };
    let jobs = a.jobs.map_or_else(
        || std::thread::available_parallelism().map_or(1, |n| n.get()),
        usize::from,
    );
    let opts = DiagnoseOptions {
        jobs,
        ..DiagnoseOptions::default()
    };
    let bar = if a.quiet {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden())
    } else {
        let b = ProgressBar::new_spinner();
        b.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        b.enable_steady_tick(std::time::Duration::from_millis(200));
        b
    };
    let mut evaluations = 0usize;
    let quiet = a.quiet;
    let mut progress = |p: DiagnoseProgress| {
        let (line, message) = match p {
            DiagnoseProgress::Stage(s) => (format!("== {s}"), s),
            DiagnoseProgress::Evaluation(s) => {
                evaluations += 1;
                (
                    format!("   hypothesis {evaluations}: {s}"),
                    format!("hypothesis {evaluations}: model runs"),
                )
            }
            DiagnoseProgress::Note(s) => (format!("   {s}"), String::new()),
        };
        if !quiet {
            bar.suspend(|| println!("{line}"));
        }
        if !message.is_empty() {
            bar.set_message(message);
        }
    };
    let input = DiagnoseInput {
        rec: &r.recording,
        summary: &r.summary,
        cfg: &cfg,
        rom: &rom,
        finer: finer.as_ref(),
        refined: refined.as_ref(),
    };
    let mut d = diagnose(&input, &opts, &mut progress)
        .with_context(|| format!("diagnosis of {}", a.file.display()))?;
    bar.finish_and_clear();
    if let Some(p) = &a.write_config {
        let mut fixed = crate::config::with_model(&text, &source, &d.model_after)?;
        if let Some(refinement) = &d.discretisation_after {
            fixed = crate::config::with_discretisation(
                &fixed,
                &source,
                refinement.reduction.as_ref(),
                refinement.steps_per_reference_period,
            )?;
        }
        std::fs::write(p, fixed).with_context(|| format!("--write-config {}", p.display()))?;
        d.model = Some(p.display().to_string());
    }
    let figures = crate::report::figures::diagnosis::draw_diagnosis(&d, &a.out)
        .with_context(|| format!("--out {}", a.out.display()))?;
    d.wall_seconds = wall.elapsed().as_secs_f64();
    super::write_json(&a.json, &d)?;
    print_diagnosis(&d);
    println!("diagnosis: {}", a.json.display());
    println!("figures: {} files in {}", figures.len(), a.out.display());
    if let Some(p) = &d.model {
        println!(
            "fixed model: {p} (rigtwin replay {} --twin --config {p})",
            a.file.display()
        );
    }
    Ok(())
}

/// Whether the impact band lies within the comparison's spread, in words.
fn within(b: &crate::diagnose::outcome::BandSpread) -> &'static str {
    match b.beyond {
        true => "beyond the spread",
        false => "within the spread",
    }
}

/// The human summary of a diagnosis.
fn print_diagnosis(d: &Diagnosis) {
    println!(
        "verdict: {}",
        match d.verdict {
            crate::diagnose::Verdict::Mismatch => "MISMATCH",
            crate::diagnose::Verdict::NoSignificantMismatch => "no significant mismatch",
        }
    );
    for r in &d.regimes_before {
        let after = d.regimes_after.iter().find(|a| a.regime == r.regime);
        println!(
            "  {:?}: {} steps, {} above {} (median largest score {:.2}){}",
            r.regime,
            r.steps,
            r.steps_above,
            d.threshold,
            r.median_max_score,
            after
                .filter(|_| !d.scores_after.is_empty())
                .map(|a| format!(
                    "; fixed model: {} above (median {:.2})",
                    a.steps_above, a.median_max_score
                ))
                .unwrap_or_default()
        );
    }
    if let Some(b) = &d.band_before {
        println!(
            "  Impacts with the comparison's spread (ensemble of {}{}): {} above {} (median {:.2}), {}{}",
            b.members,
            b.finer_modes
                .map(|m| format!(", finer model of {m} modes"))
                .unwrap_or_default(),
            b.scores.steps_above,
            d.threshold,
            b.scores.median_max_score,
            within(b),
            d.band_after
                .as_ref()
                .map(|a| format!(
                    "; fixed model: {} above (median {:.2}), {}",
                    a.scores.steps_above,
                    a.scores.median_max_score,
                    within(a)
                ))
                .unwrap_or_default()
        );
    }
    for e in &d.effects {
        println!(
            "  {}. {} {}: {} {}",
            e.rank,
            if e.accepted { "ACCEPTED" } else { "rejected" },
            e.effect,
            e.parameters,
            match (e.error_before, e.error_after) {
                (Some(b), Some(a)) => format!(
                    "(error train {:.3} -> {:.3}, validation {:.3} -> {:.3})",
                    b.train, a.train, b.validation, a.validation
                ),
                _ => String::new(),
            }
        );
        println!("       {}", e.reason);
        for alt in &e.alternatives {
            println!("       alternative: {alt}");
        }
    }
    for u in &d.undecided {
        println!("  cannot decide {}: {}", u.effect, u.reason);
    }
    if let Some(v) = &d.validation_with_spread {
        println!(
            "  Validation with the comparison's spread ({}): {:.3} -> {:.3} ({:.1}x), the model as given -> the fixed model",
            v.tests.join(", "),
            v.before,
            v.after,
            v.before / v.after.max(1e-12)
        );
    }
    println!(
        "model runs: {} ({:.0} s of rig time in {:.1} s), {:.1} s in all",
        d.cost.model_runs, d.cost.model_rig_seconds, d.cost.model_wall_seconds, d.wall_seconds
    );
    for c in d.cost.stages.iter().filter(|c| c.model_runs > 0) {
        println!(
            "  {:<20} {:>4} runs, {:>7.0} s of rig time in {:>7.1} s",
            c.stage, c.model_runs, c.model_rig_seconds, c.model_wall_seconds
        );
    }
}
