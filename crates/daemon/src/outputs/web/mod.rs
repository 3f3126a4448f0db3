//! The web page (`[web]`, docs/blueos.md): what a BlueOS extension shows
//! in BlueOS's interface, and the REST API beside it. The page's live feed
//! takes its data as the Foxglove live view does, so that no browser can
//! ever slow a frame:
//! 1. the frame thread ([`WebView::emit`]) copies the frame and its
//!    estimate into a bounded queue whose slots were allocated at start; a
//!    full queue drops the copy (counted, `handoff_dropped`): the page is
//!    a display, the next frame comes soon;
//! 2. the feed thread keeps the latest POSE text (`GET /v1/pose`) and, at
//!    most `updates_hz` times a second, formats one live event (the pose,
//!    the 5 × 5 counts, each beacon's amplitudes) and puts it into a
//!    `watch`: one slot, the latest event, replaced, never queued;
//! 3. one task per browser on the daemon's runtime ([`http`]) writes the
//!    latest event to its socket when it has written the one before: a
//!    client's queue is that one slot, and one that stops reading is cut
//!    once a write has waited [`http::Limits::write_deadline`].
//!
//! STATUS reaches the page the same way, from the supervisor's tick (a
//! [`StatusTap`]): the latest STATUS text in a `watch`, and for
//! `GET /v1/status`.

pub mod assets;
pub mod control;
pub mod event;
pub mod http;

use super::{Output, StatusTap};
use crate::config::Web;
use crate::engine::Acquired;
use bytes::Bytes;
use lightpose_core::{Frame, PoseEstimate};
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// Frames that may wait for the feed thread: it formats one in
/// `1/updates_hz` and only keeps the latest of the others.
const HANDOFF_QUEUE: usize = 16;

/// What the frame thread hands over: all Copy.
#[derive(Clone, Copy)]
struct Item {
    frame: Frame,
    est: PoseEstimate,
    wall_unix: f64,
}

/// What the page and the API read, shared by the feed thread, the STATUS
/// tap and the connection tasks.
pub struct WebFeed {
    /// Where the server listens (port 0 resolved).
    pub listen: std::net::SocketAddr,
    pub control: bool,
    /// The recording folder (`[recording] dir`), for the page's downloads,
    /// and the recorder's counters (its `paused`: start and stop).
    pub recordings: Option<std::path::PathBuf>,
    pub recorder: Option<Arc<crate::outputs::recorder::RecStats>>,
    /// A calibration reload asked from the page (`control`): the
    /// supervisor takes it as it takes SIGHUP.
    pub reload: tokio::sync::Notify,
    /// The latest live event (JSON), replaced `updates_hz` times a second.
    live: watch::Sender<Bytes>,
    /// The latest STATUS (JSON).
    status: watch::Sender<Bytes>,
    /// The latest POSE (JSON, the datagram's text); empty before the
    /// first frame.
    pose: Mutex<Bytes>,
    /// Raised at stop: every connection ends.
    closing: watch::Sender<bool>,
    closed: AtomicBool,
    /// Frames the feed thread could not take (its queue full), and those
    /// handed over.
    pub handoff_dropped: AtomicU64,
    pub handed: AtomicU64,
    /// Live events formatted.
    pub events: AtomicU64,
    pub counters: http::Counters,
}

impl WebFeed {
    fn new(listen: std::net::SocketAddr, control: bool, rec: Option<Recordings>) -> WebFeed {
        let (recordings, recorder) = rec.map_or((None, None), |r| (Some(r.dir), Some(r.stats)));
        WebFeed {
            listen,
            control,
            recordings,
            recorder,
            reload: tokio::sync::Notify::new(),
            live: watch::Sender::new(Bytes::new()),
            status: watch::Sender::new(Bytes::new()),
            pose: Mutex::new(Bytes::new()),
            closing: watch::Sender::new(false),
            closed: AtomicBool::new(false),
            handoff_dropped: AtomicU64::new(0),
            handed: AtomicU64::new(0),
            events: AtomicU64::new(0),
            counters: http::Counters::default(),
        }
    }

    /// The latest live event, STATUS and close flag, each for one client.
    pub fn subscribe(&self) -> (watch::Receiver<Bytes>, watch::Receiver<Bytes>) {
        (self.live.subscribe(), self.status.subscribe())
    }

    pub fn closing(&self) -> watch::Receiver<bool> {
        self.closing.subscribe()
    }

    pub fn latest_status(&self) -> Bytes {
        self.status.borrow().clone()
    }

    pub fn latest_pose(&self) -> Bytes {
        self.pose
            .lock()
            .map_or_else(|_| Bytes::new(), |p| p.clone())
    }

    /// The daemon stops: every connection ends, none is accepted.
    pub fn close(&self) {
        self.closed.store(true, Relaxed);
        self.closing.send_replace(true);
    }

