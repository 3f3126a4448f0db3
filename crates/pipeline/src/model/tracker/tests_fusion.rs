//! The tracker with the vehicle's own sensors (spec v2): each reading moves
//! the estimate toward itself, more the less noisy it is; a refused reading
//! changes nothing but its verdict; every refusal reason; the gate's
//! restart; the depth sensor's lever arm; and all three sensors together.

use super::readings::FrameReadings;
use super::tests::{zigzag, zigzag_velocity};
use super::*;
use crate::model::testutil::{synth_frame, Rng};
use lightpose_core::{
    Angle, Attitude, AttitudeReading, AttitudeStd, BodyVec, DepthReading, Pose, VelocityReading,
    NDET,
};
use proptest::prelude::*;

/// The readings a frame of the zigzag at `t` carries: attitude, depth and
/// DVL with MODEL.md's noise, each only if asked for.
fn with_readings(f: &mut Frame, t: f64, pose: &Pose, which: [bool; 3], rng: &mut Rng) {
    let [att, depth, dvl] = which;
    f.attitude = att.then(|| {
        AttitudeReading::new(
            pose.pitch + Angle::from_deg(0.3 * rng.normal()),
            pose.yaw + Angle::from_deg(1.5 * rng.normal()),
        )
    });
    f.depth = depth.then(|| DepthReading::new(pose.z + 0.02 * rng.normal()));
    f.velocity = dvl.then(|| {
        let v = Attitude::new(pose.pitch, pose.yaw)
            .to_body(&zigzag_velocity(t))
            .0;
        VelocityReading::new(
            v[0] + 0.02 * rng.normal(),
            v[1] + 0.02 * rng.normal(),
            v[2] + 0.02 * rng.normal(),
        )
    });
}

/// A tracker run over the first `n` frames of the zigzag with the given
/// readings, and the next frame (without readings) to test with.
fn warmed(which: [bool; 3], n: u64, seed: u64) -> (Tracker, Frame) {
    let m = SensorModel::default();
    let mut tr = Tracker::new(m.clone(), TrackerConfig::default()).unwrap();
    let mut rng = Rng::new(seed);
    for i in 0..n {
        let t = i as f64 * 0.2;
        let (pose, _) = zigzag(t);
        let mut f = synth_frame(&m, &pose, i, t, None, &mut rng);
        with_readings(&mut f, t, &pose, which, &mut rng);
        tr.estimate(&f);
    }
    let t = n as f64 * 0.2;
    let (pose, _) = zigzag(t);
    let mut f = synth_frame(&m, &pose, n, t, None, &mut rng);
    with_readings(&mut f, t, &pose, which, &mut rng);
    f.attitude = None;
    f.depth = None;
    f.velocity = None;
    (tr, f)
}

/// The estimate of `f` by a copy of `tr`.
fn one(tr: &Tracker, f: &Frame) -> PoseEstimate {
    tr.clone().estimate(f)
}

/// Frames that are `f` plus one bad reading each, what is wrong with it,
/// and the verdict it must get (`z`: the filter's z without it).
fn bad_readings(f: &Frame, z: f64) -> Vec<(Frame, &'static str, ReadingUse)> {
    let mut v = bad_depths(f, z);
    v.extend(bad_velocities_and_attitudes(f));
    v
}

fn bad_depths(f: &Frame, z: f64) -> Vec<(Frame, &'static str, ReadingUse)> {
    let f = *f;
    vec![
        (
            Frame {
                depth: Some(DepthReading::new(f64::NAN)),
                ..f
            },
            "NaN depth",
            ReadingUse::Refused(Refusal::NotFinite),
        ),
        (
            Frame {
                depth: Some(DepthReading {
                    z,
                    std: Some(-0.02),
                }),
                ..f
            },
            "negative std",
            ReadingUse::Refused(Refusal::BadStd),
        ),
        (
            Frame {
                depth: Some(DepthReading { z, std: Some(0.0) }),
                ..f
            },
            "zero std",
            ReadingUse::Refused(Refusal::BadStd),
        ),
        (
            Frame {
                depth: Some(DepthReading {
                    z,
                    std: Some(f64::INFINITY),
                }),
                ..f
            },
            "infinite std",
            ReadingUse::Refused(Refusal::BadStd),
        ),
        (
            Frame {
                depth: Some(DepthReading::new(z - 100.0)),
                ..f
            },
            "a depth 100 m off",
            ReadingUse::Refused(Refusal::Implausible),
        ),
        (
            Frame {
                depth: Some(DepthReading::new(z + 3.0)),
                ..f
            },
            "a depth 3 m off",
            ReadingUse::Refused(Refusal::Gate),
        ),
    ]
}

