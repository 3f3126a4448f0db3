//! A line far longer than any log line (garbage, a corrupt file) is
//! refused as core refuses it, counted and skipped, and never held whole:
//! reading a JSONL log (through the line tap that keeps each line for a
//! conversion) and the POSE lines of `convert --poses` peak at a few
//! hundred kB of heap, whatever the line's length. Measured with a global
//! allocator that follows the bytes in use.

mod common;
use common::data;

use lightpose_core::log::MAX_LOG_LINE_BYTES;
use lightpose_logs::{convert, FrameLog, LogFile, McapOptions};
use lightpose_testkit::alloc::Counting;
use std::io::Write;
use std::path::Path;

#[global_allocator]
static A: Counting = Counting::new();

/// `src` with a line of `len` bytes (and its newline) after its `after`th.
fn with_long_line(src: &Path, dst: &Path, after: usize, len: usize) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut out = std::io::BufWriter::new(std::fs::File::create(dst).unwrap());
    for (i, line) in text.lines().enumerate() {
        writeln!(out, "{line}").unwrap();
        if i + 1 == after {
            let chunk = vec![b'9'; 1 << 20];
            for _ in 0..len >> 20 {
                out.write_all(&chunk).unwrap();
            }
            out.write_all(b"\n").unwrap();
        }
    }
    out.flush().unwrap();
}

const LONG: usize = 24 << 20;
const BOUND: usize = 4 << 20;

// One test: the allocator's counts are global, tests beside it would blur
// them.
#[test]
fn a_line_of_24_mb_is_refused_without_being_held() {
    const { assert!(LONG > 30 * MAX_LOG_LINE_BYTES) };
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("long.jsonl");
    with_long_line(&data("dive.jsonl"), &log, 3, LONG);

    // Read through LogFile (the line tap under core's reader).
    let ((frames, refused), peak) = A.peak_of(|| {
        let mut f = LogFile::open(&log).unwrap();
        let (mut frames, mut refused) = (0, Vec::new());
        while let Some(r) = f.next_frame() {
            match r {
                Ok(_) => frames += 1,
                Err(e) => refused.push(e.to_string()),
            }
        }
        (frames, refused)
    });
    assert_eq!(frames, 41);
    assert_eq!(refused.len(), 1, "{refused:?}");
    assert!(refused[0].contains(":4: line longer than"), "{refused:?}");
    assert!(peak < BOUND, "reading held {peak} bytes at once");

    // Converted with its POSE lines, one of them as long.
    let poses = dir.path().join("long.poses.jsonl");
    with_long_line(&data("dive.poses.jsonl"), &poses, 7, LONG);
    let out = dir.path().join("long.mcap");
    let mut skipped = Vec::new();
    let (s, peak) = A.peak_of(|| {
        convert(&log, &out, Some(&poses), &McapOptions::default(), |e| {
            skipped.push(e.to_string())
        })
        .unwrap()
    });
    assert_eq!((s.frames, s.poses, s.skipped), (41, 41, 2), "{skipped:?}");
    assert!(
        skipped[1].contains("long.poses.jsonl:8: line longer than"),
        "{skipped:?}"
    );
    assert!(peak < BOUND, "converting held {peak} bytes at once");
}