    pub fn is_closed(&self) -> bool {
        self.closed.load(Relaxed)
    }

    /// STATUS's `web` object.
    pub fn report(&self) -> Value {
        let c = &self.counters;
        json!({
            "enabled": true,
            "listen": self.listen.to_string(),
            "control": self.control,
            "clients": c.open.load(Relaxed),
            "live_clients": c.live_open.load(Relaxed),
            "connections": c.accepted.load(Relaxed),
            "refused": c.refused.load(Relaxed),
            "bad_requests": c.bad_requests.load(Relaxed),
            "timed_out": c.timed_out.load(Relaxed),
            "not_reading": c.not_reading.load(Relaxed),
            "events": self.events.load(Relaxed),
            "handoff_dropped": self.handoff_dropped.load(Relaxed),
        })
    }
}

impl StatusTap for Arc<WebFeed> {
    fn status(&self, json: &[u8]) {
        self.status.send_replace(Bytes::copy_from_slice(json));
    }
}

/// The frame thread's end of the page's feed.
pub struct WebView {
    tx: Option<SyncSender<Item>>,
    feed: Arc<WebFeed>,
    join: Option<JoinHandle<()>>,
}

impl WebView {
    /// Start the feed thread publishing into `feed`, an event every
    /// `1/updates_hz` at most.
    fn start(feed: Arc<WebFeed>, updates_hz: f64) -> std::io::Result<WebView> {
        let (tx, rx) = sync_channel::<Item>(HANDOFF_QUEUE);
        let f = feed.clone();
        let every = Duration::from_secs_f64(1.0 / updates_hz);
        let join = std::thread::Builder::new()
            .name("lightposed-web".into())
            .spawn(move || run_feed(&rx, &f, every))?;
        Ok(WebView {
            tx: Some(tx),
            feed,
            join: Some(join),
        })
    }
}

/// The feed thread: the latest POSE always, a live event at most every
/// `every` (the frames between are only the latest POSE).
fn run_feed(rx: &Receiver<Item>, feed: &WebFeed, every: Duration) {
    let mut pose = Vec::with_capacity(1024);
    let mut last: Option<Instant> = None;
    while let Ok(item) = rx.recv() {
        item.est.write_json(Some(item.wall_unix), &mut pose);
        if let Ok(mut p) = feed.pose.lock() {
            *p = Bytes::copy_from_slice(&pose);
        }
        let now = Instant::now();
        if last.is_some_and(|l| now.duration_since(l) < every) {
            continue;
        }
        last = Some(now);
        let ev = event::live_event(&item.frame, &pose, item.wall_unix);
        feed.live.send_replace(Bytes::from(ev));
        feed.events.fetch_add(1, Relaxed);
    }
}

impl Output for WebView {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        let Some(tx) = &self.tx else { return };
        let item = Item {
            frame: frame.frame,
            est: *est,
            wall_unix: frame.wall_unix,
        };
        match tx.try_send(item) {
            Ok(()) => {
                self.feed.handed.fetch_add(1, Relaxed);
            }
            // A display: the next frame comes soon; counted in STATUS
            // (`web.handoff_dropped`), not logged per frame.
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.feed.handoff_dropped.fetch_add(1, Relaxed);
            }
        }
    }

    fn finish(&mut self) {
        self.tx = None;
        if let Some(j) = self.join.take() {
            if j.join().is_err() {
                tracing::error!("web feed thread panicked");
            }
        }
    }
}

impl Drop for WebView {
    fn drop(&mut self) {
        Output::finish(self);
    }
}

/// The page's parts once started: the shared feed (STATUS, the stop), the
/// frame thread's output, the accept task.
pub struct WebParts {
    pub feed: Arc<WebFeed>,
    pub output: WebView,
    pub server: tokio::task::JoinHandle<()>,
}

/// The recorder as the page sees it: its folder and its counters.
pub struct Recordings {
    pub dir: std::path::PathBuf,
    pub stats: Arc<crate::outputs::recorder::RecStats>,
}

/// Bind `cfg.listen` and start serving the page; `recordings`, the
/// recorder if any.
pub async fn start(cfg: &Web, recordings: Option<Recordings>) -> std::io::Result<WebParts> {
    let listener = tokio::net::TcpListener::bind(cfg.listen).await?;
    let listen = listener.local_addr()?;
    let feed = Arc::new(WebFeed::new(listen, cfg.control, recordings));
    let output = WebView::start(feed.clone(), cfg.updates_hz)?;
    let limits = http::Limits::new(cfg.max_clients, cfg.max_clients_per_addr);
    let server = tokio::spawn(http::serve(listener, feed.clone(), limits));
    tracing::info!("web page on http://{listen}/");
    Ok(WebParts {
        feed,
        output,
        server,
    })
}
