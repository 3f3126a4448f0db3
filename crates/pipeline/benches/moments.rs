//! Per-frame cost of the moments estimator, from counts through
//! temperature correction to pose: what the daemon pays per frame on the
//! vehicle's computer. Frames are the tank scene's dive (simulated once,
//! outside the timing) with the shipped tank calibration.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use lightpose_core::{Estimator, Frame};
use lightpose_pipeline::{Calibration, MomentsEstimator};
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::path::Path;

fn frames() -> (Calibration, Vec<Frame>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cal = Calibration::load(&root.join("config/calibration/tank.toml")).expect("calibration");
    let scene = Scene::load(&root.join("config/scenes/tank.toml")).expect("scene");
    let traj = Trajectory::load(&root.join("config/trajectories/dive.csv")).expect("trajectory");
    let rate = scene.adc.rate_hz;
    let mut sim = Simulator::new(scene, 1);
    let frames = traj
        .frame_times(rate)
        .enumerate()
        .map(|(i, t)| {
            let (pose, surge) = traj.sample(t);
            sim.frame(i as u64, t, &pose, Some(surge))
        })
        .collect();
    (cal, frames)
}

fn bench(c: &mut Criterion) {
    let (cal, frames) = frames();
    let mut est = MomentsEstimator::new(&cal);
    let mut i = 0;
    c.bench_function("moments estimator, one frame", |b| {
        b.iter(|| {
            // Walk the dive; restart (with a reset) at its end so that time
            // keeps increasing and the surge window stays in use.
            if i == frames.len() {
                i = 0;
                est.reset();
            }
            let p = est.estimate(black_box(&frames[i]));
            i += 1;
            black_box(p)
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
