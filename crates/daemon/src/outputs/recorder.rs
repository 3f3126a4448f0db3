//! Recording of raw frames as intensity logs, JSON Lines or MCAP (one file
//! in its format: `recfile.rs`), in a thread of its own so that a slow,
//! full or read-only disk never delays a POSE. The frame thread hands each
//! frame and its estimate over a bounded queue whose slots are allocated
//! once. Every `flush_s` the open file is pushed to the disk (MCAP: its
//! chunk closed) and synced; files rotate by size or age (MCAP also by
//! default: `Recording::rotation`). A disk that refuses is reported
//! (STATUS, log) and retried less and less often ([`worker`]); a nearly
//! full disk is not written to, and old recordings may be pruned to make
//! room ([`space`]), oldest first by the counter in their names
//! ([`names`]), not by the wall clock; frames that could not be recorded
//! are counted, never hidden.

pub mod clock;
mod names;
mod space;
#[cfg(test)]
mod tests;
mod worker;

pub use space::{default_floor, MIN_FREE};

use super::{Output, StatusTap};
use crate::config::{RecFormat, RecSamples, Recording};
use crate::engine::Acquired;
pub use clock::Epoch;
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::samples::Burst;
use lightpose_core::{Frame, LogHeader, PoseEstimate};
use std::io;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};
use worker::Worker;

/// How long a stop waits for the disk to take the frames still queued: a
/// disk that hangs (a dead network share, a full pipe) must not hold the
/// daemon past systemd's TimeoutStopSec.
pub const FLUSH_BOUND: Duration = Duration::from_secs(2);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum RecState {
    Off = 0,
    /// Waiting for the first frame.
    Idle = 1,
    Recording = 2,
    Error = 3,
    Closed = 4,
    /// Stopped from the page (`[web] control`): no file open, frames not
    /// recorded until it is started again.
    Paused = 5,
}

impl RecState {
    pub fn as_str(self) -> &'static str {
        match self {
            RecState::Off => "off",
            RecState::Idle => "idle",
            RecState::Recording => "recording",
            RecState::Error => "error",
            RecState::Closed => "closed",
            RecState::Paused => "paused",
        }
    }
    fn from_u8(v: u8) -> Self {
        match v {
            1 => RecState::Idle,
            2 => RecState::Recording,
            3 => RecState::Error,
            4 => RecState::Closed,
            5 => RecState::Paused,
            _ => RecState::Off,
        }
    }
}

/// What STATUS says about recording.
#[derive(Default)]
pub struct RecStats {
    state: AtomicU8,
    pub frames: AtomicU64,
    /// Frames the disk refused.
    pub failed: AtomicU64,
    /// Frames that found the queue full (disk too slow).
    pub dropped: AtomicU64,
    /// Frames the format cannot hold (MCAP: t < 0), passed over one by one.
    pub skipped: AtomicU64,
    /// STATUS objects that found their queue full (MCAP).
    pub status_dropped: AtomicU64,
    /// Times recording went into `error`, and attempts that failed again
    /// while in it (each after a longer wait).
    pub outages: AtomicU64,
    pub retries: AtomicU64,
    /// Old recordings deleted to make room (`keep_free_mb`, `max_total_mb`).
    pub pruned: AtomicU64,
    pub files: AtomicU64,
    pub bytes: AtomicU64,
    /// Frames known to be on the disk: written before the last flush
    /// (`flush_s`) or in a file closed since. A power loss keeps these.
    pub synced: AtomicU64,
    pub format: RecFormat,
    pub current: Mutex<Option<String>>,
    /// Why the state is `error`; cleared when recording resumes.
    pub error: Mutex<Option<String>>,
    /// Frames in the queue, not yet taken by the recorder thread.
    queued: AtomicU64,
    /// Set when a stop gave up waiting: the thread writes no more.
    abandoned: AtomicBool,
    /// Recording stopped from the page: the frame path hands nothing
    /// over, and the recorder thread completes and closes its file; a
    /// frame after it is cleared opens a new one.
    pub paused: AtomicBool,
    /// Held while the counts change: a stop that gives up on a blocked
    /// recorder thread settles them under it, and the thread, unblocked
    /// later, finds `abandoned` and changes nothing more (else a flush or
    /// a close that returned counted the same frames off twice).
    books: Mutex<()>,
}