fn bad_velocities_and_attitudes(f: &Frame) -> Vec<(Frame, &'static str, ReadingUse)> {
    let f = *f;
    vec![
        (
            Frame {
                velocity: Some(VelocityReading::new(50.0, 0.0, 0.0)),
                ..f
            },
            "50 m/s",
            ReadingUse::Refused(Refusal::Implausible),
        ),
        (
            Frame {
                velocity: Some(VelocityReading::new(0.5, f64::INFINITY, 0.0)),
                ..f
            },
            "infinite velocity",
            ReadingUse::Refused(Refusal::NotFinite),
        ),
        (
            Frame {
                velocity: Some(VelocityReading::new(-2.0, 1.0, 0.0)),
                ..f
            },
            "a velocity 2.5 m/s off",
            ReadingUse::Refused(Refusal::Gate),
        ),
        (
            Frame {
                attitude: Some(AttitudeReading::new(Angle::from_deg(120.0), Angle::ZERO)),
                ..f
            },
            "pitch 120°",
            ReadingUse::Refused(Refusal::Implausible),
        ),
        (
            Frame {
                attitude: Some(AttitudeReading {
                    std: Some(AttitudeStd {
                        pitch: Angle::from_deg(0.3),
                        yaw: Angle::from_deg(f64::NAN),
                    }),
                    ..AttitudeReading::new(Angle::ZERO, Angle::ZERO)
                }),
                ..f
            },
            "NaN yaw std",
            ReadingUse::Refused(Refusal::BadStd),
        ),
        (
            Frame {
                attitude: Some(AttitudeReading::new(Angle::from_deg(40.0), Angle::ZERO)),
                ..f
            },
            "pitch 40° off",
            ReadingUse::Refused(Refusal::Gate),
        ),
    ]
}

#[test]
fn each_refusal_reason_is_counted_and_the_light_still_updates() {
    let (tr, f) = warmed([true, true, true], 12, 3);
    let bare = one(&tr, &f);
    assert_eq!(bare.status, Status::Ok, "{bare:?}");
    let z = bare.z.unwrap();
    let cases = bad_readings(&f, z);
    for (frame, what, want) in cases {
        let e = one(&tr, &frame);
        let got = e
            .readings
            .all()
            .into_iter()
            .find(|u| *u != ReadingUse::Absent);
        assert_eq!(got, Some(want), "{what}: {:?}", e.readings);
        // Refused, the reading changed nothing: the light's update alone.
        assert_eq!(e.status, Status::Ok, "{what}");
        assert_eq!(e.values(), bare.values(), "{what}");
        assert_eq!(e.std, bare.std, "{what}");
    }
}

#[test]
fn a_sensor_the_settings_turn_off_is_ignored() {
    let (tr, f) = warmed([false, false, false], 8, 4);
    let cfg = TrackerConfig {
        use_depth: false,
        ..TrackerConfig::default()
    };
    let mut off = Tracker::new(SensorModel::default(), cfg).unwrap();
    off.state = tr.state;
    let e = off.estimate(&Frame {
        depth: Some(DepthReading::new(0.0)),
        ..f
    });
    assert_eq!(e.readings.depth, ReadingUse::Ignored);
    assert_eq!(e.values(), one(&tr, &f).values());
}

/// The statuses and depth verdicts of eight frames of the zigzag after a
/// warmed filter, the depth reading 1.5 m deeper than the filter's track
/// (beyond the gate); with `light_too` the light sees the vehicle there
/// too (the filter has lost it), else on the track (the depth is wrong).
fn depth_off(light_too: bool) -> Vec<(Status, ReadingUse)> {
    depth_off_with_dark(light_too, 0..0)
}

