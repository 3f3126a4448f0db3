//! The wall clock in a recording: each file's `lightpose-clock` metadata
//! (MCAP, read back with the `mcap` crate through its summary's index) and
//! HEADER `clock`, a new record when the wall clock steps.

use super::super::clock::{ClockWatch, Clocks, Epoch, Synced};
use super::{cfg, est, frame, worker, Item};
use super::{unix_now, LogHeader, Recorder};
use crate::config::RecFormat;
use lightpose_core::{Frame, PoseEstimate};
use lightpose_hal::clock::monotonic_s;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicI64, Ordering::Relaxed};
use std::time::Duration;

fn only_file(dir: &Path) -> std::path::PathBuf {
    let files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files.into_iter().next().unwrap()
}

/// The file's `lightpose-clock` records, in the order written, and its
/// HEADER line as JSON.
fn clock_records(path: &Path) -> (Vec<BTreeMap<String, String>>, Value) {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    let mut clocks = Vec::new();
    let mut header = Value::Null;
    let mut idx = summary.metadata_indexes.clone();
    idx.sort_by_key(|i| i.offset);
    for i in &idx {
        let m = mcap::read::metadata(&bytes, i).unwrap();
        match m.name.as_str() {
            "lightpose-clock" => clocks.push(m.metadata),
            "lightpose-header" => header = serde_json::from_str(&m.metadata["json"]).unwrap(),
            other => panic!("metadata {other}"),
        }
    }
    (clocks, header)
}

fn num(m: &BTreeMap<String, String>, k: &str) -> f64 {
    m[k].parse()
        .unwrap_or_else(|e| panic!("{k} = {:?}: {e}", m[k]))
}

fn mcap_cfg(dir: &Path) -> crate::config::Recording {
    let mut c = cfg(dir.to_path_buf(), None, 1024);
    c.format = RecFormat::Mcap;
    c
}

fn at(seq: u64, t: f64) -> (Frame, PoseEstimate) {
    let mut f = frame(seq);
    f.t = t;
    let mut e = est(seq);
    e.t = t;
    (f, e)
}

/// A board's recording (t on the monotonic clock): the pair was read at
/// open, between the test's own readings of both clocks, and the HEADER
/// says the same.
#[test]
fn a_boards_mcap_maps_its_log_time_to_the_wall_clock() {
    let dir = tempfile::tempdir().unwrap();
    let (mono0, unix0) = (monotonic_s(), unix_now());
    let mut r = Recorder::start(
        &mcap_cfg(dir.path()),
        LogHeader::new(10, 100.0),
        Epoch::Monotonic,
    )
    .unwrap();
    for s in 0..20 {
        let (f, e) = at(s, monotonic_s());
        r.record(&f, &e, unix_now());
    }
    r.finish();
    let (mono1, unix1) = (monotonic_s(), unix_now());
    assert_eq!(r.stats.frames.load(Relaxed), 20);

    let (clocks, header) = clock_records(&only_file(dir.path()));
    assert!(!clocks.is_empty(), "no lightpose-clock metadata");
    let c = &clocks[0];
    assert_eq!(c["epoch"], "monotonic");
    assert_eq!(c["reason"], "open");
    let (t, unix) = (num(c, "t"), num(c, "unix"));
    assert!((mono0..=mono1).contains(&t), "{mono0} ≤ {t} ≤ {mono1}");
    assert!(
        (unix0..=unix1).contains(&unix),
        "{unix0} ≤ {unix} ≤ {unix1}"
    );
    // Read together: the offset is the test's own, within its reads.
    let offset = num(c, "offset");
    assert!((offset - (unix - t)).abs() < 1e-6, "{offset}");
    assert!((offset - (unix0 - mono0)).abs() < 0.5, "{offset}");
    let log_time: u64 = c["log_time"].parse().unwrap();
    assert!(
        (log_time as f64 / 1e9 - t).abs() < 1e-6,
        "{log_time} vs {t}"
    );
    // "unknown" where adjtimex is refused (a seccomp profile, gVisor).
    assert!(["true", "false", "unknown"].contains(&c["synced"].as_str()));
    // Every record after the first is a step or a change of sync.
    assert!(clocks[1..].iter().all(|c| c["reason"] != "open"));

    let hc = &header["clock"];
    assert_eq!(hc["epoch"], "monotonic", "{header}");
    assert_eq!(hc["t"].as_f64(), Some(t), "{header}");
    assert_eq!(hc["unix"].as_f64(), Some(unix), "{header}");
    match c["synced"].as_str() {
        "unknown" => assert!(hc["synced"].is_null(), "{header}"),
        s => assert_eq!(hc["synced"].to_string(), s, "{header}"),
    }
}

