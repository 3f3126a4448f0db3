//! The daemon as a MAVLink component, end to end over UDP on loopback: it
//! replays a log that has no attitude, depth or temperature of its own,
//! a stand-in autopilot sends those readings from the log's truth in step
//! with the replay, and what the daemon sends back is judged against the
//! truth. The stand-in is pymavlink (an independent implementation,
//! tests/python/autopilot_replay.py) or, for machines without Python,
//! lightpose-vehicle's own; then bad MAVLink input into the running daemon.

mod common;

use common::run::{collect, of_class, run_in_process};
use common::subscriber;
use common::vehicle::{
    free_port, judge, mavlink_config, stand_in, stand_in_signed, write_bare_log,
};
use common::vehicle::{BEACON_DEPTH_M, HEADING_DEG, WATER_C};
use lightpose_core::LogReader;
use lightpose_testkit::python::python;
use lightpose_vehicle::mav::outbound::Encoder;
use lightpose_vehicle::mav::signing::{SigningConfig, SigningKey};
use lightposed::Config;
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use serde_json::Value;
use std::net::UdpSocket;
use std::time::Duration;

/// The bounds on the p95 errors: north, east, down (m), pitch,
/// heading (degrees).
const BOUNDS: [f64; 5] = [0.25, 0.25, 0.1, 1.5, 4.0];
/// The log: the zigzag at 20 Hz (8 s, 161 frames), replayed at its pace.
const RATE_HZ: f64 = 20.0;
const SECONDS: f64 = 8.0;
/// Coverage is counted after the first second of the log.
const COVER_AFTER_S: f64 = 1.0;
/// Errors are judged after the first second too, as the issue asks. (The
/// stand-in keeps step with the replay from the daemon's first HEARTBEAT
/// until the first pose: the daemon greets a udpin autopilot as soon as it
/// hears its HEARTBEAT, which the stand-in sends before every batch until
/// then, so the readings of the first frames are the truth of their own
/// time even when the daemon binds its port late on a loaded host.)
const P95_AFTER_S: f64 = 1.0;

fn check_p95(who: &str, p95: [f64; 5]) {
    eprintln!(
        "{who}: p95 north {:.3} m, east {:.3} m, down {:.3} m, pitch {:.2}°, heading {:.2}°",
        p95[0], p95[1], p95[2], p95[3], p95[4]
    );
    for (k, (v, b)) in p95.iter().zip(BOUNDS).enumerate() {
        assert!(
            v.is_finite() && *v <= b,
            "{who}: p95 of {} is {v} > {b}",
            ["north", "east", "down", "pitch", "heading"][k]
        );
    }
}

/// The last STATUS's `vehicle` object.
fn last_vehicle_status(msgs: &[Value]) -> Value {
    let st = of_class(msgs, "STATUS");
    st.last().expect("STATUS arrives")["vehicle"].clone()
}