impl RecStats {
    /// The counts, to change, unless a stop gave up on the recorder thread
    /// (then they are settled and stay so). Never held across I/O.
    fn book(&self) -> Option<std::sync::MutexGuard<'_, ()>> {
        let g = self.books.lock().unwrap_or_else(|p| p.into_inner());
        (!self.abandoned.load(Relaxed)).then_some(g)
    }

    pub fn state(&self) -> RecState {
        RecState::from_u8(self.state.load(Relaxed))
    }
    fn set_state(&self, s: RecState) {
        self.state.store(s as u8, Relaxed);
    }
}

/// What the frame thread hands the recorder: the frame as acquired, its
/// estimate and the wall clock of its arrival. All Copy: the queue's slots
/// are allocated once, so handing over allocates nothing.
#[derive(Clone)]
struct Item {
    /// Spec v3: the samples `frame` was demodulated from, recorded as a
    /// BURST line (`samples = "raw"`), its buffer from the pool.
    burst: Option<Box<Burst>>,
    frame: Frame,
    est: PoseEstimate,
    wall_unix: f64,
}

/// STATUS objects that may wait for the recorder (MCAP records them).
const STATUS_QUEUE: usize = 4;

/// The frame path's end of the recorder.
pub struct Recorder {
    tx: Option<SyncSender<Item>>,
    status_tx: SyncSender<Vec<u8>>,
    join: Option<JoinHandle<()>>,
    pub stats: Arc<RecStats>,
    /// Frames the full queue refused: core's rule, the first at once,
    /// then less and less often while the disk stays slow.
    drop_log: RateLog,
    /// Spec v3, `samples = "raw"` of a source of bursts: buffers for the
    /// frames' samples, made once, coming back from the recorder thread.
    raw: Option<RawPool>,
}

/// Buffers for raw samples on their way to the disk.
struct RawPool {
    free: Receiver<Box<Burst>>,
    /// The burst of the frame about to be recorded, if one was free.
    pending: Option<Box<Burst>>,
    /// [`Output::raw`] was called for that frame (a source of bursts may
    /// still give a frame demodulated already: recorded as it is).
    called: bool,
}

/// Raw bursts waiting for the disk at most: 32 × 25 × N samples (0.6 MB
/// at N = 400); past them a frame is dropped, counted, as by a full queue.
const RAW_POOL: usize = 32;

impl Recorder {
    /// Start the recorder thread. `header` is written at the top of every
    /// file (its adc_bits is taken from the first frame, and the file's
    /// `clock` added); `epoch` is what the frames' `t` counts from.
    pub fn start(cfg: &Recording, header: LogHeader, epoch: Epoch) -> io::Result<Recorder> {
        let stats = Arc::new(RecStats {
            format: cfg.format,
            ..RecStats::default()
        });
        stats.set_state(RecState::Idle);
        let n = header.samples_per_frame();
        let mut worker = Worker::new(cfg, header, stats, epoch);
        let raw = (n > 1 && cfg.samples == RecSamples::Raw).then(|| {
            let size = RAW_POOL.min(cfg.queue);
            let (back, free) = sync_channel::<Box<Burst>>(size);
            for _ in 0..size {
                let _ = back.try_send(Box::new(Burst::new(n)));
            }
            worker.free = Some(back);
            RawPool {
                free,
                pending: None,
                called: false,
            }
        });
        let mut r = Recorder::spawn(worker, cfg.queue)?;
        r.raw = raw;
        Ok(r)
    }

    /// `worker` on its thread behind a queue of `queue` frames.
    fn spawn(worker: Worker, queue: usize) -> io::Result<Recorder> {
        let (tx, rx) = sync_channel::<Item>(queue);
        let (status_tx, status_rx) = sync_channel::<Vec<u8>>(STATUS_QUEUE);
        let stats = worker.stats.clone();
        let join = std::thread::Builder::new()
            .name("lightposed-rec".into())
            .spawn(move || worker.run(rx, status_rx))?;
        Ok(Recorder {
            tx: Some(tx),
            status_tx,
            join: Some(join),
            stats,
            drop_log: RateLog::new(),
            raw: None,
        })
    }

