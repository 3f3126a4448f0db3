//! End-to-end tests of lightposed: the simulator backend on loopback, real
//! UDP sockets, the real binary where signals and exit codes matter, and a
//! Python standard-library subscriber as a client that is not ours. Each
//! runs a few seconds at most (high frame rates).

mod common;
use common::run::{run_in_process, run_to_end, signal, spawn_daemon, wait_exit, Systemd};
use common::{read_logs, root, shipped, subscriber};

use lightpose_core::LogReader;
use lightposed::Config;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A config for the simulated tank at `rate` Hz sending to `dests`, plus
/// `extra` TOML appended (tables).
fn sim_config(rate: f64, dests: &[SocketAddr], backend_extra: &str, extra: &str) -> String {
    let (scene, _, _) = shipped();
    sim_config_for("moments", &scene, rate, dests, backend_extra, extra)
}

/// [`sim_config`] with another estimator and scene.
fn sim_config_for(
    estimator: &str,
    scene: &std::path::Path,
    rate: f64,
    dests: &[SocketAddr],
    backend_extra: &str,
    extra: &str,
) -> String {
    let (_, traj, cal) = shipped();
    let d: Vec<String> = dests.iter().map(|d| format!("\"{d}\"")).collect();
    format!(
        r#"rate_hz = {rate}
estimator = "{estimator}"
calibration = "{}"
[backend]
kind = "sim"
scene = "{}"
trajectory = "{}"
{backend_extra}
[outputs]
destinations = [{}]
status_interval_s = 1.0
{extra}
"#,
        cal.display(),
        scene.display(),
        traj.display(),
        d.join(", ")
    )
}

/// Every datagram that arrives within `d`, each with its arrival time.
fn collect(s: &UdpSocket, d: Duration) -> Vec<(Instant, Value)> {
    let mut out = Vec::new();
    let mut buf = vec![0u8; 65536];
    let end = Instant::now() + d;
    while Instant::now() < end {
        if let Ok(n) = s.recv(&mut buf) {
            let v: Value =
                serde_json::from_slice(&buf[..n]).expect("every datagram is one JSON object");
            out.push((Instant::now(), v));
        }
    }
    out
}

fn of_class<'a>(msgs: &'a [(Instant, Value)], class: &str) -> Vec<&'a (Instant, Value)> {
    msgs.iter().filter(|(_, v)| v["class"] == class).collect()
}

fn assert_pose_fields(v: &Value) {
    for k in [
        "class", "seq", "t", "time", "status", "x", "y", "z", "pitch", "yaw", "surge",
    ] {
        assert!(v.get(k).is_some(), "POSE lacks {k}: {v}");
    }
    assert!(v["seq"].is_u64());
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    let time = v["time"].as_f64().expect("time is a number");
    assert!(
        (now - time).abs() < 10.0,
        "time {time} is not the wall clock {now}"
    );
    if v["status"] == "ok" {
        let x = v["x"].as_f64().expect("ok pose has x");
        assert!((2.0..12.0).contains(&x), "x = {x} outside the tank: {v}");
        assert!(v["pitch"].as_f64().is_some_and(|p| p.abs() < 45.0), "{v}");
    }
}

