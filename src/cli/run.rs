//! `rigtwin run`: a stepped-sine session on a rig backend (the simulated rig, or the hardware
//! over CAN and serial links), logged to MCAP, with a JSON summary and optionally served live to the Foxglove app (`--foxglove`);
//! `rigtwin replay`: the summary recomputed from a recording.

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::config::RigConfig;
use crate::control::{run_session, SessionProgress, SessionSetup, SessionSummary, Tee};
use crate::log::live::{LiveOptions, LiveStats, LiveView};
use crate::log::recorder::McapRecorder;
use crate::log::{Attachment, LogOptions, SessionLog};
use crate::plan::Plan;
use crate::rig::hw::{HwBackend, HwOptions};
use crate::rig::sim::{InjectedFault, SimRig};
use crate::rig::sim_backend::SimBackend;
use crate::rig::{LinkCounters, RigBackend};
use crate::rom::Rom;

/// Which rig to run on.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum BackendArg {
    /// The simulated rig (truth model + shaker + sensors + DAQ).
    Sim,
    /// The rig's electronics over CAN FD (--can) and serial links (--ldv, --amp), as
    /// firmware-interfaces/ documents; `rigtwin firmware-sim` stands in for them.
    Hw,
}

/// The session's backend: control code is generic, this picks one at run time.
#[derive(Debug)]
enum Backend {
    Sim(Box<SimBackend>),
    Hw(Box<HwBackend>),
}

impl RigBackend for Backend {
    fn layout(&self) -> &crate::rig::DaqLayout {
        match self {
            Backend::Sim(b) => b.layout(),
            Backend::Hw(b) => b.layout(),
        }
    }
    async fn start(&mut self) -> Result<(), crate::rig::RigError> {
        match self {
            Backend::Sim(b) => b.start().await,
            Backend::Hw(b) => b.start().await,
        }
    }
    async fn set_drive(
        &mut self,
        command: crate::rig::DriveCommand,
    ) -> Result<(), crate::rig::RigError> {
        match self {
            Backend::Sim(b) => b.set_drive(command).await,
            Backend::Hw(b) => b.set_drive(command).await,
        }
    }
    async fn next_block(&mut self) -> Result<Option<crate::rig::DaqBlock>, crate::rig::RigError> {
        match self {
            Backend::Sim(b) => b.next_block().await,
            Backend::Hw(b) => b.next_block().await,
        }
    }
    async fn begin_test(
        &mut self,
        test: &crate::plan::TestSpec,
    ) -> Result<(), crate::rig::RigError> {
        match self {
            Backend::Sim(b) => b.begin_test(test).await,
            Backend::Hw(b) => b.begin_test(test).await,
        }
    }
    fn status(&self) -> crate::rig::RigStatus {
        match self {
            Backend::Sim(b) => b.status(),
            Backend::Hw(b) => b.status(),
        }
    }
    async fn stop(&mut self) -> Result<(), crate::rig::RigError> {
        match self {
            Backend::Sim(b) => b.stop().await,
            Backend::Hw(b) => b.stop().await,
        }
    }
}

