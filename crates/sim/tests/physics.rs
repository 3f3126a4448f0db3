//! The simulator against MODEL.md, one effect at a time: conventions derived
//! by hand, each factor of the light equation against its closed form, the
//! temperature factor, the ADC, and the noise statistics.

use lightpose_core::array::index;
use lightpose_core::frame::volts_to_counts;
use lightpose_core::{Angle, Pose, NDET};
use lightpose_sim::{Scene, Simulator};

/// A scene with only what a test names: no scattering, no noise.
fn bare() -> Scene {
    Scene::parse("", "bare.toml").unwrap()
}

fn pose(x: f64, y: f64, z: f64, pitch: f64, yaw: f64) -> Pose {
    Pose::new(x, y, z, Angle::from_deg(pitch), Angle::from_deg(yaw))
}

fn volts(scene: &Scene, p: &Pose) -> [f64; NDET] {
    let mut v = [0.0; NDET];
    Simulator::new(scene.clone(), 0).volts(p, &mut v);
    v
}

/// Sum of the light on a row or a column, offsets removed.
fn row_sum(v: &[f64; NDET], r: usize) -> f64 {
    (0..5).map(|c| v[index(r, c)] - 0.15).sum()
}
fn col_sum(v: &[f64; NDET], c: usize) -> f64 {
    (0..5).map(|r| v[index(r, c)] - 0.15).sum()
}

#[test]
fn zero_pose_centre_brightest_and_symmetric() {
    let s = Scene::default();
    let v = volts(&s, &pose(6.0, 0.0, 0.0, 0.0, 0.0));
    let centre = v[index(2, 2)];
    for (k, vk) in v.iter().enumerate() {
        if k != index(2, 2) {
            assert!(*vk < centre, "detector {k} brighter than centre");
        }
    }
    for r in 0..5 {
        for c in 0..5 {
            let a = v[index(r, c)];
            for b in [v[index(4 - r, c)], v[index(r, 4 - c)], v[index(c, r)]] {
                assert!((a - b).abs() < 1e-12, "asymmetric at ({r},{c})");
            }
        }
    }
}

#[test]
fn positive_yaw_and_positive_y_brighten_the_left_columns() {
    // MODEL.md: positive yaw turns the bow to starboard, so the beacon
    // appears to the left; positive y puts the vehicle right of the axis,
    // where the beam's gradient makes the left side brighter... both move
    // the spot to the left columns.
    let s = Scene::default();
    for p in [pose(6.0, 0.0, 0.0, 0.0, 8.0), pose(6.0, 0.4, 0.0, 0.0, 0.0)] {
        let v = volts(&s, &p);
        assert!(col_sum(&v, 0) > col_sum(&v, 4), "{p:?}");
        assert!(col_sum(&v, 1) > col_sum(&v, 3), "{p:?}");
        // rows stay symmetric
        assert!((row_sum(&v, 0) - row_sum(&v, 4)).abs() < 1e-9);
    }
}

#[test]
fn positive_pitch_and_positive_z_brighten_the_bottom_rows() {
    let s = Scene::default();
    for p in [pose(6.0, 0.0, 0.0, 8.0, 0.0), pose(6.0, 0.0, 0.4, 0.0, 0.0)] {
        let v = volts(&s, &p);
        assert!(row_sum(&v, 4) > row_sum(&v, 0), "{p:?}");
        assert!(row_sum(&v, 3) > row_sum(&v, 1), "{p:?}");
        assert!((col_sum(&v, 0) - col_sum(&v, 4)).abs() < 1e-9);
    }
}

#[test]
fn inverse_square_and_beer_along_the_axis() {
    let mut s = bare();
    s.offset_v = [0.0; NDET];
    for x in [2.0, 4.5, 8.5, 15.0] {
        let d = x - 0.229;
        let v = volts(&s, &pose(x, 0.0, 0.0, 0.0, 0.0))[index(2, 2)];
        let want = 135.0 * (-0.09 * d).exp() / (d * d);
        assert!((v / want - 1.0).abs() < 1e-12, "x = {x}");
    }
    // Beer's law alone: ratio of two ranges with K_D on and off.
    let mut clear = s.clone();
    clear.light.k_d = 0.0;
    let (a, b) = (5.0, 9.0);
    let r_on =
        volts(&s, &pose(b, 0.0, 0.0, 0.0, 0.0))[12] / volts(&s, &pose(a, 0.0, 0.0, 0.0, 0.0))[12];
    let r_off = volts(&clear, &pose(b, 0.0, 0.0, 0.0, 0.0))[12]
        / volts(&clear, &pose(a, 0.0, 0.0, 0.0, 0.0))[12];
    assert!((r_on / r_off - (-0.09f64 * (b - a)).exp()).abs() < 1e-12);
}