#[test]
fn pose_at_the_configured_rate_and_status_every_second() {
    let (sub, addr) = subscriber();
    let text = sim_config(100.0, &[addr], "", "");
    let cfg = Config::parse(&text, "test.toml", None).expect("valid config");
    let h = run_in_process(cfg, Duration::from_millis(2600));
    let msgs = collect(&sub, Duration::from_millis(2900));
    let summary = h.join().expect("daemon thread");

    let version = of_class(&msgs, "VERSION");
    assert_eq!(version.len(), 1, "one VERSION at start");
    assert_eq!(version[0].1["name"], "lightposed");
    assert_eq!(msgs[0].1["class"], "VERSION", "VERSION comes first");

    let poses = of_class(&msgs, "POSE");
    // 2.6 s at 100 Hz: 260 frames, give or take start-up.
    assert!(
        (220..=275).contains(&poses.len()),
        "{} POSE datagrams",
        poses.len()
    );
    for (_, v) in &poses {
        assert_pose_fields(v);
    }
    let seqs: Vec<u64> = poses
        .iter()
        .filter_map(|(_, v)| v["seq"].as_u64())
        .collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "consecutive seq");
    // Status words are the estimator's business; here: known words, and
    // some poses fully known.
    let words = [
        "ok",
        "no_light",
        "saturated",
        "out_of_range",
        "initialising",
        "bad_frame",
        "diverged",
    ];
    assert!(poses
        .iter()
        .all(|(_, v)| words.iter().any(|w| v["status"] == *w)));
    let ok = poses.iter().filter(|(_, v)| v["status"] == "ok").count();
    assert!(ok > 0, "no pose is ok");
    // Measured rate between first and last POSE.
    let span = poses.last().unwrap().0 - poses[0].0;
    let rate = (poses.len() - 1) as f64 / span.as_secs_f64();
    assert!((85.0..115.0).contains(&rate), "POSE rate {rate:.1} Hz");

    let status = of_class(&msgs, "STATUS");
    // Ticks at 0, 1, 2 s and a last one at stop.
    assert!(status.len() >= 3, "{} STATUS", status.len());
    for w in status.windows(2).take(2) {
        let gap = (w[1].0 - w[0].0).as_secs_f64();
        assert!((0.8..1.2).contains(&gap), "STATUS gap {gap:.3} s");
    }
    let last = &status.last().unwrap().1;
    for k in [
        "seq",
        "t",
        "uptime",
        "frames",
        "late",
        "failed",
        "backend",
        "estimator",
        "temperature",
        "recording",
        "outputs",
    ] {
        assert!(last.get(k).is_some(), "STATUS lacks {k}: {last}");
    }
    assert_eq!(last["backend"]["kind"], "sim");
    assert_eq!(last["temperature"]["source"], "frame");
    assert_eq!(last["recording"]["state"], "off");
    assert_eq!(last["failed"], 0);
    assert!(
        last["latency"]["p99"].as_f64().is_some_and(|p| p < 0.05),
        "{last}"
    );
    assert_eq!(summary.frames, last["frames"].as_u64().unwrap());
    assert_eq!(last["outputs"][0]["errors"], 0);
}

#[test]
fn python_stdlib_subscriber_reads_the_stream() {
    let script = root().join("tests/python/subscriber.py");
    let mut child = match Command::new("python3")
        .arg(&script)
        .args(["--seconds", "2.5"])
        .stdout(Stdio::piped())
        .spawn()
    {
        Ok(c) => c,
        Err(e) => {
            eprintln!("skipped: cannot run python3: {e}");
            return;
        }
    };
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let mut line = String::new();
    out.read_line(&mut line).expect("port line");
    let port: u16 = line.trim().parse().expect("python prints its port first");
    let text = sim_config(
        100.0,
        &[SocketAddr::from((Ipv4Addr::LOCALHOST, port))],
        "",
        "",
    );
    let cfg = Config::parse(&text, "test.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(2200));
    line.clear();
    out.read_line(&mut line).expect("summary line");
    let status = child.wait().expect("python exits");
    h.join().expect("daemon");
    let v: Value = serde_json::from_str(&line).expect("python prints JSON");
    assert!(status.success(), "python subscriber found problems: {v}");
    assert_eq!(v["problems"].as_array().map(|a| a.len()), Some(0), "{v}");
    assert!(v["counts"]["POSE"].as_u64().unwrap_or(0) > 150, "{v}");
    assert!(v["counts"]["STATUS"].as_u64().unwrap_or(0) >= 2, "{v}");
    assert_eq!(v["counts"]["VERSION"], 1, "{v}");
    assert_eq!(v["seq_increasing"], true);
    assert!(v["ok_poses"].as_u64().unwrap_or(0) > 0, "{v}");
}

#[test]
fn multicast_on_loopback() {
    let group = Ipv4Addr::new(239, 255, 71, 50);
    let rx = match UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("skipped: cannot bind: {e}");
            return;
        }
    };
    let port = rx.local_addr().expect("addr").port();
    if let Err(e) = rx.join_multicast_v4(&group, &Ipv4Addr::LOCALHOST) {
        eprintln!("skipped: this machine refuses to join {group} on lo: {e}");
        return;
    }
    rx.set_read_timeout(Some(Duration::from_millis(100)))
        .expect("timeout");
    // Probe with a plain socket first: some sandboxes drop multicast on lo.
    let probe = UdpSocket::bind("127.0.0.1:0").expect("probe socket");
    let _ = probe.set_multicast_loop_v4(true);
    let sent = probe.send_to(b"{\"class\":\"PROBE\",\"seq\":0,\"t\":0}", (group, port));
    let mut buf = [0u8; 256];
    if sent.is_err() || rx.recv(&mut buf).is_err() {
        eprintln!("skipped: multicast is not delivered on loopback here ({sent:?})");
        return;
    }
    let extra = format!(
        "[outputs.multicast]\ngroup = \"{group}:{port}\"\nttl = 0\ninterface = \"127.0.0.1\"\nloopback = true\n"
    );
    let text = sim_config(100.0, &[], "", &extra);
    let cfg = Config::parse(&text, "test.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1300));
    let msgs = collect(&rx, Duration::from_millis(1500));
    h.join().expect("daemon");
    let poses = of_class(&msgs, "POSE");
    assert!(poses.len() > 80, "{} POSE by multicast", poses.len());
    assert!(!of_class(&msgs, "STATUS").is_empty());
    assert_eq!(
        of_class(&msgs, "STATUS")[0].1["outputs"][0]["multicast"],
        true
    );
}

