//! Command-line interface of the `rigtwin` binary (clap). `main.rs` only calls [`main`].
//!
//! Every command that produces results can write them as JSON (`--json PATH`) so scripts and
//! tests never parse the human-readable text.

mod demo;
mod diagnose;
mod fe;
mod firmware_sim;
mod hw;
mod models;
mod paths;
mod progress;
mod replay;
mod report;
mod rom;
mod run;
mod simulate;

use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// rigtwin: reduced-order model, stepped-sine controller and digital twin of a vibro-impact rig.
#[derive(Parser, Debug)]
#[command(name = "rigtwin", version, about, long_about = None)]
pub struct Cli {
    /// Log filter (tracing EnvFilter syntax), e.g. "info" or "rigtwin=debug".
    #[arg(long, global = true, default_value = "warn")]
    pub log: String,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// Top-level commands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// The main job on the embedded default rig: build (or reuse) the default ROM, report it and
    /// run a short virtual stepped sine through the impact band with figures.
    Demo(demo::DemoArgs),
    /// Reduced-order models: build and inspect.
    #[command(subcommand)]
    Rom(rom::RomCommand),
    /// The FE parent model: export to CalculiX.
    #[command(subcommand)]
    Fe(fe::FeCommand),
    /// Virtual stepped sine of a test plan on the ROM, or a convergence study.
    Simulate(simulate::SimulateArgs),
    /// A stepped-sine session on a rig (the simulated rig: --backend sim; the rig's
    /// electronics over CAN and serial links: --backend hw), logged to MCAP.
    Run(run::RunArgs),
    /// The rig's electronics, simulated: the other end of --backend hw's CAN and serial links.
    FirmwareSim(firmware_sim::FirmwareSimArgs),
    /// Recompute a recorded session's summary from its raw DAQ blocks.
    Replay(replay::ReplayArgs),
    /// The paper-style figures of a recorded session.
    Report(report::ReportArgs),
    /// Where a recorded session and its model differ, the physics the model left out, fitted
    /// and validated on tests it was not fitted on.
    Diagnose(diagnose::DiagnoseArgs),
}

/// A command whose output goes into a closed pipe (`rigtwin rom info FILE | head`) ends
/// quietly, as Unix tools do, instead of panicking in `println!`. Not for `run` and `demo`:
/// a session must ramp its drive down and close its log whatever happens to stdout (they
/// print after the log is closed).
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: restores the default disposition of SIGPIPE before any thread starts; no
    // handler is installed.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Entry point of the binary.
pub fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    if !matches!(
        cli.command,
        Command::Run(_) | Command::Demo(_) | Command::FirmwareSim(_)
    ) {
        default_sigpipe();
    }
    let filter = match log_filter(&cli.log) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    // Colours only for a terminal: a log redirected to a file or a pipe stays plain text.
    use std::io::IsTerminal;
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Rom(c) => rom::run(c),
        Command::Fe(c) => fe::run(c),
        Command::Simulate(a) => simulate::run(a),
        Command::Run(a) => run::run(a),
        Command::FirmwareSim(a) => firmware_sim::run(a),
        Command::Replay(a) => replay::run(a),
        Command::Report(a) => report::run(a),
        Command::Diagnose(a) => diagnose::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The `--log` filter, or what is wrong with it (a malformed filter is an error, not silently
/// replaced by the default).
fn log_filter(text: &str) -> Result<tracing_subscriber::EnvFilter, String> {
    tracing_subscriber::EnvFilter::builder()
        .parse(text)
        .map_err(|e| {
            format!(
                "--log {text:?}: not a log filter ({e}); expected tracing's EnvFilter syntax, \
                 e.g. \"info\", \"rigtwin=debug\" or \"warn,rigtwin::session=info\""
            )
        })
}

/// An error and its causes, `: `-separated, leaving out a cause whose text the message already
/// holds (many errors quote their cause), so that nothing is said twice.
fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let s = cause.to_string();
        if text.contains(&s) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&s);
    }
    text
}

/// Writes a value as pretty JSON to `path` (creating parent folders), through a temporary file
/// renamed into place: an existing file is replaced whole or not at all.
pub(crate) fn write_json<T: serde::Serialize>(
    path: &std::path::Path,
    value: &T,
) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(value)?;
    crate::log::write_atomically(path, (text + "\n").as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// The cache folder for built ROMs: `$RIGTWIN_CACHE`, else `$XDG_CACHE_HOME/rigtwin`, else
/// `~/.cache/rigtwin`, else `./.rigtwin-cache`.
pub(crate) fn cache_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("RIGTWIN_CACHE") {
        return PathBuf::from(d);
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return PathBuf::from(d).join("rigtwin");
    }
    if let Some(h) = std::env::var_os("HOME") {
        return PathBuf::from(h).join(".cache").join("rigtwin");
    }
    PathBuf::from(".rigtwin-cache")
}

/// Checks the `[model]` extensions `model` of the rig description `source` against the ROM they
/// act on (mode labels, the beams' first bending modes and tip outputs), before anything runs:
/// the error names the file and the key.
pub(crate) fn check_extensions(
    rom: &crate::rom::Rom,
    model: &crate::config::PhysicsSpec,
    source: &str,
) -> anyhow::Result<()> {
    let prepared = crate::sim::effects::prepare(rom, model, "model")
        .map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    crate::sim::effects::Effects::new(&prepared, model, "model", rom.clearance)
        .map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    Ok(())
}

/// One line naming the `[model]` extensions that are on, with their parameters (`none` when
/// none is), for the console of every command that runs the model.
pub(crate) fn extensions_line(model: &crate::config::PhysicsSpec) -> String {
    if model.any() {
        format!("{} ({})", model.effects().join(", "), model.to_json())
    } else {
        "none".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_malformed_log_filter_is_an_error() {
        for good in [
            "warn",
            "info",
            "rigtwin=debug",
            "warn,rigtwin::session=info",
            "off",
        ] {
            assert!(log_filter(good).is_ok(), "{good}");
        }
        for bad in ["rigtwin=[[", "rigtwin=loud", "=debug"] {
            let e = log_filter(bad).unwrap_err();
            assert!(e.contains("--log") && e.contains("EnvFilter"), "{bad}: {e}");
        }
    }
}
