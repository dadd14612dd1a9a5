//! The other end of the hardware links, driven by the simulated rig: `rigtwin firmware-sim`.
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

use crate::rig::hw::can::transport::UdpTunnel;
use crate::rig::hw::serial::protocol::{AmplifierStatus, VibrometerStatus};
use crate::rig::sim::SimRig;
use crate::rig::ChannelKind;

pub use faults::{Inject, LinkFault};
pub use serial::Port;
use serial::{Devices, Misbehaviour};
use session::Session;

/// How the device paces its blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// Block k leaves no earlier than the wall time of its last sample.
    Realtime,
    /// As fast as possible, at most three blocks ahead of the host (so that a lost block is
    /// detected: the host declares block s lost when the header of s + 2 arrives).
    Virtual,
}

/// Device settings.
#[derive(Clone, Debug)]
pub struct FirmwareOptions {
    /// UDP address to listen on for the CAN tunnel.
    pub listen: SocketAddr,
    /// Pacing.
    pub pace: Pace,
    /// DEVICE_HEARTBEAT period (default 100 ms).
    pub heartbeat_period: Duration,
    /// HOST_HEARTBEAT timeout (default 500 ms).
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

fn pty() -> Result<(serialport::TTYPort, serialport::TTYPort, String), String> {
    use serialport::SerialPort;
    let (mut master, slave) =
        serialport::TTYPort::pair().map_err(|e| format!("creating a pseudo-terminal: {e}"))?;
    master
        .set_timeout(Duration::from_millis(20))
        .map_err(|e| format!("pseudo-terminal: {e}"))?;
    let name = slave
        .name()
        .ok_or_else(|| "pseudo-terminal without a name".to_string())?;
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
    ) -> Result<FirmwareSim, String> {
        let tunnel = UdpTunnel::listen(opts.listen)
            .await
            .map_err(|e| e.to_string())?;
        let can_addr = tunnel
            .local_addr()
            .ok_or_else(|| "UDP tunnel: no local address".to_string())?;
        let layout = rig.layout();
        let vib = layout
            .indices_of(ChannelKind::Vibrometer)
            .first()
            .map(|&k| &layout.channels[k])
            .ok_or_else(|| "the channel map has no vibrometer channel".to_string())?;
        let range = vib.scale * (f64::from(vib.full_scale_counts) + 1.0);
        let devices = Arc::new(Mutex::new(Devices {
            vib: VibrometerStatus {
                range_mm_s: (range * 1000.0).round() as u32,
                filter_hz: 5000,
                level: 87,
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
                    .map_err(|e| e.to_string())?,
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
    pub async fn run(&mut self, mut on_end: impl FnMut(&SessionReport)) -> Result<(), String> {
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
