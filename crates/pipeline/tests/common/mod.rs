//! What the pipeline's tests share: a seeded normal draw, a run in water
//! drawn as `lightpose bench` draws it, and a minute of coming and going
//! with every own sensor.
#![allow(dead_code)]

use lightpose_core::Frame;
use lightpose_sim::{Scene, Simulator, Trajectory};
use std::path::{Path, PathBuf};

/// The workspace's root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// 95th percentile (nearest rank, as `replay --report` ranks it) of `v`;
/// the replay's own running quantile is internal to the pipeline.
pub fn p95(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty(), "no frames to rank");
    v.sort_by(f64::total_cmp);
    let k = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[k - 1]
}

/// The frames of a minute of coming and going between 4 and 6 m in the
/// tank with the attitude sensor, depth and a DVL, MODEL.md's noise
/// (tests/data/to-and-fro.csv, 301 frames at 5 Hz).
pub fn minute(seed: u64) -> Vec<Frame> {
    with_sensors("config/scenes/tank.toml", "tests/data/to-and-fro.csv", seed)
}

/// The frames of the shipped `scene` (a path from the root) with the
/// attitude sensor, depth and a DVL added, along `trajectory`, simulated
/// with `seed`.
pub fn with_sensors(scene: &str, trajectory: &str, seed: u64) -> Vec<Frame> {
    let text = std::fs::read_to_string(root().join(scene)).expect("scene");
    let scene = Scene::parse(
        &(text + "\n[attitude]\n\n[depth]\n\n[dvl]\n"),
        "scene+sensors",
    )
    .expect("scene with sensors");
    let traj = Trajectory::load(&root().join(trajectory)).expect("trajectory");
    let times: Vec<f64> = traj.frame_times(scene.adc.rate_hz).collect();
    let mut sim = Simulator::new(scene, seed);
    times
        .iter()
        .enumerate()
        .map(|(j, &t)| sim.frame_moving(j as u64, t, &traj.kinematics(t)))
        .collect()
}

/// A deterministic normal draw (Box–Muller on a small LCG) so the test
/// needs no RNG crate and every run is the same.
pub struct Lcg(pub u64);
impl Lcg {
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// A run of `scene` in water drawn as `lightpose bench` draws it (its
/// temperature, then its K_D, about the scene's), the vehicle reporting the
/// nominal temperature.
pub fn in_drawn_water(scene: &Scene, rng: &mut Lcg, seed: u64) -> Simulator {
    let mut s = scene.clone();
    s.temp_c += s.montecarlo.sigma_temp_c * rng.normal();
    s.light.k_d = (s.light.k_d + s.montecarlo.sigma_k_d * rng.normal()).max(0.0);
    let mut sim = Simulator::new(s, seed);
    sim.set_reported_temp(Some(scene.temp_c));
    sim
}
