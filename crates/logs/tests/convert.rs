//! JSONL ↔ MCAP: the regression logs go through MCAP and come back byte
//! for byte, with their POSE lines; a recording read back gives the frames
//! that were written; the `mcap` crate's own reader sees the same FRAME
//! messages; the opener tells containers apart; MCAP → MCAP keeps STATUS,
//! other programs' channels and every metadata record.

mod common;

use common::{data, frame, header, pose, record};
use lightpose_core::{FrameLog, LogReader, LogWriter};
use lightpose_logs::{convert, open, McapOptions, McapReader, McapWriter, WriteError};
use std::collections::BTreeMap;
use std::fs;

fn opts() -> McapOptions {
    McapOptions {
        chunk_bytes: 8 << 10,
        foxglove: true,
    }
}

#[test]
fn regression_logs_round_trip_byte_for_byte_with_their_poses() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["dive", "zigzag", "dive-12bit"] {
        let (log, poses) = (
            data(&format!("{name}.jsonl")),
            data(&format!("{name}.poses.jsonl")),
        );
        let mcap = dir.path().join(format!("{name}.mcap"));
        let back = dir.path().join(format!("{name}.jsonl"));
        let back_poses = dir.path().join(format!("{name}.poses.jsonl"));
        let mut skipped = Vec::new();
        let s = convert(&log, &mcap, Some(&poses), &opts(), |e| {
            skipped.push(e.to_string())
        })
        .unwrap();
        assert!(skipped.is_empty(), "{skipped:?}");
        assert_eq!((s.frames, s.poses, s.cut), (41, 41, None), "{name}");
        let s = convert(&mcap, &back, Some(&back_poses), &opts(), |e| {
            skipped.push(e.to_string())
        })
        .unwrap();
        assert_eq!(
            (s.frames, s.poses, s.cut, s.skipped),
            (41, 41, None, 0),
            "{name}"
        );
        assert_eq!(
            fs::read(&log).unwrap(),
            fs::read(&back).unwrap(),
            "{name}: frames"
        );
        assert_eq!(
            fs::read(&poses).unwrap(),
            fs::read(&back_poses).unwrap(),
            "{name}: poses"
        );
        // MCAP → MCAP carries frames and poses too.
        let again = dir.path().join(format!("{name}.again.mcap"));
        let s = convert(&mcap, &again, None, &opts(), |_| {}).unwrap();
        assert_eq!((s.frames, s.poses), (41, 41), "{name}");
    }
}

/// A log from elsewhere whose last line has no newline (LF or CRLF): its
/// last frame went into MCAP as an empty message, counted converted, and
/// was lost on the way back. Now every frame comes back, the text as it was.
#[test]
fn a_last_line_without_newline_is_converted_whole() {
    let dir = tempfile::tempdir().unwrap();
    let text = fs::read_to_string(data("dive.jsonl")).unwrap();
    let lf = text.trim_end_matches('\n').to_string();
    let crlf = lf.replace('\n', "\r\n");
    for (name, body) in [("lf", lf), ("crlf", crlf)] {
        let log = dir.path().join(format!("{name}.jsonl"));
        fs::write(&log, &body).unwrap();
        let mcap = dir.path().join(format!("{name}.mcap"));
        let back = dir.path().join(format!("{name}.back.jsonl"));
        let s = convert(&log, &mcap, None, &opts(), |e| panic!("{e}")).unwrap();
        assert_eq!(s.frames, 41, "{name}");
        let s = convert(&mcap, &back, None, &opts(), |e| panic!("{e}")).unwrap();
        assert_eq!((s.frames, s.skipped), (41, 0), "{name}");
        let frames: Vec<_> = LogReader::open(&back)
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        assert_eq!(frames.len(), 41, "{name}");
        let last_in = body.lines().last().unwrap().trim_end_matches('\r');
        let last_out = fs::read_to_string(&back).unwrap();
        let last_out = last_out
            .lines()
            .last()
            .unwrap()
            .trim_end_matches('\r')
            .to_string();
        assert_eq!(last_in, last_out, "{name}");
    }
}

#[test]
fn a_refused_line_is_named_and_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("hard.mcap");
    let mut skipped = Vec::new();
    let s = convert(&data("hard.jsonl"), &mcap, None, &opts(), |e| {
        skipped.push(e.to_string())
    })
    .unwrap();
    assert_eq!(s.skipped, 1);
    assert!(
        skipped[0].contains("hard.jsonl:13: not valid JSON"),
        "{skipped:?}"
    );
    let back = dir.path().join("hard.jsonl");
    convert(&mcap, &back, None, &opts(), |_| {}).unwrap();
    let want: Vec<String> = fs::read_to_string(data("hard.jsonl"))
        .unwrap()
        .lines()
        .enumerate()
        .filter(|(i, _)| *i != 12)
        .map(|(_, l)| format!("{l}\n"))
        .collect();
    assert_eq!(fs::read_to_string(&back).unwrap(), want.concat());
}

