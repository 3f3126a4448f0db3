//! UDP publishing: one datagram per message to every unicast destination and
//! to the multicast group. Sockets are non-blocking std sockets, shared by
//! the acquisition thread (POSE, through [`PoseDatagrams`]) and the async
//! side (STATUS, VERSION), so a datagram leaves in one `send` with no
//! hand-off between threads. A destination that fails is counted and logged
//! on its own; the others go on.
//!
//! Each unicast destination has a socket of its own, connected to it: on
//! Linux an unconnected UDP socket never hears of the ICMP "port
//! unreachable" that a host answers when nobody listens, while a connected
//! one reports it as ECONNREFUSED on its next send. So `errors` counts
//! every send the kernel refused — no route, a full buffer, a port where
//! nobody listens (about every other datagram is refused while nobody
//! does) — but not a datagram lost silently on the way (a host that does
//! not answer at all): UDP has no acknowledgement. A destination that
//! cannot be connected yet (no route at boot) is counted and connected
//! again on each send until it can; so is one whose source address has
//! gone (`lightpose_core::udp`: the vehicle renumbered).

use super::Output;
use crate::config::Outputs;
use crate::engine::Acquired;
use crate::stats::DestStats;
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::PoseEstimate;
use socket2::SockRef;
use std::io;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error("outputs: cannot open a UDP socket for {addr}")]
    Socket {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("outputs.multicast: cannot set {what}")]
    Multicast {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
}

pub struct Destination {
    pub addr: SocketAddr,
    pub multicast: bool,
    pub stats: DestStats,
    sock: UdpSocket,
    /// A unicast socket connected to `addr` (see the module).
    connected: AtomicBool,
    /// The failures' memory, under the one lock the error path already
    /// took (a send that succeeds takes none).
    failing: Mutex<Failing>,
}

#[derive(Default)]
struct Failing {
    /// The cause of `stats.last_error`: a refusal like the last one (every
    /// other datagram while nobody listens) is not formatted again.
    cause: Option<Cause>,
    /// Core's rule: the first error at once, then less and less often
    /// while they go on (a destination down for a week was a line every
    /// 1000 errors: every 40 s at 50 Hz, every 2 s at 1 kHz).
    log: RateLog,
}

/// What tells two send errors apart without formatting them.
type Cause = (io::ErrorKind, Option<i32>);

impl Destination {
    fn open(addr: SocketAddr, multicast: bool) -> Result<Destination, PublishError> {
        let unspec = if addr.is_ipv4() {
            SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0))
        } else {
            SocketAddr::from((Ipv6Addr::UNSPECIFIED, 0))
        };
        let fail = |source| PublishError::Socket { addr, source };
        let sock = UdpSocket::bind(unspec).map_err(fail)?;
        // Never block the frame path on a full socket buffer: such a
        // send is counted as an error of that destination instead.
        sock.set_nonblocking(true).map_err(fail)?;
        // Not yet reachable (no route at boot) is not fatal: counted at
        // each send, which connects again.
        let connected = !multicast && sock.connect(addr).is_ok();
        Ok(Destination {
            addr,
            multicast,
            stats: DestStats::default(),
            sock,
            connected: AtomicBool::new(connected),
            failing: Mutex::default(),
        })
    }

    /// Count the failed send `e`, log it if due (with the errors since
    /// the last line: the growth of STATUS `errors` between the lines),
    /// and keep it as the last error, formatted only when its cause changed.
    fn note_error(&self, e: &io::Error) {
        // Counted under the lock: the POSE (frame thread) and STATUS
        // (async side) sends of one destination tell one tally.
        let mut f = self.failing.lock().unwrap_or_else(|p| p.into_inner());
        let n = self.stats.errors.fetch_add(1, Relaxed) + 1;
        if let Some(k) = f.log.tick(Instant::now()) {
            tracing::warn!(
                destination = %self.addr,
                errors = n,
                since_last_line = k,
                "send failed: {e}"
            );
        }
        let cause = Some((e.kind(), e.raw_os_error()));
        if f.cause == cause {
            return;
        }
        f.cause = cause;
        if let Ok(mut g) = self.stats.last_error.lock() {
            *g = Some(e.to_string());
        }
    }

    /// The closing line of this destination's errors `when` (core's
    /// `RateLog::settle` once they stopped, `RateLog::flush` at stop): the
    /// errors since the last line.
    fn close(&self, now: Instant, when: Close) {
        let mut f = self.failing.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(k) = f.log.close(now, when) {
            tracing::warn!(
                destination = %self.addr,
                errors = self.stats.errors.load(Relaxed),
                since_last_line = k,
                "send failures: {when}: {k} more since the last line, the last {:.1} s ago",
                f.log.since_last(now).as_secs_f64()
            );
        }
    }

    fn send(&self, msg: &[u8]) -> std::io::Result<usize> {
        if self.multicast {
            return self.sock.send_to(msg, self.addr);
        }
        if !self.connected.load(Relaxed) {
            self.sock.connect(self.addr)?;
            self.connected.store(true, Relaxed);
        }
        let sent = self.sock.send(msg);
        if let Err(e) = &sent {
            if lightpose_core::udp::source_gone(e) {
                // The vehicle's own address changed under the socket: the
                // next send connects from the new one.
                if lightpose_core::udp::disconnect(&self.sock).is_ok() {
                    self.connected.store(false, Relaxed);
                }
            }
        }
        sent
    }
}