#[test]
fn pymavlink_autopilot_gets_poses_within_bounds() {
    let py = python();
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    write_bare_log(&log, RATE_HZ, SECONDS);
    let (sub, dest) = subscriber();
    let port = free_port();
    let conn = format!("udpin:127.0.0.1:{port}");
    let cfg = Config::parse(&mavlink_config(&log, dest, &conn, ""), "t.toml", None).expect("valid");
    let script = common::root().join("tests/python/autopilot_replay.py");
    let args: Vec<std::ffi::OsString> = [
        log.display().to_string(),
        port.to_string(),
        HEADING_DEG.to_string(),
        BEACON_DEPTH_M.to_string(),
        WATER_C.to_string(),
        COVER_AFTER_S.to_string(),
        P95_AFTER_S.to_string(),
        "1.5".into(),
        "25".into(),
    ]
    .into_iter()
    .map(Into::into)
    .collect();
    // The stand-in first; the daemon once it says it is ready.
    let mut child = std::process::Command::new(&py)
        .arg(&script)
        .args(&args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("python runs");
    let mut out = std::io::BufReader::new(child.stdout.take().expect("stdout"));
    let mut ready = String::new();
    std::io::BufRead::read_line(&mut out, &mut ready).expect("a first line");
    let summary = run_in_process(cfg, Duration::from_secs(30))
        .join()
        .expect("daemon");
    let done = child.wait_with_output().expect("python ends");
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut out, &mut rest).expect("stdout");
    let err = String::from_utf8_lossy(&done.stderr);
    assert!(
        ready.contains("ready") && done.status.success(),
        "{ready}{err}"
    );
    assert!(summary.source_ended, "{summary:?}");
    let r: Value = serde_json::from_str(rest.lines().last().unwrap_or("")).expect("one JSON line");
    eprintln!("pymavlink stand-in: {r}");
    assert_eq!(
        (r["bad"].as_u64(), r["v1"].as_u64()),
        (Some(0), Some(0)),
        "{r}"
    );
    assert_eq!(r["covariance_finite"], true, "{r}");
    assert!(r["counts"]["HEARTBEAT"].as_u64() >= Some(1), "{r}");
    let (covered, frames) = (
        r["covered"].as_u64().unwrap_or(0),
        r["frames"].as_u64().unwrap_or(1),
    );
    assert!(covered * 10 >= frames * 8, "{covered} of {frames}: {r}");
    let p95: Vec<f64> = ["north", "east", "down", "pitch", "heading"]
        .iter()
        .map(|k| r["p95"][k].as_f64().unwrap_or(f64::NAN))
        .collect();
    // The daemon's own account of its readings, printed before the
    // judgement so that a failure shows what the estimator had.
    let all = collect(&sub, Duration::from_millis(100));
    let v = last_vehicle_status(&all);
    eprintln!("daemon's last STATUS, vehicle: {v}");
    check_p95(
        "pymavlink stand-in",
        [p95[0], p95[1], p95[2], p95[3], p95[4]],
    );
    let used = &v["mavlink"];
    assert!(
        v["readings"]["temperature"]["attached"]
            .as_u64()
            .unwrap_or(0)
            > 0,
        "{v}"
    );
    assert!(
        v["readings"]["depth"]["attached"].as_u64().unwrap_or(0) > 0,
        "{used}"
    );
}

#[test]
fn rust_stand_in_autopilot_gets_poses_within_bounds() {
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    let truth = write_bare_log(&log, RATE_HZ, SECONDS);
    let ap = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let (sub, dest) = subscriber();
    let port = free_port();
    let conn = format!("udpin:127.0.0.1:{port}");
    let rec = dir.path().join("rec");
    let extra = format!("[recording]\ndir = \"{}\"\n", rec.display());
    let cfg =
        Config::parse(&mavlink_config(&log, dest, &conn, &extra), "t.toml", None).expect("valid");
    let daemon = run_in_process(cfg, Duration::from_secs(30));
    let to = Some(([127, 0, 0, 1], port).into());
    let heard = stand_in(
        &ap,
        to,
        &truth,
        Duration::from_millis(1500),
        Duration::from_secs(20),
    );
    let summary = daemon.join().expect("daemon thread");
    assert!(summary.source_ended, "{summary:?}");
    assert_eq!((heard.not_v2, heard.bad), (0, 0), "{heard:?}");
    assert!(heard.heartbeats >= 1);
    assert!(heard
        .positions
        .iter()
        .all(|p| p.covariance.iter().all(|c| c.is_finite())));
    let (_, covered, frames) = judge(&heard.positions, &truth, COVER_AFTER_S);
    eprintln!("rust stand-in: {covered} of {frames} frames after the first second answered");
    assert!(covered * 10 >= frames * 8, "{covered} of {frames}");
    let (stats, _, _) = judge(&heard.positions, &truth, P95_AFTER_S);
    check_p95("rust stand-in", stats.p95());
    let msgs = collect(&sub, Duration::from_millis(100));
    let v = last_vehicle_status(&msgs);
    assert_eq!(v["enabled"], true, "{v}");
    assert!(
        v["readings"]["attitude"]["attached"].as_u64().unwrap_or(0) > 0,
        "{v}"
    );
    replay_sees_what_the_live_estimator_saw(&rec, &of_class(&msgs, "POSE"));
}