/// [`depth_off`] with the frames `dark` (by their index 10..18) seen
/// without light.
fn depth_off_with_dark(light_too: bool, dark: std::ops::Range<u64>) -> Vec<(Status, ReadingUse)> {
    let m = SensorModel::default();
    let (mut tr, _) = warmed([true, true, false], 10, 5);
    let mut rng = Rng::new(55);
    let mut statuses = Vec::new();
    for i in 10..18u64 {
        let t = i as f64 * 0.2;
        let (track, _) = zigzag(t);
        let mut pose = track;
        if light_too {
            pose.z += 1.5;
        }
        let mut f = synth_frame(&m, &pose, i, t, None, &mut rng);
        with_readings(&mut f, t, &pose, [true, true, false], &mut rng);
        f.depth = Some(DepthReading::new(track.z + 1.5));
        if dark.contains(&i) {
            f.counts = [0; NDET];
        }
        let e = tr.estimate(&f);
        statuses.push((e.status, e.readings.depth));
    }
    statuses
}

/// A sensor that keeps disagreeing with a filter the light still agrees
/// with (a depth 1.5 m off) is the odd one out: refused frame after frame,
/// the poses `ok`; before, after `reading_gate_restart` refusals the
/// filter started again with the biased depth as its prior.
#[test]
fn a_sensor_refused_again_and_again_stays_refused_while_the_light_fits() {
    let statuses = depth_off(false);
    let gated = ReadingUse::Refused(Refusal::Gate);
    for s in &statuses {
        assert_eq!(*s, (Status::Ok, gated), "{statuses:?}");
    }
}

/// Frames without light cannot judge such a sensor: the state and the
/// refusal stand through them (before, a dark frame restarted the filter,
/// its start failed for want of light, and the next lit frame started
/// with the biased depth as its prior).
#[test]
fn a_sensor_refused_through_dark_frames_stays_refused() {
    let statuses = depth_off_with_dark(false, 13..16);
    let gated = ReadingUse::Refused(Refusal::Gate);
    for (k, s) in statuses.iter().enumerate() {
        let want = if (3..6).contains(&k) {
            Status::NoLight
        } else {
            Status::Ok
        };
        assert_eq!(*s, (want, gated), "frame {k}: {statuses:?}");
    }
}

/// A sensor that keeps disagreeing with a filter the light disagrees with
/// too (the vehicle is where the depth says) is refused
/// `reading_gate_restart` times, then the filter takes itself to be lost
/// and starts again with the reading.
#[test]
fn a_sensor_refused_again_and_again_restarts_a_lost_filter() {
    let statuses = depth_off(true);
    let gated = ReadingUse::Refused(Refusal::Gate);
    for s in &statuses[..4] {
        assert_eq!(*s, (Status::Ok, gated), "{statuses:?}");
    }
    assert_eq!(
        statuses[4],
        (Status::Initialising, ReadingUse::Used),
        "{statuses:?}"
    );
    // Started again with the depth in its fit: it now agrees with it.
    assert_eq!(statuses[5].1, ReadingUse::Used, "{statuses:?}");
}

/// A frame without light still takes its readings: the filter coasts on
/// them and says `no_light`.
#[test]
fn readings_keep_the_filter_going_in_the_dark() {
    let (tr, mut f) = warmed([true, true, true], 10, 6);
    f.counts = [0; NDET];
    f.depth = Some(DepthReading::new(0.0));
    let mut t2 = tr.clone();
    let e = t2.estimate(&f);
    assert_eq!(e.status, Status::NoLight);
    assert_eq!(e.readings.depth, ReadingUse::Used);
    assert!(t2.state.is_some());
}

/// With the depth sensor 0.4 m below the dome centre, its readings are the
/// dome's z − 0.4·cos θ; told the lever arm, the tracker recovers the
/// dome's z; not told, it is pulled most of the way (the light disagrees
/// and holds it back a little: measured −0.30 m).
/// Off by default: the sensors' offsets stay exactly 0, consider states of
/// the held variance (1e-12) that no update moves, through starts,
/// readings and counts updates; their covariance with the rest is the
/// state's sensitivity to them times that variance (of order one: a
/// depth offset moves z as much as itself), which moves no reported σ.
#[test]
fn the_sensor_offsets_are_held_at_zero_unless_told() {
    use super::offsets::HELD_VAR;
    use super::state::{DOFF, POFF};
    let (tr, _) = warmed([true, true, true], 30, 7);
    let s = tr.state.as_ref().expect("a state");
    for (i, c) in [(DOFF, 2), (POFF, 3)] {
        assert_eq!(s.x[i], 0.0);
        assert_eq!(s.p[(i, i)], HELD_VAR);
        let sens = s.p[(c, i)] / HELD_VAR;
        assert!(sens.abs() > 0.05 && sens.abs() < 2.0, "sensitivity {sens}");
        assert!(s.p.column(i).iter().all(|v| v.abs() <= 2.0 * HELD_VAR));
    }
    assert_eq!(s.offset_free, [false, false]);
    assert_eq!(Estimator::depth_offset(&tr), None);
    assert_eq!(Estimator::pitch_offset_deg(&tr), None);
}

