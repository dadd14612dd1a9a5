//! Carrying CAN frames: the [`CanTransport`] trait, a UDP tunnel ([`UdpTunnel`]: one CAN FD
//! frame per datagram, for kernels without SocketCAN and for `rigtwin firmware-sim`) and, on
//! Linux, SocketCAN ([`SocketCanTransport`], the `socketcan` crate on tokio). [`CanAddress`]
//! parses the `--can` argument.
//!
//! Tunnel datagram layout (all little-endian), documented in `firmware-interfaces/README.md`:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 1 | version, 1 |
//! | 1 | 1 | flags: bit 0 FD, bit 1 BRS, bit 2 ESI, bit 3 extended (29-bit) id |
//! | 2 | 1 | data length (a CAN FD length for FD frames, 0..=8 otherwise) |
//! | 3 | 1 | reserved, 0 |
//! | 4 | 4 | identifier |
//! | 8 | len | data |

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Mutex;

use super::frame::CanFrame;

/// Tunnel header size, bytes.
pub const TUNNEL_HEADER: usize = 8;
/// Tunnel layout version.
pub const TUNNEL_VERSION: u8 = 1;

/// Transport failures.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// Something arrived that is not a frame (counted as malformed; the link goes on).
    #[error("{0}")]
    Malformed(String),
    /// The link cannot be used any more (the other end is gone, the interface went down).
    #[error("{0}")]
    Gone(String),
    /// The transport could not be opened.
    #[error("{0}")]
    Open(String),
}

/// A datagram that is not a tunnel frame; the message names the byte and what is wrong.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TunnelError {
    /// Shorter than the header.
    #[error("tunnel datagram of {len} bytes: shorter than the {TUNNEL_HEADER}-byte header")]
    Short {
        /// Datagram length, bytes.
        len: usize,
    },
    /// Byte 0 is not [`TUNNEL_VERSION`].
    #[error("tunnel datagram byte 0 (version) = {version}: expected {TUNNEL_VERSION}")]
    Version {
        /// The version byte.
        version: u8,
    },
    /// Flag bits beyond the four defined.
    #[error("tunnel datagram byte 1 (flags) = {flags:#04x}: unknown bits")]
    Flags {
        /// The flags byte.
        flags: u8,
    },
    /// The length byte disagrees with the datagram.
    #[error("tunnel datagram byte 2 (length) = {len}, but {data} data bytes follow the header")]
    Length {
        /// The length byte.
        len: usize,
        /// Data bytes after the header.
        data: usize,
    },
    /// Identifier, length and flags do not make a valid frame.
    #[error(
        "tunnel datagram: id {id:#x}{} with {len} bytes is not a valid {} frame",
        extended_note(.extended),
        frame_kind(.fd)
    )]
    Frame {
        /// Identifier.
        id: u32,
        /// 29-bit identifier.
        extended: bool,
        /// CAN FD.
        fd: bool,
        /// Data bytes.
        len: usize,
    },
}

fn extended_note(extended: &bool) -> &'static str {
    if *extended {
        " (extended)"
    } else {
        ""
    }
}

fn frame_kind(fd: &bool) -> &'static str {
    if *fd {
        "CAN FD"
    } else {
        "classic CAN"
    }
}

/// A bidirectional CAN link. Methods take `&self` so one transport serves a reader task and
/// writers at the same time.
pub trait CanTransport: Send + Sync {
    /// Sends one frame.
    fn send(&self, frame: &CanFrame) -> impl Future<Output = Result<(), TransportError>> + Send;
    /// Receives one frame. `Malformed` is not fatal.
    fn recv(&self) -> impl Future<Output = Result<CanFrame, TransportError>> + Send;
    /// What the link is, for messages and the candump log's interface column.
    fn name(&self) -> String;
}

