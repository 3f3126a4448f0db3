//! Faults injected into a running daemon, end to end: the daemon runs
//! in-process (library `run`) publishing to a loopback subscriber, or as the
//! real binary where a signal is the fault. Each test checks three things:
//! STATUS keeps coming while the fault lasts, the daemon recovers within the
//! bound stated in the test (and in docs/daemon.md), and no frame the
//! recorder acknowledged is lost.
//!
//! Bounds are generous (a loaded 2-core CI machine); the daemon itself
//! recovers much faster (see docs/daemon.md, "Faults").

mod common;
use common::run::run_until;
use common::{read_logs, shipped, subscriber};

use lightpose_hal::serial::protocol::format_line;
use lightpose_testkit::pty::Pty;
use lightposed::Config;
use serde_json::Value;
use std::io::Write;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// STATUS is due every second; a gap longer than this is silence.
const STATUS_GAP_MAX: Duration = Duration::from_millis(1800);
/// Serial board replugged → POSE flowing again.
const SERIAL_RECOVERY: Duration = Duration::from_secs(2);
/// DS18B20 file gone → STATUS says fallback; file back → STATUS says sensor.
const TEMP_RECOVERY: Duration = Duration::from_secs(3);

/// Datagrams as they arrive, with their arrival time, kept by the test.
struct Inbox {
    sock: UdpSocket,
    msgs: Vec<(Instant, Value)>,
    buf: Vec<u8>,
}

impl Inbox {
    fn new(sock: UdpSocket) -> Self {
        Inbox {
            sock,
            msgs: Vec::new(),
            buf: vec![0u8; 65536],
        }
    }
    /// Read for `d`.
    fn pump(&mut self, d: Duration) {
        let end = Instant::now() + d;
        while Instant::now() < end {
            self.recv_one();
        }
    }
    fn recv_one(&mut self) -> Option<&(Instant, Value)> {
        let n = self.sock.recv(&mut self.buf).ok()?;
        let v: Value =
            serde_json::from_slice(&self.buf[..n]).expect("every datagram is one JSON object");
        self.msgs.push((Instant::now(), v));
        self.msgs.last()
    }
    /// Read until a datagram satisfies `pred` (its arrival time), or panic
    /// with `what` after `within`.
    fn until(&mut self, within: Duration, what: &str, pred: impl Fn(&Value) -> bool) -> Instant {
        let end = Instant::now() + within;
        while Instant::now() < end {
            if let Some((at, v)) = self.recv_one() {
                if pred(v) {
                    return *at;
                }
            }
        }
        let last = self.last("STATUS").cloned().unwrap_or(Value::Null);
        panic!("not within {within:?}: {what}; last STATUS {last}");
    }
    fn of_class(&self, class: &str) -> Vec<&(Instant, Value)> {
        self.msgs
            .iter()
            .filter(|(_, v)| v["class"] == class)
            .collect()
    }
    fn last(&self, class: &str) -> Option<&Value> {
        self.msgs
            .iter()
            .rev()
            .find(|(_, v)| v["class"] == class)
            .map(|(_, v)| v)
    }
}

/// No STATUS silence longer than [`STATUS_GAP_MAX`] in what was received.
fn assert_status_steady(inbox: &Inbox) {
    let st = inbox.of_class("STATUS");
    assert!(st.len() >= 3, "{} STATUS", st.len());
    for w in st.windows(2) {
        let gap = w[1].0 - w[0].0;
        assert!(gap <= STATUS_GAP_MAX, "STATUS silent for {gap:?}");
    }
}

