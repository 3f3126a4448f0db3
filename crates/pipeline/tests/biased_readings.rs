//! Own-sensor readings that are biased, not noisy: a depth sensor zeroed on
//! another day or a mis-surveyed beacon depth. The tracker believes each
//! reading's σ, so a bias goes into the pose until the reading check says
//! so (`PoseEstimate::agreement`) and its offset is learned
//! (`which_offset`; tests/sensor_offsets.rs), and it must not make it worse:
//! a depth the gate refuses frame after frame no longer restarts the
//! filter while the light still fits the state (a restart took the biased
//! depth into its start fit as a prior).
//!
//! Measured on a minute of coming and going in the tank (to-and-fro,
//! 301 frames, all three sensors): docs/estimators.md, "Biased readings".

mod common;

use common::{minute, root};
use lightpose_core::{Angle, Frame, CHECKED};
use lightpose_pipeline::{build_estimator, Calibration};

struct Run {
    /// p95 of |x error| and |z error| (m) over the `ok` poses after 10 s.
    x95: f64,
    z95: f64,
    /// Of those poses, how many have some axis beyond 3σ, and how many
    /// there are.
    beyond_3sigma: usize,
    ok: usize,
    /// Frames on which each checked component was called disagreeing.
    disagreed: [usize; 6],
}

fn p95(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[(v.len() * 95 / 100).min(v.len() - 1)]
}

/// The tracker (`auto`) over `frames` with `depth_bias` (m) added to every
/// depth reading.
fn run(frames: &[Frame], depth_bias: f64) -> Run {
    let cal = Calibration::load(&root().join("config/calibration/tank.toml")).expect("cal");
    let mut est = build_estimator("auto", &cal).expect("auto");
    let (mut ex, mut ez) = (Vec::new(), Vec::new());
    let (mut beyond, mut disagreed) = (0, [0; 6]);
    for f in frames {
        let mut f = *f;
        if let Some(d) = f.depth.as_mut() {
            d.z += depth_bias;
        }
        let e = est.estimate(&f);
        for (i, n) in disagreed.iter_mut().enumerate() {
            *n += usize::from(e.agreement.suspect >> i & 1);
        }
        let truth = f.truth.expect("truth").pose;
        if e.status != lightpose_core::Status::Ok || f.t < 10.0 {
            continue;
        }
        let err = [
            e.x.unwrap() - truth.x,
            e.y.unwrap() - truth.y,
            e.z.unwrap() - truth.z,
            e.pitch_deg.unwrap() - truth.pitch.deg(),
            e.yaw_deg.unwrap() - truth.yaw.deg(),
        ];
        let sd = [e.std.x, e.std.y, e.std.z, e.std.pitch, e.std.yaw].map(Option::unwrap);
        beyond += usize::from(err.iter().zip(sd).any(|(e, s)| e.abs() > 3.0 * s));
        ex.push(err[0].abs());
        ez.push(err[2].abs());
    }
    Run {
        ok: ex.len(),
        x95: p95(ex),
        z95: p95(ez),
        beyond_3sigma: beyond,
        disagreed,
    }
}

#[test]
fn a_biased_depth_is_told_and_a_large_one_no_longer_restarts_the_filter_onto_itself() {
    let depth = CHECKED.iter().position(|c| *c == "depth").expect("depth");
    for seed in [11, 12] {
        let frames = minute(seed);
        let clean = run(&frames, 0.0);
        eprintln!(
            "seed {seed} clean: {} ok, x p95 {:.3}, z p95 {:.3}, {} beyond 3σ, disagreed {:?}",
            clean.ok, clean.x95, clean.z95, clean.beyond_3sigma, clean.disagreed
        );
        // A reading as good as its σ is never called disagreeing.
        assert_eq!(clean.disagreed, [0; 6], "seed {seed}");
        for bias in [0.1, 0.2, -0.2, 0.5] {
            let r = run(&frames, bias);
            eprintln!(
                "seed {seed} depth {bias:+}: {} ok, x p95 {:.3}, z p95 {:.3}, {} beyond 3σ, disagreed {:?}",
                r.ok, r.x95, r.z95, r.beyond_3sigma, r.disagreed
            );
            // Told: depth called disagreeing (until its offset is learned).
            assert!(
                r.disagreed[depth] > 0,
                "seed {seed} depth {bias:+}: {:?}",
                r.disagreed
            );
            // Not taken whole: a bias the gate lets through is learned as
            // the sensor's offset once called (`which_offset`), one it
            // refuses leaves z to the light. Believed, every `ok` pose was
            // beyond 3σ at +0.1 m.
            assert!(
                r.beyond_3sigma * 50 <= r.ok,
                "seed {seed} depth {bias:+}: {} of {} beyond 3σ",
                r.beyond_3sigma,
                r.ok
            );
            // Past the gate (0.2 m and more), not made worse: x stays the
            // light's (0.14–0.72 m p95 when a restart took the biased
            // depth as its prior).
            if bias.abs() >= 0.2 {
                assert!(
                    r.ok * 5 >= clean.ok * 4,
                    "seed {seed} depth {bias:+}: {} ok",
                    r.ok
                );
                assert!(
                    r.x95 < 0.12,
                    "seed {seed} depth {bias:+}: x p95 {:.3}",
                    r.x95
                );
            }
        }
    }
}