#[test]
fn a_recording_reads_back_as_the_jsonl_of_the_same_frames() {
    let bytes = record(60, 4 << 10);
    let mut jsonl = LogWriter::new(Vec::new(), &header()).unwrap();
    for seq in 0..60 {
        jsonl.write_frame(&frame(seq)).unwrap();
    }
    let jsonl = jsonl.into_inner();
    let from_jsonl: Vec<_> = LogReader::new(&jsonl[..], "r.jsonl")
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let mut r = McapReader::new(&bytes[..], "r.mcap", Some(bytes.len() as u64)).unwrap();
    assert_eq!(r.header(), &header());
    let from_mcap: Vec<_> = r.by_ref().map(Result::unwrap).collect();
    assert_eq!(from_mcap, from_jsonl);
    assert_eq!(from_mcap.len(), 60);
    assert!(from_mcap
        .iter()
        .any(|f| f.attitude.is_some_and(|a| a.std.is_some())));
    assert_eq!(r.cut(), None);
    assert_eq!(r.seq_gaps(), (0, 0));
    // poses, statuses and the Foxglove messages were passed over
    assert!(r.other_records() > 60 * 3, "{}", r.other_records());
}

#[test]
fn the_mcap_crate_reads_the_same_frame_messages() {
    let bytes = record(30, 4 << 10);
    let frames: Vec<Vec<u8>> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == "/lightpose/frame")
        .map(|m| m.data.into_owned())
        .collect();
    let mut jsonl = LogWriter::new(Vec::new(), &header()).unwrap();
    for seq in 0..30 {
        jsonl.write_frame(&frame(seq)).unwrap();
    }
    let jsonl = jsonl.into_inner();
    let lines: Vec<&[u8]> = jsonl
        .split(|&b| b == b'\n')
        .skip(1)
        .filter(|l| !l.is_empty())
        .collect();
    assert_eq!(frames, lines);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary.chunk_indexes.len() > 3, "several chunks");
    let topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
    assert_eq!(topics.len(), 7, "{topics:?}");
}

#[test]
fn times_before_the_epoch_are_refused() {
    let mut w = McapWriter::new(Vec::new(), &header(), &opts()).unwrap();
    let mut f = frame(3);
    f.t = -0.2;
    let e = w.write_frame(&f).unwrap_err();
    assert!(matches!(e, WriteError::Time { .. }));
    assert!(
        e.to_string()
            .starts_with("frame seq 3: t = -0.2 s has no MCAP log time"),
        "{e}"
    );
    let mut p = pose(&frame(4));
    p.t = f64::NAN;
    assert!(w.write_pose(&p, None).is_err());
    assert!(w.write_status(-1.0, b"{}").is_err());
    for (line, want) in [
        (&b"{\"class\":\"POSE\",\"seq\":1}"[..], "no number t"),
        (
            b"{\"class\":\"FRAME\",\"seq\":1,\"t\":0}",
            "class is not POSE",
        ),
        (b"nope", "not a JSON object"),
    ] {
        let e = w.write_pose_line(line).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
    // The writer is still good.
    w.write_frame(&frame(5)).unwrap();
    let bytes = w.finish().unwrap();
    let got: Vec<_> = McapReader::new(&bytes[..], "t.mcap", None)
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(got, vec![frame(5)]);
}

#[test]
fn the_opener_goes_by_extension_and_magic() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    fs::write(p("rec.mcap"), record(5, 4 << 10)).unwrap();
    fs::copy(data("dive.jsonl"), p("dive.jsonl")).unwrap();
    fs::copy(p("rec.mcap"), p("rec.bin")).unwrap();
    fs::copy(data("dive.jsonl"), p("dive.log")).unwrap();
    fs::copy(p("rec.mcap"), p("wrong.jsonl")).unwrap();
    fs::copy(data("dive.jsonl"), p("wrong.mcap")).unwrap();
    for (name, frames) in [
        ("rec.mcap", 5),
        ("rec.bin", 5),
        ("dive.jsonl", 41),
        ("dive.log", 41),
    ] {
        let mut log = open(&p(name)).unwrap();
        let mut n = 0;
        while let Some(r) = log.next_frame() {
            r.unwrap();
            n += 1;
        }
        assert_eq!(n, frames, "{name}");
    }
    for (name, want) in [
        (
            "wrong.jsonl",
            "byte 0: an MCAP file (its magic) named .jsonl",
        ),
        ("wrong.mcap", "byte 0: not an MCAP file (no MCAP magic)"),
    ] {
        let e = open(&p(name)).err().unwrap().to_string();
        assert!(
            e.ends_with(&format!("{name}: {want}")) || e.contains(want),
            "{e}"
        );
        common::assert_one_line_at(&e, &p(name).display().to_string());
    }
    let e = open(&p("missing.mcap")).err().unwrap().to_string();
    assert!(e.contains("missing.mcap"), "{e}");
}

