//! The daemon and MCAP (issue 15): its replay backend reads MCAP as JSONL
//! (the same POSE datagrams, byte for byte); its MCAP recording after
//! SIGTERM is read by the reference Python `mcap` library with frames,
//! poses, STATUS and clock records, the poses equal to the POSE datagrams
//! it sent; after kill -9 of the real binary, `lightpose convert`'s
//! library recovers every frame up to the last complete chunk, at least
//! every frame STATUS called synced, and `lightpose recover`'s writes a
//! file the reference library's default reader opens (the cut one it
//! cannot) with all of them; a bad MCAP is refused at start with one line
//! and exit 2.

mod common;
use common::run::{
    collect, collect_raw, files_in, of_class, replay_config, run_in_process, signal, sim_config,
    spawn_daemon, wait_exit,
};
use common::{root, subscriber};
use lightpose_testkit::python::{python, run_python};

use lightpose_core::Cut;
use lightpose_logs::{convert, McapOptions};
use lightposed::Config;
use nix::sys::signal::Signal;
use serde_json::Value;
use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A POSE datagram without its `time` (the wall clock of the run), every
/// other byte as it was sent.
fn without_time(d: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(d).into_owned();
    let Some(at) = text.find(",\"time\":") else {
        return d.to_vec();
    };
    let rest = &text[at + 1..];
    let end = rest.find(',').map_or(rest.len(), |i| i + 1);
    format!("{}{}", &text[..at + 1], &rest[end..]).into_bytes()
}

/// The POSE datagrams of a fast replay of `log`, in order, without `time`.
fn replay_poses(log: &Path) -> Vec<Vec<u8>> {
    let (sub, addr) = subscriber();
    let cfg = Config::parse(&replay_config(log, addr), "replay.toml", None).expect("valid");
    let h = run_in_process(cfg, Duration::from_secs(20));
    let got = collect_raw(&sub, Duration::from_millis(1200));
    let s = h.join().expect("daemon");
    assert!(s.source_ended, "{}: the replay ends", log.display());
    got.iter()
        .filter(|d| d.starts_with(b"{\"class\":\"POSE\""))
        .map(|d| without_time(d))
        .collect()
}

