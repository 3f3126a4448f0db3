//! The MAVLink transports, named as MAVLink tools name them:
//! `udpout:HOST:PORT` (send to the autopilot's or router's port, hear its
//! replies), `udpin:ADDR:PORT` (listen; reply to the address the
//! autopilot's own frames come from, see [`Link::accept_sender`]),
//! `tcpout:HOST:PORT` (connect to a TCP server: mavlink-router's, BlueOS's;
//! reconnected with the task's back-off when it closes), `tcpin:ADDR:PORT`
//! (listen; one connection at a time, see [`Link::recv`]) and
//! `serial:/dev/ttyX:BAUD`. TCP and serial are streams (see `scan`).
//!
//! Serial is our own: the port is opened and set up by `serialport`
//! (without libudev, which the vehicle's Linux may lack) and then read and
//! written non-blocking through tokio's `AsyncFd`, so one task serves every
//! transport. The `mavlink` crate's own serial transport is blocking and
//! its readers drop bad frames without counting them (see `scan`).

use super::scan::Framing;
use serialport::TTYPort;
use std::fmt;
use std::io;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
use std::os::fd::AsRawFd;
use std::str::FromStr;
use std::time::{Duration, Instant};
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};

/// Where the autopilot is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    UdpOut { host: String, port: u16 },
    UdpIn(SocketAddr),
    TcpOut { host: String, port: u16 },
    TcpIn(SocketAddr),
    Serial { path: String, baud: u32 },
}

impl FromStr for Endpoint {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (kind, rest) = s.split_once(':').ok_or_else(|| {
            format!(
                "\"{s}\" is not KIND:…; want udpout:HOST:PORT, udpin:ADDR:PORT, tcpout:HOST:PORT, tcpin:ADDR:PORT or serial:PATH:BAUD"
            )
        })?;
        let (head, tail) = rest
            .rsplit_once(':')
            .ok_or_else(|| format!("\"{s}\" lacks its :PORT or :BAUD"))?;
        match kind {
            "udpout" | "udpin" | "tcpout" | "tcpin" => {
                let port: u16 = tail
                    .parse()
                    .map_err(|_| format!("\"{tail}\" in \"{s}\" is not a port number"))?;
                let host = head.trim_start_matches('[').trim_end_matches(']');
                if host.is_empty() {
                    return Err(format!("\"{s}\" has no host"));
                }
                let host_s = host.to_string();
                match kind {
                    "udpout" => return Ok(Endpoint::UdpOut { host: host_s, port }),
                    "tcpout" => return Ok(Endpoint::TcpOut { host: host_s, port }),
                    _ => {}
                }
                let ip = host.parse().map_err(|_| {
                    format!("\"{host}\" in \"{s}\" is not an IP address to listen on")
                })?;
                let at = SocketAddr::new(ip, port);
                Ok(if kind == "udpin" {
                    Endpoint::UdpIn(at)
                } else {
                    Endpoint::TcpIn(at)
                })
            }
            "serial" => {
                let baud: u32 = tail
                    .parse()
                    .ok()
                    .filter(|b| *b > 0)
                    .ok_or_else(|| format!("\"{tail}\" in \"{s}\" is not a baud rate"))?;
                if head.is_empty() {
                    return Err(format!("\"{s}\" has no device path"));
                }
                Ok(Endpoint::Serial {
                    path: head.to_string(),
                    baud,
                })
            }
            other => Err(format!(
                "unknown transport \"{other}\" in \"{s}\"; want udpout, udpin, tcpout, tcpin or serial"
            )),
        }
    }
}

impl Endpoint {
    /// The address a listening link binds (`udpin`, `tcpin`), else None.
    pub fn listen_addr(&self) -> Option<SocketAddr> {
        match self {
            Endpoint::UdpIn(a) | Endpoint::TcpIn(a) => Some(*a),
            _ => None,
        }
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::UdpOut { host, port } if host.contains(':') => {
                write!(f, "udpout:[{host}]:{port}")
            }
            Endpoint::UdpOut { host, port } => write!(f, "udpout:{host}:{port}"),
            Endpoint::UdpIn(a) => write!(f, "udpin:{a}"),
            Endpoint::TcpOut { host, port } if host.contains(':') => {
                write!(f, "tcpout:[{host}]:{port}")
            }
            Endpoint::TcpOut { host, port } => write!(f, "tcpout:{host}:{port}"),
            Endpoint::TcpIn(a) => write!(f, "tcpin:{a}"),
            Endpoint::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
        }
    }
}