#[test]
fn gaussian_beam_off_axis() {
    // The detector facing the beacon (attitude turned to look at it) sees
    // the beam factor exp(−α²/2σ_b²) with α its angle off the axis.
    let mut s = bare();
    s.offset_v = [0.0; NDET];
    let (x, y) = (6.0f64, 0.8f64);
    // Yaw so that the centre normal points at the beacon: forward = −p/|p|,
    // i.e. turn to port (negative yaw) when right of the axis.
    let yaw = -(y / x).atan();
    let p = Pose::new(x, y, 0.0, Angle::ZERO, Angle::from_rad(yaw));
    let v = volts(&s, &p)[index(2, 2)];
    let r = (x * x + y * y).sqrt();
    let d = r - 0.229;
    let alpha = (y / x).atan();
    let sb = 12f64.to_radians();
    let want = 135.0 * (-alpha * alpha / (2.0 * sb * sb)).exp() * (-0.09 * d).exp() / (d * d);
    assert!((v / want - 1.0).abs() < 1e-9, "{v} vs {want}");
}

#[test]
fn detector_response_and_halo() {
    // On the axis, yawing by β puts the centre detector at β off the beacon.
    let mut s = bare();
    s.offset_v = [0.0; NDET];
    let on = volts(&s, &pose(6.0, 0.0, 0.0, 0.0, 0.0))[12];
    let beta = 10f64;
    // Yawing about the hemisphere centre also moves the detector: by hand,
    // it sits at (x − R cos ψ, R sin ψ), sees the beacon at β = ψ + atan(y_d/x_d)
    // off its normal and is α = atan(y_d/x_d) off the beam axis.
    let off = volts(&s, &pose(6.0, 0.0, 0.0, 0.0, beta))[12];
    let (rh, psi) = (0.229f64, beta.to_radians());
    let (xd, yd) = (6.0 - rh * psi.cos(), rh * psi.sin());
    let d = (xd * xd + yd * yd).sqrt();
    let a = (yd / xd).atan();
    let b = psi + a;
    let (sb, sr) = (12f64.to_radians(), 18f64.to_radians());
    let want = 135.0 * (-a * a / (2.0 * sb * sb)).exp() * (-0.09 * d).exp() / (d * d)
        * (-b * b / (2.0 * sr * sr)).exp();
    assert!((off / want - 1.0).abs() < 1e-12, "{}", off / want);
    assert!(on > off);
    // Scattering on: at β = 0 the bracket is (1 − f) + f·σ_R²/σ_T².
    let mut turbid = s.clone();
    turbid.light.scattering = Some(lightpose_core::Scattering::default());
    let with = volts(&turbid, &pose(6.0, 0.0, 0.0, 0.0, 0.0))[12];
    let d: f64 = 6.0 - 0.229;
    let f = 1.0 - (-0.5 * 0.09 * d).exp();
    let ratio = 324.0 / (324.0 + 400.0);
    assert!((with / on - ((1.0 - f) + f * ratio)).abs() < 1e-12);
}

#[test]
fn temperature_factor_at_20_and_30() {
    let mut s = bare();
    s.offset_v = [0.0; NDET];
    let p = pose(5.0, 0.0, 0.0, 0.0, 0.0);
    let v20 = volts(&s, &p)[12];
    s.temp_c = 30.0;
    let v30 = volts(&s, &p)[12];
    assert!((v30 / v20 - (576.0 - 60.0) / (576.0 - 40.0)).abs() < 1e-12);
}

