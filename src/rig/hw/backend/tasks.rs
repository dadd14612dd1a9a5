//! The backend's tasks and what they share: the link that sends and logs frames, the receiver
//! task (frames in, reassembled blocks out), the heartbeat task (HOST_HEARTBEAT, time sync,
//! supervision of the device's heartbeat), and the serial clients' STATUS handling.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::rig::{ChannelKind, DaqBlock, DaqLayout, DriveState, LinkCounters, RigError, RigFault};

use crate::rig::hw::can::block::{feed, Reassembler};
use crate::rig::hw::can::candump::Direction;
use crate::rig::hw::can::messages::{
    self, FaultCode, HostHeartbeat, Message, TimeSyncRequest, TIME_SYNC_PERIOD,
};
use crate::rig::hw::can::transport::{AnyTransport, CanTransport, TransportError};
use crate::rig::hw::can::CanFrame;
use crate::rig::hw::serial::port::{self, SerialClient, SerialError};
use crate::rig::hw::serial::protocol::{AmplifierStatus, VibrometerStatus};

use super::HwOptions;
use crate::rig::hw::{ConfigError, LinkError};

/// Baud rate of the vibrometer controller's port (8N1).
const LDV_BAUD: u32 = 115_200;
/// Baud rate of the power amplifier's port (8N1).
const AMP_BAUD: u32 = 9600;
/// DRIVE_STATUS frames kept to find the drive of a delivered block.
const DRIVE_HISTORY: usize = 16;
/// A device heartbeat later than this many heartbeat periods counts as a miss (half a
/// period of grace).
const HEARTBEAT_MISS_PERIODS: f64 = 1.5;

pub(super) type LogTx = std::sync::mpsc::Sender<(f64, Direction, CanFrame)>;

/// State shared by the tasks and the backend.
#[derive(Debug)]
pub(super) struct Shared {
    pub(super) counters: LinkCounters,
    pub(super) drives: VecDeque<(u32, DriveState)>,
    pub(super) faults: Vec<RigFault>,
    pub(super) last_device_heartbeat: Instant,
    pub(super) device_heartbeats: u64,
    pub(super) gone: Option<LinkError>,
}

impl Shared {
    pub(super) fn fault(&mut self, f: RigFault) {
        if !self.faults.contains(&f) {
            tracing::warn!("rig fault: {f}");
            self.faults.push(f);
        }
    }
}

pub(super) fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

/// Sends frames and logs them.
#[derive(Clone, Debug)]
pub(super) struct Link {
    pub(super) transport: Arc<AnyTransport>,
    pub(super) log: Option<LogTx>,
    pub(super) t0: Instant,
    pub(super) shared: Arc<Mutex<Shared>>,
}

impl Link {
    pub(super) async fn send(&self, m: &Message) -> Result<(), RigError> {
        let f = m.encode();
        let r = self.transport.send(&f).await;
        if let Some(l) = &self.log {
            let _ = l.send((self.t0.elapsed().as_secs_f64(), Direction::Tx, f));
        }
        let mut s = lock(&self.shared);
        match r {
            Ok(()) => {
                s.counters.frames_sent += 1;
                Ok(())
            }
            Err(e) => {
                let err = LinkError::Can {
                    link: self.transport.name(),
                    error: e.to_string(),
                };
                s.counters.last_error = Some(err.to_string());
                if matches!(e, TransportError::Gone(_)) {
                    s.gone.get_or_insert_with(|| err.clone());
                }
                Err(RigError::link(err))
            }
        }
    }

    pub(super) fn now_us(&self) -> u64 {
        self.t0.elapsed().as_micros() as u64
    }
}

/// The two serial clients and the amplifier's last status.
pub(super) type SerialLinks = (
    SerialClient,
    SerialClient,
    Arc<Mutex<Option<AmplifierStatus>>>,
);

