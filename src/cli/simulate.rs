//! `rigtwin simulate`: the virtual stepped sine of a plan on a ROM (tests in parallel, one
//! progress bar per test, JSON results and paper-style figures), and
//! `rigtwin simulate convergence`: the time-step and mode convergence studies.

use anyhow::{bail, Context};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::paths::Files;
use crate::config::PhysicsSpec;
use crate::contact::SweepMethod;
use crate::plan::Plan;
use crate::report::stepped::stepped_sine_figures;
use crate::report::{self, Convergence, ConvergenceKind, ConvergenceSignal, FigureOptions};
use crate::rom::Rom;
use crate::sim::convergence::{
    dt_study, modes_study, stable_steps_per_period, ConvergenceSetup, ConvergenceStart,
    ConvergenceStudy,
};
use crate::sim::stepped::{run_plan, SteppedSineOptions, TestProgress, TestResult};
use crate::sim::{Coupling, IntegratorParameters};

/// `rigtwin simulate`
#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SimulateArgs {
    /// A study instead of a plan.
    #[command(subcommand)]
    pub command: Option<SimulateCommand>,
    /// The stepped sine of a plan.
    #[command(flatten)]
    pub run: RunArgs,
}

/// Subcommands of `simulate`.
#[derive(Subcommand, Debug)]
pub enum SimulateCommand {
    /// Convergence study (reference section 4.3): relative RMS error of the upper tip velocity
    /// over the first periods against the finest run.
    Convergence(ConvergenceArgs),
}

/// Where the ROM comes from.
#[derive(Args, Debug, Clone)]
pub struct RomSource {
    /// ROM file (from `rigtwin rom build`).
    #[arg(long, conflicts_with = "config")]
    pub rom: Option<PathBuf>,
    /// Rig description to build the ROM from (cached by build hash). Without --rom and
    /// --config: the embedded default rig.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

impl RomSource {
    /// The inputs these flags name.
    fn files(&self) -> Files {
        Files::new()
            .input_opt("--rom", self.rom.as_deref(), "the ROM")
            .input_opt("--config", self.config.as_deref(), "the rig description")
    }
}

/// The kinds of file the figures folders hold.
const FIGURE_FILES: &[&str] = &["png", "svg"];

/// Contact coupling on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum CouplingArg {
    /// Contact imposed at the end of the step (stable through persistent contact).
    EndOfStep,
    /// The reference's coupling (stable only below the closed-contact bound).
    Explicit,
}

/// Contact sweep method on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum MethodArg {
    /// Projected Gauss-Seidel.
    GaussSeidel,
    /// Projected Jacobi (the reference's).
    Jacobi,
    /// Projected Jacobi with Nesterov acceleration.
    AcceleratedJacobi,
}

/// Integrator flags shared by the plan run and the studies.
#[derive(Args, Debug, Clone)]
pub struct IntegratorArgs {
    /// Contact coupling.
    #[arg(long, value_enum, default_value = "end-of-step")]
    pub coupling: CouplingArg,
    /// Contact solver sweep.
    #[arg(long, value_enum, default_value = "gauss-seidel")]
    pub contact_method: MethodArg,
}

impl IntegratorArgs {
    fn parameters(&self) -> IntegratorParameters {
        let mut p = IntegratorParameters {
            coupling: match self.coupling {
                CouplingArg::EndOfStep => Coupling::EndOfStep,
                CouplingArg::Explicit => Coupling::Explicit,
            },
            ..Default::default()
        };
        p.contact.method = match self.contact_method {
            MethodArg::GaussSeidel => SweepMethod::GaussSeidel,
            MethodArg::Jacobi => SweepMethod::Jacobi,
            MethodArg::AcceleratedJacobi => SweepMethod::AcceleratedJacobi,
        };
        p
    }
}