/// `rigtwin run`
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Rig description (TOML). Without it: the embedded default rig.
    pub config: Option<PathBuf>,
    /// Stepped-sine plan (TOML), as for `rigtwin simulate`.
    #[arg(long)]
    pub plan: PathBuf,
    /// Rig backend.
    #[arg(long, value_enum, default_value = "sim")]
    pub backend: BackendArg,
    /// The hardware links (with --backend hw).
    #[command(flatten)]
    pub hw: super::hw::HwArgs,
    /// Session log (MCAP).
    #[arg(long)]
    pub out: PathBuf,
    /// Session summary (JSON).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Pace the simulated rig to the wall clock (default: virtual time, as fast as it runs).
    #[arg(long)]
    pub realtime: bool,
    /// Serve the session live to the Foxglove app (Open connection > Foxglove WebSocket) on
    /// ADDR: PORT (binds 127.0.0.1 only), IP:PORT (0.0.0.0:PORT for every interface) or
    /// [IPv6]:PORT; port 0 picks a free port. Off by default. Topics as in the MCAP log, the
    /// DAQ decimated for plotting on /live/daq (min/max/mean per channel, 200 points per rig
    /// second; plot e.g. /live/daq.upper_tip.max). The server stops when the session ends.
    #[arg(long, value_name = "ADDR", value_parser = crate::log::live::parse_addr)]
    pub foxglove: Option<SocketAddr>,
    /// Run the twin beside the session: the rig description's own ROM driven by the measured
    /// base acceleration on its own thread (`[twin]` settings), compared with the measurement
    /// in every record window (`tests[].steps[].twin`; logged on /twin/steps and
    /// /twin/status). It never holds the session up: when it falls behind it skips blocks and
    /// says so.
    #[arg(long)]
    pub twin: bool,
    /// Inject a fault into the simulated rig, as JSON, e.g.
    /// '{"kind":"dead_channel","at_s":3.0,"channel":"upper_tip"}' (repeatable). Kinds:
    /// daq_stall, dead_channel, drive_saturation, clearance_change.
    #[arg(long)]
    pub inject: Vec<String>,
    /// Rebuild the ROMs even if cached.
    #[arg(long)]
    pub rebuild: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

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
    /// The twin's ROM file (with `--twin`; `[twin]` settings at their defaults).
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
}

/// The twin model of `rigtwin replay --twin`: ROM, `[twin]` settings and where it came from.
fn replay_twin_model(
    a: &ReplayArgs,
    rig_toml: Option<&str>,
) -> anyhow::Result<(Rom, crate::twin::TwinSpec, String)> {
    if let Some(path) = &a.rom {
        let rom =
            crate::rom::file::read(path).with_context(|| format!("--rom {}", path.display()))?;
        return Ok((
            rom,
            crate::twin::TwinSpec::default(),
            path.display().to_string(),
        ));
    }
    let (cfg, source) = match (&a.config, rig_toml) {
        (Some(path), _) => (RigConfig::from_path(path)?, path.display().to_string()),
        (None, Some(text)) => (
            RigConfig::from_str(text, "rig.toml (attached to the log)")?,
            "the rig description in the log".to_string(),
        ),
        (None, None) => bail!(
            "{}: the log holds no rig description (rig.toml attachment); name the twin's model \
             with --config or --rom",
            a.file.display()
        ),
    };
    let (rom, path, _) = super::demo::cached_rom(&cfg, a.rebuild, true)?;
    Ok((
        rom,
        cfg.twin.clone(),
        format!("{source} (ROM {})", path.display()),
    ))
}

/// The twin ROM (the model) and the truth ROM (the simulated rig's structure: more modes).
pub(crate) fn roms(
    cfg: &RigConfig,
    rebuild: bool,
    quiet: bool,
) -> anyhow::Result<(Rom, Rom, PathBuf)> {
    let (twin, twin_path, _) = super::demo::cached_rom(cfg, rebuild, quiet)?;
    let mut truth_cfg = cfg.clone();
    truth_cfg.reduction = crate::config::ReductionSpec {
        cutoff_ratio: Some(cfg.truth.cutoff_ratio),
        cutoff_hz: None,
        modes: None,
    };
    let (truth, _, _) = super::demo::cached_rom(&truth_cfg, rebuild, quiet)?;
    Ok((twin, truth, twin_path))
}

/// What a finished session left behind.
pub(crate) struct RunOutcome {
    pub summary: SessionSummary,
    pub wall_seconds: f64,
    pub messages: u64,
    pub overruns: u64,
    /// What the live view did (with `--foxglove`).
    pub live: Option<LiveStats>,
    /// What the twin did (with `--twin`).
    pub twin: Option<crate::twin::TwinOutcome>,
    /// The hardware links' counters (with `--backend hw`).
    pub link: Option<LinkCounters>,
}

