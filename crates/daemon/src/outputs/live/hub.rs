//! The clients of the live view and what they subscribed to. The encoder
//! thread and the STATUS tick publish each message here; it goes, framed
//! as the protocol's binary `messageData`, into the bounded queue of every
//! client subscribed to its channel. A full queue (a slow or dead client)
//! drops the message for that client only, counted: nobody upstream ever
//! waits for a client.
//!
//! Framing does not allocate once warm: each client's copy of a message
//! (its subscription id differs) is a slice of a shared block
//! ([`Blocks`]), and a block is used again once every message in it was
//! written to its client.
//!
//! Each client also keeps since when it has subscribed to nothing (from
//! its join, or from the unsubscribe that left it nothing), so that a
//! newcomer finding every place taken can have the client idle the
//! longest make room ([`Hub::join`], docs/foxglove.md). One source address
//! holds at most `per_addr` of the places, so that one host (a script
//! connecting in a loop, four stuck tabs) cannot take them all.

use bytes::{BufMut, Bytes, BytesMut};
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_logs::foxglove::Stamp;
use lightpose_logs::{Channel, Message};
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::mpsc::error::TrySendError;
use tokio::sync::mpsc::Sender;
use tokio::sync::Notify;

/// Opcode of a binary `messageData` frame (server → client).
pub const MESSAGE_DATA: u8 = 0x01;

/// Bytes of a block of framed messages, and blocks kept for use again.
const BLOCK: usize = 64 << 10;
const SPARE: usize = 16;

/// The blocks that framed messages are cut from. The open block is split
/// at each message (the message a `Bytes` sharing it, no allocation); a
/// block whose messages are all written and dropped is taken back whole
/// (`try_reclaim`), so a new one is allocated only while more messages
/// wait in the clients' queues than the blocks kept hold.
struct Blocks {
    open: BytesMut,
    spare: VecDeque<BytesMut>,
}

impl Blocks {
    fn new() -> Blocks {
        Blocks {
            open: BytesMut::new(),
            spare: VecDeque::with_capacity(SPARE + 1),
        }
    }

    /// `m` framed for subscription `sub`.
    fn frame(&mut self, sub: u32, m: &Message) -> Bytes {
        self.room(13 + m.data.len());
        self.open.put_u8(MESSAGE_DATA);
        self.open.put_u32_le(sub);
        self.open.put_u64_le(m.log_time);
        self.open.extend_from_slice(m.data);
        self.open.split().freeze()
    }

    /// Room for `n` bytes in the open block: itself taken back, or a
    /// spare one, or a new one.
    fn room(&mut self, n: usize) {
        if self.open.try_reclaim(n) {
            return;
        }
        let reused = self.spare.iter_mut().position(|b| b.try_reclaim(n));
        let next = match reused.and_then(|i| self.spare.remove(i)) {
            Some(b) => b,
            None => BytesMut::with_capacity(BLOCK.max(n)),
        };
        let full = std::mem::replace(&mut self.open, next);
        if self.spare.len() >= SPARE {
            // Its memory goes with its last message.
            self.spare.pop_front();
        }
        self.spare.push_back(full);
    }
}

/// What a client subscribed to, under one lock so that a subscribe and
/// an eviction cannot cross.
struct Subs {
    /// Its subscription id for each channel (by [`Channel::index`]).
    by_channel: [Option<u32>; 7],
    /// Since when it has subscribed to nothing (its join, or the
    /// unsubscribe that left it nothing); `None` while it subscribes.
    idle_since: Option<Instant>,
    /// Out of the hub (evicted, or left): it subscribes to nothing more,
    /// so that the hub's count of subscriptions stays true.
    gone: bool,
}

impl Subs {
    fn count(&self) -> usize {
        self.by_channel.iter().filter(|x| x.is_some()).count()
    }
}

