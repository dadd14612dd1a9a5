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
//! heartbeat lost, interlock, amplifier overload, over-range) become [`RigFault`](crate::rig::daq::RigFault)s or
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
    ChannelKind, CommandError, DaqBlock, DaqLayout, DriveCommand, LinkCounters, RigBackend,
    RigError, RigStatus, StateError,
};

mod tasks;

use tasks::{heartbeats, lock, open_serial, receiver, Link, Shared};

use super::can::block::{BlockFormat, Reassembler};
use super::can::candump::CandumpLog;
use super::can::messages::{
    DriveSetpoint, HostHeartbeat, Message, StreamCommand, StreamControl, TimeSyncRequest,
    FIRST_HEARTBEAT_WAIT, HEARTBEAT_PERIOD, HEARTBEAT_TIMEOUT, NO_BLOCK,
};
use super::can::transport::{AnyTransport, CanAddress, CanTransport};
use super::serial::port::{SerialClient, SerialError};
use super::serial::protocol::{AmplifierStatus, VibrometerStatus};
use super::{ConfigError, LinkError};

/// Default serial answer timeout.
pub const DEFAULT_SERIAL_TIMEOUT: Duration = Duration::from_millis(250);
/// Default serial STATUS poll period.
pub const DEFAULT_SERIAL_POLL: Duration = Duration::from_millis(200);
/// Default vibrometer output filter, Hz (the default DAQ's anti-alias cutoff).
pub const DEFAULT_VIBROMETER_FILTER_HZ: u32 = 5000;
/// Pause between HOST_HEARTBEATs while waiting for the device's first heartbeat.
const CONNECT_RETRY: Duration = Duration::from_millis(50);
/// Pause after STREAM_CONTROL stop so the last frames in flight reach the candump log.
const STOP_DRAIN: Duration = Duration::from_millis(50);
/// Reassembled blocks queued for [`RigBackend::next_block`] (bounded: backpressure on the
/// receiver task).
const BLOCK_QUEUE: usize = 256;

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
    /// [`HEARTBEAT_PERIOD`] (100 ms).
    pub heartbeat_period: Duration,
    /// No DEVICE_HEARTBEAT for this long: the link is lost. Default [`HEARTBEAT_TIMEOUT`]
    /// (500 ms).
    pub heartbeat_timeout: Duration,
    /// Serial answer timeout. Default [`DEFAULT_SERIAL_TIMEOUT`] (250 ms).
    pub serial_timeout: Duration,
    /// Serial STATUS poll period. Default [`DEFAULT_SERIAL_POLL`] (200 ms).
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
            heartbeat_period: HEARTBEAT_PERIOD,
            heartbeat_timeout: HEARTBEAT_TIMEOUT,
            serial_timeout: DEFAULT_SERIAL_TIMEOUT,
            serial_poll: DEFAULT_SERIAL_POLL,
            amplifier_gain,
            vibrometer_filter_hz: DEFAULT_VIBROMETER_FILTER_HZ,
        }
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