/// `rigtwin simulate --plan PLAN ...`
#[derive(Args, Debug)]
pub struct RunArgs {
    #[command(flatten)]
    pub source: RomSource,
    /// Test plan (TOML), e.g. rig-config/plans/paper-table2.toml.
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Write the results (per test and step) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the figures (PNG) into this folder.
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Worker threads for `--from-rest` (tests run in parallel). Default: the available cores.
    #[arg(long, requires = "from_rest")]
    pub jobs: Option<usize>,
    /// Run every test from rest (in parallel) instead of in plan order, each from the state
    /// the previous test left, as the rig does. Either way the drive ramps in.
    #[arg(long)]
    pub from_rest: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub integrator: IntegratorArgs,
}

/// What a study varies.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum KindArg {
    /// Time steps per excitation period.
    Dt,
    /// Number of modes (the ROM truncated exactly).
    Modes,
}

/// Initial conditions of a study.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum StartArg {
    /// After a prerun, at a period start followed by impacts.
    Impacts,
    /// Zero relative to the base at t = 0.
    Rest,
}

/// `rigtwin simulate convergence`
#[derive(Args, Debug)]
pub struct ConvergenceArgs {
    #[command(flatten)]
    pub source: RomSource,
    /// What to vary.
    #[arg(long, value_enum)]
    pub kind: KindArg,
    /// Write the study as JSON here.
    #[arg(long)]
    pub json: PathBuf,
    /// Write the figure (PNG) into this folder.
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Steps per excitation period of the runs (kind dt; the largest is the reference).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1000,2000,4000,8000,16000,32000,64000,128000"
    )]
    pub steps: Vec<u32>,
    /// Mode counts (kind modes; the largest is the reference). Default: 10, 20, 40, ... and
    /// all modes of the ROM.
    #[arg(long, value_delimiter = ',')]
    pub modes: Vec<usize>,
    /// Steps per period of the mode runs. Default: 1000, or the smallest multiple of 1000
    /// stable for the ROM's highest mode.
    #[arg(long)]
    pub modes_steps: Option<u32>,
    /// Excitation periods compared.
    #[arg(long, default_value_t = 5)]
    pub periods: u32,
    /// Base displacement level / l.
    #[arg(long, default_value_t = 6e-5)]
    pub level: f64,
    /// Clearance / l.
    #[arg(long, default_value_t = 2.78e-3)]
    pub clearance: f64,
    /// Omega / omega_2.
    #[arg(long, default_value_t = 1.0)]
    pub omega: f64,
    /// Initial conditions of every run: `impacts` (after a prerun, at a period start followed
    /// by impacts) or `rest` (zero relative to the base at t = 0).
    #[arg(long, value_enum, default_value = "impacts")]
    pub start: StartArg,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub integrator: IntegratorArgs,
}

pub(crate) fn run(a: SimulateArgs) -> anyhow::Result<()> {
    match a.command {
        Some(SimulateCommand::Convergence(c)) => convergence(c),
        None => stepped_sine(a.run),
    }
}

/// Loads the ROM from a file, or builds/caches it from a rig description (default: embedded),
/// with the description's `[model]` extensions (none with a ROM file).
pub(crate) fn load_rom(
    source: &RomSource,
    quiet: bool,
) -> anyhow::Result<(Rom, String, PhysicsSpec)> {
    if let Some(p) = &source.rom {
        let rom = crate::rom::file::read(p).context("reading the ROM")?;
        super::models::warn_few_modes(&rom);
        return Ok((rom, p.display().to_string(), PhysicsSpec::default()));
    }
    let cfg = super::models::load_config(source.config.as_deref())?;
    let (rom, path, _) = super::models::cached_rom(&cfg, false, quiet)?;
    super::check_extensions(&rom, &cfg.model, &cfg.source)?;
    Ok((rom, path.display().to_string(), cfg.model))
}

