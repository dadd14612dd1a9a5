//! One session of the simulated device: the select loop that owns the device's state (the
//! simulated rig, the drive gating, pacing, heartbeats, faults) and answers the host over the
//! CAN tunnel, following the sequencing rules of `firmware-interfaces/README.md`.

use std::time::Duration;

use tokio::time::Instant;

use crate::rig::hw::can::block::{split_block, BlockFormat};
use crate::rig::hw::can::messages::{
    self, DeviceHeartbeat, DriveStatus, Fault, FaultCode, Message, StreamCommand, TimeSyncResponse,
    NO_BLOCK,
};
use crate::rig::hw::can::transport::{CanTransport, TransportError};
use crate::rig::hw::can::CanFrame;
use crate::rig::sim::SimRig;
use crate::rig::{ChannelKind, DaqBlock, DriveCommand, RigFault};

use super::serial::Devices;
use super::{
    DeviceError, FirmwareSim, Inject, LinkFault, Pace, SessionReport, SetpointReport,
    VIRTUAL_LEAD_BLOCKS,
};

/// Pause after a failed tunnel receive (the host went away: ICMP unreachable) before the
/// next one; the heartbeat timeout decides whether the session ends.
const RECV_RETRY: Duration = Duration::from_millis(10);
/// FAULT frames' channel byte when the fault concerns no channel.
const NO_CHANNEL: u8 = 255;

/// How a session ended ([`SessionReport::reason`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End {
    /// The host sent STREAM_CONTROL stop.
    Stop,
    /// No HOST_HEARTBEAT in time; the safety ramp-down finished.
    HeartbeatLost,
}

impl End {
    fn as_str(self) -> &'static str {
        match self {
            End::Stop => "stop",
            End::HeartbeatLost => "heartbeat_lost",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Idle,
    Streaming,
    /// Safety ramp-down (heartbeat lost, interlock, amplifier off).
    SafetyRamp,
}

/// One session of the device, from the host's first frame to stop or heartbeat loss.
pub(super) struct Session<'a> {
    fw: &'a FirmwareSim,
    t0: Instant,
    state: State,
    rig: Option<SimRig>,
    pending: Option<tokio::task::JoinHandle<(SimRig, DaqBlock)>>,
    commands: Vec<DriveCommand>,
    setpoint: Option<DriveCommand>,
    applied_seq: u16,
    seq: u64,
    consumed: Option<u32>,
    stream_start: Instant,
    last_host_heartbeat: Instant,
    counter: u32,
    flags: u8,
    fault_count: u16,
    reported: Vec<RigFault>,
    gated: bool,
    interlock_reported: bool,
    report: SessionReport,
    fired: Vec<bool>,
    format: BlockFormat,
    /// Sends nothing (injected hang).
    muted: bool,
}

const FLAG_INTERLOCK: u8 = 1;
const FLAG_HEARTBEAT: u8 = 2;
const FLAG_OVERLOAD: u8 = 4;
const FLAG_OVER_RANGE: u8 = 8;
const FLAG_DEVICE: u8 = 16;

impl<'a> Session<'a> {
    pub(super) fn new(fw: &'a FirmwareSim) -> Session<'a> {
        let now = Instant::now();
        Session {
            fw,
            t0: now,
            state: State::Idle,
            rig: None,
            pending: None,
            commands: Vec::new(),
            setpoint: None,
            applied_seq: 0,
            seq: 0,
            consumed: None,
            stream_start: now,
            last_host_heartbeat: now,
            counter: 0,
            flags: 0,
            fault_count: 0,
            reported: Vec::new(),
            gated: false,
            interlock_reported: false,
            report: SessionReport::default(),
            fired: vec![false; fw.opts.inject.len()],
            muted: false,
            format: BlockFormat::of(fw.rig.layout()).expect("checked at start-up"),
        }
    }

    fn devices(&self) -> std::sync::MutexGuard<'_, Devices> {
        self.fw.devices.lock().unwrap_or_else(|e| e.into_inner())
    }

    async fn send(&mut self, m: &Message) {
        self.send_frame(&m.encode()).await;
    }

    async fn send_frame(&mut self, f: &CanFrame) {
        if !self.muted && self.fw.tunnel.peer().is_some() && self.fw.tunnel.send(f).await.is_ok() {
            self.report.frames_sent += 1;
        }
    }

    async fn fault(&mut self, code: FaultCode, channel: u8, value: i32, flag: u8) {
        self.flags |= flag;
        self.fault_count = self.fault_count.wrapping_add(1);
        let m = Message::Fault(Fault {
            code,
            channel,
            value,
            count: self.fault_count,
        });
        self.send(&m).await;
    }

