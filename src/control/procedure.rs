//! The stepped-sine procedure as a synchronous state machine over DAQ blocks: for every test of
//! the plan and every frequency step, retune the amplitude controller, settle, record the
//! window, summarise; the drive commands and log records it produces are carried out by the
//! async session (`src/session/`). Being synchronous and clock-free it is tested without a
//! runtime, and replay never needs it.
//!
//! Timing: a drive command produced after a block applies from a later block (the backend's
//! latency: the simulated rig's is two blocks). A step starts with the first block whose
//! drive state (reported by the backend with the block) runs at the step's frequency: the
//! controller is retuned at that block's first sample. The blocks in between, and the rest of
//! the block that ended a record window, are not used.

use std::f64::consts::TAU;

// TEST_START_RAMP_S: the ramp of the drive command that starts a test (from rest or from the
// previous test's level), shared with the virtual stepped sine.
use crate::plan::{per_l_to_metres, Plan, TestSpec, TEST_START_RAMP_S};
use crate::rig::channels::ChannelMap;
use crate::rig::{DaqBlock, DaqLayout, DriveCommand, DriveState};

use super::amplitude::{AmplitudeController, ControlUpdate};
use super::events::{ControlState, EventKind, Phase, SessionEvent};
use super::safety::{AbortReason, SafetyMonitor};
use super::settle::{Settle, SettleDetector};
use super::spec::{ControlSpec, SafetySpec};
use super::summary::{summarize, StepInfo, StepSummary};

/// What a session runs: the plan, the controller and safety settings, and the frequency and
/// length references of the plan's ratios.
#[derive(Clone, Debug)]
pub struct SessionSetup {
    /// The stepped-sine plan.
    pub plan: Plan,
    /// `[control]`.
    pub control: ControlSpec,
    /// `[safety]`.
    pub safety: SafetySpec,
    /// omega_2, the 1FU angular frequency the plan's Omega ratios refer to, rad/s.
    pub omega_ref: f64,
    /// Beam length l, the unit of the plan's levels, m.
    pub beam_length: f64,
}

/// What one block produced.
#[derive(Debug, Default)]
pub struct BlockOutcome {
    /// Control state after the block (one log record per block).
    pub control: Option<ControlState>,
    /// Events, in order.
    pub events: Vec<SessionEvent>,
    /// Steps whose record window ended in this block.
    pub steps: Vec<(StepInfo, StepSummary)>,
    /// A drive command to send before the next block.
    pub command: Option<DriveCommand>,
    /// A test starts with the next block (the backend may prepare for it).
    pub begin_test: Option<usize>,
    /// The plan is complete.
    pub done: bool,
}

/// Where the procedure is within a step, with the state that stage owns.
#[derive(Debug)]
enum Stage {
    /// The step's frequency starts with the next block; `blocks` received so far while the
    /// drive had not taken it.
    Pending { blocks: u32 },
    /// Waiting for the response to settle.
    Settle { settle: SettleDetector },
    /// Recording a window (the settle detector keeps seeing the response).
    Record {
        settle: SettleDetector,
        window: RecordWindow,
    },
    /// The plan is complete.
    Done,
}

impl Stage {
    fn phase(&self) -> Phase {
        match self {
            Stage::Pending { .. } => Phase::Transition,
            Stage::Settle { .. } => Phase::Settle,
            Stage::Record { .. } => Phase::Record,
            Stage::Done => Phase::Done,
        }
    }

    /// The settle detector of a step past its transition.
    fn settle_detector(&mut self) -> Option<&mut SettleDetector> {
        match self {
            Stage::Settle { settle } | Stage::Record { settle, .. } => Some(settle),
            Stage::Pending { .. } | Stage::Done => None,
        }
    }
}

/// A record window being filled: channel-major counts of `len` samples from sample `first`.
#[derive(Debug)]
struct RecordWindow {
    first: u64,
    len: usize,
    counts: Vec<i32>,
    recorded: usize,
    /// Whether the step settled before this window (or the settle time ran out).
    settled: bool,
}

