//! The live view's front door: the address clients connect to. It accepts the Foxglove SDK's
//! own subprotocols (`foxglove.sdk.v1.1`, `foxglove.sdk.v1`) and the protocol's published name,
//! `foxglove.websocket.v1` (the `@foxglove/ws-protocol` reference client and the viewers built
//! on it), and relays each connection to the SDK's server, which listens on the loopback
//! interface only. Everything the protocol does (advertise, subscribe, message data, the
//! per-client backlog) stays the SDK's.
//!
// NOTE: `foxglove.sdk.v1` is the SDK's name for the protocol of the published specification
// (its message types cite `ws-protocol/docs/spec.md`): the same JSON and binary messages, so a
// `foxglove.websocket.v1` client is relayed as an `foxglove.sdk.v1` one, frame for frame. The
// SDK (0.30) negotiates only its own names and its server takes no other listener, hence the
// relay rather than a second implementation of the protocol. Back-pressure is kept: the relay
// sends a frame on only after the previous one went out, so a slow client fills the SDK's
// per-client queue, which drops that client's oldest messages as it would without the relay.

use std::net::SocketAddr;

use futures_util::{SinkExt, StreamExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::Message;

/// The protocol's published subprotocol name (`@foxglove/ws-protocol`'s
/// `FoxgloveClient.SUPPORTED_SUBPROTOCOL`).
pub const PUBLISHED_SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// The subprotocols the door accepts, most preferred first, with the one it speaks to the
/// SDK's server for each.
const ACCEPTED: [(&str, &str); 3] = [
    ("foxglove.sdk.v1.1", "foxglove.sdk.v1.1"),
    ("foxglove.sdk.v1", "foxglove.sdk.v1"),
    (PUBLISHED_SUBPROTOCOL, "foxglove.sdk.v1"),
];

/// The subprotocol to answer a client that offered `offered` (the values of its
/// `Sec-WebSocket-Protocol` headers), and the one to speak upstream; `None` when it offered
/// none of [`ACCEPTED`].
fn choose<'a>(offered: impl IntoIterator<Item = &'a str>) -> Option<(&'static str, &'static str)> {
    let offered: Vec<&str> = offered
        .into_iter()
        .flat_map(|h| h.split(','))
        .map(str::trim)
        .collect();
    ACCEPTED
        .iter()
        .find(|(name, _)| offered.contains(name))
        .copied()
}

/// Accepts connections on `listener` and relays each to the SDK's server at `upstream`, until
/// `closing` turns true; then stops accepting and returns once every relay has ended (each
/// ends when the SDK's server closes its side, after passing the close frame on to the
/// client), so stopping the runtime afterwards cuts no connection short.
pub(super) async fn serve(
    listener: TcpListener,
    upstream: SocketAddr,
    mut closing: tokio::sync::watch::Receiver<bool>,
) {
    let mut relays = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    relays.spawn(relay(stream, peer, upstream));
                }
                Err(e) => {
                    // Out of file descriptors and the like: wait a little, then go on accepting.
                    tracing::warn!("live view: cannot accept a connection: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            },
            // Reaps the relays that ended, so the set holds only live ones.
            Some(_) = relays.join_next(), if !relays.is_empty() => {}
            changed = closing.changed() => {
                if changed.is_err() || *closing.borrow() {
                    break;
                }
            }
        }
    }
    drop(listener);
    while relays.join_next().await.is_some() {}
}

