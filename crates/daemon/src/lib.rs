//! lightposed as a library: [`run`] takes a validated [`Config`], the
//! publishing sockets and a shutdown future, so that tests can run a whole
//! daemon in-process on port-0 sockets and stop it when they like (the
//! mini-redis layout); the binary only parses arguments, loads the config
//! and maps errors to an exit code.

pub mod attitude;
pub mod bench;
pub mod config;
pub mod engine;
pub mod publish;
pub mod recorder;
pub mod replay;
pub mod simsource;
pub mod stats;

pub use config::{Config, ConfigError};
pub use publish::Publisher;

use crate::attitude::AttitudeCell;
use crate::config::{Backend, Pace};
use crate::engine::{EndReason, Engine};
use crate::recorder::{RecStats, Recorder};
use crate::stats::{Stats, TempSource};
use lightpose_core::{Estimator, LogHeader, Status};
use lightpose_hal::FrameSource;
use lightpose_pipeline::Calibration;
use serde_json::json;
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Version of the message set (POSE, STATUS, VERSION) on the wire.
pub const PROTO: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("calibration {0}: {1}")]
    CalibrationRead(String, std::io::Error),
    #[error("{0}")]
    Calibration(String),
    #[error("estimator: {0}")]
    Estimator(String),
    #[error("backend {kind}: {msg}")]
    Backend { kind: String, msg: String },
    #[error(transparent)]
    Publish(#[from] publish::PublishError),
    #[error("attitude.listen {addr}: {source}")]
    AttitudeBind {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("recording: cannot start the recorder thread: {0}")]
    Recorder(std::io::Error),
    #[error("cannot start the acquisition thread: {0}")]
    Thread(std::io::Error),
}

/// What a run did, for the caller's last log line and for tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    pub frames: u64,
    pub late: u64,
    pub failed: u64,
    pub lost: u64,
    pub recorded: u64,
    pub source_ended: bool,
}

/// Load the calibration and build the configured estimator (at start and
/// on SIGHUP).
pub fn build_estimator(cfg: &Config) -> Result<Box<dyn Estimator>, DaemonError> {
    let name = cfg.calibration.describe();
    let text = cfg
        .calibration
        .read()
        .map_err(|e| DaemonError::CalibrationRead(name.clone(), e))?;
    let cal =
        Calibration::parse(&text, &name).map_err(|e| DaemonError::Calibration(e.to_string()))?;
    lightpose_pipeline::build_estimator(&cfg.estimator, &cal)
        .map_err(|e| DaemonError::Estimator(e.to_string()))
}

/// Open the configured frame source and the period it is expected to keep
/// (`None`: as fast as possible, no deadlines).
pub fn open_source(cfg: &Config) -> Result<(Box<dyn FrameSource>, Option<Duration>), DaemonError> {
    let period = |rate: f64| Some(Duration::from_secs_f64(1.0 / rate));
    match &cfg.backend {
        Backend::Sim(s) => {
            let src = simsource::open(s, cfg.rate_hz).map_err(|e| DaemonError::Backend {
                kind: "sim".into(),
                msg: e.to_string(),
            })?;
            let p = if s.pace == Pace::Fast {
                None
            } else {
                period(cfg.rate_hz)
            };
            Ok((Box::new(src), p))
        }
        Backend::Replay(r) => {
            let src = replay::ReplaySource::open(r).map_err(|e| DaemonError::Backend {
                kind: "replay".into(),
                msg: e.to_string(),
            })?;
            // A replay keeps the log's own rate, not the config's.
            let p = if r.pace == Pace::Fast {
                None
            } else {
                period(src.rate_hz())
            };
            Ok((Box::new(src), p))
        }
        Backend::Hardware { kind, rate_hz, hal } => {
            let src = lightpose_hal::open_source(hal).map_err(|e| DaemonError::Backend {
                kind: kind.clone(),
                msg: e.to_string(),
            })?;
            Ok((src, rate_hz.and_then(period)))
        }
    }
}

fn unix_now() -> f64 {
    recorder::unix_now()
}

fn opt(v: Option<f64>) -> serde_json::Value {
    v.and_then(lightpose_core::finite)
        .map_or(serde_json::Value::Null, Into::into)
}

