//! `lightposed --bench`: the real per-frame path (simulator → estimator →
//! POSE → UDP send) run as fast as it goes on the calling thread, to measure
//! frames per second, frame-to-datagram latency, CPU share and peak memory
//! against the targets (≥ 10,000 frames/s on one core, p99 < 1 ms,
//! RSS < 20 MiB); and `lightposed --soak`, the same path for an hour of
//! frames with recording on, to show that latency and memory do not drift.
//! `--bench` also reports the daemon's samples per second through the
//! demodulator and the tracker at 20 Hz (spec v3: issue 40's goal, 25
//! channels × 8 kHz in under 25 % of one core).

use crate::config::{Config, Outputs};
use crate::engine::Engine;
use crate::outputs::recorder::{Epoch, Recorder};
use crate::outputs::udp::{PoseDatagrams, PublishError, Publisher};
use crate::stats::Stats;
use crate::wiring::{build_estimator, open_source};
use crate::DaemonError;
use lightpose_core::{Burst, Demodulated, Frame, NDET};
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
use lightpose_hal::Stop;
use std::net::UdpSocket;
use std::sync::atomic::Ordering::Relaxed;
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
    /// Blinking beacons' samples through demodulation and the tracker.
    pub demod: Vec<DemodRow>,
    /// A source that gives bursts: its own, through the frame thread's
    /// parts one by one (`bench_source`).
    pub source_row: Option<crate::bench_source::SourceRow>,
}

/// One row of the demodulation bench: BURST frames of 25 channels ×
/// N = sample_hz / rate_hz samples, demodulated, then the configured
/// estimator on each frame with the amplitudes found; CPU time per frame
/// of each, in the steady state (every beacon locked).
#[derive(Debug, Clone, PartialEq)]
pub struct DemodRow {
    pub sample_hz: f64,
    pub rate_hz: f64,
    pub beacons: usize,
    pub frames: u64,
    /// CPU seconds per frame: the demodulator's, the estimator's.
    pub demod_s: f64,
    pub tracker_s: f64,
}

impl DemodRow {
    /// Samples (all channels) one core takes per second through both.
    pub fn samples_per_s(&self) -> f64 {
        let n = (self.sample_hz / self.rate_hz).round();
        NDET as f64 * n / (self.demod_s + self.tracker_s).max(1e-12)
    }

    /// The share of one core that real time takes: a frame's CPU time at
    /// rate_hz frames a second.
    pub fn core_share(&self) -> f64 {
        (self.demod_s + self.tracker_s) * self.rate_hz
    }
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
            Some(k) => write!(f, "peak rss:   {:.1} MiB (VmHWM)", k as f64 / 1024.0)?,
            None => write!(f, "peak rss:   unknown (no /proc/self/status)")?,
        }
        if let Some(r) = &self.source_row {
            write!(f, "\n{r}")?;
        }
        if self.demod.is_empty() {
            return Ok(());
        }
        writeln!(f)?;
        writeln!(
            f,
            "demodulation (25 channels, BURST frames, then the estimator; CPU time per frame, steady state):"
        )?;
        writeln!(
            f,
            "    sample_hz  rate_hz  beacons  frames  demod µs  tracker µs  samples/s per core  % of one core"
        )?;
        for (i, r) in self.demod.iter().enumerate() {
            write!(
                f,
                "    {:>9.0}  {:>7.0}  {:>7}  {:>6}  {:>8.0}  {:>10.0}  {:>18.2e}  {:>13.2}",
                r.sample_hz,
                r.rate_hz,
                r.beacons,
                r.frames,
                r.demod_s * 1e6,
                r.tracker_s * 1e6,
                r.samples_per_s(),
                r.core_share() * 100.0
            )?;
            if i + 1 < self.demod.len() {
                writeln!(f)?;
            }
        }
        Ok(())
    }
}

/// VmHWM of this process in KiB.
pub fn peak_rss_kib() -> Option<u64> {
    proc_status_kib("VmHWM:")
}

/// VmRSS (resident now) of this process in KiB.
pub fn rss_kib() -> Option<u64> {
    proc_status_kib("VmRSS:")
}

