//! The live view: a session's channels served to the Foxglove app over the Foxglove WebSocket
//! protocol (the `foxglove` SDK's server), while the session runs (`rigtwin run --foxglove ADDR`).
//! Clients may negotiate the SDK's subprotocol names (`foxglove.sdk.v1`, `.v1.1`) or the
//! protocol's published one, [`PUBLISHED_SUBPROTOCOL`] (`@foxglove/ws-protocol`'s reference
//! client and the viewers built on it): `door` (private) accepts them all on the address asked
//! for and relays to the SDK's server on the loopback interface.
//!
//! - [`LiveView::start`] binds the server (its own one-thread tokio runtime) and starts the
//!   publisher thread; it returns the [`LiveRecorder`] (a
//!   [`SessionRecorder`](super::SessionRecorder)) and the [`LiveView`] that stops both.
//! - The recorder hands every record to the publisher thread over a bounded queue with
//!   `try_send`: it never blocks and never fails the session; a full queue drops the record
//!   (counted in [`LiveStats::dropped_records`]).
//! - `publisher` (private): the thread that decimates the DAQ blocks ([`decimate`]), serialises
//!   to JSON and logs to the server only the channels some client subscribed to. The server
//!   queues per client and drops the oldest messages of a client that cannot keep up.
//!
//! Topics: the MCAP session log's, same names and JSON schemas ([`TOPIC_LAYOUT`], latched: a
//! client that subscribes gets the layout at once; [`TOPIC_CONTROL`], [`TOPIC_EVENTS`],
//! [`TOPIC_STATUS`], [`TOPIC_STEPS`]), except the raw DAQ blocks: they become [`TOPIC_LIVE_DAQ`],
//! one message per decimated time point with every channel's min, max and mean in physical
//! units (`/live/daq.upper_tip.max` in a Plot panel). Log time = rig time of the sample.
//! With the live twin (`--twin`): its [`TOPIC_TWIN_STATUS`] and [`TOPIC_TWIN_STEPS`] as in the
//! MCAP log, and [`TOPIC_LIVE_TWIN`], its predicted channels decimated in the bins of
//! [`TOPIC_LIVE_DAQ`] (its raw `/twin/blocks` are the log's only).
//!
//! [`topic_schemas`] lists every topic and schema; `rig-config/foxglove/rigtwin-live.json` is a
//! Foxglove layout for them (`run --foxglove` names it; a test checks its message paths against
//! these schemas).
//!
//! [`TOPIC_LAYOUT`]: super::topics::TOPIC_LAYOUT
//! [`TOPIC_CONTROL`]: super::topics::TOPIC_CONTROL
//! [`TOPIC_EVENTS`]: super::topics::TOPIC_EVENTS
//! [`TOPIC_STATUS`]: super::topics::TOPIC_STATUS
//! [`TOPIC_STEPS`]: super::topics::TOPIC_STEPS
//! [`TOPIC_TWIN_STATUS`]: super::topics::TOPIC_TWIN_STATUS
//! [`TOPIC_TWIN_STEPS`]: super::topics::TOPIC_TWIN_STEPS

pub mod decimate;
mod door;
mod publisher;
mod record;
mod view;

use crate::config::SpecError;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

pub use door::PUBLISHED_SUBPROTOCOL;
pub use publisher::{topic_schemas, TopicSchema};
pub use record::LiveStats;
pub use view::{LiveRecorder, LiveView};

pub use super::topics::{TOPIC_LIVE_DAQ, TOPIC_LIVE_TWIN};

/// The Foxglove layout shipped for the live view, relative to the project's root.
pub const FOXGLOVE_LAYOUT: &str = "rig-config/foxglove/rigtwin-live.json";

/// Schema name of [`TOPIC_LIVE_DAQ`] (its JSON Schema lists the session's channels).
pub const LIVE_DAQ_SCHEMA: &str = "LiveDaqPoint";

/// Schema name of [`TOPIC_LIVE_TWIN`].
pub const LIVE_TWIN_SCHEMA: &str = "LiveTwinPoint";

/// The channels of [`TOPIC_LIVE_TWIN`]: key, what it is, unit. The velocities are relative to
/// the base (the twin's coordinates); `contact`'s mean is the share of the bin's samples with a
/// closed pair.
pub const LIVE_TWIN_CHANNELS: [(&str, &str, &str); 7] = [
    (
        "lower_tip",
        "relative velocity of the lower tip sensor",
        "m/s",
    ),
    (
        "lower_mid",
        "relative velocity of the lower mid sensor",
        "m/s",
    ),
    (
        "upper_tip",
        "relative velocity of the upper tip sensor (the vibrometer's spot)",
        "m/s",
    ),
    (
        "upper_mid",
        "relative velocity of the upper mid sensor",
        "m/s",
    ),
    ("contact", "1 while a contact pair is closed, else 0", "-"),
    ("normal_force", "integrated normal contact force", "N"),
    (
        "tangential_force",
        "integrated tangential contact force",
        "N",
    ),
];