/// With `[mavlink.signing]` (a passphrase file beside the config) the
/// daemon signs everything it sends and takes only signed frames: an
/// autopilot signing with the same passphrase gets poses within the same
/// bounds and refuses none of the daemon's frames, and STATUS names the
/// key by its fingerprint.
#[test]
fn a_signed_link_carries_poses_both_ways() {
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    let truth = write_bare_log(&log, RATE_HZ, SECONDS);
    std::fs::write(dir.path().join("mav.pass"), "harbour trial\n").expect("key file");
    let ap = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let (sub, dest) = subscriber();
    let port = free_port();
    let conn = format!("udpin:127.0.0.1:{port}");
    let extra = "[mavlink.signing]\npassphrase_file = \"mav.pass\"\nlink_id = 2\n";
    let text = mavlink_config(&log, dest, &conn, extra);
    let cfg = Config::parse(&text, "t.toml", Some(dir.path())).expect("valid");
    let daemon = run_in_process(cfg, Duration::from_secs(30));
    let key = SigningKey::from_passphrase("harbour trial");
    let signing = SigningConfig {
        key: key.clone(),
        link_id: 0,
        allow_unsigned: false,
    };
    let to = Some(([127, 0, 0, 1], port).into());
    let (quiet, deadline) = (Duration::from_millis(1500), Duration::from_secs(20));
    let heard = stand_in_signed(&ap, to, &truth, quiet, deadline, Some(signing));
    let summary = daemon.join().expect("daemon thread");
    assert!(summary.source_ended, "{summary:?}");
    assert_eq!((heard.refused_signature, heard.bad), (0, 0), "{heard:?}");
    let (stats, covered, frames) = judge(&heard.positions, &truth, P95_AFTER_S);
    assert!(covered * 10 >= frames * 8, "{covered} of {frames}");
    check_p95("signed link", stats.p95());
    let v = last_vehicle_status(&collect(&sub, Duration::from_millis(100)));
    let m = &v["mavlink"];
    assert_eq!(m["signing"]["key"], key.fingerprint(), "{m}");
    assert_eq!(m["signing"]["link_id"], 2, "{m}");
    for why in ["unsigned", "bad_signature", "replayed"] {
        assert!(m["refused"].get(why).is_none(), "{m}");
    }
    assert!(
        v["readings"]["attitude"]["attached"].as_u64().unwrap_or(0) > 0,
        "{v}"
    );
}

/// The recording carries the readings the stand-in sent, and replaying it
/// (fast, no MAVLink) gives the poses the live daemon gave.
fn replay_sees_what_the_live_estimator_saw(rec: &std::path::Path, live: &[&Value]) {
    let files = common::run::files_in(rec);
    let [file] = &files[..] else {
        panic!("one recording: {files:?}")
    };
    let frames: Vec<_> = LogReader::open(file)
        .expect("log")
        .map(|f| f.expect("reads back"))
        .collect();
    let with = frames
        .iter()
        .filter(|f| f.attitude.is_some() && f.depth.is_some() && f.temp_c == Some(WATER_C))
        .count();
    assert!(
        with * 10 >= frames.len() * 9,
        "{with} of {} frames with all three",
        frames.len()
    );
    let (sub, dest) = subscriber();
    let text = format!(
        "rate_hz = 20.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{dest}\"]\n",
        common::root().join("config/calibration/tank.toml").display(),
        file.display()
    );
    let cfg = Config::parse(&text, "replay.toml", None).expect("valid");
    run_in_process(cfg, Duration::from_secs(30))
        .join()
        .expect("replay");
    let again = collect(&sub, Duration::from_millis(300));
    let again = of_class(&again, "POSE");
    assert_eq!(again.len(), live.len());
    // Bit for bit: the live path took each reading as the recording reads
    // it back (`core::log::as_logged`).
    for (a, b) in live.iter().zip(&again) {
        assert_eq!((&a["seq"], &a["status"]), (&b["seq"], &b["status"]));
        for k in ["x", "y", "z", "pitch", "yaw", "surge", "std"] {
            assert_eq!(a[k], b[k], "seq {}: {k}", a["seq"]);
        }
    }
}