/// The stepped-sine state machine.
#[derive(Debug)]
pub struct Procedure {
    setup: SessionSetup,
    layout: DaqLayout,
    /// The channels' roles (platform accelerometers, vibrometer).
    channels: ChannelMap,
    test: usize,
    step: usize,
    ratios: Vec<f64>,
    stage: Stage,
    /// The amplitude controller, made at the first step's transition and retuned at every
    /// later one.
    controller: Option<AmplitudeController>,
    /// First sample of the running step's settling.
    step_start_sample: u64,
    /// Settle time of the running step (fixed by its first record window), s.
    settle_seconds: f64,
    last_update: Option<ControlUpdate>,
    drive_v: f64,
    /// Record window of the step (1-based).
    record_attempt: u32,
}

/// Blocks a step waits for the drive to take its frequency before the session aborts.
const MAX_PENDING_BLOCKS: u32 = 20;

/// Why a session cannot run its setup.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The plan is invalid.
    #[error(transparent)]
    Plan(#[from] crate::plan::PlanError),
    /// A `[control]` or `[safety]` value is out of range.
    #[error(transparent)]
    Settings(#[from] crate::config::SpecError),
    /// The plan has no test.
    #[error("plan {plan}: no tests")]
    NoTests {
        /// Where the plan came from.
        plan: String,
    },
    /// The DAQ layout has no platform accelerometer (the base motion is not measured).
    #[error("the DAQ layout has no platform accelerometer")]
    NoPlatform,
    /// The frequency or length reference is not positive.
    #[error("omega_ref and beam_length must be > 0")]
    BadReference,
    /// A test's record window would not fit in memory.
    #[error(
        "plan {plan}, test {test:?}: record_periods = {record_periods} at Omega/omega_2 = \
         {omega_ratio} needs a record window of {bytes:.3e} bytes ({samples} samples x \
         {channels} channels), more than the limit of {MAX_RECORD_WINDOW_BYTES:.3e} bytes: \
         record fewer periods"
    )]
    RecordWindow {
        /// Where the plan came from.
        plan: String,
        /// The test.
        test: String,
        /// Its record periods.
        record_periods: u32,
        /// The step with the longest window.
        omega_ratio: f64,
        /// Samples per channel of that window.
        samples: usize,
        /// Channels of the layout.
        channels: usize,
        /// Bytes of ADC counts the window needs.
        bytes: f64,
    },
}

/// Largest record window the procedure keeps in memory, bytes of ADC counts.
pub const MAX_RECORD_WINDOW_BYTES: f64 = 2.0 * 1024.0 * 1024.0 * 1024.0;

/// Samples per channel of a record window of `periods` at `omega` (rad/s) with samples `dt`
/// apart: whole periods and the sample that closes the last one.
fn record_samples(periods: u32, omega: f64, dt: f64) -> usize {
    let spp = TAU / (omega * dt);
    (f64::from(periods) * spp).ceil() as usize + 1
}

impl Procedure {
    /// Procedure for `setup` on a stream with `layout`. Errors name what is missing.
    pub fn new(setup: &SessionSetup, layout: &DaqLayout) -> Result<Procedure, SetupError> {
        setup.plan.validate()?;
        setup.control.validate()?;
        setup.safety.validate()?;
        if setup.plan.tests.is_empty() {
            return Err(SetupError::NoTests {
                plan: setup.plan.source.clone(),
            });
        }
        let map = ChannelMap::of(layout);
        if map.platform.is_empty() {
            return Err(SetupError::NoPlatform);
        }
        if !(setup.omega_ref > 0.0 && setup.beam_length > 0.0) {
            return Err(SetupError::BadReference);
        }
        let channels = layout.channels.len();
        for t in &setup.plan.tests {
            // The longest window is at the lowest frequency.
            let omega_ratio = t.omega_start.min(t.omega_end);
            let samples =
                record_samples(t.record_periods, omega_ratio * setup.omega_ref, layout.dt());
            let bytes = (samples as f64) * (channels * std::mem::size_of::<i32>()) as f64;
            if bytes > MAX_RECORD_WINDOW_BYTES {
                return Err(SetupError::RecordWindow {
                    plan: setup.plan.source.clone(),
                    test: t.name.clone(),
                    record_periods: t.record_periods,
                    omega_ratio,
                    samples,
                    channels,
                    bytes,
                });
            }
        }
        let initial = if setup.control.initial_drive_v > 0.0 {
            setup.control.initial_drive_v
        } else {
            0.01 * setup.safety.max_drive_v
        };
        Ok(Procedure {
            setup: setup.clone(),
            layout: layout.clone(),
            channels: map,
            test: 0,
            step: 0,
            ratios: setup.plan.tests[0].omega_ratios(),
            stage: Stage::Pending { blocks: 0 },
            controller: None,
            step_start_sample: 0,
            settle_seconds: 0.0,
            last_update: None,
            drive_v: initial.min(setup.safety.max_drive_v),
            record_attempt: 1,
        })
    }

