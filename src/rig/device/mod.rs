//! The rig's electronics emulated: the other end of the hardware links, driven by the
//! simulated rig (`rigtwin firmware-sim`). It sits beside the backends: it uses the link
//! codecs of [`crate::rig::hw`] and the simulated rig of [`crate::rig::sim`]; the hardware
//! backend knows nothing of it.
//!
//! It speaks exactly the protocols of `firmware-interfaces/` — the CAN FD messages of
//! `rig.dbc` over the UDP tunnel, the vibrometer and amplifier protocols over two
//! pseudo-terminals — so `rigtwin run --backend hw` runs the whole hardware path here.
//!
//! Behaviour of the device (as the README's sequencing rules say): STREAM_CONTROL start
//! restarts the DAQ at block 0 with the drive at zero (a fresh copy of the simulated rig);
//! per block it sends DRIVE_STATUS, DAQ_BLOCK_HEADER and the DAQ_SAMPLES frames; setpoints
//! apply from the next block computed; DEVICE_HEARTBEAT every heartbeat period; when no
//! HOST_HEARTBEAT arrives for the heartbeat timeout it raises FAULT HEARTBEAT_LOST and ramps
//! the drive down itself (the rig must be safe when the host dies), then stops streaming. The
//! drive is also ramped down when the amplifier is disabled or the interlock opens.
//!
//! Pacing: `Realtime` sends block `k` no earlier than the wall time of its last sample (a
//! real DAQ); `Virtual` computes as fast as it can but at most three blocks ahead of the host's
//! `HOST_HEARTBEAT.ConsumedSeq` (flow control for tests; real hardware ignores that field).
//! Faults can be injected ([`Inject`]): the simulated rig's own, and link faults (dropped,
//! swapped, corrupted and malformed frames, serial garbage and silence, the interlock, a
//! hung or vanishing device).

pub mod faults;
pub mod serial;
mod session;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::rig::hw::can::block::SplitError;
use crate::rig::hw::can::transport::{TransportError, UdpTunnel};
use crate::rig::hw::serial::protocol::{AmplifierStatus, VibrometerStatus};
use crate::rig::sim::{SimRig, SimRigError};
use crate::rig::ChannelKind;

pub use crate::rig::hw::can::messages::{HEARTBEAT_PERIOD, HEARTBEAT_TIMEOUT};

/// Blocks the device computes ahead of the host's `HOST_HEARTBEAT.ConsumedSeq` with
/// [`Pace::Virtual`] (the host declares block s lost when the header of s + 2 arrives).
pub const VIRTUAL_LEAD_BLOCKS: i64 = 3;
/// Read timeout of the pseudo-terminal masters (how often a serial thread checks for stop).
const PTY_READ_TIMEOUT: Duration = Duration::from_millis(20);
/// The vibrometer's output filter at power-up, Hz.
const POWER_UP_FILTER_HZ: u32 = 5000;
/// The vibrometer's signal level reported, %.
const SIGNAL_LEVEL: u8 = 87;

/// Why the device could not start or serve a session.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// The UDP tunnel could not be bound.
    #[error("{0}")]
    Tunnel(TransportError),
    /// The bound tunnel has no local address.
    #[error("UDP tunnel: no local address")]
    NoLocalAddress,
    /// The simulated rig's channel map has no vibrometer.
    #[error("the channel map has no vibrometer channel")]
    NoVibrometer,
    /// A pseudo-terminal could not be created or set up.
    #[error("{what}: {error}")]
    Pty {
        /// What failed.
        what: &'static str,
        /// What `serialport` said.
        error: serialport::Error,
    },
    /// A pseudo-terminal without a name.
    #[error("pseudo-terminal without a name")]
    PtyName,
    /// A serial device's thread could not be started.
    #[error("{0}")]
    Thread(std::io::Error),
    /// The simulated rig rejected an injected fault or a drive command.
    #[error("{0}")]
    Rig(SimRigError),
    /// A block could not be split into frames.
    #[error("{0}")]
    Split(SplitError),
    /// The simulated rig's block computation panicked or was cancelled.
    #[error("simulated rig: {0}")]
    Task(tokio::task::JoinError),
}