pub struct Publisher {
    dests: Vec<Destination>,
}

impl Publisher {
    /// Open a socket for each configured destination.
    pub fn open(cfg: &Outputs) -> Result<Publisher, PublishError> {
        let mut dests = cfg
            .destinations
            .iter()
            .map(|&addr| Destination::open(addr, false))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(m) = &cfg.multicast {
            let d = Destination::open(m.group, true)?;
            let s = &d.sock;
            let mc = |what, r: std::io::Result<()>| {
                r.map_err(|source| PublishError::Multicast { what, source })
            };
            if m.group.is_ipv4() {
                mc("ttl", s.set_multicast_ttl_v4(m.ttl))?;
                mc("loopback", s.set_multicast_loop_v4(m.loopback))?;
                if !m.interface.is_unspecified() {
                    mc(
                        "interface",
                        SockRef::from(s).set_multicast_if_v4(&m.interface),
                    )?;
                }
            } else {
                mc("ttl", SockRef::from(s).set_multicast_hops_v6(m.ttl))?;
                mc("loopback", s.set_multicast_loop_v6(m.loopback))?;
            }
            dests.push(d);
        }
        Ok(Publisher { dests })
    }

    pub fn destinations(&self) -> &[Destination] {
        &self.dests
    }

    /// Send one datagram to every destination; returns how many took it.
    /// Never allocates unless a destination fails with another error than
    /// its last one (the error text) or a line about its errors is due
    /// (core's `RateLog`: at once, then after 1 s, 10 s, 1 min, then every
    /// 10 min while they go on).
    pub fn send(&self, msg: &[u8]) -> usize {
        let mut ok = 0;
        for d in &self.dests {
            match d.send(msg) {
                Ok(_) => {
                    d.stats.sent.fetch_add(1, Relaxed);
                    ok += 1;
                }
                Err(e) => d.note_error(&e),
            }
        }
        ok
    }
}

impl Publisher {
    /// Each destination's closing line, when its errors stopped with some
    /// not told yet (see [`Destination`]'s log). Called by the supervisor
    /// with each STATUS (once a second whatever happens), not per send:
    /// a send that succeeds takes no lock.
    pub fn settle(&self, now: Instant) {
        for d in &self.dests {
            d.close(now, Close::Over);
        }
    }

    /// At stop (after the last STATUS): each destination's errors not
    /// told yet, whatever the step (core's `RateLog::flush`).
    pub fn flush(&self, now: Instant) {
        for d in &self.dests {
            d.close(now, Close::AtStop);
        }
    }
}

/// The POSE of every frame, one datagram to every destination.
pub struct PoseDatagrams {
    publisher: Arc<Publisher>,
    /// The POSE text, one buffer reused for every frame.
    buf: Vec<u8>,
}

impl PoseDatagrams {
    pub fn new(publisher: Arc<Publisher>) -> Self {
        PoseDatagrams {
            publisher,
            buf: Vec::with_capacity(1024),
        }
    }
}

impl Output for PoseDatagrams {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        est.write_json(Some(frame.wall_unix), &mut self.buf);
        self.publisher.send(&self.buf);
    }
}