    fn spec(&self) -> &TestSpec {
        &self.setup.plan.tests[self.test]
    }

    fn omega(&self) -> f64 {
        self.ratios[self.step] * self.setup.omega_ref
    }

    fn target(&self) -> f64 {
        per_l_to_metres(self.spec().level, self.setup.beam_length)
    }

    /// Index of the running test and step.
    pub fn position(&self) -> (usize, usize) {
        (self.test, self.step)
    }

    /// The command and events that start the session (first test, first step), at rig time
    /// `time` and sample `sample`.
    pub fn start(&mut self, time: f64, sample: u64) -> BlockOutcome {
        let mut out = BlockOutcome {
            begin_test: Some(0),
            ..Default::default()
        };
        out.events.push(SessionEvent {
            time,
            sample,
            kind: EventKind::SessionStart {
                plan: self.setup.plan.name.clone().unwrap_or_default(),
                tests: self
                    .setup
                    .plan
                    .tests
                    .iter()
                    .map(|t| t.name.clone())
                    .collect(),
            },
        });
        self.push_test_start(&mut out, time, sample);
        self.push_step_start(&mut out, time, sample, TEST_START_RAMP_S);
        out
    }

    fn push_test_start(&mut self, out: &mut BlockOutcome, time: f64, sample: u64) {
        let t = self.spec().clone();
        out.events.push(SessionEvent {
            time,
            sample,
            kind: EventKind::TestStart {
                test: t.name,
                level: t.level,
                direction: t.direction.as_str().to_string(),
                clearance: t.clearance,
            },
        });
    }

    fn push_step_start(&mut self, out: &mut BlockOutcome, time: f64, sample: u64, ramp_s: f64) {
        let omega = self.omega();
        out.events.push(SessionEvent {
            time,
            sample,
            kind: EventKind::StepStart {
                test: self.spec().name.clone(),
                step: self.step,
                omega_ratio: self.ratios[self.step],
                frequency_hz: omega / TAU,
            },
        });
        out.command = Some(DriveCommand {
            frequency_hz: omega / TAU,
            amplitude_v: self.drive_v,
            ramp_s,
        });
        self.stage = Stage::Pending { blocks: 0 };
    }