/// A session on the simulated rig.
pub(crate) struct SimSession<'a> {
    /// The rig description.
    pub cfg: &'a RigConfig,
    /// Its text (stored in the log).
    pub config_text: &'a str,
    /// The plan.
    pub plan: &'a Plan,
    /// The session log.
    pub out: &'a Path,
    /// Pace to the wall clock.
    pub realtime: bool,
    /// Faults to inject.
    pub inject: &'a [InjectedFault],
    /// Rebuild the ROMs.
    pub rebuild: bool,
    /// No progress display.
    pub quiet: bool,
    /// Serve the session live to the Foxglove app on this address.
    pub foxglove: Option<SocketAddr>,
    /// Run the twin beside the session.
    pub twin: bool,
}

/// Starts the live view on `addr` and prints where to connect.
fn start_live_view(addr: SocketAddr) -> anyhow::Result<(crate::log::live::LiveRecorder, LiveView)> {
    let (recorder, view) = LiveView::start(addr, LiveOptions::default())
        .with_context(|| format!("--foxglove {addr}"))?;
    let bound = view.local_addr();
    if bound.ip().is_unspecified() {
        println!(
            "live view: open Foxglove, connect to ws://{}:{} (this machine) or \
             ws://HOST:{} (HOST: this machine's name or address, from another one)",
            if bound.is_ipv4() {
                "127.0.0.1"
            } else {
                "[::1]"
            },
            bound.port(),
            bound.port()
        );
    } else {
        println!("live view: open Foxglove, connect to {}", view.ws_url());
    }
    Ok((recorder, view))
}

/// Runs the plan on the simulated rig, logging to the session's file.
pub(crate) fn run_sim_session(session: &SimSession<'_>) -> anyhow::Result<RunOutcome> {
    run_session_on(session, None)
}