fn attitude(pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        pitch,
        yaw,
        ..Default::default()
    })
}

/// Bad input of every kind, then a flood of 10 000 messages in one second
/// (a quarter broken CRCs, a quarter NaN attitudes, half valid), into a
/// running daemon on a 50 Hz simulated source: every frame is still
/// acquired, estimated and published, nothing panics, and STATUS counts
/// each refusal by its reason.
#[test]
fn bad_mavlink_input_costs_no_frame() {
    let (sub, dest) = subscriber();
    let port = free_port();
    let extra = format!(
        "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"udpin:127.0.0.1:{port}\"\n"
    );
    // The tracker: its poses are ok here, so they go out all through.
    let text = common::run::sim_config(50.0, &[dest], "loop = true", &extra)
        .replace("estimator = \"moments\"", "estimator = \"tracker\"");
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    // 4.5 s: the tracker's first `ok` pose comes once surge is known
    // (1.5 s in here), and poses after the flood must be more than a
    // second's worth.
    let daemon = run_in_process(cfg, Duration::from_millis(4500));
    let to = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let tx = UdpSocket::bind("127.0.0.1:0").expect("bind");
    std::thread::sleep(Duration::from_millis(500));
    // The autopilot's own framing (system 1, component 1), sequence 0, 1.
    let mut autopilot = Encoder::new(1, 1);
    let good = autopilot.encode(&attitude(0.1, 0.5)).to_vec();
    let mut bad_crc = good.clone();
    let n = bad_crc.len();
    bad_crc[n - 2] ^= 0x5A;
    let mut unknown = good.clone();
    unknown[7..10].copy_from_slice(&[0x77, 0x77, 0x07]);
    let nan = autopilot.encode(&attitude(f32::NAN, 0.5)).to_vec();
    // Its HEARTBEAT first: without `autopilot_system_id` nothing else is
    // taken before it tells who the autopilot is.
    let beat = Encoder::new(1, 1)
        .encode(&lightpose_vehicle::standin::autopilot_heartbeat())
        .to_vec();
    for _ in 0..3 {
        tx.send_to(&beat, to).expect("send");
    }
    for d in [&bad_crc, &unknown, &nan, &b"not mavlink at all".to_vec()] {
        for _ in 0..50 {
            tx.send_to(d, to).expect("send");
        }
    }
    // The flood: 100 datagrams every 10 ms for a second.
    let t0 = std::time::Instant::now();
    for k in 0..10_000usize {
        let d = match k % 4 {
            0 => &bad_crc,
            1 => &nan,
            _ => &good,
        };
        let _ = tx.send_to(d, to);
        if k % 100 == 99 {
            let due = t0 + Duration::from_millis(10 * (k as u64 + 1) / 100);
            std::thread::sleep(due.saturating_duration_since(std::time::Instant::now()));
        }
    }
    let msgs = collect(&sub, Duration::from_millis(4200));
    let summary = daemon.join().expect("the daemon ends without panic");
    let poses = of_class(&msgs, "POSE").len() as u64;
    let status = of_class(&msgs, "STATUS");
    let last = status.last().expect("STATUS");
    eprintln!("{summary:?}; {poses} POSE; vehicle {}", last["vehicle"]);
    // 4.5 s at 50 Hz: every frame acquired, none lost or failed, each
    // published; STATUS every 0.2 s never saw the rate halve.
    assert!(summary.frames >= 150, "{summary:?}");
    assert_eq!((summary.lost, summary.failed), (0, 0), "{summary:?}");
    assert!(poses + 5 >= summary.frames, "{poses} POSE for {summary:?}");
    let slow: Vec<f64> = status[1..status.len().saturating_sub(1)]
        .iter()
        .filter_map(|s| s["fps"].as_f64())
        .filter(|f| *f < 25.0)
        .collect();
    assert!(slow.is_empty(), "fps fell to {slow:?}");
    let m = &last["vehicle"]["mavlink"];
    let refused = |k: &str| m["refused"][k].as_u64().unwrap_or(0);
    assert!(refused("bad_crc") >= 50, "{m}");
    assert!(refused("unknown_message") >= 50, "{m}");
    assert!(refused("not_finite") >= 50, "{m}");
    assert!(m["garbage_bytes"].as_u64() > Some(0), "{m}");
    // Most of the flood reached the socket and was accounted for.
    let accounted =
        refused("bad_crc") + refused("not_finite") + m["used"]["attitude"].as_u64().unwrap_or(0);
    assert!(accounted >= 9_000, "{accounted} of the flood counted: {m}");
    assert!(last["vehicle"]["readings"]["attitude"]["attached"].as_u64() > Some(0));
    // Poses went out to the autopilot (the sender of the flood): more than
    // a second's worth. (The flood's attitude is not the simulated
    // vehicle's, so the tracker may call its poses diverged after it, and
    // before the first datagram a udpin link has no one to send to.)
    let sent = m["sent"]["vision_position_estimate"].as_u64().unwrap_or(0);
    let queued = last["vehicle"]["outbox"]["queued"].as_u64().unwrap_or(0);
    assert!(
        sent >= 50 && sent <= queued,
        "{sent} sent, {queued} queued: {m}"
    );
    // STATUS names the autopilot, learned from its HEARTBEAT, and the peer.
    assert_eq!(m["autopilot"]["system"], 1, "{m}");
    assert_eq!(m["autopilot"]["configured"], false, "{m}");
    assert_eq!(m["peer"], tx.local_addr().expect("addr").to_string(), "{m}");
    assert_eq!(m["peer_changes"], 0, "{m}");
}