    /// Hand a frame and its estimate to the recorder without waiting.
    #[inline]
    pub fn record(&mut self, frame: &Frame, est: &PoseEstimate, wall_unix: f64) {
        if self.tx.is_none() {
            return;
        }
        if self.stats.paused.load(Relaxed) {
            // Its raw buffer, if any, stays pending for the next frame.
            if let Some(pool) = self.raw.as_mut() {
                pool.called = false;
            }
            return;
        }
        let mut burst = None;
        if let Some(pool) = self.raw.as_mut() {
            burst = pool.pending.take();
            if std::mem::take(&mut pool.called) && burst.is_none() {
                // Every buffer still waits for the disk: as a full queue.
                self.full();
                return;
            }
        }
        let item = Item {
            burst,
            frame: *frame,
            est: *est,
            wall_unix,
        };
        let Some(tx) = &self.tx else { return };
        match tx.try_send(item) {
            Ok(()) => {
                self.stats.queued.fetch_add(1, Relaxed);
                // Drops that stopped: the closing line, checked on the
                // frames that follow them (a field read per frame; the
                // clock only while some are untold). A frame is what
                // could be dropped, so the next one is soon enough.
                if self.drop_log.pending() > 0 {
                    self.settle_drops(Instant::now());
                }
            }
            Err(TrySendError::Full(item)) => {
                self.give_back(item.burst);
                self.full();
            }
            Err(TrySendError::Disconnected(item)) => {
                self.give_back(item.burst);
                self.stats.failed.fetch_add(1, Relaxed);
            }
        }
    }

    /// A burst not handed over, kept for the next frame.
    fn give_back(&mut self, burst: Option<Box<Burst>>) {
        if let (Some(pool), Some(b)) = (self.raw.as_mut(), burst) {
            pool.pending = Some(b);
        }
    }

    /// A frame the full queue (or an empty pool of raw buffers) refused.
    fn full(&mut self) {
        let n = self.stats.dropped.fetch_add(1, Relaxed) + 1;
        if let Some(k) = self.drop_log.tick(Instant::now()) {
            tracing::warn!(
                dropped = n,
                since_last_line = k,
                "recording queue full: the disk is too slow, frame not recorded"
            );
        }
    }

    /// The closing line of the drops (core's `RateLog::settle`).
    fn settle_drops(&mut self, now: Instant) {
        self.close_drops(now, Close::Over);
    }

    /// The closing line of the drops `when`: once they stopped, or at
    /// stop (core's `RateLog::flush`).
    fn close_drops(&mut self, now: Instant, when: Close) {
        if let Some(k) = self.drop_log.close(now, when) {
            tracing::warn!(
                dropped = self.stats.dropped.load(Relaxed),
                since_last_line = k,
                "recording queue full: {when}: {k} more frames not recorded since the last line, the last {:.1} s ago",
                self.drop_log.since_last(now).as_secs_f64()
            );
        }
    }

    /// Where the supervisor hands each STATUS (recorded in MCAP only; a
    /// full queue drops it, counted).
    pub fn status_tap(&self) -> Box<dyn StatusTap> {
        Box::new(StatusFeed {
            tx: self.status_tx.clone(),
            stats: self.stats.clone(),
            log: Mutex::default(),
        })
    }

    /// Close the queue and wait until every queued frame is on disk, at
    /// most [`FLUSH_BOUND`].
    pub fn finish(&mut self) {
        self.finish_within(FLUSH_BOUND);
    }

