//! The demodulator's cost per frame without criterion, small enough to
//! cross-build for the vehicle's ARM boards and run under qemu-user, and to
//! count instructions with `perf stat` (docs/demodulator.md, "Cost"):
//!
//!     cargo run --release -p lightpose-demod --example cost -- CASE FRAMES
//!
//! CASE is 0..=3 (the table below); FRAMES are timed after 40 frames that
//! lock every beacon. Prints the case, N, and wall µs per frame.

use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
use std::time::Instant;

/// (sample_hz, rate_hz, beacons' mod_hz): the daemon bench's cases
/// (crates/daemon/src/bench.rs) and criterion's 2 kHz one at 5 Hz.
const CASES: [(f64, f64, &[f64]); 4] = [
    (2000.0, 20.0, &[200.0]),
    (8000.0, 20.0, &[500.0]),
    (8000.0, 20.0, &[500.0, 1000.0, 2000.0, 800.0]),
    (2000.0, 5.0, &[250.0]),
];

const WARMUP: usize = 40;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let case: usize = args.get(1).and_then(|v| v.parse().ok()).unwrap_or(1);
    let frames: usize = args.get(2).and_then(|v| v.parse().ok()).unwrap_or(200);
    let Some(&(fs, rate, hz)) = CASES.get(case) else {
        eprintln!("cost: case {case}: 0..={}", CASES.len() - 1);
        std::process::exit(2);
    };
    let beacons = hz
        .iter()
        .enumerate()
        .map(|(b, &f)| BeaconSpec::new(format!("b{b}"), f))
        .collect();
    let mut cfg = DemodConfig::new(fs, rate, beacons);
    cfg.channel_skew_s = 0.9 / (fs * NDET as f64);
    let valid = match cfg.validate() {
        Ok(v) => v,
        Err(e) => {
            eprintln!("cost: case {case}: {e}");
            std::process::exit(2);
        }
    };
    let n = valid.n;
    // Every frame made before the timing: the beacons' clocks off nominal
    // (as at sea), so frames do not repeat.
    let made: Vec<Vec<u16>> = (0..WARMUP + frames).map(|j| frame(&cfg, n, j)).collect();
    let mut demod = Demodulator::new(valid);
    let mut out = demod.output();
    let mut run = |from: usize, count: usize| {
        for (j, f) in made.iter().enumerate().skip(from).take(count) {
            let t = 1000.0 + j as f64 / rate;
            if let Err(e) = demod.demodulate(f, t, 12, &mut out) {
                eprintln!("cost: frame {j}: {e}");
            }
        }
    };
    run(0, WARMUP);
    let t0 = Instant::now();
    run(WARMUP, frames);
    let us = t0.elapsed().as_secs_f64() * 1e6 / frames.max(1) as f64;
    println!(
        "case {case}: {fs} Hz / {rate} Hz, {} beacons, N = {n}: {us:.1} µs per frame over {frames} frames",
        hz.len()
    );
}

/// Frame j: each beacon on its clock (nominal + 23 ppm per beacon), an
/// ambient with flicker, uniform noise ±3 counts (xorshift), 12 bits.
fn frame(cfg: &DemodConfig, n: usize, j: usize) -> Vec<u16> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ (j as u64 + 1).wrapping_mul(0x2545_f491_4f6c_dd1d);
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        6.0 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
    };
    let mut s = vec![0u16; NDET * n];
    for k in 0..NDET {
        for i in 0..n {
            let t = 1000.0
                + j as f64 / cfg.rate_hz
                + i as f64 / cfg.sample_hz
                + k as f64 * cfg.channel_skew_s;
            let mut v = 300.0 + 40.0 * (2.0 * std::f64::consts::PI * 3.0 * t).sin();
            for (b, beacon) in cfg.beacons.iter().enumerate() {
                let hz = beacon.mod_hz * (1.0 + 23e-6 * (b + 1) as f64);
                if (hz * t + 0.17 * b as f64).rem_euclid(1.0) < 0.5 {
                    v += (100.0 + 10.0 * k as f64) / (1u32 << b) as f64;
                }
            }
            s[k * n + i] = (v + noise()).round().clamp(0.0, 4095.0) as u16;
        }
    }
    s
}