    /// Processes one block (already checked by the safety monitor for shape and sequence);
    /// `drive` is the drive state the backend produced the block with.
    pub fn on_block(
        &mut self,
        block: &DaqBlock,
        drive: &DriveState,
        safety: &mut SafetyMonitor,
    ) -> Result<BlockOutcome, AbortReason> {
        let mut out = BlockOutcome::default();
        let dt = self.layout.dt();
        match &mut self.stage {
            Stage::Done => {
                out.done = true;
                return Ok(out);
            }
            Stage::Pending { blocks } => {
                let f = self.ratios[self.step] * self.setup.omega_ref / TAU;
                if (drive.frequency_hz - f).abs() > 1e-9 * f {
                    *blocks += 1;
                    if *blocks > MAX_PENDING_BLOCKS {
                        return Err(AbortReason::Backend {
                            message: format!(
                                "the drive did not take the step's frequency {f:.4} Hz within {MAX_PENDING_BLOCKS} blocks (it runs at {:.4} Hz)",
                                drive.frequency_hz
                            ),
                        });
                    }
                    out.control = Some(self.control_state(block));
                    return Ok(out);
                }
                self.begin_settle(block, dt)?;
            }
            Stage::Settle { .. } | Stage::Record { .. } => {}
        }
        let mut drive_changed = false;
        for i in 0..block.len {
            if matches!(self.stage, Stage::Pending { .. } | Stage::Done) {
                break; // the rest of the block belongs to the previous frequency
            }
            let sample = block.first_sample + i as u64;
            let a_base = self.channels.base_acceleration(&block.counts, block.len, i);
            if let Some(k) = self.channels.vibrometer {
                let v = self.layout.channels[k].value(block.counts[k * block.len + i]);
                if let Some(settle) = self.stage.settle_detector() {
                    settle.push_response(v);
                }
            }
            if let Stage::Record { window, .. } = &mut self.stage {
                let n = window.len;
                for k in 0..self.layout.channels.len() {
                    window.counts[k * n + window.recorded] = block.counts[k * block.len + i];
                }
                window.recorded += 1;
            }
            let controller = self.controller.as_mut().expect("made at the transition");
            if let Some(u) = controller.push(a_base) {
                safety.check_update(&u, controller.target_m())?;
                if u.drive_v != self.drive_v {
                    self.drive_v = u.drive_v;
                    drive_changed = true;
                }
                self.last_update = Some(u);
                if let Stage::Settle { settle } = &mut self.stage {
                    let s = settle.period_done(u.error);
                    if s != Settle::Wait {
                        self.begin_record(&mut out, sample + 1, s == Settle::Settled);
                    }
                }
            }
            if matches!(&self.stage, Stage::Record { window, .. } if window.recorded == window.len)
            {
                self.end_record(&mut out, block.time + (i + 1) as f64 * dt, sample + 1)?;
            }
        }
        if drive_changed && out.command.is_none() && !matches!(self.stage, Stage::Done) {
            out.command = Some(DriveCommand {
                frequency_hz: self.omega() / TAU,
                amplitude_v: self.drive_v,
                ramp_s: TAU / self.omega(),
            });
        }
        out.control = Some(self.control_state(block));
        out.done = matches!(self.stage, Stage::Done);
        Ok(out)
    }

    /// The drive runs at the step's frequency from `block` on: retunes (or makes) the
    /// controller and starts settling.
    fn begin_settle(&mut self, block: &DaqBlock, dt: f64) -> Result<(), AbortReason> {
        let (omega, target) = (self.omega(), self.target());
        match &mut self.controller {
            Some(c) => c.retune(target, omega, dt, block.time),
            None => AmplitudeController::new(
                &self.setup.control,
                self.setup.safety.max_drive_v,
                target,
                omega,
                dt,
                block.time,
                self.drive_v,
            )
            .map(|c| self.controller = Some(c)),
        }
        .map_err(|e| AbortReason::Backend {
            message: format!("controller: {e}"),
        })?;
        self.stage = Stage::Settle {
            settle: SettleDetector::new(&self.setup.control, self.spec().settle_periods),
        };
        self.step_start_sample = block.first_sample;
        self.record_attempt = 1;
        Ok(())
    }

    fn control_state(&self, block: &DaqBlock) -> ControlState {
        let u = self.last_update;
        ControlState {
            time: block.time,
            seq: block.seq,
            test: self.test,
            step: self.step,
            phase: self.stage.phase(),
            frequency_hz: self.omega() / TAU,
            target_m: self.target(),
            measured_m: u.map(|u| u.measured_m),
            period_amplitude_m: u.map(|u| u.period_amplitude_m),
            error: u.map(|u| u.error),
            drive_v: self.drive_v,
        }
    }

    /// Starts a record window at sample `first` (from settling, or again after a rejected
    /// window).
    fn begin_record(&mut self, out: &mut BlockOutcome, first: u64, settled: bool) {
        let dt = self.layout.dt();
        let len = record_samples(self.spec().record_periods, self.omega(), dt);
        let window = RecordWindow {
            first,
            len,
            counts: vec![0; len * self.layout.channels.len()],
            recorded: 0,
            settled,
        };
        if self.record_attempt == 1 {
            self.settle_seconds = (first - self.step_start_sample) as f64 * dt;
        }
        self.stage = match std::mem::replace(&mut self.stage, Stage::Done) {
            Stage::Settle { settle } | Stage::Record { settle, .. } => {
                Stage::Record { settle, window }
            }
            other => unreachable!("a record window starts from settling, not {other:?}"),
        };
        out.events.push(SessionEvent {
            time: first as f64 * dt,
            sample: first,
            kind: EventKind::RecordStart {
                test: self.spec().name.clone(),
                step: self.step,
                settled,
                settle_seconds: self.settle_seconds,
            },
        });
    }

