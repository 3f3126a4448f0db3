//! Helpers shared by the test binaries of lightpose-logs.
#![allow(dead_code)]

use lightpose_core::frame::{AttitudeStd, DepthReading, VelocityReading};
use lightpose_core::{
    Angle, AttitudeReading, BodyVec, Frame, LogHeader, Pose, PoseEstimate, Status, Truth, NDET,
};
use lightpose_logs::{McapOptions, McapWriter};
use std::path::PathBuf;

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

pub fn data(name: &str) -> PathBuf {
    root().join("tests/data").join(name)
}

/// A frame with every kind of reading (some with their own std), awkward
/// numbers that must come back bit for bit.
pub fn frame(seq: u64) -> Frame {
    let mut counts = [0u16; NDET];
    for (k, c) in counts.iter_mut().enumerate() {
        *c = ((seq as usize * 37 + k * 41) % 1024) as u16;
    }
    let mut f = Frame::new(seq, seq as f64 * 0.2 + 1e-13, 10, counts);
    f.temp_c = Some(19.937845150646073 + seq as f64 * 1e-13);
    f.truth = Some(Truth {
        pose: Pose::new(
            7.8 - seq as f64 * 0.01,
            0.1 / 3.0,
            0.12,
            Angle::from_deg(9.6),
            Angle::from_deg(-2.0),
        ),
        surge: Some(0.5),
    });
    if seq.is_multiple_of(2) {
        f.attitude = Some(AttitudeReading {
            pitch: Angle::from_deg(9.5),
            yaw: Angle::from_deg(-1.25),
            roll: None,
            std: Some(AttitudeStd {
                pitch: Angle::from_deg(0.3),
                yaw: Angle::from_deg(1.5),
            }),
        });
    }
    if seq.is_multiple_of(3) {
        f.depth = Some(DepthReading {
            z: 0.123456789 + seq as f64 * 1e-9,
            std: Some(0.02),
        });
        f.velocity = Some(VelocityReading {
            v: BodyVec([0.5, -0.01, 0.02]),
            std: None,
        });
    }
    f
}

/// A pose for a frame; every fifth knows nothing (no_light, nulls).
pub fn pose(f: &Frame) -> PoseEstimate {
    if f.seq % 5 == 4 {
        return PoseEstimate::empty(f.seq, f.t, Status::NoLight, "tracker");
    }
    let mut p = PoseEstimate::empty(f.seq, f.t, Status::Ok, "tracker");
    (p.x, p.y, p.z) = (Some(7.8 - f.seq as f64 * 0.01), Some(0.03), Some(0.1));
    (p.pitch_deg, p.yaw_deg, p.surge) = (Some(9.5), Some(-2.1), Some(0.5));
    (p.std.x, p.std.yaw) = (Some(0.2), Some(0.6));
    p
}

pub fn header() -> LogHeader {
    let mut h = LogHeader::new(10, 5.0);
    h.extra.insert("scene".into(), "tank".into());
    h
}

/// A recording as the daemon would make it: frames, poses, a status now
/// and then, chunks of `chunk_bytes`.
pub fn record(n: u64, chunk_bytes: u64) -> Vec<u8> {
    let opts = McapOptions {
        chunk_bytes,
        foxglove: true,
    };
    let mut w = McapWriter::new(Vec::new(), &header(), &opts).unwrap();
    for seq in 0..n {
        write_daemon_frame(&mut w, seq);
    }
    w.finish().unwrap()
}

/// Frame `seq` as the daemon records it: the frame, its pose, and a
/// status every tenth frame; the frame, for what comes beside it.
fn write_daemon_frame(w: &mut McapWriter<Vec<u8>>, seq: u64) -> Frame {
    let f = frame(seq);
    w.write_frame(&f).unwrap();
    w.write_pose(&pose(&f), Some(1.7e9 + f.t)).unwrap();
    if seq % 10 == 9 {
        let status = format!("{{\"class\":\"STATUS\",\"seq\":{},\"t\":1.7e9}}", seq / 10);
        w.write_status(f.t, status.as_bytes()).unwrap();
    }
    f
}

/// Top-level records of a complete file: (opcode, offset, end).
pub fn records(bytes: &[u8]) -> Vec<(u8, usize, usize)> {
    let mut out = Vec::new();
    let mut p = 8;
    while p + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[p + 1..p + 9].try_into().unwrap()) as usize;
        out.push((bytes[p], p, p + 9 + len));
        if bytes[p] == mcap::records::op::DATA_END {
            break;
        }
        p += 9 + len;
    }
    out
}

/// One line, naming the file and a byte offset.
pub fn assert_one_line_at(e: &impl std::fmt::Display, name: &str) {
    let s = e.to_string();
    assert!(!s.contains('\n'), "not one line: {s}");
    assert!(
        s.starts_with(&format!("{name}: byte ")),
        "no file and offset: {s}"
    );
}

/// A recording with all a daemon's file holds beside frames and poses:
/// STATUS, `lightpose-clock` metadata at the start and at a step, another
/// metadata record, and another program's channel (a schema, channel
/// metadata, its own sequence numbers and times).
pub fn rich_record(n: u64, chunk_bytes: u64) -> Vec<u8> {
    let opts = McapOptions {
        chunk_bytes,
        foxglove: true,
    };
    let mut w = McapWriter::new(Vec::new(), &header(), &opts).unwrap();
    let clock = |reason: &str, t: f64| -> std::collections::BTreeMap<String, String> {
        [
            ("epoch", "source".to_string()),
            ("t", format!("{t}")),
            ("log_time", format!("{}", (t * 1e9) as u64)),
            ("unix", format!("{}", 1.7e9 + t)),
            ("offset", "1700000000".to_string()),
            ("synced", "true".to_string()),
            ("reason", reason.to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    };
    w.write_metadata("lightpose-clock", clock("open", 0.0))
        .unwrap();
    let meta = [("unit".to_string(), "m".to_string())].into();
    let other = w
        .add_channel(
            Some(("x.Depth", "jsonschema", br#"{"type":"object"}"#)),
            "/x/depth",
            "json",
            &meta,
        )
        .unwrap();
    for seq in 0..n {
        let f = write_daemon_frame(&mut w, seq);
        if seq % 3 == 0 {
            let data = format!("{{\"z\":{}}}", seq as f64 * 0.01);
            let t = (f.t * 1e9) as u64 + 17;
            w.write_raw(other, 1000 + seq as u32, t, t + 3, data.as_bytes())
                .unwrap();
        }
        if seq == n / 2 {
            w.write_metadata("lightpose-clock", clock("step", f.t))
                .unwrap();
            let notes = [("diver".to_string(), "A. N. Other".to_string())].into();
            w.write_metadata("notes", notes).unwrap();
        }
    }
    w.finish().unwrap()
}
