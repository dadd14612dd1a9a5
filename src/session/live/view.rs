//! Starting and stopping the live view: the WebSocket server on its own runtime, the publisher
//! thread, and the [`LiveRecorder`] the session records into.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

use crate::control::{ControlState, SessionEvent, StepInfo, StepSummary};
use crate::rig::{DaqBlock, DaqLayout, RigStatus};
use crate::twin::{TwinBlock, TwinStatus};

use super::super::recorder::{RecordError, SessionRecorder};
use super::super::topics::{StatusMessage, StepMessage, TwinStepMessage};
use super::publisher::{Channels, LayoutLatch, Publisher};
use super::record::{LiveStats, Record};
use super::{LiveError, LiveOptions};

/// State shared by the recorder and the view.
#[derive(Default)]
struct Shared {
    /// Records dropped because the queue was full.
    dropped: AtomicU64,
    /// Set when the view stops: later records are dropped silently.
    closed: AtomicBool,
}

/// The session side of the live view: queues every record for the publisher thread. Never
/// blocks and never fails: the live view must not stop a session. Records that do not fit the
/// queue are dropped and counted. Clones feed the same view (the live twin holds one).
#[derive(Clone)]
pub struct LiveRecorder {
    tx: SyncSender<Record>,
    shared: Arc<Shared>,
}

impl std::fmt::Debug for LiveRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveRecorder")
            .field("dropped", &self.shared.dropped.load(Ordering::Relaxed))
            .finish()
    }
}

impl LiveRecorder {
    fn offer(&self, record: impl FnOnce() -> Record) {
        if self.shared.closed.load(Ordering::Acquire) {
            return;
        }
        match self.tx.try_send(record()) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            }
            // The publisher stopped (it panicked): nothing to show, the session goes on.
            Err(TrySendError::Disconnected(_)) => {}
        }
    }

    /// The live twin's prediction for a block (published decimated on `/live/twin`).
    pub fn twin_block(&self, block: &TwinBlock) {
        self.offer(|| Record::TwinBlock(Box::new(block.clone())));
    }

    /// The live twin's status at rig time `time` (s), published on `/twin/status`.
    pub fn twin_status(&self, time: f64, status: &TwinStatus) {
        self.offer(|| Record::TwinStatus(time, Box::new(status.clone())));
    }

    /// The live twin's comparison of a step, logged at rig time `time` (s, the end of its record
    /// window), published on `/twin/steps`.
    pub fn twin_step(&self, time: f64, step: &TwinStepMessage) {
        self.offer(|| Record::TwinStep(time, Box::new(step.clone())));
    }
}

impl SessionRecorder for LiveRecorder {
    fn layout(&mut self, layout: &DaqLayout) -> Result<(), RecordError> {
        self.offer(|| Record::Layout(layout.clone()));
        Ok(())
    }
    fn block(&mut self, block: &DaqBlock) -> Result<(), RecordError> {
        self.offer(|| Record::Block(block.clone()));
        Ok(())
    }
    fn control(&mut self, state: &ControlState) -> Result<(), RecordError> {
        self.offer(|| Record::Control(state.clone()));
        Ok(())
    }
    fn event(&mut self, event: &SessionEvent) -> Result<(), RecordError> {
        self.offer(|| Record::Event(event.clone()));
        Ok(())
    }
    fn status(&mut self, time: f64, status: &RigStatus) -> Result<(), RecordError> {
        self.offer(|| {
            Record::Status(StatusMessage {
                block_time: time,
                status: status.clone(),
            })
        });
        Ok(())
    }
    fn step(
        &mut self,
        time: f64,
        info: &StepInfo,
        summary: &StepSummary,
    ) -> Result<(), RecordError> {
        self.offer(|| {
            Record::Step(
                time,
                Box::new(StepMessage {
                    info: info.clone(),
                    summary: summary.clone(),
                }),
            )
        });
        Ok(())
    }
}

/// A running live view: the Foxglove WebSocket server and the publisher thread. [`close`]
/// (or dropping it) publishes what is queued, then stops the server, closing every connection.
///
/// [`close`]: LiveView::close
pub struct LiveView {
    addr: SocketAddr,
    options: LiveOptions,
    shared: Arc<Shared>,
    tx: SyncSender<Record>,
    thread: Option<JoinHandle<LiveStats>>,
    server: Option<foxglove::WebSocketServerHandle>,
    /// The door's stop signal and task (see `door::serve`).
    door: Option<(
        tokio::sync::watch::Sender<bool>,
        tokio::task::JoinHandle<()>,
    )>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.addr)
            .finish()
    }
}

