//! The supervisor: the async side of a running daemon. It waits for the
//! shutdown, the end of the frame thread or a calibration reload, sends
//! STATUS at its interval and pings the systemd watchdog while the frame
//! thread is alive; at the end it stops the frame thread, sends a last
//! STATUS and sums the run up.

use crate::config::Config;
use crate::engine::EndReason;
use crate::error::{report, DaemonError};
use crate::notify::{notify, watchdog, NotifyState};
use crate::outputs::StatusTap;
use crate::status::{status_message, StatusCtx};
use crate::wiring::{build_estimator, Running};
use crate::Summary;
use lightpose_core::Estimator;
use lightpose_hal::{Stop, ValidBackend};
use lightpose_pipeline::Calibration;
use std::future::Future;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::Receiver;

/// STATUS and watchdog bookkeeping between ticks.
struct Ticker {
    interval: Duration,
    watchdog: Option<Duration>,
    last_status: Instant,
    seq: u64,
    prev_frames: u64,
    prev_at: Instant,
    /// Outputs that also take each STATUS.
    taps: Vec<Box<dyn StatusTap>>,
}

impl Ticker {
    /// A STATUS when its interval has passed; the watchdog ping while the
    /// frame thread's heartbeat moves.
    fn tick(&mut self, ctx: &StatusCtx) {
        let now = Instant::now();
        if now.duration_since(self.last_status) + Duration::from_millis(5) >= self.interval {
            self.last_status = now;
            let frames = ctx.stats.frames.load(Relaxed);
            let fps = (frames - self.prev_frames) as f64
                / now.duration_since(self.prev_at).as_secs_f64().max(1e-9);
            self.prev_frames = frames;
            self.prev_at = now;
            self.send_status(ctx, fps);
            let line = format!(
                "{} frames, {} late, {} failed, {:.1} fps",
                frames,
                ctx.stats.late.load(Relaxed),
                ctx.stats.failed.load(Relaxed),
                fps
            );
            notify(&[NotifyState::Status(&line)]);
        }
        if let Some(w) = self.watchdog {
            // Ping only while the frame thread is alive and not stuck.
            let beat = Duration::from_nanos(ctx.stats.heartbeat_ns.load(Relaxed));
            let silent = ctx.started.elapsed().saturating_sub(beat);
            if silent < w {
                notify(&[NotifyState::Watchdog]);
            } else {
                tracing::error!("frame thread silent for {silent:?}: withholding the watchdog");
            }
        }
    }

    fn send_status(&mut self, ctx: &StatusCtx, fps: f64) {
        let msg = status_message(ctx, self.seq, fps);
        self.seq += 1;
        if let Ok(bytes) = serde_json::to_vec(&msg) {
            ctx.publisher.send(&bytes);
            for t in &self.taps {
                t.status(&bytes);
            }
        }
    }
}

/// The ADC of the running source's frames: a board's configured
/// resolution, or, for the sources that open no device (a simulated
/// scene, a replayed log's header), what the source says once opened
/// again. (`Running` does not carry the source's `adc_bits`.)
fn source_adc_bits(backend: &ValidBackend) -> Result<u8, String> {
    match backend {
        ValidBackend::Spi { common, .. }
        | ValidBackend::Ads1115 { common, .. }
        | ValidBackend::Ads7828 { common, .. }
        | ValidBackend::Serial { common, .. } => Ok(common.bits),
        ValidBackend::Sim(_) | ValidBackend::Replay(_) => {
            lightpose_hal::open(backend, &Stop::new())
                .map(|s| s.adc_bits())
                .map_err(|e| report(&e))
        }
    }
}

/// The estimator of the calibration `cfg` names, refused as at start when
/// its light model is of another ADC than the source's frames
/// (`lightpose_pipeline::reads_frames_of`).
fn reloaded(cfg: &Config, adc_bits: u8) -> Result<Box<dyn Estimator>, DaemonError> {
    let estimator = build_estimator(cfg)?;
    let text = cfg
        .calibration
        .read()
        .map_err(|source| DaemonError::CalibrationRead {
            at: cfg.calibration_at.clone(),
            source,
        })?;
    let cal = Calibration::parse(&text, &cfg.calibration.describe())?;
    lightpose_pipeline::reads_frames_of(estimator.as_ref(), &cal, adc_bits).map_err(|msg| {
        DaemonError::AdcMismatch {
            backend: cfg.backend.kind(),
            msg,
        }
    })?;
    Ok(estimator)
}