#[test]
fn replay_of_mcap_sends_the_jsonl_replays_pose_datagrams() {
    assert_eq!(
        without_time(b"{\"class\":\"POSE\",\"seq\":1,\"t\":0.2,\"time\":1.5,\"status\":\"ok\"}"),
        b"{\"class\":\"POSE\",\"seq\":1,\"t\":0.2,\"status\":\"ok\"}"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    for name in ["zigzag.jsonl", "hard.jsonl"] {
        let jsonl = root().join("tests/data").join(name);
        let mcap = dir.path().join(name.replace(".jsonl", ".mcap"));
        let opts = McapOptions {
            chunk_bytes: 4 << 10,
            ..Default::default()
        };
        convert(&jsonl, &mcap, None, &opts, |_| {}).expect("converts");
        let (a, b) = (replay_poses(&jsonl), replay_poses(&mcap));
        assert!(a.len() >= 40, "{name}: {} poses", a.len());
        // Estimates, not empty poses: most know x.
        let known = a
            .iter()
            .filter(|p| !p.windows(9).any(|w| w == b"\"x\":null"))
            .count();
        assert!(known > 20, "{name}: {known} poses with x");
        assert_eq!(a, b, "{name}: POSE datagrams from JSONL and from MCAP");
    }
}

/// The POSE lines of `seqs`, from the datagrams, into a file.
fn pose_lines(dir: &Path, name: &str, poses: &BTreeMap<u64, Vec<u8>>, seqs: &[u64]) -> PathBuf {
    let mut text = Vec::new();
    for s in seqs {
        text.extend_from_slice(poses.get(s).unwrap_or_else(|| panic!("POSE {s} was sent")));
        text.push(b'\n');
    }
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write");
    p
}

/// Frame seqs of a log, through our reader.
fn frame_seqs(log: &Path) -> (Vec<u64>, Option<Cut>) {
    let mut r = lightpose_logs::open(log).expect("opens");
    let mut v = Vec::new();
    while let Some(f) = r.next_frame() {
        v.push(f.expect("every frame reads").seq);
    }
    (v, r.cut())
}

#[test]
fn sigterm_leaves_mcap_recordings_the_reference_library_reads() {
    let py = python();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\nformat = \"mcap\"\nrotate_mb = 0.25\nflush_s = 0.5\n",
        rec.display()
    );
    let (mut child, mut raw) =
        spawn_daemon(dir.path(), &sim_config(200.0, &[addr], "", &extra), &sub);
    // Until STATUS says a second file was started (the daemon's word).
    let deadline = Instant::now() + Duration::from_secs(20);
    let files = |raw: &[Vec<u8>]| {
        raw.iter()
            .rev()
            .filter_map(|d| serde_json::from_slice::<Value>(d).ok())
            .find(|v| v["class"] == "STATUS")
            .and_then(|v| v["recording"]["files"].as_u64())
            .unwrap_or(0)
    };
    while files(&raw) < 2 && Instant::now() < deadline {
        raw.extend(collect_raw(&sub, Duration::from_millis(200)));
    }
    signal(&child, Signal::SIGTERM);
    assert_eq!(
        wait_exit(&mut child, Duration::from_secs(5)).code(),
        Some(0)
    );
    raw.extend(collect_raw(&sub, Duration::from_millis(300)));
    let msgs: Vec<Value> = raw
        .iter()
        .map(|d| serde_json::from_slice(d).unwrap())
        .collect();
    let fin = of_class(&msgs, "STATUS")
        .last()
        .copied()
        .expect("STATUS")
        .clone();
    assert_eq!(fin["recording"]["format"], "mcap", "{fin}");
    let sent: BTreeMap<u64, Vec<u8>> = raw
        .iter()
        .zip(&msgs)
        .filter(|(_, v)| v["class"] == "POSE")
        .map(|(d, v)| (v["seq"].as_u64().unwrap(), d.clone()))
        .collect();

    let logs = files_in(&rec);
    assert!(logs.len() >= 2, "{logs:?}");
    let script = root().join("crates/logs/tests/mcap_check.py");
    let mut all = Vec::new();
    for (i, log) in logs.iter().enumerate() {
        // The frames as JSONL (our reader) and the POSE lines as sent over
        // UDP: Python compares the recording against both, bit for bit.
        let jsonl = dir.path().join(format!("{i}.jsonl"));
        let s = convert(log, &jsonl, None, &McapOptions::default(), |e| {
            panic!("{e}")
        })
        .expect("converts");
        assert_eq!(s.cut, None, "{}: finished at SIGTERM", log.display());
        let (seqs, _) = frame_seqs(log);
        let poses = pose_lines(dir.path(), &format!("{i}.poses.jsonl"), &sent, &seqs);
        let args = [
            OsStr::new("full"),
            log.as_os_str(),
            jsonl.as_os_str(),
            poses.as_os_str(),
        ];
        let line = run_python(&py, &script, &args);
        let n = seqs.len();
        assert!(
            line.starts_with(&format!("frame={n} pose={n} status=")),
            "{line}"
        );
        assert!(line.contains(&format!("image={n} ")), "{line}");
        let status: u64 = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("status="))
            .and_then(|v| v.parse().ok())
            .expect("status count");
        assert!(status >= 1, "{}: STATUS recorded: {line}", log.display());
        // Each file maps its log time to the wall clock (the script checks
        // the record's values).
        assert!(line.contains(" clock="), "{}: {line}", log.display());
        all.extend(seqs);
    }
    assert!(all.windows(2).all(|w| w[1] == w[0] + 1), "seq contiguous");
    assert_eq!(
        all.len() as u64,
        fin["frames"].as_u64().unwrap(),
        "every frame recorded"
    );
}

