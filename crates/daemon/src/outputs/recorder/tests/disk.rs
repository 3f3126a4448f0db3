//! A full disk without root: files made on /dev/full (`dup2` under the
//! file the recorder opens, or under its open log), which refuses every
//! write with ENOSPC; a free-space guard set above the disk's free space;
//! old recordings pruned for `max_total_mb` and `keep_free_mb`.

use super::super::space::{default_floor, free_bytes, Space, MAX_FLOOR, MIN_FREE};
use super::super::worker::{RETRY_FIRST, RETRY_MAX};
use super::RecState;
use super::{cfg, item, worker};
use crate::config::RecFormat;
use lightpose_testkit::logs::logged;
use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering::Relaxed;

/// A new file whose writes all fail as on a full disk: it exists, as a
/// file created on a full filesystem does (an inode is still free).
fn on_full_disk(path: &Path) -> io::Result<File> {
    let f = crate::outputs::recfile::create_new(path)?;
    let full = File::options().write(true).open("/dev/full")?;
    nix::unistd::dup2(full.as_raw_fd(), f.as_raw_fd())?;
    Ok(f)
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// A full disk (each new file refuses its first write): no empty file is
/// left per attempt, the attempts come less and less often (2 s doubling
/// up to 60 s), the failure is logged once and so is the resumption,
/// which waits for the new file's first sync.
#[test]
fn a_full_disk_leaves_no_empty_files_and_backs_off() {
    for format in [RecFormat::Jsonl, RecFormat::Mcap] {
        let dir = tempfile::tempdir().unwrap();
        let mut c = cfg(dir.path().to_path_buf(), None, 16);
        c.format = format;
        let (mut w, stats) = worker(&c);
        w.open_file = on_full_disk;
        let mut waits = Vec::new();
        let log = logged(|| {
            for s in 0..8 {
                w.retry_at = None; // as once the wait is over
                w.write(&item(s));
                w.flush(); // MCAP meets the disk here
                assert_eq!(files_in(dir.path()), Vec::<PathBuf>::new(), "{format:?}");
                assert_eq!(stats.state(), RecState::Error, "{format:?}");
                waits.push(w.backoff.as_secs());
            }
            w.open_file = crate::outputs::recfile::create_new;
            w.retry_at = None;
            w.write(&item(8));
            w.flush();
        });
        assert_eq!(waits, [2, 4, 8, 16, 32, 60, 60, 60], "{format:?}");
        assert_eq!((RETRY_FIRST.as_secs(), RETRY_MAX.as_secs()), (2, 60));
        assert_eq!(stats.state(), RecState::Recording, "{format:?}: {log}");
        assert_eq!(w.backoff, RETRY_FIRST, "the wait starts over");
        let count = |a: &std::sync::atomic::AtomicU64| a.load(Relaxed);
        assert_eq!(
            [&stats.outages, &stats.retries, &stats.failed, &stats.frames].map(count),
            [1, 7, 8, 1],
            "{format:?}: outages, retries, failed, frames"
        );
        assert_eq!(log.matches("ERROR").count(), 1, "{format:?}: {log}");
        assert!(log.contains("No space left"), "{log}");
        assert_eq!(log.matches("recording resumed").count(), 1, "{log}");
        assert_eq!(log.matches(" WARN ").count(), 0, "{format:?}: {log}");
        assert_eq!(files_in(dir.path()).len(), 1);
    }
}

/// An MCAP cut by a full disk mid-file is cut back to its last sync and
/// completed there (Data End, Footer): it reads whole, not cut, with the
/// frames synced; those written after it are counted as not recorded.
#[test]
fn an_mcap_cut_by_a_full_disk_is_completed_at_its_last_sync() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 16);
    c.format = RecFormat::Mcap;
    let (mut w, stats) = worker(&c);
    for s in 0..10 {
        w.write(&item(s));
    }
    w.flush();
    for s in 10..15 {
        w.write(&item(s));
    }
    let full = File::options().write(true).open("/dev/full").unwrap();
    let fd = w.file.as_ref().unwrap().sink_fd();
    nix::unistd::dup2(full.as_raw_fd(), fd).unwrap();
    w.flush();
    assert_eq!(stats.state(), RecState::Error);
    let count = |a: &std::sync::atomic::AtomicU64| a.load(Relaxed);
    assert_eq!(
        [&stats.frames, &stats.synced, &stats.failed].map(count),
        [10, 10, 5]
    );
    let files = files_in(dir.path());
    assert_eq!(files.len(), 1);
    let mut log = lightpose_logs::LogFile::open(&files[0]).unwrap();
    let mut seqs = Vec::new();
    while let Some(f) = lightpose_logs::FrameLog::next_frame(&mut log) {
        seqs.push(f.unwrap().seq);
    }
    assert_eq!(seqs, (0..10).collect::<Vec<u64>>());
    assert_eq!(lightpose_logs::FrameLog::cut(&log), None, "completed");
    // Another reader: the mcap crate finds the footer and every message.
    let bytes = std::fs::read(&files[0]).unwrap();
    let footer = mcap::read::footer(&bytes).unwrap();
    assert_eq!(footer.summary_start, 0, "no summary section");
    let frames = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/lightpose/frame")
        .count();
    assert_eq!(frames, 10);
}