fn proc_status_kib(key: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn cpu_seconds() -> f64 {
    cpu_of(nix::sys::resource::UsageWho::RUSAGE_SELF)
}

/// CPU time of the calling thread: the demodulation bench times one part
/// at a time on it.
fn thread_cpu_seconds() -> f64 {
    cpu_of(nix::sys::resource::UsageWho::RUSAGE_THREAD)
}

fn cpu_of(who: nix::sys::resource::UsageWho) -> f64 {
    use nix::sys::resource::getrusage;
    match getrusage(who) {
        Ok(u) => {
            let tv = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
            tv(u.user_time()) + tv(u.system_time())
        }
        Err(_) => f64::NAN,
    }
}

/// What --bench and --soak drive: the daemon's frame engine on the
/// configured source, free-running and looping, with its estimator and the
/// POSE output to a loopback sink that nobody reads (the kernel drops what
/// overflows; the send cost is real). No deadlines: nothing is paced.
struct Rig {
    engine: Engine,
    /// Held for the run: the datagrams' destination.
    sink: UdpSocket,
    estimator: String,
    source: String,
    adc_bits: u8,
    /// The source's frame clock (a recording's header).
    rate_hz: f64,
    /// What its frames' `t` counts from (a recording's clock record).
    epoch: Epoch,
}

/// The rig for `frames` frames; `sim_clock_hz`: the simulator's frame
/// clock when not the config's.
fn rig(
    cfg: &Config,
    mode: &'static str,
    sim_clock_hz: Option<f64>,
    stats: &Arc<Stats>,
    frames: u64,
) -> Result<Rig, DaemonError> {
    let mut cfg = cfg.clone();
    cfg.backend = cfg
        .backend
        .free_running(sim_clock_hz)
        .ok_or(DaemonError::NotFreeRunning {
            kind: cfg.backend.kind(),
            mode,
        })?;
    let sock_err = |source| PublishError::Socket {
        addr: std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0)),
        source,
    };
    let sink = UdpSocket::bind("127.0.0.1:0").map_err(sock_err)?;
    let addr = sink.local_addr().map_err(sock_err)?;
    let publisher = Arc::new(Publisher::open(&Outputs {
        destinations: vec![addr],
        multicast: None,
        status_interval: Duration::from_secs(1),
    })?);
    let estimator = build_estimator(&cfg)?;
    let source = open_source(&cfg, &Stop::new())?;
    let (est_name, source_desc, adc_bits) = (
        estimator.name().to_string(),
        source.describe(),
        source.adc_bits(),
    );
    let rate_hz = source.rate_hz().unwrap_or(cfg.rate_hz);
    let epoch = Epoch::of(source.t_is_monotonic());
    let engine = Engine::new(source, estimator)
        .stats(stats.clone())
        .period(None)
        .late_tolerance(cfg.late_tolerance)
        .fallback_temp_c(cfg.fallback_temp_c)
        .max_frames(frames)
        .output(Box::new(PoseDatagrams::new(publisher)));
    Ok(Rig {
        engine,
        sink,
        estimator: est_name,
        source: source_desc,
        adc_bits,
        rate_hz,
        epoch,
    })
}

/// Run `frames` frames of the configured simulator (or replay) backend as
/// fast as possible through the daemon's frame path, on this thread.
pub fn bench(cfg: &Config, frames: u64) -> Result<BenchReport, DaemonError> {
    let stats = Arc::new(Stats::default());
    let rig = rig(cfg, "--bench", None, &stats, frames)?;
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    rig.engine.run();
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    drop(rig.sink);
    let n = stats.frames.load(Relaxed);
    // A source of bursts is timed on its own bursts (at its own rate,
    // which the synthetic cases' 20 Hz may not be).
    let source_row = crate::bench_source::source_bench(cfg)?;
    let demod = match source_row {
        Some(_) => Vec::new(),
        None => demod_bench(cfg)?,
    };
    Ok(BenchReport {
        demod,
        source_row,
        frames: n,
        seconds: wall,
        fps: n as f64 / wall.max(1e-9),
        p50_s: stats.latency.quantile(0.5).unwrap_or(f64::NAN),
        p99_s: stats.latency.quantile(0.99).unwrap_or(f64::NAN),
        max_s: stats.latency.max().unwrap_or(f64::NAN),
        cpu_share: cpu / wall.max(1e-9),
        peak_rss_kib: peak_rss_kib(),
        estimator: rig.estimator,
        source: rig.source,
    })
}

