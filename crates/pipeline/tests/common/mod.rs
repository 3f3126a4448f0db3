//! What the Monte Carlo tests share: a seeded normal draw and a run in
//! water drawn as `lightpose bench` draws it.

use lightpose_sim::{Scene, Simulator};

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