/// Runs the plan on the simulated rig, or on the hardware with `hw`, logging to the
/// session's file.
pub(crate) fn run_session_on(
    session: &SimSession<'_>,
    hw: Option<&HwOptions>,
) -> anyhow::Result<RunOutcome> {
    let SimSession {
        cfg,
        config_text,
        plan,
        out,
        realtime,
        inject,
        rebuild,
        quiet,
        foxglove,
        twin: with_twin,
    } = *session;
    // First, so that a port in use fails before the ROMs are built.
    let (live_recorder, live_view) = foxglove.map(start_live_view).transpose()?.unzip();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let l = cfg.rig.beam_length;
    let spec = cfg.sim_rig_spec();
    let (twin, truth, twin_path, mut backend) = match hw {
        None => {
            let (twin, truth, twin_path) = roms(cfg, rebuild, quiet)?;
            let rig = SimRig::new(&truth, &spec, cfg.contact.clearance).context("simulated rig")?;
            let mut backend = SimBackend::new(rig, l, realtime);
            for f in inject {
                backend.inject(f.clone());
            }
            (
                twin,
                Some(truth),
                twin_path,
                Backend::Sim(Box::new(backend)),
            )
        }
        Some(h) => {
            let (twin, twin_path, _) = super::demo::cached_rom(cfg, rebuild, quiet)?;
            // The rig description's channel map: every block header is checked against it.
            let layout = crate::rig::sim::daq::layout(&spec.daq);
            let backend = runtime
                .block_on(HwBackend::connect(layout, h.clone()))
                .context("connecting to the rig (--backend hw)")?;
            (twin, None, twin_path, Backend::Hw(Box::new(backend)))
        }
    };
    let setup = SessionSetup {
        plan: plan.clone(),
        control: cfg.control.clone(),
        safety: cfg.safety.clone(),
        omega_ref: twin.omega_ref(),
        beam_length: l,
    };
    let mut session_meta = BTreeMap::new();
    session_meta.insert(
        "backend".to_string(),
        if hw.is_some() { "hw" } else { "sim" }.to_string(),
    );
    if let Some(h) = hw {
        session_meta.insert("can".to_string(), format!("{:?}", h.can));
        session_meta.insert("ldv".to_string(), h.ldv.clone());
        session_meta.insert("amp".to_string(), h.amp.clone());
    }
    session_meta.insert("realtime".to_string(), realtime.to_string());
    session_meta.insert("plan".to_string(), plan.name.clone().unwrap_or_default());
    session_meta.insert("plan_source".to_string(), plan.source.clone());
    session_meta.insert(
        "omega_ref_rad_s".to_string(),
        format!("{:e}", twin.omega_ref()),
    );
    session_meta.insert("beam_length_m".to_string(), format!("{l:e}"));
    // The simulated rig's hidden physics (`[truth.variants]`, also in the rig.toml
    // attachment), parsed: `{}` when none is on.
    session_meta.insert("truth_variants".to_string(), spec.truth.variants.to_json());
    session_meta.insert(
        "started_unix_s".to_string(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs())
            .to_string(),
    );
    let mut rom_meta = BTreeMap::new();
    rom_meta.insert("path".to_string(), twin_path.display().to_string());
    rom_meta.insert("config_hash".to_string(), twin.meta.config_hash.clone());
    rom_meta.insert("modes".to_string(), twin.n_modes().to_string());
    rom_meta.insert("pairs".to_string(), twin.n_pairs().to_string());
    if let Some(truth) = &truth {
        rom_meta.insert(
            "truth_config_hash".to_string(),
            truth.meta.config_hash.clone(),
        );
        rom_meta.insert("truth_modes".to_string(), truth.n_modes().to_string());
    }
    let mut plan_text = String::new();
    if let Ok(t) = std::fs::read_to_string(&plan.source) {
        plan_text = t;
    }
    let mut attachments = vec![Attachment {
        name: "rig.toml".into(),
        media_type: "application/toml".into(),
        data: config_text.as_bytes().to_vec(),
    }];
    if !plan_text.is_empty() {
        attachments.push(Attachment {
            name: "plan.toml".into(),
            media_type: "application/toml".into(),
            data: plan_text.into_bytes(),
        });
    }
    let (handle, join) = SessionLog::create(
        out,
        LogOptions::default(),
        vec![("session".into(), session_meta), ("rom".into(), rom_meta)],
        attachments,
    )
    .with_context(|| format!("creating the session log {}", out.display()))?;
    let twin_recorder = if with_twin {
        let layout = backend.layout().clone();
        let engine = crate::twin::Twin::new(&twin, &cfg.twin, &layout, cfg.contact.clearance)
            .context("the twin")?;
        let (task, rx) = crate::twin::TwinTask::spawn(engine, &cfg.twin).context("the twin")?;
        let recorder =
            crate::twin::TwinRecorder::new(task, rx, l, layout.dt(), Some(handle.clone()))?;
        Some(match &live_recorder {
            Some(live) => recorder.with_live(live.clone()),
            None => recorder,
        })
    } else {
        None
    };
    let mut recorder = Tee(
        Tee(McapRecorder::new(handle)?, live_recorder),
        twin_recorder,
    );

    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] rig t = {prefix} s {wide_msg}")
            .expect("template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(150));
    let t0 = Instant::now();
    let summary = runtime.block_on(async {
        let shutdown = async {
            let _ = tokio::signal::ctrl_c().await;
        };
        let mut progress = |p: &SessionProgress| {
            bar.set_prefix(format!("{:.1}", p.time));
            bar.set_message(format!(
                "{} step {}/{} {:?} error {}",
                p.test.1,
                p.step.0 + 1,
                p.step.1,
                p.phase,
                p.error.map_or("-".into(), |e| format!("{e:+.4}"))
            ));
        };
        let s = run_session(&mut backend, &setup, &mut recorder, shutdown, &mut progress).await?;
        let status = backend.status();
        anyhow::Ok((s, status.overruns, status.link))
    })?;
    let (mut summary, overruns, link) = summary;
    bar.finish_and_clear();
    let twin_outcome = recorder.1.take().map(crate::twin::TwinRecorder::finish);
    if let Some(t) = &twin_outcome {
        summary.attach_twin(t.comparisons.iter().cloned());
    }
    let messages = recorder.0 .0.messages();
    drop(recorder);
    join.close().context("closing the session log")?;
    let wall_seconds = t0.elapsed().as_secs_f64();
    let live = live_view.map(LiveView::close);
    Ok(RunOutcome {
        summary,
        wall_seconds,
        messages,
        overruns,
        live,
        twin: twin_outcome,
        link,
    })
}

