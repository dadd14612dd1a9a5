//! `rigtwin run`: a stepped-sine session on a rig backend (the simulated rig, or the hardware
//! over CAN and serial links), logged to MCAP, with a JSON summary and optionally served live to
//! the Foxglove app (`--foxglove`). The session itself is [`crate::session`]'s; this builds the
//! chosen backend and prints.

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use crate::config::RigConfig;
use crate::plan::Plan;
use crate::rig::hw::{HwBackend, HwOptions};
use crate::rig::sim::{InjectedFault, SimBackend, SimRig, SimRigSpec};
use crate::rom::Rom;
use crate::session::live::{LiveOptions, LiveRecorder, LiveView};
use crate::session::topics::TOPIC_LIVE_DAQ;
use crate::session::{
    BackendMetadata, RunOutcome, SessionProgress, SessionRequest, SessionSummary,
};

use super::models;
use super::paths::Files;

/// Which rig to run on.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum BackendArg {
    /// The simulated rig (truth model + shaker + sensors + DAQ).
    Sim,
    /// The rig's electronics over CAN FD (--can) and serial links (--ldv, --amp), as
    /// firmware-interfaces/ documents; `rigtwin firmware-sim` stands in for them.
    Hw,
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
    #[arg(long, value_name = "ADDR", value_parser = crate::session::live::parse_addr)]
    pub foxglove: Option<SocketAddr>,
    /// Run the twin beside the session: the rig description's own ROM driven by the measured
    /// base acceleration on its own thread (`[twin]` settings), compared with the measurement
    /// in every record window (`tests[].steps[].twin`; logged on /twin/steps and
    /// /twin/status). It never holds the session up: when it falls behind it skips blocks and
    /// says so.
    #[arg(long)]
    pub twin: bool,
    /// Inject a fault into the simulated rig, as JSON, e.g.
    /// '{"kind":"dead_channel","at_s":3.0,"channel":"upper_tip"}' (repeatable). Kinds and
    /// their fields (at_s: rig time, s): daq_stall {at_s}, dead_channel {at_s, channel: a
    /// layout channel name}, drive_saturation {at_s, limit_v: the amplifier's new output
    /// limit, V}, clearance_change {at_s, clearance_m: the new clearance, m, within the bounds
    /// of a plan's clearance: -1e-4 l to 0.1 l}.
    #[arg(long)]
    pub inject: Vec<String>,
    /// Rebuild the ROMs even if cached.
    #[arg(long)]
    pub rebuild: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

/// The faults `--inject` takes, with their fields, for error messages.
pub(crate) const INJECT_KINDS: &str = "kinds: daq_stall {at_s}, dead_channel {at_s, channel}, \
     drive_saturation {at_s, limit_v}, clearance_change {at_s, clearance_m}; at_s in rig \
     seconds, limit_v in V, clearance_m in m (-1e-4 l to 0.1 l)";

/// One `--inject` value: a fault of the simulated rig (beams of `beam_length_m`), parsed and
/// checked ([`InjectedFault::check`]: a new clearance obeys the plans' bounds).
pub(crate) fn parse_inject(s: &str, beam_length_m: f64) -> anyhow::Result<InjectedFault> {
    let f: InjectedFault = serde_json::from_str(s)
        .with_context(|| format!("--inject {s}: not a fault description ({INJECT_KINDS})"))?;
    f.check(beam_length_m)
        .map_err(|e| anyhow::anyhow!("--inject {s}: {e}"))?;
    Ok(f)
}

/// A session to run: the rig description, the plan and what to run it with.
pub(crate) struct SessionArgs<'a> {
    /// The rig description.
    pub cfg: &'a RigConfig,
    /// Its text (stored in the log).
    pub config_text: &'a str,
    /// The plan.
    pub plan: &'a Plan,
    /// The session log.
    pub out: &'a Path,
    /// Pace the simulated rig to the wall clock.
    pub realtime: bool,
    /// Faults to inject into the simulated rig.
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
fn start_live_view(addr: SocketAddr) -> anyhow::Result<(LiveRecorder, LiveView)> {
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
    // The sources' copy when this binary was built from them (a clone), else its name there.
    let layout = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(crate::session::live::FOXGLOVE_LAYOUT);
    let layout = if layout.is_file() {
        layout.display().to_string()
    } else {
        format!(
            "{} (in the rigtwin sources)",
            crate::session::live::FOXGLOVE_LAYOUT
        )
    };
    println!(
        "live view: a ready layout (tips measured and twin, control, contact, twin status, \
         step tables): import {layout} in Foxglove (Layouts > Import from file)"
    );
    Ok((recorder, view))
}

/// The session's progress line on the terminal (hidden with `quiet`).
fn progress_bar(quiet: bool) -> ProgressBar {
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
    bar
}