#[test]
fn record_then_replay_gives_the_same_poses() {
    let (scene, _, _) = shipped();
    live_then_replay("moments", &scene);
}

/// With the vehicle's three sensors on every frame: the attitude is
/// written in degrees and read back in radians, a round trip that moved
/// 79 of 81 poses in their last bits before the live path took it.
#[test]
fn record_then_replay_gives_the_same_poses_with_own_sensors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("sensors.toml");
    let text = std::fs::read_to_string(root().join("config/scenes/tank-ahrs.toml")).unwrap();
    std::fs::write(&scene, text + "\n[depth]\n\n[dvl]\n").unwrap();
    live_then_replay("tracker", &scene);
}

/// STATUS `attitude.enabled` says whether the frames have an attitude,
/// from anywhere: the simulated AHRS of the default scene without the UDP
/// input (`input` false) is enabled; the tank without one is not. (An
/// audit read `enabled: false` while the scene's attitude was used.)
#[test]
fn status_says_the_frames_have_an_attitude_from_the_backend() {
    for (scene, with) in [("tank-ahrs.toml", true), ("tank.toml", false)] {
        let (sub, addr) = subscriber();
        let scene = root().join("config/scenes").join(scene);
        let text = sim_config_for("tracker", &scene, 50.0, &[addr], "", "");
        let cfg = Config::parse(&text, "t.toml", None).expect("valid");
        let h = run_in_process(cfg, Duration::from_millis(800));
        let msgs = collect(&sub, Duration::from_millis(1200));
        h.join().expect("daemon");
        let st = &of_class(&msgs, "STATUS").last().expect("STATUS").1;
        let att = &st["attitude"];
        assert_eq!(att["enabled"], with, "{}: {att}", scene.display());
        assert_eq!(att["input"], false, "{att}");
        let n = att["frames_with"].as_u64().expect("frames_with");
        assert_eq!(n > 0, with, "{att}");
    }
}

/// The whole zigzag live, recorded, then replayed: the same POSE messages.
/// Both runs record MCAP, which keeps every POSE: the comparison is of all
/// 401, which UDP at pace "fast" cannot promise on a loaded machine (346
/// of 401 datagrams arrived once while four builds ran). The datagrams
/// that did arrive must be those poses too.
fn live_then_replay(estimator: &str, scene: &std::path::Path) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (rec, rec2) = (dir.path().join("rec"), dir.path().join("rec2"));
    let recording = |d: &std::path::Path| {
        format!(
            "[recording]\ndir = \"{}\"\nformat = \"mcap\"\n",
            d.display()
        )
    };
    // Live: the whole zigzag (8 s) at 50 Hz, as fast as possible, recorded.
    let (sub, addr) = subscriber();
    let _ = socket2::SockRef::from(&sub).set_recv_buffer_size(8 << 20);
    let backend = "pace = \"fast\"\nloop = false";
    let text = sim_config_for(estimator, scene, 50.0, &[addr], backend, &recording(&rec));
    let cfg = Config::parse(&text, "live.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_secs(20));
    let live = collect(&sub, Duration::from_millis(1500));
    let s = h.join().expect("daemon");
    assert!(s.source_ended, "a non-looping sim ends");
    assert_eq!(s.frames, 401);
    assert_eq!(s.recorded, 401);

    let logs = files_of(&rec);
    assert_eq!(logs.len(), 1, "{logs:?}");
    let replay_text = format!(
        "rate_hz = 50.0\nestimator = \"{estimator}\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\n{}",
        root().join("config/calibration/tank.toml").display(),
        logs[0].display(),
        recording(&rec2),
    );
    let cfg = Config::parse(&replay_text, "replay.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_secs(20));
    let replayed = collect(&sub, Duration::from_millis(1500));
    let s2 = h.join().expect("daemon");
    assert!(s2.source_ended);
    assert_eq!(s2.frames, 401);
    assert_eq!(s2.recorded, 401);

    let a = recorded_poses(&logs[0]);
    let replay_logs = files_of(&rec2);
    assert_eq!(replay_logs.len(), 1, "{replay_logs:?}");
    let b = recorded_poses(&replay_logs[0]);
    assert_eq!(a.len(), 401, "every live pose recorded");
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "the same seqs"
    );
    for (k, v) in &a {
        assert_eq!(v, &b[k], "pose {k} differs between live and replay");
    }
    // What UDP delivered is what was recorded, in either run.
    let mut heard = 0;
    for msgs in [&live, &replayed] {
        for (_, v) in of_class(msgs, "POSE") {
            let seq = v["seq"].as_u64().expect("seq");
            assert_eq!(without_time(v), a[&seq], "POSE datagram {seq}");
            heard += 1;
        }
    }
    // Some arrive even on a loaded machine; every one that does is checked.
    assert!(heard >= 100, "{heard} POSE datagrams of 802");
}