/// Encodes a frame as a tunnel datagram.
pub fn tunnel_encode(frame: &CanFrame, out: &mut Vec<u8>) {
    out.clear();
    out.push(TUNNEL_VERSION);
    out.push(
        u8::from(frame.fd)
            | u8::from(frame.brs) << 1
            | u8::from(frame.esi) << 2
            | u8::from(frame.extended) << 3,
    );
    out.push(frame.len() as u8);
    out.push(0);
    out.extend_from_slice(&frame.id.to_le_bytes());
    out.extend_from_slice(frame.data());
}

/// Decodes a tunnel datagram; `Err` names the byte and what is wrong.
pub fn tunnel_decode(d: &[u8]) -> Result<CanFrame, TunnelError> {
    if d.len() < TUNNEL_HEADER {
        return Err(TunnelError::Short { len: d.len() });
    }
    if d[0] != TUNNEL_VERSION {
        return Err(TunnelError::Version { version: d[0] });
    }
    let flags = d[1];
    if flags & !0x0F != 0 {
        return Err(TunnelError::Flags { flags });
    }
    let len = usize::from(d[2]);
    if d.len() != TUNNEL_HEADER + len {
        return Err(TunnelError::Length {
            len,
            data: d.len() - TUNNEL_HEADER,
        });
    }
    let id = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
    let (fd, brs, esi, ext) = (
        flags & 1 != 0,
        flags & 2 != 0,
        flags & 4 != 0,
        flags & 8 != 0,
    );
    CanFrame::new(id, ext, fd, brs, esi, &d[TUNNEL_HEADER..]).ok_or(TunnelError::Frame {
        id,
        extended: ext,
        fd,
        len,
    })
}

/// A UDP tunnel carrying one frame per datagram. The host side is connected to the device's
/// address; the device side learns its peer from the first datagram ([`UdpTunnel::listen`]).
#[derive(Debug)]
pub struct UdpTunnel {
    socket: tokio::net::UdpSocket,
    peer: Mutex<Option<SocketAddr>>,
    connected: bool,
    last_from: Mutex<Option<SocketAddr>>,
}

impl UdpTunnel {
    /// Binds `local` and connects to `remote` (host side).
    pub async fn connect(
        local: SocketAddr,
        remote: SocketAddr,
    ) -> Result<UdpTunnel, TransportError> {
        let socket = tokio::net::UdpSocket::bind(local)
            .await
            .map_err(|e| TransportError::Open(format!("UDP tunnel: binding {local}: {e}")))?;
        enlarge_receive_buffer(&socket);
        socket.connect(remote).await.map_err(|e| {
            TransportError::Open(format!("UDP tunnel: connecting to {remote}: {e}"))
        })?;
        Ok(UdpTunnel {
            socket,
            peer: Mutex::new(Some(remote)),
            connected: true,
            last_from: Mutex::new(None),
        })
    }

    /// Binds `local` and answers whoever sends (device side).
    pub async fn listen(local: SocketAddr) -> Result<UdpTunnel, TransportError> {
        let socket = tokio::net::UdpSocket::bind(local)
            .await
            .map_err(|e| TransportError::Open(format!("UDP tunnel: binding {local}: {e}")))?;
        enlarge_receive_buffer(&socket);
        Ok(UdpTunnel {
            socket,
            peer: Mutex::new(None),
            connected: false,
            last_from: Mutex::new(None),
        })
    }