#[test]
fn conversion_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let log = data("dive.jsonl");
    let cases = [
        (
            dir.path().join("x.txt"),
            None,
            "must be named .jsonl or .mcap",
        ),
        (
            dir.path().join("x.jsonl"),
            Some(data("dive.poses.jsonl")),
            "no poses to carry",
        ),
        (log.clone(), None, "same file"),
    ];
    for (out, poses, want) in cases {
        let e = convert(&log, &out, poses.as_deref(), &opts(), |_| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{e}");
    }
    // --poses named as the input or the output: refused before anything
    // is written (the input MCAP had been truncated to 0 bytes, exit 0).
    let mcap = dir.path().join("rec.mcap");
    convert(&log, &mcap, None, &opts(), |_| {}).unwrap();
    let before = fs::read(&mcap).unwrap();
    let out = dir.path().join("o.jsonl");
    let same_as_out = dir.path().join(".").join("o.jsonl");
    for (poses, flag) in [(&mcap, "--in"), (&same_as_out, "--out")] {
        let e = convert(&mcap, &out, Some(poses), &opts(), |_| {})
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("--poses and {flag} are the same file")),
            "{e}"
        );
    }
    assert_eq!(fs::read(&mcap).unwrap(), before, "the input is untouched");
    assert!(!out.exists(), "nothing written");
    // A bad POSE line is named by file and line.
    let poses = dir.path().join("bad.poses.jsonl");
    fs::write(
        &poses,
        "{\"class\":\"POSE\",\"seq\":0,\"t\":0.0}\n\n{\"class\":\"POSE\",\"t\":0.2}\n",
    )
    .unwrap();
    let e = convert(
        &log,
        &dir.path().join("y.mcap"),
        Some(&poses),
        &opts(),
        |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.ends_with("bad.poses.jsonl:3: POSE has no integer seq"),
        "{e}"
    );
}

/// Every message of a finished MCAP by topic (sequence, times, bytes, and
/// the channel's declaration), and its metadata records in order, read by
/// the `mcap` crate.
type Topics = BTreeMap<String, Vec<(u32, u64, u64, Vec<u8>, String)>>;
type Metas = Vec<(String, BTreeMap<String, String>)>;

fn contents(bytes: &[u8]) -> (Topics, Metas) {
    let mut topics = Topics::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let decl = format!(
            "{} {:?} {:?}",
            m.channel.message_encoding,
            m.channel.metadata,
            m.channel.schema.as_ref().map(|s| (
                s.name.clone(),
                s.encoding.clone(),
                s.data.to_vec()
            ))
        );
        topics.entry(m.channel.topic.clone()).or_default().push((
            m.sequence,
            m.log_time,
            m.publish_time,
            m.data.into_owned(),
            decl,
        ));
    }
    let mut metas = Vec::new();
    for r in mcap::read::LinearReader::new(bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = r.unwrap() {
            metas.push((m.name, m.metadata));
        }
    }
    (topics, metas)
}

/// MCAP → MCAP dropped `/lightpose/status` and every metadata record but
/// the HEADER's (an audit: `lightpose-clock`, the only map from a board's
/// log time to the date, gone from every converted recording). Now every
/// channel and record comes through as it was.
#[test]
fn mcap_to_mcap_keeps_status_other_channels_and_every_metadata_record() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.mcap"), dir.path().join("out.mcap"));
    let n = 30;
    std::fs::write(&input, common::rich_record(n, 2 << 10)).unwrap();
    let s = convert(&input, &output, None, &opts(), |e| panic!("{e}")).unwrap();
    assert_eq!((s.frames, s.poses), (n, n));
    assert_eq!((s.carried, s.metadata), (3 + 10, 3), "{s:?}");
    let (want, want_meta) = contents(&std::fs::read(&input).unwrap());
    let (got, got_meta) = contents(&std::fs::read(&output).unwrap());
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>()
    );
    for (topic, msgs) in &want {
        assert_eq!(msgs, &got[topic], "{topic}");
    }
    assert_eq!(got["/lightpose/status"].len(), 3);
    assert_eq!(got["/x/depth"].len(), 10);
    assert_eq!(want_meta, got_meta);
    let names: Vec<&str> = got_meta.iter().map(|m| m.0.as_str()).collect();
    assert_eq!(
        names,
        [
            "lightpose-header",
            "lightpose-clock",
            "lightpose-clock",
            "notes"
        ]
    );
    // Into JSONL (frames only) they are passed over, counted.
    let jsonl = dir.path().join("out.jsonl");
    let s = convert(&input, &jsonl, None, &opts(), |e| panic!("{e}")).unwrap();
    assert_eq!((s.carried, s.metadata), (0, 0));
    assert!(s.other >= 3 + 10 + 3, "{s:?}");
}