#[test]
fn adc_clamps_and_rounds() {
    let mut s = bare();
    // Near the beacon the centre saturates; a large negative offset clamps to 0.
    let f = Simulator::new(s.clone(), 0).frame(0, 0.0, &pose(1.0, 0.0, 0.0, 0.0, 0.0), None);
    assert_eq!(f.counts[12], 1023);
    s.offset_v = [-1.0; NDET];
    let f = Simulator::new(s.clone(), 0).frame(0, 0.0, &pose(30.0, 0.0, 0.0, 0.0, 0.0), None);
    assert_eq!(f.counts[0], 0);
    // Noise-free counts are the rounded volts.
    let s = bare();
    let p = pose(7.0, 0.1, 0.2, 1.0, -2.0);
    let v = volts(&s, &p);
    let f = Simulator::new(s.clone(), 0).frame(0, 0.0, &p, None);
    for (c, vk) in f.counts.iter().zip(v) {
        assert_eq!(*c, volts_to_counts(vk, 5.0, 10));
        let exact = vk / 5.0 * 1023.0;
        assert!((*c as f64 - exact).abs() <= 0.5 + 1e-9);
    }
    // 16-bit ADC uses the whole range.
    let mut s16 = bare();
    s16.adc.bits = 16;
    let f = Simulator::new(s16, 0).frame(0, 0.0, &pose(1.0, 0.0, 0.0, 0.0, 0.0), None);
    assert_eq!(f.adc_bits, 16);
    assert_eq!(f.counts[12], 65535);
}

#[test]
fn noise_statistics() {
    // σ_e = 0.05 V on a 16-bit ADC (fine quantization): mean and σ of a
    // dim channel over many frames.
    let mut s = Scene::default();
    s.adc.bits = 16;
    let p = pose(6.0, 0.0, 0.0, 0.0, 0.0);
    let clean = volts(&s, &p);
    let mut sim = Simulator::new(s.clone(), 42);
    let n = 20_000;
    let (mut sum, mut sum2, mut tsum, mut tsum2) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        let f = sim.frame(i, 0.0, &p, None);
        let v = f.counts[0] as f64 * 5.0 / 65535.0;
        sum += v;
        sum2 += v * v;
        let t = f.temp_c.unwrap();
        tsum += t;
        tsum2 += t * t;
    }
    let mean = sum / n as f64;
    let sd = (sum2 / n as f64 - mean * mean).sqrt();
    assert!(
        (mean - clean[0]).abs() < 4.0 * 0.05 / (n as f64).sqrt() + 1e-4,
        "{mean} vs {}",
        clean[0]
    );
    assert!((sd / 0.05 - 1.0).abs() < 0.03, "sd {sd}");
    let tm = tsum / n as f64;
    let tsd = (tsum2 / n as f64 - tm * tm).sqrt();
    assert!(
        (tm - 20.0).abs() < 0.01 && (tsd / 0.1 - 1.0).abs() < 0.03,
        "{tm} {tsd}"
    );
    // Shot noise: variance grows by κ·E.
    let mut shot = s.clone();
    if let Some(nz) = shot.noise.as_mut() {
        nz.sigma_e_v = 0.0;
        nz.kappa_v = 0.01;
    }
    let mut e = [0.0; NDET];
    shot.light.irradiance(&shot.geometry, &p, &mut e);
    let mut sim = Simulator::new(shot, 7);
    let (mut s1, mut s2) = (0.0, 0.0);
    for i in 0..n {
        let v = sim.frame(i, 0.0, &p, None).counts[12] as f64 * 5.0 / 65535.0;
        s1 += v;
        s2 += v * v;
    }
    let m = s1 / n as f64;
    let sd = (s2 / n as f64 - m * m).sqrt();
    let want = (0.01 * e[12]).sqrt();
    assert!((sd / want - 1.0).abs() < 0.03, "{sd} vs {want}");
}

#[test]
fn same_seed_same_frames_other_seed_other_frames() {
    let s = Scene::default();
    let p = pose(6.0, 0.1, 0.1, 2.0, 3.0);
    let run = |seed| {
        let mut sim = Simulator::new(s.clone(), seed);
        (0..50)
            .map(|i| sim.frame(i, 0.0, &p, None))
            .collect::<Vec<_>>()
    };
    assert_eq!(run(5), run(5));
    assert_ne!(run(5), run(6));
}

