//! Recording names and the order of pruning: by the counter in the name,
//! never by the wall-clock stamp (a vehicle computer without an RTC boots
//! with its clock behind, or repeats it); a name already taken is passed
//! over, never overwritten, and costs no frame.

use super::super::names::{self, Rank};
use super::{cfg, est, frame, item, worker};
use super::{Epoch, LogHeader, RecState, Recorder};
use crate::outputs::recfile::create_new;
use lightpose_core::LogReader;
use std::fs::File;
use std::io;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};

/// The names in `dir`, in name order.
fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The counters of the numbered recordings in `dir`, ascending.
fn counters_in(dir: &Path) -> Vec<u64> {
    let mut v: Vec<u64> = names_in(dir)
        .iter()
        .filter_map(|n| match names::rank(n) {
            Some(Rank::Numbered(c, _)) => Some(c),
            _ => None,
        })
        .collect();
    v.sort_unstable();
    v
}

/// The frames of the numbered recordings in `dir`, in counter order.
fn frames_in(dir: &Path) -> Vec<u64> {
    let mut files: Vec<(u64, String)> = names_in(dir)
        .into_iter()
        .filter_map(|n| match names::rank(&n) {
            Some(Rank::Numbered(c, _)) => Some((c, n)),
            _ => None,
        })
        .collect();
    files.sort();
    let mut seqs = Vec::new();
    for (_, n) in files {
        let mut rd = LogReader::open(&dir.join(n)).unwrap();
        for f in rd.by_ref() {
            seqs.push(f.unwrap().seq);
        }
        assert_eq!(rd.truncated_at(), None);
    }
    seqs
}

/// The audit's case: recordings of an earlier boot whose clock was ahead
/// (2099) must not outlive the current dive's. Pruning goes by counter,
/// the old naming first: the current dive keeps its newest files.
#[test]
fn pruning_keeps_the_newest_by_counter_whatever_the_clock_says() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for n in 1..=2 {
        let name = format!("lightposed-20991231T23590{n}Z-0001.jsonl");
        std::fs::write(d.join(name), vec![b'x'; 1000]).unwrap();
    }
    let mut c = cfg(d.to_path_buf(), Some(400), 16);
    c.max_total_bytes = Some(2000);
    let (mut w, stats) = worker(&c);
    for s in 0..60 {
        w.write(&item(s));
    }
    w.close();
    assert_eq!(stats.state(), RecState::Recording);
    let left = names_in(d);
    assert!(
        left.iter().all(|n| !n.contains("2099")),
        "the 2099 files outlived the dive: {left:?}"
    );
    // What is left is this run's last files, each counter once.
    let kept = counters_in(d);
    let last = *kept.last().unwrap();
    assert!(kept.len() >= 2 && last > 2, "{kept:?}");
    assert_eq!(
        kept,
        (last + 1 - kept.len() as u64..=last).collect::<Vec<_>>()
    );
    assert_eq!(*frames_in(d).last().unwrap(), 59);
    assert_eq!(stats.pruned.load(Relaxed), 2 + last - kept.len() as u64);
}

/// The stamp says nothing of the order: counter 1 stamped 2099 is older
/// than counter 2 stamped 1970; the old naming is older than both.
#[test]
fn the_old_naming_is_pruned_first_then_by_counter() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for name in [
        "lightposed-20000101T000000Z-0002.jsonl",
        "lightposed-000001-20991231T235959Z.mcap",
        "lightposed-000002-19700101T000000Z.jsonl",
    ] {
        std::fs::write(d.join(name), vec![b'x'; 1000]).unwrap();
    }
    let mut c = cfg(d.to_path_buf(), Some(500), 16);
    c.max_total_bytes = Some(1500);
    let (mut w, stats) = worker(&c);
    w.write(&item(0));
    w.close();
    assert_eq!(stats.pruned.load(Relaxed), 2);
    let left = names_in(d);
    assert_eq!(left.len(), 2, "{left:?}");
    assert_eq!(left[0], "lightposed-000002-19700101T000000Z.jsonl");
    assert!(left[1].starts_with("lightposed-000003-"), "{left:?}");
}

