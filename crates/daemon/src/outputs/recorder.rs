//! Recording of raw frames as intensity logs, JSON Lines or MCAP (one file
//! in its format: `recfile.rs`), in a thread of its own so that a slow,
//! full or read-only disk never delays a POSE. The frame thread hands each
//! frame and its estimate over a bounded queue whose slots are allocated
//! once. Every `flush_s` the open file is pushed to the disk (MCAP: its
//! chunk closed) and synced; files rotate by size or age. A disk that
//! refuses is reported (STATUS, log) and retried; frames that could not be
//! recorded are counted, never hidden.

use super::recfile::{extension, RecFile};
use super::{Output, StatusTap};
use crate::config::{RecFormat, Recording};
use crate::engine::Acquired;
use lightpose_core::{Frame, LogHeader, PoseEstimate};
use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

/// How long to wait before trying a refusing disk again.
const RETRY: Duration = Duration::from_secs(2);

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
}

impl RecState {
    pub fn as_str(self) -> &'static str {
        match self {
            RecState::Off => "off",
            RecState::Idle => "idle",
            RecState::Recording => "recording",
            RecState::Error => "error",
            RecState::Closed => "closed",
        }
    }
    fn from_u8(v: u8) -> Self {
        match v {
            1 => RecState::Idle,
            2 => RecState::Recording,
            3 => RecState::Error,
            4 => RecState::Closed,
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
}

impl RecStats {
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
#[derive(Clone, Copy)]
struct Item {
    frame: Frame,
    est: PoseEstimate,
    wall_unix: f64,
}

/// STATUS objects that may wait for the recorder (MCAP records them).
const STATUS_QUEUE: usize = 4;

/// Chunk size of an MCAP recording: chunks close when this full or on the
/// `flush_s` timer, whichever comes first.
const CHUNK_BYTES: u64 = 64 << 10;

/// How long the recorder thread sleeps at most when no frame comes (a
/// STATUS may be waiting).
const IDLE: Duration = Duration::from_millis(250);

/// The frame path's end of the recorder.
pub struct Recorder {
    tx: Option<SyncSender<Item>>,
    status_tx: SyncSender<Vec<u8>>,
    join: Option<JoinHandle<()>>,
    pub stats: Arc<RecStats>,
}

impl Recorder {
    /// Start the recorder thread. `header` is written at the top of every
    /// file (its adc_bits is taken from the first frame).
    pub fn start(cfg: &Recording, header: LogHeader) -> io::Result<Recorder> {
        let stats = Arc::new(RecStats {
            format: cfg.format,
            ..RecStats::default()
        });
        stats.set_state(RecState::Idle);
        Recorder::spawn(Worker::new(cfg, header, stats), cfg.queue)
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
        })
    }

    /// Hand a frame and its estimate to the recorder without waiting.
    #[inline]
    pub fn record(&self, frame: &Frame, est: &PoseEstimate, wall_unix: f64) {
        let Some(tx) = &self.tx else { return };
        let item = Item {
            frame: *frame,
            est: *est,
            wall_unix,
        };
        match tx.try_send(item) {
            Ok(()) => {
                self.stats.queued.fetch_add(1, Relaxed);
            }
            Err(TrySendError::Full(_)) => {
                let n = self.stats.dropped.fetch_add(1, Relaxed) + 1;
                if n == 1 || n.is_multiple_of(1000) {
                    tracing::warn!(
                        dropped = n,
                        "recording queue full: the disk is too slow, frame not recorded"
                    );
                }
            }
            Err(TrySendError::Disconnected(_)) => {
                self.stats.failed.fetch_add(1, Relaxed);
            }
        }
    }

    /// Where the supervisor hands each STATUS (recorded in MCAP only; a
    /// full queue drops it).
    pub fn status_tap(&self) -> Box<dyn StatusTap> {
        Box::new(self.status_tx.clone())
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
        self.stats.abandoned.store(true, Relaxed);
        let left = self.stats.queued.swap(0, Relaxed) + 1;
        self.stats.failed.fetch_add(left, Relaxed);
        let why = format!(
            "the disk took nothing for {bound:?} at stop: {left} frames not recorded (the last one mid-write)"
        );
        tracing::error!("recording: {why}");
        if let Ok(mut e) = self.stats.error.lock() {
            *e = Some(why);
        }
        self.stats.set_state(RecState::Error);
    }
}