#[test]
fn kill_9_mcap_recording_is_recovered_to_its_last_complete_chunk() {
    let py = python();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let (sub, addr) = subscriber();
    let extra = format!(
        "[recording]\ndir = \"{}\"\nformat = \"mcap\"\nflush_s = 0.1\n",
        rec.display()
    );
    let (mut child, first) =
        spawn_daemon(dir.path(), &sim_config(500.0, &[addr], "", &extra), &sub);
    // Until STATUS says a good number of frames are synced.
    let mut msgs: Vec<Value> = first
        .iter()
        .map(|d| serde_json::from_slice(d).unwrap())
        .collect();
    let synced = |m: &[Value]| {
        of_class(m, "STATUS")
            .last()
            .and_then(|v| v["recording"]["synced"].as_u64())
            .unwrap_or(0)
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    while synced(&msgs) < 300 && Instant::now() < deadline {
        msgs.extend(collect(&sub, Duration::from_millis(100)));
    }
    signal(&child, Signal::SIGKILL);
    wait_exit(&mut child, Duration::from_secs(5));
    msgs.extend(collect(&sub, Duration::from_millis(100)));
    let promised = synced(&msgs);
    assert!(promised >= 300, "STATUS said {promised} synced");
    let published: Vec<u64> = of_class(&msgs, "POSE")
        .iter()
        .map(|v| v["seq"].as_u64().unwrap())
        .collect();

    let logs = files_in(&rec);
    assert_eq!(logs.len(), 1, "{logs:?}");
    let fixed = dir.path().join("fixed.mcap");
    let s = convert(&logs[0], &fixed, None, &McapOptions::default(), |e| {
        panic!("{e}")
    })
    .expect("lightpose convert recovers the cut file");
    assert!(matches!(s.cut, Some(Cut::Bytes { .. })), "{:?}", s.cut);
    let (seqs, cut) = frame_seqs(&fixed);
    assert_eq!(cut, None, "the recovered file is finished");
    assert_eq!(seqs.len() as u64, s.frames);
    // Every frame STATUS called synced, in order, each one published.
    assert!(seqs.len() as u64 >= promised, "{} < {promised}", seqs.len());
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "contiguous");
    assert_eq!(seqs.first(), published.first(), "from the first frame");
    assert!(seqs.iter().all(|s| published.binary_search(s).is_ok()));
    // And exactly the frames of the complete chunks, as the reference
    // library's streaming reader finds them in the cut file.
    let script = root().join("crates/logs/tests/mcap_check.py");
    let line = run_python(&py, &script, &[OsStr::new("cut"), logs[0].as_os_str()]);
    assert_eq!(line, format!("frames={}", seqs.len()));

    // The library's default reader (it seeks to the footer) cannot open
    // the cut file; `lightpose recover` writes one it opens, with every
    // message of the complete chunks: every frame STATUS called synced,
    // the STATUS and the clock records with them.
    let theirs = run_python(&py, &script, &[OsStr::new("default"), logs[0].as_os_str()]);
    assert!(
        theirs.starts_with("error="),
        "the cut file opened: {theirs}"
    );
    let good = dir.path().join("good.mcap");
    let r = lightpose_logs::recover(&logs[0], &good, &Default::default()).expect("recovers");
    let line = run_python(&py, &script, &[OsStr::new("default"), good.as_os_str()]);
    assert!(
        line.starts_with(&format!("messages={} ", r.messages)),
        "{line} ({r})"
    );
    let (kept, cut) = frame_seqs(&good);
    assert_eq!(cut, None, "the recovered file is finished");
    assert!(line.contains(&format!(" frame={} ", kept.len())), "{line}");
    assert!(
        kept.len() >= seqs.len() && kept[..seqs.len()] == seqs[..],
        "{r}"
    );
    assert!(kept.windows(2).all(|w| w[1] == w[0] + 1), "contiguous");
    for topic in ["status", "pose", "image", "tf"] {
        let n: u64 = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{topic}=")))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0);
        assert!(n >= 1, "{topic}: {line}");
    }
    assert!(!line.contains(" clock=0 "), "{line}");
}

/// An MCAP whose frame channel carries another schema (protobuf), made
/// with the `mcap` crate as another program would.
fn wrong_schema() -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .create(std::io::Cursor::new(Vec::new()))
        .expect("writer");
    let header = std::fs::read_to_string(root().join("tests/data/zigzag.jsonl")).expect("log");
    let header = header.lines().next().expect("header line").to_string();
    w.write_metadata(&mcap::records::Metadata {
        name: "lightpose-header".into(),
        metadata: [("json".to_string(), header)].into_iter().collect(),
    })
    .expect("metadata");
    let sid = w
        .add_schema("lightpose.Frame", "protobuf", b"")
        .expect("schema");
    let ch = w
        .add_channel(sid, "/lightpose/frame", "protobuf", &BTreeMap::new())
        .expect("channel");
    let h = mcap::records::MessageHeader {
        channel_id: ch,
        sequence: 0,
        log_time: 0,
        publish_time: 0,
    };
    w.write_to_known_channel(&h, b"\x08\x01").expect("message");
    w.finish().expect("finish");
    w.into_inner().into_inner()
}

#[test]
fn bad_mcap_refused_at_start_with_one_line_and_exit_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (_sub, addr) = subscriber();
    let mut good = Vec::new();
    let src = dir.path().join("good.mcap");
    convert(
        &root().join("tests/data/zigzag.jsonl"),
        &src,
        None,
        &McapOptions::default(),
        |_| {},
    )
    .expect("converts");
    good.extend(std::fs::read(&src).expect("read"));
    let cases: [(&str, Vec<u8>, &str); 4] = [
        (
            "garbage.mcap",
            b"\x89MCAP0\r\nthis is no record".to_vec(),
            ": byte 8: ",
        ),
        (
            "text.mcap",
            b"{\"class\":\"HEADER\"}\n".to_vec(),
            ": byte 0: ",
        ),
        ("truncated.mcap", good[..40].to_vec(), ": byte "),
        ("schema.mcap", wrong_schema(), ": byte "),
    ];
    for (name, bytes, place) in cases {
        let log = dir.path().join(name);
        std::fs::write(&log, bytes).expect("write");
        let cfg = dir.path().join("replay.toml");
        std::fs::write(&cfg, replay_config(&log, addr)).expect("write");
        let out = Command::new(env!("CARGO_BIN_EXE_lightposed"))
            .arg("--config")
            .arg(&cfg)
            .env("RUST_LOG", "off")
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{name}: one line: {err}");
        let want = format!("{}{place}", log.display());
        assert!(lines[0].contains(&want), "{name}: {err}");
    }
}
