//! The composition root of a live session (`rigtwin run`, `rigtwin demo`): a rig backend (any
//! [`RigBackend`]: the caller builds the simulated rig or connects to the hardware), the
//! stepped-sine procedure ([`super::runner::run_session`]), the recorders teed together — the
//! MCAP session log, the live view (`--foxglove`) and the live twin (`--twin`) — and what the
//! session leaves behind ([`RunOutcome`]). The session never knows which backend it runs on:
//! backend-specific facts for the log come in as metadata from the caller.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use crate::config::RigConfig;
use crate::control::{Procedure, SessionSetup};
use crate::log::{Attachment, LogError, LogOptions, MetadataRecord, SessionLog};
use crate::plan::Plan;
use crate::rig::{LinkCounters, RigBackend};
use crate::rom::Rom;
use crate::twin::{ClearanceSchedule, Twin, TwinError, TwinModel, TwinTask, TwinWindows};

use super::live::{LiveRecorder, LiveStats, LiveView};
use super::mcap::McapRecorder;
use super::recorder::Tee;
use super::runner::{run_session, SessionError, SessionProgress};
use super::summary::SessionSummary;
use super::topics::{PLAN_ATTACHMENT, RIG_ATTACHMENT, ROM_METADATA, SESSION_METADATA};
use super::twin::{TwinOutcome, TwinRecorder};

