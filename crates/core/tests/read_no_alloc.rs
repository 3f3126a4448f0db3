//! A JSON Lines log read frame by frame is the daemon's frame source when
//! it replays one, so once warm, reading a FRAME line (attitude, depth and
//! velocity with their std, truth, temp_c) must not touch the heap: the
//! line buffer is reused and the line is parsed in place. Counted per
//! thread with a global allocator. (lightpose-logs' `read_no_alloc` reads
//! through `LogFile`, the opener replay uses, in both containers.)

mod support {
    pub mod every_field;
}

use lightpose_core::log::DEFAULT_MAX_GAP_S;
use lightpose_core::{Frame, FrameLog, LogHeader, LogReader, LogWriter};
use lightpose_testkit::alloc::Counting;
use support::every_field::frame;

#[global_allocator]
static A: Counting = Counting::new();

const FRAMES: u64 = 300;
const WARM: usize = 20;

#[test]
fn reading_a_frame_line_allocates_nothing_once_warm() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.jsonl");
    let written: Vec<Frame> = (0..FRAMES).map(frame).collect();
    let mut w = LogWriter::create(&path, &LogHeader::new(10, 5.0)).unwrap();
    for f in &written {
        w.write_frame(f).unwrap();
    }
    w.flush().unwrap();
    drop(w);

    let mut reader = LogReader::open(&path)
        .unwrap()
        .with_max_gap_s(DEFAULT_MAX_GAP_S);
    let log: &mut dyn FrameLog = &mut reader;
    let mut read = Vec::with_capacity(FRAMES as usize + 1);
    for _ in 0..WARM {
        read.push(log.next_frame().unwrap().unwrap());
    }
    let ((), allocs) = A.this_thread(|| {
        while let Some(r) = log.next_frame() {
            read.push(r.unwrap());
        }
    });
    let n = FRAMES - WARM as u64;
    eprintln!("{allocs} allocations over {n} frames");
    assert_eq!(allocs, 0, "{allocs} allocations over {n} frames");

    assert_eq!(read.len(), written.len());
    for (got, want) in read.iter().zip(&written) {
        // Truth angles are written in degrees and are zero here, so every
        // field reads back bit for bit.
        assert_eq!(got, want, "seq {}", want.seq);
    }
    assert_eq!(log.bad_readings(), (0, None));
    assert_eq!((log.other_records(), log.cut()), (0, None));
    assert_eq!((log.order().skipped(), log.seq_gaps()), (0, (0, 0)));
}
