//! What a recording and the live view cost per frame, off the daemon's
//! frame thread (its recorder and live-view threads do this work): a JSONL
//! line, an MCAP frame with its estimate (every channel, 64 KiB chunks),
//! and the live view's encoding of the same messages. Prints the bytes per
//! frame of each container beside criterion's times.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{frame, header, pose};
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use lightpose_core::LogWriter;
use lightpose_logs::{Encoder, McapOptions, McapWriter, Message};
use std::io::{self, Write};

/// A sink that counts bytes, as a file would take them.
#[derive(Default)]
struct Count(u64);

impl Write for Count {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        self.0 += b.len() as u64;
        Ok(b.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn bytes_per_frame() {
    let n = 10_000u64;
    let mut jsonl = LogWriter::new(Count::default(), &header()).unwrap();
    let opts = McapOptions::default();
    let mut mcap = McapWriter::new(Count::default(), &header(), &opts).unwrap();
    for seq in 0..n {
        let f = frame(seq);
        jsonl.write_frame(&f).unwrap();
        mcap.write_frame(&f).unwrap();
        mcap.write_pose(&pose(&f), Some(1.7e9 + f.t)).unwrap();
    }
    let j = jsonl.into_inner().0;
    let m = mcap.finish().unwrap().0;
    println!(
        "bytes per frame: JSONL {:.0} (frame only), MCAP {:.0} (frame, estimate, Foxglove channels)",
        j as f64 / n as f64,
        m as f64 / n as f64
    );
}

fn bench(c: &mut Criterion) {
    bytes_per_frame();
    let frames: Vec<_> = (0..1000).map(frame).collect();
    let poses: Vec<_> = frames.iter().map(pose).collect();
    let mut g = c.benchmark_group("per frame");
    let mut jsonl = LogWriter::new(io::sink(), &header()).unwrap();
    let mut k = 0;
    g.bench_function("jsonl frame", |b| {
        b.iter(|| {
            k = (k + 1) % frames.len();
            jsonl.write_frame(black_box(&frames[k])).unwrap();
        })
    });
    let mut mcap = McapWriter::new(io::sink(), &header(), &McapOptions::default()).unwrap();
    g.bench_function("mcap frame + estimate", |b| {
        b.iter(|| {
            k = (k + 1) % frames.len();
            mcap.write_frame(black_box(&frames[k])).unwrap();
            mcap.write_pose(black_box(&poses[k]), Some(1.7e9)).unwrap();
        })
    });
    let mut enc = Encoder::new(&header(), true).unwrap();
    let mut total = 0usize;
    let mut take = |m: Message| {
        total += m.data.len();
        Ok(())
    };
    g.bench_function("live view encoding", |b| {
        b.iter(|| {
            k = (k + 1) % frames.len();
            enc.frame(black_box(&frames[k]), &mut take).unwrap();
            enc.pose(black_box(&poses[k]), Some(1.7e9), &mut take)
                .unwrap();
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