/// One connected client.
pub struct Client {
    pub id: u64,
    pub addr: SocketAddr,
    subs: Mutex<Subs>,
    tx: Sender<Bytes>,
    /// Told when the client is evicted: its task ends the session.
    evict: Notify,
    /// Messages the client has shown it read (it answered a ping written
    /// after them; `server`), not merely those the kernel took: a client
    /// that reads nothing has none, however much its socket buffers held.
    pub sent: AtomicU64,
    /// Messages it did not get: its queue full, or left unread at its end.
    pub dropped: AtomicU64,
}

impl Client {
    /// Subscribe `sub` to channel `index`; whether that channel exists.
    /// A client evicted a moment ago subscribes nothing (its task is
    /// ending), but is not told the channel does not exist.
    pub fn subscribe(&self, hub: &Hub, sub: u32, index: usize) -> bool {
        let Ok(mut s) = self.subs.lock() else {
            return false;
        };
        if index >= s.by_channel.len() {
            return false;
        }
        if s.gone {
            return true;
        }
        if s.by_channel[index].replace(sub).is_none() {
            hub.subscriptions.fetch_add(1, Relaxed);
        }
        s.idle_since = None;
        true
    }

    /// End subscription `sub`, wherever it is; the one that leaves the
    /// client nothing starts its idle time (an eviction counts from it).
    pub fn unsubscribe(&self, hub: &Hub, sub: u32) {
        let Ok(mut s) = self.subs.lock() else { return };
        for slot in s.by_channel.iter_mut().filter(|x| **x == Some(sub)) {
            *slot = None;
            hub.subscriptions.fetch_sub(1, Relaxed);
        }
        if s.idle_since.is_none() && s.count() == 0 {
            s.idle_since = Some(Instant::now());
        }
    }

    /// Resolves once the client was evicted to make room: its task waits
    /// on it beside its socket and queue.
    pub async fn evicted(&self) {
        self.evict.notified().await
    }

    fn subscription(&self, channel: Channel) -> Option<u32> {
        self.subs
            .lock()
            .ok()
            // Spec v3's channels (Channel::V3) are recorded, not served
            // live: beyond the seven, no client subscribes.
            .and_then(|s| s.by_channel.get(channel.index()).copied().flatten())
    }

    fn count_subscriptions(&self) -> usize {
        self.subs.lock().map_or(0, |s| s.count())
    }

    /// How long it has subscribed to nothing at `now`; `None` while it
    /// subscribes (or is gone): what STATUS shows and eviction ranks by.
    fn idle_for(&self, now: Instant) -> Option<Duration> {
        let s = self.subs.lock().ok()?;
        let since = s.idle_since.filter(|_| !s.gone)?;
        Some(now.saturating_duration_since(since))
    }

    /// Marks it gone if it is still idle for `min_idle` at `now` (checked
    /// under the lock a subscribe takes, so a client that subscribed since
    /// it was picked is spared); how long it was idle.
    fn take_if_idle(&self, now: Instant, min_idle: Duration) -> Option<Duration> {
        let mut s = self.subs.lock().ok()?;
        let idle = now.saturating_duration_since(s.idle_since.filter(|_| !s.gone)?);
        if idle < min_idle {
            return None;
        }
        s.gone = true;
        Some(idle)
    }
}

/// A client disconnected to make room for a newcomer.
#[derive(Debug, Clone, Copy)]
pub struct Evicted {
    pub addr: SocketAddr,
    /// How long it had subscribed to nothing.
    pub idle: Duration,
}

/// A newcomer admitted, and the client it replaced if every place was
/// taken.
pub struct Joined {
    pub client: Arc<Client>,
    pub evicted: Option<Evicted>,
}

/// Why a newcomer was turned away ([`Hub::join`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// The daemon stops.
    Closing,
    /// Every place is taken, none by a client idle long enough.
    Full,
    /// Its address holds `per_addr` places already, none of them idle
    /// long enough.
    FromAddr,
}