pub use faults::{Inject, LinkFault};
pub use serial::Port;
use serial::{Devices, Misbehaviour};
use session::Session;

/// How the device paces its blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// Block k leaves no earlier than the wall time of its last sample.
    Realtime,
    /// As fast as possible, at most [`VIRTUAL_LEAD_BLOCKS`] blocks ahead of the host (so that
    /// a lost block is detected: the host declares block s lost when the header of s + 2
    /// arrives).
    Virtual,
}

/// Device settings.
#[derive(Clone, Debug)]
pub struct FirmwareOptions {
    /// UDP address to listen on for the CAN tunnel.
    pub listen: SocketAddr,
    /// Pacing.
    pub pace: Pace,
    /// DEVICE_HEARTBEAT period (default [`HEARTBEAT_PERIOD`], 100 ms).
    pub heartbeat_period: Duration,
    /// HOST_HEARTBEAT timeout (default [`HEARTBEAT_TIMEOUT`], 500 ms).
    pub heartbeat_timeout: Duration,
    /// Safety ramp-down time, s (default 0.5).
    pub ramp_down_s: f64,
    /// Serve one session, then return.
    pub once: bool,
    /// Faults to inject.
    pub inject: Vec<Inject>,
}

/// Where the device can be reached (printed as one JSON line by `rigtwin firmware-sim`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Endpoints {
    /// `--can` argument for the host.
    pub can: String,
    /// The UDP address.
    pub can_addr: SocketAddr,
    /// Vibrometer controller pty (`--ldv`).
    pub ldv: String,
    /// Amplifier pty (`--amp`).
    pub amp: String,
}

/// How a session ended (printed as JSON).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SessionReport {
    /// "stop" (host stopped it) or "heartbeat_lost".
    pub reason: String,
    /// Blocks sent.
    pub blocks: u64,
    /// CAN frames sent.
    pub frames_sent: u64,
    /// CAN frames received.
    pub frames_received: u64,
    /// Malformed frames received.
    pub rx_errors: u64,
    /// Serial lines rejected.
    pub serial_rx_errors: u64,
    /// Drive amplitude at the end, V.
    pub final_amplitude_v: f64,
    /// Drive amplitude when the heartbeat was lost, V.
    pub amplitude_at_loss_v: Option<f64>,
    /// Blocks sent during the safety ramp-down.
    pub safety_ramp_blocks: u64,
    /// Setpoints received.
    pub setpoints: u64,
    /// The last valid drive setpoint received (a host's ramp-down: amplitude 0 over its ramp
    /// time).
    pub last_setpoint: Option<SetpointReport>,
    /// Rig time when the host's STREAM_CONTROL stop arrived, s (`None`: no stop).
    pub stopped_at_s: Option<f64>,
    /// Drive amplitude when the stop arrived, before the device switched the drive off, V:
    /// 0 when the host had ramped it down.
    pub amplitude_at_stop_v: Option<f64>,
    /// The host switched the amplifier off (`ENABLE 0` on its serial link) during the session.
    pub amp_disabled_by_host: bool,
}

/// A drive setpoint as the device received it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SetpointReport {
    /// Target amplitude, V.
    pub amplitude_v: f64,
    /// Ramp time to the target, s.
    pub ramp_s: f64,
    /// Rig time of its arrival, s.
    pub at_s: f64,
}

/// The device: a simulated rig behind the documented links.
pub struct FirmwareSim {
    rig: SimRig,
    opts: FirmwareOptions,
    tunnel: Arc<UdpTunnel>,
    devices: Arc<Mutex<Devices>>,
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
    endpoints: Endpoints,
    /// Kept open so the pty masters never see a hang-up before a host connects.
    _slaves: Vec<serialport::TTYPort>,
}

