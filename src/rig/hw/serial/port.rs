//! Serial ports on `serialport` (blocking) and the host's client for a device: a dedicated
//! thread owns the port, answers requests sent over a channel (a tokio oneshot carries the
//! reply back to async code) and polls the device's STATUS when idle, so no port I/O ever runs
//! on the async runtime. Timeouts, checksum errors and garbage are counted; after
//! [`MAX_SILENT`] unanswered requests in a row, or when the port fails, the link is gone.

use std::io::{Read, Write};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::line::{encode_line, LineReader};
use super::protocol::{parse_reply, Reply};

/// Unanswered requests in a row after which the link counts as gone.
pub const MAX_SILENT: u32 = 3;

/// Read timeout of an open port: how long a worker's read waits before it checks its
/// deadlines and requests again.
pub const READ_TIMEOUT: Duration = Duration::from_millis(20);

/// Pause after a read that returned nothing before reading again.
const IDLE_POLL: Duration = Duration::from_millis(5);

/// A serial port that could not be opened.
#[derive(Clone, Debug, thiserror::Error)]
#[error("serial port {path}: {error}")]
pub struct OpenError {
    /// The port's path.
    pub path: String,
    /// What `serialport` said.
    pub error: serialport::Error,
}

/// Opens a serial port (8N1, no flow control) with a short read timeout ([`READ_TIMEOUT`]).
pub fn open(path: &str, baud: u32) -> Result<serialport::TTYPort, OpenError> {
    serialport::new(path, baud)
        .timeout(READ_TIMEOUT)
        .open_native()
        .map_err(|error| OpenError {
            path: path.to_string(),
            error,
        })
}

/// Why a request failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SerialError {
    /// No valid answer in time.
    #[error("{device} ({port}): no answer to {request:?} within {timeout_ms} ms")]
    Timeout {
        /// Device.
        device: &'static str,
        /// Port.
        port: String,
        /// The request body.
        request: String,
        /// The timeout.
        timeout_ms: u64,
    },
    /// The device refused (ERR).
    #[error("{device} ({port}): {request:?} refused: ERR {code} {text}")]
    Refused {
        /// Device.
        device: &'static str,
        /// Port.
        port: String,
        /// The request body.
        request: String,
        /// Code.
        code: u8,
        /// Text.
        text: String,
    },
    /// The port failed or the link is gone.
    #[error("{device} ({port}): link gone: {message}")]
    Gone {
        /// Device.
        device: &'static str,
        /// Port.
        port: String,
        /// What happened.
        message: String,
    },
}

/// What a client counted.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SerialStats {
    /// Requests without an answer in time.
    pub timeouts: u64,
    /// Lines with a bad checksum.
    pub checksum_errors: u64,
    /// Lines that are not protocol lines, answers that do not parse, late answers.
    pub garbage: u64,
    /// Unanswered requests in a row.
    pub silent: u32,
    /// The last problem.
    pub last_error: Option<String>,
    /// The link is gone (port error or MAX_SILENT unanswered requests).
    pub gone: Option<String>,
}

type ReplyTx = tokio::sync::oneshot::Sender<Result<Vec<String>, SerialError>>;

/// The host side of one serial device.
#[derive(Debug)]
pub struct SerialClient {
    tx: Option<mpsc::Sender<(String, ReplyTx)>>,
    join: Option<std::thread::JoinHandle<()>>,
    stats: Arc<Mutex<SerialStats>>,
    device: &'static str,
    port: String,
}

struct Worker {
    port: Box<dyn ReadWrite>,
    reader: LineReader,
    tag: u16,
    timeout: Duration,
    stats: Arc<Mutex<SerialStats>>,
    device: &'static str,
    path: String,
}

/// A port: the real one, or anything readable and writable in tests.
pub trait ReadWrite: Read + Write + Send {}
impl<T: Read + Write + Send> ReadWrite for T {}

impl Worker {
    fn note(&self, f: impl FnOnce(&mut SerialStats)) {
        f(&mut self.stats.lock().unwrap_or_else(|e| e.into_inner()));
    }

    fn gone(&self, message: String) -> SerialError {
        self.note(|s| {
            s.gone.get_or_insert_with(|| message.clone());
            s.last_error = Some(message.clone());
        });
        SerialError::Gone {
            device: self.device,
            port: self.path.clone(),
            message,
        }
    }

