//! A stand-in Water Linked DVL (a TCP server in the test speaking the
//! vendor's JSON, one report per line) drives the daemon's velocity input:
//! the frames the daemon records carry its velocity; garbage lines,
//! `velocity_valid: false` and the server closing the connection are
//! counted in STATUS and survived (the client connects again), and no
//! frame is lost meanwhile.

mod common;

use common::run::{collect, of_class, run_in_process, sim_config};
use common::subscriber;
use lightpose_core::LogReader;
use lightposed::Config;
use std::io::Write;
use std::net::{TcpListener, TcpStream};
use std::time::{Duration, Instant};

const V: [f64; 3] = [0.3, 0.05, -0.02];

/// A report of `V`, sent 10 ms after its time of validity.
fn report(valid: bool) -> String {
    lightpose_testkit::dvl::report(V, valid, 10_000)
}

/// Good reports at 10 Hz for `d`.
fn reports(s: &mut TcpStream, d: Duration) {
    let t0 = Instant::now();
    while t0.elapsed() < d {
        s.write_all(report(true).as_bytes()).expect("write");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The DVL: reports, then garbage and invalid ones, then it closes the
/// connection; the daemon connects again and gets reports.
fn dvl(listener: TcpListener) {
    let (mut s, _) = listener.accept().expect("the daemon connects");
    reports(&mut s, Duration::from_millis(800));
    for line in ["garbage\n", "{\"vx\": \n", "\u{0}\u{1}binary\n"] {
        s.write_all(line.as_bytes()).expect("write");
    }
    for _ in 0..5 {
        s.write_all(report(false).as_bytes()).expect("write");
    }
    reports(&mut s, Duration::from_millis(300));
    drop(s); // unplugged
    let (mut s, _) = listener.accept().expect("the daemon connects again");
    reports(&mut s, Duration::from_millis(800));
}

#[test]
fn a_dvl_drives_the_velocity_input_and_its_faults_are_counted() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let server = std::thread::spawn(move || dvl(listener));
    let rec = tempfile::tempdir().expect("tmp");
    let (sub, dest) = subscriber();
    let extra = format!(
        "[dvl]\naddress = \"127.0.0.1:{port}\"\nreconnect_max_s = 0.2\n[recording]\ndir = \"{}\"\n",
        rec.path().display()
    );
    let text = sim_config(20.0, &[dest], "loop = true", &extra);
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let daemon = run_in_process(cfg, Duration::from_millis(3000));
    let msgs = collect(&sub, Duration::from_millis(3300));
    let summary = daemon.join().expect("the daemon ends without panic");
    server.join().expect("the stand-in DVL ran its script");
    assert_eq!((summary.lost, summary.failed), (0, 0), "{summary:?}");
    assert!(summary.frames >= 50, "{summary:?}");

    let status = of_class(&msgs, "STATUS");
    let v = &status.last().expect("STATUS")["vehicle"];
    eprintln!("{summary:?}; vehicle {v}");
    let d = &v["dvl"];
    assert_eq!(v["enabled"], true);
    assert!(d["connects"].as_u64() >= Some(2), "{d}");
    assert!(d["drops"].as_u64() >= Some(1), "{d}");
    assert!(d["reports"].as_u64() >= Some(15), "{d}");
    assert!(d["refused"]["garbage"].as_u64() >= Some(2), "{d}");
    assert_eq!(d["refused"]["velocity_invalid"].as_u64(), Some(5), "{d}");
    assert!(d["last_error"].is_string(), "{d}");
    let attached = v["readings"]["velocity"]["attached"].as_u64().unwrap_or(0);
    assert!(attached >= 20, "{v}");

    // The recording carries the velocity with the frames that got it.
    let mut with = 0;
    for f in common::run::files_in(rec.path()) {
        for frame in LogReader::open(&f).expect("log opens") {
            let frame = frame.expect("every line reads back");
            if let Some(r) = frame.velocity {
                assert_eq!(r.v.0, V, "seq {}", frame.seq);
                let std = r.std.expect("std from the covariance").0;
                assert!((std[1] - 0.02).abs() < 1e-12, "{std:?}");
                with += 1;
            }
        }
    }
    assert!(
        with >= 20 && with as u64 <= summary.frames,
        "{with} recorded with a velocity"
    );
}

/// A DVL whose reports arrive 1.6 s old (within what a DVL may lag, over
/// the velocity's 1 s limit) for 1.5 s, then fresh ones for 1.5 s.
fn late_then_fresh(listener: TcpListener) {
    let (mut s, _) = listener.accept().expect("the daemon connects");
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        let line = lightpose_testkit::dvl::report(V, true, 1_600_000);
        s.write_all(line.as_bytes()).expect("write");
        std::thread::sleep(Duration::from_millis(100));
    }
    reports(&mut s, Duration::from_millis(1500));
}

/// Reports that come too old for any frame were only a count in STATUS:
/// the journal now says once that the velocity went stale, and once that
/// it is back (the real binary, its stderr read).
#[test]
fn a_reading_gone_stale_is_told_once_and_once_back() {
    use common::run::{signal, spawn_daemon_to, wait_exit};
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let (sub, dest) = subscriber();
    let dir = tempfile::tempdir().expect("tmp");
    let extra = format!("[dvl]\naddress = \"127.0.0.1:{port}\"\n");
    let text = sim_config(20.0, &[dest], "loop = true", &extra);
    let server = std::thread::spawn(move || late_then_fresh(listener));
    let err = dir.path().join("stderr");
    let file = std::fs::File::create(&err).expect("stderr file");
    let (mut child, _) = spawn_daemon_to(dir.path(), &text, &sub, file.into());
    let msgs = collect(&sub, Duration::from_millis(3300));
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    assert!(wait_exit(&mut child, Duration::from_secs(5)).success());
    server.join().expect("the stand-in DVL ran its script");
    let log = std::fs::read_to_string(&err).expect("stderr");
    let status = of_class(&msgs, "STATUS");
    let r = &status.last().expect("STATUS")["vehicle"]["readings"]["velocity"];
    assert!(r["stale"].as_u64() >= Some(10), "{r}");
    assert!(r["attached"].as_u64() >= Some(10), "{r}");
    let stale: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("vehicle: velocity reading stale"))
        .collect();
    let back: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("vehicle: velocity reading back"))
        .collect();
    assert_eq!((stale.len(), back.len()), (1, 1), "{log}");
    assert!(
        stale[0].contains("WARN") && stale[0].contains("over its limit of 1 s"),
        "{}",
        stale[0]
    );
    assert!(back[0].contains("frames went without it"), "{}", back[0]);
}
