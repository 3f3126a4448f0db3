//! The reference Python `mcap` library (tools/pyenv.sh: the pinned venv)
//! reads what lightpose writes: a converted regression log and a recording
//! made as the daemon makes it, every FRAME equal to its JSONL line (parsed
//! by Python's json, floats bit for bit), the Foxglove channels with their
//! schema names and decoded against the frames and poses. And a file cut
//! short gives that library's streaming reader the frames ours gives. If
//! the venv cannot be made, the test fails with pyenv's line: never a skip.

mod common;

use common::{frame, header, pose, record};
use lightpose_core::LogWriter;
use lightpose_logs::{convert, McapOptions, McapReader};
use lightpose_testkit::python::{python, run_python};
use std::path::Path;

/// Run the check script; its one line of output.
fn check(py: &Path, args: &[&Path]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_check.py");
    run_python(py, &script, args)
}

#[test]
fn the_reference_library_reads_a_converted_log() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let (log, poses) = (common::data("dive.jsonl"), common::data("dive.poses.jsonl"));
    let mcap = dir.path().join("dive.mcap");
    convert(&log, &mcap, Some(&poses), &McapOptions::default(), |e| {
        panic!("{e}")
    })
    .unwrap();
    let mode = Path::new("full");
    let got = check(&py, &[mode, &mcap, &log, &poses]);
    assert_eq!(
        got,
        "frame=41 pose=41 status=0 image=41 vehicle_pose=41 truth_pose=41 tf=41"
    );
}

#[test]
fn the_reference_library_reads_a_recording() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let n = 40;
    let mcap = dir.path().join("rec.mcap");
    std::fs::write(&mcap, record(n, 2 << 10)).unwrap();
    // The JSONL and POSE lines of the same frames and estimates.
    let log = dir.path().join("rec.jsonl");
    let poses = dir.path().join("rec.poses.jsonl");
    let mut w = LogWriter::new(Vec::new(), &header()).unwrap();
    let mut pose_lines = Vec::new();
    let mut buf = Vec::new();
    for seq in 0..n {
        let f = frame(seq);
        w.write_frame(&f).unwrap();
        pose(&f).write_json(Some(1.7e9 + f.t), &mut buf);
        pose_lines.extend_from_slice(&buf);
        pose_lines.push(b'\n');
    }
    std::fs::write(&log, w.into_inner()).unwrap();
    std::fs::write(&poses, pose_lines).unwrap();
    let got = check(&py, &[Path::new("full"), &mcap, &log, &poses]);
    // Every fifth estimate knows nothing: no Foxglove pose for it.
    assert_eq!(
        got,
        "frame=40 pose=40 status=4 image=40 vehicle_pose=32 truth_pose=40 tf=32"
    );
}

#[test]
fn a_cut_file_gives_the_reference_reader_the_frames_it_gives_ours() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let bytes = record(40, 2 << 10);
    for cut in [
        bytes.len() / 5,
        bytes.len() / 3 + 17,
        bytes.len() / 2 + 5,
        bytes.len() * 4 / 5,
    ] {
        let path = dir.path().join(format!("cut{cut}.mcap"));
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let ours = McapReader::open(&path).unwrap().map(Result::unwrap).count();
        let theirs = check(&py, &[Path::new("cut"), &path]);
        assert_eq!(theirs, format!("frames={ours}"), "cut at {cut}");
        assert!(ours > 0 && ours < 40, "cut at {cut}: {ours}");
    }
}

/// The library's default reader (`make_reader` on a file: it seeks to the
/// footer) cannot open a recording cut short; what `recover` writes from
/// it opens, with every message recover kept and the metadata.
#[test]
fn the_default_reader_opens_what_recover_writes_of_a_cut_recording() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let bytes = common::rich_record(60, 2 << 10);
    let good = dir.path().join("good.mcap");
    std::fs::write(&good, &bytes).unwrap();
    let whole = check(&py, &[Path::new("default"), &good]);
    for cut in [bytes.len() / 3 + 17, bytes.len() * 3 / 4, bytes.len() - 30] {
        let cut_file = dir.path().join(format!("cut{cut}.mcap"));
        std::fs::write(&cut_file, &bytes[..cut]).unwrap();
        let theirs = check(&py, &[Path::new("default"), &cut_file]);
        assert!(theirs.starts_with("error="), "cut at {cut}: {theirs}");
        let fixed = dir.path().join(format!("fixed{cut}.mcap"));
        let s = lightpose_logs::recover(&cut_file, &fixed, &Default::default()).unwrap();
        let line = check(&py, &[Path::new("default"), &fixed]);
        assert!(
            line.starts_with(&format!("messages={} ", s.messages)),
            "cut at {cut}: {line} ({s})"
        );
        let frames = McapReader::open(&fixed)
            .unwrap()
            .map(Result::unwrap)
            .count();
        assert!(line.contains(&format!(" frame={frames} ")), "{line}");
        assert!(line.contains(" clock="), "{line}");
    }
    // A finished file comes through whole.
    let fixed = dir.path().join("fixed.mcap");
    let s = lightpose_logs::recover(&good, &fixed, &Default::default()).unwrap();
    assert_eq!((s.lost_messages, s.lost_bytes), (0, 0), "{s}");
    assert_eq!(check(&py, &[Path::new("default"), &fixed]), whole);
    let line = check(&py, &[Path::new("alike"), &good, &fixed]);
    assert!(
        line.starts_with(&format!("messages={} ", s.messages)),
        "{line}"
    );
}

/// MCAP → MCAP, read by the reference library: every channel (STATUS and
/// another program's included) and every metadata record as they were.
#[test]
fn the_reference_library_finds_a_converted_recording_alike() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.mcap"), dir.path().join("out.mcap"));
    std::fs::write(&input, common::rich_record(40, 4 << 10)).unwrap();
    convert(&input, &output, None, &McapOptions::default(), |e| {
        panic!("{e}")
    })
    .unwrap();
    let line = check(&py, &[Path::new("alike"), &input, &output]);
    assert!(line.ends_with(" metadata=4"), "{line}");
    let line = check(&py, &[Path::new("default"), &output]);
    assert!(
        line.contains(" status=4 ") && line.contains(" depth=14 "),
        "{line}"
    );
    assert!(line.contains(" clock=2 "), "{line}");
}
