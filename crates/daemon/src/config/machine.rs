//! What the config names, tried against this machine without changing
//! it: the recording directory (not a file, nor under one) and the
//! addresses the daemon binds (bound and let go at once). `wiring::check`
//! runs these at `--check-config` and before a start; each refusal names
//! the key's `FILE:LINE`.

use super::{ConfigError, KeyAt};
use socket2::SockRef;
use std::io;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, TcpListener, UdpSocket};
use std::path::Path;

/// Whether the recording directory is one or can be made: the path, or
/// the nearest part of it that exists, must be a directory. Nothing is
/// created; what only the daemon's user may do (a directory it cannot
/// write) is not judged here: the recorder says so at its first file.
pub fn recording_dir(dir: &Path, at: &KeyAt) -> Result<(), ConfigError> {
    let key = "recording.dir";
    let mut part = Some(dir);
    while let Some(p) = part.filter(|p| !p.as_os_str().is_empty()) {
        let cannot = |why: String| {
            if p == dir {
                at.refuse(key, format!("{}: {why}", dir.display()))
            } else {
                let msg = format!(
                    "{} cannot be created: {}: {why}",
                    dir.display(),
                    p.display()
                );
                at.refuse(key, msg)
            }
        };
        match std::fs::metadata(p) {
            Ok(m) if m.is_dir() => return Ok(()),
            Ok(_) => return Err(cannot("exists and is not a directory".into())),
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                if std::fs::symlink_metadata(p).is_ok() {
                    return Err(cannot("a symbolic link to nothing".into()));
                }
            }
            // A part above is a file: that part is named when reached.
            Err(e) if e.kind() == io::ErrorKind::NotADirectory => {}
            // Not ours to judge (a directory this user may not search).
            Err(_) => return Ok(()),
        }
        part = p.parent();
    }
    Ok(())
}

/// Bind a UDP socket to `addr` as the daemon would (no SO_REUSEADDR).
pub fn try_udp(addr: SocketAddr) -> io::Result<UdpSocket> {
    UdpSocket::bind(addr)
}

/// Listen on TCP `addr` as the daemon would (std, like tokio, sets
/// SO_REUSEADDR: a port in TIME_WAIT is no obstacle).
pub fn try_tcp(addr: SocketAddr) -> io::Result<TcpListener> {
    TcpListener::bind(addr)
}

/// Open the sending socket `Publisher::open` opens for `dest`: bound to
/// the unspecified address of its family.
pub fn try_sender(dest: SocketAddr) -> io::Result<UdpSocket> {
    let unspecified: IpAddr = if dest.is_ipv4() {
        Ipv4Addr::UNSPECIFIED.into()
    } else {
        Ipv6Addr::UNSPECIFIED.into()
    };
    UdpSocket::bind((unspecified, 0))
}

/// Whether `ip` is an IPv4 address of this machine that multicast can be
/// sent from (what `Publisher::open` sets).
pub fn try_multicast_interface(ip: Ipv4Addr) -> io::Result<()> {
    let s = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))?;
    SockRef::from(&s).set_multicast_if_v4(&ip)
}

/// A bind's failure with why, where the OS error leaves it unsaid (the
/// caller says where: `DaemonError::at`).
pub fn bind_refusal(addr: SocketAddr, e: io::Error) -> io::Error {
    let why = match e.kind() {
        io::ErrorKind::AddrInUse => "in use (is lightposed already running?)".to_string(),
        io::ErrorKind::AddrNotAvailable => {
            format!("{} is not an address of this machine", addr.ip())
        }
        io::ErrorKind::PermissionDenied if addr.port() < 1024 => format!(
            "port {} is below 1024: binding it needs CAP_NET_BIND_SERVICE",
            addr.port()
        ),
        _ => return e,
    };
    io::Error::new(e.kind(), format!("{why}: {e}"))
}

/// Setting the multicast interface failed, with why.
pub fn interface_refusal(ip: Ipv4Addr, e: io::Error) -> io::Error {
    if e.kind() == io::ErrorKind::AddrNotAvailable {
        let msg = format!("{ip} is not an address of this machine: {e}");
        io::Error::new(e.kind(), msg)
    } else {
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at() -> KeyAt {
        KeyAt {
            file: "t.toml".into(),
            line: Some(7),
        }
    }

    #[test]
    fn a_file_where_the_directory_or_a_parent_must_be_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("f");
        std::fs::write(&file, b"x").expect("write");
        assert!(recording_dir(dir.path(), &at()).is_ok());
        assert!(recording_dir(&dir.path().join("new/deeper"), &at()).is_ok());
        let e = recording_dir(&file, &at()).expect_err("a file").to_string();
        assert!(e.starts_with("t.toml:7: recording.dir: "), "{e}");
        assert!(e.ends_with("f: exists and is not a directory"), "{e}");
        let e = recording_dir(&file.join("a/b"), &at())
            .expect_err("under a file")
            .to_string();
        assert!(e.contains("a/b cannot be created: "), "{e}");
        assert!(e.ends_with("f: exists and is not a directory"), "{e}");
        assert!(!file.join("a").exists() && !dir.path().join("new").exists());
    }

    #[test]
    fn bind_refusals_say_why_at_the_key() {
        let addr: SocketAddr = "127.0.0.1:9".parse().expect("addr");
        let e = io::Error::from(io::ErrorKind::AddrInUse);
        let r = bind_refusal(addr, e);
        assert_eq!(r.kind(), io::ErrorKind::AddrInUse);
        assert!(r
            .to_string()
            .starts_with("in use (is lightposed already running?): "));
    }
}
