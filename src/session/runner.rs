//! The async stepped-sine session: drives a [`RigBackend`] through the control
//! [`Procedure`], checks the safety limits on every block, hands every record to a
//! [`SessionRecorder`] (the MCAP log, teed with the live view and the live twin by [`Tee`])
//! and ramps the drive down at the end or on an abort, recording the blocks of the ramp.
//!
//! Shutdown (SIGINT or SIGTERM, whose handlers `session::run` installs) is a future passed
//! in: when it completes, the session aborts with [`AbortReason::Operator`]. The DAQ watchdog
//! is a wall-clock timeout on every block.
//!
//! [`Tee`]: super::recorder::Tee

use std::future::Future;
use std::time::Duration;

use crate::control::{
    AbortReason, BlockOutcome, ControlState, EventKind, Phase, Procedure, SafetyMonitor,
    SessionEvent, SessionSetup, SetupError,
};
use crate::rig::{DaqBlock, DaqLayout, DriveCommand, RigBackend, RigStatus};

use super::recorder::{RecordError, SessionRecorder};
use super::summary::SessionSummary;

/// Rig status is recorded about this often (rig time), s: with the first block, then with the
/// first block at least this long after the last record.
pub const STATUS_PERIOD_S: f64 = 1.0;

/// Frequency of the ramp-down command when no step ever set one (a fault before the first
/// drive command), Hz: any valid frequency does, the amplitude is ramped to zero.
const RAMP_DOWN_IDLE_FREQUENCY_HZ: f64 = 1.0;

/// A recorder's error as the abort it causes.
fn log_abort(e: RecordError) -> AbortReason {
    AbortReason::Log {
        message: e.to_string(),
    }
}

/// Progress of a session, for a progress display.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionProgress {
    /// Test index and name.
    pub test: (usize, String),
    /// Step index and number of steps of the test.
    pub step: (usize, usize),
    /// Rig time, s.
    pub time: f64,
    /// Phase.
    pub phase: Phase,
    /// Last relative control error.
    pub error: Option<f64>,
}

/// Errors that prevent a session from starting (everything after the start is an abort).
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The plan or settings cannot run.
    #[error("session setup: {0}")]
    Setup(#[from] SetupError),
    /// The backend did not start.
    #[error(transparent)]
    Rig(#[from] crate::rig::RigError),
    /// The recorder failed before the start (its error names the log file).
    #[error(transparent)]
    Log(#[from] RecordError),
}

struct Run<'a, R: SessionRecorder> {
    recorder: &'a mut R,
    summary: SessionSummary,
    last_status: f64,
    last_block_end: f64,
    /// Sample interval, s.
    dt: f64,
}

impl<R: SessionRecorder> Run<'_, R> {
    fn outcome(&mut self, out: &BlockOutcome) -> Result<(), AbortReason> {
        if let Some(c) = &out.control {
            self.recorder.control(c).map_err(log_abort)?;
        }
        for e in &out.events {
            self.summary.apply_event(e);
            self.recorder.event(e).map_err(log_abort)?;
        }
        for (info, s) in &out.steps {
            let end = info.record_end_time(self.dt);
            self.recorder.step(end, info, s).map_err(log_abort)?;
            self.summary.push_step(&info.test, s.clone());
        }
        Ok(())
    }

    fn block(
        &mut self,
        block: &DaqBlock,
        layout: &DaqLayout,
        status: &RigStatus,
    ) -> Result<(), AbortReason> {
        // The block is accounted for before it is recorded: the ramp-down after a recorder
        // failure (a full disk) runs on these times and must see them advance.
        self.summary.blocks += 1;
        self.last_block_end = block.time + block.len as f64 / layout.sample_rate;
        self.summary.rig_seconds = self.last_block_end;
        self.recorder.block(block).map_err(log_abort)?;
        if block.time - self.last_status >= STATUS_PERIOD_S || block.seq == 0 {
            self.last_status = block.time;
            self.recorder
                .status(block.time, status)
                .map_err(log_abort)?;
        }
        Ok(())
    }
}

