//! Per-frame cost of `model::station_fit` on a docking station's
//! demodulated frames (issue 41's "under 200 µs per frame with five
//! beacons" is the tracker's goal; this is the single-frame fit's figure
//! beside it): dock-example.toml's four beacons, and five at 4.8 kHz
//! (MODEL.md: five beacons need N = 480), the vehicle 3 m out, each fit
//! started from the last frame's pose (as a first fit of a track is not)
//! and from 4 m on the axis (a first frame's).

mod common;

use common::{frames, scene};
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use lightpose_analysis::bound::{sensor_of, station_of};
use lightpose_core::Amplitudes;
use lightpose_pipeline::model::station_fit::{fit_station, Pose6, StationPriors};

fn bench(c: &mut Criterion) {
    for five in [false, true] {
        let s = scene(five);
        let m = sensor_of(&s);
        let station = station_of(&s);
        let (fr, gt, truth) = frames(&s);
        let amps: Vec<Amplitudes> = fr.iter().filter_map(|f| f.amplitudes).collect();
        let priors = StationPriors {
            roll_sigma: 5f64.to_radians(),
            ..StationPriors::default()
        };
        let n = station.len();
        let mut i = 0;
        let mut last = truth;
        c.bench_function(
            &format!("station fit, {n} beacons, from the last pose"),
            |b| {
                b.iter(|| {
                    i = (i + 1) % amps.len();
                    if let Some(f) =
                        fit_station(&m, &station, black_box(&amps[i]), gt, last, &priors)
                    {
                        last = f.pose;
                    }
                })
            },
        );
        let cold = Pose6::new(4.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        c.bench_function(
            &format!("station fit, {n} beacons, from 4 m on the axis"),
            |b| {
                b.iter(|| {
                    i = (i + 1) % amps.len();
                    black_box(fit_station(
                        &m,
                        &station,
                        black_box(&amps[i]),
                        gt,
                        cold,
                        &priors,
                    ))
                })
            },
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
