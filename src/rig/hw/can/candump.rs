//! The candump log of a session's CAN traffic (`--can-log FILE`): every frame sent and
//! received in the `candump -L` format (`(SECONDS.MICROS) IFACE ID##FDATA` for CAN FD, where F
//! is the flags nibble: 1 = BRS, 2 = ESI), the interface column `tx` or `rx`, plus
//! `FILE.decoded.jsonl`: rigtwin's decoded signal values of the same frames, one JSON object
//! per line in the same order (`{"line": N, "dir": "rx", "id": 256, "name": ...,
//! "signals": {...}}`, or `"error"` for a frame that did not decode). Written on its own
//! thread; `cantools` reads the log against `firmware-interfaces/rig.dbc` (tests).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;

use super::frame::CanFrame;
use super::messages::signal_values;

/// Direction of a logged frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Sent by this side.
    Tx,
    /// Received.
    Rx,
}

/// One candump line for a frame at `t` seconds.
pub fn candump_line(t: f64, dir: Direction, f: &CanFrame) -> String {
    use std::fmt::Write;
    let iface = match dir {
        Direction::Tx => "tx",
        Direction::Rx => "rx",
    };
    let mut s = format!("({t:.6}) {iface} ");
    if f.extended {
        let _ = write!(s, "{:08X}", f.id);
    } else {
        let _ = write!(s, "{:03X}", f.id);
    }
    if f.fd {
        let flags = u8::from(f.brs) | u8::from(f.esi) << 1;
        let _ = write!(s, "##{flags:X}");
    } else {
        s.push('#');
    }
    for b in f.data() {
        let _ = write!(s, "{b:02X}");
    }
    s
}

/// A log writer on its own thread.
#[derive(Debug)]
pub struct CandumpLog {
    tx: Option<mpsc::Sender<(f64, Direction, CanFrame)>>,
    join: Option<JoinHandle<std::io::Result<()>>>,
    path: PathBuf,
}

impl CandumpLog {
    /// Creates `path` and `path.decoded.jsonl`.
    pub fn create(path: &Path) -> std::io::Result<CandumpLog> {
        let mut log = std::io::BufWriter::new(std::fs::File::create(path)?);
        let decoded_path = decoded_path(path);
        let mut dec = std::io::BufWriter::new(std::fs::File::create(&decoded_path)?);
        let (tx, rx) = mpsc::channel::<(f64, Direction, CanFrame)>();
        let join = std::thread::Builder::new()
            .name("candump-log".into())
            .spawn(move || {
                for (n, (t, dir, f)) in rx.into_iter().enumerate() {
                    writeln!(log, "{}", candump_line(t, dir, &f))?;
                    let mut o = serde_json::json!({
                        "line": n,
                        "dir": if dir == Direction::Tx { "tx" } else { "rx" },
                        "id": f.id,
                    });
                    match signal_values(&f) {
                        Ok(values) => {
                            let name = super::messages::def(f.id).map_or("", |d| d.name);
                            o["name"] = name.into();
                            let mut m = serde_json::Map::new();
                            for (k, v) in values {
                                m.insert(
                                    k.to_string(),
                                    serde_json::to_value(v).unwrap_or_default(),
                                );
                            }
                            o["signals"] = m.into();
                        }
                        Err(e) => o["error"] = e.to_string().into(),
                    }
                    writeln!(dec, "{o}")?;
                }
                log.flush()?;
                dec.flush()
            })?;
        Ok(CandumpLog {
            tx: Some(tx),
            join: Some(join),
            path: path.to_path_buf(),
        })
    }

    /// A sender for frames (cheap to clone).
    pub fn sender(&self) -> Option<mpsc::Sender<(f64, Direction, CanFrame)>> {
        self.tx.clone()
    }

    /// Flushes and closes both files once every sender is dropped.
    pub fn close(mut self) -> std::io::Result<()> {
        self.tx.take();
        match self.join.take().map(|j| j.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(std::io::Error::other(format!(
                "candump log {}: writer thread panicked",
                self.path.display()
            ))),
            None => Ok(()),
        }
    }
}

/// The decoded-values file beside a candump log.
pub fn decoded_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".decoded.jsonl");
    PathBuf::from(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_follow_candump_format() {
        let f = CanFrame::fd(0x40, &[1, 2, 3, 4, 5, 6, 7, 0xAB]).unwrap();
        assert_eq!(
            candump_line(1.5, Direction::Tx, &f),
            "(1.500000) tx 040##101020304050607AB"
        );
    }
}