#[test]
fn attitude_sensor_only_when_the_scene_has_one() {
    let p = pose(6.0, 0.0, 0.0, 4.0, -3.0);
    let f = Simulator::new(Scene::default(), 1).frame(0, 0.0, &p, None);
    assert!(f.attitude.is_none());
    let s = Scene::parse(
        "[attitude]\nsigma_pitch_deg = 0.3\nsigma_yaw_deg = 1.5\n",
        "a.toml",
    )
    .unwrap();
    let mut sim = Simulator::new(s, 1);
    let n = 4000;
    let (mut sp, mut sy) = (0.0, 0.0);
    for i in 0..n {
        let a = sim.frame(i, 0.0, &p, None).attitude.unwrap();
        sp += (a.pitch.deg() - 4.0).powi(2);
        sy += (a.yaw.deg() + 3.0).powi(2);
    }
    assert!(((sp / n as f64).sqrt() / 0.3 - 1.0).abs() < 0.05);
    assert!(((sy / n as f64).sqrt() / 1.5 - 1.0).abs() < 0.05);
}

/// A heading read near ±180° is reported within ±180°, as a sensor does
/// (a noise of 180° had written yaw readings of −219°, which replay
/// refused as no attitude at all).
#[test]
fn the_attitude_sensor_reports_its_heading_within_a_half_turn() {
    let p = pose(6.0, 0.0, 0.0, 4.0, 170.0);
    let s = Scene::parse("[attitude]\nsigma_yaw_deg = 180\n", "a.toml").unwrap();
    let mut sim = Simulator::new(s, 2);
    for i in 0..2000 {
        let yaw = sim.frame(i, 0.0, &p, None).attitude.unwrap().yaw.deg();
        assert!(yaw > -180.0 && yaw <= 180.0, "frame {i}: {yaw}");
    }
}

/// Spec v2: the depth sensor reads z, the DVL reads the velocity over the
/// ground in V (sideslip and heave included), each with its own noise, and
/// neither changes the counts of a frame.
#[test]
fn depth_and_dvl_read_the_truth_plus_their_noise() {
    use lightpose_core::{Attitude, BeamVec};
    use lightpose_sim::Kinematics;
    let k = Kinematics {
        pose: pose(6.0, 0.3, -0.2, 8.0, -20.0),
        velocity: BeamVec([-0.5, 0.1, 0.05]),
    };
    let exact = Scene::parse("[depth]\nsigma_m = 0\n[dvl]\nsigma_mps = 0\n", "s.toml").unwrap();
    let f = Simulator::new(exact, 3).frame_moving(0, 0.0, &k);
    assert_eq!(f.depth.unwrap().z, -0.2);
    let v = f.velocity.unwrap().v.0;
    let want = Attitude::new(k.pose.pitch, k.pose.yaw)
        .to_body(&k.velocity)
        .0;
    for c in 0..3 {
        assert!((v[c] - want[c]).abs() < 1e-15, "{v:?} vs {want:?}");
    }
    // Surge is the forward component of what the DVL reads.
    assert!((v[0] - k.surge()).abs() < 1e-12);

    let noisy = Scene::parse("[noise]\n[depth]\n[dvl]\n", "n.toml").unwrap();
    let mut sim = Simulator::new(noisy, 7);
    let n = 4000;
    let (mut dz, mut dz2, mut dv2) = (0.0, 0.0, [0.0; 3]);
    for i in 0..n {
        let f = sim.frame_moving(i, 0.0, &k);
        let e = f.depth.unwrap().z + 0.2;
        dz += e;
        dz2 += e * e;
        for c in 0..3 {
            let e = f.velocity.unwrap().v.0[c] - want[c];
            dv2[c] += e * e;
        }
    }
    let nf = n as f64;
    assert!((dz / nf).abs() < 0.002, "depth bias {}", dz / nf);
    let sd = (dz2 / nf).sqrt();
    assert!((sd - 0.02).abs() < 0.002, "depth σ {sd}");
    for s in dv2 {
        let sd = (s / nf).sqrt();
        assert!((sd - 0.02).abs() < 0.002, "DVL σ {sd}");
    }

    // The sensors' draws come after the light's: same seed, same counts.
    let plain = Scene::parse("[noise]\n", "p.toml").unwrap();
    let with = Scene::parse("[noise]\n[depth]\n[dvl]\n", "w.toml").unwrap();
    let a = Simulator::new(plain, 11).frame_moving(0, 0.0, &k);
    let b = Simulator::new(with, 11).frame_moving(0, 0.0, &k);
    assert_eq!(a.counts, b.counts);
    assert_eq!(a.temp_c, b.temp_c);
    assert!(a.depth.is_none() && a.velocity.is_none());
}