pub(super) fn open_serial(
    opts: &HwOptions,
    layout: &DaqLayout,
    shared: &Arc<Mutex<Shared>>,
) -> Result<SerialLinks, RigError> {
    let ldv_port = port::open(&opts.ldv, LDV_BAUD).map_err(|error| {
        RigError::config(ConfigError::SerialPort {
            flag: "--ldv",
            device: "vibrometer controller",
            error,
        })
    })?;
    let amp_port = port::open(&opts.amp, AMP_BAUD).map_err(|error| {
        RigError::config(ConfigError::SerialPort {
            flag: "--amp",
            device: "power amplifier",
            error,
        })
    })?;
    let vib_channel = layout.channels[layout.indices_of(ChannelKind::Vibrometer)[0]]
        .name
        .clone();
    let sh = shared.clone();
    let ldv_path = opts.ldv.clone();
    let ldv = SerialClient::spawn(
        "vibrometer",
        &opts.ldv,
        Box::new(ldv_port),
        opts.serial_timeout,
        opts.serial_poll,
        "STATUS",
        move |r| {
            let mut s = lock(&sh);
            match r.map(|v| VibrometerStatus::parse(&v)) {
                Ok(Ok(st)) if st.over_range => s.fault(RigFault::OverRange {
                    channel: vib_channel.clone(),
                }),
                Ok(Ok(_)) => {}
                Ok(Err(e)) => {
                    s.counters.serial_garbage += 1;
                    s.counters.last_error = Some(format!("vibrometer ({ldv_path}): {e}"));
                }
                Err(e @ SerialError::Gone { .. }) => s.fault(RigFault::device(e.to_string())),
                Err(_) => {}
            }
        },
    );
    let sh = shared.clone();
    let amp_path = opts.amp.clone();
    let amp_status = Arc::new(Mutex::new(None));
    let last = amp_status.clone();
    let amp = SerialClient::spawn(
        "power amplifier",
        &opts.amp,
        Box::new(amp_port),
        opts.serial_timeout,
        opts.serial_poll,
        "STATUS",
        move |r| {
            let mut s = lock(&sh);
            match r.map(|v| AmplifierStatus::parse(&v)) {
                Ok(Ok(st)) => {
                    *last.lock().unwrap_or_else(|e| e.into_inner()) = Some(st);
                    if st.interlock_open {
                        s.fault(RigFault::device(format!(
                            "interlock open (power amplifier {amp_path}: ILK=1, output off)"
                        )));
                    }
                    if st.overload {
                        s.fault(RigFault::device(format!(
                            "power amplifier overload (power amplifier {amp_path}: OVL=1, \
                             output limit {} V)",
                            st.limit_v
                        )));
                    }
                }
                Ok(Err(e)) => {
                    s.counters.serial_garbage += 1;
                    s.counters.last_error = Some(format!("power amplifier ({amp_path}): {e}"));
                }
                Err(e @ SerialError::Gone { .. }) => s.fault(RigFault::device(e.to_string())),
                Err(_) => {}
            }
        },
    );
    Ok((ldv, amp, amp_status))
}

/// Maps a FAULT frame to a rig fault.
fn fault_of(f: &messages::Fault, layout: &DaqLayout) -> RigFault {
    match f.code {
        FaultCode::HeartbeatLost => RigFault::device(
            "rig DAQ: host heartbeat lost, the device ramped the drive down (FAULT \
             HEARTBEAT_LOST)",
        ),
        FaultCode::Interlock => {
            RigFault::device("interlock open (FAULT INTERLOCK from the rig DAQ)")
        }
        FaultCode::AmplifierOverload => {
            RigFault::device("power amplifier overload (FAULT AMPLIFIER_OVERLOAD from the rig DAQ)")
        }
        FaultCode::OverRange => RigFault::OverRange {
            channel: layout
                .channels
                .get(usize::from(f.channel))
                .map_or_else(|| format!("#{}", f.channel), |c| c.name.clone()),
        },
        FaultCode::DriveSaturated => RigFault::DriveSaturated {
            limit_v: f64::from(f.value) * messages::FAULT_VALUE_RES,
        },
        FaultCode::DeviceError => RigFault::device("rig DAQ device error (FAULT DEVICE_ERROR)"),
    }
}

