//! Recording of raw frames as intensity logs (core's LogWriter), in a thread
//! of its own so that a slow, full or read-only disk never delays a POSE.
//! Each line reaches the file in one `write(2)` on an unbuffered file, so
//! after `kill -9` the log reads back complete up to its last line. Files
//! rotate by size or age. A disk that refuses is reported (STATUS, log) and
//! retried; frames that could not be recorded are counted, never hidden.

use super::Output;
use crate::config::Recording;
use crate::engine::Acquired;
use lightpose_core::{Frame, LogHeader, LogWriter, PoseEstimate};
use std::fs::File;
use std::io::{self, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering::Relaxed};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
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

/// The frame path's end of the recorder.
pub struct Recorder {
    tx: Option<SyncSender<Frame>>,
    join: Option<JoinHandle<()>>,
    pub stats: Arc<RecStats>,
}

/// A file that counts what went into it, for size rotation.
struct Counted {
    file: File,
    bytes: u64,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Recorder {
    /// Start the recorder thread. `header` is written at the top of every
    /// file (its adc_bits is taken from the first frame).
    pub fn start(cfg: &Recording, header: LogHeader) -> io::Result<Recorder> {
        let stats = Arc::new(RecStats::default());
        stats.set_state(RecState::Idle);
        let worker = Worker {
            cfg: cfg.clone(),
            header,
            stats,
            writer: None,
            opened: Instant::now(),
            retry_at: None,
            seq_in_run: 0,
        };
        Recorder::spawn(worker, cfg.queue)
    }

    /// `worker` on its thread behind a queue of `queue` frames.
    fn spawn(worker: Worker, queue: usize) -> io::Result<Recorder> {
        let (tx, rx) = sync_channel::<Frame>(queue);
        let stats = worker.stats.clone();
        let join = std::thread::Builder::new()
            .name("lightposed-rec".into())
            .spawn(move || worker.run(rx))?;
        Ok(Recorder {
            tx: Some(tx),
            join: Some(join),
            stats,
        })
    }

    /// Hand a frame to the recorder without waiting (Frame is Copy, and the
    /// channel's slots are allocated once).
    #[inline]
    pub fn record(&self, f: &Frame) {
        let Some(tx) = &self.tx else { return };
        match tx.try_send(*f) {
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

/// Records the frame as acquired (with its inputs' readings; the daemon's
/// fallback temperature is not the board's, and a replay applies it again).
impl Output for Recorder {
    #[inline]
    fn emit(&mut self, frame: &Acquired, _est: &PoseEstimate) {
        self.record(&frame.frame);
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
    writer: Option<LogWriter<Counted>>,
    opened: Instant,
    retry_at: Option<Instant>,
    seq_in_run: u32,
}

impl Worker {
    fn run(mut self, rx: Receiver<Frame>) {
        while let Ok(f) = rx.recv() {
            self.stats.queued.fetch_sub(1, Relaxed);
            if self.stats.abandoned.load(Relaxed) {
                break;
            }
            self.write(&f);
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
        self.writer = None;
        self.retry_at = Some(Instant::now() + RETRY);
    }

    fn write(&mut self, f: &Frame) {
        let rotate = match &self.writer {
            Some(w) => {
                self.cfg
                    .rotate_bytes
                    .is_some_and(|b| w.get_ref().bytes >= b)
                    || self
                        .cfg
                        .rotate_after
                        .is_some_and(|a| self.opened.elapsed() >= a)
            }
            None => false,
        };
        if rotate {
            self.close();
        }
        if self.writer.is_none() {
            if self.retry_at.is_some_and(|t| Instant::now() < t) {
                self.stats.failed.fetch_add(1, Relaxed);
                return;
            }
            if let Err(e) = self.open(f.adc_bits) {
                self.fail(e);
                self.stats.failed.fetch_add(1, Relaxed);
                return;
            }
        }
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        match w.write_frame(f) {
            Ok(()) => {
                self.stats.frames.fetch_add(1, Relaxed);
                self.stats.bytes.store(w.get_ref().bytes, Relaxed);
            }
            Err(e) => {
                let name = self
                    .stats
                    .current
                    .lock()
                    .ok()
                    .and_then(|c| c.clone())
                    .unwrap_or_default();
                self.stats.failed.fetch_add(1, Relaxed);
                self.fail(format!("{name}: {e}"));
            }
        }
    }

    fn open(&mut self, adc_bits: u8) -> Result<(), String> {
        std::fs::create_dir_all(&self.cfg.dir)
            .map_err(|e| format!("{}: {e}", self.cfg.dir.display()))?;
        self.seq_in_run += 1;
        let path: PathBuf = self.cfg.dir.join(format!(
            "lightposed-{}-{:04}.jsonl",
            utc_stamp(SystemTime::now()),
            self.seq_in_run
        ));
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        let mut header = self.header.clone();
        header.adc_bits = adc_bits;
        header.extra.insert("started".into(), unix_now().into());
        let w = LogWriter::new(Counted { file, bytes: 0 }, &header)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        let was_error = self.stats.state() == RecState::Error;
        self.writer = Some(w);
        self.opened = Instant::now();
        self.retry_at = None;
        self.stats.files.fetch_add(1, Relaxed);
        if let Ok(mut c) = self.stats.current.lock() {
            *c = Some(path.display().to_string());
        }
        if let Ok(mut e) = self.stats.error.lock() {
            *e = None;
        }
        if was_error {
            tracing::info!("recording resumed in {}", path.display());
        } else {
            tracing::info!("recording to {}", path.display());
        }
        self.stats.set_state(RecState::Recording);
        Ok(())
    }

    fn close(&mut self) {
        if let Some(w) = self.writer.take() {
            let c = w.into_inner();
            // Lines are already in the page cache; sync so that a power cut
            // after a clean stop or a rotation loses nothing either.
            if let Err(e) = c.file.sync_all() {
                tracing::warn!("recording: sync at close failed: {e}");
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
    use lightpose_core::{LogReader, NDET};

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

    #[test]
    fn stamp_of_known_instants() {
        assert_eq!(utc_stamp(SystemTime::UNIX_EPOCH), "19700101T000000Z");
        let t = SystemTime::UNIX_EPOCH + Duration::from_secs(1_709_210_096); // 2024-02-29 12:34:56
        assert_eq!(utc_stamp(t), "20240229T123456Z");
    }

    #[test]
    fn rotates_by_size_and_every_file_reads_back_whole() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = Recording {
            dir: dir.path().to_path_buf(),
            rotate_bytes: Some(2000),
            rotate_after: None,
            queue: 1024,
        };
        let mut r = Recorder::start(&cfg, LogHeader::new(10, 100.0)).unwrap();
        for s in 0..100 {
            r.record(&frame(s));
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
        let cfg = Recording {
            dir: blocker.join("sub"), // a directory under a file: ENOTDIR
            rotate_bytes: None,
            rotate_after: None,
            queue: 16,
        };
        let mut r = Recorder::start(&cfg, LogHeader::new(10, 5.0)).unwrap();
        r.record(&frame(0));
        r.record(&frame(1));
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
        // /dev/full refuses every write with ENOSPC: swap it in under an
        // open log, as a disk that fills up during a dive.
        let Ok(full) = File::options().write(true).open("/dev/full") else {
            eprintln!("skipped: no /dev/full on this machine");
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let stats = Arc::new(RecStats::default());
        let mut w = Worker {
            cfg: Recording {
                dir: dir.path().to_path_buf(),
                rotate_bytes: None,
                rotate_after: None,
                queue: 1,
            },
            header: LogHeader::new(10, 5.0),
            stats: stats.clone(),
            writer: None,
            opened: Instant::now(),
            retry_at: None,
            seq_in_run: 0,
        };
        w.write(&frame(0));
        assert_eq!(stats.state(), RecState::Recording);
        if let Some(lw) = w.writer.as_mut() {
            lw.get_mut().file = full;
        }
        w.write(&frame(1));
        assert_eq!(stats.state(), RecState::Error);
        let err = stats.error.lock().unwrap().clone().unwrap_or_default();
        assert!(err.contains("No space left"), "{err}");
        // Within the retry delay further frames are counted as not recorded.
        w.write(&frame(2));
        assert_eq!(stats.failed.load(Relaxed), 2);
        assert_eq!(stats.frames.load(Relaxed), 1);
    }

    fn worker(dir: PathBuf, stats: &Arc<RecStats>) -> Worker {
        Worker {
            cfg: Recording {
                dir,
                rotate_bytes: None,
                rotate_after: None,
                queue: 4096,
            },
            header: LogHeader::new(10, 5.0),
            stats: stats.clone(),
            writer: None,
            opened: Instant::now(),
            retry_at: None,
            seq_in_run: 0,
        }
    }

    /// Issue 16: once recording resumes, STATUS no longer shows the error.
    #[test]
    fn the_error_is_cleared_when_recording_resumes() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("rec");
        std::fs::write(&blocker, b"x").unwrap();
        let stats = Arc::new(RecStats::default());
        let mut w = worker(blocker.clone(), &stats);
        w.write(&frame(0));
        assert_eq!(stats.state(), RecState::Error);
        assert!(stats.error.lock().unwrap().is_some());
        std::fs::remove_file(&blocker).unwrap();
        w.retry_at = None; // as after the retry delay
        w.write(&frame(1));
        assert_eq!(stats.state(), RecState::Recording);
        assert_eq!(*stats.error.lock().unwrap(), None, "old error still shown");
    }

    /// Issue 16: a disk that takes nothing more (here a FIFO nobody reads)
    /// does not hold the stop: finish gives up after its bound and counts
    /// what was left as not recorded.
    #[test]
    fn finish_does_not_wait_for_a_stuck_disk() {
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
        let mut w = worker(dir.path().to_path_buf(), &stats);
        w.write(&frame(0));
        if let Some(lw) = w.writer.as_mut() {
            lw.get_mut().file = stuck;
        }
        let mut r = Recorder::spawn(w, 4096).unwrap();
        for s in 1..2000 {
            r.record(&frame(s));
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