    /// The bound address.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.socket.local_addr().ok()
    }

    /// Where frames go (device side: the learned peer).
    pub fn peer(&self) -> Option<SocketAddr> {
        *self.peer.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Sets where frames go (device side).
    pub fn set_peer(&self, peer: Option<SocketAddr>) {
        *self.peer.lock().unwrap_or_else(|e| e.into_inner()) = peer;
    }

    /// Sends arbitrary bytes as one datagram (fault injection: a datagram that is no frame).
    pub async fn send_raw(&self, bytes: &[u8], to: SocketAddr) -> std::io::Result<usize> {
        if self.connected {
            self.socket.send(bytes).await
        } else {
            self.socket.send_to(bytes, to).await
        }
    }

    /// The source of the last datagram received.
    pub fn last_from(&self) -> Option<SocketAddr> {
        *self.last_from.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Receive buffer asked for, bytes: a DAQ block is 142 datagrams that arrive in a burst, and
/// the kernel counts each small datagram at about 1 KiB; the default buffer (about 200 KiB)
/// overflows when the receiver is late by a block or two.
pub const TUNNEL_RCVBUF: usize = 8 << 20;

/// Enlarges a socket's receive buffer (best effort: SO_RCVBUFFORCE where allowed, else
/// SO_RCVBUF up to the system's limit, `net.core.rmem_max` on Linux).
fn enlarge_receive_buffer(socket: &tokio::net::UdpSocket) {
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        let fd = socket.as_raw_fd();
        let size = TUNNEL_RCVBUF as libc::c_int;
        let set = |opt: libc::c_int| {
            // SAFETY: setsockopt on a descriptor the socket owns, with a c_int option value.
            unsafe {
                libc::setsockopt(
                    fd,
                    libc::SOL_SOCKET,
                    opt,
                    (&size as *const libc::c_int).cast(),
                    std::mem::size_of::<libc::c_int>() as libc::socklen_t,
                )
            }
        };
        #[cfg(target_os = "linux")]
        if set(libc::SO_RCVBUFFORCE) == 0 {
            return;
        }
        let _ = set(libc::SO_RCVBUF);
    }
    #[cfg(not(unix))]
    let _ = socket;
}

fn gone(what: &str, e: std::io::Error) -> TransportError {
    TransportError::Gone(format!(
        "{what}: {e} (the other end of the link is gone or unreachable)"
    ))
}

impl CanTransport for UdpTunnel {
    async fn send(&self, frame: &CanFrame) -> Result<(), TransportError> {
        let mut buf = Vec::with_capacity(TUNNEL_HEADER + 64);
        tunnel_encode(frame, &mut buf);
        let r = if self.connected {
            self.socket.send(&buf).await
        } else {
            match self.peer() {
                Some(p) => self.socket.send_to(&buf, p).await,
                None => {
                    return Err(TransportError::Gone(
                        "UDP tunnel: no peer has connected yet".into(),
                    ))
                }
            }
        };
        r.map(|_| ())
            .map_err(|e| gone(&format!("UDP tunnel {}: send", self.name()), e))
    }

    async fn recv(&self) -> Result<CanFrame, TransportError> {
        let mut buf = [0u8; 512];
        let (n, from) = self
            .socket
            .recv_from(&mut buf)
            .await
            .map_err(|e| gone(&format!("UDP tunnel {}: receive", self.name()), e))?;
        *self.last_from.lock().unwrap_or_else(|e| e.into_inner()) = Some(from);
        tunnel_decode(&buf[..n]).map_err(|e| TransportError::Malformed(format!("from {from}: {e}")))
    }

    fn name(&self) -> String {
        format!(
            "udp:{}@{}",
            self.local_addr().map_or("?".into(), |a| a.to_string()),
            self.peer().map_or("*".into(), |a| a.to_string())
        )
    }
}

/// SocketCAN (Linux): a raw CAN FD socket on an interface.
#[cfg(target_os = "linux")]
#[derive(Debug)]
pub struct SocketCanTransport {
    socket: socketcan::tokio::CanFdSocket,
    iface: String,
}

#[cfg(target_os = "linux")]
impl SocketCanTransport {
    /// Opens `iface`. Without SocketCAN in the kernel, or without the interface, the error
    /// says which and what to do.
    pub fn open(iface: &str) -> Result<SocketCanTransport, TransportError> {
        probe_socketcan().map_err(|e| TransportError::Open(e.to_string()))?;
        let socket = socketcan::tokio::CanFdSocket::open(iface).map_err(|e| {
            TransportError::Open(if e.raw_os_error() == Some(libc::ENODEV) {
                format!(
                    "SocketCAN interface {iface}: no such interface ({e}); list them with \
                     `ip -details link show type can` (a virtual one: `modprobe vcan && ip \
                     link add {iface} type vcan && ip link set {iface} mtu 72 up`)"
                )
            } else {
                format!("SocketCAN interface {iface}: {e}")
            })
        })?;
        Ok(SocketCanTransport {
            socket,
            iface: iface.to_string(),
        })
    }
}

/// The kernel has no SocketCAN: the message names the missing support and the alternative.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "SocketCAN is not available in this kernel: socket(AF_CAN, SOCK_RAW, CAN_RAW) failed: \
     {error}. The kernel needs CAN support (CONFIG_CAN, CONFIG_CAN_RAW: modules `can` and \
     `can_raw`, `modprobe can_raw`) and a CAN interface; without them use the UDP tunnel, e.g. \
     --can udp:127.0.0.1:47000 (rigtwin firmware-sim)"
)]
pub struct NoSocketCan {
    /// What socket(2) said.
    pub error: String,
}