    fn rig_time(&self) -> f64 {
        self.seq as f64 * self.format.block_size as f64 / self.fw.rig.layout().sample_rate
    }

    fn block_duration(&self) -> Duration {
        Duration::from_secs_f64(
            f64::from(self.format.block_size) / self.fw.rig.layout().sample_rate,
        )
    }

    fn start(&mut self) -> Result<(), DeviceError> {
        let mut rig = self.fw.rig.clone();
        for f in &self.fw.opts.inject {
            if let Inject::Rig(r) = f {
                rig.schedule(r.clone()).map_err(DeviceError::Rig)?;
            }
        }
        self.rig = Some(rig);
        self.state = State::Streaming;
        self.seq = 0;
        self.consumed = None;
        self.stream_start = Instant::now();
        self.last_host_heartbeat = Instant::now();
        self.setpoint = None;
        self.commands.clear();
        self.gated = false;
        self.devices().host_disabled_amp = false;
        Ok(())
    }

    /// Drive gating: amplifier enabled and interlock closed, or ramp to zero.
    fn gate(&mut self) {
        let (enabled, interlock) = {
            let d = self.devices();
            (d.amp.enabled, d.amp.interlock_open)
        };
        let open = enabled && !interlock && self.state == State::Streaming;
        if !open && !self.gated {
            self.gated = true;
            let f = self.setpoint.map_or(1.0, |c| c.frequency_hz);
            self.commands.push(DriveCommand {
                frequency_hz: f,
                amplitude_v: 0.0,
                ramp_s: self.fw.opts.ramp_down_s,
            });
        }
    }

    async fn on_frame(&mut self, f: CanFrame) -> Result<Option<End>, DeviceError> {
        self.report.frames_received += 1;
        let from = self.fw.tunnel.last_from();
        if self.state == State::Idle {
            // A new host: answer it.
            self.fw.tunnel.set_peer(from);
        } else if from != self.fw.tunnel.peer() {
            self.report.rx_errors += 1;
            return Ok(None);
        }
        let m = match Message::decode(&f) {
            Ok(m) if m.def().sender == messages::Node::Host => m,
            _ => {
                self.report.rx_errors += 1;
                return Ok(None);
            }
        };
        match m {
            Message::StreamControl(s) => match s.command {
                StreamCommand::Start => {
                    if self.state == State::Idle {
                        self.start()?;
                    }
                }
                StreamCommand::Stop => {
                    if self.state != State::Idle {
                        self.report.stopped_at_s = Some(self.rig_time());
                        return Ok(Some(End::Stop));
                    }
                } // (On stop the drive goes off at once: see `run`.)
            },
            Message::DriveSetpoint(sp) => {
                self.report.setpoints += 1;
                let cmd = sp.command();
                let ok = crate::rig::sim::drive::DriveGenerator::check(
                    &cmd,
                    0.5 * self.fw.rig.layout().sample_rate,
                );
                if ok.is_err() {
                    self.report.rx_errors += 1;
                } else {
                    self.setpoint = Some(cmd);
                    self.report.last_setpoint = Some(SetpointReport {
                        amplitude_v: cmd.amplitude_v,
                        ramp_s: cmd.ramp_s,
                        at_s: self.rig_time(),
                    });
                    self.applied_seq = sp.seq;
                    if self.state == State::Streaming && !self.gated {
                        self.commands.push(cmd);
                    }
                }
            }
            Message::HostHeartbeat(h) => {
                self.last_host_heartbeat = Instant::now();
                self.consumed = (h.consumed != NO_BLOCK).then_some(h.consumed);
            }
            Message::TimeSyncRequest(t) => {
                let r = Message::TimeSyncResponse(TimeSyncResponse {
                    seq: t.seq,
                    host_time_us: t.host_time_us,
                    device_time_us: self.t0.elapsed().as_micros() as u64,
                });
                self.send(&r).await;
            }
            _ => {}
        }
        Ok(None)
    }

    async fn on_tick(&mut self) {
        let state = match self.state {
            State::Idle => 0,
            State::Streaming => 1,
            State::SafetyRamp => 2,
        };
        let rx_errors = (self.report.rx_errors.min(u64::from(u16::MAX))) as u16;
        let hb = Message::DeviceHeartbeat(DeviceHeartbeat {
            counter: self.counter,
            state,
            flags: self.flags,
            rx_errors,
        });
        self.counter = self.counter.wrapping_add(1);
        self.send(&hb).await;
        if self.state == State::Streaming
            && self.last_host_heartbeat.elapsed() > self.fw.opts.heartbeat_timeout
        {
            // The host is gone: make the rig safe.
            self.report.amplitude_at_loss_v = self.rig.as_ref().map(|r| r.drive().amplitude_v);
            self.state = State::SafetyRamp;
            self.gate();
            self.fault(FaultCode::HeartbeatLost, NO_CHANNEL, 0, FLAG_HEARTBEAT)
                .await;
        }
    }