/// Why a link could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("{endpoint}: cannot resolve the host")]
    Resolve {
        endpoint: String,
        #[source]
        source: io::Error,
    },
    #[error("{endpoint}: cannot open the UDP socket")]
    Socket {
        endpoint: String,
        #[source]
        source: io::Error,
    },
    #[error("{endpoint}: cannot connect or listen on TCP")]
    Tcp {
        endpoint: String,
        #[source]
        source: io::Error,
    },
    #[error("{endpoint}: cannot open the serial port")]
    Serial {
        endpoint: String,
        #[source]
        source: io::Error,
    },
}

/// How long the `udpin` peer must have sent nothing from the autopilot
/// before another address may take its place. ArduSub sends a HEARTBEAT
/// every second and its streams at several Hz, so 3 s is three missed
/// heartbeats (what GCSs call a lost link): a moved autopilot or router
/// costs at most that much of the poses, while a second sender with the
/// same ids never takes the poses from an autopilot that still speaks.
pub const PEER_SILENCE: Duration = Duration::from_secs(3);

/// How long one frame may take to go out on TCP before the far end is
/// taken to have stopped reading (its window full): the heartbeat's
/// period twice over.
pub const TCP_WRITE_BOUND: Duration = Duration::from_secs(2);

/// What [`Link::accept_sender`] did with the peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeerChange {
    /// The first peer of this link.
    First(SocketAddr),
    /// The peer moved after `PEER_SILENCE` of silence.
    Moved { from: SocketAddr, to: SocketAddr },
}

enum Inner {
    UdpOut {
        sock: UdpSocket,
        /// Where it is connected: connected again from a new source
        /// address when the vehicle's own changed (`lightpose_core::udp`).
        to: SocketAddr,
    },
    UdpIn {
        sock: UdpSocket,
        /// Where frames go: set only by `accept_sender`.
        peer: Option<SocketAddr>,
        /// When the peer last sent a frame of the autopilot.
        heard: Option<Instant>,
        /// The sender of the last datagram received, not yet vouched for.
        sender: Option<SocketAddr>,
    },
    TcpOut {
        stream: TcpStream,
    },
    TcpIn {
        listener: TcpListener,
        /// The connection held, and its far end.
        conn: Option<(TcpStream, SocketAddr)>,
        /// When it was accepted or last carried a frame of the autopilot.
        heard: Option<Instant>,
        /// The address frames go to, once its frame was taken (for
        /// STATUS `peer`, as on `udpin`).
        vouched: Option<SocketAddr>,
        /// Connections closed at once because one was held (see `recv`).
        refused: u64,
    },
    Serial {
        fd: AsyncFd<TTYPort>,
        /// How long one frame may take to go out, see [`write_bound`].
        write_bound: Duration,
    },
}

/// An open MAVLink link.
pub struct Link {
    inner: Inner,
}

impl Drop for Link {
    /// A serial port's unsent output is discarded before it closes: Linux
    /// waits up to the tty's `closing_wait` (30 s by default) for output
    /// to drain, and a far end that stopped reading never drains it, so
    /// the stop, or the reopen after a stall, would wait that long (a
    /// review). Poses that did not go out are stale by then anyway.
    fn drop(&mut self) {
        if let Inner::Serial { fd, .. } = &self.inner {
            // SAFETY: the descriptor is the TTYPort's, open until the
            // AsyncFd (dropped after this) closes it.
            let borrowed = unsafe { std::os::fd::BorrowedFd::borrow_raw(fd.as_raw_fd()) };
            let _ = nix::sys::termios::tcflush(borrowed, nix::sys::termios::FlushArg::TCOFLUSH);
        }
    }
}

/// What became of an outgoing frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sent {
    Yes,
    /// `udpin` before anyone spoke: nowhere to send yet.
    NoPeer,
}