impl std::fmt::Debug for FirmwareSim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FirmwareSim")
            .field("endpoints", &self.endpoints)
            .finish()
    }
}

fn pty() -> Result<(serialport::TTYPort, serialport::TTYPort, String), DeviceError> {
    use serialport::SerialPort;
    let (mut master, slave) = serialport::TTYPort::pair().map_err(|error| DeviceError::Pty {
        what: "creating a pseudo-terminal",
        error,
    })?;
    master
        .set_timeout(PTY_READ_TIMEOUT)
        .map_err(|error| DeviceError::Pty {
            what: "pseudo-terminal",
            error,
        })?;
    let name = slave.name().ok_or(DeviceError::PtyName)?;
    Ok((master, slave, name))
}

impl FirmwareSim {
    /// Binds the tunnel, creates both pseudo-terminals and starts the serial devices.
    /// `amplifier_gain` and `amplifier_limit_v` are what the amplifier reports; the
    /// vibrometer's range starts at the channel map's full scale.
    pub async fn bind(
        rig: SimRig,
        opts: FirmwareOptions,
        amplifier_gain: f64,
        amplifier_limit_v: f64,
    ) -> Result<FirmwareSim, DeviceError> {
        let tunnel = UdpTunnel::listen(opts.listen)
            .await
            .map_err(DeviceError::Tunnel)?;
        let can_addr = tunnel.local_addr().ok_or(DeviceError::NoLocalAddress)?;
        let layout = rig.layout();
        let vib = layout
            .indices_of(ChannelKind::Vibrometer)
            .first()
            .map(|&k| &layout.channels[k])
            .ok_or(DeviceError::NoVibrometer)?;
        let range = vib.scale * (f64::from(vib.full_scale_counts) + 1.0);
        let devices = Arc::new(Mutex::new(Devices {
            vib: VibrometerStatus {
                range_mm_s: (range * 1000.0).round() as u32,
                filter_hz: POWER_UP_FILTER_HZ,
                level: SIGNAL_LEVEL,
                over_range: false,
            },
            amp: AmplifierStatus {
                enabled: false,
                overload: false,
                interlock_open: false,
                gain: amplifier_gain,
                limit_v: amplifier_limit_v,
            },
            misbehaviour: [Misbehaviour::default(); 2],
            rx_errors: 0,
            host_disabled_amp: false,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let (ldv_m, ldv_s, ldv) = pty()?;
        let (amp_m, amp_s, amp) = pty()?;
        let mut threads = Vec::new();
        for (which, master) in [(Port::Ldv, ldv_m), (Port::Amp, amp_m)] {
            let (d, s) = (devices.clone(), stop.clone());
            threads.push(
                std::thread::Builder::new()
                    .name(format!("fw-{which:?}"))
                    .spawn(move || serial::serve(which, master, d, s))
                    .map_err(DeviceError::Thread)?,
            );
        }
        Ok(FirmwareSim {
            rig,
            opts,
            tunnel: Arc::new(tunnel),
            devices,
            stop,
            threads,
            endpoints: Endpoints {
                can: format!("udp:{can_addr}"),
                can_addr,
                ldv,
                amp,
            },
            _slaves: vec![ldv_s, amp_s],
        })
    }

    /// Where to connect.
    pub fn endpoints(&self) -> &Endpoints {
        &self.endpoints
    }

    /// Serves sessions (one with `once`); `on_end` gets each session's report.
    pub async fn run(&mut self, mut on_end: impl FnMut(&SessionReport)) -> Result<(), DeviceError> {
        loop {
            let r = Session::new(self).run().await?;
            on_end(&r);
            if self.opts.once {
                self.stop.store(true, Ordering::Relaxed);
                for t in self.threads.drain(..) {
                    let _ = t.join();
                }
                return Ok(());
            }
        }
    }
}