impl StatusTap for SyncSender<Vec<u8>> {
    fn status(&self, json: &[u8]) {
        let _ = self.try_send(json.to_vec());
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
    fn finish(&mut self) {
        Recorder::finish(self);
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.finish();
    }
}

struct Worker {
    cfg: Recording,
    header: LogHeader,
    stats: Arc<RecStats>,
    file: Option<RecFile>,
    opened: Instant,
    retry_at: Option<Instant>,
    /// When the open file is next pushed to the disk (set by the first
    /// write after a flush).
    flush_at: Option<Instant>,
    seq_in_run: u32,
    /// t of the last frame written: STATUS is recorded at it.
    last_t: Option<f64>,
}

impl Worker {
    fn new(cfg: &Recording, header: LogHeader, stats: Arc<RecStats>) -> Worker {
        Worker {
            cfg: cfg.clone(),
            header,
            stats,
            file: None,
            opened: Instant::now(),
            retry_at: None,
            flush_at: None,
            seq_in_run: 0,
            last_t: None,
        }
    }

    fn run(mut self, rx: Receiver<Item>, status_rx: Receiver<Vec<u8>>) {
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
                    self.write(&item);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            while let Ok(s) = status_rx.try_recv() {
                self.status(&s);
            }
            if self.flush_at.is_some_and(|t| Instant::now() >= t) {
                self.flush();
            }
        }
        self.close();
        // A refusing disk stays visible in the last STATUS.
        if self.stats.state() != RecState::Error {
            self.stats.set_state(RecState::Closed);
        }
    }

    fn fail(&mut self, what: String) {
        if self.stats.state() != RecState::Error {
            tracing::error!(
                "recording: {what}; publishing goes on, retrying every {}s",
                RETRY.as_secs()
            );
        }
        if let Ok(mut e) = self.stats.error.lock() {
            *e = Some(what);
        }
        self.stats.set_state(RecState::Error);
        self.file = None;
        self.flush_at = None;
        self.retry_at = Some(Instant::now() + RETRY);
    }

    fn due_for_rotation(&self) -> bool {
        let Some(f) = &self.file else { return false };
        self.cfg.rotate_bytes.is_some_and(|b| f.bytes() >= b)
            || self
                .cfg
                .rotate_after
                .is_some_and(|a| self.opened.elapsed() >= a)
    }

