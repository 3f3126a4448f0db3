//! The tracker's std is honest without the attitude sensor: a small Monte
//! Carlo on the paper's tank zigzag with the scene's K_D and temperature
//! spreads (as `lightpose bench` draws them), the ±2σ coverage of every
//! axis over the tracked frames.
//!
//! Why: without the sensor y/yaw and z/pitch lie on a ridge one frame
//! barely resolves, and the filter used to claim ridge information the
//! counts do not hold (coverage 44–80 %). This pins the fix (body motion
//! model, sigma-point update, the beam term in σx).

use lightpose_core::Angle;
use lightpose_core::Status;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Trajectory};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

mod common;
use common::{in_drawn_water, Lcg};

#[test]
fn tracker_std_covers_the_truth_without_the_attitude_sensor() {
    let r = root();
    let scene = Scene::load(&r.join("config/scenes/tank.toml")).expect("tank scene");
    let traj = Trajectory::load(&r.join("config/trajectories/zigzag.csv")).expect("zigzag");
    let cal = Calibration::load(&r.join("config/calibration/tank.toml")).expect("tank cal");
    assert!(
        scene.attitude.is_none(),
        "the tank scene has no attitude sensor"
    );
    // Each run's water is drawn below: the tracker is told its spread.
    let cal = cal.in_water_known_to(scene.montecarlo.sigma_k_d, scene.montecarlo.sigma_temp_c);
    let mut est = build_estimator("tracker", &cal).expect("tracker");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let mut rng = Lcg(7);
    let (mut inside, mut n) = ([0usize; 6], 0usize);
    for run in 0..30u64 {
        let mut sim = in_drawn_water(&scene, &mut rng, 100 + run);
        est.reset();
        for (j, &t) in times.iter().enumerate() {
            let (p, surge) = traj.sample(t);
            let e = est.estimate(&sim.frame(j as u64, t, &p, Some(surge)));
            // Without the sensor a tracked frame now says `ok`: its std is
            // honest (this test), so nothing is flagged.
            if e.status != Status::Ok {
                continue;
            }
            let truth = p.values_with_surge(surge);
            let got = e.values();
            let sd = e.std.values();
            n += 1;
            for c in 0..6 {
                let (Some(g), Some(s)) = (got[c], sd[c]) else {
                    panic!("frame {j}: field {c} missing in {e:?}");
                };
                if (g - truth[c]).abs() <= 2.0 * s {
                    inside[c] += 1;
                }
            }
        }
    }
    // Every frame after the start-up is tracked: surge, the last field to
    // be known, reaches `surge_max_sigma` 1.2–1.4 s (6–7 frames) in the
    // tank; measured 1006 of 1230 (1003 before the paper's law read K_D's
    // doubt, 1016 with `paper_range_sigma_scale` 0.5, 1027 before surge's
    // σ held the paper rate's drift, 889 before `paper_rate`, when it took
    // 1.6–2.2 s). Measured coverage: x 1.000 (0.903 with the scale at 0.5:
    // see the next test for why it is not), surge 0.988 (0.980 before the
    // law read K_D's doubt), the ridge axes 1.000.
    let start_frames = 13;
    assert!(
        n >= 30 * (times.len() - start_frames),
        "only {n} tracked frames"
    );
    let cover = inside.map(|k| k as f64 / n as f64);
    eprintln!(
        "coverage without the sensor (x, y, z, pitch, yaw, surge) over {n} frames: {cover:.3?}"
    );
    for c in cover {
        assert!(c >= 0.9, "coverage {cover:?}");
    }
}

/// And off the runs' axis: the paper's range law is read as if the vehicle
/// were on the beam axis, and its bias grows as the vehicle leaves it, so
/// σx must hold the law's error over the calibrated volume, not near the
/// axis only. Each run's truth is the tank dive moved by a constant y, z
/// of 1σ 3° of the start range off the axis and a pitch, yaw of 1σ 5°
/// (inside the calibration's grid and half the tracker's own start priors).
///
/// Why: with the law's residual halved in σx (`paper_range_sigma_scale`
/// 0.5, the default until it was measured here), x's ±2σ covered 66 % of
/// these runs (200 runs, `ridge_diag` with `OFF_AXIS=3,5`); at 1.0, 93 %.
/// Here: 786 of 1317 frames (59.7 %) at 0.5, 1164 of 1289 (90.3 %) at 1.0
/// (1171 of 1291 while one tracker took a told K_D doubt as ln(1 +
/// σ/K_D), and 1164 of 1289 before K_D was held as ln K_D; 1195 of 1293 before the paper's law read K_D's doubt: it now pins x
/// only outside that doubt, which the light's own range shares; 1193
/// before the tracker was told the temperature's doubt too).
#[test]
fn tracker_std_of_x_holds_off_the_axis_without_own_sensors() {
    let r = root();
    let scene = Scene::load(&r.join("config/scenes/tank.toml")).expect("tank scene");
    let traj = Trajectory::load(&r.join("config/trajectories/dive.csv")).expect("dive");
    let cal = Calibration::load(&r.join("config/calibration/tank.toml")).expect("tank cal");
    let cal = cal.in_water_known_to(scene.montecarlo.sigma_k_d, scene.montecarlo.sigma_temp_c);
    let mut est = build_estimator("tracker", &cal).expect("tracker");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let mut rng = Lcg(11);
    let (mut inside, mut n) = (0usize, 0usize);
    for run in 0..40u64 {
        let lateral = traj.knots()[0].pose.x * 3f64.to_radians().tan();
        let (dy, dz) = (lateral * rng.normal(), lateral * rng.normal());
        let dp = Angle::from_deg(5.0 * rng.normal());
        let dw = Angle::from_deg(5.0 * rng.normal());
        let moved = traj.moved(dy, dz, dp, dw);
        let mut sim = in_drawn_water(&scene, &mut rng, 300 + run);
        est.reset();
        for (j, &t) in times.iter().enumerate() {
            let k = moved.kinematics(t);
            let e = est.estimate(&sim.frame_moving(j as u64, t, &k));
            if let (Some(x), Some(sx), Status::Ok) = (e.x, e.std.x, e.status) {
                n += 1;
                inside += usize::from((x - k.pose.x).abs() <= 2.0 * sx);
            }
        }
    }
    let cover = inside as f64 / n as f64;
    eprintln!("x's ±2σ off the axis covers {inside}/{n} frames");
    assert!(n > 40 * 20, "only {n} tracked frames");
    assert!(
        cover >= 0.88,
        "x's ±2σ off the axis covers {:.1} %",
        100.0 * cover
    );
}