/// Errors of a live session that prevent it from running or from closing its log (an abort
/// during the session is not an error: it is in the summary).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The async runtime could not start.
    #[error("starting the async runtime: {0}")]
    Runtime(#[source] std::io::Error),
    /// The handlers of SIGINT and SIGTERM could not be installed.
    #[error("installing the SIGINT and SIGTERM handlers: {0}")]
    Signal(#[source] std::io::Error),
    /// The session log could not be created (the log error names the file).
    #[error("{0}")]
    LogCreate(#[source] LogError),
    /// The session log could not be finished (the log error names the file).
    #[error("{0} (while closing the log)")]
    LogClose(#[source] LogError),
    /// The live twin could not start.
    #[error("the twin: {0}")]
    Twin(#[from] TwinError),
    /// The twin's log channels could not be registered.
    #[error("the twin: {0}")]
    TwinLog(#[source] LogError),
    /// The session could not start.
    #[error(transparent)]
    Session(#[from] SessionError),
}

/// What a live session runs with, besides its backend.
pub struct SessionRequest<'a> {
    /// The rig description: `[control]`, `[safety]`, `[twin]`, the beam length.
    pub cfg: &'a RigConfig,
    /// Its text (attached to the log as `rig.toml`).
    pub config_text: &'a str,
    /// The plan.
    pub plan: &'a Plan,
    /// The session log (MCAP) to write.
    pub out: &'a Path,
    /// The model: the rig description's ROM (omega_2 of the plan's ratios; the live twin).
    pub model: &'a Rom,
    /// Where the model's ROM file is (for the log's metadata).
    pub model_path: &'a Path,
    /// The live twin's own ROM and its file where it is not the model's: a coarser contact
    /// patch for a session that holds the probes in contact
    /// ([`crate::config::RigConfig::held_contact_twin`]).
    pub twin_model: Option<(&'a Rom, &'a Path)>,
    /// Run the live twin beside the session.
    pub twin: bool,
    /// The live view, started by the caller (so that a port in use fails before anything
    /// else starts).
    pub live: Option<(LiveRecorder, LiveView)>,
    /// What the backend adds to the log's metadata records: `session` (the backend's name
    /// and settings) and `rom` (e.g. the simulated rig's own ROM).
    pub backend_metadata: BackendMetadata,
}

/// Backend-specific entries of the session log's metadata records.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BackendMetadata {
    /// Entries of the `session` record (at least `backend`).
    pub session: BTreeMap<String, String>,
    /// Entries of the `rom` record.
    pub rom: BTreeMap<String, String>,
}

/// What a finished session left behind.
#[derive(Debug)]
pub struct RunOutcome {
    /// The session summary (with the live twin's comparisons).
    pub summary: SessionSummary,
    /// Wall-clock time of the session, s.
    pub wall_seconds: f64,
    /// Messages queued to the session log by the session's recorder.
    pub messages: u64,
    /// Pacing overruns of the backend.
    pub overruns: u64,
    /// What the live view did (with a live view).
    pub live: Option<LiveStats>,
    /// What the twin did (with the twin).
    pub twin: Option<TwinOutcome>,
    /// The hardware links' counters (a hardware backend).
    pub link: Option<LinkCounters>,
    /// Why the session log could not be finished (e.g. a full disk): it then holds what was
    /// flushed before the failure, without its summary section.
    pub log_error: Option<String>,
}

/// The async runtime a session runs on (two worker threads: the session loop and the
/// backend's tasks).
pub fn runtime() -> Result<tokio::runtime::Runtime, RunError> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(RunError::Runtime)
}

/// The session log's metadata records and attachments.
fn log_records(r: &SessionRequest<'_>) -> (Vec<MetadataRecord>, Vec<Attachment>) {
    let (plan, model) = (r.plan, r.model);
    let mut session_meta = r.backend_metadata.session.clone();
    session_meta.insert("plan".to_string(), plan.name.clone().unwrap_or_default());
    session_meta.insert("plan_source".to_string(), plan.source.clone());
    // The model's declared extensions (`[model]`, also in the rig.toml attachment), parsed.
    session_meta.insert("model_extensions".to_string(), r.cfg.model.to_json());
    session_meta.insert(
        "omega_ref_rad_s".to_string(),
        format!("{:e}", model.omega_ref()),
    );
    session_meta.insert(
        "beam_length_m".to_string(),
        format!("{:e}", r.cfg.rig.beam_length),
    );
    session_meta.insert(
        "started_unix_s".to_string(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs())
            .to_string(),
    );
    let mut rom_meta = r.backend_metadata.rom.clone();
    rom_meta.insert("path".to_string(), r.model_path.display().to_string());
    rom_meta.insert("config_hash".to_string(), model.meta.config_hash.clone());
    rom_meta.insert("modes".to_string(), model.n_modes().to_string());
    rom_meta.insert("pairs".to_string(), model.n_pairs().to_string());
    if let Some((twin, path)) = r.twin_model {
        rom_meta.insert("twin_path".to_string(), path.display().to_string());
        rom_meta.insert(
            "twin_config_hash".to_string(),
            twin.meta.config_hash.clone(),
        );
        rom_meta.insert("twin_pairs".to_string(), twin.n_pairs().to_string());
    }
    let mut attachments = vec![Attachment {
        name: RIG_ATTACHMENT.into(),
        media_type: "application/toml".into(),
        data: r.config_text.as_bytes().to_vec(),
    }];
    let plan_text = std::fs::read_to_string(&plan.source).unwrap_or_default();
    if !plan_text.is_empty() {
        attachments.push(Attachment {
            name: PLAN_ATTACHMENT.into(),
            media_type: "application/toml".into(),
            data: plan_text.into_bytes(),
        });
    }
    (
        vec![
            (SESSION_METADATA.into(), session_meta),
            (ROM_METADATA.into(), rom_meta),
        ],
        attachments,
    )
}

/// Runs the plan on `backend` (on `runtime`), logging to the request's file, with the live
/// twin and the live view when asked; `progress` sees every block's control state. Returns when
/// the session is done, aborted (the abort is in the summary) or stopped by SIGINT or SIGTERM.
pub fn run<B: RigBackend>(
    runtime: &tokio::runtime::Runtime,
    mut backend: B,
    request: SessionRequest<'_>,
    progress: &mut (dyn FnMut(&SessionProgress) + Send),
) -> Result<RunOutcome, RunError> {
    let (cfg, out) = (request.cfg, request.out);
    let l = cfg.rig.beam_length;
    let setup = SessionSetup {
        plan: request.plan.clone(),
        control: cfg.control.clone(),
        safety: cfg.safety.clone(),
        omega_ref: request.model.omega_ref(),
        beam_length: l,
    };
    let (metadata, attachments) = log_records(&request);
    let create_error = RunError::LogCreate;
    // Everything that can refuse the session is checked before the log is created: the
    // control setup and the twin. (The log is written under a temporary name and moves into
    // place when the backend has started, so a later failure does not touch an older file of
    // that name either.)
    Procedure::new(&setup, backend.layout()).map_err(SessionError::from)?;
    let twin_engine = if request.twin {
        let rom = request.twin_model.map_or(request.model, |(rom, _)| rom);
        let model = TwinModel::of_config(rom, cfg);
        Some(Twin::new(
            &model,
            &cfg.twin,
            backend.layout(),
            cfg.contact.clearance,
        )?)
    } else {
        None
    };
    let (handle, join) = SessionLog::create(out, LogOptions::default(), metadata, attachments)
        .map_err(create_error)?;
    let (live_recorder, live_view) = request.live.unzip();
    let twin_recorder = if let Some(engine) = twin_engine {
        let layout = backend.layout().clone();
        let o = engine.observation();
        let windows = TwinWindows::new(o, cfg.twin.tolerance);
        let clearances = ClearanceSchedule::new(l, cfg.model.clearance.as_ref());
        let (task, rx) = TwinTask::spawn(engine, &cfg.twin)?;
        let recorder = TwinRecorder::new(
            task,
            rx,
            clearances,
            windows,
            layout.dt(),
            Some(handle.clone()),
        )
        .map_err(RunError::TwinLog)?;
        Some(match &live_recorder {
            Some(live) => recorder.with_live(live.clone()),
            None => recorder,
        })
    } else {
        None
    };
    let mut recorder = Tee(
        Tee(
            McapRecorder::new(handle).map_err(create_error)?,
            live_recorder,
        ),
        twin_recorder,
    );

    let t0 = Instant::now();
    let (mut summary, overruns, link) = runtime.block_on(async {
        let shutdown = operator_stop()?;
        let s = run_session(&mut backend, &setup, &mut recorder, shutdown, progress).await?;
        let status = backend.status();
        Ok::<_, RunError>((s, status.overruns, status.link))
    })?;
    let twin = recorder.1.take().map(TwinRecorder::finish);
    if let Some(t) = &twin {
        summary.attach_twin(t.comparisons.iter().cloned());
        summary.twin_model = Some(cfg.model.clone());
    }
    let messages = recorder.0 .0.messages();
    drop(recorder);
    // A log that cannot be finished (a full disk) is not the end of the outcome: the summary
    // and what the log kept are still reported.
    let log_error = join
        .close()
        .err()
        .map(|source| error_chain(&RunError::LogClose(source)));
    let wall_seconds = t0.elapsed().as_secs_f64();
    let live = live_view.map(LiveView::close);
    Ok(RunOutcome {
        summary,
        wall_seconds,
        messages,
        overruns,
        live,
        twin,
        link,
        log_error,
    })
}

/// An error and its causes, `: `-separated, without a cause whose text is already said.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let s = c.to_string();
        if !text.contains(&s) {
            text.push_str(": ");
            text.push_str(&s);
        }
        cause = c.source();
    }
    text
}

/// Completes when the operator stops the session: Ctrl-C (SIGINT) or SIGTERM (`kill`,
/// `timeout`, `systemctl stop`); both abort it with a ramp-down and a closed log. The handlers
/// are installed here, before the session starts, so that neither signal kills the process
/// outright once the rig may be driven.
fn operator_stop() -> Result<impl std::future::Future<Output = ()>, RunError> {
    use tokio::signal::unix::{signal, SignalKind};
    let install = |kind| signal(kind).map_err(RunError::Signal);
    let mut interrupt = install(SignalKind::interrupt())?;
    let mut terminate = install(SignalKind::terminate())?;
    Ok(async move {
        tokio::select! {
            _ = interrupt.recv() => {}
            _ = terminate.recv() => {}
        }
    })
}
