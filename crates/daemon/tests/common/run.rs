//! Running a daemon for a test: in-process on its own thread, or the real
//! binary; collecting its datagrams.

use super::{root, shipped};
use lightposed::{Config, Publisher};
use serde_json::Value;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A config for the simulated tank at `rate` Hz sending to `dests`, plus
/// `backend_extra` lines in `[backend]` and `extra` TOML appended (tables).
pub fn sim_config(rate: f64, dests: &[SocketAddr], backend_extra: &str, extra: &str) -> String {
    let (scene, traj, cal) = shipped();
    let d: Vec<String> = dests.iter().map(|d| format!("\"{d}\"")).collect();
    format!(
        "rate_hz = {rate}\nestimator = \"moments\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\n{backend_extra}\n[outputs]\ndestinations = [{}]\nstatus_interval_s = 0.2\n{extra}\n",
        cal.display(),
        scene.display(),
        traj.display(),
        d.join(", ")
    )
}

/// A config for the mock backend along the tank zigzag with all three own
/// sensors at 10 Hz, its DVL turned `dvl_turned_deg`, the tracker, STATUS
/// every 0.2 s to `dest`.
pub fn dvl_mock_config(dvl_turned_deg: f64, dest: SocketAddr) -> String {
    let r = root();
    format!(
        "rate_hz = 10.0\nestimator = \"tracker\"\ncalibration = \"{}\"\n[backend]\nkind = \"mock\"\nscene = \"{}\"\ntrajectory = \"{}\"\nfaults = {{ dvl_turned_deg = {dvl_turned_deg} }}\n[outputs]\ndestinations = [\"{dest}\"]\nstatus_interval_s = 0.2\n",
        r.join("config/calibration/tank.toml").display(),
        r.join("tests/data/tank-sensors.toml").display(),
        r.join("config/trajectories/zigzag.csv").display(),
    )
}

/// A config replaying `log` as fast as it goes, sending to `dest`.
pub fn replay_config(log: &Path, dest: SocketAddr) -> String {
    format!(
        "rate_hz = 5.0\nestimator = \"moments\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{dest}\"]\n",
        root().join("config/calibration/tank.toml").display(),
        log.display()
    )
}

/// Every datagram that arrives within `d`, as it came.
pub fn collect_raw(s: &UdpSocket, d: Duration) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut buf = vec![0u8; 65536];
    let end = Instant::now() + d;
    while Instant::now() < end {
        if let Ok(n) = s.recv(&mut buf) {
            out.push(buf[..n].to_vec());
        }
    }
    out
}

/// Every datagram that arrives within `d`, parsed.
pub fn collect(s: &UdpSocket, d: Duration) -> Vec<Value> {
    collect_raw(s, d)
        .iter()
        .map(|b| serde_json::from_slice(b).expect("every datagram is one JSON object"))
        .collect()
}

pub fn of_class<'a>(msgs: &'a [Value], class: &str) -> Vec<&'a Value> {
    msgs.iter().filter(|v| v["class"] == class).collect()
}

/// Run the daemon in-process on a thread of its own until `stop`
/// resolves or its source ends.
pub fn run_until<F>(cfg: Config, stop: F) -> std::thread::JoinHandle<lightposed::Summary>
where
    F: std::future::Future<Output = ()> + Send + 'static,
{
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        rt.block_on(async move {
            let p = Publisher::open(&cfg.outputs).expect("publisher");
            lightposed::run(cfg, p, stop).await.expect("daemon runs")
        })
    })
}

/// Run the daemon in-process on a thread of its own until `run_for` has
/// passed or its source ends.
pub fn run_in_process(
    cfg: Config,
    run_for: Duration,
) -> std::thread::JoinHandle<lightposed::Summary> {
    // The timer is made inside the daemon's runtime, when first polled.
    run_until(cfg, async move { tokio::time::sleep(run_for).await })
}

