//! Demodulator throughput: µs per frame of 25 channels, for 1 and 4
//! beacons, at N = 400 samples per channel (2 kHz at 5 Hz; 8 kHz at
//! 20 Hz) and at 4 kHz and 5 Hz (N = 800), tracked (the steady state).
//! Throughput is in samples (25·N per frame).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
use std::hint::black_box;

/// A frame of every beacon at once (on its nominal clock, so that the
/// frames repeat seamlessly as the bench cycles through them), with daylight
/// and a little noise (a fixed pseudo-random sequence).
fn frames(cfg: &DemodConfig, count: usize) -> Vec<Vec<u16>> {
    let n = (cfg.sample_hz / cfg.rate_hz).round() as usize;
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..count)
        .map(|j| {
            let mut s = vec![0u16; NDET * n];
            for k in 0..NDET {
                for i in 0..n {
                    let t = j as f64 / cfg.rate_hz
                        + i as f64 / cfg.sample_hz
                        + k as f64 * cfg.channel_skew_s;
                    let mut v = 300.0 + 40.0 * (2.0 * std::f64::consts::PI * 3.0 * t).sin();
                    for (b, beacon) in cfg.beacons.iter().enumerate() {
                        let on = (beacon.mod_hz * t + 0.1 * b as f64).rem_euclid(1.0) < 0.5;
                        if on {
                            v += 100.0 + 10.0 * k as f64;
                        }
                    }
                    s[k * n + i] = (v + 6.0 * noise()).round().clamp(0.0, 4095.0) as u16;
                }
            }
            s
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let cases = [
        ("2 kHz, 5 Hz, 1 beacon", 2000.0, 5.0, vec![250.0]),
        (
            "2 kHz, 5 Hz, 4 beacons",
            2000.0,
            5.0,
            vec![1000.0, 500.0, 250.0, 125.0],
        ),
        ("8 kHz, 20 Hz, 1 beacon", 8000.0, 20.0, vec![500.0]),
        (
            "8 kHz, 20 Hz, 4 beacons",
            8000.0,
            20.0,
            vec![4000.0, 2000.0, 1000.0, 500.0],
        ),
        ("4 kHz, 5 Hz, 1 beacon", 4000.0, 5.0, vec![250.0]),
        (
            "4 kHz, 5 Hz, 4 beacons",
            4000.0,
            5.0,
            vec![2000.0, 1000.0, 500.0, 250.0],
        ),
    ];
    let mut g = c.benchmark_group("demodulate");
    for (name, fs, rate, hz) in cases {
        let beacons = hz
            .iter()
            .enumerate()
            .map(|(b, &f)| BeaconSpec::new(format!("b{b}"), f))
            .collect();
        let mut cfg = DemodConfig::new(fs, rate, beacons);
        cfg.channel_skew_s = 4e-5 / (fs / 2000.0);
        let frames = frames(&cfg, 64);
        let mut demod = Demodulator::new(cfg.validate().unwrap());
        let mut out = demod.output();
        // Locked first: the steady state is what a frame costs.
        for (j, f) in frames.iter().enumerate() {
            demod.demodulate(f, j as f64 / rate, 12, &mut out).unwrap();
        }
        g.throughput(Throughput::Elements(frames[0].len() as u64));
        let mut j = frames.len();
        g.bench_function(name, |b| {
            b.iter(|| {
                let f = &frames[j % frames.len()];
                demod
                    .demodulate(black_box(f), j as f64 / rate, 12, &mut out)
                    .unwrap();
                j += 1;
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
