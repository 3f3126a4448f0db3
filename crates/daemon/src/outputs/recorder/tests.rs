//! The recorder's tests: rotation, a refusing or stuck disk, frames the
//! format cannot hold, STATUS behind a slow disk ([`disk`]: a full disk;
//! [`lost`]: a file removed, a failed sync; [`names`]: the recordings'
//! names and the order of pruning).

mod clock;
mod disk;
mod lost;
mod names;

use super::worker::Worker;
use super::*;
use lightpose_core::{LogReader, Status, NDET};
use std::fs::File;
use std::path::PathBuf;

pub(super) fn frame(seq: u64) -> Frame {
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
        amplitudes: None,
    }
}

pub(super) fn est(seq: u64) -> PoseEstimate {
    PoseEstimate::empty(seq, seq as f64 * 0.01, Status::NoLight, "test")
}

/// The frame and estimate `seq` as the frame thread hands them over.
pub(super) fn item(seq: u64) -> Item {
    Item {
        burst: None,
        frame: frame(seq),
        est: est(seq),
        wall_unix: 1.7e9,
    }
}

/// A recording worker of `c` and its counters.
pub(super) fn worker(c: &Recording) -> (Worker, Arc<RecStats>) {
    let stats = Arc::new(RecStats {
        format: c.format,
        ..RecStats::default()
    });
    let w = Worker::new(c, LogHeader::new(10, 5.0), stats.clone(), Epoch::Source);
    (w, stats)
}

pub(super) fn cfg(dir: PathBuf, rotate_bytes: Option<u64>, queue: usize) -> Recording {
    Recording {
        samples: Default::default(),
        dir,
        rotate_bytes,
        rotate_after: None,
        queue,
        format: crate::config::RecFormat::Jsonl,
        flush: Duration::from_secs(2),
        keep_free_bytes: None,
        max_total_bytes: None,
        bag: Default::default(),
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
    let mut r = Recorder::start(&cfg, LogHeader::new(10, 100.0), Epoch::Source).unwrap();
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
    let mut r = Recorder::start(&cfg, LogHeader::new(10, 5.0), Epoch::Source).unwrap();
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
    for format in [RecFormat::Jsonl, RecFormat::Mcap, RecFormat::Ros2] {
        let dir = tempfile::tempdir().unwrap();
        let stats = Arc::new(RecStats::default());
        let mut c = cfg(dir.path().to_path_buf(), None, 1);
        c.format = format;
        let mut w = Worker::new(&c, LogHeader::new(10, 5.0), stats.clone(), Epoch::Source);
        let item = |seq| Item {
            burst: None,
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
        // recorded. JSONL keeps its whole line; MCAP had synced nothing:
        // its two frames are lost (counted) and the file is removed.
        w.write(&item(2));
        let failed = stats.failed.load(Relaxed);
        let files = std::fs::read_dir(dir.path()).unwrap().count();
        match format {
            RecFormat::Jsonl => assert_eq!((failed, stats.frames.load(Relaxed), files), (2, 1, 1)),
            RecFormat::Mcap | RecFormat::Ros2 => {
                assert_eq!(
                    (failed, stats.frames.load(Relaxed), files),
                    (3, 0, 0),
                    "{format:?}"
                )
            }
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
        Epoch::Source,
    );
    w.write(&item(0));
    assert_eq!(stats.state(), RecState::Error);
    assert!(stats.error.lock().unwrap().is_some());
    std::fs::remove_file(&blocker).unwrap();
    w.retry_at = None; // as after the retry delay
    w.write(&item(1));
    // Resumed once the new file reached the disk (its first sync).
    assert_eq!(stats.state(), RecState::Error);
    w.flush();
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
        Epoch::Source,
    );
    w.write(&Item {
        burst: None,
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
    assert!(err.contains("not known to be recorded"), "{err}");
    // Only what reached the disk counts as recorded (an audit: an MCAP
    // chunk still in memory was counted).
    assert_eq!(stats.frames.load(Relaxed), stats.synced.load(Relaxed));
    let recorded = stats.frames.load(Relaxed);
    let failed = stats.failed.load(Relaxed);
    assert!(
        failed > 0 && recorded + failed >= 1999,
        "{recorded} + {failed}"
    );
    // Let the writer go: drain the FIFO. The thread, unblocked, changes
    // no count the stop settled (its write, then its close, counted the
    // same frames again: a review).
    let mut rd = File::open(&fifo).unwrap();
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut rd, &mut std::io::sink());
    });
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(
        (stats.frames.load(Relaxed), stats.failed.load(Relaxed)),
        (recorded, failed)
    );
    assert_eq!(stats.state(), RecState::Error);
    assert_eq!(stats.error.lock().unwrap().clone().unwrap_or_default(), err);
}

/// A frame whose t has no MCAP log time (t < 0, a replayed log whose
/// epoch is not its start) costs that frame only: counted as skipped, the
/// file goes on (it used to be dropped and every frame for 2 s failed).
#[test]
fn a_frame_without_log_time_is_skipped_and_the_file_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 1024);
    c.format = RecFormat::Mcap;
    let mut r = Recorder::start(&c, LogHeader::new(10, 100.0), Epoch::Source).unwrap();
    for s in 0..40 {
        let (mut f, mut e) = (frame(s), est(s));
        if s == 5 || s == 17 {
            (f.t, e.t) = (-1.0, -1.0);
        }
        r.record(&f, &e, 1.7e9);
    }
    r.finish();
    let st = &r.stats;
    let counts = [&st.frames, &st.skipped, &st.failed, &st.files].map(|a| a.load(Relaxed));
    assert_eq!(counts, [38, 2, 0, 1], "frames, skipped, failed, files");
    assert_eq!(st.state(), RecState::Closed);
    let path = std::fs::read_dir(dir.path())
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let mut log = lightpose_logs::LogFile::open(&path).unwrap();
    let mut seqs = Vec::new();
    while let Some(f) = lightpose_logs::FrameLog::next_frame(&mut log) {
        seqs.push(f.unwrap().seq);
    }
    let want: Vec<u64> = (0..40).filter(|s| *s != 5 && *s != 17).collect();
    assert_eq!(seqs, want);
    assert_eq!(lightpose_logs::FrameLog::cut(&log), None);
}

