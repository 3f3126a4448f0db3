//! The figures docs/demodulator.md quotes, measured and held to the claims:
//! the flicker's worst leak (dB) over 0.5–20 Hz, the noise against the
//! white-noise limit, per configuration. `cargo test -p lightpose-demod
//! --test figures -- --nocapture` prints them.

#![allow(clippy::needless_range_loop)]

mod common;

use common::{limit_var, rng, Flicker, Scene, Wave};
use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};

fn run(sc: &Scene, frames: usize, seed: u64) -> Vec<[f64; NDET]> {
    let beacons = sc
        .waves
        .iter()
        .enumerate()
        .map(|(b, w)| BeaconSpec::new(format!("b{b}"), w.mod_hz))
        .collect();
    let mut cfg = DemodConfig::new(sc.sample_hz, sc.rate_hz, beacons);
    cfg.channel_skew_s = sc.skew_s;
    let mut d = Demodulator::new(cfg.validate().unwrap());
    let mut out = d.output();
    let mut r = rng(seed);
    (0..frames)
        .map(|j| {
            d.demodulate(&sc.frame(j, &mut r), sc.t(j), sc.bits, &mut out)
                .unwrap();
            out.light.beacons[0].amplitude
        })
        .collect()
}

fn scene(fs: f64, rate: f64, hz: f64, bits: u8, level: f64, a: [f64; NDET]) -> Scene {
    Scene {
        sample_hz: fs,
        rate_hz: rate,
        skew_s: 1.3e-5,
        bits,
        level: [level; NDET],
        waves: vec![Wave {
            mod_hz: hz,
            phase: 0.377,
            drift: 63e-6,
            amplitude: a,
        }],
        flicker: Vec::new(),
        noise: 0.0,
        clip: None,
        t0: 20.0,
    }
}

const CASES: [(f64, f64, f64); 5] = [
    (2000.0, 5.0, 250.0),
    (4000.0, 5.0, 200.0),
    (4000.0, 10.0, 100.0),
    (8000.0, 20.0, 500.0),
    (4000.0, 5.0, 1000.0),
];

#[test]
fn flicker_leak_db() {
    let mut a = [0.0; NDET];
    for (k, v) in a.iter_mut().enumerate() {
        *v = (2000 + 200 * k) as f64;
    }
    for (fs, rate, hz) in CASES {
        let mut worst: f64 = 0.0;
        for fl in [0.5, 1.0, 2.0, 3.7, 5.0, 8.0, 12.0, 16.0, 20.0] {
            let mut sc = scene(fs, rate, hz, 16, 25000.0, a);
            let af = 12000.0;
            sc.flicker.push(Flicker {
                hz: fl,
                amplitude: af,
                phase: 0.4,
            });
            for amp in run(&sc, 10, 1) {
                for k in 0..NDET {
                    worst = worst.max((amp[k] - a[k]).abs() / af);
                }
            }
        }
        let db = 20.0 * worst.max(1e-12).log10();
        eprintln!("{fs} Hz / {rate} Hz frames, beacon {hz} Hz: flicker 0.5–20 Hz leaks at most {db:.1} dB");
        assert!(db <= -60.0);
    }
}

#[test]
fn noise_against_limit() {
    let mut a = [0.0; NDET];
    for (k, v) in a.iter_mut().enumerate() {
        *v = if k % 4 == 0 {
            0.0
        } else {
            40.0 + 10.0 * k as f64
        };
    }
    for (fs, rate, hz) in CASES {
        let mut sc = scene(fs, rate, hz, 12, 900.0, a);
        sc.noise = 4.0;
        let frames = 150;
        let mut sq = 0.0;
        for amp in run(&sc, frames, 2) {
            for k in 0..NDET {
                sq += (amp[k] - a[k]).powi(2);
            }
        }
        let ratio = sq / (frames * NDET) as f64 / limit_var((16.0f64 + 1.0 / 12.0).sqrt(), sc.n());
        eprintln!("{fs} Hz / {rate} Hz frames, beacon {hz} Hz: variance {ratio:.3}× the white-noise limit");
        assert!(ratio <= 1.2);
    }
}