/// Runs the plan on the simulated rig, or on the hardware with `hw`, logging to the
/// session's file.
pub(crate) fn run_session_on(
    session: &SessionArgs<'_>,
    hw: Option<&HwOptions>,
) -> anyhow::Result<RunOutcome> {
    let cfg = session.cfg;
    // First, so that a port in use fails before the ROMs are built.
    let live = session.foxglove.map(start_live_view).transpose()?;
    let runtime = crate::session::runtime()?;
    let (model, model_path, _) = models::cached_rom(cfg, session.rebuild, session.quiet)?;
    super::check_extensions(&model, &cfg.model, &cfg.source)?;
    let twin_model = if session.twin {
        println!(
            "twin model extensions: {}",
            super::extensions_line(&cfg.model)
        );
        let clearances: Vec<f64> = session.plan.tests.iter().map(|t| t.clearance).collect();
        models::held_contact_twin_rom(cfg, &clearances, session.rebuild, session.quiet)?
    } else {
        None
    };
    let mut metadata = BackendMetadata::default();
    metadata
        .session
        .insert("realtime".to_string(), session.realtime.to_string());
    let bar = progress_bar(session.quiet);
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
    let request = |metadata| SessionRequest {
        cfg,
        config_text: session.config_text,
        plan: session.plan,
        out: session.out,
        model: &model,
        model_path: &model_path,
        twin_model: twin_model.as_ref().map(|(rom, path)| (rom, path.as_path())),
        twin: session.twin,
        live,
        backend_metadata: metadata,
    };
    let outcome = match hw {
        None => {
            let truth = models::truth_rom(cfg, session.rebuild, session.quiet)?;
            let backend = sim_backend(cfg, &truth, session)?;
            metadata
                .session
                .insert("backend".to_string(), "sim".to_string());
            metadata.session.extend(sim_metadata(cfg));
            metadata.rom.insert(
                "truth_config_hash".to_string(),
                truth.meta.config_hash.clone(),
            );
            metadata
                .rom
                .insert("truth_modes".to_string(), truth.n_modes().to_string());
            crate::session::run::run(&runtime, backend, request(metadata), &mut progress)
        }
        Some(h) => {
            // The rig description's channel map: every block header is checked against it.
            let layout = crate::rig::channels::layout(&cfg.daq);
            let backend = runtime
                .block_on(HwBackend::connect(layout, h.clone()))
                .context("connecting to the rig (--backend hw)")?;
            metadata
                .session
                .insert("backend".to_string(), "hw".to_string());
            metadata
                .session
                .insert("can".to_string(), format!("{:?}", h.can));
            metadata.session.insert("ldv".to_string(), h.ldv.clone());
            metadata.session.insert("amp".to_string(), h.amp.clone());
            crate::session::run::run(&runtime, backend, request(metadata), &mut progress)
        }
    };
    bar.finish_and_clear();
    Ok(outcome?)
}

/// The simulated rig on its truth ROM, with the faults to inject.
fn sim_backend(
    cfg: &RigConfig,
    truth: &Rom,
    session: &SessionArgs<'_>,
) -> anyhow::Result<SimBackend> {
    let rig = SimRig::new(truth, &SimRigSpec::from_config(cfg), cfg.contact.clearance)
        .context("simulated rig")?;
    let mut backend = SimBackend::new(rig, cfg.rig.beam_length, session.realtime);
    for f in session.inject {
        backend.inject(f.clone()).context("--inject")?;
    }
    Ok(backend)
}

