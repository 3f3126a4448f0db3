//! SIGHUP reloads the calibration; a calibration the start would refuse is
//! refused on reload too, said in the log naming its file, and the daemon
//! goes on with the calibration it runs.

mod common;
use common::run::{collect, of_class, signal, sim_config, wait_exit};
use common::{calibration_copy, other_calibration, shipped, subscriber};

use nix::sys::signal::Signal;
use serde_json::Value;
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Start the binary on `cfg` with its stderr into `log`; once POSE flows.
fn start(cfg: &Path, log: &Path, sub: &UdpSocket) -> Child {
    let err = std::fs::File::create(log).expect("log file");
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--config")
        .arg(cfg)
        .env_remove("RUST_LOG")
        .env_remove("JOURNAL_STREAM")
        .stdout(Stdio::null())
        .stderr(Stdio::from(err))
        .spawn()
        .expect("spawn lightposed");
    let t0 = Instant::now();
    while !collect(sub, Duration::from_millis(100))
        .iter()
        .any(|v| v["class"] == "POSE")
    {
        if t0.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("no POSE within 20 s: {}", read(log));
        }
    }
    child
}

fn read(log: &Path) -> String {
    std::fs::read_to_string(log).unwrap_or_default()
}

/// The reloads the latest STATUS within `d` counts.
fn reloads(sub: &UdpSocket, d: Duration) -> Option<u64> {
    let msgs: Vec<Value> = collect(sub, d);
    of_class(&msgs, "STATUS")
        .last()
        .and_then(|v| v["estimator"]["reloads"].as_u64())
}

/// Audit: a reloaded calibration whose light model is of a 12-bit ADC,
/// where the frames are of a 10-bit one, was taken (the tracker would call
/// every frame bad_frame); the start refuses it. Now the reload is refused,
/// one ERROR naming the file, and a good calibration reloads after it.
#[test]
fn sighup_refuses_a_calibration_of_another_adc() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (_, _, shipped_cal) = shipped();
    let good = std::fs::read_to_string(&shipped_cal).expect("calibration");
    let physical = "v_ref = 5.0\nadc_bits = 10\n";
    assert_eq!(good.matches(physical).count(), 1, "the [physical] ADC");
    let bad = good
        .replace(physical, "v_ref = 5.0\nadc_bits = 12\n")
        .replace("[scene]\nadc_bits = 10\n", "[scene]\nadc_bits = 12\n");
    assert_ne!(bad, good);
    let cal = dir.path().join("cal.toml");
    std::fs::write(&cal, &good).expect("calibration");
    let (sub, addr) = subscriber();
    let text = sim_config(20.0, &[addr], "", "")
        .replace("estimator = \"moments\"", "estimator = \"tracker\"")
        .replace(
            &shipped_cal.display().to_string(),
            &cal.display().to_string(),
        );
    let cfg = dir.path().join("lightposed.toml");
    std::fs::write(&cfg, text).expect("config");
    let log = dir.path().join("stderr.log");
    let mut child = start(&cfg, &log, &sub);

    std::fs::write(&cal, &bad).expect("12-bit calibration");
    signal(&child, Signal::SIGHUP);
    let t0 = Instant::now();
    while !read(&log).contains("refused") {
        if t0.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("no refusal in the log: {}", read(&log));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(reloads(&sub, Duration::from_millis(600)), Some(0));

    // The daemon runs on. The calibration it runs, written back, is no
    // reload (the track is kept); another good one reloads.
    std::fs::write(&cal, &good).expect("calibration again");
    signal(&child, Signal::SIGHUP);
    let t0 = Instant::now();
    while !read(&log).contains("unchanged") {
        assert!(t0.elapsed() < Duration::from_secs(10), "{}", read(&log));
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(reloads(&sub, Duration::from_millis(300)), Some(0));
    std::fs::write(&cal, other_calibration(&good)).expect("another calibration");
    signal(&child, Signal::SIGHUP);
    let t0 = Instant::now();
    while reloads(&sub, Duration::from_millis(300)) != Some(1) {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the good calibration did not reload: {}",
            read(&log)
        );
    }
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(status.code(), Some(0), "{}", read(&log));

    let log = read(&log);
    let refusals: Vec<&str> = log.lines().filter(|l| l.contains("refused")).collect();
    assert_eq!(refusals.len(), 1, "{log}");
    let line = refusals[0];
    assert!(line.contains("ERROR"), "{line}");
    assert!(line.contains(&cal.display().to_string()), "{line}");
    assert!(
        line.contains("12-bit") && line.contains("10-bit ADC"),
        "{line}"
    );
}

/// The latest STATUS within `d`: (reloads, the DVL's readings used, refused
/// by the light, and whether the checks stand refused).
type DvlBooks = (u64, u64, u64, bool);