/// Prints a finished session: speed, then the steps.
pub(crate) fn print_session(o: &RunOutcome) {
    println!(
        "session: {} blocks, {:.1} s of rig time in {:.1} s wall ({:.2}x real time), {} log messages, {} overruns",
        o.summary.blocks,
        o.summary.rig_seconds,
        o.wall_seconds,
        o.summary.rig_seconds / o.wall_seconds,
        o.messages,
        o.overruns
    );
    if let Some(l) = &o.live {
        println!(
            "live view: stopped; {} messages sent to clients ({} on /live/daq), {} decimated DAQ points, {} records dropped",
            l.sent_total(),
            l.sent.get(crate::log::live::TOPIC_LIVE_DAQ).copied().unwrap_or(0),
            l.points,
            l.dropped_records
        );
    }
    if let Some(t) = &o.twin {
        let s = &t.status;
        println!(
            "twin: {} of {} blocks ({} skipped while behind, {} gaps), {:.1}x real time, {} contact-solver failures, {} of {} steps compared",
            s.blocks_processed,
            s.blocks_offered,
            s.blocks_skipped,
            s.gaps,
            s.realtime_factor,
            s.solver_failures,
            t.comparisons.iter().filter(|c| c.is_some()).count(),
            t.comparisons.len()
        );
        for e in &t.errors {
            println!("twin error: {e}");
        }
    }
    if let Some(c) = &o.link {
        println!(
            "links: {} frames received, {} sent, {} malformed, {} sequence gaps, {} reordered, \
             {} duplicates, {} CRC errors, {} heartbeat misses; serial: {} timeouts, {} \
             checksum errors, {} garbage{}",
            c.frames_received,
            c.frames_sent,
            c.malformed,
            c.sequence_gaps,
            c.reordered,
            c.duplicates,
            c.crc_errors,
            c.heartbeat_misses,
            c.serial_timeouts,
            c.serial_checksum_errors,
            c.serial_garbage,
            c.last_error
                .as_ref()
                .map_or(String::new(), |e| format!("; last problem: {e}"))
        );
    }
    print_summary(&o.summary);
}

fn print_summary(s: &SessionSummary) {
    for t in &s.tests {
        println!("  test {} ({} steps):", t.name, t.steps.len());
        for st in &t.steps {
            println!(
                "    Omega/omega_2 {:.4}  rms upper {:7.2} lower {:7.2}  contact {:.3}  impacts/period {:.2}  base {:.4e} m (target {:.4e}, {:+.2} %)  drive {:.4} V  settle {:.2} s{}",
                st.omega_ratio,
                st.metrics.rms_upper,
                st.metrics.rms_lower,
                st.metrics.contact_fraction,
                st.metrics.impacts_per_period,
                st.base_amp_measured,
                st.base_amp_target,
                100.0 * (st.base_amp_measured / st.base_amp_target - 1.0),
                st.drive_amplitude,
                st.settle_seconds,
                if st.settled { "" } else { " (not settled)" }
            );
            if let Some(w) = &st.twin {
                println!(
                    "        twin     rms upper {:7.2} ({:+.1} %) lower {:7.2} ({:+.1} %)  contact {:.3} ({:+.3})  impacts/period {:.2}  spectrum {}",
                    w.metrics.rms_upper,
                    100.0 * w.rms_error_upper,
                    w.metrics.rms_lower,
                    100.0 * w.rms_error_lower,
                    w.metrics.contact_fraction,
                    w.contact_fraction_error,
                    w.metrics.impacts_per_period,
                    w.spectrum_distance_db
                        .map_or("-".to_string(), |d| format!("{d:.1} dB")),
                );
            }
        }
    }
    if let Some(r) = &s.abort_reason {
        println!("ABORTED: {r}");
    }
}