    fn write(&mut self, item: &Item) {
        if self.due_for_rotation() {
            self.close();
        }
        if self.file.is_none() {
            if self.retry_at.is_some_and(|t| Instant::now() < t) {
                self.stats.failed.fetch_add(1, Relaxed);
                return;
            }
            if let Err(e) = self.open(item.frame.adc_bits) {
                self.fail(e);
                self.stats.failed.fetch_add(1, Relaxed);
                return;
            }
        }
        let Some(f) = self.file.as_mut() else {
            return;
        };
        match f.write(&item.frame, &item.est, item.wall_unix) {
            Ok(()) => {
                self.stats.frames.fetch_add(1, Relaxed);
                self.stats.bytes.store(f.bytes(), Relaxed);
                self.last_t = Some(item.frame.t);
                if self.flush_at.is_none() {
                    self.flush_at = Some(Instant::now() + self.cfg.flush);
                }
            }
            Err(e) => {
                self.stats.failed.fetch_add(1, Relaxed);
                self.fail(e);
            }
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

    /// Push the open file to the disk (the flush_s timer).
    fn flush(&mut self) {
        self.flush_at = None;
        let Some(f) = self.file.as_mut() else { return };
        match f.flush() {
            Ok(()) => {
                self.stats.bytes.store(f.bytes(), Relaxed);
                let synced = self.stats.frames.load(Relaxed) - f.unsynced();
                self.stats.synced.store(synced, Relaxed);
            }
            Err(e) => self.fail(e),
        }
    }

    fn open(&mut self, adc_bits: u8) -> Result<(), String> {
        std::fs::create_dir_all(&self.cfg.dir)
            .map_err(|e| format!("{}: {e}", self.cfg.dir.display()))?;
        self.seq_in_run += 1;
        let path: PathBuf = self.cfg.dir.join(format!(
            "lightposed-{}-{:04}.{}",
            utc_stamp(SystemTime::now()),
            self.seq_in_run,
            extension(self.cfg.format)
        ));
        let mut header = self.header.clone();
        header.adc_bits = adc_bits;
        header.extra.insert("started".into(), unix_now().into());
        let file = RecFile::create(path, self.cfg.format, &header, CHUNK_BYTES)?;
        let was_error = self.stats.state() == RecState::Error;
        let shown = file.path.display().to_string();
        self.file = Some(file);
        self.opened = Instant::now();
        self.retry_at = None;
        self.stats.files.fetch_add(1, Relaxed);
        if was_error {
            tracing::info!("recording resumed in {shown}");
        } else {
            tracing::info!("recording to {shown}");
        }
        if let Ok(mut c) = self.stats.current.lock() {
            *c = Some(shown);
        }
        if let Ok(mut e) = self.stats.error.lock() {
            *e = None;
        }
        self.stats.set_state(RecState::Recording);
        Ok(())
    }

    /// Complete the open file (MCAP: summary and footer) and sync it, so
    /// that a power cut after a clean stop or a rotation loses nothing.
    fn close(&mut self) {
        self.flush_at = None;
        if let Some(f) = self.file.take() {
            match f.close() {
                Ok(()) => {
                    let frames = self.stats.frames.load(Relaxed);
                    self.stats.synced.store(frames, Relaxed);
                }
                Err(e) => tracing::warn!("recording: closing failed: {e}"),
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use lightpose_core::{LogReader, Status, NDET};
    use std::fs::File;

    fn frame(seq: u64) -> Frame {
        Frame {
            seq,
            t: seq as f64 * 0.01,
            adc_bits: 10,
            counts: [seq as u16 % 1000; NDET],
            temp_c: Some(20.0),
            truth: None,
            attitude: None,
            depth: None,
            velocity: None,
        }
    }

    fn est(seq: u64) -> PoseEstimate {
        PoseEstimate::empty(seq, seq as f64 * 0.01, Status::NoLight, "test")
    }

    fn cfg(dir: PathBuf, rotate_bytes: Option<u64>, queue: usize) -> Recording {
        Recording {
            dir,
            rotate_bytes,
            rotate_after: None,
            queue,
            format: crate::config::RecFormat::Jsonl,
            flush: Duration::from_secs(2),
        }
    }

    #[test]
    fn stamp_of_known_instants() {
        assert_eq!(utc_stamp(SystemTime::UNIX_EPOCH), "19700101T000000Z");
        let t = SystemTime::UNIX_EPOCH + Duration::from_secs(1_709_210_096); // 2024-02-29 12:34:56
        assert_eq!(utc_stamp(t), "20240229T123456Z");
    }

    #[test]
    fn rotates_by_size_and_every_file_reads_back_whole() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = cfg(dir.path().to_path_buf(), Some(2000), 1024);
        let mut r = Recorder::start(&cfg, LogHeader::new(10, 100.0)).unwrap();
        for s in 0..100 {
            r.record(&frame(s), &est(s), 1.7e9);
        }
        r.finish();
        assert_eq!(r.stats.frames.load(Relaxed), 100);
        let mut files: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        assert!(files.len() > 3, "rotated into {} files", files.len());
        let mut seqs = Vec::new();
        for f in &files {
            let mut rd = LogReader::open(f).unwrap();
            for fr in rd.by_ref() {
                seqs.push(fr.unwrap().seq);
            }
            assert_eq!(rd.truncated_at(), None);
        }
        assert_eq!(seqs, (0..100).collect::<Vec<_>>());
        assert_eq!(r.stats.state(), RecState::Closed);
    }

    #[test]
    fn refusing_disk_is_reported_not_fatal() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("file");
        std::fs::write(&blocker, b"x").unwrap();
        // A directory under a file: ENOTDIR.
        let cfg = cfg(blocker.join("sub"), None, 16);
        let mut r = Recorder::start(&cfg, LogHeader::new(10, 5.0)).unwrap();
        r.record(&frame(0), &est(0), 1.7e9);
        r.record(&frame(1), &est(1), 1.7e9);
        let t0 = Instant::now();
        while r.stats.failed.load(Relaxed) < 2 && t0.elapsed() < Duration::from_secs(2) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(r.stats.state(), RecState::Error);
        assert_eq!(r.stats.failed.load(Relaxed), 2);
        assert!(r
            .stats
            .error
            .lock()
            .unwrap()
            .as_deref()
            .unwrap_or("")
            .contains("sub"));
        r.finish();
    }

    #[test]
    fn full_disk_mid_file_is_reported() {
        // /dev/full refuses every write with ENOSPC: put it under an open
        // log (dup2 onto the sink's descriptor), as a disk that fills up
        // during a dive. JSON Lines meets it at the next line, MCAP at the
        // next flush (its chunk is held in memory until then).
        use crate::config::RecFormat;
        use std::os::fd::AsRawFd;
        let full = File::options().write(true).open("/dev/full").unwrap();
        for format in [RecFormat::Jsonl, RecFormat::Mcap] {
            let dir = tempfile::tempdir().unwrap();
            let stats = Arc::new(RecStats::default());
            let mut c = cfg(dir.path().to_path_buf(), None, 1);
            c.format = format;
            let mut w = Worker::new(&c, LogHeader::new(10, 5.0), stats.clone());
            let item = |seq| Item {
                frame: frame(seq),
                est: est(seq),
                wall_unix: 1.7e9,
            };
            w.write(&item(0));
            assert_eq!(stats.state(), RecState::Recording);
            let fd = w.file.as_ref().unwrap().sink_fd();
            nix::unistd::dup2(full.as_raw_fd(), fd).unwrap();
            w.write(&item(1));
            w.flush();
            assert_eq!(stats.state(), RecState::Error, "{format:?}");
            let err = stats.error.lock().unwrap().clone().unwrap_or_default();
            assert!(err.contains("No space left"), "{format:?}: {err}");
            assert!(err.contains(dir.path().to_str().unwrap()), "{err}");
            // Within the retry delay further frames are counted as not
            // recorded.
            w.write(&item(2));
            let failed = stats.failed.load(Relaxed);
            match format {
                RecFormat::Jsonl => assert_eq!((failed, stats.frames.load(Relaxed)), (2, 1)),
                RecFormat::Mcap => assert_eq!((failed, stats.frames.load(Relaxed)), (1, 2)),
            }
        }
    }

    /// Issue 16: once recording resumes, STATUS no longer shows the error.
    #[test]
    fn the_error_is_cleared_when_recording_resumes() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("rec");
        std::fs::write(&blocker, b"x").unwrap();
        let stats = Arc::new(RecStats::default());
        let mut w = Worker::new(
            &cfg(blocker.clone(), None, 16),
            LogHeader::new(10, 5.0),
            stats.clone(),
        );
        let item = |seq| Item {
            frame: frame(seq),
            est: est(seq),
            wall_unix: 1.7e9,
        };
        w.write(&item(0));
        assert_eq!(stats.state(), RecState::Error);
        assert!(stats.error.lock().unwrap().is_some());
        std::fs::remove_file(&blocker).unwrap();
        w.retry_at = None; // as after the retry delay
        w.write(&item(1));
        assert_eq!(stats.state(), RecState::Recording);
        assert_eq!(*stats.error.lock().unwrap(), None, "old error still shown");
    }

    /// Issue 16: a disk that takes nothing more (here a FIFO nobody reads,
    /// put under the open log) does not hold the stop: finish gives up
    /// after its bound and counts what was left as not recorded.
    #[test]
    fn finish_does_not_wait_for_a_stuck_disk() {
        use std::os::fd::AsRawFd;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("stuck");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success(), "mkfifo");
        // Read and write: opening does not wait for a reader, writes block
        // once the pipe's 64 KiB are full.
        let stuck = File::options().read(true).write(true).open(&fifo).unwrap();
        let stats = Arc::new(RecStats::default());
        let rec = dir.path().join("rec");
        let mut w = Worker::new(
            &cfg(rec, None, 4096),
            LogHeader::new(10, 5.0),
            stats.clone(),
        );
        w.write(&Item {
            frame: frame(0),
            est: est(0),
            wall_unix: 1.7e9,
        });
        let fd = w.file.as_ref().unwrap().sink_fd();
        nix::unistd::dup2(stuck.as_raw_fd(), fd).unwrap();
        let mut r = Recorder::spawn(w, 4096).unwrap();
        for s in 1..2000 {
            r.record(&frame(s), &est(s), 1.7e9);
        }
        let t0 = Instant::now();
        r.finish_within(Duration::from_millis(300));
        let took = t0.elapsed();
        assert!(took < Duration::from_secs(2), "{took:?}");
        assert_eq!(stats.state(), RecState::Error);
        let err = stats.error.lock().unwrap().clone().unwrap_or_default();
        assert!(err.contains("not recorded"), "{err}");
        let recorded = stats.frames.load(Relaxed);
        let failed = stats.failed.load(Relaxed);
        assert!(
            failed > 0 && recorded + failed >= 1999,
            "{recorded} + {failed}"
        );
        // Let the writer go: drain the FIFO.
        let mut rd = File::open(&fifo).unwrap();
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut rd, &mut std::io::sink());
        });
    }
}
