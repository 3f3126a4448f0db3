//! The recorder thread: frames and STATUS into the open file, the file
//! pushed to the disk on its timer, rotated, and a refusing disk retried
//! with a wait that doubles at each failed attempt (2 s up to 60 s). Going
//! into `error` and coming back out are each logged once, not each
//! attempt; a file opened while in error must reach the disk (its first
//! sync) before recording counts as resumed.

use super::clock::{ClockPair, ClockWatch, Epoch, Reason, Synced};
use super::names;
use super::space::{Space, EVERY};
use super::{Item, RecState, RecStats};
use crate::config::recording::Rotation;
use crate::config::Recording;
use crate::outputs::recfile::{self, extension, Closed, Opener, RecError, RecFile};
use lightpose_core::ratelog::{Close, RateLog};
use lightpose_core::LogHeader;
use lightpose_logs::WriteError;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// The first wait before trying a refusing disk again, and the longest.
pub(super) const RETRY_FIRST: Duration = Duration::from_secs(2);
pub(super) const RETRY_MAX: Duration = Duration::from_secs(60);

/// Chunk size of an MCAP recording: chunks close when this full or on the
/// `flush_s` timer, whichever comes first.
const CHUNK_BYTES: u64 = 64 << 10;

/// How long the recorder thread sleeps at most when no frame comes (a
/// STATUS may be waiting, the disk's room is checked).
const IDLE: Duration = Duration::from_millis(250);

pub(super) struct Worker {
    cfg: Recording,
    /// When a new file starts: `cfg`'s, or MCAP's default (tests shorten it).
    pub(super) rotation: Rotation,
    header: LogHeader,
    pub(super) stats: Arc<RecStats>,
    pub(super) file: Option<RecFile>,
    opened: Instant,
    pub(super) retry_at: Option<Instant>,
    /// The wait after the next failure while in error.
    pub(super) backoff: Duration,
    /// The open file was opened while in error and has not reached the
    /// disk yet: recording has not resumed.
    probation: bool,
    /// When the open file is next pushed to the disk (set by the first
    /// write after a flush).
    flush_at: Option<Instant>,
    pub(super) space: Space,
    /// When the disk's room is next checked (while a file is open).
    space_at: Option<Instant>,
    /// The counter of the last file this run opened (the next one takes
    /// the higher of it and the directory's highest, + 1).
    counter: u64,
    /// t of the last frame written: STATUS is recorded at it.
    last_t: Option<f64>,
    pub(super) open_file: Opener,
    /// Frames the format cannot hold: core's rule, the first at once,
    /// then less and less often while they go on (a whole replayed log).
    skip_log: RateLog,
    /// The wall clock against the frames' time: each file's pair, and
    /// MCAP's new records when the wall clock steps.
    pub(super) clock: ClockWatch,
    /// Where a recorded BURST's buffer goes back (spec v3, raw samples).
    pub(super) free: Option<std::sync::mpsc::SyncSender<Box<lightpose_core::samples::Burst>>>,
}

impl Worker {
    /// A worker writing `cfg`'s files, `header` at the top of each, the
    /// frames' `t` counting from `epoch` (what ties them to the wall clock).
    pub(super) fn new(
        cfg: &Recording,
        header: LogHeader,
        stats: Arc<RecStats>,
        epoch: Epoch,
    ) -> Worker {
        Worker {
            cfg: cfg.clone(),
            rotation: cfg.rotation(),
            header,
            stats,
            file: None,
            opened: Instant::now(),
            retry_at: None,
            backoff: RETRY_FIRST,
            probation: false,
            flush_at: None,
            space: Space::new(cfg),
            space_at: None,
            counter: 0,
            last_t: None,
            open_file: recfile::create_new,
            skip_log: RateLog::new(),
            clock: ClockWatch::new(epoch),
            free: None,
        }
    }

