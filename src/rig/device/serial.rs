//! The device side of both serial links: a thread per pseudo-terminal answers the vibrometer
//! controller's and the power amplifier's protocol ([`crate::rig::hw::serial::protocol`]) from
//! the shared device state. Lines that fail their checksum or do not parse get no answer (the
//! host times out), as the documented protocol says.

use std::io::{Read, Write};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::rig::hw::serial::line::{encode_line, LineReader};
use crate::rig::hw::serial::protocol::{
    format_reply, parse_request, AmplifierStatus, Reply, VibrometerStatus,
};

/// Which serial device.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Port {
    /// The vibrometer controller.
    Ldv,
    /// The power amplifier.
    Amp,
}

/// Serial misbehaviour to inject (tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Misbehaviour {
    /// Stop answering.
    pub silent: bool,
    /// Before the next answer: garbage bytes and a line with a wrong checksum (once).
    pub garbage: bool,
}

/// What the serial devices and the rig loop share.
#[derive(Clone, Debug)]
pub struct Devices {
    /// Vibrometer state.
    pub vib: VibrometerStatus,
    /// Amplifier state.
    pub amp: AmplifierStatus,
    /// Per port (ldv, amp).
    pub misbehaviour: [Misbehaviour; 2],
    /// Lines received that failed (checksum, garbage, unknown request).
    pub rx_errors: u64,
    /// The host sent the amplifier `ENABLE 0` (since the session started).
    pub host_disabled_amp: bool,
}

/// Pause after a read that returned nothing before reading again.
const IDLE_POLL: Duration = Duration::from_millis(5);
/// Pause after a port error (no client holds the other end yet, or a write failed).
const PORT_RETRY: Duration = Duration::from_millis(20);

/// Allowed vibrometer output filters, Hz.
pub const FILTERS_HZ: [u32; 5] = [1000, 2560, 5000, 20000, 100000];

fn handle(port: Port, d: &mut Devices, verb: &str, arg: Option<&str>) -> Reply {
    let ok = |verb: &str, values: Vec<String>| Reply::Ok {
        verb: verb.to_string(),
        values,
    };
    let err = |code: u8, text: String| Reply::Err { code, text };
    match (port, verb, arg) {
        (Port::Ldv, "IDN", None) => ok("IDN", vec!["rigtwin-firmware-sim-LDV".into()]),
        (Port::Amp, "IDN", None) => ok("IDN", vec!["rigtwin-firmware-sim-AMP".into()]),
        (Port::Ldv, "RANGE", Some(a)) => match a.parse::<u32>() {
            Ok(r) if (1..=10_000_000).contains(&r) => {
                d.vib.range_mm_s = r;
                ok("RANGE", vec![r.to_string()])
            }
            _ => err(2, format!("RANGE {a}: expected 1..=10000000 mm/s")),
        },
        (Port::Ldv, "FILTER", Some(a)) => match a.parse::<u32>() {
            Ok(f) if FILTERS_HZ.contains(&f) => {
                d.vib.filter_hz = f;
                ok("FILTER", vec![f.to_string()])
            }
            _ => err(2, format!("FILTER {a}: expected one of {FILTERS_HZ:?} Hz")),
        },
        (Port::Ldv, "STATUS", None) => ok("STATUS", d.vib.values()),
        (Port::Ldv, "CLEAR", None) => {
            d.vib.over_range = false;
            ok("CLEAR", vec![])
        }
        (Port::Amp, "GAIN", None) => ok("GAIN", vec![d.amp.gain.to_string()]),
        (Port::Amp, "ENABLE", Some(a)) => match a {
            "0" => {
                d.amp.enabled = false;
                d.host_disabled_amp = true;
                ok("ENABLE", vec!["0".into()])
            }
            "1" if d.amp.interlock_open => err(3, "interlock open".into()),
            "1" if d.amp.overload => err(3, "overload latched: CLEAR first".into()),
            "1" => {
                d.amp.enabled = true;
                ok("ENABLE", vec!["1".into()])
            }
            _ => err(2, format!("ENABLE {a}: expected 0 or 1")),
        },
        (Port::Amp, "STATUS", None) => ok("STATUS", d.amp.values()),
        (Port::Amp, "CLEAR", None) => {
            d.amp.overload = false;
            ok("CLEAR", vec![])
        }
        _ => err(
            1,
            format!(
                "unknown command {verb}{}",
                arg.map_or(String::new(), |a| format!(" {a}"))
            ),
        ),
    }
}

/// Serves one device on `port` (the pty master) until `stop` is set or the port fails.
pub fn serve(
    which: Port,
    mut port: serialport::TTYPort,
    devices: Arc<Mutex<Devices>>,
    stop: Arc<std::sync::atomic::AtomicBool>,
) {
    let mut reader = LineReader::new();
    let mut buf = [0u8; 256];
    let k = which as usize;
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let n = match port.read(&mut buf) {
            Ok(0) => {
                std::thread::sleep(IDLE_POLL);
                continue;
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) => {
                // EIO while no one holds the other end open: wait for a client.
                std::thread::sleep(PORT_RETRY);
                continue;
            }
        };
        for line in reader.push(&buf[..n]) {
            let mut d = devices.lock().unwrap_or_else(|e| e.into_inner());
            let Ok(body) = line else {
                d.rx_errors += 1;
                continue;
            };
            let Ok(req) = parse_request(&body) else {
                d.rx_errors += 1;
                continue;
            };
            if d.misbehaviour[k].silent {
                continue;
            }
            let reply = handle(which, &mut d, &req.verb, req.arg.as_deref());
            let mut out = Vec::new();
            if std::mem::take(&mut d.misbehaviour[k].garbage) {
                out.extend_from_slice(b"\x00\xfe\x13 noise\n");
                let bad = format_reply(req.tag, &reply);
                let l = encode_line(&bad).unwrap_or_default();
                // Same line, checksum off by one digit.
                let mut l = l.into_bytes();
                if let Some(p) = l.len().checked_sub(2) {
                    l[p] = if l[p] == b'0' { b'1' } else { b'0' };
                }
                out.extend_from_slice(&l);
            }
            drop(d);
            if let Ok(l) = encode_line(&format_reply(req.tag, &reply)) {
                out.extend_from_slice(l.as_bytes());
            }
            if port.write_all(&out).and_then(|_| port.flush()).is_err() {
                std::thread::sleep(PORT_RETRY);
            }
        }
    }
}
