//! The server side of Foxglove's WebSocket protocol, the subset a live
//! view needs (https://github.com/foxglove/ws-protocol, docs/foxglove.md
//! says why not the `foxglove` crate): the handshake with subprotocol
//! `foxglove.sdk.v1` or `foxglove.websocket.v1`, then `serverInfo` and
//! `advertise` (the seven channels of a recording, each with its JSON
//! Schema), then `subscribe` / `unsubscribe` from the client, and binary
//! `messageData` frames (opcode 1, subscription id, log time, the JSON)
//! from the hub. Anything else a client sends (another op, a binary
//! message) is answered with a warning `status`, short whatever it quotes,
//! and otherwise ignored.
//!
//! One task per client, on the daemon's runtime: it reads the client's
//! requests and writes what the hub queued for it. A client that has not
//! read what it was sent (the greeting, a reply, queued messages) within
//! [`STALL`] is cut, its place freed. Whether it read is not what the
//! kernel took: the socket buffers on both ends (megabytes, autotuned), an
//! SSH tunnel's window, hold tens of seconds of the stream for a client
//! that stopped reading (four such held every place for ~38 s, not 10, and
//! were counted thousands of messages `sent`). So each Ping carries a
//! number, and its Pong, which a WebSocket sends only on reading the Ping
//! and so everything before it, is the proof ([`Reading`]); `sent` counts
//! only messages so shown read. The send buffer is kept small
//! ([`SEND_BUFFER`]) so that a client that reads, slowly, answers soon
//! (it loses messages, counted, rather than getting them late). Every
//! write is bounded by the same deadline, as it waits in the same loop as
//! the checks. Meanwhile a non-reader's queue fills and the hub drops and
//! counts its messages.
//!
//! At most [`HANDSHAKES`] connections may be in their handshake at once,
//! [`HANDSHAKES_PER_ADDR`] of them from one address, each for
//! [`HANDSHAKE`] at most; more are closed at once and counted
//! (`handshakes_refused`): each holds a descriptor, and a flood of
//! half-open ones once took every descriptor the daemon had (the DVL's
//! reconnect and the recording's rotation need them); 40 connections
//! sending their headers a byte at a time, or 16 sending nothing, from one
//! host kept every other client out for 25 s. Past the handshake, one
//! address holds at most `max_clients_per_addr` places ([`Hub::join`]).
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

mod admission;
mod requests;

use super::hub::{host, Client, Hub, Refused};
use admission::{handshake, FloodLog, Gate, Pass, Shut};
use futures_util::{SinkExt, StreamExt};
use lightpose_core::ratelog::{Close, RateLog};
pub use requests::greeting;
use requests::{binary_warning, request};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::time::{Instant, MissedTickBehavior};
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::{Bytes, Error as WsError, Message as Ws};
use tokio_tungstenite::WebSocketStream;

/// Subprotocols served, best first: both name protocol v1 with channels
/// advertised with their schemas inline (the newer name is the SDK's).
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.websocket.v1"];

/// A client that has not read what it was sent this long ago is cut
/// (docs/foxglove.md: "reads nothing for 10 s").
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
/// A handshake that takes longer ends the connection: a real client's
/// takes milliseconds (one request, one response), even over a tether.
pub const HANDSHAKE: Duration = Duration::from_secs(2);
/// Connections in their handshake at once: real clients are a handful
/// (`max_clients`), so 16 is plenty and bounds what a flood costs.
pub const HANDSHAKES: usize = 16;
/// Of them, from one address: a host flooding half-open connections
/// leaves the other 12 to everyone else.
pub const HANDSHAKES_PER_ADDR: usize = 4;
/// Send buffer asked for each connection (Linux doubles it): what a
/// client that reads slowly has waiting in the kernel, beside its queue.
/// Autotuned it grew to 4 MB, seconds of the stream; 128 KiB is still
/// 6 MB/s over a 20 ms round trip, thirty times the live view's rate at
/// 100 Hz.
pub const SEND_BUFFER: usize = 64 << 10;
/// Longest text of a `status` message: an error quotes the request (an
/// unknown op whole), and a 60 KiB op was sent back whole.
const STATUS_TEXT: usize = 256;
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
    /// [`HANDSHAKES`], [`HANDSHAKES_PER_ADDR`], [`HANDSHAKE`].
    pub handshakes: usize,
    pub handshakes_per_addr: usize,
    pub handshake: Duration,
    /// Places one source address may hold (`[foxglove]`
    /// `max_clients_per_addr`).
    pub max_clients_per_addr: usize,
    /// [`IDLE_EVICT`]; shorter in tests.
    pub idle_evict: Duration,
}

