//! UDP publishing: one datagram per message to every unicast destination and
//! to the multicast group. Sockets are non-blocking std sockets, shared by
//! the acquisition thread (POSE, through [`PoseDatagrams`]) and the async
//! side (STATUS, VERSION), so a datagram leaves in one `sendto` with no
//! hand-off between threads. A destination that fails is counted and logged
//! on its own; the others go on.

use super::Output;
use crate::config::Outputs;
use crate::engine::Acquired;
use crate::stats::DestStats;
use lightpose_core::PoseEstimate;
use socket2::SockRef;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error("outputs: cannot open a UDP socket for {family}")]
    Socket {
        family: &'static str,
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
}

pub struct Publisher {
    v4: Option<UdpSocket>,
    v6: Option<UdpSocket>,
    dests: Vec<Destination>,
}

impl Publisher {
    /// Open the sockets the configured destinations need.
    pub fn open(cfg: &Outputs) -> Result<Publisher, PublishError> {
        let mut dests: Vec<Destination> = cfg
            .destinations
            .iter()
            .map(|&addr| Destination {
                addr,
                multicast: false,
                stats: DestStats::default(),
            })
            .collect();
        if let Some(m) = &cfg.multicast {
            dests.push(Destination {
                addr: m.group,
                multicast: true,
                stats: DestStats::default(),
            });
        }
        let need_v4 = dests.iter().any(|d| d.addr.is_ipv4());
        let need_v6 = dests.iter().any(|d| d.addr.is_ipv6());
        let open = |unspec: SocketAddr, family: &'static str| {
            let s = UdpSocket::bind(unspec)
                .map_err(|source| PublishError::Socket { family, source })?;
            // Never block the frame path on a full socket buffer: such a
            // send is counted as an error of that destination instead.
            s.set_nonblocking(true)
                .map_err(|source| PublishError::Socket { family, source })?;
            Ok::<_, PublishError>(s)
        };
        let v4 = if need_v4 {
            Some(open(SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)), "IPv4")?)
        } else {
            None
        };
        let v6 = if need_v6 {
            Some(open(SocketAddr::from((Ipv6Addr::UNSPECIFIED, 0)), "IPv6")?)
        } else {
            None
        };
        if let Some(m) = &cfg.multicast {
            let mc = |what, r: std::io::Result<()>| {
                r.map_err(|source| PublishError::Multicast { what, source })
            };
            match (m.group, &v4, &v6) {
                (SocketAddr::V4(_), Some(s), _) => {
                    mc("ttl", s.set_multicast_ttl_v4(m.ttl))?;
                    mc("loopback", s.set_multicast_loop_v4(m.loopback))?;
                    if !m.interface.is_unspecified() {
                        mc(
                            "interface",
                            SockRef::from(s).set_multicast_if_v4(&m.interface),
                        )?;
                    }
                }
                (SocketAddr::V6(_), _, Some(s)) => {
                    mc("ttl", SockRef::from(s).set_multicast_hops_v6(m.ttl))?;
                    mc("loopback", s.set_multicast_loop_v6(m.loopback))?;
                }
                _ => {}
            }
        }
        Ok(Publisher { v4, v6, dests })
    }

    pub fn destinations(&self) -> &[Destination] {
        &self.dests
    }

    /// Send one datagram to every destination; returns how many took it.
    /// Never allocates unless a destination fails (the error text).
    pub fn send(&self, msg: &[u8]) -> usize {
        let mut ok = 0;
        for d in &self.dests {
            let sock = if d.addr.is_ipv4() { &self.v4 } else { &self.v6 };
            let Some(sock) = sock else { continue };
            match sock.send_to(msg, d.addr) {
                Ok(_) => {
                    d.stats.sent.fetch_add(1, Relaxed);
                    ok += 1;
                }
                Err(e) => {
                    let n = d.stats.errors.fetch_add(1, Relaxed) + 1;
                    // Log the first error and then every 1000th, so a dead
                    // destination is visible without flooding the journal.
                    if n == 1 || n.is_multiple_of(1000) {
                        tracing::warn!(destination = %d.addr, errors = n, "send failed: {e}");
                    }
                    if let Ok(mut g) = d.stats.last_error.lock() {
                        if g.as_deref() != Some(&e.to_string()) {
                            *g = Some(e.to_string());
                        }
                    }
                }
            }
        }
        ok
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
        // Port 0 cannot be sent to: every send to it fails.
        let bad: SocketAddr = "127.0.0.1:0".parse().unwrap();
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
}