/// Checks that the kernel has SocketCAN: a raw CAN socket (address family AF_CAN, protocol
/// CAN_RAW) can be created. The error names the missing kernel support.
#[cfg(target_os = "linux")]
pub fn probe_socketcan() -> Result<(), NoSocketCan> {
    // SAFETY: plain socket(2) call; the descriptor is closed right away.
    let fd = unsafe { libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW) };
    if fd < 0 {
        return Err(NoSocketCan {
            error: std::io::Error::last_os_error().to_string(),
        });
    }
    // SAFETY: fd is a descriptor we own.
    unsafe { libc::close(fd) };
    Ok(())
}

#[cfg(target_os = "linux")]
impl CanTransport for SocketCanTransport {
    async fn send(&self, frame: &CanFrame) -> Result<(), TransportError> {
        use socketcan::frame::FdFlags;
        use socketcan::{
            CanAnyFrame, CanDataFrame, CanFdFrame, EmbeddedFrame, ExtendedId, Id, StandardId,
        };
        let id: Id = if frame.extended {
            ExtendedId::new(frame.id).map(Id::from)
        } else {
            StandardId::new(frame.id as u16).map(Id::from)
        }
        .ok_or_else(|| TransportError::Malformed(format!("CAN id {:#x} out of range", frame.id)))?;
        let any: CanAnyFrame = if frame.fd {
            let mut flags = FdFlags::empty();
            if frame.brs {
                flags |= FdFlags::BRS;
            }
            if frame.esi {
                flags |= FdFlags::ESI;
            }
            CanFdFrame::with_flags(id, frame.data(), flags)
                .ok_or_else(|| TransportError::Malformed(format!("{frame:?}: not a CAN FD frame")))?
                .into()
        } else {
            CanDataFrame::new(id, frame.data())
                .ok_or_else(|| TransportError::Malformed(format!("{frame:?}: not a CAN frame")))?
                .into()
        };
        self.socket
            .write_frame(&any)
            .await
            .map_err(|e| gone(&format!("SocketCAN {}: send", self.iface), e))
    }

    async fn recv(&self) -> Result<CanFrame, TransportError> {
        use socketcan::{CanAnyFrame, EmbeddedFrame, Frame};
        let f = self
            .socket
            .read_frame()
            .await
            .map_err(|e| gone(&format!("SocketCAN {}: receive", self.iface), e))?;
        let (fd, brs, esi) = match &f {
            CanAnyFrame::Fd(x) => (true, x.is_brs(), x.is_esi()),
            CanAnyFrame::Normal(_) => (false, false, false),
            CanAnyFrame::Remote(_) | CanAnyFrame::Error(_) => {
                return Err(TransportError::Malformed(format!(
                    "SocketCAN {}: remote or error frame {:#x}",
                    self.iface,
                    f.raw_id()
                )))
            }
        };
        let id = match f.id() {
            socketcan::Id::Standard(s) => u32::from(s.as_raw()),
            socketcan::Id::Extended(x) => x.as_raw(),
        };
        CanFrame::new(id, f.is_extended(), fd, brs, esi, f.data()).ok_or_else(|| {
            TransportError::Malformed(format!("SocketCAN {}: bad frame", self.iface))
        })
    }

