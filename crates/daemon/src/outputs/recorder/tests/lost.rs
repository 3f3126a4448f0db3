//! What a recording loses without the disk refusing a write (a disk-fault
//! audit: each was counted recorded, and synced, while lost): the file
//! removed with its directory, a sync that fails (EIO: pages the device
//! lost), an MCAP file killed before its first chunk.

use super::super::Recorder;
use super::{cfg, est, frame, item, worker, RecState};
use crate::config::RecFormat;
use crate::outputs::recfile::{create_new, RecFile};
use lightpose_core::{LogHeader, LogReader};
use lightpose_testkit::logs::logged;
use std::os::fd::AsRawFd;
use std::path::Path;
use std::sync::atomic::Ordering::Relaxed;

fn files_in(dir: &Path) -> usize {
    std::fs::read_dir(dir).map_or(0, |d| d.count())
}

/// Removed with its directory while written: the next room check (2 s)
/// finds it, every frame in it is counted lost, the state is `error`, and
/// the next attempt makes the directory again and records.
#[test]
fn a_recording_removed_while_written_is_lost_counted_and_recording_resumes() {
    for format in [RecFormat::Jsonl, RecFormat::Mcap] {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("rec");
        let mut c = cfg(rec.clone(), None, 16);
        c.format = format;
        let (mut w, stats) = worker(&c);
        for s in 0..5 {
            w.write(&item(s));
        }
        w.flush();
        assert_eq!(stats.synced.load(Relaxed), 5, "{format:?}");
        std::fs::remove_dir_all(&rec).unwrap();
        for s in 5..8 {
            w.write(&item(s)); // taken by a file nobody can read
        }
        let log = logged(|| w.check_space());
        assert_eq!(stats.state(), RecState::Error, "{format:?}");
        let counts = (stats.frames.load(Relaxed), stats.failed.load(Relaxed));
        assert_eq!(counts, (0, 8), "{format:?}");
        assert_eq!(stats.synced.load(Relaxed), 0, "{format:?}");
        assert!(
            log.contains("removed while being written: its 8 frames are lost"),
            "{format:?}: {log}"
        );
        let err = stats.error.lock().unwrap().clone().unwrap_or_default();
        assert!(err.contains("removed while being written"), "{err}");
        w.retry_at = None; // as once the wait is over
        w.write(&item(8));
        w.flush();
        assert_eq!(stats.state(), RecState::Recording, "{format:?}");
        assert_eq!((files_in(&rec), stats.frames.load(Relaxed)), (1, 1));
    }
}

/// Removed at stop, before a room check saw it: the last STATUS says so.
#[test]
fn a_recording_removed_before_the_stop_leaves_the_state_in_error() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let (w, stats) = worker(&cfg(rec.clone(), None, 64));
    let mut r = Recorder::spawn(w, 64).unwrap();
    for s in 0..10 {
        r.record(&frame(s), &est(s), 1.7e9);
    }
    while stats.frames.load(Relaxed) < 10 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::fs::remove_dir_all(&rec).unwrap();
    r.finish();
    assert_eq!(stats.state(), RecState::Error);
    let err = stats.error.lock().unwrap().clone().unwrap_or_default();
    assert!(err.contains("its 10 frames are lost"), "{err}");
    assert_eq!(
        (stats.frames.load(Relaxed), stats.failed.load(Relaxed)),
        (0, 10)
    );
}

/// A sync that fails (here on a pipe, EINVAL; on a dying card, EIO) ends
/// the file at the last sync that succeeded: the kernel tells a lost
/// write-back once, so a second sync at close would have said all was
/// well and counted the lost frames recorded.
#[test]
fn a_failed_sync_keeps_only_what_the_last_good_sync_holds() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.jsonl");
    let file = create_new(&path).unwrap();
    let header = LogHeader::new(10, 5.0);
    let mut f = RecFile::create(
        path.clone(),
        file,
        RecFormat::Jsonl,
        &header,
        1 << 16,
        &Default::default(),
    )
    .unwrap();
    for s in 0..3 {
        f.write(&frame(s), &est(s), 1.7e9).unwrap();
    }
    f.flush().unwrap();
    for s in 3..5 {
        f.write(&frame(s), &est(s), 1.7e9).unwrap();
    }
    let (_r, pipe) = nix::unistd::pipe().unwrap();
    let fd = f.sync_fd();
    let saved = nix::unistd::dup(fd).unwrap();
    nix::unistd::dup2(pipe.as_raw_fd(), fd).unwrap();
    let e = f.flush().expect_err("a sync on a pipe fails");
    assert!(e.contains("r.jsonl"), "{e}");
    // The file again under it, to see where it is cut.
    nix::unistd::dup2(saved, fd).unwrap();
    nix::unistd::close(saved).unwrap();
    let c = f.close();
    assert_eq!((c.kept, c.lost, c.removed), (3, 2, false), "{c:?}");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut r = LogReader::new(text.as_bytes(), "r.jsonl").unwrap();
    let mut n = 0;
    while let Some(frame) = r.next_frame() {
        frame.unwrap();
        n += 1;
    }
    assert_eq!(n, 3);
}

/// An MCAP file reads as MCAP from its creation, before its first chunk:
/// killed within `flush_s` of a rotation, it was a file of 0 bytes that
/// replay and convert refused.
#[test]
fn an_mcap_recording_has_its_header_on_the_disk_from_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 16);
    c.format = RecFormat::Mcap;
    let (mut w, _stats) = worker(&c);
    w.write(&item(0));
    let path = w.file.as_ref().unwrap().path.clone();
    let bytes = std::fs::read(&path).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n"), "{} bytes", bytes.len());
}
