//! The frame thread as the supervisor watches it: a thread that panics is
//! a failure (not a stop), and a thread that only waits as configured (a
//! frame due in 10 s) keeps the systemd watchdog fed.

mod common;
use common::run::{signal, sim_config, wait_exit, Systemd};
use common::subscriber;

use lightposed::engine::EndReason;
use lightposed::{Config, Publisher};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// Audit: a panic on the frame thread dropped its `done` unsent, which the
/// supervisor took for a stop: "stopped", exit 0, and systemd's
/// Restart=on-failure never restarted the daemon. The running daemon's
/// frame thread is swapped for one that panics.
#[test]
fn a_panicked_frame_thread_is_a_failure_not_a_stop() {
    let (_sub, addr) = subscriber();
    let cfg = Config::parse(&sim_config(50.0, &[addr], "", ""), "t.toml", None).expect("valid");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let end = rt.block_on(async {
        let p = Publisher::open(&cfg.outputs).expect("publisher");
        let mut d = lightposed::wiring::start(&cfg, p).await.expect("start");
        d.stop.raise();
        let real = d.frames.take().expect("the frame thread");
        assert_eq!(real.join().expect("joined"), EndReason::Stopped);
        let (tx, rx) = tokio::sync::oneshot::channel::<EndReason>();
        d.frames = Some(std::thread::spawn(move || -> EndReason {
            let _done = tx;
            std::thread::sleep(Duration::from_millis(100));
            panic!("injected fault");
        }));
        d.done = rx;
        let (_reload, reloads) = tokio::sync::mpsc::channel(1);
        let never = std::future::pending::<()>();
        let t0 = Instant::now();
        let (_, end) = lightposed::supervisor::supervise_to_end(&cfg, d, never, reloads).await;
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
        end
    });
    assert_eq!(end, EndReason::Panicked("injected fault".into()));
    assert!(end.is_failure());
}

/// Audit: at rate_hz = 0.1 the frame thread waits 10 s for each frame,
/// and with WatchdogSec shorter than that the daemon said "frame thread
/// silent… withholding the watchdog" and systemd killed a healthy daemon.
/// The pacing wait beats: WATCHDOG=1 keeps coming.
#[test]
fn a_slow_source_keeps_the_watchdog_fed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let systemd = Systemd::new(dir.path());
    let (_sub, addr) = subscriber();
    let cfg = dir.path().join("slow.toml");
    std::fs::write(&cfg, sim_config(0.1, &[addr], "", "")).expect("write");
    let log = dir.path().join("stderr.log");
    let mut child = systemd
        .command(&cfg, 1_500_000)
        .env("RUST_LOG", "info")
        .stderr(Stdio::from(std::fs::File::create(&log).expect("log")))
        .spawn()
        .expect("spawn");
    let pings: Vec<Duration> = systemd
        .listen(Duration::from_millis(4500))
        .into_iter()
        .filter(|(_, said)| said.contains("WATCHDOG=1"))
        .map(|(t, _)| t)
        .collect();
    signal(&child, nix::sys::signal::Signal::SIGTERM);
    let st = wait_exit(&mut child, Duration::from_secs(5));
    let said = std::fs::read_to_string(&log).unwrap_or_default();
    assert_eq!(st.code(), Some(0), "{said}");
    assert!(!said.contains("withholding"), "{said}");
    // The first frame comes at once, the next in 10 s: from 1.5 s on the
    // frame thread only waits, and the pings must go on.
    let late = pings
        .iter()
        .filter(|t| **t > Duration::from_secs(3))
        .count();
    assert!(late >= 2, "WATCHDOG=1 at {pings:?}\n{said}");
}