fn sock_err(ep: &Endpoint) -> impl FnOnce(io::Error) -> LinkError + '_ {
    move |source| LinkError::Socket {
        endpoint: ep.to_string(),
        source,
    }
}

impl Link {
    pub async fn open(ep: &Endpoint) -> Result<Link, LinkError> {
        let inner = match ep {
            Endpoint::UdpOut { host, port } => {
                let resolve = |source| LinkError::Resolve {
                    endpoint: ep.to_string(),
                    source,
                };
                let to = tokio::net::lookup_host((host.as_str(), *port))
                    .await
                    .map_err(resolve)?
                    .next()
                    .ok_or_else(|| {
                        resolve(io::Error::new(io::ErrorKind::NotFound, "no address"))
                    })?;
                let any = if to.is_ipv4() {
                    SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0))
                } else {
                    SocketAddr::from((Ipv6Addr::UNSPECIFIED, 0))
                };
                let sock = UdpSocket::bind(any).await.map_err(sock_err(ep))?;
                sock.connect(to).await.map_err(sock_err(ep))?;
                Inner::UdpOut { sock, to }
            }
            Endpoint::UdpIn(addr) => Inner::UdpIn {
                sock: UdpSocket::bind(addr).await.map_err(sock_err(ep))?,
                peer: None,
                heard: None,
                sender: None,
            },
            Endpoint::TcpOut { host, port } => {
                let tcp = |source| LinkError::Tcp {
                    endpoint: ep.to_string(),
                    source,
                };
                let stream = TcpStream::connect((host.as_str(), *port))
                    .await
                    .map_err(tcp)?;
                // Frames are small and each is due now.
                stream.set_nodelay(true).map_err(tcp)?;
                Inner::TcpOut { stream }
            }
            Endpoint::TcpIn(addr) => Inner::TcpIn {
                listener: TcpListener::bind(addr)
                    .await
                    .map_err(|source| LinkError::Tcp {
                        endpoint: ep.to_string(),
                        source,
                    })?,
                conn: None,
                heard: None,
                vouched: None,
                refused: 0,
            },
            Endpoint::Serial { path, baud } => Inner::Serial {
                fd: open_serial(path, *baud).map_err(|source| LinkError::Serial {
                    endpoint: ep.to_string(),
                    source,
                })?,
                write_bound: write_bound(*baud),
            },
        };
        Ok(Link { inner })
    }

    /// How frames arrive on this link.
    pub fn framing(&self) -> Framing {
        match self.inner {
            Inner::Serial { .. } | Inner::TcpOut { .. } | Inner::TcpIn { .. } => Framing::Stream,
            _ => Framing::Datagram,
        }
    }

    /// The local UDP or TCP address (for tests and logs).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.inner {
            Inner::UdpOut { sock: s, .. } | Inner::UdpIn { sock: s, .. } => s.local_addr().ok(),
            Inner::TcpOut { stream } => stream.local_addr().ok(),
            Inner::TcpIn { listener, .. } => listener.local_addr().ok(),
            Inner::Serial { .. } => None,
        }
    }

    /// Whether a send has somewhere to go: always, but on `udpin` only
    /// once a sender has been accepted, on `tcpin` while a connection is
    /// held.
    pub fn has_peer(&self) -> bool {
        match &self.inner {
            Inner::UdpIn { peer, .. } => peer.is_some(),
            Inner::TcpIn { conn, .. } => conn.is_some(),
            _ => true,
        }
    }

    /// The `udpin` or `tcpin` peer, if any (elsewhere none: the far end is
    /// fixed).
    pub fn peer(&self) -> Option<SocketAddr> {
        match &self.inner {
            Inner::UdpIn { peer, .. } => *peer,
            Inner::TcpIn { vouched, .. } => *vouched,
            _ => None,
        }
    }

    /// Connections a `tcpin` link closed at once since the last call,
    /// because it held one that still spoke (see [`Link::recv`]).
    pub fn take_refused_connections(&mut self) -> u64 {
        match &mut self.inner {
            Inner::TcpIn { refused, .. } => std::mem::take(refused),
            _ => 0,
        }
    }

    /// Where the last datagram came from (`udpin`), else None.
    pub fn sender(&self) -> Option<SocketAddr> {
        match &self.inner {
            Inner::UdpIn { sender, .. } => *sender,
            _ => None,
        }
    }

    /// Whether the last datagram may speak for the autopilot: on `udpin`
    /// only the peer's may, or anyone's when there is no peer yet or it
    /// has been silent for [`PEER_SILENCE`]; elsewhere always.
    pub fn sender_admitted(&self, now: Instant) -> bool {
        match &self.inner {
            Inner::UdpIn {
                peer: Some(p),
                heard,
                sender,
                ..
            } => {
                *sender == Some(*p)
                    || heard.is_none_or(|h| now.saturating_duration_since(h) >= PEER_SILENCE)
            }
            _ => true,
        }
    }

    /// On `udpin`, make the sender of the datagram last received the peer
    /// that frames go to, if [`Link::sender_admitted`] (elsewhere nothing).
    /// The caller does so only when that datagram held a valid frame of
    /// the autopilot: any host can send to a listening port, and garbage,
    /// another system's frame or a second sender with the autopilot's ids
    /// must not redirect the poses.
    pub fn accept_sender(&mut self, now: Instant) -> Option<PeerChange> {
        if let Inner::TcpIn {
            conn: Some((_, addr)),
            heard,
            vouched,
            ..
        } = &mut self.inner
        {
            *heard = Some(now);
            return match vouched.replace(*addr) {
                None => Some(PeerChange::First(*addr)),
                Some(old) if old != *addr => Some(PeerChange::Moved {
                    from: old,
                    to: *addr,
                }),
                Some(_) => None,
            };
        }
        let admitted = self.sender_admitted(now);
        let Inner::UdpIn {
            peer,
            heard,
            sender,
            ..
        } = &mut self.inner
        else {
            return None;
        };
        let s = sender.take()?;
        if !admitted {
            return None;
        }
        *heard = Some(now);
        match peer.replace(s) {
            None => Some(PeerChange::First(s)),
            Some(old) if old != s => Some(PeerChange::Moved { from: old, to: s }),
            Some(_) => None,
        }
    }

    /// Receive a datagram or a burst of serial or TCP bytes. Cancel-safe.
    ///
    /// `tcpin` holds one connection at a time: while it is held, a new one
    /// is closed at once (counted, [`Link::take_refused_connections`])
    /// unless the held one has carried no frame of the autopilot for
    /// [`PEER_SILENCE`] since it was accepted or last did, and then the new
    /// one replaces it (a router restarted, a peer gone without a FIN). A
    /// held connection that closes is let go and the next is awaited.
    pub async fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match &mut self.inner {
            Inner::TcpOut { stream } => match stream.read(buf).await? {
                0 => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the TCP server closed the connection",
                )),
                n => Ok(n),
            },
            Inner::TcpIn {
                listener,
                conn,
                heard,
                refused,
                ..
            } => loop {
                let Some((stream, _)) = conn.as_mut() else {
                    let (s, a) = listener.accept().await?;
                    let _ = s.set_nodelay(true);
                    (*conn, *heard) = (Some((s, a)), Some(Instant::now()));
                    continue;
                };
                enum Ev {
                    Read(io::Result<usize>),
                    Accept(io::Result<(TcpStream, SocketAddr)>),
                }
                let ev = tokio::select! {
                    r = stream.read(buf) => Ev::Read(r),
                    a = listener.accept() => Ev::Accept(a),
                };
                match ev {
                    Ev::Read(Ok(n)) if n > 0 => return Ok(n),
                    // Closed or reset: wait for the next connection.
                    Ev::Read(_) => *conn = None,
                    Ev::Accept(a) => {
                        let (s, addr) = a?;
                        let silent = heard.is_none_or(|h| h.elapsed() >= PEER_SILENCE);
                        if silent {
                            let _ = s.set_nodelay(true);
                            (*conn, *heard) = (Some((s, addr)), Some(Instant::now()));
                        } else {
                            *refused += 1;
                            drop(s);
                        }
                    }
                }
            },
            Inner::UdpOut { sock: s, .. } => s.recv(buf).await,
            Inner::UdpIn { sock, sender, .. } => {
                let (n, from) = sock.recv_from(buf).await?;
                *sender = Some(from);
                Ok(n)
            }
            Inner::Serial { fd, .. } => loop {
                let mut guard = fd.readable().await?;
                match guard.try_io(|p| {
                    nix::unistd::read(p.get_ref().as_raw_fd(), buf).map_err(io::Error::from)
                }) {
                    // A tty whose other end is gone reads 0 bytes forever.
                    Ok(Ok(0)) => {
                        return Err(io::Error::new(
                            io::ErrorKind::UnexpectedEof,
                            "serial port closed",
                        ))
                    }
                    Ok(r) => return r,
                    Err(_would_block) => continue,
                }
            },
        }
    }

    /// Send one frame. On serial, a frame that has not gone out within
    /// the link's [`write_bound`] fails with [`WriteStalled`] (kind
    /// `TimedOut`): the far end stopped reading, and the link is lost.
    pub async fn send(&mut self, bytes: &[u8]) -> io::Result<Sent> {
        match &mut self.inner {
            Inner::UdpOut { sock, to } => match sock.send(bytes).await {
                Ok(_) => Ok(Sent::Yes),
                Err(e) => {
                    if lightpose_core::udp::source_gone(&e)
                        && lightpose_core::udp::disconnect(sock).is_ok()
                    {
                        // Counted as this send's error; the next one goes
                        // from the new address (or fails to connect, and
                        // is counted, until the network is back).
                        sock.connect(*to).await?;
                    }
                    Err(e)
                }
            },
            Inner::UdpIn { sock, peer, .. } => match peer {
                Some(p) => sock.send_to(bytes, *p).await.map(|_| Sent::Yes),
                None => Ok(Sent::NoPeer),
            },
            Inner::TcpOut { stream } => tcp_write(stream, bytes).await.map(|_| Sent::Yes),
            // A connection that cannot take a frame is let go (the link
            // stays, listening): the next one is awaited.
            Inner::TcpIn { conn, .. } => match conn.as_mut() {
                None => Ok(Sent::NoPeer),
                Some((s, _)) => match tcp_write(s, bytes).await {
                    Ok(()) => Ok(Sent::Yes),
                    Err(_) => {
                        *conn = None;
                        Ok(Sent::NoPeer)
                    }
                },
            },
            Inner::Serial { fd, write_bound } => {
                let bound = *write_bound;
                let write = async {
                    let mut rest = bytes;
                    while !rest.is_empty() {
                        let mut guard = fd.writable().await?;
                        match guard.try_io(|p| nix::unistd::write(p, rest).map_err(io::Error::from))
                        {
                            Ok(Ok(n)) => rest = &rest[n..],
                            Ok(Err(e)) => return Err(e),
                            Err(_would_block) => continue,
                        }
                    }
                    Ok(Sent::Yes)
                };
                // A USB CDC autopilot that stops reading but stays
                // enumerated never fails a write: the tty's buffer fills
                // and `writable` never comes.
                match tokio::time::timeout(bound, write).await {
                    Ok(r) => r,
                    Err(_elapsed) => Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        WriteStalled { bound },
                    )),
                }
            }
        }
    }
}

