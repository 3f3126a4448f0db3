//! Spec v3 in MCAP: BURST logs (raw samples, on the binary
//! `/lightpose/burst`) and demodulated logs (on `/lightpose/demodulated`)
//! convert JSONL → MCAP → JSONL byte for byte, read back as the same
//! records, and the reference Python `mcap` library reads the burst channel
//! (its layout decoded by an implementation of its own) and the POSE's
//! roll in the Foxglove quaternion. A v2 log's MCAP declares neither new
//! channel.

mod common;

use lightpose_core::FrameLog;
use lightpose_core::{
    Angle, AttitudeReading, BeaconAmplitude, BeaconInfo, Burst, Demodulated, LogHeader, LogWriter,
    Pose, PoseEstimate, Record, Status, Truth, NDET,
};
use lightpose_logs::{convert, LogFile, McapOptions};
use lightpose_testkit::python::{python, run_python};
use std::path::Path;

fn v3_header(n: usize) -> LogHeader {
    let mut h = LogHeader::new(12, 20.0);
    h.sample_hz = Some(20.0 * n as f64);
    h.channel_skew_s = Some(2e-5);
    h.beacons = vec![BeaconInfo {
        id: "top".into(),
        mod_hz: 200.0,
    }];
    h
}

/// A burst of square-wave-ish samples with noise-like digits, every
/// reading, and a rolled truth.
fn burst(seq: u64, n: usize) -> Burst {
    let mut b = Burst::new(n);
    for k in 0..NDET {
        for (i, v) in b.channel_mut(k).iter_mut().enumerate() {
            let on = (i / 4) % 2 == 0;
            let noise = (seq as usize * 7919 + k * 104_729 + i * 1_299_709) % 23;
            *v = (300 + k * 20 + if on { 900 } else { 0 } + noise).min(4095) as u16;
        }
    }
    b.seq = seq;
    b.t = 10.0 + seq as f64 * 0.05 + 1e-13;
    b.adc_bits = 12;
    if seq % 3 != 1 {
        b.temp_c = Some(14.0 + seq as f64 * 1e-3);
    }
    let pose = Pose::new(
        6.0 - seq as f64 * 0.01,
        0.2,
        -0.1,
        Angle::from_deg(3.0),
        Angle::from_deg(-4.0),
    )
    .with_roll(Angle::from_deg(7.5 - seq as f64 * 0.1));
    b.truth = Some(Truth {
        pose,
        surge: Some(0.4),
    });
    let mut att = AttitudeReading::new(Angle::from_deg(3.1), Angle::from_deg(-4.2));
    att.roll = Some(Angle::from_deg(7.4));
    b.attitude = Some(att);
    b
}

fn demodulated(seq: u64) -> Demodulated {
    let mut d = Demodulated {
        seq,
        t: 1.025 + seq as f64 * 0.05,
        adc_bits: 12,
        ..Demodulated::default()
    };
    d.light.n_beacons = 1;
    let mut b = BeaconAmplitude::default();
    for k in 0..NDET {
        b.amplitude[k] = 800.0 / (1.0 + k as f64) + seq as f64 / 3.0;
        b.std[k] = 1.5 + k as f64 * 0.01;
        d.light.ambient[k] = 120.25 + k as f64;
    }
    d.light.beacons[0] = b;
    d.light.clipped[3] = seq as u32 % 2;
    d
}

/// JSONL → MCAP → JSONL; the MCAP's path.
fn round_trip(dir: &Path, name: &str, text: &[u8]) -> std::path::PathBuf {
    let (log, mcap, back) = (
        dir.join(format!("{name}.jsonl")),
        dir.join(format!("{name}.mcap")),
        dir.join(format!("{name}.back.jsonl")),
    );
    std::fs::write(&log, text).unwrap();
    let opts = McapOptions::default();
    let s = convert(&log, &mcap, None, &opts, |e| panic!("{e}")).unwrap();
    assert_eq!(s.skipped, 0);
    convert(&mcap, &back, None, &opts, |e| panic!("{e}")).unwrap();
    assert_eq!(
        std::fs::read(&back).unwrap(),
        text,
        "{name}: JSONL → MCAP → JSONL"
    );
    mcap
}

