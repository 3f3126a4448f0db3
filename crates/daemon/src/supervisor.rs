//! The supervisor: the async side of a running daemon. It waits for the
//! shutdown, the end of the frame thread or a calibration reload, sends
//! STATUS at its interval and pings the systemd watchdog while the frame
//! thread is alive; at the end it stops the frame thread, sends a last
//! STATUS and sums the run up. A frame thread that panicked is a failure
//! ([`EndReason::Panicked`]: one ERROR line, a non-zero exit), not a stop.

use crate::config::Config;
use crate::engine::EndReason;
use crate::notify::{notify, watchdog, NotifyState};
use crate::outputs::StatusTap;
use crate::reload::Reloads;
use crate::status::{status_message, StatusCtx};
use crate::wiring::Running;
use crate::Summary;
use lightpose_core::ratelog::Close;
use lightpose_hal::Stop;
use lightpose_vehicle::readings::ReadingsStatus;
use lightpose_vehicle::stale::{Change, SilenceWatch, StaleWatch, Voice};
use lightpose_vehicle::MaxAge;
use std::any::Any;
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
    /// The frame thread's stop, whose waits beat while they wait.
    alive: Stop,
    /// The vehicle's readings going stale and coming back, told; the
    /// attitude input's apart.
    stale: Option<StaleWatch>,
    stale_input: Option<StaleWatch>,
    /// The autopilot's heartbeat (with a MAVLink link).
    autopilot: Option<SilenceWatch>,
}

impl Ticker {
    /// STATUS every `interval`, the watchdog pinged within `watchdog`, the
    /// taps taken from `d`, and a watch on each reading source `cfg` has.
    fn new(cfg: &Config, d: &mut Running, interval: Duration, watchdog: Option<Duration>) -> Self {
        Ticker {
            interval,
            watchdog,
            last_status: Instant::now() - interval,
            seq: 0,
            prev_frames: 0,
            prev_at: Instant::now(),
            taps: std::mem::take(&mut d.status_taps),
            alive: d.stop.clone(),
            stale: cfg.vehicle.as_ref().map(|v| StaleWatch::new(v.max_age)),
            autopilot: cfg
                .vehicle
                .as_ref()
                .and_then(|v| v.mavlink.as_ref())
                .map(|_| SilenceWatch::new(AUTOPILOT_SILENT)),
            stale_input: cfg.attitude.as_ref().map(|a| {
                StaleWatch::new(MaxAge {
                    attitude: a.max_age,
                    ..MaxAge::default()
                })
            }),
        }
    }

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
            if let (Some(w), Some(hub)) = (&mut self.stale, ctx.vehicle) {
                w.look(&hub.readings.status(now), now, |c| tell_stale("vehicle", c));
                w.close(now, Close::Over, |c| tell_stale("vehicle", c));
            }
            if let (Some(w), Some(hub)) = (&mut self.autopilot, ctx.vehicle) {
                // The age alone: a whole `status` (tables, strings) was
                // built for it, beside the one STATUS builds.
                let age = hub.mavlink.autopilot_heartbeat_age_s(now);
                if let Some(v) = w.look(age, now.duration_since(ctx.started), now) {
                    tell_voice(v);
                }
                if let Some(v) = w.close(now, Close::Over) {
                    tell_voice(v);
                }
            }
            if let (Some(w), Some(att)) = (&mut self.stale_input, ctx.att) {
                let st = ReadingsStatus::only_attitude(att.status(now));
                w.look(&st, now, |c| tell_stale("attitude input", c));
                w.close(now, Close::Over, |c| tell_stale("attitude input", c));
            }
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
            // Ping only while the frame thread is alive and not stuck: it
            // beats its stop once a frame, and while it waits as configured
            // (a frame due later, a board given `timeout_ms` to answer) its
            // waits beat it at least once a second. A read that
            // never returns does not beat.
            let silent = self.alive.since_beat();
            if silent < w {
                notify(&[NotifyState::Watchdog]);
            } else {
                tracing::error!("frame thread silent for {silent:?}: withholding the watchdog");
            }
        }
    }

    /// At stop: the stale and silent episodes not told yet.
    fn close_watches(&mut self) {
        let now = Instant::now();
        if let Some(w) = &mut self.stale {
            w.close(now, Close::AtStop, |c| tell_stale("vehicle", c));
        }
        if let Some(w) = &mut self.stale_input {
            w.close(now, Close::AtStop, |c| tell_stale("attitude input", c));
        }
        if let Some(v) = self
            .autopilot
            .as_mut()
            .and_then(|w| w.close(now, Close::AtStop))
        {
            tell_voice(v);
        }
    }

    fn send_status(&mut self, ctx: &StatusCtx, fps: f64) {
        let msg = status_message(ctx, self.seq, fps);
        self.seq += 1;
        if let Ok(bytes) = serde_json::to_vec(&msg) {
            ctx.publisher.send(&bytes);
            // The destinations' closing lines (send errors that stopped):
            // STATUS comes whatever happens, POSE only with frames.
            ctx.publisher.settle(Instant::now());
            for t in &self.taps {
                t.status(&bytes);
            }
        }
    }
}