/// Below the free space to keep, no file is started (and none left
/// empty); an open file is completed, with its summary, and recording
/// stops until there is room.
#[test]
fn a_nearly_full_disk_is_not_written_to() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cfg(dir.path().to_path_buf(), None, 16);
    c.format = RecFormat::Mcap;
    let (mut w, stats) = worker(&c);
    w.space.keep_free = Some(u64::MAX);
    w.write(&item(0));
    assert_eq!(stats.state(), RecState::Error);
    let err = stats.error.lock().unwrap().clone().unwrap_or_default();
    assert!(err.contains("MiB kept free"), "{err}");
    assert_eq!(files_in(dir.path()), Vec::<PathBuf>::new());
    assert_eq!(stats.failed.load(Relaxed), 1);

    let (mut w, stats) = worker(&c);
    for s in 0..5 {
        w.write(&item(s));
    }
    w.space.keep_free = Some(free_bytes(dir.path()).unwrap().saturating_add(1 << 40));
    w.check_space();
    assert_eq!(stats.state(), RecState::Error);
    assert_eq!(stats.synced.load(Relaxed), 5);
    let files = files_in(dir.path());
    assert_eq!(files.len(), 1);
    let bytes = std::fs::read(&files[0]).unwrap();
    let footer = mcap::read::footer(&bytes).unwrap();
    assert!(footer.summary_start > 0, "completed with its summary");
}

/// Without `keep_free_mb` the free space kept scales with the filesystem:
/// 2 % of it, at least 32 MiB, at most 1 GiB (it was 32 MiB on any disk,
/// which left an SD card's system nothing); nothing is pruned for it.
#[test]
fn the_default_floor_scales_with_the_disk() {
    const GB: u64 = 1_000_000_000;
    assert_eq!((MIN_FREE, MAX_FLOOR), (32 << 20, 1 << 30));
    assert_eq!(default_floor(0), MIN_FREE);
    assert_eq!(default_floor(GB), MIN_FREE, "a small disk keeps 32 MiB");
    assert_eq!(default_floor(8 * GB), 160 * GB / 1000);
    assert_eq!(default_floor(32 * GB), 640 * GB / 1000);
    assert_eq!(default_floor(4000 * GB), MAX_FLOOR, "capped");
    let dir = tempfile::tempdir().unwrap();
    let c = cfg(dir.path().to_path_buf(), None, 16);
    let (free, keep) = Space::new(&c).room().unwrap();
    let size = nix::sys::statvfs::statvfs(dir.path()).unwrap();
    #[allow(clippy::useless_conversion)]
    let size = u64::from(size.blocks()) * u64::from(size.fragment_size());
    assert_eq!(keep, default_floor(size));
    assert!(free > 0);
    let mut c = c;
    c.keep_free_bytes = Some(5 << 20);
    assert_eq!(Space::new(&c).room().unwrap().1, 5 << 20, "configured wins");
}

/// `max_total_mb` deletes the oldest recordings (by name) until the total
/// fits; `keep_free_mb` deletes them while the disk has less free; neither
/// touches other files or the open recording.
#[test]
fn old_recordings_are_pruned_oldest_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for n in 1..=3 {
        let name = format!("lightposed-20000101T00000{n}Z-0001.jsonl");
        std::fs::write(d.join(name), vec![b'x'; 1000]).unwrap();
    }
    std::fs::write(d.join("notes.txt"), vec![b'x'; 5000]).unwrap();
    std::fs::write(d.join("lightposed-notes.txt"), b"x").unwrap();
    let mut c = cfg(d.to_path_buf(), Some(500), 16);
    c.max_total_bytes = Some(2500);
    let (mut w, stats) = worker(&c);
    w.write(&item(0));
    assert_eq!(stats.state(), RecState::Recording);
    let name = |p: &PathBuf| p.file_name().unwrap().to_string_lossy().into_owned();
    let left: Vec<String> = files_in(d).iter().map(name).collect();
    assert_eq!(stats.pruned.load(Relaxed), 1);
    assert!(!left.contains(&"lightposed-20000101T000001Z-0001.jsonl".to_string()));
    assert_eq!(left.len(), 5, "{left:?}");
    w.close();

    let mut c = cfg(d.to_path_buf(), None, 16);
    c.keep_free_bytes = Some(free_bytes(d).unwrap().saturating_add(1 << 40));
    let (mut w, stats) = worker(&c);
    w.write(&item(1));
    let left: Vec<String> = files_in(d).iter().map(name).collect();
    assert_eq!(left, ["lightposed-notes.txt", "notes.txt"]);
    assert_eq!(stats.pruned.load(Relaxed), 3);
    assert_eq!(stats.state(), RecState::Error, "still no room");
}

/// The limits as the configuration gives them.
#[test]
fn the_limits_are_read_and_checked() {
    let base = "rate_hz = 50.0\ncalibration = \"cal.toml\"\n[backend]\nkind = \"replay\"\nlog = \"x.jsonl\"\npace = \"fast\"\n[outputs]\ndestinations = [\"127.0.0.1:9999\"]\n[recording]\ndir = \"/tmp/r\"\n";
    let parse =
        |extra: &str| crate::config::Config::parse(&format!("{base}{extra}"), "t.toml", None);
    let r = parse("").unwrap().recording.unwrap();
    assert_eq!((r.keep_free_bytes, r.max_total_bytes), (None, None));
    let r = parse("rotate_mb = 10\nmax_total_mb = 100\nkeep_free_mb = 0.5\n")
        .unwrap()
        .recording
        .unwrap();
    assert_eq!(
        (r.keep_free_bytes, r.max_total_bytes),
        (Some(512 << 10), Some(100 << 20))
    );
    let e = parse("max_total_mb = 100\n").unwrap_err().to_string();
    assert!(e.contains("recording.max_total_mb: needs rotate_mb"), "{e}");
    let e = parse("rotate_mb = 200\nmax_total_mb = 100\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("recording.max_total_mb: 100 MiB is less than rotate_mb = 200 MiB"),
        "{e}"
    );
    let e = parse("keep_free_mb = -1\n").unwrap_err().to_string();
    assert!(e.contains("recording.keep_free_mb: -1 is not in"), "{e}");
}