/// Run the daemon in-process until `stop` is set (or 60 s, a backstop).
fn run_in_process(
    cfg: Config,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<lightposed::Summary> {
    run_until(cfg, async move {
        let t0 = Instant::now();
        while !stop.load(Relaxed) && t0.elapsed() < Duration::from_secs(60) {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
}

// ---- serial boards on pseudo-terminals ----------------------------------

/// One fake board: a pty whose port is reached through `link`, as a udev
/// symlink would give it, living until the board is unplugged. Its writes
/// are non-blocking: a board whose port nobody reads (the daemon is busy
/// failing on the other one) must not stall the streamer.
fn plug(link: &Path) -> Pty {
    Pty::plug(link).nonblocking()
}

/// Two 16-channel boards streaming `$LPADC` lines at about 250 Hz each
/// from a thread, until dropped. `unplug`/`replug` swap board 0's pty.
struct Boards {
    links: [PathBuf; 2],
    ptys: Arc<Mutex<[Option<Pty>; 2]>>,
    stop: Arc<AtomicBool>,
    join: Option<std::thread::JoinHandle<()>>,
}

impl Boards {
    fn start(dir: &Path) -> Boards {
        let links = [dir.join("lpadc0"), dir.join("lpadc1")];
        let ptys = Arc::new(Mutex::new([Some(plug(&links[0])), Some(plug(&links[1]))]));
        let stop = Arc::new(AtomicBool::new(false));
        let (p, s) = (ptys.clone(), stop.clone());
        let join = std::thread::spawn(move || {
            let mut line = Vec::new();
            let mut seq = 0u32;
            while !s.load(Relaxed) {
                if let Ok(mut g) = p.lock() {
                    for (id, pty) in g.iter_mut().enumerate() {
                        if let Some(pty) = pty {
                            // A bright, even dome: any estimator status will
                            // do, these tests are about the frame path.
                            let values: Vec<u16> = (0..16).map(|c| 400 + c * 3).collect();
                            line.clear();
                            format_line(id as u8, seq, 10, &values, &mut line);
                            // EAGAIN (buffer full) or EIO: the daemon is not
                            // reading this port right now; that line is lost,
                            // as on a real board.
                            let _ = pty.master.write_all(&line);
                        }
                    }
                }
                seq = seq.wrapping_add(1);
                std::thread::sleep(Duration::from_millis(4));
            }
        });
        Boards {
            links,
            ptys,
            stop,
            join: Some(join),
        }
    }
    /// Board 0 gone: its pty closed (the daemon's read fails) and the link
    /// removed, as udev does when a USB device is pulled.
    fn unplug(&self) {
        if let Ok(mut g) = self.ptys.lock() {
            g[0] = None;
        }
        let _ = std::fs::remove_file(&self.links[0]);
    }
    /// Board 0 back: a new pty behind the same link.
    fn replug(&self) {
        let pty = plug(&self.links[0]);
        if let Ok(mut g) = self.ptys.lock() {
            g[0] = Some(pty);
        }
    }
}

impl Drop for Boards {
    fn drop(&mut self) {
        self.stop.store(true, Relaxed);
        if let Some(j) = self.join.take() {
            let _ = j.join();
        }
    }
}

/// `[backend]` for the two serial boards: detectors 0..15 on board m0,
/// 16..24 on m1; `temperature` is appended as given.
fn serial_config(
    rate: f64,
    boards: &Boards,
    sub: SocketAddr,
    temperature: &str,
    extra: &str,
) -> String {
    let (_, _, cal) = shipped();
    let map: Vec<String> = (0..25)
        .map(|k| {
            let (board, ch) = if k < 16 { ("m0", k) } else { ("m1", k - 16) };
            format!(
                "{{ r = {}, c = {}, board = \"{board}\", channel = {ch} }}",
                k / 5,
                k % 5
            )
        })
        .collect();
    format!(
        r#"rate_hz = {rate}
estimator = "moments"
calibration = "{}"
[backend]
kind = "serial"
rate_hz = {rate}
adc_bits = 10
v_ref = 5.0
timeout_ms = 200
boards = [
    {{ name = "m0", id = 0, path = "{}", baud = 115200, channels = 16 }},
    {{ name = "m1", id = 1, path = "{}", baud = 115200, channels = 16 }},
]
map = [{}]
{temperature}
[outputs]
destinations = ["{sub}"]
status_interval_s = 1.0
{extra}
"#,
        cal.display(),
        boards.links[0].display(),
        boards.links[1].display(),
        map.join(", ")
    )
}

#[test]
fn serial_board_unplugged_and_replugged() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let boards = Boards::start(dir.path());
    let (sock, addr) = subscriber();
    let extra = format!("[recording]\ndir = \"{}\"\n", rec.display());
    let text = serial_config(100.0, &boards, addr, "", &extra);
    let cfg = Config::parse(&text, "serial.toml", None).expect("valid config");
    let stop = Arc::new(AtomicBool::new(false));
    let h = run_in_process(cfg, stop.clone());
    let mut inbox = Inbox::new(sock);

    inbox.until(
        Duration::from_secs(5),
        "first POSE from the serial boards",
        |v| v["class"] == "POSE",
    );
    inbox.pump(Duration::from_millis(1200));
    let poses_before = inbox.of_class("POSE").len();
    assert!(poses_before > 50, "{poses_before} POSE before the unplug");

    // Unplugged for about 2.5 s: STATUS keeps coming and says so.
    boards.unplug();
    let unplugged = Instant::now();
    inbox.until(Duration::from_secs(3), "STATUS backend failing", |v| {
        v["class"] == "STATUS" && v["backend"]["state"] == "failing"
    });
    let failed_during = inbox.until(Duration::from_secs(3), "failed frames counted", |v| {
        v["class"] == "STATUS" && v["failed"].as_u64().unwrap_or(0) > 5
    });
    let st = inbox.last("STATUS").cloned().expect("STATUS");
    let err = st["backend"]["last_error"].as_str().unwrap_or("");
    assert!(
        err.contains("board m0") && err.contains("lpadc0"),
        "the error names the board and its port: {st}"
    );
    let rest = Duration::from_millis(2500).saturating_sub(unplugged.elapsed());
    inbox.pump(rest);
    // No POSE while board 0 is out (some may have been in flight at the
    // unplug: only those sent in the last 300 ms before it).
    let out_poses = inbox
        .of_class("POSE")
        .iter()
        .filter(|(at, _)| *at > unplugged + Duration::from_millis(300))
        .count();
    assert_eq!(out_poses, 0, "POSE while a board is unplugged");
    assert!(failed_during > unplugged);

    // Replugged: POSE within the bound, STATUS says running and counts the
    // reopen.
    boards.replug();
    let replugged = Instant::now();
    let back = inbox.until(
        SERIAL_RECOVERY,
        "POSE within SERIAL_RECOVERY of the replug",
        |v| v["class"] == "POSE",
    );
    eprintln!("serial: POSE again {:?} after the replug", back - replugged);
    inbox.until(
        Duration::from_secs(3),
        "STATUS running with a reopen",
        |v| {
            v["class"] == "STATUS"
                && v["backend"]["state"] == "running"
                && v["backend"]["health"]["reopens"].as_u64().unwrap_or(0) >= 1
        },
    );
    inbox.pump(Duration::from_millis(500));
    let poses_after = inbox
        .of_class("POSE")
        .iter()
        .filter(|(at, _)| *at >= back)
        .count();
    assert!(poses_after > 20, "{poses_after} POSE after the replug");

    stop.store(true, Relaxed);
    let s = h.join().expect("daemon");
    inbox.pump(Duration::from_millis(300));
    assert_status_steady(&inbox);
    let fin = inbox.last("STATUS").cloned().expect("final STATUS");
    assert_eq!(fin["frames"].as_u64(), Some(s.frames), "{fin}");
    assert!(s.failed > 5, "{s:?}");

    // Every frame the recorder acknowledged reads back; none of the failed
    // ones was recorded.
    let (seqs, cut) = read_logs(&rec);
    assert!(!cut, "a clean stop leaves no cut line");
    assert_eq!(seqs.len() as u64, s.recorded, "{s:?}");
    assert_eq!(s.recorded, s.frames, "every published frame recorded");
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "seq increasing");
    let gap = seqs.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    assert!(gap > 5, "the outage is a gap in the recorded seq ({gap})");
}

// ---- SPI / I²C bus errors from the mock ----------------------------------

#[test]
fn bus_errors_every_n_frames_are_counted_and_pose_goes_on() {
    let (scene, traj, cal) = shipped();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sock, addr) = subscriber();
    // Every 7th frame is a bus error: frame s fails iff (s + 1) % 7 == 0.
    let text = format!(
        r#"rate_hz = 200.0
estimator = "moments"
calibration = "{}"
[backend]
kind = "mock"
scene = "{}"
trajectory = "{}"
faults = {{ bus_error_every = 7 }}
[outputs]
destinations = ["{addr}"]
status_interval_s = 1.0
[recording]
dir = "{}"
"#,
        cal.display(),
        scene.display(),
        traj.display(),
        rec.display()
    );
    let cfg = Config::parse(&text, "mock.toml", None).expect("valid");
    let stop = Arc::new(AtomicBool::new(false));
    let h = run_in_process(cfg, stop.clone());
    let mut inbox = Inbox::new(sock);
    inbox.pump(Duration::from_millis(3300));
    stop.store(true, Relaxed);
    let s = h.join().expect("daemon");
    inbox.pump(Duration::from_millis(300));

    assert_status_steady(&inbox);
    // The failed count grows STATUS after STATUS: errors all the way, each
    // counted.
    let failed: Vec<u64> = inbox
        .of_class("STATUS")
        .iter()
        .filter_map(|(_, v)| v["failed"].as_u64())
        .collect();
    assert!(
        failed.windows(2).skip(1).all(|w| w[1] > w[0]),
        "failed grows: {failed:?}"
    );
    let fin = inbox.last("STATUS").cloned().expect("STATUS");
    assert_eq!(fin["failed"].as_u64(), Some(s.failed), "{fin}");
    assert_eq!(fin["lost"], 0, "failures are not counted again as lost");
    // One in seven attempts fails.
    let share = s.failed as f64 / (s.failed + s.frames) as f64;
    assert!((0.12..0.17).contains(&share), "failed share {share}: {s:?}");

    // POSE goes on, and exactly the failing seqs are missing.
    let seqs: Vec<u64> = inbox
        .of_class("POSE")
        .iter()
        .filter_map(|(_, v)| v["seq"].as_u64())
        .collect();
    assert!(seqs.len() > 300, "{} POSE", seqs.len());
    assert!(
        seqs.iter().all(|q| (q + 1) % 7 != 0),
        "a failed frame was published"
    );
    for w in seqs.windows(2) {
        let expect = if (w[0] + 2) % 7 == 0 { 2 } else { 1 };
        assert_eq!(w[1] - w[0], expect, "POSE seq {} → {}", w[0], w[1]);
    }
    // The recording has every acknowledged frame, and only good ones.
    let (rseqs, cut) = read_logs(&rec);
    assert!(!cut);
    assert_eq!(rseqs.len() as u64, s.recorded);
    assert_eq!(s.recorded, s.frames, "{s:?}");
    assert!(rseqs.iter().all(|q| (q + 1) % 7 != 0));
}

/// The tracker on the mock tank for 2.5 s with `faults`: its POSE
/// statuses by word and the last STATUS.
fn mock_run(faults: &str) -> (std::collections::BTreeMap<String, usize>, Value) {
    let (scene, traj, cal) = shipped();
    let (sock, addr) = subscriber();
    let text = format!(
        r#"rate_hz = 50.0
estimator = "tracker"
calibration = "{}"
[backend]
kind = "mock"
scene = "{}"
trajectory = "{}"
faults = {{ {faults} }}
[outputs]
destinations = ["{addr}"]
status_interval_s = 0.5
"#,
        cal.display(),
        scene.display(),
        traj.display(),
    );
    let cfg = Config::parse(&text, "mock.toml", None).expect("valid");
    let stop = Arc::new(AtomicBool::new(false));
    let h = run_in_process(cfg, stop.clone());
    let mut inbox = Inbox::new(sock);
    inbox.pump(Duration::from_millis(2500));
    stop.store(true, Relaxed);
    h.join().expect("daemon");
    inbox.pump(Duration::from_millis(300));
    let mut statuses = std::collections::BTreeMap::new();
    for (_, v) in inbox.of_class("POSE") {
        *statuses
            .entry(v["status"].as_str().unwrap_or("?").to_string())
            .or_insert(0) += 1;
    }
    (statuses, inbox.last("STATUS").cloned().expect("STATUS"))
}

/// A stuck channel is left out by the tracker: as many poses come `ok` as
/// without it, and STATUS names the channel.
/// - At full scale (the shipped mock example's fault): a bound no light
///   gives beside its neighbours. (Read as saturated, it made 91 of 98
///   `diverged`.)
/// - The spot's centre at 400 counts, a value light can give: no bound
///   one frame can refuse, but its history can (a count noise alone would
///   have moved), after a few frames. (What it costs read as data is
///   measured in the pipeline's tests/stuck_channel.rs: here it was only
///   not named.)
#[test]
fn a_stuck_channel_is_left_out_named_and_poses_go_on() {
    let (clean, _) = mock_run("");
    let ok = |m: &std::collections::BTreeMap<String, usize>| m.get("ok").copied().unwrap_or(0);
    assert!(ok(&clean) > 30, "clean: {clean:?}");
    for (r, c, value) in [(0, 0, 1023), (2, 2, 400)] {
        let (stuck, fin) = mock_run(&format!(
            "stuck = [{{ r = {r}, c = {c}, value = {value} }}]"
        ));
        assert!(
            ok(&stuck) * 10 >= ok(&clean) * 9,
            "({r},{c}) at {value}: stuck {stuck:?}, clean {clean:?}"
        );
        assert_eq!(
            fin["channels"]["excluded_now"],
            serde_json::json!([[r, c]]),
            "{fin}"
        );
        let frames = fin["channels"]["excluded_frames"][0]["frames"].as_u64();
        assert!(frames.is_some_and(|n| n > 50), "{fin}");
    }
}

// ---- the DS18B20 vanishing -------------------------------------------------

const W1_GOOD: &str =
    "72 01 4b 46 7f ff 0e 10 57 : crc=57 YES\n72 01 4b 46 7f ff 0e 10 57 t=18250\n";

#[test]
fn temperature_sensor_vanishes_and_returns() {
    let dir = tempfile::tempdir().expect("tempdir");
    let w1 = dir.path().join("w1");
    let id = "28-0000075a1b2c";
    lightpose_hal::temp::write_fake_w1(&w1, id, W1_GOOD).expect("fake sysfs");
    let slave = w1.join(id).join("w1_slave");
    let boards = Boards::start(dir.path());
    let (sock, addr) = subscriber();
    let temperature = format!(
        "temperature = {{ kind = \"ds18b20\", fallback_c = 11.5, root = \"{}\", interval_s = 0.05, max_age_s = 0.5 }}",
        w1.display()
    );
    let text = serial_config(100.0, &boards, addr, &temperature, "");
    let cfg = Config::parse(&text, "ds18b20.toml", None).expect("valid config");
    let stop = Arc::new(AtomicBool::new(false));
    let h = run_in_process(cfg, stop.clone());
    let mut inbox = Inbox::new(sock);

    let sensor_ok = |v: &Value| {
        v["class"] == "STATUS"
            && v["temperature"]["c"] == 18.25
            && v["temperature"]["fallback"] == false
            && v["temperature"]["sensor"]["kind"] == "ds18b20"
    };
    inbox.until(
        Duration::from_secs(5),
        "STATUS with the sensor's 18.25 °C",
        sensor_ok,
    );

    std::fs::remove_file(&slave).expect("remove w1_slave");
    let gone = Instant::now();
    let fell_back = inbox.until(TEMP_RECOVERY, "STATUS saying fallback 11.5 °C", |v| {
        v["class"] == "STATUS"
            && v["temperature"]["c"] == 11.5
            && v["temperature"]["fallback"] == true
            && v["temperature"]["sensor"]["fallback_active"] == true
    });
    let st = inbox.last("STATUS").cloned().expect("STATUS");
    assert!(
        st["temperature"]["error"]
            .as_str()
            .is_some_and(|e| e.contains("w1_slave")),
        "the error names the file: {st}"
    );
    eprintln!(
        "ds18b20: fallback reported {:?} after removal",
        fell_back - gone
    );
    // POSE keeps flowing on the fallback value.
    inbox.pump(Duration::from_millis(800));
    let during = inbox
        .of_class("POSE")
        .iter()
        .filter(|(at, _)| *at > fell_back)
        .count();
    assert!(during > 40, "{during} POSE while the sensor is gone");

    lightpose_hal::temp::write_fake_w1(&w1, id, W1_GOOD).expect("file back");
    let back = Instant::now();
    let ok = inbox.until(TEMP_RECOVERY, "STATUS back on the sensor", sensor_ok);
    eprintln!(
        "ds18b20: sensor reported again {:?} after return",
        ok - back
    );
    let st = inbox.last("STATUS").cloned().expect("STATUS");
    assert!(
        st["temperature"]["sensor"]["fallbacks"]
            .as_u64()
            .unwrap_or(0)
            > 10,
        "{st}"
    );
    assert_eq!(st["temperature"]["error"], Value::Null, "{st}");

    stop.store(true, Relaxed);
    let s = h.join().expect("daemon");
    inbox.pump(Duration::from_millis(300));
    assert_status_steady(&inbox);
    assert_eq!(s.failed, 0, "a temperature outage fails no frame: {s:?}");
}

// ---- SIGKILL mid-recording: the acknowledged frames ----------------------

/// The real binary (stderr discarded) on the shipped simulation at 500 Hz,
/// sending to `sub` with STATUS every second and recording into `rec`
/// (`recording_extra`: more lines of `[recording]`); its config file is
/// written into `dir`.
fn recording_daemon(dir: &Path, sub: SocketAddr, rec: &Path, recording_extra: &str) -> Command {
    let (scene, traj, cal) = shipped();
    let text = format!(
        r#"rate_hz = 500.0
estimator = "moments"
calibration = "{}"
[backend]
kind = "sim"
scene = "{}"
trajectory = "{}"
[outputs]
destinations = ["{sub}"]
status_interval_s = 1.0
[recording]
dir = "{}"
{recording_extra}"#,
        cal.display(),
        scene.display(),
        traj.display(),
        rec.display()
    );
    let cfg_path = dir.join("lightposed.toml");
    std::fs::write(&cfg_path, text).expect("write config");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_lightposed"));
    cmd.arg("--config").arg(&cfg_path).stderr(Stdio::null());
    cmd
}

#[test]
fn kill_9_loses_no_acknowledged_frame() {
    // e2e.rs checks that the log is whole to its last line after kill -9;
    // here: every frame the recorder had reported as written (STATUS
    // recording.frames) before the kill reads back, across rotations.
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sock, addr) = subscriber();
    let mut child = recording_daemon(dir.path(), addr, &rec, "rotate_mb = 0.1\n")
        .spawn()
        .expect("spawn lightposed");
    let mut inbox = Inbox::new(sock);
    let acked =
        |v: &Value| v["class"] == "STATUS" && v["recording"]["frames"].as_u64().unwrap_or(0) > 0;
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        inbox.until(
            Duration::from_secs(10),
            "a STATUS with frames recorded",
            acked,
        );
        // Then one after the files have rotated; the kill lands right
        // after it, mid-recording.
        inbox.until(Duration::from_secs(10), "a STATUS after rotation", |v| {
            v["class"] == "STATUS" && v["recording"]["files"].as_u64().unwrap_or(0) >= 2
        });
    }));
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGKILL,
    );
    let _ = child.wait();
    if let Err(p) = r {
        std::panic::resume_unwind(p);
    }
    let st = inbox.last("STATUS").cloned().expect("STATUS");
    let acked = st["recording"]["frames"]
        .as_u64()
        .expect("recording.frames");
    assert!(acked > 300, "{st}");
    assert!(
        st["recording"]["files"].as_u64().unwrap_or(0) > 1,
        "rotated: {st}"
    );
    let (seqs, _cut) = read_logs(&rec);
    assert!(
        seqs.len() as u64 >= acked,
        "{} frames read back, {acked} acknowledged",
        seqs.len()
    );
    let first: Vec<u64> = seqs.iter().take(acked as usize).copied().collect();
    assert!(
        first.iter().enumerate().all(|(i, q)| *q == i as u64),
        "the acknowledged frames are seq 0..{acked}, in order, across files"
    );
}