/// The demodulation bench's cases: (sample_hz, beacons' mod_hz), each at
/// DEMOD_RATE_HZ. One beacon at 2 and 8 kHz, and four at 8 kHz (MODEL.md's
/// rules: m = 8, 4, 2 and 5 samples per half period, whole periods in a
/// frame of N = 400).
const DEMOD_CASES: [(f64, &[f64]); 3] = [
    (2000.0, &[200.0]),
    (8000.0, &[500.0]),
    (8000.0, &[500.0, 1000.0, 2000.0, 800.0]),
];
const DEMOD_RATE_HZ: f64 = 20.0;
/// Frames demodulated before timing (the beacons locked), and timed.
const DEMOD_WARMUP: usize = 40;
const DEMOD_FRAMES: usize = 400;

/// Each of [`DEMOD_CASES`] through the demodulator and then the
/// configured estimator. The light of each frame is the configured
/// source's (its counts, at 20 Hz, with its readings), made into a BURST:
/// each channel's count is the first beacon's amplitude (the others at
/// 1/2, 1/4, ...), on an ambient with daylight flicker, white noise, the
/// channels' skew, each beacon's clock off by some tens of ppm. The
/// estimator gets the source's frame with the amplitudes found. Every
/// BURST is made before the timing, and each part is timed over all the
/// frames on this thread's CPU clock.
pub fn demod_bench(cfg: &Config) -> Result<Vec<DemodRow>, DaemonError> {
    let mut cfg = cfg.clone();
    cfg.backend =
        cfg.backend
            .free_running(Some(DEMOD_RATE_HZ))
            .ok_or(DaemonError::NotFreeRunning {
                kind: cfg.backend.kind(),
                mode: "--bench",
            })?;
    let mut source = open_source(&cfg, &Stop::new())?;
    // A source of bursts has no frames of counts to make bursts from (its
    // next_frame refuses, every time): its own bursts are timed instead.
    if source.sampling().is_some() {
        return Ok(Vec::new());
    }
    let total = DEMOD_WARMUP + DEMOD_FRAMES;
    let mut frames = Vec::with_capacity(total);
    while frames.len() < total {
        match source.next_frame() {
            Ok(f) => frames.push(f),
            Err(lightpose_hal::SourceError::Ended) => break,
            Err(e) => tracing::warn!("demodulation bench: source: {e}"),
        }
    }
    if frames.len() < total {
        return Ok(Vec::new());
    }
    let mut rows = Vec::new();
    for (sample_hz, hz) in DEMOD_CASES {
        let beacons = hz
            .iter()
            .enumerate()
            .map(|(b, &f)| BeaconSpec::new(format!("b{b}"), f))
            .collect();
        let mut dc = DemodConfig::new(sample_hz, DEMOD_RATE_HZ, beacons);
        // A scan of the 25 channels over 90 % of a sample period.
        dc.channel_skew_s = 0.9 / (sample_hz * NDET as f64);
        // The cases are this file's (a test checks them): not expected.
        let valid = match dc.validate() {
            Ok(v) => v,
            Err(e) => {
                tracing::warn!("demodulation bench at {sample_hz} Hz: {e}");
                continue;
            }
        };
        let bursts: Vec<Burst> = frames
            .iter()
            .enumerate()
            .map(|(j, f)| burst_of(f, j, &dc))
            .collect();
        let mut demod = Demodulator::new(valid);
        let mut outs = vec![demod.output(); total];
        let mut estimator = build_estimator(&cfg)?;
        let mut run_demod = |range: std::ops::Range<usize>, outs: &mut [Demodulated]| {
            for j in range {
                if let Err(e) = demod.demodulate_burst(&bursts[j], &mut outs[j]) {
                    tracing::warn!("demodulation bench: frame {j}: {e}");
                }
            }
        };
        run_demod(0..DEMOD_WARMUP, &mut outs);
        let c0 = thread_cpu_seconds();
        run_demod(DEMOD_WARMUP..total, &mut outs);
        let demod_s = thread_cpu_seconds() - c0;
        let tracked: Vec<Frame> = frames
            .iter()
            .zip(&outs)
            .map(|(f, o)| Frame {
                amplitudes: Some(o.light),
                ..*f
            })
            .collect();
        for f in &tracked[..DEMOD_WARMUP] {
            std::hint::black_box(estimator.estimate(f));
        }
        let c0 = thread_cpu_seconds();
        for f in &tracked[DEMOD_WARMUP..] {
            std::hint::black_box(estimator.estimate(f));
        }
        let tracker_s = thread_cpu_seconds() - c0;
        rows.push(DemodRow {
            sample_hz,
            rate_hz: DEMOD_RATE_HZ,
            beacons: hz.len(),
            frames: DEMOD_FRAMES as u64,
            demod_s: demod_s / DEMOD_FRAMES as f64,
            tracker_s: tracker_s / DEMOD_FRAMES as f64,
        });
    }
    Ok(rows)
}

