//! The server side of Foxglove's WebSocket protocol, the subset a live
//! view needs (https://github.com/foxglove/ws-protocol, docs/foxglove.md
//! says why not the `foxglove` crate): the handshake with subprotocol
//! `foxglove.sdk.v1` or `foxglove.websocket.v1`, then `serverInfo` and
//! `advertise` (the seven channels of a recording, each with its JSON
//! Schema), then `subscribe` / `unsubscribe` from the client, and binary
//! `messageData` frames (opcode 1, subscription id, log time, the JSON)
//! from the hub. Anything else a client sends is answered with a warning
//! `status` and otherwise ignored.
//!
//! One task per client, on the daemon's runtime: it reads the client's
//! requests and writes what the hub queued for it. Every write (the
//! greeting, a reply, queued messages, a ping, the close) that does not
//! finish within [`STALL`] (a client that stopped reading, a cable pulled)
//! ends that client: a write waits in the same loop as the silence check,
//! so an unbounded one would hold the client's place for as long as it
//! keeps its socket open. Meanwhile its queue fills and the hub drops and
//! counts its messages. At most [`HANDSHAKES`] connections may be in their
//! handshake at once; more are closed at once and counted
//! (`handshakes_refused`): each holds a descriptor, and a flood of
//! half-open ones once took every descriptor the daemon had (the DVL's
//! reconnect and the recording's rotation need them).
//!
//! A client that subscribed to nothing is never written to, so the
//! server pings every client ([`PING`]; browsers and
//! Foxglove answer by themselves) and ends one from which nothing at all
//! has come for [`SILENCE`] (counted, `timed_out`): else a laptop
//! unplugged from the tether would hold its place among `max_clients`
//! until a restart.
//!
//! A client that answers the pings but subscribes to nothing (a forgotten
//! browser tab, a script left connected) would still hold its place, and
//! `max_clients` of them would turn the operator's Foxglove away at sea.
//! So a newcomer that finds every place taken has the client that has
//! subscribed to nothing the longest, for [`IDLE_EVICT`] at least, closed
//! to make room ([`Hub::join`]; logged, counted `evicted`); idle time
//! counts from the join or from the unsubscribe that left the client
//! nothing. A client that subscribes to anything is never evicted; with
//! no client idle long enough the newcomer is refused as before.

use super::hub::{Client, Hub};
use futures_util::{SinkExt, StreamExt};
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_logs::schema::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use lightpose_logs::Channel;
use serde::Deserialize;
use serde_json::json;
use std::net::SocketAddr;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, MissedTickBehavior};
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::{CloseFrame, WebSocketConfig};
use tokio_tungstenite::tungstenite::{Bytes, Error as WsError, Message as Ws};
use tokio_tungstenite::WebSocketStream;

/// Subprotocols served, best first: both name protocol v1 with channels
/// advertised with their schemas inline (the newer name is the SDK's).
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.websocket.v1"];

/// A write that takes longer ends the client.
pub const STALL: Duration = Duration::from_secs(10);
/// A WebSocket Ping to every client this often.
pub const PING: Duration = Duration::from_secs(15);
/// A client from which nothing (a pong, a request) came for this long is
/// gone: three pings unanswered.
pub const SILENCE: Duration = Duration::from_secs(45);
/// A client that has subscribed to nothing for this long may be closed to
/// make room for a newcomer when every place is taken. Foxglove subscribes
/// within a second or two of connecting (its panels ask for their topics
/// as the layout loads), and switching layouts unsubscribes and
/// subscribes again within a second, so a minute never catches a client
/// in use; it is short beside a dive, so an operator turned away by
/// forgotten tabs gets in on retrying within a minute. Longer than
/// [`SILENCE`], so a client that is gone altogether is ended by the pings
/// first.
pub const IDLE_EVICT: Duration = Duration::from_secs(60);
/// A handshake that takes longer ends the connection.
const HANDSHAKE: Duration = Duration::from_secs(5);
/// Connections in their handshake at once: real clients are a handful
/// (`max_clients`), so 16 is plenty and bounds what a flood costs.
pub const HANDSHAKES: usize = 16;
/// Queued messages written before one flush.
const BATCH: usize = 64;
/// Largest message a client may send (a subscribe to every channel is
/// about 300 bytes).
const REQUEST_LIMIT: usize = 64 << 10;