/// A POSE object without its `time` (the wall clock of the run).
fn without_time(v: &Value) -> Value {
    let mut v = v.clone();
    if let Some(o) = v.as_object_mut() {
        o.remove("time");
    }
    v
}

/// The recordings in `dir`, by name.
fn files_of(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("recorded")
        .map(|e| e.expect("entry").path())
        .collect();
    logs.sort();
    logs
}

/// Every POSE message of an MCAP recording, by seq, without `time`.
fn recorded_poses(log: &std::path::Path) -> std::collections::BTreeMap<u64, Value> {
    let bytes = std::fs::read(log).expect("recording");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a whole message"))
        .filter(|m| m.channel.topic == lightpose_logs::schema::topic::POSE)
        .map(|m| {
            let v: Value = serde_json::from_slice(&m.data).expect("POSE is JSON");
            (v["seq"].as_u64().expect("seq"), without_time(&v))
        })
        .collect()
}

#[test]
fn refusing_disk_is_reported_and_publishing_goes_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("not-a-dir");
    std::fs::write(&file, b"x").expect("write");
    let (sub, addr) = subscriber();
    let extra = format!("[recording]\ndir = \"{}\"\n", file.join("rec").display());
    let text = sim_config(100.0, &[addr], "", &extra);
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1300));
    let msgs = collect(&sub, Duration::from_millis(1500));
    h.join().expect("daemon");
    assert!(of_class(&msgs, "POSE").len() > 100);
    let st = &of_class(&msgs, "STATUS").last().expect("a STATUS").1;
    assert_eq!(st["recording"]["state"], "error", "{st}");
    assert!(
        st["recording"]["error"]
            .as_str()
            .unwrap_or("")
            .contains("not-a-dir"),
        "{st}"
    );
    assert!(
        st["recording"]["failed"].as_u64().unwrap_or(0) > 100,
        "{st}"
    );
}