    /// Link faults due now (by rig time).
    async fn timed_faults(&mut self) {
        let t = self.rig_time();
        for i in 0..self.fw.opts.inject.len() {
            if self.fired[i] {
                continue;
            }
            let Inject::Link(f) = &self.fw.opts.inject[i] else {
                continue;
            };
            let due = match f {
                LinkFault::Interlock { at_s }
                | LinkFault::SerialGarbage { at_s, .. }
                | LinkFault::SerialSilent { at_s, .. }
                | LinkFault::Vanish { at_s }
                | LinkFault::Mute { at_s } => *at_s <= t,
                _ => false,
            };
            if !due {
                continue;
            }
            self.fired[i] = true;
            match f.clone() {
                LinkFault::Interlock { .. } => {
                    let mut d = self.devices();
                    d.amp.interlock_open = true;
                    d.amp.enabled = false;
                }
                LinkFault::SerialGarbage { port, .. } => {
                    self.devices().misbehaviour[port as usize].garbage = true;
                }
                LinkFault::SerialSilent { port, .. } => {
                    self.devices().misbehaviour[port as usize].silent = true;
                }
                LinkFault::Vanish { .. } => std::process::exit(3),
                LinkFault::Mute { .. } => self.muted = true,
                _ => {}
            }
        }
        if self.devices().amp.interlock_open && !self.interlock_reported {
            self.interlock_reported = true;
            self.fault(FaultCode::Interlock, NO_CHANNEL, 0, FLAG_INTERLOCK)
                .await;
        }
    }

    fn block_faults(&self, seq: u64) -> Vec<LinkFault> {
        self.fw
            .opts
            .inject
            .iter()
            .filter_map(|f| match f {
                Inject::Link(
                    l @ (LinkFault::DropFrame { block, .. }
                    | LinkFault::SwapFrames { block }
                    | LinkFault::CorruptSample { block }
                    | LinkFault::BadFrames { block }),
                ) if *block == seq => Some(l.clone()),
                _ => None,
            })
            .collect()
    }

    async fn on_block(&mut self, rig: SimRig, block: DaqBlock) -> Result<Option<End>, DeviceError> {
        let drive = rig.drive();
        let faults = rig.faults().to_vec();
        self.rig = Some(rig);
        // Faults of the simulated rig: over the CAN link, and in the serial devices' state.
        let layout = self.fw.rig.layout().clone();
        for f in faults {
            if self.reported.contains(&f) {
                continue;
            }
            self.reported.push(f.clone());
            match &f {
                RigFault::DriveSaturated { limit_v } => {
                    self.devices().amp.overload = true;
                    let v = (limit_v / messages::FAULT_VALUE_RES).round() as i32;
                    self.fault(FaultCode::DriveSaturated, NO_CHANNEL, v, FLAG_OVERLOAD)
                        .await;
                }
                RigFault::OverRange { channel } => {
                    let k = layout.index(channel).unwrap_or(usize::from(NO_CHANNEL));
                    if layout.channels.get(k).map(|c| c.kind) == Some(ChannelKind::Vibrometer) {
                        self.devices().vib.over_range = true;
                    }
                    self.fault(FaultCode::OverRange, k as u8, 0, FLAG_OVER_RANGE)
                        .await;
                }
                RigFault::Device { .. } => {
                    self.fault(FaultCode::DeviceError, NO_CHANNEL, 0, FLAG_DEVICE)
                        .await;
                }
            }
        }
        let state = match self.state {
            State::Streaming if self.gated => 2,
            State::Streaming => 1,
            State::SafetyRamp => 2,
            State::Idle => 0,
        };
        let status = Message::DriveStatus(DriveStatus::from_state(
            block.seq as u32,
            self.applied_seq,
            state,
            &drive,
        ));
        self.send(&status).await;
        let timestamp_us = (self.stream_start - self.t0).as_micros() as u64
            + (block.first_sample as f64 / layout.sample_rate * 1e6).round() as u64;
        let mut frames: Vec<CanFrame> = split_block(&block, &self.format, timestamp_us)
            .map_err(DeviceError::Split)?
            .iter()
            .map(Message::encode)
            .collect();
        for f in self.block_faults(block.seq) {
            match f {
                LinkFault::DropFrame { frame, .. } if frame + 1 < frames.len() => {
                    frames.remove(frame + 1);
                }
                LinkFault::SwapFrames { .. } if frames.len() > 3 => frames.swap(2, 3),
                LinkFault::CorruptSample { .. } if frames.len() > 1 => {
                    if let Ok(Message::Samples(mut s)) = Message::decode(&frames[1]) {
                        s.samples[0] = if s.samples[0] == 0 { 1 } else { 0 };
                        frames[1] = Message::Samples(s).encode();
                    }
                }
                LinkFault::BadFrames { .. } => {
                    let short = CanFrame::fd(messages::id::DAQ_SAMPLES, &[0; 48]);
                    let unknown = CanFrame::fd(0x7AB, &[1, 2, 3]);
                    for f in [short, unknown].into_iter().flatten() {
                        self.send_frame(&f).await;
                    }
                    if let Some(p) = self.fw.tunnel.peer() {
                        let _ = self.fw.tunnel.send_raw(b"not a tunnel datagram", p).await;
                    }
                }
                _ => {}
            }
        }
        if self.fw.opts.pace == Pace::Realtime {
            let due = self.stream_start + self.block_duration() * (block.seq as u32 + 1);
            tokio::time::sleep_until(due).await;
        }
        for f in &frames {
            self.send_frame(f).await;
        }
        self.report.blocks += 1;
        if self.state == State::SafetyRamp {
            self.report.safety_ramp_blocks += 1;
            if drive.amplitude_v == 0.0 && drive.target_amplitude_v == 0.0 {
                return Ok(Some(End::HeartbeatLost));
            }
        }
        Ok(None)
    }

