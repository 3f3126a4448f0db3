//! Spec v3 logs through the operator's readers: a BURST log from
//! `lightpose simulate` of a blinking beacon by day (one beacon:
//! config/scenes/harbour-day.toml; two: tests/data/v3/two-beacons.toml)
//! replays to poses, demodulated on the way, and the same poses as the
//! daemon's replay backend would give are not this test's (crates/daemon
//! tests/v3.rs); `convert` carries a BURST log into JSON Lines unchanged,
//! and into MCAP (its binary `/lightpose/burst`) and back byte for byte.

mod common;

use common::{root, run, s};
use std::path::Path;

fn simulate(scene: &Path, out: &Path) {
    let traj = root().join("config/trajectories/dock.csv");
    let (ok, _, err) = run(&[
        "simulate",
        "--scene",
        s(scene),
        "--trajectory",
        s(&traj),
        "--out",
        s(out),
        "--seed",
        "3",
    ]);
    assert!(ok, "{err}");
}

fn lines(p: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(p)
        .expect("read")
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect()
}

#[test]
fn a_burst_log_replays_to_poses() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("day.jsonl");
    simulate(&root().join("config/scenes/harbour-day.toml"), &log);
    assert_eq!(lines(&log)[1]["class"], "BURST");
    let poses = dir.path().join("day.poses.jsonl");
    let cal = root().join("config/calibration/harbour.toml");
    let (ok, _, err) = run(&[
        "replay",
        "--log",
        s(&log),
        "--calibration",
        s(&cal),
        "--out",
        s(&poses),
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("demodulating 400 samples a frame at 2000 Hz (1 beacon(s))"),
        "{err}"
    );
    let p = lines(&poses);
    // dock.csv: 10 s at 5 Hz, a frame while its middle is within it.
    assert_eq!(p.len(), 50, "{err}");
    assert!(p.iter().all(|v| v["class"] == "POSE"));
    // A frame's t is the middle of its samples.
    assert!((p[0]["t"].as_f64().expect("t") - 399.0 / 4000.0).abs() < 1e-12);
    let ok_poses = p.iter().filter(|v| v["status"] == "ok").count();
    assert!(ok_poses >= 30, "{ok_poses} ok of 50: {err}");
}

#[test]
fn a_two_beacon_burst_log_is_demodulated_for_both() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("two.jsonl");
    simulate(&root().join("tests/data/v3/two-beacons.toml"), &log);
    let out = dir.path().join("two.poses.jsonl");
    // The moments estimator reads any ADC (the scene's is 12-bit).
    let cal = root().join("config/calibration/tank.toml");
    let (ok, _, err) = run(&[
        "replay",
        "--log",
        s(&log),
        "--calibration",
        s(&cal),
        "--estimator",
        "moments",
        "--out",
        s(&out),
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("demodulating 200 samples a frame at 2000 Hz (2 beacon(s))"),
        "{err}"
    );
    assert_eq!(lines(&out).len(), 100, "{err}");
}

#[test]
fn convert_carries_bursts_into_jsonl_and_through_mcap_unchanged() {
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("day.jsonl");
    simulate(&root().join("config/scenes/harbour-day.toml"), &log);
    let back = dir.path().join("back.jsonl");
    let (ok, _, err) = run(&["convert", "--in", s(&log), "--out", s(&back)]);
    assert!(ok, "{err}");
    assert_eq!(
        std::fs::read(&log).expect("log"),
        std::fs::read(&back).expect("copy")
    );
    let mcap = dir.path().join("day.mcap");
    let (ok, _, err) = run(&["convert", "--in", s(&log), "--out", s(&mcap)]);
    assert!(ok, "{err}");
    let again = dir.path().join("again.jsonl");
    let (ok, _, err) = run(&["convert", "--in", s(&mcap), "--out", s(&again)]);
    assert!(ok, "{err}");
    assert_eq!(
        std::fs::read(&log).expect("log"),
        std::fs::read(&again).expect("through MCAP")
    );
    // Two bytes a sample, not the JSON's four or five.
    let (j, m) = (
        std::fs::metadata(&log).expect("log").len(),
        std::fs::metadata(&mcap).expect("mcap").len(),
    );
    assert!(m * 4 < j * 3, "MCAP {m} B against JSONL {j} B");
}