/// Frame j's light as a BURST of `dc`'s sampling (see [`demod_bench`]).
fn burst_of(f: &Frame, j: usize, dc: &DemodConfig) -> Burst {
    let n = (dc.sample_hz / dc.rate_hz).round() as usize;
    let full = f64::from(f.full_scale());
    let mut b = Burst::new(n);
    let t0 = 1000.0 + j as f64 / dc.rate_hz;
    // A fixed pseudo-random sequence (xorshift), uniform ±3 counts.
    let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ (j as u64).wrapping_mul(0x2545_f491_4f6c_dd1d);
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        6.0 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
    };
    for k in 0..NDET {
        let light = f64::from(f.counts[k]);
        for i in 0..n {
            let t = t0 + i as f64 / dc.sample_hz + k as f64 * dc.channel_skew_s;
            let day = 0.2 * light + 0.05 * light * (2.0 * std::f64::consts::PI * 1.3 * t).sin();
            let mut v = 50.0 + day;
            for (q, beacon) in dc.beacons.iter().enumerate() {
                let hz = beacon.mod_hz * (1.0 + 23e-6 * (q + 1) as f64);
                if (hz * t + 0.17 * q as f64).rem_euclid(1.0) < 0.5 {
                    v += light / (1u32 << q) as f64;
                }
            }
            b.channel_mut(k)[i] = (v + noise()).round().clamp(0.0, full) as u16;
        }
    }
    b.seq = f.seq;
    b.t = t0;
    b.adc_bits = f.adc_bits;
    b.temp_c = f.temp_c;
    b
}

/// Frames of a simulated hour at 1 kHz: the soak's default.
pub const SOAK_FRAMES: u64 = 3_600_000;

/// The simulator's frame clock in the soak.
const SOAK_CLOCK_HZ: f64 = 1000.0;

/// Size at which the soak's recording rotates; the soak deletes all but the
/// two newest files, so its disk use stays under about three of these.
const SOAK_ROTATE_BYTES: u64 = 16 << 20;

/// Latency of one stretch of the soak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    pub frames: u64,
    pub p50_s: f64,
    pub p99_s: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SoakReport {
    pub frames: u64,
    pub seconds: f64,
    pub fps: f64,
    /// The first and the last 10 % of the frames.
    pub first: Stretch,
    pub last: Stretch,
    pub max_s: f64,
    /// VmRSS after the first 10 % and at the end, VmHWM at the end (KiB).
    pub rss_early_kib: Option<u64>,
    pub rss_end_kib: Option<u64>,
    pub peak_rss_kib: Option<u64>,
    pub recorded: u64,
    pub rec_dropped: u64,
    pub rec_failed: u64,
    pub rec_files: u64,
    /// Most bytes the recording directory held at one time.
    pub disk_peak_bytes: u64,
    pub source: String,
    pub estimator: String,
}