/// Write one frame, within [`TCP_WRITE_BOUND`].
async fn tcp_write(stream: &mut TcpStream, bytes: &[u8]) -> io::Result<()> {
    match tokio::time::timeout(TCP_WRITE_BOUND, stream.write_all(bytes)).await {
        Ok(r) => r,
        Err(_elapsed) => Err(io::Error::new(
            io::ErrorKind::TimedOut,
            WriteStalled {
                bound: TCP_WRITE_BOUND,
            },
        )),
    }
}

/// A serial frame that did not go out within the link's [`write_bound`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a frame did not go out within {} ms: the far end reads nothing", bound.as_millis())]
pub struct WriteStalled {
    pub bound: Duration,
}

/// The kernel transmit buffer a live serial link may have to drain before
/// a frame of ours goes out: a UART's is a page (`UART_XMIT_SIZE`), 4 KiB
/// on most machines but 16 KiB on a Raspberry Pi 5's kernel, and the tty
/// layer wakes a writer only once it is nearly empty, so a frame may wait
/// for all of it (a review: a fixed 4 KiB called a healthy 57600-baud
/// radio lost on 16 KiB pages).
fn tx_buffer_bytes() -> u64 {
    let page = nix::unistd::sysconf(nix::unistd::SysconfVar::PAGE_SIZE);
    page.ok().flatten().map_or(4096, |p| p.max(4096) as u64)
}