    fn end_record(
        &mut self,
        out: &mut BlockOutcome,
        time: f64,
        sample: u64,
    ) -> Result<(), AbortReason> {
        let Stage::Record { window, .. } = &self.stage else {
            unreachable!("a record window ends while recording");
        };
        let info = StepInfo {
            test: self.spec().name.clone(),
            step: self.step,
            omega_ratio: self.ratios[self.step],
            omega: self.omega(),
            base_amp_target: self.target(),
            drive_amplitude: self.drive_v,
            settle_seconds: self.settle_seconds,
            settled: window.settled,
            record_first_sample: window.first,
            record_samples: window.len,
            contact_threshold_v: self.setup.control.contact_threshold_v,
            record_attempt: self.record_attempt,
            record_tolerance: Some(self.setup.control.record_tolerance),
        };
        let summary =
            summarize(&self.layout, &info, &window.counts).map_err(|e| AbortReason::Backend {
                message: format!("step summary: {e}"),
            })?;
        let base_amp_error = summary.base_amp_measured / info.base_amp_target - 1.0;
        // NaN (a broken window) is never within tolerance.
        let within = base_amp_error.abs() <= self.setup.control.record_tolerance;
        if !within && self.record_attempt < self.setup.control.record_attempts {
            out.events.push(SessionEvent {
                time,
                sample,
                kind: EventKind::RecordRejected {
                    info,
                    base_amp_error,
                },
            });
            self.record_attempt += 1;
            let settled = window.settled;
            self.begin_record(out, sample, settled);
            return Ok(());
        }
        out.events.push(SessionEvent {
            time,
            sample,
            kind: EventKind::RecordEnd { info: info.clone() },
        });
        out.steps.push((info, summary));
        // Next step, next test, or done.
        if self.step + 1 < self.ratios.len() {
            self.step += 1;
            self.push_step_start(out, time, sample, 0.0);
        } else {
            out.events.push(SessionEvent {
                time,
                sample,
                kind: EventKind::TestEnd {
                    test: self.spec().name.clone(),
                },
            });
            if self.test + 1 < self.setup.plan.tests.len() {
                let old = self.target();
                self.test += 1;
                self.step = 0;
                self.ratios = self.spec().omega_ratios();
                // Feed-forward: scale the drive with the level.
                self.drive_v =
                    (self.drive_v * self.target() / old).min(self.setup.safety.max_drive_v);
                out.begin_test = Some(self.test);
                self.push_test_start(out, time, sample);
                self.push_step_start(out, time, sample, TEST_START_RAMP_S);
            } else {
                self.stage = Stage::Done;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ControlSpec, DaqSpec, SafetySpec};

    fn setup(record_periods: u32) -> SessionSetup {
        let text = format!(
            "[[test]]\nname = \"slow\"\nlevel = 6e-5\nclearance = 2.78e-3\ndirection = \"up\"\n\
             omega_start = 0.1\nomega_end = 0.2\nsteps = 2\nsettle_periods = 20\n\
             record_periods = {record_periods}\n"
        );
        SessionSetup {
            plan: Plan::from_str(&text, "slow.toml").unwrap(),
            control: ControlSpec::default(),
            safety: SafetySpec::default(),
            omega_ref: TAU * 51.27,
            beam_length: 0.3,
        }
    }

    /// Issue 17, case 5: a record window that does not fit in memory is refused before the
    /// session starts (4e9 periods aborted a session mid-test with the drive on); the plan's
    /// own limit allows 1e5 periods, which at 0.1 omega_2 is 8.8 GB of counts.
    #[test]
    fn a_record_window_beyond_memory_is_refused_at_setup() {
        let layout = crate::rig::channels::layout(&DaqSpec::default());
        let e = Procedure::new(&setup(100_000), &layout).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(
                e,
                SetupError::RecordWindow {
                    record_periods: 100_000,
                    channels: 11,
                    ..
                }
            ),
            "{msg}"
        );
        assert!(
            msg.contains("test \"slow\"") && msg.contains("limit"),
            "{msg}"
        );
        assert!(Procedure::new(&setup(1_000), &layout).is_ok());
    }
}
