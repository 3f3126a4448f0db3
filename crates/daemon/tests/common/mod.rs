//! Helpers shared by the daemon's end-to-end and fault tests: where the
//! shipped files are, a loopback subscriber, and reading recordings back.
#![allow(dead_code)] // each test binary uses its own subset

pub mod run;
pub mod vehicle;

use lightpose_core::LogReader;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::Duration;

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The shipped scene, trajectory and calibration the tests run on.
pub fn shipped() -> (PathBuf, PathBuf, PathBuf) {
    let r = root();
    let files = (
        r.join("config/scenes/tank.toml"),
        r.join("config/trajectories/zigzag.csv"),
        r.join("config/calibration/tank.toml"),
    );
    for p in [&files.0, &files.1, &files.2] {
        assert!(
            p.is_file(),
            "{} is part of the project and must exist",
            p.display()
        );
    }
    files
}

/// A TCP port free a moment ago: the config refuses port 0 (a listener
/// there gets a port nobody knows), so a test asks the kernel for one.
pub fn free_tcp_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("probe listener");
    l.local_addr().expect("probe address").port()
}

pub fn subscriber() -> (UdpSocket, SocketAddr) {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind subscriber");
    s.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let _ = socket2::SockRef::from(&s).set_recv_buffer_size(4 << 20);
    let a = s.local_addr().expect("addr");
    (s, a)
}

/// Frames of every log in `dir`, and whether any log ended cut short.
pub fn read_logs(dir: &Path) -> (Vec<u64>, bool) {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("e").path())
        .collect();
    logs.sort();
    let (mut seqs, mut cut) = (Vec::new(), false);
    for l in logs {
        let mut r = LogReader::open(&l).expect("log opens");
        for f in r.by_ref() {
            seqs.push(f.expect("every line reads back").seq);
        }
        cut |= r.truncated_at().is_some();
    }
    (seqs, cut)
}