/// A new estimator for the frame thread, or why the running one is kept:
/// a calibration that does not load, or whose light model is of another
/// ADC than the frames (the start refuses both).
fn reload(cfg: &Config, to_frames: &std::sync::mpsc::Sender<Box<dyn Estimator>>) {
    let file = cfg.calibration.describe();
    let checked = source_adc_bits(&cfg.backend)
        .map_err(|e| format!("cannot tell the ADC of the backend's frames: {e}"))
        .and_then(|bits| reloaded(cfg, bits).map_err(|e| report(&e)));
    match checked {
        Ok(e) => {
            tracing::info!("reloading calibration {file}");
            let _ = to_frames.send(e);
        }
        Err(why) => tracing::error!(
            "reload of calibration {file} refused, keeping the running calibration: {why}"
        ),
    }
}

/// Watch `d` until `shutdown` completes or the frame thread ends; each
/// message on `reloads` reloads the calibration.
pub async fn supervise(
    cfg: &Config,
    mut d: Running,
    shutdown: impl Future<Output = ()>,
    mut reloads: Receiver<()>,
) -> Summary {
    let watchdog = watchdog();
    let interval = cfg.outputs.status_interval;
    // STATUS at its interval; the watchdog at half its timeout if shorter.
    let mut tick = tokio::time::interval(watchdog.map_or(interval, |w| interval.min(w / 2)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut ticker = Ticker {
        interval,
        watchdog,
        last_status: Instant::now() - interval,
        seq: 0,
        prev_frames: 0,
        prev_at: Instant::now(),
        taps: std::mem::take(&mut d.status_taps),
    };
    // The hub outlives the tasks it is taken from (the last STATUS reads it).
    let vehicle_hub = d.vehicle.as_ref().map(|v| v.hub.clone());
    let ctx = StatusCtx {
        cfg,
        stats: &d.stats,
        rec: d.rec_stats.as_deref(),
        att: d.attitude.as_deref(),
        live: d.live.as_deref(),
        vehicle: vehicle_hub.as_deref(),
        publisher: &d.publisher,
        source: &d.source,
        estimator: d.estimator,
        started: d.started,
    };
    tokio::pin!(shutdown);
    let mut reload_open = true;
    let end = loop {
        tokio::select! {
            _ = &mut shutdown => {
                tracing::info!("shutdown requested");
                notify(&[NotifyState::Stopping]);
                break None;
            }
            r = &mut d.done => break r.ok(),
            msg = reloads.recv(), if reload_open => match msg {
                None => reload_open = false,
                Some(()) => reload(cfg, &d.reload),
            },
            _ = tick.tick() => ticker.tick(&ctx),
        }
    };
    if let Some(h) = d.listener.take() {
        h.abort();
    }
    if let Some(h) = d.live_server.take() {
        h.abort();
    }
    let reason = stop(&d.stop, d.frames.take(), end).await;
    if let Some(v) = d.vehicle.take() {
        v.stop().await;
    }
    if let Some(hub) = &d.live {
        hub.close();
    }
    // A last STATUS so that subscribers see the final counts and state.
    ticker.send_status(&ctx, 0.0);
    summary(&ctx, reason)
}

/// How long a stop waits for the frame thread: its waits end on the stop
/// and the recorder's flush is bounded (2 s), so only a device read that
/// hangs in the kernel can take longer; the daemon then exits without it,
/// well within systemd's TimeoutStopSec (10 s).
const JOIN_BOUND: Duration = Duration::from_secs(4);

/// Stop the frame thread (it finishes its frame and flushes the
/// recording); why it ended.
async fn stop(
    stop: &Stop,
    frames: Option<std::thread::JoinHandle<EndReason>>,
    ended: Option<EndReason>,
) -> EndReason {
    stop.raise();
    let joined = match frames {
        Some(f) => {
            let join = tokio::task::spawn_blocking(move || f.join());
            match tokio::time::timeout(JOIN_BOUND, join).await {
                Ok(j) => j.ok(),
                Err(_) => {
                    tracing::error!(
                        "the frame thread did not stop within {JOIN_BOUND:?} (a device read hangs?): exiting without it"
                    );
                    None
                }
            }
        }
        None => None,
    };
    match (ended, joined) {
        (Some(r), _) => r,
        (None, Some(Ok(r))) => r,
        _ => EndReason::Stopped,
    }
}

fn summary(ctx: &StatusCtx, reason: EndReason) -> Summary {
    let s = ctx.stats;
    let summary = Summary {
        frames: s.frames.load(Relaxed),
        late: s.late.load(Relaxed),
        failed: s.failed.load(Relaxed),
        lost: s.lost.load(Relaxed),
        recorded: ctx.rec.map_or(0, |r| r.frames.load(Relaxed)),
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
    summary
}
