//! lightposed against a hostile but fair user (issue 16): signals during a
//! long gap of a replayed log, configurations that must be refused before a
//! start and at it (exit 2, so systemd does not restart them forever), a
//! port that is taken, bad attitude datagrams, logs out of order. Real
//! binary, real sockets, real files; each test a few seconds at most.

mod common;
use common::run::{collect, run_in_process, wait_exit};
use common::{shipped, subscriber};

use lightpose_core::{LogHeader, LogWriter, NDET};
use lightposed::Config;
use serde_json::Value;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_lightposed"))
}

/// A log of `frames` (seq, t) at `rate` Hz, lines written as given (a t
/// of 1e300 too), with the counts of the shipped dive's first frame.
fn write_log(path: &Path, rate: f64, frames: &[(u64, &str)]) {
    let mut w = LogWriter::create(path, &LogHeader::new(10, rate)).expect("log");
    w.flush().expect("flush");
    drop(w);
    let mut text = std::fs::read_to_string(path).expect("header");
    let counts: Vec<String> = (0..NDET).map(|k| (40 + 10 * k).to_string()).collect();
    for (seq, t) in frames {
        text.push_str(&format!(
            "{{\"class\":\"FRAME\",\"seq\":{seq},\"t\":{t},\"counts\":[{}]}}\n",
            counts.join(",")
        ));
    }
    std::fs::write(path, text).expect("write log");
}

fn replay_config(log: &Path, dests: &[SocketAddr], backend_extra: &str, extra: &str) -> String {
    let (_, _, cal) = shipped();
    let d: Vec<String> = dests.iter().map(|d| format!("\"{d}\"")).collect();
    format!(
        "rate_hz = 10.0\nestimator = \"moments\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\n{backend_extra}\n[outputs]\ndestinations = [{}]\nstatus_interval_s = 0.2\n{extra}\n",
        cal.display(),
        log.display(),
        d.join(", ")
    )
}

fn last_status(msgs: &[Value]) -> &Value {
    msgs.iter()
        .rev()
        .find(|v| v["class"] == "STATUS")
        .expect("a STATUS")
}

/// Item 1: SIGTERM while the replay waits through a 60 s gap of `t` (a gap
/// bound of an hour, so that it does wait): the daemon exits 0 at once.
#[test]
fn sigterm_during_a_long_replay_wait_exits_at_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("gap.jsonl");
    write_log(
        &log,
        10.0,
        &[(0, "0.0"), (1, "0.1"), (2, "60.1"), (3, "60.2")],
    );
    let (sub, addr) = subscriber();
    let cfg = dir.path().join("d.toml");
    let text = replay_config(&log, &[addr], "pace = \"recorded\"\nmax_gap_s = 3600.0", "");
    std::fs::write(&cfg, text).expect("config");
    let mut child = bin()
        .arg("--config")
        .arg(&cfg)
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    // Both frames before the gap, then into the wait.
    let t0 = Instant::now();
    let mut poses = 0;
    let mut buf = [0u8; 65536];
    while poses < 2 && t0.elapsed() < Duration::from_secs(10) {
        if let Ok(n) = sub.recv(&mut buf) {
            let v: Value = serde_json::from_slice(&buf[..n]).expect("JSON");
            poses += usize::from(v["class"] == "POSE");
        }
    }
    assert_eq!(poses, 2, "the frames before the gap");
    std::thread::sleep(Duration::from_millis(200));
    let sent = Instant::now();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let st = wait_exit(&mut child, Duration::from_secs(5));
    let took = sent.elapsed();
    assert_eq!(st.code(), Some(0));
    eprintln!("SIGTERM to exit during a 60 s wait: {took:?}");
    assert!(took < Duration::from_secs(2), "{took:?}");
}

