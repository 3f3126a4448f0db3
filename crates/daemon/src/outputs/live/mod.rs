//! The live view: the channels of an MCAP recording (frames, estimates,
//! STATUS, and Foxglove's image, poses and transform) served to Foxglove
//! over its WebSocket protocol while the daemon runs (`[foxglove]`,
//! docs/foxglove.md).
//!
//! Three stages, so that no client can ever slow a frame:
//! 1. the frame thread ([`LiveView::emit`]) copies the frame and its
//!    estimate into a bounded queue whose slots are allocated once, and
//!    only when some client subscribed to something; a full queue drops
//!    the frame (counted, `handoff_dropped`, as is a frame handed to an
//!    encoder thread that is gone);
//! 2. the encoder thread formats the messages (lightpose-logs' `Encoder`,
//!    the same bytes as a recording) and hands each to the [`hub::Hub`],
//!    which puts it into the bounded queue of every subscribed client,
//!    dropping (and counting) it for a client whose queue is full; a frame
//!    or estimate without a log time (t < 0) has no message (counted,
//!    `skipped`);
//! 3. one task per client on the daemon's runtime writes its queue to its
//!    socket ([`server`]).

pub mod hub;
pub mod server;

use super::Output;
use crate::config::Foxglove;
use crate::engine::Acquired;
use hub::Hub;
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::{Frame, LogHeader, PoseEstimate};
use lightpose_logs::{Encoder, Message, WriteError};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Frames that may wait for the encoder thread.
const HANDOFF_QUEUE: usize = 64;

/// What the frame thread hands over: all Copy.
#[derive(Clone, Copy)]
struct Item {
    frame: Frame,
    est: PoseEstimate,
    wall_unix: f64,
}

/// The frame thread's end of the live view.
pub struct LiveView {
    tx: Option<SyncSender<Item>>,
    hub: Arc<Hub>,
    join: Option<JoinHandle<()>>,
    /// Frames the encoder could not take: core's rule for repeated lines.
    dropped_log: RateLog,
    /// Whether the last of them found the encoder thread gone (an error,
    /// not a warning): the closing line's level.
    dropped_gone: bool,
}

impl LiveView {
    /// Start the encoder thread publishing into `hub`; frames are
    /// formatted as a log of `header` would hold them.
    pub fn start(hub: Arc<Hub>, header: &LogHeader) -> std::io::Result<LiveView> {
        let (tx, rx) = sync_channel::<Item>(HANDOFF_QUEUE);
        let enc = Encoder::new(header, true)?;
        let h = hub.clone();
        let join = std::thread::Builder::new()
            .name("lightposed-live".into())
            .spawn(move || encode(rx, enc, &h))?;
        Ok(LiveView {
            tx: Some(tx),
            hub,
            join: Some(join),
            dropped_log: RateLog::new(),
            dropped_gone: false,
        })
    }
}

/// The encoder thread: each frame's and estimate's messages to the hub.
fn encode(rx: Receiver<Item>, mut enc: Encoder, hub: &Hub) {
    let mut publish = |m: Message| {
        hub.publish(&m);
        Ok(())
    };
    let mut log = RateLog::new();
    loop {
        // Skips not told yet: wake at least every second for their
        // closing line (frames stop coming when nobody subscribes);
        // else wait for the next frame as long as it takes.
        let got = if log.pending() > 0 {
            match rx.recv_timeout(Duration::from_secs(1)) {
                Ok(item) => Some(item),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => break,
            }
        } else {
            match rx.recv() {
                Ok(item) => Some(item),
                Err(_) => break,
            }
        };
        if log.pending() > 0 {
            close_skipped(hub, &mut log, Instant::now(), Close::Over);
        }
        let Some(item) = got else { continue };
        hub.note_frame_t(item.frame.t);
        // A frame or estimate without a log time (t < 0) has no message:
        // the recording refuses it the same way.
        if let Err(e) = enc.frame(&item.frame, &mut publish) {
            skipped(hub, &mut log, &e);
        }
        if let Err(e) = enc.pose(&item.est, Some(item.wall_unix), &mut publish) {
            skipped(hub, &mut log, &e);
        }
    }
    // The frame thread let go of the queue: the daemon stops.
    close_skipped(hub, &mut log, Instant::now(), Close::AtStop);
}

/// The closing line of the skips `when`: once they stopped (core's
/// `RateLog::settle`), or at stop (`RateLog::flush`).
fn close_skipped(hub: &Hub, log: &mut RateLog, now: Instant, when: Close) {
    if let Some(k) = log.close(now, when) {
        tracing::warn!(
            skipped = hub.skipped.load(Relaxed),
            since_last_line = k,
            "live view: messages not shown: {when}: {k} more since the last line, the last {:.1} s ago",
            log.since_last(now).as_secs_f64()
        );
    }
}