/// Bytes a connection may hold unsent (tungstenite's write buffer, 128 KiB
/// by default, plus this): more, and the client is not reading. Unbounded
/// (tungstenite's default), a client that sent pings without end and read
/// nothing grew the daemon by its upload rate, its pongs queued (an audit:
/// 3.4 GB in 17 s); the data the daemon sends has its own stall limit.
const WRITE_BACKLOG: usize = 1 << 20;

/// Queue sizes and limits of the server.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub client_queue: usize,
    pub max_clients: usize,
    /// [`PING`] and [`SILENCE`]; shorter in tests.
    pub ping: Duration,
    pub silence: Duration,
    /// [`STALL`]; shorter in tests.
    pub stall: Duration,
    /// [`HANDSHAKES`].
    pub handshakes: usize,
    /// [`IDLE_EVICT`]; shorter in tests.
    pub idle_evict: Duration,
}

impl Limits {
    /// The daemon's limits, with its queue size and client count.
    pub fn new(client_queue: usize, max_clients: usize) -> Limits {
        Limits {
            client_queue,
            max_clients,
            ping: PING,
            silence: SILENCE,
            stall: STALL,
            handshakes: HANDSHAKES,
            idle_evict: IDLE_EVICT,
        }
    }
}

/// Why a session ended.
enum End {
    /// Nothing came from the client for this long (no pong either).
    Silent(Duration),
    /// Closed to make room for a newcomer: it subscribed to nothing.
    Evicted,
    /// Cut for not reading: a write stalled, or what waits unsent for it
    /// reached `WRITE_BACKLOG` (a client that sends and never reads).
    NotReading(String),
    /// It closed, an error, the daemon stopping.
    Other(String),
}

impl From<String> for End {
    fn from(why: String) -> End {
        End::Other(why)
    }
}