/// One client: the handshake (a client without a Foxglove subprotocol gets HTTP 400 and a log
/// line), the upstream connection, then frames both ways until either side closes.
async fn relay(stream: TcpStream, peer: SocketAddr, upstream: SocketAddr) {
    let mut chosen = None;
    let mut refused = None;
    // The signature tungstenite's handshake callback has (its error is the HTTP response).
    #[allow(clippy::result_large_err)]
    let callback = |req: &Request, mut res: Response| -> Result<Response, ErrorResponse> {
        let offered: Vec<&str> = req
            .headers()
            .get_all("sec-websocket-protocol")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .collect();
        match choose(offered.iter().copied()) {
            Some((answer, up)) => {
                res.headers_mut()
                    .insert("sec-websocket-protocol", HeaderValue::from_static(answer));
                chosen = Some((answer, up));
                Ok(res)
            }
            None => {
                refused = Some(offered.join(", "));
                let mut e = ErrorResponse::new(Some(format!(
                    "expected the Sec-WebSocket-Protocol header to offer {}",
                    accepted_list()
                )));
                *e.status_mut() = StatusCode::BAD_REQUEST;
                Err(e)
            }
        }
    };
    let client = match tokio_tungstenite::accept_hdr_async(stream, callback).await {
        Ok(ws) => ws,
        Err(e) => {
            match refused {
                Some(offered) => tracing::warn!(
                    "live view: refused a client at {peer}: it offered the subprotocols \
                     [{offered}], none of {}",
                    accepted_list()
                ),
                None => tracing::debug!("live view: handshake with {peer} failed: {e}"),
            }
            return;
        }
    };
    let Some((answer, up)) = chosen else {
        return;
    };
    let upstream_ws = match connect_upstream(upstream, up).await {
        Ok(ws) => ws,
        Err(e) => {
            tracing::warn!("live view: cannot reach the server for {peer}: {e}");
            let mut client = client;
            let _ = client.close(None).await;
            return;
        }
    };
    tracing::debug!("live view: client {peer} connected with {answer}");
    let (mut to_client, mut from_client) = client.split();
    let (mut to_server, mut from_server) = upstream_ws.split();
    loop {
        tokio::select! {
            m = from_server.next() => match m {
                Some(Ok(m @ (Message::Text(_) | Message::Binary(_)))) => {
                    if to_client.send(m).await.is_err() {
                        break;
                    }
                }
                Some(Ok(Message::Close(frame))) => {
                    let _ = to_client.send(Message::Close(frame)).await;
                    break;
                }
                // Pings are answered by each side's own connection.
                Some(Ok(_)) => {}
                Some(Err(_)) | None => break,
            },
            m = from_client.next() => match m {
                Some(Ok(m @ (Message::Text(_) | Message::Binary(_)))) => {
                    if to_server.send(m).await.is_err() {
                        break;
                    }
                }
                Some(Ok(Message::Close(frame))) => {
                    let _ = to_server.send(Message::Close(frame)).await;
                    break;
                }
                Some(Ok(_)) => {}
                Some(Err(_)) | None => break,
            },
        }
    }
    let _ = to_client.close().await;
    let _ = to_server.close().await;
}

async fn connect_upstream(
    upstream: SocketAddr,
    subprotocol: &'static str,
) -> Result<
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<TcpStream>>,
    tokio_tungstenite::tungstenite::Error,
> {
    let mut request = format!("ws://{upstream}").into_client_request()?;
    request.headers_mut().insert(
        "sec-websocket-protocol",
        HeaderValue::from_static(subprotocol),
    );
    let (ws, _) = tokio_tungstenite::connect_async(request).await?;
    Ok(ws)
}

fn accepted_list() -> String {
    ACCEPTED
        .iter()
        .map(|(name, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_published_and_the_sdk_subprotocols_are_accepted() {
        assert_eq!(
            choose(["foxglove.websocket.v1"]),
            Some(("foxglove.websocket.v1", "foxglove.sdk.v1"))
        );
        assert_eq!(
            choose(["foxglove.sdk.v1"]),
            Some(("foxglove.sdk.v1", "foxglove.sdk.v1"))
        );
        // The SDK's newest first, whatever the client's order; lists in one header too.
        assert_eq!(
            choose([
                "foxglove.websocket.v1, foxglove.sdk.v1",
                "foxglove.sdk.v1.1"
            ]),
            Some(("foxglove.sdk.v1.1", "foxglove.sdk.v1.1"))
        );
        assert_eq!(choose(["foxglove.websocket.v2", "x"]), None);
        assert_eq!(choose([]), None);
    }
}