/// The receiver task: every frame in, blocks out.
pub(super) async fn receiver(
    link: Link,
    mut reasm: Reassembler,
    layout: DaqLayout,
    blocks: mpsc::Sender<Result<DaqBlock, RigError>>,
) {
    loop {
        let r = link.transport.recv().await;
        let f = match r {
            Ok(f) => f,
            Err(TransportError::Malformed(m)) => {
                let mut s = lock(&link.shared);
                s.counters.frames_received += 1;
                s.counters.malformed += 1;
                s.counters.last_error = Some(m);
                continue;
            }
            Err(e) => {
                let err = LinkError::Can {
                    link: link.transport.name(),
                    error: e.to_string(),
                };
                lock(&link.shared).gone.get_or_insert_with(|| err.clone());
                let _ = blocks.send(Err(RigError::link(err))).await;
                return;
            }
        };
        if let Some(l) = &link.log {
            let _ = l.send((link.t0.elapsed().as_secs_f64(), Direction::Rx, f));
        }
        let decoded = Message::decode(&f);
        let mut ready = Vec::new();
        let mut fatal = None;
        {
            let mut s = lock(&link.shared);
            s.counters.frames_received += 1;
            match decoded {
                Err(e) => {
                    s.counters.malformed += 1;
                    s.counters.last_error = Some(e.to_string());
                }
                Ok(m) if m.def().sender == messages::Node::Host => {
                    s.counters.malformed += 1;
                    s.counters.last_error = Some(format!(
                        "CAN frame {:#05x} ({}): sent by the host, received from the bus",
                        f.id,
                        m.def().name
                    ));
                }
                Ok(m) => match m {
                    Message::BlockHeader(_) | Message::Samples(_) => {
                        if let Err(e) = feed(&mut reasm, &m) {
                            s.counters.last_error = Some(e.to_string());
                            fatal = Some(RigError::config(ConfigError::Header(e)));
                        }
                        while let Some(b) = reasm.pop() {
                            ready.push(b);
                        }
                        let c = reasm.counters();
                        if c.sequence_gaps > s.counters.sequence_gaps {
                            s.counters.last_error = Some(format!(
                                "DAQ blocks lost: {} so far ({} with a payload CRC mismatch; \
                                 the others incomplete when a block two later began)",
                                c.sequence_gaps, c.crc_errors
                            ));
                        }
                        s.counters.sequence_gaps = c.sequence_gaps;
                        s.counters.reordered = c.reordered;
                        s.counters.duplicates = c.duplicates;
                        s.counters.crc_errors = c.crc_errors;
                        // Sample-frame problems are malformed frames too (kept in sync).
                        s.counters.malformed = s.counters.malformed.max(c.malformed);
                    }
                    Message::DriveStatus(d) => {
                        s.drives.push_back((d.block_seq, d.drive()));
                        if s.drives.len() > DRIVE_HISTORY {
                            s.drives.pop_front();
                        }
                    }
                    Message::DeviceHeartbeat(_) => {
                        s.last_device_heartbeat = Instant::now();
                        s.device_heartbeats += 1;
                    }
                    Message::Fault(fl) => s.fault(fault_of(&fl, &layout)),
                    Message::TimeSyncResponse(t) => {
                        let now = link.now_us();
                        let rtt = now.saturating_sub(t.host_time_us) as f64 * 1e-6;
                        s.counters.round_trip_s = Some(rtt);
                        s.counters.clock_offset_s = Some(
                            t.device_time_us as f64 * 1e-6
                                - (t.host_time_us as f64 * 1e-6 + 0.5 * rtt),
                        );
                    }
                    _ => {}
                },
            }
        }
        if let Some(e) = fatal {
            let _ = blocks.send(Err(e)).await;
            return;
        }
        for b in ready {
            if blocks.send(Ok(b)).await.is_err() {
                return;
            }
        }
    }
}

/// The heartbeat task: HOST_HEARTBEAT, TIME_SYNC_REQUEST, device heartbeat supervision.
pub(super) async fn heartbeats(
    link: Link,
    period: Duration,
    timeout: Duration,
    consumed: Arc<AtomicU32>,
    counter: Arc<AtomicU32>,
    blocks: mpsc::Sender<Result<DaqBlock, RigError>>,
) {
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let per_second = (TIME_SYNC_PERIOD.as_secs_f64() / period.as_secs_f64())
        .round()
        .max(1.0) as u64;
    let mut n: u64 = 0;
    let mut last_counted = None;
    loop {
        tick.tick().await;
        n += 1;
        let c = counter.fetch_add(1, Ordering::Relaxed);
        let hb = Message::HostHeartbeat(HostHeartbeat {
            counter: c,
            consumed: consumed.load(Ordering::Relaxed),
        });
        let _ = link.send(&hb).await;
        if n % per_second == 0 {
            let _ = link
                .send(&Message::TimeSyncRequest(TimeSyncRequest {
                    seq: (n / per_second) as u32,
                    host_time_us: link.now_us(),
                }))
                .await;
        }
        let lost = {
            let mut s = lock(&link.shared);
            if s.device_heartbeats == 0 {
                continue;
            }
            let since = s.last_device_heartbeat.elapsed();
            // One miss per heartbeat period that passed without one (after a grace of half
            // a period).
            let late = since > period.mul_f64(HEARTBEAT_MISS_PERIODS);
            if late && last_counted != Some(s.device_heartbeats) {
                s.counters.heartbeat_misses += 1;
            }
            if late {
                last_counted = None;
            } else {
                last_counted = Some(s.device_heartbeats);
            }
            if since > timeout && s.gone.is_none() {
                let err = LinkError::HeartbeatLost {
                    link: link.transport.name(),
                    since_s: since.as_secs_f64(),
                    timeout_s: timeout.as_secs_f64(),
                };
                s.gone = Some(err.clone());
                s.counters.last_error = Some(err.to_string());
                Some(err)
            } else {
                None
            }
        };
        if let Some(err) = lost {
            let _ = blocks.send(Err(RigError::link(err))).await;
        }
    }
}