#[test]
fn attitude_readings_ride_with_frames_and_are_recorded() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let port = UdpSocket::bind("127.0.0.1:0")
        .expect("free port")
        .local_addr()
        .expect("addr")
        .port();
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\n[attitude]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\nbeacon_axis_heading_deg = 90.0\nmax_age_s = 0.5\n",
        rec.display()
    );
    let text = sim_config(100.0, &[addr], "", &extra);
    let cfg = Config::parse(&text, "t.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1400));
    let ahrs = UdpSocket::bind("127.0.0.1:0").expect("ahrs");
    let t0 = Instant::now();
    // Heading 280° with the beam to the east (90°): yaw 10° in B.
    while t0.elapsed() < Duration::from_millis(1000) {
        let _ = ahrs.send_to(
            br#"{"class":"ATTITUDE","t":1.0,"pitch":4.0,"yaw":280.0}"#,
            ("127.0.0.1", port),
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let msgs = collect(&sub, Duration::from_millis(600));
    h.join().expect("daemon");
    let st = &of_class(&msgs, "STATUS").last().expect("STATUS").1;
    assert!(
        st["attitude"]["frames_with"].as_u64().unwrap_or(0) > 50,
        "{st}"
    );
    let log = std::fs::read_dir(&rec)
        .expect("rec")
        .next()
        .expect("a log")
        .expect("entry")
        .path();
    let with: Vec<_> = LogReader::open(&log)
        .expect("log")
        .filter_map(|f| f.ok().and_then(|f| f.attitude))
        .collect();
    assert!(
        with.len() > 50,
        "{} recorded frames with attitude",
        with.len()
    );
    assert!((with[0].yaw.deg() - 10.0).abs() < 1e-9 && (with[0].pitch.deg() - 4.0).abs() < 1e-9);
}

// ---- the real binary -------------------------------------------------------

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_lightposed"))
}

#[test]
fn sigterm_exits_0_with_recording_complete_and_a_sighup_keeps_the_track() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\nrotate_mb = 0.05\n",
        rec.display()
    );
    let text = sim_config(200.0, &[addr], "", &extra);
    let (mut child, _) = spawn_daemon(dir.path(), &text, &sub);
    signal(&child, nix::sys::signal::Signal::SIGHUP);
    // Run until STATUS shows the log has rotated (the daemon's own word,
    // not a guess at how fast a loaded machine goes), then stop it.
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut msgs = Vec::new();
    let rotated = |m: &[(Instant, Value)]| {
        of_class(m, "STATUS")
            .last()
            .and_then(|(_, v)| v["recording"]["files"].as_u64())
            .is_some_and(|n| n > 1)
    };
    while !rotated(&msgs) && Instant::now() < deadline {
        msgs.extend(collect(&sub, Duration::from_millis(300)));
    }
    let reloads = of_class(&msgs, "STATUS")
        .last()
        .map(|(_, v)| v["estimator"]["reloads"].as_u64().unwrap_or(0));
    // The calibration is the running one: nothing is replaced, the track
    // is kept (a reload of another is tests/reload.rs's).
    assert_eq!(reloads, Some(0), "SIGHUP with the running calibration");
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(status.code(), Some(0), "SIGTERM exits 0");
    let last_status = collect(&sub, Duration::from_millis(300));
    let fin = of_class(&last_status, "STATUS");
    let fin = &fin.last().expect("a final STATUS at stop").1;
    let (seqs, cut) = read_logs(&rec);
    assert!(!cut, "a clean stop leaves no cut line");
    assert!(!seqs.is_empty(), "frames recorded");
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "recorded seq contiguous"
    );
    assert_eq!(
        seqs.len() as u64,
        fin["frames"].as_u64().unwrap(),
        "every published frame recorded"
    );
    assert!(
        fin["recording"]["files"].as_u64().unwrap() > 1,
        "rotated by size: {fin}"
    );
}

#[test]
fn kill_9_leaves_a_log_complete_to_its_last_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, addr) = subscriber();
    let extra = format!("[recording]\ndir = \"{}\"\n", rec.display());
    let text = sim_config(500.0, &[addr], "", &extra);
    let (mut child, _) = spawn_daemon(dir.path(), &text, &sub);
    std::thread::sleep(Duration::from_millis(600));
    signal(&child, nix::sys::signal::Signal::SIGKILL);
    wait_exit(&mut child, Duration::from_secs(5));
    let (seqs, _cut) = read_logs(&rec);
    assert!(seqs.len() > 100, "{} frames", seqs.len());
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1));
}