/// The address a client counts under: an IPv4 client of an IPv6 socket
/// (`::ffff:a.b.c.d`) is the IPv4 host it is.
pub fn host(addr: SocketAddr) -> IpAddr {
    addr.ip().to_canonical()
}

/// The live view's clients and counters, shared by the encoder thread, the
/// client tasks and STATUS.
pub struct Hub {
    pub listen: SocketAddr,
    /// Names this run of the daemon to clients (`serverInfo.sessionId`).
    pub session: String,
    clients: Mutex<Vec<Arc<Client>>>,
    next_id: AtomicU64,
    /// (client, channel) subscriptions: none, and frames are not encoded.
    subscriptions: AtomicUsize,
    /// Connections accepted, and turned away (too many clients).
    pub connections: AtomicU64,
    pub refused: AtomicU64,
    /// Connections closed at once: `server::HANDSHAKES` already in their
    /// handshake (a flood of half-open connections).
    pub handshakes_refused: AtomicU64,
    /// Clients ended because nothing came from them (no pong) for long.
    pub timed_out: AtomicU64,
    /// Clients disconnected to make room: subscribed to nothing for long.
    pub evicted: AtomicU64,
    /// Clients cut for not reading what they were sent (`server::End`).
    pub not_reading: AtomicU64,
    /// Set by `close`: the daemon stops.
    closing: std::sync::atomic::AtomicBool,
    /// Messages dropped for clients that went before, summed in.
    dropped_gone: AtomicU64,
    sent_gone: AtomicU64,
    /// Frames the encoder thread could not take (its queue full).
    pub handoff_dropped: AtomicU64,
    /// Frames and estimates without a log time (t < 0): no message.
    pub skipped: AtomicU64,
    /// t of the last frame (f64 bits): STATUS goes out at it.
    last_t: AtomicU64,
    status_seq: AtomicU32,
    blocks: Mutex<Blocks>,
    /// Per-connection lines (connected, gone, a handshake that failed,
    /// turned away), by core's rule for repeated lines: a client
    /// connecting in a loop wrote one or two lines per connection (an
    /// audit: 267 455 lines, 29 MB, in 20 s).
    conn_log: Mutex<RateLog>,
}

impl Hub {
    /// Whether a per-connection line is written now: `Some`, with the
    /// connection events since the last line (core's `RateLog::tick`).
    pub fn conn_line(&self) -> Option<u64> {
        self.conn_log.lock().ok()?.tick(Instant::now())
    }

    /// Connection events not told yet, for the closing line.
    pub fn conn_lines_pending(&self) -> bool {
        self.conn_log.lock().is_ok_and(|l| l.pending() > 0)
    }

    /// The closing line of the connection events `when`, if one is due:
    /// how many since the last line, and how long since the last event.
    pub fn close_conn_lines(&self, now: Instant, when: Close) -> Option<(u64, Duration)> {
        let mut log = self.conn_log.lock().ok()?;
        let k = log.close(now, when)?;
        Some((k, log.since_last(now)))
    }

    pub fn new(listen: SocketAddr) -> Hub {
        Hub {
            listen,
            session: format!("{:.0}", crate::outputs::recorder::unix_now() * 1e3),
            clients: Mutex::new(Vec::new()),
            next_id: AtomicU64::new(1),
            subscriptions: AtomicUsize::new(0),
            connections: AtomicU64::new(0),
            refused: AtomicU64::new(0),
            handshakes_refused: AtomicU64::new(0),
            timed_out: AtomicU64::new(0),
            evicted: AtomicU64::new(0),
            not_reading: AtomicU64::new(0),
            closing: std::sync::atomic::AtomicBool::new(false),
            dropped_gone: AtomicU64::new(0),
            sent_gone: AtomicU64::new(0),
            handoff_dropped: AtomicU64::new(0),
            skipped: AtomicU64::new(0),
            last_t: AtomicU64::new(0f64.to_bits()),
            status_seq: AtomicU32::new(0),
            blocks: Mutex::new(Blocks::new()),
            conn_log: Mutex::new(RateLog::new()),
        }
    }

