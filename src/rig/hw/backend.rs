//! [`HwBackend`]: the rig's electronics as a [`RigBackend`]. One CAN FD link to the DAQ
//! front-end / signal generator (blocks, drive, heartbeats, faults, time sync) and two serial
//! links (vibrometer controller, power amplifier), as documented in `firmware-interfaces/`.
//!
//! Tasks (mini-redis style, each owning its state): a receiver task decodes every frame,
//! reassembles DAQ blocks and queues them (bounded) for [`RigBackend::next_block`]; a
//! heartbeat task sends HOST_HEARTBEAT every `heartbeat_period` (and the host sends one more
//! after each block it consumed), TIME_SYNC_REQUEST once per second, and supervises the
//! device's heartbeat; one thread per serial device answers requests and polls STATUS.
//! Everything counted goes to [`RigStatus::link`]; faults that end the test (link gone,
//! heartbeat lost, interlock, amplifier overload, over-range) become [`RigFault`]s or
//! [`RigError::Link`] so the session aborts with its ramp-down, which goes over the link too.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::rig::{
    ChannelKind, DaqBlock, DaqLayout, DriveCommand, DriveState, LinkCounters, RigBackend, RigError,
    RigFault, RigStatus,
};

use super::can::block::{feed, BlockFormat, Reassembler};
use super::can::candump::{CandumpLog, Direction};
use super::can::messages::{
    self, DriveSetpoint, FaultCode, HostHeartbeat, Message, StreamCommand, StreamControl,
    TimeSyncRequest, NO_BLOCK,
};
use super::can::transport::{AnyTransport, CanAddress, CanTransport, TransportError};
use super::can::CanFrame;
use super::serial::port::{self, SerialClient, SerialError};
use super::serial::protocol::{AmplifierStatus, VibrometerStatus};

/// How to reach the rig and what to expect of it.
#[derive(Clone, Debug)]
pub struct HwOptions {
    /// The CAN link (`--can`).
    pub can: CanAddress,
    /// The vibrometer controller's serial port (`--ldv`).
    pub ldv: String,
    /// The power amplifier's serial port (`--amp`).
    pub amp: String,
    /// Write every CAN frame as a candump log here, with rigtwin's decoded values beside it
    /// (`--can-log`).
    pub can_log: Option<PathBuf>,
    /// HOST_HEARTBEAT period; the device heartbeat is expected at the same period. Default
    /// 100 ms.
    pub heartbeat_period: Duration,
    /// No DEVICE_HEARTBEAT for this long: the link is lost. Default 500 ms.
    pub heartbeat_timeout: Duration,
    /// Serial answer timeout. Default 250 ms.
    pub serial_timeout: Duration,
    /// Serial STATUS poll period. Default 200 ms.
    pub serial_poll: Duration,
    /// The amplifier gain the rig description states (`shaker.amplifier_gain`), V/V; the
    /// amplifier's own must match.
    pub amplifier_gain: f64,
    /// Vibrometer output filter to set, Hz (the DAQ's anti-alias cutoff).
    pub vibrometer_filter_hz: u32,
}

impl HwOptions {
    /// Options with the default timing.
    pub fn new(can: CanAddress, ldv: String, amp: String, amplifier_gain: f64) -> HwOptions {
        HwOptions {
            can,
            ldv,
            amp,
            can_log: None,
            heartbeat_period: Duration::from_millis(100),
            heartbeat_timeout: Duration::from_millis(500),
            serial_timeout: Duration::from_millis(250),
            serial_poll: Duration::from_millis(200),
            amplifier_gain,
            vibrometer_filter_hz: 5000,
        }
    }
}

type LogTx = std::sync::mpsc::Sender<(f64, Direction, CanFrame)>;

/// State shared by the tasks and the backend.
#[derive(Debug)]
struct Shared {
    counters: LinkCounters,
    drives: VecDeque<(u32, DriveState)>,
    faults: Vec<RigFault>,
    last_device_heartbeat: Instant,
    device_heartbeats: u64,
    gone: Option<String>,
}

impl Shared {
    fn fault(&mut self, f: RigFault) {
        if !self.faults.contains(&f) {
            tracing::warn!("rig fault: {f}");
            self.faults.push(f);
        }
    }
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

/// Sends frames and logs them.
#[derive(Clone, Debug)]
struct Link {
    transport: Arc<AnyTransport>,
    log: Option<LogTx>,
    t0: Instant,
    shared: Arc<Mutex<Shared>>,
}

impl Link {
    async fn send(&self, m: &Message) -> Result<(), RigError> {
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
                let msg = format!("CAN link {}: {e}", self.transport.name());
                s.counters.last_error = Some(msg.clone());
                if matches!(e, TransportError::Gone(_)) {
                    s.gone.get_or_insert_with(|| msg.clone());
                }
                Err(RigError::Link(msg))
            }
        }
    }

    fn now_us(&self) -> u64 {
        self.t0.elapsed().as_micros() as u64
    }
}