#[test]
fn bad_config_exits_nonzero_with_one_clear_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "rate_hz = 5.0\ncalibration = \"c.toml\"\n[backend]\nkind = \"sim\"\n[outputs]\ndestinations = [\"127.0.0.1\"]\n")
        .expect("write");
    for flag in ["--config", "--check-config"] {
        let out = bin().arg(flag).arg(&bad).output().expect("run");
        assert_eq!(out.status.code(), Some(2), "{flag}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.lines().count(), 1, "one line: {err}");
        assert!(err.contains("bad.toml:6: outputs.destinations:"), "{err}");
    }
    let out = bin()
        .arg("--config")
        .arg(dir.path().join("none.toml"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("none.toml"));
}

#[test]
fn shipped_configs_validate_and_version_prints() {
    let out = bin().arg("--version").output().expect("run");
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("lightposed "));
    let mut files = vec![root().join("config/lightposed.toml")];
    if let Ok(rd) = std::fs::read_dir(root().join("config/examples")) {
        files.extend(
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "toml")),
        );
    }
    // --check-config reads every file a start would: the examples that
    // name files of a deployed system (/etc/lightpose/, /var/lib/lightposed/)
    // are refused for that file alone; everything else in them validates.
    for f in files {
        let out = bin().arg("--check-config").arg(&f).output().expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        let deployed = ["/etc/lightpose/", "/var/lib/lightposed/"];
        let only_deployed = out.status.code() == Some(2)
            && deployed.iter().any(|d| err.contains(d))
            && err.contains("No such file");
        assert!(
            out.status.success() || only_deployed,
            "{}: {err}",
            f.display()
        );
        Config::load(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
    }
    for ok in ["lightposed.toml", "examples/sim.toml", "examples/mock.toml"] {
        let out = bin()
            .arg("--check-config")
            .arg(root().join("config").join(ok))
            .output()
            .expect("run");
        assert!(
            out.status.success(),
            "{ok}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// Each shipped example with `[mavlink]` added: `--check-config` passes
/// with the estimator it ships (the one a vehicle should run: the tracker,
/// which gives a std with every `ok` pose), and refuses, at the estimator's
/// line, the paper's moments, which give none, so that no
/// VISION_POSITION_ESTIMATE would ever be sent (an audit found every
/// board example so, `--check-config` saying ok).
#[test]
fn a_configuration_that_could_never_send_the_autopilot_a_pose_is_refused() {
    let examples = root().join("config/examples");
    for name in ["mcp3008", "ads1115", "ads7828", "serial", "sim"] {
        let text = std::fs::read_to_string(examples.join(format!("{name}.toml"))).expect("read");
        let est: toml::Table = toml::from_str(&text).expect("toml");
        let est = est.get("estimator").and_then(|v| v.as_str());
        assert!(
            matches!(est, Some("auto" | "tracker")),
            "{name}.toml ships estimator {est:?}"
        );
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let sim = std::fs::read_to_string(examples.join("sim.toml")).expect("read sim.toml");
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    // sim.toml's paths are relative to its own folder; the copy's are made
    // absolute so that it checks from the test's own folder.
    let config = root().join("config");
    let sim = sim.replace("\"../", &format!("\"{}/", config.display()));
    let at = |text: &str| {
        let f = dir.path().join("with-mavlink.toml");
        std::fs::write(&f, text).expect("write");
        bin().arg("--check-config").arg(&f).output().expect("run")
    };
    let with_mavlink = format!(
        "{sim}\n[site]\nbeacon_heading_deg = 0.0\nbeacon_depth_m = 5.0\n[mavlink]\nconnection = \"udpout:127.0.0.1:{port}\"\n"
    );
    let out = at(&with_mavlink);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let moments = with_mavlink.replace("estimator = \"auto\"", "estimator = \"moments\"");
    assert_ne!(moments, with_mavlink, "sim.toml names its estimator");
    let out = at(&moments);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(
        err.contains(": estimator: ")
            && err.contains("\"moments\" gives no std")
            && err.contains("VISION_POSITION_ESTIMATE"),
        "{err}"
    );
    // Told to assume a std, it sends: not refused.
    let assume = format!("{moments}missing_std = \"assume\"\n");
    let out = at(&assume);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn embedded_default_runs_from_anywhere() {
    // The default publishes to 127.0.0.1:17150; run it briefly from /
    // and check it starts and says where it publishes.
    let mut child = bin()
        .current_dir("/")
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut err = BufReader::new(child.stderr.take().expect("stderr"));
    let mut first = String::new();
    err.read_line(&mut first).expect("first log line");
    std::thread::sleep(Duration::from_millis(300));
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    let st = wait_exit(&mut child, Duration::from_secs(5));
    assert!(
        first.contains("127.0.0.1:17150") && first.contains("listen with"),
        "{first}"
    );
    assert_eq!(st.code(), Some(0));
}

#[test]
fn failed_and_dropped_frames_are_counted_not_hidden() {
    // hal's mock backend with injected bus errors and dropped frames.
    let (scene, traj, cal) = shipped();
    let (sub, addr) = subscriber();
    let text = format!(
        r#"rate_hz = 200.0
estimator = "moments"
# A loaded CI machine oversleeps by milliseconds: what is tested is that
# a drop or a failure does not make the frames after it late.
late_tolerance = 4.0
calibration = "{}"
[backend]
kind = "mock"
scene = "{}"
trajectory = "{}"
faults = {{ bus_error_every = 10, drop_every = 15 }}
[outputs]
destinations = ["{addr}"]
"#,
        cal.display(),
        scene.display(),
        traj.display()
    );
    let cfg = Config::parse(&text, "mock.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_millis(1300));
    let msgs = collect(&sub, Duration::from_millis(1500));
    let s = h.join().expect("daemon");
    assert!(s.failed > 5, "{s:?}");
    assert!(s.lost > 5, "{s:?}");
    // seq s is dropped when (s+1) % 15 == 0, fails when (s+1) % 10 == 0
    // (and not dropped): about as many of each. lost counts only the drops,
    // not the failures a second time.
    let ratio = s.lost as f64 / s.failed as f64;
    assert!((0.6..1.6).contains(&ratio), "lost/failed = {ratio}: {s:?}");
    // A frame after a drop or failure is judged by its own slot: not late.
    assert!(s.late * 10 < s.frames, "{s:?}");
    assert!(of_class(&msgs, "POSE").len() > 100, "publishing goes on");
    let st = &of_class(&msgs, "STATUS").last().expect("STATUS").1;
    assert_eq!(st["failed"].as_u64(), Some(s.failed), "{st}");
    assert_eq!(st["lost"].as_u64(), Some(s.lost), "{st}");
    assert!(
        st["backend"]["last_error"]
            .as_str()
            .is_some_and(|e| !e.is_empty()),
        "{st}"
    );
    assert!(
        st["backend"]["health"]["injected_faults"]
            .as_u64()
            .unwrap_or(0)
            > 10,
        "{st}"
    );
}

#[test]
fn tells_systemd_ready_status_and_watchdog() {
    let dir = tempfile::tempdir().expect("tempdir");
    let systemd = Systemd::new(dir.path());
    let (sub, addr) = subscriber();
    let text = sim_config(50.0, &[addr], "", "");
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, text).expect("write");
    let mut child = systemd
        .command(&cfg, 1_000_000)
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let got: String = systemd
        .listen(Duration::from_millis(2500))
        .into_iter()
        .map(|(_, said)| said + "\n")
        .collect();
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    let st = wait_exit(&mut child, Duration::from_secs(5));
    drop(sub);
    assert_eq!(st.code(), Some(0));
    assert!(got.contains("READY=1"), "{got}");
    assert!(got.contains("WATCHDOG=1"), "{got}");
    assert!(got.contains("STATUS=") && got.contains("frames"), "{got}");
}

/// Told that the depth and the attitude's pitch may be off by a constant
/// (`depth_offset_sigma_m`, `pitch_offset_sigma_deg`), the daemon's STATUS
/// says by how much the tracker found each off: a minute of coming and
/// going with all three sensors, replayed from a log whose depth readings
/// are 0.2 m off and pitch readings 1° off. Told nothing it finds them
/// too, once the reading check calls (`which_offset`); with the calls
/// unanswered as well it says null.
#[test]
fn status_reports_the_sensor_offsets_the_tracker_learned() {
    use lightpose_core::{LogHeader, LogWriter};
    use lightpose_sim::{Scene, Simulator, Trajectory};
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(root().join("config/scenes/tank.toml")).unwrap();
    let scene = Scene::parse(&(text + "\n[attitude]\n\n[depth]\n\n[dvl]\n"), "s").unwrap();
    let traj = Trajectory::load(&root().join("tests/data/to-and-fro.csv")).unwrap();
    let log = dir.path().join("biased.jsonl");
    let header = LogHeader::new(scene.adc.bits, scene.adc.rate_hz);
    let file = std::io::BufWriter::new(std::fs::File::create(&log).unwrap());
    let mut w = LogWriter::new(file, &header).unwrap();
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let mut sim = Simulator::new(scene, 5);
    for (seq, t) in times.into_iter().enumerate() {
        let mut f = sim.frame_moving(seq as u64, t, &traj.kinematics(t));
        if let Some(d) = f.depth.as_mut() {
            d.z += 0.2;
        }
        if let Some(a) = f.attitude.as_mut() {
            a.pitch = lightpose_core::Angle::from_deg(a.pitch.deg() - 1.0);
        }
        w.write_frame(&f).unwrap();
    }
    w.flush().unwrap();
    let untold = root().join("config/calibration/tank.toml");
    let told = dir.path().join("told.toml");
    let mut cal = std::fs::read_to_string(&untold).unwrap();
    cal += "\n[estimator.tracker]\ndepth_offset_sigma_m = 0.3\npitch_offset_sigma_deg = 2.0\n";
    std::fs::write(&told, cal).unwrap();
    let believed = dir.path().join("believed.toml");
    let mut cal = std::fs::read_to_string(&untold).unwrap();
    cal += "\n[estimator.tracker]\ncalled_depth_offset_sigma_m = 0.0\ncalled_pitch_offset_sigma_deg = 0.0\n";
    std::fs::write(&believed, cal).unwrap();
    for (cal, want) in [(&told, true), (&untold, true), (&believed, false)] {
        let (sub, addr) = subscriber();
        let text = format!(
            "rate_hz = 5.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 1.0\n",
            cal.display(),
            log.display()
        );
        let cfg = Config::parse(&text, "offset.toml", None).expect("valid");
        let (s, msgs) = run_to_end(cfg, Duration::from_secs(60), &sub);
        assert!(s.source_ended && s.frames == 301, "{} frames", s.frames);
        let status = common::run::of_class(&msgs, "STATUS");
        let last = *status.last().expect("a STATUS at stop");
        let (o, po) = (
            &last["estimator"]["depth_offset"],
            &last["estimator"]["pitch_offset"],
        );
        if want {
            let (m, sd) = (o["m"].as_f64(), o["std"].as_f64());
            let (m, sd) = m
                .zip(sd)
                .unwrap_or_else(|| panic!("depth_offset in {last}"));
            assert!((m - 0.2).abs() <= 3.0 * sd && sd < 0.05, "{m} ± {sd}");
            let (d, sd) = (po["deg"].as_f64(), po["std"].as_f64());
            let (d, sd) = d
                .zip(sd)
                .unwrap_or_else(|| panic!("pitch_offset in {last}"));
            assert!((d + 1.0).abs() <= 3.0 * sd && sd < 0.5, "{d} ± {sd}");
        } else {
            assert!(o.is_null() && po.is_null(), "{last}");
        }
    }
}

/// Told that the water may be far from the calibration's (`k_d_sigma =
/// 0.3`: the tracker runs as a bank of waters), the daemon's STATUS says
/// which water the tracker found: a minute of coming and going at 4–6 m in
/// K_D 0.19 water, against the tank calibration's 0.09. The paper's method
/// learns no water, and says null. Told nothing, the tracker finds it too
/// when the vehicle has a DVL (its water check); without one it cannot,
/// and says null.
#[test]
fn status_reports_the_water_the_tracker_learned() {
    let dir = tempfile::tempdir().expect("tempdir");
    let murky = root().join("tests/data/tank-murky.toml");
    let with_dvl = dir.path().join("murky-dvl.toml");
    let mut scene = std::fs::read_to_string(&murky).unwrap();
    scene += "\n[depth]\n\n[dvl]\n";
    std::fs::write(&with_dvl, scene).unwrap();
    let traj = root().join("tests/data/to-and-fro.csv");
    let untold = root().join("config/calibration/tank.toml");
    let cal = dir.path().join("told.toml");
    let mut told = std::fs::read_to_string(&untold).unwrap();
    told += "\n[estimator.tracker]\nk_d_sigma = 0.3\n";
    std::fs::write(&cal, told).unwrap();
    for (estimator, cal, scene, want) in [
        ("tracker", &cal, &murky, true),
        ("moments", &cal, &murky, false),
        ("tracker", &untold, &with_dvl, true),
        ("tracker", &untold, &murky, false),
    ] {
        let (sub, addr) = subscriber();
        let text = format!(
            "rate_hz = 5.0\nestimator = \"{estimator}\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\npace = \"fast\"\nloop = false\n[outputs]\ndestinations = [\"{addr}\"]\nstatus_interval_s = 1.0\n",
            cal.display(),
            scene.display(),
            traj.display()
        );
        let cfg = Config::parse(&text, "murky.toml", None).expect("valid");
        let (s, msgs) = run_to_end(cfg, Duration::from_secs(60), &sub);
        assert!(s.source_ended && s.frames == 301, "{} frames", s.frames);
        let status = common::run::of_class(&msgs, "STATUS");
        let last = *status.last().expect("a STATUS at stop");
        let k = &last["estimator"]["water_k_d"];
        if want {
            let k = k.as_f64().unwrap_or_else(|| panic!("water_k_d in {last}"));
            assert!(
                (0.15..=0.24).contains(&k),
                "{estimator} {}: K_D {k}",
                scene.display()
            );
        } else {
            assert!(k.is_null(), "{estimator} {}: {last}", scene.display());
        }
    }
}