fn dvl_books(sub: &UdpSocket, d: Duration) -> Option<DvlBooks> {
    let msgs: Vec<Value> = collect(sub, d);
    let st = *of_class(&msgs, "STATUS").last()?;
    let vel = &st["readings"]["velocity"];
    Some((
        st["estimator"]["reloads"].as_u64()?,
        vel["used"].as_u64()?,
        vel["refused"]["light"].as_u64()?,
        st["readings"]["check"]["dvl"]["refused"].as_bool()?,
    ))
}

/// A DVL mounted backwards (the mock's `faults.dvl_turned_deg = 180`), found
/// by the light, stays refused across a calibration reload: the new
/// estimator takes over what the old one found of the hardware, where it
/// used to fuse the DVL again until its own checks had a window (2–3 s,
/// and a second restart of the track).
#[test]
fn sighup_keeps_a_dvl_set_up_wrong_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, addr) = subscriber();
    let (cal, text, good) =
        calibration_copy(dir.path(), &common::run::dvl_mock_config(180.0, addr));
    let cfg = dir.path().join("lightposed.toml");
    std::fs::write(&cfg, text).expect("config");
    let log = dir.path().join("stderr.log");
    let mut child = start(&cfg, &log, &sub);
    let wait_for = |what: &str, ok: &dyn Fn(&DvlBooks) -> bool| {
        let t0 = Instant::now();
        loop {
            if let Some(b) = dvl_books(&sub, Duration::from_millis(300)).filter(|b| ok(b)) {
                return Ok(b);
            }
            if t0.elapsed() > Duration::from_secs(20) {
                return Err(format!("{what} not within 20 s: {}", read(&log)));
            }
        }
    };
    let refused = wait_for("the DVL refused", &|b| b.3);
    let refused = refused.unwrap_or_else(|e| {
        let _ = child.kill();
        panic!("{e}")
    });
    assert_eq!(refused.0, 0);
    std::fs::write(&cal, other_calibration(&good)).expect("another calibration");
    signal(&child, Signal::SIGHUP);
    let reloaded = wait_for("the reload", &|b| b.0 == 1).unwrap_or_else(|e| {
        let _ = child.kill();
        panic!("{e}")
    });
    // 20 more refusals after the reload (2 s at 10 Hz; a fresh tracker
    // fused the DVL for 2–3 s): the DVL refused on every frame.
    let after = wait_for("20 refusals after the reload", &|b| b.2 >= reloaded.2 + 20);
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(status.code(), Some(0), "{}", read(&log));
    let after = after.unwrap_or_else(|e| panic!("{e}"));
    assert!(after.3, "{after:?}");
    assert_eq!(
        after.1, reloaded.1,
        "the DVL used after the reload: {after:?}"
    );
    let log = read(&log);
    assert!(
        log.lines()
            .any(|l| l.contains("calibration reloaded") && l.contains("kept")),
        "{log}"
    );
}

/// A config on a copy of the shipped calibration in `dir` (the tracker, 20
/// Hz, STATUS every 0.2 s to `addr`); the copy's path and text.
fn on_a_copy(
    dir: &Path,
    addr: std::net::SocketAddr,
) -> (std::path::PathBuf, std::path::PathBuf, String) {
    let text = sim_config(20.0, &[addr], "", "")
        .replace("estimator = \"moments\"", "estimator = \"tracker\"");
    let (cal, text, good) = calibration_copy(dir, &text);
    let cfg = dir.join("lightposed.toml");
    std::fs::write(&cfg, text).expect("config");
    (cfg, cal, good)
}

/// Audit: a SIGHUP every 5 ms made a reload each (lines without bound,
/// estimators piling up in memory, the track restarted at every frame).
/// Now a storm is a reload at most a second, its SIGHUPs told by the rule
/// for repeated lines, and the track runs on (`ok` poses during it).
#[test]
fn a_sighup_storm_is_a_reload_a_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, addr) = subscriber();
    let (cfg, cal, good) = on_a_copy(dir.path(), addr);
    let log = dir.path().join("stderr.log");
    let mut child = start(&cfg, &log, &sub);
    std::fs::write(&cal, other_calibration(&good)).expect("another calibration");
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    let storm = std::thread::spawn(move || {
        let t0 = Instant::now();
        let mut sent = 0;
        while t0.elapsed() < Duration::from_millis(2500) {
            sent += u32::from(nix::sys::signal::kill(pid, Signal::SIGHUP).is_ok());
            std::thread::sleep(Duration::from_millis(5));
        }
        sent
    });
    let msgs = collect(&sub, Duration::from_millis(4000));
    let sent = storm.join().expect("storm");
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(status.code(), Some(0), "{}", read(&log));
    let log = read(&log);
    let last = of_class(&msgs, "STATUS")
        .last()
        .map(|v| v["estimator"]["reloads"].clone());
    // One replaced (the changed file), the rest the same file: unchanged.
    assert_eq!(last, Some(Value::from(1)), "{log}");
    let lines = log.lines().filter(|l| l.contains("SIGHUP")).count();
    let unchanged = log.lines().filter(|l| l.contains("unchanged")).count();
    assert!(
        sent > 200 && lines <= 6,
        "{sent} SIGHUPs, {lines} lines: {log}"
    );
    assert!(
        (1..=4).contains(&unchanged),
        "{unchanged} reloads of the same file: {log}"
    );
    let ok_after = of_class(&msgs, "POSE")
        .iter()
        .skip(40)
        .filter(|p| p["status"] == "ok")
        .count();
    assert!(ok_after > 20, "{ok_after} ok poses during the storm");
}