    /// Whether any client subscribed to anything (else frames are not
    /// even handed to the encoder).
    pub fn wanted(&self) -> bool {
        self.subscriptions.load(Relaxed) > 0
    }

    pub fn client_count(&self) -> usize {
        self.clients.lock().map_or(0, |c| c.len())
    }

    /// A new client whose queue is `tx`. When `max` clients are already
    /// served, the one that has subscribed to nothing the longest, and for
    /// at least `min_idle`, is evicted to make room (an operator's
    /// Foxglove must not be refused for a forgotten tab); when `per_addr`
    /// of them come from the newcomer's address, the longest idle of
    /// those. Refused (counted `refused`) when none qualifies: a client
    /// that subscribes is never evicted.
    pub fn join(
        &self,
        addr: SocketAddr,
        tx: Sender<Bytes>,
        max: usize,
        per_addr: usize,
        min_idle: Duration,
    ) -> Result<Joined, Refused> {
        let mut clients = self.clients.lock().map_err(|_| Refused::Closing)?;
        // After `close` (set under this lock), a handshake that finishes
        // joins nothing: its task would wait on a queue nobody writes.
        if self.closing() {
            return Err(Refused::Closing);
        }
        let ip = host(addr);
        let mine = clients.iter().filter(|c| host(c.addr) == ip).count();
        let mut evicted = None;
        // One of its own makes room first: that frees a place of the
        // total as well.
        let full = if mine >= per_addr {
            Some((Some(ip), Refused::FromAddr))
        } else if clients.len() >= max {
            Some((None, Refused::Full))
        } else {
            None
        };
        if let Some((among, why)) = full {
            evicted = self.evict_idlest(&mut clients, min_idle, among);
            if evicted.is_none() || clients.len() >= max {
                self.refused.fetch_add(1, Relaxed);
                return Err(why);
            }
        }
        let c = Arc::new(Client {
            id: self.next_id.fetch_add(1, Relaxed),
            addr,
            subs: Mutex::new(Subs {
                by_channel: [None; 7],
                idle_since: Some(Instant::now()),
                gone: false,
            }),
            tx,
            evict: Notify::new(),
            sent: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
        });
        clients.push(c.clone());
        self.connections.fetch_add(1, Relaxed);
        Ok(Joined { client: c, evicted })
    }

    /// Out of `clients` (those from `among` if given), the one idle
    /// (subscribed to nothing) the longest, if for `min_idle` at least:
    /// retired, counted, its task told to end. Picked, then taken under its
    /// own lock, again if it subscribed in between (bounded: each retry
    /// means one client fewer qualifies).
    fn evict_idlest(
        &self,
        clients: &mut Vec<Arc<Client>>,
        min_idle: Duration,
        among: Option<IpAddr>,
    ) -> Option<Evicted> {
        let now = Instant::now();
        for _ in 0..clients.len() {
            let (i, _) = clients
                .iter()
                .enumerate()
                .filter(|(_, c)| among.is_none_or(|ip| host(c.addr) == ip))
                .filter_map(|(i, c)| Some((i, c.idle_for(now)?)))
                .filter(|&(_, idle)| idle >= min_idle)
                .max_by_key(|&(_, idle)| idle)?;
            let Some(idle) = clients[i].take_if_idle(now, min_idle) else {
                continue;
            };
            let c = clients.swap_remove(i);
            self.retire(&c);
            self.evicted.fetch_add(1, Relaxed);
            c.evict.notify_one();
            return Some(Evicted { addr: c.addr, idle });
        }
        None
    }

    /// A client went: its subscriptions end, its counts join the totals.
    pub fn leave(&self, id: u64) {
        let Ok(mut clients) = self.clients.lock() else {
            return;
        };
        if let Some(i) = clients.iter().position(|c| c.id == id) {
            let c = clients.swap_remove(i);
            self.retire(&c);
        }
    }