    pub(super) fn run(mut self, rx: Receiver<Item>, status_rx: Receiver<Vec<u8>>) {
        loop {
            let now = Instant::now();
            let wait = self
                .flush_at
                .map_or(IDLE, |t| t.saturating_duration_since(now).min(IDLE));
            match rx.recv_timeout(wait) {
                Ok(item) => {
                    self.stats.queued.fetch_sub(1, Relaxed);
                    if self.stats.abandoned.load(Relaxed) {
                        break;
                    }
                    // A frame handed over just before a stop from the
                    // page: not recorded (it would open a file again).
                    if !self.stats.paused.load(Relaxed) {
                        self.write(&item);
                    }
                    if let (Some(b), Some(back)) = (item.burst, &self.free) {
                        // Its buffer back to the frame thread's pool.
                        let _ = back.try_send(b);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            while let Ok(s) = status_rx.try_recv() {
                self.status(&s);
            }
            if self.stats.paused.load(Relaxed) {
                self.pause();
            }
            let now = Instant::now();
            // The loop wakes at least every `IDLE`: the skips' closing
            // line comes at most that late.
            self.settle_skips(now);
            if self.flush_at.is_some_and(|t| now >= t) {
                self.flush();
            }
            if self.file.is_some() && self.space_at.is_some_and(|t| now >= t) {
                self.check_space();
            }
            // JSON Lines has no place for a record after its header.
            if self.file.is_some() && self.cfg.format.is_mcap() {
                if let Some((pair, step)) = self.clock.check(now) {
                    self.clock_record(&pair, step);
                }
            }
        }
        if let Some(Err(why)) = self.close() {
            // The last file could not be completed: said in the last
            // STATUS, as a refusing disk is.
            if let Ok(mut e) = self.stats.error.lock() {
                *e = Some(why);
            }
            self.stats.set_state(RecState::Error);
        }
        self.close_skips(Instant::now(), Close::AtStop);
        // A refusing disk stays visible in the last STATUS.
        if self.stats.state() != RecState::Error {
            self.stats.set_state(RecState::Closed);
        }
    }

    /// Stopped from the page: the open file completed and closed (whole,
    /// downloadable), the state `paused` until a frame comes again.
    fn pause(&mut self) {
        if self.file.is_some() {
            if let Some(Err(why)) = self.close() {
                self.fail(why);
                return;
            }
            tracing::info!("recording stopped from the page");
        }
        if self.stats.state() != RecState::Error {
            self.stats.set_state(RecState::Paused);
        }
    }

    /// Recording failed (`what`): the open file is ended (cut back to its
    /// last whole point), and the next attempt waits, longer each time.
    pub(super) fn fail(&mut self, what: String) {
        let first = self.stats.state() != RecState::Error;
        self.end_file(!first);
        self.probation = false;
        let Some(_books) = self.stats.book() else {
            return;
        };
        if first {
            self.backoff = RETRY_FIRST;
            self.stats.outages.fetch_add(1, Relaxed);
            tracing::error!(
                "recording: {what}; publishing goes on, retrying in {} s, then less often (at most every {} s)",
                RETRY_FIRST.as_secs(),
                RETRY_MAX.as_secs()
            );
        } else {
            self.stats.retries.fetch_add(1, Relaxed);
            self.backoff = (self.backoff * 2).min(RETRY_MAX);
            tracing::debug!(
                "recording: still failing: {what}; next try in {:?}",
                self.backoff
            );
        }
        if let Ok(mut e) = self.stats.error.lock() {
            *e = Some(what);
        }
        self.stats.set_state(RecState::Error);
        self.retry_at = Some(Instant::now() + self.backoff);
    }

    fn due_for_rotation(&self) -> bool {
        let Some(f) = &self.file else { return false };
        let r = &self.rotation;
        r.bytes.is_some_and(|b| f.bytes() >= b)
            || r.after.is_some_and(|a| self.opened.elapsed() >= a)
            || r.chunks.is_some_and(|c| f.chunks() >= c)
    }

    pub(super) fn write(&mut self, item: &Item) {
        if let Some(e) = recfile::unencodable(self.cfg.format, &item.frame, &item.est) {
            self.skip(&e);
            return;
        }
        if self.due_for_rotation() {
            if let Some(Err(why)) = self.close() {
                // Not completed (removed while written, a failed sync):
                // an outage like any refusal of the disk.
                self.fail(why);
            }
        }
        if self.file.is_none() {
            if self.retry_at.is_some_and(|t| Instant::now() < t) {
                self.count_failed(1);
                return;
            }
            if let Err(e) = self.open(item) {
                self.fail(e);
                self.count_failed(1);
                return;
            }
        }
        let Some(f) = self.file.as_mut() else {
            return;
        };
        let written = f.write_of(
            &item.frame,
            item.burst.as_deref(),
            &item.est,
            item.wall_unix,
        );
        match written {
            Ok(()) => {
                {
                    let Some(_books) = self.stats.book() else {
                        return;
                    };
                    self.stats.frames.fetch_add(1, Relaxed);
                    self.stats.bytes.store(f.bytes(), Relaxed);
                }
                self.last_t = Some(item.frame.t);
                if self.flush_at.is_none() {
                    self.flush_at = Some(Instant::now() + self.cfg.flush);
                }
                if let Some((pair, step)) = self.clock.frame(item.frame.t, item.wall_unix) {
                    self.clock_record(&pair, step);
                }
            }
            Err(RecError::Skip(e)) => self.skip(&e),
            Err(RecError::Disk(e)) => {
                self.count_failed(1);
                self.fail(e);
            }
        }
    }

    /// `n` frames not recorded (unless a stop gave up on this thread).
    fn count_failed(&self, n: u64) {
        if let Some(_books) = self.stats.book() {
            self.stats.failed.fetch_add(n, Relaxed);
        }
    }

    /// A frame the format cannot hold: counted and passed over, the file
    /// goes on; logged at the first, then less and less often.
    fn skip(&mut self, e: &WriteError) {
        let n = self.stats.skipped.fetch_add(1, Relaxed) + 1;
        if let Some(k) = self.skip_log.tick(Instant::now()) {
            tracing::warn!(
                skipped = n,
                since_last_line = k,
                "recording: {e}: frame not recorded"
            );
        }
    }

    /// The closing line of the skips once they stopped (core's
    /// `RateLog::settle`).
    pub(super) fn settle_skips(&mut self, now: Instant) {
        self.close_skips(now, Close::Over);
    }

    /// The closing line of the skips `when`: once they stopped, or at
    /// stop (core's `RateLog::flush`).
    pub(super) fn close_skips(&mut self, now: Instant, when: Close) {
        if let Some(k) = self.skip_log.close(now, when) {
            tracing::warn!(
                skipped = self.stats.skipped.load(Relaxed),
                since_last_line = k,
                "recording: frames the format cannot hold: {when}: {k} more not recorded since the last line, the last {:.1} s ago",
                self.skip_log.since_last(now).as_secs_f64()
            );
        }
    }

    /// A STATUS into the open file, at the last frame's t.
    fn status(&mut self, json: &[u8]) {
        let (Some(f), Some(t)) = (self.file.as_mut(), self.last_t) else {
            return;
        };
        if let Err(e) = f.status(t, json) {
            self.fail(e);
        }
    }

    /// A new clock record into the open file (MCAP): the wall clock
    /// stepped by `step` s, or its synchronization changed.
    fn clock_record(&mut self, pair: &ClockPair, step: f64) {
        let Some(f) = self.file.as_mut() else { return };
        let (name, pairs) = pair.metadata();
        if let Err(e) = f.metadata(name, pairs) {
            self.fail(e);
            return;
        }
        match pair.reason {
            Reason::Step => tracing::info!(
                "recording: the wall clock stepped by {step:+.3} s; a {name} record gives the new mapping"
            ),
            _ => tracing::info!(
                "recording: the kernel now says the wall clock is {}synchronized ({name} record)",
                if pair.synced == Synced::Yes { "" } else { "not " }
            ),
        }
    }

    /// Push the open file to the disk (the flush_s timer).
    pub(super) fn flush(&mut self) {
        self.flush_at = None;
        let Some(f) = self.file.as_mut() else { return };
        match f.flush() {
            Ok(()) => {
                {
                    let Some(_books) = self.stats.book() else {
                        return;
                    };
                    self.stats.bytes.store(f.bytes(), Relaxed);
                    let frames = self.stats.frames.load(Relaxed);
                    let synced = frames.saturating_sub(f.unsynced());
                    self.stats.synced.store(synced, Relaxed);
                }
                if self.probation {
                    self.resumed();
                }
            }
            Err(e) => self.fail(e),
        }
    }

    /// Prune as configured and, when the disk is still nearly full,
    /// complete the open file while it can be and stop until there is room.
    pub(super) fn check_space(&mut self) {
        self.space_at = Some(Instant::now() + EVERY);
        // Checked with the room: a file removed with its directory took
        // writes without a word (and the room of a directory that is gone
        // is not known).
        if let Some(why) = self.file.as_ref().and_then(RecFile::gone) {
            self.fail(why);
            return;
        }
        let current = self.file.as_ref().map(|f| f.path.clone());
        if let Err(why) = self.space.make_room(current.as_deref(), &self.stats) {
            self.end_file(false);
            self.fail(why);
        }
    }

    fn open(&mut self, item: &Item) -> Result<(), String> {
        std::fs::create_dir_all(&self.cfg.dir)
            .map_err(|e| format!("{}: {e}", self.cfg.dir.display()))?;
        // Before pruning, which may delete the highest.
        let highest = names::highest(&self.cfg.dir)
            .map_err(|e| format!("{}: {e}", self.cfg.dir.display()))?;
        self.space.make_room(None, &self.stats)?;
        let (counter, path, file) = names::create(
            &self.cfg.dir,
            highest.max(self.counter).saturating_add(1),
            &super::utc_stamp(SystemTime::now()),
            extension(self.cfg.format),
            self.open_file,
        )?;
        self.counter = counter;
        let mut header = self.header.clone();
        header.adc_bits = item.frame.adc_bits;
        header
            .extra
            .insert("started".into(), super::unix_now().into());
        let clock = self
            .clock
            .open(item.frame.t, item.wall_unix, Instant::now());
        header.extra.insert("clock".into(), clock.header_json());
        let mut file = RecFile::create(
            path,
            file,
            self.cfg.format,
            &header,
            CHUNK_BYTES,
            &self.cfg.bag,
        )?;
        let (name, pairs) = clock.metadata();
        if let Err(e) = file.metadata(name, pairs) {
            // No frame in it: removed.
            file.close();
            return Err(e);
        }
        let shown = file.path.display().to_string();
        self.file = Some(file);
        self.opened = Instant::now();
        self.space_at = Some(self.opened + EVERY);
        self.retry_at = None;
        let Some(_books) = self.stats.book() else {
            return Ok(());
        };
        self.stats.files.fetch_add(1, Relaxed);
        if let Ok(mut c) = self.stats.current.lock() {
            *c = Some(shown.clone());
        }
        if self.stats.state() == RecState::Error {
            // Resumed once this file reaches the disk.
            self.probation = true;
            tracing::debug!("recording: trying {shown}");
        } else {
            tracing::info!("recording to {shown}");
            self.stats.set_state(RecState::Recording);
        }
        Ok(())
    }

    /// The disk took a file opened while in error: recording resumed.
    fn resumed(&mut self) {
        self.probation = false;
        self.backoff = RETRY_FIRST;
        let Some(_books) = self.stats.book() else {
            return;
        };
        if let Ok(mut e) = self.stats.error.lock() {
            *e = None;
        }
        self.stats.set_state(RecState::Recording);
        let shown = self.stats.current.lock().ok().and_then(|c| c.clone());
        tracing::info!(
            retries = self.stats.retries.load(Relaxed),
            "recording resumed in {}",
            shown.unwrap_or_default()
        );
    }

    /// Complete the open file (MCAP: summary and footer) and sync it, so
    /// that a power cut after a clean stop or a rotation loses nothing.
    /// `None` without an open file, else whether it was completed (why
    /// not).
    pub(super) fn close(&mut self) -> Option<Result<(), String>> {
        let ended = self.end_file(false);
        if matches!(ended, Some(Ok(()))) && self.probation {
            self.resumed();
        }
        ended
    }

    /// End the open file, whole if it can be (see [`RecFile::close`]):
    /// `None` without one, else whether it was completed (why not). Frames
    /// cut off it move from `frames` to `failed`. `quiet`: while retrying,
    /// a file that did not take is not logged.
    fn end_file(&mut self, quiet: bool) -> Option<Result<(), String>> {
        self.flush_at = None;
        let f = self.file.take()?;
        let shown = f.path.display().to_string();
        let c = f.close();
        // A stop that gave up on this thread has settled the counts.
        let _books = self.stats.book()?;
        if c.lost > 0 {
            self.stats.frames.fetch_sub(c.lost, Relaxed);
            self.stats.failed.fetch_add(c.lost, Relaxed);
        }
        let frames = self.stats.frames.load(Relaxed);
        self.stats.synced.store(frames, Relaxed);
        if c.error.is_none() && !c.removed && c.lost == 0 {
            return Some(Ok(()));
        }
        Some(Err(report_end(&shown, &c, quiet)))
    }
}

/// One line on a file that could not be completed; what it says.
fn report_end(shown: &str, c: &Closed, quiet: bool) -> String {
    let what = match (&c.error, c.removed) {
        (Some(e), true) => format!("{e}: its {} frames are lost", c.lost),
        (None, true) => format!("{shown} removed: no frame reached the disk"),
        (Some(e), false) => format!(
            "{e}; {shown} cut back to its last whole point: {} frames kept, {} lost",
            c.kept, c.lost
        ),
        (None, false) => format!(
            "{shown} cut back to its last whole point: {} frames kept, {} lost",
            c.kept, c.lost
        ),
    };
    match (quiet, c.removed && c.error.is_none()) {
        (true, _) => tracing::debug!("recording: {what}"),
        (false, true) => tracing::info!("recording: {what}"),
        (false, false) => tracing::warn!("recording: {what}"),
    }
    what
}