/// Audit: a calibration replaced by a FIFO that no one writes, then a
/// SIGHUP, hung the reload in open(2) on the supervisor's thread: no
/// STATUS, no watchdog, SIGTERM unheard. Now it is refused (it reads as
/// empty), STATUS goes on and SIGTERM ends the daemon at once.
#[test]
fn a_calibration_that_is_a_fifo_hangs_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, addr) = subscriber();
    let (cfg, cal, _) = on_a_copy(dir.path(), addr);
    let log = dir.path().join("stderr.log");
    let mut child = start(&cfg, &log, &sub);
    std::fs::remove_file(&cal).expect("rm");
    nix::unistd::mkfifo(&cal, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    signal(&child, Signal::SIGHUP);
    let statuses = of_class(&collect(&sub, Duration::from_millis(1500)), "STATUS").len();
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(3));
    assert_eq!(status.code(), Some(0), "{}", read(&log));
    assert!(statuses >= 5, "{statuses} STATUS in 1.5 s: {}", read(&log));
    let log = read(&log);
    assert!(
        log.lines()
            .any(|l| l.contains("ERROR") && l.contains("refused") && l.contains("cal.toml")),
        "{log}"
    );
}

/// Audit: a SIGHUP in the first milliseconds, before the handler was set,
/// ended the daemon without a line. It is held until then, and asks for a
/// reload.
#[test]
fn a_sighup_at_start_is_held_not_fatal() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, addr) = subscriber();
    let (cfg, _, _) = on_a_copy(dir.path(), addr);
    let log = dir.path().join("stderr.log");
    let err = std::fs::File::create(&log).expect("log file");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_lightposed"));
    cmd.arg("--config")
        .arg(&cfg)
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(Stdio::from(err));
    // The child starts with SIGHUP blocked, so that the one sent at once
    // is pending whenever the child gets to main (before main it cannot
    // be helped): it must reach the handler, not end the daemon.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            nix::sys::signal::SigSet::from(Signal::SIGHUP)
                .thread_block()
                .map_err(std::io::Error::from)
        });
    }
    let mut child = cmd.spawn().expect("spawn lightposed");
    signal(&child, Signal::SIGHUP);
    let poses = of_class(&collect(&sub, Duration::from_millis(1500)), "POSE").len();
    let alive = child.try_wait().expect("wait").is_none();
    if alive {
        signal(&child, Signal::SIGTERM);
    }
    let status = wait_exit(&mut child, Duration::from_secs(5));
    assert!(
        alive && poses > 5,
        "{status:?}, {poses} POSE: {}",
        read(&log)
    );
    assert_eq!(status.code(), Some(0), "{}", read(&log));
    assert!(read(&log).contains("SIGHUP"), "{}", read(&log));
}

/// Re-audit: a calibration refused at every SIGHUP of a storm wrote an
/// ERROR a second (a reload a second), and a FIFO whose writer holds it
/// open without writing kept a reload reading for good without a word.
/// Now the refusals follow the rule for repeated lines, and the stuck
/// reload is told after 5 s; SIGTERM still ends the daemon at once.
#[test]
fn refusals_in_a_storm_are_rate_limited_and_a_stuck_reload_is_told() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (sub, addr) = subscriber();
    let (cfg, cal, _) = on_a_copy(dir.path(), addr);
    let log = dir.path().join("stderr.log");
    let mut child = start(&cfg, &log, &sub);
    std::fs::write(&cal, "not a calibration").expect("bad calibration");
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(5) {
        signal(&child, Signal::SIGHUP);
        std::thread::sleep(Duration::from_millis(100));
    }
    // A FIFO held open by a writer that never writes.
    std::fs::remove_file(&cal).expect("rm");
    nix::unistd::mkfifo(&cal, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    let holder = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&cal)
        .expect("hold the FIFO");
    std::thread::sleep(Duration::from_millis(1200));
    signal(&child, Signal::SIGHUP);
    let statuses = of_class(&collect(&sub, Duration::from_millis(6500)), "STATUS").len();
    signal(&child, Signal::SIGTERM);
    let status = wait_exit(&mut child, Duration::from_secs(3));
    drop(holder);
    assert_eq!(status.code(), Some(0), "{}", read(&log));
    assert!(statuses >= 25, "{statuses} STATUS in 6.5 s");
    let log = read(&log);
    let errors = log
        .lines()
        .filter(|l| l.contains("ERROR") && l.contains("refused"))
        .count();
    assert!(
        (1..=3).contains(&errors),
        "{errors} refusal lines for 5 s of SIGHUPs: {log}"
    );
    assert!(log.contains("calibration reload still reading"), "{log}");
}