/// Items 1 and 5: a forward jump of 60 s is not slept through (the gap
/// bound), `t = 1e300` is refused by its line and the frames after it go
/// on; STATUS counts both.
#[test]
fn a_jump_of_t_is_cut_and_an_absurd_t_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("jumps.jsonl");
    write_log(
        &log,
        10.0,
        &[
            (0, "0.0"),
            (1, "0.1"),
            (2, "60.1"),
            (3, "1e300"),
            (4, "60.3"),
            (5, "60.4"),
        ],
    );
    let (sub, addr) = subscriber();
    let text = replay_config(&log, &[addr], "pace = \"recorded\"\nmax_gap_s = 1.0", "");
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_secs(4));
    let msgs = collect(&sub, Duration::from_millis(2500));
    let summary = h.join().expect("daemon");
    let seqs: Vec<u64> = msgs
        .iter()
        .filter(|v| v["class"] == "POSE")
        .filter_map(|v| v["seq"].as_u64())
        .collect();
    assert_eq!(seqs, vec![0, 1, 2, 4, 5], "within 2.5 s, not after 60");
    assert!(summary.source_ended);
    let st = last_status(&msgs);
    let health = &st["backend"]["health"];
    assert_eq!(health["time_jumps"], 1, "{st}");
    assert_eq!(health["skipped_frames"], 1, "{st}");
    assert!(
        st["backend"]["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("jumps.jsonl:5: t = 1e300")),
        "{st}"
    );
}

/// Item 5: a step back of seq in a looping log is a skip, never frames
/// lost (nor 2^64 of them).
#[test]
fn a_backward_seq_is_skipped_not_counted_lost() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("back.jsonl");
    write_log(
        &log,
        10.0,
        &[(5, "0.0"), (6, "0.1"), (7, "0.2"), (3, "0.3")],
    );
    let (sub, addr) = subscriber();
    let text = replay_config(&log, &[addr], "pace = \"fast\"\nloop = true", "");
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(300));
    let msgs = collect(&sub, Duration::from_millis(500));
    let summary = h.join().expect("daemon");
    assert!(summary.frames > 30, "{summary:?}");
    assert_eq!(summary.lost, 0, "{summary:?}");
    let seqs: Vec<u64> = msgs
        .iter()
        .filter(|v| v["class"] == "POSE")
        .filter_map(|v| v["seq"].as_u64())
        .collect();
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "{:?}",
        &seqs[..10]
    );
}

/// Item 6: bad attitude datagrams are counted by reason in STATUS.
#[test]
fn bad_attitude_datagrams_are_counted_by_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("a.jsonl");
    let port = two_seconds_of_log_and_a_port(&log);
    let (sub, addr) = subscriber();
    let extra = format!(
        "[attitude]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\nbeacon_axis_heading_deg = 0.0\n"
    );
    let text = replay_config(&log, &[addr], "pace = \"recorded\"", &extra);
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1500));
    std::thread::sleep(Duration::from_millis(300));
    let ahrs = UdpSocket::bind("127.0.0.1:0").expect("ahrs");
    // A good object, then past byte 2048 (the buffer's size before) garbage.
    let mut long = br#"{"class":"ATTITUDE","t":2,"pitch":3,"yaw":10}"#.to_vec();
    long.resize(2048, b' ');
    long.extend_from_slice(&[0xff; 3000]);
    for d in [
        &br#"{"class":"ATTITUDE","t":1e12,"pitch":0,"yaw":0}"#[..],
        br#"{"class":"ATTITUDE","t":"yesterday","pitch":0,"yaw":0}"#,
        br#"{"class":"ATTITUDE","t":1,"pitch":0,"yaw":1e308}"#,
        br#"{"class":"POSE","t":1,"pitch":0,"yaw":0}"#,
        b"garbage",
        br#"["ATTITUDE",1,42,20]"#,
        &long,
        br#"{"class":"ATTITUDE","t":1,"pitch":3,"yaw":10}"#,
        br#"{"class":"ATTITUDE","t":1,"pitch":3,"yaw":10}"#,
    ] {
        ahrs.send_to(d, ("127.0.0.1", port)).expect("send");
    }
    let msgs = collect(&sub, Duration::from_millis(1500));
    h.join().expect("daemon");
    let att = &last_status(&msgs)["attitude"];
    assert_eq!(att["received"], 2, "{att}");
    assert_eq!(att["repeated"], 1, "{att}");
    assert_eq!(att["rejected"], 7, "{att}");
    let by = &att["rejected_by"];
    assert_eq!(
        (
            by["time"].as_u64(),
            by["angle"].as_u64(),
            by["class"].as_u64(),
            by["malformed"].as_u64(),
        ),
        (Some(2), Some(1), Some(1), Some(3)),
        "{att}"
    );
}