    /// The accounts of a client just taken out of the list: its
    /// subscriptions end (and no more may start), its counts join the
    /// totals.
    fn retire(&self, c: &Client) {
        let n = c.subs.lock().map_or(0, |mut s| {
            s.gone = true;
            let n = s.count();
            s.by_channel = [None; 7];
            n
        });
        self.subscriptions.fetch_sub(n, Relaxed);
        self.dropped_gone
            .fetch_add(c.dropped.load(Relaxed), Relaxed);
        self.sent_gone.fetch_add(c.sent.load(Relaxed), Relaxed);
    }

    /// Every client goes (the daemon stops): each is taken out and its
    /// task told, as an eviction tells it, so that it says goodbye and
    /// ends. (Taking them out alone did not end them: a client's queue
    /// sender lives in the `Client` its own task holds, so the queue never
    /// closed and the tasks lived until the runtime was dropped.)
    pub fn close(&self) {
        let gone: Vec<Arc<Client>> = self.clients.lock().map_or_else(
            |_| Vec::new(),
            |mut c| {
                self.closing.store(true, Relaxed);
                c.drain(..).collect()
            },
        );
        for c in gone {
            self.retire(&c);
            c.evict.notify_one();
        }
    }

    /// Whether the daemon is stopping (`close`): a told client's session
    /// ends for that, not for a newcomer.
    pub fn closing(&self) -> bool {
        self.closing.load(Relaxed)
    }

    pub fn note_frame_t(&self, t: f64) {
        self.last_t.store(t.to_bits(), Relaxed);
    }

    /// `m` to every client subscribed to its channel.
    pub fn publish(&self, m: &Message) {
        let Ok(clients) = self.clients.lock() else {
            return;
        };
        let Ok(mut blocks) = self.blocks.lock() else {
            return;
        };
        for c in clients.iter() {
            let Some(sub) = c.subscription(m.channel) else {
                continue;
            };
            match c.tx.try_send(blocks.frame(sub, m)) {
                Ok(()) => {}
                // Its task is ending (it leaves in a moment): not shown
                // either.
                Err(TrySendError::Full(_) | TrySendError::Closed(_)) => {
                    c.dropped.fetch_add(1, Relaxed);
                }
            }
        }
    }

    /// STATUS, as the recording has it: at the last frame's t.
    pub fn publish_status(&self, json: &[u8]) {
        let t = f64::from_bits(self.last_t.load(Relaxed));
        let Some(stamp) = Stamp::of(t) else { return };
        let m = Message {
            channel: Channel::Status,
            sequence: self.status_seq.fetch_add(1, Relaxed),
            log_time: stamp.nanos(),
            data: json,
        };
        self.publish(&m);
    }

    /// The live view in STATUS.
    pub fn report(&self) -> Value {
        let clients = self
            .clients
            .lock()
            .map_or_else(|_| Vec::new(), |c| c.clone());
        let now = Instant::now();
        let (mut sent, mut dropped) = (
            self.sent_gone.load(Relaxed),
            self.dropped_gone.load(Relaxed),
        );
        let list: Vec<Value> = clients
            .iter()
            .map(|c| {
                let (s, d) = (c.sent.load(Relaxed), c.dropped.load(Relaxed));
                sent += s;
                dropped += d;
                json!({
                    "addr": c.addr.to_string(),
                    "subscriptions": c.count_subscriptions(),
                    "idle_s": c.idle_for(now).map(|d| (d.as_secs_f64() * 10.0).round() / 10.0),
                    "sent": s,
                    "dropped": d,
                })
            })
            .collect();
        json!({
            "enabled": true,
            "listen": self.listen.to_string(),
            "clients": list.len(),
            "connections": self.connections.load(Relaxed),
            "refused": self.refused.load(Relaxed),
            "handshakes_refused": self.handshakes_refused.load(Relaxed),
            "timed_out": self.timed_out.load(Relaxed),
            "evicted": self.evicted.load(Relaxed),
            "not_reading": self.not_reading.load(Relaxed),
            "sent": sent,
            "dropped": dropped,
            "handoff_dropped": self.handoff_dropped.load(Relaxed),
            "skipped": self.skipped.load(Relaxed),
            "client_list": list,
        })
    }
}

