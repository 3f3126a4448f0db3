//! Reading a log is the daemon's frame source when it replays one (hal's
//! replay backend opens it with `LogFile::open` and reads it through core's
//! `FrameLog`), so reading a frame is on the hot path: once warm, a FRAME
//! line with every reading (attitude, depth, velocity, each with its std,
//! truth, temp_c) must not touch the heap. The MCAP container reads one
//! chunk at a time into a reused buffer: measured and bounded per chunk.
//! Counted per thread with a global allocator.

// The same frames as core's no-allocation test.
#[path = "../../core/tests/support/every_field.rs"]
mod every_field;

use every_field::frame;
use lightpose_core::log::DEFAULT_MAX_GAP_S;
use lightpose_core::{Frame, LogHeader};
use lightpose_logs::{create, FrameLog, LogFile, McapOptions};
use lightpose_testkit::alloc::Counting;
use std::path::Path;

#[global_allocator]
static A: Counting = Counting::new();

const FRAMES: u64 = 400;
const WARM: usize = 50;

/// Write `FRAMES` frames to `path` (container by extension), read them back
/// as replay does, and return the allocations over the frames after the
/// warm-up, checking every frame read against the one written; and the
/// records of other kinds passed over.
fn allocs_reading(path: &Path) -> (u64, u64) {
    let written: Vec<Frame> = (0..FRAMES).map(frame).collect();
    let mut sink = create(path, &LogHeader::new(10, 5.0), &McapOptions::default()).unwrap();
    for f in &written {
        sink.write_frame(f).unwrap();
    }
    sink.finish().unwrap();

    // As hal's replay backend opens a log.
    let mut log: Box<dyn FrameLog + Send> = Box::new(
        LogFile::open(path)
            .unwrap()
            .with_max_gap_s(DEFAULT_MAX_GAP_S),
    );
    let mut read = Vec::with_capacity(FRAMES as usize + 1);
    for _ in 0..WARM {
        read.push(log.next_frame().unwrap().unwrap());
    }
    let ((), allocs) = A.this_thread(|| {
        while let Some(r) = log.next_frame() {
            read.push(r.unwrap());
        }
    });
    assert_eq!(read.len(), written.len());
    for (got, want) in read.iter().zip(&written) {
        let (gt, wt) = (got.truth.unwrap(), want.truth.unwrap());
        assert!((gt.pose.pitch.rad() - wt.pose.pitch.rad()).abs() < 1e-15);
        assert!((gt.pose.yaw.rad() - wt.pose.yaw.rad()).abs() < 1e-15);
        let exact = Frame {
            truth: want.truth,
            ..*got
        };
        assert_eq!(&exact, want, "seq {}", want.seq);
        assert_eq!(gt.pose.x, wt.pose.x);
        assert_eq!(gt.surge, wt.surge);
    }
    assert_eq!(log.bad_readings(), (0, None));
    assert_eq!(log.order().skipped(), 0);
    assert_eq!(log.seq_gaps(), (0, 0));
    (allocs, log.other_records())
}

#[test]
fn reading_a_jsonl_frame_allocates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (allocs, other) = allocs_reading(&dir.path().join("r.jsonl"));
    assert_eq!(other, 0);
    let n = FRAMES - WARM as u64;
    eprintln!("JSONL: {allocs} allocations over {n} frames");
    assert_eq!(allocs, 0, "{allocs} allocations over {n} frames");
}

#[test]
fn reading_an_mcap_frame_allocates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    // Its Foxglove channels (image, pose) are passed over.
    let path = dir.path().join("r.mcap");
    let (allocs, _) = allocs_reading(&path);
    let size = std::fs::metadata(&path).unwrap().len();
    let chunks = size / McapOptions::default().chunk_bytes;
    assert!(chunks >= 4, "{size} bytes: the read must cross chunks");
    let n = FRAMES - WARM as u64;
    eprintln!("MCAP: {allocs} allocations over {n} frames, {chunks} chunks of 64 KiB");
    assert_eq!(allocs, 0, "{allocs} allocations over {n} frames");
}