/// Seconds the fake wall clock is set forward by.
static STEPPED: AtomicI64 = AtomicI64::new(0);

/// The machine's clocks with the wall clock `STEPPED` ahead; never synced.
fn stepped_clocks() -> Clocks {
    Clocks {
        mono: monotonic_s(),
        unix: unix_now() + STEPPED.load(Relaxed) as f64,
        synced: Synced::No,
    }
}

fn wait_until(mut done: impl FnMut() -> bool) {
    let t0 = std::time::Instant::now();
    while !done() && t0.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The wall clock set an hour forward during a recording: a board's MCAP
/// gets a second record right away (on the recorder's check), another
/// epoch's with the next frame (its own t and arrival); none more while
/// the clock stays. JSON Lines keeps its HEADER's only.
#[test]
fn a_wall_clock_step_writes_a_new_record() {
    for epoch in [Epoch::Monotonic, Epoch::Source] {
        STEPPED.store(0, Relaxed);
        let dir = tempfile::tempdir().unwrap();
        let (mut w, stats) = worker(&mcap_cfg(dir.path()));
        w.clock = ClockWatch::new(epoch);
        w.clock.read = stepped_clocks;
        w.clock.every = Duration::from_millis(10);
        let mut r = Recorder::spawn(w, 64).unwrap();
        let t_of = |s: u64| match epoch {
            Epoch::Monotonic => monotonic_s(),
            Epoch::Source => s as f64 * 0.01,
        };
        let item = |s: u64, stepped: i64| {
            let (frame, est) = at(s, t_of(s));
            Item {
                burst: None,
                frame,
                est,
                wall_unix: 1.7e9 + s as f64 + stepped as f64,
            }
        };
        for s in 0..5 {
            let i = item(s, 0);
            r.record(&i.frame, &i.est, i.wall_unix);
        }
        wait_until(|| stats.frames.load(Relaxed) == 5);
        std::thread::sleep(Duration::from_millis(50));
        STEPPED.store(3600, Relaxed);
        // Checks go by: the recorder thread wakes every 250 ms when idle.
        std::thread::sleep(Duration::from_millis(400));
        for s in 5..10 {
            let i = item(s, 3600);
            r.record(&i.frame, &i.est, i.wall_unix);
        }
        wait_until(|| stats.frames.load(Relaxed) == 10);
        std::thread::sleep(Duration::from_millis(50));
        r.finish();

        let (clocks, _) = clock_records(&only_file(dir.path()));
        let what: Vec<_> = clocks.iter().map(|c| c["reason"].as_str()).collect();
        assert_eq!(what, ["open", "step"], "{epoch:?}: {clocks:?}");
        let (a, b) = (&clocks[0], &clocks[1]);
        assert!(clocks.iter().all(|c| c["synced"] == "false"));
        let jump = num(b, "offset") - num(a, "offset");
        match epoch {
            // Both pairs read from the clocks: the offset moved an hour.
            Epoch::Monotonic => assert!((jump - 3600.0).abs() < 0.1, "{jump}"),
            // The frames' pairs: the first frame's, then the first after
            // the step (seq 5, t 0.05).
            Epoch::Source => {
                assert_eq!((num(a, "t"), num(a, "unix")), (0.0, 1.7e9));
                assert_eq!((num(b, "t"), num(b, "unix")), (0.05, 1.7e9 + 3605.0));
            }
        }
    }
    STEPPED.store(0, Relaxed);

    // JSON Lines: the HEADER's clock, no other line.
    let dir = tempfile::tempdir().unwrap();
    let mut r = Recorder::start(
        &cfg(dir.path().to_path_buf(), None, 64),
        LogHeader::new(10, 100.0),
        Epoch::Source,
    )
    .unwrap();
    for s in 0..3 {
        r.record(&frame(s), &est(s), 1.7e9 + s as f64);
    }
    r.finish();
    let text = std::fs::read_to_string(only_file(dir.path())).unwrap();
    let lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 4, "{text}");
    let hc = &lines[0]["clock"];
    assert_eq!(hc["epoch"], "source", "{text}");
    assert_eq!(
        (hc["t"].as_f64(), hc["unix"].as_f64()),
        (Some(0.0), Some(1.7e9))
    );
    assert!(
        hc["synced"].is_boolean() || hc["synced"].is_null(),
        "{text}"
    );
    assert!(lines[1..].iter().all(|l| l["class"] == "FRAME"));
}
