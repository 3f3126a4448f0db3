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

/// A copy in `dir` of the shipped calibration that `cfg_text` names, and
/// `cfg_text` naming the copy: a test that reloads writes
/// [`other_calibration`] there first (a reload of the running calibration
/// is no reload).
pub fn calibration_copy(dir: &Path, cfg_text: &str) -> (PathBuf, String, String) {
    let (_, _, shipped_cal) = shipped();
    let good = std::fs::read_to_string(&shipped_cal).expect("calibration");
    let cal = dir.join("cal.toml");
    std::fs::write(&cal, &good).expect("calibration copy");
    let shipped_s = shipped_cal.display().to_string();
    assert!(
        cfg_text.contains(&shipped_s),
        "the config names the shipped calibration"
    );
    let text = cfg_text.replace(&shipped_s, &cal.display().to_string());
    (cal, text, good)
}

/// `cal` (a calibration's text) with a field changed that no estimate
/// reads: a calibration other than the running one.
pub fn other_calibration(cal: &str) -> String {
    let changed = cal.replacen("bad_lines = 0\n", "bad_lines = 1\n", 1);
    assert_ne!(changed, cal, "[meta] bad_lines");
    changed
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
