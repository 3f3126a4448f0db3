//! Per-frame cost of the tracker on a docking station (issue 41: under
//! 200 µs per frame with five beacons): `Tracker::with_station` on
//! dock-example.toml's four beacons and on five at 4.8 kHz, the vehicle
//! 3 m out, each frame one step of a running track (the frames of a still
//! vehicle fed in turn, their times running on, so that the track never
//! restarts).

mod common;

use common::{frames, scene};
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use lightpose_analysis::bound::{sensor_of, station_of};
use lightpose_core::{Estimator, Status};
use lightpose_pipeline::model::tracker::Tracker;
use lightpose_pipeline::settings::TrackerConfig;

fn bench(c: &mut Criterion) {
    for five in [false, true] {
        let s = scene(five);
        let (mut fr, _, _) = frames(&s);
        let cfg = TrackerConfig {
            x_range: [1.0, 12.0],
            ..TrackerConfig::default()
        };
        let mut tr = Tracker::new(sensor_of(&s), cfg)
            .expect("tracker")
            .with_station(station_of(&s));
        let dt = 1.0 / s.adc.rate_hz;
        let mut seq = 0u64;
        let mut step = |tr: &mut Tracker, fr: &mut Vec<lightpose_core::Frame>| {
            let f = &mut fr[(seq % 20) as usize];
            f.seq = seq;
            f.t = seq as f64 * dt;
            seq += 1;
            tr.estimate(black_box(f))
        };
        // Warm: the track started and `ok`.
        for _ in 0..40 {
            step(&mut tr, &mut fr);
        }
        let e = step(&mut tr, &mut fr);
        assert_eq!(e.status, Status::Ok, "{e:?}");
        let n = station_of(&s).len();
        c.bench_function(&format!("station tracker, {n} beacons, per frame"), |b| {
            b.iter(|| step(&mut tr, &mut fr))
        });
        let e = step(&mut tr, &mut fr);
        assert_eq!(
            e.status,
            Status::Ok,
            "still on track after the bench: {e:?}"
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