/// The binary with `cfg_text`: its exit code and stderr.
fn start_binary(dir: &std::path::Path, cfg_text: &str) -> (Option<i32>, String) {
    let cfg = dir.join("lightposed.toml");
    std::fs::write(&cfg, cfg_text).expect("write config");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run lightposed");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).trim().to_string(),
    )
}

/// A port that is taken or a serial device that is not there stops the
/// start with exit 1 (a restart may help); a value that cannot be is
/// exit 2 (it cannot). Each is one line on stderr.
#[test]
fn a_link_that_cannot_open_is_exit_1_a_bad_value_exit_2() {
    let dir = tempfile::tempdir().expect("tmp");
    let (_sub, dest) = subscriber();
    let held = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let taken = held.local_addr().expect("addr");
    let held_tcp = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let taken_tcp = held_tcp.local_addr().expect("addr");
    let with = |conn: &str| {
        let extra = format!(
            "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"{conn}\"\n"
        );
        // The tracker: [mavlink] refuses an estimator without a std.
        common::run::sim_config(20.0, &[dest], "", &extra)
            .replace("estimator = \"moments\"", "estimator = \"tracker\"")
    };
    for (conn, code, says) in [
        (format!("udpin:{taken}"), 1, "mavlink: udpin:"),
        (format!("tcpin:{taken_tcp}"), 1, "mavlink: tcpin:"),
        // Issue 44: unsigned on every address is a decision.
        (
            "udpin:0.0.0.0:14961".into(),
            2,
            "mavlink.connection: udpin:0.0.0.0:14961 listens on 0.0.0.0:14961, not a loopback address, without signing",
        ),
        (
            "serial:/dev/lightpose-no-such-tty:115200".into(),
            1,
            "mavlink: serial:/dev/lightpose-no-such-tty:115200: cannot open",
        ),
        (
            "udpin:127.0.0.1:0".into(),
            2,
            "mavlink.connection: udpin:127.0.0.1:0: port 0",
        ),
        (
            "tcp:127.0.0.1:14550".into(),
            2,
            "mavlink.connection: unknown transport",
        ),
    ] {
        let (got, err) = start_binary(dir.path(), &with(&conn));
        assert_eq!(got, Some(code), "{conn}: {err}");
        let last = err.lines().last().unwrap_or("");
        assert!(last.contains(says), "{conn}: {err}");
    }
}