pub(crate) fn run(a: RunArgs) -> anyhow::Result<()> {
    let hw = match a.backend {
        BackendArg::Sim => {
            if a.hw.can.is_some()
                || a.hw.ldv.is_some()
                || a.hw.amp.is_some()
                || a.hw.can_log.is_some()
            {
                bail!("--can, --ldv, --amp and --can-log are for --backend hw");
            }
            None
        }
        BackendArg::Hw => {
            if !a.inject.is_empty() || a.realtime {
                bail!(
                    "--inject and --realtime are for --backend sim (the hardware runs in real \
                     time; inject faults into `rigtwin firmware-sim`)"
                );
            }
            Some((a.hw.can.clone(), a.hw.ldv.clone(), a.hw.amp.clone()))
        }
    };
    let (cfg, text) = match &a.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the rig description {}", p.display()))?;
            (RigConfig::from_str(&text, &p.display().to_string())?, text)
        }
        None => (
            RigConfig::default_rig(),
            crate::config::DEFAULT_RIG_TOML.to_string(),
        ),
    };
    let plan = Plan::from_path(&a.plan)?;
    if cfg.truth.variants.any() {
        println!(
            "simulated rig: hidden physics on ([truth.variants]): {}",
            cfg.truth.variants.to_json()
        );
    }
    let inject: Vec<InjectedFault> = a
        .inject
        .iter()
        .map(|s| {
            serde_json::from_str(s)
                .with_context(|| format!("--inject {s}: not a fault description"))
        })
        .collect::<anyhow::Result<_>>()?;
    let hw = match hw {
        None => None,
        Some((Some(can), Some(ldv), Some(amp))) => {
            let mut o = HwOptions::new(can, ldv, amp, cfg.shaker.amplifier_gain);
            o.can_log = a.hw.can_log.clone();
            o.vibrometer_filter_hz =
                (cfg.daq.anti_alias_cutoff * cfg.daq.sample_rate).round() as u32;
            Some(o)
        }
        Some(_) => bail!("--backend hw needs --can, --ldv and --amp"),
    };
    let o = run_session_on(
        &SimSession {
            cfg: &cfg,
            config_text: &text,
            plan: &plan,
            out: &a.out,
            realtime: a.realtime,
            inject: &inject,
            rebuild: a.rebuild,
            quiet: a.quiet,
            foxglove: a.foxglove,
            twin: a.twin,
        },
        hw.as_ref(),
    )?;
    print_session(&o);
    println!("log: {}", a.out.display());
    if let Some(j) = &a.json {
        super::write_json(j, &o.summary)?;
        println!("summary: {}", j.display());
    }
    if o.summary.aborted {
        bail!(
            "session aborted: {}",
            o.summary.abort_reason.as_deref().unwrap_or("unknown")
        );
    }
    Ok(())
}

pub(crate) fn replay(a: ReplayArgs) -> anyhow::Result<()> {
    let r = crate::log::replay::replay(&a.file)?;
    if !r.complete {
        println!(
            "note: the log was not closed ({}); replaying what it holds",
            r.note.as_deref().unwrap_or("truncated")
        );
    }
    let same = r.logged_steps.len() == r.summary.tests.iter().map(|t| t.steps.len()).sum::<usize>()
        && r.logged_steps
            .iter()
            .zip(r.summary.tests.iter().flat_map(|t| t.steps.iter()))
            .all(|(a, b)| &a.summary == b);
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
        let (rom, spec, source) = replay_twin_model(&a, r.rig_toml.as_deref())?;
        let mut copy = match &a.out {
            Some(out) => {
                let session = crate::log::read_session(&a.file)?;
                Some(
                    crate::twin::TwinLogCopy::create(
                        out,
                        &session,
                        &source,
                        r.recording.layout.dt(),
                    )
                    .with_context(|| format!("--out {}", out.display()))?,
                )
            }
            None => None,
        };
        let sink: &mut dyn crate::twin::TwinSink = match &mut copy {
            Some(c) => c,
            None => &mut (),
        };
        let stats = crate::twin::replay_twin(
            &r.recording,
            &mut summary,
            &rom,
            &spec,
            rom.meta.beam_length,
            sink,
        )
        .with_context(|| format!("twin replay of {}", a.file.display()))?;
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