// ---- a disk that fills up mid-line ---------------------------------------

#[test]
fn full_disk_mid_line_loses_no_acknowledged_frame() {
    // e2e.rs covers a recording directory that cannot be created at all, and
    // recorder.rs a log swapped for /dev/full. Here the real binary runs
    // with RLIMIT_FSIZE at 48 KiB (SIGXFSZ ignored), so every log file hits
    // "File too large" part-way through a line, as a filling disk does: the
    // recorder must report the error, resume in a new file after its retry
    // delay, count as written exactly the lines that read back whole, and
    // cut the half-written line back off each file.
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sock, addr) = subscriber();
    let mut cmd = recording_daemon(dir.path(), addr, &rec, "");
    // SAFETY: between fork and exec only async-signal-safe system calls
    // (setrlimit, sigaction), no allocation.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            use nix::sys::resource::{setrlimit, Resource};
            use nix::sys::signal::{signal, SigHandler, Signal};
            setrlimit(Resource::RLIMIT_FSIZE, 48 * 1024, 48 * 1024)?;
            signal(Signal::SIGXFSZ, SigHandler::SigIgn)?;
            Ok(())
        });
    }
    let mut child = cmd.spawn().expect("spawn lightposed");
    let mut inbox = Inbox::new(sock);
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let full = inbox.until(Duration::from_secs(10), "STATUS recording error", |v| {
            v["class"] == "STATUS" && v["recording"]["state"] == "error"
        });
        let st = inbox.last("STATUS").cloned().unwrap_or(Value::Null);
        let files = st["recording"]["files"].as_u64().unwrap_or(0);
        let frames = st["recording"]["frames"].as_u64().unwrap_or(0);
        // Resumed in a new file after the 2 s retry delay (which fills up in
        // turn well within a STATUS interval, so `state` is seldom seen as
        // "recording": the new file and its frames are the evidence).
        let resumed = inbox.until(Duration::from_secs(5), "recording resumed", |v| {
            v["class"] == "STATUS"
                && v["recording"]["files"].as_u64().unwrap_or(0) > files
                && v["recording"]["frames"].as_u64().unwrap_or(0) > frames
        });
        eprintln!("full disk: resumed {:?} after the error", resumed - full);
    }));
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break Some(s);
        }
        if t0.elapsed() > Duration::from_secs(5) {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    if let Err(p) = r {
        std::panic::resume_unwind(p);
    }
    assert_eq!(status.and_then(|s| s.code()), Some(0), "SIGTERM exits 0");
    inbox.pump(Duration::from_millis(300));
    assert_status_steady(&inbox);
    let fin = inbox.last("STATUS").cloned().expect("final STATUS");
    let err = fin["recording"]["error"].as_str().unwrap_or("");
    assert!(err.contains("too large"), "{fin}");
    assert!(
        inbox.of_class("POSE").len() > 1000,
        "publishing goes on while the disk refuses"
    );
    let acked = fin["recording"]["frames"].as_u64().expect("frames");
    let failed = fin["recording"]["failed"].as_u64().expect("failed");
    assert!(failed > 100, "refused frames counted: {fin}");
    let (seqs, cut) = read_logs(&rec);
    assert!(!cut, "a line the limit cut in two was left in its file");
    assert_eq!(
        seqs.len() as u64,
        acked,
        "lines that read back whole = frames acknowledged: {fin}"
    );
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "seq increasing");
}