/// Frames the format cannot hold, a burst of 3: the first said at once,
/// the 2 after it by the closing line once none came for 1 s (the
/// recorder thread's loop asks at least every 250 ms); once.
#[test]
fn the_end_of_a_burst_of_skipped_frames_is_told() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 1024);
    c.format = RecFormat::Mcap;
    let (mut w, stats) = worker(&c);
    let text = lightpose_testkit::logs::logged(|| {
        for s in 0..3 {
            let (mut f, mut e) = (frame(s), est(s));
            (f.t, e.t) = (-1.0, -1.0);
            w.write(&Item {
                burst: None,
                frame: f,
                est: e,
                wall_unix: 1.7e9,
            });
        }
        let now = Instant::now();
        w.settle_skips(now);
        w.settle_skips(now + Duration::from_secs(2));
        w.settle_skips(now + Duration::from_secs(3));
    });
    assert_eq!(stats.skipped.load(Relaxed), 3);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert!(lines[0].contains("skipped=1 since_last_line=1"), "{text}");
    assert!(
        lines[1].contains("WARN")
            && lines[1].contains("skipped=3 since_last_line=2")
            && lines[1].contains("the condition is over: 2 more not recorded since the last line"),
        "{text}"
    );
}

/// STATUS that finds its queue full (the recorder thread held by a disk
/// that takes nothing: a FIFO nobody reads) is counted, not dropped
/// silently.
#[test]
fn status_behind_a_stuck_disk_is_counted() {
    use std::os::fd::AsRawFd;
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("stuck");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success(), "mkfifo");
    let stuck = File::options().read(true).write(true).open(&fifo).unwrap();
    let stats = Arc::new(RecStats {
        format: RecFormat::Mcap,
        ..RecStats::default()
    });
    let mut c = cfg(dir.path().join("rec"), None, 4096);
    c.format = RecFormat::Mcap;
    let mut w = Worker::new(&c, LogHeader::new(10, 5.0), stats.clone(), Epoch::Source);
    w.write(&Item {
        burst: None,
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
    // Held once the queue stops draining.
    let mut last = u64::MAX;
    loop {
        std::thread::sleep(Duration::from_millis(200));
        let q = stats.queued.load(Relaxed);
        if q == last && q > 0 {
            break;
        }
        last = q;
    }
    let tap = r.status_tap();
    for _ in 0..10 {
        tap.status(br#"{"class":"STATUS"}"#);
    }
    assert_eq!(stats.status_dropped.load(Relaxed), 10 - STATUS_QUEUE as u64);
    let mut rd = File::open(&fifo).unwrap();
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut rd, &mut std::io::sink());
    });
    r.finish_within(Duration::from_millis(300));
}

