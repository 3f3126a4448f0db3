//! Spec v3 through the daemon: the simulator's harbour by day with a
//! blinking beacon sampled at 2 kHz (config/examples/sim-v3.toml's scene),
//! each frame's 400 samples per channel demodulated on the frame thread;
//! POSE flows with the beacon's amplitudes behind it, STATUS says the
//! demodulator's lock, the recording holds BURST lines (or demodulated
//! frames when asked), and a replay of the BURST recording through the
//! replay backend gives the same poses, bit for bit.

mod common;
use common::run::{of_class, run_to_end};
use common::{root, subscriber};

use lightpose_core::samples::RecordKind;
use lightpose_core::LogReader;
use lightposed::Config;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// sim-v3.toml's scene, trajectory and calibration, not looping, as fast
/// as it goes, sending to `dest`, recording `samples` into `rec`.
fn v3_config(dest: std::net::SocketAddr, rec: &Path, samples: &str) -> String {
    let r = root();
    format!(
        "rate_hz = 5.0\nestimator = \"auto\"\ncalibration = \"{}\"\n[backend]\nkind = \"sim\"\nscene = \"{}\"\ntrajectory = \"{}\"\nloop = false\npace = \"fast\"\n[outputs]\ndestinations = [\"{dest}\"]\nstatus_interval_s = 0.2\n[recording]\ndir = \"{}\"\nsamples = \"{samples}\"\n",
        r.join("config/calibration/harbour.toml").display(),
        r.join("config/scenes/harbour-day.toml").display(),
        r.join("config/trajectories/dock.csv").display(),
        rec.display(),
    )
}

fn load(dir: &Path, text: &str) -> Config {
    let p = dir.join("lightposed.toml");
    std::fs::write(&p, text).expect("write config");
    Config::load(&p).expect("config loads")
}

fn recording(dir: &Path) -> PathBuf {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("recording dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files.remove(0)
}

/// The kind of frame a log holds and how many.
fn kind_of(log: &Path) -> (RecordKind, usize) {
    let f = std::fs::File::open(log).expect("open recording");
    let mut r = LogReader::new(std::io::BufReader::new(f), log.display().to_string())
        .expect("recording header");
    let mut kinds = Vec::new();
    while let Some(rec) = r.next_record() {
        kinds.push(rec.expect("recorded frame reads back").kind());
    }
    assert!(kinds.windows(2).all(|w| w[0] == w[1]));
    (kinds[0], kinds.len())
}

fn poses(msgs: &[Value]) -> BTreeMap<u64, Value> {
    of_class(msgs, "POSE")
        .into_iter()
        .map(|p| {
            let mut p = p.clone();
            // The wall clock of the run, not of the frame.
            p.as_object_mut().expect("object").remove("time");
            (p["seq"].as_u64().expect("seq"), p)
        })
        .collect()
}

#[test]
fn a_blinking_beacon_is_demodulated_live_recorded_raw_and_replays_the_same() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, dest) = subscriber();
    let cfg = load(dir.path(), &v3_config(dest, &rec, "raw"));
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(120), &sub);
    // dock.csv: 10 s at 5 Hz, a frame while its middle is in the trajectory.
    assert_eq!(summary.frames, 50, "{summary:?}");
    let live = poses(&msgs);
    assert_eq!(live.len(), 50);
    let ok = live.values().filter(|p| p["status"] == "ok").count();
    // How many are `ok` is the estimator's (39 of 50 as this was written,
    // the tracker reading the amplitudes' mean levels): most of them.
    assert!(ok >= 30, "{ok} ok poses of 50");
    // A frame's t is the middle of its samples (MODEL.md): 399/2 samples
    // at 2 kHz after the first, k / 5 Hz.
    let t = live[&10]["t"].as_f64().expect("t");
    assert!((t - (2.0 + 399.0 / 4000.0)).abs() < 1e-9, "{t}");

    let status = of_class(&msgs, "STATUS");
    let last = status.last().expect("a STATUS");
    let d = &last["demodulator"];
    assert_eq!(d["enabled"], true, "{d}");
    assert_eq!(d["samples_per_frame"], 400);
    assert_eq!(d["refused"], 0);
    assert_eq!(last["failed"], 0);
    let b = &d["beacons"][0];
    assert_eq!(
        (b["id"].as_str(), b["locked"].as_bool()),
        (Some("beacon"), Some(true)),
        "{d}"
    );
    // The scene's beacon runs 40 ppm fast: the demodulator finds it.
    let ppm = b["offset_ppm"].as_f64().expect("offset_ppm");
    assert!((ppm - 40.0).abs() < 5.0, "offset {ppm} ppm: {d}");

    let log = recording(&rec);
    assert_eq!(kind_of(&log), (RecordKind::Burst, 50));

    // The recording, replayed through the daemon: the same demodulator on
    // the same samples, the same poses.
    let (sub2, dest2) = subscriber();
    let text = format!(
        "rate_hz = 5.0\nestimator = \"auto\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{dest2}\"]\nstatus_interval_s = 0.2\n",
        root().join("config/calibration/harbour.toml").display(),
        log.display()
    );
    let dir2 = tempfile::tempdir().expect("tempdir");
    let (_, msgs2) = run_to_end(load(dir2.path(), &text), Duration::from_secs(120), &sub2);
    assert_eq!(poses(&msgs2), live);
}

#[test]
fn demodulated_frames_are_recorded_when_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, dest) = subscriber();
    let cfg = load(dir.path(), &v3_config(dest, &rec, "demodulated"));
    let (summary, msgs) = run_to_end(cfg, Duration::from_secs(120), &sub);
    assert_eq!(summary.frames, 50);
    let log = recording(&rec);
    assert_eq!(kind_of(&log), (RecordKind::Demodulated, 50));
    // Replayed, a demodulated frame is the frame the live estimator read.
    let (sub2, dest2) = subscriber();
    let text = format!(
        "rate_hz = 5.0\nestimator = \"auto\"\ncalibration = \"{}\"\n[backend]\nkind = \"replay\"\nlog = \"{}\"\npace = \"fast\"\n[outputs]\ndestinations = [\"{dest2}\"]\n",
        root().join("config/calibration/harbour.toml").display(),
        log.display()
    );
    let dir2 = tempfile::tempdir().expect("tempdir");
    let (_, msgs2) = run_to_end(load(dir2.path(), &text), Duration::from_secs(120), &sub2);
    let (a, b) = (poses(&msgs), poses(&msgs2));
    assert_eq!(a.len(), 50);
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, p) in &a {
        assert_eq!(p["status"], b[k]["status"], "seq {k}");
        for f in ["x", "y", "z"] {
            let (u, v) = (p[f].as_f64(), b[k][f].as_f64());
            if let (Some(u), Some(v)) = (u, v) {
                // The amplitudes are written as JSON numbers (shortest
                // round-trip): the same f64s.
                assert_eq!(u, v, "seq {k} {f}");
            }
        }
    }
}