/// A depth grossly off (a wrong beacon depth, a sensor zeroed elsewhere:
/// 3 m and more) from the start, or from 10 s in: the light starts the
/// track alone and the gate refuses the depth. Before, it was the start
/// fit's tight prior at every restart and no fit of the light could meet
/// it: `diverged` on every frame, no pose at all for the minute (+5 m,
/// −10 m), or the last 8 s lost (+5 m from 10 s in), in an audit.
#[test]
fn a_depth_grossly_off_does_not_keep_the_track_from_starting() {
    for seed in [11, 12] {
        let frames = minute(seed);
        let clean = run(&frames, 0.0);
        for (bias, from_t) in [(5.0, 0.0), (-10.0, 0.0), (3.0, 0.0), (5.0, 10.0)] {
            let late: Vec<Frame> = frames
                .iter()
                .map(|f| {
                    let mut f = *f;
                    if f.t < from_t {
                        if let Some(d) = f.depth.as_mut() {
                            d.z -= bias; // run() adds it back: unbiased before from_t
                        }
                    }
                    f
                })
                .collect();
            let r = run(&late, bias);
            eprintln!(
                "seed {seed} depth {bias:+} from {from_t} s: {} ok (clean {}), x p95 {:.3}, z p95 {:.3}",
                r.ok, clean.ok, r.x95, r.z95
            );
            assert!(
                r.ok * 20 >= clean.ok * 19,
                "seed {seed} depth {bias:+} from {from_t} s: {} ok of {}",
                r.ok,
                clean.ok
            );
            assert!(
                r.x95 < 0.1 && r.z95 < 0.1,
                "seed {seed}: x {:.3}, z {:.3}",
                r.x95,
                r.z95
            );
        }
    }
}

/// An attitude grossly off (a pitch 30° off, a heading 90° off: an AHRS
/// mounted askew or a compass beside a thruster), taken as the start's
/// prior, started track after track onto itself, each lost at once: not
/// one `ok` pose in the minute. After two tracks lost within 2 s of their
/// start, the next starts from the light alone and the gate judges the
/// readings.
#[test]
fn an_attitude_grossly_off_does_not_keep_the_track_from_starting() {
    let cal = Calibration::load(&root().join("config/calibration/tank.toml")).expect("cal");
    for seed in [11, 12] {
        let frames = minute(seed);
        let clean = run(&frames, 0.0).ok;
        for (pitch, yaw) in [(30.0, 0.0), (0.0, 90.0)] {
            let mut est = build_estimator("auto", &cal).expect("auto");
            let mut ok = 0;
            for f in &frames {
                let mut f = *f;
                if let Some(a) = f.attitude.as_mut() {
                    a.pitch = a.pitch + Angle::from_deg(pitch);
                    a.yaw = a.yaw + Angle::from_deg(yaw);
                }
                let e = est.estimate(&f);
                ok += usize::from(e.status == lightpose_core::Status::Ok && f.t >= 10.0);
            }
            eprintln!("seed {seed} attitude off by ({pitch}°, {yaw}°): {ok} ok (clean {clean})");
            // Measured 222 / 211 (pitch) and 246 / 236 (heading) of the
            // clean 251 (222 / 127 and 245 / 92 before a failed start was
            // retried from the light alone and the unmeasured angles
            // bounded): a track, where there was none (0).
            assert!(
                ok * 3 >= clean,
                "seed {seed} ({pitch}, {yaw}): {ok} of {clean}"
            );
        }
    }
}

/// A minute's slow approach (8.3 → 4.8 m, weaving) in the harbour's
/// water (K_D 0.2) with all three sensors, simulated with `seed`.
fn harbour_approach(seed: u64) -> Vec<Frame> {
    common::with_sensors(
        "config/scenes/harbour.toml",
        "tests/data/slow-approach.csv",
        seed,
    )
}

/// Audit: a depth 0.3 m off from 30 s in (a sensor re-zeroed mid-dive)
/// made the counts misfit, the water check took it for another water,
/// and the bank it became learned K_D 0.75–1.08 (true 0.2) with x 2.3 m
/// short, `out_of_range` to the end of the run, on 3 of 15 harbour runs.
/// The water check now waits while a reading is suspect: the track keeps
/// its range.
#[test]
fn a_depth_biased_from_mid_run_is_not_taken_for_another_water() {
    let cal = Calibration::load(&root().join("config/calibration/harbour.toml")).expect("cal");
    for seed in [1, 4] {
        let mut est = build_estimator("auto", &cal).expect("auto");
        let (mut ex, mut out_of_range, mut k_d) = (Vec::new(), 0, 0.0f64);
        for f in harbour_approach(seed) {
            let mut f = f;
            if f.t >= 30.0 {
                if let Some(d) = f.depth.as_mut() {
                    d.z += 0.3;
                }
            }
            let e = est.estimate(&f);
            k_d = k_d.max(est.water_k_d().unwrap_or(0.0));
            if f.t < 30.0 {
                continue;
            }
            out_of_range += usize::from(e.status == lightpose_core::Status::OutOfRange);
            if let Some(x) = e.x {
                ex.push((x - f.truth.expect("truth").pose.x).abs());
            }
        }
        let x95 = p95(ex);
        assert!(
            x95 < 0.5 && out_of_range == 0 && k_d < 0.3,
            "seed {seed}: x p95 {x95:.2} m, {out_of_range} out_of_range, K_D learned up to {k_d:.2}"
        );
    }
}
