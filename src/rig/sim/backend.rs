//! The simulated rig as a [`RigBackend`]: the deterministic core ([`SimRig`]) runs on the
//! blocking pool one block ahead of the consumer, like a DAQ with one block of buffering, on
//! virtual time (as fast as it computes) or paced to the wall clock (`realtime`).
//!
//! Timing, identical in both modes so that a paced session reproduces a virtual one: when the
//! consumer takes block `k`, block `k + 1` is already being computed, so a drive command sent
//! after block `k` applies from block `k + 2`; the status returned after block `k` describes
//! the drive of block `k`. With `realtime`, block `k` is handed out no earlier than the wall
//! time of its last sample; a block finished later than that counts as an overrun.

use crate::config::physics::test_clearance;
use std::time::Duration;

use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::plan::TestSpec;

use super::{InjectedFault, SimRig, SimRigError};
use crate::rig::{
    CommandError, DaqBlock, DaqLayout, DriveCommand, DriveState, RigBackend, RigError, RigFault,
    RigStatus, StateError,
};

/// The simulation task computing a block panicked or was cancelled.
#[derive(Debug, thiserror::Error)]
#[error("simulation task: {0}")]
pub struct TaskFailed(tokio::task::JoinError);

type Pending = JoinHandle<(SimRig, DaqBlock, DriveState, Vec<RigFault>, bool)>;

/// The simulated rig backend.
#[derive(Debug)]
pub struct SimBackend {
    rig: Option<SimRig>,
    layout: DaqLayout,
    pending: Option<Pending>,
    /// A computed block waiting for its wall-clock time (`realtime`), kept here so that a
    /// cancelled `next_block` (the session's shutdown branch winning a `select!`) loses
    /// nothing: the next call hands it out.
    ready: Option<(DaqBlock, DriveState, Vec<RigFault>)>,
    commands: Vec<DriveCommand>,
    faults: Vec<InjectedFault>,
    realtime: bool,
    started: Option<Instant>,
    status: RigStatus,
    /// Beam length, m: the unit of a test's clearance.
    beam_length: f64,
    /// The hidden clearance per test (`[truth.variants.clearance]`), if any.
    hidden_clearance: Option<crate::physics::ClearanceSpec>,
    stalled: bool,
}

impl SimBackend {
    /// Backend around `rig`; `beam_length` (m) converts a test's clearance (/ l) to metres.
    pub fn new(rig: SimRig, beam_length: f64, realtime: bool) -> SimBackend {
        SimBackend {
            layout: rig.layout().clone(),
            hidden_clearance: rig.variants().clearance.clone(),
            rig: Some(rig),
            pending: None,
            ready: None,
            commands: Vec::new(),
            faults: Vec::new(),
            realtime,
            started: None,
            status: RigStatus::default(),
            beam_length,
            stalled: false,
        }
    }

    /// Schedules an injected fault (applied before the next block is computed), after
    /// checking its values ([`InjectedFault::check`] on this rig's beam length).
    pub fn inject(&mut self, fault: InjectedFault) -> Result<(), SimRigError> {
        fault.check(self.beam_length).map_err(SimRigError::Fault)?;
        self.faults.push(fault);
        Ok(())
    }

    /// Takes the core back from the computation in flight (if any). Cancel-safe: the
    /// computation stays in flight until it is awaited to the end.
    async fn settle_pending(
        &mut self,
    ) -> Result<Option<(DaqBlock, DriveState, Vec<RigFault>, bool)>, RigError> {
        let Some(h) = self.pending.as_mut() else {
            return Ok(None);
        };
        let done = h.await;
        self.pending = None;
        let (rig, block, drive, faults, stalled) =
            done.map_err(|e| RigError::link(TaskFailed(e)))?;
        self.rig = Some(rig);
        Ok(Some((block, drive, faults, stalled)))
    }

    fn spawn_next(&mut self) -> Result<(), RigError> {
        let mut rig = self
            .rig
            .take()
            .ok_or(RigError::State(StateError::SimulationCoreMissing))?;
        for f in self.faults.drain(..) {
            rig.schedule(f).map_err(RigError::config)?;
        }
        for c in self.commands.drain(..) {
            rig.set_drive(c).map_err(RigError::command)?;
        }
        self.pending = Some(tokio::task::spawn_blocking(move || {
            let stalled_before = rig.stalled();
            let block = rig.next_block();
            let drive = rig.drive();
            let faults = rig.faults().to_vec();
            (rig, block, drive, faults, stalled_before)
        }));
        Ok(())
    }
}

impl RigBackend for SimBackend {
    fn layout(&self) -> &DaqLayout {
        &self.layout
    }

    async fn start(&mut self) -> Result<(), RigError> {
        if self.started.is_some() {
            return Err(RigError::State(StateError::AlreadyStarted));
        }
        self.started = Some(Instant::now());
        self.status.running = true;
        self.spawn_next()
    }

    async fn set_drive(&mut self, command: DriveCommand) -> Result<(), RigError> {
        let valid = command.frequency_hz.is_finite()
            && command.frequency_hz > 0.0
            && command.amplitude_v.is_finite()
            && command.amplitude_v >= 0.0
            && command.ramp_s.is_finite()
            && command.ramp_s >= 0.0;
        if !valid {
            return Err(RigError::command(CommandError::Invalid { command }));
        }
        self.commands.push(command);
        Ok(())
    }

    async fn begin_test(&mut self, test: &TestSpec) -> Result<(), RigError> {
        // Applies from the next block computed (the one after the block in flight). A hidden
        // clearance variant changes the plan's clearance.
        let plan_m = test.clearance_m(self.beam_length);
        self.faults.push(InjectedFault::ClearanceChange {
            at_s: 0.0,
            clearance_m: test_clearance(self.hidden_clearance.as_ref(), &test.name, plan_m),
        });
        Ok(())
    }

    async fn next_block(&mut self) -> Result<Option<DaqBlock>, RigError> {
        let Some(started) = self.started else {
            return Err(RigError::State(StateError::NotStarted));
        };
        if self.stalled {
            std::future::pending::<()>().await;
        }
        if self.ready.is_none() {
            let Some((block, drive, faults, stalled)) = self.settle_pending().await? else {
                return Ok(None);
            };
            if stalled {
                // The DAQ stopped: this block and all later ones never arrive.
                self.stalled = true;
                std::future::pending::<()>().await;
            }
            self.spawn_next()?;
            if self.realtime {
                let len_s = block.len as f64 / self.layout.sample_rate;
                let deadline = started + Duration::from_secs_f64(block.time + len_s);
                if Instant::now() > deadline + Duration::from_secs_f64(len_s) {
                    self.status.overruns += 1;
                }
            }
            self.ready = Some((block, drive, faults));
        }
        // Cancel-safe from here: the block stays in `ready` until the wait is over.
        let end = {
            let (block, _, _) = self.ready.as_ref().expect("set above");
            block.time + block.len as f64 / self.layout.sample_rate
        };
        if self.realtime {
            tokio::time::sleep_until(started + Duration::from_secs_f64(end)).await;
        }
        let (block, drive, faults) = self.ready.take().expect("set above");
        self.status.time = end;
        self.status.drive = drive;
        self.status.faults = faults;
        Ok(Some(block))
    }

    fn status(&self) -> RigStatus {
        self.status.clone()
    }

    async fn stop(&mut self) -> Result<(), RigError> {
        let _ = self.settle_pending().await;
        self.status.running = false;
        self.status.drive.amplitude_v = 0.0;
        Ok(())
    }
}