/// The simulated rig's entries of the `session` metadata record: its hidden physics
/// (`[truth.variants]`, also in the rig.toml attachment), parsed: `{}` when none is on.
fn sim_metadata(cfg: &RigConfig) -> BTreeMap<String, String> {
    BTreeMap::from([("truth_variants".to_string(), cfg.truth.variants.to_json())])
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
            l.sent.get(TOPIC_LIVE_DAQ).copied().unwrap_or(0),
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

pub(crate) fn print_summary(s: &SessionSummary) {
    for t in &s.tests {
        println!("  test {} ({} steps):", t.name, t.steps.len());
        for step in &t.steps {
            let st = &step.measured;
            println!(
                "    Omega/omega_2 {:.4}  rms upper {:7.2} lower {:7.2}  contact {:.3}  impacts/period {:.2}  base {:.4e} m (target {:.4e}, {:+.2} %)  drive {:.4} V  settle {:.2} s{}{}",
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
                if st.settled { "" } else { " (not settled)" },
                if st.base_amp_off_tolerance {
                    format!(
                        "  BASE OFF TOLERANCE after {} record windows",
                        st.record_attempt
                    )
                } else {
                    String::new()
                }
            );
            if let Some(w) = &step.twin {
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
    let off: Vec<String> = s
        .tests
        .iter()
        .flat_map(|t| {
            t.steps
                .iter()
                .filter(|step| step.measured.base_amp_off_tolerance)
                .map(move |step| {
                    format!(
                        "{} at {:.4} ({:+.2} %)",
                        t.name,
                        step.measured.omega_ratio,
                        100.0 * step.measured.base_amp_error()
                    )
                })
        })
        .collect();
    if !off.is_empty() {
        println!(
            "BASE AMPLITUDE OFF TOLERANCE: {} step(s) kept a record window whose base amplitude \
             misses [control] record_tolerance after the last window allowed: {}",
            off.len(),
            off.join(", ")
        );
    }
    if let Some(r) = &s.abort_reason {
        println!("ABORTED: {r}");
    }
    if let Some(m) = &s.missing {
        println!("INCOMPLETE: {}", m.description);
        for f in &m.file {
            println!("  file: {f}");
        }
    }
}

/// The files `run` reads and writes (checked before anything starts).
fn files(a: &RunArgs) -> Files {
    let mut files = Files::new()
        .input_opt("CONFIG", a.config.as_deref(), "the rig description")
        .input("--plan", &a.plan, "the plan")
        .output("--out", &a.out, "the session log")
        .output_opt("--json", a.json.as_deref(), "the session summary");
    for (flag, tty) in [("--ldv", &a.hw.ldv), ("--amp", &a.hw.amp)] {
        if let Some(t) = tty {
            files = files.input(flag, Path::new(t), "a serial port");
        }
    }
    if let Some(log) = &a.hw.can_log {
        let mut decoded = log.clone().into_os_string();
        decoded.push(".decoded.jsonl");
        files = files.output("--can-log", log, "the CAN log").output(
            "--can-log",
            Path::new(&decoded),
            "the decoded CAN log",
        );
    }
    files
}

/// What `run` says of a plan that sets `steps_per_period`.
const STEPS_PER_PERIOD_NOTE: &str = "note: the plan's steps_per_period is not used by `run`: it \
     is the time step of `rigtwin simulate`; the rig samples at [daq] sample_rate and the twin \
     steps [twin] steps_per_sample times per sample";

/// Whether the plan file sets `steps_per_period` (in `[defaults]` or in a test).
fn sets_steps_per_period(plan: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(plan) else {
        return false;
    };
    let Ok(value) = text.parse::<toml::Table>() else {
        return false;
    };
    let has = |t: Option<&toml::Value>| {
        t.and_then(toml::Value::as_table)
            .is_some_and(|t| t.contains_key("steps_per_period"))
    };
    has(value.get("defaults"))
        || value
            .get("test")
            .and_then(toml::Value::as_array)
            .is_some_and(|tests| tests.iter().any(|t| has(Some(t))))
}

/// What a session log that could not be finished (a full disk) holds, in rig time and steps.
fn what_the_log_kept(out: &Path) -> String {
    match crate::session::replay::replay(out) {
        Ok(r) => format!(
            "the log keeps {} DAQ blocks ({:.2} s of rig time) and {} finished steps, up to its \
             last flush; `rigtwin replay {}` reads them",
            r.summary.blocks,
            r.summary.rig_seconds,
            r.summary.steps().count(),
            out.display()
        ),
        Err(e) => format!("the log keeps nothing that can be replayed: {e}"),
    }
}

/// Removes what a `run` killed before its session started left of `--out` and `--json`: their
/// staged files (`NAME.partial-PID-N`) of processes that ended, and says so.
fn remove_stale_partials(a: &RunArgs) {
    for dest in std::iter::once(&a.out).chain(a.json.as_ref()) {
        for p in crate::log::stale_partials(dest) {
            match std::fs::remove_file(&p) {
                Ok(()) => println!(
                    "removed {}: a staged file of {} left by a run killed before it finished \
                     it (a staged session log holds no samples: the log takes its name when the \
                     session starts)",
                    p.display(),
                    dest.display()
                ),
                Err(e) => println!(
                    "note: {} is a staged file of {} left by a run that was killed; it could \
                     not be removed: {e}",
                    p.display(),
                    dest.display()
                ),
            }
        }
    }
}

pub(crate) fn run(a: RunArgs) -> anyhow::Result<()> {
    files(&a).ready()?;
    remove_stale_partials(&a);
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
    let (cfg, text) = models::load_config_text(a.config.as_deref())?;
    let plan = Plan::from_path(&a.plan)?;
    if sets_steps_per_period(&a.plan) {
        println!("{STEPS_PER_PERIOD_NOTE}");
    }
    if cfg.truth.variants.any() {
        println!(
            "simulated rig: hidden physics on ([truth.variants]): {}",
            cfg.truth.variants.to_json()
        );
    }
    let inject: Vec<InjectedFault> = a
        .inject
        .iter()
        .map(|s| parse_inject(s, cfg.rig.beam_length))
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
        &SessionArgs {
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
    if let Some(e) = &o.log_error {
        println!("log not finished: {e}");
        println!("{}", what_the_log_kept(&a.out));
    }
    if let Some(j) = &a.json {
        super::write_json(j, &o.summary)?;
        println!("summary: {}", j.display());
    }
    if let Some(e) = &o.log_error {
        bail!("the session log could not be finished: {e}");
    }
    if o.summary.aborted {
        bail!(
            "session aborted: {}",
            o.summary.abort_reason.as_deref().unwrap_or("unknown")
        );
    }
    Ok(())
}