/// The JSON of `rigtwin simulate`.
#[derive(serde::Serialize)]
struct SimulateReport<'a> {
    plan: Option<&'a str>,
    plan_source: &'a str,
    rom: RomSummary,
    /// The `[model]` extensions the ROM ran with (`{}`: none).
    model: &'a PhysicsSpec,
    integrator: &'a IntegratorParameters,
    jobs: usize,
    tests: &'a [TestResult],
    time_steps: u64,
    wall_seconds: f64,
    /// Time steps integrated per wall-clock second, all workers together.
    steps_per_second: f64,
    /// Per worker: `steps_per_second / jobs` (the single-core speed when the tests keep every
    /// worker busy).
    steps_per_second_per_worker: f64,
    solver_failures: u64,
}

#[derive(serde::Serialize)]
struct RomSummary {
    path: String,
    config_hash: String,
    n_modes: usize,
    n_pairs: usize,
    f_1fu_hz: f64,
    beam_length: f64,
}

impl RomSummary {
    fn new(rom: &Rom, path: &str) -> RomSummary {
        RomSummary {
            path: path.into(),
            config_hash: rom.meta.config_hash.clone(),
            n_modes: rom.n_modes(),
            n_pairs: rom.n_pairs(),
            f_1fu_hz: rom.omega_ref() / (2.0 * std::f64::consts::PI),
            beam_length: rom.meta.beam_length,
        }
    }
}

/// What [`run_plan_to_outputs`] writes and how it runs.
#[derive(Clone, Copy)]
pub(crate) struct PlanOutputs<'a> {
    /// Worker threads with `from_rest` (default: the available cores).
    pub jobs: Option<usize>,
    /// Every test from rest, in parallel (else in plan order, the state carried).
    pub from_rest: bool,
    /// JSON results file.
    pub json: Option<&'a Path>,
    /// Figures folder.
    pub figures: Option<&'a Path>,
    /// No progress display.
    pub quiet: bool,
    /// The `[model]` extensions (valid).
    pub model: &'a PhysicsSpec,
}