impl std::fmt::Display for SoakReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mib = |k: Option<u64>| {
            k.map_or("unknown".into(), |k| {
                format!("{:.1} MiB", k as f64 / 1024.0)
            })
        };
        writeln!(f, "source:     {}", self.source)?;
        writeln!(f, "estimator:  {}", self.estimator)?;
        writeln!(f, "frames:     {} in {:.1} s", self.frames, self.seconds)?;
        writeln!(f, "rate:       {:.0} frames/s", self.fps)?;
        writeln!(f, "latency (frame to datagram sent):")?;
        writeln!(f, "                 first 10 %    last 10 %")?;
        writeln!(
            f,
            "    frames      {:>10}   {:>10}",
            self.first.frames, self.last.frames
        )?;
        writeln!(
            f,
            "    p50         {:>7.1} µs   {:>7.1} µs",
            self.first.p50_s * 1e6,
            self.last.p50_s * 1e6
        )?;
        writeln!(
            f,
            "    p99         {:>7.1} µs   {:>7.1} µs",
            self.first.p99_s * 1e6,
            self.last.p99_s * 1e6
        )?;
        writeln!(f, "    max (whole run) {:.1} µs", self.max_s * 1e6)?;
        writeln!(
            f,
            "memory:     VmRSS {} after 10 %, {} at the end; VmHWM {}",
            mib(self.rss_early_kib),
            mib(self.rss_end_kib),
            mib(self.peak_rss_kib)
        )?;
        write!(
            f,
            "recording:  {} frames in {} files, {} dropped (queue full), {} refused; disk peak {:.1} MiB",
            self.recorded,
            self.rec_files,
            self.rec_dropped,
            self.rec_failed,
            self.disk_peak_bytes as f64 / (1024.0 * 1024.0)
        )
    }
}

/// Bytes in `dir`; deletes all but the `keep` newest logs first (the
/// recorder names them by time and run number, so name order is age order
/// and the newest is the one being written).
fn prune(dir: &std::path::Path, keep: usize) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut logs: Vec<std::path::PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    logs.sort();
    let total = logs
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    let old = logs.len().saturating_sub(keep);
    for p in &logs[..old] {
        if let Err(e) = std::fs::remove_file(p) {
            tracing::warn!("soak: cannot remove {}: {e}", p.display());
        }
    }
    total
}