/// The start's ties between the pose and the offsets (depth and pitch at
/// once) keep the covariance positive semi-definite whatever the fit's
/// widening (a review found it indefinite at a reduced χ² of 1.2 when the
/// light said little of z and the tie was taken from the widened
/// covariance). The fit's covariance here is a posterior of the two
/// priors and a light that ties z to pitch (the ridge), weak or strong.
#[test]
fn the_start_s_offset_ties_keep_the_covariance_positive() {
    use super::state::{Ms, Vs, DOFF, NS, POFF};
    let cfg = TrackerConfig {
        depth_offset_sigma_m: 0.3,
        pitch_offset_sigma_deg: 2.0,
        ..TrackerConfig::default()
    };
    let mut tr = Tracker::new(SensorModel::default(), cfg.clone()).unwrap();
    tr.offsets.start_at(1.0, &cfg);
    let mut rng = Rng::new(3);
    let (pose, _) = zigzag(1.0);
    let mut f = synth_frame(&SensorModel::default(), &pose, 0, 1.0, None, &mut rng);
    with_readings(&mut f, 1.0, &pose, [true, true, false], &mut rng);
    let r = FrameReadings::check(&f, &tr.cfg);
    let (vd, vp) = (0.09, 2f64.to_radians().powi(2));
    let rd = r.depth.ready().expect("depth").sigma[0].powi(2) + vd;
    let rp = r.attitude.ready().expect("attitude").sigma[0].powi(2) + vp;
    for light in [1e-3f64, 1.0, 1e3] {
        for ridge in [0.0, 0.9, 0.999] {
            // The fit's information: the light's on the pose (z and pitch
            // tied by `ridge`), plus the two priors.
            let mut info = nalgebra::Matrix5::<f64>::identity() * 25.0;
            info[(2, 2)] = light;
            info[(3, 3)] = light * 100.0;
            info[(2, 3)] = -ridge * (info[(2, 2)] * info[(3, 3)]).sqrt();
            info[(3, 2)] = info[(2, 3)];
            info[(2, 2)] += 1.0 / rd;
            info[(3, 3)] += 1.0 / rp;
            let cov = info.try_inverse().expect("invertible");
            let mut p_fit = Ms::zeros();
            p_fit.fixed_view_mut::<5, 5>(0, 0).copy_from(&cov);
            for red in [1.0, 1.2, 5.0, 100.0] {
                let mut p = p_fit * red;
                for i in 5..NS {
                    p[(i, i)] = p[(i, i)].max(1e-4);
                }
                let mut x = Vs::zeros();
                tr.start_offsets(&mut x, &mut p, &p_fit, &r);
                assert_eq!((p[(DOFF, DOFF)], p[(POFF, POFF)]), (vd, vp));
                let least = p.symmetric_eigen().eigenvalues.min();
                assert!(
                    least >= -1e-12 * p.norm(),
                    "light {light}, ridge {ridge}, widened {red}: λ {least}"
                );
            }
        }
    }
}

#[test]
fn the_depth_lever_arm_is_applied_with_the_attitude() {
    let m = SensorModel::default();
    let lever = [0.1, 0.0, 0.4];
    let run = |told: bool| -> f64 {
        let cfg = TrackerConfig {
            depth_lever_arm_m: if told { lever } else { [0.0; 3] },
            ..TrackerConfig::default()
        };
        let mut tr = Tracker::new(m.clone(), cfg).unwrap();
        let mut rng = Rng::new(8);
        let mut err = 0.0;
        for i in 0..30u64 {
            let t = i as f64 * 0.2;
            let (pose, _) = zigzag(t);
            let mut f = synth_frame(&m, &pose, i, t, None, &mut rng);
            with_readings(&mut f, t, &pose, [true, true, false], &mut rng);
            let (st, ct) = pose.pitch.rad().sin_cos();
            f.depth = Some(DepthReading::new(pose.z + lever[0] * st - lever[2] * ct));
            let e = tr.estimate(&f);
            err = e.z.unwrap() - pose.z;
        }
        err
    };
    let (told, not_told) = (run(true), run(false));
    assert!(told.abs() < 0.03, "told: {told}");
    assert!(not_told < -0.2 && not_told > -0.45, "not told: {not_told}");
}