impl Limits {
    /// The daemon's limits, with its queue size and client count; every
    /// place may go to one address until `max_clients_per_addr` is set
    /// (the daemon sets it from its config).
    pub fn new(client_queue: usize, max_clients: usize) -> Limits {
        Limits {
            client_queue,
            max_clients,
            ping: PING,
            silence: SILENCE,
            stall: STALL,
            handshakes: HANDSHAKES,
            handshakes_per_addr: HANDSHAKES_PER_ADDR,
            handshake: HANDSHAKE,
            max_clients_per_addr: max_clients,
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
    /// Cut for not reading: what it was sent `stall` ago not shown read,
    /// or what waits unsent for it reached `WRITE_BACKLOG` (a client that
    /// sends and never reads).
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
    let gate = Arc::new(Gate {
        total: limits.handshakes,
        per_addr: limits.handshakes_per_addr,
        held: Mutex::new((0, HashMap::new())),
    });
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
            Ok((stream, addr)) => match gate.enter(addr) {
                Ok(pass) => {
                    tokio::spawn(client(stream, addr, hub.clone(), limits, pass));
                }
                Err(shut) => {
                    // Closed at once (dropped): the descriptor is back.
                    let n = hub.handshakes_refused.fetch_add(1, Relaxed) + 1;
                    if let Some(k) = flood.log.tick(std::time::Instant::now()) {
                        let why = match shut {
                            Shut::Total => format!("{} connections", limits.handshakes),
                            Shut::Addr(ip) => {
                                format!("{} connections from {ip}", limits.handshakes_per_addr)
                            }
                        };
                        tracing::warn!(
                            handshakes_refused = n,
                            since_last_line = k,
                            "foxglove: {addr} closed: {why} already in their handshake"
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

/// What a client has shown it read. A Ping carries a number, and the
/// client's WebSocket answers it (the Pong echoes it) on reading it, so
/// after everything written before it: what the kernel buffers, a tunnel
/// or a proxy hold for a client that stopped reading does not pass for
/// read. One Ping at a time: a WebSocket answers only the latest of
/// several it has not answered yet.
#[derive(Debug, Default)]
pub struct Reading {
    /// `messageData` written to the socket, and those of them shown read.
    pub written: u64,
    pub read: u64,
    /// The first write (greeting, reply, message) not shown read, before
    /// the Ping in flight; the first after it.
    unread_since: Option<Instant>,
    after_ping: Option<Instant>,
    /// The Ping in flight: its number, and `written` when it went.
    ping: Option<(u64, u64)>,
    last_ping: Option<Instant>,
    next: u64,
}

impl Reading {
    /// Something was written at `at` (not a Ping).
    fn wrote(&mut self, at: Instant) {
        if self.ping.is_some() {
            self.after_ping.get_or_insert(at);
        } else {
            self.unread_since.get_or_insert(at);
        }
    }

    /// The oldest write not shown read.
    fn oldest_unread(&self) -> Option<Instant> {
        self.unread_since.or(self.after_ping)
    }

    /// When the client is cut unless it shows it read: `stall` after the
    /// oldest write not shown read, or after `now` (a write's bound).
    fn deadline(&self, now: Instant, stall: Duration) -> Instant {
        self.oldest_unread().unwrap_or(now) + stall
    }

    /// When a Ping should go: none in flight and something unread, `gap`
    /// after it was written (one Ping covers what a gap brings) and after
    /// the last Ping.
    fn ping_due(&self, gap: Duration) -> Option<Instant> {
        if self.ping.is_some() {
            return None;
        }
        let due = self.unread_since? + gap;
        Some(self.last_ping.map_or(due, |t| (t + gap).max(due)))
    }

    /// The next Ping, in flight from `at`.
    fn ping(&mut self, at: Instant) -> Ws {
        let n = self.next;
        self.next += 1;
        self.ping = Some((n, self.written));
        self.last_ping = Some(at);
        Ws::Ping(Bytes::copy_from_slice(&n.to_le_bytes()))
    }

    /// A Pong came: if it answers the Ping in flight, all before that
    /// Ping was read; whether it did.
    fn pong(&mut self, payload: &[u8]) -> bool {
        match self.ping {
            Some((n, covers)) if payload == n.to_le_bytes() => {
                self.read = covers;
                self.ping = None;
                self.unread_since = self.after_ping.take();
                true
            }
            _ => false,
        }
    }
}

/// Write `first` and whatever else is queued (up to [`BATCH`]), then flush,
/// by the client's deadline; a batch not written is counted dropped.
async fn write_batch(
    ws: &mut WebSocketStream<TcpStream>,
    rx: &mut mpsc::Receiver<Bytes>,
    c: &Client,
    r: &mut Reading,
    first: Bytes,
    stall: Duration,
) -> Result<(), End> {
    let start = Instant::now();
    r.wrote(start);
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
    let written = tokio::time::timeout_at(r.deadline(start, stall), write).await;
    if matches!(written, Ok(Ok(()))) {
        r.written += n as u64;
    } else {
        c.dropped.fetch_add(n as u64, Relaxed);
    }
    ended(written, stall)
}

/// Send `msg` (the greeting, a reply, a Ping), bounded by the client's
/// deadline like every write to it.
async fn send(
    ws: &mut WebSocketStream<TcpStream>,
    msg: Ws,
    r: &mut Reading,
    stall: Duration,
) -> Result<(), End> {
    let start = Instant::now();
    if !matches!(msg, Ws::Ping(_)) {
        r.wrote(start);
    }
    let until = r.deadline(start, stall);
    ended(tokio::time::timeout_at(until, ws.send(msg)).await, stall)
}

/// The Ping due now (none in flight), bounded like any write.
async fn send_ping(
    ws: &mut WebSocketStream<TcpStream>,
    r: &mut Reading,
    stall: Duration,
) -> Result<(), End> {
    let ping = r.ping(Instant::now());
    send(ws, ping, r, stall).await
}

/// The end of a client that has not shown it read what it was sent
/// `stall` ago.
fn unread(stall: Duration) -> End {
    End::NotReading(format!(
        "not reading: what it was sent {stall:?} ago is unread (no answer to a ping sent after it)"
    ))
}

/// How a write bounded by the deadline ended the session, if it did.
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
        Err(_) => Err(unread(stall)),
    }
}

/// One client's session, from the handshake to its end.
async fn client(stream: TcpStream, addr: SocketAddr, hub: Arc<Hub>, limits: Limits, pass: Pass) {
    let _ = stream.set_nodelay(true);
    // Small, so that what a client has not read waits in its queue
    // (dropped and counted when it is full), not seconds of it in the
    // kernel (the `Reading` proof does not need it).
    let _ = socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER);
    let shaken = handshake(stream, limits.handshake).await;
    drop(pass); // the handshake is over: room for another
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
    let mut r = Reading::default();
    let end = session_loop(&mut ws, &mut rx, &hub, &c, &limits, &mut r).await;
    // What was written and not shown read: never read by a client cut for
    // not reading or gone silent; one that closed (or was closed) was
    // reading it. What waits in its queue is not shown.
    let unread = r.written - r.read;
    if matches!(end, End::NotReading(_) | End::Silent(_)) {
        c.dropped.fetch_add(unread, Relaxed);
    } else {
        c.sent.store(r.written, Relaxed);
    }
    rx.close();
    while rx.try_recv().is_ok() {
        c.dropped.fetch_add(1, Relaxed);
    }
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
/// place (or every place of its address) is taken (one line for the
/// operator saying who went and why); `None` (logged) when the newcomer
/// is turned away.
fn admit(
    hub: &Hub,
    addr: SocketAddr,
    tx: mpsc::Sender<Bytes>,
    limits: &Limits,
) -> Option<Arc<Client>> {
    let (max, per_addr) = (limits.max_clients, limits.max_clients_per_addr);
    let joined = match hub.join(addr, tx, max, per_addr, limits.idle_evict) {
        Ok(j) => j,
        Err(Refused::Closing) => {
            tracing::info!("foxglove: {addr} turned away: the daemon stops");
            return None;
        }
        Err(why) => {
            if let Some(k) = hub.conn_line() {
                let held = match why {
                    Refused::FromAddr => format!("{per_addr} clients from {} already", host(addr)),
                    _ => format!("{max} clients already"),
                };
                tracing::warn!(
                    refused = hub.refused.load(Relaxed),
                    since_last_line = k,
                    "foxglove: {addr} turned away: {held}, none of them \
                     subscribed to nothing for {:.0} s or more",
                    limits.idle_evict.as_secs_f64()
                );
            }
            return None;
        }
    };
    if let Some(gone) = joined.evicted {
        tracing::warn!(
            evicted = hub.evicted.load(Relaxed),
            "foxglove: {} disconnected to make room for {addr} ({max} clients already, \
             at most {per_addr} from one address): it held a place for {:.0} s without \
             subscribing to anything",
            gone.addr,
            gone.idle.as_secs_f64()
        );
    }
    Some(joined.client)
}

/// Greet, then serve requests, queued messages and pings until the client
/// or the hub ends; why it ended.
async fn session_loop(
    ws: &mut WebSocketStream<TcpStream>,
    rx: &mut mpsc::Receiver<Bytes>,
    hub: &Hub,
    c: &Client,
    limits: &Limits,
    r: &mut Reading,
) -> End {
    let stall = limits.stall;
    for text in greeting(&hub.session) {
        if let Err(e) = send(ws, Ws::text(text), r, stall).await {
            return e;
        }
    }
    // Pings that prove reading go at most ten per stall: a reading client
    // shows it long before the cut.
    let gap = stall / 10;
    let mut heard = Instant::now();
    let mut ticks = tokio::time::interval_at(heard + limits.ping, limits.ping);
    // After a long stall, one ping, not a burst of them.
    ticks.set_missed_tick_behavior(MissedTickBehavior::Delay);
    loop {
        let cut = r.oldest_unread().map(|t| t + stall);
        let due = r.ping_due(gap);
        let wake = cut.into_iter().chain(due).min();
        tokio::select! {
            msg = ws.next() => {
                if let Some(Ok(_)) = &msg {
                    heard = Instant::now(); // a pong or anything else
                }
                let reply = match msg {
                    Some(Ok(Ws::Text(t))) => request(hub, c, t.as_str()),
                    Some(Ok(Ws::Binary(b))) => Some(binary_warning(b.len())),
                    Some(Ok(Ws::Pong(p))) => {
                        if r.pong(&p) {
                            c.sent.store(r.read, Relaxed);
                        }
                        None
                    }
                    Some(Ok(Ws::Close(_))) | None => return "closed".to_string().into(),
                    Some(Ok(_)) => None, // pings are answered by tungstenite
                    Some(Err(e)) => return e.to_string().into(),
                };
                if let Some(reply) = reply {
                    if let Err(e) = send(ws, reply, r, stall).await {
                        return e;
                    }
                }
            }
            out = rx.recv() => match out {
                Some(first) => {
                    if let Err(e) = write_batch(ws, rx, c, r, first, stall).await {
                        return e;
                    }
                }
                None => return "the daemon stops".to_string().into(),
            },
            _ = ticks.tick() => {
                let quiet = heard.elapsed();
                if quiet >= limits.silence {
                    return End::Silent(quiet);
                }
                // A Ping in flight asks for an answer already.
                if r.ping.is_none() {
                    if let Err(e) = send_ping(ws, r, stall).await {
                        return e;
                    }
                }
            }
            _ = tokio::time::sleep_until(wake.unwrap_or_else(Instant::now)), if wake.is_some() => {
                if cut.is_some_and(|t| Instant::now() >= t) {
                    return unread(stall);
                }
                if let Err(e) = send_ping(ws, r, stall).await {
                    return e;
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
    use super::requests::{channel_index, clip};
    use super::*;
    use lightpose_logs::Channel;

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
            .join("127.0.0.1:2".parse().unwrap(), tx, 4, 4, IDLE_EVICT)
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

    /// What a status message quotes is cut at a character, saying how
    /// much went; a short text is kept as it is.
    #[test]
    fn clip_cuts_at_a_character_and_says_how_much() {
        assert_eq!(clip("short", 8), "short");
        let long = "é".repeat(100); // 200 bytes
        let c = clip(&long, 7);
        assert_eq!(c, format!("{}… (194 bytes more)", "é".repeat(3)));
    }

    /// A Pong proves only what was written before the Ping it answers:
    /// another Pong (a keepalive's, a forged one) proves nothing, and what
    /// was written after the Ping stays unread, from when it was written.
    #[test]
    fn a_pong_proves_what_was_written_before_its_ping() {
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        let gap = Duration::from_millis(100);
        let mut r = Reading::default();
        assert_eq!((r.oldest_unread(), r.ping_due(gap)), (None, None));
        r.wrote(t0);
        r.written = 3;
        assert_eq!(r.ping_due(gap), Some(t0 + gap), "a gap after the write");
        let Ws::Ping(p) = r.ping(t0) else {
            panic!("a ping")
        };
        assert_eq!(r.ping_due(gap), None, "one in flight at a time");
        r.wrote(t0 + s);
        r.written = 5;
        assert!(!r.pong(b""), "the keepalive's pong");
        assert!(!r.pong(&1u64.to_le_bytes()), "not the ping in flight");
        assert_eq!(r.deadline(t0 + 3 * s, s), t0 + s);
        assert!(r.pong(&p));
        assert_eq!((r.written, r.read), (5, 3));
        assert_eq!(r.oldest_unread(), Some(t0 + s), "written after the ping");
        assert_eq!(r.ping_due(gap), Some(t0 + s + gap), "a gap after the write");
        let Ws::Ping(p) = r.ping(t0 + s) else {
            panic!("a ping")
        };
        assert!(r.pong(&p));
        assert_eq!((r.read, r.oldest_unread()), (5, None));
        assert_eq!(r.deadline(t0 + 2 * s, s), t0 + 3 * s, "a bound from now");
    }
}
