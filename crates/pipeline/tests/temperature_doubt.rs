//! The tracker's σx holds a temperature read wrong: in the calibrated
//! water (K_D as the sweep's) with the attitude sensor, each run's water is
//! T0 ± 3 °C while the frames report T0 (MODEL.md's Monte Carlo), so every
//! channel is scaled by up to 1 % for the whole run and the light reads it
//! as range. Told that doubt (`temp_sigma_c`, which `lightpose montecarlo`
//! and `bench` set from the scene's spread), x's ±2σ covers the truth.
//!
//! Why: without it x covered 91–92 % with the attitude sensor and 70–76 %
//! with all three sensors (`ridge_diag`, 200 runs; the DVL and depth pin
//! everything but the range's offset), the RMS error 0.023 m against a σ
//! of 0.009–0.016 m. In water whose K_D is doubted (the bench's) K_D's
//! range doubt, ten times larger, hid it.

use lightpose_core::Status;
use lightpose_pipeline::{build_estimator, Calibration};
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// x's ±2σ coverage over `runs` runs of the tank zigzag with the attitude
/// sensor, each run's temperature drawn, the estimator told `sigma_temp_c`.
fn x_coverage(sigma_temp_c: f64, runs: u64) -> (usize, usize) {
    let r = root();
    let scene = Scene::load(&r.join("config/scenes/tank-ahrs.toml")).expect("tank-ahrs");
    let traj = Trajectory::load(&r.join("config/trajectories/zigzag.csv")).expect("zigzag");
    let cal = Calibration::load(&r.join("config/calibration/tank.toml")).expect("tank cal");
    assert!(
        scene.attitude.is_some(),
        "tank-ahrs has the attitude sensor"
    );
    let cal = cal.in_water_known_to(0.0, sigma_temp_c);
    let mut est = build_estimator("tracker", &cal).expect("tracker");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let (mut inside, mut n) = (0, 0);
    for run in 0..runs {
        // Temperatures spread evenly over ±2σ of 3 °C: the same draws for
        // both estimators, and no RNG in the test.
        let u = (run as f64 + 0.5) / runs as f64;
        let mut s = scene.clone();
        s.temp_c += 3.0 * 4.0 * (u - 0.5);
        let mut sim = Simulator::new(s, 500 + run);
        sim.set_reported_temp(Some(scene.temp_c));
        est.reset();
        for (j, &t) in times.iter().enumerate() {
            let (p, surge) = traj.sample(t);
            let e = est.estimate(&sim.frame(j as u64, t, &p, Some(surge)));
            if let (Some(x), Some(sx), Status::Ok) = (e.x, e.std.x, e.status) {
                n += 1;
                inside += usize::from((x - p.x).abs() <= 2.0 * sx);
            }
        }
    }
    (inside, n)
}

#[test]
fn x_sigma_holds_a_temperature_read_wrong() {
    let (told, n) = x_coverage(3.0, 24);
    let (untold, m) = x_coverage(0.0, 24);
    eprintln!("x's ±2σ covers {told}/{n} frames told the doubt, {untold}/{m} not");
    assert!(n > 24 * 30 && m > 24 * 30, "tracked frames: {n}, {m}");
    let share = |k: usize, n: usize| k as f64 / n as f64;
    assert!(share(told, n) >= 0.93, "told: {told}/{n}");
    // Not a wider σ everywhere: the runs whose temperature is near T0 are
    // covered either way; it is the far ones that the doubt holds.
    assert!(
        share(untold, m) < share(told, n) - 0.05,
        "untold: {untold}/{m}"
    );
}