    /// As [`Recorder::finish`], waiting at most `bound`: frames the disk has
    /// not taken by then are counted as not recorded (`failed`), said in
    /// STATUS and the log, and the recorder thread is left behind.
    pub fn finish_within(&mut self, bound: Duration) {
        self.tx = None;
        // No frame comes after: the drops not told yet, at stop.
        self.close_drops(Instant::now(), Close::AtStop);
        let Some(j) = self.join.take() else { return };
        let deadline = Instant::now() + bound;
        while !j.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        if j.is_finished() {
            if j.join().is_err() {
                tracing::error!("recorder thread panicked");
            }
            return;
        }
        let _settled = self.stats.books.lock().unwrap_or_else(|p| p.into_inner());
        self.stats.abandoned.store(true, Relaxed);
        let left = self.stats.queued.swap(0, Relaxed) + 1;
        // Frames written since the last sync are not known to be on the
        // disk (an MCAP chunk is still in memory, and goes with the
        // process): only the synced count as recorded.
        let frames = self.stats.frames.load(Relaxed);
        let unsynced = frames.saturating_sub(self.stats.synced.load(Relaxed));
        self.stats.frames.fetch_sub(unsynced, Relaxed);
        self.stats.failed.fetch_add(left + unsynced, Relaxed);
        let why = format!(
            "the disk took nothing for {bound:?} at stop: {} frames not known to be recorded ({left} queued or mid-write, {unsynced} written since the last sync)",
            left + unsynced
        );
        tracing::error!("recording: {why}");
        if let Ok(mut e) = self.stats.error.lock() {
            *e = Some(why);
        }
        self.stats.set_state(RecState::Error);
    }
}

/// STATUS on its way to the recorder thread.
struct StatusFeed {
    tx: SyncSender<Vec<u8>>,
    stats: Arc<RecStats>,
    /// STATUS the recorder thread had no room for (the async side, once
    /// per STATUS: a lock is no cost here).
    log: Mutex<RateLog>,
}

impl StatusTap for StatusFeed {
    fn status(&self, json: &[u8]) {
        // JSON Lines keeps no STATUS: nothing to queue.
        if !self.stats.format.is_mcap() {
            return;
        }
        // Disconnected: the recorder thread ended (the daemon stops).
        let full = matches!(self.tx.try_send(json.to_vec()), Err(TrySendError::Full(_)));
        let mut log = self.log.lock().unwrap_or_else(|p| p.into_inner());
        let now = Instant::now();
        if full {
            let n = self.stats.status_dropped.fetch_add(1, Relaxed) + 1;
            if let Some(k) = log.tick(now) {
                tracing::warn!(
                    status_dropped = n,
                    since_last_line = k,
                    "recording: the recorder thread is behind (a slow disk): STATUS not recorded"
                );
            }
        } else {
            // Each STATUS is the periodic call: the closing line of the
            // drops that stopped.
            self.close(&mut log, now, Close::Over);
        }
    }

    fn stop(&self) {
        let mut log = self.log.lock().unwrap_or_else(|p| p.into_inner());
        self.close(&mut log, Instant::now(), Close::AtStop);
    }
}

impl StatusFeed {
    /// The closing line of the STATUS not recorded `when` (core's
    /// `RateLog::settle` or, at stop, `RateLog::flush`).
    fn close(&self, log: &mut RateLog, now: Instant, when: Close) {
        if let Some(k) = log.close(now, when) {
            tracing::warn!(
                status_dropped = self.stats.status_dropped.load(Relaxed),
                since_last_line = k,
                "recording: STATUS not recorded: {when}: {k} more since the last line, the last {:.1} s ago",
                log.since_last(now).as_secs_f64()
            );
        }
    }
}

/// Records the frame as acquired (with its inputs' readings; the daemon's
/// fallback temperature is not the board's, and a replay applies it again)
/// and, in MCAP, its estimate.
impl Output for Recorder {
    #[inline]
    fn emit(&mut self, frame: &Acquired, est: &PoseEstimate) {
        self.record(&frame.frame, est, frame.wall_unix);
    }
    /// Kept for the frame's record when it records raw samples: copied
    /// into a buffer of the pool (none free: that frame is dropped).
    fn raw(&mut self, burst: &Burst) {
        let Some(pool) = self.raw.as_mut() else {
            return;
        };
        pool.called = true;
        if pool.pending.is_none() {
            pool.pending = pool.free.try_recv().ok();
        }
        if let Some(b) = pool.pending.as_mut() {
            b.copy_from(burst);
        }
    }
    fn finish(&mut self) {
        Recorder::finish(self);
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.finish();
    }
}

pub fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// `YYYYmmddTHHMMSSZ` without a date crate (days → civil date, Hinnant).
pub fn utc_stamp(t: SystemTime) -> String {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}