/// All three sensors on a zigzag livelier than the paper's (y and yaw
/// swinging faster): p95 after the first second within the issue's
/// targets (x ≤ 0.1 m, z ≤ 0.05 m, pitch ≤ 1°, yaw ≤ 3°, surge ≤ 0.05
/// m/s) except y, which this zigzag's yaw swings leave at 0.12 m (the
/// paper's zigzag: 0.07 m, docs/estimators.md), with a ±2σ that covers
/// the truth.
#[test]
fn all_three_sensors_track_the_zigzag_tightly_and_honestly() {
    let m = SensorModel::default();
    let cfg = TrackerConfig {
        k_d_sigma: Some(0.0),
        ..TrackerConfig::default()
    };
    let mut tr = Tracker::new(m.clone(), cfg).unwrap();
    let (mut inside, mut n) = ([0usize; 6], 0usize);
    let mut errs: [Vec<f64>; 6] = Default::default();
    for seed in 0..10u64 {
        tr.reset();
        let mut rng = Rng::new(300 + seed);
        for i in 0..41u64 {
            let t = i as f64 * 0.2;
            let (pose, surge) = zigzag(t);
            let mut f = synth_frame(&m, &pose, i, t, None, &mut rng);
            with_readings(&mut f, t, &pose, [true, true, true], &mut rng);
            let e = tr.estimate(&f);
            assert_eq!(e.readings.all(), [ReadingUse::Used; 3], "{e:?}");
            if t < 1.0 {
                continue;
            }
            let truth = pose.values_with_surge(surge);
            n += 1;
            for c in 0..6 {
                let err = e.values()[c].unwrap() - truth[c];
                errs[c].push(err.abs());
                inside[c] += usize::from(err.abs() <= 2.0 * e.std.values()[c].unwrap());
            }
        }
    }
    let p95 = errs.map(|mut v| {
        v.sort_by(f64::total_cmp);
        v[(0.95 * v.len() as f64) as usize]
    });
    let cover = inside.map(|k| k as f64 / n as f64);
    eprintln!("all sensors: p95 {p95:.3?}, coverage {cover:.3?}");
    let target = [0.1, 0.15, 0.05, 1.0, 3.0, 0.05];
    for c in 0..6 {
        assert!(p95[c] <= target[c], "axis {c}: p95 {p95:?}");
        // Measured 0.86 (y) to 0.98: this zigzag's fast yaw swings make
        // y/yaw a little overconfident; the paper's zigzag covers
        // 93–97 % (docs/estimators.md).
        assert!(cover[c] >= 0.8, "axis {c}: coverage {cover:?}");
    }
}

/// Which reading a property test offsets, with the state component it
/// reads and its noise given as the reading's own std.
#[derive(Debug, Clone, Copy)]
enum Which {
    Depth,
    Pitch,
    Surge,
}

/// The frame `f` with one reading of `which` at `value`, 1σ `sigma`.
fn reading(f: &Frame, which: Which, value: f64, sigma: f64, yaw: f64) -> Frame {
    match which {
        Which::Depth => Frame {
            depth: Some(DepthReading {
                z: value,
                std: Some(sigma),
            }),
            ..*f
        },
        Which::Pitch => Frame {
            attitude: Some(AttitudeReading {
                pitch: Angle::from_rad(value),
                yaw: Angle::from_rad(yaw),
                roll: None,
                std: Some(AttitudeStd {
                    pitch: Angle::from_rad(sigma),
                    yaw: Angle::from_deg(1.5),
                }),
            }),
            ..*f
        },
        Which::Surge => Frame {
            velocity: Some(VelocityReading {
                v: BodyVec([value, 0.0, 0.0]),
                std: Some(BodyVec([sigma, 10.0, 10.0])),
            }),
            ..*f
        },
    }
}

