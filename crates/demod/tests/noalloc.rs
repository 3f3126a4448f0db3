//! A frame allocates nothing: the demodulator is made once with every
//! buffer it needs (the counting allocator of the testkit, counting on
//! this thread only), through acquisition, tracking, a clipped channel,
//! a beacon that is dark and the refit of a channel whose edge crosses a sample.

mod common;

use common::{rng, Scene, Wave};
use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulator};
use lightpose_testkit::alloc::Counting;

#[global_allocator]
static A: Counting = Counting::new();

#[test]
fn demodulate_does_not_allocate() {
    let hz = [1000.0, 500.0, 250.0, 125.0];
    let waves: Vec<Wave> = hz
        .iter()
        .enumerate()
        .map(|(b, &f)| Wave {
            mod_hz: f,
            phase: 0.13 * b as f64 + 0.01,
            drift: [90e-6, -80e-6, 40e-6, 0.0][b],
            amplitude: [if b == 3 { 0.0 } else { 150.0 + 20.0 * b as f64 }; NDET],
        })
        .collect();
    let mut sc = Scene {
        sample_hz: 2000.0,
        rate_hz: 5.0,
        skew_s: 2e-5,
        bits: 12,
        level: [600.0; NDET],
        waves,
        flicker: vec![common::Flicker {
            hz: 3.0,
            amplitude: 80.0,
            phase: 0.2,
        }],
        noise: 3.0,
        clip: Some((7, 0.3)),
        t0: 50.0,
    };
    let beacons = hz
        .iter()
        .enumerate()
        .map(|(b, &f)| BeaconSpec::new(format!("b{b}"), f))
        .collect();
    let mut cfg = DemodConfig::new(sc.sample_hz, sc.rate_hz, beacons);
    cfg.channel_skew_s = sc.skew_s;
    let mut demod = Demodulator::new(cfg.validate().unwrap());
    let mut out = demod.output();
    let mut r = rng(11);
    let frames: Vec<Vec<u16>> = (0..60).map(|j| sc.frame(j, &mut r)).collect();
    sc.clip = None;
    let ((), allocs) = A.this_thread(|| {
        for (j, f) in frames.iter().enumerate() {
            demod.demodulate(f, sc.t(j), sc.bits, &mut out).unwrap();
        }
    });
    assert_eq!(allocs, 0, "allocations in 60 frames");
    assert!(demod.lock(0).locked && demod.lock(2).locked);
    assert!(out.light.clipped[7] > 0 && out.light.beacons[0].std[7] >= 4095.0);
}