    fn may_compute(&self) -> bool {
        if self.pending.is_some() || self.state == State::Idle || self.muted {
            return false;
        }
        match self.fw.opts.pace {
            Pace::Virtual if self.state == State::Streaming => {
                let consumed = self.consumed.map_or(-1, i64::from);
                (self.seq as i64) <= consumed + VIRTUAL_LEAD_BLOCKS
            }
            _ => true,
        }
    }

    fn compute(&mut self) -> Result<(), DeviceError> {
        let Some(mut rig) = self.rig.take() else {
            return Ok(());
        };
        for c in self.commands.drain(..) {
            rig.set_drive(c).map_err(DeviceError::Rig)?;
        }
        self.pending = Some(tokio::task::spawn_blocking(move || {
            let b = rig.next_block();
            (rig, b)
        }));
        self.seq += 1;
        Ok(())
    }

    pub(super) async fn run(mut self) -> Result<SessionReport, DeviceError> {
        let mut tick = tokio::time::interval(self.fw.opts.heartbeat_period);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let end = loop {
            if self.state != State::Idle {
                self.gate();
            }
            if self.may_compute() {
                self.compute()?;
            }
            tokio::select! {
                r = self.fw.tunnel.recv() => match r {
                    Ok(f) => {
                        if let Some(end) = self.on_frame(f).await? {
                            break end;
                        }
                    }
                    Err(TransportError::Malformed(_)) => self.report.rx_errors += 1,
                    // The host went away (ICMP unreachable): the heartbeat timeout decides.
                    Err(_) => tokio::time::sleep(RECV_RETRY).await,
                },
                _ = tick.tick() => self.on_tick().await,
                r = async { self.pending.as_mut().expect("guarded").await }, if self.pending.is_some() => {
                    self.pending = None;
                    let (rig, block) = r.map_err(DeviceError::Task)?;
                    self.timed_faults().await;
                    if let Some(end) = self.on_block(rig, block).await? {
                        break end;
                    }
                }
            }
        };
        if let Some(p) = self.pending.take() {
            if let Ok((rig, _)) = p.await {
                self.rig = Some(rig);
            }
        }
        if end == End::Stop {
            self.report.amplitude_at_stop_v = self.rig.as_ref().map(|r| r.drive().amplitude_v);
            // STREAM_CONTROL stop: drive off (the host ramped it down before).
            if let Some(rig) = self.rig.as_mut() {
                let f = rig.drive().frequency_hz.max(1.0);
                let _ = rig.set_drive(DriveCommand {
                    frequency_hz: f,
                    amplitude_v: 0.0,
                    ramp_s: 0.0,
                });
            }
        }
        self.report.reason = end.as_str().to_string();
        self.report.final_amplitude_v = self.rig.as_ref().map_or(0.0, |r| r.drive().amplitude_v);
        let (serial_rx_errors, host_disabled_amp) = {
            let d = self.devices();
            (d.rx_errors, d.host_disabled_amp)
        };
        self.report.serial_rx_errors = serial_rx_errors;
        self.report.amp_disabled_by_host = host_disabled_amp;
        {
            let mut d = self.devices();
            d.amp.enabled = false;
        }
        self.fw.tunnel.set_peer(None);
        Ok(self.report)
    }
}
