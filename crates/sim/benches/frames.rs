//! Simulator throughput: frames per second for the tank scene, and the time
//! to write the default full sweep (61,600 frames) as an intensity log.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lightpose_core::{Angle, Pose};
use lightpose_sim::{Scene, Simulator, SweepKind, SweepPlan};
use std::hint::black_box;

fn frames(c: &mut Criterion) {
    let mut g = c.benchmark_group("simulator");
    g.throughput(Throughput::Elements(1));
    let pose = Pose::new(6.0, 0.2, 0.1, Angle::from_deg(3.0), Angle::from_deg(-4.0));
    let mut sim = Simulator::new(Scene::default(), 1);
    let mut seq = 0;
    g.bench_function("tank frame", |b| {
        b.iter(|| {
            seq += 1;
            black_box(sim.frame(seq, 0.0, black_box(&pose), None))
        })
    });
    g.finish();

    let mut g = c.benchmark_group("sweep");
    g.sample_size(10);
    let plan = SweepPlan::new(SweepKind::All, 200);
    g.throughput(Throughput::Elements(plan.frames()));
    g.bench_function("full sweep 61600 frames to log", |b| {
        b.iter(|| {
            // Into memory: the disk is not what is measured.
            let mut out = Vec::with_capacity(16 << 20);
            black_box(plan.write(&Scene::default(), 1, &mut out).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