impl HwBackend {
    /// Opens the CAN link and both serial ports and waits for the device's first heartbeat.
    /// `layout` is the rig description's channel map: every block header is checked against
    /// it. Must be called inside a tokio runtime.
    pub async fn connect(layout: DaqLayout, opts: HwOptions) -> Result<HwBackend, RigError> {
        let format =
            BlockFormat::of(&layout).map_err(|e| RigError::config(ConfigError::Format(e)))?;
        let vibrometers = layout.indices_of(ChannelKind::Vibrometer).len();
        if vibrometers != 1 {
            return Err(RigError::config(ConfigError::Vibrometers {
                count: vibrometers,
            }));
        }
        let transport = AnyTransport::open(&opts.can)
            .await
            .map_err(|e| RigError::config(ConfigError::Can(e)))?;
        let log = opts
            .can_log
            .as_ref()
            .map(|p| {
                CandumpLog::create(p).map_err(|error| {
                    RigError::config(ConfigError::CanLog {
                        path: p.clone(),
                        error,
                    })
                })
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
        let (blocks_tx, blocks) = mpsc::channel(BLOCK_QUEUE);
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
        let wait = b.opts.heartbeat_timeout.max(FIRST_HEARTBEAT_WAIT);
        let deadline = Instant::now() + wait;
        loop {
            b.heartbeat_now().await?;
            if lock(&b.link.shared).device_heartbeats > 0 {
                break;
            }
            if let Some(g) = lock(&b.link.shared).gone.clone() {
                return Err(RigError::link(g));
            }
            if Instant::now() >= deadline {
                return Err(RigError::link(LinkError::NoDevice {
                    link: b.link.transport.name(),
                    wait_s: wait.as_secs_f64(),
                }));
            }
            tokio::time::sleep(CONNECT_RETRY).await;
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
            SerialError::Gone { .. } => RigError::link(LinkError::Serial(e)),
            _ => RigError::config(ConfigError::Serial(e)),
        })
    }

    /// Flushes and closes the candump log (after stop).
    fn close_log(&mut self) -> Result<(), RigError> {
        self.link.log = None;
        for t in self.tasks.drain(..) {
            t.abort();
        }
        match self.log.take() {
            Some(l) => l.close().map_err(|e| {
                RigError::link(LinkError::CanLog {
                    error: e.to_string(),
                })
            }),
            None => Ok(()),
        }
    }
}

impl RigBackend for HwBackend {
    fn layout(&self) -> &DaqLayout {
        &self.layout
    }

    async fn start(&mut self) -> Result<(), RigError> {
        if self.started {
            return Err(RigError::State(StateError::AlreadyStarted));
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
        let st = VibrometerStatus::parse(&self.serial(&self.ldv, "STATUS").await?)
            .map_err(|e| RigError::config(ConfigError::Status(e)))?;
        if st.range_mm_s != range_mm_s {
            return Err(RigError::config(ConfigError::VibrometerRange {
                port: self.opts.ldv.clone(),
                range_mm_s: st.range_mm_s,
                set_mm_s: range_mm_s,
                channel: vib.name.clone(),
            }));
        }
        // Amplifier: its gain must be the rig description's.
        let gain = self.serial(&self.amp, "GAIN").await?;
        let gain: f64 = gain.first().and_then(|g| g.parse().ok()).ok_or_else(|| {
            RigError::config(ConfigError::GainAnswer {
                port: self.opts.amp.clone(),
                answer: gain.clone(),
            })
        })?;
        let want = self.opts.amplifier_gain;
        if (gain - want).abs() > 1e-9 * want.abs().max(1.0) {
            return Err(RigError::config(ConfigError::Gain {
                port: self.opts.amp.clone(),
                gain,
                want,
            }));
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
            DriveSetpoint::from_command(self.setpoint_seq, &command).map_err(RigError::command)?;
        if !(command.ramp_s.is_finite() && command.amplitude_v.is_finite()) {
            return Err(RigError::command(CommandError::Invalid { command }));
        }
        self.setpoint_seq = self.setpoint_seq.wrapping_add(1);
        self.link.send(&Message::DriveSetpoint(sp)).await
    }

    async fn next_block(&mut self) -> Result<Option<DaqBlock>, RigError> {
        if !self.started {
            return Err(RigError::State(StateError::NotStarted));
        }
        if let Some(g) = lock(&self.link.shared).gone.clone() {
            return Err(RigError::link(g));
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
        tokio::time::sleep(STOP_DRAIN).await;
        self.blocks_tx.take();
        let log = self.close_log();
        if let Some(st) = *self.amp_status.lock().unwrap_or_else(|e| e.into_inner()) {
            tracing::debug!("last amplifier status: {st:?}");
        }
        stop?;
        amp.map_err(|e| RigError::link(LinkError::Serial(e)))?;
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