/// The hardware rig backend.
#[derive(Debug)]
pub struct HwBackend {
    layout: DaqLayout,
    opts: HwOptions,
    link: Link,
    format: BlockFormat,
    blocks: mpsc::Receiver<Result<DaqBlock, RigError>>,
    blocks_tx: Option<mpsc::Sender<Result<DaqBlock, RigError>>>,
    tasks: Vec<JoinHandle<()>>,
    ldv: SerialClient,
    amp: SerialClient,
    amp_status: Arc<Mutex<Option<AmplifierStatus>>>,
    log: Option<CandumpLog>,
    consumed: Arc<AtomicU32>,
    host_counter: Arc<AtomicU32>,
    setpoint_seq: u16,
    status: RigStatus,
    started: bool,
    stopped: bool,
}

fn config(e: impl std::fmt::Display) -> RigError {
    RigError::Config(e.to_string())
}

impl HwBackend {
    /// Opens the CAN link and both serial ports and waits for the device's first heartbeat.
    /// `layout` is the rig description's channel map: every block header is checked against
    /// it. Must be called inside a tokio runtime.
    pub async fn connect(layout: DaqLayout, opts: HwOptions) -> Result<HwBackend, RigError> {
        let format = BlockFormat::of(&layout).map_err(config)?;
        if layout.indices_of(ChannelKind::Vibrometer).len() != 1 {
            return Err(config(
                "the hardware backend needs exactly one vibrometer channel in the channel map",
            ));
        }
        let transport = AnyTransport::open(&opts.can)
            .await
            .map_err(|e| RigError::Config(format!("--can: {e}")))?;
        let log = opts
            .can_log
            .as_ref()
            .map(|p| {
                CandumpLog::create(p).map_err(|e| config(format!("--can-log {}: {e}", p.display())))
            })
            .transpose()?;
        let t0 = Instant::now();
        let shared = Arc::new(Mutex::new(Shared {
            counters: LinkCounters::default(),
            drives: VecDeque::new(),
            faults: Vec::new(),
            last_device_heartbeat: t0,
            device_heartbeats: 0,
            gone: None,
        }));
        let link = Link {
            transport: Arc::new(transport),
            log: log.as_ref().and_then(CandumpLog::sender),
            t0,
            shared: shared.clone(),
        };
        let (ldv, amp, amp_status) = open_serial(&opts, &layout, &shared)?;
        let (blocks_tx, blocks) = mpsc::channel(256);
        let mut b = HwBackend {
            layout,
            opts,
            link,
            format,
            blocks,
            blocks_tx: Some(blocks_tx),
            tasks: Vec::new(),
            ldv,
            amp,
            amp_status,
            log,
            consumed: Arc::new(AtomicU32::new(NO_BLOCK)),
            host_counter: Arc::new(AtomicU32::new(0)),
            setpoint_seq: 0,
            status: RigStatus::default(),
            started: false,
            stopped: false,
        };
        b.spawn_tasks();
        // The device learns where we are from our first frame; wait for its heartbeat.
        let wait = b.opts.heartbeat_timeout.max(Duration::from_millis(1000));
        let deadline = Instant::now() + wait;
        loop {
            b.heartbeat_now().await?;
            if lock(&b.link.shared).device_heartbeats > 0 {
                break;
            }
            if let Some(g) = lock(&b.link.shared).gone.clone() {
                return Err(RigError::Link(g));
            }
            if Instant::now() >= deadline {
                return Err(RigError::Link(format!(
                    "CAN link {}: no DEVICE_HEARTBEAT within {:.1} s: is the rig (or \
                     `rigtwin firmware-sim`) running and listening there?",
                    b.link.transport.name(),
                    wait.as_secs_f64()
                )));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok(b)
    }

    async fn heartbeat_now(&self) -> Result<(), RigError> {
        let counter = self.host_counter.fetch_add(1, Ordering::Relaxed);
        self.link
            .send(&Message::HostHeartbeat(HostHeartbeat {
                counter,
                consumed: self.consumed.load(Ordering::Relaxed),
            }))
            .await
    }

    fn spawn_tasks(&mut self) {
        let tx = self.blocks_tx.clone().expect("before stop");
        let rx_task = receiver(
            self.link.clone(),
            Reassembler::new(self.format, self.layout.sample_rate),
            self.layout.clone(),
            tx.clone(),
        );
        self.tasks.push(tokio::spawn(rx_task));
        self.tasks.push(tokio::spawn(heartbeats(
            self.link.clone(),
            self.opts.heartbeat_period,
            self.opts.heartbeat_timeout,
            self.consumed.clone(),
            self.host_counter.clone(),
            tx,
        )));
    }

    /// Link counters so far (CAN and serial).
    pub fn counters(&self) -> LinkCounters {
        let mut c = lock(&self.link.shared).counters.clone();
        for s in [self.ldv.stats(), self.amp.stats()] {
            c.serial_timeouts += s.timeouts;
            c.serial_checksum_errors += s.checksum_errors;
            c.serial_garbage += s.garbage;
            if c.last_error.is_none() {
                c.last_error = s.last_error;
            }
        }
        c
    }

    async fn serial(&self, client: &SerialClient, req: &str) -> Result<Vec<String>, RigError> {
        client.request(req).await.map_err(|e| match e {
            SerialError::Gone { .. } => RigError::Link(e.to_string()),
            _ => RigError::Config(e.to_string()),
        })
    }

    /// Flushes and closes the candump log (after stop).
    fn close_log(&mut self) -> Result<(), RigError> {
        self.link.log = None;
        for t in self.tasks.drain(..) {
            t.abort();
        }
        match self.log.take() {
            Some(l) => l
                .close()
                .map_err(|e| RigError::Link(format!("--can-log: {e}"))),
            None => Ok(()),
        }
    }
}

/// The two serial clients and the amplifier's last status.
type SerialLinks = (
    SerialClient,
    SerialClient,
    Arc<Mutex<Option<AmplifierStatus>>>,
);

fn open_serial(
    opts: &HwOptions,
    layout: &DaqLayout,
    shared: &Arc<Mutex<Shared>>,
) -> Result<SerialLinks, RigError> {
    let ldv_port = port::open(&opts.ldv, 115_200)
        .map_err(|e| config(format!("--ldv (vibrometer controller): {e}")))?;
    let amp_port =
        port::open(&opts.amp, 9600).map_err(|e| config(format!("--amp (power amplifier): {e}")))?;
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
async fn receiver(
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
                let msg = format!("CAN link {}: {e}", link.transport.name());
                lock(&link.shared).gone.get_or_insert_with(|| msg.clone());
                let _ = blocks.send(Err(RigError::Link(msg))).await;
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
                            fatal = Some(RigError::Config(e.to_string()));
                        }
                        while let Some(b) = reasm.pop() {
                            ready.push(b);
                        }
                        let c = reasm.counters();
                        s.counters.sequence_gaps = c.sequence_gaps;
                        s.counters.reordered = c.reordered;
                        s.counters.duplicates = c.duplicates;
                        s.counters.crc_errors = c.crc_errors;
                        // Sample-frame problems are malformed frames too (kept in sync).
                        s.counters.malformed = s.counters.malformed.max(c.malformed);
                    }
                    Message::DriveStatus(d) => {
                        s.drives.push_back((d.block_seq, d.drive()));
                        if s.drives.len() > 16 {
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
async fn heartbeats(
    link: Link,
    period: Duration,
    timeout: Duration,
    consumed: Arc<AtomicU32>,
    counter: Arc<AtomicU32>,
    blocks: mpsc::Sender<Result<DaqBlock, RigError>>,
) {
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let per_second = (1.0 / period.as_secs_f64()).round().max(1.0) as u64;
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
            if since > period.mul_f64(1.5) && last_counted != Some(s.device_heartbeats) {
                s.counters.heartbeat_misses += 1;
            }
            if since > period.mul_f64(1.5) {
                last_counted = None;
            } else {
                last_counted = Some(s.device_heartbeats);
            }
            if since > timeout && s.gone.is_none() {
                let msg = format!(
                    "CAN link {}: no DEVICE_HEARTBEAT for {:.2} s (timeout {:.2} s): the rig DAQ \
                     is gone",
                    link.transport.name(),
                    since.as_secs_f64(),
                    timeout.as_secs_f64()
                );
                s.gone = Some(msg.clone());
                s.counters.last_error = Some(msg.clone());
                Some(msg)
            } else {
                None
            }
        };
        if let Some(msg) = lost {
            let _ = blocks.send(Err(RigError::Link(msg))).await;
        }
    }
}

impl RigBackend for HwBackend {
    fn layout(&self) -> &DaqLayout {
        &self.layout
    }

    async fn start(&mut self) -> Result<(), RigError> {
        if self.started {
            return Err(RigError::State("already started".into()));
        }
        // Vibrometer: the range that makes its output match the channel map's full scale.
        let vib = &self.layout.channels[self.layout.indices_of(ChannelKind::Vibrometer)[0]];
        let full_scale = vib.scale * (f64::from(vib.full_scale_counts) + 1.0);
        let range_mm_s = (full_scale * 1000.0).round() as u32;
        self.serial(&self.ldv, &format!("RANGE {range_mm_s}"))
            .await?;
        self.serial(
            &self.ldv,
            &format!("FILTER {}", self.opts.vibrometer_filter_hz),
        )
        .await?;
        self.serial(&self.ldv, "CLEAR").await?;
        let st =
            VibrometerStatus::parse(&self.serial(&self.ldv, "STATUS").await?).map_err(config)?;
        if st.range_mm_s != range_mm_s {
            return Err(config(format!(
                "vibrometer ({}): RANGE {} mm/s after setting {range_mm_s} mm/s (the channel \
                 map's full scale of {})",
                self.opts.ldv, st.range_mm_s, vib.name
            )));
        }
        // Amplifier: its gain must be the rig description's.
        let gain = self.serial(&self.amp, "GAIN").await?;
        let gain: f64 = gain.first().and_then(|g| g.parse().ok()).ok_or_else(|| {
            config(format!(
                "power amplifier ({}): GAIN answer {gain:?}",
                self.opts.amp
            ))
        })?;
        let want = self.opts.amplifier_gain;
        if (gain - want).abs() > 1e-9 * want.abs().max(1.0) {
            return Err(config(format!(
                "power amplifier ({}): gain {gain} V/V, but the rig description says \
                 shaker.amplifier_gain = {want}: set the amplifier or the description",
                self.opts.amp
            )));
        }
        self.serial(&self.amp, "CLEAR").await?;
        self.serial(&self.amp, "ENABLE 1").await?;
        self.link
            .send(&Message::StreamControl(StreamControl {
                command: StreamCommand::Start,
                session: (self.link.now_us() & 0xFFFF_FFFF) as u32,
            }))
            .await?;
        // A first time sync right away (then once per second).
        self.link
            .send(&Message::TimeSyncRequest(TimeSyncRequest {
                seq: 0,
                host_time_us: self.link.now_us(),
            }))
            .await?;
        self.started = true;
        self.status.running = true;
        Ok(())
    }

    async fn set_drive(&mut self, command: DriveCommand) -> Result<(), RigError> {
        let sp =
            DriveSetpoint::from_command(self.setpoint_seq, &command).map_err(RigError::Command)?;
        if !(command.ramp_s.is_finite() && command.amplitude_v.is_finite()) {
            return Err(RigError::Command(format!("{command:?}")));
        }
        self.setpoint_seq = self.setpoint_seq.wrapping_add(1);
        self.link.send(&Message::DriveSetpoint(sp)).await
    }

    async fn next_block(&mut self) -> Result<Option<DaqBlock>, RigError> {
        if !self.started {
            return Err(RigError::State("next_block before start".into()));
        }
        if let Some(g) = lock(&self.link.shared).gone.clone() {
            return Err(RigError::Link(g));
        }
        let b = match self.blocks.recv().await {
            Some(Ok(b)) => b,
            Some(Err(e)) => return Err(e),
            None => return Ok(None),
        };
        self.consumed.store(b.seq as u32, Ordering::Relaxed);
        // Tells the device at once (flow control of `firmware-sim --pace virtual`).
        let _ = self.heartbeat_now().await;
        let end = b.time + b.len as f64 / self.layout.sample_rate;
        let (drive, faults) = {
            let s = lock(&self.link.shared);
            let d = s
                .drives
                .iter()
                .rev()
                .find(|(q, _)| u64::from(*q) <= b.seq)
                .map(|x| x.1);
            (d, s.faults.clone())
        };
        self.status.time = end;
        if let Some(d) = drive {
            self.status.drive = d;
        }
        self.status.faults = faults;
        Ok(Some(b))
    }

    fn status(&self) -> RigStatus {
        let mut s = self.status.clone();
        s.faults = lock(&self.link.shared).faults.clone();
        s.link = Some(self.counters());
        s
    }

    async fn stop(&mut self) -> Result<(), RigError> {
        if self.stopped {
            return Ok(());
        }
        self.stopped = true;
        // Amplifier off first, serial links closed, then the stream: the device may go away
        // once the stream stops.
        let amp = self.amp.request("ENABLE 0").await;
        self.ldv.close();
        self.amp.close();
        let stop = self
            .link
            .send(&Message::StreamControl(StreamControl {
                command: StreamCommand::Stop,
                session: 0,
            }))
            .await;
        self.status.running = false;
        self.status.drive.amplitude_v = 0.0;
        self.status.drive.target_amplitude_v = 0.0;
        // Let the last frames in flight reach the log.
        tokio::time::sleep(Duration::from_millis(50)).await;
        self.blocks_tx.take();
        let log = self.close_log();
        if let Some(st) = *self.amp_status.lock().unwrap_or_else(|e| e.into_inner()) {
            tracing::debug!("last amplifier status: {st:?}");
        }
        stop?;
        amp.map_err(|e| RigError::Link(e.to_string()))?;
        log
    }
}

impl Drop for HwBackend {
    fn drop(&mut self) {
        for t in self.tasks.drain(..) {
            t.abort();
        }
    }
}