    /// One request: returns the OK answer's values.
    fn transact(&mut self, request: &str) -> Result<Vec<String>, SerialError> {
        if let Some(g) = self
            .stats
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .gone
            .clone()
        {
            return Err(SerialError::Gone {
                device: self.device,
                port: self.path.clone(),
                message: g,
            });
        }
        self.tag = (self.tag + 1) % 1000;
        let body = format!("{} {request}", self.tag);
        let line = encode_line(&body).map_err(|e| SerialError::Refused {
            device: self.device,
            port: self.path.clone(),
            request: request.to_string(),
            code: 0,
            text: format!("not sendable: {e}"),
        })?;
        if let Err(e) = self
            .port
            .write_all(line.as_bytes())
            .and_then(|_| self.port.flush())
        {
            return Err(self.gone(format!("write: {e}")));
        }
        let deadline = Instant::now() + self.timeout;
        let mut buf = [0u8; 256];
        while Instant::now() < deadline {
            let n = match self.port.read(&mut buf) {
                Ok(0) => {
                    std::thread::sleep(IDLE_POLL);
                    continue;
                }
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    continue
                }
                Err(e) => return Err(self.gone(format!("read: {e}"))),
            };
            for r in self.reader.push(&buf[..n]) {
                let body = match r {
                    Ok(b) => b,
                    Err(e) => {
                        let msg = format!("{} ({}): {e}", self.device, self.path);
                        let ck = e.is_checksum();
                        self.note(|s| {
                            if ck {
                                s.checksum_errors += 1;
                            } else {
                                s.garbage += 1;
                            }
                            s.last_error = Some(msg);
                        });
                        continue;
                    }
                };
                match parse_reply(&body) {
                    Ok((tag, reply)) if tag == self.tag => {
                        self.note(|s| s.silent = 0);
                        return match reply {
                            Reply::Ok { verb, values } => {
                                let expected = request.split(' ').next().unwrap_or("");
                                if verb == expected {
                                    Ok(values)
                                } else {
                                    let msg = format!(
                                        "{} ({}): answer to {request:?} is for {verb}",
                                        self.device, self.path
                                    );
                                    self.note(|s| {
                                        s.garbage += 1;
                                        s.last_error = Some(msg.clone());
                                    });
                                    Err(SerialError::Refused {
                                        device: self.device,
                                        port: self.path.clone(),
                                        request: request.to_string(),
                                        code: 0,
                                        text: msg,
                                    })
                                }
                            }
                            Reply::Err { code, text } => Err(SerialError::Refused {
                                device: self.device,
                                port: self.path.clone(),
                                request: request.to_string(),
                                code,
                                text,
                            }),
                        };
                    }
                    Ok(_) => self.note(|s| {
                        s.garbage += 1;
                        s.last_error = Some(format!(
                            "{} ({}): late or foreign answer {body:?}",
                            self.device, self.path
                        ));
                    }),
                    Err(e) => self.note(|s| {
                        s.garbage += 1;
                        s.last_error = Some(format!("{} ({}): {e}", self.device, self.path));
                    }),
                }
            }
        }
        let err = SerialError::Timeout {
            device: self.device,
            port: self.path.clone(),
            request: request.to_string(),
            timeout_ms: self.timeout.as_millis() as u64,
        };
        let mut gone = None;
        self.note(|s| {
            s.timeouts += 1;
            s.silent += 1;
            s.last_error = Some(err.to_string());
            if s.silent >= MAX_SILENT && s.gone.is_none() {
                let g = format!("{MAX_SILENT} requests in a row unanswered");
                s.gone = Some(g.clone());
                gone = Some(g);
            }
        });
        match gone {
            Some(message) => Err(SerialError::Gone {
                device: self.device,
                port: self.path.clone(),
                message,
            }),
            None => Err(err),
        }
    }
}

impl SerialClient {
    /// Starts the client thread on `port` (`path` names it in messages). When idle for
    /// `poll`, it sends `poll_request` and hands the result to `on_poll`.
    pub fn spawn(
        device: &'static str,
        path: &str,
        port: Box<dyn ReadWrite>,
        timeout: Duration,
        poll: Duration,
        poll_request: &'static str,
        mut on_poll: impl FnMut(Result<Vec<String>, SerialError>) + Send + 'static,
    ) -> SerialClient {
        let stats = Arc::new(Mutex::new(SerialStats::default()));
        let (tx, rx) = mpsc::channel::<(String, ReplyTx)>();
        let mut w = Worker {
            port,
            reader: LineReader::new(),
            tag: 0,
            timeout,
            stats: stats.clone(),
            device,
            path: path.to_string(),
        };
        let join = std::thread::Builder::new()
            .name(format!("serial-{device}"))
            .spawn(move || loop {
                match rx.recv_timeout(poll) {
                    Ok((req, reply)) => {
                        let _ = reply.send(w.transact(&req));
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => on_poll(w.transact(poll_request)),
                    Err(mpsc::RecvTimeoutError::Disconnected) => return,
                }
            })
            .expect("spawning a thread");
        SerialClient {
            tx: Some(tx),
            join: Some(join),
            stats,
            device,
            port: path.to_string(),
        }
    }

    /// Sends a request and waits for the answer (without blocking the runtime).
    pub async fn request(&self, req: &str) -> Result<Vec<String>, SerialError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let gone = |m: &str| SerialError::Gone {
            device: self.device,
            port: self.port.clone(),
            message: m.to_string(),
        };
        self.tx
            .as_ref()
            .ok_or_else(|| gone("client closed"))?
            .send((req.to_string(), tx))
            .map_err(|_| gone("client thread ended"))?;
        rx.await.map_err(|_| gone("client thread ended"))?
    }

    /// What was counted so far.
    pub fn stats(&self) -> SerialStats {
        self.stats.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Stops the thread (after the request in progress).
    pub fn close(&mut self) {
        self.tx.take();
        if let Some(j) = self.join.take() {
            let _ = j.join();
        }
    }
}

impl Drop for SerialClient {
    fn drop(&mut self) {
        self.close();
    }
}
