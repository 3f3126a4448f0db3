//! Per-frame cost of `model::station_fit` on a docking station's
//! demodulated frames (issue 41's "under 200 µs per frame with five
//! beacons" is the tracker's goal; this is the single-frame fit's figure
//! beside it): dock-example.toml's four beacons, and five at 4.8 kHz
//! (MODEL.md: five beacons need N = 480), the vehicle 3 m out, each fit
//! started from the last frame's pose (as a first fit of a track is not)
//! and from 4 m on the axis (a first frame's).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use lightpose_analysis::bound::{sensor_of, station_of};
use lightpose_core::light::temperature_gain;
use lightpose_core::{Amplitudes, Angle, BeamVec, Pose};
use lightpose_pipeline::model::station_fit::{fit_station, Pose6, StationPriors};
use lightpose_sim::{EstimatorFrames, Kinematics, Scene, Simulator};
use std::path::Path;

fn scene(five: bool) -> Scene {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/spec/dock-example.toml");
    let mut s = Scene::load(&p).expect("dock-example.toml");
    if five {
        // 4 800 / 2m with m = 3, 2, 4, 8, 16: no two in an odd : odd ratio.
        s.adc.sample_hz = 4800.0;
        let mut extra = s.beacons[0].clone();
        extra.id = "centre".into();
        extra.position_m = [0.0, 0.35, 0.35];
        s.beacons.push(extra);
        for (b, hz) in s
            .beacons
            .iter_mut()
            .zip([800.0, 1200.0, 600.0, 300.0, 150.0])
        {
            b.blink.mod_hz = hz;
        }
    }
    s
}

fn frames(s: &Scene) -> (Vec<Amplitudes>, f64, Pose6) {
    let truth = Pose::new(
        3.0,
        0.12,
        -0.08,
        Angle::from_deg(3.0),
        Angle::from_deg(-4.0),
    )
    .with_roll(Angle::from_deg(6.0));
    let mut f = EstimatorFrames::new(Simulator::new(s.clone(), 5)).expect("frames");
    let still = Kinematics {
        pose: truth,
        velocity: BeamVec::default(),
    };
    let mut gt = 1.0;
    let amps = (0..20)
        .map(|i| {
            let fr = f.frame(i, i as f64 / s.adc.rate_hz, |_| still);
            gt = temperature_gain(fr.temp_c.unwrap_or(s.temp_c));
            fr.amplitudes.expect("demodulated")
        })
        .collect();
    let q = Pose6::new(
        truth.x,
        truth.y,
        truth.z,
        truth.pitch.rad(),
        truth.yaw.rad(),
        truth.roll.rad(),
    );
    (amps, gt, q)
}

fn bench(c: &mut Criterion) {
    for five in [false, true] {
        let s = scene(five);
        let m = sensor_of(&s);
        let station = station_of(&s);
        let (amps, gt, truth) = frames(&s);
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
