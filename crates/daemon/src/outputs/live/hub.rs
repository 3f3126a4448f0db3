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

use bytes::{BufMut, Bytes, BytesMut};
use lightpose_logs::foxglove::Stamp;
use lightpose_logs::{Channel, Message};
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use tokio::sync::mpsc::error::TrySendError;
use tokio::sync::mpsc::Sender;

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

/// One connected client.
pub struct Client {
    pub id: u64,
    pub addr: SocketAddr,
    /// Its subscription id for each channel (by [`Channel::index`]).
    subs: Mutex<[Option<u32>; 7]>,
    tx: Sender<Bytes>,
    pub sent: AtomicU64,
    pub dropped: AtomicU64,
}

impl Client {
    /// Subscribe `sub` to channel `index`; whether that channel exists.
    pub fn subscribe(&self, hub: &Hub, sub: u32, index: usize) -> bool {
        let Ok(mut s) = self.subs.lock() else {
            return false;
        };
        let Some(slot) = s.get_mut(index) else {
            return false;
        };
        if slot.replace(sub).is_none() {
            hub.subscriptions.fetch_add(1, Relaxed);
        }
        true
    }

    /// End subscription `sub`, wherever it is.
    pub fn unsubscribe(&self, hub: &Hub, sub: u32) {
        if let Ok(mut s) = self.subs.lock() {
            for slot in s.iter_mut().filter(|x| **x == Some(sub)) {
                *slot = None;
                hub.subscriptions.fetch_sub(1, Relaxed);
            }
        }
    }

    fn subscription(&self, channel: Channel) -> Option<u32> {
        self.subs.lock().ok().and_then(|s| s[channel.index()])
    }

    fn count_subscriptions(&self) -> usize {
        self.subs
            .lock()
            .map_or(0, |s| s.iter().filter(|x| x.is_some()).count())
    }
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
}

impl Hub {
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
            dropped_gone: AtomicU64::new(0),
            sent_gone: AtomicU64::new(0),
            handoff_dropped: AtomicU64::new(0),
            skipped: AtomicU64::new(0),
            last_t: AtomicU64::new(0f64.to_bits()),
            status_seq: AtomicU32::new(0),
            blocks: Mutex::new(Blocks::new()),
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

    /// A new client with a queue of `queue` messages; `None` when
    /// `max` clients are already served.
    pub fn join(&self, addr: SocketAddr, tx: Sender<Bytes>, max: usize) -> Option<Arc<Client>> {
        let mut clients = self.clients.lock().ok()?;
        if clients.len() >= max {
            self.refused.fetch_add(1, Relaxed);
            return None;
        }
        let c = Arc::new(Client {
            id: self.next_id.fetch_add(1, Relaxed),
            addr,
            subs: Mutex::new([None; 7]),
            tx,
            sent: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
        });
        clients.push(c.clone());
        self.connections.fetch_add(1, Relaxed);
        Some(c)
    }

    /// A client went: its subscriptions end, its counts join the totals.
    pub fn leave(&self, id: u64) {
        let Ok(mut clients) = self.clients.lock() else {
            return;
        };
        if let Some(i) = clients.iter().position(|c| c.id == id) {
            let c = clients.swap_remove(i);
            let n = c.count_subscriptions();
            self.subscriptions.fetch_sub(n, Relaxed);
            self.dropped_gone
                .fetch_add(c.dropped.load(Relaxed), Relaxed);
            self.sent_gone.fetch_add(c.sent.load(Relaxed), Relaxed);
        }
    }

    /// Every client goes (the daemon stops): their queues close, so their
    /// tasks say goodbye and end.
    pub fn close(&self) {
        let ids: Vec<u64> = self
            .clients
            .lock()
            .map_or_else(|_| Vec::new(), |c| c.iter().map(|c| c.id).collect());
        for id in ids {
            self.leave(id);
        }
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
                Err(TrySendError::Full(_)) => {
                    c.dropped.fetch_add(1, Relaxed);
                }
                // Its task is ending; it leaves in a moment.
                Err(TrySendError::Closed(_)) => {}
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
        let c = hub.join("127.0.0.1:2".parse().unwrap(), tx, 1).unwrap();
        let (tx2, _rx2) = tokio::sync::mpsc::channel(2);
        assert!(hub.join("127.0.0.1:3".parse().unwrap(), tx2, 1).is_none());
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
}
