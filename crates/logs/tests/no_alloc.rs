//! The MCAP writer sits in the daemon's recorder thread. Once warm, what
//! lightpose does per frame (FRAME line, image, truth) and per pose (POSE
//! object, Foxglove pose and transform) must not touch the heap; the
//! `mcap` crate allocates per chunk (its CRC writers batch bytes in a Vec
//! made anew for each chunk, and it keeps a chunk index per chunk for the
//! summary), which these tests measure and bound. Counted with a global
//! allocator; the sink counts bytes, which arrive when a chunk closes
//! (chunks are buffered whole).

use lightpose_core::{Angle, Frame, LogHeader, Pose, PoseEstimate, Status, Truth, NDET};
use lightpose_logs::{McapOptions, McapWriter};
use lightpose_testkit::alloc::Counting;
use std::io::{self, Write};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Arc;

// Counted per thread (`A.this_thread`): the tests run side by side.
#[global_allocator]
static A: Counting = Counting::new();

/// A sink that only counts what reaches it.
#[derive(Default, Clone)]
struct Bytes(Arc<AtomicU64>);

impl Write for Bytes {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        self.0.fetch_add(b.len() as u64, Relaxed);
        Ok(b.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn frame(seq: u64) -> Frame {
    let mut counts = [0u16; NDET];
    for (k, c) in counts.iter_mut().enumerate() {
        *c = ((seq as usize * 7 + k * 40) % 1024) as u16;
    }
    let mut f = Frame::new(seq, seq as f64 * 0.2, 10, counts);
    f.temp_c = Some(19.9 + seq as f64 * 1e-3);
    f.truth = Some(Truth {
        pose: Pose::new(7.8, 0.1, 0.12, Angle::from_deg(9.6), Angle::from_deg(-2.0)),
        surge: Some(0.5),
    });
    f
}

fn pose(f: &Frame) -> PoseEstimate {
    let mut p = PoseEstimate::empty(f.seq, f.t, Status::Ok, "tracker");
    (p.x, p.y, p.z) = (Some(7.8), Some(0.1), Some(0.12));
    (p.pitch_deg, p.yaw_deg, p.surge) = (Some(9.5), Some(-2.1), Some(0.5));
    p.std.x = Some(0.2);
    p
}

/// Everything lightpose formats per frame and per pose, into warm buffers.
#[test]
fn formatting_a_frame_and_a_pose_allocates_nothing() {
    use lightpose_core::LogWriter;
    use lightpose_logs::foxglove::{self, Stamp};
    let mut lines = LogWriter::new(Vec::with_capacity(1024), &LogHeader::new(10, 5.0)).unwrap();
    let mut buf = Vec::with_capacity(1024);
    let mut run = |seq: u64| {
        let f = frame(seq);
        let p = pose(&f);
        lines.get_mut().clear();
        lines.write_frame(&f).unwrap();
        let stamp = Stamp::of(f.t).unwrap();
        foxglove::raw_image(stamp, &f.counts, &mut buf);
        foxglove::pose_in_frame(stamp, &f.truth.unwrap().pose, &mut buf);
        p.write_json(Some(1.7e9), &mut buf);
        foxglove::frame_transform(stamp, &f.truth.unwrap().pose, &mut buf);
    };
    for seq in 0..50 {
        run(seq);
    }
    let ((), allocs) = A.this_thread(|| {
        for seq in 50..2000 {
            run(seq);
        }
    });
    assert_eq!(allocs, 0);
}

/// The whole writer at the recorder's chunk size: allocations come with
/// chunks, a bounded number each, never with frames.
#[test]
fn the_writer_allocates_per_chunk_not_per_frame() {
    let opts = McapOptions::default();
    let sink = Bytes::default();
    let mut w = McapWriter::new(sink.clone(), &LogHeader::new(10, 5.0), &opts).unwrap();
    let write = |w: &mut McapWriter<Bytes>, seq: u64| {
        let f = frame(seq);
        w.write_frame(&f).unwrap();
        w.write_pose(&pose(&f), Some(1.7e9)).unwrap();
    };
    // Warm up: buffers reach their size, every channel has a message count.
    for seq in 0..300 {
        write(&mut w, seq);
    }
    let n = 5000u64;
    let start = sink.0.load(Relaxed);
    let (mut chunks, mut last) = (0u64, start);
    let ((), allocs) = A.this_thread(|| {
        for seq in 300..300 + n {
            write(&mut w, seq);
            let now = sink.0.load(Relaxed);
            chunks += u64::from(now > last);
            last = now;
        }
    });
    let bytes = sink.0.load(Relaxed) - start;
    eprintln!(
        "{n} frames and poses, 64 KiB chunks: {chunks} chunks, {allocs} allocations \
         ({:.1} per chunk, {:.3} per frame); {:.0} bytes per frame and pose",
        allocs as f64 / chunks as f64,
        allocs as f64 / n as f64,
        bytes as f64 / n as f64
    );
    assert!(chunks >= 50, "the test must cross chunk boundaries");
    assert!(
        allocs <= 40 * chunks,
        "{allocs} allocations for {chunks} chunks"
    );
}

/// Spec v3: a BURST (binary on `/lightpose/burst`, its image and truth)
/// costs the writer no allocation per frame either, once warm: allocations
/// come with chunks (a 2 kHz burst of 25 × 100 samples is about 5 kB, so a
/// 64 KiB chunk holds about twelve).
#[test]
fn writing_bursts_allocates_per_chunk_not_per_frame() {
    let mut h = LogHeader::new(10, 20.0);
    h.sample_hz = Some(2000.0);
    h.beacons = vec![lightpose_core::BeaconInfo {
        id: "top".into(),
        mod_hz: 200.0,
    }];
    let sink = Bytes::default();
    let mut w = McapWriter::new(sink.clone(), &h, &McapOptions::default()).unwrap();
    let mut b = lightpose_core::Burst::new(100);
    b.adc_bits = 10;
    let mut write = |w: &mut McapWriter<Bytes>, seq: u64| {
        b.seq = seq;
        b.t = seq as f64 * 0.05;
        for (i, v) in b.samples_mut().iter_mut().enumerate() {
            *v = ((i as u64 * 13 + seq * 7) % 1024) as u16;
        }
        b.truth = frame(seq).truth;
        w.write_burst(&b).unwrap();
    };
    for seq in 0..100 {
        write(&mut w, seq);
    }
    let n = 2000u64;
    let (mut chunks, mut last) = (0u64, sink.0.load(Relaxed));
    let ((), allocs) = A.this_thread(|| {
        for seq in 100..100 + n {
            write(&mut w, seq);
            let now = sink.0.load(Relaxed);
            chunks += u64::from(now > last);
            last = now;
        }
    });
    eprintln!("{n} bursts: {chunks} chunks, {allocs} allocations");
    assert!(chunks >= 50, "the test must cross chunk boundaries");
    assert!(
        allocs <= 40 * chunks,
        "{allocs} allocations for {chunks} chunks"
    );
}
