//! SIGHUP reloads the calibration; a calibration the start would refuse is
//! refused on reload too, said in the log naming its file, and the daemon
//! goes on with the calibration it runs.

mod common;
use common::run::{collect, of_class, signal, sim_config, wait_exit};
use common::{shipped, subscriber};

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

    // The daemon runs on, and a good calibration reloads.
    std::fs::write(&cal, &good).expect("calibration again");
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
    let text = common::run::dvl_mock_config(180.0, addr);
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