/// Push `frames` frames of the configured simulator through the whole
/// path as fast as it goes: free-running source → estimator → POSE →
/// `sendto` a loopback sink, with recording on (rotating, old files
/// deleted) in a temporary directory. The engine runs in its own thread, as
/// in the daemon; this thread watches it, snapshots the latency histogram
/// at 10 % and 90 % of the frames, and keeps the disk use bounded.
pub fn soak(cfg: &Config, frames: u64) -> Result<SoakReport, DaemonError> {
    let frames = frames.max(10);
    // Simulated time runs at 1 kHz, so that the default 3.6 M frames are an
    // hour of the board's clock (frame t, recording).
    let stats = Arc::new(Stats::default());
    let rig = rig(cfg, "--soak", Some(SOAK_CLOCK_HZ), &stats, frames)?;
    let dir = std::env::temp_dir().join(format!("lightposed-soak-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(DaemonError::Recorder)?;
    let rec = cfg.recording.as_ref();
    let rec_cfg = crate::config::Recording {
        samples: Default::default(),
        dir: dir.clone(),
        rotate_bytes: Some(SOAK_ROTATE_BYTES),
        rotate_after: None,
        queue: 4096,
        // The configured format, so that the soak measures MCAP too.
        format: rec.map_or_else(Default::default, |r| r.format),
        flush: rec.map_or(crate::config::recording::DEFAULT_FLUSH, |r| r.flush),
        // Old files are deleted by the soak itself.
        keep_free_bytes: None,
        max_total_bytes: None,
        bag: rec.map_or_else(Default::default, |r| r.bag.clone()),
    };
    let header = lightpose_core::LogHeader::new(rig.adc_bits, rig.rate_hz);
    let recorder = Recorder::start(&rec_cfg, header, rig.epoch).map_err(DaemonError::Recorder)?;
    let rec_stats = recorder.stats.clone();
    let engine = rig.engine.output(Box::new(recorder));
    let t0 = Instant::now();
    let worker = std::thread::Builder::new()
        .name("lightposed-frames".into())
        .spawn(move || engine.run())
        .map_err(DaemonError::Thread)?;
    let (tenth, ninth) = (frames / 10, frames - frames / 10);
    let (mut at_tenth, mut at_ninth, mut rss_early) = (None, None, None);
    let mut disk_peak = 0u64;
    let mut last_prune = Instant::now();
    while !worker.is_finished() {
        std::thread::sleep(Duration::from_millis(1));
        let n = stats.frames.load(Relaxed);
        if at_tenth.is_none() && n >= tenth {
            at_tenth = Some((n, stats.latency.snapshot()));
            rss_early = rss_kib();
        }
        if at_ninth.is_none() && n >= ninth {
            at_ninth = Some((n, stats.latency.snapshot()));
        }
        if last_prune.elapsed() >= Duration::from_millis(500) {
            last_prune = Instant::now();
            disk_peak = disk_peak.max(prune(&dir, 2));
        }
    }
    let _ = worker.join();
    let wall = t0.elapsed().as_secs_f64();
    let rss_end = rss_kib();
    disk_peak = disk_peak.max(prune(&dir, 2));
    let n = stats.frames.load(Relaxed);
    let end = stats.latency.snapshot();
    let stretch = |count: u64, h: &crate::stats::HistSnapshot| Stretch {
        frames: count,
        p50_s: h.quantile(0.5).unwrap_or(f64::NAN),
        p99_s: h.quantile(0.99).unwrap_or(f64::NAN),
    };
    let empty = crate::stats::Histogram::default().snapshot();
    let first = match &at_tenth {
        Some((k, h)) => stretch(*k, h),
        None => stretch(0, &empty),
    };
    let last = match &at_ninth {
        Some((k, h)) => stretch(n.saturating_sub(*k), &end.since(h)),
        None => stretch(0, &empty),
    };
    let report = SoakReport {
        frames: n,
        seconds: wall,
        fps: n as f64 / wall.max(1e-9),
        first,
        last,
        max_s: stats.latency.max().unwrap_or(f64::NAN),
        rss_early_kib: rss_early,
        rss_end_kib: rss_end,
        // The kernel updates VmHWM lazily: it can read below a VmRSS seen.
        peak_rss_kib: peak_rss_kib().max(rss_early).max(rss_end),
        recorded: rec_stats.frames.load(Relaxed),
        rec_dropped: rec_stats.dropped.load(Relaxed),
        rec_failed: rec_stats.failed.load(Relaxed),
        rec_files: rec_stats.files.load(Relaxed),
        disk_peak_bytes: disk_peak,
        source: rig.source,
        estimator: rig.estimator,
    };
    if let Err(e) = std::fs::remove_dir_all(&dir) {
        tracing::warn!("soak: cannot remove {}: {e}", dir.display());
    }
    drop(rig.sink);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demod_cases_are_valid_configurations() {
        for (sample_hz, hz) in DEMOD_CASES {
            let beacons = hz
                .iter()
                .enumerate()
                .map(|(b, &f)| BeaconSpec::new(format!("b{b}"), f))
                .collect();
            let mut dc = DemodConfig::new(sample_hz, DEMOD_RATE_HZ, beacons);
            dc.channel_skew_s = 0.9 / (sample_hz * NDET as f64);
            assert!(
                dc.validate().is_ok(),
                "{sample_hz} Hz {hz:?}: {:?}",
                dc.validate()
            );
        }
    }

    #[test]
    fn prune_keeps_the_newest_and_counts_bytes() {
        let d = std::env::temp_dir().join(format!("lightposed-prune-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        for (name, len) in [
            ("a-0001.jsonl", 10),
            ("a-0002.jsonl", 20),
            ("a-0003.jsonl", 30),
        ] {
            std::fs::write(d.join(name), vec![b'x'; len]).unwrap();
        }
        assert_eq!(prune(&d, 2), 60);
        let mut left: Vec<String> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["a-0002.jsonl", "a-0003.jsonl"]);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