impl LiveView {
    /// Starts the server on `addr` (port 0: a free port) and the publisher thread. Returns the
    /// recorder to hand the session's records to and the view (the bound address; stops it).
    ///
    /// Blocks while binding: call it outside an async context.
    pub fn start(
        addr: SocketAddr,
        options: LiveOptions,
    ) -> Result<(LiveRecorder, LiveView), LiveError> {
        options.check()?;
        // NOTE: the server gets its own runtime and thread, so client connections never run on
        // the session's workers.
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("rigtwin-live-ws")
            .enable_all()
            .build()
            .map_err(|e| LiveError::Start {
                what: "cannot start the server's runtime",
                detail: e.to_string(),
            })?;
        let ctx = foxglove::Context::new();
        let channels = Channels::new(&ctx).map_err(|e| LiveError::Start {
            what: "cannot create the channels",
            detail: e.to_string(),
        })?;
        let latch = Arc::new(LayoutLatch::new(Arc::clone(&channels.layout)));
        // The front door first: a busy or foreign address fails before anything starts.
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind(addr))
            .map_err(|io| LiveError::Bind { addr, io })?;
        let bound = listener
            .local_addr()
            .map_err(|io| LiveError::Bind { addr, io })?;
        // The SDK's server listens on the loopback interface only; clients reach it through
        // the door (`door.rs`), which also speaks the protocol's published subprotocol name.
        let server = runtime
            .block_on(
                foxglove::WebSocketServer::new()
                    .name(format!("rigtwin {}", env!("CARGO_PKG_VERSION")))
                    .context(&ctx)
                    .bind("127.0.0.1", 0)
                    .tokio_runtime(runtime.handle())
                    .listener(Arc::clone(&latch) as Arc<dyn foxglove::websocket::ServerListener>)
                    .message_backlog_size(options.client_backlog)
                    .start(),
            )
            .map_err(|e| LiveError::Start {
                what: "cannot start the server",
                detail: e.to_string(),
            })?;
        let upstream = SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, server.port()));
        let (closing, door_closing) = tokio::sync::watch::channel(false);
        let door = runtime.spawn(super::door::serve(listener, upstream, door_closing));

        let shared = Arc::new(Shared::default());
        let (tx, rx) = mpsc::sync_channel(options.queue_capacity);
        let publisher = Publisher::new(ctx, channels, latch, options.daq_points_per_second);
        let thread = std::thread::Builder::new()
            .name("rigtwin-live".into())
            .spawn(move || publisher.run(rx))
            .map_err(|e| LiveError::Start {
                what: "cannot start the publisher thread",
                detail: e.to_string(),
            })?;
        let recorder = LiveRecorder {
            tx: tx.clone(),
            shared: Arc::clone(&shared),
        };
        Ok((
            recorder,
            LiveView {
                addr: bound,
                options,
                shared,
                tx,
                thread: Some(thread),
                server: Some(server),
                door: Some((closing, door)),
                runtime: Some(runtime),
            },
        ))
    }

    /// The address the server listens on (with the port chosen when 0 was asked for).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URL to connect the Foxglove app to (`ws://IP:PORT`).
    pub fn ws_url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// Clients connected now.
    pub fn client_count(&self) -> usize {
        self.server.as_ref().map_or(0, |s| s.client_count())
    }

    /// Publishes what is queued, then stops the server (closing every connection, waiting up
    /// to [`LiveOptions::shutdown_timeout`]) and its runtime. Blocks: call it outside an async
    /// context.
    pub fn close(mut self) -> LiveStats {
        self.stop()
    }

    fn stop(&mut self) -> LiveStats {
        self.shared.closed.store(true, Ordering::Release);
        // Waits for queue space; the publisher always drains (fails only if it is gone).
        let _ = self.tx.send(Record::Close);
        let mut stats = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(stats)) => stats,
            Some(Err(_)) => {
                tracing::warn!("live view: the publisher thread panicked");
                LiveStats::default()
            }
            None => LiveStats::default(),
        };
        stats.dropped_records = self.shared.dropped.load(Ordering::Relaxed);
        if let (Some(server), Some(runtime)) = (self.server.take(), self.runtime.as_ref()) {
            let shutdown = server.stop();
            let timeout = self.options.shutdown_timeout;
            if runtime
                .block_on(async { tokio::time::timeout(timeout, shutdown.wait()).await })
                .is_err()
            {
                tracing::warn!("live view: connections still open after {timeout:?}; closing them");
            }
        }
        // The SDK's server has closed its connections; the door's relays pass each close
        // frame on to their client before the runtime (and every task on it) goes.
        if let (Some((closing, door)), Some(runtime)) = (self.door.take(), self.runtime.as_ref()) {
            let _ = closing.send(true);
            let timeout = self.options.shutdown_timeout;
            if runtime
                .block_on(async { tokio::time::timeout(timeout, door).await })
                .is_err()
            {
                tracing::warn!("live view: relays still open after {timeout:?}; closing them");
            }
        }
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_timeout(self.options.shutdown_timeout);
        }
        stats
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        if self.runtime.is_some() {
            self.stop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_records_instead_of_waiting() {
        // Nobody reads the queue: every record past its capacity is dropped and counted.
        let (tx, _rx) = mpsc::sync_channel(2);
        let shared = Arc::new(Shared::default());
        let mut recorder = LiveRecorder {
            tx,
            shared: Arc::clone(&shared),
        };
        let block = DaqBlock {
            seq: 0,
            first_sample: 0,
            time: 0.0,
            len: 1,
            counts: vec![0],
        };
        for _ in 0..10 {
            assert!(recorder.block(&block).is_ok());
        }
        assert_eq!(shared.dropped.load(Ordering::Relaxed), 8);
        // A stopped publisher does not fail the session either.
        let (tx, rx) = mpsc::sync_channel(2);
        drop(rx);
        let mut recorder = LiveRecorder { tx, shared };
        assert!(recorder.block(&block).is_ok());
    }

    #[test]
    fn a_port_in_use_is_a_bind_error_with_a_hint() {
        let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = busy.local_addr().unwrap();
        let err = LiveView::start(addr, LiveOptions::default()).unwrap_err();
        assert!(matches!(err, LiveError::Bind { .. }), "{err:?}");
        let text = err.to_string();
        assert!(text.contains(&addr.to_string()), "{text}");
        assert!(text.contains("choose another port"), "{text}");
    }

    #[test]
    fn an_ipv6_address_binds_when_the_machine_has_ipv6() {
        let addr: SocketAddr = "[::1]:0".parse().unwrap();
        match LiveView::start(addr, LiveOptions::default()) {
            Ok((_, view)) => {
                assert!(
                    view.ws_url().starts_with("ws://[::1]:"),
                    "{}",
                    view.ws_url()
                );
                view.close();
            }
            // No IPv6 loopback here: the error says so.
            Err(e) => assert!(e.to_string().contains("[::1]:0"), "{e}"),
        }
    }

    #[test]
    fn the_door_accepts_the_published_and_the_sdk_subprotocols_and_refuses_others() {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;
        use tokio_tungstenite::tungstenite::http::HeaderValue;
        use tokio_tungstenite::tungstenite::Error;

        let addr: SocketAddr = "127.0.0.1:0".parse().unwrap();
        let (_recorder, view) = LiveView::start(addr, LiveOptions::default()).unwrap();
        let url = view.ws_url();
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let connect = |protocol: &'static str| {
            let mut request = url.as_str().into_client_request().unwrap();
            request
                .headers_mut()
                .insert("sec-websocket-protocol", HeaderValue::from_static(protocol));
            rt.block_on(tokio_tungstenite::connect_async(request))
        };
        for protocol in [
            super::super::PUBLISHED_SUBPROTOCOL,
            "foxglove.sdk.v1",
            "foxglove.sdk.v1.1",
        ] {
            let (mut ws, response) = connect(protocol).unwrap();
            assert_eq!(
                response.headers()["sec-websocket-protocol"],
                protocol,
                "{protocol}"
            );
            // The SDK's server answers through the door: its serverInfo comes first.
            let first = rt
                .block_on(futures_util::StreamExt::next(&mut ws))
                .unwrap()
                .unwrap();
            assert!(
                first.to_text().unwrap().contains("\"serverInfo\""),
                "{protocol}: {first}"
            );
        }
        match connect("foxglove.websocket.v2") {
            Err(Error::Http(response)) => assert_eq!(response.status(), 400),
            other => panic!("expected HTTP 400, got {other:?}"),
        }
        view.close();
    }

    #[test]
    fn a_view_starts_on_a_free_port_and_stops_cleanly() {
        let addr: SocketAddr = "127.0.0.1:0".parse().unwrap();
        let (mut recorder, view) = LiveView::start(addr, LiveOptions::default()).unwrap();
        assert_ne!(view.local_addr().port(), 0);
        assert_eq!(view.ws_url(), format!("ws://{}", view.local_addr()));
        let layout = DaqLayout {
            sample_rate: 1000.0,
            block_size: 100,
            channels: vec![crate::rig::ChannelSpec {
                name: "upper_tip".into(),
                kind: crate::rig::ChannelKind::BeamAcceleration,
                scale: 1e-3,
                full_scale_counts: 1000,
            }],
        };
        recorder.layout(&layout).unwrap();
        for seq in 0..10u64 {
            let block = DaqBlock {
                seq,
                first_sample: seq * 100,
                time: seq as f64 * 0.1,
                len: 100,
                counts: vec![1; 100],
            };
            recorder.block(&block).unwrap();
        }
        let stats = view.close();
        // 1000 samples in bins of 5 (200 points per second at 1 kHz); no client: nothing sent.
        assert_eq!(stats.points, 200);
        assert_eq!(stats.sent_total(), 0);
        assert_eq!(stats.dropped_records, 0);
        // After the stop the recorder still does not fail.
        assert!(recorder.layout(&layout).is_ok());
    }
}