/// Errors of starting the live view.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The server could not listen on the address.
    #[error("live view: cannot listen on {addr}: {io}{}", bind_hint(io))]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The I/O error (in the message, not repeated as a cause).
        io: std::io::Error,
    },
    /// The options are out of range.
    #[error("live view: bad options: {0}")]
    Options(#[from] SpecError),
    /// A thread or the server's runtime could not start, or the SDK refused the server.
    #[error("live view: {what}: {detail}")]
    Start {
        /// What was being started.
        what: &'static str,
        /// The underlying error.
        detail: String,
    },
}

fn bind_hint(e: &std::io::Error) -> &'static str {
    use std::io::ErrorKind;
    match e.kind() {
        ErrorKind::AddrInUse => {
            " (another program, e.g. another rigtwin session or a Foxglove bridge, uses the \
             port: choose another port, or port 0 for a free one)"
        }
        ErrorKind::AddrNotAvailable => {
            " (the address is not one of this machine's: use 127.0.0.1 for this machine only, \
             or 0.0.0.0 for every interface)"
        }
        ErrorKind::PermissionDenied => " (ports below 1024 need privileges: use e.g. 8765)",
        _ => "",
    }
}

/// Parses a live-view address: `PORT` (binds 127.0.0.1), `IP:PORT` (`127.0.0.1:8765`,
/// `0.0.0.0:8765` for every interface), `[IPv6]:PORT` or `localhost:PORT`. Port 0 picks a free
/// port. Never binds every interface unless the address says so.
pub fn parse_addr(text: &str) -> Result<SocketAddr, AddrError> {
    let t = text.trim();
    if let Ok(port) = t.parse::<u16>() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
    }
    if let Ok(addr) = t.parse::<SocketAddr>() {
        return Ok(addr);
    }
    if let Some(port) = t.strip_prefix("localhost:") {
        if let Ok(port) = port.parse::<u16>() {
            return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
        }
    }
    Err(AddrError {
        text: text.to_owned(),
    })
}

/// A live-view address that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{text:?} is not a listen address: expected PORT (binds 127.0.0.1, e.g. 8765), \
     IP:PORT (e.g. 127.0.0.1:8765, or 0.0.0.0:8765 for every interface), [IPv6]:PORT or \
     localhost:PORT, with PORT in 0..=65535 (0: a free port)"
)]
pub struct AddrError {
    /// The text given.
    pub text: String,
}

/// How the live view serves a session.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveOptions {
    /// Decimated DAQ points per second of rig time, Hz. Default 200: a bin of 51 samples at
    /// 10,240 Hz (about a quarter of a 1FU period), 200.8 messages per rig second, which the
    /// Plot panel draws without effort. Sessions on virtual time run faster than real time, so
    /// the wall-clock message rate is this times the speed-up.
    pub daq_points_per_second: f64,
    /// Capacity of the queue between the session and the publisher thread, records (a DAQ
    /// block, a control state, an event...). When it is full, records are dropped, never waited
    /// for. Default 512 (about 6 s of rig time at 40 blocks per second).
    pub queue_capacity: usize,
    /// Messages the server queues per client before dropping the client's oldest ones.
    /// Default 1024 (about 4 s of messages).
    pub client_backlog: usize,
    /// Longest wait for the server's connections to close when the view stops. Default 2 s.
    pub shutdown_timeout: Duration,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            daq_points_per_second: 200.0,
            queue_capacity: 512,
            client_backlog: 1024,
            shutdown_timeout: Duration::from_secs(2),
        }
    }
}

impl LiveOptions {
    /// Checks the values; the first problem (option, value, what was expected).
    pub fn check(&self) -> Result<(), SpecError> {
        if !(self.daq_points_per_second.is_finite() && self.daq_points_per_second > 0.0) {
            return Err(SpecError::new(
                "daq_points_per_second",
                self.daq_points_per_second,
                "a positive rate in Hz",
            ));
        }
        if self.queue_capacity == 0 {
            return Err(SpecError::new("queue_capacity", 0, "at least 1 record"));
        }
        if self.client_backlog == 0 {
            return Err(SpecError::new("client_backlog", 0, "at least 1 message"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bare_port_binds_the_loopback_interface_only() {
        assert_eq!(
            parse_addr("8765").unwrap(),
            "127.0.0.1:8765".parse().unwrap()
        );
        assert_eq!(parse_addr("0").unwrap(), "127.0.0.1:0".parse().unwrap());
        assert_eq!(
            parse_addr("localhost:9000").unwrap(),
            "127.0.0.1:9000".parse().unwrap()
        );
        assert_eq!(
            parse_addr("0.0.0.0:8765").unwrap(),
            "0.0.0.0:8765".parse().unwrap()
        );
        assert_eq!(
            parse_addr("[::1]:8765").unwrap(),
            "[::1]:8765".parse().unwrap()
        );
    }

    #[test]
    fn bad_addresses_are_described() {
        for bad in [
            "",
            "65536",
            "127.0.0.1",
            "127.0.0.1:http",
            "host:80",
            "::1:8765",
        ] {
            let e = parse_addr(bad).unwrap_err();
            assert!(e.to_string().contains("expected PORT"), "{bad}: {e}");
        }
    }

    #[test]
    fn options_are_checked() {
        assert!(LiveOptions::default().check().is_ok());
        let bad = LiveOptions {
            daq_points_per_second: 0.0,
            ..LiveOptions::default()
        };
        assert_eq!(bad.check().unwrap_err().key, "daq_points_per_second");
    }
}
