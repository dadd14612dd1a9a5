//! `rigtwin demo`: the main job on the embedded default rig. It builds (or reuses from the
//! cache) the default ROM and the simulated rig's truth ROM, reports the model, runs the demo
//! plan (`rig-config/plans/demo.toml`, embedded) on the simulated rig under closed-loop
//! amplitude control — session log (MCAP), summary and figures from the recording — and the
//! same plan as the model's virtual stepped sine, with figures, for comparison.

use clap::Args;
use std::path::PathBuf;

use super::models::cached_rom;
use super::paths::Files;
use crate::rom::info::{RomInfo, RomOrigin};

/// The demo plan, embedded so that the demo runs from any folder.
const DEMO_PLAN: &str = include_str!("../../rig-config/plans/demo.toml");

/// `rigtwin demo`
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder for the demo's results.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Rebuild the ROM even if the cache holds one for this rig.
    #[arg(long)]
    pub rebuild: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

pub(crate) fn run(a: DemoArgs) -> anyhow::Result<()> {
    Files::new()
        .output("--out", &a.out.join("rom-info.json"), "the ROM summary")
        .output(
            "--out",
            &a.out.join("stepped-sine.json"),
            "the stepped sine",
        )
        .output_folder(
            "--out",
            &a.out.join("figures"),
            "the figures",
            &["png", "svg"],
        )
        .output("--out", &a.out.join("session.mcap"), "the session log")
        .output("--out", &a.out.join("session.json"), "the session summary")
        .output_folder(
            "--out",
            &a.out.join("session-figures"),
            "the session figures",
            super::report::FOLDER_FILES,
        )
        .ready()?;
    let cfg = crate::config::RigConfig::default_rig();
    let (rom, path, reused) = cached_rom(&cfg, a.rebuild, a.quiet)?;
    let info = RomInfo::new(&rom);
    println!(
        "{}",
        info.text(if reused {
            RomOrigin::Cache
        } else {
            RomOrigin::Built
        })
    );
    println!(
        "ROM {} {}",
        if reused {
            "reused from"
        } else {
            "built and cached in"
        },
        path.display()
    );
    let json = a.out.join("rom-info.json");
    super::write_json(&json, &info)?;
    println!("ROM summary: {}", json.display());

    let plan = crate::plan::Plan::from_str(DEMO_PLAN, "rig-config/plans/demo.toml (embedded)")?;
    println!(
        "virtual stepped sine: plan \"{}\", {} tests",
        plan.name.as_deref().unwrap_or("demo"),
        plan.tests.len()
    );
    super::simulate::run_plan_to_outputs(
        &rom,
        &path.display().to_string(),
        &plan,
        crate::sim::IntegratorParameters::default(),
        &super::simulate::PlanOutputs {
            jobs: None,
            from_rest: false,
            json: Some(&a.out.join("stepped-sine.json")),
            figures: Some(&a.out.join("figures")),
            quiet: a.quiet,
            model: &cfg.model,
        },
    )?;

    println!("stepped sine on the simulated rig (closed-loop base amplitude control):");
    let mcap = a.out.join("session.mcap");
    let o = super::run::run_session_on(
        &super::run::SessionArgs {
            cfg: &cfg,
            config_text: crate::config::DEFAULT_RIG_TOML,
            plan: &plan,
            out: &mcap,
            realtime: false,
            inject: &[],
            rebuild: false,
            quiet: a.quiet,
            foxglove: None,
            twin: true,
        },
        None,
    )?;
    super::run::print_session(&o);
    let json = a.out.join("session.json");
    super::write_json(&json, &o.summary)?;
    let figures = a.out.join("session-figures");
    let (written, _) = super::report::figures(&mcap, &figures)?;
    println!("session log: {}", mcap.display());
    println!("session summary: {}", json.display());
    println!("session figures ({}): {}", written.len(), figures.display());
    if let Some(e) = &o.log_error {
        anyhow::bail!("the session log could not be finished: {e}");
    }
    if o.summary.aborted {
        anyhow::bail!(
            "the session aborted: {}",
            o.summary.abort_reason.as_deref().unwrap_or("unknown")
        );
    }
    Ok(())
}