/// The first log line's hint: a one-line way to watch the stream.
pub fn listen_hint(cfg: &Outputs) -> String {
    let Some(first) = cfg
        .destinations
        .first()
        .copied()
        .or(cfg.multicast.as_ref().map(|m| m.group))
    else {
        return "no destinations configured: nothing is published".into();
    };
    let port = first.port();
    match &cfg.multicast {
        Some(m) if cfg.destinations.is_empty() => format!(
            "listen with: python3 -c \"import socket,struct;s=socket.socket(2,2);s.setsockopt(1,2,1);s.bind(('',{port}));s.setsockopt(0,35,struct.pack('4s4s',socket.inet_aton('{}'),socket.inet_aton('0.0.0.0')));[print(s.recv(65536).decode()) for _ in iter(int,1)]\"",
            m.group.ip()
        ),
        _ => format!(
            "listen with: socat -u UDP-RECV:{port} STDOUT   or   python3 -c \"import socket;s=socket.socket(2,2);s.bind(('{}',{port}));[print(s.recv(65536).decode()) for _ in iter(int,1)]\"",
            first.ip()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Outputs;
    use std::time::Duration;

    #[test]
    fn one_dead_destination_does_not_stop_the_others() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let good = rx.local_addr().unwrap();
        // Broadcast without SO_BROADCAST: the kernel refuses every send
        // (EACCES) at once.
        let bad: SocketAddr = "255.255.255.255:9".parse().unwrap();
        let p = Publisher::open(&Outputs {
            destinations: vec![bad, good],
            multicast: None,
            status_interval: Duration::from_secs(1),
        })
        .unwrap();
        for _ in 0..3 {
            assert_eq!(p.send(b"{\"class\":\"X\"}"), 1);
        }
        let mut buf = [0u8; 64];
        let n = rx.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"{\"class\":\"X\"}");
        let d = p.destinations();
        assert_eq!(d[0].stats.errors.load(Relaxed), 3);
        assert_eq!(d[0].stats.sent.load(Relaxed), 0);
        assert!(d[0].stats.last_error.lock().unwrap().is_some());
        assert_eq!(d[1].stats.sent.load(Relaxed), 3);
    }

    /// Soak audit: a destination that keeps failing was logged at every
    /// 1000th error for as long as it failed. Now core's rule: the first
    /// error at once, the next line no sooner than 1 s later, whatever the
    /// number of errors in between (5000 here, all counted).
    #[test]
    fn a_failing_destination_is_not_logged_every_thousand_errors() {
        let bad: SocketAddr = "255.255.255.255:9".parse().unwrap();
        let p = Publisher::open(&Outputs {
            destinations: vec![bad],
            multicast: None,
            status_interval: Duration::from_secs(1),
        })
        .unwrap();
        let t0 = std::time::Instant::now();
        let log = lightpose_testkit::logs::logged(|| {
            for _ in 0..5000 {
                p.send(b"{}");
            }
        });
        let lines: Vec<&str> = log.lines().filter(|l| l.contains("send failed")).collect();
        assert_eq!(p.destinations()[0].stats.errors.load(Relaxed), 5000);
        assert!(lines[0].contains("errors=1 since_last_line=1"), "{log}");
        // One more line per second the sends took on a loaded host.
        let most = 1 + t0.elapsed().as_secs() as usize;
        assert!((1..=most).contains(&lines.len()), "{log}");
    }

    /// A publisher whose one destination every send fails to (the
    /// broadcast address, which an unprivileged socket may not send to).
    fn failing_publisher() -> Publisher {
        let bad: SocketAddr = "255.255.255.255:9".parse().unwrap();
        Publisher::open(&Outputs {
            destinations: vec![bad],
            multicast: None,
            status_interval: Duration::from_secs(1),
        })
        .unwrap()
    }

    /// Errors that stop are told to the end: the first at once, the 4
    /// after it by the closing line once none came for the step in force
    /// (1 s), which the STATUS tick asks for; once.
    #[test]
    fn the_end_of_a_destination_s_errors_is_told() {
        let p = failing_publisher();
        let log = lightpose_testkit::logs::logged(|| {
            for _ in 0..5 {
                p.send(b"{}");
            }
            let now = Instant::now();
            p.settle(now);
            p.settle(now + Duration::from_secs(2));
            p.settle(now + Duration::from_secs(3));
        });
        let lines: Vec<&str> = log.lines().collect();
        assert_eq!(lines.len(), 2, "{log}");
        assert!(lines[0].contains("send failed"), "{log}");
        assert!(
            lines[1].contains("WARN")
                && lines[1].contains("errors=5 since_last_line=4")
                && lines[1]
                    .contains("send failures: the condition is over: 4 more since the last line"),
            "{log}"
        );
    }

    /// Errors whose end the stop cuts (none for the step yet): told by
    /// the line at stop, after the last STATUS; once.
    #[test]
    fn errors_not_told_yet_are_told_at_stop() {
        let p = failing_publisher();
        let log = lightpose_testkit::logs::logged(|| {
            for _ in 0..5 {
                p.send(b"{}");
            }
            let now = Instant::now();
            p.settle(now);
            p.flush(now);
            p.flush(now + Duration::from_secs(1));
        });
        let lines: Vec<&str> = log.lines().collect();
        assert_eq!(lines.len(), 2, "{log}");
        assert!(
            lines[1].contains("WARN")
                && lines[1].contains("errors=5 since_last_line=4")
                && lines[1].contains("send failures: at stop: 4 more since the last line"),
            "{log}"
        );
    }

    /// Issue 16: a unicast destination where nobody listens is counted as
    /// failing: the kernel's ICMP "port unreachable" is reported on the
    /// next send of a connected socket.
    #[test]
    fn a_destination_where_nobody_listens_is_counted() {
        let closed = {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            s.local_addr().unwrap()
        }; // dropped: nobody listens there now
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let p = Publisher::open(&Outputs {
            destinations: vec![closed, rx.local_addr().unwrap()],
            multicast: None,
            status_interval: Duration::from_secs(1),
        })
        .unwrap();
        for _ in 0..20 {
            p.send(b"{\"class\":\"X\"}");
            std::thread::sleep(Duration::from_millis(2));
        }
        let d = p.destinations();
        let errors = d[0].stats.errors.load(Relaxed);
        assert!(errors >= 5, "{errors} errors of 20 sends");
        let last = d[0]
            .stats
            .last_error
            .lock()
            .unwrap()
            .clone()
            .unwrap_or_default();
        assert!(last.contains("refused"), "{last}");
        assert_eq!(d[1].stats.sent.load(Relaxed), 20);
        assert_eq!(d[1].stats.errors.load(Relaxed), 0);
    }
}