/// Runs a plan and writes what was asked for. Returns the results (for `demo`).
pub(crate) fn run_plan_to_outputs(
    rom: &Rom,
    rom_path: &str,
    plan: &Plan,
    params: IntegratorParameters,
    out: &PlanOutputs<'_>,
) -> anyhow::Result<Vec<TestResult>> {
    let PlanOutputs {
        jobs,
        from_rest,
        json,
        figures,
        quiet,
        model,
    } = *out;
    let jobs = jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let opts = SteppedSineOptions {
        integrator: params,
        model: model.clone(),
        carry_state: !from_rest,
        ..Default::default()
    };
    if !quiet {
        eprintln!("model extensions: {}", super::extensions_line(model));
    }
    let multi = MultiProgress::with_draw_target(if quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    });
    let style = ProgressStyle::with_template(
        "{prefix:>14} [{bar:30}] {percent:>3}% {msg} ({elapsed}, eta {eta})",
    )
    .expect("template")
    .progress_chars("=> ");
    let bars: Vec<ProgressBar> = plan
        .tests
        .iter()
        .map(|t| {
            let b = multi.add(ProgressBar::new(t.total_periods()));
            b.set_style(style.clone());
            b.set_prefix(t.name.clone());
            b
        })
        .collect();
    let on_progress = |p: &TestProgress<'_>| {
        let b = &bars[p.test];
        b.set_position(p.periods_done);
        if p.finished {
            b.finish_with_message("done");
        } else {
            b.set_message(format!(
                "step {}/{} Omega/omega_2 = {:.4}",
                p.step + 1,
                p.steps,
                p.omega_ratio
            ));
        }
    };
    let t0 = Instant::now();
    let results = run_plan(rom, plan, &opts, jobs, &on_progress)?;
    let wall = t0.elapsed().as_secs_f64();
    let time_steps: u64 = results.iter().map(|r| r.time_steps).sum();
    let failures: u64 = results.iter().map(|r| r.solver_failures).sum();
    let workers = if from_rest {
        jobs.min(plan.tests.len()).max(1)
    } else {
        1 // in plan order, the state carried from test to test
    };

    println!(
        "{} tests, {} frequency steps, {:.3e} time steps in {:.1} s: {:.0} steps/s ({} workers)",
        results.len(),
        results.iter().map(|r| r.steps.len()).sum::<usize>(),
        time_steps as f64,
        wall,
        time_steps as f64 / wall,
        workers
    );
    for r in &results {
        let band: Vec<f64> = r
            .steps
            .iter()
            .filter(|s| s.metrics.contact_fraction > 0.0)
            .map(|s| s.omega_ratio)
            .collect();
        let band = match (
            band.iter().copied().reduce(f64::min),
            band.iter().copied().reduce(f64::max),
        ) {
            (Some(lo), Some(hi)) => format!("impacts at Omega/omega_2 {lo:.3}..{hi:.3}"),
            _ => "no impacts".into(),
        };
        let peak = r
            .steps
            .iter()
            .max_by(|a, b| a.metrics.rms_upper.total_cmp(&b.metrics.rms_upper));
        println!(
            "  {:>14}: {} steps, {band}, peak RMS upper {:.1} at {:.3}, {} solver failures{}",
            r.spec.name,
            r.steps.len(),
            peak.map_or(f64::NAN, |s| s.metrics.rms_upper),
            peak.map_or(f64::NAN, |s| s.omega_ratio),
            r.solver_failures,
            r.stopped
                .as_deref()
                .map(|s| format!("; STOPPED: {s}"))
                .unwrap_or_default()
        );
    }
    if let Some(path) = json {
        let report = SimulateReport {
            plan: plan.name.as_deref(),
            plan_source: &plan.source,
            rom: RomSummary::new(rom, rom_path),
            model,
            integrator: &opts.integrator,
            jobs: workers,
            tests: &results,
            time_steps,
            wall_seconds: wall,
            steps_per_second: time_steps as f64 / wall,
            steps_per_second_per_worker: time_steps as f64 / wall / workers as f64,
            solver_failures: failures,
        };
        super::write_json(path, &report)?;
        println!("results: {}", path.display());
    }
    if let Some(dir) = figures {
        let written = stepped_sine_figures(&results, rom.meta.beam_length, dir)?;
        println!("figures: {} files in {}", written.len(), dir.display());
    }
    Ok(results)
}

fn stepped_sine(a: RunArgs) -> anyhow::Result<()> {
    let Some(plan_path) = &a.plan else {
        bail!("--plan PLAN is required (e.g. rig-config/plans/paper-table2.toml)");
    };
    a.source
        .files()
        .input("--plan", plan_path, "the plan")
        .output_opt("--json", a.json.as_deref(), "the results")
        .output_folder_opt(
            "--figures",
            a.figures.as_deref(),
            "the figures",
            FIGURE_FILES,
        )
        .ready()?;
    let plan = Plan::from_path(plan_path)?;
    let (rom, rom_path, model) = load_rom(&a.source, a.quiet)?;
    run_plan_to_outputs(
        &rom,
        &rom_path,
        &plan,
        a.integrator.parameters(),
        &PlanOutputs {
            jobs: a.jobs,
            from_rest: a.from_rest,
            json: a.json.as_deref(),
            figures: a.figures.as_deref(),
            quiet: a.quiet,
            model: &model,
        },
    )?;
    Ok(())
}