/// The VERSION banner sent once at start.
pub fn version_message(cfg: &Config, source: &str, estimator: &str) -> Vec<u8> {
    let v = json!({
        "class": "VERSION",
        "seq": 0,
        "t": unix_now(),
        "name": "lightposed",
        "release": env!("CARGO_PKG_VERSION"),
        "proto": PROTO,
        "backend": cfg.backend.kind(),
        "source": source,
        "estimator": estimator,
        "calibration": cfg.calibration.describe(),
        "rate_hz": cfg.rate_hz,
    });
    serde_json::to_vec(&v).unwrap_or_default()
}

struct StatusCtx<'a> {
    cfg: &'a Config,
    stats: &'a Stats,
    rec: Option<&'a RecStats>,
    att: Option<&'a AttitudeCell>,
    publisher: &'a Publisher,
    source: &'a str,
    estimator: &'a str,
    started: Instant,
}

fn status_message(c: &StatusCtx, seq: u64, fps: f64) -> serde_json::Value {
    let s = c.stats;
    let now = Instant::now();
    let (temp, tsrc) = s.temp();
    let last_status = Status::ALL
        .get(s.last_status.load(Relaxed) as usize)
        .map_or("none", |st| st.as_str());
    let counts: serde_json::Map<String, serde_json::Value> = Status::ALL
        .iter()
        .zip(&s.by_status)
        .map(|(st, n)| (st.as_str().to_string(), n.load(Relaxed).into()))
        .collect();
    let recording = match c.rec {
        None => json!({"state": "off"}),
        Some(r) => json!({
            "state": r.state().as_str(),
            "file": r.current.lock().ok().and_then(|g| g.clone()),
            "frames": r.frames.load(Relaxed),
            "failed": r.failed.load(Relaxed),
            "dropped": r.dropped.load(Relaxed),
            "files": r.files.load(Relaxed),
            "bytes": r.bytes.load(Relaxed),
            "error": r.error.lock().ok().and_then(|g| g.clone()),
        }),
    };
    let health = s.source_health.lock().ok().and_then(|h| h.clone());
    let sensor = health.as_ref().and_then(|h| h.temp.as_ref());
    // hal stamps its own fallback on the frame when its sensor fails, so
    // `source` alone would say "frame" during a sensor outage: `fallback`
    // and `error` say plainly whether the value in use is a stand-in and why.
    let sensor_fallback = sensor.is_some_and(|t| t.fallback_active);
    let mut temperature = json!({
        "c": opt(temp),
        "source": tsrc.as_str(),
        "fallback_c": opt(c.cfg.fallback_temp_c),
        "fallback": sensor_fallback || tsrc == TempSource::Fallback,
        "error": if sensor_fallback { sensor.and_then(|t| t.last_error.clone()) } else { None },
    });
    if let Some(t) = sensor {
        temperature["sensor"] = json!({
            "kind": t.source,
            "fallback_active": t.fallback_active,
            "fallbacks": t.fallbacks,
            "last_error": t.last_error,
        });
    }
    let attitude = match c.att {
        None => json!({"enabled": false}),
        Some(a) => json!({
            "enabled": true,
            "received": a.received.load(Relaxed),
            "rejected": a.rejected.load(Relaxed),
            "age": a.age(now).map(|d| d.as_secs_f64()),
            "frames_with": s.frames_with_attitude.load(Relaxed),
        }),
    };
    let outputs: Vec<serde_json::Value> = c
        .publisher
        .destinations()
        .iter()
        .map(|d| {
            json!({
                "addr": d.addr.to_string(),
                "multicast": d.multicast,
                "sent": d.stats.sent.load(Relaxed),
                "errors": d.stats.errors.load(Relaxed),
                "last_error": d.stats.last_error.lock().ok().and_then(|g| g.clone()),
            })
        })
        .collect();
    json!({
        "class": "STATUS",
        "seq": seq,
        "t": unix_now(),
        "uptime": c.started.elapsed().as_secs_f64(),
        "backend": {
            "kind": c.cfg.backend.kind(),
            "source": c.source,
            "state": s.state().as_str(),
            "last_error": s.last_error.lock().ok().and_then(|g| g.clone()),
            "health": health.as_ref().map(|h| json!({
                "bad_lines": h.bad_lines,
                "wrong_board_lines": h.wrong_board_lines,
                "last_bad_line": h.last_bad_line,
                "reopens": h.reopens,
                "injected_faults": h.injected_faults,
            })),
        },
        "frames": s.frames.load(Relaxed),
        "late": s.late.load(Relaxed),
        "failed": s.failed.load(Relaxed),
        "lost": s.lost.load(Relaxed),
        "last_seq": s.last_seq.load(Relaxed),
        "fps": fps,
        "latency": {
            "p50": opt(s.latency.quantile(0.5)),
            "p99": opt(s.latency.quantile(0.99)),
            "max": opt(s.latency.max()),
        },
        "estimator": {
            "name": c.estimator,
            "status": last_status,
            "counts": counts,
            "calibration": c.cfg.calibration.describe(),
            "reloads": s.calibration_reloads.load(Relaxed),
        },
        "temperature": temperature,
        "recording": recording,
        "attitude": attitude,
        "outputs": outputs,
    })
}

