//! Log lines against a stderr that takes nothing (soak audit: journald
//! stalled long enough to fill its socket's buffer): the lines were written
//! on the logging thread, so the frame thread blocked on its next line and
//! the watchdog restarted the daemon. They are written by a thread of their
//! own now: the daemon runs on while stderr is stalled, writes what was
//! queued once it moves again (the last lines included, at exit), and a
//! stderr still stalled at exit does not hold the exit.

mod common;
use common::run::{collect, sim_config, wait_exit};
use common::subscriber;

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use std::io::{ErrorKind, PipeReader, Read, Write};
use std::os::fd::AsRawFd;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A pipe whose buffer is already full: whoever writes to it blocks.
fn full_pipe() -> (PipeReader, std::io::PipeWriter) {
    let (r, mut w) = std::io::pipe().expect("pipe");
    let fd = w.as_raw_fd();
    let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL).expect("F_GETFL"));
    fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).expect("F_SETFL");
    for chunk in [4096, 1] {
        loop {
            match w.write(&vec![b'.'; chunk]) {
                Ok(_) => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) => panic!("filling the pipe: {e}"),
            }
        }
    }
    // The child's writes must block, as on a full journald socket.
    fcntl(fd, FcntlArg::F_SETFL(flags)).expect("F_SETFL");
    (r, w)
}

/// The real binary on the simulator, its stderr a full pipe; the pipe's
/// other end, and the STATUS and POSE subscriber.
fn stalled_daemon(dir: &std::path::Path) -> (Child, PipeReader, std::net::UdpSocket) {
    let (sub, addr) = subscriber();
    let cfg = dir.join("lightposed.toml");
    std::fs::write(&cfg, sim_config(50.0, &[addr], "", "")).expect("config");
    let (r, w) = full_pipe();
    let child = Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--config")
        .arg(&cfg)
        .env_remove("JOURNAL_STREAM")
        .env_remove("NO_COLOR")
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(w)
        .spawn()
        .expect("spawn");
    (child, r, sub)
}

/// POSE and STATUS keep coming for a second while stderr takes nothing
/// (before, the first log line blocked the start: nothing came at all).
fn frames_go_on(child: &mut Child, sub: &std::net::UdpSocket) {
    let t0 = Instant::now();
    let (mut poses, mut statuses) = (0, 0);
    while t0.elapsed() < Duration::from_secs(10) && (poses < 50 || statuses < 3) {
        for v in collect(sub, Duration::from_millis(100)) {
            poses += usize::from(v["class"] == "POSE");
            statuses += usize::from(v["class"] == "STATUS");
        }
    }
    if poses < 50 || statuses < 3 {
        let _ = child.kill();
        panic!("stderr stalled: {poses} POSE and {statuses} STATUS in 10 s");
    }
}

#[test]
fn a_stalled_stderr_stops_no_frame_and_loses_no_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut child, mut r, sub) = stalled_daemon(dir.path());
    frames_go_on(&mut child, &sub);
    // stderr moves again: what was queued is written, then the last lines.
    let reader = std::thread::spawn(move || {
        let mut got = Vec::new();
        r.read_to_end(&mut got).expect("read");
        got
    });
    std::thread::sleep(Duration::from_millis(200));
    common::run::signal(&child, nix::sys::signal::Signal::SIGTERM);
    let st = wait_exit(&mut child, Duration::from_secs(10));
    let got = reader.join().expect("reader");
    let text = String::from_utf8_lossy(&got);
    let text = text.trim_start_matches('.');
    assert_eq!(st.code(), Some(0), "{text}");
    let first = text.find("publishing to").expect("the first line");
    let sigterm = text.find("SIGTERM").expect("the SIGTERM line");
    let last = text
        .find("stopped (")
        .expect("the last line, flushed at exit");
    assert!(first < sigterm && sigterm < last, "{text}");
    assert!(!text.contains("log lines lost"), "none lost: {text}");
}

#[test]
fn a_stderr_still_stalled_at_exit_does_not_hold_the_exit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut child, _r, sub) = stalled_daemon(dir.path());
    frames_go_on(&mut child, &sub);
    let t0 = Instant::now();
    common::run::signal(&child, nix::sys::signal::Signal::SIGTERM);
    let st = wait_exit(&mut child, Duration::from_secs(10));
    assert_eq!(st.code(), Some(0));
    // The writer is given ~1.1 s to flush, then left behind.
    assert!(t0.elapsed() < Duration::from_secs(4), "{:?}", t0.elapsed());
}