fn convergence(a: ConvergenceArgs) -> anyhow::Result<()> {
    a.source
        .files()
        .output("--json", &a.json, "the study")
        .output_folder_opt(
            "--figures",
            a.figures.as_deref(),
            "the figure",
            FIGURE_FILES,
        )
        .ready()?;
    if !(a.omega > 0.0 && a.omega < 10.0) {
        bail!("--omega = {}: expected Omega/omega_2 in (0, 10)", a.omega);
    }
    if !(a.level > 0.0 && a.level <= 1e-2 && a.clearance > 0.0 && a.clearance <= 0.1) {
        bail!(
            "--level = {} / --clearance = {}: expected a level in (0, 1e-2] and a clearance in (0, 0.1] (fractions of l)",
            a.level,
            a.clearance
        );
    }
    if a.periods == 0 {
        bail!("--periods must be at least 1");
    }
    let (rom, _, _) = load_rom(&a.source, a.quiet)?;
    let setup = ConvergenceSetup {
        omega_ratio: a.omega,
        level: a.level,
        clearance: a.clearance,
        periods: a.periods,
        start: match a.start {
            StartArg::Impacts => ConvergenceStart::Impacts,
            StartArg::Rest => ConvergenceStart::Rest,
        },
        integrator: a.integrator.parameters(),
        ..Default::default()
    };
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {pos}/{len} runs {msg}")
            .expect("template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(150));
    let t0 = Instant::now();
    let study = match a.kind {
        KindArg::Dt => {
            if a.steps.contains(&0) {
                bail!("--steps: steps per period must be at least 1");
            }
            bar.set_length(a.steps.len() as u64);
            dt_study(&rom, &setup, &a.steps, &mut |x| {
                bar.inc(1);
                bar.set_message(format!("done: {x} steps/period"));
            })?
        }
        KindArg::Modes => {
            let m = rom.n_modes();
            let modes: Vec<usize> = if a.modes.is_empty() {
                let mut v: Vec<usize> = [5, 10, 20, 40, 60, 80, 100, 120, 160, 200]
                    .into_iter()
                    .filter(|&k| k < m && k > rom.meta.reference_mode)
                    .collect();
                v.push(m);
                v
            } else {
                a.modes.clone()
            };
            let spp = match a.modes_steps {
                Some(spp) => spp,
                None => stable_steps_per_period(&rom, setup.omega_ratio)?,
            };
            bar.set_length(modes.len() as u64);
            modes_study(&rom, &setup, &modes, spp, &mut |x| {
                bar.inc(1);
                bar.set_message(format!("done: {x} modes"));
            })?
        }
    };
    bar.finish_and_clear();
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "{} convergence, {} runs in {:.1} s (reference x = {}):",
        study.kind,
        study.runs.len(),
        wall,
        study.reference
    );
    for r in &study.runs {
        println!(
            "  x = {:>8}  dt = {:.3e} s  relative RMS error {:.3e}  RMS change {:.2e}  closed steps {}  solver failures {}",
            r.x, r.dt, r.error, r.rms_change, r.closed_steps, r.solver_failures
        );
    }
    #[derive(serde::Serialize)]
    struct Out<'a> {
        #[serde(flatten)]
        study: &'a ConvergenceStudy,
        wall_seconds: f64,
    }
    super::write_json(
        &a.json,
        &Out {
            study: &study,
            wall_seconds: wall,
        },
    )?;
    println!("results: {}", a.json.display());
    if let Some(dir) = &a.figures {
        let p = dir.join(format!("convergence_{}.png", study.kind));
        convergence_figure(&study, &p)?;
        println!("figure: {}", p.display());
    }
    Ok(())
}

fn convergence_figure(study: &ConvergenceStudy, out: &Path) -> anyhow::Result<()> {
    let kind = if study.kind == "dt" {
        ConvergenceKind::Dt
    } else {
        ConvergenceKind::Modes
    };
    let data = Convergence {
        kind,
        x: study.runs.iter().map(|r| r.x).collect(),
        error: study.runs.iter().map(|r| r.error).collect(),
        reference: Some(study.reference),
        signals: study
            .runs
            .iter()
            .map(|r| ConvergenceSignal {
                x: r.x,
                t: (0..r.u.len()).map(|k| k as f64 * r.dt).collect(),
                u: r.u.clone(),
            })
            .collect(),
    };
    report::convergence(&data, out, &FigureOptions::default())?;
    Ok(())
}