/// A 2 s log of 200 frames at `log`, and a free UDP port for an input.
fn two_seconds_of_log_and_a_port(log: &std::path::Path) -> u16 {
    let frames: Vec<(u64, String)> = (0..200)
        .map(|k| (k, format!("{}", k as f64 * 0.01)))
        .collect();
    let refs: Vec<(u64, &str)> = frames.iter().map(|(k, t)| (*k, t.as_str())).collect();
    write_log(log, 100.0, &refs);
    UdpSocket::bind("127.0.0.1:0")
        .expect("port")
        .local_addr()
        .expect("addr")
        .port()
}

/// Audit: with `allow_from`, a stranger's valid readings are counted
/// `sender` and never attached, while the AHRS's are.
#[test]
fn attitude_from_a_sender_not_allowed_is_refused_and_not_attached() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("a.jsonl");
    let rec = dir.path().join("rec");
    let port = two_seconds_of_log_and_a_port(&log);
    // Both on loopback: the AHRS is named with its port, so the stranger
    // differs only by port (an address alone is unit-tested in config).
    let ahrs = UdpSocket::bind("127.0.0.1:0").expect("ahrs");
    let stranger = UdpSocket::bind("127.0.0.1:0").expect("stranger");
    let ahrs_at = ahrs.local_addr().expect("ahrs addr");
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\n[attitude]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\nallow_from = [\"{ahrs_at}\"]\nbeacon_axis_heading_deg = 0.0\nmax_age_s = 0.5\n",
        rec.display()
    );
    let text = replay_config(&log, &[addr], "pace = \"recorded\"", &extra);
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1500));
    std::thread::sleep(Duration::from_millis(300));
    let (mut sent_ahrs, mut sent_stranger) = (0u64, 0u64);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(800) {
        let to = ("127.0.0.1", port);
        // t advances, as an AHRS's own stamp does.
        let good = format!(r#"{{"class":"ATTITUDE","t":{sent_ahrs},"pitch":3,"yaw":180}}"#);
        sent_ahrs += u64::from(ahrs.send_to(good.as_bytes(), to).is_ok());
        for _ in 0..5 {
            let evil = br#"{"class":"ATTITUDE","t":1,"pitch":30,"yaw":90}"#;
            sent_stranger += u64::from(stranger.send_to(evil, to).is_ok());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let msgs = collect(&sub, Duration::from_millis(1200));
    h.join().expect("daemon");
    let att = &last_status(&msgs)["attitude"];
    // Loopback does not drop here; the counts are those sent.
    assert_eq!(att["received"].as_u64(), Some(sent_ahrs), "{att}");
    assert_eq!(
        att["rejected_by"]["sender"].as_u64(),
        Some(sent_stranger),
        "{att}"
    );
    assert_eq!(att["rejected"].as_u64(), Some(sent_stranger), "{att}");
    let file = std::fs::read_dir(&rec)
        .expect("rec")
        .next()
        .expect("a log")
        .expect("entry")
        .path();
    let pitches: Vec<f64> = lightpose_core::LogReader::open(&file)
        .expect("log")
        .filter_map(|f| f.ok().and_then(|f| f.attitude))
        .map(|a| a.pitch.deg())
        .collect();
    assert!(pitches.len() > 10, "{} frames with attitude", pitches.len());
    assert!(
        pitches.iter().all(|p| (p - 3.0).abs() < 1e-9),
        "{pitches:?}"
    );
}

/// A config file in `dir` for the sim backend with `top` keys and `backend`
/// keys, calibration and scene from the shipped files unless given.
fn sim_config(dir: &Path, top: &str, backend: &str) -> PathBuf {
    let (scene, traj, cal) = shipped();
    let text = format!(
        "rate_hz = 50.0\ncalibration = \"{}\"\n{top}\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n{backend}\n[outputs]\ndestinations = [\"127.0.0.1:9\"]\n",
        cal.display(),
        scene.display(),
        traj.display()
    );
    let p = dir.join(format!("c{}.toml", text.len()));
    std::fs::write(&p, text).expect("config");
    p
}

/// Item 2: what a start would refuse, --check-config refuses too, and both
/// exit 2 with one line naming the place.
#[test]
fn check_config_refuses_what_a_start_would_and_both_exit_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let (_, _, cal) = shipped();
    let corrupt = d.join("corrupt.toml");
    std::fs::write(&corrupt, "this is not a calibration = [\n").expect("write");
    let bad_traj = d.join("bad.csv");
    std::fs::write(&bad_traj, "t,x,y\n").expect("write");
    let bad_log = d.join("bad.jsonl");
    std::fs::write(&bad_log, "{\"class\":\"FRAME\"}\n").expect("write");
    let (scene, traj, _) = shipped();
    let configs = [
        (
            std::fs::read_to_string(sim_config(d, "", ""))
                .expect("read")
                .replace(&cal.display().to_string(), "/nonexistent/cal.toml"),
            "/nonexistent/cal.toml",
        ),
        (
            std::fs::read_to_string(sim_config(d, "", ""))
                .expect("read")
                .replace(&cal.display().to_string(), &corrupt.display().to_string()),
            "corrupt.toml:",
        ),
        (
            std::fs::read_to_string(sim_config(d, "estimator = \"bogus\"", "")).expect("read"),
            "unknown estimator \"bogus\"",
        ),
        (
            std::fs::read_to_string(sim_config(d, "", ""))
                .expect("read")
                .replace(&traj.display().to_string(), "/nonexistent/t.csv"),
            "/nonexistent/t.csv",
        ),
        (
            std::fs::read_to_string(sim_config(d, "", ""))
                .expect("read")
                .replace(&traj.display().to_string(), &bad_traj.display().to_string()),
            "bad.csv:1: header",
        ),
        (
            std::fs::read_to_string(sim_config(d, "", ""))
                .expect("read")
                .replace(&scene.display().to_string(), "/nonexistent/scene.toml"),
            "/nonexistent/scene.toml",
        ),
        (
            replay_config(&bad_log, &["127.0.0.1:9".parse().expect("addr")], "", ""),
            "bad.jsonl:1: first line must be class HEADER",
        ),
    ];
    for (i, (text, want)) in configs.iter().enumerate() {
        let p = d.join(format!("case{i}.toml"));
        std::fs::write(&p, text).expect("write");
        let out = bin().arg("--check-config").arg(&p).output().expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--check-config {want}: {err}");
        assert!(err.contains(want), "--check-config {want}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        let mut child = bin()
            .arg("--config")
            .arg(&p)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        let st = wait_exit(&mut child, Duration::from_secs(10));
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut err)
            .expect("stderr");
        assert_eq!(st.code(), Some(2), "start with {want}: {err}");
        assert!(err.contains(want), "start: {want}: {err}");
        assert_eq!(err.matches(want).count(), 1, "said once: {err}");
    }
    // The shipped files pass.
    let ok = sim_config(d, "", "");
    let out = bin().arg("--check-config").arg(&ok).output().expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Item 7: a port that is taken is a runtime failure (exit 1: it may be
/// free after a restart), said once.
#[test]
fn a_busy_attitude_port_is_said_once_and_exits_1() {
    let dir = tempfile::tempdir().expect("tempdir");
    let taken = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let p = sim_config(dir.path(), "", "");
    let mut text = std::fs::read_to_string(&p).expect("read");
    text.push_str(&format!(
        "[attitude]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\nbeacon_axis_heading_deg = 0.0\n"
    ));
    std::fs::write(&p, text).expect("write");
    let out = bin().arg("--config").arg(&p).output().expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let want = format!("attitude.listen 127.0.0.1:{port}");
    assert_eq!(err.matches(&want).count(), 1, "said once: {err}");
    drop(taken);
}