/// A frame or estimate that has no message: counted, logged by core's
/// rule for repeated lines.
fn skipped(hub: &Hub, log: &mut RateLog, e: &WriteError) {
    let n = hub.skipped.fetch_add(1, Relaxed) + 1;
    if let Some(k) = log.tick(Instant::now()) {
        tracing::warn!(
            skipped = n,
            since_last_line = k,
            "live view: {e}: not shown"
        );
    }
}

impl Output for LiveView {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        // Drops that stopped (or nobody wants frames now): the closing
        // line, checked on the frames that follow (a field read per
        // frame; the clock only while some are untold).
        if self.dropped_log.pending() > 0 {
            self.close_dropped(Instant::now(), Close::Over);
        }
        if !self.hub.wanted() {
            return;
        }
        let Some(tx) = &self.tx else { return };
        let item = Item {
            frame: frame.frame,
            est: *est,
            wall_unix: frame.wall_unix,
        };
        let gone = match tx.try_send(item) {
            Ok(()) => return,
            Err(TrySendError::Full(_)) => false,
            Err(TrySendError::Disconnected(_)) => true,
        };
        let n = self.hub.handoff_dropped.fetch_add(1, Relaxed) + 1;
        self.dropped_gone = gone;
        if let Some(k) = self.dropped_log.tick(Instant::now()) {
            if gone {
                tracing::error!(
                    handoff_dropped = n,
                    since_last_line = k,
                    "live view: the encoder thread is gone: frame not shown"
                );
            } else {
                tracing::warn!(
                    handoff_dropped = n,
                    since_last_line = k,
                    "live view: the encoder thread is behind: frame not shown"
                );
            }
        }
    }

    fn finish(&mut self) {
        self.tx = None;
        if let Some(j) = self.join.take() {
            if j.join().is_err() {
                tracing::error!("live view encoder thread panicked");
            }
        }
        // No frame comes after: the drops not told yet, at stop.
        self.close_dropped(Instant::now(), Close::AtStop);
    }
}

impl LiveView {
    /// The closing line of the frames not handed over `when` (core's
    /// `RateLog::settle` once they stopped, `RateLog::flush` at stop), at
    /// the level of their lines.
    fn close_dropped(&mut self, now: Instant, when: Close) {
        let Some(k) = self.dropped_log.close(now, when) else {
            return;
        };
        let n = self.hub.handoff_dropped.load(Relaxed);
        let ago = self.dropped_log.since_last(now).as_secs_f64();
        if self.dropped_gone {
            tracing::error!(
                handoff_dropped = n,
                since_last_line = k,
                "live view: frames not shown (the encoder thread is gone): {when}: {k} more since the last line, the last {ago:.1} s ago"
            );
        } else {
            tracing::warn!(
                handoff_dropped = n,
                since_last_line = k,
                "live view: frames not shown (the encoder thread behind): {when}: {k} more since the last line, the last {ago:.1} s ago"
            );
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        Output::finish(self);
    }
}

/// The live view's parts once started: the hub (for STATUS and the
/// shutdown), the frame thread's output, the accept task.
pub struct Live {
    pub hub: Arc<Hub>,
    pub output: LiveView,
    pub server: tokio::task::JoinHandle<()>,
}

/// Bind `cfg.listen` and start serving; frames are formatted as a log of
/// `header` would hold them.
pub async fn start(cfg: &Foxglove, header: &LogHeader) -> std::io::Result<Live> {
    let listener = tokio::net::TcpListener::bind(cfg.listen).await?;
    let listen = listener.local_addr()?;
    let hub = Arc::new(Hub::new(listen));
    let output = LiveView::start(hub.clone(), header)?;
    let mut limits = server::Limits::new(cfg.client_queue, cfg.max_clients);
    limits.max_clients_per_addr = cfg.max_clients_per_addr;
    let server = tokio::spawn(server::serve(listener, hub.clone(), limits));
    tracing::info!("foxglove live view on ws://{listen}");
    Ok(Live {
        hub,
        output,
        server,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Messages not shown, a burst of 3: the first said at once, the 2
    /// after it by the closing line once none came for 1 s (the encoder
    /// thread wakes every second while some are untold); once.
    #[test]
    fn skips_that_stop_are_told_by_a_closing_line() {
        let hub = Hub::new("127.0.0.1:0".parse().unwrap());
        let mut log = RateLog::new();
        let e = WriteError::Time {
            what: "frame",
            seq: 1,
            t: -1.0,
        };
        let text = lightpose_testkit::logs::logged(|| {
            for _ in 0..3 {
                skipped(&hub, &mut log, &e);
            }
            let now = Instant::now();
            let settle = |log: &mut RateLog, at| close_skipped(&hub, log, at, Close::Over);
            settle(&mut log, now);
            settle(&mut log, now + Duration::from_secs(2));
            settle(&mut log, now + Duration::from_secs(3));
            close_skipped(&hub, &mut log, now + Duration::from_secs(4), Close::AtStop);
        });
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[1].contains("WARN")
                && lines[1].contains("skipped=3 since_last_line=2")
                && lines[1]
                    .contains("live view: messages not shown: the condition is over: 2 more"),
            "{text}"
        );
    }
}