/// Past 999999 the counter takes a seventh digit and still orders as a
/// number (by name, "1000000" would come before "999999").
#[test]
fn the_counter_goes_past_six_digits_as_a_number() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let old = "lightposed-999999-20260101T000000Z.jsonl";
    std::fs::write(d.join(old), vec![b'x'; 2000]).unwrap();
    let mut c = cfg(d.to_path_buf(), Some(200), 16);
    c.max_total_bytes = Some(1000);
    let (mut w, stats) = worker(&c);
    w.write(&item(0));
    // Room made for the new file: the oldest, 999999, went.
    assert_eq!(stats.pruned.load(Relaxed), 1);
    w.write(&item(1));
    w.write(&item(2));
    w.close();
    assert_eq!(
        counters_in(d).first(),
        Some(&1_000_000),
        "{:?}",
        names_in(d)
    );
    assert!(names_in(d)
        .iter()
        .all(|n| n.starts_with("lightposed-100000")));
    assert!(names::rank(old) < names::rank("lightposed-1000000-19700101T000000Z.jsonl"));
    // A number no counter reaches (made by hand) is no counter: the next
    // would have nowhere to go past u64::MAX.
    let huge = "lightposed-18446744073709551615-20260101T000000Z.mcap";
    assert!(matches!(
        names::rank(huge),
        Some(names::Rank::Unnumbered(_))
    ));
    assert!(
        names::rank("lightposed-20991231T235959Z-0001.mcap")
            < names::rank("lightposed-000001-19700101T000000Z.mcap")
    );
    assert_eq!(names::rank("lightposed-notes.txt"), None);
    assert_eq!(names::rank("other-000001-x.jsonl"), None);
}

/// A file that appears under the name being taken, between the listing
/// and the creation (another process), is passed over: not overwritten,
/// and the frame waiting for the file is recorded in the next number.
#[test]
fn a_name_clash_overwrites_nothing_and_loses_no_frame() {
    // The first name tried is taken as it is created.
    fn raced_once(path: &Path) -> io::Result<File> {
        static DONE: AtomicBool = AtomicBool::new(false);
        if !DONE.swap(true, Relaxed) {
            std::fs::write(path, b"theirs")?;
        }
        create_new(path)
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (mut w, stats) = worker(&cfg(d.to_path_buf(), Some(400), 16));
    w.open_file = raced_once;
    for s in 0..20 {
        w.write(&item(s));
    }
    w.close();
    assert_eq!(stats.state(), RecState::Recording);
    let count = |a: &std::sync::atomic::AtomicU64| a.load(Relaxed);
    assert_eq!([&stats.frames, &stats.failed].map(count), [20, 0]);
    let theirs = d.join(&names_in(d)[0]);
    assert_eq!(std::fs::read(&theirs).unwrap(), b"theirs", "overwritten");
    assert!(theirs.to_string_lossy().contains("lightposed-000001-"));
    // Ours from 2 on, every frame there.
    std::fs::remove_file(theirs).unwrap();
    assert_eq!(counters_in(d)[0], 2);
    assert_eq!(frames_in(d), (0..20).collect::<Vec<_>>());
}

/// The counter goes on from one run to the next (the highest in the
/// directory + 1), so the second run's files are newer whatever its clock.
#[test]
fn the_counter_continues_across_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let c = cfg(d.to_path_buf(), Some(400), 1024);
    let mut first = 0;
    for run in 0..2u64 {
        let mut r = Recorder::start(&c, LogHeader::new(10, 100.0), Epoch::Source).unwrap();
        for s in run * 30..run * 30 + 30 {
            r.record(&frame(s), &est(s), 1.7e9);
        }
        r.finish();
        assert_eq!(r.stats.frames.load(Relaxed), 30);
        if run == 0 {
            first = counters_in(d).len() as u64;
            assert!(first > 1, "rotated");
        }
    }
    let all = counters_in(d);
    assert_eq!(all, (1..=all.len() as u64).collect::<Vec<_>>());
    assert!(all.len() as u64 > first + 1);
    assert_eq!(frames_in(d), (0..60).collect::<Vec<_>>());
}