    fn name(&self) -> String {
        self.iface.clone()
    }
}

/// Where the CAN link goes (`--can`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CanAddress {
    /// A SocketCAN interface, e.g. `can0`.
    SocketCan(String),
    /// The UDP tunnel: local bind address (port 0: any) and the device's address.
    Udp {
        /// Local address.
        local: SocketAddr,
        /// The device's address.
        remote: SocketAddr,
    },
}

/// A `--can` argument that is not a link.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CanAddressError {
    /// A UDP address that does not parse.
    #[error(
        "--can {arg}: {which} address {address:?}: {error} (expected HOST:PORT, IPv6 as \
         [ADDR]:PORT)"
    )]
    Address {
        /// The whole argument.
        arg: String,
        /// "local" or "remote".
        which: &'static str,
        /// The address.
        address: String,
        /// Why it does not parse.
        error: std::net::AddrParseError,
    },
    /// Local and remote addresses of different families (IPv4 and IPv6).
    #[error("--can {arg}: local and remote addresses of different families")]
    Families {
        /// The whole argument.
        arg: String,
    },
    /// Neither `udp:...` nor a SocketCAN interface name.
    #[error(
        "--can {arg}: expected a SocketCAN interface name (e.g. can0, at most 15 characters) \
         or udp:[LOCAL@]HOST:PORT"
    )]
    Interface {
        /// The whole argument.
        arg: String,
    },
}

impl std::str::FromStr for CanAddress {
    type Err = CanAddressError;

    /// `IFACE` (SocketCAN), or `udp:REMOTE` / `udp:LOCAL@REMOTE` with `HOST:PORT` addresses
    /// (IPv6 in brackets; without LOCAL the wildcard of REMOTE's family, port 0).
    fn from_str(s: &str) -> Result<CanAddress, CanAddressError> {
        if let Some(rest) = s.strip_prefix("udp:") {
            let parse = |a: &str, which: &'static str| -> Result<SocketAddr, CanAddressError> {
                a.parse().map_err(|error| CanAddressError::Address {
                    arg: s.to_string(),
                    which,
                    address: a.to_string(),
                    error,
                })
            };
            let (local, remote) = match rest.split_once('@') {
                Some((l, r)) => (Some(parse(l, "local")?), parse(r, "remote")?),
                None => (None, parse(rest, "remote")?),
            };
            let local = local.unwrap_or_else(|| {
                if remote.is_ipv4() {
                    SocketAddr::from(([0, 0, 0, 0], 0))
                } else {
                    SocketAddr::from(([0u16; 8], 0))
                }
            });
            if local.is_ipv4() != remote.is_ipv4() {
                return Err(CanAddressError::Families { arg: s.to_string() });
            }
            return Ok(CanAddress::Udp { local, remote });
        }
        let ok = !s.is_empty()
            && s.len() < 16
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c));
        if ok {
            Ok(CanAddress::SocketCan(s.to_string()))
        } else {
            Err(CanAddressError::Interface { arg: s.to_string() })
        }
    }
}

/// Any transport (an enum: the trait's futures are not object-safe).
#[derive(Debug)]
pub enum AnyTransport {
    /// UDP tunnel.
    Udp(UdpTunnel),
    /// SocketCAN.
    #[cfg(target_os = "linux")]
    SocketCan(SocketCanTransport),
}

impl AnyTransport {
    /// Opens the link to `addr` (host side).
    pub async fn open(addr: &CanAddress) -> Result<AnyTransport, TransportError> {
        match addr {
            CanAddress::Udp { local, remote } => {
                Ok(AnyTransport::Udp(UdpTunnel::connect(*local, *remote).await?))
            }
            #[cfg(target_os = "linux")]
            CanAddress::SocketCan(iface) => Ok(AnyTransport::SocketCan(SocketCanTransport::open(iface)?)),
            #[cfg(not(target_os = "linux"))]
            CanAddress::SocketCan(iface) => Err(TransportError::Open(format!(
                "SocketCAN interface {iface}: SocketCAN exists on Linux only; use --can udp:HOST:PORT"
            ))),
        }
    }
}