/// An MCAP recording without rotation keys rotates by default (an hour,
/// or 8192 chunks: the `mcap` writer keeps an index entry per chunk until
/// the file closes); a configured rotation replaces the hour, never the
/// chunk bound, and JSONL has none. Shortened here, each file reads back whole.
#[test]
fn mcap_without_rotation_rotates_by_default() {
    use crate::config::recording::{Rotation, MCAP_MAX_CHUNKS, MCAP_ROTATE_AFTER};
    let base = "rate_hz = 50.0\ncalibration = \"cal.toml\"\n[backend]\nkind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"\n[outputs]\ndestinations = [\"127.0.0.1:9999\"]\n[recording]\ndir = \"/tmp/r\"\n";
    let rotation = |extra: &str| {
        let c = crate::config::Config::parse(&format!("{base}{extra}"), "t.toml", None);
        c.unwrap().recording.unwrap().rotation()
    };
    let default = Rotation {
        bytes: None,
        after: Some(Duration::from_secs(3600)),
        chunks: Some(8192),
    };
    assert_eq!(
        (MCAP_ROTATE_AFTER, MCAP_MAX_CHUNKS),
        (default.after.unwrap(), 8192)
    );
    assert_eq!(rotation("format = \"mcap\"\n"), default);
    let ten = Some(Duration::from_secs(600));
    let configured = rotation("format = \"mcap\"\nrotate_minutes = 10\n");
    // The chunk bound stays: a configured day at 1 kHz would be ~260 k
    // index entries.
    assert_eq!((configured.after, configured.chunks), (ten, Some(8192)));
    let jsonl = rotation("");
    assert_eq!((jsonl.bytes, jsonl.after, jsonl.chunks), (None, None, None));

    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 16);
    c.format = RecFormat::Mcap;
    let stats = Arc::new(RecStats::default());
    let mut w = Worker::new(&c, LogHeader::new(10, 5.0), stats.clone(), Epoch::Source);
    assert_eq!(w.rotation, default);
    let item = |seq| Item {
        burst: None,
        frame: frame(seq),
        est: est(seq),
        wall_unix: 1.7e9,
    };
    // By chunks: one per flush here.
    w.rotation.chunks = Some(3);
    for s in 0..10 {
        w.write(&item(s));
        w.flush();
    }
    assert_eq!(stats.files.load(Relaxed), 4, "3 + 3 + 3 + 1 frames");
    // By age (from a new file).
    w.close();
    w.rotation = Rotation {
        chunks: None,
        after: Some(Duration::from_millis(50)),
        ..default
    };
    w.write(&item(10));
    std::thread::sleep(Duration::from_millis(60));
    w.write(&item(11));
    w.close();
    assert_eq!(stats.files.load(Relaxed), 6);
    let mut seqs = Vec::new();
    let mut paths: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    paths.sort();
    for p in &paths {
        let mut log = lightpose_logs::LogFile::open(p).unwrap();
        while let Some(f) = lightpose_logs::FrameLog::next_frame(&mut log) {
            seqs.push(f.unwrap().seq);
        }
        assert_eq!(lightpose_logs::FrameLog::cut(&log), None, "{p:?} whole");
    }
    assert_eq!(seqs, (0..12).collect::<Vec<u64>>());
}