/// Run the daemon in-process until its source ends (`backstop`: the most
/// it may take), collecting what `sub` receives meanwhile and the last
/// STATUS, which may still be on its way when the run ends.
pub fn run_to_end(
    cfg: Config,
    backstop: Duration,
    sub: &UdpSocket,
) -> (lightposed::Summary, Vec<Value>) {
    let h = run_in_process(cfg, backstop);
    let mut msgs = Vec::new();
    while !h.is_finished() {
        msgs.extend(collect(sub, Duration::from_millis(100)));
    }
    msgs.extend(collect(sub, Duration::from_millis(300)));
    (h.join().expect("daemon"), msgs)
}

/// Start the real binary with `cfg_text` (written into `dir`); wait until
/// POSE flows to `sub`, and give the datagrams received until then. The
/// caller owns the child and waits for it.
pub fn spawn_daemon(dir: &Path, cfg_text: &str, sub: &UdpSocket) -> (Child, Vec<Vec<u8>>) {
    spawn_daemon_to(dir, cfg_text, sub, Stdio::null())
}

/// As [`spawn_daemon`], its log (stderr) to `stderr`.
#[allow(clippy::zombie_processes)]
pub fn spawn_daemon_to(
    dir: &Path,
    cfg_text: &str,
    sub: &UdpSocket,
    stderr: Stdio,
) -> (Child, Vec<Vec<u8>>) {
    let cfg = dir.join("lightposed.toml");
    std::fs::write(&cfg, cfg_text).expect("write config");
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightposed"))
        .arg("--config")
        .arg(&cfg)
        .env_remove("RUST_LOG")
        .stderr(stderr)
        .spawn()
        .expect("spawn lightposed");
    let mut buf = [0u8; 65536];
    let mut got = Vec::new();
    let t0 = Instant::now();
    loop {
        if t0.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("no POSE from the binary within 10 s");
        }
        if let Ok(n) = sub.recv(&mut buf) {
            got.push(buf[..n].to_vec());
            if serde_json::from_slice::<Value>(&buf[..n]).is_ok_and(|v| v["class"] == "POSE") {
                return (child, got);
            }
        }
    }
}

pub fn signal(child: &Child, sig: nix::sys::signal::Signal) {
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(child.id() as i32), sig).expect("signal");
}

pub fn wait_exit(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(s) = child.try_wait().expect("wait") {
            return s;
        }
        if t0.elapsed() > within {
            let _ = child.kill();
            panic!("lightposed did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The files of `dir` in name order (recordings are named by time and
/// number, so this is their order).
pub fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").path())
        .collect();
    v.sort();
    v
}

/// systemd's side of a `Type=notify` service with a watchdog: the notify
/// socket the daemon is given, and the daemon started as systemd starts it.
pub struct Systemd {
    socket: std::os::unix::net::UnixDatagram,
    path: PathBuf,
}

impl Systemd {
    /// A notify socket in `dir`.
    pub fn new(dir: &Path) -> Systemd {
        let path = dir.join("notify.sock");
        let socket = std::os::unix::net::UnixDatagram::bind(&path).expect("bind notify socket");
        socket
            .set_read_timeout(Some(Duration::from_millis(100)))
            .expect("timeout");
        Systemd { socket, path }
    }

    /// The real binary with the config file `cfg`, told this socket and a
    /// watchdog of `watchdog_usec`. systemd sets WATCHDOG_PID to the
    /// service's pid: a shell that execs the daemon knows it beforehand.
    pub fn command(&self, cfg: &Path, watchdog_usec: u64) -> Command {
        let mut c = Command::new("sh");
        c.arg("-c")
            .arg(format!(
                "WATCHDOG_PID=$$ exec '{}' --config '{}'",
                env!("CARGO_BIN_EXE_lightposed"),
                cfg.display()
            ))
            .env("NOTIFY_SOCKET", &self.path)
            .env("WATCHDOG_USEC", watchdog_usec.to_string());
        c
    }

    /// What the daemon says on the socket for `d` from now: each datagram
    /// with when it came.
    pub fn listen(&self, d: Duration) -> Vec<(Duration, String)> {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        let t0 = Instant::now();
        while t0.elapsed() < d {
            if let Ok(n) = self.socket.recv(&mut buf) {
                got.push((
                    t0.elapsed(),
                    String::from_utf8_lossy(&buf[..n]).into_owned(),
                ));
            }
        }
        got
    }
}