/// Runs the plan of `setup` on `backend`, recording into `recorder`, until done, aborted or
/// `shutdown` completes. Returns the summary (also when aborted); errors only if the session
/// could not start.
pub async fn run_session<B: RigBackend, R: SessionRecorder>(
    backend: &mut B,
    setup: &SessionSetup,
    recorder: &mut R,
    shutdown: impl Future<Output = ()>,
    progress: &mut (dyn FnMut(&SessionProgress) + Send),
) -> Result<SessionSummary, SessionError> {
    let layout = backend.layout().clone();
    let mut procedure = Procedure::new(setup, &layout)?;
    let mut safety = SafetyMonitor::new(&setup.safety, &layout, setup.control.contact_threshold_v);
    let timeout = Duration::from_secs_f64(setup.safety.daq_timeout_s);
    recorder.layout(&layout)?;
    backend.start().await?;
    let mut run = Run {
        recorder,
        summary: SessionSummary::default(),
        last_status: f64::NEG_INFINITY,
        last_block_end: 0.0,
        dt: layout.dt(),
    };
    tokio::pin!(shutdown);
    let mut last_seq: i64 = -1;
    let mut frequency_hz = 0.0;
    let mut drive_on = false;
    let start = procedure.start(0.0, 0);
    let abort: Option<AbortReason> = 'session: {
        if let Err(e) = run.recorder.started() {
            break 'session Some(log_abort(e));
        }
        if let Err(e) = run.outcome(&start) {
            break 'session Some(e);
        }
        if let Some(t) = start.begin_test {
            if let Err(e) = backend.begin_test(&setup.plan.tests[t]).await {
                break 'session Some(AbortReason::Backend {
                    message: e.to_string(),
                });
            }
        }
        if let Some(cmd) = start.command {
            frequency_hz = cmd.frequency_hz;
            drive_on = cmd.amplitude_v > 0.0;
            if let Err(e) = backend.set_drive(cmd).await {
                break 'session Some(AbortReason::Backend {
                    message: e.to_string(),
                });
            }
        }
        loop {
            let next = tokio::select! {
                biased;
                _ = &mut shutdown => break 'session Some(AbortReason::Operator),
                r = tokio::time::timeout(timeout, backend.next_block()) => r,
            };
            let block = match next {
                Err(_) => {
                    break 'session Some(AbortReason::DaqTimeout {
                        seconds: setup.safety.daq_timeout_s,
                        last_seq,
                    })
                }
                Ok(Err(e)) => {
                    break 'session Some(AbortReason::Backend {
                        message: e.to_string(),
                    })
                }
                Ok(Ok(None)) => break 'session Some(AbortReason::StreamEnded { last_seq }),
                Ok(Ok(Some(b))) => b,
            };
            last_seq = block.seq as i64;
            let status = backend.status();
            if let Err(e) = run.block(&block, &layout, &status) {
                break 'session Some(e);
            }
            if let Some(f) = status.faults.first() {
                break 'session Some(AbortReason::Rig { fault: f.clone() });
            }
            if let Err(e) = safety.check_block(&block, &layout, drive_on) {
                break 'session Some(e);
            }
            let out = match procedure.on_block(&block, &status.drive, &mut safety) {
                Ok(o) => o,
                Err(e) => break 'session Some(e),
            };
            if let Err(e) = run.outcome(&out) {
                break 'session Some(e);
            }
            if let Some(c) = &out.control {
                let (t, _) = procedure.position();
                progress(&SessionProgress {
                    test: (t, setup.plan.tests[t].name.clone()),
                    step: (c.step, setup.plan.tests[t].steps as usize),
                    time: c.time,
                    phase: c.phase,
                    error: c.error,
                });
            }
            if out.done {
                break 'session None;
            }
            if let Some(t) = out.begin_test {
                if let Err(e) = backend.begin_test(&setup.plan.tests[t]).await {
                    break 'session Some(AbortReason::Backend {
                        message: e.to_string(),
                    });
                }
            }
            if let Some(cmd) = out.command {
                frequency_hz = cmd.frequency_hz;
                drive_on = cmd.amplitude_v > 0.0;
                if let Err(e) = backend.set_drive(cmd).await {
                    break 'session Some(AbortReason::Backend {
                        message: e.to_string(),
                    });
                }
            }
        }
    };

    // Ramp-down: always, also after an abort; record the blocks of the ramp when the DAQ is
    // alive.
    let t_now = run.last_block_end;
    if let Some(reason) = &abort {
        tracing::warn!("session aborted: {reason}");
        let e = SessionEvent {
            time: t_now,
            sample: (t_now * layout.sample_rate).round() as u64,
            kind: EventKind::Abort {
                reason: reason.clone(),
                message: reason.to_string(),
            },
        };
        run.summary.apply_event(&e);
        let _ = run.recorder.event(&e);
    }
    let ramp = setup.safety.ramp_down_s;
    let _ = backend
        .set_drive(DriveCommand {
            frequency_hz: if frequency_hz > 0.0 {
                frequency_hz
            } else {
                RAMP_DOWN_IDLE_FREQUENCY_HZ
            },
            amplitude_v: 0.0,
            ramp_s: ramp,
        })
        .await;
    let daq_alive = !matches!(
        abort,
        Some(
            AbortReason::DaqTimeout { .. }
                | AbortReason::StreamEnded { .. }
                | AbortReason::SequenceGap { .. }
        )
    );
    if daq_alive {
        let block_s = layout.block_size as f64 / layout.sample_rate;
        let end = t_now + ramp + block_s;
        // Until the ramp's time has passed and the backend reports the drive at zero (a
        // block computed before the command, e.g. one in flight when Ctrl-C cancelled a
        // wait, delays the ramp by a block); however the blocks' times and the drive behave,
        // no more blocks than the ramp's length and a few in flight.
        let max_blocks = (ramp / block_s).ceil() as u64 + 4;
        let mut taken = 0u64;
        while taken < max_blocks
            && (run.last_block_end < end || backend.status().drive.amplitude_v != 0.0)
        {
            taken += 1;
            match tokio::time::timeout(timeout, backend.next_block()).await {
                Ok(Ok(Some(b))) => {
                    let status = backend.status();
                    let _ = run.block(&b, &layout, &status);
                    let _ = run.recorder.control(&ControlState {
                        time: b.time,
                        seq: b.seq,
                        test: procedure.position().0,
                        step: procedure.position().1,
                        phase: Phase::RampDown,
                        frequency_hz,
                        target_m: 0.0,
                        measured_m: None,
                        period_amplitude_m: None,
                        error: None,
                        drive_v: status.drive.amplitude_v,
                    });
                }
                _ => break,
            }
        }
    } else {
        tokio::time::sleep(Duration::from_secs_f64(ramp)).await;
    }
    let _ = backend.stop().await;
    // The final status (faults, link counters) is always in the log, also after an abort.
    let _ = run.recorder.status(run.last_block_end, &backend.status());
    let end = SessionEvent {
        time: run.last_block_end,
        sample: (run.last_block_end * layout.sample_rate).round() as u64,
        kind: EventKind::SessionEnd {
            aborted: abort.is_some(),
        },
    };
    let _ = run.recorder.event(&end);
    Ok(run.summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ControlSpec, DaqSpec, SafetySpec};
    use crate::log::LogError;
    use crate::plan::Plan;
    use crate::rig::{DriveState, RigError};

    /// A rig that streams quiet blocks (all counts zero) and takes every command at once.
    struct QuietRig {
        layout: DaqLayout,
        seq: u64,
        drive: DriveState,
        stopped: bool,
        commands: Vec<DriveCommand>,
    }

    impl RigBackend for QuietRig {
        fn layout(&self) -> &DaqLayout {
            &self.layout
        }
        async fn start(&mut self) -> Result<(), RigError> {
            Ok(())
        }
        async fn set_drive(&mut self, cmd: DriveCommand) -> Result<(), RigError> {
            self.drive.frequency_hz = cmd.frequency_hz;
            self.drive.target_amplitude_v = cmd.amplitude_v;
            self.commands.push(cmd);
            Ok(())
        }
        async fn next_block(&mut self) -> Result<Option<DaqBlock>, RigError> {
            // Yields like a real stream, so that the test's timeout can fire on a hang.
            tokio::task::yield_now().await;
            let n = self.layout.block_size;
            let first_sample = self.seq * n as u64;
            let block = DaqBlock {
                seq: self.seq,
                first_sample,
                time: first_sample as f64 / self.layout.sample_rate,
                len: n,
                counts: vec![0; n * self.layout.channels.len()],
            };
            self.seq += 1;
            Ok(Some(block))
        }
        fn status(&self) -> RigStatus {
            RigStatus {
                running: !self.stopped,
                drive: self.drive,
                ..RigStatus::default()
            }
        }
        async fn stop(&mut self) -> Result<(), RigError> {
            self.stopped = true;
            Ok(())
        }
    }

    /// A recorder whose disk fills up: every block from block `fail_from` on fails to record,
    /// and so does everything after it.
    struct DiskFull {
        fail_from: u64,
        full: bool,
        events: Vec<SessionEvent>,
    }

    impl DiskFull {
        fn check(&self) -> Result<(), RecordError> {
            if self.full {
                return Err(RecordError::Log(LogError::Closed {
                    path: "full.mcap".into(),
                    reason: "No space left on device (os error 28)".into(),
                }));
            }
            Ok(())
        }
    }

    impl SessionRecorder for DiskFull {
        fn layout(&mut self, _: &DaqLayout) -> Result<(), RecordError> {
            Ok(())
        }
        fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
            self.full |= block.seq >= self.fail_from;
            self.check()
        }
        fn control(&mut self, _: &ControlState) -> Result<(), RecordError> {
            self.check()
        }
        fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
            // Kept in memory to see what the session said, whether or not the disk took it.
            self.events.push(event.clone());
            self.check()
        }
        fn status(&mut self, _: f64, _: &RigStatus) -> Result<(), RecordError> {
            self.check()
        }
        fn step(
            &mut self,
            _: f64,
            _: &crate::control::StepInfo,
            _: &crate::control::StepSummary,
        ) -> Result<(), RecordError> {
            self.check()
        }
    }

    /// Issue 17, case 1: a recorder failure (a full disk) aborts the session, which ramps the
    /// drive down over the ramp time, stops the stream and returns; it used to spin forever
    /// because the blocks of the ramp were never accounted for.
    #[test]
    fn a_full_disk_aborts_ramps_down_and_returns() {
        let layout = crate::rig::channels::layout(&DaqSpec::default());
        let plan = Plan::from_str(
            "[[test]]\nname = \"t\"\nlevel = 6e-5\nclearance = 2.78e-3\ndirection = \"up\"\n\
             omega_start = 0.95\nomega_end = 1.05\nsteps = 3\nsettle_periods = 20\n\
             record_periods = 20\n",
            "full-disk.toml",
        )
        .unwrap();
        let safety = SafetySpec::default();
        let setup = SessionSetup {
            plan,
            control: ControlSpec::default(),
            safety: safety.clone(),
            omega_ref: std::f64::consts::TAU * 51.27,
            beam_length: 0.3,
        };
        let mut rig = QuietRig {
            layout: layout.clone(),
            seq: 0,
            drive: DriveState::default(),
            stopped: false,
            commands: Vec::new(),
        };
        let mut recorder = DiskFull {
            fail_from: 5,
            full: false,
            events: Vec::new(),
        };
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .unwrap();
        let summary = runtime
            .block_on(async {
                tokio::time::timeout(
                    Duration::from_secs(20),
                    run_session(
                        &mut rig,
                        &setup,
                        &mut recorder,
                        std::future::pending(),
                        &mut |_| {},
                    ),
                )
                .await
            })
            .expect("the session returns after a full disk instead of hanging")
            .unwrap();
        let block_s = layout.block_size as f64 / layout.sample_rate;
        let abort = recorder
            .events
            .iter()
            .find_map(|e| match &e.kind {
                EventKind::Abort { reason, .. } => Some((e.time, reason.clone())),
                _ => None,
            })
            .expect("an abort event");
        assert!(
            matches!(abort.1, AbortReason::Log { .. }),
            "aborted for {:?}",
            abort.1
        );
        assert!(
            (abort.0 - 6.0 * block_s).abs() < 1e-9,
            "the abort stands after the failed block 5: {}",
            abort.0
        );
        // The drive ramps to zero over the ramp time, then the stream stops.
        let last = rig.commands.last().expect("a ramp-down command");
        assert_eq!(last.amplitude_v, 0.0);
        assert_eq!(last.ramp_s, safety.ramp_down_s);
        assert!(rig.stopped, "the stream is stopped");
        let ramp_blocks = rig.seq - 6;
        let expected = (safety.ramp_down_s / block_s).ceil() as u64 + 1;
        assert!(
            ramp_blocks >= expected - 1 && ramp_blocks <= expected + 1,
            "{ramp_blocks} blocks of ramp-down, expected about {expected}"
        );
        assert!(summary.aborted);
        assert!(
            (summary.rig_seconds - rig.seq as f64 * block_s).abs() < 1e-9,
            "the summary's rig time covers every block taken: {} s",
            summary.rig_seconds
        );
        let end = recorder.events.last().expect("a session end");
        assert!(matches!(end.kind, EventKind::SessionEnd { aborted: true }));
    }
}
