//! `lightposed --bench`: the real per-frame path (simulator → estimator →
//! POSE → UDP send) run as fast as it goes on the calling thread, to measure
//! frames per second, frame-to-datagram latency, CPU share and peak memory
//! against the targets (≥ 10,000 frames/s on one core, p99 < 1 ms,
//! RSS < 20 MiB).

use crate::config::{Backend, Config, Outputs, Pace};
use crate::engine::Engine;
use crate::publish::Publisher;
use crate::stats::Stats;
use crate::DaemonError;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, PartialEq)]
pub struct BenchReport {
    pub frames: u64,
    pub seconds: f64,
    pub fps: f64,
    pub p50_s: f64,
    pub p99_s: f64,
    pub max_s: f64,
    /// CPU time over wall time: 1.0 is one whole core.
    pub cpu_share: f64,
    /// Peak resident set (VmHWM), KiB.
    pub peak_rss_kib: Option<u64>,
    pub estimator: String,
    pub source: String,
}

impl std::fmt::Display for BenchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "source:     {}", self.source)?;
        writeln!(f, "estimator:  {}", self.estimator)?;
        writeln!(f, "frames:     {} in {:.3} s", self.frames, self.seconds)?;
        writeln!(f, "rate:       {:.0} frames/s", self.fps)?;
        writeln!(
            f,
            "latency:    p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs (frame to datagram sent)",
            self.p50_s * 1e6,
            self.p99_s * 1e6,
            self.max_s * 1e6
        )?;
        writeln!(f, "cpu:        {:.0} % of one core", self.cpu_share * 100.0)?;
        match self.peak_rss_kib {
            Some(k) => write!(f, "peak rss:   {:.1} MiB (VmHWM)", k as f64 / 1024.0),
            None => write!(f, "peak rss:   unknown (no /proc/self/status)"),
        }
    }
}

/// VmHWM of this process in KiB.
pub fn peak_rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn cpu_seconds() -> f64 {
    use nix::sys::resource::{getrusage, UsageWho};
    match getrusage(UsageWho::RUSAGE_SELF) {
        Ok(u) => {
            let tv = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
            tv(u.user_time()) + tv(u.system_time())
        }
        Err(_) => f64::NAN,
    }
}

/// Run `frames` frames of the configured simulator (or replay) backend as
/// fast as possible, publishing to a local socket that nobody reads (the
/// kernel drops what overflows; the send cost is real).
pub fn bench(cfg: &Config, frames: u64) -> Result<BenchReport, DaemonError> {
    let mut cfg = cfg.clone();
    match &mut cfg.backend {
        Backend::Sim(s) => {
            s.pace = Pace::Fast;
            s.looping = true;
        }
        Backend::Replay(r) => {
            r.pace = Pace::Fast;
            r.looping = true;
        }
        Backend::Hardware { kind, .. } => {
            return Err(DaemonError::Backend {
                kind: kind.clone(),
                msg: "--bench runs the sim or replay backend only".into(),
            })
        }
    }
    let sink =
        UdpSocket::bind("127.0.0.1:0").map_err(|source| crate::publish::PublishError::Socket {
            family: "IPv4",
            source,
        })?;
    let addr = sink
        .local_addr()
        .map_err(|source| crate::publish::PublishError::Socket {
            family: "IPv4",
            source,
        })?;
    let publisher = Arc::new(Publisher::open(&Outputs {
        destinations: vec![addr],
        multicast: None,
        status_interval: Duration::from_secs(1),
    })?);
    let estimator = crate::build_estimator(&cfg)?;
    let est_name = estimator.name().to_string();
    let (source, _) = crate::open_source(&cfg)?;
    let source_desc = source.describe();
    let stats = Arc::new(Stats::default());
    let engine = Engine {
        source,
        estimator,
        publisher,
        stats: stats.clone(),
        recorder: None,
        attitude: None,
        stop: Arc::new(AtomicBool::new(false)),
        reload: None,
        period: None,
        late_tolerance: cfg.late_tolerance,
        fallback_temp_c: cfg.fallback_temp_c,
        max_frames: Some(frames),
        epoch: Instant::now(),
    };
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    engine.run();
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    drop(sink);
    let n = stats.frames.load(Relaxed);
    Ok(BenchReport {
        frames: n,
        seconds: wall,
        fps: n as f64 / wall.max(1e-9),
        p50_s: stats.latency.quantile(0.5).unwrap_or(f64::NAN),
        p99_s: stats.latency.quantile(0.99).unwrap_or(f64::NAN),
        max_s: stats.latency.max().unwrap_or(f64::NAN),
        cpu_share: cpu / wall.max(1e-9),
        peak_rss_kib: peak_rss_kib(),
        estimator: est_name,
        source: source_desc,
    })
}