impl crate::outputs::StatusTap for Arc<Hub> {
    fn status(&self, json: &[u8]) {
        self.publish_status(json);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(channel: Channel, data: &[u8]) -> Message<'_> {
        Message {
            channel,
            sequence: 3,
            log_time: 0x0102_0304_0506_0708,
            data,
        }
    }

    #[test]
    fn framing_subscriptions_and_drops() {
        let hub = Hub::new("127.0.0.1:1".parse().unwrap());
        let (tx, mut rx) = tokio::sync::mpsc::channel(2);
        let never = Duration::from_secs(3600);
        let c = hub
            .join("127.0.0.1:2".parse().unwrap(), tx, 1, 1, never)
            .unwrap()
            .client;
        let (tx2, _rx2) = tokio::sync::mpsc::channel(2);
        assert_eq!(
            hub.join("127.0.0.2:3".parse().unwrap(), tx2, 1, 1, never)
                .err(),
            Some(Refused::Full)
        );
        assert_eq!(hub.refused.load(Relaxed), 1);
        assert!(!hub.wanted());
        hub.publish(&msg(Channel::Frame, b"{}"));
        assert!(
            rx.try_recv().is_err(),
            "nothing for a channel not subscribed"
        );
        assert!(c.subscribe(&hub, 0xAABB_CCDD, Channel::Frame.index()));
        assert!(!c.subscribe(&hub, 9, 7), "no eighth channel");
        assert!(hub.wanted());
        hub.publish(&msg(Channel::Frame, b"{}"));
        let got = rx.try_recv().unwrap();
        let mut want = vec![MESSAGE_DATA, 0xDD, 0xCC, 0xBB, 0xAA];
        want.extend_from_slice(&[8, 7, 6, 5, 4, 3, 2, 1]);
        want.extend_from_slice(b"{}");
        assert_eq!(got, want);
        // A client that does not take its messages: the third is dropped.
        for _ in 0..3 {
            hub.publish(&msg(Channel::Frame, b"{}"));
        }
        assert_eq!(c.dropped.load(Relaxed), 1);
        c.unsubscribe(&hub, 0xAABB_CCDD);
        assert!(!hub.wanted());
        c.sent.store(5, Relaxed);
        hub.leave(c.id);
        let r = hub.report();
        assert_eq!(
            (r["clients"].as_u64(), r["connections"].as_u64()),
            (Some(0), Some(1))
        );
        assert_eq!(
            (r["sent"].as_u64(), r["dropped"].as_u64()),
            (Some(5), Some(1))
        );
    }

    /// A client joined with a throwaway queue.
    fn join(hub: &Hub, port: u16, max: usize, min_idle: Duration) -> Option<Joined> {
        let (tx, _rx) = tokio::sync::mpsc::channel(2);
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        hub.join(addr, tx, max, max, min_idle).ok()
    }

    /// A client from `ip` joined with a throwaway queue, at most `per_addr`
    /// from one address among 4.
    fn join_from(
        hub: &Hub,
        ip: [u8; 4],
        per_addr: usize,
        min_idle: Duration,
    ) -> Result<Joined, Refused> {
        let (tx, _rx) = tokio::sync::mpsc::channel(2);
        hub.join(SocketAddr::from((ip, 40000)), tx, 4, per_addr, min_idle)
    }