/// How long one frame may take to go out at `baud` before the far end is
/// taken to have stopped reading: twice the time a full transmit buffer
/// (a page) takes to drain at 10 bits a byte (8N1), and never under 1 s
/// (the heartbeat period; USB's scheduling). A port that is read drains,
/// one that is not fills at any rate we send, so the bound only decides
/// how soon a stall is called lost. With 4 KiB pages: 1 s up to 115200
/// baud (a USB CDC autopilot, whose nominal baud is ignored), 1.4 s at
/// 57600, 8.5 s at 9600; with 16 KiB, 2.8 s / 5.7 s / 34 s.
pub fn write_bound(baud: u32) -> Duration {
    write_bound_for(baud, tx_buffer_bytes())
}

fn write_bound_for(baud: u32, buffer_bytes: u64) -> Duration {
    let drain_us = buffer_bytes * 10 * 1_000_000 / u64::from(baud.max(1));
    Duration::from_secs(1).max(Duration::from_micros(2 * drain_us))
}

/// Open a serial port raw at `baud`, non-blocking, registered with tokio.
fn open_serial(path: &str, baud: u32) -> io::Result<AsyncFd<TTYPort>> {
    let port = serialport::new(path, baud)
        .open_native()
        .map_err(io::Error::from)?;
    let fd = port.as_raw_fd();
    let flags = nix::fcntl::fcntl(fd, nix::fcntl::FcntlArg::F_GETFL).map_err(io::Error::from)?;
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(fd, nix::fcntl::FcntlArg::F_SETFL(flags)).map_err(io::Error::from)?;
    // SAFETY: the TTYPort owns its file descriptor, returns that same one
    // from every as_raw_fd() and closes it only when dropped, which is
    // after the AsyncFd that owns it has deregistered it (tokio's
    // documented use of `register`).
    unsafe { AsyncFd::register(port) }.map_err(io::Error::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_parse_and_print_back() {
        for s in [
            "udpout:127.0.0.1:14550",
            "udpout:blueos.local:14550",
            "udpin:0.0.0.0:14660",
            "serial:/dev/ttyACM0:115200",
            "udpin:[::1]:14550",
            "tcpout:127.0.0.1:5760",
            "tcpout:blueos.local:5777",
            "tcpin:0.0.0.0:5760",
            "tcpin:[::1]:5760",
        ] {
            let e: Endpoint = s.parse().unwrap();
            assert_eq!(e.to_string(), s);
        }
        for (s, why) in [
            ("tcp:1.2.3.4:5", "unknown transport"),
            ("tcpin:host:5", "not an IP address"),
            ("udpin:host:5", "not an IP address"),
            ("udpout:1.2.3.4:x", "not a port"),
            ("serial:/dev/ttyS0:0", "not a baud"),
            ("udpout:14550", "lacks"),
            ("14550", "is not KIND"),
        ] {
            let e = s.parse::<Endpoint>().unwrap_err();
            assert!(e.contains(why), "{s}: {e}");
        }
    }

    #[test]
    fn the_write_bound_is_a_second_or_twice_a_full_buffer_at_the_baud() {
        let page = 4096;
        assert_eq!(write_bound_for(921_600, page), Duration::from_secs(1));
        assert_eq!(write_bound_for(115_200, page), Duration::from_secs(1));
        // 4096 bytes × 10 bits at 57600 baud: 711 ms, twice over.
        let b = write_bound_for(57_600, page);
        assert!(
            b > Duration::from_millis(1420) && b < Duration::from_millis(1425),
            "{b:?}"
        );
        assert!(write_bound_for(9_600, page) > Duration::from_secs(8));
        assert!(write_bound_for(0, page) >= Duration::from_secs(1));
        // A Raspberry Pi 5's 16 KiB pages: four times the drain.
        let b = write_bound_for(57_600, 16_384);
        assert!(b > Duration::from_millis(5680) && b < Duration::from_millis(5700));
        // This machine's page, at least 4 KiB.
        assert!(write_bound(57_600) >= write_bound_for(57_600, page));
    }
}
