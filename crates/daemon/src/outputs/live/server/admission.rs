//! Who may start a session: the places in the handshake (at most
//! [`super::HANDSHAKES`], [`super::HANDSHAKES_PER_ADDR`] from one address,
//! each for [`super::HANDSHAKE`]), the one line a flood of refusals is
//! logged as, and the HTTP upgrade with its subprotocol. Apart from the
//! session so that what a connection costs before it is a client is read
//! in one place.

use super::{REQUEST_LIMIT, SUBPROTOCOLS, WRITE_BACKLOG};
use crate::outputs::live::hub::{host, Hub};
use lightpose_core::ratelog::{Close, RateLog};
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::WebSocketStream;

/// The connections in their handshake: how many, and from each address.
pub(super) struct Gate {
    pub(super) total: usize,
    pub(super) per_addr: usize,
    pub(super) held: Mutex<(usize, HashMap<IpAddr, usize>)>,
}

/// Why a connection found no place in the handshake.
pub(super) enum Shut {
    Total,
    Addr(IpAddr),
}

/// A place in the handshake, given back when dropped.
pub(super) struct Pass {
    gate: Arc<Gate>,
    ip: IpAddr,
}

impl Gate {
    pub(super) fn enter(self: &Arc<Gate>, addr: SocketAddr) -> Result<Pass, Shut> {
        let ip = host(addr);
        let mut held = self.held.lock().map_err(|_| Shut::Total)?;
        let (all, by_addr) = &mut *held;
        if *all >= self.total {
            return Err(Shut::Total);
        }
        let n = by_addr.entry(ip).or_insert(0);
        if *n >= self.per_addr {
            return Err(Shut::Addr(ip));
        }
        *n += 1;
        *all += 1;
        Ok(Pass {
            gate: self.clone(),
            ip,
        })
    }
}

impl Drop for Pass {
    fn drop(&mut self) {
        let Ok(mut held) = self.gate.held.lock() else {
            return;
        };
        let (all, by_addr) = &mut *held;
        *all = all.saturating_sub(1);
        if let Some(n) = by_addr.get_mut(&self.ip) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                by_addr.remove(&self.ip);
            }
        }
    }
}

/// Connections refused for too many in their handshake, by core's rule.
pub(super) struct FloodLog {
    pub(super) log: RateLog,
    pub(super) hub: Arc<Hub>,
}

impl FloodLog {
    /// The closing line of the refusals `when` (core's `RateLog::settle`
    /// once they stopped, `RateLog::flush` at stop).
    pub(super) fn close(&mut self, now: std::time::Instant, when: Close) {
        if let Some((k, last)) = self.hub.close_conn_lines(now, when) {
            tracing::info!(
                connections = self.hub.connections.load(Relaxed),
                since_last_line = k,
                "foxglove: connection events (connected, gone, turned away, a failed handshake): {when}: {k} more since the last line, the last {:.1} s ago",
                last.as_secs_f64()
            );
        }
        if let Some(k) = self.log.close(now, when) {
            tracing::warn!(
                handshakes_refused = self.hub.handshakes_refused.load(Relaxed),
                since_last_line = k,
                "foxglove: connections refused (too many in their handshake): {when}: {k} more since the last line, the last {:.1} s ago",
                self.log.since_last(now).as_secs_f64()
            );
        }
    }
}

/// The accept loop ends only by being dropped (its task aborted at stop).
impl Drop for FloodLog {
    fn drop(&mut self) {
        self.close(std::time::Instant::now(), Close::AtStop);
    }
}

/// The subprotocol to answer with, from the client's offer.
fn choose(req: &Request) -> Option<&'static str> {
    let offered: Vec<String> = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(|p| p.trim().to_string())
        .collect();
    SUBPROTOCOLS
        .into_iter()
        .find(|p| offered.iter().any(|o| o == p))
}

/// The HTTP upgrade, within `deadline` in all (a client that sends its
/// request a byte at a time does not get longer).
pub(super) async fn handshake(
    stream: TcpStream,
    deadline: Duration,
) -> Result<WebSocketStream<TcpStream>, String> {
    #[allow(clippy::result_large_err)] // tungstenite's callback signature
    let callback = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
        let Some(p) = choose(req) else {
            let mut e = ErrorResponse::new(Some(format!(
                "lightposed speaks Foxglove's WebSocket protocol: offer subprotocol {}",
                SUBPROTOCOLS.join(" or ")
            )));
            *e.status_mut() = StatusCode::BAD_REQUEST;
            return Err(e);
        };
        resp.headers_mut()
            .insert("sec-websocket-protocol", HeaderValue::from_static(p));
        Ok(resp)
    };
    // A client's requests are a few hundred bytes: refuse a flood.
    let limits = WebSocketConfig::default()
        .max_message_size(Some(REQUEST_LIMIT))
        .max_frame_size(Some(REQUEST_LIMIT));
    let limits = limits.max_write_buffer_size(limits.write_buffer_size + WRITE_BACKLOG);
    let accept = tokio_tungstenite::accept_hdr_async_with_config(stream, callback, Some(limits));
    match tokio::time::timeout(deadline, accept).await {
        Ok(Ok(ws)) => Ok(ws),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err(format!("no WebSocket handshake within {deadline:?}")),
    }
}
