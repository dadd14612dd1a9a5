//! Where a session's records go: the [`SessionRecorder`] trait the session loop records into,
//! and the combinators that fan records out ([`Tee`], `Option`, [`NullRecorder`]). The
//! recorders themselves are the MCAP log's (`mcap`), the live view's (`live`) and the live
//! twin's (`twin`).

use crate::control::{ControlState, SessionEvent, StepInfo, StepSummary};
use crate::log::LogError;
use crate::rig::{DaqBlock, DaqLayout, RigStatus};

/// Why a recorder could not take a record (the session aborts with
/// [`crate::control::AbortReason::Log`]).
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The session log refused the message (its queue is full, the writer stopped, ...).
    #[error(transparent)]
    Log(#[from] LogError),
}

/// Where a session's records go. Implementations must not block (the MCAP recorder queues to
/// a writer thread); an error aborts the session.
pub trait SessionRecorder: Send {
    /// The DAQ layout, once before the first block.
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), RecordError>;
    /// A raw DAQ block.
    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError>;
    /// The control state after a block.
    fn control(&mut self, state: &ControlState) -> Result<(), RecordError>;
    /// A session event.
    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError>;
    /// Rig status (about once per second of rig time).
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), RecordError>;
    /// A finished step.
    fn step(
        &mut self,
        time: f64,
        info: &StepInfo,
        summary: &StepSummary,
    ) -> Result<(), RecordError>;
    /// The backend started: from here on what is recorded is worth keeping even if the
    /// session aborts (the MCAP log moves into place, replacing an older file of its name).
    /// Before, a failed start leaves nothing behind.
    fn started(&mut self) -> Result<(), RecordError> {
        Ok(())
    }
}

/// A recorder that keeps nothing.
#[derive(Debug, Default, Clone, Copy)]
pub struct NullRecorder;

impl SessionRecorder for NullRecorder {
    fn layout(&mut self, _: &DaqLayout) -> Result<(), RecordError> {
        Ok(())
    }
    fn block(&mut self, _: &DaqBlock) -> Result<(), RecordError> {
        Ok(())
    }
    fn control(&mut self, _: &ControlState) -> Result<(), RecordError> {
        Ok(())
    }
    fn event(&mut self, _: &SessionEvent) -> Result<(), RecordError> {
        Ok(())
    }
    fn status(&mut self, _: f64, _: &RigStatus) -> Result<(), RecordError> {
        Ok(())
    }
    fn step(&mut self, _: f64, _: &StepInfo, _: &StepSummary) -> Result<(), RecordError> {
        Ok(())
    }
}

/// No recorder: `None` keeps nothing (e.g. the live view when `--foxglove` is not given).
impl<R: SessionRecorder> SessionRecorder for Option<R> {
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.layout(layout))
    }
    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.block(block))
    }
    fn control(&mut self, state: &ControlState) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.control(state))
    }
    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.event(event))
    }
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.status(time, status))
    }
    fn step(
        &mut self,
        time: f64,
        info: &StepInfo,
        summary: &StepSummary,
    ) -> Result<(), RecordError> {
        self.as_mut()
            .map_or(Ok(()), |r| r.step(time, info, summary))
    }
    fn started(&mut self) -> Result<(), RecordError> {
        self.as_mut().map_or(Ok(()), |r| r.started())
    }
}

/// Hands every record to two recorders, the first then the second (e.g. the MCAP log, then the
/// live view). Both always get the record; the first error (the first recorder's when both
/// fail) is returned.
#[derive(Debug, Default, Clone, Copy)]
pub struct Tee<A, B>(pub A, pub B);

impl<A: SessionRecorder, B: SessionRecorder> SessionRecorder for Tee<A, B> {
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), RecordError> {
        let a = self.0.layout(layout);
        a.and(self.1.layout(layout))
    }
    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
        let a = self.0.block(block);
        a.and(self.1.block(block))
    }
    fn control(&mut self, state: &ControlState) -> Result<(), RecordError> {
        let a = self.0.control(state);
        a.and(self.1.control(state))
    }
    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
        let a = self.0.event(event);
        a.and(self.1.event(event))
    }
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), RecordError> {
        let a = self.0.status(time, status);
        a.and(self.1.status(time, status))
    }
    fn step(
        &mut self,
        time: f64,
        info: &StepInfo,
        summary: &StepSummary,
    ) -> Result<(), RecordError> {
        let a = self.0.step(time, info, summary);
        a.and(self.1.step(time, info, summary))
    }
    fn started(&mut self) -> Result<(), RecordError> {
        let a = self.0.started();
        a.and(self.1.started())
    }
}