#[test]
fn burst_logs_round_trip_byte_for_byte_and_read_back_as_bursts() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100;
    let mut w = LogWriter::new(Vec::new(), &v3_header(n)).unwrap();
    let bursts: Vec<Burst> = (0..30).map(|s| burst(s, n)).collect();
    for b in &bursts {
        w.write_burst(b).unwrap();
    }
    let mut text = w.into_inner();
    // A line written by another program: spaces in its samples.
    let odd = {
        let mut w = LogWriter::new(Vec::new(), &v3_header(n)).unwrap();
        w.get_mut().clear();
        w.write_burst(&burst(30, n)).unwrap();
        String::from_utf8(w.into_inner())
            .unwrap()
            .replace("],[", "], [")
    };
    text.extend_from_slice(odd.as_bytes());
    let mcap = round_trip(dir.path(), "burst", &text);
    // Much smaller than its JSON: 2 bytes a sample.
    let (j, m) = (
        text.len() as f64,
        std::fs::metadata(&mcap).unwrap().len() as f64,
    );
    assert!(m < 0.75 * j, "MCAP {m} B against JSONL {j} B");
    let mut r = LogFile::open(&mcap).unwrap();
    assert_eq!(r.header().sample_hz, Some(2000.0));
    let mut got = 0;
    while let Some(rec) = r.next_record() {
        match rec.unwrap() {
            Record::Burst(b) => {
                let want = if got < 30 {
                    bursts[got].clone()
                } else {
                    burst(30, n)
                };
                assert_eq!(b.samples(), want.samples(), "burst {got}");
                assert_eq!((b.seq, b.t, b.temp_c), (want.seq, want.t, want.temp_c));
                let roll = b.truth.map(|t| t.pose.roll.deg());
                assert!((roll.unwrap() - (7.5 - got as f64 * 0.1)).abs() < 1e-9);
                assert!(b.attitude.and_then(|a| a.roll).is_some());
            }
            other => panic!("{other:?}"),
        }
        got += 1;
    }
    assert_eq!(got, 31);
    // A reader of counts is refused the bursts, named, as with JSONL.
    let mut r = LogFile::open(&mcap).unwrap();
    let e = r.next_frame().unwrap().unwrap_err();
    assert!(e.to_string().contains("BURST"), "{e}");
}

#[test]
fn demodulated_logs_round_trip_on_their_own_channel() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = LogWriter::new(Vec::new(), &v3_header(100)).unwrap();
    for s in 0..12 {
        w.write_demodulated(&demodulated(s)).unwrap();
    }
    let text = w.into_inner();
    let mcap = round_trip(dir.path(), "demod", &text);
    let mut r = LogFile::open(&mcap).unwrap();
    let mut k = 0;
    while let Some(rec) = r.next_record() {
        let Record::Demodulated(d) = rec.unwrap() else {
            panic!("not demodulated")
        };
        assert_eq!(*d, demodulated(k));
        k += 1;
    }
    assert_eq!(k, 12);
}

/// The reference library reads the binary channel (the layout decoded in
/// Python, each line rebuilt and compared with the JSONL's), the images,
/// the truth with its roll, and poses with roll in their quaternion.
#[test]
fn the_reference_library_reads_the_burst_channel_and_rolled_poses() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let n = 160;
    let mut w = LogWriter::new(Vec::new(), &v3_header(n)).unwrap();
    for s in 0..20 {
        w.write_burst(&burst(s, n)).unwrap();
    }
    let log = dir.path().join("b.jsonl");
    std::fs::write(&log, w.into_inner()).unwrap();
    let poses = dir.path().join("b.poses.jsonl");
    let mut lines = Vec::new();
    let mut buf = Vec::new();
    for s in 0..20u64 {
        let mut p = PoseEstimate::empty(s, 10.0 + s as f64 * 0.05 + 1e-13, Status::Ok, "tracker");
        (p.x, p.y, p.z) = (Some(6.0), Some(0.2), Some(-0.1));
        (p.pitch_deg, p.yaw_deg) = (Some(3.0), Some(-4.0));
        if s % 2 == 0 {
            (p.roll_deg, p.std.roll) = (Some(-12.0 + s as f64), Some(0.3));
        }
        p.write_json(None, &mut buf);
        lines.extend_from_slice(&buf);
        lines.push(b'\n');
    }
    std::fs::write(&poses, lines).unwrap();
    let mcap = dir.path().join("b.mcap");
    convert(&log, &mcap, Some(&poses), &McapOptions::default(), |e| {
        panic!("{e}")
    })
    .unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_check.py");
    let got = run_python(&py, &script, &[Path::new("v3"), &mcap, &log, &poses]);
    assert_eq!(
        got,
        "burst=20 pose=20 image=20 vehicle_pose=20 truth_pose=20 tf=20 rolled=10"
    );
}

#[test]
fn a_v2_log_declares_no_v3_channel() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("dive.mcap");
    convert(
        &common::data("dive.jsonl"),
        &mcap,
        None,
        &McapOptions::default(),
        |e| panic!("{e}"),
    )
    .unwrap();
    let bytes = std::fs::read(&mcap).unwrap();
    let has = |s: &[u8]| bytes.windows(s.len()).any(|w| w == s);
    assert!(has(b"/lightpose/frame"));
    assert!(!has(b"/lightpose/burst") && !has(b"/lightpose/demodulated"));
}