    /// One address holds at most `per_addr` places (loopback like any
    /// other): its next client is refused while other hosts still get in,
    /// or has the longest idle of its own address's clients make room, not
    /// another host's; an IPv4 client on an IPv6 socket counts as its IPv4
    /// host.
    #[test]
    fn one_address_takes_at_most_its_share_of_the_places() {
        let hub = Hub::new("127.0.0.1:1".parse().unwrap());
        let never = Duration::from_secs(3600);
        // b, idle the longest of all.
        let b = join_from(&hub, [127, 0, 0, 1], 2, never).unwrap().client;
        let a1 = join_from(&hub, [127, 0, 0, 2], 2, never).unwrap().client;
        let a2 = join_from(&hub, [127, 0, 0, 2], 2, never).unwrap().client;
        assert_eq!(
            join_from(&hub, [127, 0, 0, 2], 2, never).err(),
            Some(Refused::FromAddr)
        );
        let (tx, _rx) = tokio::sync::mpsc::channel(2);
        let mapped: SocketAddr = "[::ffff:127.0.0.2]:40001".parse().unwrap();
        assert_eq!(
            hub.join(mapped, tx, 4, 2, never).err(),
            Some(Refused::FromAddr),
            "::ffff:127.0.0.2 is 127.0.0.2"
        );
        assert!(join_from(&hub, [127, 0, 0, 3], 2, never).is_ok());
        assert_eq!(hub.refused.load(Relaxed), 2);
        // Idle long enough: the longest idle of 127.0.0.2 makes room for
        // its newcomer; b, idle longer, from another host, is not touched.
        assert!(a2.subscribe(&hub, 1, 0));
        let j = join_from(&hub, [127, 0, 0, 2], 2, Duration::ZERO).unwrap();
        assert_eq!(j.evicted.map(|e| e.addr), Some(a1.addr));
        assert!(hub.clients.lock().unwrap().iter().any(|c| c.id == b.id));
        assert_eq!(hub.client_count(), 4);
    }

    /// Every place taken: the client idle the longest goes for a newcomer,
    /// idle counting from its last unsubscribe; a subscribed one never
    /// goes, and one evicted a moment ago subscribes nothing (the hub's
    /// count of subscriptions stays true).
    #[test]
    fn the_longest_idle_client_makes_room_and_a_subscribed_one_never() {
        let hub = Hub::new("127.0.0.1:1".parse().unwrap());
        let zero = Duration::ZERO;
        let a = join(&hub, 2, 2, zero).unwrap().client;
        let b = join(&hub, 3, 2, zero).unwrap().client;
        // a subscribes, then unsubscribes everything: idle from then,
        // after b.
        assert!(a.subscribe(&hub, 1, 0));
        assert!(a.idle_for(Instant::now()).is_none());
        a.unsubscribe(&hub, 1);
        assert!(!hub.wanted());
        let joined = join(&hub, 4, 2, zero).expect("room made");
        let gone = joined.evicted.expect("one evicted");
        assert_eq!(gone.addr, b.addr, "b, idle since its join, before a");
        assert_eq!(hub.evicted.load(Relaxed), 1);
        assert!(b.subscribe(&hub, 9, 0), "not told the channel is missing");
        assert!(!hub.wanted(), "an evicted client subscribed");
        // Both left subscribe: a newcomer is refused, whatever the minimum.
        let c = joined.client;
        assert!(a.subscribe(&hub, 1, 0) && c.subscribe(&hub, 1, 6));
        assert!(join(&hub, 5, 2, zero).is_none());
        // Idle, but not yet for the minimum: refused too.
        a.unsubscribe(&hub, 1);
        assert!(join(&hub, 6, 2, Duration::from_secs(3600)).is_none());
        assert_eq!(
            (hub.refused.load(Relaxed), hub.evicted.load(Relaxed)),
            (2, 1)
        );
        let r = hub.report();
        assert_eq!(
            (r["clients"].as_u64(), r["evicted"].as_u64()),
            (Some(2), Some(1))
        );
        let idle: Vec<bool> = r["client_list"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["idle_s"].is_f64())
            .collect();
        assert_eq!(idle.iter().filter(|&&x| x).count(), 1, "{r}");
    }
}