impl CanTransport for AnyTransport {
    async fn send(&self, frame: &CanFrame) -> Result<(), TransportError> {
        match self {
            AnyTransport::Udp(t) => t.send(frame).await,
            #[cfg(target_os = "linux")]
            AnyTransport::SocketCan(t) => t.send(frame).await,
        }
    }

    async fn recv(&self) -> Result<CanFrame, TransportError> {
        match self {
            AnyTransport::Udp(t) => t.recv().await,
            #[cfg(target_os = "linux")]
            AnyTransport::SocketCan(t) => t.recv().await,
        }
    }

    fn name(&self) -> String {
        match self {
            AnyTransport::Udp(t) => t.name(),
            #[cfg(target_os = "linux")]
            AnyTransport::SocketCan(t) => t.name(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn addresses_parse_or_say_what_is_wrong() {
        assert_eq!("can0".parse(), Ok(CanAddress::SocketCan("can0".into())));
        assert_eq!(
            "udp:127.0.0.1:47000".parse(),
            Ok(CanAddress::Udp {
                local: "0.0.0.0:0".parse().unwrap(),
                remote: "127.0.0.1:47000".parse().unwrap()
            })
        );
        assert_eq!(
            "udp:[::1]:5@[::1]:6".parse::<CanAddress>().unwrap(),
            CanAddress::Udp {
                local: "[::1]:5".parse().unwrap(),
                remote: "[::1]:6".parse().unwrap()
            }
        );
        for bad in [
            "udp:localhost",
            "udp:1.2.3.4:5@[::1]:6",
            "",
            "can 0",
            "averyveryverylongname",
        ] {
            assert!(bad.parse::<CanAddress>().is_err(), "{bad}");
        }
    }

    /// This kernel has no SocketCAN (no AF_CAN): opening an interface names what is missing.
    /// Where SocketCAN exists, a missing interface is named instead.
    #[cfg(target_os = "linux")]
    #[test]
    fn opening_socketcan_names_the_missing_kernel_support_or_interface() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let e = rt
            .block_on(AnyTransport::open(&CanAddress::SocketCan(
                "rtwnocan0".into(),
            )))
            .unwrap_err()
            .to_string();
        if probe_socketcan().is_err() {
            assert!(
                e.contains("AF_CAN")
                    && e.contains("can_raw")
                    && e.contains("not available in this kernel"),
                "{e}"
            );
        } else {
            assert!(
                e.contains("rtwnocan0") && e.contains("no such interface"),
                "{e}"
            );
        }
    }

    #[test]
    fn tunnel_round_trip_over_loopback() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            let dev = UdpTunnel::listen("127.0.0.1:0".parse().unwrap())
                .await
                .unwrap();
            let host =
                UdpTunnel::connect("127.0.0.1:0".parse().unwrap(), dev.local_addr().unwrap())
                    .await
                    .unwrap();
            let f = CanFrame::fd(0x101, &[7; 64]).unwrap();
            host.send(&f).await.unwrap();
            assert_eq!(dev.recv().await.unwrap(), f);
            dev.set_peer(dev.last_from());
            let g = CanFrame::new(
                0x1234_5678 & 0x1FFF_FFFF,
                true,
                false,
                false,
                false,
                &[1, 2],
            )
            .unwrap();
            dev.send(&g).await.unwrap();
            assert_eq!(host.recv().await.unwrap(), g);
        });
    }

    proptest! {
        #[test]
        fn tunnel_decoder_never_panics(d in prop::collection::vec(any::<u8>(), 0..100)) {
            if let Ok(f) = tunnel_decode(&d) {
                let mut out = Vec::new();
                tunnel_encode(&f, &mut out);
                prop_assert_eq!(out, d);
            }
        }
    }
}
