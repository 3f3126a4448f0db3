//! What the daemon's connected UDP sockets (its POSE destinations, the
//! MAVLink `udpout` link) share: telling when the vehicle's own address has
//! gone from under a socket, and letting the socket pick a new one.
//!
//! A connected UDP socket keeps the source address the kernel chose when
//! it connected. When the vehicle's address changes (a DHCP renumber, the
//! tether taking over from Wi-Fi), every later send fails ("Network is
//! unreachable") for as long as the daemon runs, while a new socket would
//! send at once: an audit saw 0 of ~410 datagrams leave in 8 s, and the
//! MAVLink stream stop for good, the watchdog still fed. Connecting again
//! is not enough: Linux keeps a connected socket's source; only a
//! disconnect (`connect` to `AF_UNSPEC`) clears it, for a socket bound to
//! the unspecified address as these are.

use std::io;
use std::os::fd::AsRawFd;

/// Whether a send failed because the socket's source address is no longer
/// usable: no route from it (`ENETUNREACH`), the address gone
/// (`EADDRNOTAVAIL`), or the kernel refusing the pair (`EINVAL`).
pub fn source_gone(e: &io::Error) -> bool {
    use nix::libc::{EADDRNOTAVAIL, EINVAL, ENETUNREACH};
    matches!(e.raw_os_error(), Some(ENETUNREACH | EADDRNOTAVAIL | EINVAL))
}

/// Disconnect a connected UDP socket, so that its next `connect` picks its
/// source address afresh.
pub fn disconnect(sock: &impl AsRawFd) -> io::Result<()> {
    use nix::libc;
    // SAFETY: a plain sockaddr, valid zeroed with the family AF_UNSPEC,
    // which `connect` reads and does not keep.
    let mut sa: libc::sockaddr = unsafe { std::mem::zeroed() };
    sa.sa_family = libc::AF_UNSPEC as libc::sa_family_t;
    let len = std::mem::size_of::<libc::sockaddr>() as libc::socklen_t;
    // SAFETY: the descriptor is the caller's open socket; `sa` outlives
    // the call.
    if unsafe { libc::connect(sock.as_raw_fd(), &sa, len) } == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::UdpSocket;

    /// A socket bound to the unspecified address takes the route's source
    /// when it connects, and lets it go when disconnected, so the next
    /// connect chooses again.
    #[test]
    fn a_disconnected_socket_forgets_its_source() {
        let far = UdpSocket::bind("127.0.0.1:0").unwrap();
        let s = UdpSocket::bind("0.0.0.0:0").unwrap();
        s.connect(far.local_addr().unwrap()).unwrap();
        assert_eq!(s.local_addr().unwrap().ip().to_string(), "127.0.0.1");
        disconnect(&s).unwrap();
        assert!(s.local_addr().unwrap().ip().is_unspecified());
        assert!(s.send(b"x").is_err(), "no longer connected");
        s.connect(far.local_addr().unwrap()).unwrap();
        s.send(b"x").unwrap();
        let mut buf = [0u8; 4];
        assert_eq!(far.recv(&mut buf).unwrap(), 1);
    }

    #[test]
    fn only_a_lost_source_is_told_as_one() {
        use nix::libc::{EADDRNOTAVAIL, ECONNREFUSED, EINVAL, ENETUNREACH};
        for e in [ENETUNREACH, EADDRNOTAVAIL, EINVAL] {
            assert!(source_gone(&io::Error::from_raw_os_error(e)));
        }
        assert!(!source_gone(&io::Error::from_raw_os_error(ECONNREFUSED)));
        assert!(!source_gone(&io::Error::other("x")));
    }
}