/// systemd notifications; no-ops when not run by systemd (no NOTIFY_SOCKET).
fn notify(states: &[sd_notify::NotifyState]) {
    if std::env::var_os("NOTIFY_SOCKET").is_some() {
        if let Err(e) = sd_notify::notify(false, states) {
            tracing::debug!("sd_notify: {e}");
        }
    }
}

/// Run the daemon until `shutdown` completes or the source ends.
pub async fn run(
    cfg: Config,
    publisher: Publisher,
    shutdown: impl Future<Output = ()>,
) -> Result<Summary, DaemonError> {
    let (_tx, rx) = tokio::sync::mpsc::channel(1);
    run_with_reload(cfg, publisher, shutdown, rx).await
}

/// As [`run`], and each message on `reload` reloads the calibration
/// (SIGHUP in the binary). A calibration that fails to load is reported and
/// the running one is kept.
pub async fn run_with_reload(
    cfg: Config,
    publisher: Publisher,
    shutdown: impl Future<Output = ()>,
    mut reload: tokio::sync::mpsc::Receiver<()>,
) -> Result<Summary, DaemonError> {
    let started = Instant::now();
    let estimator = build_estimator(&cfg)?;
    let est_name = estimator.name();
    let (source, period) = open_source(&cfg)?;
    let source_desc = source.describe();
    let publisher = Arc::new(publisher);
    let stats = Arc::new(Stats::default());

    let mut att_listener = None;
    let att_for_engine = match &cfg.attitude {
        Some(a) => {
            let sock = tokio::net::UdpSocket::bind(a.listen)
                .await
                .map_err(|source| DaemonError::AttitudeBind {
                    addr: a.listen,
                    source,
                })?;
            let cell = Arc::new(AttitudeCell::default());
            tracing::info!("attitude input on {}", a.listen);
            att_listener = Some(tokio::spawn(attitude::listen(
                sock,
                a.clone(),
                cell.clone(),
            )));
            Some((cell, a.max_age))
        }
        None => None,
    };

    let recorder = match &cfg.recording {
        Some(r) => {
            let mut h = LogHeader::new(
                source.adc_bits(),
                period.map_or(cfg.rate_hz, |p| 1.0 / p.as_secs_f64()),
            );
            h.extra.insert(
                "recorder".into(),
                format!("lightposed {}", env!("CARGO_PKG_VERSION")).into(),
            );
            h.extra.insert("source".into(), source_desc.clone().into());
            Some(Recorder::start(r, h).map_err(DaemonError::Recorder)?)
        }
        None => None,
    };
    let rec_stats = recorder.as_ref().map(|r| r.stats.clone());

    let version = version_message(&cfg, &source_desc, est_name);
    publisher.send(&version);

    let stop = Arc::new(AtomicBool::new(false));
    let (reload_tx, reload_rx) = std::sync::mpsc::channel::<Box<dyn Estimator>>();
    let (done_tx, mut done_rx) = tokio::sync::oneshot::channel::<EndReason>();
    let engine = Engine {
        source,
        estimator,
        publisher: publisher.clone(),
        stats: stats.clone(),
        recorder,
        attitude: att_for_engine.clone(),
        stop: stop.clone(),
        reload: Some(reload_rx),
        period,
        late_tolerance: cfg.late_tolerance,
        fallback_temp_c: cfg.fallback_temp_c,
        max_frames: None,
        epoch: started,
    };
    let thread = std::thread::Builder::new()
        .name("lightposed-frames".into())
        .spawn(move || {
            let r = engine.run();
            let _ = done_tx.send(r.clone());
            r
        })
        .map_err(DaemonError::Thread)?;

    notify(&[sd_notify::NotifyState::Ready]);
    tracing::info!("running: {source_desc}; estimator {est_name}");

    let mut wd_usec = 0u64;
    let watchdog =
        sd_notify::watchdog_enabled(false, &mut wd_usec).then(|| Duration::from_micros(wd_usec));
    // STATUS at its interval; the watchdog at half its timeout if shorter.
    let tick_every = match watchdog {
        Some(w) => cfg.outputs.status_interval.min(w / 2),
        None => cfg.outputs.status_interval,
    };
    let mut tick = tokio::time::interval(tick_every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_status = Instant::now() - cfg.outputs.status_interval;
    let mut status_seq = 0u64;
    let mut prev_frames = 0u64;
    let mut prev_at = Instant::now();
    let ctx = StatusCtx {
        cfg: &cfg,
        stats: &stats,
        rec: rec_stats.as_deref(),
        att: att_for_engine.as_ref().map(|(c, _)| c.as_ref()),
        publisher: &publisher,
        source: &source_desc,
        estimator: est_name,
        started,
    };
    tokio::pin!(shutdown);
    let mut reload_open = true;
    let end = loop {
        tokio::select! {
            _ = &mut shutdown => {
                tracing::info!("shutdown requested");
                notify(&[sd_notify::NotifyState::Stopping]);
                break None;
            }
            r = &mut done_rx => break r.ok(),
            msg = reload.recv(), if reload_open => {
                match msg {
                    None => reload_open = false,
                    Some(()) => match build_estimator(&cfg) {
                        Ok(e) => {
                            tracing::info!("reloading calibration {}", cfg.calibration.describe());
                            let _ = reload_tx.send(e);
                        }
                        Err(e) => tracing::error!("reload refused, keeping the running calibration: {e}"),
                    },
                }
            }
            _ = tick.tick() => {
                let now = Instant::now();
                if now.duration_since(last_status) + Duration::from_millis(5) >= cfg.outputs.status_interval {
                    last_status = now;
                    let frames = stats.frames.load(Relaxed);
                    let fps = (frames - prev_frames) as f64 / now.duration_since(prev_at).as_secs_f64().max(1e-9);
                    prev_frames = frames;
                    prev_at = now;
                    let msg = status_message(&ctx, status_seq, fps);
                    status_seq += 1;
                    if let Ok(bytes) = serde_json::to_vec(&msg) {
                        publisher.send(&bytes);
                    }
                    let line = format!("{} frames, {} late, {} failed, {:.1} fps", frames, stats.late.load(Relaxed), stats.failed.load(Relaxed), fps);
                    notify(&[sd_notify::NotifyState::Status(&line)]);
                }
                if let Some(w) = watchdog {
                    // Ping only while the frame thread is alive and not stuck.
                    let beat = Duration::from_nanos(stats.heartbeat_ns.load(Relaxed));
                    if started.elapsed().saturating_sub(beat) < w {
                        notify(&[sd_notify::NotifyState::Watchdog]);
                    } else {
                        tracing::error!("frame thread silent for {:?}: withholding the watchdog", started.elapsed().saturating_sub(beat));
                    }
                }
            }
        }
    };
    stop.store(true, Relaxed);
    if let Some(h) = att_listener {
        h.abort();
    }
    // The frame thread finishes its frame and flushes the recording.
    let reason = match end {
        Some(r) => {
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
            r
        }
        None => match tokio::task::spawn_blocking(move || thread.join()).await {
            Ok(Ok(r)) => r,
            _ => EndReason::Stopped,
        },
    };
    // A last STATUS so that subscribers see the final counts and state.
    let msg = status_message(&ctx, status_seq, 0.0);
    if let Ok(bytes) = serde_json::to_vec(&msg) {
        publisher.send(&bytes);
    }
    let summary = Summary {
        frames: stats.frames.load(Relaxed),
        late: stats.late.load(Relaxed),
        failed: stats.failed.load(Relaxed),
        lost: stats.lost.load(Relaxed),
        recorded: rec_stats.as_ref().map_or(0, |r| r.frames.load(Relaxed)),
        source_ended: reason == EndReason::SourceEnded,
    };
    tracing::info!(
        "stopped ({:?}): {} frames, {} late, {} failed, {} lost, {} recorded",
        reason,
        summary.frames,
        summary.late,
        summary.failed,
        summary.lost,
        summary.recorded
    );
    Ok(summary)
}