/// SIGHUP reloads the calibration with the link up: the link is neither
/// reopened nor stopped (heartbeats and poses go on), and SIGTERM ends
/// the daemon and its link with exit 0.
#[test]
fn sighup_keeps_the_link_and_sigterm_ends_it() {
    use common::run::{signal, spawn_daemon, wait_exit};
    use nix::sys::signal::Signal;
    let dir = tempfile::tempdir().expect("tmp");
    let (sub, dest) = subscriber();
    let ap = UdpSocket::bind("127.0.0.1:0").expect("bind");
    ap.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let extra = format!(
        "[site]\nbeacon_heading_deg = 30.0\nbeacon_depth_m = 3.0\n[mavlink]\nconnection = \"udpout:{}\"\n",
        ap.local_addr().expect("addr")
    );
    let text = common::run::sim_config(20.0, &[dest], "", &extra)
        .replace("estimator = \"moments\"", "estimator = \"tracker\"");
    let (cal, text, good) = common::calibration_copy(dir.path(), &text);
    let (mut child, _) = spawn_daemon(dir.path(), &text, &sub);
    std::fs::write(&cal, common::other_calibration(&good)).expect("another calibration");
    signal(&child, Signal::SIGHUP);
    let msgs = collect(&sub, Duration::from_millis(800));
    let mut buf = [0u8; 2048];
    let (t0, mut after) = (std::time::Instant::now(), 0);
    while t0.elapsed() < Duration::from_millis(1500) {
        if let Ok(n) = ap.recv(&mut buf) {
            after += usize::from(n > 0 && buf[0] == 0xFD);
        }
    }
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(status.code(), Some(0), "SIGTERM exits 0");
    let st = of_class(&msgs, "STATUS");
    let last = st.last().expect("STATUS");
    assert_eq!(last["estimator"]["reloads"], 1, "{}", last["estimator"]);
    assert_eq!(
        last["vehicle"]["mavlink"]["link_opens"], 1,
        "{}",
        last["vehicle"]
    );
    assert!(after >= 1, "MAVLink 2 frames after the reload: {after}");
}

/// Audit: an autopilot away for a minute (its heartbeat age growing, every
/// send refused by ICMP) left STATUS counting and the journal silent. Now
/// its silence is told once, its return once, and the send errors by the
/// rule for repeated lines (the real binary's log).
#[test]
fn an_autopilot_away_and_back_is_told() {
    use common::run::{signal, spawn_daemon_to, wait_exit};
    let dir = tempfile::tempdir().expect("tmp");
    let log = dir.path().join("bare.jsonl");
    let truth = common::vehicle::write_bare_log(&log, 10.0, 30.0);
    let port = common::vehicle::free_port();
    let (sub, dest) = subscriber();
    let text = common::vehicle::mavlink_config(&log, dest, &format!("udpout:127.0.0.1:{port}"), "");
    let err = dir.path().join("stderr");
    let file = std::fs::File::create(&err).expect("stderr file");
    let (mut child, _) = spawn_daemon_to(dir.path(), &text, &sub, file.into());
    // Nobody at the port for 4 s: sends refused, no heartbeat heard.
    std::thread::sleep(Duration::from_secs(4));
    let sock = UdpSocket::bind(("127.0.0.1", port)).expect("the autopilot's port");
    let heard = common::vehicle::stand_in(
        &sock,
        None,
        &truth,
        Duration::from_millis(1500),
        Duration::from_secs(3),
    );
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    assert!(wait_exit(&mut child, Duration::from_secs(5)).success());
    let text = std::fs::read_to_string(&err).expect("stderr");
    let count = |s: &str| text.lines().filter(|l| l.contains(s)).count();
    assert!(heard.heartbeats >= 1, "the stand-in heard the daemon");
    assert_eq!(count("no HEARTBEAT from the autopilot"), 1, "{text}");
    assert_eq!(count("HEARTBEAT is back"), 1, "{text}");
    let sends = count("mavlink: send failed");
    assert!((1..=3).contains(&sends), "{sends} lines: {text}");
}