/// Watch `d` until `shutdown` completes or the frame thread ends; each
/// message on `reloads` reloads the calibration.
pub async fn supervise(
    cfg: &Config,
    d: Running,
    shutdown: impl Future<Output = ()>,
    reloads: Receiver<()>,
) -> Summary {
    supervise_to_end(cfg, d, shutdown, reloads).await.0
}

/// As [`supervise`], and why the frame thread ended: the binary exits
/// non-zero when that is a failure ([`EndReason::is_failure`]).
pub async fn supervise_to_end(
    cfg: &Config,
    mut d: Running,
    shutdown: impl Future<Output = ()>,
    mut reloads: Receiver<()>,
) -> (Summary, EndReason) {
    let watchdog = watchdog();
    let interval = cfg.outputs.status_interval;
    // STATUS at its interval; the watchdog at half its timeout if shorter.
    let mut tick = tokio::time::interval(watchdog.map_or(interval, |w| interval.min(w / 2)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut ticker = Ticker::new(cfg, &mut d, interval, watchdog);
    // The hub outlives the tasks it is taken from (the last STATUS reads it).
    let vehicle_hub = d.vehicle.as_ref().map(|v| v.hub.clone());
    let ctx = StatusCtx {
        cfg,
        stats: &d.stats,
        rec: d.rec_stats.as_deref(),
        att: d.attitude.as_deref(),
        live: d.live.as_deref(),
        web: d.web.as_deref(),
        #[cfg(feature = "ros2")]
        ros2: d.ros2.as_deref(),
        vehicle: vehicle_hub.as_deref(),
        publisher: &d.publisher,
        source: &d.source,
        estimator: d.estimator,
        started: d.started,
    };
    tokio::pin!(shutdown);
    let mut reload_open = true;
    let mut rl = Reloads::new(cfg, &d);
    // The page's reloads (`[web] control`) beside SIGHUP's.
    let web = d.web.clone();
    let web_reload = page_reload(web.as_deref());
    tokio::pin!(web_reload);
    let end = loop {
        let wake = rl.wake_at();
        tokio::select! {
            _ = &mut shutdown => {
                tracing::info!("shutdown requested");
                notify(&[NotifyState::Stopping]);
                break Seen::Shutdown;
            }
            // A thread that panicked drops its end of `done` unsent.
            r = &mut d.done => break r.map_or(Seen::Vanished, Seen::Ended),
            msg = reloads.recv(), if reload_open => match msg {
                None => reload_open = false,
                Some(()) => rl.ask(),
            },
            () = &mut web_reload => {
                web_reload.set(page_reload(web.as_deref()));
                rl.ask();
            }
            () = rl.finished() => rl.start(),
            () = tokio::time::sleep_until(wake.unwrap_or_else(tokio::time::Instant::now)), if wake.is_some() => rl.start(),
            _ = tick.tick() => {
                ticker.tick(&ctx);
                rl.close(Close::Over);
                rl.check_slow();
            }
        }
    };
    rl.close(Close::AtStop);
    ticker.close_watches();
    // Aborted, and awaited (an abort ends them at their next poll; bounded
    // all the same, as the vehicle's stop is): their logs tell what is
    // pending as they are dropped (at stop), before the summary.
    if let Some(w) = &d.web {
        w.close();
    }
    for h in [d.listener.take(), d.live_server.take(), d.web_server.take()]
        .into_iter()
        .flatten()
    {
        h.abort();
        let _ = tokio::time::timeout(Duration::from_secs(2), h).await;
    }
    let reason = stop(&d.stop, d.frames.take(), end).await;
    if let Some(v) = d.vehicle.take() {
        v.stop().await;
    }
    if let Some(hub) = &d.live {
        hub.close();
    }
    // A last STATUS so that subscribers see the final counts and state;
    // then what the log was not told yet of the send errors and of the
    // STATUS the taps dropped, so that the journal's counts add up to it.
    ticker.send_status(&ctx, 0.0);
    ctx.publisher.flush(Instant::now());
    for t in &ticker.taps {
        t.stop();
    }
    (summary(&ctx, &reason), reason)
}

/// Resolves when the page asks for a calibration reload; never without
/// the page.
async fn page_reload(web: Option<&crate::outputs::web::WebFeed>) {
    match web {
        Some(w) => w.reload.notified().await,
        None => std::future::pending().await,
    }
}

/// A reading that stopped reaching the frames (a DVL whose reports come
/// older than their limit, an autopilot that stopped streaming one while
/// its link is up), or is back: one line each way.
fn tell_stale(input: &str, c: Change) {
    match c {
        Change::Stale {
            reading,
            age_s,
            max_age_s,
            episodes,
        } => tracing::warn!(
            reading,
            age_s,
            stale_episodes_since_last_line = episodes,
            "{input}: {reading} reading stale: the latest was taken {} ago, over its limit of {max_age_s} s; frames go without it until a fresh one comes",
            age_s.map_or("?".to_string(), |a| format!("{a:.2} s"))
        ),
        Change::Back {
            reading,
            after_s,
            frames_without,
        } => tracing::info!(
            reading,
            frames_without,
            "{input}: {reading} reading back after {after_s:.1} s stale: {frames_without} frames went without it"
        ),
        Change::Untold {
            reading,
            episodes,
            when,
        } => tracing::warn!(
            reading,
            stale_episodes_since_last_line = episodes,
            "{input}: {reading} reading went stale and back: {when}: {episodes} more times since the last line"
        ),
    }
}

/// The autopilot is silent once three heartbeats (1 Hz) are missed.
const AUTOPILOT_SILENT: Duration = Duration::from_secs(3);

/// The autopilot falling silent, or heard again: one line each way.
fn tell_voice(v: Voice) {
    match v {
        Voice::Silent {
            age_s: Some(a),
            limit_s,
            episodes,
        } => tracing::warn!(
            age_s = a,
            silences_since_last_line = episodes,
            "MAVLink: no HEARTBEAT from the autopilot for {a:.1} s (over {limit_s} s): poses go on being sent; readings from it go stale"
        ),
        Voice::Silent {
            age_s: None,
            limit_s,
            ..
        } => tracing::warn!(
            "MAVLink: no HEARTBEAT from the autopilot in the {limit_s} s since the start: check the connection and autopilot_system_id; poses go on being sent"
        ),
        Voice::Untold { episodes, when } => tracing::warn!(
            silences_since_last_line = episodes,
            "MAVLink: the autopilot's HEARTBEAT went silent and back: {when}: {episodes} more times since the last line"
        ),
        Voice::Back { after_s } => {
            tracing::info!("MAVLink: the autopilot's HEARTBEAT is back, {after_s:.1} s after it was told silent")
        }
    }
}

/// What the supervisor saw of the frame thread's end before joining it.
#[derive(Debug)]
enum Seen {
    /// A shutdown was asked for first.
    Shutdown,
    /// The thread ended by itself, saying why.
    Ended(EndReason),
    /// The thread ended without saying why: it panicked.
    Vanished,
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
    seen: Seen,
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
    outcome(seen, joined)
}

/// Why the frame thread ended, from what the supervisor saw and what
/// joining it gave (`None`: not joined). A panic, seen either way, is a
/// failure, not a stop.
fn outcome(seen: Seen, joined: Option<std::thread::Result<EndReason>>) -> EndReason {
    match (seen, joined) {
        (_, Some(Err(payload))) => EndReason::Panicked(panic_message(payload.as_ref())),
        (Seen::Ended(r), _) => r,
        (Seen::Vanished, _) => EndReason::Panicked(String::new()),
        (Seen::Shutdown, Some(Ok(r))) => r,
        (Seen::Shutdown, None) => EndReason::Stopped,
    }
}

/// The text a panic was raised with, if it had one.
fn panic_message(payload: &(dyn Any + Send)) -> String {
    match (
        payload.downcast_ref::<&str>(),
        payload.downcast_ref::<String>(),
    ) {
        (Some(s), _) => (*s).to_string(),
        (None, Some(s)) => s.clone(),
        (None, None) => String::new(),
    }
}

/// The run summed up, and its last line: the counts, or, for a failure,
/// one ERROR line that says it and the counts.
fn summary(ctx: &StatusCtx, reason: &EndReason) -> Summary {
    let s = ctx.stats;
    let summary = Summary {
        frames: s.frames.load(Relaxed),
        late: s.late.load(Relaxed),
        failed: s.failed.load(Relaxed),
        lost: s.lost.load(Relaxed),
        recorded: ctx.rec.map_or(0, |r| r.frames.load(Relaxed)),
        source_ended: *reason == EndReason::SourceEnded,
    };
    if let EndReason::Panicked(msg) = reason {
        let msg = if msg.is_empty() { "no message" } else { msg };
        tracing::error!(
            "the frame thread panicked ({}): {} frames, {} late, {} failed, {} lost, {} recorded; exiting with a failure",
            lightpose_core::textfile::excerpt(msg, 500),
            summary.frames,
            summary.late,
            summary.failed,
            summary.lost,
            summary.recorded
        );
        return summary;
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn panicked(payload: Box<dyn Any + Send>) -> Option<std::thread::Result<EndReason>> {
        Some(Err(payload))
    }

    /// Audit: a panic on the frame thread was taken for a stop ("stopped",
    /// exit 0), and systemd's Restart=on-failure never restarted it.
    #[test]
    fn a_panic_is_a_failure_however_it_is_seen() {
        let boom = || panicked(Box::new("index out of bounds"));
        let want = EndReason::Panicked("index out of bounds".into());
        assert_eq!(outcome(Seen::Vanished, boom()), want);
        assert_eq!(outcome(Seen::Shutdown, boom()), want, "while stopping");
        let formatted = panicked(Box::new(format!("seq {}", 7)));
        assert_eq!(
            outcome(Seen::Vanished, formatted),
            EndReason::Panicked("seq 7".into())
        );
        // Gone without a word and not joined (or a payload of no text).
        assert_eq!(
            outcome(Seen::Vanished, None),
            EndReason::Panicked(String::new())
        );
        assert_eq!(
            outcome(Seen::Vanished, panicked(Box::new(42u8))),
            EndReason::Panicked(String::new())
        );
        assert!(want.is_failure());
    }

    #[test]
    fn an_ordinary_end_is_what_the_thread_said() {
        let ended = |r: EndReason| Some(Ok(r));
        assert_eq!(
            outcome(
                Seen::Ended(EndReason::SourceEnded),
                ended(EndReason::SourceEnded)
            ),
            EndReason::SourceEnded
        );
        assert_eq!(
            outcome(Seen::Shutdown, ended(EndReason::Stopped)),
            EndReason::Stopped
        );
        // A thread that did not stop within the bound: the shutdown stands.
        assert_eq!(outcome(Seen::Shutdown, None), EndReason::Stopped);
        for r in [
            EndReason::Stopped,
            EndReason::SourceEnded,
            EndReason::FrameLimit,
        ] {
            assert!(!r.is_failure(), "{r:?}");
        }
    }
}