/// Accept clients on `listener` until the task is aborted.
pub async fn serve(listener: TcpListener, hub: Arc<Hub>, limits: Limits) {
    let handshaking = Arc::new(Semaphore::new(limits.handshakes));
    // A flood is logged by core's rule for repeated lines, not per
    // connection. Dropped with the task (aborted at stop), it tells what
    // is pending.
    let mut flood = FloodLog {
        log: RateLog::new(),
        hub: hub.clone(),
    };
    loop {
        // Refusals not told yet: wake at least every second for their
        // closing line (accept is cancel-safe); else wait for the next
        // connection as long as it takes.
        let pending = || flood.log.pending() > 0 || flood.hub.conn_lines_pending();
        let accepted = if pending() {
            tokio::time::timeout(Duration::from_secs(1), listener.accept())
                .await
                .ok()
        } else {
            Some(listener.accept().await)
        };
        flood.close(std::time::Instant::now(), Close::Over);
        let Some(accepted) = accepted else { continue };
        match accepted {
            Ok((stream, addr)) => match handshaking.clone().try_acquire_owned() {
                Ok(permit) => {
                    tokio::spawn(client(stream, addr, hub.clone(), limits, permit));
                }
                Err(_) => {
                    // Closed at once (dropped): the descriptor is back.
                    let n = hub.handshakes_refused.fetch_add(1, Relaxed) + 1;
                    if let Some(k) = flood.log.tick(std::time::Instant::now()) {
                        tracing::warn!(
                            handshakes_refused = n,
                            since_last_line = k,
                            "foxglove: {addr} closed: {} connections already in their handshake",
                            limits.handshakes
                        );
                    }
                }
            },
            Err(e) => {
                // Out of descriptors, say: wait rather than spin.
                tracing::warn!("foxglove: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    }
}

/// Connections refused for too many in their handshake, by core's rule.
struct FloodLog {
    log: RateLog,
    hub: Arc<Hub>,
}

impl FloodLog {
    /// The closing line of the refusals `when` (core's `RateLog::settle`
    /// once they stopped, `RateLog::flush` at stop).
    fn close(&mut self, now: std::time::Instant, when: Close) {
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

async fn handshake(stream: TcpStream) -> Result<WebSocketStream<TcpStream>, String> {
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
    match tokio::time::timeout(HANDSHAKE, accept).await {
        Ok(Ok(ws)) => Ok(ws),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err("handshake timed out".into()),
    }
}

/// `serverInfo` and `advertise`, the first two messages of a session.
pub fn greeting(session: &str) -> [String; 2] {
    let info = json!({
        "op": "serverInfo",
        "name": format!("lightposed {}", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "metadata": {},
        "sessionId": session,
    });
    let channels: Vec<_> = Channel::ALL
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "id": i + 1,
                "topic": c.topic(),
                "encoding": MESSAGE_ENCODING,
                "schemaName": c.schema_name(),
                "schemaEncoding": SCHEMA_ENCODING,
                "schema": c.schema(),
            })
        })
        .collect();
    let adv = json!({"op": "advertise", "channels": channels});
    [info.to_string(), adv.to_string()]
}

/// What a client may send (the ops a live view needs).
#[derive(Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum Request_ {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct Subscription {
    id: u32,
    channel_id: u64,
}

/// The index of channel `id` (advertised from 1): `None` for 0 and for
/// an id beyond `usize`, which must not wrap (on 32-bit ARM 2³² + 1 would
/// be channel 1).
fn channel_index(id: u64) -> Option<usize> {
    let i = usize::try_from(id.checked_sub(1)?).ok()?;
    (i < Channel::ALL.len()).then_some(i)
}

/// A warning `status` message for the client.
fn warning(msg: &str) -> Ws {
    Ws::text(json!({"op": "status", "level": 1, "message": msg}).to_string())
}

/// Act on one text message; a reply when there is something to say.
fn request(hub: &Hub, c: &Client, text: &str) -> Option<Ws> {
    match serde_json::from_str::<Request_>(text) {
        Ok(Request_::Subscribe { subscriptions }) => {
            let unknown: Vec<u64> = subscriptions
                .iter()
                .filter(|s| {
                    let index = channel_index(s.channel_id);
                    !index.is_some_and(|i| c.subscribe(hub, s.id, i))
                })
                .map(|s| s.channel_id)
                .collect();
            (!unknown.is_empty()).then(|| warning(&format!("no channel {unknown:?}")))
        }
        Ok(Request_::Unsubscribe { subscription_ids }) => {
            for id in subscription_ids {
                c.unsubscribe(hub, id);
            }
            None
        }
        Err(e) => Some(warning(&format!(
            "not understood (lightposed takes subscribe and unsubscribe): {e}"
        ))),
    }
}

/// Write `first` and whatever else is queued (up to [`BATCH`]), then flush.
async fn write_batch(
    ws: &mut WebSocketStream<TcpStream>,
    rx: &mut mpsc::Receiver<Bytes>,
    c: &Client,
    first: Bytes,
    stall: Duration,
) -> Result<(), End> {
    let mut n = 1;
    let write = async {
        ws.feed(Ws::binary(first)).await?;
        while n < BATCH {
            let Ok(more) = rx.try_recv() else { break };
            ws.feed(Ws::binary(more)).await?;
            n += 1;
        }
        ws.flush().await
    };
    let written = tokio::time::timeout(stall, write).await;
    if matches!(written, Ok(Ok(()))) {
        c.sent.fetch_add(n as u64, Relaxed);
    }
    ended(written, stall)
}

/// Send `msg`, bounded by `stall` like every write to a client.
async fn send(ws: &mut WebSocketStream<TcpStream>, msg: Ws, stall: Duration) -> Result<(), End> {
    ended(tokio::time::timeout(stall, ws.send(msg)).await, stall)
}

/// How a write bounded by `stall` ended the session, if it did.
fn ended(
    written: Result<Result<(), WsError>, tokio::time::error::Elapsed>,
    stall: Duration,
) -> Result<(), End> {
    match written {
        Ok(Ok(())) => Ok(()),
        Ok(Err(WsError::WriteBufferFull(_))) => Err(End::NotReading(format!(
            "not reading: {WRITE_BACKLOG} bytes wait unsent for it"
        ))),
        Ok(Err(e)) => Err(End::Other(e.to_string())),
        Err(_) => Err(End::NotReading(format!(
            "not reading: a write took more than {stall:?}"
        ))),
    }
}

/// One client's session, from the handshake to its end.
async fn client(
    stream: TcpStream,
    addr: SocketAddr,
    hub: Arc<Hub>,
    limits: Limits,
    handshaking: OwnedSemaphorePermit,
) {
    let _ = stream.set_nodelay(true);
    let shaken = handshake(stream).await;
    drop(handshaking); // the handshake is over: room for another
    let mut ws = match shaken {
        Ok(ws) => ws,
        Err(e) => {
            if let Some(k) = hub.conn_line() {
                tracing::info!(since_last_line = k, "foxglove: {addr}: {e}");
            }
            return;
        }
    };
    let (tx, mut rx) = mpsc::channel(limits.client_queue);
    let Some(c) = admit(&hub, addr, tx, &limits) else {
        let _ = tokio::time::timeout(limits.stall, ws.close(None)).await;
        return;
    };
    if let Some(k) = hub.conn_line() {
        tracing::info!(since_last_line = k, "foxglove: {addr} connected");
    }
    let end = session_loop(&mut ws, &mut rx, &hub, &c, &limits).await;
    if matches!(end, End::NotReading(_)) {
        // Counted before its place is freed: whoever sees it gone sees why.
        hub.not_reading.fetch_add(1, Relaxed);
    }
    hub.leave(c.id);
    let close = limits.stall.min(Duration::from_secs(1));
    let frame = matches!(end, End::Evicted).then(|| CloseFrame {
        code: CloseCode::Again,
        reason: "closed to make room for another client: subscribed to nothing".into(),
    });
    let _ = tokio::time::timeout(close, ws.close(frame)).await;
    let (sent, dropped) = (c.sent.load(Relaxed), c.dropped.load(Relaxed));
    match end {
        End::Silent(d) => {
            hub.timed_out.fetch_add(1, Relaxed);
            tracing::warn!(
                "foxglove: {addr} dropped: nothing from it for {d:.0?} (pings unanswered: \
                 a cable pulled?); {sent} messages sent, {dropped} dropped"
            );
        }
        End::Evicted => tracing::info!(
            "foxglove: {addr} gone (closed to make room); {sent} messages sent, {dropped} dropped"
        ),
        End::NotReading(why) => {
            if let Some(k) = hub.conn_line() {
                tracing::warn!(
                    since_last_line = k,
                    "foxglove: {addr} cut ({why}); {sent} messages sent, {dropped} dropped"
                )
            }
        }
        End::Other(why) => {
            if let Some(k) = hub.conn_line() {
                tracing::info!(
                    since_last_line = k,
                    "foxglove: {addr} gone ({why}); {sent} messages sent, {dropped} dropped"
                )
            }
        }
    }
}

/// Join the hub, making room by evicting a long-idle client if every
/// place is taken (one line for the operator saying who went and why);
/// `None` (logged) when the newcomer is turned away.
fn admit(
    hub: &Hub,
    addr: SocketAddr,
    tx: mpsc::Sender<Bytes>,
    limits: &Limits,
) -> Option<Arc<Client>> {
    let max = limits.max_clients;
    let Some(joined) = hub.join(addr, tx, max, limits.idle_evict) else {
        if hub.closing() {
            tracing::info!("foxglove: {addr} turned away: the daemon stops");
            return None;
        }
        if let Some(k) = hub.conn_line() {
            tracing::warn!(
                refused = hub.refused.load(Relaxed),
                since_last_line = k,
                "foxglove: {addr} turned away: {max} clients already, none of them \
                 subscribed to nothing for {:.0} s or more",
                limits.idle_evict.as_secs_f64()
            );
        }
        return None;
    };
    if let Some(gone) = joined.evicted {
        tracing::warn!(
            evicted = hub.evicted.load(Relaxed),
            "foxglove: {} disconnected to make room for {addr} ({max} clients already): \
             it held a place for {:.0} s without subscribing to anything",
            gone.addr,
            gone.idle.as_secs_f64()
        );
    }
    Some(joined.client)
}

/// On each ping tick: the end of a client silent for `silence`, else a
/// Ping sent (bounded like any write).
async fn ping(
    ws: &mut WebSocketStream<TcpStream>,
    heard: Instant,
    limits: &Limits,
) -> Result<(), End> {
    let quiet = heard.elapsed();
    if quiet >= limits.silence {
        return Err(End::Silent(quiet));
    }
    send(ws, Ws::Ping(Bytes::new()), limits.stall).await
}

/// Greet, then serve requests, queued messages and pings until the client
/// or the hub ends; why it ended.
async fn session_loop(
    ws: &mut WebSocketStream<TcpStream>,
    rx: &mut mpsc::Receiver<Bytes>,
    hub: &Hub,
    c: &Client,
    limits: &Limits,
) -> End {
    for text in greeting(&hub.session) {
        if let Err(e) = send(ws, Ws::text(text), limits.stall).await {
            return e;
        }
    }
    let mut heard = Instant::now();
    let mut ticks = tokio::time::interval_at(heard + limits.ping, limits.ping);
    // After a long stall, one ping, not a burst of them.
    ticks.set_missed_tick_behavior(MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            msg = ws.next() => {
                if let Some(Ok(_)) = &msg {
                    heard = Instant::now(); // a pong or anything else
                }
                match msg {
                    Some(Ok(Ws::Text(t))) => {
                        if let Some(reply) = request(hub, c, t.as_str()) {
                            if let Err(e) = send(ws, reply, limits.stall).await {
                                return e;
                            }
                        }
                    }
                    Some(Ok(Ws::Close(_))) | None => return "closed".to_string().into(),
                    Some(Ok(_)) => {} // pongs; pings are answered by tungstenite
                    Some(Err(e)) => return e.to_string().into(),
                }
            }
            out = rx.recv() => match out {
                Some(first) => {
                    if let Err(e) = write_batch(ws, rx, c, first, limits.stall).await {
                        return e;
                    }
                }
                None => return "the daemon stops".to_string().into(),
            },
            _ = ticks.tick() => {
                if let Err(end) = ping(ws, heard, limits).await {
                    return end;
                }
            }
            _ = c.evicted() => {
                if hub.closing() {
                    return "the daemon stops".to_string().into();
                }
                return End::Evicted;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greeting_advertises_every_channel_with_its_schema() {
        let [info, adv] = greeting("s1");
        let info: serde_json::Value = serde_json::from_str(&info).unwrap();
        assert_eq!(info["op"], "serverInfo");
        assert_eq!(info["sessionId"], "s1");
        let adv: serde_json::Value = serde_json::from_str(&adv).unwrap();
        let ch = adv["channels"].as_array().unwrap();
        assert_eq!(ch.len(), 7);
        for (i, c) in ch.iter().enumerate() {
            assert_eq!(c["id"], i + 1);
            assert_eq!(c["topic"], Channel::ALL[i].topic());
            let schema: serde_json::Value =
                serde_json::from_str(c["schema"].as_str().unwrap()).unwrap();
            assert_eq!(schema["title"], c["schemaName"]);
        }
    }

    #[test]
    fn requests_subscribe_unsubscribe_and_the_rest_is_warned() {
        let hub = Hub::new("127.0.0.1:1".parse().unwrap());
        let (tx, _rx) = mpsc::channel(4);
        let c = hub
            .join("127.0.0.1:2".parse().unwrap(), tx, 4, IDLE_EVICT)
            .unwrap()
            .client;
        let sub = r#"{"op":"subscribe","subscriptions":[{"id":5,"channelId":1},{"id":6,"channelId":9},{"id":7,"channelId":0}]}"#;
        let reply = request(&hub, &c, sub).expect("a warning for channels 9 and 0");
        assert!(
            reply.to_text().unwrap().contains("no channel [9, 0]"),
            "{reply}"
        );
        assert!(hub.wanted());
        assert!(request(&hub, &c, r#"{"op":"unsubscribe","subscriptionIds":[5]}"#).is_none());
        assert!(!hub.wanted());
        // 2³² + 1: channel 1 once cut to 32 bits (armv7's usize).
        let wide = r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":4294967297}]}"#;
        let reply = request(&hub, &c, wide).expect("a warning");
        assert!(
            reply.to_text().unwrap().contains("no channel [4294967297]"),
            "{reply}"
        );
        assert!(!hub.wanted(), "subscribed to a channel that does not exist");
        assert_eq!(channel_index(1), Some(0));
        assert_eq!(channel_index(7), Some(6));
        for bad in [0, 8, 1 << 32, (1 << 32) + 1, u64::MAX] {
            assert_eq!(channel_index(bad), None, "{bad}");
        }
        let reply = request(&hub, &c, r#"{"op":"advertise","channels":[]}"#).unwrap();
        assert!(
            reply.to_text().unwrap().contains("not understood"),
            "{reply}"
        );
    }
}