/// The component `which` reads, of an estimate.
fn read(e: &PoseEstimate, which: Which) -> f64 {
    match which {
        Which::Depth => e.z.unwrap(),
        Which::Pitch => e.pitch_deg.unwrap().to_radians(),
        Which::Surge => e.surge.unwrap(),
    }
}

proptest! {
    // Few cases: each runs the filter over several frames (seconds in a
    // debug build).
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// A reading pulls the estimate toward itself, and a less noisy one
    /// pulls harder: exactly so in the reading's own update; and after the
    /// light's update too, the estimate has moved the reading's way from
    /// where the light alone puts it.
    #[test]
    fn a_reading_moves_the_estimate_toward_itself_more_with_less_noise(
        which in prop_oneof![Just(Which::Depth), Just(Which::Pitch), Just(Which::Surge)],
        offset in -2.5f64..2.5,
        seed in 0u64..4,
        ratio in 1.5f64..6.0,
    ) {
        prop_assume!(offset.abs() > 0.3);
        let (tr, f) = warmed([true, false, false], 7, 100 + seed);
        let bare = one(&tr, &f);
        let mut prior = *tr.state.as_ref().unwrap();
        let dt = f.t - prior.t;
        tr.predict(&mut prior, dt);
        let i = match which { Which::Depth => 2, Which::Pitch => 3, Which::Surge => VEL };
        // The reading sits `offset` predicted σ from the prediction.
        let sd = prior.sd(i);
        let value = prior.x[i] + offset * sd;
        // Where the light alone already puts the estimate on the reading,
        // which way the light's (nonlinear) update leaves it is second
        // order: the last saved case in proptest-regressions had the
        // reading 0.017σ from it (about 4 % of generated cases are within
        // 0.2σ).
        prop_assume!((value - read(&bare, which)).abs() > 0.2 * sd);
        let yaw = prior.x[4];
        let after = |sigma: f64| {
            let mut s = prior;
            let r = FrameReadings::check(&reading(&f, which, value, sigma, yaw), &tr.cfg);
            let (uses, _) = tr.update_readings(&mut s, &r);
            assert!(uses.contains(&ReadingUse::Used), "{uses:?}");
            (s.x[i] - value).abs()
        };
        let (d0, d1, d2) = ((prior.x[i] - value).abs(), after(sd), after(sd / ratio));
        prop_assert!(d1 < d0 && d2 < d1, "{which:?}: {d0} {d1} {d2}");
        // The whole frame, light included: the reading still pulls the
        // estimate its way from where the light alone puts it.
        let e = one(&tr, &reading(&f, which, value, sd / ratio, yaw));
        let (b, r) = (read(&bare, which), read(&e, which));
        prop_assert!(
            (r - b) * (value - b) > 0.0,
            "{which:?}: without the reading {b}, with it {r}, reading {value}"
        );
    }

    /// A refused reading changes nothing, now or later: the estimates of
    /// this frame and the next are those without it.
    #[test]
    fn a_refused_reading_changes_nothing_but_its_verdict(
        bad in prop_oneof![
            Just(f64::NAN), Just(f64::INFINITY), 30.0f64..1e6, -1e6f64..-30.0,
        ],
        std in prop_oneof![Just(None), Just(Some(-0.1)), Just(Some(0.0)), Just(Some(f64::NAN))],
        seed in 0u64..4,
    ) {
        let (tr, f) = warmed([true, true, true], 8, 200 + seed);
        let m = SensorModel::default();
        let mut rng = Rng::new(9);
        let (pose, _) = zigzag(1.8);
        let next = synth_frame(&m, &pose, 9, 1.8, None, &mut rng);
        let (mut a, mut b) = (tr.clone(), tr.clone());
        let fa = Frame {
            depth: Some(DepthReading { z: bad, std }),
            velocity: Some(VelocityReading { v: BodyVec([bad, 0.0, 0.0]), std: None }),
            ..f
        };
        let ea = a.estimate(&fa);
        let eb = b.estimate(&f);
        prop_assert!(matches!(ea.readings.depth, ReadingUse::Refused(_)), "{:?}", ea.readings);
        prop_assert!(matches!(ea.readings.velocity, ReadingUse::Refused(_)), "{:?}", ea.readings);
        prop_assert_eq!(ea.values(), eb.values());
        prop_assert_eq!(a.estimate(&next).values(), b.estimate(&next).values());
    }
}
